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
Reading recorded runs back: a bag directory or a single .mcap, finalised or not.

Reading streams: opening a log reads its channels, metadata and message counts (from the
summary of a finalised file, else by one pass over the records); messages are read from the
file each time they are asked for, one chunk at a time, so memory stays bounded for any
bag size.  A file whose writer was killed (SIGKILL: no summary, no footer) is read record by
record from the start: every complete chunk is recovered and the torn tail is dropped
(``LogData.truncated`` says so).  A recording stopped by a write error says so in its
``umbrella_sim.recording_error`` record (``LogData.ended_early``).

Segments: a ~/reset restarts sim time at 0; the recorder then offsets log times so they never
go backwards and writes an ``umbrella_sim.segment.K`` record with the offset and the new
parameters.  ``LogData.segments()`` lists them; ``decoded(topic, segment=K)`` gives that
segment's messages in its own sim time; ``run_record`` and ``summary`` its run records (its
events and summary figures, written when it ended).

Everything that makes a file unusable raises LogError naming the file and the reason: not a
regular file, not MCAP, not an umbrella_sim recording, unknown message types, payloads that
do not decode.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import importlib
import json
import os
import stat
import struct

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk, StreamReader
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
import yaml
from zstandard import ZstdError

from .format import (ENDED_EARLY_RECORD, MCAP_MAGIC, PARAMETERS_RECORD, SEGMENT_RECORD,
                     segment_record, SUMMARY_RECORD, TOPICS_RECORD)
from .provenance import summary_of


class LogError(ValueError):
    """A log that cannot be used, with the reason (file, topic) in the message."""


#: what the mcap library raises on damaged bytes: its own errors, a short read (EOFError,
#: struct.error), a bad field (ValueError, AssertionError, KeyError), a chunk that does not
#: decompress (ZstdError)
DAMAGED = (McapError, EOFError, struct.error, ValueError, AssertionError, KeyError, ZstdError)


@dataclass
class RawMessage:
    topic: str
    log_time: int
    data: bytes


@dataclass(frozen=True)
class Segment:
    index: int
    offset_ns: int          # log time = offset_ns + sim time (ns)
    end_ns: int | None      # first log time of the next segment, None for the last
    params: dict


