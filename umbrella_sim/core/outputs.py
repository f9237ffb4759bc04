# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Output layer: one Sample per output instant, a RunResult of samples, and its summary."""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cache
from typing import Callable

import numpy as np

from .kernel import STEP_FIELDS


def build_frozen(cls, values: dict):
    """
    Return an instance of the frozen dataclass cls holding values (every field, trusted).

    The per-publication hot path: a frozen dataclass's __init__ sets each field through
    object.__setattr__ (~0.1 us a field); values, a dict the caller made for it, becomes the
    instance's __dict__ as it is.
    """
    if len(values) != _field_count(cls):
        raise TypeError(f'{cls.__name__} has {_field_count(cls)} fields, {len(values)} given')
    obj = object.__new__(cls)
    object.__setattr__(obj, '__dict__', values)
    return obj


@cache
def _field_count(cls) -> int:
    return len(fields(cls))


@dataclass(frozen=True)
class Sample:
    """
    The state of the planar frame at one instant, and what is recovered from it (SI units).

    time in s from the start; stage 'deploying' (stage 1) or 'locked' (stage 2); q, q' the
    generalized coordinates (RunResult.q_labels names them) and their rates; angles in rad
    from +X (alpha1 the leaf's, alpha2 the link's), the sleeve's height y_H in m; the tip
    G's deflection in m in the leaf's floating frame; fibre stresses in Pa, tension
    positive, at the stress points RunResult.leaf_stress_x / link_stress_x (m from O along
    the leaf, from O'' along the link), the peak |sigma| and where it is; energies in J.
    The comment beside each field says more.
    """

    time: float
    stage: str                     # "deploying" | "locked"
    q: np.ndarray
    qd: np.ndarray
    alpha1: float
    alpha2: float
    alpha1_rate: float
    alpha2_rate: float
    alpha1_accel: float
    sleeve_position: float         # y_H (m)
    sleeve_velocity: float         # dy_H/dt (m/s)
    sleeve_force: float            # F_H applied during the step that ended here (N, along -Y)
    tip_axial: float               # u of G in the leaf frame (m)
    tip_transverse: float          # v of G in the leaf frame (m)
    leaf_stress: np.ndarray        # (2, n_points): top, bottom fibre at leaf_stress_x (Pa)
    link_stress: np.ndarray        # (2, n_points): top, bottom fibre at link_stress_x (Pa)
    peak_stress_leaf: float        # max |sigma| on the leaf now (Pa; a step's: over the step)
    peak_stress_leaf_x: float      # where, m from O along the leaf
    peak_stress_link: float
    peak_stress_link_x: float      # m from O'' along the link
    stress_leaf_joint: float       # top-fibre stress on the leaf at O'' (Pa, Fig. 6.5)
    stress_link_mid: float         # top-fibre stress at mid-link (Pa, Fig. 6.6)
    multipliers: np.ndarray        # lambda (thesis sign: M q'' = ... + J^T lambda)
    sleeve_reaction: tuple         # force on the sleeve from axle (X) and stop (Y), N
    kinetic_energy: float          # T = 1/2 q'.M q' (J)
    strain_energy: float           # V (J): 1/2 q.K q, or the nonlinear law's
    work: float                    # work done by F_H since t = 0 (J)
    lock_energy_loss: float        # energy removed by the lock so far (J)
    constraint_residual: float     # max(|Phi|, |J q'|)
    damping_dissipation: float = 0.0   # energy removed by structural damping so far (J)
    axial_stress: float = 0.0      # largest |axial stress| of leaf and link (Pa; axial_stress_of)

    @property
    def sleeve_reaction_x(self) -> float:
        """Return the axle's force on the sleeve, X (N): sleeve_reaction[0]."""
        return self.sleeve_reaction[0]

    @property
    def sleeve_reaction_y(self) -> float:
        """Return the stop's force on the sleeve, Y (N; 0 before the lock): sleeve_reaction[1]."""
        return self.sleeve_reaction[1]

    def with_peaks(self, hold: dict) -> 'Sample':
        """Return this sample with the peak stresses (and where) held (StepBlock.merge_peaks)."""
        # (dataclasses.replace re-runs __init__: a per-publication cost)
        return build_frozen(Sample, {
            **self.__dict__, 'peak_stress_leaf': hold['leaf'][0],
            'peak_stress_leaf_x': hold['leaf'][1], 'peak_stress_link': hold['link'][0],
            'peak_stress_link_x': hold['link'][1]})


