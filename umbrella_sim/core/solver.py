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
Solver layer: the stepping simulator (stage 1, lock event, stage 2) and a whole-run helper.

``UmbrellaSimulator`` advances on a fixed grid t_k = k h (h = step_rule.physics_step_of(params)).
The sleeve force is a zero-order hold: the value set with ``set_sleeve_force`` acts from the
start of the next step.  ``step()`` and ``advance_to(t)`` therefore give identical results
however the calls are split.  When the sleeve reaches the stop S inside a step, the crossing
time is root-found by re-taking the step from its start with a shorter length (Illinois
method, |dt| < 1e-12 s), the lock is applied there, and the step is completed under Case 2,
so the grid is kept.  Where the step is chosen for the run (step_rule.follows_lock), a lock
whose stage 2 needs a finer step (step_rule.stage2_step_needed: stage-2 tip deflections past
the modes' coupling) makes every stage-2 grid step k equal physics steps
(``stage2_substeps``); the grid, the outputs (one per grid step, the peak stresses over its
physics steps) and the inputs stay on t_k = k h.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from . import nonlinear
from .engines import (DIVERGENCE_RESIDUAL, event_root, EVENT_TIME_TOLERANCE, fault_message,
                      FiniteElementEngine, RigidEngine, SimulationDiverged)
from .forcing import command_force, ForceSchedule
from .kernel import ALPHA1_AXLE, AXLE_REASON, ConvergenceError, DynamicState, SAMPLE_VECTOR
from .model import DEFORMING, LOCKED, Stage, UmbrellaModel
from .outputs import (axial_stress_of, build_frozen, fold_substeps, LockEvent,
                      physics_tips_of, Sample, state_row, STEP_FIELDS, step_peaks, step_row,
                      StepBlock, TIP_ROWS)
from .params import UmbrellaParams
from .registry import SPECS
from .step_rule import physics_step_of, stage2_physics_steps


#: the row of a step's time (StepBlock.rows)
_TIME = STEP_FIELDS.index('time')


def nonlinear_model_needed(p: UmbrellaParams) -> bool:
    """Say whether nonlinear.py steps p (the nonlinear model, or the damped linear one)."""
    return p.model == 'flexible-nonlinear' or (p.model == 'flexible' and p.damping_ratio > 0.0)


class ModelError(ValueError):
    """Valid parameters whose model cannot be built (e.g. a singular mass matrix)."""

    def __init__(self, params: UmbrellaParams, reason: BaseException):
        changed = [f'{name}={getattr(params, name)!r}' for name, spec in SPECS.items()
                   if getattr(params, name) != spec.default]
        super().__init__(
            f'the parameters do not give a model that can be simulated '
            f'({type(reason).__name__}: {reason}); set away from the defaults: '
            + (', '.join(changed) if changed else 'none'))


# ------------------------------------------------------------------- simulator
class UmbrellaSimulator:
    """Steps one model in time; see the module docstring for the time grid and the lock."""

    #: the physics step of a model's parameters (step_rule's rule)
    grid_step = staticmethod(physics_step_of)

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
                model, engine = nonlinear.build(p)
            else:
                model = UmbrellaModel(p)
                engine = (RigidEngine if p.model == 'rigid' else FiniteElementEngine)(p, model)
            state = engine.initial(force)
        except (ArithmeticError, MemoryError, ValueError) as exc:   # (LinAlgError too)
            raise ModelError(p, exc) from None
        self.params, self.model, self.engine = p, model, engine
        self.h = physics_step_of(p)
        self._force = force
        self._k = 0
        self._stage = DEFORMING
        self._state = state
        self._applied_force = self._force
        self._work = 0.0
        self._lock_loss = 0.0
        self.lock_event: LockEvent | None = None
        self._locked_at = None
        self._substep_figures = None     # (stage 2's substeps: peaks, axial stress, tips)
        #: the last grid step's physics steps' (time, tip) where it took them in substeps
        #: (StepBlock.physics_tips), else None
        self._substep_tips = None
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

    @property
    def stage2_substeps(self) -> int:
        """Return the physics steps a stage-2 grid step takes (1 until a lock needs more)."""
        return self.engine.stage2_substeps

    def _substeps(self, stage: Stage) -> int:
        return self.stage2_substeps if stage == LOCKED else 1

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
        s1, self._substep_figures = self._physics_steps(s0, t_next - s0.t, force, stage)
        tips = self._substep_figures and self._substep_figures[2]
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
                s1, after = self._physics_steps(s_locked, remaining, force, LOCKED)
                tips = after and after[2]        # (stage 2's substeps of the step's rest)
                work += force * (eng.sleeve_height(s_locked) - eng.sleeve_height(s1))
            else:
                s1 = s_locked
        # the grid time exactly, whatever the rounding of t0 + h
        s1 = replace(s1, t=t_next)
        if tips is not None:
            tips[0, -1] = t_next
        self._substep_tips = tips
        self._commit(s1, stage, force, work, lock_loss, lock_event, 1)
        if lock_event is not None:
            self._locked_at = locked_at
        if record:
            out.append(self.sample())
        return out

    def _physics_steps(self, s0: DynamicState, dt: float, force: float, stage: Stage
                       ) -> tuple[DynamicState, tuple | None]:
        """
        Return the state dt after s0: one physics step, or stage 2's substeps.

        With substeps, also the largest fibre stress over them and where (step_peaks: leaf,
        x, link, x), the largest axial stress of their states (outputs.fold_substeps' rule)
        and each one's time and tip deflection (StepBlock.physics_tips' rows), else None.
        """
        eng, m = self.engine, self._substeps(stage)
        if m == 1:
            return self._checked(lambda: eng.step(s0, dt, force, stage), stage), None
        n = stage2_physics_steps(dt, self.h, m)
        model = self.model
        xs = (model.leaf.stress_x, model.link.stress_x)
        s, start, peaks, axial = s0, self._fibre_stress_of(s0), None, 0.0
        tips = np.empty((2, n))
        for i in range(n):
            s = self._checked(lambda s=s: eng.step(s, dt / n, force, stage), stage)
            end = self._fibre_stress_of(s)
            step = step_peaks(start, end, dt / n, xs)
            peaks = step if peaks is None else tuple(
                v for body in (0, 2) for v in max(peaks[body:body + 2], step[body:body + 2]))
            axial = max(axial, axial_stress_of(*end[0]))
            tips[:, i] = s.t, model.tip_displacement(eng.fe_state(s)[0])[1]
            start = end
        return s, (peaks, axial, tips)

    def _commit(self, s1, stage, force, work, lock_loss, lock_event, steps) -> None:
        """Only after everything succeeded: a failure leaves the last good state."""
        self._state, self._stage, self._k = s1, stage, self._k + steps
        self._work += work
        self._lock_loss += lock_loss
        self._applied_force = force
        if lock_event is not None:
            self.lock_event = lock_event
        self.steps += steps

    def advance(self, n_steps: int, states: bool = False, until_lock: bool = False
                ) -> StepBlock:
        """
        Take n_steps grid steps and return their outputs as a StepBlock.

        Take n_steps grid steps (stopping early only at a fault) and return their outputs,
        one entry per step, with the final Sample and the lock if it happened in the block;
        with states, also the state at the end of every step (``StepBlock.states``: q, q' and
        the fibre stresses); with until_lock, the block ends with the step the lock happens
        in (the lock is an event its consumers act on: a run that stops a time after it).

        The engine's compiled path runs the steps in one call each (two around the lock,
        whose step is taken here); engines without one, or UMBRELLA_SIM_KERNEL=numpy, take
        them one by one with outputs from ``sample()`` (the reference path).  n_steps is a
        whole number >= 0 (ValueError otherwise).
        """
        _check_steps(n_steps)
        parts = []      # (rows, state rows or None, physics_tips or None) of the steps taken
        done = 0
        error = None
        lock_before = self.lock_event
        force = self._force
        while done < n_steps:
            m = self._substeps(self._stage)
            fast = self.engine.advance(self._state, self._k * m, self.h / m,
                                       (n_steps - done) * m, force, self._stage, self._work,
                                       self._lock_loss, states)
            if fast is not None:
                state, block, work, stop, block_states = fast
                tips = None
                if m > 1 and block.shape[1]:     # (copies: the engine's buffers are kept)
                    whole = block.shape[1] // m          # (a fault may end one early)
                    tips = block[TIP_ROWS]               # (every physics step's)
                    block, block_states = fold_substeps(block, block_states, m)
                    block[_TIME, :whole] = tips[0, m - 1::m][:whole] = (
                        self._k + 1 + np.arange(whole)) * self.h
                k = block.shape[1]
                if k:      # (the engine's buffers: copied before its next call)
                    parts.append((block.copy() if m == 1 else block,
                                  block_states.copy() if states and m == 1 else block_states,
                                  tips))
                    self._commit(state, self._stage, force, work - self._work, 0.0, None, k)
                    done += k
                if stop is None:
                    break
                if stop != 'crossing':
                    error = stop
                    break
            start, t_start = self._fibre_stress(), self.time
            try:                          # the lock step, or every step without a fast path
                self.step(record=False)
            except SimulationDiverged as exc:
                error = str(exc)
                break
            m, sample = self.model, self.sample()
            peaks, axial, _ = self._substep_figures or (None, None, None)
            row = step_row(sample, peaks or step_peaks(
                start, self._fibre_stress(), self.time - t_start,
                (m.leaf.stress_x, m.link.stress_x)), axial)
            parts.append((np.array(row)[:, None], state_row(sample)[:, None] if states else None,
                          self._substep_tips))
            done += 1
            if until_lock and self.lock_event is not lock_before:
                break
        lock = self.lock_event if self.lock_event is not lock_before else None
        final = (self._state, self._stage, self._applied_force, self._work, self._lock_loss)
        tips = physics_tips_of([(r, t) for r, _, t in parts])
        if len(parts) == 1:               # (the usual block: one compiled call)
            rows, kept, _ = parts[0]
        elif parts:
            rows = np.hstack([r for r, _, _ in parts])
            kept = np.hstack([k for _, k, _ in parts]) if states else None
        else:
            m = self.model
            rows = np.empty((len(STEP_FIELDS), 0))
            kept = np.empty((2 * m.n + 2 * (m.leaf.n_stress_points + m.link.n_stress_points),
                             0)) if states else None
        return StepBlock.from_rows(rows, lambda: self._sample(*final), lock, error, kept, tips)

    def advance_schedule(self, schedule: ForceSchedule, n_steps: int, states: bool = False,
                         until_lock: bool = False
                         ) -> tuple[StepBlock, list[tuple[float, float]]]:
        """
        Take n_steps steps with F_H from the schedule (forcing.py's one rule).

        Returns the block of those steps (stopped early at a fault, and with until_lock at
        the lock, as ``advance``) and the values that took effect in it, [(t, F)], each at
        the step it acts from.
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
            blocks.append(self.advance(n, states, until_lock))
            if (blocks[-1].error is not None or self._k >= k_end
                    or until_lock and blocks[-1].lock is not None):
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
                             f'{self.time:.9g} s (it only goes forward; reset() starts again)')
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
            raise SimulationDiverged(fault_message(self.time, 'the state became non-finite'))
        res = self.engine.residual(s, stage)
        if not res <= DIVERGENCE_RESIDUAL:
            raise SimulationDiverged(fault_message(
                self.time, f'constraint residual {res:.3g} past tolerance '
                           f'{DIVERGENCE_RESIDUAL:g}'))
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

        return event_root(at, h, eng.sleeve_height(s0) - y_stop)

    # -- outputs
    def _fibre_stress(self) -> tuple:
        """Return the fibre stresses and their rates of the current state (step_peaks)."""
        return self._fibre_stress_of(self._state)

    def _fibre_stress_of(self, s: DynamicState) -> tuple:
        q, qd, _ = self.engine.fe_state(s)
        return self.model.stresses(q), self.model.stress_rates(q, qd)

    def sample(self) -> Sample:
        return self._sample(self._state, self._stage, self._applied_force, self._work,
                            self._lock_loss)

    def _sample(self, s: DynamicState, stage: Stage, force: float, work: float,
                lock_loss: float) -> Sample:
        m, eng = self.model, self.engine
        q, qd, qdd = eng.fe_state(s)
        stage = stage if type(stage) is Stage else Stage(stage)
        common = {'time': s.t, 'stage': stage, 'q': _frozen(q), 'qd': _frozen(qd),
                  'alpha1_accel': qdd.item(0), 'sleeve_force': force,
                  'multipliers': _frozen(s.multipliers), 'work': float(work),
                  'lock_energy_loss': float(lock_loss),
                  'damping_dissipation': float(s.dissipation)}
        vector = eng.sample_outputs(s, stage)
        if vector is not None:
            # compiled (integrators.SAMPLE_VECTOR): the rest in one list and the stresses as
            # views of the vector (read-only, of its own), without a numpy call per figure
            n = len(SAMPLE_VECTOR)
            values = dict(zip(SAMPLE_VECTOR, vector[:n].tolist()))
            values['sleeve_reaction'] = (values.pop('sleeve_reaction_x'),
                                         values.pop('sleeve_reaction_y'))
            stress = vector[n:].reshape(2, -1)
            n_leaf = m.leaf.n_stress_points
            values['leaf_stress'], values['link_stress'] = stress[:, :n_leaf], stress[:, n_leaf:]
            values['axial_stress'] = axial_stress_of(values['leaf_stress'],
                                                     values['link_stress'])
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
            'alpha1': q.item(0), 'alpha2': q.item(ia), 'alpha1_rate': qd.item(0),
            'alpha2_rate': qd.item(ia),
            'sleeve_position': float(m.sleeve_height(q)),
            'sleeve_velocity': float(m.sleeve_height_gradient(q) @ qd),
            'tip_axial': tip_axial, 'tip_transverse': tip_transverse,
            'leaf_stress': _frozen((lt, lb)), 'link_stress': _frozen((kt, kb)),
            'axial_stress': axial_stress_of((lt, lb), (kt, kb)),
            'peak_stress_leaf': float(leaf_abs[il]),
            'peak_stress_leaf_x': float(m.leaf.stress_x[il]),
            'peak_stress_link': float(link_abs[ik]),
            'peak_stress_link_x': float(m.link.stress_x[ik]),
            'stress_leaf_joint': joint_stress, 'stress_link_mid': mid_link_stress,
            'sleeve_reaction': eng.sleeve_reaction(s, stage),
            'kinetic_energy': eng.kinetic_energy(s, stage),
            'strain_energy': eng.strain_energy(s, stage),
            'constraint_residual': eng.residual(s, stage)})


def _frozen(a) -> np.ndarray:
    """Return a read-only float array of a: a itself if it is one (the compiled states')."""
    if type(a) is np.ndarray and not a.flags.writeable and a.dtype == np.float64:
        return a
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


def _check_steps(n_steps) -> None:
    if isinstance(n_steps, bool) or not float(n_steps).is_integer() or n_steps < 0:
        raise ValueError(f'n_steps={n_steps!r}: must be a whole number >= 0')
