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

What it hands on (blocks3d.py): ``Sample3D``, one instant's figures, per rib where the rib
has its own (arrays of N), and ``StepBlock3D``, the rows of a chunk's steps; its summary
(summary3d.py): ``Summary3D``, the run's figures from every step.  ``sleeve_force`` is per
rib, as the parameter (the sleeve is pushed with N times it), so that N identical ribs are
the planar model; the figures' ``sleeve_force`` is the whole sleeve's.
"""
from __future__ import annotations

from .blocks3d import RibPeaks, Sample3D, StepBlock3D
from .params3d import UmbrellaRibsParams
from .simulator3d import SimulationFailed, UmbrellaSimulator3D
from .summary3d import Summary3D
from ..forcing import command_force
from ..model import Stage
from ..outputs import LockEvent

#: steps of a chunk: a numpy step of the umbrella costs 2 to 3 ms at 3 to 6 ribs (one element
#: a segment; 6 to 9 ms with a moving base), so a chunk stays near the planar rule's ~10 ms
#: (driver.CHUNK_WORK); the compiled step ~0.05 ms at 6 ribs (fixed hub; 0.13 to 0.16 ms with
#: a moving base): COMPILED_CHUNK_STEPS
CHUNK_STEPS = 4
COMPILED_CHUNK_STEPS = 64


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
        self._lock_event: LockEvent | None = None      # (lock_event, once it happened)
        # the record's row of t = 0 is the initial sample: the blocks hold the steps' rows
        self._current = Sample3D.of_row(self.record.take(), -1)

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
        event = self._lock_event
        if event is None and self.record.lock_events:      # (made once: it never changes)
            t, before, after = self.record.lock_events[0]    # (judged at the lock: its step)
            event = self._lock_event = LockEvent(t, self.params.lock_rule, before, after,
                                                 stage2_resolution=self.stage2_resolution)
        return event

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
        peaks = self.record.taken_peaks
        if rows:
            self._current = Sample3D.of_row(rows, -1)
        lock = self.lock_event if self.locked and not locked_before else None
        return StepBlock3D(rows, self._current, lock, error,
                           None if peaks is None else RibPeaks(*peaks),
                           self.record.taken_tips), applied

    # ------------------------------------------------------------------- outputs
    def sample(self) -> Sample3D:
        return self._current

    def lock_sample(self) -> Sample3D | None:
        """Return the Sample3D right after the lock, at its instant (None before the lock)."""
        if self.lock_state is None:
            return None
        s, hit, (work, friction, drive, damping) = self.lock_state
        return Sample3D.of_row(self.record.row(
            s, True, self.force, self.lock_loss,
            (work + hit.force, friction + hit.friction, drive + hit.drive,
             damping + hit.damping)))

    def new_summary(self, initial: Sample3D) -> 'Summary3D':
        return Summary3D(self, initial)