def axial_stress_of(leaf_stress, link_stress) -> float:
    """
    Return the largest axial stress |sigma_top + sigma_bottom| / 2 of leaf and link (Pa).

    leaf_stress, link_stress: (2, points), top and bottom fibre (a Sample's): the elastic
    axial stress the beams' strain gives (the compiled step's axial_stress row, the same
    arithmetic).
    """
    return float(max(np.abs(0.5 * (leaf_stress[0] + leaf_stress[1])).max(initial=0.0),
                     np.abs(0.5 * (link_stress[0] + link_stress[1])).max(initial=0.0)))


def mechanical_energy(s):
    """
    Return T + V (J): the energy of the balance, one rule.

    Of a Sample, or per step of a StepBlock or per sample of a RunResult (arrays).
    """
    if hasattr(s, 'column'):                        # a RunResult: its sample columns
        return s.column('kinetic_energy') + s.column('strain_energy')
    return s.kinetic_energy + s.strain_energy


def energy_balance(s, initial_energy: float):
    """
    Return the energy balance error (J), one rule: 0 for a run that keeps its energy.

    mechanical_energy - initial_energy - work of F_H + energy the lock removed + energy the
    damping dissipated, of a Sample or per step of a StepBlock (arrays).
    """
    return (mechanical_energy(s) - initial_energy - s.work + s.lock_energy_loss
            + s.damping_dissipation)


# STEP_FIELDS (kernel.py, from _kernel.h's UMBRELLA_STEP_FIELDS): the per-physics-step outputs
# of ``UmbrellaSimulator.advance``, in the order the compiled loop writes them; stage is the
# int code of model.Stage.  The state's figures at the step's end, except the peak stresses
# (and where): the largest over the whole step (``step_peaks``), so that a crest between two
# steps is not lost.


def step_row(s: Sample, peaks: tuple | None = None,
             axial_stress: float | None = None) -> list[float]:
    """
    Return the STEP_FIELDS of one sample (the reference the compiled outputs are tested on).

    peaks: the step's (peak_stress_leaf, its x, peak_stress_link, its x) (``step_peaks``)
    in place of the sample's own, which are those of its instant; axial_stress: the largest
    of the step's substeps' (fold_substeps) in place of the sample's.
    """
    row = [float(s.stage.code) if f == 'stage' else float(getattr(s, f)) for f in STEP_FIELDS]
    if peaks is not None:
        row[_STEP_PEAKS] = [float(v) for v in peaks]
    if axial_stress is not None:
        row[_AXIAL_STRESS] = float(axial_stress)
    return row


def state_row(s: Sample) -> np.ndarray:
    """
    Return the state row of one sample (a column of StepBlock.states).

    q, qd, then the fibre stresses: top of every stress point, then bottom, leaf points first.
    """
    return np.concatenate([s.q, s.qd, s.leaf_stress[0], s.link_stress[0], s.leaf_stress[1],
                           s.link_stress[1]])


#: a crest of hermite_peak inside the step counts if |p''| <= this * |p| there: the local
#: frequency its curvature gives, omega = sqrt(|p''| / |p|) / h, resolved (omega h <= 1)
RESOLVED_CREST = 1.0


def hermite_peak(s0, d0, s1, d1) -> np.ndarray:
    """
    Return the largest |p| on [0, 1] of the cubic p(0) = s0, p(1) = s1, p'(0) = d0, p'(1) = d1.

    Elementwise.  A fibre's stress over a physics step, from its values and its rates times
    the step at the two ends: the cubic Hermite interpolant, whose crest may lie between the
    steps (for the midpoint rule it is the constant-acceleration path between them, nearly
    a parabola).  A crest inside the step counts only where the step resolves it
    (RESOLVED_CREST): a sharper one belongs to a mode the step does not resolve, which the
    midpoint rule keeps at its energy but at an aliased frequency, and the interpolant is
    then not the motion (with a 0.5 ms step, N = 8, V0 = -0.2, it put the leaf's peak 35 %
    above the converged one); the ends' values stand there.  _kernel.c hermite_peak is the
    same arithmetic.
    """
    s0, d0, s1, d1 = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (s0, d0, s1, d1)))
    return _hermite_crest(s0, d0, s1, d1, np.maximum(np.abs(s0), np.abs(s1)))


#: |p(t)| <= max(|s0|, |s1|) + HERMITE_RATE_BOUND (|d0| + |d1|) on [0, 1]: the value basis
#: functions of the cubic Hermite interpolant sum to 1 there and are >= 0, the slope basis
#: functions are at most 4/27 in magnitude
HERMITE_RATE_BOUND = 4.0 / 27.0


