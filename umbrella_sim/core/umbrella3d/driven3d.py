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
The umbrella as the run driver steps it: the planar simulator's surface, per-rib figures.

``RunDriver`` (core/driver.py) is the one loop of every consumer.  ``DrivenSimulator3D`` is
``UmbrellaSimulator3D`` with the surface the driver consumes from the planar
``UmbrellaSimulator``: ``advance_schedule`` (the steps with F from a ``ForceSchedule``,
stopped at the lock or a fault, as a ``StepBlock3D``), ``sample``, ``lock_sample``,
``step_index``, ``stage``, ``lock_event``, ``steps``, ``engine`` (backend, lock kind) and
``new_summary``.  The steps are the simulator's own ``step`` and their figures its
``Record3D`` rows, taken from the record a chunk at a time (a run's memory stays bounded).

``Sample3D`` is one instant's figures, per rib where the rib has its own (arrays of N);
``StepBlock3D`` the rows of a chunk's steps; ``Summary3D`` the run's figures from every
step: each rib's deployment instant and the lag of the latest, the largest out-of-plane tip,
each rib's peak of every stress component (where, when), the energy balance with the
hinges' friction work, the bus state of a moving base.  ``sleeve_force`` is per rib, as the
parameter (the sleeve is pushed with N times it), so that N identical ribs are the planar
model; the figures' ``sleeve_force`` is the whole sleeve's.
"""
from __future__ import annotations

import numpy as np

from .outputs3d import (BODIES, deployment_spread, energy_balance3d, first_reach,
                        largest_out_of_plane_tip, STRESS_NAMES)
from .params3d import UmbrellaRibsParams
from .simulator3d import SimulationFailed, UmbrellaSimulator3D
from ..forcing import command_force
from ..model import Stage
from ..outputs import LockEvent
from ..summary import (deploy_start, ENERGY_SCALE_FLOOR, validity_warnings)

#: steps of a chunk: a numpy step of the umbrella costs 2 to 3 ms at 3 to 6 ribs (one element
#: a segment), so a chunk stays near the planar rule's ~10 ms (driver.CHUNK_WORK); the
#: compiled step (fixed hub) ~0.1 ms at 6 ribs: COMPILED_CHUNK_STEPS
CHUNK_STEPS = 4
COMPILED_CHUNK_STEPS = 64


class Sample3D:
    """
    The umbrella's figures at one instant (read-only): Record3D's row names as attributes.

    time, stage (model.Stage), sleeve_position, sleeve_velocity, sleeve_force (the whole
    sleeve's, N), alpha1, alpha2, alpha1_rate, alpha2_rate (per rib, rad, rad/s), tip (ribs,
    3: u, v, w of G in the leaf frame, m), kinetic_energy, strain_energy, work, friction_work
    (per rib), drive_work, lock_energy_loss (J), holding_torque, stuck (per rib),
    stop_reaction, stress_<component> (per rib, Pa) and stress_<component>_at (ribs, 2: body
    0 leaf / 1 link, x along it), and with a moving base bus_q, bus_v (and the momenta of a
    free bus).
    """

    __slots__ = ('_values',)

    def __init__(self, values: dict):
        object.__setattr__(self, '_values', values)

    def __getattr__(self, name: str):
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name, value):
        raise AttributeError(f'Sample3D is read-only (cannot set {name!r})')

    def __getitem__(self, name: str):
        """Return a figure by name, as a Record3D row holds it (energy_balance3d)."""
        return self._values[name]

    def fields(self) -> dict:
        """Return every figure by name (a copy of the mapping; the arrays are shared)."""
        return dict(self._values)

    @classmethod
    def of_row(cls, row: dict) -> 'Sample3D':
        """Return the sample of a Record3D row (its 'locked' flag as the stage)."""
        values = dict(row)
        values['stage'] = Stage.LOCKED if values.pop('locked') else Stage.DEPLOYING
        return cls(values)

    def with_peaks(self, hold: dict) -> 'Sample3D':
        """Return this sample with each rib's stress figures the held ones (merge_peaks)."""
        values = dict(self._values)
        for name, (top, at, _) in hold.items():
            values[f'stress_{name}'], values[f'stress_{name}_at'] = top, at
        return Sample3D(values)


class StepBlock3D:
    """
    The steps of one ``advance_schedule``: Record3D's rows (steps first), as a StepBlock.

    ``last`` is the Sample3D of the final state, ``lock`` the LockEvent if the lock happened
    in these steps, ``error`` the fault that ended them early; ``states`` is None (the
    umbrella's state rows are not offered).
    """

    states = None

    def __init__(self, rows: dict, last: Sample3D, lock: LockEvent | None = None,
                 error: str | None = None):
        self.rows, self.lock, self.error = rows, lock, error
        self._last = last
        self._peaks = None

    def __len__(self) -> int:
        return len(self.rows['time']) if self.rows else 0

    @property
    def time(self) -> np.ndarray:
        return self.rows['time'] if self.rows else np.zeros(0)

    @property
    def last(self) -> Sample3D:
        return self._last

    @property
    def peaks(self) -> dict:
        """
        Return {component: (each rib's largest |value| over the steps, where, when)}.

        where: (ribs, 2), body code and x (Sample3D); when: (ribs,) s; the first step holding
        the largest value.  {} for a block without steps.
        """
        if self._peaks is None:
            out = {}
            if len(self):
                t, ribs = self.rows['time'], None
                for name in STRESS_NAMES:
                    values = self.rows[f'stress_{name}']
                    i = values.argmax(0)
                    ribs = np.arange(values.shape[1]) if ribs is None else ribs
                    out[name] = (values[i, ribs], self.rows[f'stress_{name}_at'][i, ribs], t[i])
            self._peaks = out
        return self._peaks

    def merge_peaks(self, hold: dict) -> dict:
        """Return the held peaks (peaks' form) with this block's larger ones, rib by rib."""
        if not hold:
            return dict(self.peaks)
        return {name: _larger(hold[name], peak) for name, peak in self.peaks.items()} or hold


def _larger(held: tuple, new: tuple) -> tuple:
    """Return, rib by rib, the larger of two (value, where, when) peaks (held on a tie)."""
    better = new[0] > held[0]
    return (np.where(better, new[0], held[0]), np.where(better[:, None], new[1], held[1]),
            np.where(better, new[2], held[2]))


class Engine3D:
    """What the driver and its consumers read of an engine: its lock kind and backend."""

    def __init__(self, lock_kind: str, backend: str):
        self.lock_kind, self.backend = lock_kind, backend


class DrivenSimulator3D(UmbrellaSimulator3D):
    """UmbrellaSimulator3D with the run driver's surface; see the module docstring."""

    def __init__(self, params: UmbrellaRibsParams):
        super().__init__(params)
        compiled = self.integrator.compiled is not None
        self.engine = Engine3D(self.params.lock_rule, 'compiled' if compiled else 'numpy')
        self.chunk_steps = COMPILED_CHUNK_STEPS if compiled else CHUNK_STEPS
        self._force_per_rib = command_force(self.params.planar.sleeve_force, self.params)
        # the record's row of t = 0 is the initial sample: the blocks hold the steps' rows
        self._current = Sample3D.of_row({k: v[-1] for k, v in self.record.take().items()})

    # ------------------------------------------------------------------- inputs
    @property
    def sleeve_force(self) -> float:
        """Return F (N per rib) acting now."""
        return self._force_per_rib

    def set_sleeve_force(self, force: float) -> None:
        """F >= 0 per rib (the sleeve takes N F along -Y), from the next step on."""
        self._force_per_rib = command_force(force, self.params)
        self.force = self._force_per_rib * self.model.n_ribs

    # ------------------------------------------------------------------- state
    @property
    def step_index(self) -> int:
        return self.k

    @property
    def steps(self) -> int:
        return self.k

    @property
    def stage(self) -> Stage:
        return Stage.LOCKED if self.locked else Stage.DEPLOYING

    @property
    def lock_event(self) -> LockEvent | None:
        if not self.record.lock_events:
            return None
        t, before, after = self.record.lock_events[0]
        return LockEvent(t, self.params.lock_rule, before, after)

    # ------------------------------------------------------------------- stepping
    def advance_schedule(self, schedule, n_steps: int, states: bool = False,
                         until_lock: bool = False) -> tuple[StepBlock3D, list]:
        """
        Take n_steps steps with F from the schedule; return their block and the forces applied.

        As the planar simulator's: each value of the schedule acts from its step (applied:
        [(t, F)] at the step it acts from); the block ends early at a fault (``error``, the
        state the last good step) and, with until_lock, with the step the lock happens in.
        states: refused (no state rows; ValueError).
        """
        if states:
            raise ValueError('the umbrella of N ribs offers no state rows (states=True)')
        applied, error = [], None
        locked_before = self.locked
        k_end = self.k + int(n_steps)
        while self.k < k_end:
            f = schedule.force_at(self.k)
            if f != self._force_per_rib:
                self.set_sleeve_force(f)
                applied.append((self.time, f))
            change = schedule.next_change(self.k)
            try:       # (compiled: in runs of steps; the lock's step taken here)
                self.advance((k_end if change is None else min(change, k_end)) - self.k,
                             stop_at_lock=until_lock and not self.locked)
            except SimulationFailed as exc:
                error = str(exc)
                break
            if until_lock and self.locked and not locked_before:
                break
        rows = self.record.take()
        if rows:
            self._current = Sample3D.of_row({name: v[-1] for name, v in rows.items()})
        lock = self.lock_event if self.locked and not locked_before else None
        return StepBlock3D(rows, self._current, lock, error), applied

    # ------------------------------------------------------------------- outputs
    def sample(self) -> Sample3D:
        return self._current

    def lock_sample(self) -> Sample3D | None:
        """Return the Sample3D right after the lock, at its instant (None before the lock)."""
        if self.lock_state is None:
            return None
        s, hit, (work, friction, drive) = self.lock_state
        return Sample3D.of_row(self.record.row(
            s, True, self.force, self.lock_loss,
            (work + hit.force, friction + hit.friction, drive + hit.drive)))

    def new_summary(self, initial: Sample3D) -> 'Summary3D':
        return Summary3D(self, initial)


class Summary3D:
    """
    The umbrella run's figures from every step (StepBlock3D), as SummaryAccumulator's.

    Record3D.summary's figures (each rib's deployment instant and the lag of the latest,
    the largest out-of-plane tip, each rib's peak stresses, the energy balance with friction
    work) for a run taken a chunk at a time, plus the lock and the bus state of a moving base.
    """

    def __init__(self, sim: DrivenSimulator3D, initial: Sample3D):
        self.sim = sim
        m = sim.model
        self.lock_kind = sim.engine.lock_kind
        self.lock: LockEvent | None = None
        self.error: str | None = None
        self.steps = 0
        self.final_time = float(initial.time)
        self._e0 = float(initial.kinetic_energy + initial.strain_energy)
        self._scale = max(abs(self._e0), ENERGY_SCALE_FLOOR)
        self._balance = 0.0
        self._last = (initial.time, np.array(initial.alpha1))
        self._deployed = np.array([first_reach(np.array([initial.time]),
                                               np.array([initial.alpha1[k] - m.alpha_deployed[k]]))
                                   for k in range(m.n_ribs)])
        self._oop = largest_out_of_plane_tip(np.array([initial.time]), initial.tip[None])
        self._in_plane = np.abs(initial.tip[:, 1])
        t0 = np.full(m.n_ribs, float(initial.time))
        self._peaks = {name: (getattr(initial, f'stress_{name}'),
                              getattr(initial, f'stress_{name}_at'), t0)
                       for name in STRESS_NAMES}
        self._final = initial
        self._start = deploy_start(float(sim.params.planar.v0), ())
        self._warned: set = set()

    def add(self, block: StepBlock3D) -> None:
        """Take the steps of one block."""
        if block.lock is not None and self.lock is None:
            self.lock = block.lock
        if block.error is not None:
            self.error = block.error
        if not len(block):
            return
        m, rows = self.sim.model, block.rows
        t = rows['time']
        if self._start is None:
            self._start = deploy_start(0.0, zip([self.final_time, *t[:-1].tolist()],
                                                rows['sleeve_force'].tolist()))
        t_before, alpha_before = self._last
        for k in np.nonzero(np.isnan(self._deployed))[0]:
            self._deployed[k] = first_reach(t, rows['alpha1'][:, k] - m.alpha_deployed[k],
                                            (t_before, alpha_before[k] - m.alpha_deployed[k]))
        self._last = (float(t[-1]), rows['alpha1'][-1])
        energy = rows['kinetic_energy'] + rows['strain_energy']
        self._scale = max(self._scale, float(np.abs(energy).max()))
        self._balance = max(self._balance,
                            float(np.abs(energy_balance3d(rows, self._e0)).max()))
        oop = largest_out_of_plane_tip(t, rows['tip'])
        if oop[0] > self._oop[0]:
            self._oop = oop
        self._in_plane = np.maximum(self._in_plane, np.abs(rows['tip'][:, :, 1]).max(0))
        self._peaks = block.merge_peaks(self._peaks)
        self.steps += len(block)
        self.final_time = float(t[-1])
        self._final = block.last

    @property
    def energy_drift(self) -> float:
        return self._balance / self._scale

    def figures(self) -> dict:
        """Return the run's figures so far, JSON-ready (lists per rib, ribs numbered from 0)."""
        start = self._start if self._start is not None else 0.0
        out = {'ribs': self.sim.model.n_ribs,
               'lock_time': self.lock.time if self.lock else None,
               'deploy_time': self.lock.time - start if self.lock else None,
               'deploy_start': self._start,
               **deployment_spread(self._deployed),
               'max_out_of_plane_tip': self._oop[0],
               'max_out_of_plane_tip_rib': self._oop[1],
               'max_out_of_plane_tip_time': self._oop[2],
               'max_in_plane_tip': self._in_plane.tolist(),
               'energy_balance_residual': self._balance,
               'energy_scale': self._scale,
               'energy_drift': self.energy_drift,
               'friction_work': np.asarray(self._final.friction_work).tolist(),
               'drive_work': float(self._final.drive_work),
               'lock_energy_loss': float(self._final.lock_energy_loss),
               'peak_stress': {name: {'value': top.tolist(),
                                      'body': [BODIES[int(b)] for b in at[:, 0]],
                                      'x': at[:, 1].tolist(), 'time': when.tolist()}
                               for name, (top, at, when) in self._peaks.items()},
               'final_time': self.final_time, 'steps': self.steps}
        if self.lock:
            out.update(lock=self.lock.kind, lock_energy_before=self.lock.energy_before,
                       lock_energy_after=self.lock.energy_after)
        for name in ('bus_q', 'bus_v', 'linear_momentum', 'angular_momentum'):
            value = getattr(self._final, name, None)
            if value is not None:
                out[name] = np.asarray(value).tolist()
        out['warnings'] = self.warnings()
        if self.error:
            out['error'] = self.error
        return out

    def warnings(self) -> list[str]:
        """Return the validity warnings: summary's one rule, on the worst rib's figures."""
        return validity_warnings(self.sim.params.planar.as_dict(), self.lock_kind,
                                 float(self._peaks['von_mises'][0].max()),
                                 float(self._in_plane.max()), locked=self.lock is not None,
                                 energy_drift=self.energy_drift)

    def new_warnings(self) -> list[str]:
        """Return the warnings not returned by an earlier call (a log line each, once)."""
        fresh = [w for w in self.warnings() if w.split(':')[0] not in self._warned]
        self._warned.update(w.split(':')[0] for w in fresh)
        return fresh
