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
Writing a recording: one rosbag2 bag directory, crash-safe, never overwriting.

``BagRecorder`` writes ``NAME/NAME_0.mcap`` (profile ``ros2``, one ``ros2msg`` schema per type,
``cdr`` messages, ``offered_qos_profiles`` on every channel, log/publish times in sim time
(ns), zstd chunks with message indexes, a Statistics record and, at close, a ``rosbag2``
metadata record like rosbag2's MCAP plugin) and ``metadata.yaml``.  Metadata records are
written outside chunks at once, so they survive a crash; a write error stops only the
recording, which ends as a readable file saying why.
"""
from __future__ import annotations

import collections
import json
import os
import threading

from mcap.writer import CompressionType, IndexType, Writer
from rclpy.qos import QoSProfile
import yaml

from .cdr import (BAG_FORMAT_VERSION, cdr_bytes, message_definition, qos_profiles, qos_yaml,
                  type_description_hash, type_name)
from .format import CHUNK_SIZE, MAGNIFICATION_RECORD, SEGMENT_RECORD, segment_record
from .mcap_stream import (CommittedFile, ended_early_tail, keep_definitions_out_of_chunks,
                          MessageAppender, SpilledChunkIndex, write_all)
from .paths import absolute_path, check_new_output
from .. import __version__


# ---------------------------------------------------------------------- recorder
def default_bag_name(namespace: str = '/', when: float | None = None) -> str:
    """Return umbrella[_ns]_YYYY_MM_DD-HH_MM_SS, as ros2 bag record names its bags."""
    import time

    ns = namespace.strip('/').replace('/', '_')
    stamp = time.strftime('%Y_%m_%d-%H_%M_%S', time.localtime(when))
    return '_'.join(['umbrella'] + ([ns] if ns else []) + [stamp])


def new_bag_recorder(namespace: str, metadata, parent: str = '.',
                     on_error=None, background: bool = False) -> 'BagRecorder':
    """
    Open a new timestamped bag directory in parent (default: the working directory).

    Never overwrites: when the name is taken (two antennas started in the same second, or
    a bag left from a run a moment ago) the next free NAME_1, NAME_2, ... is used.
    metadata(bag_dir) returns the run's metadata records.
    """
    base = os.path.join(absolute_path(parent, 'recording directory'),
                        default_bag_name(namespace))
    for k in range(1000):
        bag_dir = base if k == 0 else f'{base}_{k}'
        if os.path.exists(bag_dir):
            continue
        try:
            return BagRecorder(bag_dir, metadata(bag_dir), on_error=on_error,
                               background=background)
        except ValueError:
            if os.path.exists(bag_dir):      # taken meanwhile by another process: next name
                continue
            raise
    raise ValueError(f'recording: no free bag directory name {base}_N in {parent}')


def check_record_path(bag_dir: str, what: str = 'record_path') -> str:
    """
    Return the absolute bag directory, or raise ValueError why it cannot be created.

    The absolute bag directory, or ValueError naming why it cannot be created (cheap
    checks before any simulation work; nothing is created; never overwrites).  An empty
    bag_dir is a new bag in the working directory (new_bag_recorder): that directory's.
    """
    if not bag_dir:
        return absolute_path('.', f"{what} '' (a new bag in the working directory)")
    return check_new_output(bag_dir, what, overwrite_option=None)


class BagRecorder:
    """
    Write one bag directory, thread-safe; never overwrites.

    Thread-safe writer of one bag directory; never overwrites.

    A write error (disk full, I/O error, permissions) never propagates to the caller's
    publishing: the recording stops at the last complete record, an ``umbrella_sim.
    recording_error`` metadata record and a footer are appended if the disk takes them,
    ``error`` holds the reason and ``on_error`` (if given) is called once with it.  A failure
    while starting removes everything the recorder created and raises ValueError.

    background=True (the live node): ``write`` only queues the message (bounded, QUEUE_LIMIT;
    a full queue makes the caller wait, nothing is dropped) and a writer thread does the CDR
    trim, the chunking, the zstd compression and the file writes, so none of it runs on the
    publishing thread.  The writer wakes every WRITE_PERIOD and writes what accumulated (a
    wake-up per message cost more CPU than the writing: a thread switch and a GIL handover
    each).  A write error there stops the recording as above (``on_error`` is then
    called from the writer thread); the other methods first wait for the queue to drain, so
    segments, counts and the footer see every message queued before them.
    """

    #: messages queued at most for the background writer (~1 s of a 1 kHz publication)
    QUEUE_LIMIT = 8192
    #: the background writer's period (s)
    WRITE_PERIOD = 0.02

    def __init__(self, bag_dir: str, metadata: dict[str, dict[str, str]], on_error=None,
                 background: bool = False, what: str = 'record_path'):
        # (what: the option that named it, which has no overwrite)
        bag_dir = check_new_output(bag_dir, what, overwrite_option=None)
        try:
            os.mkdir(bag_dir)
        except OSError as exc:
            raise ValueError(f'{what} {bag_dir}: {exc.strerror}') from None
        self.bag_dir = bag_dir
        self.file_name = os.path.basename(bag_dir) + '_0.mcap'
        self.path = os.path.join(bag_dir, self.file_name)
        self.error: str | None = None
        self.on_error = on_error
        self._fh = None
        self._chunk_index = None
        try:
            # committed after every write: a finished chunk reaches the OS at once, so a
            # SIGKILL loses only the chunk being filled (messages accumulate in memory)
            self._fh = CommittedFile(self.path)
            self._writer = Writer(self._fh, chunk_size=CHUNK_SIZE,
                                  compression=CompressionType.ZSTD,
                                  index_types=IndexType.ALL, use_chunking=True,
                                  use_statistics=True)
            # the writer's growing chunk index goes to disk (mcap's private list, replaced
            # where this mcap version has it; otherwise it stays in memory as before)
            self._chunk_index = SpilledChunkIndex(bag_dir)
            if isinstance(getattr(self._writer, '_Writer__chunk_indices', None), list):
                self._writer._Writer__chunk_indices = self._chunk_index
            # Schema and Channel records once each, outside the chunks (add_channel)
            self._definitions_outside = keep_definitions_out_of_chunks(self._writer)
            self._appender = MessageAppender.create(self._writer)
            self._writer.start(profile='ros2', library=f'umbrella_sim {__version__}')
            for name, data in metadata.items():
                self._writer.add_metadata(name, data)
            self._written_records = set(metadata)
            self._fh.commit()
        except OSError as exc:
            self._remove_partial()
            raise ValueError(f'{what} {bag_dir}: cannot start the recording: '
                             f'{exc.strerror or exc}') from None
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str, QoSProfile]] = {}
        self.counts: dict[str, int] = {}
        self._first = self._last = None
        self._on_disk: tuple[dict, int | None] = ({}, None)   # counts, last time in the file
        self._closed = False
        self.segment = 0
        self.offset_ns = 0
        self._magnifications = 0
        self._queue = None
        if background:
            self._queue = collections.deque()        # append/popleft are thread-safe
            self._cv = threading.Condition()
            self._writing = False
            self._stop_writer = False
            self._writer_thread = threading.Thread(target=self._write_queued,
                                                   name='recorder', daemon=True)
            self._writer_thread.start()

    def _write_queued(self) -> None:
        """Write what write() queued, every WRITE_PERIOD, until close() (writer thread)."""
        items = self._queue
        while True:
            with self._cv:
                if not items:
                    if self._stop_writer:
                        return
                    self._cv.wait(self.WRITE_PERIOD)
                self._writing = True
            while items:
                # what accumulated, in one go (one lock for all: ~1 us a message less)
                batch = [items.popleft() for _ in range(len(items))]
                try:
                    self._write_many(batch)
                except Exception as exc:  # never lose the thread silently: stop the recording
                    with self._lock:
                        if not self._closed:
                            self._fail(OSError(f'{type(exc).__name__}: {exc}'), 'recording',
                                       None)
            with self._cv:
                self._writing = False
                self._cv.notify_all()

    def _drain(self) -> None:
        """Wait until the writer thread has written everything queued so far."""
        if self._queue is None:
            return
        with self._cv:
            self._cv.notify_all()
            while (self._queue or self._writing) and self._writer_thread.is_alive():
                self._cv.wait(0.1)

    def _remove_partial(self) -> None:
        self._release_index()
        if self._fh is not None:
            try:
                self._fh.close(sync=False)
            except OSError:
                pass
        for path in (self.path, self.bag_dir):
            try:
                (os.rmdir if path == self.bag_dir else os.unlink)(path)
            except OSError:
                pass

    def _release_index(self) -> None:
        if self._chunk_index is not None:
            self._chunk_index.close()

    def _fail(self, exc: OSError, what: str, t_ns: int | None) -> None:
        """Stop recording after a write error (called with the lock held)."""
        self.error = f'{what}: {exc.strerror or exc} (errno {exc.errno})' if exc.errno else \
            f'{what}: {exc}'
        self._closed = True
        # what the file holds: the messages of the chunks written before the failure (the
        # chunk being filled was only in memory)
        counts, last = self._on_disk
        self.counts = {topic: counts.get(topic, 0) for topic in self.counts}
        self._last = last
        meta = {'ended_early': 'true', 'error': self.error,
                'last_log_time_ns': '' if last is None else str(last),
                'failed_at_log_time_ns': '' if t_ns is None else str(t_ns),
                'recorded': json.dumps(self.counts)}
        try:
            write_all(self._fh.fd, ended_early_tail(meta))
        except OSError:
            self._fh.rollback()     # a clean prefix without footer: readers recover it
        self._release_index()
        try:
            self._fh.close()
        except OSError:
            pass
        try:
            self._write_bag_info()
        except OSError:
            pass
        if self.on_error is not None:
            self.on_error(self.error)

    def add_channel(self, topic: str, msg_type, qos: QoSProfile) -> None:
        self._drain()
        with self._lock:
            if topic in self._channels or self._closed:
                return
            tname = type_name(msg_type)
            new_schema = tname not in self._schemas
            definition = message_definition(tname).encode('utf-8')
            if new_schema:
                self._schemas[tname] = self._writer.register_schema(
                    name=tname, encoding='ros2msg', data=definition)
            # what rosbag2 (Jazzy) puts on a channel: the QoS and the type's RIHS01 hash
            channel_metadata = {'offered_qos_profiles': qos_yaml(qos),
                                'topic_type_hash': type_description_hash(tname)}
            cid = self._writer.register_channel(
                topic=topic, message_encoding='cdr', schema_id=self._schemas[tname],
                metadata=channel_metadata)
            self._channels[topic] = (cid, tname, qos)
            self.counts[topic] = 0
            if not self._definitions_outside:
                return          # the writer put them into the chunk being filled
            # once each, outside the chunks, now: a recording cut short by a write error
            # keeps its channels even if its first chunk never reached the disk
            from mcap.data_stream import RecordBuilder
            from mcap.records import Channel, Schema
            builder = RecordBuilder()
            if new_schema:
                Schema(id=self._schemas[tname], name=tname, encoding='ros2msg',
                       data=definition).write(builder)
            Channel(id=cid, topic=topic, message_encoding='cdr', schema_id=self._schemas[tname],
                    metadata=channel_metadata).write(builder)
            self._fh.write(builder.end())
            try:
                self._fh.commit()
            except OSError as exc:
                self._fail(exc, f'writing channel {topic}', None)

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """Write a metadata record now (outside the chunks: it survives a crash); once a name."""
        self._drain()
        with self._lock:
            if self._closed or name in self._written_records:
                return
            self._writer.add_metadata(name, values)
            self._written_records.add(name)
            try:
                self._fh.commit()
            except OSError as exc:
                self._fail(exc, f'writing {name}', None)

    def marker_magnification(self, value: float, t_ns: int) -> None:
        """Record a runtime marker_magnification: the markers after sim time t_ns carry it."""
        self._magnifications += 1
        self.add_metadata(f'{MAGNIFICATION_RECORD}.{self._magnifications}', {
            'log_time_ns': str(t_ns + self.offset_ns), 'value': json.dumps(float(value))})

    def drained_counts(self) -> dict[str, int]:
        """Return the messages recorded per topic, once every queued message is written."""
        self._drain()
        return dict(self.counts)

    def start_segment(self, parameters: dict[str, str], gap_ns: int,
                      ended: dict[str, dict[str, str]] | None = None) -> int:
        """
        Start a new segment (after a reset, maybe with new parameters).

        A new segment (after a reset with maybe new parameters): sim time restarts at 0,
        so from now on log times are offset to follow the previous segment's last message by
        gap_ns (log time never goes backwards; header stamps stay sim time).  A metadata
        record ``umbrella_sim.segment.K`` holds the offset and the segment's parameters.
        Returns K (the first segment, 0, is described by ``umbrella_sim.parameters``).
        ended: the run records of the segment that ends, by name (its events and summary,
        each written as ``name.K-1``: format.segment_record; the last segment's are written
        at close under their own names).
        """
        self._drain()
        with self._lock:
            if self._closed:
                return self.segment
            for name, values in (ended or {}).items():
                self._writer.add_metadata(segment_record(name, self.segment), values)
            self.segment += 1
            self.offset_ns = (self._last if self._last is not None else self.offset_ns) + gap_ns
            self._writer.add_metadata(f'{SEGMENT_RECORD}.{self.segment}', {
                'index': str(self.segment), 'log_time_offset_ns': str(self.offset_ns),
                'parameters': json.dumps(parameters)})
            try:
                self._fh.commit()
            except OSError as exc:
                self._fail(exc, f'writing segment {self.segment}', None)
            return self.segment

    def write(self, topic: str, msg, t_ns: int, data: bytes | None = None) -> bool:
        """
        Record one message at sim time t_ns (plus the segment's log-time offset).

        Record one message at sim time t_ns (plus the segment's log-time offset); False
        once the recording has stopped (closed or failed).  data: serialize_message(msg)
        when the caller has it already; msg None: data is the message's exact CDR
        (cdr_bytes, or ros_io's encoders: what the node publishes), written as it is.
        With a background writer the message is queued (msg must not be changed afterwards)
        and True means queued; a later write error shows in ``error``, ``on_error`` and the
        next call.
        """
        return self.write_all(((topic, msg, t_ns, data),))

    def write_all(self, records) -> bool:
        """Record messages (topic, msg, t_ns, data) in order, each as ``write`` does."""
        if self._closed:
            return False
        offset = self.offset_ns
        batch = [(topic, msg, t_ns + offset, data) for topic, msg, t_ns, data in records]
        if self._queue is not None:
            self._queue.extend(batch)
            if len(self._queue) >= self.QUEUE_LIMIT:      # full: wait for the writer
                with self._cv:
                    self._cv.notify_all()
                    while (len(self._queue) >= self.QUEUE_LIMIT
                           and self._writer_thread.is_alive()):
                        self._cv.wait(0.1)
            return True
        return self._write_many(batch)

    def _write_many(self, batch) -> bool:
        """Write messages (topic, msg, t_ns, data) in order; False once the recording stopped."""
        if self._closed:
            return False
        with self._lock:
            for topic, msg, t_ns, data in batch:
                if self._closed:
                    return False
                if msg is not None:   # else data is the exact CDR already (SampleEncoder)
                    data = cdr_bytes(msg, data)
                cid = self._channels[topic][0]
                seq = self.counts[topic]
                if self._appender is not None:
                    self._appender.add(cid, seq, t_ns, data)
                else:
                    self._writer.add_message(channel_id=cid, log_time=t_ns, publish_time=t_ns,
                                             data=data, sequence=seq)
                try:
                    wrote = self._fh.commit()
                except OSError as exc:
                    self._fail(exc, f'writing {topic}', t_ns)
                    return False
                self.counts[topic] = seq + 1
                if self._first is None or t_ns < self._first:
                    self._first = t_ns
                if self._last is None or t_ns > self._last:
                    self._last = t_ns
                if wrote:       # a chunk (holding this message) reached the file
                    self._on_disk = (dict(self.counts), self._last)
            return True

    def close(self, final_metadata: dict[str, dict[str, str]] | None = None) -> None:
        if self._queue is not None and self._writer_thread.is_alive():
            with self._cv:
                self._stop_writer = True
                self._cv.notify_all()
            self._writer_thread.join()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                for name, data in (final_metadata or {}).items():
                    self._writer.add_metadata(name, data)
                self._fh.commit()          # the counts and events first: they are small
                info = self._bag_info()
                self._writer.add_metadata('rosbag2', {
                    'serialized_metadata': yaml.safe_dump(info, sort_keys=False),
                    'ROS_DISTRO': 'jazzy'})
                self._writer.finish()
                self._release_index()
                self._fh.commit()
                self._fh.close()
            except OSError as exc:
                self._closed = False
                self._fail(exc, 'finalising', None)
                return
            try:
                self._write_bag_info()
            except OSError as exc:
                self.error = f'writing metadata.yaml: {exc.strerror or exc}'
                if self.on_error is not None:
                    self.on_error(self.error)

    def _write_bag_info(self) -> None:
        path = os.path.join(self.bag_dir, 'metadata.yaml')
        text = yaml.safe_dump({'rosbag2_bagfile_information': self._bag_info()},
                              sort_keys=False)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            write_all(fd, text.encode('utf-8'))
        except OSError:
            os.close(fd)
            os.unlink(path)       # no half-written metadata.yaml: readers fall back to the .mcap
            raise
        os.close(fd)

    def _bag_info(self) -> dict:
        start = self._first or 0
        duration = (self._last or 0) - start
        total = sum(self.counts.values())
        topics = [{'topic_metadata': {'name': topic, 'type': tname,
                                      'serialization_format': 'cdr',
                                      'offered_qos_profiles': qos_profiles(qos),
                                      'type_description_hash': type_description_hash(tname)},
                   'message_count': self.counts[topic]}
                  for topic, (_, tname, qos) in self._channels.items()]
        return {
            'version': BAG_FORMAT_VERSION, 'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': total, 'topics_with_message_count': topics,
            'compression_format': '', 'compression_mode': '',
            'relative_file_paths': [self.file_name],
            'files': [{'path': self.file_name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration}, 'message_count': total}],
            'custom_data': {}, 'ros_distro': 'jazzy',
        }