def hermite_crests(s0, d0, s1, d1) -> np.ndarray:
    """
    Return hermite_peak of same-shape arrays whose last axis is a body's stress points.

    What the largest over the last axis needs: where a point's bound (HERMITE_RATE_BOUND)
    cannot pass the largest end value of its row, its own end values stand (its crest lies
    between them and that bound), and the interpolant is solved for the others only.
    """
    ends = np.maximum(np.abs(s0), np.abs(s1))
    reach = ends + HERMITE_RATE_BOUND * (np.abs(d0) + np.abs(d1))
    may = reach > ends.max(-1, keepdims=True)
    if not may.any():
        return ends
    out = ends.copy()
    out[may] = _hermite_crest(s0[may], d0[may], s1[may], d1[may], ends[may])
    return out


def _hermite_crest(s0, d0, s1, d1, best) -> np.ndarray:
    """Return hermite_peak of arrays of one shape, best = the larger |end value|."""
    a = 3.0 * (s1 - s0) - 2.0 * d0 - d1
    b = 2.0 * (s0 - s1) + d0 + d1
    qa, qb = 3.0 * b, 2.0 * a               # p'(t) = qa t^2 + qb t + d0
    disc = qb * qb - 4.0 * qa * d0
    real = disc >= 0.0
    r = -0.5 * (qb + np.copysign(np.sqrt(np.where(real, disc, 0.0)), qb))
    with np.errstate(divide='ignore', invalid='ignore'):
        for t in (np.where(r != 0.0, d0 / r, np.nan), np.where(qa != 0.0, r / qa, np.nan)):
            val = np.abs(s0 + t * (d0 + t * (a + t * b)))
            resolved = np.abs(2.0 * a + 6.0 * b * t) <= RESOLVED_CREST * val
            best = np.where(real & (t > 0.0) & (t < 1.0) & resolved & (val > best), val, best)
    return best


def step_peaks(start, end, h: float, stress_x: tuple) -> tuple[float, float, float, float]:
    """
    Return the largest fibre stress over a step and where: (leaf, x, link, x).

    start, end: (stresses, rates) at the step's two ends, each as ``UmbrellaModel.stresses``
    gives them ((leaf top, leaf bottom), (link top, link bottom)); h: the step (s);
    stress_x: the leaf's and the link's stress point abscissae.  Per point the larger of its
    two fibres' ``hermite_peak``; the first point holding the largest value.
    """
    out: list[float] = []
    for body, xs in enumerate(stress_x):
        peak = np.max([hermite_peak(start[0][body][f], h * start[1][body][f],
                                    end[0][body][f], h * end[1][body][f]) for f in (0, 1)],
                      axis=0)
        i = int(np.argmax(peak))
        out += [float(peak[i]), float(xs[i])]
    return tuple(out)


@dataclass
class LockEvent:
    time: float
    kind: str
    energy_before: float
    energy_after: float
    free_velocities: tuple = ()
    #: how well the physics step resolves the stage-2 stresses this lock starts
    #: (step_rule.stage2_resolution; None for the rigid models)
    stage2_resolution: dict | None = None


