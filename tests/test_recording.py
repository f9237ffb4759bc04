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

"""MCAP recording, replay and comparison (real node processes, real DDS)."""
from collections import Counter, defaultdict
import json
import math
import os
from pathlib import Path
import re
import signal
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String

from tests.ros_helpers import (keep_every_message, main_thread_sleeps, NodeProcess, poll,
                               Probe, ros_env, signal_and_collect, stamp)
from umbrella_sim.bag.reader import LogError, read_log
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.step_rule import physics_step_of
from umbrella_sim.ros.messages import CLOCK_READER_QOS, COMMAND_ECHO_QOS, LATCHED

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_cli(*args, timeout=300):
    return subprocess.run([sys.executable, '-m', *args], capture_output=True, text=True,
                          cwd=ROOT, env=ros_env(), timeout=timeout)


def mcap_file(bag: Path) -> Path:
    return bag / (bag.name + '_0.mcap')


@pytest.fixture(scope='module')
def live_bag(tmp_path_factory):
    """Record a live run: V0 = 0, accepted and refused commands, stopped with SIGTERM."""
    bag = tmp_path_factory.mktemp('live') / 'live_run'
    probe = Probe('recorder_probe')
    try:
        probe.subscribe('/deployment_phase', String, LATCHED)
        probe.subscribe('/diagnostics', DiagnosticArray)
        # published live as recorded: each value as it starts acting, each refused command
        probe.subscribe('/sleeve_force/applied', Float64, COMMAND_ECHO_QOS)
        probe.subscribe('/sleeve_force/refused', Float64, COMMAND_ECHO_QOS)
        with NodeProcess('-p', 'v0:=0.0', '-p', f'record_path:={bag}') as node:
            node.wait_for_log('recording to')
            pub = probe.publisher('/sleeve_force', Float64)
            probe.wait_for_subscribers(pub)
            for value in (float('nan'), -2.0):
                pub.publish(Float64(data=value))
            pub.publish(Float64(data=15.0))
            # (one writer, reliable: the node took the two refused ones before it)
            probe.wait_for('/sleeve_force/applied', lambda m: m.data == 15.0, timeout=30)
            pub.publish(Float64(data=25.0))             # applied in a later period
            probe.wait_for('/deployment_phase', lambda m: m.data == 'locked', timeout=30)
            probe.wait_for('/sleeve_force/applied', lambda m: m.data == 25.0, timeout=30)
            probe.wait_for_count('/diagnostics', 1)     # published, so recorded
            assert node.stop(signal.SIGTERM) == 0
            log = node.output()
        assert [m.data for m in probe.messages('/sleeve_force/applied')] == [15.0, 25.0]
        refused = [m.data for m in probe.messages('/sleeve_force/refused')]
        assert len(refused) == 2 and math.isnan(refused[0]) and refused[1] == -2.0
    finally:
        probe.close()
    assert 'recording finalised' in log
    assert 'sleeve force 15 N applied from t = ' in log      # the first one at INFO
    return bag


@pytest.mark.ros
@pytest.mark.slow
def test_independent_readers_decode_every_message(live_bag):
    meta = read_log(str(live_bag)).metadata
    counts = json.loads(meta['umbrella_sim.counts']['recorded'])
    # 1) mcap + mcap-ros2-support, through the summary and indexes
    per_topic = Counter()
    times = defaultdict(list)
    with open(mcap_file(live_bag), 'rb') as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary.statistics.message_count == sum(counts.values())
        assert all(ch.message_encoding == 'cdr' for ch in summary.channels.values())
        assert all(summary.schemas[ch.schema_id].encoding == 'ros2msg'
                   for ch in summary.channels.values())
        assert all('offered_qos_profiles' in ch.metadata for ch in summary.channels.values())
        assert summary.chunk_indexes and all(ci.compression == 'zstd'
                                             for ci in summary.chunk_indexes)
        for schema, channel, message, decoded in reader.iter_decoded_messages(
                log_time_order=False):
            per_topic[channel.topic] += 1
            times[channel.topic].append(message.log_time)
            assert decoded is not None
    assert dict(per_topic) == {k: v for k, v in counts.items() if v}
    for topic, ts in times.items():
        assert all(b >= a for a, b in zip(ts, ts[1:])), f'{topic} log times not monotonic'
    # 2) rosbags, on the bag directory and on the .mcap alone (it rejects inexact CDR sizes)
    store = get_typestore(Stores.ROS2_JAZZY)
    for target in (live_bag, mcap_file(live_bag)):
        with AnyReader([Path(target)], default_typestore=store) as rd:
            seen = Counter()
            for conn, _, raw in rd.messages():
                rd.deserialize(raw, conn.msgtype)
                seen[conn.topic] += 1
        assert dict(seen) == dict(per_topic)


