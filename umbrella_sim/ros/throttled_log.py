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
Warnings logged at most once a period per kind, each saying how many were held back.

rclpy's own ``throttle_duration_sec`` inspects the caller's frame on every call (~3.5 ms
measured), which throttled the command callback to ~130 commands/s during a flood; this
costs a dictionary look-up.
"""
from __future__ import annotations

import math
import time


class ThrottledWarnings:
    """warn(key, period, text): log text() as a WARN at most once per period (s) per key."""

    def __init__(self, logger):
        self.logger = logger
        self._at: dict[str, float] = {}       # wall time of the last warning, per key
        self._more: dict[str, int] = {}       # warnings held back since, per key

    def warn(self, key: str, period: float, text) -> None:
        now = time.monotonic()
        last = self._at.get(key, -math.inf)
        if now - last >= period:
            more = self._more.pop(key, 0)
            self._at[key] = now
            self.logger.warning(text() + (f' (the same said {more} more time(s) in the '
                                          f'{now - last:.0f} s since it was last logged, '
                                          'not logged)' if more else ''))
        else:
            self._more[key] = self._more.get(key, 0) + 1
