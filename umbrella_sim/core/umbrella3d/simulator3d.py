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
The umbrella's run: time grid, sleeve force, the stop and lock, stuck hinges, the base.

``UmbrellaSimulator3D`` steps on the planar simulator's grid t_k = k h (h: the planar rule for
the mesh, ``step_rule.physics_step_of``, with the stage-2 mode fit where it applies:
``phase_correction`` on, on every base, the locked modes fitted from the lock on
(integrator3d.MidpointUmbrella.fit_stage2_modes: each rib's in the hub's frame with the hub
fixed or driven, the free system's with a free bus: stage2fit.py); else the rule without
it; unless the planar record sets ``time_step``) and
applies the lock as it does: when the sleeve passes the stop inside a step the step is taken
again from its start with the length root-found by the Illinois method (|dt| < 1e-12 s), the
lock is applied there (plastic: the velocity projected onto the locked joints in the mass
metric; energy: each rib's rigid velocities and the link's end velocities redistributed
keeping the rib's kinetic energy, the planar rule rib by rib, the sleeve's own kinetic
energy lost), and the step is completed locked.  A stuck hinge (``stick_until`` /
``stick_torque``) is a joint alpha1 = its angle, released after the step at whose end the
time has reached stick_until or its holding torque (the joint's multiplier) has reached
stick_torque.  Every step's figures go to a ``Record3D`` (outputs3d.py).  Where the step is
chosen for the run (step_rule.follows_lock), a lock whose worst rib needs a finer stage-2
step (substeps3d.py: the planar rule on each rib's in-plane state) makes every stage-2 grid
step k physics steps (``stage2_substeps``; the grid, the inputs and Record3D's rows stay on
t_k = k h, a row's peaks the largest over its physics steps).

The model is the parameters' (corotational3d.umbrella_model): the linear 3D beams, or with
``model: flexible-nonlinear`` the co-rotational ribs (compiled: _kernel3d_nonlinear.h),
which take no stage-2 mode fit.  With the compiled step
(``MidpointUmbrella.backend`` 'compiled': the library built), ``advance`` and ``run`` take
the grid steps in runs of up to ADVANCE_BLOCK steps a call (_kernel3d.c: the same steps and
release; a run stops before the step that reaches the stop, which ``step`` then takes here,
with the lock); ``step`` alone takes one step a call.
"""
from __future__ import annotations

from dataclasses import replace
import math

import numpy as np

from .corotational3d import umbrella_model
from .integrator3d import ConvergenceError3D, MidpointUmbrella, State3D
from .model3d import ROW_STICK
from .outputs3d import Record3D
from .params3d import UmbrellaRibsParams
from .substeps3d import stage2_resolution
from ..engines import event_root, EVENT_TIME_TOLERANCE
from ..integrators import newton_tolerance
from ..kernel import ALPHA1_AXLE, kernel_error, STATUS
from ..lock import locked_velocity_base, LockImpossible, velocity_keeping_energy
from ..outputs import substep_ends
from ..step_rule import (follows_lock, physics_step_of, stage2_physics_steps, stage2_step_of,
                         stage2_substeps_for)


#: physics steps a compiled call takes at most (its output rows: ~0.3 MB at 12 ribs x 2
#: elements): grid steps, or in stage 2's substeps this / their count
ADVANCE_BLOCK = 256


class SimulationFailed(RuntimeError):
    """A step failed (Newton, a singular matrix, an impossible energy lock)."""


class UmbrellaSimulator3D:
    """Steps the umbrella; see the module docstring."""

    def __init__(self, params: UmbrellaRibsParams, step: float | None = None,
                 tolerance: float | None = None, kernel: str | None = None,
                 carry_steps: int | None = None):
        self.params = params.validated()
        self.model = m = umbrella_model(self.params)
        #: stage 2's mode fit (the planar rule's: stage2fit.py for each base)
        self.mode_fit = self.fits_modes(self.params)
        self.h = self.grid_step(self.params) if step is None else step
        self.integrator = MidpointUmbrella(
            m, newton_tolerance(self.h) if tolerance is None else tolerance, kernel=kernel,
            **({} if carry_steps is None else {'carry_steps': carry_steps}))
        self._follows_lock = step is None and follows_lock(self.params)
        #: the step the lock is judged at: the grid's, or where stage 2 follows its lock the
        #: grid's largest divisor no coarser than the mesh's (step_rule.stage2_step_of)
        self.stage2_base = (self.stage2_step(self.params, self.h) if self._follows_lock
                            else self.h)
        if self.mode_fit:       # (at the step stage 2 takes short of its lock's needs)
            self.integrator.fit_stage2_modes(self.stage2_base)
        #: the physics steps a stage-2 grid step takes (1 until a lock needs more:
        #: ``_judge_stage2``), and how well the stage-2 step resolves the lock's modes (the
        #: worst rib's step_rule.stage2_resolution; None before the lock, co-rotational ribs)
        self.stage2_substeps = 1
        self.stage2_resolution: dict | None = None
        #: a Newton tolerance given: kept at the substeps (else theirs, newton_tolerance)
        self._tolerance = tolerance
        self.force = self.params.planar.sleeve_force * m.n_ribs
        self.locked = False
        self.lock_time: float | None = None
        #: (the state right after the lock, the work of the step up to it, the record's
        #: work totals before that step); None before the lock
        self.lock_state = None
        self.lock_loss = 0.0
        self.k = 0
        ribs = m.ribs
        self.stick_until = np.array([r.stick_until for r in ribs])
        self.stick_torque = np.array([r.stick_torque for r in ribs])
        self.state = self.integrator.consistent(self.initial_state(), self.force, False)
        self.record = Record3D(m)
        self.record.add(self.state, self.locked, self.force, None, 0.0)

    @staticmethod
    def fits_modes(params: UmbrellaRibsParams) -> bool:
        """
        Say whether stage 2 takes the planar mode fit: phase_correction, on every base.

        A driven hub's ribs have the fixed hub's locked modes in the hub's frame, and a free
        bus's system has the same count of them resolved at the planar rule's step (6 ribs,
        1 element, bus 5 to 100 kg: 84 of 90 at 0.1 ms either way; the free system's modes
        that couple to the bus are a few % stiffer), so the step follows the mode fit there
        as with the hub fixed.  Not with flexible-nonlinear (as the planar model: step_rule.py
        says why).
        """
        return params.planar.phase_correction and params.planar.model == 'flexible'

    @classmethod
    def grid_step(cls, params: UmbrellaRibsParams) -> float:
        """
        Return the grid's step of these parameters (the planar rule, its mode fit's).

        A driven base that moves, with time_step 0, keeps stage 2's step in stage 1 too: its
        drive sets the modes vibrating before the lock, which stage 1's step does not
        resolve (step_rule.STAGE1_STEP_CEILING says what was measured).
        """
        rule = cls._planar_rule(params)
        drive = (params.base_accel_x, params.base_accel_z, params.base_spin_rate)
        if params.base == 'prescribed' and any(drive) and rule.time_step == 0.0:
            return stage2_step_of(rule)
        return physics_step_of(rule)

    @classmethod
    def stage2_step(cls, params: UmbrellaRibsParams, grid: float | None = None) -> float:
        """Return stage 2's step short of its lock's needs on the grid (the planar rule)."""
        return stage2_step_of(cls._planar_rule(params), grid)

    @classmethod
    def _planar_rule(cls, params: UmbrellaRibsParams):
        planar = params.planar
        return planar if cls.fits_modes(params) else planar.replace(phase_correction=False)

    # ------------------------------------------------------------ start
    def initial_state(self) -> State3D:
        """
        Return the state at t = 0: every rib rigid at the start height of the sleeve.

        Its sleeve moves at v0; per-rib angle, rate and out-of-plane perturbations are applied
        and projected onto the joints (positions by Newton in the mass metric, velocities by
        the mass-metric projection); a free bus takes the velocity that makes the momentum
        zero; a stuck hinge holds its root's initial turn (its velocity projected to 0).
        """
        m, p = self.model, self.params
        nr, n = m.n_ribs, m.n_rib
        v0 = p.planar.v0
        qr, vr = np.zeros((nr, n)), np.zeros((nr, n))
        for k in range(nr):
            q = m.rigid_rib(k, m.rib_angle_at_height(k, m.y_start))
            unit = m.rigid_rib_velocity(k, q, 1.0)
            qr[k] = q
            vr[k] = unit * (v0 / (m.sleeve_height_gradient(q, k) @ unit))
        qs, vs = np.zeros(m.n_shared), np.zeros(m.n_shared)
        qs[0], vs[0] = m.y_start, v0
        drive = self.integrator.drive
        if drive is not None:
            g, gd, _ = drive(0.0)
            qs[1:7], vs[1:7] = g, gd
        offsets = np.array([r.alpha0_offset for r in m.ribs])
        rates = np.array([r.rate_offset for r in m.ribs])
        kicks = np.array([r.out_of_plane_rate for r in m.ribs])
        stuck = np.where((self.stick_until > 0.0) | (self.stick_torque > 0.0),
                         m.hinge_angle(qr) + offsets, np.nan)
        if np.any(offsets != 0.0):
            qr[:, m.i_a1] += offsets
            qr, qs = self._settle_positions(qr, qs, stuck)
        perturbed = np.any(rates != 0.0) or np.any(kicks != 0.0) or np.any(~np.isnan(stuck))
        vr[:, m.i_a1] += rates
        vr[:, m.i_tip[2]] += kicks
        kin = m.kinematics(qr, qs)
        mass = m.mass_matrix(kin)
        if perturbed or np.any(offsets != 0.0):
            vr, vs = self.integrator.project(kin, mass, qr, vr, vs, stuck, False,
                                             None if drive is None else vs[1:7])
        if p.base == 'free':
            pr, ps = m.matvec(mass, vr, vs)
            vs = vs.copy()
            vs[1:7] -= np.linalg.solve(mass[2][1:7, 1:7], ps[1:7])
        return State3D(0.0, qr, qs, vr, vs, np.zeros((nr, 9)),
                       np.zeros(m.n_shared_rows), stuck)

    def _settle_positions(self, qr, qs, stuck):
        """Return the nearest configuration (mass metric) on the joints: Newton projection."""
        m = self.model
        integ = self.integrator
        drive = None if integ.drive is None else integ.drive(0.0)[0]
        for _ in range(50):
            phi_r, phi_s = m.constraints(qr, qs, stuck, False, drive)
            if max(np.max(np.abs(phi_r)), np.max(np.abs(phi_s))) < 1e-13:
                break
            kin = m.kinematics(qr, qs)
            mass = m.mass_matrix(kin)
            # the projection of 0 onto J dq = -Phi: the same arrow solve as the velocities'
            j_rr, j_rs, j_ss, active = m.constraint_jacobian(qr, stuck, False)
            blocks = integ._blocks(mass, (j_rr, j_rs, j_ss), (j_rr, j_rs, j_ss), stuck,
                                   active, sign=1.0)
            from . import arrow
            f = arrow.factor(*blocks)
            n, ns = m.n_rib, m.n_shared
            rr = np.concatenate([np.zeros_like(qr), -phi_r], 1)
            sh = np.concatenate([np.zeros(ns), np.where(active, -phi_s, 0.0)])
            xr, xs = f.solve(rr, sh)
            qr, qs = qr + xr[:, :n], qs + xs[:ns]
        return qr, qs

    # ------------------------------------------------------------ stepping
    @property
    def time(self) -> float:
        return self.state.t

    def _step(self, s, h, locked):
        try:
            out = self.integrator.step(s, h, self.force, locked)
            self.model.note_state(out[0].qr)
            return out
        except (ConvergenceError3D, np.linalg.LinAlgError) as exc:
            raise self._failed(s.qr, f'step after t = {s.t:.9g} s failed: {exc}') from None

    def _failed(self, qr, text: str) -> SimulationFailed:
        """Return the failure of a step from the state qr: text, and why where the model knows."""
        explain = getattr(self.model, 'failure_reason', None)     # (the co-rotational ribs)
        reason = explain(qr) if explain is not None else None
        return SimulationFailed(text if reason is None else f'{text}: {reason}')

    def step(self) -> None:
        """Advance by one grid step, with the lock if the sleeve reaches the stop in it."""
        m, s0 = self.model, self.state
        t_next = (self.k + 1) * self.h
        if self.locked and self.stage2_substeps > 1:
            self._substep_grid(s0, t_next)
            return
        s1, work = self._step(s0, t_next - s0.t, self.locked)
        if not self.locked and s1.qs[0] - m.y_stop > 0.0:
            if np.any(s1.qr[:, m.i_a1] >= ALPHA1_AXLE):
                raise self._at_axle()
        lock_event = tips = None      # (tips: the lock's rest's, if in substeps)
        if not self.locked and s1.qs[0] - m.y_stop <= 0.0:
            s_hit, work_hit = self._find_lock(s0, t_next - s0.t)
            before = self.energy(s_hit)
            s_locked = self._lock(s_hit)
            self._judge_stage2(s_locked)
            self.integrator.lock_at(s_locked)
            rec = self.record
            self.lock_state = (s_locked, work_hit, (rec.work, rec.friction, rec.drive,
                                                    rec.damping))
            after = self.energy(s_locked)
            self.locked, self.lock_time = True, s_locked.t
            self.lock_loss += before - after
            lock_event = (s_locked.t, before, after)
            remaining = t_next - s_locked.t
            if remaining > EVENT_TIME_TOLERANCE:
                s1, work2, tips = self._locked_steps(s_locked, remaining)
                work = work_hit.plus(work2)
            else:
                s1, work = s_locked, work_hit
        s1 = s1.at(t_next)
        s1 = self._release(s1)
        self.state = s1
        self.k += 1
        if tips is not None:        # (the last at the row's time)
            tips[0][-1] = t_next
        self.record.add(s1, self.locked, self.force, work, self.lock_loss, lock_event,
                        tips=tips)

    def advance(self, steps: int, stop_at_lock: bool = False) -> None:
        """
        Take `steps` grid steps (as many calls of ``step``; compiled: in runs of them).

        stop_at_lock: return after the step in which the lock happens, if it does.
        """
        target = self.k + steps
        compiled = self.integrator.compiled
        while self.k < target:
            if compiled is None:
                self.step()
                if stop_at_lock and self.locked:
                    return
                continue
            sub = self.stage2_substeps if self.locked else 1
            grid = min(target - self.k, max(1, ADVANCE_BLOCK // sub))   # (physics steps a call)
            # (the kernel folds the substeps' rows where it gives their stress figures)
            fold = sub if compiled.figures else 1
            status, done, rows = compiled.advance_rows(
                self.state, self.k * sub, self.h / sub, grid * sub, self.force, self.locked,
                self.record.crest_continues(self.locked), fold=fold)
            if done:
                total = np.add.reduce       # (np.sum's, without its dispatch)
                self.integrator.iterations += int(total(rows['iterations']))
                self.integrator.factorisations += int(total(rows['factorisations']))
                self.model.note_state(rows['qr'])
                times = t = None        # (t: the state's time; None, the call's own)
                if sub > 1:     # (grid rows the kernel folded, at the grid's times)
                    first = self.k + 1
                    times = np.arange(first, first - (-done // sub)) * self.h
                    if done % sub:          # (a fault's last grid step: its own time)
                        times[-1] = compiled.call.t
                    t = float(times[-1])
                state = compiled.reached(t)
                tips = None        # (every physics step's, where the kernel folded them)
                if fold > 1:       # (a grid step's last at its row's time)
                    first = self.k * sub + 1
                    tips = (np.arange(first, first + done) * (self.h / sub),
                            compiled.physics_tips(done).copy())
                    tips[0][substep_ends(done, sub)] = times
                self.record.add_steps(rows, self.locked, self.force, self.lock_loss,
                                      sub // fold, times, tips)
                self.state = state
                self.k += done // sub
            if status == STATUS['crossing']:
                self.step()                     # the lock, here
                if stop_at_lock:
                    return
            elif status == STATUS['axle']:      # (the state: the last step before it)
                raise self._at_axle()
            elif status != STATUS['ok']:
                raise self._failed(self.state.qr, f'step after t = {self.state.t:.9g} s failed: '
                                   f'{kernel_error(status, self.state.t + self.h / sub)}')

    # ------------------------------------------------------------ stage-2 substeps
    def _judge_stage2(self, s: State3D) -> None:
        """
        Judge the stage-2 step on the lock's state s: the worst rib's (substeps3d.py).

        Where the step is chosen for the run (step_rule.follows_lock), stage 2 then takes
        the substeps its lock needs (step_rule.substeps_for: the planar engine's rule), the
        Newton tolerance and mode fit of that step (MidpointUmbrella.take_substeps).
        """
        if self.params.planar.model != 'flexible':
            return
        resolution = stage2_resolution(self.model, s.qr, s.vr, self.stage2_base)
        if self._follows_lock:
            k = stage2_substeps_for(self.h, self.stage2_base, resolution['needed_step'])
            self.integrator.take_substeps(self.h / k, self._tolerance)
            if k > 1:
                self.stage2_substeps = k
                # (judged again at the step stage 2 takes, as the planar engine)
                resolution = stage2_resolution(self.model, s.qr, s.vr, self.h / k)
        self.stage2_resolution = resolution

    def _locked_steps(self, s: State3D, dt: float):
        """
        Return the state dt after s in stage 2, the work, and its physics steps' tips.

        Its physics steps: n of dt / n, the fewest no longer than the stage-2 step h /
        stage2_substeps (the planar simulator's _physics_steps); their tips: the time and
        each rib's tip v and w (Record3D's physics_tips3d) if n > 1, else None.
        """
        n = stage2_physics_steps(dt, self.h, self.stage2_substeps)
        s, work = self._step(s, dt / n, True)
        states = [s]
        for _ in range(n - 1):
            s, w = self._step(s, dt / n, True)
            work = work.plus(w)
            states.append(s)
        tips = None if n == 1 else (np.array([x.t for x in states]), np.array(
            [x.qr[:, self.model.i_tip[1:]] for x in states]))
        return s, work, tips

    def _substep_grid(self, s0: State3D, t_next: float) -> None:
        """
        Take a stage-2 grid step in its physics steps (``step`` past a lock that needs them).

        Each physics step's figures go to the record, which keeps the grid step's row: its
        last step's figures, the peaks the largest over its steps (Record3D.add_substeps).
        A stuck hinge is released after the physics step that releases it (as the compiled
        advance).
        """
        n = stage2_physics_steps(t_next - s0.t, self.h, self.stage2_substeps)
        dt = (t_next - s0.t) / n
        states, works, s = [], [], s0
        for _ in range(n):
            s, work = self._step(s, dt, True)
            s = self._release(s)
            states.append(s)
            works.append(work)
        states[-1] = s = s.at(t_next)
        self.state = s
        self.k += 1
        self.record.add_substeps(states, works, True, self.force, self.lock_loss)

    def _steps_to(self, t_end: float) -> int:
        """Return the grid steps from now until the time reaches t_end (within 1e-12 s)."""
        n = max(1, math.ceil((t_end - 1e-12) / self.h) - self.k)
        while n > 1 and (self.k + n - 1) * self.h >= t_end - 1e-12:
            n -= 1
        while (self.k + n) * self.h < t_end - 1e-12:
            n += 1
        return n

    def run(self, duration: float, after_lock: float | None = None) -> 'Record3D':
        """
        Take every grid step that ends by t = duration (or to after_lock s past the lock).

        The planar simulator's rule (UmbrellaSimulator.advance_to, the run driver's): a
        duration between grid steps ends at the step before it.  Returns the record.
        """
        k_end = math.floor(duration / self.h + 1e-9)
        while self.k < k_end:
            n = k_end - self.k
            if after_lock is not None and self.locked:
                n = min(n, self._steps_to(self.lock_time + after_lock))
            self.advance(n if self.integrator.compiled else 1,
                         stop_at_lock=after_lock is not None and not self.locked)
            if after_lock is not None and self.locked and self.time >= self.lock_time + after_lock:
                break
        return self.record

    def _at_axle(self) -> SimulationFailed:
        """
        Return the fault of a step that took a leaf to the axle before the lock.

        It names the rib whose leaf was nearest the axle at the last good step (self.state,
        which either path keeps: the compiled step does not hand over the failed one).
        """
        rib = int(np.argmax(self.state.qr[:, self.model.i_a1]))
        return SimulationFailed(
            f'step after t = {self.state.t:.9g} s failed: rib {rib}: the leaf reached the axle '
            f'(alpha1 = pi/2 = {ALPHA1_AXLE:.6g} rad) before the lock: the rib folded back past '
            'its start, where the model has no stop (a stuck or slowed rib can hold the sleeve '
            'while the others swing there: start such a run from rest, v0 0, and push the '
            'sleeve with a sleeve_force; the planar model: a fault too)')

    def _release(self, s: State3D) -> State3D:
        stuck = s.stuck
        if np.all(np.isnan(stuck)):
            return s
        torque = np.abs(s.lam_r[:, ROW_STICK])
        free = ~np.isnan(stuck) & (((self.stick_until > 0.0) & (s.t >= self.stick_until - 1e-12))
                                   | ((self.stick_torque > 0.0) & (torque >= self.stick_torque)))
        if not np.any(free):
            return s
        lam = s.lam_r.copy()
        lam[free, ROW_STICK] = 0.0
        return replace(s, stuck=np.where(free, np.nan, stuck), lam_r=lam)

    def _find_lock(self, s0: State3D, h: float):
        """Illinois root find of y_s(t0 + dt) = y_stop on the step length (the planar rule)."""
        y_stop = self.model.y_stop

        def at(dt):
            s, w = self._step(s0, dt, False)
            return (s, w), s.qs[0] - y_stop

        return event_root(at, h, s0.qs[0] - y_stop)

    # ------------------------------------------------------------ the lock
    def _lock(self, s: State3D) -> State3D:
        m, integ = self.model, self.integrator
        kin = m.kinematics(s.qr, s.qs)
        mass = m.mass_matrix(kin)
        drive = integ.drive
        target = None if drive is None else drive(s.t)[1]
        if self.params.lock_rule == 'plastic':
            vr, vs = integ.project(kin, mass, s.qr, s.vr, s.vs, s.stuck, True, target)
        else:
            vr, vs = self._energy_lock(mass, s)
        s = replace(s, vr=vr, vs=vs, pr=None, ps=None)
        return integ.consistent(s, self.force, True)

    def _energy_lock(self, mass, s: State3D):
        """
        Return the velocities after the energy lock, rib by rib (Hu, McGill 2006, §5.2.2).

        Only each rib's rigid velocities (alpha1, R2, alpha2) and the link's end ones (u, w
        at H; slope and twist at O'') change, to satisfy the locked joints and keep the rib's
        kinetic energy; of the two roots the one closest to the velocity before (mass
        metric).  The sleeve stops.
        """
        m = self.model
        vr, vs = s.vr.copy(), s.vs.copy()
        vs[0] = 0.0
        j_rr = m.constraint_jacobian(s.qr, s.stuck, True)[0]
        free = [m.i_a1, m.i_rx, m.i_ry, m.i_a2, m.i_uh, m.i_rz, m.i_wh, m.i_s2, m.i_p2]
        for k in range(m.n_ribs):
            rows = list(range(8)) + ([ROW_STICK] if not np.isnan(s.stuck[k]) else [])
            jac = j_rr[k][rows]
            if len(rows) >= len(free):          # a stuck rib: no free direction left
                vr[k] = locked_velocity_base(jac, vr[k], free)
                continue
            try:
                vr[k] = velocity_keeping_energy(jac, mass[0][k], vr[k], free)
            except LockImpossible:
                raise SimulationFailed(
                    f'energy lock impossible for rib {k}: its kinetic energy is below the '
                    'least the locked joints allow (lock plastic takes such a lock: it '
                    'stops what the locked joints do not allow and loses its energy)'
                ) from None
        return vr, vs

    # ------------------------------------------------------------ figures
    def energy(self, s: State3D) -> float:
        m = self.model
        return m.kinetic_energy(m.kinematics(s.qr, s.qs), s.vr, s.vs) + m.strain_energy(s.qr)
