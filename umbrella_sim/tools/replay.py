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
umbrella_replay LOG: republish a recorded run over ROS 2, or re-simulate and check it.

    umbrella_replay run1                      # republish with the recorded timing
    umbrella_replay run1 --rate 2 --start-offset 0.1 --loop
    umbrella_replay run1 --resimulate         # re-run the physics from the log and compare
    umbrella_replay run1 --info               # what it holds (as `ros2 bag info`), no ROS

Republishing sends the recorded serialized bytes (exactly what was recorded) on the
recorded topics with the recorded QoS, including /clock, spaced by the recorded log times
divided by --rate.  The recorded commands (sleeve_force and its refused/applied records) are
not republished unless --with-commands: they would drive a live simulator.
"""
from __future__ import annotations

import argparse
import math
import posixpath
import sys
import time

import numpy as np

from .arguments import ArgumentParser
from .replay_info import info_text
from ..bag.format import APPLIED_SUFFIX, REFUSED_SUFFIX, TOPICS_RECORD
from ..bag.provenance import build_environment
from ..bag.reader import LogData, LogError, qos_from_yaml, read_log
from ..core.driver import RunDriver
from ..core.forcing import command_force, ForceSchedule
from ..core.integrators import INTEGRATOR_REVISION
from ..core.params import physics_step, recorded_params
from ..core.step_rule import follows_lock
from ..core.umbrella3d.params3d import (umbrella_model, umbrella_parameter_names,
                                        umbrella_values, UmbrellaRibsParams)
from ..ros.messages import (ABSOLUTE_TOPIC_NAMES, COMMAND, joint_state_figures,
                            peak_stress_figures, tip_deflection_figures)
from ..ros.signals import interruptible, raise_if_stopped

#: the node's command topic and its records (each as the node names it, before remapping)
COMMAND_SUFFIXES = tuple(COMMAND.name + s for s in ('', REFUSED_SUFFIX, APPLIED_SUFFIX))
ACK_TIMEOUT_S = 3.5      # > Fast DDS's default 3 s heartbeat period, which prompts the acks


def _is_command(topic: str, log: LogData) -> bool:
    """Tell whether a recorded topic is the node's command or its records (remapped too)."""
    recorded = log.metadata.get(TOPICS_RECORD, {})
    if any(recorded.get(s) == topic for s in COMMAND_SUFFIXES):
        return True
    return any(topic.endswith('/' + s) or topic == s for s in COMMAND_SUFFIXES)


# ------------------------------------------------------------------- resimulate
#: the signals compared, by the node's names (joint names for joint_states), and the Sample's
#: figure each is (the link's joint: alpha2 - alpha1)
SIGNALS = {'leaf_hinge': 'alpha1', 'link_hinge': 'link_angle', 'sleeve_slider': 'sleeve_position',
           'leaf_hinge_rate': 'alpha1_rate', 'sleeve_velocity': 'sleeve_velocity',
           'sleeve_force': 'sleeve_force', 'tip_axial': 'tip_axial',
           'tip_transverse': 'tip_transverse', 'peak_stress_leaf': 'peak_stress_leaf',
           'peak_stress_link': 'peak_stress_link'}


#: the signals of a recording of the umbrella of N ribs: each the largest difference over
#: the joints of joint_states (positions, velocities), the sleeve's force, and every value
#: of the ribs' arrays (msg_docs/topic_ribs.md)
RIB_SIGNALS = ('joint_position', 'joint_velocity', 'sleeve_force', 'rib_tip_deflection',
               'rib_peak_stress')


def recorded_umbrella(params: dict) -> dict:
    """Return the umbrella's values of a recording's parameters ({}: the planar model)."""
    return umbrella_values({k: v for k, v in params.items() if k in umbrella_parameter_names()})


def _reference(s, name: str) -> float:
    """Return a Sample's figure of that name (link_angle: the link's joint, alpha2 - alpha1)."""
    return s.alpha2 - s.alpha1 if name == 'link_angle' else getattr(s, name)


