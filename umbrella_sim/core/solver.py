"""
Solver layer: the stepping simulator (stage 1, lock event, stage 2) and a whole-run helper.

``UmbrellaSimulator`` advances on a fixed grid t_k = k h (h = params.physics_time_step).
The sleeve force is a zero-order hold: the value set with ``set_sleeve_force`` acts from the
start of the next step.  ``step()`` and ``advance_to(t)`` therefore give identical results
however the calls are split.  When the sleeve reaches the stop S inside a step, the crossing
time is root-found by re-taking the step from its start with a shorter length (Illinois
method, |dt| < 1e-12 s), the lock is applied there, and the step is completed under Case 2,
so the grid is kept.
"""
from __future__ import annotations

import abc
from dataclasses import replace
import math
import re
import time as _time
from typing import Callable, Iterable

import numpy as np

from .forcing import ForceSchedule
from .integrators import (ADVANCE_CROSSING, ADVANCE_DIVERGED, ADVANCE_DONE, ALPHA1_AXLE,
                          AXLE_REASON, ConvergenceError, DynamicState, MidpointDAE,
                          newton_tolerance, SAMPLE_VECTOR)
from .model import ConstraintSet, DEFORMING, LOCKED, Stage, UmbrellaModel
from .outputs import (build_frozen, LockEvent, RunResult, Sample, STEP_FIELDS, step_peaks,
                      step_row, StepBlock, SummaryAccumulator)
from .params import SPECS, UmbrellaParams
from .rigid import RigidMechanism

#: residual above which a run is declared diverged (m, m/s)
DIVERGENCE_RESIDUAL = 1e-6
EVENT_TIME_TOLERANCE = 1e-12


def nonlinear_model_needed(p: UmbrellaParams) -> bool:
    """Say whether nonlinear.py steps p (the nonlinear model, or the damped linear one)."""
    return p.model == "flexible-nonlinear" or (p.model == "flexible" and p.damping_ratio > 0.0)


class SimulationDiverged(RuntimeError):
    """The state became non-finite or left the constraint manifold; nothing was advanced."""


class ModelError(ValueError):
    """Valid parameters whose model cannot be built (e.g. a singular mass matrix)."""

    def __init__(self, params: UmbrellaParams, reason: BaseException):
        changed = [f"{name}={getattr(params, name)!r}" for name, spec in SPECS.items()
                   if getattr(params, name) != spec.default]
        super().__init__(
            f"the parameters do not give a model that can be simulated "
            f"({type(reason).__name__}: {reason}); set away from the defaults: "
            + (", ".join(changed) if changed else "none"))


def fault_message(t_good: float, reason: str) -> str:
    """
    Return the text of a solver fault with one time in it: the last good state's.

    reason: what failed (an integrator's own 'at t = ...' is dropped: the failed step is
    the one after t_good, and the recording's fault_time is t_good).
    """
    reason = re.sub(r" at t = \S+ s", "", reason)
    return f"solver failed in the step after t = {t_good:.9g} s: {reason}"


def validate_force(force: float, limit: float | None = None, minimum: float = 0.0) -> float:
    """
    Return F_H as a float, or raise ValueError naming the rule it breaks.

    F_H must be finite, >= minimum (the model's ``sleeve_force_min``: 0 for the thesis's
    push-only sleeve, < 0 for a drive that can hold the sleeve back) and, given the model's
    UmbrellaParams.sleeve_force_limit, at most that (N).  Every command is checked with
    ``command_force`` below, which takes both bounds from the model.
    """
    try:
        f = float(force)
    except (TypeError, ValueError):
        raise ValueError(f"sleeve force {force!r}: not a number") from None
    # the same range as the sleeve_force parameter: one rule (params.REGISTRY)
    SPECS["sleeve_force"].check(f, what="sleeve force F_H")
    if f < minimum:
        raise ValueError(f"sleeve force F_H={f}: must be >= {minimum:g} (sleeve_force_min; "
                         "below 0 only for a drive that can hold the sleeve back)")
    if limit is not None and f > limit:
        raise ValueError(f"sleeve force {f:g} N: above {limit:.6g} N, the axial load the link "
                         "can carry (Euler buckling / squash load)")
    return f


