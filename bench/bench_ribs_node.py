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
What the umbrella of N ribs costs the node: the step through the run driver, and live rates.

  * offline, per --ribs: CPU time per physics step of UmbrellaSimulator3D's own loop and of
    the RunDriver's (its chunks, the per-rib peak-hold, the summary) with a publication
    every 1 ms encoded as the node does (ribs_messages.RibsPublicationEncoder), per step and
    per step and rib; the encoder's cost per publication; and a 1 ms block's parts: the
    compiled steps (with their stress figures), Record3D's rows, the summary, the
    publication's sample, the encoding; and what a block costs beside the kernel (the
    compiled call stubbed: outside_kernel); from the start (deploying) or, with
    --after-lock S, from S s after the lock (stage 2); the hub fixed or, with --base, a
    base spun up about Y (prescribed, to --spin rad/s) or a free bus;
  * live (--live): umbrella_node with ribs --live-ribs at 1 kHz: the measured real-time
    factor its diagnostics report at real_time_factor 1 (with recording), whether it says
    it is behind, and the node process's CPU share (its CPU time, every thread, over the
    wall time between --live-windows + 1 diagnostics, from /proc/<pid>/stat: 1.0 is one
    core busy; its busiest threads' too, the physics thread first), and CPU seconds a sim
    second: after the lock (stage 2: 6 x 1 locks at 0.23 s) or, with --live-deploying, in a
    slow deployment (stage 1); and in lockstep, a commander answering every joint_states for
    --periods publications: sim seconds per wall second, and each period's delay from the
    command to the state it lets out (median, max; --lockstep-only: this line alone;
    --periods 0: none).
The machine is shared (2 cores): wall figures are noisy; the CPU time is what a step costs.

    python bench/bench_ribs_node.py [--ribs [2 3 6]] [--duration 0.02] [--after-lock S] [--live]
                                    [--step 0] [--base fixed|prescribed|free] [--spin 10]
                                    [--live-ribs 6] [--live-windows 3] [--periods 40]
                                    [--live-deploying] [--lockstep-only]
"""
import argparse
import math
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))

from umbrella_sim.core.driver import RunDriver  # noqa: E402
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams  # noqa: E402
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D  # noqa: E402

#: s: time_step 0, the run's own steps (stage 1 0.2 ms, stage 2 the mesh's: 0.1 ms at 1
#: element); --step: e.g. 1e-4, 10 a 1 kHz publication in both stages
STEP = 0.0


def offline(ribs: int, duration: float, after_lock: float | None = None,
            base: dict | None = None) -> None:
    """Print the offline figures; base: the base's values (--base, --spin; None: fixed)."""
    from umbrella_sim.ros.ribs_messages import RibsPublicationEncoder

    params = UmbrellaRibsParams.from_mapping({'ribs': ribs, 'time_step': STEP, **(base or {})})
    sim = UmbrellaSimulator3D(params)
    if after_lock is not None:
        sim.run(10.0, after_lock=after_lock)
    k0, t0 = sim.k, time.thread_time()
    sim.run(sim.time + duration)
    own = (time.thread_time() - t0) / (sim.k - k0)
    driver = RunDriver(params, 1000.0)
    encoder = RibsPublicationEncoder(driver)
    encoder.messages(driver.publication())     # (warm: the message modules' first use)
    if after_lock is not None:
        driver.run(10.0, stop_after_lock=after_lock, on_publication=encoder.messages)
    encoding = [0.0]

    def published(sample):
        t = time.thread_time()
        encoder.messages(sample)
        encoding[0] += time.thread_time() - t

    parts = timed_parts(driver)
    k0, t0 = driver.sim.steps, time.thread_time()
    driver.run(driver.time + duration, on_publication=published)
    steps = driver.sim.steps - k0
    driven = (time.thread_time() - t0) / steps
    grid = driver.step
    per_publication = encoding[0] / max(steps * grid / 1e-3 - 1, 1)
    stage = ('' if after_lock is None
             else f', {after_lock:g} s after the lock at {driver.sim.lock_time:.4f} s')
    if base:
        stage += ', ' + ', '.join(f'{k} {v}' for k, v in base.items())
    print(f'ribs {ribs:2d}{stage}: own loop {own * 1e3:.3f} ms/step ({own / ribs * 1e3:.3f} per '
          f'rib); run driver + 1 kHz publications {driven * 1e3:.3f} ms/step '
          f'({driven / ribs * 1e3:.3f} per rib); encoding {per_publication * 1e3:.3f} ms a '
          f'publication; real-time factor at {grid * 1e6:.0f} us grid steps '
          f'{grid / driven:.3f}')
    blocks = steps * grid / 1e-3
    print(f'          a 1 ms block ({round(1e-3 / grid)} grid steps) of the run driver: '
          + ', '.join(f'{name} {cpu / blocks * 1e6:.0f} us' for name, cpu in parts.items())
          + f', encoding {encoding[0] / blocks * 1e6:.0f} us (of '
          f'{driven * round(1e-3 / grid) * 1e6:.0f} us; CPU of this thread)')
    print(f'          without the compiled call: {outside_kernel(driver, encoder):.0f} us a 1 ms '
          'block (best of 9)')