class StepBlock:
    """
    Hold the outputs of every physics step of one advance call.

    What ``UmbrellaSimulator.advance(n_steps)`` returns: one entry per physics step taken
    (1-D arrays, one attribute per name of STEP_FIELDS: ``block.time``, ``block.tip_transverse``,
    ...), the Sample of the final state (``last``, built on first use: stresses along the
    bodies, multipliers and residuals cost more than a step), the lock if it happened inside
    the block, and the fault that stopped the block early (the state is then the last good
    step, and the entries cover the steps taken before it).

    The entries are rows of one (len(STEP_FIELDS), steps) array, ``rows``, as the compiled
    loop writes them; a field is a view of its row, made when it is read (a block is made once
    per publication period, and most readers look at a few fields).  Read-only.

    ``states``: None, or with ``advance(n_steps, states=True)`` the state at the end of every
    step, one column a step, field-major as the compiled loop writes them (_kernel.h
    AdvanceCall.states): (2 n + 2 P, steps) for n coordinates and P stress points, the rows

        q (n: the Sample's q), q' (n: its qd), then the fibre stress at every stress point,
        top of every point, then bottom, leaf points first (P top rows: the leaf's
        leaf_stress[0], the link's link_stress[0]; then P bottom rows: leaf_stress[1],
        link_stress[1]),

    i.e. ``state_row`` of each step's Sample.

    ``physics_tips``: None where the rows are the block's physics steps; where stage 2 took
    its grid steps in substeps (a row folds them: fold_substeps), the time and tip deflection
    (tip_transverse) at the end of every physics step of the block, (2, physics steps) in
    order, what the summary's stage-2 figures take (summary.Stage2Series): those of the
    physics, not of the grid.
    """

    __slots__ = ('rows', 'make_last', 'lock', 'error', 'states', 'physics_tips', '_last',
                 '_peaks')

    def __init__(self, rows: np.ndarray, make_last: Callable[[], Sample],
                 lock: LockEvent | None = None, error: str | None = None,
                 states: np.ndarray | None = None, physics_tips: np.ndarray | None = None):
        if len(rows) != len(STEP_FIELDS):
            raise ValueError(f'a block has {len(STEP_FIELDS)} rows, not {len(rows)}')
        if states is not None and states.shape[1] != rows.shape[1]:
            raise ValueError(f'a block of {rows.shape[1]} steps with state rows of '
                             f'{states.shape[1]}')
        if physics_tips is not None and physics_tips.shape[1] < rows.shape[1]:
            raise ValueError(f'a block of {rows.shape[1]} steps with the tips of '
                             f'{physics_tips.shape[1]} physics steps')
        _set = object.__setattr__        # (read-only: __setattr__ refuses)
        _set(self, 'rows', rows)
        _set(self, 'make_last', make_last)
        _set(self, 'lock', lock)
        _set(self, 'error', error)
        _set(self, 'states', states)
        _set(self, 'physics_tips', physics_tips)
        _set(self, '_last', None)
        _set(self, '_peaks', None)

    def __setattr__(self, name, value):
        raise AttributeError(f'StepBlock is read-only (cannot set {name!r})')

    @property
    def last(self) -> Sample:
        if self._last is None:
            object.__setattr__(self, '_last', self.make_last())
        return self._last

    @classmethod
    def from_rows(cls, rows: np.ndarray, make_last: Callable[[], Sample], lock=None,
                  error=None, states: np.ndarray | None = None,
                  physics_tips: np.ndarray | None = None) -> 'StepBlock':
        """
        Build a block from its rows (len(STEP_FIELDS), steps).

        rows: (len(STEP_FIELDS), steps), owned by the block; make_last builds the Sample
        of the final state (a closure over that immutable state); states: the state rows
        (owned by the block too), or None; physics_tips: the tips of its physics steps
        where its rows fold stage 2's substeps (``physics_tips``), else None.
        """
        return cls(rows, make_last, lock, error, states, physics_tips)

    def __len__(self) -> int:
        return self.rows.shape[1]

    @classmethod
    def concatenate(cls, blocks: list['StepBlock']) -> 'StepBlock':
        """
        Return one block of consecutive blocks' steps (the last block's final state).

        Its state rows: every block's, if every block has them, else None.
        """
        if len(blocks) == 1:
            return blocks[0]
        rows = np.array([np.concatenate([getattr(b, f) for b in blocks]) for f in STEP_FIELDS])
        lock = next((b.lock for b in blocks if b.lock is not None), None)
        error = next((b.error for b in blocks if b.error is not None), None)
        states = (np.concatenate([b.states for b in blocks], axis=1)
                  if all(b.states is not None for b in blocks) else None)
        return cls.from_rows(rows, blocks[-1].make_last, lock, error, states,
                             physics_tips_of([(b.rows, b.physics_tips) for b in blocks]))

    @property
    def peaks(self) -> dict[str, tuple[float, float, float]]:
        """
        Return {body: (largest peak |sigma| over the block's steps, where, when)}.

        {} if the block is empty; the first step holding the largest value (as np.argmax).
        Computed once per block on Python floats: a live node's block holds ~10 steps, where
        every numpy call costs more than the loop (the publication and the summary share it).
        """
        if self._peaks is None:
            out: dict = {}
            if len(self):
                # one fancy index and one tolist for the five rows (a publication's ~10
                # steps: Python floats beat numpy calls)
                t, *rows = self.rows.take(_PEAK_ROWS, axis=0).tolist()
                for body, peaks, where in (('leaf', rows[0], rows[1]),
                                           ('link', rows[2], rows[3])):
                    i = peaks.index(max(peaks))
                    out[body] = (peaks[i], where[i], t[i])
            object.__setattr__(self, '_peaks', out)
        return self._peaks

    def merge_peaks(self, hold: dict) -> dict:
        """
        Return {body: (peak, x)}: the held peaks, with this block's where they are larger.

        A publication's peak-hold over the steps since the last one (RunDriver), updated in
        place and returned.
        """
        for body, (peak, x, _) in self.peaks.items():
            if peak > hold.get(body, (-1.0, 0.0))[0]:
                hold[body] = (peak, x)
        return hold


