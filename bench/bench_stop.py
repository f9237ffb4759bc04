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
How long umbrella_node takes from SIGINT to its exit, and how much of that is ROS's own.

Starts the node (default configuration, recording on and off) --repeat times, sends SIGINT
a second after it runs and times the exit (wall s); then times a bare rclpy process (init, a
node, shutdown) from its last line to its exit: the middleware's teardown, which every ROS 2
Python process pays.  Target: ~0.1 s beyond that.  Uses UMBRELLA_TEST_DOMAIN_ID (or the
test API's default).

    python bench/bench_stop.py [--repeat 3]
"""
import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time

BARE = ('import sys, time, rclpy\n'
        'rclpy.init(); n = rclpy.create_node("bare"); n.destroy_node(); rclpy.try_shutdown()\n'
        'print(time.time(), flush=True)\n')


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument('--repeat', type=int, default=3)
    args = ap.parse_args()
    from umbrella_sim.testing.processes import NodeProcess, ros_env

    os.chdir(tempfile.mkdtemp(prefix='stop-'))
    print(f'loadavg {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs')
    for record in ('true', 'false'):
        times = []
        for _ in range(args.repeat):
            with NodeProcess('-p', f'record:={record}') as node:
                node.wait_for_log('kernel compiled', timeout=60)
                time.sleep(1.0)                  # (a bench: the run going for a second)
                t0 = time.perf_counter()
                node.proc.send_signal(signal.SIGINT)
                node.proc.wait(30)
                times.append(time.perf_counter() - t0)
        print(f'record:={record}: SIGINT -> exit ' + ', '.join(f'{t:.3f}' for t in times) + ' s')
    bare = []
    for _ in range(args.repeat):
        proc = subprocess.Popen([sys.executable, '-c', BARE], stdout=subprocess.PIPE,
                                env=ros_env(), text=True)
        last = float(proc.stdout.readline())
        proc.wait()
        bare.append(time.time() - last)
    print("a bare rclpy process, its last line -> exit (the middleware's teardown): "
          + ', '.join(f'{t:.3f}' for t in bare) + ' s')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
