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

"""The whole umbrella's state and a step's work (integrator3d.py, kernel3d.py step them)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class ConvergenceError3D(ArithmeticError):
    """Newton did not converge, or a matrix was singular."""


@dataclass(frozen=True)
class State3D:
    """The umbrella's state: rib part (R, n) and shared part of q, v, multipliers, momentum."""

    t: float
    qr: np.ndarray
    qs: np.ndarray
    vr: np.ndarray
    vs: np.ndarray
    lam_r: np.ndarray
    lam_s: np.ndarray
    stuck: np.ndarray          # (R,) the hinge_angle a stuck hinge holds, NaN where free
    pr: np.ndarray | None = None
    ps: np.ndarray | None = None

    def at(self, t: float) -> 'State3D':
        """Return this state at the time t, the same arrays (dataclasses.replace, directly)."""
        return State3D(t, self.qr, self.qs, self.vr, self.vs, self.lam_r, self.lam_s,
                       self.stuck, self.pr, self.ps)


@dataclass(frozen=True)
class StepWork:
    """What one step did: work of the sleeve force, of each hinge's friction, of the drive."""

    force: float
    friction: np.ndarray
    drive: float
    iterations: int
    factorisations: int = 0    # of the iteration matrix (a kept one serves without)
    damping: float = 0.0       # the energy the beams' damping dissipated (J, >= 0)

    def plus(self, other: 'StepWork') -> 'StepWork':
        """Return what this step and the next (other) did together: every figure summed."""
        return StepWork(self.force + other.force, self.friction + other.friction,
                        self.drive + other.drive, self.iterations + other.iterations,
                        self.factorisations + other.factorisations,
                        self.damping + other.damping)
