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

import json
import os
import subprocess
import sys
import threading

from mcap.writer import CompressionType, IndexType, Writer
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
import yaml

from . import __version__

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


def _align(pos: int, n: int) -> int:
    return (pos + n - 1) // n * n


def _cdr_end(msg, pos: int) -> int:
    for field, ftype in msg.get_fields_and_field_types().items():
        value = getattr(msg, field)
        pos = _cdr_field(ftype, value, pos)
    return pos


def _cdr_field(ftype: str, value, pos: int) -> int:
    if ftype.startswith("sequence<"):
        inner = ftype[len("sequence<"):-1].rsplit(",", 1)[0].strip()
        pos = _align(pos, 4) + 4
        return _cdr_items(inner, value, pos)
    if ftype.endswith("]"):
        inner = ftype[:ftype.index("[")]
        return _cdr_items(inner, value, pos)
    return _cdr_items(ftype, [value], pos)


def _cdr_items(ftype: str, values, pos: int) -> int:
    if ftype.startswith("string") or ftype.startswith("wstring"):
        for v in values:
            pos = _align(pos, 4) + 4
            pos += (len(v.encode("utf-8")) + 1) if ftype.startswith("string") else 4 * (len(v) + 1)
        return pos
    size = _SIZES.get(ftype)
    if size is not None:
        n = len(values)
        return (_align(pos, size) + size * n) if n else pos
    for v in values:                           # nested message
        pos = _cdr_end(v, pos)
    return pos


def cdr_bytes(msg) -> bytes:
    """
    Serialise to CDR, trimmed to the exact size.

    (rclpy may return a few padding bytes more,
    which rosbags rejects; ros2 bag record writes the exact size).
    """
    data = serialize_message(msg)
    size = 4 + _cdr_end(msg, 0)                # 4-byte encapsulation header
    if size > len(data):
        raise RuntimeError(f"CDR size walk overran the payload for {type_name(msg)}")
    return data[:size]


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
                               "python": sys.version.split()[0]},
        "umbrella_sim.mesh": {
            "model": params.model, "lock": params.lock,
            "elements_per_segment": str(params.elements_per_segment),
            "coordinates": json.dumps(model.coordinate_labels()),
            "leaf_node_x": json.dumps(list(model.leaf.node_x)),
            "link_node_x": json.dumps(list(model.link.node_x)),
        },
    }


def events_metadata(sim) -> dict[str, dict[str, str]]:
    """Return the exact lock instant (the phase message comes at the next publication)."""
    ev = sim.lock_event
    if ev is None:
        return {"umbrella_sim.events": {"locked": "false"}}
    return {"umbrella_sim.events": {"locked": "true", "lock_time": repr(ev.time),
                                    "lock_kind": ev.kind,
                                    "energy_before": repr(ev.energy_before),
                                    "energy_after": repr(ev.energy_after)}}


# ---------------------------------------------------------------------- recorder
def default_bag_name(namespace: str = "/", when: float | None = None) -> str:
    """Return umbrella[_ns]_YYYY_MM_DD-HH_MM_SS, as ros2 bag record names its bags."""
    import time

    ns = namespace.strip("/").replace("/", "_")
    stamp = time.strftime("%Y_%m_%d-%H_%M_%S", time.localtime(when))
    return "_".join(["umbrella"] + ([ns] if ns else []) + [stamp])


def new_bag_recorder(namespace: str, metadata, parent: str = ".") -> "BagRecorder":
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
            return BagRecorder(bag_dir, metadata(bag_dir))
        except ValueError:
            if os.path.exists(bag_dir):      # taken meanwhile by another process: next name
                continue
            raise
    raise ValueError(f"recording: no free bag directory name {base}_N in {parent}")