@pytest.mark.ros
def test_nothing_lost_published_and_received_equal_recorded(live_bag):
    log = read_log(str(live_bag))
    c = log.metadata['umbrella_sim.counts']
    published = json.loads(c['published'])
    recorded = json.loads(c['recorded'])
    for topic, n in published.items():
        assert recorded[topic] == n == log.count(topic), topic
    assert int(c['commands_accepted']) == log.count('/sleeve_force') == 2
    assert int(c['commands_refused']) == log.count('/sleeve_force/refused') == 2
    assert log.count('/sleeve_force/applied') == 2
    assert log.count('/diagnostics') >= 1
    assert log.metadata['umbrella_sim.events']['locked'] == 'true'


@pytest.mark.ros
def test_log_is_self_describing(live_bag):
    log = read_log(str(live_bag))
    params = log.parameters()
    assert params['v0'] == 0.0 and params['model'] == 'flexible'
    assert params['physics_step'] == pytest.approx(physics_step_of(UmbrellaParams()))
    build = log.metadata['umbrella_sim.build']
    assert build['package_version'] and build['git_revision']
    mesh = log.metadata['umbrella_sim.mesh']
    assert json.loads(mesh['coordinates'])[0] == 'alpha1'
    bag_yaml = (live_bag / 'metadata.yaml').read_text()
    # rosbag2 Jazzy's version 9: QoS policies by name, RIHS01 type hashes (test_bag_format)
    assert 'version: 9' in bag_yaml and 'storage_identifier: mcap' in bag_yaml
    assert 'history: keep_last' in bag_yaml and 'type_description_hash: RIHS01_' in bag_yaml
    assert 'serialized_metadata' in log.metadata['rosbag2']


@pytest.mark.ros
def test_resimulate_live_log_with_force_profile(live_bag):
    r = run_cli('umbrella_sim.tools.replay', str(live_bag), '--resimulate')
    assert r.returncode == 0, r.stdout + r.stderr
    assert 'PASS' in r.stdout and 'leaf_hinge' in r.stdout


def test_resimulation_under_another_blas_kernel_passes_and_says_why_it_differs(tmp_path):
    """
    Recorded with OPENBLAS_CORETYPE=Haswell, re-simulated with OpenBLAS's own pick.

    The model's matrices round differently in the last bit: the differences are round-off
    (a user's recording failed at an absolute 1e-9 on 0.84 Pa of a 240 MPa peak stress).
    """
    bag = tmp_path / 'haswell'
    env = dict(os.environ, OPENBLAS_CORETYPE='Haswell')
    assert subprocess.run([sys.executable, '-m', 'umbrella_sim', 'simulate', '--duration',
                           '1.0', '--mcap', str(bag)], env=env, capture_output=True,
                          timeout=300).returncode == 0
    assert read_log(str(bag)).metadata['umbrella_sim.build']['openblas_coretype'] == 'Haswell'
    env.pop('OPENBLAS_CORETYPE')
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.tools.replay', str(bag),
                        '--resimulate'], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and 'PASS' in r.stdout, r.stdout + r.stderr
    worst = float(re.search(r'largest relative difference (\S+)', r.stdout).group(1))
    assert worst < 1e-9
    if worst > 0.0:       # (on a CPU whose own pick is Haswell the two agree bit for bit)
        assert "openblas_coretype 'Haswell' there, 'auto' here" in r.stdout, r.stdout


