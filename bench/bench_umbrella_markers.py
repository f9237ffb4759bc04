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
Cost of the whole umbrella's markers and URDF (ros.umbrella_markers, ros.robot_description).

For ribs x elements a segment, on a state of the deployment (a few steps from t = 0), CPU
time of this thread, best of --repeat, each over --calls calls:

  * points: UmbrellaShapes.positions (every rib's drawn points, einsums over all ribs);
  * bytes: UmbrellaMarkers.encode (the points and their CDR bytes: what the node publishes);
  * message: UmbrellaMarkers.message + serialization (the MarkerArray's Python objects, the
    path the encoder avoids), for comparison;
  * per rib: bytes / ribs (it should stay flat or fall: the work is vectorised over ribs);
  * the share of a core at marker_rate (default 30 Hz) of the bytes path;
  * urdf: robot_description.urdf of those parameters (once a launch), and the message size.
The machine is shared (2 cores): the figures are noisy; nothing here is asserted.

    python bench/bench_umbrella_markers.py [--ribs 1 6 12 24] [--elements 1 2]
                                           [--calls 200] [--repeat 3] [--rate 30]
"""
import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))

from umbrella_sim.bag.cdr import cdr_bytes  # noqa: E402
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams  # noqa: E402
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D  # noqa: E402
from umbrella_sim.ros.robot_description import urdf  # noqa: E402
from umbrella_sim.ros.umbrella_markers import UmbrellaMarkers  # noqa: E402


def best_time(call, calls: int, repeat: int) -> float:
    """Return the least CPU seconds per call of call() over repeat runs of calls calls."""
    best = float('inf')
    for _ in range(repeat):
        t0 = time.thread_time()
        for _ in range(calls):
            call()
        best = min(best, (time.thread_time() - t0) / calls)
    return best


def figures(ribs: int, elements: int, calls: int, repeat: int) -> dict:
    params = UmbrellaRibsParams.from_mapping(
        {'ribs': ribs, 'elements_per_segment': elements, 'time_step': 1e-4,
         'hub_radius': 0.05, 'v0': -0.5})
    sim = UmbrellaSimulator3D(params)
    for _ in range(5):
        sim.step()
    qr, qs, t = sim.state.qr, sim.state.qs, sim.time
    markers = UmbrellaMarkers(sim.model, 'umbrella', 'a1/')
    data = markers.encode(t, qr, qs, 10.0)               # builds the template once
    points = sum(len(b) for b in markers.shapes.bodies(qr))
    return {
        'points': best_time(lambda: markers.shapes.positions(qr, 10.0), calls, repeat),
        'bytes': best_time(lambda: markers.encode(t, qr, qs, 10.0), calls, repeat),
        'message': best_time(lambda: cdr_bytes(markers.message(t, qr, qs, 10.0)),
                             max(1, calls // 10), repeat),
        'urdf': best_time(lambda: urdf(params), max(1, calls // 10), repeat),
        'size': len(data), 'n_points': points,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--ribs', type=int, nargs='+', default=[1, 6, 12, 24])
    ap.add_argument('--elements', type=int, nargs='+', default=[1, 2])
    ap.add_argument('--calls', type=int, default=200)
    ap.add_argument('--repeat', type=int, default=3)
    ap.add_argument('--rate', type=float, default=30.0, help='marker_rate (Hz)')
    args = ap.parse_args()
    print(f'load average {os.getloadavg()[0]:.2f}; CPU time of this thread, best of '
          f'{args.repeat}')
    print(f"{'ribs':>4} {'el':>3} {'points':>7} {'bytes':>7} {'pos us':>8} {'encode us':>10} "
          f"{'msg us':>9} {'per rib us':>10} {'core %':>7} {'urdf ms':>8}")
    for elements in args.elements:
        for ribs in args.ribs:
            f = figures(ribs, elements, args.calls, args.repeat)
            print(f"{ribs:>4} {elements:>3} {f['n_points']:>7} {f['size']:>7} "
                  f"{f['points'] * 1e6:>8.1f} {f['bytes'] * 1e6:>10.1f} "
                  f"{f['message'] * 1e6:>9.0f} {f['bytes'] * 1e6 / ribs:>10.2f} "
                  f"{100 * f['bytes'] * args.rate:>7.3f} {f['urdf'] * 1e3:>8.2f}")


if __name__ == '__main__':
    main()
