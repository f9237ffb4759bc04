"""
One publication period at a time.

The code path shared by the live node and the offline
MCAP writer, so that both produce the same messages at the same sim times.

The physics step is the largest step <= time_step dividing 1/publish_rate, so publications
fall on steps.  The sleeve force follows the driver's ForceSchedule (forcing.py, the one
zero-order-hold rule): the node adds a command at the start of the next publication period,
the offline driver (solver.simulate) gives the whole profile, each value acting from its
own step.  Every applied value and the lock are reported as events (the node logs and
records them).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from . import messages as ros_io
from ..core.engines import SimulationDiverged
from ..core.forcing import command_force, ForceSchedule
from ..core.outputs import build_frozen, mechanical_energy, Sample, StepBlock
from ..core.params import NODE_PARAMETERS, physics_step, UmbrellaParams
from ..core.solver import UmbrellaSimulator
from ..core.summary import SummaryAccumulator


#: steps per advance_schedule call of a period when a stop may come (PublicationDriver.advance):
#: at most ~0.3 s of the slowest model (N = 64, flexible-nonlinear), a few ms of most
STOP_CHECK_STEPS = 256


@dataclass(frozen=True)
class Event:
    kind: str          # "applied" (force value from t) | "locked"
    time: float
    force: float = 0.0
    detail: str = ""


class PublicationDriver:
    """
    The simulator and its force schedule, one publication period at a time.

    ``advance`` (the live node) and ``take`` (the offline driver, which steps through
    solver.simulate) report the applied forces and the lock as events and keep the block
    of steps of the last period.
    """

    def __init__(self, params: UmbrellaParams, publish_rate: float,
                 marker_rate: float = NODE_PARAMETERS["marker_rate"].default):
        self.params = params
        self.publish_rate = publish_rate
        self.step = physics_step(params.physics_time_step, publish_rate)
        self.publish_every = round((1.0 / publish_rate) / self.step)
        # markers on every marker_every-th publication (t = 0 included)
        self.marker_every = max(1, round(publish_rate / marker_rate))
        self.periods = 0
        self.sim = UmbrellaSimulator(params.with_physics_step(self.step))
        self.schedule = ForceSchedule(self.step, self.sim.sleeve_force,
                                      check=lambda f: command_force(f, self.sim.params))
        self.last_block: StepBlock | None = None
        first = self.sim.sample()
        self.initial_energy = mechanical_energy(first)
        # the live node's summary of every step (the offline driver keeps its own)
        self.summary = SummaryAccumulator(self.sim.params.as_dict(), first,
                                          self.sim.engine.lock_kind)
        self._peaks: dict = {}       # peak stresses over the steps since the last publication
        self._first = first
        self._encoders: dict[str, ros_io.SampleEncoder] = {}    # by frame_prefix
        self._marker_encoders: dict = {}            # by (marker namespace, frame_prefix)

    @property
    def backend(self) -> str:
        return self.sim.engine.backend

    def command(self, force: float) -> None:
        """Schedule a live command: F_H = force from the current step on (raises ValueError)."""
        if force != self.schedule.force_at(self.sim.step_index):
            self.schedule.add(self.sim.time, force)

    def advance(self, commanded_force: float | None = None,
                should_stop: Callable[[], bool] | None = None) -> list[Event]:
        """
        Step one publication period.

        With the commanded force (if given) scheduled from its first step,
        ``UmbrellaSimulator.advance_schedule`` calls (their StepBlock kept as
        ``last_block``); raises SimulationDiverged after the steps that succeeded (state
        kept, their outputs in ``last_block``).  With should_stop, a long period goes in
        calls of STOP_CHECK_STEPS steps and ends early once it returns True (``at_publication``
        then says False): a stop does not wait for a period of many slow steps.  The summary
        takes the period's steps as one block either way.
        """
        if commanded_force is not None:
            self.command(commanded_force)
        chunk = self.publish_every if should_stop is None else STOP_CHECK_STEPS
        blocks, applied = [], []
        k_end = self.sim.step_index + self.publish_every - \
            self.sim.step_index % self.publish_every
        while self.sim.step_index < k_end:
            block, values = self.sim.advance_schedule(
                self.schedule, min(chunk, k_end - self.sim.step_index))
            blocks.append(block)
            applied += values
            if block.error is not None or (should_stop is not None and should_stop()):
                break
        block = StepBlock.concatenate(blocks)
        self.summary.add(block)
        events = self.take(block, applied)
        if block.error is not None:
            raise SimulationDiverged(block.error)
        return events

    @property
    def at_publication(self) -> bool:
        """Say whether the simulator is at a publication instant (not stopped mid-period)."""
        return self.sim.step_index % self.publish_every == 0

    def take(self, block: StepBlock, applied: list[tuple[float, float]]) -> list[Event]:
        """Note one period's block of steps; return its events (applied forces, the lock)."""
        self.last_block = block
        self.periods += 1
        for body, (peak, x, _) in block.peaks.items():
            if peak > self._peaks.get(body, (-1.0, 0.0))[0]:
                self._peaks[body] = (peak, x)
        if not applied and block.lock is None:      # most periods: nothing to report
            return []
        lock = self.sim.lock_event
        events = [Event("applied", t, f, " (locked: no effect on motion)"
                        if lock is not None and t >= lock.time else "") for t, f in applied]
        ev = block.lock
        if ev is not None:
            events.append(Event("locked", ev.time, detail=(
                f"energy {ev.energy_before:.6g} J -> {ev.energy_after:.6g} J, "
                f"{ev.kind} lock")))
        events.sort(key=lambda e: e.time)
        return events

    def publication_sample(self):
        """
        Return the Sample a publication now carries.

        The current state, with the peak stresses (and where) replaced by the largest over
        every step since the previous publication (the first publication: the initial
        state's), so that no peak between publications is lost.
        """
        block = self.last_block
        s = block.last if block is not None and len(block) and \
            block.last.time == self.sim.time else self.sim.sample()
        peaks, self._peaks = self._peaks, {}
        if peaks:       # dataclasses.replace re-runs __init__ (~40 us): a per-publication cost
            s = build_frozen(Sample, {
                **s.__dict__, "peak_stress_leaf": peaks["leaf"][0],
                "peak_stress_leaf_x": peaks["leaf"][1], "peak_stress_link": peaks["link"][0],
                "peak_stress_link_x": peaks["link"][1]})
        return s

    def messages(self, marker_ns: str, magnification: float, frame_prefix: str = "") -> dict:
        """
        Return what the current state publishes, keyed as ros_io.TOPICS.

        The per-publication topics as their CDR bytes (ros_io.SampleEncoder: built once,
        published and recorded as they are); the markers, at their own rate only, likewise
        (ros_io.MarkerEncoder).  The Sample they carry is kept as ``published_sample``.
        """
        s = self.published_sample = self.publication_sample()
        encoder = self._encoders.get(frame_prefix)
        if encoder is None:
            encoder = self._encoders[frame_prefix] = ros_io.SampleEncoder(
                self._first, self.sim.params, self.initial_energy, frame_prefix)
        out: dict = encoder.encode(s)
        if self.periods % self.marker_every == 0:
            positions = self.sim.model.node_positions(s.q, magnification)
            markers = self._marker_encoders.get((marker_ns, frame_prefix))
            if markers is None:
                markers = self._marker_encoders[marker_ns, frame_prefix] = \
                    ros_io.MarkerEncoder(positions, marker_ns, frame_prefix)
            out["markers"] = markers.encode(s.time, s.sleeve_position, positions)
        return out
