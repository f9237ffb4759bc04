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
The lockstep handshake of the node (``lockstep:=true``): a command answers each joint state.

The co-simulation handshake of SITL simulators: while deploying, the physics thread waits,
at each publication instant, for a command answering the last ``joint_states`` before it
computes the next period, so that a closed loop does not depend on how the operating system
schedules the controller.  The handshake is armed when the first command (after start or
~/reset) starts acting; any command, accepted or refused, answers the last state.
"""
from __future__ import annotations

import threading
import time


class Lockstep:
    """The handshake's state: armed, answered, and the waits it made."""

    def __init__(self):
        self.armed = False
        self.answered = threading.Event()
        self.waits = 0                  # periods that waited for their command
        self.waiting_since = 0.0        # monotonic start of the current wait, 0 = none

    def restart(self) -> None:
        """Start over for a new run (~/reset): the next command starts the handshake again."""
        self.armed = False
        self.answered.clear()

    def command_came(self) -> None:
        """Note a command (accepted or refused): it answers the last state."""
        self.answered.set()

    def published(self) -> None:
        """Note a joint state that went out: a command from now on answers it."""
        if self.armed:
            self.answered.clear()

    def waiting(self, on: bool, at_publication: bool, deploying: bool) -> bool:
        """Say whether the next period waits for its command."""
        return on and self.armed and at_publication and deploying and not self.answered.is_set()

    def wait_turn(self) -> float:
        """Take one idle turn of a wait; return how long this wait has lasted (wall s)."""
        if not self.waiting_since:
            self.waiting_since = time.monotonic()
            self.waits += 1
        return time.monotonic() - self.waiting_since

    def go(self, on: bool, at_publication: bool) -> bool:
        """
        Note that the run steps on: arm the handshake; True if a wait ended (pace on from it).

        Armed at a publication instant only, where the command starts acting: armed between
        two (a chunk of a long period), the period's end cleared the answer of a command not
        yet taken and the node waited for another, the first never applied.
        """
        ended = bool(self.waiting_since)
        self.waiting_since = 0.0
        if on and at_publication and self.answered.is_set():
            self.armed = True           # the handshake starts (or goes on)
        return ended
