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
Real-time pacing of the node: the state of sim time t goes out at wall time anchor + t / rtf.

Paced against ``time.monotonic()``, not a ROS timer: the node is the /clock source, and a
timer on sim time would wait on itself.  Sim time is anchored to the wall time of the last
(re)start, pause or lockstep wait, so it does not accumulate drift.  The overload policy:
more than MAX_LAG_S behind, the pacing restarts from now (the backlog is dropped, never caught
up in a burst); the sim then runs at the speed the machine allows, and the dropped wall time
accumulates in ``slip`` (the node's diagnostics report it).
"""
from __future__ import annotations

import threading
import time

#: the physics may fall this far behind wall time x real_time_factor; past it the pacing is
#: re-anchored (the backlog is dropped, not caught up) and the slip reported
MAX_LAG_S = 0.5
#: pacing waits up to this long are a plain sleep (sleep_until)
PLAIN_SLEEP_S = 0.005


def behind_text(lag: float, measured: float, real_time_factor: float) -> str:
    """
    Say how far behind real time a run is, and whether it is catching up.

    lag: how far behind its target the run is now (s); measured: the real-time factor over
    the last diagnostics interval, which exceeds the requested one while a lag shrinks.
    """
    shown = round(measured, 3)
    trend = ('catching up' if shown > real_time_factor else
             'keeping pace' if shown == real_time_factor else 'falling behind')
    return (f'behind real time by {lag:.3f} s ({trend}: {shown:.3f}x of {real_time_factor:g}x '
            'over the last second)')


#: wall seconds between two warnings that the physics cannot keep up (each says how many
#: more came meanwhile; diagnostics report the lag at 1 Hz)
LAG_WARN_PERIOD = 60.0


def lag_advice(real_time_factor: float, measured: float | None) -> str:
    """
    Say what makes a node that cannot keep up with real_time_factor keep up.

    measured: the last second's factor (diagnostics'), quoted where it shows the shortfall:
    a lag that began within the second follows a second that kept up, whose factor said
    nothing of it (and read 'cannot ... at 1x (measured 1.00x)').
    """
    can = (f' (measured {measured:.2f}x)' if measured and measured < real_time_factor
           else '')
    return (f'this machine cannot step this model at {real_time_factor:g}x real time{can}: '
            'give a lower real_time_factor, real_time_factor:=0 (as fast as it can; '
            'sim time is still exact), or, for a closed-loop controller, lockstep:=true '
            '(the node waits for each command: no command falls behind)')


class Pacer:
    """Wall-clock anchors of a run's sim time, its lag and slip; sleeps until a target."""

    def __init__(self, stop: threading.Event, wake: threading.Event):
        self._stop, self._wake = stop, wake
        self.wall_anchor = self.sim_anchor = 0.0
        self.slip = 0.0           # wall seconds dropped by re-anchoring (overload)
        self.re_anchors = 0
        self.max_lag = 0.0        # the largest lag since the last reset_max_lag (s)

    def anchor(self, sim_t: float, now: float | None = None) -> None:
        """Pace from here: sim time sim_t is wall time now."""
        self.wall_anchor = time.monotonic() if now is None else now
        self.sim_anchor = sim_t

    def target(self, sim_t: float, real_time_factor: float) -> float | None:
        """Return the wall time sim time sim_t is due at (None: not paced, rtf 0)."""
        if real_time_factor <= 0:
            return None
        return self.wall_anchor + (sim_t - self.sim_anchor) / real_time_factor

    def lag(self, target: float, now: float) -> float:
        """Return how far behind its target the run is at now (s; < 0: ahead), noted."""
        lag = now - target
        self.max_lag = max(self.max_lag, lag)
        return lag

    def after_wait(self, sim_t: float, period: float, real_time_factor: float,
                   now: float | None = None) -> None:
        """
        Pace on from a lockstep wait for a command answering the state of sim_t, now ended.

        The wait counts toward the period (sim s) the command lets run, all of it at most:
        the next state stays due a period after sim_t was due (the cadence of a run without
        lockstep) while the controller answers within the period; a later answer makes the
        period due at once (the wait is not lag).  Not paced (real_time_factor 0): from now.
        """
        now = time.monotonic() if now is None else now
        due = self.target(sim_t, real_time_factor)
        self.anchor(sim_t, now if due is None else max(due, now - period / real_time_factor))

    def re_anchor(self, now: float, sim_t: float, lag: float) -> None:
        """Apply the overload policy: pace from now, the lag counted as slip."""
        self.anchor(sim_t, now)
        self.slip += lag
        self.re_anchors += 1

    def sleep_until(self, target: float) -> None:
        """
        Sleep until the wall time target (or a stop).

        No spinning: a spin of the last 0.3 ms cost up to 0.3 core at 1 kHz; the kernel's
        wake-up latency (~0.1 ms) is well inside a publication period.  A wait of up to
        PLAIN_SLEEP_S is a plain sleep: an Event wait costs ~15 us of CPU against ~5 us (its
        lock and condition), and a stop or reset then waits at most that long.
        """
        while not self._stop.is_set():
            remaining = target - time.monotonic()
            if remaining <= 0:
                return
            if remaining <= PLAIN_SLEEP_S:
                time.sleep(remaining)
                return
            self._wake.wait(remaining - PLAIN_SLEEP_S)
            self._wake.clear()


class RateWindow:
    """
    The measured real-time factor of diagnostics: sim s per wall s the physics ran.

    The wall time of a pause (~/pause) is left out: a window that spans a pause and a run
    measured the run's pace diluted by the pause (0.06x for a run at 1x after a pause of
    most of the second), which the 'cannot keep up' warning then quoted as the machine's.
    A window that was paused all along measures 0 (sim time did not move).
    """

    def __init__(self, now: float, sim_t: float, paused: bool = False):
        self.restart(now, sim_t, paused)

    def restart(self, now: float, sim_t: float, paused: bool | None = None) -> None:
        """Start a window at now (paused: whether the run is paused; None: as it was)."""
        if paused is None:
            paused = self._since is not None
        self.wall, self.sim, self.paused_wall = now, sim_t, 0.0
        self._since = now if paused else None

    def pause(self, now: float, paused: bool) -> None:
        """Note whether the run is paused at now (a pause starting or ending then)."""
        if paused and self._since is None:
            self._since = now
        elif not paused and self._since is not None:
            self.paused_wall += now - self._since
            self._since = None

    def due(self, now: float, period: float = 1.0) -> bool:
        """Tell whether the window has lasted period (wall s)."""
        return now - self.wall >= period

    def factor(self, now: float, sim_t: float) -> float:
        """Return sim s per wall s of running since the window started (0: none ran)."""
        paused = self.paused_wall + (0.0 if self._since is None else now - self._since)
        running = now - self.wall - paused
        return (sim_t - self.sim) / running if running > 0 else 0.0
