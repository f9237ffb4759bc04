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
The umbrella's outputs as plain data: every step's figures per rib, peaks, spread, balance.

``Record3D`` keeps, for every physics step, the joint angles and rates of every rib, the
sleeve, each rib's tip deflection in its leaf frame (axial u, in-plane v, out-of-plane w), the
energies and the work of the sleeve force, of each hinge's friction and of a prescribed base,
the energy lost at the lock, each stuck hinge's holding torque, the bus state and, with a
free-floating bus, the linear and angular momentum.  Stresses: at both ends of every element,
axial E u', bending E c v'' (in the rib plane) and E c w'' (out of it), the St-Venant shear
G c_t phi'; the combined figure is the von Mises stress of the worst corner fibre with the
largest torsion shear, sqrt((|sigma_a| + |sigma_bz| + |sigma_by|)^2 + 3 tau^2), an upper bound
of the section's von Mises stress.  Each rib's peak of every component over the run is kept
with where (body, abscissa) and when; every step's row has each rib's largest of every
component over both bodies (``stress_<name>``) and where (``stress_<name>_at``: body code,
0 leaf 1 link, and x), the leaf's on a tie.
"""
from __future__ import annotations

import math

import numpy as np

from .substeps3d import fold_substeps3d, physics_tips3d
from ..outputs import hermite_crests, running_total, substep_ends

STRESS_NAMES = ('axial', 'bending_in_plane', 'bending_out_of_plane', 'torsion', 'von_mises')
#: the bodies of a rib, by the code a stress's place carries (stress_<name>_at)
BODIES = ('leaf', 'link')
#: Record3D's row names of each stress channel's value and where, in STRESS_NAMES' order
STRESS_ROWS = tuple((f'stress_{name}', f'stress_{name}_at') for name in STRESS_NAMES)
#: ndarray.max's and .any's reductions (over axis 0 unless told; axis=None: all), without
#: the methods' dispatch, which costs more than the reduction of a block's small arrays
largest, any_of = np.maximum.reduce, np.logical_or.reduce


class Record3D:
    """Per-step figures of one run (blocks of steps while running; ``arrays()`` joins them)."""

    def __init__(self, model):
        self.model = model
        #: the blocks of steps added since the last ``take``: name -> array (steps first) each
        self._blocks: list[dict] = []
        #: each block's physics steps' tips where its rows fold substeps (physics_tips3d),
        #: and those of the rows the last ``take`` returned (``taken_tips``)
        self._tips: list = []
        self.taken_tips = None
        nr = model.n_ribs
        self.work = 0.0
        self.friction = np.zeros(nr)
        self.drive = 0.0
        #: the energy the beams' damping dissipated so far (J, >= 0: damping3d.py)
        self.damping = 0.0
        self.lock_events: list = []
        self.iterations = 0
        # a stress point's x along its body: the leaf's points, then the link's
        xs = (model.leaf_bodies[0].stress_x, model.link_bodies[0].stress_x)
        self._leaf_points, self._x_of = len(xs[0]), np.concatenate(xs)
        #: each rib's peak of every stress channel over the run (a column each, in
        #: STRESS_NAMES' order), where (body code, NaN before any peak; x) and when
        #: (``peak``, ``peak_where``)
        self._peaks = np.zeros((nr, len(STRESS_NAMES)))
        self._peak_at = np.zeros((nr, len(STRESS_NAMES), 2))
        self._peak_at[..., 0] = np.nan
        self._peak_when = np.zeros((nr, len(STRESS_NAMES)))
        #: the last step's (time, its five channels' values and rates (_crests), locked):
        #: the start of the next step's crests; after the compiled step's figures (time,
        #: qr, vr, locked, 'state'): the channels computed from them when needed
        self._last_stress = None
        #: each rib's largest of every stress channel over the steps added since the last
        #: ``take`` (value, at, when: blocks3d.RibPeaks' arrays; None: no steps), and those
        #: of the rows the last ``take`` returned (``taken_peaks``)
        self._held = None
        self.taken_peaks = None
        #: a step's (rib, channel) figures, flattened: their count and indices
        self._per_step = nr * len(STRESS_NAMES)
        self._per_step_index = np.arange(self._per_step).reshape(nr, len(STRESS_NAMES))
        self._tip = np.array(model.i_tip)
        #: no hinge ever sticks (none has stick_until or stick_torque): stuck is NaN throughout
        self._never_stuck = all(r.stick_until <= 0.0 and r.stick_torque <= 0.0
                                for r in model.ribs)
        #: the rows of a constant figure (locked, sleeve_force, lock_energy_loss) by (name,
        #: steps, value): shared by the blocks, read-only
        self._constant_rows: dict = {}
        self._block_constants: dict = {}    # (_constants': a block's rows of them)

    @property
    def peak(self) -> dict:
        """Return each rib's peak of every stress channel over the run (name -> (ribs,))."""
        return {name: self._peaks[:, j].copy() for j, name in enumerate(STRESS_NAMES)}

    @property
    def peak_where(self) -> dict:
        """Return where and when each peak is: name -> [(body, x, t)] a rib ('' before one)."""
        out = {}
        for j, name in enumerate(STRESS_NAMES):
            out[name] = [('' if np.isnan(body) else BODIES[int(body)], float(x), float(when))
                         for (body, x), when in zip(self._peak_at[:, j], self._peak_when[:, j])]
        return out

    def _names(self) -> list:
        """Return the names of the figures of every step (those of the blocks)."""
        return list(self._blocks[0]) if self._blocks else []

    def add(self, s, locked: bool, force: float, work, lock_loss: float, lock_event=None,
            tips=None):
        """
        Add the figures of state s, reached by a step that did work (None: the start).

        tips: the physics steps' tips (physics_tips3d) if the step took stage 2's substeps.
        """
        m = self.model
        if work is not None:
            self.work += work.force
            self.friction = self.friction + work.friction
            self.drive += work.drive
            self.damping += work.damping
            self.iterations += work.iterations
        if lock_event is not None:
            self.lock_events.append(lock_event)
        kin = None
        if s.pr is None:
            kin = m.kinematics(s.qr, s.qs)
            pr, ps = m.matvec(m.mass_matrix(kin), s.vr, s.vs)
        else:
            pr, ps = s.pr, s.ps
        kinetic = 0.5 * (float(np.sum(pr * s.vr)) + float(ps @ s.vs))
        one = {name: np.asarray(getattr(s, name))[None]
               for name in ('qr', 'qs', 'vr', 'vs', 'lam_r', 'lam_s', 'stuck')}
        block = self._put_steps(np.array([s.t]), one, np.array([kinetic]),
                                np.array([m.strain_energy(s.qr)]), np.array([self.work]),
                                self.friction[None].copy(), np.array([self.drive]),
                                np.array([self.damping]), locked, force, lock_loss,
                                tips=tips)
        if m.moving_base:
            block['bus_q'] = s.qs[None, 1:7].copy()
            block['bus_v'] = s.vs[None, 1:7].copy()
            if m.params.base == 'free':
                kin = kin if kin is not None else m.kinematics(s.qr, s.qs)
                p, h = m.momentum(kin, s.vr, s.vs)
                block['linear_momentum'] = np.array(p)[None]
                block['angular_momentum'] = np.array(h)[None]

    def add_steps(self, rows: dict, locked: bool, force: float, lock_loss: float,
                  substeps: int = 1, times=None, tips=None):
        """
        Add the figures of a run of steps (the compiled step's rows, kernel3d.row_layout).

        rows: arrays with the steps first: t, qr, qs, vr, vs, lam_r, lam_s, stuck, kinetic,
        strain, work_force, work_friction, iterations, work_drive and, with a free bus,
        linear_momentum and angular_momentum (``add``'s figures of each state); and maybe
        the steps' stress figures, stress_top (step, rib, 5) and stress_at (step, rib, 5, 2),
        computed by the compiled step with ``_crests``' rule (kernel3d.row_layout; their
        first step's crest from the last step added if ``crest_continues``), else computed
        here.  substeps: the rows are physics steps taken that many a grid step (stage 2's
        substeps), kept as grid rows (fold_substeps3d); times: the rows' (the grid's) times;
        tips: the physics steps' tips of rows the kernel folded (physics_tips3d), those of
        rows folded here taken from them.
        """
        if substeps > 1:
            tips = (rows['t'].copy(), rows['qr'][:, :, self._tip[1:]])
            if times is not None:           # (a grid step's last at its row's time)
                tips[0][substep_ends(len(tips[0]), substeps)] = times
            rows = self._grid_rows(rows, locked, substeps, times)
        elif times is not None:         # (rows the kernel folded: at the grid's times)
            rows = dict(rows, t=np.asarray(times, dtype=float))
        # (each work summed on from its total so far, step by step, as add sums it: the
        # same bits however the run is chunked into blocks)
        work = running_total(self.work, rows['work_force'])
        friction = running_total(self.friction, rows['work_friction'])
        drive = running_total(self.drive, rows['work_drive'])
        self.work, self.friction = float(work[-1]), friction[-1].copy()
        self.drive = float(drive[-1])
        if 'work_damping' in rows:
            damping = running_total(self.damping, rows['work_damping'])
        else:
            damping = self._constant('damping_dissipation', len(work), self.damping)
        self.damping = float(damping[-1])
        self.iterations += int(np.add.reduce(rows['iterations']))
        figures = None
        if 'stress_top' in rows:        # (the compiled step's: _crests' rule, computed there)
            figures = rows['stress_top'], rows['stress_at']
        block = self._put_steps(rows['t'], rows, rows['kinetic'], rows['strain'], work,
                                friction, drive, damping, locked, force, lock_loss, figures,
                                tips)
        if self.model.moving_base:      # (copies: the rows' buffers are reused)
            block['bus_q'] = rows['qs'][:, 1:7].copy()
            block['bus_v'] = rows['vs'][:, 1:7].copy()
            if self.model.params.base == 'free':
                block['linear_momentum'] = rows['linear_momentum'].copy()
                block['angular_momentum'] = rows['angular_momentum'].copy()

    def crest_continues(self, locked: bool) -> bool:
        """Say whether the next step's stress crests start from the last step added."""
        last = self._last_stress
        return last is not None and last[3] == locked

    def _constant(self, name: str, shape, value) -> np.ndarray:
        """Return the rows of a figure constant over steps (np.full's; shared, read-only)."""
        key = (name, shape, type(value), value, math.copysign(1.0, value))   # (0.0 not -0.0)
        rows = self._constant_rows.get(key)
        if rows is None:
            if len(self._constant_rows) > 64:        # (values change seldom: a few at once)
                self._constant_rows.clear()
            rows = self._constant_rows[key] = np.full(shape, value)
            rows.flags.writeable = False
        return rows

    def _constants(self, k: int, locked: bool, force: float, lock_loss: float) -> tuple:
        """Return k steps' locked, sleeve_force, lock_energy_loss, holding_torque, stuck rows."""
        key = (k, locked, force, lock_loss, math.copysign(1.0, force),
               math.copysign(1.0, lock_loss), type(locked), type(force), type(lock_loss))
        rows = self._block_constants.get(key)
        if rows is None:    # (_constant's, once a block alike; the last two None where a
            # hinge may stick: its own rows)
            c, ribs = self._constant, (k, len(self.friction))
            rows = (c('locked', k, locked), c('sleeve_force', k, force),
                    c('lock_energy_loss', k, lock_loss),
                    *((c('holding_torque', ribs, 0.0), c('stuck', ribs, False))
                      if self._never_stuck else (None, None)))
            if len(self._block_constants) > 64:      # (values change seldom: a few at once)
                self._block_constants.clear()
            self._block_constants[key] = rows
        return rows

    def _put_steps(self, t, st, kinetic, strain, work, friction, drive, damping, locked,
                   force, lock_loss, figures=None, tips=None) -> dict:
        """
        Append k steps' figures (arrays with the steps first), update the peaks; return them.

        t, st's arrays, kinetic and strain may be views of a buffer reused (copied here);
        work, friction, drive, damping are the caller's own (kept).  figures: (top, at) of the
        steps' stresses (add_steps), else computed here (_crests); tips: the physics steps'
        the rows fold (physics_tips3d), or None.  Returns the block's rows by name (the
        caller may add its own).
        """
        m = self.model
        k = len(t)
        qr, vr = st['qr'], st['vr']
        locked_rows, force_rows, loss_rows, holding, stuck = self._constants(
            k, locked, force, lock_loss)
        if holding is None:         # (a hinge that sticks: its own rows)
            free = np.isnan(st['stuck'])
            holding, stuck = np.where(free, 0.0, st['lam_r'][:, :, -1]), ~free
        i_a1, i_a2 = m.i_a1, m.i_a2
        # stresses: each rib's worst point per step, and where: the first of the largest in
        # the order leaf points, link points (the leaf's on a tie; a NaN the largest, as
        # argmax); every component at once, in STRESS_NAMES' order
        if figures is None:
            top, at = self._step_figures(t, qr, st['vr'], locked)
        else:      # (the next step's crests start from the last state: its channels if asked)
            top, at = figures[0].copy(), figures[1].copy()
            self._last_stress = (float(t[-1]), qr[-1].copy(), vr[-1].copy(), locked, 'state')
        block = {      # (copies: the rows' buffers are reused)
            'locked': locked_rows, 'sleeve_force': force_rows, 'lock_energy_loss': loss_rows,
            'time': t.copy(), 'sleeve_position': st['qs'][:, 0].copy(),
            'sleeve_velocity': st['vs'][:, 0].copy(), 'alpha1': qr[:, :, i_a1].copy(),
            'alpha2': qr[:, :, i_a2].copy(), 'alpha1_rate': vr[:, :, i_a1].copy(),
            'alpha2_rate': vr[:, :, i_a2].copy(),
            'tip': qr[:, :, self._tip],         # (a new array)
            'kinetic_energy': kinetic.copy(), 'strain_energy': strain.copy(),
            'work': work, 'friction_work': friction, 'drive_work': drive,
            'damping_dissipation': damping, 'holding_torque': holding, 'stuck': stuck,
            'stop_reaction': st['lam_s'][:, 0].copy()}
        # (each channel's value and place: views of top and at, the channels' axis first)
        for (name, name_at), value, where in zip(STRESS_ROWS, top.transpose(2, 0, 1),
                                                 at.transpose(2, 0, 1, 3)):
            block[name], block[name_at] = value, where
        block['von_mises'] = np.maximum(top[:, :, -1], 0.0)
        self._blocks.append(block)
        self._tips.append(tips)
        # the peaks over these steps, rib by rib: the first of the largest step by step (the
        # leaf before the link: each step's own rule above; a NaN the largest, as argmax)
        first = top.argmax(0)                                   # (rib, 5)
        # (each rib's and channel's row of the flattened steps: takes, not a fancy index)
        i = first * self._per_step
        i += self._per_step_index
        best = top.take(i)
        held = (best, at.reshape(-1, 2).take(i, 0), t.take(first))
        self._held = held if self._held is None else merged_peaks(self._held, held)
        # the run's: a larger one only (a NaN never)
        better = best > self._peaks
        if any_of(better, axis=None):
            self._peaks = np.where(better, best, self._peaks)
            self._peak_at = np.where(better[..., None], held[1], self._peak_at)
            self._peak_when = np.where(better, held[2], self._peak_when)
        return block

    def _step_figures(self, t, qr, vr, locked: bool):
        """Return each step's (top, at) of every stress channel: (step, rib, 5), (.., 2)."""
        m = self.model
        every = self._crests(t, np.concatenate(m.stress_blocks(qr), -1),
                             np.concatenate(m.stress_rate_blocks(qr, vr), -1), locked)
        top, point = every.max(-1), every.argmax(-1)           # (step, rib, 5)
        at = np.empty(top.shape + (2,))
        at[..., 0] = point >= self._leaf_points                  # the body's code
        at[..., 1] = self._x_of[point]
        return top, at

    # ---------------------------------------------------- stage-2 substeps (substeps3d.py)
    def _grid_rows(self, rows: dict, locked: bool, substeps: int, times) -> dict:
        """Return physics steps' rows as their grid steps' (fold_substeps3d), at times."""
        if 'stress_top' not in rows:        # (each physics step's crests, from the last)
            rows = dict(rows)
            rows['stress_top'], rows['stress_at'] = self._step_figures(
                rows['t'], rows['qr'], rows['vr'], locked)
        out = fold_substeps3d(rows, substeps)
        if times is not None:
            out['t'] = np.asarray(times, dtype=float)
        return out

    def add_substeps(self, states, works, locked: bool, force: float, lock_loss: float):
        """
        Add one grid step taken in physics steps: their states and works (``add``'s rule).

        The grid step's row is its last state's figures with each stress channel's largest
        over its physics steps (each a Hermite crest from the one before: ``_crests``).
        """
        m = self.model
        rows = {name: np.array([getattr(s, name) for s in states])
                for name in ('t', 'qr', 'qs', 'vr', 'vs', 'lam_r', 'lam_s', 'stuck')}
        rows['work_damping'] = np.array([w.damping for w in works])
        rows['kinetic'] = np.array([0.5 * (float(np.sum(s.pr * s.vr)) + float(s.ps @ s.vs))
                                    for s in states])
        rows['strain'] = np.array([m.strain_energy(s.qr) for s in states])
        for name, field in (('work_force', 'force'), ('work_friction', 'friction'),
                            ('work_drive', 'drive'), ('iterations', 'iterations'),
                            ('factorisations', 'factorisations')):
            rows[name] = np.array([getattr(w, field) for w in works])
        if m.params.base == 'free':
            s = states[-1]
            momenta = m.momentum(m.kinematics(s.qr, s.qs), s.vr, s.vs)
            for name, value in zip(('linear_momentum', 'angular_momentum'), momenta):
                rows[name] = np.repeat(np.asarray(value)[None], len(states), 0)
        self.add_steps(rows, locked, force, lock_loss, len(states), [states[-1].t])

    def _crests(self, t, stress, rate, locked: bool) -> np.ndarray:
        """
        Return each step's largest |stress| of every component and von Mises, per point.

        stress, rate: (step, rib, 4, point), the components and their rates at the steps'
        ends (the model's stress_rate_blocks: for the linear beams, the stresses of the
        elastic velocities).  Over a step from the previous one, the crest of the cubic
        Hermite interpolant of the ends' values and rates (outputs.hermite_peak, the planar
        model's rule: a crest between two steps counts where the step resolves it), of each
        signed component and of the combined figure sqrt((|axial| + |bending z| + |bending
        y|)^2 + 3 shear^2) with its rate; the end's own value for the first step of a run,
        and for a step across the lock, whose velocity jumps.  Returns (step, rib, 5, point).
        """
        values, rates = _channels(stress, rate)
        end = np.abs(values)
        last = self._last_stress
        if last is not None and len(last) == 5 and last[3] == locked:   # (compiled rows)
            q, v = last[1][None], last[2][None]
            st_values, st_rates = _channels(
                np.concatenate(self.model.stress_blocks(q), -1),
                np.concatenate(self.model.stress_rate_blocks(q, v), -1))
            last = (last[0], st_values[0], st_rates[0], last[3])
        self._last_stress = (float(t[-1]), values[-1], rates[-1], locked)
        first = 0
        if last is None or last[3] != locked:    # (a run's first step, or across the lock)
            last, first = (float(t[0]), values[0], rates[0], locked), 1
            if len(t) == 1:
                return end
        before = np.concatenate([last[1][None], values[:-1]])[first:]
        rate_before = np.concatenate([last[2][None], rates[:-1]])[first:]
        h = (t - np.concatenate([[last[0]], t[:-1]]))[first:, None, None, None]
        out = end.copy()
        out[first:] = hermite_crests(before, h * rate_before, values[first:], h * rates[first:])
        return out

    def arrays(self) -> dict:
        """Return every per-step figure as an array (steps first, then ribs or components)."""
        blocks = self._blocks
        return {name: np.concatenate([b[name] for b in blocks]) for name in self._names()}

    def take(self) -> dict:
        """
        Return the rows added since the last take as arrays (``arrays``), and drop them.

        ``taken_peaks`` is then their peaks: each rib's largest of every stress channel, the
        first step holding it (value and where, (ribs, 5) and (ribs, 5, 2), and when, s;
        None: no steps), blocks3d.RibPeaks.of_rows' of the rows; ``taken_tips`` their
        physics steps' tips where they fold substeps (physics_tips3d), else None.
        """
        # (one block of steps: its own arrays, which nothing else holds)
        out = self._blocks[0] if len(self._blocks) == 1 else self.arrays()
        self.taken_tips = physics_tips3d(self._blocks, self._tips)
        self._blocks, self._tips = [], []
        self.taken_peaks, self._held = self._held, None
        return out

    def row(self, s, locked: bool, force: float, lock_loss: float, totals) -> dict:
        """
        Return the figures of the state s as a row, without adding it (``add``'s rule).

        totals: the work of the sleeve force, each hinge's friction work and the drive's work
        from t = 0 to s (and the damping's dissipation, if given).
        """
        scratch = Record3D(self.model)
        scratch.work, friction, scratch.drive, *damping = totals
        scratch.damping = float(damping[0]) if damping else 0.0
        scratch.friction = np.array(friction, dtype=float)
        scratch.add(s, locked, force, None, lock_loss)
        return {name: values[0] for name, values in scratch.arrays().items()}

    def summary(self) -> dict:
        """
        Return the run's figures: lock time, each rib's deployment, spread, peaks, balance.

        A rib's deployment instant is when its leaf angle first reaches its deployed angle
        (linear between steps; the lock's instant where it does so in the lock's step:
        first_reach); the lag is the latest rib's after the earliest.  The energy
        balance residual is max |T + V - (T + V)(0) - W_F - W_friction - W_drive + lock loss
        + damping dissipation|.
        """
        m = self.model
        a = self.arrays()
        t = a['time']
        alpha = a['alpha1']
        lock = self.lock_events[0][0] if self.lock_events else None
        deployed = np.array([first_reach(t, alpha[:, k] - m.alpha_deployed[k], lock=lock)
                             for k in range(m.n_ribs)])
        energy = a['kinetic_energy'] + a['strain_energy']
        balance = energy_balance3d(a, energy[0])
        spread = deployment_spread(deployed)
        w, rib, when = largest_out_of_plane_tip(t, a['tip'])
        deploying = ~a['locked']
        angles, angles_when = largest_leaf_angle_spread(t[deploying], alpha[deploying])
        out = {
            'lock_time': self.lock_events[0][0] if self.lock_events else None,
            'rib_deploy_time': deployed,
            'deployment_lag': (np.nan if spread['deployment_lag'] is None
                               else spread['deployment_lag']),
            'max_leaf_angle_spread': angles,
            'max_leaf_angle_spread_time': angles_when,
            'max_out_of_plane_tip': w,
            'max_out_of_plane_tip_rib': rib,
            'max_out_of_plane_tip_time': when,
            'max_in_plane_tip': np.abs(a['tip'][:, :, 1]).max(0),
            'energy_balance_residual': float(np.max(np.abs(balance))),
            'energy_scale': float(np.max(np.abs(energy))),
            'friction_work': a['friction_work'][-1],
            'damping_dissipation': float(a['damping_dissipation'][-1]),
            'newton_iterations': self.iterations,
            'peak_stress': {name: (self.peak[name].copy(), list(self.peak_where[name]))
                            for name in STRESS_NAMES},
        }
        return out


