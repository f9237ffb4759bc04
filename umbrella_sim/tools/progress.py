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

"""One progress line for the command lines: bar, how far, elapsed and ETA."""
from __future__ import annotations

import math
import sys
import time


class Progress:
    """
    A progress line on stderr, rewritten in place on a terminal, else one line per update.

    total: the amount to reach (simulated seconds, cases); what(done): how far, in words.
    """

    def __init__(self, total: float, what, stream=None, width: int = 25):
        self.total, self.what, self.width = total, what, width
        self.done, self.failed = 0.0, 0
        self.stream = stream or sys.stderr     # (at call time: a redirected stderr)
        self.tty = hasattr(self.stream, 'isatty') and self.stream.isatty()
        self.t0 = time.monotonic()

    @staticmethod
    def _hms(s: float) -> str:
        s = int(round(s))
        return f'{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}'

    def update(self, done: float, failed: bool = False, note: str = '') -> None:
        """Note that `done` of the total is reached (a failed item: counted as such)."""
        if not math.isfinite(done):         # (a chunk that took no step)
            return
        self.done = done
        self.failed += bool(failed)
        elapsed = time.monotonic() - self.t0
        frac = min(1.0, done / self.total) if self.total > 0 else 1.0
        eta = elapsed / frac * (1.0 - frac) if frac > 0 else math.inf
        line = (f"[{'#' * int(self.width * frac):<{self.width}}] {self.what(done)}"
                f"{f', {self.failed} failed' if self.failed else ''}  elapsed "
                f"{self._hms(elapsed)}  ETA {self._hms(eta) if math.isfinite(eta) else '-'}")
        if self.tty:
            self.stream.write('\r' + line)
        else:
            self.stream.write(line + (f'  ({note})' if note else '') + '\n')
        self.stream.flush()

    def close(self) -> None:
        if self.tty and self.done:
            self.stream.write('\n')
            self.stream.flush()
