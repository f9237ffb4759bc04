#!/usr/bin/env python3

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
Real-time factor of the geometrically exact and the damped models.

Real-time factor of the geometrically exact model (flexible-nonlinear: co-rotational beams)
and of the damped linear one, beside the linear flexible model (simulated seconds per wall
second, one process).

V0 = -0.2, through the lock to t = 1.0 s, at the default (accuracy-chosen) time step (h1 / h2:
the steps stage 1 and stage 2 take; flexible up to 2 elements a segment: stage 1 on a 0.2 ms
grid, stage 2 in substeps of it; a step, and its Newton iterations, is a physics step, each
substep one: bench/step_figures.py), in blocks of 1 ms of simulated time through
UmbrellaSimulator.advance (the compiled loop with every step's outputs, what the node pays),
best of --repeat runs; us/step and the CPU real-time factor from process time, beside the
wall-clock one; each block builds the Sample of its last step, as a publication does.
Target: >= 5x at N = 4 for flexible-nonlinear (at V0 = -0.2; --v0 -1 -2 prints the
large-motion cost beside it: more Newton iterations a step where the frame swings and
buckles).  All four cases run on the compiled kernel (the nonlinear and damped ones with the
elastic law of _kernel_nonlinear.c attached); UMBRELLA_SIM_KERNEL=numpy gives the numpy
reference.  The machine is shared, so figures are noisy.

    python bench/bench_nonlinear.py [--meshes 1 2 4 8] [--repeat 2] [--duration 1.0]
                                    [--v0 -0.2 -1 -2]
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from bench.step_figures import physics_steps  # noqa: E402
from umbrella_sim.core.model import Stage  # noqa: E402
from umbrella_sim.core.params import UmbrellaParams  # noqa: E402
from umbrella_sim.core.solver import UmbrellaSimulator  # noqa: E402
from umbrella_sim.core.step_rule import step_taken_now  # noqa: E402

TARGETS = {('flexible-nonlinear', 4): 5.0}
CASES = (('flexible', 0.0), ('flexible', 0.02), ('flexible-nonlinear', 0.0),
         ('flexible-nonlinear', 0.02))


class RunStopped(Exception):
    """A benchmarked run that ended in a fault (e.g. a fibre turned 90 deg at V0 = -2, N = 1)."""


def one_run(params, duration):
    """
    Whole run in 1 ms blocks of simulated time (what the node pays).

    Returns wall and CPU seconds, the simulator, and the Newton iterations per physics step in
    stage 1 and in stage 2 (counted at the first block boundary after the lock).
    """
    sim = UmbrellaSimulator(params)
    integ = sim.engine.integrator
    per_block = max(1, round(1e-3 / sim.h))
    at_lock = None
    t0, c0 = time.perf_counter(), time.process_time()
    while sim.time < duration - 1e-12:
        block = sim.advance(per_block)
        block.last                            # the Sample a publication carries
        if block.error:
            raise RunStopped(f"stopped at t = {sim.time:.4f} s: {block.error.split(': ', 1)[-1]}")
        if at_lock is None and sim.stage == Stage.LOCKED:
            at_lock = (integ.iterations, sim.steps)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    its1 = its2 = float('nan')
    if at_lock is not None:
        before = physics_steps(sim, at_lock[1])
        its1 = at_lock[0] / before
        if sim.steps > at_lock[1]:
            its2 = (integ.iterations - at_lock[0]) / (physics_steps(sim) - before)
    return wall, cpu, sim, its1, its2


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--meshes', type=int, nargs='+', default=[1, 2, 4, 8])
    ap.add_argument('--repeat', type=int, default=2)
    ap.add_argument('--duration', type=float, default=1.0)
    ap.add_argument('--time-step', type=float, default=0.0,
                    help='s; 0 (default): the step chosen for each model and mesh '
                         '(step_rule.physics_step_of)')
    ap.add_argument('--v0', type=float, nargs='+', default=[-0.2],
                    help="initial sleeve velocities (m/s); the target is V0 = -0.2's")
    args = ap.parse_args()
    print(f"V0 = {', '.join(f'{v:g}' for v in args.v0)}, t = 0 -> {args.duration:g} s through "
          f"the lock, h = {f'{args.time_step:g} s' if args.time_step else 'chosen per mesh'}, "
          f'best of {args.repeat}, 1 ms blocks; loadavg {os.getloadavg()[0]:.2f} on '
          f'{os.cpu_count()} CPUs')
    print('newton/step 1|2: Newton iterations per step in stage 1 (deploying) | stage 2 (locked)')
    print('RTF = simulated s per second (CPU: process time, what the step costs; wall: what a '
          'loaded machine gave)')
    print(f"{'model':>19} {'zeta':>5} {'V0':>5} {'N':>3} {'dofs':>5} {'backend':>8} "
          f"{'h1 / h2 us':>11} {'newton/step 1|2':>15} {'us/step':>8} {'RTF cpu':>8} "
          f"{'RTF wall':>9} {'target':>9}")
    for v0 in args.v0:
        for n in args.meshes:
            for model, zeta in CASES:
                bench_case(args, v0, n, model, zeta)


def bench_case(args, v0, n, model, zeta):
    """Run one case --repeat times and print its line."""
    p = UmbrellaParams(v0=v0, model=model, damping_ratio=zeta, elements_per_segment=n,
                       time_step=args.time_step)
    walls, cpus = [], []
    for _ in range(args.repeat):
        try:
            wall, cpu, sim, its1, its2 = one_run(p, args.duration)
        except RunStopped as stopped:
            print(f'{model:>19} {zeta:>5g} {v0:>5g} {n:>3} {stopped}')
            return
        walls.append(wall)
        cpus.append(cpu)
    integ = sim.engine.integrator
    us_step = 1e6 * min(cpus) / physics_steps(sim)
    h12 = f'{1e6 * sim.h:.3g} / {1e6 * step_taken_now(sim):.3g}'
    rtf = args.duration / min(cpus)
    rtf_wall = args.duration / min(walls)
    target = TARGETS.get((model, n)) if v0 == -0.2 else None
    verdict = ('' if target is None
               else f"{target:>4.0f}x {'ok' if rtf >= target else 'MISS'}")
    print(f'{model:>19} {zeta:>5g} {v0:>5g} {n:>3} {sim.model.n:>5} {integ.backend:>8} '
          f'{h12:>11} {its1:>7.2f} {its2:>7.2f} {us_step:>8.1f} {rtf:>7.2f}x '
          f'{rtf_wall:>8.2f}x {verdict:>9}')


if __name__ == '__main__':
    main()