def _channels(stress, rate):
    """
    Return every stress channel's values and rates: the four components, then von Mises.

    stress, rate: (step, rib, 4, point); returns two (step, rib, 5, point): the combined
    figure sqrt((|axial| + |bending z| + |bending y|)^2 + 3 shear^2) and its rate.
    """
    s, r = stress, rate
    total = np.abs(s[:, :, 0]) + np.abs(s[:, :, 1]) + np.abs(s[:, :, 2])
    vm = np.sqrt(total * total + 3.0 * s[:, :, 3] * s[:, :, 3])
    growth = (np.sign(s[:, :, 0]) * r[:, :, 0] + np.sign(s[:, :, 1]) * r[:, :, 1]
              + np.sign(s[:, :, 2]) * r[:, :, 2])
    with np.errstate(divide='ignore', invalid='ignore'):
        vm_rate = np.where(vm > 0.0, (total * growth + 3.0 * s[:, :, 3] * r[:, :, 3]) / vm, 0.0)
    return (np.concatenate([stress, vm[:, :, None]], 2),
            np.concatenate([rate, vm_rate[:, :, None]], 2))


def merged_peaks(held: tuple, new: tuple) -> tuple:
    """
    Return two runs of steps' peaks (value, at, when) as those of both, held's before new's.

    Rib by rib and channel by channel the first of the largest (argmax's rule over the steps
    of both: held's on a tie, a NaN the largest).
    """
    value, at, when = held
    better = (new[0] > value) | (np.isnan(new[0]) & ~np.isnan(value))
    return (np.where(better, new[0], value), np.where(better[..., None], new[1], at),
            np.where(better, new[2], when))


