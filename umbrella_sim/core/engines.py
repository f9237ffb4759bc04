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
Engines: how one model steps in time (the ``Engine`` interface and its implementations).

``FiniteElementEngine`` steps the flexible (Case 1 -> Case 2) and rigid-FE (Case 3) models
on the midpoint DAE integrator (compiled, or numpy as the reference); ``RigidEngine`` the
closed-form two-angle model; nonlinear.py adds the geometrically nonlinear / damped one.
``UmbrellaSimulator`` (solver.py) drives any of them on the time grid and applies the lock.
"""
from __future__ import annotations

import abc
from dataclasses import replace
import math
import re

import numpy as np

from .integrators import MidpointDAE, newton_tolerance
from .kernel import (ADVANCE_CROSSING, ADVANCE_DIVERGED, ADVANCE_DONE, ALPHA1_AXLE, AXLE_REASON,
                     DynamicState)
from .lock import energy_velocity, LockImpossible
from .model import ConstraintSet, DEFORMING, LOCKED, Stage, UmbrellaModel
from .outputs import LockEvent, STEP_FIELDS, step_peaks
from .params import UmbrellaParams
from .rigid import RigidMechanism
from .step_rule import (follows_lock, physics_step_of, stage2_resolution, stage2_step_of,
                        stage2_substeps_for)

#: the row of each STEP_FIELDS name
_STEP_ROW = {name: row for row, name in enumerate(STEP_FIELDS)}
#: residual above which a run is declared diverged (m, m/s)
DIVERGENCE_RESIDUAL = 1e-6
EVENT_TIME_TOLERANCE = 1e-12


class SimulationDiverged(RuntimeError):
    """The state became non-finite or left the constraint manifold; nothing was advanced."""


def fault_message(t_good: float, reason: str) -> str:
    """
    Return the text of a solver fault with one time in it: the last good state's.

    reason: what failed (an integrator's own 'at t = ...' is dropped: the failed step is
    the one after t_good, and the recording's fault_time is t_good).
    """
    reason = re.sub(r' at t = \S+ s', '', reason)
    return f'solver failed in the step after t = {t_good:.9g} s: {reason}'


class Engine(abc.ABC):
    """
    Define what the simulator needs of a model's time stepping.

    What the simulator needs of a model's time stepping (flexible / rigid-FE on the
    midpoint DAE integrator, the closed-form rigid model, or any other model).

    States are DynamicState; the stage selects the constraints.  ``advance`` is the fast
    path (many steps in one call, compiled); an engine without one returns None from it and
    the simulator loops over ``step``.
    """

    lock_kind: str
    #: physics steps a stage-2 grid step takes (an engine whose lock may need more sets it)
    stage2_substeps = 1

    @property
    @abc.abstractmethod
    def backend(self) -> str:
        """Name what does the stepping, for logs and recordings."""

    @abc.abstractmethod
    def initial(self, force: float) -> DynamicState:
        """Return the state at t = 0, stage deploying."""

    @abc.abstractmethod
    def step(self, s: DynamicState, h: float, force: float, stage: Stage) -> DynamicState:
        """One step of length h (raises ConvergenceError)."""

    @abc.abstractmethod
    def fe_state(self, s: DynamicState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q', q'') in the finite-element coordinates of UmbrellaModel."""

    @abc.abstractmethod
    def residual(self, s: DynamicState, stage: Stage) -> float:
        """max(|Phi|, |J q'|)."""

    @abc.abstractmethod
    def sleeve_height(self, s: DynamicState) -> float:
        """y_H (m)."""

    @abc.abstractmethod
    def kinetic_energy(self, s: DynamicState, stage: Stage) -> float:
        """T (J)."""

    def strain_energy(self, s: DynamicState, stage: Stage) -> float:
        """V (J)."""
        return float(self.model.strain_energy(self.fe_state(s)[0]))

    @abc.abstractmethod
    def sleeve_reaction(self, s: DynamicState, stage: Stage) -> tuple[float, float]:
        """Force on the sleeve from the axle (X) and the stop (Y), N."""

    @abc.abstractmethod
    def lock(self, s: DynamicState, force: float) -> tuple[DynamicState, LockEvent]:
        """Return the state right after the lock at s (same t), and what the lock did."""

    def newton_iterations(self) -> int:
        """Newton iterations so far (0 for explicit schemes)."""
        return 0

    def sample_outputs(self, s: DynamicState, stage: Stage):
        """
        Return the Sample vector of s from compiled code, or None (no fast path).

        A read-only array of s's own (for a state an advance made, it shares that state's
        copy): kernel.SAMPLE_VECTOR (figures and residual max(|Phi|, |J q'|)), then the
        top and bottom fibre stress at every stress point, leaf points first.  What
        ``_sample`` otherwise computes with numpy, in one call.
        """
        return None

    def find_crossing(self, s: DynamicState, h: float, force: float):
        """
        Return the state at the lock instant inside a step of length h from s, or None.

        The fast path of ``UmbrellaSimulator._find_lock`` (compiled, the same root find);
        None if this engine has none.  Raises SimulationDiverged like a failed step.
        """
        return None

    def advance(self, s: DynamicState, k0: int, h: float, n_steps: int, force: float,
                stage: Stage, work: float, lock_loss: float, states: bool = False):
        """
        Take up to n_steps grid steps in one call (the fast path).

        Up to n_steps grid steps t_k -> (k + 1) h from s at t = k0 h in one call; stops
        before a step in which the sleeve reaches the stop (stage deploying), and at a
        failure.  Returns None if this engine has no such path, else (state, rows, work,
        stop, state_rows): rows (len(STEP_FIELDS), steps done; may be the engine's buffer,
        valid until its next call), stop None (all steps done), "crossing", or a failure
        message; state_rows, if states, the steps' state rows (outputs.StepBlock.states;
        may be the engine's buffer too), else None.
        """
        return None