def _step_field(row: int, name: str) -> property:
    return property(lambda block: block.rows[row], doc=f'{name} at every step of the block')


for _row, _name in enumerate(STEP_FIELDS):
    setattr(StepBlock, _name, _step_field(_row, _name))
del _row, _name
#: the rows of a step's peak stresses and where (step_peaks)
_STEP_PEAKS = slice(STEP_FIELDS.index('peak_stress_leaf'),
                    STEP_FIELDS.index('peak_stress_link_x') + 1)
#: the row of a step's largest axial stress (the largest of its substeps': fold_substeps)
_AXIAL_STRESS = STEP_FIELDS.index('axial_stress')
#: rows StepBlock.peaks and SummaryAccumulator.add read together
_PEAK_ROWS = np.array([STEP_FIELDS.index(f) for f in (
    'time', 'peak_stress_leaf', 'peak_stress_leaf_x', 'peak_stress_link', 'peak_stress_link_x')])


def fold_substeps(rows: np.ndarray, states: np.ndarray | None, m: int
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    """
    Return the grid steps' rows (and state rows) of physics steps taken m to a grid step.

    rows: (len(STEP_FIELDS), steps) of consecutive physics steps, the first starting a grid
    step; each group of m ends a grid step (a last, shorter group: the steps a fault left).
    A grid step's row is its last physics step's, with the step's peak stresses the largest
    of its physics steps' (and where), and its axial stress the largest of theirs; its state
    row, its last one's.
    """
    ends = substep_ends(rows.shape[1], m)
    out = rows[:, ends]
    for peak in (_STEP_PEAKS.start, _STEP_PEAKS.start + 2):       # leaf, link: value, x
        at = first_largest_of_substeps(rows[peak], m)
        out[peak], out[peak + 1] = rows[peak, at], rows[peak + 1, at]
    out[_AXIAL_STRESS] = rows[_AXIAL_STRESS, first_largest_of_substeps(rows[_AXIAL_STRESS], m)]
    return out, None if states is None else states[:, ends]


def running_total(total, steps) -> np.ndarray:
    """
    Return a running figure after each of steps, summed on from its total before them.

    total: the figure so far (a work, a dissipation; a scalar or one value per rib); steps:
    what each step adds, steps first.  Each row is the row before plus its step, as one step
    at a time adds it, so the figure has the same bits however the run is chunked into
    blocks (np.cumsum(steps) + total rounds a block's partial sums apart from the total).
    """
    out = np.array(steps, dtype=float)      # (a copy: steps may be a reused buffer's view)
    if len(out):
        out[0] += total                     # (total + the first step: the sum one step makes)
        np.add.accumulate(out, axis=0, out=out)
    return out


#: the rows of a physics step's time and tip deflection (StepBlock.physics_tips)
TIP_ROWS = np.array([STEP_FIELDS.index('time'), STEP_FIELDS.index('tip_transverse')])


def physics_tips_of(parts: list) -> np.ndarray | None:
    """
    Return the physics_tips of consecutive parts of a block: [(rows, physics_tips or None)].

    None if no part folds substeps (its rows are then its physics steps); else every
    part's tips, a part whose rows are its physics steps giving their time and tip.
    """
    if all(tips is None for _, tips in parts):
        return None
    return np.hstack([rows[TIP_ROWS] if tips is None else tips for rows, tips in parts])


def substep_ends(steps: int, m: int) -> np.ndarray:
    """Return each grid step's last physics step of `steps` taken m a grid step (fold)."""
    if steps % m == 0:          # (whole grid steps, the usual run: no shorter last group)
        return np.arange(m - 1, steps, m)
    return np.minimum(np.arange(m - 1, steps + m - 1, m), steps - 1)


def first_largest_of_substeps(values: np.ndarray, m: int) -> np.ndarray:
    """
    Return each grid step's physics step of the largest of values (steps first), element-wise.

    Groups of m consecutive steps along the first axis, the last one possibly shorter; the
    first of the largest (argmax's: a NaN the largest).  The one rule of a grid step's peak
    over its substeps, for fold_substeps and the umbrella's (substeps3d.fold_substeps3d).
    """
    steps = len(values)
    groups = -(-steps // m)
    padded = values
    if steps % m:                   # (the shorter last group padded)
        padded = np.full((groups * m,) + values.shape[1:], -np.inf)
        padded[:steps] = values
    first = (m * np.arange(groups)).reshape((groups,) + (1,) * (values.ndim - 1))
    return padded.reshape((groups, m) + values.shape[1:]).argmax(1) + first