#: how far (s) a lock instant may lie past the sample it is recorded at (integer ns)
LOCK_INSTANT_TOLERANCE = 1e-9


def first_reach(t: np.ndarray, gap: np.ndarray, before: tuple | None = None,
                lock: float | None = None) -> float:
    """
    Return when gap first reaches 0 from above (linear between steps); nan if it does not.

    A rib's deployment instant (gap: its leaf angle less its deployed angle); t[0] if it
    starts there.  before: (t, gap) of the step before t[0], for a record taken in parts.
    lock: the lock's instant, if the run locked: a rib whose leaf reaches its deployed angle
    in the step (or between the samples) the lock falls in deploys at the lock, the lock's
    own instant.  The sleeve at the stop is every rib at its deployed angle, but for the
    rib's elastic deformation (its leaf angle 7e-6 rad past it at the lock, V0 = -0.5,
    identical ribs): a line between the steps around the lock, across which the velocity
    jumps, put it 3.4 us before the lock at a 0.2 ms step (5.6 us with a rubbing hinge).
    """
    hit = np.nonzero(gap <= 0.0)[0]
    if len(hit) == 0:
        return np.nan
    i = hit[0]
    if i == 0:
        if before is None or before[1] <= 0.0:
            return float(t[0])
        t0, g0 = before
    else:
        t0, g0 = t[i - 1], gap[i - 1]
    if lock is not None and t0 < lock <= t[i] + LOCK_INSTANT_TOLERANCE:
        return float(lock)
    return float(t0 + (t[i] - t0) * g0 / (g0 - gap[i]))


