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
Cost of the physics core: per-step cost vs mesh, and whole-run real-time factors.

For each mesh N (flexible model, V0 = -0.2 m/s unless --v0, energy lock, t = 0 -> 1.0 s through
the lock, at the default time step unless --time-step; --mesh-step: time_step 0, the step chosen
for the run: stage 1 on its grid, 0.2 ms up to 2 elements a segment and the mesh's step above,
stage 2 in substeps of it, the mesh's step or the finer one its lock needs; h1 / h2 are the
steps stage 1 and stage 2 took; a step is a physics step, each of stage 2's substeps one,
bench/step_figures.py):
  * us/step (kernel): the whole run in one UmbrellaSimulator.advance call (the compiled loop
    with every step's outputs, the lock's root find; Python enters three times), CPU time of
    this thread, best of --repeat;
  * us/step (1 ms): UmbrellaSimulator.advance in blocks of one publication period (1 ms) and
    the full Sample of each block's last step (what a 1 kHz publication pays), CPU time;
  * RTF: simulated seconds per wall second of that 1 ms-block run, best of --repeat;
  * the cost per step divided by the number of coordinates, to show the growth is linear;
  * of that 1 ms-block run (one more run, CPU time): the compiled calls per block
    (CompiledKernel.advance, timed around each call) and the rest (Python: the block, the
    state, the Sample, the lock), and the real-time factor the compiled calls alone would
    allow (1 ms over their CPU time per block): the ceiling no Python trimming can pass.
Then, side by side, CPU seconds per simulated second of the same run on three paths:
  * node: what umbrella_node computes, a RunDriver at 1 kHz, each period's steps and its
    publication Sample (no ROS: bench_node.py measures the node itself);
  * simulate: ``umbrella_sim simulate --json``'s run (the run driver's chunks, the summary of
    every step), and with --csv every step's row written (tools/csv_output.py);
and the CPU of starting the offline command line (``umbrella_sim simulate --duration 2e-4
--json``, a child process: start-up and imports).
The machine is shared: CPU time is what the step costs; wall RTF is what a user saw.
Targets: <= 10 us/step at N = 2, <= 40 us/step at N = 8; RTF >= 10 at N = 2, >= 2 at N = 8
(flexible); RTF >= 5 at N = 4 (--model flexible-nonlinear); simulate <= 1.3x the node path
and simulate --csv <= 2x at N = 2; the command line's start-up < 0.5 s of CPU.

    python bench/bench_core.py [--meshes 1 2 4 8 16] [--repeat 3] [--time-step H | --mesh-step]
                               [--model flexible-nonlinear] [--damping-ratio Z]
