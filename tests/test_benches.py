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
The benches against the code they measure: the steps they count.

A bench drifts when the code it measures changes under it: a figure per step whose step is
no longer one (the planar benches divided by grid steps where stage 2 takes substeps of
them).  The physics steps the planar benches divide by.
"""
from bench.step_figures import lock_grid_steps, physics_steps
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.solver import UmbrellaSimulator
from umbrella_sim.core.step_rule import step_taken_now


def test_physics_steps_of_a_run_with_stage2_substeps_cover_its_time():
    # N = 2 at time_step 0: stage 1 on the 0.2 ms grid, stage 2 in substeps of the mesh's step
    sim = UmbrellaSimulator(UmbrellaParams(elements_per_segment=2, time_step=0.0))
    sim.advance(round(0.5 / sim.h))
    assert sim.lock_event is not None and sim.stage2_substeps > 1
    before = lock_grid_steps(sim)
    stage1 = before * sim.h
    stage2 = (physics_steps(sim) - before) * step_taken_now(sim)
    assert abs(stage1 + stage2 - sim.time) < sim.h        # (the lock's grid step counts one)
    assert physics_steps(sim, before) == before           # (stage 1: one a grid step)