def deployment_spread(deployed) -> dict:
    """
    Return the spread of the ribs' deployment instants (first_reach each; NaN: not reached).

    rib_deploy_time (a list, None where not reached), deployment_lag (the latest rib's
    deployment after the earliest's; None until every rib deployed: a rib still to deploy
    lags by more than any figure yet) and latest_rib (the first rib still to deploy once
    one has, else the first of the latest; None if none did).
    """
    deployed = np.asarray(deployed, dtype=float)
    reached = np.isfinite(deployed)
    if not reached.any():
        latest = None
    elif reached.all():
        latest = int(np.argmax(deployed))
    else:
        latest = int(np.argmin(reached))
    return {'rib_deploy_time': [float(v) if ok else None for v, ok in zip(deployed, reached)],
            'deployment_lag': float(deployed.max() - deployed.min()) if reached.all()
            else None,
            'latest_rib': latest}


def largest_out_of_plane_tip(t: np.ndarray, tip: np.ndarray) -> tuple[float, int, float]:
    """
    Return the largest |w| of the ribs' tips over rows of them, its rib and when (the first).

    t: (T,) s; tip: (T, ribs, 3), u, v, w of each rib's G in its leaf frame (m).
    """
    w = np.abs(np.asarray(tip)[:, :, 2])
    i, k = np.unravel_index(np.argmax(w), w.shape)
    return float(w[i, k]), int(k), float(t[i])


