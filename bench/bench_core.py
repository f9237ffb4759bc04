#!/usr/bin/env python3
"""
Real-time factor of the physics core (simulated seconds per wall second, one process).

Flexible model, V0 = -0.2, through the lock to t = 1.0 s, at the default time step (the
accuracy the tests demand).  Two figures per mesh: stepping only (what the node pays between
publications) and stepping with a full output sample (stresses, energies) every step.
Best of --repeat runs.  Targets (issue 2): >= 20x at N = 1, >= 10x at N = 2, >= 1x at N = 8.

    python bench/bench_core.py [--meshes 1 2 4 8] [--repeat 3] [--time-step 0.002]
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from umbrella_sim.params import UmbrellaParams  # noqa: E402
from umbrella_sim.solver import UmbrellaSimulator  # noqa: E402

TARGETS = {1: 20.0, 2: 10.0, 8: 1.0}


def one_run(params, record):
    sim = UmbrellaSimulator(params)
    t0 = time.perf_counter()
    sim.advance_to(1.0, record=record)
    wall = time.perf_counter() - t0
    assert sim.lock_event is not None, "the run did not reach the lock"
    return wall, sim


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--time-step", type=float, default=UmbrellaParams().time_step)
    args = ap.parse_args()
    print(f"flexible model, V0 = -0.2, t = 0 -> 1.0 s through the lock, h = {args.time_step:g} s, "
          f"best of {args.repeat}")
    print(f"{'N':>3} {'dofs':>5} {'steps':>6} {'newton/step':>11} {'RTF step':>9} "
          f"{'RTF +samples':>12} {'target':>7}")
    for n in args.meshes:
        p = UmbrellaParams(v0=-0.2, elements_per_segment=n, time_step=args.time_step)
        best = {}
        for record in (False, True):
            walls = []
            for _ in range(args.repeat):
                wall, sim = one_run(p, record)
                walls.append(wall)
            best[record] = min(walls)
        its = sim.engine.integrator.iterations / sim.steps
        target = TARGETS.get(n)
        ok = target is not None and 1.0 / best[False] >= target
        verdict = "" if target is None else f"{target:>5.0f}x {'ok' if ok else 'MISS'}"
        print(f"{n:>3} {sim.model.n:>5} {sim.steps:>6} {its:>11.2f} {1.0 / best[False]:>8.1f}x "
              f"{1.0 / best[True]:>11.1f}x {verdict}")


if __name__ == "__main__":
    main()
