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
The node's outbox: a thread that sends the publications the physics thread hands it, in order.

Why a thread: a publication's DDS writes and its recording cost the publishing thread ~0.1
ms of CPU (five topics to a subscriber in another process), a tenth of a 1 kHz period, and
the physics thread would spend it between two chunks of steps.  Handed over here, they run
while the physics thread is in the next chunk's compiled call (a ctypes call: the GIL is
released), so the physics thread keeps real time where its own work alone would (the
ribs' stage 2).  Order is kept: the items go out one at a time, first in first out;
``flush`` waits until every item handed over has gone out (the node calls it before it
publishes anything itself, so that nothing overtakes a publication still queued).  An error
of an item is kept (``error``): the items after it are dropped, and the physics thread
raises it at its next turn, as if it had published them itself.
"""
from __future__ import annotations

import collections
import threading
from typing import Callable


class Outbox:
    """A FIFO of items sent by one thread of its own (``send(item)``), in order."""

    def __init__(self, send: Callable[[object], None], name: str = 'outbox'):
        self._send = send
        self._items: collections.deque = collections.deque()
        self._ready = threading.Condition()
        self._pending = 0           # items handed over and not yet sent (or dropped)
        self._closed = False
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, item) -> None:
        """Hand an item over, to be sent after every item before it."""
        with self._ready:
            if self._closed:
                raise RuntimeError('the outbox is closed')
            self._items.append(item)
            self._pending += 1
            self._ready.notify_all()

    def submit(self, item, now: bool = False) -> None:
        """Hand an item over; now: send it from this thread, after every item before it."""
        if now:
            self.flush()
            self._send(item)
        else:
            self.put(item)

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until every item handed over has been sent; False if timeout came first."""
        if threading.current_thread() is self._thread:
            return True                 # (an item's own send: what it waits for is itself)
        with self._ready:
            return self._ready.wait_for(lambda: self._pending == 0, timeout)

    def close(self, timeout: float | None = 5.0) -> None:
        """Send what is queued, then end the thread."""
        with self._ready:
            self._closed = True
            self._ready.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._ready:
                self._ready.wait_for(lambda: self._items or self._closed)
                if not self._items:
                    return              # closed, and nothing left
                item = self._items.popleft()
            try:
                if self.error is None:
                    self._send(item)
            except BaseException as exc:    # kept for the physics thread to raise
                self.error = exc
            finally:
                with self._ready:
                    self._pending -= 1
                    self._ready.notify_all()
