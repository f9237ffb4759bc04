"""
One publication period at a time.

The code path shared by the live node and the offline
MCAP writer, so that both produce the same messages at the same sim times.

The physics step is the largest step <= time_step dividing 1/publish_rate, so publications
fall on steps; a commanded force is applied at the next step boundary; every applied value
and the lock are reported as events (the node logs and records them).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from . import ros_io
from .params import NODE_PARAMETERS, UmbrellaParams
from .solver import SimulationDiverged, UmbrellaSimulator


def physics_step(time_step: float, publish_rate: float) -> float:
    """Return the largest step <= time_step that divides the publication period."""
    period = 1.0 / publish_rate
    return period / math.ceil(period / time_step - 1e-9)


@dataclass(frozen=True)
class Event:
    kind: str          # "applied" (force value from t) | "locked"
    time: float
    force: float = 0.0
    detail: str = ""


class PublicationDriver:

    def __init__(self, params: UmbrellaParams, publish_rate: float,
                 marker_rate: float = NODE_PARAMETERS["marker_rate"].default):
        self.params = params
        self.step = physics_step(params.time_step, publish_rate)
        self.publish_every = round((1.0 / publish_rate) / self.step)
        # markers on every marker_every-th publication (t = 0 included)
        self.marker_every = max(1, round(publish_rate / marker_rate))
        self.periods = 0
        self.sim = UmbrellaSimulator(params.replace(time_step=self.step))
        self.last_block = None
        first = self.sim.sample()
        self.initial_energy = first.kinetic_energy + first.strain_energy

    @property
    def backend(self) -> str:
        return self.sim.engine.backend

    def advance(self, commanded_force: float) -> list[Event]:
        """
        Step one publication period.

        Step one publication period (one ``UmbrellaSimulator.advance`` call, its StepBlock
        kept as ``last_block``); raises SimulationDiverged after the steps that succeeded
        (state kept, their outputs in ``last_block``).
        """
        sim = self.sim
        events = []
        if commanded_force != sim.sleeve_force:
            sim.set_sleeve_force(commanded_force)
            note = " (locked: no effect on motion)" if sim.stage == "locked" else ""
            events.append(Event("applied", sim.time, commanded_force, note))
        block = self.last_block = sim.advance(self.publish_every)
        self.periods += 1
        ev = block.lock
        if ev is not None:
            events.append(Event("locked", ev.time, detail=(
                f"energy {ev.energy_before:.6g} J -> {ev.energy_after:.6g} J, "
                f"{ev.kind} lock")))
        if block.error is not None:
            raise SimulationDiverged(block.error)
        return events

    def messages(self, marker_ns: str, magnification: float, frame_prefix: str = "") -> dict:
        """Return the messages of the current state; markers only at their own rate."""
        block = self.last_block
        s = block.last if block is not None and block.last.time == self.sim.time else \
            self.sim.sample()
        with_markers = self.periods % self.marker_every == 0
        positions = self.sim.model.node_positions(s.q, magnification) if with_markers else None
        return ros_io.sample_messages(s, self.sim.params, positions, marker_ns,
                                      self.initial_energy, frame_prefix)
