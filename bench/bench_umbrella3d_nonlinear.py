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
Cost of the umbrella's co-rotational ribs (model flexible-nonlinear) per step, both paths.

For ribs x elements, CPU time of this thread per grid step (the midpoint step, its Newton
iterations, the projection, the per-step stress figures and Record3D's rows) at h = 0.1 ms,
V0 = -1 m/s (the links buckle), plastic lock: stage 1 over --steps steps from t = 0, stage 2
over --steps steps from the lock on; the Newton iterations and factorisations a step; on the
compiled step (_kernel3d.c with _kernel3d_nonlinear.h, UmbrellaSimulator3D.advance: the
steps in one call, their stress figures computed there, _kernel3d_figures.h) and the numpy
reference (UmbrellaSimulator3D.step, Record3D's numpy figures); and the same runs of the
linear model (flexible, no mode fit) beside them.  Prints the figures and the machine's
load; no figure is asserted.  The co-rotational ribs' stress figures, once Record3D's numpy
(45 of 112 us a step at 6 x 1 in stage 1), computed in the library, their elements' strains
kept from one iteration to the next: compiled 6 x 1 94 -> 59 us a step in stage 1 and 134 ->
91 in stage 2, 6 x 2 193 -> 114 and 300 -> 214 (best of two, load 4.4-4.5;
docs/umbrella3d_nonlinear.md).

--damping 0 0.05 measures each row undamped and with structural damping (damping_ratio zeta:
C(q) = beta B^T D B of the co-rotated strain rates, damping3d.py); --repeat takes the best of
that many runs a row.

    PYTHONPATH=. python bench/bench_umbrella3d_nonlinear.py [--steps 100] [--carry K]
        [--ribs 3 6] [--elements 1 2] [--paths compiled numpy] [--damping 0 0.05]
        [--repeat 1]
"""
import argparse
import os
import time

from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D


def per_step(sim, steps: int):
    """Return (CPU us a step, Newton iterations a step, factorisations a step) of `steps`."""
    integ = sim.integrator
    it0, f0 = integ.iterations, integ.factorisations
    t0 = time.thread_time()
    if integ.compiled is not None:
        sim.advance(steps)
    else:
        for _ in range(steps):
            sim.step()
    cpu = time.thread_time() - t0
    return 1e6 * cpu / steps, (integ.iterations - it0) / steps, (integ.factorisations - f0) / steps


def measure(model: str, ribs: int, elements: int, steps: int, carry: int, kernel: str,
            zeta: float = 0.0):
    values = {'ribs': ribs, 'elements_per_segment': elements, 'model': model, 'v0': -1.0,
              'lock': 'plastic', 'time_step': 1e-4, 'phase_correction': False,
              'damping_ratio': zeta}
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values), kernel=kernel,
                              carry_steps=carry)
    stage1 = per_step(sim, steps)
    while not sim.locked:
        sim.advance(10 ** 6, stop_at_lock=True)
    return stage1, per_step(sim, steps)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument('--steps', type=int, default=100)
    ap.add_argument('--carry', type=int, default=None,
                    help="carry_steps of the iteration matrix (default: each model's)")
    ap.add_argument('--ribs', type=int, nargs='+', default=[3, 6])
    ap.add_argument('--elements', type=int, nargs='+', default=[1, 2])
    ap.add_argument('--paths', nargs='+', choices=('compiled', 'numpy'),
                    default=['compiled', 'numpy'], help='the steps measured (default both)')
    ap.add_argument('--damping', type=float, nargs='+', default=[0.0],
                    help='damping_ratio zeta of the rows (default 0: undamped)')
    ap.add_argument('--repeat', type=int, default=1, help='runs a row, the best taken')
    args = ap.parse_args()
    print(f'load {os.getloadavg()[0]:.2f} (2 cores); h = 0.1 ms, V0 = -1, plastic lock; '
          f"carry_steps {args.carry or 'the model default'}")
    print('| model | zeta | path | ribs x elements | stage 1 us/step (its, fact) '
          '| stage 2 us/step (its, fact) |')
    print('|---|---|---|---|---|---|')
    for ribs in args.ribs:
        for elements in args.elements:
            for model in ('flexible', 'flexible-nonlinear'):
                for kernel, zeta in ((k, z) for k in args.paths for z in args.damping):
                    runs = [measure(model, ribs, elements, args.steps, args.carry, kernel,
                                    zeta) for _ in range(args.repeat)]
                    s1, s2 = (min((r[i] for r in runs), key=lambda x: x[0]) for i in (0, 1))
                    print(f'| {model} | {zeta:g} | {kernel} | {ribs} x {elements} '
                          f'| {s1[0]:.0f} ({s1[1]:.2f}, {s1[2]:.2f}) '
                          f'| {s2[0]:.0f} ({s2[1]:.2f}, {s2[2]:.2f}) |', flush=True)
    print(f'load {os.getloadavg()[0]:.2f}')


if __name__ == '__main__':
    main()
