"""
MCAP recording with the ROS 2 profile, laid out as rosbag2 writes it.

A recording is a bag directory ``NAME/`` holding ``NAME_0.mcap`` and ``metadata.yaml`` (bag
metadata version 8).  The .mcap also stands alone: profile ``ros2``, one ``ros2msg`` schema
per type (the full .msg text with its dependencies), ``cdr`` messages from
rclpy.serialization trimmed to the exact CDR size, ``offered_qos_profiles`` on every
channel, log/publish times in sim time (ns), zstd chunks with message indexes, a Statistics
record, and at close a ``rosbag2`` metadata record (``serialized_metadata``) like rosbag2's
MCAP plugin.

Self-describing: metadata records ``umbrella_sim.parameters`` (every parameter, including the
physics step actually used), ``umbrella_sim.build`` (version, git revision, kernel),
``umbrella_sim.mesh`` and, at close, ``umbrella_sim.counts`` (messages published / commands
received per topic).  They are written outside chunks at once, so they survive a crash.
"""
from __future__ import annotations

import collections
import itertools
import json
import os
import struct
import subprocess
import sys
import threading

from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import CompressionType, IndexType, Writer
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
import yaml

from .paths import check_new_output
from .reader import SEGMENT_RECORD, TOPICS_RECORD
from .. import __version__
from ..ros.signals import deferred

CHUNK_SIZE = 64 * 1024
DELIMITER = "=" * 80
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}
_INFINITE = {"sec": 9223372036, "nsec": 854775807}


# ------------------------------------------------------------------ type metadata
def type_name(msg_or_type) -> str:
    """'sensor_msgs/msg/JointState' for a message class or instance."""
    cls = msg_or_type if isinstance(msg_or_type, type) else type(msg_or_type)
    pkg = cls.__module__.split(".")[0]
    return f"{pkg}/msg/{cls.__name__}"


def _share_dirs() -> list[str]:
    dirs = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    dirs.append(sys.prefix)
    return [os.path.join(d, "share") for d in dirs]


def _msg_text(full_name: str) -> str:
    pkg, _, name = full_name.split("/")
    for share in _share_dirs():
        path = os.path.join(share, pkg, "msg", name + ".msg")
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as fh:
                return fh.read()
    raise FileNotFoundError(f"message definition {full_name}.msg not found under "
                            "AMENT_PREFIX_PATH or the interpreter's share/")


def _dependencies(pkg: str, text: str) -> list[str]:
    """Message types used by the fields of a .msg text (constants are always primitive)."""
    deps = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        base = line.split()[0].split("[", 1)[0].split("<=", 1)[0]
        if base in _PRIMITIVES:
            continue
        p, n = (base.split("/")[0], base.split("/")[-1]) if "/" in base else (pkg, base)
        deps.append(f"{p}/msg/{n}")
    return deps


def message_definition(full_name: str) -> str:
    """
    Return the ros2msg 'complete message definition'.

    The type's .msg text, then every dependency
    after a line of 80 '=' and 'MSG: pkg/msg/Type' (rosbag2 docs/message_definition_encoding).
    """
    order: list[str] = []
    texts: dict[str, str] = {}

    def visit(name: str) -> None:
        if name in texts:
            return
        texts[name] = _msg_text(name)
        order.append(name)
        for dep in _dependencies(name.split("/")[0], texts[name]):
            visit(dep)

    visit(full_name)
    parts = [texts[order[0]].rstrip("\n")]
    for name in order[1:]:
        parts.append(f"{DELIMITER}\nMSG: {name}\n{texts[name].rstrip(chr(10))}")
    return "\n".join(parts) + "\n"


def qos_yaml(qos: QoSProfile) -> str:
    """offered_qos_profiles as rosbag2 writes it (enum values as integers)."""
    profile = {
        "history": int(qos.history), "depth": int(qos.depth),
        "reliability": int(qos.reliability), "durability": int(qos.durability),
        "deadline": dict(_INFINITE), "lifespan": dict(_INFINITE),
        "liveliness": int(qos.liveliness), "liveliness_lease_duration": dict(_INFINITE),
        "avoid_ros_namespace_conventions": False,
    }
    return yaml.safe_dump([profile], sort_keys=False).rstrip("\n")


# --------------------------------------------------------------- exact CDR size
_SIZES = {"boolean": 1, "octet": 1, "char": 1, "uint8": 1, "int8": 1, "int16": 2, "uint16": 2,
          "int32": 4, "uint32": 4, "float": 4, "int64": 8, "uint64": 8, "double": 8,
          "long double": 16, "wchar": 2}


