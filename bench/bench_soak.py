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
Soak benchmark: umbrella_node at 1 kHz with recording for a long run.

Prints the resident memory slope (kB per simulated second, fitted after a warm-up), the lag
behind wall time (largest, and the slip dropped by the overload policy), CPU seconds per
simulated second, and recording bytes per simulated second.

    python bench/bench_soak.py                  # 10 minutes, 1 kHz, recording
    python bench/bench_soak.py --minutes 1 --publish-rate 100

The machine's load changes every figure but the memory slope; say how loaded it was.
"""
import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

PAGE = os.sysconf('SC_PAGE_SIZE')
TICK = os.sysconf('SC_CLK_TCK')


def rss_kb(pid: int) -> float:
    with open(f'/proc/{pid}/statm') as fh:
        return int(fh.read().split()[1]) * PAGE / 1024.0


def cpu_s(pid: int) -> float:
    with open(f'/proc/{pid}/stat') as fh:
        fields = fh.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK      # utime + stime


class Diagnostics:
    """Latest values of the node's diagnostics, from a probe node in a thread."""

    def __init__(self):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('soak_probe', context=self.context)
        self.values: dict = {}
        self.max_lag = 0.0
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 10)
        self.stopping = False
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _on_diag(self, msg):
        values = {kv.key: kv.value for kv in msg.status[0].values}
        self.max_lag = max(self.max_lag, float(values.get('max_lag_s', 0.0)))
        self.values = values

    def _spin(self):
        while self.context.ok() and not self.stopping:
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except Exception:
                return

    def close(self):
        # the spinning thread ends before the executor and context go away (else the C++
        # executor can be torn down under it: 'terminate called without an active exception')
        self.stopping = True
        self.thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--minutes', type=float, default=10.0, help='wall minutes (default 10)')
    ap.add_argument('--publish-rate', type=float, default=1000.0)
    ap.add_argument('--interval', type=float, default=5.0, help='sampling period (s)')
    ap.add_argument('--no-record', action='store_true')
    args = ap.parse_args()
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', '77')
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    tmp = tempfile.mkdtemp(prefix='soak-')
    bag = os.path.join(tmp, 'soak')
    cmd = [sys.executable, '-m', 'umbrella_sim.node', '--ros-args',
           '-p', f'publish_rate:={args.publish_rate}', '-p', 'v0:=-0.2']
    if not args.no_record:
        cmd += ['-p', f'record_path:={bag}']
    log = open(os.path.join(tmp, 'node.log'), 'w')
    diag = Diagnostics()
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=ROOT)
    rows = []          # wall, sim, rss kB, cpu s
    t_end = time.monotonic() + 60.0 * args.minutes
    try:
        while time.monotonic() < t_end and proc.poll() is None:
            time.sleep(args.interval)
            if 'sim_time_s' not in diag.values:
                continue
            rows.append((time.monotonic(), float(diag.values['sim_time_s']), rss_kb(proc.pid),
                         cpu_s(proc.pid)))
    finally:
        final = dict(diag.values)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
        diag.close()
        log.close()
    if len(rows) < 4:
        print(f'not enough samples ({len(rows)}); node log: {log.name}')
        return 1
    a = np.array(rows)
    warm = a[a[:, 0] >= a[0, 0] + 0.2 * (a[-1, 0] - a[0, 0])]       # skip the first 20 %
    slope = np.polyfit(warm[:, 1], warm[:, 2], 1)[0]
    sim_span = a[-1, 1] - a[0, 1]
    wall_span = a[-1, 0] - a[0, 0]
    cpu_per_sim = (a[-1, 3] - a[0, 3]) / sim_span
    size = sum(os.path.getsize(os.path.join(bag, f)) for f in os.listdir(bag)) \
        if os.path.isdir(bag) else 0
    print(f'soak: {wall_span / 60:.1f} wall min, {sim_span:.1f} simulated s at '
          f"{args.publish_rate:g} Hz, recording {'off' if args.no_record else 'on'} "
          f'(exit code {proc.returncode})')
    print(f'RSS: {a[0, 2] / 1024:.1f} MB -> {a[-1, 2] / 1024:.1f} MB; slope after warm-up '
          f'{slope:.2f} kB per simulated s ({slope * 60 / 1024:.2f} MB per simulated min)')
    quarters = [a[min(len(a) - 1, round(q * (len(a) - 1)))] for q in (0.25, 0.5, 0.75, 1.0)]
    print('RSS at 1/4, 1/2, 3/4, end of the run: ' + ', '.join(
        f'{r[2] / 1024:.1f} MB (t = {r[1]:.0f} s)' for r in quarters))
    print(f"lag: largest max_lag_s {diag.max_lag:.3f} s; slip {final.get('slip_s', '?')} s "
          f"in {final.get('re_anchors', '?')} re-anchors; achieved real-time factor "
          f'{sim_span / wall_span:.3f}')
    print(f'CPU: {cpu_per_sim:.3f} CPU-s per simulated s')
    if size:
        print(f'recording: {size / sim_span / 1024:.1f} KiB per simulated s '
              f'({size / 2**20:.1f} MiB)')
    print(f'files: {tmp}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
