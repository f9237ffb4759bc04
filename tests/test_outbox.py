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
The node's outbox (ros/outbox.py): what the physics thread hands over goes out in order.

Its promises, each tested with a send that blocks or fails on purpose (threads and events,
no sleeps): the items go out first in first out; flush returns only when every item handed
over has gone out; an error is kept, the items after it dropped, and flush still returns;
close sends what is queued.  Needs no ROS.
"""
import threading

import pytest

from umbrella_sim.ros.outbox import Outbox


def test_items_go_out_in_order_and_flush_waits_for_them():
    sent, gate = [], threading.Event()

    def send(item):
        gate.wait(10)               # the first item holds the others in the queue
        sent.append(item)

    box = Outbox(send)
    for i in range(200):
        box.put(i)
    assert not box.flush(timeout=0.01)      # held: not gone out yet
    gate.set()
    assert box.flush(timeout=10)
    assert sent == list(range(200))
    box.close()


def test_items_from_two_threads_keep_each_threads_order():
    sent = []
    box = Outbox(sent.append)

    def producer(name):
        for i in range(500):
            box.put((name, i))

    threads = [threading.Thread(target=producer, args=(n,)) for n in 'ab']
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert box.flush(timeout=10)
    for name in 'ab':
        assert [i for n, i in sent if n == name] == list(range(500))
    box.close()


def test_an_error_is_kept_and_the_items_after_it_dropped():
    sent = []

    def send(item):
        if item == 3:
            raise OSError('the writer is gone')
        sent.append(item)

    box = Outbox(send)
    for i in range(6):
        box.put(i)
    assert box.flush(timeout=10)            # (does not hang on the failed item)
    assert sent == [0, 1, 2]
    assert isinstance(box.error, OSError) and 'writer is gone' in str(box.error)
    box.close()


def test_close_sends_what_is_queued_then_refuses_more():
    sent, gate = [], threading.Event()

    def send(item):
        gate.wait(10)
        sent.append(item)

    box = Outbox(send)
    for i in range(5):
        box.put(i)
    closer = threading.Thread(target=box.close, kwargs={'timeout': 10})
    closer.start()
    gate.set()
    closer.join(10)
    assert sent == list(range(5))
    with pytest.raises(RuntimeError, match='closed'):
        box.put(5)


def test_flush_from_a_send_returns():
    box, flushed = None, []

    def send(item):
        flushed.append(box.flush(timeout=1))   # a send that publishes itself: no deadlock

    box = Outbox(send)
    box.put('x')
    assert box.flush(timeout=10)
    assert flushed == [True]
    box.close()