def _align(pos: int, n: int, pads: list | None = None) -> int:
    """Return pos aligned to n, noting the gap in pads (CDR padding) if any."""
    end = (pos + n - 1) // n * n
    if pads is not None and end > pos:
        pads.append((pos, end))
    return end


#: message class -> its fields' size functions (built once per type: the walk runs for every
#: recorded message, so the type strings are parsed once, not per message)
_PLANS: dict = {}


def _cdr_end(msg, pos: int, pads: list | None = None) -> int:
    """Return where msg's CDR ends from pos; pads: collects its alignment gaps (start, end)."""
    plan = _PLANS.get(type(msg))
    if plan is None:
        plan = _PLANS[type(msg)] = [(field, _field_size(ftype)) for field, ftype
                                    in msg.get_fields_and_field_types().items()]
    for field, size in plan:
        pos = size(getattr(msg, field), pos, pads)
    return pos


def _field_size(ftype: str):
    """Return size(value, pos, pads) -> end position of one field of IDL type ftype."""
    if ftype.startswith("sequence<"):
        items = _items_size(ftype[len("sequence<"):-1].rsplit(",", 1)[0].strip())
        return lambda value, pos, pads: items(value, _align(pos, 4, pads) + 4, pads)
    if ftype.endswith("]"):
        return _items_size(ftype[:ftype.index("[")])
    items = _items_size(ftype)
    return lambda value, pos, pads: items((value,), pos, pads)


def _items_size(ftype: str):
    """Return size(values, pos, pads) -> end position of consecutive items of IDL type ftype."""
    if ftype.startswith("wstring"):
        def size(values, pos, pads):
            for v in values:
                pos = _align(pos, 4, pads) + 4 + 4 * (len(v) + 1)
            return pos
        return size
    if ftype.startswith("string"):
        def size(values, pos, pads):
            for v in values:
                pos = _align(pos, 4, pads) + 4 + len(v.encode("utf-8")) + 1
            return pos
        return size
    n = _SIZES.get(ftype)
    if n is not None:
        def size(values, pos, pads):
            k = len(values)
            return _align(pos, n, pads) + n * k if k else pos
        return size

    def size(values, pos, pads):                    # nested messages
        for v in values:
            pos = _cdr_end(v, pos, pads)
        return pos
    return size


def cdr_bytes(msg, data: bytes | None = None) -> bytes:
    """
    Serialise to CDR, trimmed to the exact size, with zero padding.

    rclpy may return a few padding bytes more, which rosbags rejects; ros2 bag record writes
    the exact size.  The alignment gaps are set to 0: the serializer leaves whatever its
    buffer held there, so the same message would serialize to different bytes from one
    process to the next, and a recording would depend on the process that made it.  data:
    msg already serialized, to serialize once.
    """
    if data is None:
        data = serialize_message(msg)
    pads: list = []
    size = 4 + _cdr_end(msg, 0, pads)           # 4-byte encapsulation header
    if size > len(data):
        raise RuntimeError(f"CDR size walk overran the payload for {type_name(msg)}")
    if not pads:
        return data[:size]
    out = bytearray(data[:size])
    for start, end in pads:                     # positions after the 4-byte header
        out[4 + start:4 + end] = bytes(end - start)
    return bytes(out)


