"""
Topic-driven actuation tests against a real ``umbrella_node``: the public test API.

Start the simulated antenna in a child process on a private ROS domain, command the sleeve
over ``sleeve_force``, wait for what comes back, and assert on the run's summary::

    from umbrella_sim.testing import SimulatedAntenna

    def test_twenty_newtons_deploy_the_frame(tmp_path):
        with SimulatedAntenna({"v0": 0.0}) as antenna:
            antenna.wait_for_phase("deploying")
            antenna.publish_force(20.0)
            antenna.wait_for_phase("locked", timeout=30)
            summary = antenna.summary(after_lock=0.3)
        assert summary.deploy_time < 0.5

Everything here talks over real DDS, so:

* **Isolation.**  Each process runs with ``ROS_DOMAIN_ID`` = :func:`default_domain_id` (the
  ``UMBRELLA_TEST_DOMAIN_ID`` environment variable, else a domain of 10..99 that no other
  test session on the machine holds) and
  ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; pass ``domain_id=`` to choose another.
  :class:`Probe` (the test's own rclpy node) sets the same two variables in this process.
* **Waiting.**  Every wait polls what has been received, up to a timeout, and fails with an
  ``AssertionError`` that says what was awaited and what was seen: no fixed sleeps.
  Messages on different topics have no mutual order in DDS, and a transient-local sample
  reaches a late reader only after the handshake: wait for what you assert on.
* **Cleanup.**  ``stop()`` (also on leaving a ``with`` block) sends SIGTERM, waits, then
  SIGKILLs the process group; Fast DDS shared-memory segments (``/dev/shm/fastrtps_*``) that
  the process had open and no live process still uses are removed, so even a killed node
  leaves nothing behind.  Its log file is deleted.
* **Summaries.**  :meth:`SimulatedAntenna.summary` computes the deploy time, the stage-2 peak
  stress and tip amplitude from the node's topics and log; :func:`summary_from_recording`
  computes the same figures, exactly on sim time, from an MCAP recording (``record_path``).

Pytest fixtures (import them into your ``conftest.py``): ``ros_domain_id``, ``probe`` and
``antenna_factory`` (starts :class:`SimulatedAntenna` objects and stops them at teardown).
rclpy is imported only when a probe or an antenna is created.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Callable, Iterable
import weakref

#: environment variable that sets the default ROS domain of tests
DOMAIN_ID_ENV = "UMBRELLA_TEST_DOMAIN_ID"
PHASES = ("deploying", "locked", "fault")


#: the domains handed out by default, and where a process holding one says so (a lock file)
FREE_DOMAINS = range(10, 100)
_DOMAIN_LOCKS = os.path.join(tempfile.gettempdir(), "umbrella_sim_ros_domains")
_held_domain_locks: list = []      # open lock files: a domain is held while its process lives


def reserve_domain(first: int) -> int:
    """
    Return a domain of FREE_DOMAINS that no other process of this machine holds, from first.

    Held until this process exits (an exclusive flock on a file per domain), so that two test
    sessions on one machine (two CI jobs, a user's tests beside ours) never share a domain:
    they drove each other's antennas when both took the pid's domain.  If every domain is
    held (or locks are not possible here), first.
    """
    try:
        import fcntl

        os.makedirs(_DOMAIN_LOCKS, exist_ok=True)
    except (ImportError, OSError):
        return first
    span = len(FREE_DOMAINS)
    for k in range(span):
        domain = FREE_DOMAINS[(first - FREE_DOMAINS[0] + k) % span]
        try:
            fh = open(os.path.join(_DOMAIN_LOCKS, f"{domain}.lock"), "a")
        except OSError:
            continue
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            continue
        _held_domain_locks.append(fh)
        return domain
    return first


def default_domain_id() -> int:
    """
    ``$UMBRELLA_TEST_DOMAIN_ID`` if set, else a free domain of 10..99 (one per test session).

    The free domain is reserved for this process (:func:`reserve_domain`), from one derived
    from the pid; its child processes get it through the environment (:func:`ros_env`).
    """
    value = os.environ.get(DOMAIN_ID_ENV)
    if value is None:
        return reserve_domain(os.getpid() % len(FREE_DOMAINS) + FREE_DOMAINS[0])
    try:
        domain = int(value)
    except ValueError:
        raise ValueError(f"{DOMAIN_ID_ENV}={value!r}: must be an integer 0..232") from None
    if not 0 <= domain <= 232:
        raise ValueError(f"{DOMAIN_ID_ENV}={value!r}: must be an integer 0..232")
    return domain


DOMAIN_ID = default_domain_id()


def ros_env(domain_id: int | None = None) -> dict:
    """Return the environment for a child ROS process: private domain, localhost discovery."""
    domain = str(DOMAIN_ID if domain_id is None else domain_id)
    env = dict(os.environ)
    # the domain goes in DOMAIN_ID_ENV too: a child that imports this module (a test helper,
    # a user's wrapper around the node) then has the same DOMAIN_ID instead of one from its pid
    env.update({DOMAIN_ID_ENV: domain}, ROS_DOMAIN_ID=domain,
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               RMW_IMPLEMENTATION="rmw_fastrtps_cpp", PYTHONUNBUFFERED="1",
               RCUTILS_LOGGING_BUFFERED_STREAM="0")
    return env


def poll(condition: Callable[[], Any], timeout: float, failure: Callable[[], str],
         interval: float = 0.02):
    """condition()'s first truthy value, polling; AssertionError(failure()) at the timeout."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if result:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(failure())
        time.sleep(interval)


def _brief(msg, limit: int = 160) -> str:
    text = repr(msg)
    return text if len(text) <= limit else text[:limit] + "..."


# ------------------------------------------------------------- shared memory
_SHM = "/dev/shm/"


def _shm_segments(pid: int) -> set[str]:
    """Fast DDS segments a live process has mapped or open."""
    found = set()
    try:
        with open(f"/proc/{pid}/maps", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                path = line.rstrip("\n").split(" ")[-1]
                if path.startswith(_SHM + "fastrtps_"):
                    found.add(path)
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if target.startswith(_SHM + "fastrtps_") or target.startswith(_SHM + "sem.fastrtps_"):
                found.add(target)
    except OSError:
        pass
    return found


def _segment_family(path: str) -> set[str]:
    """Return a segment, its lock file (_el) and its named semaphore (sem.<name>_mutex)."""
    name = os.path.basename(path)
    name = name[len("sem."):] if name.startswith("sem.") else name
    name = name[:-len("_mutex")] if name.endswith("_mutex") else name
    name = name[:-len("_el")] if name.endswith("_el") else name
    return {_SHM + name, _SHM + name + "_el", _SHM + "sem." + name + "_mutex"}


def remove_stale_shm(paths: Iterable[str]) -> list[str]:
    """
    Remove the given Fast DDS participant segments that no live process uses; return them.

    A segment goes with its lock file when no live process maps or holds either open.  The
    per-domain port segments (``fastrtps_port*``) are left to Fast DDS, which reclaims them
    on the next start in that domain: a process that used one keeps a handle to it after its
    participant is gone, and a port file unlinked under it would cut it off from the domain.
    """
    families = [_segment_family(p) for p in set(paths)
                if not os.path.basename(p).removeprefix("sem.").startswith("fastrtps_port")]
    if not families:
        return []
    in_use: set[str] = set()
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            in_use |= _shm_segments(int(entry))
    removed = []
    for family in families:
        if family & in_use:
            continue
        for path in sorted(family):
            try:
                os.unlink(path)
                removed.append(path)
            except FileNotFoundError:
                pass
            except OSError:
                pass
    return removed


# -------------------------------------------------------------- child process
class NodeProcess:
    """
    A ROS node in a child process (its own session); output goes to a log file.

    ``NodeProcess("-p", "v0:=0.0")`` starts ``umbrella_node`` with raw ROS arguments;
    ``parameters={"v0": 0.0}`` and ``namespace="a1"`` build them for you; ``module=`` runs
    another node of the package (``"umbrella_sim.deploy_controller"``).
    """

    def __init__(self, *ros_args: str, executable: list[str] | None = None,
                 module: str = "umbrella_sim.node", parameters: dict | None = None,
                 namespace: str | None = None, domain_id: int | None = None,
                 cwd: str | None = None):
        self.domain_id = DOMAIN_ID if domain_id is None else domain_id
        args = list(ros_args)
        if namespace:
            args += ["-r", f"__ns:=/{namespace.strip('/')}"]
        for name, value in (parameters or {}).items():
            args += ["-p", f"{name}:={_ros_literal(value)}"]
        fd, self.log_path = tempfile.mkstemp(prefix="umbrella_node-", suffix=".log")
        self.log = os.fdopen(fd, "w+")
        self.command = (executable or [sys.executable, "-m", module]) + ["--ros-args", *args]
        # the node records by default into its working directory: unless cwd is given it
        # runs in a temporary one, removed by close(), so tests never leave bags behind
        self._own_cwd = None if cwd else tempfile.mkdtemp(prefix="umbrella_node_")
        self.cwd = cwd or self._own_cwd
        self.proc = subprocess.Popen(self.command, stdout=self.log, stderr=subprocess.STDOUT,
                                     env=ros_env(self.domain_id), start_new_session=True,
                                     cwd=self.cwd)
        self.shm: set[str] = set()

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        with open(self.log_path, encoding="utf-8", errors="replace") as fh:
            return fh.read()

    def wait_for_log(self, pattern: str, timeout: float = 20.0, count: int = 1):
        """Return the count-th match of a regular expression in the output, waiting for it."""
        def found():
            matches = list(re.finditer(pattern, self.output()))
            if len(matches) >= count:
                return matches[count - 1]
            if not self.running:
                raise AssertionError(
                    f"process exited (code {self.proc.returncode}) before {count} log "
                    f"line(s) matching {pattern!r}; output:\n{self.output()}")
            return None
        self.shm |= _shm_segments(self.pid)
        return poll(found, timeout, lambda: f"no {count} log line(s) matching {pattern!r} "
                                            f"within {timeout} s; output:\n{self.output()}")

    def stop(self, sig=signal.SIGTERM, timeout: float = 10.0) -> int:
        """
        Signal, wait (SIGKILL to the group after timeout), remove leftover shared memory.

        Returns the exit code (negative: killed by that signal).
        """
        if self.running:
            self.shm |= _shm_segments(self.pid)
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                pass
        try:                                   # anything left in its session
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        self.proc.wait()
        remove_stale_shm(self.shm)
        return self.proc.returncode

    def close(self) -> None:
        self.stop()
        self.log.close()
        try:
            os.unlink(self.log_path)
        except FileNotFoundError:
            pass
        if self._own_cwd:
            shutil.rmtree(self._own_cwd, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _ros_literal(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


# ------------------------------------------------------------------- probe
class Probe:
    """The test's own rclpy node (its own context) spinning in a background thread."""

    def __init__(self, name: str = "probe", domain_id: int | None = None):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.domain_id = DOMAIN_ID if domain_id is None else domain_id
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
        self.rclpy = rclpy
        self.context = rclpy.Context()
        # no rclpy signal handlers: Ctrl-C stays a KeyboardInterrupt of the test runner (which
        # tears the fixtures down) instead of shutting the context under a waiting test
        rclpy.init(context=self.context, domain_id=self.domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list] = {}
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:
                if not self.context.ok():
                    return
                raise

    def subscribe(self, topic: str, msg_type, qos=10):
        """Keep every message on topic with its arrival time (time.monotonic())."""
        if topic in self.received:
            return
        self.received[topic] = []

        def cb(msg, topic=topic):
            with self._lock:
                self.received[topic].append((time.monotonic(), msg))
        self.node.create_subscription(msg_type, topic, cb, qos)

    def messages(self, topic: str) -> list:
        with self._lock:
            return [m for _, m in self.received.get(topic, [])]

    def timed(self, topic: str) -> list:
        """Return [(arrival time.monotonic(), message)] of topic."""
        with self._lock:
            return list(self.received.get(topic, []))

    _poll = staticmethod(poll)

    def wait_for(self, topic: str, predicate=lambda m: True, timeout: float = 20.0,
                 what: str = "the condition"):
        """Return the first message on topic satisfying predicate, waiting for it."""
        def failure():
            msgs = self.messages(topic)
            last = f"; last: {_brief(msgs[-1])}" if msgs else ""
            return (f"no message on {topic} satisfying {what} within {timeout} s "
                    f"(got {len(msgs)}{last})")
        found = poll(lambda: [m for m in self.messages(topic) if predicate(m)][:1], timeout,
                     failure)
        return found[0]

    def wait_for_count(self, topic: str, count: int, timeout: float = 20.0) -> list:
        """Return the first ``count`` messages on topic, waiting for them."""
        poll(lambda: len(self.messages(topic)) >= count, timeout,
             lambda: f"fewer than {count} messages on {topic} within {timeout} s"
                     f" (got {len(self.messages(topic))})")
        return self.messages(topic)[:count]

    def publisher(self, topic: str, msg_type, qos=10):
        return self.node.create_publisher(msg_type, topic, qos)

    def wait_for_subscribers(self, pub, count: int = 1, timeout: float = 20.0):
        poll(lambda: pub.get_subscription_count() >= count, timeout,
             lambda: f"no {count} subscriber(s) on {pub.topic_name} within {timeout} s "
                     f"(got {pub.get_subscription_count()})")

    def call(self, srv_type, name: str, request, timeout: float = 20.0):
        client = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise AssertionError(f"service {name} not available within {timeout} s")
        future = client.call_async(request)
        poll(future.done, timeout, lambda: f"service {name} did not answer within {timeout} s")
        return future.result()

    def close(self):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=2.0)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ------------------------------------------------------------------ summary
@dataclass(frozen=True)
class RunSummary:
    """What an actuation test asserts on (SI units, sim time)."""

    first_push_time: float | None   # sim time the first non-zero force acted from
    lock_time: float | None         # sim time the sleeve reached the stop
    deploy_time: float | None       # lock_time - first_push_time (from 0 if it moved at start)
    stage2_peak_stress: float       # max over leaf and link of peak |sigma| after the lock (Pa)
    stage2_tip_amplitude: float     # half peak-to-peak transverse tip deflection after it (m),
    #                                 of the samples at publish_rate: a crest between two is
    #                                 missed (100 Hz: up to 6.4 % low at V0 = -0.2; 1 kHz: < 0.9 %;
    #                                 the offline summary takes every physics step)
    stage2_samples: int             # samples the stage-2 figures come from
    stage2_span: float              # sim time those samples cover (s)


#: the stage-2 window of a run summary (s of sim time after the lock), live or recorded
SUMMARY_AFTER_LOCK = 0.3


def summarize_run(applied: list[tuple[float, float]], lock_time: float | None,
                  started_moving: bool, tip: list[tuple[float, float]],
                  stress: list[tuple[float, float]],
                  after_lock: float | None = None) -> RunSummary:
    """
    Return the run summary: the one place these figures are defined.

    From the applied force history [(t, F)], the lock time, whether the frame moved from
    t = 0 (v0 != 0 or an initial force), tip [(t, transverse deflection)] and stress
    [(t, max(peak leaf, peak link))].  Stage 2 is lock < t <= lock + after_lock (None:
    every sample after the lock).
    """
    from ..core.summary import deploy_start  # (the one rule: the summary, compare, this)

    first_push = 0.0 if started_moving else deploy_start(0.0, applied)
    deploy = (lock_time - first_push if lock_time is not None and first_push is not None
              else None)
    end = math.inf if after_lock is None or lock_time is None else lock_time + after_lock
    after = (lambda t: lock_time is not None and lock_time < t <= end + 1e-9)
    tip2 = [y for t, y in tip if after(t)]
    stress2 = [s for t, s in stress if after(t)]
    times2 = [t for t, _ in tip if after(t)]
    return RunSummary(
        first_push_time=first_push, lock_time=lock_time, deploy_time=deploy,
        stage2_peak_stress=max(stress2) if stress2 else math.nan,
        stage2_tip_amplitude=0.5 * (max(tip2) - min(tip2)) if tip2 else math.nan,
        stage2_samples=len(tip2),
        stage2_span=(times2[-1] - lock_time) if times2 else 0.0)


def summary_from_recording(path: str,
                           after_lock: float | None = SUMMARY_AFTER_LOCK) -> RunSummary:
    """
    Return the run summary of a finalised (or torn) MCAP recording of umbrella_node.

    Of its last run (a ~/reset starts a new segment); every figure is on that run's sim
    time, stage 2 over ``after_lock`` s after the lock as :meth:`SimulatedAntenna.summary`
    (None: to the end of the recording), so neither depends on when the node was stopped.
    """
    from ..bag.reader import read_log

    log = read_log(path)
    seg = log.segments()[-1]
    params = seg.params
    events = log.metadata.get("umbrella_sim.events", {})      # the last segment's
    lock_time = float(events["lock_time"]) if events.get("lock_time") else None
    applied_topic = log.find_topic("sleeve_force/applied", required=False)
    applied = ([(t, m.data) for t, m in log.decoded(applied_topic, seg)]
               if applied_topic else [])
    tip = [(t, m.point.y) for t, m in log.decoded(log.find_topic("tip_deflection"), seg)]
    stress = [(t, max(m.data[0], m.data[4]))
              for t, m in log.decoded(log.find_topic("peak_stress"), seg)]
    if lock_time is None:          # a torn recording: the first 'locked' phase message
        locked = [t for t, m in log.decoded(log.find_topic("deployment_phase"), seg)
                  if m.data == "locked"]
        lock_time = locked[0] if locked else None
    from ..core.summary import deploy_start_of

    return summarize_run(applied, lock_time, deploy_start_of(params, applied) == 0.0, tip,
                         stress, after_lock)


# ------------------------------------------------------------------ antenna
APPLIED_RE = r"sleeve force ([0-9.eE+-]+|nan|inf|-inf) N applied from t = ([0-9.]+) s"
RESET_LINE = "reset: simulation restarted"
LOCKED_RE = r"locked at t = ([0-9.]+) s"


class SimulatedAntenna:
    """
    An ``umbrella_node`` under test plus a probe subscribed to its topics.

    ``parameters``: node parameters by name (``{"v0": 0.0, "publish_rate": 200.0}``);
    ``namespace``: run the node under ``/namespace``; ``record_path``: record to that bag
    directory (see :func:`summary_from_recording`), else the node does not record;
    ``probe``: share one :class:`Probe` between several antennas (default: one of its own,
    closed with the antenna).  The constructor returns once the node has started and its
    first joint state arrived (its phase, with ``start_paused``: the node then holds t = 0
    until :meth:`resume`).
    """

    _count = 0          # probe node names stay unique within a process
    _live: dict = {}    # (domain, namespace) -> the NodeProcess of the last antenna there

    def __init__(self, parameters: dict | None = None, namespace: str = "",
                 record_path: str | None = None, domain_id: int | None = None,
                 probe: Probe | None = None, startup_timeout: float = 30.0):
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PointStamped
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64, Float64MultiArray, String

        from ..ros import messages as ros_io

        self.parameters = dict(parameters or {})
        if record_path is not None:
            # the node runs in a temporary directory of its own (NodeProcess): a relative
            # path means the test's working directory, where the test will look for it
            record_path = os.path.abspath(os.path.expanduser(str(record_path)))
            self.parameters["record_path"] = record_path
        else:                                  # recording is optional: off unless asked for
            self.parameters.setdefault("record", False)
        self.record_path = record_path
        self.namespace = namespace.strip("/")
        domain = (probe.domain_id if probe is not None
                  else DOMAIN_ID if domain_id is None else domain_id)
        self._key = (domain, self.namespace)
        other = SimulatedAntenna._live.get(self._key)
        if other is not None and other.running:
            raise ValueError(f"an antenna already runs in namespace '/{self.namespace}' on ROS "
                             f"domain {domain}: their topics would be one; give each antenna "
                             "its own namespace (namespace=...)")
        prefix = f"/{self.namespace}/" if self.namespace else "/"
        # relative names resolve under the namespace; absolute ones (/diagnostics) do not
        self.topics = {key: t.name if t.name.startswith("/") else prefix + t.name
                       for key, t in ros_io.TOPICS.items()}
        self.topics["sleeve_force"] = prefix + ros_io.COMMAND.name
        self._diag = ros_io.diagnostic_name(prefix + "umbrella_node")   # its status name
        self._own_probe = probe is None
        SimulatedAntenna._count += 1
        self.probe = probe or Probe(f"antenna_probe_{SimulatedAntenna._count}",
                                    domain_id=domain_id)
        self.domain_id = self.probe.domain_id
        for key, msg_type in (("joint_states", JointState), ("tip_deflection", PointStamped),
                              ("peak_stress", Float64MultiArray),
                              ("diagnostics", DiagnosticArray)):
            self.probe.subscribe(self.topics[key], msg_type, ros_io.TOPICS[key].qos)
        self.probe.subscribe(self.topics["deployment_phase"], String, ros_io.LATCHED)
        self._float64 = Float64
        self._command_pub = None
        self._runs = 0          # resets so far: waits and figures are of the current run
        self._marks: dict[str, int] = {}    # messages per key received before the last reset
        self._pending: dict = {}            # parameters set that apply on the next reset
        self.node = NodeProcess(parameters=self.parameters, namespace=self.namespace or None,
                                domain_id=self.domain_id)
        SimulatedAntenna._live[self._key] = self.node
        # a forgotten close(): the node and the probe still go, at the latest at exit
        self._finalizer = weakref.finalize(self, _close_antenna, self.node,
                                           self.probe if self._own_probe else None, self._key)
        try:
            self.physics_step = float(self.node.wait_for_log(
                r"physics step ([0-9.eE+-]+) s", timeout=startup_timeout).group(1))
            # (a node started paused published its t = 0 state before this probe matched:
            # the latched phase arrives late, a joint state would not)
            first = "deployment_phase" if self.parameters.get("start_paused") else "joint_states"
            poll(lambda: self.probe.messages(self.topics[first]) or not self.node.running,
                 startup_timeout,
                 lambda: f"no message on {self.topics[first]} within "
                         f"{startup_timeout} s of the node's start (node "
                         f"{'running' if self.node.running else 'exited'}); node output:\n"
                         f"{self.node.output()[-2000:]}")
            if not self.probe.messages(self.topics[first]):
                raise AssertionError(f"the node exited (code {self.node.proc.returncode}) "
                                     f"before its first message on {self.topics[first]}; "
                                     f"node output:\n{self.node.output()[-2000:]}")
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------ commands
    def publish_force(self, force: float, timeout: float = 20.0, check: bool = True) -> None:
        """
        Publish one sleeve_force command (after the node's subscription has matched).

        A force the node would refuse (solver.command_force: NaN, below sleeve_force_min,
        above what the link carries) raises ValueError here, with the node's reason;
        check=False sends it anyway (a test of the node's refusal).
        """
        if check:
            from ..core.forcing import command_force
            from ..core.params import UmbrellaParams
            from ..core.registry import SPECS
            command_force(force, UmbrellaParams.from_mapping(
                {k: v for k, v in self.parameters.items() if k in SPECS}))
        self._command_publisher(timeout).publish(self._float64(data=float(force)))

    def _command_publisher(self, timeout: float):
        """Return the sleeve_force publisher, made and matched with the node's subscription."""
        if self._command_pub is None:
            from ..ros import messages as ros_io
            self._command_pub = self.probe.publisher(self.topics["sleeve_force"], self._float64,
                                                     ros_io.COMMAND.qos)
            self.probe.wait_for_subscribers(self._command_pub, timeout=timeout)
        return self._command_pub

    def play_force_profile(self, profile: Iterable[tuple[float, float]],
                           timeout: float = 30.0) -> None:
        """
        Publish each (t, F) of a profile when the node's sim time reaches start + t.

        The start is sim_time() once the command publisher has matched the node (joint_states
        stamps; the run's first state is waited for); returns after the last command.
        Commands act from the next publication after they arrive, so each lands on the
        publication grid a little after its t; a profile exact in sim time is
        ``umbrella_sim simulate --force-profile`` (offline, the same physics).
        """
        rows = sorted(profile, key=lambda tf: tf[0])
        self.wait_for("joint_states", lambda m: True, timeout, "a first joint state")
        self._command_publisher(timeout)    # matched first: its ~0.4 s not inside the profile
        t0 = self.sim_time()
        for t_rel, force in rows:
            self.wait_for_sim_time(t0 + t_rel, timeout=timeout)
            self.publish_force(force)

    def set_parameters(self, timeout: float = 20.0, **values) -> None:
        """
        Set node parameters at run time (SetParameters, as ``ros2 param set`` does).

        ``antenna.set_parameters(v0=-0.5, sleeve_force_min=-5.0)``: one request, each value
        checked and set on its own (AssertionError naming those refused, with the node's
        reasons; the others are set).  Model
        parameters apply on the next :meth:`reset`, as on the node, and from then on this
        antenna's figures and force checks (:meth:`publish_force`) use them; the node's own
        (``real_time_factor``, ``marker_magnification``...) apply at once.
        """
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        from ..core.registry import REGISTRY, RESET

        request = SetParameters.Request(parameters=[
            Parameter(name, value=value).to_parameter_msg() for name, value in values.items()])
        results = self.probe.call(SetParameters, self._service("set_parameters"), request,
                                  timeout).results
        for (name, value), r in zip(values.items(), results):
            if r.successful:
                spec = REGISTRY.get(name)
                (self._pending if spec is not None and spec.applies == RESET
                 else self.parameters)[name] = value
        refused = [f"{name}: {r.reason}" for name, r in zip(values, results) if not r.successful]
        if refused:
            raise AssertionError(f"parameters refused: {'; '.join(refused)}")

    def pause(self, paused: bool = True) -> None:
        """Pause (or resume) the simulation: ``~/pause``; sim time holds while paused."""
        from std_srvs.srv import SetBool
        r = self.probe.call(SetBool, self._service("pause"), SetBool.Request(data=paused))
        if not r.success:
            raise AssertionError(f"~/pause {paused}: refused: {r.message}")

    def resume(self) -> None:
        """Resume a paused run (also the start of one made with ``start_paused``)."""
        self.pause(False)

    def reset(self, timeout: float = 20.0) -> None:
        """
        Restart the run at t = 0 (``~/reset``, with the parameters set since the start).

        Returns once the node has restarted (its log, the new run's "deploying" phase and
        its t = 0 joint state);
        from then on every wait, message list and figure (phases, sim_time, messages,
        applied_forces, lock_time, summary) is of the new run only, which begins with its
        t = 0 state (published at the reset, paused or not).  AssertionError with the
        node's reason if it refuses.
        """
        from std_srvs.srv import Trigger
        resets = self.node.output().count(RESET_LINE)
        topic = self.topics["deployment_phase"]

        def runs_begun():
            return [m.data for m in self.probe.messages(topic)].count("deploying")
        begun = runs_begun()
        marks = {key: len(self._received(key)) for key, topic in self.topics.items()
                 if topic in self.probe.received}
        r = self.probe.call(Trigger, self._service("reset"), Trigger.Request(), timeout)
        if not r.success:
            raise AssertionError(f"~/reset refused: {r.message}")
        self._runs += 1
        self._marks = marks
        self.parameters.update(self._pending)     # the model parameters set apply now
        self._pending = {}
        poll(lambda: self.node.output().count(RESET_LINE) > resets, timeout,
             lambda: f"no '{RESET_LINE}' in the node's log within {timeout} s")
        poll(lambda: runs_begun() > begun, timeout,
             lambda: f"no new 'deploying' on {topic} within {timeout} s of ~/reset")
        poll(lambda: self.messages("joint_states"), timeout,
             lambda: f"no t = 0 state on {self.topics['joint_states']} within {timeout} s of "
                     "~/reset")

    def _service(self, name: str) -> str:
        return (f"/{self.namespace}" if self.namespace else "") + f"/umbrella_node/{name}"

    # --------------------------------------------------------------- waits
    def sim_time(self) -> float | None:
        """Stamp of the latest joint state of this run received (s); None before the first."""
        states = self.messages("joint_states")
        return _stamp(states[-1]) if states else None

    def _sim_time_text(self) -> str:
        t = self.sim_time()
        return "no joint state yet" if t is None else f"latest stamp {t:.6f} s"

    def phases(self) -> list[str]:
        """Return the deployment phases of this run, in order ("deploying" first)."""
        return [m.data for _, m in self._timed_run("deployment_phase")]

    def wait_for_phase(self, phase: str, timeout: float = 20.0) -> None:
        if phase not in PHASES:
            raise ValueError(f"phase {phase!r}: must be one of {', '.join(PHASES)}")
        poll(lambda: phase in self.phases(), timeout,
             lambda: f"deployment_phase never became {phase!r} within {timeout} s on "
                     f"{self.topics['deployment_phase']} (saw {self.phases() or 'nothing'}; "
                     f"{self._sim_time_text()}; node "
                     f"{'running' if self.node.running else 'exited'})")

    def wait_for_sim_time(self, t: float, timeout: float = 20.0) -> None:
        def reached():
            now = self.sim_time()
            return now is not None and now >= t

        poll(reached, timeout,
             lambda: f"sim time never reached {t:.6f} s within {timeout} s on "
                     f"{self.topics['joint_states']} ({self._sim_time_text()})")

    def wait_for(self, key: str, predicate, timeout: float = 20.0, what: str = "the condition"):
        """Return this run's first message on a node topic (``"joint_states"``...) that fits."""
        topic = self._received_topic(key)

        def failure():
            msgs = self.messages(key)
            last = f"; last: {_brief(msgs[-1])}" if msgs else ""
            return (f"no message on {topic} satisfying {what} within {timeout} s "
                    f"(got {len(msgs)}{last})")
        return poll(lambda: [m for m in self.messages(key) if predicate(m)][:1], timeout,
                    failure)[0]

    def messages(self, key: str) -> list:
        """Return this run's messages on a node topic (after ``reset()``, the new run's)."""
        return [m for _, m in self._timed_run(key)]

    def _received(self, key: str) -> list:
        """Return [(arrival, message)] received on a key's topic, this node's only."""
        timed = self.probe.timed(self._received_topic(key))
        if key == "diagnostics":            # /diagnostics is every node's: this node's only
            timed = [(a, m) for a, m in timed if m.status and m.status[0].name == self._diag]
        return timed

    def _timed_run(self, key: str) -> list:
        """Return [(arrival, message)] of this run on a topic the antenna receives."""
        timed = self._received(key)
        if key == "deployment_phase":       # each run's phases start with "deploying"
            starts = [i for i, (_, m) in enumerate(timed) if m.data == "deploying"]
            return timed[starts[-1]:] if starts and self._runs else timed
        if not self._runs:
            return timed
        if key != "diagnostics" and hasattr(timed[-1][1] if timed else None, "header"):
            i = self._run_index(timed, self._marks.get(key, 0))
            return [] if i is None else timed[i:]
        # unstamped, or diagnostics (1 Hz: its first stamp of a new run need not fall below
        # the last of the old one): what arrived since the run's first joint state
        states = self._received("joint_states")
        i = self._run_index(states, self._marks.get("joint_states", 0))
        return [] if i is None else [(a, m) for a, m in timed if a >= states[i][0]]

    def _run_index(self, timed: list, mark: int) -> int | None:
        """
        Return where this run begins in [(arrival, stamped message)] (None: not yet).

        After a reset: the last message since the reset call (``mark`` messages came
        before it) that restarts sim time: its t = 0 state, or a stamp below the one before
        it.  The last: what the previous run still had in flight comes first, and may
        restart sim time itself (a paused start's t = 0 state that arrives late).  (Before
        any reset a run is every message: _timed_run.)
        """
        for i in range(len(timed) - 1, mark - 1, -1):
            t = _stamp(timed[i][1])
            if t == 0.0 or (i > 0 and t < _stamp(timed[i - 1][1])):
                return i
        return None

    def _received_topic(self, key: str) -> str:
        """Return the topic of a key the antenna receives (else ValueError: which it does)."""
        received = [k for k, name in self.topics.items() if name in self.probe.received]
        if key not in received:
            what = ("receives" if key not in self.topics
                    else "does not subscribe to it; it receives")
            raise ValueError(f"topic key {key!r}: the antenna {what} {', '.join(received)} "
                             f"(subscribe to others with antenna.probe.subscribe"
                             f"(antenna.topics[key], type, qos))")
        return self.topics[key]

    # --------------------------------------------------------- what happened
    def _run_output(self) -> str:
        """Return the node's log since this run began (after the last reset line, if any)."""
        out = self.node.output()
        return out[out.rfind(RESET_LINE):] if self._runs else out

    def applied_forces(self) -> list[tuple[float, float]]:
        """
        [(sim time, F)] every commanded value the node applied in this run, from its log.

        Exact; the ``sleeve_force`` parameter's value, which acts from t = 0, is not a
        command and is not listed.
        """
        return [(float(t), float(f)) for f, t in re.findall(APPLIED_RE, self._run_output())]

    def lock_time(self) -> float | None:
        m = re.search(LOCKED_RE, self._run_output())
        return float(m.group(1)) if m else None

    def diagnostics(self) -> dict:
        """Return the key/values of the latest diagnostics message ({} before the first)."""
        msgs = self.messages("diagnostics")
        return {kv.key: kv.value for kv in msgs[-1].status[0].values} if msgs else {}

    def summary(self, after_lock: float = SUMMARY_AFTER_LOCK,
                timeout: float = 30.0) -> RunSummary:
        """
        Return the run summary from the topics, stage 2 over ``after_lock`` s after the lock.

        The tip figures are of the tip messages, each exact at its stamp: the amplitude
        is of those samples, so it reads a few per cent low at 100 Hz (RunSummary).  The
        stress figure is a peak-hold over each period.  AssertionError if none of the window's
        messages were received (a probe that subscribed after it).  The stress message has no
        stamp: stage-2
        stress samples are those received after the 'locked' phase message and before the
        first tip message past the window, so a publication at either end may be left out
        or taken in; a recording gives the exact figures (:func:`summary_from_recording`).
        """
        if after_lock is None or not after_lock > 0:
            raise ValueError(f"after_lock={after_lock!r}: seconds of sim time after the lock "
                             "(> 0); a live run has no end to summarise to (None, the whole "
                             "run, is for summary_from_recording)")
        self.wait_for_phase("locked", timeout)
        lock = poll(self.lock_time, timeout, lambda: "no 'locked at' line in the node's log")
        end = lock + after_lock
        self.wait_for_sim_time(end, timeout)
        # joint_states sets the sim time; the tip and stress streams (one message each per
        # publication) may still be in flight behind it on a busy machine: wait for them too
        tips = poll(lambda: [m for m in self.messages("tip_deflection")
                             if _stamp(m) > end + 1e-9][:1] and
                    self.messages("tip_deflection"), timeout,
                    lambda: f"tip_deflection never reached sim time {lock + after_lock:.6f} s "
                            f"within {timeout} s")
        poll(lambda: len(self.messages("peak_stress")) >= len(tips), timeout,
             lambda: f"peak_stress lags tip_deflection ({len(self.messages('peak_stress'))} "
                     f"vs {len(tips)} messages) after {timeout} s")
        phase_arrival = next(t for t, m in self._timed_run("deployment_phase")
                             if m.data == "locked")
        tip = [(_stamp(m), m.point.y) for m in self.messages("tip_deflection")]
        cut = next(a for a, m in self._timed_run("tip_deflection") if _stamp(m) > end + 1e-9)

        def when(arrival):  # no stamp: before, in or after the window by when it arrived
            return -math.inf if arrival <= phase_arrival else end if arrival < cut else math.inf
        stress = [(when(arrival), max(m.data[0], m.data[4]))
                  for arrival, m in self._timed_run("peak_stress")]
        from ..core.summary import deploy_start_of

        applied = self.applied_forces()
        out = summarize_run(applied, lock, deploy_start_of(self.parameters, applied) == 0.0,
                            tip, stress, after_lock)
        window = f"({lock:.6f}, {end:.6f}] s of sim time"
        if out.stage2_samples == 0:
            first = min((t for t, _ in tip), default=math.inf)
            why = (f"its first tip message is at {first:.6f} s: this antenna's probe "
                   "subscribed after the window" if first > end else
                   "no publication falls in it: after_lock is shorter than a publication "
                   "period")
            raise AssertionError(f"no stage-2 tip samples in {window}: {why}; take a summary "
                                 "of a window it saw, or summary_from_recording")
        if not any(w == end for w, _ in stress):
            raise AssertionError(
                f"no peak_stress message of {window} received between the 'locked' phase "
                "message and the first tip message past the window (messages on different "
                "topics have no mutual order): take a longer after_lock, or "
                "summary_from_recording")
        return out

    # ------------------------------------------------------------- lifetime
    def stop(self, timeout: float = 10.0) -> int:
        """
        SIGTERM the node (it finalises its recording), wait; the exit code.

        The antenna's command publisher goes too: a controller started next to another
        antenna in the same namespace would otherwise count it as a second commander.
        """
        if self._command_pub is not None:
            self.probe.node.destroy_publisher(self._command_pub)
            self._command_pub = None
        return self.node.stop(timeout=timeout)

    def close(self) -> None:
        self._finalizer()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _close_antenna(node: NodeProcess, probe: Probe | None, key: tuple) -> None:
    try:
        node.close()
    finally:
        if SimulatedAntenna._live.get(key) is node:
            del SimulatedAntenna._live[key]
        if probe is not None:
            probe.close()


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


# ------------------------------------------------------------------ fixtures
try:
    import pytest
except ImportError:                                    # pragma: no cover
    pytest = None

if pytest is not None:
    @pytest.fixture(scope="session")
    def ros_domain_id() -> int:
        """Return the ROS domain of this session (UMBRELLA_TEST_DOMAIN_ID, else a free one)."""
        return DOMAIN_ID

    @pytest.fixture
    def probe(ros_domain_id):
        """Yield a Probe on the session's domain, closed after the test."""
        p = Probe(domain_id=ros_domain_id)
        yield p
        p.close()

    @pytest.fixture
    def antenna_factory(ros_domain_id):
        """Start SimulatedAntenna(**kwargs) objects; all are closed after the test."""
        started: list[SimulatedAntenna] = []

        def start(parameters: dict | None = None, **kwargs) -> SimulatedAntenna:
            kwargs.setdefault("domain_id", ros_domain_id)
            antenna = SimulatedAntenna(parameters, **kwargs)
            started.append(antenna)
            return antenna
        yield start
        for antenna in reversed(started):
            antenna.close()
