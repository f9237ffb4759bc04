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
from .params import UmbrellaParams
from .solver import UmbrellaSimulator


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

    def __init__(self, params: UmbrellaParams, publish_rate: float):
        self.params = params
        self.step = physics_step(params.time_step, publish_rate)
        self.publish_every = round((1.0 / publish_rate) / self.step)
        self.sim = UmbrellaSimulator(params.replace(time_step=self.step))
        first = self.sim.sample()
        self.initial_energy = first.kinetic_energy + first.strain_energy

    @property
    def backend(self) -> str:
        integrator = getattr(self.sim.engine, "integrator", None)
        return integrator.backend if integrator is not None else "closed-form rigid (numpy)"

    def advance(self, commanded_force: float) -> list[Event]:
        """Step one publication period; raises SimulationDiverged (state kept)."""
        sim = self.sim
        events = []
        for _ in range(self.publish_every):
            if commanded_force != sim.sleeve_force:
                sim.set_sleeve_force(commanded_force)
                note = " (locked: no effect on motion)" if sim.stage == "locked" else ""
                events.append(Event("applied", sim.time, commanded_force, note))
            stage = sim.stage
            sim.step(record=False)
            if stage != sim.stage:
                ev = sim.lock_event
                events.append(Event("locked", ev.time, detail=(
                    f"energy {ev.energy_before:.6g} J -> {ev.energy_after:.6g} J, "
                    f"{ev.kind} lock")))
        return events

    def messages(self, marker_ns: str, magnification: float, frame_prefix: str = "") -> dict:
        s = self.sim.sample()
        positions = self.sim.model.node_positions(s.q, magnification)
        return ros_io.sample_messages(s, self.sim.params, positions, marker_ns,
                                      self.initial_energy, frame_prefix)
