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
Whether the umbrella's deployment stalled: the sleeve held short of the stop ('stalled').

Summary3D's watch on the deployment's rows; its text joins the run's validity warnings.
"""
from __future__ import annotations

import numpy as np

#: a stalled deployment ('stalled'), once it started: the sleeve short of the stop and at
#: rest, slower than STALL_SPEED_SHARE of its largest speed so far for STALL_TIME of sim time
#: (a rubbing hinge's regularised Coulomb torque lets a held frame creep at ~1e-3 of a
#: deployment's speed: not a motion), or a hinge stuck with no release time to come (only
#: its stick_torque releases it) for STUCK_TIME (the undamped frame it holds rings in place;
#: its holding torque peaks in the first cycles of the locked-hinge frame, ~20 Hz)
STALL_SPEED_SHARE = 0.01
STALL_TIME = 0.05
STUCK_TIME = 0.2


class StallWatch:
    """
    Whether the deployment stalled: the sleeve short of the stop, held back.

    A stuck hinge that the sleeve force does not release, hinge friction more than the
    frame's kinetic energy can pay over the rest of the travel, or a sleeve force that
    holds it back: the frame stops (or rings in place) on its way, and will not lock while
    that lasts.  ``stall`` is (t, y_H, the ribs stuck then) from when it is so, until it
    moves on or locks.  ribs: the run's (params3d.RibProperties): each one's release time
    (stick_until, 0: none) and whether its hinge rubs.
    """

    def __init__(self, y0: float, y_stop: float, speed: float, ribs):
        self.y0, self.y_stop = y0, y_stop
        self.until = np.array([r.stick_until for r in ribs], dtype=float)
        self.friction = any(r.hinge_coulomb > 0.0 or r.hinge_viscous > 0.0 for r in ribs)
        self.peak, self.slow_since, self.stuck_since = abs(speed), None, None
        self.stall: tuple | None = None

    def add(self, t: np.ndarray, y: np.ndarray, v: np.ndarray, locked: bool,
            stuck: np.ndarray) -> None:
        """Take the rows of a block of the started deployment (t, sleeve height and rate)."""
        if locked or not len(t):
            self.slow_since = self.stuck_since = self.stall = None
            return
        now = float(t[-1])
        self.peak = max(self.peak, float(np.abs(v).max()))
        if self.peak == 0.0 or abs(float(v[-1])) >= STALL_SPEED_SHARE * self.peak:
            self.slow_since = None
        elif self.slow_since is None:
            self.slow_since = now
        held_by = [int(k) for k in np.flatnonzero(stuck) if not self.until[k] > now]
        if not held_by:
            self.stuck_since = None
        elif self.stuck_since is None:
            self.stuck_since = now
        held = any(since is not None and now - since >= wait for since, wait in (
            (self.slow_since, STALL_TIME), (self.stuck_since, STUCK_TIME)))
        if not held:
            self.stall = None
        elif self.stall is None:
            self.stall = (now, float(y[-1]), held_by)

    def warnings(self) -> list[str]:
        """Return the 'stalled' text while the deployment is stalled."""
        if self.stall is None:
            return []
        t, y, stuck = self.stall
        short = (y - self.y_stop) / (self.y0 - self.y_stop) if self.y0 != self.y_stop else 0.0
        if stuck:
            why = (f"rib {', '.join(map(str, stuck))}'s hinge is stuck and holds the frame "
                   '(its stick_torque not reached)')
        elif self.friction:
            why = ("the hinges' friction takes more than the frame's kinetic energy can pay "
                   'over the rest of the travel')
        else:
            why = 'the sleeve force holds it back'
        return [f'stalled: the sleeve came to rest short of the stop by {100 * short:.1f} % '
                f'of its travel (y_H = {y:.4f} m at t = {t:.4f} s): {why}; it will not lock '
                'while that lasts (a larger v0 or sleeve_force deploys it)']
