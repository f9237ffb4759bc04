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
import threading

import pytest

from umbrella_sim.testing.processes import poll

pytestmark = [pytest.mark.ros]


def test_a_callback_waiting_for_a_worker_is_submitted_once(probe):
    import rclpy
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
    from std_msgs.msg import Float64

    from umbrella_sim.ros.executor import CallbackPool

    node = rclpy.create_node('callback_pool_test', context=probe.context)
    executor = CallbackPool(num_threads=1, context=probe.context)
    executor.add_node(node)
    busy, release, taken = threading.Event(), threading.Event(), []

    def hold_the_worker(msg):
        busy.set()
        release.wait(20.0)

    for topic, callback in (('pool_busy', hold_the_worker),
                            ('pool_waiting', lambda msg: taken.append(msg.data))):
        node.create_subscription(Float64, topic, callback, 10,
                                 callback_group=MutuallyExclusiveCallbackGroup())
    pubs = [probe.publisher(topic, Float64) for topic in ('pool_busy', 'pool_waiting')]
    for pub in pubs:
        probe.wait_for_subscribers(pub)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.01)
    spinning = threading.Thread(target=spin, daemon=True)
    spinning.start()
    try:
        pubs[0].publish(Float64(data=1.0))
        assert busy.wait(20.0), 'the first callback never began'
        pubs[1].publish(Float64(data=2.0))
        # the second is ready, the only worker busy: the executor yields it turn after turn
        poll(lambda: executor.waited >= 3, 20.0,
             lambda: f'the waiting callback was yielded again {executor.waited} time(s)')
        assert executor.submitted == 2          # each callback once, however often yielded
        release.set()
        poll(lambda: taken, 20.0, lambda: 'the waiting callback never ran')
        assert taken == [2.0]
        assert executor.submitted == 2
    finally:
        release.set()
        stop.set()
        spinning.join(timeout=5.0)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()


def test_a_dedicated_group_is_waited_and_run_on_its_own_thread(probe):
    """
    A dedicated group's callback runs while the pool's only worker is busy, on its own thread.

    Its subscription and that subscription's event handlers are left out of the pool's wait
    set (can_execute), every other entity stays in it; the thread ends at shutdown.
    """
    import rclpy
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
    from std_msgs.msg import Float64

    from umbrella_sim.ros.executor import CallbackPool

    node = rclpy.create_node('dedicated_group_test', context=probe.context)
    executor = CallbackPool(num_threads=1, context=probe.context)
    executor.add_node(node)
    busy, release, ran_on = threading.Event(), threading.Event(), []

    def hold_the_worker(msg):
        busy.set()
        release.wait(20.0)

    pooled = node.create_subscription(Float64, 'pool_held', hold_the_worker, 10,
                                      callback_group=MutuallyExclusiveCallbackGroup())
    own = MutuallyExclusiveCallbackGroup()
    dedicated = node.create_subscription(
        Float64, 'dedicated', lambda msg: ran_on.append(threading.current_thread()), 10,
        callback_group=own)
    executor.dedicate(own)
    assert list(dedicated.event_handlers)               # (rclpy's default QoS events)
    assert not any(map(executor.can_execute, [dedicated, *dedicated.event_handlers]))
    assert all(map(executor.can_execute, [pooled, *pooled.event_handlers, *node.services]))
    pubs = [probe.publisher(topic, Float64) for topic in ('pool_held', 'dedicated')]
    for pub in pubs:
        probe.wait_for_subscribers(pub)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.01)
    spinning = threading.Thread(target=spin, daemon=True)
    spinning.start()
    try:
        pubs[0].publish(Float64(data=1.0))
        assert busy.wait(20.0), 'the pooled callback never began'
        pubs[1].publish(Float64(data=2.0))
        poll(lambda: ran_on, 20.0, lambda: 'the dedicated callback never ran (worker busy)')
        assert not release.is_set() and ran_on[0].name == 'dedicated callbacks'
        # an entity the group gets while its thread waits is waited from then on
        node.create_subscription(Float64, 'dedicated_later',
                                 lambda msg: ran_on.append(threading.current_thread()), 10,
                                 callback_group=own)
        later = probe.publisher('dedicated_later', Float64)
        probe.wait_for_subscribers(later)
        later.publish(Float64(data=3.0))
        poll(lambda: len(ran_on) == 2, 20.0, lambda: "the group's later subscription never ran")
        assert ran_on[1] is ran_on[0]
    finally:
        release.set()
        stop.set()
        spinning.join(timeout=5.0)
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()
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