class BagRecorder:
    """Thread-safe writer of one bag directory; never overwrites."""

    def __init__(self, bag_dir: str, metadata: dict[str, dict[str, str]]):
        bag_dir = os.path.abspath(bag_dir.rstrip("/"))
        if os.path.exists(bag_dir):
            raise ValueError(f"record_path {bag_dir}: already exists, not overwriting")
        parent = os.path.dirname(bag_dir)
        if not os.path.isdir(parent):
            raise ValueError(f"record_path {bag_dir}: parent directory {parent} does not exist")
        if not os.access(parent, os.W_OK):
            raise ValueError(f"record_path {bag_dir}: parent directory {parent} is not writable")
        try:
            os.mkdir(bag_dir)
        except OSError as exc:
            raise ValueError(f"record_path {bag_dir}: {exc.strerror}") from None
        self.bag_dir = bag_dir
        self.file_name = os.path.basename(bag_dir) + "_0.mcap"
        self.path = os.path.join(bag_dir, self.file_name)
        # flushed after every write: a finished chunk reaches the OS at once, so a SIGKILL
        # loses only the chunk being filled (messages accumulate in memory until then)
        self._fh = open(self.path, "xb")
        self._writer = Writer(self._fh, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD,
                              index_types=IndexType.ALL, use_chunking=True,
                              use_statistics=True)
        self._writer.start(profile="ros2", library=f"umbrella_sim {__version__}")
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str, QoSProfile]] = {}
        self.counts: dict[str, int] = {}
        self._first = self._last = None
        self._closed = False
        for name, data in metadata.items():
            self._writer.add_metadata(name, data)
        self._fh.flush()

    def add_channel(self, topic: str, msg_type, qos: QoSProfile) -> None:
        with self._lock:
            if topic in self._channels:
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

    def add_umbrella_channels(self, topic_names: dict, command_topic: str) -> None:
        """
        Add the channels of an umbrella_sim run, live or offline.

        Every published topic
        (topic key -> resolved name) and the command with its refused/applied records.
        """
        from std_msgs.msg import Float64

        from . import ros_io
        for key, name in topic_names.items():
            self.add_channel(name, ros_io.TOPICS[key].type, ros_io.TOPICS[key].qos)
        for suffix in ("", ros_io.COMMAND_REFUSED_SUFFIX, ros_io.COMMAND_APPLIED_SUFFIX):
            self.add_channel(command_topic + suffix, Float64, ros_io.COMMAND.qos)

    def close_run(self, sim, published: dict, accepted: int, refused: int) -> None:
        """Finalise with the counts (published vs recorded) and the exact lock event."""
        self.close({"umbrella_sim.counts": {
            "published": json.dumps(published), "commands_accepted": str(accepted),
            "commands_refused": str(refused), "recorded": json.dumps(self.counts)},
            **events_metadata(sim)})

    def write(self, topic: str, msg, t_ns: int) -> None:
        data = cdr_bytes(msg)
        with self._lock:
            if self._closed:
                return
            cid = self._channels[topic][0]
            seq = self.counts[topic]
            self._writer.add_message(channel_id=cid, log_time=t_ns, publish_time=t_ns,
                                     data=data, sequence=seq)
            self._fh.flush()
            self.counts[topic] = seq + 1
            self._first = t_ns if self._first is None else min(self._first, t_ns)
            self._last = t_ns if self._last is None else max(self._last, t_ns)

    def close(self, final_metadata: dict[str, dict[str, str]] | None = None) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            for name, data in (final_metadata or {}).items():
                self._writer.add_metadata(name, data)
            info = self._bag_info()
            self._writer.add_metadata("rosbag2", {
                "serialized_metadata": yaml.safe_dump(info, sort_keys=False),
                "ROS_DISTRO": "jazzy"})
            self._writer.finish()
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
            with open(os.path.join(self.bag_dir, "metadata.yaml"), "w", encoding="utf-8") as fh:
                yaml.safe_dump({"rosbag2_bagfile_information": info}, fh, sort_keys=False)

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
def record_offline(params, bag_dir: str, duration: float, force_profile=None,
                   publish_rate: float = 100.0, marker_magnification: float = 1.0,
                   progress=None):
    """
    Run the physics offline and record it as a live umbrella_node would.

    Goes through the node's publication path and records the same
    topics, layout and metadata as a live umbrella_node (root namespace).  Returns the
    RunResult of the samples at the publication instants (error set if it diverged).
    """
    import time as _time

    from diagnostic_msgs.msg import DiagnosticStatus
    from std_msgs.msg import Float64

    from . import ros_io
    from .outputs import RunResult
    from .params import node_defaults
    from .publication import PublicationDriver
    from .solver import SimulationDiverged, validate_force

    profile = sorted(force_profile or [], key=lambda tf: tf[0])
    for _, f in profile:
        validate_force(f)
    node_cfg = node_defaults()
    node_cfg.update(publish_rate=publish_rate, real_time_factor=0.0, duration=duration,
                    record_path=bag_dir, marker_magnification=marker_magnification)
    driver = PublicationDriver(params, publish_rate)
    rec = BagRecorder(bag_dir, run_metadata(params, node_cfg, driver.step, driver.sim.model,
                                            driver.backend, source="umbrella_sim simulate"))
    topics = {key: "/" + t.name.lstrip("/") for key, t in ros_io.TOPICS.items()}
    command = "/" + ros_io.COMMAND.name
    rec.add_umbrella_channels(topics, command)
    published: dict[str, int] = {}

    def publish(key, msg, t):
        published[topics[key]] = published.get(topics[key], 0) + 1
        rec.write(topics[key], msg, ros_io.stamp_ns(t))

    sim = driver.sim
    result = RunResult(params=params.as_dict(), q_labels=sim.model.coordinate_labels(),
                       leaf_stress_x=list(sim.model.leaf.stress_x),
                       link_stress_x=list(sim.model.link.stress_x))
    wall0 = _time.perf_counter()
    publish("deployment_phase", ros_io.phase_msg("deploying"), 0.0)
    force, i_cmd, next_diag = params.sleeve_force, 0, 1.0
    n_periods = int(round(duration * publish_rate))
    try:
        for k in range(n_periods + 1):
            t = sim.time
            result.samples.append(sim.sample())
            for key, msg in driver.messages("umbrella", marker_magnification).items():
                publish(key, msg, t)
            if t >= next_diag - 1e-12:
                wall = _time.perf_counter() - wall0
                publish("diagnostics", ros_io.diagnostics_msg(
                    t, "umbrella_sim offline: physics", DiagnosticStatus.OK, "offline",
                    {"sim_time_s": f"{t:.6f}", "measured_real_time_factor":
                     f"{t / wall:.4f}" if wall > 0 else "inf", "steps": sim.steps,
                     "physics_step_s": sim.h}), t)
                next_diag += 1.0
            if k == n_periods:
                break
            while i_cmd < len(profile) and profile[i_cmd][0] <= t + 1e-12:
                force = profile[i_cmd][1]
                rec.write(command, Float64(data=force), ros_io.stamp_ns(profile[i_cmd][0]))
                i_cmd += 1
            for ev in driver.advance(force):
                if ev.kind == "applied":
                    rec.write(command + ros_io.COMMAND_APPLIED_SUFFIX, Float64(data=ev.force),
                              ros_io.stamp_ns(ev.time))
                else:
                    publish("deployment_phase", ros_io.phase_msg("locked"), sim.time)
            if progress is not None and k % 20 == 0:
                progress(sim.time)
    except SimulationDiverged as exc:
        result.error = str(exc)
        publish("deployment_phase", ros_io.phase_msg("fault"), sim.time)
    finally:
        rec.close_run(sim, published, accepted=i_cmd, refused=0)
    result.wall_time = _time.perf_counter() - wall0
    result.steps = sim.steps
    result.lock = sim.lock_event
    return result