def resimulate(log: LogData) -> dict:
    """
    Re-run the physics of every segment and compare it with the log.

    Re-run the physics of every segment from its parameters and the applied forces;
    returns {"compared": publications, "max_abs_diff": {signal: largest |recorded -
    re-simulated|}, "segments": [...], "problems": [...]}.  A recorded fault must be
    reproduced at the same sim time, a fault the log does not show is a problem.  Streams:
    one publication's messages in memory at a time.
    """
    signals = (RIB_SIGNALS if any(recorded_umbrella(seg.params).get('ribs', 1) > 1
                                  for seg in log.segments()) else SIGNALS)
    diffs = dict.fromkeys(signals, 0.0)
    scales = dict.fromkeys(signals, 0.0)
    out = {'compared': 0, 'max_abs_diff': diffs, 'scale': scales, 'segments': [],
           'problems': []}
    for seg in log.segments():
        res = _resimulate_segment(log, seg, diffs, scales)
        out['compared'] += res['compared']
        out['segments'].append(res)
        out['problems'] += [f'segment {seg.index}: {p}' for p in res['problems']]
    if out['compared'] == 0:
        raise LogError(f'{log.path}: no joint_states messages to compare'
                       + log.truncation_note())
    for group in SCALE_GROUPS if signals is SIGNALS else ():   # one scale a quantity
        common = max(scales[name] for name in group)
        for name in group:
            scales[name] = common
    out['relative_diff'] = {name: relative_difference(diffs[name], scales[name])
                            for name in signals}
    return out


#: signals that measure one quantity: relative to the larger's magnitude (the tip's axial
#: displacement is ~10^-3 of its transverse one; round-off is of the deflection's size)
SCALE_GROUPS = (('tip_axial', 'tip_transverse'), ('peak_stress_leaf', 'peak_stress_link'),
                ('leaf_hinge', 'link_hinge'))


#: --resimulate's default tolerance, relative: the same build on the same machine gives 0;
#: another BLAS kernel (OPENBLAS_CORETYPE) or CPU rounds the model's matrices differently in
#: the last bit, 1e-12 at the first publication, grown to 3.5e-9 of a peak stress over 80 s
#: of stage 2 (measured); any change to the physics or the force history shows far above it
DEFAULT_TOLERANCE = 1e-6


def build_difference(log: LogData) -> str:
    """Say how the recording's integrator, build and floating-point environment differ."""
    recorded = log.metadata.get('umbrella_sim.build', {})
    notes = []
    integrator = recorded.get('integrator', 'an earlier one (unrecorded)')
    if integrator != INTEGRATOR_REVISION:
        notes.append(f'recorded by another integrator ({integrator} there, '
                     f'{INTEGRATOR_REVISION} here): the physics differs, in stage 2 at least')
    here = build_environment()
    differ = [f"{k} {recorded.get(k, 'unrecorded')!r} there, {v!r} here"
              for k, v in here.items() if recorded.get(k) != v]
    if differ:
        notes.append('recorded with another floating-point environment (' + '; '.join(differ)
                     + '): round-off differs from the first step on')
    return '; '.join(notes)


def relative_difference(diff: float, scale: float) -> float:
    """Return diff over its quantity's largest recorded magnitude (0 / inf for a zero one)."""
    if diff == 0.0:
        return 0.0
    return diff / scale if scale > 0.0 else math.inf


