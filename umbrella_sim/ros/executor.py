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
Jazzy's wheels).  Measured on the node in lockstep at 1 kHz, a command every ~20 ms: up to
~260 turns of the executor for each /sleeve_force command, whose callback ran a median
1.1-46 ms (8 runs) and up to 148 ms after the command was published, the physics thread
waiting for it all along; here 0.9-1.2 ms, at most 7 ms.

:class:`CallbackPool` is built on rclpy's public Executor API (``wait_for_ready_callbacks``,
as a custom executor is meant to be): a callback is submitted to the pool once; yielded
again before a worker has begun it, the spinning thread waits, GIL released, until one does.
Callback groups, the services' and the command's, keep their meaning: the executor's base
class only yields a callback whose group can run it.

rclpy 7.1's executor builds its wait set anew at every turn from every entity of its nodes
(``_wait_for_ready_callbacks``: no cache across turns), and runs each callback's group's
bookkeeping through a guard condition that wakes the wait again.  The node's 9 services,
1 subscription and 25 event handlers (rclpy's default incompatible-QoS and -type ones of
each publisher, and the subscription's) cost the spinning thread ~0.36 ms of CPU a turn, and
a command took ~1.7 turns, then a hand-over to a worker.  :meth:`CallbackPool.dedicate` gives
one callback group a thread and a wait set of its own: the command's subscription and its
event handlers are waited there alone and their callbacks run on that thread as they come,
while the pool's wait set keeps the rest, idle in a run.  Nothing is dropped: every entity
is waited by one of the two (the parameter and type-description services and the
publishers' QoS events stay, in the idle one).  A turn of the small wait set costs ~64 us
of CPU against ~157 us of the whole (a node of 10 publishers, 1 subscription, 9 services;
best of 3, alone).  Only public API: each waiter is an :class:`~rclpy.executors.Executor`
whose ``can_execute`` admits its own entities; the dedicated one waits on the pool's nodes
(``wait_for_ready_callbacks(nodes=...)``) without being added to them (a node has one
executor).
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
import threading
import time

from rclpy.executors import (ConditionReachedException, Executor, ExternalShutdownException,
                             ShutdownException, TimeoutException)


class CallbackPool(Executor):
    """Run callbacks in a pool of ``num_threads`` threads, each ready callback submitted once."""

    def __init__(self, num_threads: int = 2, *, context=None):
        self._dedicated: dict = {}      # callback group -> its _GroupWaiter
        super().__init__(context=context)
        self._pool = ThreadPoolExecutor(num_threads, thread_name_prefix='callbacks')
        # task submitted -> (Event set when a worker begins it, Event set when that call returns)
        self._calls: dict = {}
        self.submitted = 0          # tasks handed to the pool (a coroutine's resumption too)
        self.waited = 0             # turns that found their task not yet begun (and waited)
        self._stopping = threading.Event()
        self._errors: list[BaseException] = []     # a dedicated thread's callback raised

    def dedicate(self, group) -> None:
        """
        Wait for and run the callbacks of ``group`` on a thread and in a wait set of their own.

        Its entities (a subscription and its event handlers) leave the pool's wait set.  Each
        is run on that thread as it comes, one at a time (a dedicated group is mutually
        exclusive whatever its type); the thread starts at the first spin and ends at
        :meth:`shutdown`; a callback's exception is raised by the next spin_once.
        """
        if group not in self._dedicated:
            self._dedicated[group] = _GroupWaiter(group, self.get_nodes, self._stopping,
                                                  self._context)
            self.wake()         # the pool's next wait set leaves them out

    def wake(self) -> None:
        """Wake every wait (a node's new entity, say, may be a dedicated group's)."""
        super().wake()
        for waiter in self._dedicated.values():
            waiter.wake()

    def can_execute(self, entity) -> bool:
        """As rclpy's, and not an entity of a dedicated group (its own thread waits for it)."""
        return entity.callback_group not in self._dedicated and super().can_execute(entity)

    def _start_dedicated(self) -> None:
        for waiter in self._dedicated.values():
            if waiter.thread is None:
                waiter.thread = threading.Thread(target=self._run_dedicated, args=(waiter,),
                                                 name='dedicated callbacks', daemon=True)
                waiter.thread.start()

    def _run_dedicated(self, waiter: '_GroupWaiter') -> None:
        try:
            while not self._stopping.is_set():
                waiter.spin_once()
        except (ExternalShutdownException, ShutdownException):
            pass
        except BaseException as exc:     # a callback's: the pool's spin_once raises it
            self._errors.append(exc)
            self.wake()

    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False) -> None:
        if self._errors:
            raise self._errors.pop(0)
        self._start_dedicated()
        try:
            task, _, _ = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ConditionReachedException, ExternalShutdownException, ShutdownException,
                TimeoutException):
            return
        begun, returned = self._calls.get(task, (None, None))
        if begun is None or returned.is_set():      # new, or a coroutine's task to resume
            self._calls[task] = begun, returned = threading.Event(), threading.Event()
            self._pool.submit(_call, task, begun, returned)
            self.submitted += 1
        elif not begun.is_set():
            # yielded again before a worker took it: let one take it (this wait releases
            # the GIL), instead of submitting it once more
            self.waited += 1
            begun.wait(timeout_sec if timeout_sec is not None and timeout_sec >= 0 else None)
        else:       # begun, not yet marked executing by rclpy's Task: give it the GIL
            time.sleep(0)
        for done in [t for t in self._calls if t.done()]:
            del self._calls[done]
            done.result()           # a callback's exception is raised here, as rclpy's

    def spin_once(self, timeout_sec: float | None = None) -> None:
        self._spin_once_impl(timeout_sec)

    def spin_once_until_future_complete(self, future, timeout_sec: float | None = None) -> None:
        future.add_done_callback(lambda _: self.wake())
        self._spin_once_impl(timeout_sec, future.done)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Stop (rclpy's Executor.shutdown: wait for the callbacks running), then the pool."""
        self._stopping.set()
        for waiter in self._dedicated.values():
            if waiter.thread is not None:       # its wait returns, its callback ends: it ends
                waiter.wake()
                waiter.thread.join(None if timeout_sec is None or timeout_sec < 0
                                   else timeout_sec)
            waiter.shutdown(0)
        done = super().shutdown(timeout_sec)
        self._pool.shutdown(wait=False, cancel_futures=True)
        return done


class _GroupWaiter(Executor):
    """Wait for the entities of one callback group of some nodes, and run their callbacks."""

    def __init__(self, group, nodes, stopping: threading.Event, context):
        super().__init__(context=context)
        self._group, self._nodes, self._stopping = group, nodes, stopping
        self.thread: threading.Thread | None = None

    def can_execute(self, entity) -> bool:
        return entity.callback_group is self._group and super().can_execute(entity)

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """
        Wait (without timeout: no timer to build each turn) for a callback, and run it.

        A wake() after the stopping Event is set ends the wait.
        """
        try:
            task, _, _ = self.wait_for_ready_callbacks(timeout_sec, self._nodes(),
                                                       self._stopping.is_set)
        except (ConditionReachedException, TimeoutException):
            return
        task()
        if task.done():
            task.result()           # a callback's exception is raised here


def _call(task, begun: threading.Event, returned: threading.Event) -> None:
    begun.set()
    try:
        task()
    finally:
        returned.set()