def outside_kernel(driver, encoder, blocks: int = 200, repeats: int = 9) -> float:
    """
    Return the CPU (us) a 1 ms block of the driver and its encoding costs beside the kernel.

    The compiled call is stubbed (it returns the last block's rows again, its state moved
    on in time), so that what is timed is everything else a publication costs the physics
    thread: the call's Python side, Record3D's rows, the summary, the publication's sample
    and its encoding (no markers); best of repeats.  The rows repeat, so that the run's
    peaks never grow (Record3D's update of them is skipped: a little less than a run's).
    The driver is spent afterwards.
    """
    compiled = driver.sim.integrator.compiled
    library, call = compiled.lib, compiled.call

    class Stub:

        def __getattr__(self, name):
            return getattr(library, name)

        @staticmethod
        def umbrella3d_advance(ctx, ref):
            call.n_done = call.n_steps
            call.t = call.t + call.n_steps * call.h
            return 0

    compiled.lib = Stub()
    encoder.marker_every = 10 ** 9
    encoder.count = 1
    best = math.inf
    for _ in range(repeats):
        t0 = time.thread_time()
        for _ in range(blocks):
            driver.advance()
            encoder.messages(driver.publication())
        best = min(best, (time.thread_time() - t0) / blocks)
    compiled.lib = library
    return best * 1e6


def timed_parts(driver) -> dict:
    """
    Time what a run driver's chunk does, part by part (CPU of this thread, summed in place).

    The compiled call (its steps and stress figures), Record3D's rows of them, the summary,
    and the publication's sample (its peak-hold); returns {part: CPU s so far}.
    """
    sim = driver.sim
    parts = {'compiled steps': 0.0, 'Record3D': 0.0, 'Summary3D': 0.0, 'publication': 0.0}
    for name, owner, method in (('compiled steps', sim.integrator.compiled, 'advance_rows'),
                                ('Record3D', sim.record, 'add_steps'),
                                ('Summary3D', driver.summary, 'add'),
                                ('publication', driver, 'publication')):
        if owner is None:
            continue

        def timed(*args, _f=getattr(owner, method), _name=name, **kwargs):
            t = time.thread_time()
            try:
                return _f(*args, **kwargs)
            finally:
                parts[_name] += time.thread_time() - t

        setattr(owner, method, timed)
    return parts


def cpu_seconds(stat: str) -> float:
    """Return the CPU time (user + system) of a /proc stat file so far (s)."""
    with open(stat) as fh:
        fields = fh.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')   # utime, stime