class FiniteElementEngine(Engine):
    """Flexible (Case 1 -> Case 2) or rigid-FE (Case 3) model on the midpoint DAE integrator."""

    def __init__(self, params: UmbrellaParams, model: UmbrellaModel):
        self.model = model
        self.rigid = params.model == 'rigid-fe'
        self.lock_kind = params.lock_rule
        self.integrator = self._integrator(model)
        self.h = physics_step_of(params)
        self.integrator.tolerance = newton_tolerance(self.h)
        self.stage2_substeps = 1       # (until the lock: step_rule.follows_lock)
        self._follows_lock = follows_lock(params)
        #: the step the lock is judged at: the grid's, or where stage 2 follows its lock the
        #: grid's largest divisor no coarser than the mesh's (step_rule.stage2_step_of)
        self.stage2_base = stage2_step_of(params, self.h)
        if params.phase_correction and self.phase_correctable:   # LockedModeFit
            self.integrator.fit_stage2_modes(self.stage2_base)
        self._cs = {stage: ConstraintSet(locked=stage == LOCKED, rigid=self.rigid)
                    for stage in Stage}

    @staticmethod
    def _integrator(model: UmbrellaModel) -> MidpointDAE:
        return MidpointDAE(model)

    @property
    def phase_correctable(self) -> bool:
        """Stage 2 takes LockedModeFit: its elastic coordinates vibrate (not rigid-FE)."""
        return not self.rigid

    @property
    def backend(self) -> str:
        return self.integrator.backend

    def newton_iterations(self) -> int:
        return self.integrator.iterations

    def initial(self, force: float) -> DynamicState:
        q, qd = self.model.initial_state()
        qdd, lam = self.integrator.consistent_acceleration(q, qd, force, self._cs[DEFORMING])
        return DynamicState(0.0, q, qd, qdd, lam)

    def step(self, s: DynamicState, h: float, force: float, stage: Stage) -> DynamicState:
        return self.integrator.step(s, h, force, self._cs[stage])

    def sample_outputs(self, s, stage):
        kernel = self.integrator.kernel
        if kernel is None or s.momentum is None:
            return None
        return kernel.sample(s, self._cs[stage])

    def find_crossing(self, s, h, force):
        kernel = self.integrator.kernel
        # an elastic law (nonlinear.py) carries its dissipation and halves failed steps:
        # its crossing goes through its own step
        if kernel is None or getattr(kernel, 'elastic_law', None) is not None:
            return None
        integ = self.integrator
        status, state, dt, its, residual = kernel.find_crossing(
            s, h, force, self._cs[DEFORMING], integ.tolerance, integ.max_iterations,
            DIVERGENCE_RESIDUAL, EVENT_TIME_TOLERANCE)
        integ.iterations += its
        if status == ADVANCE_DIVERGED:
            raise SimulationDiverged(fault_message(s.t, f'constraint residual {residual:.3g} '
                                                        f'past tolerance {DIVERGENCE_RESIDUAL:g}'))
        if status != ADVANCE_DONE:
            raise SimulationDiverged(fault_message(s.t, integ.kernel_error(status, s.t + dt)))
        return state

    def advance(self, s, k0, h, n_steps, force, stage, work, lock_loss, states=False):
        kernel = self.integrator.kernel
        if kernel is None:
            return None
        integ, cs = self.integrator, self._cs[stage]
        kernel.load(s, work, lock_loss)     # a no-op when s is the state it returned last
        status, done, its, residual = kernel.advance(
            cs, k0, h, n_steps, force, integ.tolerance, integ.max_iterations,
            DIVERGENCE_RESIDUAL, states)
        integ.iterations += its
        t = (k0 + done) * h
        if status == ADVANCE_DONE:
            stop = None
        elif status == ADVANCE_CROSSING:
            stop = 'crossing'
        elif status == ADVANCE_DIVERGED:
            stop = fault_message(t, f'constraint residual {residual:.3g} past tolerance '
                                    f'{DIVERGENCE_RESIDUAL:g}')
        else:
            stop = fault_message(t, integ.kernel_error(status, t + h))
        state = kernel.state(t, self.model.n_constraints(cs)) if done else s
        return (state, kernel.out[:, :done], float(kernel.acc[0]), stop,
                kernel.states_out[:, :done] if states else None)

    def fe_state(self, s: DynamicState):
        return s.q, s.qd, s.qdd

    def kinetic_energy(self, s: DynamicState, stage: Stage) -> float:
        # the step leaves its momentum M(q) qd in the state: T = 1/2 qd . p without
        # re-assembling M
        if s.momentum is not None:
            return float(0.5 * s.qd @ s.momentum)
        return float(self.model.kinetic_energy(s.q, s.qd))

    def strain_energy(self, s: DynamicState, stage: Stage) -> float:
        return self.integrator.strain_energy(s.q, self._cs[stage])

    def sleeve_reaction(self, s: DynamicState, stage: Stage) -> tuple[float, float]:
        lam = s.multipliers
        return float(lam[2]), float(lam[3]) if stage == LOCKED else 0.0

    def residual(self, s: DynamicState, stage: Stage) -> float:
        cs = self._cs[stage]
        m = self.model
        return max(float(np.max(np.abs(m.constraint_residual(s.q, cs)))),
                   float(np.max(np.abs(m.constraint_jacobian(s.q, cs) @ s.qd))))

    def sleeve_height(self, s: DynamicState) -> float:
        return float(self.model.sleeve_height(s.q))

    def lock(self, s: DynamicState, force: float) -> tuple[DynamicState, LockEvent]:
        m = self.model
        cs = self._cs[LOCKED]
        before = m.kinetic_energy(s.q, s.qd) + m.strain_energy(s.q)
        free: tuple = ()
        if self.lock_kind == 'energy':
            try:
                qd, free = energy_velocity(m, s.q, s.qd, cs)
            except LockImpossible as exc:
                raise SimulationDiverged(str(exc)) from None
        else:
            qd = self.integrator.project_velocity(s.q, s.qd, cs)
        s = self.integrator.with_constraints(replace(s, qd=qd), force, cs)
        after = m.kinetic_energy(s.q, s.qd) + m.strain_energy(s.q)
        resolution = None if self.rigid else stage2_resolution(m, s.q, s.qd, self.stage2_base)
        if resolution is not None and self._follows_lock:
            self._follow(resolution['needed_step'])
            if self.stage2_substeps > 1:       # (judged again at the step stage 2 takes)
                resolution = stage2_resolution(m, s.q, s.qd, self.h / self.stage2_substeps)
        self.integrator.lock_at()
        return s, LockEvent(s.t, self.lock_kind, float(before), float(after), free, resolution)

    def _follow(self, needed: float | None) -> None:
        """Take stage 2 in the substeps its lock needs (None: the finest the rule allows)."""
        k = stage2_substeps_for(self.h, self.stage2_base, needed)
        if k <= 1:
            return
        self.stage2_substeps = k
        integ = self.integrator
        integ.tolerance = newton_tolerance(self.h / k)
        if integ.mode_fit is not None and integ.mode_fit.step != self.h / k:
            integ.fit_stage2_modes(self.h / k)


