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
How long the tools take to read large inputs: a params file and a sweep spec of many cases.

  * a ROS 2 params file of --megabytes (sections for many namespaced nodes, each with a few
    parameters, as a fleet's file): the ROS-typed YAML read (``read_params_file``), its
    second read (what a node's start-up adds), and PyYAML's C loader alone on the same text
    for scale;
  * a sweep spec whose grid has --cases cases: ``load_spec`` (every case's parameters
    checked as the command line checks one).

Prints CPU and wall seconds with the load average (the machine may be shared).  Run it with
PYTHONPATH set to another checkout for a before/after.

    python bench/bench_inputs.py [--megabytes 23] [--cases 10000]
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # (not the repo: see --help)

from process_figures import load  # noqa: E402


def timed(what: str, fn):
    c0, w0 = time.process_time(), time.perf_counter()
    result = fn()
    print(f'{what}: {time.process_time() - c0:.2f} s CPU, {time.perf_counter() - w0:.2f} s '
          f'wall; {load()}')
    return result


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--megabytes', type=float, default=23.0)
    ap.add_argument('--cases', type=int, default=10000)
    args = ap.parse_args()
    import yaml

    import umbrella_sim
    from umbrella_sim.ros.params_file import read_params_file
    from umbrella_sim.tools.sweep_spec import load_spec

    print(f'umbrella_sim from {os.path.dirname(umbrella_sim.__file__)}')
    tmp = tempfile.mkdtemp(prefix='inputs-')
    path = os.path.join(tmp, 'fleet.yaml')
    with open(path, 'w') as fh:
        i = 0
        while fh.tell() < args.megabytes * 1e6:
            fh.write(f'/a{i}/umbrella_node:\n  ros__parameters:\n    v0: -0.5\n    l1: 0.3\n'
                     '    youngs_modulus: 72.0e9\n    model: flexible\n'
                     '    publish_rate: 100.0\n    elements_per_segment: 4\n')
            i += 1
    print(f'params file: {os.path.getsize(path) / 1e6:.1f} MB, {i} sections')
    text = open(path).read()
    timed("  PyYAML's C loader alone", lambda: yaml.load(text, Loader=yaml.CSafeLoader))
    timed('  read_params_file (ROS-typed)', lambda: read_params_file(path))
    # a node's process reads its files before rclpy.init and again as the node starts
    timed('  read_params_file again (the same text: not parsed again)',
          lambda: read_params_file(path))
    side = int(round(args.cases ** 0.5))
    v0 = ', '.join(f'{-0.5 - 0.001 * k:.4f}' for k in range(side))
    l1 = ', '.join(f'{0.3 + 0.0001 * k:.4f}' for k in range(args.cases // side))
    spec = os.path.join(tmp, 'spec.yaml')
    with open(spec, 'w') as fh:
        fh.write(f'base: {{model: rigid}}\nduration: 0.05\ngrid:\n  v0: [{v0}]\n  l1: [{l1}]\n')
    sweep = timed(f'sweep spec of {side * (args.cases // side)} cases: load_spec',
                  lambda: load_spec(spec))
    print(f'  {len(sweep.cases)} cases checked')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
