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
Cost of the whole umbrella's step (core.umbrella3d): per-step cost vs ribs x elements, RTF.

  * us/step: CPU time of this thread per grid step (the midpoint step, its Newton
    iterations, the projection and every step's figures in Record3D), over --steps steps of
    the deployment from t = 0 (no lock), best of --repeat, on both paths: the compiled step
    (_kernel3d.c, UmbrellaSimulator3D.advance: the steps in one call, the figures added as a
    run) and the numpy reference (UmbrellaSimulator3D.step, one step a call); and that
    divided by the number of ribs: it must stay flat (block-arrow algebra: a step costs
    linearly in the ribs), and by the coordinates of a rib;
  * kernel us/step: the compiled step alone (CompiledStep3D.advance: --kernel-steps steps
    in one call, with the rows' stress figures it computes, no Record3D), best of
    --repeat, at the step chosen for the mesh (as the real-time factors below), in stage 1
    (from t = 0) and in stage 2 (from the lock on, the mode fit acting), with the Newton
    iterations and factorisations a step; stage 2 at the physics step the run takes there
    (the grid's step over the substeps a lock may need: the step column; at 12 ribs x 2 a
    moving base's lock takes 2), with the fit and Newton tolerance the run set for it;
  * real-time factors: simulated seconds per wall second, and CPU seconds per simulated
    second, of the runs the node would make: ribs 6 x 1 element in blocks of 1 ms (a 1 kHz
    publication), ribs 12 x 2 elements in blocks of 10 ms (100 Hz), each at the step chosen
    for its mesh (UmbrellaSimulator3D's default: the planar rule with the stage-2 mode fit,
    which the 3D model takes on every base: stage2fit.py), over --duration simulated
    seconds from t = 0 (deployment; --after-lock: stage 2, from the lock on), on the
    compiled path (advance a block at a time, as a driver would); the figures of the last
    step of each block are read as a publication would.
  * --base: every figure with the hub fixed (default), driven (prescribed: a half-sine jolt
    in X-Z and a spin-up about Y, BASE_VALUES) or on a free-floating bus (the default bus);
    a moving base takes its stage-2 mode fit (umbrella3d/stage2fit.py: the ribs' modes in the
    driven hub's frame, the free system's modes of a free bus: the ribs' fits with a
    low-rank correction, linear in the ribs), so its step for the mesh is the fixed hub's
    (0.1 ms at 1 element, 33 us at 2; without the fit 33 and 9.1 us).  Measured
    (--no-numpy --kernel-ribs 6 12 24, load 1.2-2.5), the compiled step alone in stage 2:
    free bus 131.7 / 263.5 / 530.9 us (22.0 us a rib; 151.9 / 417.2 / 1164.1 with the whole
    fit's dense maps it took before), hub fixed 47.5 / 95.1 / 190.5 us (7.9 a rib).  At 12 x 2
    a moving base's lock takes stage 2 in 2 substeps of 16.7 us (--kernel-ribs 6 12, load
    ~2): driven / free 445.5 / 464.8 us a substep, 2.03 / 2.04 Newton iterations, 0.125
    factorisations (hub fixed 174.2 us a 33 us step, 2.20); stepped at the grid's 33 us (this
    bench before) the fit of the substep took 4.74 / 4.88 iterations with the compiled step's
    Newton shrinks of the fit's own step, 2.33 / 2.29 with the step's (docs/umbrella3d.md).
The machine is shared (2 cores): CPU time is what the step costs, wall RTF what a user saw.
Targets: ribs 6 x 1 real time at 1 kHz within 0.5 core, ribs 12 x 2 real time
at 100 Hz.  Measured (--no-numpy --ribs 6 --elements 1 2 --kernel-ribs 6 12 --repeat 3, load
4.8-5.0, best of two runs), the compiled step alone, CPU us a step deploying / in stage 2:
6 x 1 29.7 / 48.6 (0.30 / 0.49 core), 12 x 2 105.7 / 191.7 (3.2 / 5.8 cores); 2.00 / 2.81
and 2.00 / 2.20 Newton iterations, 0.125 factorisations a step (docs/umbrella3d.md: what the
rest of a step is).  Since, a stage-2 step whose joints do not hold after the update that
converges in q takes a correction of the joints alone (integrators.newton_converged):
(--no-numpy --ribs 1 --elements 1 2 --kernel-ribs 6 12 --repeat 3, interleaved, load 0.5-1.3)
stage 2 at 1 element 6 x 1 47.5-47.9 -> 41.4-41.5 us (2.81 -> 2.09 iterations), 12 x 1
93.5-93.8 -> 82.1-82.3; at 2 elements and in stage 1 unchanged.  Since, the projection kept
with the iteration matrix, fewer and vectorised fit maps and the joint solve by columns
(docs/umbrella3d.md, what made the step cheaper): (--no-numpy --ribs 6 --kernel-ribs 6 12,
best of four runs, load ~1) 6 x 1 34.9 / 37.6 us (0.17 / 0.38 core), 12 x 2 120.3 / 147.7
(0.60 / 4.43 cores), the same iterations and factorisations a step.

    python bench/bench_umbrella3d.py [--ribs 1 2 4 8 16] [--elements 1 2] [--steps 40]
                                     [--repeat 2] [--duration 0.05] [--no-numpy]
                                     [--after-lock] [--base fixed|prescribed|free]
"""
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))

from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams  # noqa: E402
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D  # noqa: E402

#: each base's parameters: the driven one jolted along X and Z during the first 20 ms and
#: spun up to 3 rad/s about Y in 50 ms; the free bus the parameters' default (100 kg, 10 kg m2)
BASE_VALUES = {'fixed': {},
               'prescribed': {'base': 'prescribed', 'base_accel_x': 20.0, 'base_accel_z': -10.0,
                              'base_accel_duration': 0.02, 'base_spin_rate': 3.0,
                              'base_spin_ramp': 0.05},
               'free': {'base': 'free'}}
#: the base of every figure (set from --base)
BASE = BASE_VALUES['fixed']


def kernel_cost(sim: UmbrellaSimulator3D, steps: int, repeat: int):
    """
    Return (physics step, CPU s, iterations, factorisations) a step of the compiled step alone.

    From now, at the physics step the simulator takes (stage 2: h / stage2_substeps, with
    the fit and Newton tolerance it set for it; the grid's step there would step a fit made
    for another step).
    """
    compiled, best = sim.integrator.compiled, float('inf')
    sub = sim.stage2_substeps if sim.locked else 1
    for _ in range(repeat):
        t0 = time.thread_time()
        _, done, rows, _ = compiled.advance(sim.state, sim.k * sub, sim.h / sub, steps,
                                            sim.force, sim.locked)
        best = min(best, (time.thread_time() - t0) / done)
    return sim.h / sub, best, rows['iterations'].mean(), rows['factorisations'].mean()


def kernel_stages(ribs: int, elements: int, steps: int, repeat: int, stage2: bool):
    """Return (kernel_cost in stage 1 from t = 0, in stage 2 from the lock or None)."""
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': ribs, 'elements_per_segment': elements, **BASE}), kernel='compiled')
    sim.advance(2)                        # (the first factorisation, at the grid's step)
    deploying = kernel_cost(sim, steps, repeat)
    if not stage2:
        return deploying, None
    sim.run(1.0, after_lock=0.0)
    sim.advance(2)
    return deploying, kernel_cost(sim, steps, repeat)


def step_cost(ribs: int, elements: int, steps: int, repeat: int, kernel: str):
    """Return (CPU s per step, coordinates of a rib, Newton iterations per step)."""
    best = float('inf')
    for _ in range(repeat):
        sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
            {'ribs': ribs, 'elements_per_segment': elements, 'time_step': 1e-4, **BASE}),
            kernel=kernel)
        sim.step()                       # warm (imports, first factorisation)
        iterations = sim.integrator.iterations
        t0 = time.thread_time()
        if kernel == 'compiled':
            sim.advance(steps)
        else:
            for _ in range(steps):
                sim.step()
        best = min(best, (time.thread_time() - t0) / steps)
        per_step = (sim.integrator.iterations - iterations) / steps
    return best, sim.model.n_rib, per_step


def real_time(ribs: int, elements: int, block: float, duration: float, after_lock: bool):
    """Return (step h, wall RTF, CPU s per simulated s) of a run in publication blocks."""
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': ribs, 'elements_per_segment': elements, **BASE}), kernel='compiled')
    h = sim.h
    per_block = max(1, round(block / h))
    if after_lock:
        sim.run(1.0, after_lock=0.0)
    start = sim.time
    wall0, cpu0 = time.perf_counter(), time.process_time()
    published = 0
    while sim.time < start + duration - 1e-12:
        sim.advance(per_block)
        rows = sim.record.take()        # what a publication reads: the last step's figures
        published += len(rows['alpha1'][-1]) + len(rows['tip'][-1])
    assert published > 0
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return h, (sim.time - start) / wall, cpu / (sim.time - start)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--ribs', type=int, nargs='+', default=[1, 2, 4, 8, 16])
    ap.add_argument('--elements', type=int, nargs='+', default=[1, 2])
    ap.add_argument('--steps', type=int, default=40)
    ap.add_argument('--repeat', type=int, default=2)
    ap.add_argument('--duration', type=float, default=0.05)
    ap.add_argument('--no-numpy', action='store_true', help='the compiled path only')
    ap.add_argument('--after-lock', action='store_true',
                    help='real-time factors of stage 2 (from the lock on, the mode fit acting)')
    ap.add_argument('--base', default='fixed', choices=list(BASE_VALUES),
                    help='the hub fixed, driven (prescribed) or a free bus (BASE_VALUES)')
    ap.add_argument('--kernel-ribs', type=int, nargs='*', default=[1, 3, 6, 12],
                    help='ribs of the kernel table (none: no table)')
    ap.add_argument('--kernel-steps', type=int, default=1000)
    ap.add_argument('--no-stage2', action='store_true',
                    help='no kernel figures of stage 2 (each needs a run to the lock)')
    args = ap.parse_args(argv)
    global BASE
    BASE = BASE_VALUES[args.base]
    print(f'base: {args.base} {BASE}')
    print('per-step cost (h = 0.1 ms, deployment from t = 0; CPU of this thread)')
    print(f"{'path':>9} {'ribs':>5} {'elements':>9} {'coords/rib':>10} {'Newton it':>9} "
          f"{'us/step':>10} {'us/step/rib':>12} {'ns/step/rib/coord':>18}")
    for kernel in ('compiled',) + (() if args.no_numpy else ('numpy',)):
        for elements in args.elements:
            costs = []
            for ribs in args.ribs:
                cost, n_rib, its = step_cost(ribs, elements, args.steps, args.repeat, kernel)
                costs.append(cost)
                print(f'{kernel:>9} {ribs:5d} {elements:9d} {n_rib:10d} {its:9.2f} '
                      f'{1e6 * cost:10.1f} {1e6 * cost / ribs:12.1f} '
                      f'{1e9 * cost / ribs / n_rib:18.0f}', flush=True)
            if len(costs) > 2:
                fit = np.polyfit(args.ribs, costs, 1)
                worst = np.max(np.abs(np.polyval(fit, args.ribs) / costs - 1))
                quad = np.polyfit(args.ribs, costs, 2)[0] * max(args.ribs) ** 2 / max(costs)
                print(f'          {kernel}, {elements} element(s): cost = {1e6 * fit[1]:.1f} us '
                      f'+ {1e6 * fit[0]:.1f} us x ribs (largest deviation {100 * worst:.0f} %; '
                      f'a quadratic term would carry {100 * quad:+.0f} % at {max(args.ribs)} '
                      'ribs)')
    if args.kernel_ribs:
        print('\nthe compiled step alone (its stress figures, no Record3D; the physics step the '
              "run takes: the mesh's, over stage 2's substeps; CPU of this thread)")
        print(f"{'ribs':>5} {'elements':>9} {'step (us)':>10} {'stage':>6} {'us/step':>9} "
              f"{'us/step/rib':>12} {'Newton it':>10} {'factorisations':>15} {'core':>6}")
    for elements in args.elements if args.kernel_ribs else ():
        by_stage = {1: [], 2: []}
        for ribs in args.kernel_ribs:
            stages = kernel_stages(ribs, elements, args.kernel_steps, args.repeat,
                                   not args.no_stage2)
            for stage, figures in enumerate(stages, 1):
                if figures is None:
                    continue
                h, cost, its, facts = figures
                by_stage[stage].append(cost)
                print(f'{ribs:5d} {elements:9d} {1e6 * h:10.2f} {stage:6d} {1e6 * cost:9.1f} '
                      f'{1e6 * cost / ribs:12.2f} {its:10.2f} {facts:15.3f} {cost / h:6.2f}',
                      flush=True)
        for stage, costs in by_stage.items():
            if len(costs) > 1:
                fit = 1e6 * np.polyfit(args.kernel_ribs, costs, 1)
                print(f'          {elements} element(s), stage {stage}: {fit[1]:.1f} us + '
                      f'{fit[0]:.2f} us x ribs')
    print(f'\nreal-time factors over {args.duration} s simulated (step chosen for the mesh)')
    print(f"{'ribs':>5} {'elements':>9} {'block':>8} {'step (us)':>10} {'RTF (wall)':>11} "
          f"{'CPU s / sim s':>14} {'target':>30}")
    for ribs, elements, block, target in ((6, 1, 1e-3, 'RTF >= 1 within 0.5 core'),
                                          (12, 2, 1e-2, 'RTF >= 1')):
        h, rtf, cpu = real_time(ribs, elements, block, args.duration, args.after_lock)
        print(f'{ribs:5d} {elements:9d} {1e3 * block:6.0f}ms {1e6 * h:10.2f} {rtf:11.4f} '
              f'{cpu:14.2f} {target:>30}', flush=True)


if __name__ == '__main__':
    main()