class RigidEngine(Engine):
    """Closed-form two-angle model (4.120-4.125), RK4 with projection, sub-stepped."""

    max_substep = 1e-4
    backend = 'closed-form rigid (Python)'

    def __init__(self, params: UmbrellaParams, model: UmbrellaModel):
        self.model = model
        self.mech = RigidMechanism(params)
        self.lock_kind = 'plastic'

    def initial(self, force: float) -> DynamicState:
        y = self.mech.initial_state(self.model.params.v0)
        return self._state(0.0, y, force, DEFORMING)

    def _state(self, t, y, force, stage) -> DynamicState:
        if stage == LOCKED:
            return DynamicState(t, np.array(y[:2]), np.zeros(2), np.zeros(2),
                                np.array([0.0, force]))
        acc = self.mech.accelerations(y[0], y[1], y[2], y[3], force)
        return DynamicState(t, np.array(y[:2]), np.array(y[2:4]), np.array(acc[:2]),
                            np.array([acc[2], 0.0]))

    def _rk4(self, y, h: float, force: float):
        """(alpha1, alpha2, rates) after a step of length h: RK4 sub-steps <= max_substep."""
        n_sub = max(1, math.ceil(h / self.max_substep - 1e-9))
        for _ in range(n_sub):
            y = self.mech.rk4_step(y, h / n_sub, force)
        return y

    def step(self, s: DynamicState, h: float, force: float, stage: Stage) -> DynamicState:
        if stage == LOCKED:
            return replace(s, t=s.t + h, multipliers=np.array([0.0, force]))
        return self._state(s.t + h, self._rk4((*s.q, *s.qd), h, force), force, stage)

    def advance(self, s, k0, h, n_steps, force, stage, work, lock_loss, states=False):
        """
        Take n_steps steps of ``step`` in one loop (the fast path), rows from the angles.

        Each row holds what a Sample of the rigid state holds (no elastic field: tip
        deflection, strain energy and stresses zero; the acceleration and the sleeve's
        reaction of the closed-form equations at the state), so the per-step Samples and
        stress peaks of the generic path (~0.7 ms a step) are not made; stops before the
        step in which the sleeve reaches the stop, as the compiled engines do.  states: the
        state rows too, in the finite-element coordinates of the mechanism (``fe_state``).
        """
        mech, p = self.mech, self.model.params
        y = (*(float(v) for v in s.q), *(float(v) for v in s.qd))
        height = mech.sleeve_height(y[0], y[1])
        # at rest once locked (qd, qdd zero), the stop holding the sleeve force
        figures = (0.0, 0.0, force, self._residual(*y))
        stop, steps, kept = None, [], []
        for i in range(n_steps):
            if stage == DEFORMING:     # (a grid step's length, as UmbrellaSimulator.step's)
                y1 = self._rk4(y, (k0 + i + 1) * h - (k0 + i) * h, force)
                residual = self._residual(*y1)
                reason = self._check(y1, residual)
                if reason is not None:
                    stop = fault_message((k0 + i) * h, reason)
                    break
                h1 = mech.sleeve_height(y1[0], y1[1])
                if h1 - self.model.y_stop <= 0.0:
                    stop = 'crossing'
                    break
                work += force * (height - h1)
                y, height = y1, h1
                accel, _, reaction = mech.accelerations(*y, force)
                figures = (accel, reaction, 0.0, residual)
            a1, a2, w1, w2 = y
            steps.append((a1, a2, w1, height, p.l1 * math.cos(a1) * w1 + p.l3 * math.cos(a2) * w2,
                          # alpha2's rate as fe_state's, to the bit (model.rigid_velocity)
                          -p.l1 * math.sin(a1) * w1 / (p.l3 * math.sin(a2)),
                          mech.kinetic_energy(a1, a2, w1, w2), work, *figures))
            if states:
                kept.append(self._state_row(a1, w1))
        done = len(steps)
        rows = np.empty((len(STEP_FIELDS), done))
        if done:
            (a1, a2, w1, height_, velocity, w2, kinetic, work_, accel, reaction_x, reaction_y,
             residual) = np.array(steps).T
            columns = dict(
                time=(k0 + np.arange(1, done + 1)) * h, stage=float(stage.code), alpha1=a1,
                alpha1_rate=w1, sleeve_position=height_, sleeve_velocity=velocity,
                sleeve_force=force, kinetic_energy=kinetic, work=work_,
                lock_energy_loss=lock_loss, alpha2=a2, alpha2_rate=w2, alpha1_accel=accel,
                sleeve_reaction_x=reaction_x, sleeve_reaction_y=reaction_y,
                constraint_residual=residual,
                **self._zero_figures())
            for name, values in columns.items():
                rows[_STEP_ROW[name]] = values
            if len(columns) != len(STEP_FIELDS):
                raise RuntimeError('RigidEngine.advance fills ' + ', '.join(
                    sorted(columns)) + f', not every one of {STEP_FIELDS}')
        state_rows = None
        if states:
            state_rows = np.array(kept).T if done else np.zeros((self._state_rows(), 0))
        if not done:
            return s, rows, work, stop, state_rows
        state = (replace(s, t=(k0 + done) * h, multipliers=np.array([0.0, force]))
                 if stage == LOCKED else self._state((k0 + done) * h, y, force, stage))
        return state, rows, work, stop, state_rows

    def _state_rows(self) -> int:
        m = self.model
        return 2 * m.n + 2 * (m.leaf.n_stress_points + m.link.n_stress_points)

    def _state_row(self, alpha1: float, alpha1_rate: float) -> np.ndarray:
        """Return the state row (outputs.StepBlock.states) of the mechanism (fe_state's)."""
        m = self.model
        q = m.rigid_configuration(alpha1)
        (lt, lb), (kt, kb) = m.stresses(q)
        return np.concatenate([q, m.rigid_velocity(q, alpha1_rate), lt, kt, lb, kb])

    def _zero_figures(self) -> dict:
        """Return the step figures of the elastic field, which has none here: zeros."""
        if not hasattr(self, '_zeros'):
            m = self.model
            zero = tuple(np.zeros((2, len(b.stress_x))) for b in (m.leaf, m.link))
            peaks = step_peaks((zero, zero), (zero, zero), 1.0,
                               (m.leaf.stress_x, m.link.stress_x))
            names = ('peak_stress_leaf', 'peak_stress_leaf_x', 'peak_stress_link',
                     'peak_stress_link_x', 'stress_leaf_joint', 'stress_link_mid')
            values = (*peaks, *m.reference_stresses(zero[0][0], zero[1][0]))
            self._zeros = dict(zip(names, (float(v) for v in values)),
                               tip_axial=0.0, tip_transverse=0.0, strain_energy=0.0,
                               damping_dissipation=0.0, axial_stress=0.0)
        return self._zeros

    def _check(self, y, res: float) -> str | None:
        """Why the state y, residual res, cannot be taken (UmbrellaSimulator._checked's rule)."""
        if not all(math.isfinite(v) for v in y):
            return 'the state became non-finite'
        if not res <= DIVERGENCE_RESIDUAL:
            return f'constraint residual {res:.3g} past tolerance {DIVERGENCE_RESIDUAL:g}'
        if y[0] >= ALPHA1_AXLE:
            return AXLE_REASON
        return None

    def _residual(self, a1, a2, w1, w2) -> float:
        p = self.model.params
        return max(abs(p.l1 * math.cos(a1) + p.l3 * math.cos(a2)),
                   abs(p.l1 * math.sin(a1) * w1 + p.l3 * math.sin(a2) * w2))

    def fe_state(self, s: DynamicState):
        m = self.model
        q = m.rigid_configuration(float(s.q[0]))
        qd = m.rigid_velocity(q, float(s.qd[0]))
        qdd = np.zeros(m.n)
        qdd[0] = s.qdd[0]
        qdd[m.i_alpha2] = s.qdd[1]
        return q, qd, qdd

    def kinetic_energy(self, s: DynamicState, stage: Stage) -> float:
        return float(self.mech.kinetic_energy(*s.q, *s.qd))

    def sleeve_reaction(self, s: DynamicState, stage: Stage) -> tuple[float, float]:
        return float(s.multipliers[0]), float(s.multipliers[1])

    def residual(self, s: DynamicState, stage: Stage) -> float:
        return self._residual(*s.q, *s.qd)

    def sleeve_height(self, s: DynamicState) -> float:
        return self.mech.sleeve_height(float(s.q[0]), float(s.q[1]))

    def lock(self, s: DynamicState, force: float):
        before = self.mech.kinetic_energy(*s.q, *s.qd)
        s = DynamicState(s.t, s.q, np.zeros(2), np.zeros(2), np.array([0.0, force]))
        return s, LockEvent(s.t, 'plastic', float(before), 0.0, ())


def event_root(at, h: float, f0: float):
    """
    Return the result of `at` at the root of an event function inside a step of length h.

    at(dt) -> (result, f): the step of length dt from the step's start and the event
    function there (f0 at dt = 0, opposite signs at 0 and h).  Illinois root finding on dt
    to EVENT_TIME_TOLERANCE (or an exact zero); the result of the smallest |f| seen.
    """
    a, fa, b = 0.0, f0, h
    best, fb = at(b)
    f_best = fb
    side = 0
    for _ in range(200):
        if b - a < EVENT_TIME_TOLERANCE or f_best == 0.0:
            break
        c = b - fb * (b - a) / (fb - fa)
        if not a < c < b:
            c = 0.5 * (a + b)
        result, fc = at(c)
        if abs(fc) < abs(f_best):
            best, f_best = result, fc
        if fc > 0.0:
            a, fa = c, fc
            if side == -1:
                fb *= 0.5
            side = -1
        else:
            b, fb = c, fc
            if side == 1:
                fa *= 0.5
            side = 1
    return best