@pytest.mark.ros
def test_a_remapped_node_s_recording_serves_every_tool(tmp_path):
    """
    -r joint_states:=js -r sleeve_force:=/cmd in a namespace: the tools find the topics.

    Replay, compare and the test API's summary looked for topics ending in joint_states
    and sleeve_force/applied; the recording names its topics' remappings now.
    """
    from umbrella_sim.testing import summary_from_recording

    bag = tmp_path / 'remapped'
    probe = Probe('remap_probe')
    try:
        probe.subscribe('/r1/deployment_phase', String, LATCHED)
        probe.subscribe('/r1/js', JointState)
        with NodeProcess('-r', '__ns:=/r1', '-r', 'joint_states:=js', '-r',
                         'sleeve_force:=/cmd', '-p', 'v0:=0.0',
                         '-p', f'record_path:={bag}') as node:
            node.wait_for_log('recording to')
            pub = probe.publisher('/cmd', Float64)
            probe.wait_for_subscribers(pub)
            # (the push after the start, so that its instant, found on the remapped applied
            # topic, is not the 0 of a push acting from the first publication)
            probe.wait_for('/r1/js', lambda m: stamp(m) > 0.01, what='a state past 0.01 s')
            pub.publish(Float64(data=20.0))
            probe.wait_for('/r1/deployment_phase', lambda m: m.data == 'locked', timeout=30)
            lock = float(node.wait_for_log(r'locked at t = ([0-9.]+) s').group(1))
            # published past the summary's window below (0.1 s after the lock): recorded
            probe.wait_for('/r1/js', lambda m: stamp(m) > lock + 0.1,
                           what=f'a state past {lock + 0.1:.6f} s')
            assert node.stop(signal.SIGTERM) == 0
    finally:
        probe.close()
    log = read_log(str(bag))
    assert {'/r1/js', '/cmd/applied'} <= set(log.topics())
    # the remapped command is still a command: not republished unless --with-commands
    from umbrella_sim.tools.replay import _is_command
    assert sorted(t for t in log.topics() if _is_command(t, log)) == [
        '/cmd', '/cmd/applied', '/cmd/refused']
    summary = summary_from_recording(str(bag), after_lock=0.1)
    assert summary.first_push_time is not None and summary.first_push_time > 0
    assert summary.deploy_time == pytest.approx(summary.lock_time - summary.first_push_time)
    r = run_cli('umbrella_sim.tools.replay', str(bag), '--resimulate')
    assert r.returncode == 0 and 'PASS' in r.stdout, r.stdout + r.stderr
    r = run_cli('umbrella_sim.tools.compare', str(bag), str(bag), '--out', str(tmp_path / 'cmp'),
                '--no-plots')
    assert r.returncode == 0, r.stderr
    diffs = json.loads((tmp_path / 'cmp' / 'compare.json').read_text())['runs'][1]
    assert diffs['differences']['alpha1']['max'] == 0.0


@pytest.mark.ros
def test_offline_recording_has_the_live_layout(live_bag, tmp_path):
    bag = tmp_path / 'offline_run'
    r = run_cli('umbrella_sim', 'simulate', '--v0', '0', '--force', '10', '--duration', '0.6',
                '--mcap', str(bag))
    assert r.returncode == 0, r.stderr
    live, off = read_log(str(live_bag)), read_log(str(bag))
    assert {t: ty for t, (ty, _) in live.channels.items()} == \
        {t: ty for t, (ty, _) in off.channels.items()}
    assert set(live.metadata) == set(off.metadata)
    again = run_cli('umbrella_sim', 'simulate', '--duration', '0.1', '--mcap', str(bag))
    assert again.returncode == 2 and 'not overwriting' in again.stderr


def recovered_states(bag: Path) -> int:
    """Return the joint states in the complete chunks of a recording so far (0: none yet)."""
    try:
        return read_log(str(bag)).count('/joint_states')
    except LogError:
        return 0


@pytest.mark.ros
def test_sigkill_leaves_readable_chunks(tmp_path):
    bag = tmp_path / 'killed'
    with NodeProcess('-p', 'v0:=-0.2', '-p', 'real_time_factor:=0.0',
                     '-p', f'record_path:={bag}') as node:
        node.wait_for_log('recording to')
        # several complete chunks on disk: what the writer had written is what a kill leaves
        poll(lambda: recovered_states(bag) > 100, 60,
             lambda: f'the recording holds {recovered_states(bag)} joint states in complete '
                     f'chunks after 60 s (awaited > 100)')
        node.stop(signal.SIGKILL)
    assert not (bag / 'metadata.yaml').exists()        # never finalised
    with open(mcap_file(bag), 'rb') as fh:
        with pytest.raises(Exception):
            make_reader(fh).get_summary().statistics  # no summary section
    # read how: scan records from the start, keep complete chunks (umbrella_sim.bag.reader)
    log = read_log(str(bag))
    assert log.truncated
    n = log.count('/joint_states')
    assert n > 100
    t = [tm for tm, _ in log.decoded('/joint_states')]
    assert np.allclose(np.diff(t), 0.01)               # no gap inside what was recovered
    assert 'umbrella_sim.parameters' in log.metadata   # written at start, outside chunks
    r = run_cli('umbrella_sim.tools.replay', str(bag), '--resimulate')
    assert r.returncode == 0 and 'truncated log' in r.stdout, r.stdout + r.stderr
    # a killed Fast DDS participant leaves its shared-memory segments behind
    fastdds = os.path.join(os.path.dirname(sys.executable), 'fastdds')
    if os.path.exists(fastdds):
        subprocess.run([fastdds, 'shm', 'clean'], capture_output=True, timeout=60)