def thread_cpu_seconds(pid: int) -> dict:
    """Return {thread id: CPU time so far (s)} of every thread of a process."""
    out = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            out[tid] = cpu_seconds(f'/proc/{pid}/task/{tid}/stat')
        except FileNotFoundError:        # (ended meanwhile)
            pass
    return out


def thread_names(pid: int) -> dict:
    """Return {thread id: its name} (Fast DDS names its own: dds.ev.*, dds.shm.*...)."""
    out = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm') as fh:
                out[tid] = fh.read().strip()
        except FileNotFoundError:
            pass
    return out


def thread_split(before: dict, after: dict, names: dict, wall: float) -> str:
    """
    Say each busy thread's share (core) over wall seconds, busiest first, by name.

    Python's threads are all 'python' (the busiest is the physics thread, which makes the
    DDS writes too; the recorder's writer thread next; the executor's); Fast DDS's are named
    (dds.ev: its event thread, dds.shm / dds.udp: its receive threads).
    """
    shares = sorted(((v - before.get(k, 0.0)) / wall, names.get(k, '?'))
                    for k, v in after.items())
    return ', '.join(f'{name} {share:.3f}' for share, name in reversed(shares) if share >= 0.002)


#: a slow deployment for --live-deploying: from rest at 0.05 N a rib (6 x 1: the lock at 6.7 s)
DEPLOYING = {'v0': 0.0, 'sleeve_force': 0.05}


def live(ribs: int, periods: int, windows: int, deploying: bool = False) -> None:
    from umbrella_sim.testing import SimulatedAntenna
    from umbrella_sim.testing.processes import poll

    with tempfile.TemporaryDirectory() as tmp:
        with SimulatedAntenna({'ribs': ribs, 'time_step': STEP, 'publish_rate': 1000.0,
                               **(DEPLOYING if deploying else {})},
                              record_path=os.path.join(tmp, 'bag')) as antenna:
            antenna.wait_for('diagnostics', lambda m: True, timeout=30)
            pid = antenna.node.pid
            cpu, threads, wall = cpu_seconds(f'/proc/{pid}/stat'), thread_cpu_seconds(pid), \
                time.monotonic()
            sim = antenna.sim_time()
            first, rates = len(antenna.messages('diagnostics')), []
            for i in range(first, first + windows):   # (after the start-up's)
                status = poll(lambda: antenna.messages('diagnostics')[i:i + 1], 30,
                              lambda: 'no diagnostics within 30 s')[0]
                values = {kv.key: kv.value for kv in status.status[0].values}
                rates.append(values['measured_real_time_factor'])
            cpu = cpu_seconds(f'/proc/{pid}/stat') - cpu
            after, names = thread_cpu_seconds(pid), thread_names(pid)
            wall, sim = time.monotonic() - wall, antenna.sim_time() - sim
            print(f'live ribs {ribs}, real_time_factor 1, recording: measured '
                  f"{', '.join(rates)} (a second each; {sim / wall:.3f} over {wall:.1f} s), "
                  f"lag {values['lag_s']} s; node CPU share {cpu / wall:.3f} core, "
                  f'{cpu / sim:.3f} CPU s a sim s (its threads: '
                  f'{thread_split(threads, after, names, wall)} core); '
                  f'load {os.getloadavg()[0]:.2f}; status '
                  f'{status.status[0].message!r}')
    if periods:
        lockstep(ribs, periods)