def largest_leaf_angle_spread(t: np.ndarray, alpha1: np.ndarray) -> tuple[float, float | None]:
    """
    Return the largest spread of the ribs' leaf angles over rows of them, and when (the first).

    t: (T,) s; alpha1: (T, ribs) rad, the rows of the deployment (before the lock).  The
    spread of a row is its largest alpha1 less its smallest: how far the ribs are apart.
    One sleeve ties every leaf to it through its link, so the ribs reach full deployment
    together, at the lock; what asymmetry (friction, a stiffer rib) makes is this spread on
    the way and a later lock.  (0.0, None) without rows.
    """
    if not len(t):
        return 0.0, None
    spread = np.asarray(alpha1).max(1) - np.asarray(alpha1).min(1)
    i = int(np.argmax(spread))
    return float(spread[i]), float(t[i])


def energy_balance3d(rows, initial_energy: float, energy=None) -> np.ndarray:
    """
    Return T + V - (T + V)(0) - W_F - W_friction - W_drive + lock loss + dissipation (J).

    rows: a Record3D's arrays (one figure a step) or one row (a Sample3D).  The umbrella's
    energy balance, one rule: 0 for a run that keeps its energy (friction work is negative:
    the hinges take energy out; the beams' damping dissipation is positive, energy out).
    energy: T + V of rows if the caller has it already.
    """
    if energy is None:
        energy = rows['kinetic_energy'] + rows['strain_energy']
    friction = np.add.reduce(rows['friction_work'], axis=-1)    # (np.sum's, undispatched)
    return (energy - initial_energy - rows['work'] - friction
            - rows['drive_work'] + rows['lock_energy_loss'] + rows['damping_dissipation'])