def _segment_inputs(log: LogData, seg):
    """
    Return what re-running one segment needs: (run driver, t_last, t_fault).

    The applied forces (``sleeve_force/applied``, each at the step it acts from) become the
    driver's force schedule; t_last is the segment's last publication, t_fault the recorded
    fault (None without one).
    """
    p_all = seg.params
    try:
        params = recorded_params(p_all)
        rate = float(p_all['publish_rate'])
        step = float(p_all['physics_step'])
    except (KeyError, TypeError, ValueError) as exc:
        raise LogError(f'{log.path}: segment {seg.index}: parameters cannot be used '
                       f'({exc})') from None
    # the recorded step itself (a recording made under an earlier step rule replays at its
    # own step), if it is one a run can take: it divides the publication period
    if not (step > 0.0 and abs(physics_step(step, rate) - step) <= 1e-15):
        raise LogError(f'{log.path}: physics step {step} cannot be reproduced: it does not '
                       f'divide the publication period 1/{rate:g} s (a run would take '
                       f"{physics_step(step, rate) if step > 0.0 else 'none'})")
    params = umbrella_model(params, recorded_umbrella(p_all))
    params = params.with_physics_step(step, follows_lock(params))
    # the force history, the recorded fault and the last publication (only the few command
    # and phase records are decoded)
    applied, t_last, t_fault = [], 0.0, None
    for key in ('sleeve_force/applied', 'deployment_phase', 'joint_states'):
        topic = log.find_topic(key, required=False)
        for m in (log.iter_raw([topic]) if topic else ()):
            if not _in_segment(seg, m):
                continue
            t = (m.log_time - seg.offset_ns) * 1e-9
            if key == 'joint_states':
                t_last = max(t_last, t)
                continue
            msg = log.decode(m.topic, m.data)
            if key == 'deployment_phase':
                if msg.data == 'fault' and t_fault is None:
                    t_fault = t
            else:
                applied.append((t, msg.data))
    try:
        schedule = ForceSchedule(step, params.sleeve_force, applied,
                                 check=lambda f: command_force(f, params))
    except ValueError as exc:
        raise LogError(f'{log.path}: segment {seg.index}: sleeve_force/applied: {exc}') from None
    return RunDriver(params, rate, force_profile=schedule), t_last, t_fault


def _in_segment(seg, m) -> bool:
    return m.log_time >= seg.offset_ns and (seg.end_ns is None or m.log_time < seg.end_ns)


def physics_series(log: LogData, seg, until: float | None = None,
                   figures: bool = False) -> dict:
    """
    Re-run one segment and return its signals at every physics step (arrays by name).

    Names: time, alpha1, alpha1_rate, tip_transverse, peak_stress_leaf, peak_stress_link
    (the StepBlock fields); the run stops at the segment's last publication or its fault,
    or at until (sim time) if that comes first.  figures: it goes on to the segment's end,
    and "figures" holds its summary figures of every physics step (as the recorded run's).
    """
    driver, t_last, t_fault = _segment_inputs(log, seg)
    names = ('time', 'alpha1', 'alpha1_rate', 'tip_transverse', 'peak_stress_leaf',
             'peak_stress_link')
    parts = {n: [] for n in names}

    def on_chunk(chunk) -> None:
        for n in names:
            parts[n].append(getattr(chunk.block, n))

    t_end = t_last if t_fault is None else max(t_last, t_fault)
    error = driver.run(t_end if until is None else min(t_end, until), on_chunk=on_chunk)
    out = {n: np.concatenate(v) if v else np.zeros(0) for n, v in parts.items()}
    if figures:     # on to the segment's end (the series stop at until, the figures not)
        if error is None:
            driver.run(t_end)
        out['figures'] = driver.summary.figures()
    return out