@dataclass
class LogData:
    path: str
    channels: dict = field(default_factory=dict)      # topic -> (type name, qos yaml)
    metadata: dict = field(default_factory=dict)      # record name -> {key: value}
    counts: dict = field(default_factory=dict)        # topic -> messages in the file
    truncated: bool = False
    damaged: bool = False               # truncated where the file goes on to its end magic
    indexed: bool = False
    time_range: tuple = (None, None)                  # first, last log time (ns)
    _types: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ topics
    def topics(self) -> list[str]:
        return sorted(self.channels)

    def find_topic(self, suffix: str, required: bool = True) -> str | None:
        """
        Return the recorded topic the node's topic `suffix` went to (None / LogError).

        Through the recording's topic record (a remapped or namespaced node's names), else
        (older recordings) the one topic whose name ends in it.
        """
        recorded = self.metadata.get(TOPICS_RECORD, {}).get(suffix.lstrip('/'))
        if recorded in self.channels:
            return recorded
        matches = [t for t in self.channels if t == suffix or t.endswith('/' + suffix.lstrip('/'))]
        matches = [t for t in matches if not t.endswith(('/refused', '/applied'))
                   or suffix.endswith(('/refused', '/applied'))]
        if len(matches) == 1:
            return matches[0]
        if not matches:
            if required:
                raise LogError(f"{self.path}: no topic '{suffix}' in the log "
                               f"(topics: {', '.join(self.topics()) or 'none'})")
            return None
        raise LogError(f"{self.path}: several topics end in '{suffix}': {', '.join(matches)}")

    def msg_type(self, topic: str):
        if topic not in self._types:
            try:
                self._types[topic] = import_type(self.channels[topic][0])
            except LogError as exc:
                raise LogError(f'{self.path}: topic {topic}: {exc}') from None
        return self._types[topic]

    def truncation_note(self) -> str:
        """Return ' (...)' saying the file is truncated, for errors about missing messages."""
        if self.damaged:
            return (' (the file is damaged: a record in it does not parse, and only the records '
                    'before that one could be read)')
        return (' (the file is truncated: only its complete chunks could be read; a killed '
                'recorder loses the chunk it was filling)') if self.truncated else ''

    @property
    def cut_short(self) -> str:
        """Return 'damaged log', 'truncated log' or '' (what the tools' notes say)."""
        return 'damaged log' if self.damaged else 'truncated log' if self.truncated else ''

    def count(self, topic: str) -> int:
        return self.counts.get(topic, 0)

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    # ---------------------------------------------------------------- messages
    def iter_raw(self, topics=None):
        """
        Stream the RawMessages of the given topics.

        RawMessage of the given topics (all if None), streamed from the file: log-time
        order for a finalised file, file order for a recovered one (the recorder writes in
        publication order).
        """
        wanted = None if topics is None else set(topics)
        if self.indexed:
            with open(self.path, 'rb') as fh:
                # each chunk's CRC checked: damaged bytes in a chunk whose compression does
                # not notice them (a stored block) are named here, not as a payload that
                # does not decode
                reader = make_reader(fh, validate_crcs=True)
                try:
                    for _, channel, message in reader.iter_messages(
                            topics=None if wanted is None else sorted(wanted),
                            log_time_order=True):
                        yield RawMessage(channel.topic, message.log_time, message.data)
                except DAMAGED as exc:
                    raise LogError(f'{self.path}: unreadable MCAP data ({exc})') from None
            return
        for record, topic in _scan(self.path, {}, {}):
            if isinstance(record, Message) and (wanted is None or topic in wanted):
                yield RawMessage(topic, record.log_time, record.data)

    @property
    def messages(self) -> list[RawMessage]:
        """Every message in memory (small logs and tests only; tools use iter_raw)."""
        return list(self.iter_raw())

    def iter_decoded(self, topic: str, segment: 'Segment | None' = None):
        """(time in s, message) of one topic: log time, or the segment's sim time."""
        cls = self.msg_type(topic)
        for i, m in enumerate(self.iter_raw([topic])):
            if segment is not None:
                if m.log_time < segment.offset_ns or (segment.end_ns is not None
                                                      and m.log_time >= segment.end_ns):
                    continue
                t = (m.log_time - segment.offset_ns) * 1e-9
            else:
                t = m.log_time * 1e-9
            yield t, self.decode(topic, m.data, cls, i, m.log_time)

    def decoded(self, topic: str, segment: 'Segment | None' = None) -> list[tuple[float, object]]:
        """[(time in s, message)] of one topic, in time order (see iter_decoded)."""
        out = list(self.iter_decoded(topic, segment))
        out.sort(key=lambda tm: tm[0])
        return out

    def decode(self, topic: str, data: bytes, cls=None, index: int | None = None,
               log_time: int | None = None):
        cls = cls or self.msg_type(topic)
        try:
            return deserialize_message(data, cls)
        except Exception as exc:      # rclpy raises RMWError / RuntimeError on bad CDR
            where = '' if index is None else f' message {index} (log time {log_time} ns)'
            reason = ' '.join(str(exc).split())
            raise LogError(f'{self.path}: topic {topic}{where}: payload does not decode as '
                           f'{self.channels[topic][0]} ({reason})') from None

    # ----------------------------------------------------------------- metadata
    @property
    def ended_early(self) -> str | None:
        """Why the recording stopped early (write error), or None."""
        rec = self.metadata.get(ENDED_EARLY_RECORD)
        return rec.get('error', 'unknown error') if rec else None

    def parameters(self) -> dict:
        rec = self.metadata.get(PARAMETERS_RECORD)
        if rec is None:
            raise LogError(f'{self.path}: no {PARAMETERS_RECORD} metadata record '
                           '(not recorded by umbrella_sim?)')
        try:
            return {k: json.loads(v) for k, v in rec.items()}
        except (TypeError, ValueError):
            raise LogError(f'{self.path}: {PARAMETERS_RECORD} holds values that are not '
                           'JSON') from None

    def segments(self) -> list[Segment]:
        """Segment 0 (start parameters), then one per ~/reset recorded."""
        starts = [(0, 0, self.parameters())]
        for name, rec in self.metadata.items():
            if not name.startswith(SEGMENT_RECORD + '.'):
                continue
            try:
                # a JSON object of JSON texts, as in umbrella_sim.parameters
                params = {k: json.loads(v) for k, v in json.loads(rec['parameters']).items()}
                starts.append((int(rec['index']), int(rec['log_time_offset_ns']), params))
            except (KeyError, TypeError, ValueError):
                raise LogError(f'{self.path}: metadata record {name} is malformed') from None
        starts.sort()
        return [Segment(k, off, starts[i + 1][1] if i + 1 < len(starts) else None, params)
                for i, (k, off, params) in enumerate(starts)]

    def segment(self, index: int) -> Segment:
        segs = self.segments()
        if not 0 <= index < len(segs):
            raise LogError(f'{self.path}: no segment {index} (the log has {len(segs)})')
        return segs[index]

    def run_record(self, name: str, index: int) -> dict:
        """
        Return a run record (EVENTS_RECORD, SUMMARY_RECORD) of segment index, {} if none.

        The last segment's is written at close, an earlier one's at the ~/reset that ended
        it (format.segment_record; a recording made before resets wrote the summary has
        only their events).
        """
        last = index == len(self.segments()) - 1
        return self.metadata.get(segment_record(name, None if last else index), {})

    def summary(self, index: int) -> tuple[dict, list] | None:
        """
        Return segment index's summary record: (figures of every physics step, warnings).

        None where the log has none (killed or ended early before it, or an earlier
        segment of an older recording); LogError if it is not JSON.
        """
        try:
            return summary_of(self.run_record(SUMMARY_RECORD, index))
        except ValueError:
            last = index == len(self.segments()) - 1
            name = segment_record(SUMMARY_RECORD, None if last else index)
            raise LogError(f'{self.path}: metadata {name} is not valid JSON') from None