# ------------------------------------------------------------------- provenance
def git_revision() -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        out = subprocess.run(["git", "-C", here, "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5)
        if out.returncode == 0:
            dirty = subprocess.run(["git", "-C", here, "status", "--porcelain", "--", "."],
                                   capture_output=True, text=True, timeout=5).stdout.strip()
            return out.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return "unknown"


def build_environment() -> dict[str, str]:
    """
    Return what sets a run's floating-point round-off besides the code.

    numpy, its BLAS kernel (OpenBLAS picks one per CPU unless OPENBLAS_CORETYPE names it)
    and the CPU.  The model's matrices go through BLAS; another kernel rounds them
    differently in the last bit, so a re-simulation elsewhere agrees to round-off, not bit
    for bit.
    """
    import platform

    import numpy

    cpu = platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            cpu = next((line.split(":", 1)[1].strip() for line in fh
                        if line.startswith("model name")), cpu)
    except OSError:
        pass
    return {"numpy": numpy.__version__,
            "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE", "auto"), "cpu": cpu}


def run_metadata(params, node_cfg: dict, physics_step: float, model, backend: str,
                 source: str) -> dict[str, dict[str, str]]:
    """Metadata records that make a log reproducible from the file alone."""
    all_params = dict(params.as_dict())
    all_params.update(node_cfg)
    all_params["physics_step"] = physics_step
    return {
        "umbrella_sim.parameters": {k: json.dumps(v) for k, v in all_params.items()},
        "umbrella_sim.build": {"package_version": __version__, "git_revision": git_revision(),
                               "kernel": backend, "source": source,
                               "python": sys.version.split()[0], **build_environment()},
        "umbrella_sim.mesh": {
            "model": params.model, "lock": params.lock,
            "elements_per_segment": str(params.elements_per_segment),
            "coordinates": json.dumps(model.coordinate_labels()),
            "leaf_node_x": json.dumps(list(model.leaf.node_x)),
            "link_node_x": json.dumps(list(model.link.node_x)),
        },
    }


def events_metadata(sim, fault: str | None = None) -> dict[str, dict[str, str]]:
    """
    Return the events record: the exact lock instant and the fault, if any.

    The exact lock instant (the phase message comes at the next publication) and the
    solver fault that ended the run, if any (at the last good state's time).
    """
    ev = sim.lock_event
    out = {"locked": "false"} if ev is None else {
        "locked": "true", "lock_time": repr(ev.time), "lock_kind": ev.kind,
        "energy_before": repr(ev.energy_before), "energy_after": repr(ev.energy_after)}
    if fault is not None:
        out.update(fault=fault, fault_time=repr(sim.time))
    return {"umbrella_sim.events": out}


# ---------------------------------------------------------------------- recorder
def default_bag_name(namespace: str = "/", when: float | None = None) -> str:
    """Return umbrella[_ns]_YYYY_MM_DD-HH_MM_SS, as ros2 bag record names its bags."""
    import time

    ns = namespace.strip("/").replace("/", "_")
    stamp = time.strftime("%Y_%m_%d-%H_%M_%S", time.localtime(when))
    return "_".join(["umbrella"] + ([ns] if ns else []) + [stamp])


def new_bag_recorder(namespace: str, metadata, parent: str = ".",
                     on_error=None, background: bool = False) -> "BagRecorder":
    """
    Open a new timestamped bag directory in parent (default: the working directory).

    Never overwrites: when the name is taken (two antennas started in the same second, or
    a bag left from a run a moment ago) the next free NAME_1, NAME_2, ... is used.
    metadata(bag_dir) returns the run's metadata records.
    """
    base = os.path.join(os.path.abspath(parent), default_bag_name(namespace))
    for k in range(1000):
        bag_dir = base if k == 0 else f"{base}_{k}"
        if os.path.exists(bag_dir):
            continue
        try:
            return BagRecorder(bag_dir, metadata(bag_dir), on_error=on_error,
                               background=background)
        except ValueError:
            if os.path.exists(bag_dir):      # taken meanwhile by another process: next name
                continue
            raise
    raise ValueError(f"recording: no free bag directory name {base}_N in {parent}")


def _write_all(fd: int, data) -> None:
    """os.write until everything is written (the one place bytes reach the file)."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


class _CommittedFile:
    """
    Write the MCAP writer's records to the file between records only.

    The MCAP writer's stream: buffers records in memory and writes them to the file only
    on commit(), which happens between records.  A failed commit (ENOSPC, EIO, EACCES...)
    truncates the file back to the last committed record boundary, so the file never holds
    a torn record and the space of the failed write is given back.
    """

    def __init__(self, path: str):
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.committed = 0
        self._pending = bytearray()

    def write(self, data) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self.committed + len(self._pending)

    def flush(self) -> None:           # the writer's flush(); commits happen explicitly
        pass

    def commit(self) -> bool:
        """Write what is pending; True if anything was written."""
        if not self._pending:
            return False
        # an immutable copy: a failed os.write leaves views of its buffer in the traceback,
        # and a bytearray with live views cannot be cleared (BufferError on a full tmpfs)
        data = bytes(self._pending)
        self._pending.clear()
        try:
            _write_all(self.fd, data)
        except OSError:
            self.rollback()
            raise
        self.committed += len(data)
        return True

    def rollback(self) -> None:
        try:
            os.ftruncate(self.fd, self.committed)
            os.lseek(self.fd, self.committed, os.SEEK_SET)
        except OSError:
            pass

    def close(self, sync: bool = True) -> None:
        if self.fd < 0:
            return
        try:
            if sync:
                os.fsync(self.fd)
        finally:
            os.close(self.fd)
            self.fd = -1


def _ended_early_tail(metadata: dict[str, str]) -> bytes:
    """
    Return the trailer of a recording stopped by a write error.

    A Metadata record, DataEnd and a Footer without summary: appended at the last record
    boundary, it makes a failed recording a complete MCAP again that says why it ended.
    """
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer, Metadata

    builder = RecordBuilder()
    Metadata(name=ENDED_EARLY_RECORD, metadata=metadata).write(builder)
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return bytes(builder.end()) + b"\x89MCAP0\r\n"


class _SpilledChunkIndex:
    """
    The MCAP writer's chunk index, kept on disk while recording (bounded memory).

    The writer keeps one ChunkIndex object per chunk until finish() writes the summary
    section (measured: ~1.2 kB of Python objects per 64 KiB chunk, 8 to 15 kB per simulated
    second at 1 kHz, growing without bound).  This list stand-in serialises each index to
    its MCAP record at once (~190 bytes) and moves the records to an anonymous temporary
    file next to the recording (unlinked from the start: nothing is left behind) every
    64 KiB; finish() reads them back in order into the summary, which therefore still holds
    every chunk index (readers seek by time as before).  If the temporary file cannot be
    written (disk full) the records stay in memory: the recording itself fails soon after.
    """

    SPILL_BYTES = 64 * 1024

    def __init__(self, directory: str):
        import tempfile

        self._records = bytearray()
        self.count = 0
        try:
            self._file = tempfile.TemporaryFile(dir=directory)
        except OSError:
            self._file = None

    def append(self, index) -> None:
        from mcap.data_stream import RecordBuilder

        builder = RecordBuilder()
        index.write(builder)
        self._records += builder.end()
        self.count += 1
        if self._file is not None and len(self._records) >= self.SPILL_BYTES:
            try:
                self._file.write(self._records)
                self._records.clear()
            except OSError:
                pass

    def __len__(self) -> int:
        return self.count

    def __iter__(self):
        """Yield the records in order, in pieces the writer copies into its summary."""
        if self._file is not None:
            self._file.flush()
            self._file.seek(0)
            while True:
                piece = self._file.read(1 << 20)
                if not piece:
                    break
                yield _RawRecords(piece)
        yield _RawRecords(bytes(self._records))

    def in_memory_bytes(self) -> int:
        return len(self._records)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


class _RawRecords:
    """Already serialised MCAP records, written as they are."""

    def __init__(self, data: bytes):
        self.data = data

    def write(self, builder) -> None:
        builder.write(self.data)


#: metadata record of a recording that stopped on a write error (see msg_docs/recording.md)
ENDED_EARLY_RECORD = "umbrella_sim.recording_error"
#: metadata records umbrella_sim.segment.K: a reset started segment K (msg_docs/recording.md)


#: a Message record up to its data: opcode, record length, channel id, sequence, log time,
#: publish time (the MCAP specification's Message record)
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")


class _PackedMessageIndex(MessageIndex):
    """A chunk's MessageIndex record written in one struct.pack (the same bytes)."""

    def write(self, stream) -> None:
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(self.records) * 16)
        stream.write(struct.pack(f"<{2 * len(self.records)}Q",
                                 *itertools.chain.from_iterable(self.records)))
        stream.finish_record()


