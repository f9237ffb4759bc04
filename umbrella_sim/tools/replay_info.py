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
umbrella_replay --info: what a recording holds and the run it is of.

Its topics as `ros2 bag info` says them, then each segment's model, the lock, the fault, the
build and the summary records; no ROS traffic, the log's records only.
"""
from __future__ import annotations

import math

from ..bag.format import BUILD_RECORD, EVENTS_RECORD, MESH_RECORD, SUMMARY_RECORD
from ..bag.reader import LogData, LogError, qos_from_yaml


def info_text(log: LogData) -> str:
    """
    Return what a recording holds, as `ros2 bag info` says it, and the run it is of.

    The file, its span of log (sim) time and message count, each topic with its type, count
    and offered QoS, then each run (a ~/reset's segments alike): model, mesh, ribs, v0, lock
    and grid step, its lock instant and the fault that ended it (if one did, from its events
    record), and where the summary figures are (their records).
    """
    first, last = log.time_range
    span = 0.0 if first is None else (last - first) * 1e-9
    lines = [f'path:          {log.path}',
             f'span:          {span:.6f} s of log time'
             + ('' if first is None else f' (from {first * 1e-9:.6f} s)'),
             f'messages:      {log.message_count}'
             + (' (damaged: only the records before one that does not parse read)'
                if log.damaged else
                ' (truncated: only complete chunks read)' if log.truncated else ''),
             'topics:']
    width = max((len(t) for t in log.topics()), default=0)
    for topic in log.topics():
        kind, qos_yaml = log.channels[topic]
        qos = qos_from_yaml(qos_yaml)
        lines.append(f'  {topic:<{width}}  {kind}  {log.count(topic)} msgs  '
                     f'({qos.reliability.name.lower()}, {qos.durability.name.lower()}, '
                     f'{qos.history.name.lower()} {qos.depth})')
    if log.ended_early:
        lines.append(f'recording ended early: {log.ended_early}')
    try:
        segments = log.segments()
    except LogError:
        segments = []
    # (~/reset: a run a segment, each labelled alike, each with its own events)
    label = ('segment 0:' if len(segments) > 1 else 'run:').ljust(15)
    mesh = log.metadata.get(MESH_RECORD)
    if mesh:
        try:
            start = log.parameters()
        except LogError:            # (the mesh record alone: what it says)
            start = {}
        lines.append(label + _run_text({**mesh, **start}, _stage2_step(log, 0)))
    for seg in segments[1:]:
        lines.append(f'segment {seg.index}:'.ljust(15) + f'from log time '
                     f'{seg.offset_ns * 1e-9:.6f} s (~/reset): '
                     + _run_text(seg.params, _stage2_step(log, seg.index)))
    for k in range(len(segments) or 1):
        events = (log.run_record(EVENTS_RECORD, k) if len(segments) > 1
                  else log.metadata.get(EVENTS_RECORD, {}))
        which = ('' if len(segments) < 2 else
                 f' (segment {k}, the last)' if k == len(segments) - 1 else f' (segment {k})')
        if events.get('locked') == 'true':
            lines.append(f"locked:        at t = {float(events['lock_time']):.9f} s "
                         f"({events.get('lock_kind')} lock){which}")
        if 'fault' in events:
            lines.append(f"fault:         at t = {float(events['fault_time']):.9f} s: "
                         f"{events['fault']}{which}")
    build = log.metadata.get(BUILD_RECORD)
    if build:
        # (written at the start: segment 0's kernel; a later segment's model may step on
        # another, e.g. a rigid model's closed form)
        first = ' (segment 0)' if len(segments) > 1 else ''
        lines.append(f"build:         umbrella_sim {build.get('package_version')} "
                     f"({build.get('git_revision', '?')[:12]}), kernel {build.get('kernel')}"
                     f"{first}, {build.get('source', '')}".rstrip(', '))
    if len(segments) < 2:
        if SUMMARY_RECORD in log.metadata:
            lines.append(f'summary:       the figures of every physics step in the '
                         f"'{SUMMARY_RECORD}' metadata record (umbrella_compare prints them)")
        return '\n'.join(lines)
    # (~/reset: each segment's run has its own, the last one's written at close)
    have = [s.index for s in segments if 'figures' in log.run_record(SUMMARY_RECORD, s.index)]
    none = ', '.join(str(s.index) for s in segments if s.index not in have)
    none = none and (f'none of segment(s) {none} (umbrella_compare --physics-rate re-runs a '
                     'segment for its figures)')
    if have:
        lines.append(f'summary:       the figures of every physics step of segment(s) '
                     f"{', '.join(map(str, have))} in the '{SUMMARY_RECORD}[.K]' metadata "
                     'records (umbrella_compare --segment K prints them)'
                     + (f'; {none}' if none else ''))
    elif none:
        lines.append(f'summary:       {none}')
    return '\n'.join(lines)


def _stage2_step(log: LogData, index: int) -> float | None:
    """Return the physics step stage 2 took in segment index (its summary's), or None."""
    try:
        summary = log.summary(index)
    except LogError:
        return None
    resolution = summary[0].get('stage2_resolution') if summary else None
    return resolution.get('step') if isinstance(resolution, dict) else None


def _run_text(p: dict, stage2_step: float | None = None) -> str:
    """
    Return a run's line: its model, mesh, ribs, v0, lock and grid step.

    The grid step (the parameters record's physics_step: the inputs' and outputs' step,
    stage 1's physics step), and stage 2's physics step where it took substeps of it (as the
    node's start line and its diagnostics' physics_step_s and grid_step_s say them).
    """
    ribs = int(p.get('ribs', 1) or 1)
    step = p.get('physics_step')
    substeps = (stage2_step is not None and step is not None
                and not math.isclose(stage2_step, float(step), rel_tol=1e-9))
    return (f"model {p.get('model')}, {p.get('elements_per_segment')} element(s) a segment, "
            + (f'{ribs} ribs, ' if ribs > 1 else '')
            + (f"v0 {p['v0']} m/s, " if 'v0' in p else '')
            + f"lock {p.get('lock')}"
            + (f', grid step {float(step):g} s' if step is not None else '')
            + (f" (stage 2's physics step {stage2_step:.3g} s)" if substeps else ''))
