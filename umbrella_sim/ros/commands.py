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
The node's sleeve_force command intake: each command checked, counted, recorded, held.

A command is checked against the running model (``core.forcing.command_force``), counted,
recorded as it came (accepted, or refused: at most REFUSED_RECORD_RATE refused ones a wall
second, so a flood of bad commands cannot fill the disk) and answers the lockstep handshake;
the latest accepted value is held for the physics thread, which applies it at the next
publication instant (node.py).  A burst is drained by the subscription's callback itself,
up to COMMAND_BATCH commands a turn of the executor, in order.
"""
from __future__ import annotations

import threading
import time
from typing import Callable

from rclpy.exceptions import InvalidHandle

from ..core.forcing import command_force

#: refused commands recorded (and published on sleeve_force/refused) per wall second at most
#: (the rest are counted only)
REFUSED_RECORD_RATE = 10
#: wall seconds between INFO lines about applied commands (each is a DEBUG line; a deploy
#: controller applies one per publication, 100 a second)
APPLIED_INFO_PERIOD = 5.0
#: commands taken in one turn of the executor at most: a burst is drained by the command
#: callback itself (rclpy's executor costs ~1-2 ms a turn, which held the intake to a few
#: hundred commands a second and kept ~/pause waiting behind a flood); the bound gives the
#: executor back between batches
COMMAND_BATCH = 256
#: the log line of a publisher of commands matched by the node (or gone): "<this> matched on
#: <topic> (N now)"
COMMANDER_LINE = 'sleeve_force publisher'
#: at a stop, the commands still queued are taken (checked, counted, recorded) for up to this
#: long (wall s), then for as long again only counted as dropped: none is lost uncounted
STOP_DRAIN_S = 1.0
#: ... and until none has come for this long (DDS may still be delivering what was sent
#: before the stop: an empty queue for a moment is not the end of it)
STOP_QUIET_S = 0.05


class CommandIntake:
    """
    The commands a node receives: counts, the refused ones' recording limit, the held value.

    sim() returns the running simulator (its time and model), recording() the recording
    being written (or None), warn(key, period, text) logs a throttled WARN; lockstep is the
    node's handshake (every command answers it).
    """

    def __init__(self, sim: Callable, recording: Callable, warn: Callable, lockstep):
        self._sim, self._recording, self._warn, self._lockstep = sim, recording, warn, lockstep
        self.subscription = None            # the node's: a burst is drained from it
        self.accepted = self.refused = 0
        self.refused_not_recorded = 0
        self._refused_window = (0.0, 0)     # (wall start, recorded in this 1 s window)
        self.taken_at_stop = self.dropped_at_stop = 0
        self._intake = threading.Lock()     # the callback's batches and the stop's drain
        self._lock = threading.Lock()
        self._force = 0.0
        self._last_applied = 0.0            # the last value on sleeve_force/applied
        self.logger = None                  # the node's
        self._topic = ''                    # the subscription's (resolved)
        self._echo = {}                     # "applied", "refused" -> the node's publisher
        self._info_at = -float('inf')       # wall time of the last INFO line on an applied one
        self._since_info = 0                # applied since that line

    def connect(self, node, command_topic: str) -> None:
        """
        Publish each command applied and refused, on <command>/applied and <command>/refused.

        The same topics, types and QoS as the recording's records (messages.COMMAND_ECHO).
        """
        from .messages import COMMAND_ECHO_QOS, COMMAND_ECHO_SUFFIXES, own_qos
        self.logger = node.get_logger()
        self._topic = command_topic
        self._echo = {key: node.create_publisher(self.command_type(), command_topic + suffix,
                                                 own_qos(COMMAND_ECHO_QOS))
                      for key, suffix in COMMAND_ECHO_SUFFIXES.items()}

    def event_callbacks(self):
        """Return the subscription's event callbacks: matched()."""
        from rclpy.event_handler import SubscriptionEventCallbacks
        return SubscriptionEventCallbacks(matched=self.matched)

    def matched(self, status) -> None:
        """
        Log each publisher of commands the subscription matches, or loses (its event callback).

        A command published before this side has matched its publisher is lost to the node
        until the publisher's next heartbeat (Fast DDS: every 3 s), though the publisher's
        side may already count this subscription (it matches first, measured 3-24 ms
        before): a publisher that must not lose its first command waits for this line
        (testing.SimulatedAntenna does).
        """
        change = status.current_count_change
        if change and self.logger is not None:
            self.logger.info(f"{COMMANDER_LINE} {'matched' if change > 0 else 'gone'} on "
                             f'{self._topic} ({status.current_count} now)')

    @staticmethod
    def command_type():
        from std_msgs.msg import Float64
        return Float64

    def applied(self, force: float, t: float, locked: bool) -> None:
        """
        Log, record and publish F_H = force acting from sim time t (before the solver sees it).

        Each at DEBUG; at INFO the first after APPLIED_INFO_PERIOD wall seconds without one,
        with how many came since the last.
        """
        note = ' (locked: no effect on motion)' if locked else ''
        now = time.monotonic()
        if now - self._info_at >= APPLIED_INFO_PERIOD:
            more = (f'; {self._since_info} more applied since the last report (each at DEBUG)'
                    if self._since_info else '')
            self.logger.info(f'sleeve force {force:.6g} N applied from t = {t:.9f} s{note}'
                             f'{more}')
            self._info_at, self._since_info = now, 0
        else:
            self._since_info += 1
            self.logger.debug(f'sleeve force {force:.17g} N applied from t = {t:.9f} s{note}')
        rec = self._recording()
        if rec is not None:
            rec.applied(force, t)
        if 'applied' in self._echo:
            self._echo['applied'].publish(self.command_type()(data=float(force)))
        self._last_applied = force

    def start_run(self, force: float) -> None:
        """
        Apply a new run's starting force (its sleeve_force, held already) at t = 0 if news.

        The applied history is the whole force history: the starting force goes on it, at
        start and after each ~/reset, where it differs from the last value applied (0 before
        any: a run starting from rest with no force says nothing).  Not held here: a command
        taken since the new run's driver was installed (hold) stays the latest.
        """
        if force != self._last_applied:
            self.applied(force, 0.0, False)

    @property
    def force(self) -> float:
        """Return the latest accepted value (the run's initial force until a command)."""
        with self._lock:
            return self._force

    def hold(self, force: float) -> None:
        """Hold force as if commanded (a new run: its sleeve_force parameter)."""
        with self._lock:
            self._force = force

    def on_message(self, msg) -> None:
        """
        Take a command and those queued behind it (up to COMMAND_BATCH), each in order.

        Inside the subscription's callback its (mutually exclusive) group is held, so taking
        more from it here is what the executor's next turns would do, without their cost.
        """
        with self._intake:
            self.take(msg)
            for _ in range(COMMAND_BATCH - 1):
                taken = self._queued()
                if taken is None:
                    return
                self.take(taken)

    def _queued(self):
        """Return the next command queued on the subscription, or None."""
        sub = self.subscription
        try:
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
        except InvalidHandle:         # (the node is being destroyed)
            return None
        return None if taken is None else taken[0]

    def counts_record(self) -> dict[str, str]:
        """Return the counts the recording's umbrella_sim.counts adds for the commands."""
        return {'refused_not_recorded': str(self.refused_not_recorded),
                'commands_taken_at_stop': str(self.taken_at_stop),
                'commands_dropped_at_stop': str(self.dropped_at_stop)}

    def drain_at_stop(self, period: float = STOP_DRAIN_S) -> str:
        """
        Take the commands still queued when the run stops: none is left uncounted.

        Until none has come for STOP_QUIET_S (at once when no publisher of commands is
        matched: none can be on its way), for `period` s at most, each is taken as during
        the run (checked, counted, recorded at the run's last time; none is applied: the run
        has ended) and counted in taken_at_stop;
        then, a flood still coming, for as long again each is only counted, in
        dropped_at_stop.  Called once the executor no longer spins, before the recording
        is closed (its counts record both).  Returns what it did, in words ('' if nothing).
        """
        if self.subscription is not None:
            with self._intake:
                start = last = time.monotonic()
                while time.monotonic() - start < 2 * period:
                    taken = self._queued()
                    if taken is None:
                        if (time.monotonic() - last >= min(STOP_QUIET_S, period)
                                or not self._publishers_matched()):
                            break
                        time.sleep(0.002)
                        continue
                    last = time.monotonic()
                    if last - start < period:
                        self.take(taken)
                        self.taken_at_stop += 1
                    else:
                        self.dropped_at_stop += 1
        if not (self.taken_at_stop or self.dropped_at_stop):
            return ''
        return (f'at the stop: {self.taken_at_stop} queued command(s) taken (counted and '
                'recorded, not applied: the run had ended)'
                + (f', {self.dropped_at_stop} more counted as dropped'
                   if self.dropped_at_stop else ''))

    def _publishers_matched(self) -> bool:
        """Say whether a publisher of commands is matched (one that may still be delivering)."""
        try:
            return self.subscription.get_publisher_count() > 0
        except Exception:      # (a subscription already destroyed: nothing can come)
            return False

    def take(self, msg) -> None:
        """Check, count and record one command; hold it if accepted."""
        sim = self._sim()
        t = sim.time
        try:
            force = command_force(msg.data, sim.params)
        except ValueError as exc:
            reason = str(exc)
            self.refused += 1
            now = time.monotonic()
            start, n = self._refused_window
            if now - start >= 1.0:
                start, n = now, 0
            rec = self._recording()
            if n < REFUSED_RECORD_RATE:       # a flood of bad commands cannot fill the disk
                if rec is not None:
                    rec.refused(msg, t)
                if 'refused' in self._echo:
                    self._echo['refused'].publish(msg)
                n += 1
            else:
                self.refused_not_recorded += 1
            self._refused_window = (start, n)
            self._warn('refused', 1.0, lambda: f'refused sleeve_force command: {reason} '
                       f'(refused so far: {self.refused})')
        else:
            self.accepted += 1
            rec = self._recording()
            if rec is not None:
                rec.command(msg, t)
            self.hold(force)
        self._lockstep.command_came()