@pytest.mark.ros
@pytest.mark.slow
def test_replay_republishes_with_recorded_spacing(tmp_path):
    """
    Replay at rates 0.5 and 1: every recorded tick, in order, paced by the recording.

    Paced: the ticks arrive over at least the recorded span / rate, less 0.5 s for the first
    tick's way in on a loaded machine (a replay that ignored the rate or the spacing sent
    them in a burst).  How evenly a machine keeps the 20 ms / 10 ms spacing is its speed
    and load, a benchmark figure: a replay that fell behind catches up in a burst (at rate
    2, once, under a load average of 7).
    """
    bag = tmp_path / 'replay_src'
    assert run_cli('umbrella_sim', 'simulate', '--v0', '-0.5', '--duration', '1.0',
                   '--mcap', str(bag)).returncode == 0
    recorded = read_log(str(bag)).count('/clock')
    probe = Probe('replay_probe')
    try:
        probe.subscribe('/clock', Clock, CLOCK_READER_QOS)
        probe.subscribe('/joint_states', JointState)
        for rate in (0.5, 1.0):
            probe.received['/clock'] = []
            r = subprocess.run([sys.executable, '-m', 'umbrella_sim.tools.replay', str(bag),
                                '--rate', str(rate), '--topics', '/clock', '/joint_states',
                                '--wait-for-subscribers', '20'], capture_output=True,
                               text=True, env=ros_env(), timeout=60)
            assert r.returncode == 0, r.stderr
            assert 'not acknowledged' not in r.stdout
            # nothing beyond what was recorded was sent (the replay has ended)
            sent = int(re.search(r'replayed (\d+) messages', r.stdout).group(1))
            assert sent == recorded + read_log(str(bag)).count('/joint_states'), r.stdout
            probe.wait_for_count('/clock', recorded, timeout=30)
            arrivals = probe.timed('/clock')
            assert len(arrivals) == recorded
            stamps = [m.clock.sec + 1e-9 * m.clock.nanosec for _, m in arrivals]
            assert stamps == sorted(stamps)
            span = arrivals[-1][0] - arrivals[0][0]
            assert span >= (stamps[-1] - stamps[0]) / rate - 0.5, (rate, span)
    finally:
        probe.close()


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGINT])
@pytest.mark.ros
def test_replay_stopped_by_a_signal_delivers_what_it_sent_and_exits_0(tmp_path, signum):
    """
    A looping replay stopped by SIGTERM or SIGINT: exit 0, no traceback, its count printed.

    It still waits for its reliable subscriber to acknowledge what was sent, so the ROS
    context must outlive the signal (rclpy's own handlers shut it down at once, and the wait
    then raised RCLError).
    """
    bag = tmp_path / 'loop_src'
    assert run_cli('umbrella_sim', 'simulate', '--v0', '-0.5', '--duration', '0.3',
                   '--mcap', str(bag)).returncode == 0
    probe = Probe('replay_stop_probe')
    try:
        keep_every_message(probe, keys=('joint_states',))     # each one is counted
        proc = subprocess.Popen([sys.executable, '-m', 'umbrella_sim.tools.replay', str(bag),
                                 '--loop', '--topics', '/joint_states',
                                 '--wait-for-subscribers', '20'],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=ros_env())
        out, err = signal_and_collect(
            proc, signum, lambda: probe.wait_for_count('/joint_states', 20, timeout=30))
        assert proc.returncode == 0, err
        assert 'Traceback' not in out + err, err
        sent = int(re.search(r'replayed (\d+) messages', out).group(1))
        probe.wait_for_count('/joint_states', sent, timeout=30)  # acknowledged = delivered
    finally:
        probe.close()