def bus_attitude(rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the bus's turn about the hub axis and the hub axis's tilt (rad) of rotations R.

    R (..., 3, 3) takes the bus frame to the inertial one.  The turn is the twist of R's
    swing-twist decomposition about Y, 2 atan2(R_02 - R_20, 1 + tr R) (the quaternion's
    2 atan2(q_y, q_w)); the tilt is the angle between the bus's Y axis and the inertial Y,
    acos(R_11).  Neither depends on how the attitude is parametrised.
    """
    rot = np.asarray(rot)
    trace = rot[..., 0, 0] + rot[..., 1, 1] + rot[..., 2, 2]
    turn = 2.0 * np.arctan2(rot[..., 0, 2] - rot[..., 2, 0], 1.0 + trace)
    return turn, np.arccos(np.clip(rot[..., 1, 1], -1.0, 1.0))


def hub_spin_rate(bus_q, bus_v):
    """
    Return the bus's angular rate about its own hub axis Y (rad/s) of bus states (..., 6).

    bus_q = [X, Y, Z, psi, beta, gamma] (R = Ry(psi) Rx(beta) Rz(gamma)), bus_v their rates:
    the body-frame angular velocity is B theta' (model3d.BusFrame), whose Y component is
    cos(beta) cos(gamma) psi' - sin(gamma) beta' (a prescribed base's spin: psi').
    """
    bus_q, bus_v = np.asarray(bus_q), np.asarray(bus_v)
    gamma = bus_q[..., 5]
    out = np.cos(bus_q[..., 4])
    out *= np.cos(gamma)
    out *= bus_v[..., 3]
    out -= np.sin(gamma) * bus_v[..., 4]
    return out


def bus_odometry(bus_q, bus_v) -> np.ndarray:
    """
    Return the bus's pose and twist of a bus state: (13,) in nav_msgs/Odometry's order.

    bus_q = [X, Y, Z, psi, beta, gamma] (R = Ry(psi) Rx(beta) Rz(gamma), bus to inertial),
    bus_v their rates.  Out: the position X, Y, Z (inertial, m); R's unit quaternion x, y,
    z, w (qy(psi) qx(beta) qz(gamma), w >= 0); the linear velocity R^T X' and the angular
    velocity B theta' (model3d.BusFrame's basis B, whose Y row is hub_spin_rate's) in the
    bus frame (m/s, rad/s): the pose in the inertial frame, the twist in the body's (REP
    105).  Scalar arithmetic, once a publication: BusFrame.of builds its matrices and their
    derivatives, about ten times the cost (tests/test_ribs_publication.py ties the two).
    """
    x, y, z, psi, beta, gamma = (float(a) for a in bus_q)
    xd, yd, zd, psi_d, beta_d, gamma_d = (float(a) for a in bus_v)
    (cp, sp), (cb, sb), (cg, sg) = ((math.cos(a / 2.0), math.sin(a / 2.0))
                                    for a in (psi, beta, gamma))
    # qy(psi) qx(beta) = (cp sb, sp cb, -sp sb, cp cb), then times qz(gamma)
    qx, qy, qz, qw = cp * sb, sp * cb, -sp * sb, cp * cb
    a, b, c, w = qx * cg + qy * sg, qy * cg - qx * sg, qz * cg + qw * sg, qw * cg - qz * sg
    if w < 0.0:
        a, b, c, w = -a, -b, -c, -w
    # R^T X', R the quaternion's rotation
    linear = ((1.0 - 2.0 * (b * b + c * c)) * xd + 2.0 * (a * b + c * w) * yd
              + 2.0 * (a * c - b * w) * zd,
              2.0 * (a * b - c * w) * xd + (1.0 - 2.0 * (a * a + c * c)) * yd
              + 2.0 * (b * c + a * w) * zd,
              2.0 * (a * c + b * w) * xd + 2.0 * (b * c - a * w) * yd
              + (1.0 - 2.0 * (a * a + b * b)) * zd)
    # B theta', B's columns Rz^T Rx^T e_y, Rz^T e_x, e_z
    c_beta, s_beta, c_gamma, s_gamma = (math.cos(beta), math.sin(beta), math.cos(gamma),
                                        math.sin(gamma))
    angular = (s_gamma * c_beta * psi_d + c_gamma * beta_d,
               c_beta * c_gamma * psi_d - s_gamma * beta_d,
               -s_beta * psi_d + gamma_d)
    return np.array([x, y, z, a, b, c, w, *linear, *angular])
