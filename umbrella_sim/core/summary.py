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

"""
Summary figures of a run, from every physics step: one rule for each figure, used everywhere.

``SummaryAccumulator`` takes the StepBlocks of a run as they come (the CLI, the node, the
offline recorder and the sweep all feed it) and gives the figures: deploy time, stage-1 tip
deflection, stage-2 amplitude and period over a fixed window after the lock, peak stresses
and where, the energy balance, and where the run left the model's validity (the warnings).

Why one module: the figures and the validity rules that judge them (validity_warnings, with
each limit's calibration beside it) are one contract: every consumer (the planar and the
ribs' accumulators, the node, the CLI, a recording's reader) takes both from here, so that a
figure and the limit it is held to change together.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
import math
from typing import Callable

import numpy as np

from .forcing import TIME_RESOLUTION
from .outputs import (energy_balance, LockEvent, mechanical_energy, Sample, STEP_FIELDS,
                      step_row, StepBlock)
from .registry import SPECS
from .step_rule import (beams_record, COUPLING_DEFLECTION, lock_amplitudes, MAX_STEP_DIVISOR,
                        physics_step_of, resolution_of, resolving_step_hint,
                        STAGE1_STEP_LIMIT, stage2_step_needed, STRESS_SHARE_LIMIT)

#: the smallest energy scale of energy_drift (J): a run that never moves (V0 = 0, no force)
#: has round-off of ~1e-20 J on energies of ~1e-20 J, which is no drift of 100 %
ENERGY_SCALE_FLOOR = 1e-9
_TIME, _STAGE, _TIP, _FORCE, _RESIDUAL, _RATE, _AXIAL = (STEP_FIELDS.index(f) for f in (
    'time', 'stage', 'tip_transverse', 'sleeve_force', 'constraint_residual', 'alpha1_rate',
    'axial_stress'))


class _StepFieldBasis:
    """
    Each step field as a unit vector over STEP_FIELDS.

    A linear rule applied to it gives its coefficients on a block's rows: the rule stays
    written once, in outputs.py.
    """

    def __init__(self):
        for i, name in enumerate(STEP_FIELDS):
            setattr(self, name, np.eye(len(STEP_FIELDS))[i])


_BASIS = _StepFieldBasis()
#: per step, as _LINEAR @ block.rows: the mechanical energy, the energy balance without the
#: initial energy, the work, the tip deflection (the summary keeps their largest magnitudes)
_LINEAR = np.array([mechanical_energy(_BASIS), energy_balance(_BASIS, 0.0), _BASIS.work,
                    _BASIS.tip_transverse])
#: the step fields they combine, and the coefficients of each
_LINEAR_FIELDS = np.flatnonzero(np.any(_LINEAR != 0.0, axis=0))
_LINEAR_COEFFICIENTS = [_LINEAR[:, [j]] for j in _LINEAR_FIELDS]


def _linear_figures(rows: np.ndarray) -> np.ndarray:
    """
    Return _LINEAR @ rows, each column summed field by field in one order.

    A matrix product's rounding depends on how many columns it is given (its kernels
    differ), which made a summary figure at round-off level (energy_drift) depend on how a
    run was chunked; summed term by term each step's figures are the same bits whatever the
    block.
    """
    out = _LINEAR_COEFFICIENTS[0] * rows[_LINEAR_FIELDS[0]]
    for coefficients, row in zip(_LINEAR_COEFFICIENTS[1:], _LINEAR_FIELDS[1:]):
        out += coefficients * rows[row]
    return out


@dataclass
class RunResult:
    """
    What driver.simulate returns: a run's parameters, kept Samples, lock and summary figures.

    samples: the Sample kept every output_every steps (a run of N ribs keeps the umbrella's
    own samples); column(name) one field of them as an array; summary() the figures;
    error: why the run stopped early (what was computed before it is kept).
    """

    params: dict
    samples: list = field(default_factory=list)
    lock: LockEvent | None = None
    steps: int = 0
    wall_time: float = 0.0
    error: str | None = None
    recording_error: str | None = None       # the MCAP recording stopped early (why)
    q_labels: list = field(default_factory=list)
    leaf_stress_x: list = field(default_factory=list)   # m from O, per stress point
    link_stress_x: list = field(default_factory=list)   # m from O''
    figures: dict | None = None     # SummaryAccumulator.figures() of every physics step

    def column(self, name: str) -> np.ndarray:
        """Return a Sample field of every kept sample as an array (its unit: Sample's)."""
        return np.array([getattr(s, name) for s in self.samples], dtype=float)

    def summary(self) -> dict:
        """Return the run's summary figures (deploy_time, tip maxima, peaks: SI units)."""
        return summarize(self)


#: the stage-2 amplitude and period are measured over this window after the lock (s): six
#: periods of the thesis frame's first locked mode (~0.05 s), the same for a 1 s offline run
#: and a 10 min live one, so that runs of different lengths compare
STAGE2_WINDOW = 0.3
#: the stage-2 tip series kept for its period: the first physics step in each STAGE2_WINDOW /
#: STAGE2_SAMPLES (4.6 us) of the window, i.e. every step at any step above that (the
#: default 0.1 ms included); a 0.1 us step keeps 65 536 of its 3e6 (1 MB and ~0.1 s to
#: analyse, where all of them held 48 MB and took ~4 s at a node's stop); the amplitude and
#: the window's end stay those of every step.  With stage 2's substeps every physics step's
#: tip counts, not only the grid rows' (the blocks' physics_tips): on a 5 ms grid
#: (step_follows_mesh, 0.1 ms substeps, V0 = -0.2) the grid rows' period came out 4.2e-4
#: low and their amplitude 0.41 % low against the physics steps' (-0.05: 2.0e-4 and 0.87 %),
#: at the default run's 0.2 ms grid in two substeps the amplitude 0.12 % low
STAGE2_SAMPLES = 1 << 16
#: validity of the small-deformation (linear elastic field) model: the tip deflection |v_G|
#: may reach this fraction of the leaf length l1 + l2.  Beyond it the slope of the bent
#: leaf passes ~0.15 rad, where the neglected terms of the curvature and the membrane strain
#: (~v'^2, model flexible-nonlinear) reach a few percent (linear beam theory's L/10 rule)
TIP_DEFLECTION_LIMIT = 0.10
#: validity of the small-strain measures (u', v'' linear in the displacements, Hooke's law):
#: the peak fibre strain |sigma| / E may reach this (a metal yields first: 0.7 % for the
#: thesis's Al 7075-T6; a soft section does not)
STRAIN_LIMIT = 0.01


def oscillation_period(t: np.ndarray, x: np.ndarray) -> float:
    """
    Return the period of the dominant oscillation of x(t), robust to ripple and drift.

    x is detrended (least-squares straight line removed).  A first estimate comes from its
    upward zero crossings (linear interpolation between samples; a crossing counts only
    after x went below -30 % of its largest |x| since the previous one: hysteresis against
    the ripple of the higher modes): (last - first crossing) / (crossings - 1).  It is then
    refined to the period maximising the Hann-windowed Fourier amplitude (golden-section
    search in [0.8, 1.25] x the estimate), which the higher modes riding on the signal do
    not shift as they shift crossing times.  nan with fewer than two full periods.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if len(x) < 8 or t[-1] <= t[0]:
        return math.nan
    x = x - np.polyval(np.polyfit(t - t[0], x, 1), t - t[0])
    amp = float(np.abs(x).max())
    if amp == 0.0:
        return math.nan
    up = np.flatnonzero((x[:-1] < 0.0) & (x[1:] >= 0.0))
    low = np.flatnonzero(x < -0.3 * amp)
    crossings, last = [], -1
    for i in up:
        j = np.searchsorted(low, last + 1)     # armed: below -0.3 amp since the last one
        if j < len(low) and low[j] <= i:
            frac = -x[i] / (x[i + 1] - x[i])
            crossings.append(t[i] + frac * (t[i + 1] - t[i]))
            last = i
    if len(crossings) < 3:
        return math.nan
    guess = float((crossings[-1] - crossings[0]) / (len(crossings) - 1))
    xw = x * np.hanning(len(x))

    def minus_amplitude(period):
        return -abs(np.dot(xw, np.exp(-2j * math.pi * t / period)))

    lo, hi = 0.8 * guess, 1.25 * guess
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = hi - g * (hi - lo), lo + g * (hi - lo)
    fc, fd = minus_amplitude(c), minus_amplitude(d)
    while hi - lo > 1e-9 * guess:
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - g * (hi - lo)
            fc = minus_amplitude(c)
        else:
            lo, c, fc = c, d, fd
            d = lo + g * (hi - lo)
            fd = minus_amplitude(d)
    return 0.5 * (lo + hi)


def deploy_start(v0: float, forces) -> float | None:
    """
    Return when the deployment started: the origin of a run's deploy time (one rule).

    t = 0 if the frame moves from the start (v0 != 0), else the first instant a non-zero
    sleeve force acts; None if neither happened.  forces: (t, F) in time order, each F
    acting from t, a later value at the same t replacing an earlier one (the parameter's
    value at t = 0, then a command or profile row at t = 0 that replaces it).  A frame at
    rest that waits for its first command does not deploy while it waits: the thesis's
    deploy time runs from the initial velocity V0.
    """
    if v0 != 0.0:
        return 0.0
    pending = None          # (t, F) not yet known to be the last value at its t
    for t, f in forces:
        if pending is not None and t > pending[0] + 1e-12 and pending[1] != 0.0:
            return float(pending[0])
        pending = (t, f)
    return float(pending[0]) if pending is not None and pending[1] != 0.0 else None


def deploy_start_of(params, applied) -> float | None:
    """deploy_start of a recorded run: its parameters (registry defaults) and applied forces."""
    from .registry import defaults

    given = {**defaults(), **dict(params)}
    return deploy_start(float(given['v0']),
                        [(0.0, float(given['sleeve_force'])), *applied])


def in_stage2_window(t, lock_time: float, window: float = STAGE2_WINDOW):
    """
    Say which instants t (an array, or one) are in stage 2's window: (lock, lock + window].

    The one rule of every stage-2 figure, offline and live; a time within TIME_RESOLUTION
    (the 1 ns of a recording's stamps) of the window's end is in it.
    """
    return (t > lock_time) & (t <= lock_time + window + TIME_RESOLUTION)


def amplitude(v) -> float:
    """Return the amplitude of a vibration v: half its peak-to-peak."""
    return 0.5 * float(np.max(v) - np.min(v))


def stage2_figures(t: np.ndarray, v: np.ndarray, lock_time: float | None) -> dict:
    """
    Return the stage-2 amplitude and period of the tip deflection v(t).

    Over the window (lock, lock + STAGE2_WINDOW], or the part of it the run covers
    (reported as stage2_window): the amplitude of v and oscillation_period(t, v).
    """
    out = {'stage2_window': None, 'stage2_tip_amplitude': None, 'stage2_tip_period': None}
    if lock_time is None:
        return out
    keep = in_stage2_window(t, lock_time)
    t, v = t[keep], v[keep]
    if len(v) <= 8:
        return out
    out['stage2_window'] = [float(lock_time), float(t[-1])]
    out['stage2_tip_amplitude'] = amplitude(v)
    period = oscillation_period(t, v)
    out['stage2_tip_period'] = None if math.isnan(period) else period
    return out


class Stage2Series:
    """
    The tip deflections of stage 2's window, a block of steps at a time: what its figures need.

    Columns of tip deflection (the planar tip's v: one; the umbrella's: each rib's in-plane v
    and out-of-plane w) over (lock, lock + STAGE2_WINDOW] at every physics step (where
    stage 2 takes substeps, each substep's: the blocks' physics_tips, not only their grid
    rows): each column's extremes and the window's end of every step, and for the periods
    the first step in each of STAGE2_SAMPLES bins of the window.  figures() gives
    stage2_figures' of each column, its amplitude of every step.
    """

    def __init__(self, columns: int = 1):
        self._t: list = []
        self._v: list = []
        self._bin, self._end = -1.0, 0.0
        self._lo, self._hi = np.full(columns, math.inf), np.full(columns, -math.inf)
        self._said: tuple | None = None      # (the rows and lock it was of, figures())

    @property
    def kept(self) -> int:
        """Return how many steps are kept for the periods (at most STAGE2_SAMPLES + 1)."""
        return sum(len(t) for t in self._t)

    def end(self, lock_time: float) -> float:
        """Return the window's end: steps after it are not taken."""
        return lock_time + STAGE2_WINDOW + TIME_RESOLUTION

    def add(self, t: np.ndarray, v: np.ndarray, lock_time: float) -> None:
        """Take steps at times t (stage 2 or not), v (steps, columns), the lock at lock_time."""
        keep = in_stage2_window(t, lock_time)
        t2, v2 = t[keep], v[keep]
        if not len(t2):
            return
        np.minimum(self._lo, v2.min(0), out=self._lo)
        np.maximum(self._hi, v2.max(0), out=self._hi)
        self._end = float(t2[-1])
        bins = np.floor((t2 - lock_time) * (STAGE2_SAMPLES / STAGE2_WINDOW))
        first = np.diff(bins, prepend=self._bin) != 0      # (STAGE2_SAMPLES)
        self._bin = float(bins[-1])
        self._t.append(t2[first])
        self._v.append(v2[first])

    def figures(self, lock_time: float | None) -> list[dict]:
        """Return each column's stage-2 figures by stage2_figures' rule (None: no window)."""
        if not self._t:
            return [stage2_figures(np.zeros(0), np.zeros(0), None) for _ in self._lo]
        # (a period's search costs ~1 ms a column, and a node asks every second: made again
        # only when rows came, or for another lock)
        key = (len(self._t), self._end, lock_time)
        if self._said is None or self._said[0] != key:
            self._said = (key, self._figures(lock_time))
        return [dict(f, stage2_window=f['stage2_window'] and list(f['stage2_window']))
                for f in self._said[1]]

    def _figures(self, lock_time: float) -> list[dict]:
        t, v = np.concatenate(self._t), np.concatenate(self._v)
        out = []
        for j in range(v.shape[1]):
            f = stage2_figures(t, v[:, j], lock_time)
            if f['stage2_tip_amplitude'] is not None:     # of every step, not those kept
                f['stage2_tip_amplitude'] = 0.5 * float(self._hi[j] - self._lo[j])
                f['stage2_window'][1] = self._end
            out.append(f)
        return out


def lock_warning(params: dict, lock_kind: str | None) -> str | None:
    """Return a warning if the lock asked for does not apply to the model (else None)."""
    asked = params.get('lock')
    if lock_kind is not None and asked not in (None, 'auto') and asked != lock_kind:
        return (f'lock not applicable: lock={asked} does not apply to model='
                f"{params.get('model')} (a rigid mechanism stopped at a point keeps no "
                f'kinetic energy to redistribute); the {lock_kind} lock is used; set '
                f'lock={lock_kind} to silence this')
    return None


def coarse_step_warning(resolution: dict | None, hint: str | Callable[[float], str] = '',
                        deflection: float = 0.0) -> str | None:
    """
    Return a warning when the step leaves the modes carrying the stage-2 stresses unresolved.

    resolution: the lock's (LockEvent.stage2_resolution), None before the lock or for a
    rigid model.  The step stage 2 needs: step_rule.stage2_step_needed at the lock's stage-2
    tip deflection over the leaf (its "deflection"; else the run's largest, deflection).
    Coarser, the stage-2 peaks (and the tip series past step_rule.COUPLING_DEFLECTION,
    where the modes couple) are not those of the model (docs/validation.md).  The text names
    the shares and that step; hint: how the run's parameters get it
    (step_rule.resolving_step_hint), '' if they already do, or a function of that step
    giving it.
    """
    if not resolution:
        return None
    deflection = resolution.get('deflection', deflection)
    h = resolution['step']
    enough = stage2_step_needed(resolution, deflection)
    if enough is not None and enough >= h * (1.0 - 1e-9):
        return None
    if enough is None:
        fix = (f'no step down to {h / MAX_STEP_DIVISOR:.3g} s (1/{MAX_STEP_DIVISOR} of this '
               'one) resolves them: give a smaller time_step')
    else:
        hint = hint(enough) if callable(hint) else hint
        fix = f'time_step <= {_rounded_down(enough):.3g} s resolves them' + (
            f' ({hint})' if hint else '')
    crest = (f"{100 * resolution['leaf']:.3g} % of the leaf's and "
             f"{100 * resolution['link']:.3g} % of the link's stage-2 stress crest at the lock")
    if deflection > COUPLING_DEFLECTION:
        modes = (f'modes the physics step {h:g} s does not resolve carry {crest}, and'
                 if max(resolution['leaf'], resolution['link']) > 0.0 else
                 f'the physics step {h:g} s resolves every mode carrying stage-2 stress, but')
        return (f'coarse step: {modes} at a tip deflection of {100 * deflection:.3g} % of the '
                f'leaf (past {100 * COUPLING_DEFLECTION:g} %) the frame couples its modes: the '
                'stage-2 '
                'peak stresses may be several % off and the tip series several mm (3-5 % and '
                '2-4 mm at one element per segment in the step study); '
                f'{fix}')
    return (f'coarse step: modes the physics step {h:g} s does not resolve carry {crest} '
            f'(limit {100 * STRESS_SHARE_LIMIT:g} %): the stage-2 peak stresses are not those '
            f'of the model; {fix}')


def _rounded_down(x: float) -> float:
    """Return x rounded down to three significant digits."""
    scale = 10.0 ** (math.floor(math.log10(x)) - 2)
    return math.floor(x / scale * (1 + 1e-12)) * scale


def mesh_resolution(params: dict, step: float) -> dict | None:
    """
    Return stage2_resolution of a run known by its parameters and step alone (no lock state).

    For a recording without the lock's own figures: the mesh's lock (step_rule.lock_amplitudes)
    stands for the run's.  None for a rigid model or parameters that do not make one.
    """
    p = beams_record(params)
    try:
        return None if p is None else _mesh_resolution(p, float(step))
    except ValueError:      # (parameters that make no model: no model to judge)
        return None


@cache
def _mesh_resolution(p, step: float) -> dict:
    from .model import UmbrellaModel

    model = UmbrellaModel(p)
    return resolution_of(model, lock_amplitudes(model), step)


#: rigid-fe's figures of the elastic field, which its constraints hold at zero: their
#: round-off (1e-26 m, 1e-14 Pa) is reported as the zero the model means
RIGID_FE_ZEROS = ('tip_deflection_max', 'stage2_tip_amplitude', 'peak_stress_leaf',
                  'peak_stress_link', 'stress_ratio_max', 'tip_deflection_ratio_max')


#: Euler-Bernoulli beams leave out shear deformation and rotary inertia: a member may be as
#: short as this many times its section's depth.  A pinned member's first bending frequency,
#: Timoshenko's against Euler-Bernoulli's, 1 / sqrt(1 + (pi r / L)^2 (1 + E / (kappa G))) (r
#: the radius of gyration, kappa 5/6 for a rectangle, nu 0.33): 1.7 % lower at L / b = 10,
#: 6.3 % at 5, 27 % at 2 (Timoshenko, Philosophical Magazine 41, 1921)
SLENDERNESS_LIMIT = 10.0
#: kg/m³: below every solid a rib is made of (balsa ~150, CFRP ~1600, aluminium ~2700): a
#: density given in g/cm³ (2.77 for 2770) runs a frame a thousand times too light, whose
#: figures no other warning questions
DENSITY_LOW = 100.0
#: Pa: below every solid a rib is made of (soft rubber ~1e6, polymers 1e9-3e9, aluminium
#: 7.2e10): a modulus given in GPa (72 for 72e9) or MPa (72000) runs beams millions of times
#: too soft, which the strain and deflection warnings question only as their figures
YOUNGS_MODULUS_LOW = 1e6
#: m: longer than the ribs of any deployable antenna (tens of m at most): a length given in mm
#: (600 for 0.6 m) runs a frame a thousand times too large, whose first steps fail ('Newton
#: did not converge') without naming the length
LENGTH_HIGH = 100.0


def parameter_warnings(params: dict) -> list[str]:
    """
    Return where the parameters leave the model's assumptions (static warnings).

    From the parameters alone: 'damping not applicable', a damping_ratio given to a model
    without an elastic field (rigid, rigid-fe), which takes no effect; for the beams'
    models, 'outer fibre', area and second_moment_of_area given beside section_height at
    its default (the thesis's 10 mm square) whose square they are not (a round bar's A and
    I, say): the stresses take the outer fibre at b/2 all the same (params.fibre_distance);
    'thick beam', a member (l1, l2, l3) shorter than SLENDERNESS_LIMIT section depths, and
    'coarse stage-1 step', a stage-1 step coarser than step_rule.STAGE1_STEP_LIMIT; for
    every model 'density', a density below DENSITY_LOW (kg/m³ given as g/cm³, say); for the
    beams' models 'youngs_modulus', a modulus below YOUNGS_MODULUS_LOW (GPa or MPa, say);
    for every model 'length', a member (l1, l2, l3) longer than LENGTH_HIGH (mm, say).
    """
    density = params.get('density', SPECS['density'].default)
    out = [f'density: {density:g} kg/m³ is below any solid a rib is made of (balsa ~150, '
           'CFRP ~1600, aluminium ~2700 kg/m³): its unit is kg/m³ (a density in g/cm³ times '
           '1000)'] if density < DENSITY_LOW else []
    long = [f'{n} = {params.get(n, SPECS[n].default):g} m' for n in ('l1', 'l2', 'l3')
            if params.get(n, SPECS[n].default) > LENGTH_HIGH]
    if long:
        out.append(f"length: {', '.join(long)}: longer than the ribs of any deployable "
                   f'antenna (tens of m at most; limit {LENGTH_HIGH:g} m): its unit is m (a '
                   'length in mm times 1e-3)')
    beams = beams_record(params)
    if beams is not None and beams.youngs_modulus < YOUNGS_MODULUS_LOW:
        out.append(f'youngs_modulus: {beams.youngs_modulus:g} Pa is below any solid a rib is '
                   'made of (soft rubber ~1e6, polymers ~1e9 to 3e9, aluminium ~7.2e10 Pa): '
                   'its unit is Pa (a modulus in GPa times 1e9, in MPa times 1e6)')
    if beams is None:
        model, damping = params.get('model'), params.get('damping_ratio', 0.0)
        return out + ([f"damping not applicable: damping_ratio {damping:g} is the beams' "
                       f'structural damping; model {model} has no elastic field to damp and '
                       'takes no effect of it'] if damping > 0.0 and model in (
                           'rigid', 'rigid-fe') else [])
    stage1, measured = physics_step_of(beams), STAGE1_STEP_LIMIT
    if stage1 > measured * (1.0 + 1e-9):
        out.append(f'coarse stage-1 step: stage 1 (the deployment) takes the physics step '
                   f'{stage1:g} s, coarser than the {measured:g} s up to which its peak '
                   "stresses were measured within 3 %: the elements' modes that carry them, "
                   'and the state the lock starts stage 2 from, are not resolved (the '
                   "thesis's frame, 1-8 elements a segment, against 5-10 us: up to 4.4 % off "
                   f'at 0.4-0.5 ms, up to 15 % at 1 ms); time_step <= {measured:g} s '
                   'resolves them (time_step 0 takes 0.2 ms or finer)')
    area, inertia = beams.area, beams.second_moment_of_area
    height = beams.section_height
    if area > 0.0 and inertia > 0.0 and height == SPECS['section_height'].default and not (
            math.isclose(area, height ** 2, rel_tol=1e-3)       # (a rounded square's too)
            and math.isclose(inertia, height ** 4 / 12.0, rel_tol=1e-3)):
        rectangle = beams.replace(section_height=0.0).fibre_distance    # (params' rule)
        out.append(f'outer fibre: area {area:.6g} m² and second_moment_of_area {inertia:.6g} '
                   'm⁴ are given beside section_height at its default b = '
                   f"{1e3 * height:.6g} mm, and they are not that square's (A = "
                   f'{height ** 2:.6g} m², I = {height ** 4 / 12.0:.6g} m⁴): the stresses take '
                   f'the outer fibre at b/2 = {500 * height:.6g} mm; if that is not your '
                   "section's, give section_height twice its outer fibre distance (a round "
                   "bar: its diameter), or 0 for a rectangle's √(3I/A) = "
                   f'{1e3 * rectangle:.4g} mm')
    if height <= 0.0 and not (area > 0.0 and inertia > 0.0):
        return out                  # (no section to judge: refused by validation)
    depth = 2.0 * beams.fibre_distance          # (the section's depth: b, or the rectangle's)
    name, length = min((('l1', beams.l1), ('l2', beams.l2), ('l3', beams.l3)),
                       key=lambda nl: nl[1])
    if length < SLENDERNESS_LIMIT * depth:
        out.append(f'thick beam: {name} = {length:.6g} m is {length / depth:.3g} section '
                   f'depths ({1e3 * depth:.6g} mm; limit {SLENDERNESS_LIMIT:g}): '
                   'Euler-Bernoulli beams leave out shear deformation and rotary inertia, '
                   "which lower a pinned member's first bending frequency by 1.7 % at 10 "
                   'depths, 6.3 % at 5, 27 % at 2 (Timoshenko)')
    return out


#: the geometrically exact beam (flexible-nonlinear) takes a fibre's slope |v'| in its body
#: frame as sin psi of its turn psi from that frame: its coordinates end at psi = 90 deg (the
#: run stops there), and near it the small-strain error eps tan(psi) of the section angle grows
#: (tan 80 deg = 5.7); a run whose fibres turn past this slope (80 deg) is named
SECTION_SLOPE_LIMIT = math.sin(math.radians(80.0))


def geometric_validity_warnings(params: dict, peak_stress: float,
                                section_slope: float | None = None,
                                strain: tuple | None = None) -> list[str]:
    """
    Return where a run of the geometrically exact model left that model's validity.

    flexible-nonlinear (the co-rotational beam of nonlinear.py) is exact for large rotations
    and small strains: 'large strain' when the peak fibre strain |sigma| / E (which bounds the
    membrane strain |eps| too) passes STRAIN_LIMIT (above yield too, where validity_warnings'
    own large-strain warning gives way to the yield warning); 'fibre rotation' when a section
    turned past SECTION_SLOPE_LIMIT from its body frame (section_slope: the largest |v'| over
    every step, from the engine; None when not known, e.g. a recording's figures).  strain:
    (|sigma| / E, |sigma|) of the fibre strained most where E is not params' alone (the
    umbrella's ribs, each of its own E: validity_warnings).  Other models: none.
    """
    if params.get('model') != 'flexible-nonlinear':
        return []
    out = []
    strain, strained = strain or (peak_stress / params['youngs_modulus'], peak_stress)
    if strain > STRAIN_LIMIT and strained > params['yield_strength']:
        out.append(f'large strain: peak |sigma| / youngs_modulus = {100 * strain:.3g} % '
                   f'(limit {100 * STRAIN_LIMIT:g} %): the co-rotational beam of '
                   'flexible-nonlinear is exact for large rotations but small strains only')
    if section_slope is not None and section_slope > SECTION_SLOPE_LIMIT:
        turn = math.degrees(math.asin(min(section_slope, 1.0)))
        out.append(f"fibre rotation: a fibre turned {turn:.1f} deg from its body frame (|v'| = "
                   f'{section_slope:.4f}; limit {math.degrees(math.asin(SECTION_SLOPE_LIMIT)):g}'
                   " deg): flexible-nonlinear's slope coordinates end at 90 deg, and near it "
                   'the error eps tan(psi) of its section angles grows '
                   '(docs/validation_nonlinear.md)')
    return out


#: validity of the linear beams (model flexible) in a turning leaf: the leaf's centrifugal
#: tension at its hinge over its Euler load pi^2 E I / L^2 (leaf_tension_ratio: omega^2
#: (rho A L^2 / 2 + m_tip L) with omega its hinge rate and L = l1 + l2, plus a spinning
#: base's share) may reach this fraction in stage 1 (before the lock).  The floating-frame
#: beams have no geometric stiffness: a leaf under tension bends less than they say, by about
#: that fraction (the rotating cantilever's published stiffening,
#: docs/validation_nonlinear.md).  Calibrated against flexible-nonlinear in stage 1 over 26
#: runs on a fixed hub (docs/validation_nonlinear.md, "Where the linear model leaves its
#: range": V0, mesh, sleeve force, section, the ribs' tip mass): the stage-1 tip error is
#: 0.53-1.8 times the ratio; planar V0 = -0.2 (the default) 0.0095 and 0.5-0.7 %, V0 = -0.3
#: 0.021 and 1.6-1.7 %, V0 = -0.5 0.059 and 5.5-6.5 %, V0 = -1 0.237 and 19-21 %; the ribs'
#: Exudyn case (V0 = -1, 0.1 kg tip on rib 1) 0.41 and 44 % in plane (35 % out of it), at
#: V0 = -0.3 0.037 and 5.2 %, at -0.2 0.016 and 1.5-2.1 %.  At 0.025 every run more than 5 %
#: off (tip or peak stress) warns, no quiet run is more than 2.1 % off, the warned ones at
#: least 3.6 %, and the default runs (0.0095) are quiet: with the thesis's data it warns from
#: V0 = -0.32 m/s.  The link's compression (< 1.5 % of its Euler load in a free stage 1) and
#: the largest section rotation |v'| do not separate those runs.
#: A base spinning about the hub axis at Omega (base prescribed or free, ribs >= 2) adds the
#: spin's share of leaf_tension_ratio, (Omega cos alpha1)^2 (rho A L^2 / 2 + m_tip L) +
#: Omega^2 cos alpha1 a (rho A L + m_tip), largest as the leaf opens; it stiffens mostly the
#: out-of-plane bending the spin-up drives.  Checked over 15 spinning runs (the same section:
#: 3 ribs at V0 = -0.2 spun up to 2-30 rad/s over 0.05 or 0.2 s, 1 or 2 elements, a hub
#: radius, a light free bus): the largest stage-1 error (tips, von Mises) is 0.32-1.07 times
#: the ratio, less than on a fixed hub; 5 rad/s 0.0145 and 1.1 %, 10 rad/s 0.040 and 2.6 %
#: (out of plane), 15 rad/s 0.083 and 6.2 %, 20 rad/s 0.141 and 12.7 %, 20 rad/s over 0.2 s
#: 0.093 and 9.1 % (the hinge rate alone 0.023: quiet before the spin counted).  The same
#: limit still separates them: every run more than 5 % off warns, no quiet run is more than
#: 1.9 % off, a warned one at least 2.6 % (the spin's warning comes early, on the safe side):
#: with the thesis's data at V0 = -0.2 it warns from a spin of about 7.5 rad/s (0.05 s ramp)
CENTRIFUGAL_TENSION_LIMIT = 0.025


def centrifugal_tension_per_rate(p, tip_mass: float = 0.0) -> float:
    """
    Return the leaf's centrifugal tension over its Euler load, per squared hinge rate (s^2).

    p: the planar record (UmbrellaParams, a rib's own); tip_mass: a point mass at G (kg).  A
    leaf of length L = l1 + l2 turning at omega about its hinge carries there the tension
    omega^2 (rho A L^2 / 2 + m_tip L); its Euler load pi^2 E I / L^2.  The ratio times
    omega^2 is CENTRIFUGAL_TENSION_LIMIT's figure on a fixed hub (leaf_tension_ratio).
    """
    length = p.l1 + p.l2
    return (p.mass_per_length * length ** 2 / 2.0 + tip_mass * length) / _euler_load(p)


def _euler_load(p) -> float:
    """Return the leaf's Euler load pi^2 E I / L^2 (N), L = l1 + l2 (the planar record p)."""
    return math.pi ** 2 * p.youngs_modulus * p.cross_section_inertia / (p.l1 + p.l2) ** 2


def hub_spin_tension_per_rate(p, tip_mass: float = 0.0, hub_radius: float = 0.0) -> float:
    """
    Return the hub circle's share of a spinning base's leaf tension over the Euler load (s^2).

    a (rho A L + m_tip) / (pi^2 E I / L^2): the leaf's mass at the hub radius a
    (leaf_tension_ratio's per_hub).  p, tip_mass as centrifugal_tension_per_rate's.
    """
    return hub_radius * (p.mass_per_length * (p.l1 + p.l2) + tip_mass) / _euler_load(p)


def leaf_tension_ratio(per_rate, rate, spin=None, alpha1=None, per_hub=None):
    """
    Return the leaf's tension at its hinge over its Euler load: CENTRIFUGAL_TENSION_LIMIT's figure.

    per_rate: centrifugal_tension_per_rate (s^2); rate: the hinge rate omega = alpha1' (rad/s);
    spin: the base's rate Omega about the hub axis Y (rad/s; None: a fixed hub, the planar
    model), alpha1 the leaf's angle from the hub plane (rad: model3d's, the leaf along
    cos alpha1 e_r + sin alpha1 e_Y), per_hub: hub_spin_tension_per_rate (s^2; None: a hub
    of radius 0).  Arrays broadcast (steps, ribs: spin (steps, 1)).

    The leaf as a rigid line from its hinge O at radius a: a point at x along it is at
    r(x) = a + x cos alpha1 from the axis.  The leaf turns at w = Omega e_Y + omega e_t, O
    circles the axis: the inertial force per unit mass along the leaf is
    omega^2 x + Omega^2 cos alpha1 (a + x cos alpha1) (the spin's centrifugal Omega^2 r
    outward, its component along the leaf); the Coriolis force of the hinge rate in the
    spin, omega Omega x sin alpha1 e_t, and the spin-up's Euler force are out of the rib's
    plane and add no tension.  The tension at O, the integral over the leaf and the tip mass
    m at x = L:

        N(0) = int_0^L rho A [omega^2 x + Omega^2 c (a + x c)] dx
               + m [omega^2 L + Omega^2 c (a + L c)]
             = (omega^2 + Omega^2 c^2) (rho A L^2 / 2 + m L) + Omega^2 c a (rho A L + m),

    c = cos alpha1: over the Euler load, (omega^2 + (Omega c)^2) per_rate + Omega^2 c per_hub.
    The leaf's own bending and the tip mass's offset are left out (as on a fixed hub), and so
    is the Coriolis force of the out-of-plane bending's rate w' in the spin, -2 Omega w' e_r,
    whose share along the leaf lowers the tension while a spin-up swings the tip out of
    plane: the rule then overstates the tension (tests/test_linear_range.py).
    """
    out = rate * rate
    if spin is None:
        out *= per_rate
        return out
    # (in place, few calls: a live node judges every 1 ms block of steps)
    radial = np.cos(alpha1)
    radial *= spin                           # Omega cos alpha1
    if per_hub is None:                      # (a = 0)
        out += radial * radial
        out *= per_rate
        return out
    hub = per_rate * radial
    hub += per_hub * spin
    hub *= radial
    out *= per_rate
    out += hub
    return out


def _geometric_stiffness_warning(params: dict, ratio: float | None, limit: float,
                                 reached: str, effect: str, advice: str) -> str | None:
    """
    Return a warning of the linear beams' missing geometric stiffness, or None.

    Model flexible only, once an axial force's ratio to its Euler load passed limit:
    reached (the key and the figure, 'ratio' formatted in), effect (what the missing
    stiffness does), advice (which model to take).
    """
    if ratio is None or ratio <= limit or params.get('model') != 'flexible':
        return None
    return (f'{reached.format(ratio=f"{100 * ratio:.3g}")} (limit {100 * limit:g} %): the '
            f'linear beams of model flexible have no geometric stiffness {effect} '
            f'(docs/validation_nonlinear.md); {advice} model flexible-nonlinear')


#: _geometric_stiffness_warning's texts of 'centrifugal stiffening'
_CENTRIFUGAL_TEXTS = (
    "centrifugal stiffening: the leaf's centrifugal tension reached {ratio} % of its Euler "
    'load pi^2 E I / (l1 + l2)^2 before the lock',
    'and overstate the stage-1 tip and stresses of a leaf under that tension by about as much',
    'take')


def centrifugal_tension_warning(params: dict, ratio: float | None) -> str | None:
    """Return 'centrifugal stiffening' when flexible's leaf tension passed its limit, else None."""
    return _geometric_stiffness_warning(params, ratio, CENTRIFUGAL_TENSION_LIMIT,
                                        *_CENTRIFUGAL_TEXTS)


#: validity of the linear beams (model flexible) in stage 2: the axial force in the frame's
#: members over the link's Euler load pi^2 E I / l3^2 (params.link_euler_load) may reach this
#: fraction (axial_load_ratio_max: each step's largest elastic axial stress of leaf and link,
#: |sigma_top + sigma_bottom| / 2 (the step row axial_stress, outputs.axial_stress_of; the
#: largest of stage 2's substeps), times the area; each rib's for the umbrella).  The locked
#: frame's vibration loads the link along its axis, in compression and in tension each
#: period; the floating-frame beams have no geometric stiffness, and the link's stage-2
#: bending (and stress) is what that stiffness changes.  Measured against flexible-nonlinear
#: (docs/validation_nonlinear.md, "Stage 2 and the link's axial load": the thesis's frame, 2
#: elements a segment, both at 25 us, 0.3 s past the lock): V0 = -0.02 0.16, the peaks 5.2 %
#: (leaf) and 3.1 % (link) off, the stage-2 tip series 2.9 % of its amplitude apart; -0.05
#: 0.39, the link 8.4 %; -0.1 0.77, 11.6 %; -0.15 1.18, 17.7 %; -0.2 (the thesis's run) 1.54,
#: 15.3 % (plastic lock 1.43: the leaf 16.2 %); a 12 mm section at -0.2 1.20, 20.3 %, at -0.3
#: 1.68, 9.0 % (the leaf); the tip series 5-24 % apart, the periods within 0.13 %; at 1
#: element -0.1 0.79, the link 7.3 % (the tip series 8.6 %), -0.2 1.57, 3.7 % (14.8 %).  At
#: 0.25 every run it warns is at least 8.4 % off (a peak, the amplitude or the tip series);
#: the quiet one is 5.2 % off (the leaf's peak: a difference the axial load does not explain
#: alone).  Past 1 the members carry more than a static column of the link's section could:
#: the dynamic load of a vibration, not a buckling the model could show.  The stress
#: recovery's figure, not the link force the stop's and the axle's reactions hold: those
#: carry the axial mode the lock excites (~30 krad/s; the default run's 1.35-1.66 with the
#: step) and, damped, the dampers' forces (a stiffness-proportional damping's of that mode:
#: 3.1 at damping_ratio 0.05, where the stress recovery's falls to 0.39).
AXIAL_LOAD_LIMIT = 0.25


#: _geometric_stiffness_warning's texts of 'axial load'
_AXIAL_LOAD_TEXTS = (
    "axial load: the axial force in the frame's members reached {ratio} % of the link's Euler "
    'load pi^2 E I / l3^2 in stage 2 so far',
    "to it: the stage-2 bending and stresses change (the thesis's frame at 2 elements a "
    "segment: the larger stage-2 peak stress, the leaf's or the link's, 8-20 % off "
    "flexible-nonlinear's from 39 % of the Euler load on; at 1 element 4-7 %)", 'compare')


def axial_load_warning(params: dict, ratio: float | None) -> str | None:
    """Return 'axial load' when flexible's members' axial force passed its limit, else None."""
    return _geometric_stiffness_warning(params, ratio, AXIAL_LOAD_LIMIT, *_AXIAL_LOAD_TEXTS)


#: an energy balance error (energy_drift) past which a run is named: well above round-off
#: (~1e-13) and the Newton tolerance's share (< 1e-4 in every documented run)
ENERGY_DRIFT_LIMIT = 1e-3


def validity_warnings(params: dict, lock_kind: str | None, peak_stress: float,
                      tip_deflection: float, locked: bool = False,
                      energy_drift: float | None = None,
                      stage2_resolution: dict | None = None,
                      section_slope: float | None = None,
                      centrifugal_tension: float | None = None,
                      link_axial_load: float | None = None,
                      ribs: dict | None = None,
                      out_of_plane_tip: float | None = None,
                      strain: tuple | None = None,
                      leaf_lengths: tuple | None = None) -> list[str]:
    """
    Return where a run left the model's validity: one rule, used everywhere.

    Each text starts with a fixed key ('lock not applicable', 'coarse step' once locked,
    'energy not conserved', 'yield exceeded', 'large strain' (below yield; above it too for
    flexible-nonlinear), 'large deflection' (small-deformation models), 'centrifugal
    stiffening' (flexible, from stage 1: centrifugal_tension_warning), 'fibre rotation'
    (flexible-nonlinear: geometric_validity_warnings)) before a colon.  stage2_resolution:
    the lock's (LockEvent), for 'coarse step'; section_slope: the largest |v'| of
    flexible-nonlinear's fibres (geometric_validity_warnings); centrifugal_tension: the
    largest of the leaf's centrifugal tension over its Euler load in stage 1
    (CENTRIFUGAL_TENSION_LIMIT; None when not known, e.g. a recording's samples);
    link_axial_load: the largest of the link's axial force over its Euler load in stage 2
    ('axial load', flexible: axial_load_warning; None when not known).  ribs:
    the umbrella's, the rib a figure is of, by the warning's key ('yield exceeded': k, ...):
    'rib k, ' after the key, so that an engineer knows which rib to look at.
    out_of_plane_tip: the umbrella's largest |w_G| (its ribs bend out of their planes too):
    'large out-of-plane deflection' past the same limit as the in-plane tip's.  The
    umbrella's ribs may each have their own E and lengths: strain, (|sigma| / E, |sigma|) of
    the rib strained most, each rib's peak over its own E (default: peak_stress over params'
    E); leaf_lengths, the l1 + l2 of the ribs whose tip_deflection and out_of_plane_tip these
    are (each rib's deflection over its own leaf; default: params').
    """
    out = []
    lw = lock_warning(params, lock_kind)
    if lw:
        out.append(lw)
    length, oop_length = leaf_lengths or (params['l1'] + params['l2'],) * 2
    cw = (coarse_step_warning(stage2_resolution,
                              lambda needed: resolving_step_hint(params, needed),
                              tip_deflection / length) if locked else None)
    if cw:
        out.append(cw)
    if energy_drift is not None and energy_drift > ENERGY_DRIFT_LIMIT:
        out.append(f'energy not conserved: the energy balance is off by {100 * energy_drift:.3g}'
                   f" % of the run's energy (limit {100 * ENERGY_DRIFT_LIMIT:g} %): a step "
                   'too coarse for this motion, whose energy restoration was skipped (more '
                   'than 1 % a step); use a smaller time_step')
    ys = params['yield_strength']
    if peak_stress > ys:
        out.append(f'yield exceeded: peak |sigma| {peak_stress / 1e6:.4g} MPa is '
                   f'{peak_stress / ys:.3g} x yield_strength {ys / 1e6:.4g} MPa; the linear '
                   'elastic material law no longer holds')
    fibre, strained = strain or (peak_stress / params['youngs_modulus'], peak_stress)
    if fibre > STRAIN_LIMIT and strained <= ys:      # (past yield: the warning above)
        out.append(f'large strain: peak |sigma| / youngs_modulus = {100 * fibre:.3g} % '
                   f'(limit {100 * STRAIN_LIMIT:g} %): the small-strain measures and '
                   "Hooke's law of the beam elements no longer hold")
    if (tip_deflection > TIP_DEFLECTION_LIMIT * length
            and params.get('model') != 'flexible-nonlinear'):     # (its own: below)
        out.append(f'large deflection: |v_G| reached {tip_deflection * 1e3:.4g} mm = '
                   f'{100 * tip_deflection / length:.3g} % of the leaf length {length:g} m '
                   f'(limit {100 * TIP_DEFLECTION_LIMIT:g} %): small-deformation theory no '
                   'longer holds (compare model flexible-nonlinear)')
    if (out_of_plane_tip is not None and out_of_plane_tip > TIP_DEFLECTION_LIMIT * oop_length
            and params.get('model') != 'flexible-nonlinear'):
        out.append(f'large out-of-plane deflection: |w_G| reached {out_of_plane_tip * 1e3:.4g} '
                   f'mm = {100 * out_of_plane_tip / oop_length:.3g} % of the leaf length '
                   f'{oop_length:g} '
                   f'm (limit {100 * TIP_DEFLECTION_LIMIT:g} %): small-deformation theory no '
                   'longer holds (compare model flexible-nonlinear)')
    tw = centrifugal_tension_warning(params, centrifugal_tension)
    if tw:
        out.append(tw)
    aw = axial_load_warning(params, link_axial_load)
    if aw:
        out.append(aw)
    out += geometric_validity_warnings(params, peak_stress, section_slope, strain)
    out += parameter_warnings(params)
    if ribs:
        out = [naming_rib(w, ribs.get(w.split(':', 1)[0])) for w in out]
    return out


def naming_rib(warning: str, rib: int | None) -> str:
    """Return a warning with its rib after its key, 'key: rib k, text' (None: as it is)."""
    if rib is None:
        return warning
    key, text = warning.split(':', 1)
    return f'{key}: rib {rib}, {text.lstrip()}'


class WarningsSaid:
    """
    Which validity warnings a run has said: each once, by its key (the text before ':').

    new(inputs, warnings): the warnings not said yet, judged again only when the figures the
    warnings depend on (inputs, a tuple) changed since the last call; unchanged (most chunks
    once the peaks are reached), nothing can be new.
    """

    def __init__(self):
        self._keys: set = set()
        self._inputs: tuple | None = None

    def new(self, inputs: tuple, warnings: Callable[[], list[str]]) -> list[str]:
        if inputs == self._inputs:
            return []
        self._inputs = inputs
        fresh = [w for w in warnings() if w.split(':')[0] not in self._keys]
        self._keys.update(w.split(':')[0] for w in fresh)
        return fresh


class SummaryAccumulator:
    """
    Summary figures of a run from every physics step (StepBlocks).

    Independent of the publication or recording rate, and of how the steps are split into
    blocks: every figure, the energy balance and the constraint residual included, comes
    from each step's row.  Written once; used by the CLI, the node (diagnostics, recording
    metadata) and, through the recording's metadata, umbrella_compare.
    """

    def __init__(self, params: dict, initial: Sample, lock_kind: str | None = None,
                 section_slope: Callable[[], float | None] | None = None):
        """section_slope: the engine's largest |v'| of a section so far (flexible-nonlinear)."""
        self.params = dict(params)
        self._section_slope = section_slope
        self.lock_kind = lock_kind
        self.lock: LockEvent | None = None
        self.steps = 0
        self.final_time = float(initial.time)
        self.error: str | None = None
        self._e0 = mechanical_energy(initial)
        self._scale = max(abs(self._e0), ENERGY_SCALE_FLOOR)
        self._balance = 0.0
        self._residual = float(initial.constraint_residual)
        self._tip1 = ((abs(initial.tip_transverse), float(initial.time))
                      if initial.stage == 'deploying' else (None, None))
        self._tip_all = abs(initial.tip_transverse)
        self._peaks = {b: (getattr(initial, f'peak_stress_{b}'),
                           getattr(initial, f'peak_stress_{b}_x'), float(initial.time))
                       for b in ('leaf', 'link')}
        self._stage2 = Stage2Series()
        # deploy_start: t = 0 if the frame moves at t = 0, else found in the steps' forces
        self._start = deploy_start(float(self.params.get('v0', 0.0)), ())
        self._said = WarningsSaid()
        # the leaf's centrifugal tension over its Euler load per squared hinge rate (None:
        # no beams), and its largest in stage 1 (leaf_tension_ratio: the planar model's hub
        # is fixed, CENTRIFUGAL_TENSION_LIMIT)
        beams = beams_record(self.params)
        self._tension_per_rate = None if beams is None else centrifugal_tension_per_rate(beams)
        self._tension = None if beams is None else (
            float(leaf_tension_ratio(self._tension_per_rate, float(initial.alpha1_rate)))
            if initial.stage == 'deploying' else 0.0)
        # the members' largest axial force over the link's Euler load in stage 2 (None: no
        # beams, or no stage 2 yet; AXIAL_LOAD_LIMIT): per Pa of axial stress, and the largest
        self._axial_per_stress = (None if beams is None else
                                  beams.cross_section_area / beams.link_euler_load)
        self._link_load = None

    def add(self, block: StepBlock) -> None:
        """Take the steps of one block."""
        if block.lock is not None and self.lock is None:
            self.lock = block.lock
        if block.error is not None:
            self.error = block.error
        n = len(block)
        if n == 0:
            return
        rows = block.rows
        t, v, stage = rows[_TIME], rows[_TIP], rows[_STAGE]
        if self._start is None:     # (until the first push: then never again)
            # each step's force acts from the step's start: the previous step's end
            self._start = deploy_start(0.0, zip([self.final_time, *t[:-1].tolist()],
                                                rows[_FORCE].tolist()))
        self.steps += n
        self.final_time = float(t[-1])
        # one product for the block's energies, work and tip: a live node adds ~10 steps a
        # publication, where every numpy call costs more than the arithmetic
        linear = _linear_figures(rows)
        linear[1] -= self._e0
        energy, balance, work, tip = np.abs(linear).max(axis=1).tolist()
        self._scale = max(self._scale, energy, work)
        self._balance = max(self._balance, balance)
        self._tip_all = max(self._tip_all, tip)
        self._residual = max(self._residual, float(rows[_RESIDUAL].max()))
        if stage[0] == 0:                                  # stage 1 (deploying) in the block
            deploying = np.abs(np.where(stage == 0, v, 0.0))
            i = int(deploying.argmax())
            if self._tip1[0] is None or deploying[i] > self._tip1[0]:
                self._tip1 = (float(deploying[i]), float(t[i]))
            if self._tension is not None:       # (ufunc reductions: a block's are small)
                rate = rows[_RATE] if stage[-1] == 0 else rows[_RATE][stage == 0]
                self._tension = max(self._tension, float(np.maximum.reduce(
                    leaf_tension_ratio(self._tension_per_rate, rate))))
        if self._axial_per_stress is not None and stage[-1] != 0:     # stage 2 in the block
            axial = rows[_AXIAL] if stage[0] != 0 else rows[_AXIAL][stage != 0]
            self._link_load = max(self._link_load or 0.0,
                                  float(np.maximum.reduce(axial)) * self._axial_per_stress)
        if self.lock is not None and stage[-1] != 0:
            tips = block.physics_tips       # (stage 2's substeps: each one's tip)
            t2, v2 = (t, v[:, None]) if tips is None else (tips[0], tips[1:].T)
            if t2[0] <= self._stage2.end(self.lock.time):
                self._stage2.add(t2, v2, self.lock.time)
        for body, (peak, x, ti) in block.peaks.items():
            if peak > self._peaks[body][0]:
                self._peaks[body] = (peak, x, ti)

    def figures(self) -> dict:
        """Return the physics figures of the run so far (no wall-clock ones), JSON-ready."""
        p = self.params
        start = self._start if self._start is not None else 0.0    # (None: never pushed)
        out: dict = {'deploy_time': self.lock.time - start if self.lock else None,
                     'deploy_start': self._start,
                     'lock_time': self.lock.time if self.lock else None,
                     'tip_deflection_max': self._tip1[0],
                     'tip_deflection_max_time': self._tip1[1]}
        out.update(self._stage2.figures(self.lock.time if self.lock else None)[0])
        for body in ('leaf', 'link'):
            peak, x, t = self._peaks[body]
            out[f'peak_stress_{body}'] = peak
            out[f'peak_stress_{body}_x'] = x
            out[f'peak_stress_{body}_time'] = t
        out['yield_strength'] = p.get('yield_strength')
        out['stress_ratio_max'] = max(out['peak_stress_leaf'], out['peak_stress_link']) / \
            p['yield_strength']
        out['tip_deflection_ratio_max'] = self._tip_all / (p['l1'] + p['l2'])
        out['leaf_tension_ratio_max'] = self._tension
        out['axial_load_ratio_max'] = self._link_load
        out['energy_drift'] = self._balance / self._scale
        if self.lock:
            out['lock'] = self.lock.kind
            out['lock_energy_before'] = self.lock.energy_before
            out['lock_energy_after'] = self.lock.energy_after
            out['lock_free_velocities'] = list(self.lock.free_velocities)
            if self.lock.stage2_resolution:
                out['stage2_resolution'] = dict(self.lock.stage2_resolution)
        if p.get('model') == 'rigid-fe':    # (what the rigid model has by construction)
            out.update(dict.fromkeys(RIGID_FE_ZEROS, 0.0), tip_deflection_max_time=0.0,
                       peak_stress_leaf_time=0.0, peak_stress_link_time=0.0)
        out['constraint_residual_max'] = self._residual
        out['final_time'] = self.final_time
        out['steps'] = self.steps
        out['warnings'] = self.warnings()
        if self.error:
            out['error'] = self.error
        return out

    def warnings(self) -> list[str]:
        """Return the validity warnings so far (validity_warnings)."""
        return validity_warnings(self.params, self.lock_kind,
                                 max(self._peaks['leaf'][0], self._peaks['link'][0]),
                                 self._tip_all, locked=self.lock is not None,
                                 energy_drift=self._balance / self._scale,
                                 stage2_resolution=self.lock.stage2_resolution
                                 if self.lock else None,
                                 section_slope=self._slope(),
                                 centrifugal_tension=self._tension,
                                 link_axial_load=self._link_load)

    def _slope(self) -> float | None:
        return self._section_slope() if self._section_slope is not None else None

    def new_warnings(self) -> list[str]:
        """Return the warnings not returned by an earlier call (a log line each, once)."""
        # the warnings depend on the run only through these
        return self._said.new((self._peaks['leaf'][0], self._peaks['link'][0], self._tip_all,
                               self.lock is not None,
                               self._balance / self._scale > ENERGY_DRIFT_LIMIT, self._slope(),
                               (self._tension or 0.0) > CENTRIFUGAL_TENSION_LIMIT,
                               (self._link_load or 0.0) > AXIAL_LOAD_LIMIT),
                              self.warnings)


def blocks_from_samples(samples: list, lock=None, error: str | None = None) -> StepBlock:
    """Return a StepBlock of samples (each taken as one step's end), with its lock and fault."""
    rows = np.array([step_row(s) for s in samples], dtype=float).reshape(-1, len(STEP_FIELDS))
    last = samples[-1]
    return StepBlock.from_rows(rows.T.copy(), lambda: last, lock, error)


def summarize(r: RunResult) -> dict:
    """
    Return the summary of a run.

    The figures of every physics step (``r.figures``, from solver.simulate's
    SummaryAccumulator) if the run has them, else from its samples ('figures_from':
    'samples'), plus the wall-clock figures.
    """
    if r.figures is not None:
        out = dict(r.figures)
    elif not r.samples:
        return {'error': r.error, 'steps': r.steps}
    else:
        acc = SummaryAccumulator(r.params, r.samples[0], r.lock.kind if r.lock else None)
        if len(r.samples) > 1:
            acc.add(blocks_from_samples(r.samples[1:], r.lock, r.error))
        out = acc.figures()
        out['figures_from'] = 'samples'
    out['steps'] = r.steps
    out['wall_time'] = r.wall_time
    ft = out.get('final_time')
    out['real_time_factor'] = float(ft / r.wall_time) if r.wall_time > 0 and ft else None
    if r.error:
        out['error'] = r.error
    return out


def energy_balance_error(r: RunResult) -> np.ndarray:
    """outputs.energy_balance of every sample of a run (J)."""
    return np.array([energy_balance(s, mechanical_energy(r.samples[0])) for s in r.samples])


def relative_drift(balance_error, energy, work) -> float:
    """
    Return max |balance error| over the largest |energy| or |work| (series): energy_drift.

    One rule for a run's samples (energy_drift) and a recording's energy topic (compare).
    """
    scale = max(float(np.abs(energy).max()), float(np.abs(work).max()), ENERGY_SCALE_FLOOR)
    return float(np.abs(balance_error).max() / scale)


def energy_drift(r: RunResult) -> float:
    """Return max |energy balance error| relative to the largest mechanical energy."""
    return relative_drift(energy_balance_error(r), mechanical_energy(r), r.column('work'))
