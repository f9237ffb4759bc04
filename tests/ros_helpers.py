"""
Real node processes over real DDS: start/stop umbrella_node, probe its topics.

Each test session runs in its own ROS_DOMAIN_ID with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST.
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time

DOMAIN_ID = int(os.environ.get("UMBRELLA_TEST_DOMAIN_ID", str(os.getpid() % 90 + 10)))


def ros_env() -> dict:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(DOMAIN_ID), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               RMW_IMPLEMENTATION="rmw_fastrtps_cpp", PYTHONUNBUFFERED="1",
               RCUTILS_LOGGING_BUFFERED_STREAM="0")
    return env


os.environ.update({k: v for k, v in ros_env().items()
                   if k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE",
                            "RMW_IMPLEMENTATION")})


class NodeProcess:
    """
    umbrella_node in a child process; its stderr/stdout go to a file we can read.

    The node records by default into its working directory: unless cwd is given it runs in
    a temporary directory that is removed afterwards, so tests never leave bags behind.
    """

    def __init__(self, *ros_args: str, executable: list[str] | None = None,
                 cwd: str | None = None):
        self.log = tempfile.NamedTemporaryFile("w+", suffix=".log", delete=False)
        self._own_cwd = None if cwd else tempfile.mkdtemp(prefix="umbrella_node_")
        self.cwd = cwd or self._own_cwd
        cmd = ((executable or [sys.executable, "-m", "umbrella_sim.node"])
               + ["--ros-args", *ros_args])
        self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=subprocess.STDOUT,
                                     env=ros_env(), start_new_session=True, cwd=self.cwd)

    def output(self) -> str:
        with open(self.log.name, encoding="utf-8", errors="replace") as fh:
            return fh.read()

    def wait_for_log(self, pattern: str, timeout: float = 20.0, count: int = 1):
        """Return the count-th match of pattern in the node's output, waiting for it."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = list(re.finditer(pattern, self.output()))
            if len(found) >= count:
                return found[count - 1]
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(f"no log line matching {pattern!r}; output:\n{self.output()}")

    def stop(self, sig=signal.SIGTERM, timeout: float = 10.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
        os.unlink(self.log.name)
        if self._own_cwd:
            shutil.rmtree(self._own_cwd, ignore_errors=True)


class Probe:
    """A test-side rclpy node spinning in a background thread."""

    def __init__(self, name: str = "probe"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=DOMAIN_ID)
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
        self.received.setdefault(topic, [])

        def cb(msg, topic=topic):
            with self._lock:
                self.received[topic].append((time.monotonic(), msg))
        self.node.create_subscription(msg_type, topic, cb, qos)

    def messages(self, topic: str) -> list:
        with self._lock:
            return [m for _, m in self.received.get(topic, [])]

    def timed(self, topic: str) -> list:
        with self._lock:
            return list(self.received.get(topic, []))

    @staticmethod
    def _poll(condition, timeout: float, failure):
        """condition()'s first truthy value, polling; AssertionError(failure()) at the timeout."""
        deadline = time.monotonic() + timeout
        while True:
            result = condition()
            if result:
                return result
            if time.monotonic() > deadline:
                raise AssertionError(failure())
            time.sleep(0.02)

    def wait_for(self, topic: str, predicate=lambda m: True, timeout: float = 20.0):
        found = self._poll(lambda: [m for m in self.messages(topic) if predicate(m)][:1], timeout,
                           lambda: f"no message on {topic} satisfying the condition within "
                                   f"{timeout} s (got {len(self.messages(topic))})")
        return found[0]

    def wait_for_count(self, topic: str, count: int, timeout: float = 20.0) -> list:
        """
        Return the first `count` messages on topic, waiting for them.

        Messages on different topics have no mutual order in DDS, and a latched (transient
        local) sample reaches a late-matched reader only after the reliable handshake, so a
        test waits for what it asserts on instead of assuming it is already there.
        """
        self._poll(lambda: len(self.messages(topic)) >= count, timeout,
                   lambda: f"fewer than {count} messages on {topic} within {timeout} s"
                           f" (got {len(self.messages(topic))})")
        return self.messages(topic)[:count]

    def publisher(self, topic: str, msg_type, qos=10):
        return self.node.create_publisher(msg_type, topic, qos)

    def wait_for_subscribers(self, pub, count: int = 1, timeout: float = 20.0):
        self._poll(lambda: pub.get_subscription_count() >= count, timeout,
                   lambda: f"no subscriber on {pub.topic_name}")

    def call(self, srv_type, name: str, request, timeout: float = 20.0):
        client = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise AssertionError(f"service {name} not available")
        future = client.call_async(request)
        self._poll(future.done, timeout, lambda: f"service {name} did not answer")
        return future.result()

    def close(self):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=2.0)
