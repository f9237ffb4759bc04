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
Measure umbrella_node timing from a separate subscriber process over DDS.

Default config.  Prints:
  * a table of CPU seconds per simulated second of the node process (all its threads:
    physics, publication, recording writer, executor) at real_time_factor = 1, for
    N = 2 and 8 (--cpu-elements) x publish_rate 100 Hz and 1 kHz (--cpu-rates), without and
    with recording, and with recording while this process subscribes to /clock
    (--cpu-seconds of steady state, after a 2 s warm-up), with the load average (the machine
    may be shared: the figures include what other load costs the node).  The sim time of
    each mark comes from /diagnostics (1 Hz), so the first two columns have no subscriber to
    a per-period topic: what delivering each publication to a subscriber costs the node's
    Fast DDS is the third column less the second;
  * the achieved real-time factor with real_time_factor = 0 (as fast as possible);
  * at real_time_factor = 1, publish_rate 200 Hz and 1 kHz: p50 / p99 of |interval - period|
    of /clock arrivals, and the sim-time vs wall-time drift over the run (--seconds, 60).
The arrival times include DDS transport, so they bound the node's own publication jitter.

    python bench/bench_node.py [--seconds 60] [--elements 2] [--rates 200 1000]
    python bench/bench_node.py --cpu-only            # the CPU table only
    # the 10-minute drift run:
    python bench/bench_node.py --seconds 600 --rates 200 --fast-seconds 0
