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
The run driver: one simulation advanced a bounded chunk of steps at a time.

Every consumer of a run goes through ``RunDriver``: the live node, the offline recorder
(``umbrella_sim simulate --mcap``), ``umbrella_sim simulate`` itself, ``umbrella_replay
--resimulate``, ``umbrella_compare --physics-rate``, the sweep and the deploy controller's
offline loop.  It owns what they all need and which used to be written once each:

* the time grid: the physics step, shortened when a publication rate is given to the
  largest one that divides the publication period (``params.physics_step``), so that
  publications fall on steps;
* the sleeve force: one ``ForceSchedule`` (forcing.py's zero-order hold), fed by a profile
  or by live commands (``command``), each value acting from the first step at or after its
  instant;
* the steps: ``advance`` runs them in the compiled loop in chunks of at most
  ``chunk_steps`` and never past the next publication instant, so that memory and the time
  between two returns are bounded whatever the steps of a publication period;
* what the steps give: every chunk goes to the run's ``SummaryAccumulator`` (the figures of
  every physics step) and to the peak-hold of the next publication, and comes back as a
  ``Chunk`` with the force values that took effect, the lock and the fault;
* publications: ``publication()`` is the Sample a publication at the current instant
  carries (the state, with the peak stresses held over every step since the last one).

``run`` is the loop itself, for the offline consumers: to a duration, or a time after the
lock, or until asked to stop, with callbacks for each chunk and each publication.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import time as _time
from typing import Callable, Iterable

from .forcing import command_force, ForceSchedule
from .outputs import LockEvent, Sample, StepBlock
from .params import physics_step, UmbrellaParams
from .solver import UmbrellaSimulator
from .step_rule import follows_lock
from .summary import RunResult, SummaryAccumulator
from .umbrella3d.driven3d import DrivenSimulator3D
from .umbrella3d.params3d import UmbrellaRibsParams

#: the work of one chunk, in coordinate-steps of the linear model (a nonlinear step counts
#: NONLINEAR_WEIGHT times): ~10 ms of compiled stepping on this project's reference machine
#: at any mesh (0.2 us per coordinate and step), so that a chunk's memory is bounded and a
#: node between two chunks answers its services promptly; deterministic (not timed), so
#: that a run's chunks are the same on any machine
CHUNK_WORK = 50_000
NONLINEAR_WEIGHT = 10
#: chunk length bounds (steps)
MIN_CHUNK_STEPS, MAX_CHUNK_STEPS = 8, 4096


@dataclass(frozen=True)
class Chunk:
    """What one ``RunDriver.advance`` did."""

    block: StepBlock                        # the steps taken, one row each (may be none)
    applied: tuple                          # ((t, F), ...): force values that took effect
    lock: LockEvent | None                  # the lock, if it happened in these steps
    error: str | None                       # the fault that ended them early, if any
    at_publication: bool                    # the run stands at a publication instant
    lock_sample: Sample | None = None       # the state right after the lock, at its instant

    @property
    def end_time(self) -> float:
        return float(self.block.time[-1]) if len(self.block) else math.nan


def simulator_class(params) -> type:
    """
    Return the simulator of these parameters: the planar model's, or the umbrella's.

    UmbrellaParams: UmbrellaSimulator (the thesis's planar rib, every planar model);
    UmbrellaRibsParams: the umbrella of N ribs in 3D (umbrella3d.driven3d).
    """
    if isinstance(params, UmbrellaRibsParams):
        return DrivenSimulator3D
    return UmbrellaSimulator