class _MessageAppender:
    """
    Append Message records to the open chunk of an mcap Writer, one struct.pack each.

    What ``Writer.add_message`` does for a chunked writer (the statistics, the chunk's time
    range and message index, the record, closing a full chunk) without building a Message
    object and writing its five fields one by one, and with each chunk's message indexes
    packed at once (_PackedMessageIndex).  ``create`` returns None where this mcap version
    lacks the members it uses; ``add_message`` serves then.  The files are byte for byte
    those of ``add_message`` (tests/test_recorder_background.py).
    """

    def __init__(self, stats, chunk, finish_full_chunk):
        self.stats = stats
        self.chunk = chunk
        self.finish_full_chunk = finish_full_chunk

    @classmethod
    def create(cls, writer: Writer) -> "_MessageAppender | None":
        stats = getattr(writer, "_Writer__statistics", None)
        chunk = getattr(writer, "_Writer__chunk_builder", None)
        finish = getattr(writer, "_Writer__maybe_finalize_chunk", None)
        needed = (hasattr(stats, "channel_message_counts") and hasattr(chunk, "message_indices")
                  and hasattr(getattr(chunk, "record_writer", None), "_buffer")
                  and callable(finish))
        return cls(stats, chunk, finish) if needed else None

    def add(self, channel_id: int, sequence: int, t_ns: int, data: bytes) -> None:
        st = self.stats
        if st.message_count == 0 or t_ns < st.message_start_time:
            st.message_start_time = t_ns
        if t_ns > st.message_end_time:
            st.message_end_time = t_ns
        st.channel_message_counts[channel_id] += 1
        st.message_count += 1
        chunk = self.chunk
        if chunk.num_messages == 0 or t_ns < chunk.message_start_time:
            chunk.message_start_time = t_ns
        if t_ns > chunk.message_end_time:
            chunk.message_end_time = t_ns
        stream = chunk.record_writer._buffer      # a new one after every finished chunk
        index = chunk.message_indices.get(channel_id)
        if index is None:
            index = chunk.message_indices[channel_id] = _PackedMessageIndex(
                channel_id=channel_id, records=[])
        index.records.append((t_ns, stream.tell()))
        chunk.num_messages += 1
        stream.write(_MESSAGE_HEAD.pack(Opcode.MESSAGE, 22 + len(data), channel_id, sequence,
                                        t_ns, t_ns))
        stream.write(data)
        self.finish_full_chunk()


