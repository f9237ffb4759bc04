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
Throughput of `umbrella_sim sweep`: cases/s with 1 and 2 local Dask workers, overhead per case.

The sweep: --cases flexible cases (N = 1, V0 spread over -0.3 .. -1.5 m/s), each run for
--duration simulated seconds.  For each worker count, a fresh local cluster runs the whole
sweep into a fresh directory (the same code path as the command line) and we print:
- cluster start: starting the worker processes and checking their umbrella_sim;
- cases/s: cases finished per wall second, first submission to last result (store writes
  included, cluster start excluded);
- idle/case: time a worker spends between the end of one of its cases and the start of its
  next (Dask handing over the next task: the scheduling overhead per case as the workers see
  it; the next task is usually queued on the worker already);
- wall overhead/case: (wall time x workers - sum of the cases' own wall times on the workers)
  / cases: the idle time above plus the start (first task reaching each worker) and the tail
  (workers idle while the last cases finish), i.e. everything that is not computing;
- no-op round trip: submit -> result of an empty task on the same cluster, one at a time.
The machine is shared: wall-clock figures are noisy.

    python bench/bench_sweep.py [--cases 24] [--duration 0.3] [--workers 1 2]
"""
import argparse
import io
import json
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from umbrella_sim.tools import sweep  # noqa: E402


def noop(x):
    return x


def idle_between_cases(out_dir: str) -> tuple[float, int]:
    """Return the summed gaps between consecutive cases on each worker, and their number."""
    by_worker: dict[str, list] = {}
    store = os.path.join(out_dir, 'cases')
    for name in os.listdir(store):
        with open(os.path.join(store, name)) as fh:
            rec = json.load(fh)
        by_worker.setdefault(rec['worker'], []).append((rec['started_at'], rec['finished_at']))
    total, gaps = 0.0, 0
    for spans in by_worker.values():
        spans.sort()
        total += sum(start - end for (_, end), (start, _) in zip(spans, spans[1:]))
        gaps += len(spans) - 1
    return total, gaps


def round_trip(n_workers: int, n: int = 50) -> float:
    client, cluster = sweep._client(n_workers, None, lambda msg: None)
    try:
        client.submit(noop, -1, pure=False).result()        # warm up
        t0 = time.perf_counter()
        for i in range(n):
            client.submit(noop, i, pure=False).result()
        return (time.perf_counter() - t0) / n
    finally:
        client.close()
        cluster.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--cases', type=int, default=24)
    ap.add_argument('--duration', type=float, default=0.3, help='simulated s per case')
    ap.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    args = ap.parse_args()
    v0s = [round(-0.3 - 1.2 * i / max(args.cases - 1, 1), 6) for i in range(args.cases)]
    print(f'{args.cases} cases: flexible N = 1, V0 = {v0s[0]} .. {v0s[-1]} m/s, '
          f'{args.duration} s simulated each; {os.cpu_count()} cores (shared machine), '
          f'load average {os.getloadavg()[0]:.1f}')
    print(f"{'workers':>7} {'cluster start':>13} {'wall':>7} {'cases/s':>8} "
          f"{'compute/case':>12} {'idle/case':>10} {'wall overhead/case':>18} "
          f"{'no-op round trip':>16}")
    with tempfile.TemporaryDirectory(prefix='bench_sweep_') as tmp:
        spec = os.path.join(tmp, 'spec.yaml')
        with open(spec, 'w') as fh:
            fh.write(f'grid:\n  v0: {v0s}\nduration: {args.duration}\n')
        loaded = sweep.load_spec(spec)
        for n in args.workers:
            log = io.StringIO()
            out = os.path.join(tmp, f'out{n}')
            report = sweep.run_sweep(loaded, out, workers=n, stream=log)
            assert report.ran == args.cases and report.failed == 0, log.getvalue()
            overhead = (report.run_s * n - report.compute_s) / report.ran
            rt = round_trip(n)
            idle, gaps = idle_between_cases(out)
            compute_ms = report.compute_s / report.ran * 1e3
            print(f'{n:>7} {report.setup_s:>11.2f} s {report.run_s:>5.2f} s '
                  f'{report.ran / report.run_s:>8.2f} {compute_ms:>9.1f} ms'
                  f' {idle / max(gaps, 1) * 1e3:>7.1f} ms {overhead * 1e3:>15.1f} ms'
                  f' {rt * 1e3:>13.2f} ms'
                  f'   (load average {os.getloadavg()[0]:.1f})')


if __name__ == '__main__':
    main()
