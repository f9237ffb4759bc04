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
What the benches count of a planar run: its physics steps, stage 2's substeps each one.

A run whose step is chosen for it (``time_step`` 0) steps stage 1 on its grid (0.2 ms up to
2 elements a segment) and takes stage 2 in substeps of the grid step
(``UmbrellaSimulator.stage2_substeps``); ``UmbrellaSimulator.steps`` counts grid steps.  A
figure per step is a figure per physics step: these counts.
"""
import math


def lock_grid_steps(sim) -> int:
    """Return the grid steps a simulator took up to and including its lock's (all if none)."""
    if sim.lock_event is None:
        return sim.steps
    return min(sim.steps, math.floor(sim.lock_event.time / sim.h) + 1)


def physics_steps(sim, grid_steps: int | None = None) -> int:
    """
    Return the physics steps of a simulator's first grid_steps grid steps (default: all).

    Every grid step after the lock's counts stage 2's substeps (``stage2_substeps``); the
    lock's own grid step counts one (its part after the lock, fewer substeps than a full
    step, is left out: a count short by less than a grid step's substeps).
    """
    grid_steps = sim.steps if grid_steps is None else grid_steps
    before = min(grid_steps, lock_grid_steps(sim))
    return before + (grid_steps - before) * sim.stage2_substeps