def _resimulate_segment(log: LogData, seg, diffs: dict, scales: dict) -> dict:
    """
    Re-run one segment on a run driver and compare each publication with the recorded one.

    The recorded publications are streamed and compared as the re-simulation reaches each
    one.
    """
    driver, t_last, t_fault = _segment_inputs(log, seg)
    ribs = isinstance(driver.params, UmbrellaRibsParams)
    topics = {'joint': log.find_topic('joint_states'),
              'tip': log.find_topic('rib_tip_deflection' if ribs else 'tip_deflection',
                                    required=False),
              'peak': log.find_topic('rib_peak_stress' if ribs else 'peak_stress',
                                     required=False)}
    compare = _ribs_comparison(driver) if ribs else _compare_publication
    by_topic = {t: k for k, t in topics.items() if t}
    sim = driver.sim
    res = {'index': seg.index, 'compared': 0, 'problems': [], 'fault': None,
           'recorded_fault': t_fault}

    def groups():
        group, t_group = {}, None
        for m in log.iter_raw(list(by_topic)):
            if not _in_segment(seg, m):
                continue
            t = (m.log_time - seg.offset_ns) * 1e-9
            if t_group is not None and abs(t - t_group) > 1e-10:
                yield t_group, group
                group = {}
            t_group = t
            group[by_topic[m.topic]] = log.decode(m.topic, m.data)
        if t_group is not None:
            yield t_group, group

    stream = groups()
    pending = [next(stream, None)]

    def compare_until(s) -> None:
        """Compare the recorded publication at s.time; none may be left behind before it."""
        t_now = s.time
        while pending[0] is not None and pending[0][0] < t_now + 1e-9:
            t, group = pending[0]
            if 'joint' in group:
                if abs(t - t_now) > 1e-9:
                    raise LogError(f'{log.path}: recorded publication at t = {t} s is not on '
                                   f'the re-simulated grid (t = {t_now})')
                compare(s, group, diffs, scales)
                res['compared'] += 1
            pending[0] = next(stream, None)

    compare_until(driver.publication())
    # to the log's last publication, or one period past a recorded fault (the
    # re-simulation must fault there too, from the same last good state)
    t_end = t_last
    if t_fault is not None:
        t_end = max(t_end, t_fault + 1.0 / driver.publish_rate)
    error = driver.run(t_end, on_publication=compare_until)
    if error is not None:
        res['fault'] = {'time': sim.time, 'reason': error}
        if pending[0] is not None:
            res['problems'].append(f'the re-simulation faulted at t = {sim.time:.9f} s '
                                   f'({error}) where the log goes on to t = '
                                   f'{pending[0][0]:.9f} s')
    if t_fault is not None:
        if error is None:
            res['problems'].append(f'the log faults at t = {t_fault:.9f} s; '
                                   'the re-simulation does not')
        elif abs(sim.time - t_fault) > 1e-9:
            res['problems'].append(f'the log faults at t = {t_fault:.9f} s, the '
                                   f're-simulation at t = {sim.time:.9f} s')
    return res


def _ribs_comparison(driver):
    """Return the comparison of a publication of the umbrella: its messages re-encoded."""
    from ..ros.ribs_messages import rib_messages

    first = driver.initial
    energy0 = float(first.kinetic_energy + first.strain_energy)
    yield_strength = driver.params.planar.yield_strength

    def compare(s, group: dict, diffs: dict, scales: dict) -> None:
        ref = rib_messages(s, yield_strength, energy0)
        joint, ref_joint = group['joint'], ref['joint_states']
        pairs = {'joint_position': (joint.position, ref_joint.position),
                 'joint_velocity': (joint.velocity, ref_joint.velocity),
                 'sleeve_force': (joint.effort[-1:], ref_joint.effort[-1:])}
        for key, name in (('tip', 'rib_tip_deflection'), ('peak', 'rib_peak_stress')):
            if key in group:
                pairs[name] = (group[key].data, ref[name].data)
        for name, (rec, res) in pairs.items():
            rec, res = np.asarray(rec, dtype=float), np.asarray(res, dtype=float)
            d = float(np.max(np.abs(rec - res))) if rec.shape == res.shape else math.inf
            diffs[name] = max(diffs[name], d if d == d else math.inf)    # NaN counts as inf
            scales[name] = max(scales[name], float(np.max(np.abs(rec))))
    return compare


def _compare_publication(s, group: dict, diffs: dict, scales: dict) -> None:
    rec = joint_state_figures(group['joint'])
    if 'tip' in group:
        rec.update(tip_deflection_figures(group['tip']))
    if 'peak' in group:
        rec.update(peak_stress_figures(group['peak']))
    rec = {signal: rec[name] for signal, name in SIGNALS.items() if name in rec}
    ref = {signal: _reference(s, name) for signal, name in SIGNALS.items() if signal in rec}
    for name in rec:
        d = abs(rec[name] - ref[name])
        diffs[name] = max(diffs[name], d if d == d else float('inf'))    # NaN counts as inf
        scales[name] = max(scales[name], abs(rec[name]))