def import_type(type_name: str):
    try:
        pkg, kind, name = type_name.split('/')
        return getattr(importlib.import_module(f'{pkg}.{kind}'), name)
    except (ValueError, ImportError, AttributeError):
        raise LogError(f'message type {type_name!r} is not available here') from None


def _policy(kind, value, default):
    """Return a QoS policy of rosbag2's YAML: a name (metadata version 9) or number (8)."""
    if value is None:
        return kind(default)
    return kind(value) if isinstance(value, int) else kind[str(value).upper()]


def qos_from_yaml(text) -> QoSProfile:
    """Return the first offered QoS profile of a channel (YAML text) or metadata.yaml (list)."""
    try:
        prof = ((yaml.safe_load(text) if isinstance(text, str) else text) or [{}])[0]
        return QoSProfile(history=_policy(HistoryPolicy, prof.get('history'), 1),
                          depth=max(int(prof.get('depth', 10)), 1),
                          reliability=_policy(ReliabilityPolicy, prof.get('reliability'), 1),
                          durability=_policy(DurabilityPolicy, prof.get('durability'), 2))
    except Exception:
        return QoSProfile(depth=10)


def _regular_file(path: str) -> None:
    try:
        st = os.stat(path)
    except OSError as exc:
        raise LogError(f'{path}: {exc.strerror}') from None
    if not stat.S_ISREG(st.st_mode):
        raise LogError(f'{path}: not a regular file (a FIFO, device or socket cannot be read '
                       'as a log)')


def resolve_path(path: str) -> str:
    """Return the .mcap of a bag directory (metadata.yaml, else the only .mcap), or the file."""
    if os.path.isdir(path):
        meta = os.path.join(path, 'metadata.yaml')
        if os.path.isfile(meta):
            try:
                with open(meta, 'rb') as fh:
                    info = yaml.safe_load(fh.read().decode('utf-8'))['rosbag2_bagfile_information']
                return os.path.join(path, os.path.basename(info['relative_file_paths'][0]))
            except (KeyError, IndexError, TypeError, UnicodeDecodeError, yaml.YAMLError):
                raise LogError(f'{meta}: not a rosbag2 metadata file') from None
            except OSError as exc:
                raise LogError(f'{meta}: {exc.strerror}') from None
        found = [f for f in sorted(os.listdir(path)) if f.endswith('.mcap')]
        if len(found) != 1:
            raise LogError(f'{path}: a bag directory needs metadata.yaml or exactly one .mcap '
                           f'(found {len(found)}){_bags_inside(path) if not found else ""}')
        return os.path.join(path, found[0])
    if not os.path.lexists(path):
        raise LogError(f'{path}: no such file or directory')
    return path


def _bags_inside(path: str, shown: int = 3) -> str:
    """Say which bag directories a directory of them holds (runs/: its runs), the latest last."""
    bags = sorted(d for d in os.listdir(path) if os.path.isdir(os.path.join(path, d))
                  and any(f.endswith('.mcap') or f == 'metadata.yaml'
                          for f in os.listdir(os.path.join(path, d))))
    if not bags:
        return ''
    more = f' and {len(bags) - shown} more' if len(bags) > shown else ''
    return ('; it holds bag directories: give one of them, ' + ', '.join(
        os.path.join(path, d) for d in bags[-shown:]) + more)