def command_force(force: float, params: UmbrellaParams) -> float:
    """Return a force command as a float if the model accepts it, else raise ValueError."""
    return validate_force(force, params.sleeve_force_limit, params.sleeve_force_min)


# --------------------------------------------------------------------- engines
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

    def phase_correction_energy(self, s: DynamicState, stage: Stage) -> float:
        """Return the integrator's correction term of the balance (J; outputs.Sample), 0 here."""
        return 0.0

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
        copy): integrators.SAMPLE_VECTOR (figures and residual max(|Phi|, |J q'|)), then the
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
                stage: Stage, work: float, lock_loss: float):
        """
        Take up to n_steps grid steps in one call (the fast path).

        Up to n_steps grid steps t_k -> (k + 1) h from s at t = k0 h in one call; stops
        before a step in which the sleeve reaches the stop (stage deploying), and at a
        failure.  Returns None if this engine has no such path, else (state, rows, work,
        stop): rows (len(STEP_FIELDS), steps done; may be the engine's buffer, valid until
        its next call), stop None (all steps done), "crossing", or a failure message.
        """
        return None


class FiniteElementEngine(Engine):
    """Flexible (Case 1 -> Case 2) or rigid-FE (Case 3) model on the midpoint DAE integrator."""

    def __init__(self, params: UmbrellaParams, model: UmbrellaModel):
        self.model = model
        self.rigid = params.model == "rigid-fe"
        self.lock_kind = "plastic" if self.rigid else params.lock
        self.integrator = self._integrator(model)
        self.integrator.tolerance = newton_tolerance(params.physics_time_step)
        if params.phase_correction and self.phase_correctable:   # ModalPhaseCorrection
            self.integrator.correct_stage2_phase(params.physics_time_step)
        self._cs = {stage: ConstraintSet(locked=stage == LOCKED, rigid=self.rigid)
                    for stage in Stage}

    @staticmethod
    def _integrator(model: UmbrellaModel) -> MidpointDAE:
        return MidpointDAE(model)

    @property
    def phase_correctable(self) -> bool:
        """Stage 2 takes ModalPhaseCorrection: its elastic coordinates vibrate (not rigid-FE)."""
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
        if kernel is None or getattr(kernel, "elastic_law", None) is not None:
            return None
        integ = self.integrator
        status, state, dt, its, residual = kernel.find_crossing(
            s, h, force, self._cs[DEFORMING], integ.tolerance, integ.max_iterations,
            DIVERGENCE_RESIDUAL, EVENT_TIME_TOLERANCE)
        integ.iterations += its
        if status == ADVANCE_DIVERGED:
            raise SimulationDiverged(fault_message(s.t, f"constraint residual {residual:.3g} "
                                                        f"past tolerance {DIVERGENCE_RESIDUAL:g}"))
        if status != ADVANCE_DONE:
            raise SimulationDiverged(fault_message(s.t, integ.kernel_error(status, s.t + dt)))
        return state

    def advance(self, s, k0, h, n_steps, force, stage, work, lock_loss):
        kernel = self.integrator.kernel
        if kernel is None:
            return None
        integ, cs = self.integrator, self._cs[stage]
        kernel.load(s, work, lock_loss)     # a no-op when s is the state it returned last
        status, done, its, residual = kernel.advance(
            cs, k0, h, n_steps, force, integ.tolerance, integ.max_iterations,
            DIVERGENCE_RESIDUAL)
        integ.iterations += its
        t = (k0 + done) * h
        if status == ADVANCE_DONE:
            stop = None
        elif status == ADVANCE_CROSSING:
            stop = "crossing"
        elif status == ADVANCE_DIVERGED:
            stop = fault_message(t, f"constraint residual {residual:.3g} past tolerance "
                                    f"{DIVERGENCE_RESIDUAL:g}")
        else:
            stop = fault_message(t, integ.kernel_error(status, t + h))
        state = kernel.state(t, self.model.n_constraints(cs)) if done else s
        return state, kernel.out[:, :done], float(kernel.acc[0]), stop

    def fe_state(self, s: DynamicState):
        return s.q, s.qd, s.qdd

    def kinetic_energy(self, s: DynamicState, stage: Stage) -> float:
        # the step leaves its momentum in the state: T = 1/2 qd . p without re-assembling M
        # (p = (M + D) qd with the stage-2 phase correction, whose 1/2 qd . D qd is its own
        # term: phase_correction_energy)
        if s.momentum is not None:
            pc = self.integrator.stage2_correction(self._cs[stage])
            t = float(0.5 * s.qd @ s.momentum)
            return t if pc is None else t - pc.energy(s.qd)
        return float(self.model.kinetic_energy(s.q, s.qd))

    def strain_energy(self, s: DynamicState, stage: Stage) -> float:
        return self.integrator.strain_energy(s.q, self._cs[stage])

    def phase_correction_energy(self, s: DynamicState, stage: Stage) -> float:
        # the modified modal masses' 1/2 qd . D qd less its value just after the lock: in the
        # energy the integrator keeps, not in T or V (a damped frame at rest keeps it)
        pc = self.integrator.stage2_correction(self._cs[stage])
        return 0.0 if pc is None else pc.energy(s.qd) - pc.lock_energy

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
        if self.lock_kind == "energy":
            qd, free = self._energy_redistribution(s.q, s.qd, cs)
        else:
            qd = self.integrator.project_velocity(s.q, s.qd, cs)
        s = self.integrator.with_constraints(replace(s, qd=qd), force, cs)
        after = m.kinetic_energy(s.q, s.qd) + m.strain_energy(s.q)
        self.integrator.lock_at(s.qd)
        return s, LockEvent(s.t, self.lock_kind, float(before), float(after), free)

    def _energy_redistribution(self, q, qd, cs):
        """
        Redistribute the velocities at the lock, keeping the kinetic energy.

        Thesis 5.2.2 for any mesh: only the rigid velocities (R2x', R2y', alpha1',
        alpha2') and the link's axial velocity at H change; they satisfy J2 qd = 0 (5.36-5.39)
        and keep the kinetic energy (5.35).  Of the two energy roots, the one closest to the
        pre-lock velocities in the mass metric is taken.
        """
        m = self.model
        free = [m.i_alpha1, m.i_r2x, m.i_r2y, m.i_alpha2, m.i_u_sleeve]
        fixed = np.setdiff1d(np.arange(m.n), free)
        jac = m.constraint_jacobian(q, cs)
        a_free = jac[:, free]
        rhs = -jac[:, fixed] @ qd[fixed]
        particular = np.linalg.lstsq(a_free, rhs, rcond=None)[0]
        null = np.linalg.svd(a_free)[2][-1]
        base = qd.copy()
        base[free] = particular
        z = np.zeros(m.n)
        z[free] = null
        mass = m.mass_matrix(q)
        t_target = 0.5 * qd @ mass @ qd
        a = 0.5 * z @ mass @ z
        b = z @ mass @ base
        c = 0.5 * base @ mass @ base - t_target
        disc = b * b - 4 * a * c
        if disc < 0.0:
            raise SimulationDiverged("energy lock impossible: the kinetic energy before the lock "
                                     "is below the least energy compatible with the lock "
                                     f"({c + t_target - b * b / (4 * a):.6g} J > "
                                     f"{t_target:.6g} J)")
        roots = [(-b + sgn * math.sqrt(disc)) / (2 * a) for sgn in (1.0, -1.0)]
        candidates = [base + r * z for r in roots]
        best = min(candidates, key=lambda v: (v - qd) @ mass @ (v - qd))
        labels = m.coordinate_labels()
        return best, tuple(labels[i] for i in free)


class RigidEngine(Engine):
    """Closed-form two-angle model (4.120-4.125), RK4 with projection, sub-stepped."""

    max_substep = 1e-4
    backend = "closed-form rigid (Python)"

    def __init__(self, params: UmbrellaParams, model: UmbrellaModel):
        self.model = model
        self.mech = RigidMechanism(params)
        self.lock_kind = "plastic"

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

    def advance(self, s, k0, h, n_steps, force, stage, work, lock_loss):
        """
        Take n_steps steps of ``step`` in one loop (the fast path), rows from the angles.

        Each row holds what a Sample of the rigid state holds (no elastic field: tip
        deflection, strain energy and stresses zero), so the per-step Samples and stress
        peaks of the generic path (~0.7 ms a step) are not made; stops before the step in
        which the sleeve reaches the stop, as the compiled engines do.
        """
        mech, p = self.mech, self.model.params
        rows = np.empty((len(STEP_FIELDS), n_steps))
        zero_peaks = self._zero_peaks()
        y = (*(float(v) for v in s.q), *(float(v) for v in s.qd))
        height = mech.sleeve_height(y[0], y[1])
        code = float(stage.code)
        stop, done = None, 0
        for i in range(n_steps):
            if stage == DEFORMING:     # (a grid step's length, as UmbrellaSimulator.step's)
                y1 = self._rk4(y, (k0 + i + 1) * h - (k0 + i) * h, force)
                reason = self._check(y1)
                if reason is not None:
                    stop = fault_message((k0 + i) * h, reason)
                    break
                h1 = mech.sleeve_height(y1[0], y1[1])
                if h1 - self.model.y_stop <= 0.0:
                    stop = "crossing"
                    break
                work += force * (height - h1)
                y, height = y1, h1
            a1, a2, w1, w2 = y
            velocity = p.l1 * math.cos(a1) * w1 + p.l3 * math.cos(a2) * w2
            rows[:, i] = ((k0 + i + 1) * h, code, a1, w1, height, velocity, force, 0.0, 0.0,
                          *zero_peaks, mech.kinetic_energy(a1, a2, w1, w2), 0.0, work,
                          lock_loss, 0.0)
            done += 1
        if not done:
            return s, rows[:, :0], work, stop
        state = (replace(s, t=(k0 + done) * h, multipliers=np.array([0.0, force]))
                 if stage == LOCKED else self._state((k0 + done) * h, y, force, stage))
        return state, rows[:, :done], work, stop

    def _zero_peaks(self) -> tuple:
        """Return a step's stress peaks (outputs.step_peaks) with no elastic field: zeros."""
        if not hasattr(self, "_peaks0"):
            m = self.model
            zero = tuple(np.zeros((2, len(b.stress_x))) for b in (m.leaf, m.link))
            self._peaks0 = tuple(float(v) for v in step_peaks(
                (zero, zero), (zero, zero), 1.0, (m.leaf.stress_x, m.link.stress_x)))
        return self._peaks0

    def _check(self, y) -> str | None:
        """Why the state y cannot be taken (UmbrellaSimulator._checked's rule), or None."""
        if not all(math.isfinite(v) for v in y):
            return "the state became non-finite"
        res = self._residual(*y)
        if not res <= DIVERGENCE_RESIDUAL:
            return f"constraint residual {res:.3g} past tolerance {DIVERGENCE_RESIDUAL:g}"
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
        return s, LockEvent(s.t, "plastic", float(before), 0.0, ())


# ------------------------------------------------------------------- simulator
class UmbrellaSimulator:
    """Steps one model in time; see the module docstring for the time grid and the lock."""

    def __init__(self, params: UmbrellaParams):
        self.reset(params)

    # -- lifecycle
    def reset(self, params: UmbrellaParams | None = None) -> None:
        """
        Start again at t = 0 (with params, if given).

        Raises ValueError naming the culprit (ModelError: valid parameters whose model
        cannot be built, e.g. a section so thin that the mass matrix is singular); the
        simulator is then as it was.
        """
        p = params.validated() if params is not None else self.params
        force = command_force(p.sleeve_force, p)
        try:
            if nonlinear_model_needed(p):   # geometrically nonlinear and/or damped beams
                from . import nonlinear
                model, engine = nonlinear.build(p)
            else:
                model = UmbrellaModel(p)
                engine = (RigidEngine if p.model == "rigid" else FiniteElementEngine)(p, model)
            state = engine.initial(force)
        except (ArithmeticError, MemoryError, ValueError) as exc:   # (LinAlgError too)
            raise ModelError(p, exc) from None
        self.params, self.model, self.engine = p, model, engine
        self.h = p.physics_time_step
        self._force = force
        self._k = 0
        self._stage = DEFORMING
        self._state = state
        self._applied_force = self._force
        self._work = 0.0
        self._lock_loss = 0.0
        self.lock_event: LockEvent | None = None
        self._locked_at = None
        self.steps = 0

    # -- inputs
    def set_sleeve_force(self, force: float) -> None:
        """F_H >= 0 (N, along -Y); acts from the start of the next step (zero-order hold)."""
        self._force = command_force(force, self.params)

    @property
    def sleeve_force(self) -> float:
        return self._force

    # -- state
    @property
    def time(self) -> float:
        return self._state.t

    @property
    def stage(self) -> Stage:
        return self._stage

    @property
    def state(self) -> DynamicState:
        return self._state

    # -- stepping
    def step(self, record: bool = True) -> list[Sample]:
        """
        Advance one grid step and return the samples produced.

        Two if the lock happened;
        none with record=False, for callers that sample at their own rate).
        """
        eng, s0, force = self.engine, self._state, self._force
        t_next = (self._k + 1) * self.h
        out: list[Sample] = []
        stage = self._stage
        s1 = self._checked(lambda: eng.step(s0, t_next - s0.t, force, stage), stage)
        work = force * (eng.sleeve_height(s0) - eng.sleeve_height(s1))
        lock_loss = 0.0
        lock_event = None
        if stage == DEFORMING and eng.sleeve_height(s1) - self.model.y_stop <= 0.0:
            s_hit = self._find_lock(s0, t_next - s0.t, force)
            work = force * (eng.sleeve_height(s0) - eng.sleeve_height(s_hit))
            s_locked, lock_event = eng.lock(s_hit, force)
            lock_loss = lock_event.energy_before - lock_event.energy_after
            stage = LOCKED
            locked_at = (s_locked, stage, force, self._work + work, self._lock_loss + lock_loss)
            if record:
                out.append(self._sample(*locked_at))
            remaining = t_next - s_locked.t
            if remaining > EVENT_TIME_TOLERANCE:
                s1 = self._checked(lambda: eng.step(s_locked, remaining, force, LOCKED), LOCKED)
                work += force * (eng.sleeve_height(s_locked) - eng.sleeve_height(s1))
            else:
                s1 = s_locked
        # the grid time exactly, whatever the rounding of t0 + h
        s1 = replace(s1, t=t_next)
        self._commit(s1, stage, force, work, lock_loss, lock_event, 1)
        if lock_event is not None:
            self._locked_at = locked_at
        if record:
            out.append(self.sample())
        return out

    def _commit(self, s1, stage, force, work, lock_loss, lock_event, steps) -> None:
        """Only after everything succeeded: a failure leaves the last good state."""
        self._state, self._stage, self._k = s1, stage, self._k + steps
        self._work += work
        self._lock_loss += lock_loss
        self._applied_force = force
        if lock_event is not None:
            self.lock_event = lock_event
        self.steps += steps

    def advance(self, n_steps: int) -> StepBlock:
        """
        Take n_steps grid steps and return their outputs as a StepBlock.

        Take n_steps grid steps (stopping early only at a fault) and return their outputs,
        one entry per step, with the final Sample and the lock if it happened in the block.

        The engine's compiled path runs the steps in one call each (two around the lock,
        whose step is taken here); engines without one, or UMBRELLA_SIM_KERNEL=numpy, take
        them one by one with outputs from ``sample()`` (the reference path).  n_steps is a
        whole number >= 0 (ValueError otherwise).
        """
        _check_steps(n_steps)
        rows = None
        done = 0
        error = None
        lock_before = self.lock_event
        force = self._force
        while done < n_steps:
            fast = self.engine.advance(self._state, self._k, self.h, n_steps - done, force,
                                       self._stage, self._work, self._lock_loss)
            if fast is not None:
                state, block, work, stop = fast
                k = block.shape[1]
                if k == n_steps:              # the whole block in one call (the usual case)
                    rows = block.copy()
                elif k:
                    if rows is None:
                        rows = np.empty((len(STEP_FIELDS), n_steps))
                    rows[:, done:done + k] = block
                if k:
                    self._commit(state, self._stage, force, work - self._work, 0.0, None, k)
                    done += k
                if stop is None:
                    break
                if stop != "crossing":
                    error = stop
                    break
            start, t_start = self._fibre_stress(), self.time
            try:                          # the lock step, or every step without a fast path
                self.step(record=False)
            except SimulationDiverged as exc:
                error = str(exc)
                break
            if rows is None:
                rows = np.empty((len(STEP_FIELDS), n_steps))
            m = self.model
            rows[:, done] = step_row(self.sample(), step_peaks(
                start, self._fibre_stress(), self.time - t_start,
                (m.leaf.stress_x, m.link.stress_x)))
            done += 1
        lock = self.lock_event if self.lock_event is not lock_before else None
        final = (self._state, self._stage, self._applied_force, self._work, self._lock_loss)
        if rows is None:
            rows = np.empty((len(STEP_FIELDS), 0))
        return StepBlock.from_rows(rows[:, :done].copy() if done < rows.shape[1] else rows,
                                   lambda: self._sample(*final), lock, error)

    def advance_schedule(self, schedule: ForceSchedule, n_steps: int
                         ) -> tuple[StepBlock, list[tuple[float, float]]]:
        """
        Take n_steps steps with F_H from the schedule (forcing.py's one rule).

        Returns the block of those steps (stopped early only at a fault, as ``advance``)
        and the values that took effect in it, [(t, F)], each at the step it acts from.
        """
        _check_steps(n_steps)
        applied: list[tuple[float, float]] = []
        blocks: list[StepBlock] = []
        k_end = self._k + int(n_steps)
        while True:
            f = schedule.force_at(self._k)
            if f != self._force:
                self.set_sleeve_force(f)
                applied.append((self.time, f))
            change = schedule.next_change(self._k)
            n = (k_end if change is None else min(change, k_end)) - self._k
            blocks.append(self.advance(n))
            if blocks[-1].error is not None or self._k >= k_end:
                break
        return StepBlock.concatenate(blocks), applied

    @property
    def step_index(self) -> int:
        """Return the steps taken since t = 0 (the simulator is at t = step_index * h)."""
        return self._k

    def lock_sample(self) -> Sample | None:
        """Return the Sample of the state right after the lock (None before the lock)."""
        return None if self._locked_at is None else self._sample(*self._locked_at)

    def advance_to(self, t: float, record: bool = True) -> list[Sample]:
        """Take every grid step that ends at or before t (ValueError for a t already past)."""
        if not t >= self.time - 1e-12 * max(1.0, abs(t)):     # (NaN too)
            raise ValueError(f"advance_to({t!r}): before the simulator's time "
                             f"{self.time:.9g} s (it only goes forward; reset() starts again)")
        out: list[Sample] = []
        while (self._k + 1) * self.h <= t + 1e-12 * max(1.0, abs(t)):
            out.extend(self.step(record))
        return out

    def _checked(self, fn: Callable[[], DynamicState], stage: Stage) -> DynamicState:
        try:
            s = fn()
        except (ConvergenceError, np.linalg.LinAlgError) as exc:
            raise SimulationDiverged(fault_message(self.time, str(exc))) from None
        if not (np.all(np.isfinite(s.q)) and np.all(np.isfinite(s.qd))):
            raise SimulationDiverged(fault_message(self.time, "the state became non-finite"))
        res = self.engine.residual(s, stage)
        if not res <= DIVERGENCE_RESIDUAL:
            raise SimulationDiverged(fault_message(
                self.time, f"constraint residual {res:.3g} past tolerance "
                           f"{DIVERGENCE_RESIDUAL:g}"))
        if stage == DEFORMING and s.q[0] >= ALPHA1_AXLE:
            raise SimulationDiverged(fault_message(self.time, AXLE_REASON))
        return s

    def _find_lock(self, s0: DynamicState, h: float, force: float) -> DynamicState:
        """
        Find the lock instant inside the step.

        Illinois root-finding of y_H(t0 + dt) = y_S over the step length dt: the sleeve
        reaches the stop on the integrator's own trajectory, to |dt| < 1e-12 s.
        """
        eng, y_stop = self.engine, self.model.y_stop
        fast = eng.find_crossing(s0, h, force)
        if fast is not None:
            return fast

        def at(dt):
            s = self._checked(lambda: eng.step(s0, dt, force, DEFORMING), DEFORMING)
            return s, eng.sleeve_height(s) - y_stop

        a, fa = 0.0, eng.sleeve_height(s0) - y_stop
        b = h
        sb, fb = at(b)
        best, f_best = sb, fb
        side = 0
        for _ in range(200):
            if b - a < EVENT_TIME_TOLERANCE or f_best == 0.0:
                break
            c = b - fb * (b - a) / (fb - fa)
            if not a < c < b:
                c = 0.5 * (a + b)
            sc, fc = at(c)
            if abs(fc) < abs(f_best):
                best, f_best = sc, fc
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

    # -- outputs
    def _fibre_stress(self) -> tuple:
        """Return the fibre stresses and their rates of the current state (step_peaks)."""
        q, qd, _ = self.engine.fe_state(self._state)
        return self.model.stresses(q), self.model.stress_rates(q, qd)

    def sample(self) -> Sample:
        return self._sample(self._state, self._stage, self._applied_force, self._work,
                            self._lock_loss)

    def _sample(self, s: DynamicState, stage: Stage, force: float, work: float,
                lock_loss: float) -> Sample:
        m, eng = self.model, self.engine
        q, qd, qdd = eng.fe_state(s)
        stage = stage if type(stage) is Stage else Stage(stage)
        common = {"time": s.t, "stage": stage, "q": _frozen(q), "qd": _frozen(qd),
                  "alpha1_accel": qdd.item(0), "sleeve_force": force,
                  "multipliers": _frozen(s.multipliers), "work": float(work),
                  "lock_energy_loss": float(lock_loss),
                  "damping_dissipation": float(s.dissipation)}
        vector = eng.sample_outputs(s, stage)
        if vector is not None:
            # compiled (integrators.SAMPLE_VECTOR): the rest in one list and the stresses as
            # views of the vector (read-only, of its own), without a numpy call per figure
            n = len(SAMPLE_VECTOR)
            values = dict(zip(SAMPLE_VECTOR, vector[:n].tolist()))
            values["sleeve_reaction"] = (values.pop("sleeve_reaction_x"),
                                         values.pop("sleeve_reaction_y"))
            stress = vector[n:].reshape(2, -1)
            n_leaf = m.leaf.n_stress_points
            values["leaf_stress"], values["link_stress"] = stress[:, :n_leaf], stress[:, n_leaf:]
            values.update(common)
            return build_frozen(Sample, values)
        (lt, lb), (kt, kb) = m.stresses(q)
        leaf_abs = np.maximum(np.abs(lt), np.abs(lb))
        link_abs = np.maximum(np.abs(kt), np.abs(kb))
        il, ik = int(np.argmax(leaf_abs)), int(np.argmax(link_abs))
        tip_axial, tip_transverse = m.tip_displacement(q)
        joint_stress, mid_link_stress = m.reference_stresses(lt, kt)
        ia = m.i_alpha2
        # every field of Sample in one dict (build_frozen, without a frozen dataclass's
        # per-field setattr)
        return build_frozen(Sample, {
            **common,
            "alpha1": q.item(0), "alpha2": q.item(ia), "alpha1_rate": qd.item(0),
            "alpha2_rate": qd.item(ia),
            "sleeve_position": float(m.sleeve_height(q)),
            "sleeve_velocity": float(m.sleeve_height_gradient(q) @ qd),
            "tip_axial": tip_axial, "tip_transverse": tip_transverse,
            "leaf_stress": _frozen((lt, lb)), "link_stress": _frozen((kt, kb)),
            "peak_stress_leaf": float(leaf_abs[il]),
            "peak_stress_leaf_x": float(m.leaf.stress_x[il]),
            "peak_stress_link": float(link_abs[ik]),
            "peak_stress_link_x": float(m.link.stress_x[ik]),
            "stress_leaf_joint": joint_stress, "stress_link_mid": mid_link_stress,
            "sleeve_reaction": eng.sleeve_reaction(s, stage),
            "kinetic_energy": eng.kinetic_energy(s, stage),
            "strain_energy": eng.strain_energy(s, stage),
            "phase_correction_energy": eng.phase_correction_energy(s, stage),
            "constraint_residual": eng.residual(s, stage)})


def _frozen(a) -> np.ndarray:
    """Return a read-only float array of a: a itself if it is one (the compiled states')."""
    if type(a) is np.ndarray and not a.flags.writeable and a.dtype == np.float64:
        return a
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


def _check_steps(n_steps) -> None:
    if isinstance(n_steps, bool) or not float(n_steps).is_integer() or n_steps < 0:
        raise ValueError(f"n_steps={n_steps!r}: must be a whole number >= 0")


def simulate(params: UmbrellaParams, duration: float,
             force_profile: Iterable[tuple[float, float]] | ForceSchedule | None = None,
             stop_after_lock: float | None = None,
             progress: Callable[[float], None] | None = None, *,
             simulator: UmbrellaSimulator | None = None, output_every: int = 1,
             on_output: Callable[[StepBlock, list], None] | None = None,
             keep_samples: bool = True,
             summary: SummaryAccumulator | None = None) -> RunResult:
    """
    Run a whole simulation: the one offline driver.

    ``umbrella_sim simulate``, ``--mcap`` (recording.record_offline) and ``umbrella_replay
    --resimulate`` all run through here, on ``UmbrellaSimulator.advance_schedule``, as the
    node does one publication period at a time; so they give identical states.

    force_profile: (t, F) pairs or a ForceSchedule: F_H as forcing.py's zero-order hold
    (each value acts from the first step that starts at or after its time).  Every
    output_every steps (and at the end) ``on_output(block, applied)`` gets the StepBlock of
    those steps and the force values that took effect in them; ``result.figures`` are the
    summary figures of every step (outputs.SummaryAccumulator); keep_samples keeps the
    Sample at each of those instants (and right after the lock) in ``result.samples``.
    simulator: step this one (fresh, at t = 0) instead of a new one; summary: accumulate into
    this one (of its first state), which the caller keeps if the run is interrupted.  On a
    diverged run what was computed before the failure is kept and ``result.error`` says why.
    """
    sim = simulator if simulator is not None else UmbrellaSimulator(params)
    if isinstance(force_profile, ForceSchedule):
        schedule = force_profile
    else:
        schedule = ForceSchedule(sim.h, sim.sleeve_force,
                                 sorted(force_profile or [], key=lambda tf: tf[0]),
                                 check=lambda f: command_force(f, sim.params))
    result = RunResult(params=sim.params.as_dict(), q_labels=sim.model.coordinate_labels(),
                       leaf_stress_x=list(sim.model.leaf.stress_x),
                       link_stress_x=list(sim.model.link.stress_x))
    first = sim.sample()
    if keep_samples:
        result.samples.append(first)
    if summary is None:
        summary = SummaryAccumulator(result.params, first, sim.engine.lock_kind)
    every = max(1, int(output_every))
    wall0 = _time.perf_counter()
    k_end = int(round(duration / sim.h))
    next_progress = 0
    while sim.step_index < k_end:
        block, applied = sim.advance_schedule(schedule, min(every, k_end - sim.step_index))
        summary.add(block)
        if keep_samples:
            if block.lock is not None:
                result.samples.append(sim.lock_sample())
            if len(block):
                result.samples.append(block.last)
        if on_output is not None:
            on_output(block, applied)
        if block.error is not None:
            result.error = block.error
            break
        if progress is not None and sim.step_index >= next_progress:
            progress(sim.time)
            next_progress = sim.step_index + max(50, every)
        if (stop_after_lock is not None and sim.lock_event is not None
                and sim.time >= sim.lock_event.time + stop_after_lock):
            break
    result.wall_time = _time.perf_counter() - wall0
    result.steps = sim.steps
    result.lock = sim.lock_event
    result.figures = summary.figures()
    return result
