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
The node's executor (ros/executor.py): each ready callback is handed to the pool once.

rclpy's executor yields a callback again at each turn while no worker has begun it; rclpy's
MultiThreadedExecutor submitted it again each time, looping with the GIL held.  Here the
pool's one worker is kept busy by one callback while another is ready: the second is
yielded turn after turn, and submitted once.
"""
import contextlib
import threading
from types import SimpleNamespace

import pytest

from umbrella_sim.testing.processes import poll

pytestmark = [pytest.mark.ros]


@contextlib.contextmanager
def pool_with_a_held_worker(probe, node_name: str):
    """
    Yield a one-worker CallbackPool's (node, executor, busy, release, hold, spinning).

    A callback ``hold`` sets busy and keeps the worker until release is set; ``spinning`` is
    the thread that spins the executor; ``start(held, other)`` waits for the two publishers'
    subscribers, starts the spin, publishes 1.0 on held, waits until the worker is held, then
    publishes 2.0 on other.  Leaving releases the worker, stops the spin and destroys the node.
    """
    import rclpy

    from umbrella_sim.ros.executor import CallbackPool

    node = rclpy.create_node(node_name, context=probe.context)
    executor = CallbackPool(num_threads=1, context=probe.context)
    executor.add_node(node)
    busy, release, stop = threading.Event(), threading.Event(), threading.Event()

    def hold(msg):
        busy.set()
        release.wait(20.0)

    def spin():
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.01)
    spinning = threading.Thread(target=spin, daemon=True)

    def start(held, other):
        from std_msgs.msg import Float64

        for pub in (held, other):
            probe.wait_for_subscribers(pub)
        spinning.start()
        held.publish(Float64(data=1.0))
        assert busy.wait(20.0), 'the holding callback never began'
        other.publish(Float64(data=2.0))

    try:
        yield SimpleNamespace(node=node, executor=executor, busy=busy, release=release,
                              hold=hold, spinning=spinning, start=start)
    finally:
        release.set()
        stop.set()
        if spinning.is_alive():
            spinning.join(timeout=5.0)
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()


def test_a_callback_waiting_for_a_worker_is_submitted_once(probe):
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
    from std_msgs.msg import Float64

    with pool_with_a_held_worker(probe, 'callback_pool_test') as pool:
        node, executor = pool.node, pool.executor
        taken = []
        for topic, callback in (('pool_busy', pool.hold),
                                ('pool_waiting', lambda msg: taken.append(msg.data))):
            node.create_subscription(Float64, topic, callback, 10,
                                     callback_group=MutuallyExclusiveCallbackGroup())
        pool.start(*(probe.publisher(topic, Float64) for topic in ('pool_busy', 'pool_waiting')))
        # the second is ready, the only worker busy: the executor yields it turn after turn
        poll(lambda: executor.waited >= 3, 20.0,
             lambda: f'the waiting callback was yielded again {executor.waited} time(s)')
        assert executor.submitted == 2          # each callback once, however often yielded
        pool.release.set()
        poll(lambda: taken, 20.0, lambda: 'the waiting callback never ran')
        assert taken == [2.0]
        assert executor.submitted == 2


def test_a_dedicated_group_is_waited_and_run_on_its_own_thread(probe):
    """
    A dedicated group's callback runs while the pool's only worker is busy, on its own thread.

    Its subscription and that subscription's event handlers are left out of the pool's wait
    set (can_execute), every other entity stays in it; the thread ends at shutdown.
    """
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
    from std_msgs.msg import Float64

    ran_on = []
    with pool_with_a_held_worker(probe, 'dedicated_group_test') as pool:
        node, executor = pool.node, pool.executor
        pooled = node.create_subscription(Float64, 'pool_held', pool.hold, 10,
                                          callback_group=MutuallyExclusiveCallbackGroup())
        own = MutuallyExclusiveCallbackGroup()
        dedicated = node.create_subscription(
            Float64, 'dedicated', lambda msg: ran_on.append(threading.current_thread()), 10,
            callback_group=own)
        executor.dedicate(own)
        assert list(dedicated.event_handlers)               # (rclpy's default QoS events)
        assert not any(map(executor.can_execute, [dedicated, *dedicated.event_handlers]))
        assert all(map(executor.can_execute, [pooled, *pooled.event_handlers, *node.services]))
        pool.start(*(probe.publisher(topic, Float64) for topic in ('pool_held', 'dedicated')))
        poll(lambda: ran_on, 20.0, lambda: 'the dedicated callback never ran (worker busy)')
        assert not pool.release.is_set() and ran_on[0].name == 'dedicated callbacks'
        # an entity the group gets while its thread waits is waited from then on
        node.create_subscription(Float64, 'dedicated_later',
                                 lambda msg: ran_on.append(threading.current_thread()), 10,
                                 callback_group=own)
        later = probe.publisher('dedicated_later', Float64)
        probe.wait_for_subscribers(later)
        later.publish(Float64(data=3.0))
        poll(lambda: len(ran_on) == 2, 20.0, lambda: "the group's later subscription never ran")
        assert ran_on[1] is ran_on[0]
    assert not ran_on[0].is_alive()


def test_a_dedicated_callbacks_exception_is_raised_by_spin_once(probe):
    """As rclpy's executors: a callback's exception comes out of the spin (here, the next)."""
    import rclpy
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
    from std_msgs.msg import Float64

    from umbrella_sim.ros.executor import CallbackPool

    node = rclpy.create_node('dedicated_raise_test', context=probe.context)
    executor = CallbackPool(num_threads=1, context=probe.context)
    executor.add_node(node)
    own = MutuallyExclusiveCallbackGroup()

    def fails(msg):
        raise RuntimeError(f'command {msg.data} failed')

    node.create_subscription(Float64, 'dedicated_raise', fails, 10, callback_group=own)
    executor.dedicate(own)
    pub = probe.publisher('dedicated_raise', Float64)
    probe.wait_for_subscribers(pub)
    try:
        pub.publish(Float64(data=3.0))
        with pytest.raises(RuntimeError, match='command 3.0 failed'):
            poll(lambda: executor.spin_once(timeout_sec=0.01), 20.0,
                 lambda: "the dedicated callback's exception never came out of spin_once")
    finally:
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()