"""
import argparse
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from bench.step_figures import physics_steps  # noqa: E402
from umbrella_sim.core.driver import RunDriver, simulate  # noqa: E402
from umbrella_sim.core.params import physics_step, UmbrellaParams  # noqa: E402
from umbrella_sim.core.solver import UmbrellaSimulator  # noqa: E402
from umbrella_sim.core.step_rule import AUTO_STEP_CEILING, step_taken_now  # noqa: E402
from umbrella_sim.tools.csv_output import StepCsv  # noqa: E402

#: model -> {N: target}
COST_TARGETS = {'flexible': {2: 10.0, 8: 40.0}}
RTF_TARGETS = {'flexible': {2: 10.0, 8: 2.0}, 'flexible-nonlinear': {4: 5.0}}
#: at N = 2: simulate's CPU over the node path's, without and with --csv; start-up CPU (s)
OFFLINE_TARGETS = {'json': 1.3, 'csv': 2.0}
START_TARGET = 0.5
PUBLISH_RATE = 1000.0
DURATION = 1.0
SAMPLE_PERIOD = 1e-3
BLOCKS = round(DURATION / SAMPLE_PERIOD)   # sample periods in the run


def block_run(params, time_compiled=False):
    """
    Run the whole run in blocks of one sample period.

    Whole run in blocks of one sample period (each block builds the Sample of its last
    step); returns (cpu s, wall s, sim, compiled cpu s).  With time_compiled, the compiled
    multi-step calls are timed around each call (CompiledKernel.advance, ~1 us of timing in
    ~100; this run's other figures are not used), else (and without a compiled kernel) the
    last is None.
    """
    sim = UmbrellaSimulator(params)
    per_block = round(SAMPLE_PERIOD / sim.h)
    kernel = sim.engine.integrator.kernel
    compiled = None
    if time_compiled and kernel is not None:
        compiled = [0.0]
        advance = kernel.advance

        def timed(*args):
            c = time.thread_time()
            out = advance(*args)
            compiled[0] += time.thread_time() - c
            return out

        kernel.advance = timed       # this instance only
    c0, w0 = time.thread_time(), time.perf_counter()
    for _ in range(BLOCKS):
        sim.advance(per_block).last
    cpu, wall = time.thread_time() - c0, time.perf_counter() - w0
    assert sim.lock_event is not None, 'the run did not reach the lock'
    return cpu, wall, sim, None if compiled is None else compiled[0]


def node_path_cpu(params) -> float:
    """CPU s per simulated s of the node's stepping: a 1 kHz RunDriver, its publication Sample."""
    driver = RunDriver(params, PUBLISH_RATE)
    c0 = time.thread_time()
    while driver.time < DURATION - 1e-9:
        driver.advance_period()
        driver.publication()
    return (time.thread_time() - c0) / driver.time


def offline_cpu(params, csv: bool) -> float:
    """CPU s per simulated s of umbrella_sim simulate's run (--json; with csv, --csv too)."""
    with tempfile.TemporaryDirectory(prefix='bench_core_') as tmp:
        out = StepCsv(os.path.join(tmp, 'run.csv')) if csv else None
        c0 = time.thread_time()
        result = simulate(params, DURATION, keep_samples=False,
                          on_chunk=(lambda chunk: out.write(chunk.block)) if out else None)
        cpu = time.thread_time() - c0
        if out is not None:
            out.close()
    return cpu / result.figures['final_time']


def cli_start_cpu() -> float:
    """
    CPU s (user + system) of `umbrella_sim simulate --duration 2e-4 --json`: start-up.

    As a user's start: with the bytecode caches Python writes (PYTHONDONTWRITEBYTECODE
    dropped from the child's environment; with it, every start compiles the sources again:
    0.55-0.60 s against 0.36-0.40 s measured).
    """
    env = {k: v for k, v in os.environ.items() if k != 'PYTHONDONTWRITEBYTECODE'}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([os.path.join(os.path.dirname(sys.executable), 'umbrella_sim'), 'simulate',
                    '--duration', '2e-4', '--json'], check=True, stdout=subprocess.DEVNULL,
                   env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def kernel_run(params):
    """Return the CPU s per physics step of the whole run in one advance call."""
    sim = UmbrellaSimulator(params)
    n = round(DURATION / sim.h)
    c0 = time.thread_time()
    sim.advance(n)
    return (time.thread_time() - c0) / physics_steps(sim)


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--meshes', type=int, nargs='+', default=[1, 2, 4, 8, 16])
    ap.add_argument('--repeat', type=int, default=3)
    ap.add_argument('--time-step', type=float, default=AUTO_STEP_CEILING,
                    help="a fixed step for every mesh (default: the one-element mesh's chosen "
                         'step, 0.1 ms)')
    ap.add_argument('--mesh-step', action='store_true',
                    help='each mesh at the step chosen for it (time_step 0, step_study.mesh_step: '
                         'docs/validation.md), not --time-step')
    ap.add_argument('--model', default='flexible',
                    choices=('flexible', 'flexible-nonlinear', 'rigid-fe'))
    ap.add_argument('--damping-ratio', type=float, default=0.0)
    ap.add_argument('--v0', type=float, default=-0.2,
                    help="initial sleeve velocity (m/s); -0.5: stage 2 past the modes' "
                         'coupling, where time_step 0 takes the step its lock needs')
    args = ap.parse_args()
    h = physics_step(args.time_step, 1.0 / SAMPLE_PERIOD)
    steps = ('h = the step chosen for the mesh (time_step 0)' if args.mesh_step else
             f'h = {h:.6g} s ({round(DURATION / h)} steps)')
    cost_targets = COST_TARGETS.get(args.model, {})
    rtf_targets = RTF_TARGETS.get(args.model, {})
    print(f'{args.model} (damping_ratio {args.damping_ratio:g}), V0 = {args.v0:g}, energy lock, '
          f't = 0 -> {DURATION:g} s through the lock, '
          f'{steps}, a Sample every '
          f'{SAMPLE_PERIOD * 1e3:g} ms; '
          f'best of {args.repeat}; loadavg {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs')
    print(f"{'N':>3} {'h1 / h2':>11} {'coords':>6} {'newton':>6} {'us/step':>8} {'us/step':>8} "
          f"{'ns/step/coord':>13}"
          f" {'RTF':>7} {'targets (us, RTF)':>18} {'us/1 ms block':>15} {'RTF':>7}")
    print(f"{'':>3} {'us':>11} {'':>6} {'/step':>6} {'kernel':>8} {'1 ms':>8} {'kernel':>13} "
          f"{'wall':>7}"
          f" {'':>18} {'kernel':>7} {'rest':>7} {'kernel':>7}")
    for n in args.meshes:
        p = UmbrellaParams(v0=args.v0, elements_per_segment=n, time_step=h, model=args.model,
                           damping_ratio=args.damping_ratio)
        if args.mesh_step:      # (time_step 0: its grid, 0.2 ms or 0.1 ms / k, divides 1 ms)
            p = p.replace(time_step=0.0)
        cpus, walls = [], []
        for _ in range(args.repeat):
            cpu, wall, sim, _ = block_run(p)
            cpus.append(cpu)
            walls.append(wall)
        steps = physics_steps(sim)
        us = 1e6 * min(cpus) / steps
        kernel = 1e6 * min(kernel_run(p) for _ in range(args.repeat))
        newton = sim.engine.newton_iterations() / steps
        h12 = f'{1e6 * sim.h:.3g} / {1e6 * step_taken_now(sim):.3g}'
        rtf = DURATION / min(walls)
        tgt = ''
        if n in rtf_targets and args.v0 == -0.2:     # (the targets' case)
            ok = kernel <= cost_targets.get(n, math.inf) and rtf >= rtf_targets[n]
            cost = f'{cost_targets[n]:>4.0f}' if n in cost_targets else f"{'-':>4}"
            tgt = f"{cost}, {rtf_targets[n]:>3.0f}x {'ok' if ok else 'MISS'}"
        total, _, _, compiled = block_run(p, time_compiled=True)
        if compiled is None:
            tail = f"{'-':>7} {'-':>7} {'-':>7}"
        else:
            compiled, total = 1e6 * compiled / BLOCKS, 1e6 * total / BLOCKS
            tail = f'{compiled:>7.1f} {total - compiled:>7.1f} {1e3 / compiled:>6.1f}x'
        print(f'{n:>3} {h12:>11} {sim.model.n:>6} {newton:>6.2f} {kernel:>8.2f} '
              f'{us:>8.2f} '
              f'{1e3 * kernel / sim.model.n:>13.1f} {rtf:>6.1f}x {tgt:>18} {tail}', flush=True)
    print(f"\nCPU s per simulated s, best of {args.repeat}: the node's path (1 kHz) and "
          "umbrella_sim simulate's")
    print(f"{'N':>3} {'node':>7} {'simulate':>9} {'ratio':>6} {'--csv':>7} {'ratio':>6} "
          f"{'targets (x)':>12}")
    for n in args.meshes:
        p = UmbrellaParams(v0=args.v0, elements_per_segment=n, time_step=h, model=args.model,
                           damping_ratio=args.damping_ratio)
        if args.mesh_step:
            p = p.replace(time_step=0.0)
        node = min(node_path_cpu(p) for _ in range(args.repeat))
        plain = min(offline_cpu(p, csv=False) for _ in range(args.repeat))
        csv = min(offline_cpu(p, csv=True) for _ in range(args.repeat))
        tgt = ''
        if n == 2 and args.model == 'flexible' and args.v0 == -0.2:
            ok = (plain / node <= OFFLINE_TARGETS['json']
                  and csv / node <= OFFLINE_TARGETS['csv'])
            tgt = (f"{OFFLINE_TARGETS['json']:g}, {OFFLINE_TARGETS['csv']:g} "
                   f"{'ok' if ok else 'MISS'}")
        print(f'{n:>3} {node:>7.3f} {plain:>9.3f} {plain / node:>5.2f}x {csv:>7.3f} '
              f'{csv / node:>5.2f}x {tgt:>12}', flush=True)
    cli_start_cpu()                 # (the bytecode caches written, if they were not)
    start = min(cli_start_cpu() for _ in range(args.repeat))
    print(f'\nstarting umbrella_sim simulate (--duration 2e-4 --json, a child process): '
          f'{start:.2f} s of CPU (target < {START_TARGET:g} s: '
          f"{'ok' if start < START_TARGET else 'MISS'})")


if __name__ == '__main__':
    main()