def check_record_path(bag_dir: str, what: str = "record_path") -> str:
    """
    Return the absolute bag directory, or raise ValueError why it cannot be created.

    The absolute bag directory, or ValueError naming why it cannot be created (cheap
    checks before any simulation work; nothing is created; never overwrites).
    """
    return check_new_output(bag_dir, what)


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
                 background: bool = False):
        bag_dir = check_record_path(bag_dir)
        try:
            os.mkdir(bag_dir)
        except OSError as exc:
            raise ValueError(f"record_path {bag_dir}: {exc.strerror}") from None
        self.bag_dir = bag_dir
        self.file_name = os.path.basename(bag_dir) + "_0.mcap"
        self.path = os.path.join(bag_dir, self.file_name)
        self.error: str | None = None
        self.on_error = on_error
        self._fh = None
        self._chunk_index = None
        try:
            # committed after every write: a finished chunk reaches the OS at once, so a
            # SIGKILL loses only the chunk being filled (messages accumulate in memory)
            self._fh = _CommittedFile(self.path)
            self._writer = Writer(self._fh, chunk_size=CHUNK_SIZE,
                                  compression=CompressionType.ZSTD,
                                  index_types=IndexType.ALL, use_chunking=True,
                                  use_statistics=True)
            # the writer's growing chunk index goes to disk (mcap's private list, replaced
            # where this mcap version has it; otherwise it stays in memory as before)
            self._chunk_index = _SpilledChunkIndex(bag_dir)
            if isinstance(getattr(self._writer, "_Writer__chunk_indices", None), list):
                self._writer._Writer__chunk_indices = self._chunk_index
            self._appender = _MessageAppender.create(self._writer)
            self._writer.start(profile="ros2", library=f"umbrella_sim {__version__}")
            for name, data in metadata.items():
                self._writer.add_metadata(name, data)
            self._written_records = set(metadata)
            self._fh.commit()
        except OSError as exc:
            self._remove_partial()
            raise ValueError(f"record_path {bag_dir}: cannot start the recording: "
                             f"{exc.strerror or exc}") from None
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._schema_written: set[int] = set()
        self._channels: dict[str, tuple[int, str, QoSProfile]] = {}
        self.counts: dict[str, int] = {}
        self._first = self._last = None
        self._on_disk: tuple[dict, int | None] = ({}, None)   # counts, last time in the file
        self._closed = False
        self.segment = 0
        self.offset_ns = 0
        self._queue = None
        if background:
            self._queue = collections.deque()        # append/popleft are thread-safe
            self._cv = threading.Condition()
            self._writing = False
            self._stop_writer = False
            self._writer_thread = threading.Thread(target=self._write_queued,
                                                   name="recorder", daemon=True)
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
                            self._fail(OSError(f"{type(exc).__name__}: {exc}"), "recording",
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
        self.error = f"{what}: {exc.strerror or exc} (errno {exc.errno})" if exc.errno else \
            f"{what}: {exc}"
        self._closed = True
        # what the file holds: the messages of the chunks written before the failure (the
        # chunk being filled was only in memory)
        counts, last = self._on_disk
        self.counts = {topic: counts.get(topic, 0) for topic in self.counts}
        self._last = last
        meta = {"ended_early": "true", "error": self.error,
                "last_log_time_ns": "" if last is None else str(last),
                "failed_at_log_time_ns": "" if t_ns is None else str(t_ns),
                "recorded": json.dumps(self.counts)}
        try:
            _write_all(self._fh.fd, _ended_early_tail(meta))
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
            if tname not in self._schemas:
                self._schemas[tname] = self._writer.register_schema(
                    name=tname, encoding="ros2msg",
                    data=message_definition(tname).encode("utf-8"))
            cid = self._writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=self._schemas[tname],
                metadata={"offered_qos_profiles": qos_yaml(qos)})
            self._channels[topic] = (cid, tname, qos)
            self.counts[topic] = 0
            # the writer puts Schema and Channel records into the chunk being filled; repeat
            # them outside chunks now, so that a recording cut short by a write error keeps
            # its channels even if its first chunk never reached the disk (MCAP allows
            # identical repeats)
            from mcap.data_stream import RecordBuilder
            from mcap.records import Channel, Schema
            builder = RecordBuilder()
            if self._schemas[tname] not in self._schema_written:
                Schema(id=self._schemas[tname], name=tname, encoding="ros2msg",
                       data=message_definition(tname).encode("utf-8")).write(builder)
                self._schema_written.add(self._schemas[tname])
            Channel(id=cid, topic=topic, message_encoding="cdr", schema_id=self._schemas[tname],
                    metadata={"offered_qos_profiles": qos_yaml(qos)}).write(builder)
            self._fh.write(builder.end())
            try:
                self._fh.commit()
            except OSError as exc:
                self._fail(exc, f"writing channel {topic}", None)

    def add_umbrella_channels(self, topic_names: dict, command_topic: str,
                              qos: dict | None = None) -> None:
        """
        Add the channels of an umbrella_sim run, live or offline.

        Every published topic (topic key -> resolved name) with the QoS it is published with
        (qos: topic key -> profile, the node's after qos_overrides; else ros_io.TOPICS's) and
        the command with its refused/applied records.
        """
        from std_msgs.msg import Float64

        from ..ros import messages as ros_io
        resolved = {}       # the node's own topic name -> the name recorded (remapped)
        for key, name in topic_names.items():
            self.add_channel(name, ros_io.TOPICS[key].type,
                             (qos or {}).get(key, ros_io.TOPICS[key].qos))
            resolved[ros_io.TOPICS[key].name.lstrip("/")] = name
        for suffix in ("", ros_io.COMMAND_REFUSED_SUFFIX, ros_io.COMMAND_APPLIED_SUFFIX):
            self.add_channel(command_topic + suffix, Float64, ros_io.COMMAND.qos)
            resolved[ros_io.COMMAND.name.lstrip("/") + suffix] = command_topic + suffix
        with self._lock:    # so that the tools find each topic however it was remapped
            if not self._closed and TOPICS_RECORD not in self._written_records:
                self._writer.add_metadata(TOPICS_RECORD, resolved)
                self._written_records.add(TOPICS_RECORD)

    def close_run(self, sim, published: dict, accepted: int, refused: int,
                  fault: str | None = None, extra: dict | None = None,
                  summary: dict | None = None) -> None:
        """
        Finalise with the counts, the exact lock event and the fault, if any.

        Finalise with the counts (published vs recorded), the exact lock event and the
        fault, if any; extra: more counts (e.g. refused commands not recorded); summary:
        the summary record (summary_metadata).
        """
        self._drain()       # the background writer's queue first: "recorded" counts all of it
        self.close({"umbrella_sim.counts": {
            "published": json.dumps(published), "commands_accepted": str(accepted),
            "commands_refused": str(refused), "recorded": json.dumps(self.counts),
            **(extra or {})},
            **events_metadata(sim, fault), **(summary or {})})

    def start_segment(self, parameters: dict[str, str], gap_ns: int,
                      ended_events: dict[str, str] | None = None) -> int:
        """
        Start a new segment (after a reset, maybe with new parameters).

        A new segment (after a reset with maybe new parameters): sim time restarts at 0,
        so from now on log times are offset to follow the previous segment's last message by
        gap_ns (log time never goes backwards; header stamps stay sim time).  A metadata
        record ``umbrella_sim.segment.K`` holds the offset and the segment's parameters.
        Returns K (the first segment, 0, is described by ``umbrella_sim.parameters``).
        ended_events: the events of the segment that ends (``umbrella_sim.events.K-1``; the
        last segment's are ``umbrella_sim.events``, written at close).
        """
        self._drain()
        with self._lock:
            if self._closed:
                return self.segment
            if ended_events is not None:
                self._writer.add_metadata(f"umbrella_sim.events.{self.segment}", ended_events)
            self.segment += 1
            self.offset_ns = (self._last if self._last is not None else self.offset_ns) + gap_ns
            self._writer.add_metadata(f"{SEGMENT_RECORD}.{self.segment}", {
                "index": str(self.segment), "log_time_offset_ns": str(self.offset_ns),
                "parameters": json.dumps(parameters)})
            try:
                self._fh.commit()
            except OSError as exc:
                self._fail(exc, f"writing segment {self.segment}", None)
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
        if self._closed:
            return False
        t_ns += self.offset_ns
        if self._queue is not None:
            self._queue.append((topic, msg, t_ns, data))
            if len(self._queue) >= self.QUEUE_LIMIT:      # full: wait for the writer
                with self._cv:
                    self._cv.notify_all()
                    while (len(self._queue) >= self.QUEUE_LIMIT
                           and self._writer_thread.is_alive()):
                        self._cv.wait(0.1)
            return True
        return self._write_now(topic, msg, t_ns, data)

    def _write_now(self, topic: str, msg, t_ns: int, data: bytes | None) -> bool:
        return self._write_many(((topic, msg, t_ns, data),))

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
                    self._fail(exc, f"writing {topic}", t_ns)
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
                self._writer.add_metadata("rosbag2", {
                    "serialized_metadata": yaml.safe_dump(info, sort_keys=False),
                    "ROS_DISTRO": "jazzy"})
                self._writer.finish()
                self._release_index()
                self._fh.commit()
                self._fh.close()
            except OSError as exc:
                self._closed = False
                self._fail(exc, "finalising", None)
                return
            try:
                self._write_bag_info()
            except OSError as exc:
                self.error = f"writing metadata.yaml: {exc.strerror or exc}"
                if self.on_error is not None:
                    self.on_error(self.error)

    def _write_bag_info(self) -> None:
        path = os.path.join(self.bag_dir, "metadata.yaml")
        text = yaml.safe_dump({"rosbag2_bagfile_information": self._bag_info()},
                              sort_keys=False)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            _write_all(fd, text.encode("utf-8"))
        except OSError:
            os.close(fd)
            os.unlink(path)       # no half-written metadata.yaml: readers fall back to the .mcap
            raise
        os.close(fd)

    def _bag_info(self) -> dict:
        start = self._first or 0
        duration = (self._last or 0) - start
        total = sum(self.counts.values())
        topics = [{"topic_metadata": {"name": topic, "type": tname,
                                      "serialization_format": "cdr",
                                      "offered_qos_profiles": qos_yaml(qos),
                                      "type_description_hash": ""},
                   "message_count": self.counts[topic]}
                  for topic, (_, tname, qos) in self._channels.items()]
        return {
            # version 8: offered_qos_profiles as a YAML string with integer enums, which is
            # what qos_yaml() writes (version 9 switched to a list with enum names)
            "version": 8, "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": total, "topics_with_message_count": topics,
            "compression_format": "", "compression_mode": "",
            "relative_file_paths": [self.file_name],
            "files": [{"path": self.file_name,
                       "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": total}],
            "custom_data": {}, "ros_distro": "jazzy",
        }


