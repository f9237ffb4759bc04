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
The benches against the code they measure: their options, smallest cases and step counts.

A bench drifts when the code it measures changes under it: a command line it times that
now refuses its options (bench_core's start-up ran ``--duration 1e-4``, shorter than the
0.2 ms step the command line then took, and crashed), a figure per step whose step is no
longer one (the planar benches divided by grid steps where stage 2 takes substeps of them).
Every bench's imports and parser (--help: the ones that start a node too), each offline
bench's smallest case with the options its docstring names, and the physics steps the
planar benches divide by.
"""
import glob
import os
import subprocess
import sys

from bench.step_figures import lock_grid_steps, physics_steps
import pytest
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.solver import UmbrellaSimulator
from umbrella_sim.core.step_rule import step_taken_now

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BENCHES = sorted(os.path.basename(p) for p in glob.glob(os.path.join(ROOT, 'bench', 'bench_*.py')))


def run_bench(name: str, *args: str, timeout: float = 120.0) -> str:
    """Run bench/<name> with args from the repository root; return its output (exit 0)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [ROOT] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]))
    done = subprocess.run([sys.executable, os.path.join('bench', name), *args], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f'bench/{name} {" ".join(args)}:\n{done.stdout}{done.stderr}'
    return done.stdout


@pytest.mark.slow
@pytest.mark.parametrize('name', BENCHES)
def test_every_bench_imports_what_it_measures_and_parses_its_options(name):
    assert 'usage:' in run_bench(name, '--help')


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


#: each offline bench's smallest case, its options as its docstring names them (slow tests, as
#: the --help runs: benches are not the fast subset's physics, formats and tools)
SMALLEST_CASES = [
    ('bench_nonlinear.py', '--meshes', '1', '--repeat', '1', '--duration', '0.3'),
    ('bench_recording.py', '--seconds', '0.2'),
    ('bench_inputs.py', '--megabytes', '0.01', '--cases', '4'),
    ('bench_umbrella_markers.py', '--ribs', '2', '--elements', '1', '--calls', '1',
     '--repeat', '1'),
    ('bench_umbrella3d.py', '--ribs', '2', '--elements', '1', '--steps', '2', '--repeat', '1',
     '--duration', '0.002', '--kernel-ribs', '2', '--kernel-steps', '5', '--no-numpy'),
    ('bench_umbrella3d_nonlinear.py', '--steps', '2', '--ribs', '2', '--elements', '1',
     '--paths', 'compiled'),
    ('bench_ribs_node.py', '--ribs', '2', '--duration', '0.002'),
    ('bench_core.py', '--meshes', '1', '--repeat', '1'),
    ('bench_sweep.py', '--cases', '2', '--duration', '0.01', '--workers', '1'),
]


@pytest.mark.slow
@pytest.mark.parametrize('case', SMALLEST_CASES, ids=lambda case: case[0])
def test_each_offline_bench_runs_its_smallest_case(case):
    run_bench(*case)