@pytest.mark.ros
def test_a_stop_signal_inside_a_decoding_stops_a_looping_replay(tmp_path, monkeypatch, capsys):
    """
    A stop signal that lands inside rclpy's message conversion comes back as its own error.

    The replay took it for an undecodable payload, skipped it and looped on for ever (a
    fresh clone's suite: the signal test's replay outlived its 90 s).  Made here: the
    decoding of the 5th message receives SIGTERM and fails as rclpy's conversion does.
    """
    from umbrella_sim.bag.reader import LogData, LogError
    from umbrella_sim.ros import signals
    from umbrella_sim.tools import replay

    bag = tmp_path / 'loop_src'
    assert run_cli('umbrella_sim', 'simulate', '--v0', '-0.5', '--duration', '0.02',
                   '--mcap', str(bag)).returncode == 0
    decode, calls = LogData.decode, [0]

    def interrupted(self, topic, data, *args, **kwargs):
        calls[0] += 1
        if calls[0] == 5:
            signals.received.append(signal.SIGTERM)       # (what _interrupt notes)
            raise LogError('Unable to convert function return value to a Python type!')
        return decode(self, topic, data, *args, **kwargs)
    monkeypatch.setattr(LogData, 'decode', interrupted)
    monkeypatch.setenv('ROS_DOMAIN_ID', str(ros_env()['ROS_DOMAIN_ID']))
    code = replay.main([str(bag), '--loop', '--rate', '1000', '--topics', '/joint_states'])
    out = capsys.readouterr()
    assert code == 0 and 'skipped' not in out.err, out
    assert 'replayed 4 messages' in out.out, out


