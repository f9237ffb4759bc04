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
Recording a run: the node's topics, commands and run records into a bag (bag/writer.py).

``RunRecording`` adds an umbrella_sim run's channels to a ``BagRecorder`` (every published
topic with its QoS, the command topic with its ``/refused`` and ``/applied`` records, and the
record of which name each topic was recorded under) and writes the run's records: the
segments of ~/reset (with the events and the summary of the run each ended), the counts,
the events and the summary at close.  The live node and
``record_offline`` (``umbrella_sim simulate --mcap``, the sweep's recordings) write through
it, so both produce the same topics, layout and metadata.
"""
from __future__ import annotations

import json
import time as _time

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64

from . import messages
from .publication import run_driver
from .ribs_messages import BUS_TOPIC, node_topics, RIB_TOPICS
from .signals import deferred
from ..bag.format import (APPLIED_SUFFIX, COUNTS_RECORD, PARAMETERS_RECORD, REFUSED_SUFFIX,
                          TOPICS_RECORD)
from ..bag.provenance import run_metadata, run_records
from ..bag.writer import BagRecorder
from ..core.driver import Chunk, RunDriver
from ..core.registry import node_defaults
from ..core.step_rule import step_taken_now
from ..core.summary import RunResult

#: every topic a run may record: the planar model's, and the umbrella's per-rib ones
TOPICS = {**messages.TOPICS, **RIB_TOPICS, 'bus_state': BUS_TOPIC}


class RunRecording:
    """
    One run's recording: its channels, its messages as published, its records.

    topics: topic key (messages.TOPICS) -> the name it is published under (resolved);
    command_topic: the command's resolved name; qos: topic key -> the profile each is
    published with (the node's after qos_overrides), else messages.TOPICS's; command_qos:
    the command subscription's (after qos_overrides), else messages.COMMAND's.
    """

    def __init__(self, recorder: BagRecorder, topics: dict[str, str], command_topic: str,
                 qos: dict | None = None, command_qos: QoSProfile | None = None):
        self.recorder = recorder
        self.topics = dict(topics)
        self.command_topic = command_topic
        self.published: dict[str, int] = {}       # resolved name -> messages published
        resolved = {}       # the node's own topic name -> the name recorded (remapped)
        for key, name in self.topics.items():
            topic = TOPICS[key]
            recorder.add_channel(name, topic.type, (qos or {}).get(key, topic.qos))
            resolved[topic.name.lstrip('/')] = name
        for suffix in ('', REFUSED_SUFFIX, APPLIED_SUFFIX):   # (the last two as published)
            recorder.add_channel(command_topic + suffix, Float64,
                                 messages.COMMAND_ECHO_QOS if suffix
                                 else command_qos or messages.COMMAND.qos)
            resolved[messages.COMMAND.name.lstrip('/') + suffix] = command_topic + suffix
        # so that the tools find each topic however it was remapped
        recorder.add_metadata(TOPICS_RECORD, resolved)

    @property
    def path(self) -> str:
        return self.recorder.path

    @property
    def error(self) -> str | None:
        return self.recorder.error

    def publish(self, key: str, msg, t: float) -> None:
        """Record what topic key published at sim time t (exact CDR bytes, or a message)."""
        self.publish_all({key: msg}, t)

    def publish_all(self, msgs: dict, t: float) -> None:
        """Record what topics published at sim time t: key -> exact CDR bytes or a message."""
        t_ns = messages.stamp_ns(t)
        published, records = self.published, []
        for key, msg in msgs.items():
            name = self.topics[key]
            published[name] = published.get(name, 0) + 1
            if isinstance(msg, bytes):      # the encoders' exact CDR, as published
                records.append((name, None, t_ns, msg))
            else:
                records.append((name, msg, t_ns, None))
        self.recorder.write_all(records)

    def command(self, msg, t: float) -> None:
        """Record a command received at sim time t."""
        self.recorder.write(self.command_topic, msg, messages.stamp_ns(t))

    def refused(self, msg, t: float) -> None:
        """Record a command refused at sim time t."""
        self.recorder.write(self.command_topic + REFUSED_SUFFIX, msg, messages.stamp_ns(t))

    def applied(self, force: float, t: float) -> None:
        """Record F_H = force acting from sim time t (the force history a re-run takes)."""
        self.recorder.write(self.command_topic + APPLIED_SUFFIX, Float64(data=float(force)),
                            messages.stamp_ns(t))

    def marker_magnification(self, value: float, t: float) -> None:
        """Record a runtime marker_magnification, which the markers after sim time t carry."""
        self.recorder.marker_magnification(value, messages.stamp_ns(t))

    def start_segment(self, metadata: dict, driver: RunDriver, ended_sim, figures: dict,
                      fault: str | None) -> int:
        """
        Start a new segment (a ~/reset) with these run records; keep the ended one's records.

        The ended run's events and summary (figures: its SummaryAccumulator.figures()), as
        close writes the last one's, named for its segment.
        """
        return self.recorder.start_segment(
            metadata[PARAMETERS_RECORD], gap_ns=messages.stamp_ns(driver.step),
            ended=run_records(ended_sim, figures, fault))

    def close(self, sim, accepted: int, refused: int, figures: dict,
              fault: str | None = None, extra: dict | None = None) -> None:
        """
        Finalise: the counts (published against recorded), the events, the summary.

        extra: more counts (e.g. refused commands not recorded); figures: the run's
        SummaryAccumulator.figures().
        """
        recorded = self.recorder.drained_counts()
        self.recorder.close({
            COUNTS_RECORD: {'published': json.dumps(self.published),
                            'commands_accepted': str(accepted),
                            'commands_refused': str(refused), 'recorded': json.dumps(recorded),
                            **(extra or {})},
            **run_records(sim, figures, fault)})


def record_offline(params, bag_dir: str, duration: float, force_profile=None,
                   publish_rate: float = 100.0, marker_magnification: float = 1.0,
                   on_chunk=None, keep_samples: bool = False,
                   states: bool = False, what: str = 'record_path',
                   umbrella: dict | None = None) -> RunResult:
    """
    Run the physics offline and record it as a live umbrella_node (root namespace) would.

    The run driver steps it (the same states as ``umbrella_sim simulate``, on the
    publication grid), PublicationEncoder encodes each publication, RunRecording writes the
    same topics, layout and metadata as the node.  Each profile row is recorded as a command
    at its own time, each value as applied from the step it acts from.  on_chunk(chunk):
    after each chunk (progress, a CSV; with states, their state rows too).  Returns the
    RunResult (figures of every step; with keep_samples, the Sample of every publication);
    ``error`` set if it diverged, ``recording_error`` if the recording stopped (naming
    what, the option that gave bag_dir, and bag_dir).  umbrella: the umbrella's values
    (params3d.umbrella_values): with ribs >= 2 the umbrella of N ribs, recorded as the node
    records it (publication.run_driver).
    """
    umbrella = umbrella or {}
    node_cfg = node_defaults()
    node_cfg.update(publish_rate=publish_rate, real_time_factor=0.0, duration=duration,
                    record_path=bag_dir, marker_magnification=marker_magnification, **umbrella)
    profile = sorted(force_profile or [], key=lambda tf: tf[0])
    # (checked before the bag)
    driver, encoder = run_driver(params, umbrella, publish_rate, force_profile=profile)
    driver.states = states
    sim = driver.sim
    recorder = BagRecorder(bag_dir, run_metadata(params, node_cfg, driver.step, sim.model,
                                                 driver.backend, source='umbrella_sim simulate'),
                           what=what)
    topics = node_topics(umbrella.get('ribs', 1), umbrella.get('base', 'fixed'))
    rec = RunRecording(recorder, {key: '/' + t.name.lstrip('/') for key, t in topics.items()},
                       '/' + messages.COMMAND.name)
    state = {'next_diag': 1.0, 'i_cmd': 0}
    wall0 = _time.perf_counter()
    result = RunResult(params=sim.params.as_dict())

    def commands_until(t):
        # each command at its own time, as the node records one at receipt
        while state['i_cmd'] < len(profile) and profile[state['i_cmd']][0] <= t + 1e-12:
            t_cmd, f_cmd = profile[state['i_cmd']]
            rec.command(Float64(data=float(f_cmd)), t_cmd)
            state['i_cmd'] += 1

    def publication(s):
        t = s.time
        if keep_samples:
            result.samples.append(s)
        rec.publish_all(encoder.messages(s, 'umbrella', marker_magnification), t)
        if t >= state['next_diag'] - 1e-12:
            wall = _time.perf_counter() - wall0
            rec.publish('diagnostics', messages.diagnostics_msg(
                t, 'umbrella_sim offline: physics', DiagnosticStatus.OK, 'offline',
                {'sim_time_s': f'{t:.6f}', 'measured_real_time_factor':
                 f'{t / wall:.4f}' if wall > 0 else 'inf', 'steps': sim.steps,
                 'physics_step_s': step_taken_now(sim), 'grid_step_s': sim.h}), t)
            state['next_diag'] += 1.0

    def chunk_done(chunk: Chunk):
        with deferred():    # a stop signal lands between chunks, never inside a write
            commands_until(sim.time)
            for t, f in chunk.applied:      # at the step it acts from, as the node records
                rec.applied(f, t)
            if chunk.lock is not None:
                rec.publish('deployment_phase', messages.phase_msg('locked'), sim.time)
            if chunk.error is not None:
                rec.publish('deployment_phase', messages.phase_msg('fault'), sim.time)
        if on_chunk is not None:
            on_chunk(chunk)

    def published(s):
        with deferred():
            publication(s)

    try:
        rec.publish('deployment_phase', messages.phase_msg('deploying'), 0.0)
        commands_until(0.0)
        publication(driver.publication())
        result.error = driver.run(duration, on_chunk=chunk_done, on_publication=published)
    finally:    # interrupted: the summary of every step computed, as the node's at a stop
        rec.close(sim, accepted=state['i_cmd'], refused=0, figures=driver.summary.figures(),
                  fault=result.error)
    result.steps, result.lock = sim.steps, sim.lock_event
    result.figures = driver.summary.figures()
    result.recording_error = rec.error and f'{what} {recorder.bag_dir}: {rec.error}'
    result.wall_time = _time.perf_counter() - wall0
    return result
