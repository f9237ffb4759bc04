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
umbrella_node's command intake under a paced stream, a second publisher and a stop in a flood.

Starts the node (recording on, into a temporary directory) and, from a probe process:

  1. publishes a stream of sleeve_force commands paced at --rate (default 10 kHz) for
     --seconds, while a second publisher (its own DDS writer) sends one command every 0.25 s;
  2. waits until the node's diagnostics count every command (1 Hz: the backlog's bound);
  3. floods --flood commands as fast as the writer goes and sends SIGINT halfway.

Then reads the recording and prints, with the load average:

  * the stream's achieved rate, and each command's delay from its send to the node's taking
    it: the recorded receipt time is sim time, mapped to the probe's wall clock by the
    arrival of the first /clock at or after it (so a delay includes up to one publication
    period, 10 ms, and /clock's own delivery): p50 / p99 / max for the stream and for the
    second publisher, and the stream's last command (the backlog when the stream ended);
  * when the diagnostics had counted every command of the stream after its last was sent;
  * the stop: SIGINT -> exit, commands sent, counted (accepted + refused), taken at the
    stop, dropped at the stop (delivered after the stop's first second: counted apart, in
    commands_dropped_at_stop), and sent before the node exited but neither counted nor
    dropped (in flight in the writer's history: DDS had not delivered them to the node).

``--node-root DIR`` runs the node from another checkout (PYTHONPATH=DIR), for a before/after.

    python bench/bench_command_streams.py [--rate 10000] [--seconds 5] [--flood 20000]
"""
import argparse
import bisect
import json
import os
import signal
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.process_figures import counted_commands, load  # noqa: E402
from tests.ros_helpers import NodeProcess, Probe  # noqa: E402


STREAM, SECOND, FLOOD = 1.0, 100.0, 2.0     # each source's base value (+ index x 1e-6 / + k)


def pct(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))] if v else float('nan')


def publish(pub, msg):
    """Publish, retrying while the reliable writer's history is full (DDS flow control)."""
    while True:
        try:
            pub.publish(msg)
            return
        except Exception:       # RCLError: the history is full
            time.sleep(0.0005)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--rate', type=float, default=10000.0, help='stream rate (Hz)')
    ap.add_argument('--seconds', type=float, default=5.0, help='stream length (s)')
    ap.add_argument('--flood', type=int, default=20000, help="commands of the stop's flood")
    ap.add_argument('--node-root', help='run the node from this checkout (PYTHONPATH)')
    args = ap.parse_args()
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    from umbrella_sim.bag.reader import read_log

    if args.node_root:
        os.environ['PYTHONPATH'] = os.path.abspath(args.node_root)
    tmp = tempfile.mkdtemp(prefix='command-streams-')
    bag = os.path.join(tmp, 'bag')
    probe = Probe('streams_probe')
    probe.subscribe('/diagnostics', DiagnosticArray)
    probe.subscribe('/clock', Clock, QoSProfile(depth=1000,
                                                reliability=ReliabilityPolicy.BEST_EFFORT))
    keep_all = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL,
                          reliability=ReliabilityPolicy.RELIABLE)
    pub_a = probe.publisher('/sleeve_force', Float64, keep_all)
    pub_b = probe.publisher('/sleeve_force', Float64, keep_all)
    node = NodeProcess('-p', 'v0:=0.0', '-p', f'record_path:={bag}', cwd=tmp)
    sent_a, sent_b = {}, {}
    try:
        node.wait_for_log('recording to', timeout=60)
        probe.wait_for_subscribers(pub_a)
        probe.wait_for_subscribers(pub_b)
        time.sleep(1.0)
        n = int(args.rate * args.seconds)
        done = threading.Event()

        def second():
            k = 0
            while not done.is_set():
                sent_b[k] = time.monotonic()
                publish(pub_b, Float64(data=SECOND + k))
                k += 1
                done.wait(0.25)
        other = threading.Thread(target=second, daemon=True)
        print(f'stream: {n} commands at {args.rate:g} Hz, a second publisher at 4 Hz; {load()}')
        t0 = time.monotonic()
        other.start()
        i = 0
        while i < n:        # the commands due by now, then a short sleep (GIL for the probe)
            due = min(n, int((time.monotonic() - t0) * args.rate) + 1)
            while i < due:
                sent_a[i] = time.monotonic()
                publish(pub_a, Float64(data=STREAM + i * 1e-6))
                i += 1
            time.sleep(0.0005)
        t_end = time.monotonic()
        done.set()
        other.join()

        total = n + len(sent_b)
        deadline = time.monotonic() + 600
        while counted_commands(probe) < total and time.monotonic() < deadline:
            time.sleep(0.02)
        t_counted = time.monotonic() - t_end
        # the stop in a flood
        flood_sent = [0]
        node_gone = threading.Event()

        def flood():
            for j in range(args.flood):
                if node_gone.is_set():
                    return
                publish(pub_a, Float64(data=FLOOD + j * 1e-6))
                flood_sent[0] += 1
        flooder = threading.Thread(target=flood, daemon=True)
        flooder.start()
        while flood_sent[0] < args.flood // 2 and flooder.is_alive():
            time.sleep(0.001)
        t_sig = time.monotonic()
        sent_before_sigint = flood_sent[0]
        node.proc.send_signal(signal.SIGINT)
        code = node.proc.wait(60)
        t_exit = time.monotonic() - t_sig
        node_gone.set()             # (sent after the exit: to nobody)
        sent_before_exit = flood_sent[0]
        flooder.join(120)
        probe_clock = [(m.clock.sec + 1e-9 * m.clock.nanosec, wall)
                       for wall, m in probe.timed('/clock')]
    finally:
        node.close()
        probe.close()
    log = read_log(bag)
    recv = [(t, msg.data) for t, msg in log.decoded('/sleeve_force')]    # receipt times
    delay_a, delay_b = {}, {}
    for t, v in recv:
        if v >= SECOND:
            delay_b[int(round(v - SECOND))] = t
        elif v < FLOOD:
            delay_a[int(round((v - STREAM) * 1e6))] = t
    # sim time -> wall time: when the first /clock at or after it arrived (the node's next
    # publication after taking the command; re-anchored pacing included)
    clock = probe_clock
    sims = [c for c, _ in clock]

    def seen_at(t):
        k = bisect.bisect_left(sims, t - 1e-9)
        return clock[k][1] if k < len(clock) else float('nan')
    da = {i: seen_at(t) - sent_a[i] for i, t in delay_a.items()}
    db = [seen_at(t) - sent_b[k] for k, t in delay_b.items() if k in sent_b]
    counts = log.metadata['umbrella_sim.counts']
    accepted, refused = int(counts['commands_accepted']), int(counts['commands_refused'])
    sent = n + len(sent_b) + sent_before_exit
    print(f'stream sent in {t_end - t0:.2f} s ({n / (t_end - t0):.0f}/s); {load()}')
    print(f'stream delay send -> taken: p50 {pct(da.values(), 0.5) * 1e3:.1f} ms, p99 '
          f'{pct(da.values(), 0.99) * 1e3:.1f} ms, max {max(da.values()) * 1e3:.1f} ms; '
          f"its last command {da.get(n - 1, float('nan')) * 1e3:.1f} ms (the backlog at its end)")
    print(f"second publisher's delay: p50 {pct(db, 0.5) * 1e3:.1f} ms, max "
          f'{max(db) * 1e3:.1f} ms ({len(db)} of {len(sent_b)} recorded)')
    print(f'every stream command counted by diagnostics {t_counted:.2f} s after the last was '
          'sent (1 Hz diagnostics)')
    taken = counts.get('commands_taken_at_stop', 'n/a')
    dropped = counts.get('commands_dropped_at_stop', 'n/a')
    dropped_n = int(dropped) if str(dropped).isdigit() else 0     # ('n/a': an older node)
    undelivered = sent - accepted - refused - dropped_n
    before_sigint = n + len(sent_b) + sent_before_sigint
    print(f'stop in a flood: SIGINT -> exit {t_exit:.2f} s (exit {code}); sent {before_sigint} '
          f'before SIGINT and {sent} before the exit; counted {accepted + refused}, of which '
          f'taken at the stop {taken}; dropped at the stop {dropped}; sent before SIGINT but '
          f'not counted {max(0, before_sigint - accepted - refused)}; sent before the exit but '
          f'neither counted nor dropped {undelivered} (in the writer, never delivered)')
    print(json.dumps({'stream_per_s': n / (t_end - t0),
                      'stream_delay_p50_ms': pct(da.values(), 0.5) * 1e3,
                      'stream_last_delay_ms': da.get(n - 1, float('nan')) * 1e3,
                      'second_delay_max_ms': max(db) * 1e3, 'counted_after_s': t_counted,
                      'sigint_exit_s': t_exit,
                      'sent_before_sigint_not_counted': max(0, before_sigint - accepted - refused),
                      'dropped_at_stop': dropped_n,
                      'sent_before_exit_undelivered': undelivered}))
    print(f'files: {tmp}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