@pytest.mark.ros
def test_replay_stopped_while_waiting_for_subscribers_exits_0(tmp_path):
    """SIGTERM before the first message (no subscriber yet): as a stop while replaying."""
    bag = tmp_path / 'wait_src'
    assert run_cli('umbrella_sim', 'simulate', '--v0', '-0.5', '--duration', '0.05',
                   '--mcap', str(bag)).returncode == 0
    proc = subprocess.Popen([sys.executable, '-m', 'umbrella_sim.tools.replay', str(bag),
                             '--topics', '/joint_states', '--wait-for-subscribers', '120'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=ros_env())

    def in_the_wait():
        assert proc.stdout.readline().startswith('replaying up to')
        # past its discovery pause (one sleep of its main thread), in the wait itself, which
        # sleeps 50 ms a turn: three sleeps of the main thread since the line
        before = main_thread_sleeps(proc.pid)
        poll(lambda: main_thread_sleeps(proc.pid) >= before + 3, 60,
             lambda: f"the replay's main thread slept {main_thread_sleeps(proc.pid) - before} "
                     "time(s) in 60 s since 'replaying up to' (awaited 3: in the wait)")

    out, err = signal_and_collect(proc, signal.SIGTERM, in_the_wait)
    assert proc.returncode == 0, err
    assert 'replayed 0 messages' in out and 'Traceback' not in err, (out, err)


@pytest.mark.ros
@pytest.mark.slow
def test_replay_under_a_namespace_moves_the_node_topics(tmp_path, live_bag):
    """``--ros-args -r __ns:=/replay`` moves the recorded node's topics, as it moves a node."""
    from umbrella_sim.tools.replay import moved_topics

    log = read_log(str(live_bag))
    names, note = moved_topics(log, log.topics(), '/replay')
    assert names['/joint_states'] == '/replay/joint_states'
    assert names['/sleeve_force/applied'] == '/replay/sleeve_force/applied'
    assert names['/diagnostics'] == '/diagnostics'         # absolute, as the node's own
    assert moved_topics(log, log.topics(), '/')[0] == {t: t for t in log.topics()}
    assert 'moved to /replay' in note
    # over DDS: the subscriber under /replay gets every recorded state
    probe = Probe('replay_ns_probe')
    try:
        keep_every_message(probe, 'replay', ('joint_states',))  # each one is counted
        r = subprocess.run([sys.executable, '-m', 'umbrella_sim.tools.replay', str(live_bag),
                            '--topics', '/joint_states',
                            '--wait-for-subscribers', '20', '--ros-args', '-r',
                            '__ns:=/replay'], capture_output=True, text=True, env=ros_env(),
                           timeout=120)
        assert r.returncode == 0 and 'no subscriber' not in r.stdout, r.stdout + r.stderr
        probe.wait_for_count('/replay/joint_states', log.count('/joint_states'), timeout=10)
    finally:
        probe.close()


@pytest.mark.ros
@pytest.mark.slow
def test_a_marker_magnification_set_at_runtime_is_undone_in_the_compared_shapes(
        antenna_factory, tmp_path):
    """
    marker_magnification applies at once: the markers after the set are drawn at 200.

    The recording says from when (umbrella_sim.marker_magnification.K), and the shapes
    umbrella_compare draws undo each marker's own magnification: they took the start's 1,
    and drew the tip 9 m off its 46 mm.
    """
    from umbrella_sim.tools.runs import load_run

    bag = tmp_path / 'mag'
    antenna = antenna_factory(record_path=str(bag))
    antenna.wait_for_sim_time(0.3, timeout=60)
    antenna.set_parameters(marker_magnification=200.0)
    antenna.wait_for_sim_time(antenna.sim_time() + 0.3, timeout=60)
    assert antenna.stop() == 0
    run = load_run(str(bag))
    for tm, _, _ in run.shapes:     # the tip's transverse deflection, as drawn at 1
        t, leaf, _ = run.shape(tm, 1.0)
        a1 = np.interp(t, run.t, run.alpha1)
        drawn = float(leaf[-1] @ [-math.sin(a1), math.cos(a1)])
        assert drawn == pytest.approx(np.interp(t, run.tip_t, run.tip_v), abs=1e-12), t
    (since, value), = run.magnifications
    assert value == 200.0 and 0.3 <= since < run.shapes[-1][0]


@pytest.mark.slow
def test_compare_known_runs(tmp_path):
    a, b = tmp_path / 'v05', tmp_path / 'v10'
    for bag, v0 in ((a, '-0.5'), (b, '-1.0')):
        assert run_cli('umbrella_sim', 'simulate', '--v0', v0, '--duration', '0.2',
                       '--mcap', str(bag)).returncode == 0
    out = tmp_path / 'cmp'
    r = run_cli('umbrella_sim.tools.compare', str(a), str(b), '--out', str(out), '--thesis')
    assert r.returncode == 0, r.stderr
    result = json.loads((out / 'compare.json').read_text())
    ta, tb = read_log(str(a)).metadata, read_log(str(b)).metadata
    expected = float(tb['umbrella_sim.events']['lock_time']) - \
        float(ta['umbrella_sim.events']['lock_time'])
    assert result['runs'][1]['deploy_time_difference'] == pytest.approx(expected, abs=1e-12)
    # Table 6.1 (deformable FEA): 0.04525 s and 0.09040 s, each within 0.5 %
    assert expected == pytest.approx(0.04525 - 0.09040, abs=0.005 * (0.04525 + 0.09040))
    assert result['runs'][0]['thesis']['deploy_time_deformable_fea'] == 0.09040
    assert '0.0904' in r.stdout and 'thesis' in r.stdout
    for name in ('alpha1.png', 'tip_deflection.png', 'stress.png', 'shapes.png'):
        png = out / name
        assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b'\x89PNG'


@pytest.mark.slow      # ~2.5 s
def test_compare_of_one_run_recorded_at_two_rates_finds_no_difference(tmp_path):
    """
    The same physics recorded at 100 Hz and 1 kHz: every difference is zero, either order.

    Differences are taken on the coarser run's publications: the finer run's samples include
    them, and its peak-holds re-held over the coarser periods are the coarser run's own
    (interpolating 100 Hz samples at 1 kHz made 17 mm of tip and 146 MPa of peak stress).
    """
    scale = {'alpha1': 1.0, 'alpha1_rate': 1.0, 'tip_deflection': 0.06,
             'peak_stress_leaf': 2e8, 'peak_stress_link': 1e8}
    for first, diffs in compare_at_two_rates(tmp_path, '100', '1000'):
        for name, d in diffs.items():
            assert d['max'] <= 1e-9 * scale[name], (first, name, d)


def compare_at_two_rates(tmp_path, *rates) -> list[tuple[str, dict]]:
    """
    Record one run (0.35 s) at two publication rates; compare them in either order.

    Return (the reference run's name, umbrella_compare's differences of the other), in each order.
    """
    bags = [tmp_path / f'r{rate}' for rate in rates]
    for bag, rate in zip(bags, rates):
        assert run_cli('umbrella_sim', 'simulate', '--duration', '0.35', '--mcap', str(bag),
                       '--publish-rate', rate).returncode == 0
    out = []
    for order in (bags, bags[::-1]):
        cmp_dir = tmp_path / f'cmp_{order[0].name}'
        r = run_cli('umbrella_sim.tools.compare', *map(str, order), '--out', str(cmp_dir),
                    '--no-plots')
        assert r.returncode == 0, r.stderr
        out.append((order[0].name, json.loads((cmp_dir / 'compare.json').read_text())
                    ['runs'][1]['differences']))
    return out


def test_peak_holds_compare_on_the_coarser_grid_when_the_runs_start_apart():
    """A coarse run from 0.5 s, a fine one from 0: its first period took every earlier peak."""
    from umbrella_sim.tools.compare import _diff

    fine_t = np.arange(0.0, 2.0 + 1e-9, 0.001)
    fine = np.sin(40 * fine_t) ** 2 + 5.0 * (fine_t < 0.3)     # a crest long before 0.5 s
    coarse_t = np.arange(0.5, 2.0 + 1e-9, 0.01)
    coarse = np.array([fine[(fine_t > t - 0.01 + 1e-9) & (fine_t <= t + 1e-9)].max()
                       for t in coarse_t])      # the coarse run's own peak-hold of the same
    assert _diff(coarse_t, coarse, fine_t, fine, True) == (0.0, 0.0)
    assert _diff(fine_t, fine, coarse_t, coarse, True) == (0.0, 0.0)


@pytest.mark.slow      # ~2.5 s
def test_compare_of_one_run_recorded_at_100_and_40_hz_finds_no_difference(tmp_path):
    """The 40 Hz instants fall between 100 Hz samples (interpolating there made 14 mm of tip)."""
    for first, diffs in compare_at_two_rates(tmp_path, '100', '40'):
        assert all(d['max'] == 0.0 for d in diffs.values()), (first, diffs)


@pytest.mark.slow      # ~2 s
def test_the_difference_table_says_it_spans_the_runs_not_the_plot_window(tmp_path):
    """--window is the plots' span: the differences are the same with it, and say so."""
    bags = [tmp_path / 'undamped', tmp_path / 'damped']
    for bag, zeta in zip(bags, ('0.0', '0.02')):
        assert run_cli('umbrella_sim', 'simulate', '--duration', '0.35', '--mcap', str(bag),
                       '--set', f'damping_ratio={zeta}').returncode == 0
    tables = []
    for window in ([], ['--window', '0', '0.2']):
        out = tmp_path / f'cmp{len(window)}'
        r = run_cli('umbrella_sim.tools.compare', *map(str, bags), '--out', str(out),
                    '--no-plots', *window)
        assert r.returncode == 0, r.stderr
        assert ('each run against the reference run over the time both cover (the plots: '
                '--window)') in r.stdout, r.stdout
        assert 'over the window' not in r.stdout
        tables.append(json.loads((out / 'compare.json').read_text())['runs'][1]['differences'])
    assert tables[0] == tables[1]


def test_runs_at_rates_whose_instants_differ_compare_where_both_published():
    """
    The same signal at 100 Hz and at 40 Hz: no difference, in either order.

    The 40 Hz instants 0.025, 0.075, ... fall between two 100 Hz samples, and a value
    interpolated there differs from the signal by up to (omega h)^2 / 8 of its amplitude
    (a 47 ms vibration: 22 %); the differences are taken at the instants both runs published
    at (every 0.05 s), the peak-holds over the coarse periods that both runs' periods tile.
    """
    from umbrella_sim.tools.compare import _diff

    def signal(t):
        return np.sin(2 * np.pi * t / 0.047)

    def held(t, period):                    # a run's peak-hold over each of its periods
        fine = np.arange(0.0, 1.0 + 1e-9, 1e-4)
        return np.array([signal(fine[(fine > s - period + 1e-9) & (fine <= s + 1e-9)]).max()
                         if s > 0 else signal(0.0) for s in t])

    t100, t40 = np.round(np.arange(101) * 0.01, 9), np.round(np.arange(41) * 0.025, 9)
    for a, b in (((t100, 0.01), (t40, 0.025)), ((t40, 0.025), (t100, 0.01))):
        assert _diff(a[0], signal(a[0]), b[0], signal(b[0])) == (0.0, 0.0)
        assert _diff(a[0], held(*a), b[0], held(*b), True) == (0.0, 0.0)


@pytest.mark.ros
def test_bad_files_give_clear_errors(tmp_path, live_bag):
    not_mcap = tmp_path / 'x.mcap'
    not_mcap.write_bytes(b'definitely not an mcap file')
    truncated = tmp_path / 't.mcap'
    truncated.write_bytes(mcap_file(live_bag).read_bytes()[:200])
    missing = tmp_path / 'nofile.mcap'
    # a valid MCAP without the topics compare needs
    from mcap.writer import Writer
    other = tmp_path / 'other.mcap'
    with open(other, 'wb') as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema('x', 'jsonschema', b'{}')
        cid = w.register_channel('/something', 'json', sid)
        w.add_message(cid, 0, b'{}', 0)
        w.finish()
    cases = [(not_mcap, 'not an MCAP file'), (truncated, 'no channels'),
             (missing, 'no such file'), (other, 'umbrella_sim.parameters')]
    for path, words in cases:
        for tool in (['umbrella_sim.tools.compare', str(path), '--out', str(tmp_path / 'o')],
                     ['umbrella_sim.tools.replay', str(path), '--resimulate']):
            r = run_cli(*tool)
            assert r.returncode == 2, (tool, r.stdout, r.stderr)
            assert words in r.stderr and 'Traceback' not in r.stderr, (tool, r.stderr)


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
@pytest.mark.ros
def test_signal_stops_physics_then_finalises_the_recording(tmp_path, sig):
    """
    Stop cleanly on a signal while publishing at 1 kHz.

    At 1 kHz the physics thread publishes nearly all the time: the signal must stop it
    before rclpy shuts down, or a publish hits a dead context (it did, 12 times in 12).
    """
    bag = tmp_path / 'interrupted'
    probe = Probe('interrupt_probe')
    try:
        probe.subscribe('/clock', Clock, CLOCK_READER_QOS)
        with NodeProcess('-p', 'v0:=-0.5', '-p', 'publish_rate:=1000.0',
                         '-p', f'record_path:={bag}') as node:
            node.wait_for_log('recording to')
            lock = float(node.wait_for_log(r'locked at t = ([0-9.]+) s').group(1))
            # publishing for 0.3 s of sim time past the lock
            probe.wait_for('/clock', lambda m: m.clock.sec + 1e-9 * m.clock.nanosec > lock + 0.3,
                           what=f'a tick past {lock + 0.3:.6f} s')
            assert node.stop(sig) == 0
            out = node.output()
    finally:
        probe.close()
    assert 'recording finalised' in out
    assert '[ERROR]' not in out and 'Failed to publish' not in out, out
    assert (bag / 'metadata.yaml').exists()
    with open(mcap_file(bag), 'rb') as fh:
        summary = make_reader(fh).get_summary()
    log = read_log(str(bag))
    assert not log.truncated
    assert summary.statistics.message_count == len(log.messages) > 50


def test_a_recording_from_before_the_phase_correction_re_runs_without_it():
    """A recording whose parameters lack phase_correction was made by the plain midpoint rule."""
    from types import SimpleNamespace

    from umbrella_sim.core.params import physics_step
    from umbrella_sim.tools.replay import _segment_inputs

    old = {k: v for k, v in UmbrellaParams(time_step=1e-4).as_dict().items()
           if k != 'phase_correction'}
    seg = SimpleNamespace(index=0, offset_ns=0, end_ns=None,
                          params={**old, 'publish_rate': 100.0,
                                  'physics_step': physics_step(old['time_step'], 100.0)})
    log = SimpleNamespace(path='old.mcap', find_topic=lambda key, required=False: None)
    assert _segment_inputs(log, seg)[0].params.phase_correction is False
    seg.params['phase_correction'] = True              # what a recording of today holds
    assert _segment_inputs(log, seg)[0].params.phase_correction is True


@pytest.mark.ros
def test_the_starting_force_is_on_the_applied_history(tmp_path):
    """
    A run started with sleeve_force 3 N: the applied history holds it at t = 0.

    sleeve_force/applied is the whole force history (msg_docs/topic_sleeve_force.md): the
    starting force acts from t = 0 and is recorded there (it was left off, so a force profile
    made from the applied values missed it), and the recording re-simulates to zero
    difference.  The run (0.05 s) ends before the first 1 Hz status: it publishes its last.
    """
    from umbrella_sim.tools.replay import resimulate

    bag = tmp_path / 'pushed'
    with NodeProcess('-p', 'v0:=0.0', '-p', 'sleeve_force:=3.0', '-p', 'duration:=0.05',
                     '-p', 'real_time_factor:=0.0', '-p', f'record_path:={bag}') as node:
        assert node.proc.wait(timeout=120) == 0
        assert 'sleeve force 3 N applied from t = 0.000000000 s' in node.output()
    log = read_log(str(bag))
    applied = [(t, m.data) for t, m in log.decoded('/sleeve_force/applied')]
    assert [f for _, f in applied] == [3.0] and applied[0][0] == pytest.approx(0.0, abs=1e-9)
    res = resimulate(log)
    assert not res['problems'] and max(res['max_abs_diff'].values()) == 0.0
    # a run shorter than a second: its last status, at its duration, is its one /diagnostics
    (_, status), = log.decoded('/diagnostics')
    values = {kv.key: kv.value for kv in status.status[0].values}
    assert values['sim_time_s'] == '0.050000' and values['accepted_commands'] == '0'