# ------------------------------------------------------------------ offline runs
#: metadata record of the run's summary figures from every physics step (recording.md)
SUMMARY_RECORD = "umbrella_sim.summary"


def summary_metadata(figures: dict) -> dict[str, dict[str, str]]:
    """
    Return the summary metadata record: figures of every physics step and the warnings.

    From outputs.SummaryAccumulator.figures(), so that umbrella_compare reports the
    physics, not the recorded samples.
    """
    return {SUMMARY_RECORD: {
        "figures": json.dumps({k: v for k, v in figures.items() if k != "warnings"}),
        "warnings": json.dumps(figures.get("warnings", [])),
        "source": "every physics step"}}


def record_offline(params, bag_dir: str, duration: float, force_profile=None,
                   publish_rate: float = 100.0, marker_magnification: float = 1.0,
                   progress=None):
    """
    Run the physics offline and record it as a live umbrella_node would.

    Steps through solver.simulate (the one offline driver: same states as ``umbrella_sim
    simulate`` without a recording) and publishes through the node's publication path,
    recording the same topics, layout and metadata as a live umbrella_node (root
    namespace).  Returns the RunResult with the samples at the publication instants
    (error set if it diverged).
    """
    import time as _time

    from diagnostic_msgs.msg import DiagnosticStatus
    from std_msgs.msg import Float64

    from ..core.forcing import command_force, ForceSchedule
    from ..core.params import node_defaults
    from ..core.solver import simulate
    from ..ros import messages as ros_io
    from ..ros.publication import PublicationDriver

    node_cfg = node_defaults()
    node_cfg.update(publish_rate=publish_rate, real_time_factor=0.0, duration=duration,
                    record_path=bag_dir, marker_magnification=marker_magnification)
    driver = PublicationDriver(params, publish_rate)
    sim = driver.sim
    profile = sorted(force_profile or [], key=lambda tf: tf[0])
    # checked before the bag is created
    schedule = ForceSchedule(sim.h, sim.sleeve_force, profile,
                             check=lambda f: command_force(f, sim.params))
    rec = BagRecorder(bag_dir, run_metadata(params, node_cfg, driver.step, sim.model,
                                            driver.backend, source="umbrella_sim simulate"))
    topics = {key: "/" + t.name.lstrip("/") for key, t in ros_io.TOPICS.items()}
    command = "/" + ros_io.COMMAND.name
    rec.add_umbrella_channels(topics, command)
    published: dict[str, int] = {}
    state = {"next_diag": 1.0, "i_cmd": 0}
    wall0 = _time.perf_counter()

    def publish(key, msg, t):
        published[topics[key]] = published.get(topics[key], 0) + 1
        if isinstance(msg, bytes):      # exact CDR from ros_io.SampleEncoder, as the node's
            rec.write(topics[key], None, ros_io.stamp_ns(t), msg)
        else:
            rec.write(topics[key], msg, ros_io.stamp_ns(t))

    def commands_until(t):
        # each command at its own time, as the node records one at receipt
        while state["i_cmd"] < len(profile) and profile[state["i_cmd"]][0] <= t + 1e-12:
            t_cmd, f_cmd = profile[state["i_cmd"]]
            rec.write(command, Float64(data=float(f_cmd)), ros_io.stamp_ns(t_cmd))
            state["i_cmd"] += 1

    def publication():
        t = sim.time
        for key, msg in driver.messages("umbrella", marker_magnification).items():
            publish(key, msg, t)
        if t >= state["next_diag"] - 1e-12:
            wall = _time.perf_counter() - wall0
            publish("diagnostics", ros_io.diagnostics_msg(
                t, "umbrella_sim offline: physics", DiagnosticStatus.OK, "offline",
                {"sim_time_s": f"{t:.6f}", "measured_real_time_factor":
                 f"{t / wall:.4f}" if wall > 0 else "inf", "steps": sim.steps,
                 "physics_step_s": sim.h}), t)
            state["next_diag"] += 1.0

    def on_output(block, applied):
        with deferred():    # a stop signal lands between periods, never inside a write
            record_period(block, applied)

    def record_period(block, applied):
        commands_until(sim.time)
        for ev in driver.take(block, applied):
            if ev.kind == "applied":    # at the step it acts from, as the node records it
                rec.write(command + ros_io.COMMAND_APPLIED_SUFFIX, Float64(data=ev.force),
                          ros_io.stamp_ns(ev.time))
            else:
                publish("deployment_phase", ros_io.phase_msg("locked"), sim.time)
        if block.error is not None:
            publish("deployment_phase", ros_io.phase_msg("fault"), sim.time)
        elif sim.step_index % driver.publish_every == 0:
            publication()

    result = None
    try:
        publish("deployment_phase", ros_io.phase_msg("deploying"), 0.0)
        commands_until(0.0)
        publication()
        result = simulate(params, duration, schedule, progress=progress, simulator=sim,
                          output_every=driver.publish_every, on_output=on_output,
                          summary=driver.summary)
    finally:    # interrupted: the summary of every step computed, as the node's at a stop
        rec.close_run(sim, published, accepted=state["i_cmd"], refused=0,
                      fault=result.error if result is not None else None,
                      summary=summary_metadata(driver.summary.figures()))
    result.recording_error = rec.error
    result.wall_time = _time.perf_counter() - wall0
    return result
