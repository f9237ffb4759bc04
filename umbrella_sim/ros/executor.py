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
The node's executor: callbacks run by a pool of threads, each ready callback handed over once.

rclpy's MultiThreadedExecutor (Jazzy's rclpy 7.1) yields a ready callback again, and submits
it to its thread pool again, for as long as no worker has begun it, and each of these turns
returns at once: the spinning thread loops holding the GIL while the worker that should run
the callback waits for the GIL (ros2/rclpy#1452, fixed upstream by ros2/rclpy#1547, not in
Jazzy's wheels).  Measured on the node in lockstep at 1 kHz: ~270 turns of the executor for
each /sleeve_force command, which the subscription's callback took 20-240 ms (median 43 ms,
up to 1.4 s) after it was published, the physics thread waiting for it all along.

:class:`CallbackPool` is built on rclpy's public Executor API (``wait_for_ready_callbacks``,
as a custom executor is meant to be): a callback is submitted to the pool once; yielded
again before a worker has begun it, the spinning thread waits, GIL released, until one does.
Callback groups, the services' and the command's, keep their meaning: the executor's base
class only yields a callback whose group can run it.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import threading

from rclpy.executors import (ConditionReachedException, Executor, ExternalShutdownException,
                             ShutdownException, TimeoutException)


class CallbackPool(Executor):
    """Run callbacks in a pool of ``num_threads`` threads, each ready callback submitted once."""

    def __init__(self, num_threads: int = 2, *, context=None):
        super().__init__(context=context)
        self._pool = ThreadPoolExecutor(num_threads, thread_name_prefix='callbacks')
        self._begun: dict = {}      # task submitted -> Event set when a worker begins it
        self.resubmissions = 0      # turns that found their task not yet begun (waited)

    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False) -> None:
        try:
            task, _, _ = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ConditionReachedException, ExternalShutdownException, ShutdownException,
                TimeoutException):
            return
        begun = self._begun.get(task)
        if begun is not None and not begun.is_set():
            # yielded again before a worker took it: let one take it (this wait releases
            # the GIL), instead of submitting it once more
            self.resubmissions += 1
            begun.wait(timeout_sec if timeout_sec is not None and timeout_sec >= 0 else None)
        else:       # a new task, or a coroutine's task to resume
            begun = self._begun[task] = threading.Event()
            self._pool.submit(_begin, task, begun)
        for done in [t for t in self._begun if t.done()]:
            del self._begun[done]
            done.result()           # a callback's exception is raised here, as rclpy's

    def spin_once(self, timeout_sec: float | None = None) -> None:
        self._spin_once_impl(timeout_sec)

    def spin_once_until_future_complete(self, future, timeout_sec: float | None = None) -> None:
        future.add_done_callback(lambda _: self.wake())
        self._spin_once_impl(timeout_sec, future.done)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Stop (rclpy's Executor.shutdown: wait for the callbacks running), then the pool."""
        done = super().shutdown(timeout_sec)
        self._pool.shutdown(wait=False, cancel_futures=True)
        return done


def _begin(task, begun: threading.Event) -> None:
    begun.set()
    task()