# -------------------------------------------------------------------- republish
def moved_topics(log: LogData, topics: list[str], namespace: str) -> tuple[dict, str]:
    """
    Return where each recorded topic is republished, and a note saying what moved.

    The node's topics are relative to its namespace (``/a1/joint_states``), and a log
    holds them resolved.  ``--ros-args -r __ns:=/replay`` moves those under the recorded
    node's namespace (that of its ``joint_states``) to ``/replay``, as it would move the node
    itself; the node's absolute topics (``/diagnostics``) stay.  Without it nothing moves.
    """
    names = {t: t for t in topics}
    if namespace == '/':
        return names, ''

    recorded = posixpath.dirname(log.find_topic('joint_states'))
    under = recorded.rstrip('/') + '/'
    for t in topics:
        if t.startswith(under) and t not in ABSOLUTE_TOPIC_NAMES:
            names[t] = namespace.rstrip('/') + '/' + t[len(under):]
    return names, f' (topics under {recorded} moved to {namespace})'


class RosArgumentsError(ValueError):
    """The ROS arguments (after --ros-args) that rclpy refused, said in one line."""


def _bus_broadcaster(node, topics: list[str]) -> tuple[dict, str]:
    """
    Return {bus_state topic: its /tf broadcaster} of the topics replayed, and what to say.

    A moving bus's bus_state is broadcast again on /tf, world -> umbrella_base, as the node
    did (bus_tf.py), where tf2_msgs is installed; else nothing, said once.
    """
    from ..ros.bus_tf import BusTransformBroadcaster, NO_TF, tf_message_type
    from ..ros.ribs_messages import BUS_TOPIC

    states = [t for t in topics if t.rsplit('/', 1)[-1] == BUS_TOPIC.name]
    if not states:
        return {}, ''
    message_type = tf_message_type()
    if message_type is None:
        return {}, f'; {NO_TF}'
    broadcaster = BusTransformBroadcaster(node, message_type=message_type)
    return {t: broadcaster for t in states}, '; the bus on /tf (world -> umbrella_base)'


