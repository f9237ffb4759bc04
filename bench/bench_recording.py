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
Measure the bytes per simulated second of an MCAP recording.

At the default publish rate (100 Hz),
the default config (N = 1) and N = 2, through the lock, and the time it takes to write.

    python bench/bench_recording.py [--seconds 10]
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))

from umbrella_sim.bag.reader import read_log  # noqa: E402
from umbrella_sim.core.params import UmbrellaParams  # noqa: E402
from umbrella_sim.ros.recording import record_offline  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument('--seconds', type=float, default=10.0)
    args = ap.parse_args()
    for n_el in (1, 2):
        with tempfile.TemporaryDirectory() as tmp:
            bag = os.path.join(tmp, 'run')
            t0 = time.perf_counter()
            record_offline(UmbrellaParams(elements_per_segment=n_el), bag, args.seconds)
            wall = time.perf_counter() - t0
            size = os.path.getsize(os.path.join(bag, 'run_0.mcap'))
            log = read_log(bag)
            per_topic = {t: log.count(t) for t in log.topics() if log.count(t)}
            print(f'N = {n_el}: {size / args.seconds / 1024:.1f} KiB per simulated second '
                  f'({size} bytes for {args.seconds:g} s, {len(log.messages)} messages, '
                  f'zstd chunks), written at {args.seconds / wall:.1f}x real time')
            print('   messages per topic:', per_topic)


if __name__ == '__main__':
    main()
