"""
Reading recorded runs back: a bag directory or a single .mcap, finalised or not.

A finalised file is read through its summary and indexes.  A file whose writer was killed
(SIGKILL: no summary, no footer) is read record by record from the start: every complete
chunk is recovered and the torn tail is dropped (``LogData.truncated`` says so).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import importlib
import json
import os

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk, StreamReader
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
import yaml

MCAP_MAGIC = b"\x89MCAP0\r\n"


class LogError(ValueError):
    """A log that cannot be used, with the reason (file, topic) in the message."""


@dataclass
class RawMessage:
    topic: str
    log_time: int
    data: bytes


@dataclass
class LogData:
    path: str
    channels: dict = field(default_factory=dict)      # topic -> (type name, qos yaml)
    messages: list = field(default_factory=list)      # RawMessage, file order
    metadata: dict = field(default_factory=dict)      # record name -> {key: value}
    truncated: bool = False
    _types: dict = field(default_factory=dict)

    def topics(self) -> list[str]:
        return sorted(self.channels)

    def find_topic(self, suffix: str, required: bool = True) -> str | None:
        matches = [t for t in self.channels if t == suffix or t.endswith("/" + suffix.lstrip("/"))]
        matches = [t for t in matches if not t.endswith(("/refused", "/applied"))
                   or suffix.endswith(("/refused", "/applied"))]
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
            self._types[topic] = import_type(self.channels[topic][0])
        return self._types[topic]

    def decoded(self, topic: str) -> list[tuple[float, object]]:
        """[(log time in s, message)] of one topic, in log-time order."""
        cls = self.msg_type(topic)
        out = [(m.log_time * 1e-9, deserialize_message(m.data, cls))
               for m in self.messages if m.topic == topic]
        out.sort(key=lambda tm: tm[0])
        return out

    def count(self, topic: str) -> int:
        return sum(1 for m in self.messages if m.topic == topic)

    def parameters(self) -> dict:
        rec = self.metadata.get("umbrella_sim.parameters")
        if rec is None:
            raise LogError(f"{self.path}: no umbrella_sim.parameters metadata record "
                           "(not recorded by umbrella_sim?)")
        return {k: json.loads(v) for k, v in rec.items()}


def import_type(type_name: str):
    try:
        pkg, kind, name = type_name.split("/")
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ValueError, ImportError, AttributeError):
        raise LogError(f"message type {type_name} is not available here") from None


def qos_from_yaml(text: str) -> QoSProfile:
    try:
        prof = (yaml.safe_load(text) or [{}])[0]
        return QoSProfile(history=HistoryPolicy(int(prof.get("history", 1))),
                          depth=max(int(prof.get("depth", 10)), 1),
                          reliability=ReliabilityPolicy(int(prof.get("reliability", 1))),
                          durability=DurabilityPolicy(int(prof.get("durability", 2))))
    except Exception:
        return QoSProfile(depth=10)


def resolve_path(path: str) -> str:
    """Return the .mcap of a bag directory (metadata.yaml, else the only .mcap), or the file."""
    if os.path.isdir(path):
        meta = os.path.join(path, "metadata.yaml")
        if os.path.isfile(meta):
            try:
                info = yaml.safe_load(open(meta, encoding="utf-8"))["rosbag2_bagfile_information"]
                return os.path.join(path, os.path.basename(info["relative_file_paths"][0]))
            except (KeyError, IndexError, TypeError, yaml.YAMLError):
                raise LogError(f"{meta}: not a rosbag2 metadata file") from None
        found = [f for f in sorted(os.listdir(path)) if f.endswith(".mcap")]
        if len(found) != 1:
            raise LogError(f"{path}: a bag directory needs metadata.yaml or exactly one .mcap "
                           f"(found {len(found)})")
        return os.path.join(path, found[0])
    if not os.path.exists(path):
        raise LogError(f"{path}: no such file or directory")
    return path


def read_log(path: str) -> LogData:
    mcap_path = resolve_path(path)
    try:
        with open(mcap_path, "rb") as fh:
            head = fh.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise LogError(f"{mcap_path}: {exc.strerror}") from None
    if head != MCAP_MAGIC:
        raise LogError(f"{mcap_path}: not an MCAP file (bad magic bytes)")
    log = LogData(path=mcap_path)
    try:
        _read_indexed(log)
    except (McapError, EOFError, ValueError, AssertionError, KeyError, OSError):
        log.channels.clear()
        log.messages.clear()
        log.metadata.clear()
        _read_recovering(log)
    if not log.channels:
        raise LogError(f"{mcap_path}: no channels (empty or unreadable MCAP)")
    return log


def _read_indexed(log: LogData) -> None:
    with open(log.path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        if summary is None:
            raise McapError("no summary")
        for ch in summary.channels.values():
            schema = summary.schemas[ch.schema_id]
            log.channels[ch.topic] = (schema.name, ch.metadata.get("offered_qos_profiles", ""))
        for m in reader.iter_metadata():
            log.metadata[m.name] = dict(m.metadata)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            log.messages.append(RawMessage(channel.topic, message.log_time, message.data))


def _read_recovering(log: LogData) -> None:
    """Scan records from the start, keeping every complete one (a killed writer)."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}

    def take(record) -> None:
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            channels[record.id] = record
            schema = schemas.get(record.schema_id)
            log.channels[record.topic] = (schema.name if schema else "",
                                          record.metadata.get("offered_qos_profiles", ""))
        elif isinstance(record, Message):
            ch = channels.get(record.channel_id)
            if ch is not None:
                log.messages.append(RawMessage(ch.topic, record.log_time, record.data))
        elif isinstance(record, Metadata):
            log.metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Chunk):
            for inner in breakup_chunk(record, validate_crc=True):
                take(inner)

    with open(log.path, "rb") as fh:
        try:
            for record in StreamReader(fh, skip_magic=False).records:
                take(record)
        except Exception:
            log.truncated = True
