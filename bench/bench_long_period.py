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
umbrella_node through long publication periods: memory, service answers, diagnostics, stop.

A low ``publish_rate`` with a small physics step makes a publication period of millions of
steps (``-p publish_rate:=1.0 -p time_step:=1e-7``: 10^7 steps, tens of seconds of CPU).
The node must stay a ROS node through it.  This script starts one (recording on, into a
temporary directory), then for --minutes of wall time:

  * samples its resident memory (RSS) every --interval seconds;
  * calls ``~/pause`` (true, then false) every --pause-every seconds and times the answers;
  * times the gaps between the node's /diagnostics statuses (1 Hz of wall time);
  * publishes a sleeve_force command and notes when the node says it applied it;

then sends SIGINT and times the exit.  It prints each figure with the load average (the
machine may be shared; every wall-clock figure moves with the load, the RSS does not).
Targets: RSS flat after start-up (no growth with the run); ``~/pause`` answered within
0.1 s; /diagnostics every 1 s (+ one chunk, ~10 ms); the exit within 1 s of SIGINT.

    python bench/bench_long_period.py                      # 3 min, 1 Hz, 1e-7 s
    python bench/bench_long_period.py --minutes 10 --args -p publish_rate:=1.0
"""
import argparse
import os
import signal
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.process_figures import load, rss_mb  # noqa: E402
from tests.ros_helpers import NodeProcess, Probe  # noqa: E402


def percentiles(values, qs=(50, 99, 100)) -> str:
    if not values:
        return 'none'
    v = sorted(values)
    return ', '.join(f'p{q} {v[min(len(v) - 1, int(q / 100 * len(v)))] * 1e3:.1f} ms'
                     for q in qs)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--minutes', type=float, default=3.0, help='wall minutes (default 3)')
    ap.add_argument('--interval', type=float, default=2.0, help='RSS sampling period (s)')
    ap.add_argument('--pause-every', type=float, default=10.0,
                    help='seconds between two ~/pause true/false pairs')
    ap.add_argument('--args', nargs=argparse.REMAINDER,
                    default=['-p', 'publish_rate:=1.0', '-p', 'time_step:=1e-7'],
                    help="the node's ROS arguments (default: -p publish_rate:=1.0 -p "
                         'time_step:=1e-7)')
    args = ap.parse_args()
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64
    from std_srvs.srv import SetBool

    tmp = tempfile.mkdtemp(prefix='long-period-')
    print(f"node: umbrella_node --ros-args {' '.join(args.args)}; {load()}")
    probe = Probe('long_period_probe')
    probe.subscribe('/diagnostics', DiagnosticArray)
    pub = probe.publisher('/sleeve_force', Float64)
    node = NodeProcess(*args.args, cwd=tmp)
    rss, pauses, resumes = [], [], []
    try:
        node.wait_for_log(r'recording to', timeout=60)
        t0 = time.monotonic()
        next_pause = t0 + args.pause_every
        commanded = False
        while time.monotonic() - t0 < 60.0 * args.minutes and node.running:
            rss.append((time.monotonic() - t0, rss_mb(node.pid)))
            if not commanded and time.monotonic() - t0 > 5.0:
                probe.wait_for_subscribers(pub)
                pub.publish(Float64(data=20.0))
                commanded = time.monotonic()
            if time.monotonic() >= next_pause:
                for data, times in ((True, pauses), (False, resumes)):
                    start = time.monotonic()
                    probe.call(SetBool, '/umbrella_node/pause', SetBool.Request(data=data),
                               timeout=120.0)
                    times.append(time.monotonic() - start)
                next_pause = time.monotonic() + args.pause_every
            time.sleep(args.interval)
        arrivals = [t for t, _ in probe.timed('/diagnostics')]
        gaps = [b - a for a, b in zip(arrivals, arrivals[1:])]
        last = probe.messages('/diagnostics')[-1] if arrivals else None
        start = time.monotonic()
        node.proc.send_signal(signal.SIGINT)
        try:
            code = node.proc.wait(120)
        except Exception:
            code = None
        stop_s = time.monotonic() - start
        out = node.output()
    finally:
        node.close()
        probe.close()
    print(f'after {rss[-1][0]:.0f} s: {load()}')
    print('RSS (MB): ' + ', '.join(f'{m:.1f} at {t:.0f} s' for t, m in
                                   rss[::max(1, len(rss) // 8)] + rss[-1:]))
    print(f'RSS growth: {rss[-1][1] - rss[min(len(rss) - 1, 3)][1]:+.1f} MB from '
          f'{rss[min(len(rss) - 1, 3)][0]:.0f} s to {rss[-1][0]:.0f} s')
    print(f'~/pause true answered in: {percentiles(pauses)} ({len(pauses)} calls)')
    print(f'~/pause false answered in: {percentiles(resumes)} ({len(resumes)} calls)')
    print(f'/diagnostics gaps: {percentiles(gaps)} ({len(arrivals)} statuses)')
    if last is not None:
        values = {kv.key: kv.value for kv in last.status[0].values}
        print(f'last /diagnostics: {last.status[0].message!r}, sim_time_s '
              f"{values.get('sim_time_s')}, steps {values.get('steps')}")
    applied = [line for line in out.splitlines() if 'sleeve force 20 N applied' in line]
    print(f"command 20 N: {'applied: ' + applied[0] if applied else 'not applied yet'}"
          if commanded else 'command: not sent')
    print(f'SIGINT -> exit {code} in {stop_s:.2f} s; {load()}')
    print(f'files: {tmp}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