def republish(log: LogData, rate: float, start_offset: float, loop: bool,
              with_commands: bool, topics: list[str] | None, ros_args: list[str],
              wait_for_subscribers: float = 0.0) -> int:
    import rclpy
    from rclpy.duration import Duration
    from rclpy.exceptions import InvalidParameterTypeException
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    from ..ros.parameters import wrong_type_text

    chosen = [t for t in log.topics() if (with_commands or not _is_command(t, log))
              and (not topics or t in topics)]
    if topics:
        missing = sorted(set(topics) - set(log.channels))
        if missing:
            raise LogError(f"{log.path}: topics not in the log: {', '.join(missing)}")
    total = sum(log.count(t) for t in chosen)
    if total == 0:
        raise LogError(f'{log.path}: nothing to replay{log.truncation_note()}')
    first = next(log.iter_raw(chosen))
    t0 = first.log_time + int(round(start_offset * 1e9))
    if log.time_range[1] is not None and t0 > log.time_range[1]:
        raise LogError(f'{log.path}: --start-offset {start_offset} s is past the end of the log')
    # SIGINT/SIGTERM raise KeyboardInterrupt here (stop_signals.interruptible), with the context
    # still valid for the acknowledgements below; rclpy's own handlers would shut it down
    # first, and waiting for them then raised RCLError
    try:
        rclpy.init(args=['umbrella_replay', '--ros-args', *ros_args],
                   signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:    # RCLError, UnknownROSArgsError: the arguments are wrong
        reason = ' '.join(str(exc).split())
        if type(exc).__name__ == 'UnknownROSArgsError':
            reason = f'unknown ROS arguments {reason}'
        raise RosArgumentsError(f'invalid ROS arguments: {reason}') from None
    try:
        node = rclpy.create_node('umbrella_replay')
    except InvalidParameterTypeException as exc:      # -p use_sim_time:=abc
        rclpy.try_shutdown()
        raise RosArgumentsError(wrong_type_text(None, exc)) from None
    names, moved = moved_topics(log, chosen, node.get_namespace())
    pubs = {t: node.create_publisher(log.msg_type(t), names[t],
                                     qos_from_yaml(log.channels[t][1])) for t in chosen}
    bus, tf = _bus_broadcaster(node, chosen)
    print(f'replaying up to {total} messages on {len(pubs)} topics from {log.path} at '
          f"{rate:g}x{f' ({log.cut_short})' if log.cut_short else ''}{moved}{tf}", flush=True)
    sent = read = skipped = 0       # skipped: payloads that do not decode
    first_skipped = ''
    try:        # a stop while waiting for subscribers ends like one while replaying
        time.sleep(0.5)   # let subscribers discover the publishers
        if wait_for_subscribers > 0:
            deadline = time.monotonic() + wait_for_subscribers
            while any(p.get_subscription_count() == 0 for p in pubs.values()):
                if time.monotonic() > deadline:
                    idle = sorted(names[t] for t, p in pubs.items()
                                  if p.get_subscription_count() == 0)
                    print(f'no subscriber after {wait_for_subscribers:g} s on: '
                          f"{', '.join(idle)}; replaying anyway", flush=True)
                    break
                time.sleep(0.05)
        while True:
            wall0 = time.monotonic()
            for m in log.iter_raw(chosen):      # streamed: bounded memory for any log
                if m.log_time < t0:
                    continue
                target = wall0 + (m.log_time - t0) * 1e-9 / rate
                delay = target - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                try:        # an undecodable payload is skipped and named, as --resimulate
                    msg = log.decode(m.topic, m.data, index=read, log_time=m.log_time)
                except LogError as exc:
                    # (a stop signal inside the decoding comes back as rclpy's conversion
                    # error: an interrupt, not a bad payload, or a --loop never ends)
                    raise_if_stopped()
                    if not skipped:
                        first_skipped = str(exc)
                        print(f'umbrella_replay: skipped: {exc}', file=sys.stderr, flush=True)
                    skipped += 1
                    continue
                finally:
                    read += 1
                pubs[m.topic].publish(m.data)
                sent += 1
                if m.topic in bus:
                    bus[m.topic].publish(bus[m.topic].replayed(msg))
            if not loop:
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # reliable subscribers get every sample (a lost one is resent on their NACK) before the
        # publishers go away; Fast DDS asks for acknowledgements with its periodic heartbeat,
        # every 3 s by default, hence the bound
        unacked = [t for t, pub in pubs.items()
                   if not pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S))]
        if unacked:
            print(f'not acknowledged by every subscriber within {ACK_TIMEOUT_S:g} s: '
                  f"{', '.join(unacked)}", flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    print(f'replayed {sent} messages', flush=True)
    if skipped:
        raise LogError(f'{skipped} message(s) skipped: their payload does not decode (the '
                       f'first: {first_skipped})')
    return 0


@interruptible('umbrella_replay', 'nothing was written')
def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args = []
    if '--ros-args' in argv:
        i = argv.index('--ros-args')
        argv, ros_args = argv[:i], argv[i + 1:]
    ap = ArgumentParser(prog='umbrella_replay', description=__doc__,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('log', help='bag directory or .mcap file')
    ap.add_argument('--rate', type=float, default=None, help='playback rate factor (1)')
    ap.add_argument('--start-offset', type=float, default=0.0,
                    help='skip the first S seconds of the log')
    ap.add_argument('--loop', action='store_true', help='replay until interrupted')
    ap.add_argument('--topics', nargs='+', help='only these topics')
    ap.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='SECONDS',
                    help='before replaying, wait up to SECONDS until every replayed topic '
                         'has a subscriber')
    ap.add_argument('--with-commands', action='store_true',
                    help='also republish the recorded sleeve_force commands')
    ap.add_argument('--resimulate', action='store_true',
                    help='re-run the physics from the log and compare, no ROS traffic')
    ap.add_argument('--info', action='store_true',
                    help='print what the recording holds (topics, counts, QoS, the run) '
                         'and exit, no ROS traffic')
    ap.add_argument('--tolerance', type=float, default=None,
                    help='largest accepted difference for --resimulate, relative to the '
                         "largest recorded magnitude of the signal's quantity (>= 0; "
                         f'{DEFAULT_TOLERANCE:g})')
    args = ap.parse_args(argv)
    # argument values: an argparse usage error (exit 2) before any file is read
    if args.info and (args.resimulate or args.tolerance is not None):
        ap.error('--info prints what the recording holds: it takes no --resimulate or '
                 '--tolerance')
    if args.resimulate or args.info:     # what only republishing takes: refused, not ignored
        given = [flag for flag, value in (
            ('--rate', args.rate is not None), ('--start-offset', args.start_offset != 0.0),
            ('--loop', args.loop), ('--topics', args.topics),
            ('--wait-for-subscribers', args.wait_for_subscribers != 0.0),
            ('--with-commands', args.with_commands), ('--ros-args', ros_args)) if value]
        if given:
            ap.error(f"{', '.join(given)}: options of republishing; "
                     + ('--info reads the log only' if args.info else
                        '--resimulate re-runs the whole log without ROS traffic'))
    elif args.tolerance is not None:
        ap.error('--tolerance: an option of --resimulate (republishing compares nothing)')
    args.rate = 1.0 if args.rate is None else args.rate
    args.tolerance = DEFAULT_TOLERANCE if args.tolerance is None else args.tolerance
    if not (math.isfinite(args.tolerance) and args.tolerance >= 0):
        ap.error(f'--tolerance {args.tolerance}: must be a finite number >= 0')
    if not (math.isfinite(args.rate) and 1e-6 <= args.rate <= 1e6):
        ap.error(f'--rate {args.rate}: must be a number in [1e-6, 1e6]')
    if not (math.isfinite(args.start_offset) and 0 <= args.start_offset <= 1e9):
        ap.error(f'--start-offset {args.start_offset}: must be a number in [0, 1e9] s')
    if not (math.isfinite(args.wait_for_subscribers) and args.wait_for_subscribers >= 0):
        ap.error(f'--wait-for-subscribers {args.wait_for_subscribers}: must be >= 0')
    try:
        log = read_log(args.log)
        if args.info:
            print(info_text(log))
            return 0
        if args.resimulate:
            res = resimulate(log)
            worst = max(res['relative_diff'].values())
            notes = [n for n in (log.cut_short,
                                 f'recording ended early: {log.ended_early}'
                                 if log.ended_early else '',
                                 f"{len(res['segments'])} segments (resets)"
                                 if len(res['segments']) > 1 else '') if n]
            print(f"resimulated {res['compared']} publications of {log.path}"
                  + (f" ({'; '.join(notes)})" if notes else ''))
            for seg in res['segments']:
                if seg['fault']:
                    print(f"segment {seg['index']}: fault reproduced at t = "
                          f"{seg['fault']['time']:.9f} s: {seg['fault']['reason']}"
                          if seg['recorded_fault'] is not None else
                          f"segment {seg['index']}: re-simulation faulted at t = "
                          f"{seg['fault']['time']:.9f} s: {seg['fault']['reason']}")
            print(f"{'signal':<20} {'max |recorded - resimulated|':>30} "
                  f"{'relative to max |recorded|':>28}")
            for name, d in res['max_abs_diff'].items():
                print(f"{name:<20} {d:>30.3e} {res['relative_diff'][name]:>28.3e}")
            for problem in res['problems']:
                print(f'problem: {problem}')
            ok = worst <= args.tolerance and not res['problems']
            note = build_difference(log)
            print(f"{'PASS' if ok else 'FAIL'}: largest relative difference {worst:.3e} "
                  f'(tolerance {args.tolerance:g})'
                  + (f"; {len(res['problems'])} problem(s)" if res['problems'] else ''))
            if note and worst > 0.0:
                print(f'note: {note}')
            return 0 if ok else 1
        return republish(log, args.rate, args.start_offset, args.loop, args.with_commands,
                         args.topics, ros_args, args.wait_for_subscribers)
    except (LogError, RosArgumentsError) as exc:
        raise_if_stopped()           # (a stop signal inside a decoding: an interrupt)
        print(f'umbrella_replay: error: {exc}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
