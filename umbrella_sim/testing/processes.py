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
ROS processes under test: private domains, node processes, a probe node, waits that poll.

Each process runs with ``ROS_DOMAIN_ID`` = :func:`default_domain_id` (``UMBRELLA_TEST_DOMAIN_ID``,
else a domain of 10..99 that no other test session on the machine holds) and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``.  :class:`NodeProcess` starts any node and stops it
leaving no process or Fast DDS shared-memory segment behind; :class:`Probe` is the test's own
rclpy node; :func:`poll` waits for a condition and fails saying what it awaited and saw.
"""
from __future__ import annotations

import json
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

from ..ros.signals import STOP_WITH_ENV

#: environment variable that sets the default ROS domain of tests
DOMAIN_ID_ENV = 'UMBRELLA_TEST_DOMAIN_ID'


#: the domains handed out by default, and where a process holding one says so (a lock file)
FREE_DOMAINS = range(10, 100)


_DOMAIN_LOCKS = os.path.join(tempfile.gettempdir(), 'umbrella_sim_ros_domains')


_started: weakref.WeakSet = weakref.WeakSet()     # NodeProcess objects not closed

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
            fh = open(os.path.join(_DOMAIN_LOCKS, f'{domain}.lock'), 'a')
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


#: the environment variable naming a pytest-xdist worker (gw0, gw1, ...) in its process
XDIST_WORKER_ENV = 'PYTEST_XDIST_WORKER'


def default_domain_id() -> int:
    """
    ``$UMBRELLA_TEST_DOMAIN_ID`` if set, else a free domain of 10..99 (one per test session).

    The free domain is reserved for this process (:func:`reserve_domain`), from one derived
    from the pid; its child processes get it through the environment (:func:`ros_env`).  In
    pytest-xdist's worker k (``-n``), the set domain is that plus k: each worker's nodes and
    probes are a session of their own, as the free domains of different processes are.
    """
    value = os.environ.get(DOMAIN_ID_ENV)
    if value is None:
        return reserve_domain(os.getpid() % len(FREE_DOMAINS) + FREE_DOMAINS[0])
    try:
        domain = int(value)
    except ValueError:
        raise ValueError(f'{DOMAIN_ID_ENV}={value!r}: must be an integer 0..232') from None
    worker = os.environ.get(XDIST_WORKER_ENV, '')
    offset = int(worker[2:]) if worker.startswith('gw') and worker[2:].isdigit() else 0
    if not 0 <= domain <= 232 - offset:
        raise ValueError(f'{DOMAIN_ID_ENV}={value!r}: must be an integer 0..232'
                         + (f' less the worker index ({worker}: {offset})' if offset else ''))
    return domain + offset


DOMAIN_ID = default_domain_id()


def ros_env(domain_id: int | None = None) -> dict:
    """Return the environment for a child ROS process: private domain, localhost discovery."""
    domain = str(DOMAIN_ID if domain_id is None else domain_id)
    env = dict(os.environ)
    # the domain goes in DOMAIN_ID_ENV too: a child that imports this module (a test helper,
    # a user's wrapper around the node) then has the same DOMAIN_ID instead of one from its pid;
    # STOP_WITH_ENV: a node stops when this process has gone, even killed with no cleanup
    env.pop(XDIST_WORKER_ENV, None)     # (the domain given is this worker's already)
    env.update({DOMAIN_ID_ENV: domain, STOP_WITH_ENV: str(os.getpid())}, ROS_DOMAIN_ID=domain,
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               RMW_IMPLEMENTATION='rmw_fastrtps_cpp', PYTHONUNBUFFERED='1',
               RCUTILS_LOGGING_BUFFERED_STREAM='0')
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
    return text if len(text) <= limit else text[:limit] + '...'


# ------------------------------------------------------------- shared memory
_SHM = '/dev/shm/'


def _shm_segments(pid: int) -> set[str]:
    """Fast DDS segments a live process has mapped or open."""
    found = set()
    try:
        with open(f'/proc/{pid}/maps', encoding='utf-8', errors='replace') as fh:
            for line in fh:
                path = line.rstrip('\n').split(' ')[-1]
                if path.startswith(_SHM + 'fastrtps_'):
                    found.add(path)
        for fd in os.listdir(f'/proc/{pid}/fd'):
            try:
                target = os.readlink(f'/proc/{pid}/fd/{fd}')
            except OSError:
                continue
            if target.startswith(_SHM + 'fastrtps_') or target.startswith(_SHM + 'sem.fastrtps_'):
                found.add(target)
    except OSError:
        pass
    return found


def _segment_family(path: str) -> set[str]:
    """Return a segment, its lock file (_el) and its named semaphore (sem.<name>_mutex)."""
    name = os.path.basename(path)
    name = name[len('sem.'):] if name.startswith('sem.') else name
    name = name[:-len('_mutex')] if name.endswith('_mutex') else name
    name = name[:-len('_el')] if name.endswith('_el') else name
    return {_SHM + name, _SHM + name + '_el', _SHM + 'sem.' + name + '_mutex'}


def remove_stale_shm(paths: Iterable[str]) -> list[str]:
    """
    Remove the given Fast DDS participant segments that no live process uses; return them.

    A segment goes with its lock file when no live process maps or holds either open.  The
    per-domain port segments (``fastrtps_port*``) are left to Fast DDS, which reclaims them
    on the next start in that domain: a process that used one keeps a handle to it after its
    participant is gone, and a port file unlinked under it would cut it off from the domain.
    """
    families = [_segment_family(p) for p in set(paths)
                if not os.path.basename(p).removeprefix('sem.').startswith('fastrtps_port')]
    if not families:
        return []
    in_use: set[str] = set()
    for entry in os.listdir('/proc'):
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
def processes_text(node: NodeProcess | None) -> str:
    """
    Say whether a node runs, and which other NodeProcess of its domain ended by itself.

    For the failure of a wait on the node's topics: a deploy_controller that died leaves the
    node waiting for commands, and the message names the dead controller (exit_text), not
    only the node it watched.
    """
    if node is None:
        return 'no node started'
    state = ('node running' if node.running else f'node exited (code {node.proc.returncode})')
    return '; '.join([state, *(text for p in list(_started) if p is not node
                               and p.domain_id == node.domain_id
                               for text in [p.exit_text()] if text)])


class NodeProcess:
    """
    A ROS node in a child process (its own session); output goes to a log file.

    ``NodeProcess("-p", "v0:=0.0")`` starts ``umbrella_node`` with raw ROS arguments;
    ``parameters={"v0": 0.0}`` and ``namespace="a1"`` build them for you; ``module=`` runs
    another node of the package (``"umbrella_sim.deploy_controller"``).
    """

    def __init__(self, *ros_args: str, executable: list[str] | None = None,
                 module: str = 'umbrella_sim.node', parameters: dict | None = None,
                 namespace: str | None = None, domain_id: int | None = None,
                 cwd: str | None = None):
        self.domain_id = DOMAIN_ID if domain_id is None else domain_id
        args = list(ros_args)
        if namespace:
            args += ['-r', f"__ns:=/{namespace.strip('/')}"]
        for name, value in (parameters or {}).items():
            args += ['-p', f'{name}:={_ros_literal(value)}']
        fd, self.log_path = tempfile.mkstemp(prefix='umbrella_node-', suffix='.log')
        self.log = os.fdopen(fd, 'w+')
        self.command = (executable or [sys.executable, '-m', module]) + ['--ros-args', *args]
        # the node records by default into its working directory: unless cwd is given it
        # runs in a temporary one, removed by close(), so tests never leave bags behind
        self._own_cwd = None if cwd else tempfile.mkdtemp(prefix='umbrella_node_')
        self.cwd = cwd or self._own_cwd
        self.proc = subprocess.Popen(self.command, stdout=self.log, stderr=subprocess.STDOUT,
                                     env=ros_env(self.domain_id), start_new_session=True,
                                     cwd=self.cwd)
        self.shm: set[str] = set()
        self.name = os.path.basename(executable[0]) if executable else module
        self._stopped = False               # stop() called: an exit the test asked for
        _started.add(self)

    def exit_text(self) -> str | None:
        """
        Say how this process ended by itself (its exit code, its last line); None if not.

        None while it runs or once stop() ended it: an exit the test did not ask for, as a
        controller that died of a bad parameter or a misspelt module, is what a wait on
        another process's topics should name.
        """
        if self._stopped or self.running:
            return None
        lines = [line for line in self.output().splitlines() if line.strip()]
        return (f'{self.name} (pid {self.pid}) exited (code {self.proc.returncode})'
                + (f': {lines[-1].strip()}' if lines else ', printing nothing'))

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        with open(self.log_path, encoding='utf-8', errors='replace') as fh:
            return fh.read()

    def wait_for_log(self, pattern: str, timeout: float = 20.0, count: int = 1):
        """Return the count-th match of a regular expression in the output, waiting for it."""
        def found():
            matches = list(re.finditer(pattern, self.output()))
            if len(matches) >= count:
                return matches[count - 1]
            if not self.running:
                raise AssertionError(
                    f'process exited (code {self.proc.returncode}) before {count} log '
                    f'line(s) matching {pattern!r}; output:\n{self.output()}')
            return None
        self.shm |= _shm_segments(self.pid)
        return poll(found, timeout, lambda: f'no {count} log line(s) matching {pattern!r} '
                                            f'within {timeout} s; output:\n{self.output()}')

    def stop(self, sig=signal.SIGTERM, timeout: float = 10.0) -> int:
        """
        Signal, wait (SIGKILL to the group after timeout), remove leftover shared memory.

        Returns the exit code (negative: killed by that signal).
        """
        self._stopped = True
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
        _started.discard(self)
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


def python_value(value):
    """
    Return a parameter value as the Python value of its ROS type.

    numpy scalars and arrays become Python's (a float32 is no ROS type); a list of numbers
    with a float in it becomes a list of floats (a double[]: [0, 0.05, 0]).
    """
    if hasattr(value, 'tolist') and not isinstance(value, str):    # numpy
        value = value.tolist()
    if isinstance(value, (list, tuple)) and any(isinstance(v, float) for v in value) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        value = [float(v) for v in value]
    return value


def _ros_literal(value) -> str:
    """
    Return a Python value as the YAML of ``-p name:=value``, of the type Python gives it.

    A string stays a string ('1', 'true', 'a: b' are not read as a number, a bool or a
    mapping); a list of numbers with a float in it is a double[] ([0, 0.05, 0], which rcl
    refuses as a mixed sequence); numpy scalars and arrays are their Python values.
    """
    value = python_value(value)
    if isinstance(value, (list, tuple)):        # a ROS array: rib.<name> per-rib values
        return '[' + ', '.join(_ros_literal(v) for v in value) + ']'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):                  # a double-quoted YAML scalar: a string
        return json.dumps(value)
    return str(value)


# ------------------------------------------------------------------- probe
#: the depth of a probe's keep-last readers, at least: 10 s of a 100 Hz topic
PROBE_DEPTH = 1000


class Probe:
    """The test's own rclpy node (its own context) spinning in a background thread."""

    def __init__(self, name: str = 'probe', domain_id: int | None = None):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.parameter import Parameter
        from rclpy.signals import SignalHandlerOptions
        from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

        self.domain_id = DOMAIN_ID if domain_id is None else domain_id
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
        self.rclpy = rclpy
        self.context = rclpy.Context()
        # no rclpy signal handlers: Ctrl-C stays a KeyboardInterrupt of the test runner (which
        # tears the fixtures down) instead of shutting the context under a waiting test
        rclpy.init(context=self.context, domain_id=self.domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        # no parameter or type-description services: every service is one more entity for
        # the executor to gather at each turn, and nothing asks a probe for them
        self.node = rclpy.create_node(
            name, context=self.context, start_parameter_services=False,
            parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list] = {}
        self._clients: dict = {}
        self._lock = threading.Lock()
        self._arrival = threading.Condition()   # notified at each message received
        self._arrivals: dict[str, int] = {}     # topic -> messages received
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        # no timeout: each turn with one built a timer; a context shut down wakes the wait
        while self.context.ok():
            try:
                self.executor.spin_once()
            except Exception:
                if not self.context.ok():
                    return
                raise

    def subscribe(self, topic: str, msg_type, qos=10):
        """
        Keep every message on topic with its arrival time (time.monotonic()).

        Its keep-last reader is PROBE_DEPTH deep at least, whatever the publisher's depth
        (10 for the node's joint_states): a probe that fell behind on a loaded machine lost
        states, and the test API's matching of joint_states to sleeve_force/applied failed.
        """
        if topic in self.received:
            return
        from rclpy.qos import HistoryPolicy, QoSProfile

        from ..ros.messages import own_qos

        if isinstance(qos, int):
            qos = QoSProfile(depth=max(qos, PROBE_DEPTH))
        elif qos.history == HistoryPolicy.KEEP_LAST and qos.depth < PROBE_DEPTH:
            qos = own_qos(qos)
            qos.depth = PROBE_DEPTH
        self.received[topic] = []

        def cb(msg, topic=topic):
            with self._lock:
                self.received[topic].append((time.monotonic(), msg))
            with self._arrival:
                self._arrivals[topic] = self._arrivals.get(topic, 0) + 1
                self._arrival.notify_all()
        self.node.create_subscription(msg_type, topic, cb, qos,
                                      event_callbacks=self._events(topic))

    def _events(self, topic: str):
        """
        Return a subscription's event callbacks: an incompatible QoS logged, as rclpy's default.

        Not rclpy's default incompatible-type one: each event handler is one more entity for
        the executor to gather at every turn (15 subscriptions: 196 -> 145 us a turn), and
        a publisher of another type reports it on its side (the node's log: rclpy's default).
        """
        from rclpy.event_handler import SubscriptionEventCallbacks
        from rclpy.qos import qos_policy_name_from_kind

        def incompatible_qos(event):
            self.node.get_logger().warning(
                f"New publisher discovered on topic '{topic}', offering incompatible QoS. No "
                'messages will be received from it. Last incompatible policy: '
                f'{qos_policy_name_from_kind(event.last_policy_kind)}')
        return SubscriptionEventCallbacks(incompatible_qos=incompatible_qos,
                                          use_default_callbacks=False)

    def messages(self, topic: str) -> list:
        with self._lock:
            return [m for _, m in self.received.get(topic, [])]

    def timed(self, topic: str) -> list:
        """Return [(arrival time.monotonic(), message)] of topic."""
        with self._lock:
            return list(self.received.get(topic, []))

    _poll = staticmethod(poll)

    def last(self, topic: str):
        """Return the latest (arrival, message) received on topic, or None."""
        with self._lock:
            received = self.received.get(topic)
            return received[-1] if received else None

    def wait_until(self, condition: Callable[[], Any], topic: str, timeout: float,
                   failure: Callable[[], str], interval: float = 0.02):
        """
        condition()'s first truthy value, tried again at each message on topic (as poll()).

        A wait for a message wakes when it comes, not at the next turn of a poll (a lockstep
        loop at 1 kHz, one state per command, went at the poll's 50 periods a second); at
        least every `interval` s too (a condition may depend on more than that topic).
        """
        deadline = time.monotonic() + timeout
        while True:
            with self._arrival:
                seen = self._arrivals.get(topic, 0)
            result = condition()
            if result:
                return result
            left = deadline - time.monotonic()
            if left < 0:
                raise AssertionError(failure())
            with self._arrival:
                self._arrival.wait_for(lambda: self._arrivals.get(topic, 0) != seen,
                                       min(left, interval))

    def wait_for(self, topic: str, predicate=lambda m: True, timeout: float = 20.0,
                 what: str = 'the condition'):
        """Return the first message on topic satisfying predicate, waiting for it."""
        def failure():
            msgs = self.messages(topic)
            last = f'; last: {_brief(msgs[-1])}' if msgs else ''
            return (f'no message on {topic} satisfying {what} within {timeout} s '
                    f'(got {len(msgs)}{last})')
        found = poll(lambda: [m for m in self.messages(topic) if predicate(m)][:1], timeout,
                     failure)
        return found[0]

    def wait_for_count(self, topic: str, count: int, timeout: float = 20.0) -> list:
        """Return the first ``count`` messages on topic, waiting for them."""
        poll(lambda: len(self.messages(topic)) >= count, timeout,
             lambda: f'fewer than {count} messages on {topic} within {timeout} s'
                     f' (got {len(self.messages(topic))})')
        return self.messages(topic)[:count]

    def publisher(self, topic: str, msg_type, qos=10):
        return self.node.create_publisher(msg_type, topic, qos)

    def wait_for_subscribers(self, pub, count: int = 1, timeout: float = 20.0):
        poll(lambda: pub.get_subscription_count() >= count, timeout,
             lambda: f'no {count} subscriber(s) on {pub.topic_name} within {timeout} s '
                     f'(got {pub.get_subscription_count()})')

    def call(self, srv_type, name: str, request, timeout: float = 20.0):
        """
        Call a service and return its response (AssertionError if none within timeout).

        One client per service, kept: a new client per call has to be discovered by the
        server before its answer can come back, which cost up to ~0.1 s a call.
        """
        key = (srv_type, name)
        client = self._clients.get(key)
        if client is None:
            client = self._clients[key] = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise AssertionError(f'service {name} not available within {timeout} s')
        future = client.call_async(request)
        poll(future.done, timeout, lambda: f'service {name} did not answer within {timeout} s',
             interval=0.002)
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