def lockstep(ribs: int, periods: int, rate_hz: float = 1000.0) -> None:
    """
    In lockstep at rate_hz, a commander answering every joint_states: rate and each delay.

    The first command arms the handshake; the node runs the period it acts for, then waits:
    from the state after it, each command lets exactly one period run.  Printed: sim seconds
    per wall second over `periods` periods, and each period's delay from the command's
    publication to the arrival of the state it let out (median, max).
    """
    from umbrella_sim.testing import SimulatedAntenna
    from umbrella_sim.testing.processes import poll

    period = 1.0 / rate_hz
    with SimulatedAntenna({'ribs': ribs, 'time_step': STEP, 'publish_rate': 1 / period,
                           'lockstep': True, 'v0': 0.0}) as antenna:
        antenna.publish_force(5.0)
        applied = poll(antenna.applied_forces, 30, lambda: 'the first command never applied')
        sim = applied[0][0] + period            # the state it let out: the node waits on it
        antenna.wait_for_sim_time(sim - 1e-9)
        topic, delays = antenna.topics['joint_states'], []
        wall = time.monotonic()
        for i in range(periods):
            sent = time.monotonic()
            antenna.publish_force(5.0)
            antenna.wait_for_sim_time(sim + (i + 1) * period - 1e-9)
            delays.append(next(a for a, m in reversed(antenna.probe.timed(topic))
                               if abs(stamp(m) - sim - (i + 1) * period) < 1e-9) - sent)
        rate = (antenna.sim_time() - sim) / (time.monotonic() - wall)
        delays.sort()
        print(f'live ribs {ribs}, lockstep at {rate_hz:g} Hz over {periods} periods: real-time '
              f'factor {rate:.4f}; a command to the state it lets out: median '
              f'{delays[len(delays) // 2] * 1e3:.2f} ms, max {delays[-1] * 1e3:.2f} ms; '
              f'load {os.getloadavg()[0]:.2f}')


def stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--ribs', type=int, nargs='*', default=[2, 3, 6],
                    help='offline figures of these (none: --ribs alone)')
    ap.add_argument('--duration', type=float, default=0.02)
    ap.add_argument('--live', action='store_true')
    ap.add_argument('--live-ribs', type=int, default=6)
    ap.add_argument('--live-windows', type=int, default=3)
    ap.add_argument('--periods', type=int, default=40)
    ap.add_argument('--after-lock', type=float, default=None, metavar='S',
                    help='offline: time the steps from S s after the lock (stage 2)')
    ap.add_argument('--live-deploying', action='store_true',
                    help=f'live: a slow deployment ({DEPLOYING}), timed before its lock')
    ap.add_argument('--lockstep-only', action='store_true',
                    help='only the live lockstep figures (of --live-ribs, --periods)')
    ap.add_argument('--lockstep-rate', type=float, default=1000.0, metavar='HZ',
                    help='the publication rate of the lockstep line (1000; 100: the default '
                         'of the node, the tested rate of deploy_controller)')
    ap.add_argument('--base', choices=('fixed', 'prescribed', 'free'), default='fixed',
                    help='offline: the base (prescribed: spun up about Y to --spin)')
    ap.add_argument('--spin', type=float, default=10.0, metavar='RAD/S',
                    help='offline, --base prescribed: base_spin_rate (10)')
    ap.add_argument('--step', type=float, default=STEP, metavar='S',
                    help="time_step (s; 0, the default: the run's own, stage 1 at 0.2 ms and "
                         "stage 2 at the mesh's step); 1e-4: 10 a 1 kHz publication in both "
                         'stages')
    args = ap.parse_args()
    if args.step and (not 0 < args.step <= 1e-3
                      or abs(1e-3 / args.step - round(1e-3 / args.step)) > 1e-9):
        ap.error(f'--step {args.step:g}: must divide the 1 ms publication period')
    globals()['STEP'] = args.step
    if args.lockstep_only:
        lockstep(args.live_ribs, args.periods, args.lockstep_rate)
        return
    base = ({} if args.base == 'fixed' else {'base': args.base} if args.base == 'free'
            else {'base': 'prescribed', 'base_spin_rate': args.spin})
    for ribs in args.ribs:
        offline(ribs, args.duration, args.after_lock, base)
    if args.live:
        live(args.live_ribs, args.periods, args.live_windows, args.live_deploying)


if __name__ == '__main__':
    main()