"""
import argparse
import gc
import os
import sys
import tempfile
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rosgraph_msgs.msg import Clock

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
sys.path.insert(0, ROOT)

from tests.ros_helpers import NodeProcess, Probe  # noqa: E402
from umbrella_sim.ros.messages import CLOCK_READER_QOS  # noqa: E402


def wall_stamp(line_match) -> float:
    return float(line_match.group(1))


def as_fast_as_possible(n_el: int, sim_seconds: float) -> float:
    with NodeProcess('-p', f'elements_per_segment:={n_el}', '-p', 'real_time_factor:=0.0',
                     '-p', f'duration:={sim_seconds}') as node:
        start = wall_stamp(node.wait_for_log(
            r'\[INFO\] \[([0-9.]+)\] \[umbrella_node\]: umbrella_sim'))
        end = wall_stamp(node.wait_for_log(r'\[INFO\] \[([0-9.]+)\] \[umbrella_node\]: duration',
                                           timeout=600))
        node.proc.wait(60)
    return sim_seconds / (end - start)


def process_cpu(pid: int) -> float:
    """Return the CPU seconds (user + system, all threads) of a running process."""
    with open(f'/proc/{pid}/stat') as fh:
        fields = fh.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def cpu_per_sim_second(probe: Probe, n_el: int, rate: float, record: bool, seconds: float,
                       clock_subscriber: bool = False):
    """
    Return (node CPU s per simulated s, simulated s per wall s) in steady state.

    The marks are taken as /diagnostics messages arrive (probe subscribes to it: 1 Hz,
    carrying the node's sim time); with clock_subscriber, a second probe subscribes to
    /clock (one publication a period) meanwhile.
    """
    probe.received['/diagnostics'] = []
    clock_probe = None
    with tempfile.TemporaryDirectory(prefix='bench_node_') as tmp:
        rec = ['-p', f'record_path:={tmp}/bag'] if record else ['-p', 'record:=false']
        with NodeProcess('-p', f'elements_per_segment:={n_el}', '-p', f'publish_rate:={rate}',
                         '-p', 'real_time_factor:=1.0', *rec, cwd=tmp) as node:
            try:
                node.wait_for_log('physics step')
                if clock_subscriber:
                    clock_probe = Probe('bench_cpu_clock_probe')
                    clock_probe.subscribe('/clock', Clock, CLOCK_READER_QOS)
                    clock_probe.wait_for('/clock', timeout=30)
                probe.wait_for('/diagnostics', timeout=30)
                time.sleep(2.0)                              # discovery, warm-up
                marks = []
                for wait in (0.0, seconds):
                    time.sleep(wait)
                    count = len(probe.messages('/diagnostics'))
                    msg = probe.wait_for_count('/diagnostics', count + 1, timeout=30)[-1]
                    cpu = process_cpu(node.proc.pid)     # as the message arrives
                    values = {kv.key: kv.value for kv in msg.status[0].values}
                    marks.append((cpu, float(values['sim_time_s']), time.monotonic()))
            finally:
                if clock_probe is not None:
                    clock_probe.close()
    (c0, s0, w0), (c1, s1, w1) = marks
    return (c1 - c0) / (s1 - s0), (s1 - s0) / (w1 - w0)


def physics_alone(n_el: int, rate: float, sim_seconds: float = 1.0) -> float:
    """
    Return the CPU s per simulated s of the physics alone (this process, no ROS).

    RunDriver.advance_period, one publication period at a time (steps, StepBlock, summary),
    without messages: the node's figure minus this one is the publication path's cost.
    """
    from umbrella_sim.core.driver import RunDriver
    from umbrella_sim.core.params import UmbrellaParams
    driver = RunDriver(UmbrellaParams(elements_per_segment=n_el), rate)
    periods = int(round(sim_seconds * rate))
    for _ in range(periods // 10):           # warm-up
        driver.advance_period()
    c0 = time.thread_time()
    for _ in range(periods):
        driver.advance_period()
    return (time.thread_time() - c0) / (periods / rate)


def cpu_table(args) -> None:
    """Print CPU s per simulated s, without and with recording, for each N and rate."""
    probe = Probe('bench_cpu_probe')
    probe.subscribe('/diagnostics', DiagnosticArray)
    print('CPU seconds per simulated second of umbrella_node (all threads), real_time_factor 1;'
          '\nno subscriber to a per-period topic, then recording with one /clock subscriber;'
          '\nphysics alone: the same periods stepped in this process without ROS (the '
          'difference is\nthe publication path: messages, publishing, recording, pacing)')
    print(f"{'N':>3} {'rate Hz':>8} {'no recording':>13} {'recording':>10} "
          f"{'+ /clock sub':>13} {'physics alone':>14} {'achieved x':>11} {'loadavg':>8}")
    try:
        for n_el in args.cpu_elements:
            for rate in args.cpu_rates:
                row = [cpu_per_sim_second(probe, n_el, rate, record, args.cpu_seconds, sub)
                       for record, sub in ((False, False), (True, False), (True, True))]
                alone = physics_alone(n_el, rate)
                print(f'{n_el:>3} {rate:>8g} {row[0][0]:>13.3f} {row[1][0]:>10.3f} '
                      f'{row[2][0]:>13.3f} {alone:>14.3f} {min(r[1] for r in row):>11.3f} '
                      f'{os.getloadavg()[0]:>8.2f} (on {os.cpu_count()} CPUs)', flush=True)
    finally:
        probe.close()


def paced(probe: Probe, n_el: int, rate: float, seconds: float):
    topic = '/clock'
    probe.received[topic] = []
    probe.received['/diagnostics'] = []
    with NodeProcess('-p', f'elements_per_segment:={n_el}', '-p', f'publish_rate:={rate}',
                     '-p', 'real_time_factor:=1.0') as node:
        node.wait_for_log('physics step')
        probe.wait_for(topic, timeout=30)
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds + 2.0:
            time.sleep(0.5)
        behind = 'cannot keep up' in node.output()
    data = probe.timed(topic)
    wall = np.array([w for w, _ in data])
    sim = np.array([m.clock.sec + 1e-9 * m.clock.nanosec for _, m in data])
    keep = wall >= wall[0] + 1.0            # skip the first second (discovery, warm-up)
    wall, sim = wall[keep], sim[keep]
    wall, sim = wall[wall <= wall[0] + seconds], sim[wall <= wall[0] + seconds]
    period = 1.0 / rate
    jitter = np.abs(np.diff(wall) - period)
    drift = (sim - sim[0]) - (wall - wall[0])
    expected = int(round((sim[-1] - sim[0]) / period)) + 1
    node_lag = max(float({kv.key: kv.value for kv in m.status[0].values}['max_lag_s'])
                   for m in probe.messages('/diagnostics')[1:])
    beyond = int(np.sum(np.abs(drift) > period))
    return {'node_max_lag': node_lag, 'beyond': beyond,
            'p50': np.percentile(jitter, 50), 'p99': np.percentile(jitter, 99),
            'drift_end': drift[-1], 'drift_max': np.abs(drift).max(), 'span': wall[-1] - wall[0],
            'received': len(sim), 'expected': expected, 'behind': behind}


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--elements', type=int, default=2)
    ap.add_argument('--fast-seconds', type=float, default=20.0,
                    help='sim seconds of the as-fast-as-possible run (0 skips it)')
    ap.add_argument('--rates', type=float, nargs='+', default=[200.0, 1000.0],
                    help='publish rates (Hz) of the paced runs')
    ap.add_argument('--cpu-rates', type=float, nargs='*', default=[100.0, 1000.0],
                    help='publish rates (Hz) of the CPU table (none skips it)')
    ap.add_argument('--cpu-elements', type=int, nargs='+', default=[2, 8],
                    help='elements per segment of the CPU table')
    ap.add_argument('--cpu-seconds', type=float, default=10.0,
                    help='wall seconds of steady state the CPU is measured over')
    ap.add_argument('--cpu-only', action='store_true', help='only the CPU measurement')
    args = ap.parse_args()
    if args.cpu_rates:
        cpu_table(args)
        if args.cpu_only:
            return
    if args.fast_seconds > 0:
        rtf = as_fast_as_possible(args.elements, args.fast_seconds)
        print(f'N = {args.elements}, real_time_factor = 0 (publish 100 Hz): achieved {rtf:.1f}x '
              f'real time over {args.fast_seconds:g} s of sim time')
    # the probe keeps every /clock sample (120 000 in ten minutes at 200 Hz): the collector's
    # full passes over them would stall arrivals by tens of ms and show up as fake drift
    gc.disable()
    probe = Probe('bench_probe')
    probe.subscribe('/clock', Clock, CLOCK_READER_QOS)  # /clock is best effort
    probe.subscribe('/diagnostics', DiagnosticArray)
    try:
        for rate in args.rates:
            r = paced(probe, args.elements, rate, args.seconds)
            print(f'N = {args.elements}, real_time_factor = 1, {rate:g} Hz over '
                  f"{r['span']:.1f} s: "
                  f"interval jitter p50 {r['p50'] * 1e6:.0f} us, p99 {r['p99'] * 1e6:.0f} us; "
                  f"sim - wall drift at end {r['drift_end'] * 1e3:+.3f} ms, max |drift| "
                  f"{r['drift_max'] * 1e3:.3f} ms at the subscriber ({r['beyond']} samples "
                  f'beyond one period), node-side max lag '
                  f"{r['node_max_lag'] * 1e3:.3f} ms (one period = {1e3 / rate:g} ms); "
                  f"received {r['received']}/{r['expected']}"
                  + ('; node reported falling behind' if r['behind'] else ''))
    finally:
        probe.close()


if __name__ == '__main__':
    main()
