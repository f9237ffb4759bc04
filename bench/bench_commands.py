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
Command intake of umbrella_node: a burst of sleeve_force commands, as fast as DDS takes them.

Starts the node (recording on, into a temporary directory) and, from a probe process,
publishes --count commands (reliable, keep all: none may be lost) as fast as the publisher
goes (when its history is full, rclpy's publish fails after DDS's blocking time: it retries),
a tenth of them refused (negative).  Prints, with the load average:

  * the publishing time and rate (what the probe's reliable writer was let through);
  * the node's intake: the span of the commands' receipt times in the recording (sim time
    at receipt, which real_time_factor 1 keeps on wall time while the physics keeps up) and
    the rate, and when the node's diagnostics counted the last one;
  * whether any was lost (accepted + refused counted = sent; recorded = accepted + the
    refused within the 10/s recording limit);
  * the node's largest lag behind real time and its RSS before, during and after;
  * ``~/pause`` answer times during the burst.

    python bench/bench_commands.py [--count 20000] [--publish-rate 100] [--args -p ...]
"""
import argparse
import json
import os
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.process_figures import counted_commands, load, rss_mb  # noqa: E402
from tests.ros_helpers import NodeProcess, Probe  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--count', type=int, default=20000)
    ap.add_argument('--publish-rate', type=float, default=100.0, help="the node's (Hz)")
    ap.add_argument('--args', nargs=argparse.REMAINDER, default=[],
                    help='more ROS arguments for the node (e.g. -p start_paused:=true)')
    args = ap.parse_args()
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64
    from std_srvs.srv import SetBool

    from umbrella_sim.bag.reader import read_log

    tmp = tempfile.mkdtemp(prefix='commands-')
    bag = os.path.join(tmp, 'bag')
    probe = Probe('commands_probe')
    probe.subscribe('/diagnostics', DiagnosticArray)
    keep_all = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                          reliability=ReliabilityPolicy.RELIABLE)
    pub = probe.publisher('/sleeve_force', Float64, keep_all)
    node = NodeProcess('-p', f'publish_rate:={args.publish_rate}', '-p', 'v0:=0.0',
                       '-p', f'record_path:={bag}', *args.args, cwd=tmp)
    rss, pauses = [], []
    try:
        node.wait_for_log('recording to', timeout=60)
        probe.wait_for_subscribers(pub)
        time.sleep(1.0)
        rss.append(rss_mb(node.pid))
        stop = threading.Event()

        def during():
            while not stop.is_set():
                rss.append(rss_mb(node.pid))
                start = time.monotonic()     # (a resume of a running node: answered as a
                # pause is, after the same wait for the sim lock; it re-anchors the pacing)
                probe.call(SetBool, '/umbrella_node/pause', SetBool.Request(data=False))
                pauses.append(time.monotonic() - start)
                time.sleep(0.2)
        watcher = threading.Thread(target=during, daemon=True)
        watcher.start()
        print(f'publishing {args.count} commands; {load()}')
        t0 = time.monotonic()
        held_back = 0
        for i in range(args.count):
            msg = Float64(data=-1.0 if i % 10 == 9 else 1.0 + (i % 7))
            while True:
                try:
                    pub.publish(msg)
                    break
                except Exception:     # RCLError: the writer's history is full (flow control)
                    held_back += 1
                    time.sleep(0.001)
        t_pub = time.monotonic() - t0

        deadline = time.monotonic() + 600
        while counted_commands(probe) < args.count and time.monotonic() < deadline:
            time.sleep(0.05)
        t_counted = time.monotonic() - t0
        stop.set()
        watcher.join()
        max_lag = max(float({kv.key: kv.value for kv in m.status[0].values}['max_lag_s'])
                      for m in probe.messages('/diagnostics'))
        rss.append(rss_mb(node.pid))
        code = node.stop()
    finally:
        node.close()
        probe.close()
    log = read_log(bag)
    times = [t for t, _ in log.decoded('/sleeve_force')]
    counts = log.metadata['umbrella_sim.counts']
    accepted, refused = int(counts['commands_accepted']), int(counts['commands_refused'])
    span = times[-1] - times[0] if len(times) > 1 else float('nan')
    print(f"published in {t_pub:.2f} s ({args.count / t_pub:.0f}/s; the writer's history was "
          f'full {held_back} times: DDS flow control holding it back); {load()}')
    print(f'node intake: {len(times)} accepted recorded over {span:.2f} s of sim time '
          f'({args.count / span:.0f} commands/s); all counted by diagnostics '
          f'{t_counted:.1f} s after the first was sent')
    lost = args.count - accepted - refused
    print(f'counted: {accepted} accepted + {refused} refused = {accepted + refused} of '
          f"{args.count} sent ({'none' if lost == 0 else lost} lost); recorded refused "
          f"{log.count('/sleeve_force/refused')} + not recorded "
          f"{counts.get('refused_not_recorded')}")
    print(f'node: largest lag behind real time {max_lag * 1e3:.1f} ms; RSS {rss[0]:.1f} MB '
          f'before, {max(rss):.1f} MB peak, {rss[-1]:.1f} MB after; exit {code}')
    if pauses:
        p = sorted(pauses)
        print(f'~/pause during the burst: p50 {p[len(p) // 2] * 1e3:.1f} ms, max '
              f'{p[-1] * 1e3:.1f} ms ({len(p)} calls)')
    print(json.dumps({'published_per_s': args.count / t_pub, 'intake_per_s': args.count / span,
                      'lost': lost}))
    print(f'files: {tmp}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