def chunk_steps_for(params: UmbrellaParams, coordinates: int) -> int:
    """Return the steps of a chunk for a model of that many coordinates (CHUNK_WORK)."""
    weight = NONLINEAR_WEIGHT if params.model == 'flexible-nonlinear' else 1
    return max(MIN_CHUNK_STEPS, min(MAX_CHUNK_STEPS, CHUNK_WORK // (coordinates * weight)))


class RunDriver:
    """
    One run: the simulator, its force schedule, its publication grid and its summary.

    publish_rate (Hz): publications at that rate of sim time, the physics step shortened to
    divide their period; or period_steps: a publication every that many steps (the step
    unchanged); neither: no publications (``advance`` only chunks).  force_profile: (t, F)
    pairs (or a ForceSchedule on the driver's step) giving F_H; live commands (``command``)
    add to it.  Raises ValueError (a ModelError names the parameters) before any step.
    """

    def __init__(self, params: UmbrellaParams, publish_rate: float | None = None, *,
                 period_steps: int | None = None,
                 force_profile: Iterable[tuple[float, float]] | ForceSchedule | None = None,
                 chunk_steps: int | None = None):
        simulator = simulator_class(params)
        if publish_rate is not None:
            step = physics_step(simulator.grid_step(params), publish_rate)
            period_steps = round((1.0 / publish_rate) / step)
            params = params.with_physics_step(step, follows_lock(params))
        elif period_steps is not None and not (isinstance(period_steps, int)
                                               and period_steps >= 1):
            raise ValueError(f'period_steps={period_steps!r}: must be a whole number >= 1')
        self.publish_rate = publish_rate
        self.period_steps = period_steps
        self.sim = sim = simulator(params)
        self.params = sim.params
        self.step = sim.h
        if isinstance(force_profile, ForceSchedule):
            self.schedule = force_profile
        else:
            self.schedule = ForceSchedule(
                self.step, sim.sleeve_force, sorted(force_profile or [], key=lambda tf: tf[0]),
                check=lambda f: command_force(f, sim.params))
        self.states = False            # chunks with the state rows of their steps
        first = sim.sample()
        self.initial = first
        if simulator is UmbrellaSimulator:
            self.chunk_steps = chunk_steps or chunk_steps_for(self.params, sim.model.n)
            self.summary = SummaryAccumulator(
                self.params.as_dict(), first, sim.engine.lock_kind,
                section_slope=getattr(sim.engine, 'max_section_slope', None))
        else:
            self.chunk_steps = chunk_steps or sim.chunk_steps
            self.summary = sim.new_summary(first)
        self.publications = 0          # publications taken so far (publication())
        #: the last force value command_force accepted for these parameters (each
        #: publication of the node asks again for the force acting: checked once)
        self._accepted: float | None = None
        self._hold: dict = {}          # peak stresses over the steps since the last one
        self._last_block: StepBlock | None = None

    # ------------------------------------------------------------------- inputs
    @property
    def backend(self) -> str:
        return self.sim.engine.backend

    def command(self, force: float) -> float | None:
        """
        Schedule F_H = force from the current step on (a live command; ValueError if refused).

        Returns the instant it acts from, or None if it is the force acting already.
        """
        k = self.sim.step_index
        if force == self.schedule.force_at(k):
            if force != self._accepted:         # (refused all the same if invalid)
                command_force(force, self.sim.params)
                self._accepted = force
            return None
        self.schedule.add(self.sim.time, force)
        return k * self.step

    # ------------------------------------------------------------------- stepping
    @property
    def time(self) -> float:
        return self.sim.time

    @property
    def at_publication(self) -> bool:
        """Say whether the run stands at a publication instant."""
        return self.period_steps is not None and self.sim.step_index % self.period_steps == 0

    def steps_to_publication(self) -> int | None:
        """Return the steps left to the next publication instant (None: no publications)."""
        if self.period_steps is None:
            return None
        return self.period_steps - self.sim.step_index % self.period_steps

    def advance(self, max_steps: int | None = None) -> Chunk:
        """
        Take the next chunk of steps: at most chunk_steps and max_steps, not past a publication.

        The steps go through the compiled loop (UmbrellaSimulator.advance_schedule) with
        F_H from the schedule; the summary and the publication's peak-hold take them.  The
        lock ends a chunk (an event its consumers act on); a fault too, the state staying
        at the last good step (``error``).  With ``states`` set, each chunk's block carries
        the state rows of its steps (StepBlock.states).
        """
        n = self.chunk_steps
        to_publication = self.steps_to_publication()
        if to_publication is not None:
            n = min(n, to_publication)
        if max_steps is not None:
            n = min(n, int(max_steps))
        block, applied = self.sim.advance_schedule(self.schedule, max(n, 0), self.states,
                                                   until_lock=True)
        self.summary.add(block)
        self._hold = block.merge_peaks(self._hold)
        if len(block):
            self._last_block = block
        return Chunk(block, tuple(applied), block.lock, block.error,
                     block.error is None and self.at_publication,
                     self.sim.lock_sample() if block.lock is not None else None)

    def advance_period(self) -> list[Chunk]:
        """Take the chunks of steps to the next publication instant (or to a fault)."""
        chunks = []
        while True:
            chunk = self.advance()
            chunks.append(chunk)
            if chunk.error is not None or chunk.at_publication or self.period_steps is None:
                return chunks

    def _steps_left(self, k_end: int, stop_after_lock: float | None) -> int:
        """Return the steps left to k_end, or to the first step ending stop_after_lock past it."""
        k = self.sim.step_index
        lock = self.sim.lock_event
        if stop_after_lock is not None and lock is not None:
            k_end = min(k_end, math.ceil((lock.time + stop_after_lock) / self.step - 1e-9))
        return k_end - k

    # ------------------------------------------------------------------- outputs
    def state_sample(self) -> Sample:
        """Return the Sample of the current state (its own peak stresses)."""
        block = self._last_block
        if block is not None and block.last.time == self.sim.time:
            return block.last                  # (built once, from the compiled call)
        return self.sim.sample()

    def publication(self) -> Sample:
        """
        Return the Sample a publication at the current instant carries, and start a new hold.

        The current state, with the peak stresses (and where) replaced by the largest over
        every step since the previous publication (the first publication: the initial
        state's), so that no peak between publications is lost.
        """
        s = self.state_sample()
        hold, self._hold = self._hold, {}
        self.publications += 1
        return s.with_peaks(hold) if hold else s

    # ------------------------------------------------------------------- the loop
    def run(self, duration: float, *, stop_after_lock: float | None = None,
            on_chunk: Callable[[Chunk], None] | None = None,
            on_publication: Callable[[Sample], None] | None = None,
            should_stop: Callable[[], bool] | None = None) -> str | None:
        """
        Step to t = duration (every step that ends by then), or stop_after_lock s past the lock.

        on_chunk(chunk) after every chunk; on_publication(sample) at every publication
        instant reached (t = 0's is the caller's); should_stop() is asked after each chunk.
        Returns the fault that ended the run, or None.
        """
        k_end = math.floor(duration / self.step + 1e-9)     # (round() took one step past)
        sim = self.sim
        while sim.step_index < k_end:
            chunk = self.advance(self._steps_left(k_end, stop_after_lock))
            if on_chunk is not None:
                on_chunk(chunk)
            if chunk.error is not None:
                return chunk.error
            if chunk.at_publication and on_publication is not None:
                on_publication(self.publication())
            if self._steps_left(k_end, stop_after_lock) <= 0:
                break
            if should_stop is not None and should_stop():
                break
        return None


def simulate(params: UmbrellaParams, duration: float,
             force_profile: Iterable[tuple[float, float]] | ForceSchedule | None = None,
             stop_after_lock: float | None = None, *, output_every: int = 1,
             keep_samples: bool = True,
             on_chunk: Callable[[Chunk], None] | None = None,
             should_stop: Callable[[], bool] | None = None, states: bool = False,
             driver: RunDriver | None = None) -> RunResult:
    """
    Run a whole simulation offline on a RunDriver and return its RunResult.

    ``result.figures`` are the summary figures of every physics step; keep_samples keeps
    the state's Sample every output_every steps (and right after the lock) in
    ``result.samples`` (a Python object a step at output_every = 1: for tests and studies;
    the command line keeps none and streams what it writes); on_chunk(chunk) gets every
    chunk of steps (with states, their state rows too).  On a diverged run what was
    computed before the failure is kept and ``result.error`` says why.  driver: run this
    one (built by the caller, at t = 0, for the same parameters and profile) instead.
    """
    if driver is None:
        driver = RunDriver(params, period_steps=output_every if keep_samples else None,
                           force_profile=force_profile)
    driver.states = states
    sim = driver.sim
    result = RunResult(params=sim.params.as_dict())
    if isinstance(sim, UmbrellaSimulator):   # (the planar model's coordinates and stresses)
        result.q_labels = sim.model.coordinate_labels()
        result.leaf_stress_x = list(sim.model.leaf.stress_x)
        result.link_stress_x = list(sim.model.link.stress_x)
    if keep_samples:
        result.samples.append(driver.initial)

    def chunk_done(chunk: Chunk) -> None:
        if keep_samples and chunk.lock is not None:
            result.samples.append(chunk.lock_sample)
        if on_chunk is not None:
            on_chunk(chunk)

    def published(_: Sample) -> None:
        result.samples.append(driver.state_sample())

    wall0 = _time.perf_counter()
    result.error = driver.run(duration, stop_after_lock=stop_after_lock, on_chunk=chunk_done,
                              on_publication=published if keep_samples else None,
                              should_stop=should_stop)
    if keep_samples and result.samples[-1].time < sim.time:    # ended between two outputs
        result.samples.append(driver.state_sample())
    result.wall_time = _time.perf_counter() - wall0
    result.steps = sim.steps
    result.lock = sim.lock_event
    result.figures = driver.summary.figures()
    return result