def read_log(path: str, umbrella: bool = True) -> LogData:
    """
    Open a log (channels, metadata, counts; no messages in memory).

    Open a log (channels, metadata, counts; no messages in memory).  umbrella=True: it
    must be an umbrella_sim recording (its parameters record).
    """
    mcap_path = resolve_path(path)
    _regular_file(mcap_path)
    try:
        with open(mcap_path, 'rb') as fh:
            head = fh.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise LogError(f'{mcap_path}: {exc.strerror}') from None
    if head != MCAP_MAGIC:
        raise LogError(f'{mcap_path}: not an MCAP file (bad magic bytes)')
    log = LogData(path=mcap_path)
    try:
        _open_indexed(log)
    except DAMAGED + (OSError,):
        log.channels.clear()
        log.metadata.clear()
        log.counts.clear()
        _open_recovering(log)
    if not log.channels:
        why = ('the file is damaged: a record before its first channel does not parse'
               if log.damaged else
               f'the file is truncated: it ends after {os.path.getsize(mcap_path)} bytes, '
               'before its first channel record' if log.truncated
               else 'empty or unreadable MCAP')
        raise LogError(f'{mcap_path}: no channels ({why})')
    if umbrella:
        if PARAMETERS_RECORD not in log.metadata:
            raise LogError(f'{mcap_path}: not an umbrella_sim recording (no '
                           f'{PARAMETERS_RECORD} metadata record)')
        log.segments()          # malformed segment records fail here, not half-way
    for topic, (tname, _) in log.channels.items():
        if log.counts.get(topic):
            log.msg_type(topic)     # a type we cannot decode fails now, naming the topic
    return log


def _open_indexed(log: LogData) -> None:
    with open(log.path, 'rb') as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            raise McapError('no summary')
        for ch in summary.channels.values():
            schema = summary.schemas.get(ch.schema_id)
            log.channels[ch.topic] = (schema.name if schema else '',
                                      ch.metadata.get('offered_qos_profiles', ''))
            log.counts[ch.topic] = log.counts.get(ch.topic, 0) + \
                summary.statistics.channel_message_counts.get(ch.id, 0)
        for m in reader.iter_metadata():
            log.metadata[m.name] = dict(m.metadata)
        st = summary.statistics
        if st.message_count:
            log.time_range = (st.message_start_time, st.message_end_time)
    log.indexed = True


def _scan(path: str, schemas: dict, channels: dict, state: dict | None = None):
    """
    Yield (record, topic) for every complete record.

    (record, topic) for every complete record, chunks opened; stops at a torn tail
    (state["truncated"] = True).  One chunk in memory at a time.
    """
    def take(record):
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Chunk):
            for inner in breakup_chunk(record, validate_crc=True):
                yield from take(inner)
            return
        topic = None
        if isinstance(record, Message):
            ch = channels.get(record.channel_id)
            if ch is None:
                return
            topic = ch.topic
        yield record, topic

    with open(path, 'rb') as fh:
        try:
            for record in StreamReader(fh, skip_magic=False).records:
                yield from take(record)
        except Exception:
            if state is not None:
                state['truncated'] = True


def _open_recovering(log: LogData) -> None:
    """One pass over the records of a file without a usable summary (a killed writer)."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    state = {'truncated': False}
    for record, topic in _scan(log.path, schemas, channels, state):
        if isinstance(record, Channel):
            schema = schemas.get(record.schema_id)
            log.channels[record.topic] = (schema.name if schema else '',
                                          record.metadata.get('offered_qos_profiles', ''))
            log.counts.setdefault(record.topic, 0)
        elif isinstance(record, Message):
            log.counts[topic] += 1
            lo, hi = log.time_range
            log.time_range = (record.log_time if lo is None else min(lo, record.log_time),
                              record.log_time if hi is None else max(hi, record.log_time))
        elif isinstance(record, Metadata):
            log.metadata[record.name] = dict(record.metadata)
    log.truncated = state['truncated']
    log.damaged = log.truncated and _ends_in_magic(log.path)


def _ends_in_magic(path: str) -> bool:
    """Say whether the file ends as a finished MCAP does (its footer, then the magic)."""
    try:
        with open(path, 'rb') as fh:
            fh.seek(0, os.SEEK_END)
            if fh.tell() < 2 * len(MCAP_MAGIC):
                return False
            fh.seek(-len(MCAP_MAGIC), os.SEEK_END)
            return fh.read() == MCAP_MAGIC
    except OSError:
        return False
