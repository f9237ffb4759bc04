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
Test faults and bad input.

Faults and bad input: write errors while recording, solver faults, unknown parameters,
bad params files and ROS arguments, foreign and damaged logs, overload, resets.
"""
import errno
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, String
from std_srvs.srv import Trigger

from tests.disk_faults import full_disk_write
from tests.ros_helpers import (cpu_seconds, NodeProcess, poll, Probe, ros_env,
                               signal_and_collect, wait_for_stamp_in_last_run)
from umbrella_sim.bag import cdr, mcap_stream, writer as recording
from umbrella_sim.bag.reader import LogError, read_log
from umbrella_sim.core.driver import simulate
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.registry import SPECS
from umbrella_sim.ros.commands import REFUSED_RECORD_RATE
from umbrella_sim.ros.messages import LATCHED
from umbrella_sim.ros.pacing import MAX_LAG_S

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(*args, timeout=120):
    return subprocess.run([sys.executable, '-m', *args], capture_output=True, text=True,
                          cwd=ROOT, env=ros_env(), timeout=timeout)


def diag_values(msg: DiagnosticArray) -> dict:
    return {kv.key: kv.value for kv in msg.status[0].values}


def stamp_s(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


@pytest.fixture
def probe():
    p = Probe('faults_probe')
    yield p
    p.close()


# ------------------------------------------------------------------ write errors
def _disk(monkeypatch, limit, code=errno.ENOSPC):
    monkeypatch.setattr(os, 'write', full_disk_write(limit, code))


@pytest.mark.parametrize('code', [errno.ENOSPC, errno.EIO, errno.EACCES])
def test_write_error_stops_recording_cleanly_and_keeps_what_was_written(
        tmp_path, monkeypatch, code):
    _disk(monkeypatch, 100_000, code)
    errors = []
    rec = recording.BagRecorder(str(tmp_path / 'bag'), {'umbrella_sim.parameters': {}},
                                on_error=errors.append)
    rec.add_channel('/x', Float64, QoSProfile(depth=10))
    n = 0
    while rec.write('/x', Float64(data=float(n)), n * 1_000_000):
        n += 1
        assert n < 10**6
    assert not rec.write('/x', Float64(data=-1.0), 0)          # stays stopped, no exception
    rec.close({'late': {'a': 'b'}})                             # no exception either
    assert len(errors) == 1 and os.strerror(code) in errors[0]
    log = read_log(str(tmp_path / 'bag'))
    assert log.ended_early and os.strerror(code) in log.ended_early
    values = [m.data for _, m in log.decoded('/x')]
    # every complete chunk is there, in order, and the counts say what the file holds
    assert values == [float(i) for i in range(len(values))] and len(values) > 1000
    assert log.count('/x') == rec.counts['/x'] == len(values) < n
    assert os.path.getsize(log.path) <= 100_000


def test_disk_full_at_start_leaves_nothing_behind(tmp_path, monkeypatch):
    _disk(monkeypatch, 20)
    with pytest.raises(ValueError, match='cannot start the recording: No space left'):
        recording.BagRecorder(str(tmp_path / 'bag'), {'umbrella_sim.parameters': {'a': '1'}})
    assert os.listdir(tmp_path) == []


def test_write_error_at_close_still_marks_the_recording(tmp_path, monkeypatch):
    rec = recording.BagRecorder(str(tmp_path / 'bag'), {'umbrella_sim.parameters': {}})
    rec.add_channel('/x', Float64, QoSProfile(depth=10))
    for i in range(3000):
        assert rec.write('/x', Float64(data=float(i)), i)
    size = os.path.getsize(rec.path)
    # room for the trailer, not for the last chunk and the summary
    _disk(monkeypatch, size + 800, errno.EIO)
    rec.close()
    assert rec.error and 'finalising' in rec.error
    log = read_log(str(tmp_path / 'bag'))
    assert log.ended_early
    assert log.count('/x') == 0 or [m.data for _, m in log.decoded('/x')] == \
        [float(i) for i in range(log.count('/x'))]


@pytest.mark.ros
@pytest.mark.slow
def test_node_recording_disk_full_goes_on_and_exits_4(tmp_path, probe):
    probe.subscribe('/joint_states', JointState)
    bag = tmp_path / 'full'
    # 15 sim s at 3x real time: ~5 s of wall time after the disk fills, so the probe has
    # discovered the node and counts messages published after the error even on a busy machine.
    # The disk fills inside a chunk that leaves room for the ended-early trailer (~9 kB here;
    # at 150000 B, once schemas and channels were no longer repeated outside the chunks,
    # 110 B were left, too few: the file is then a clean prefix without the mark)
    with NodeProcess('-p', 'publish_rate:=1000.0', '-p', 'duration:=15.0',
                     '-p', 'real_time_factor:=3.0', '-p', f'record_path:={bag}',
                     executable=[sys.executable, '-m', 'tests.disk_faults', '160000',
                                 str(errno.ENOSPC)], cwd=ROOT) as node:
        node.wait_for_log('recording stopped', timeout=60)
        n_at_error = len(probe.messages('/joint_states'))
        probe.wait_for_count('/joint_states', 1, timeout=30)     # (the probe has the node)
        n_before = len(probe.messages('/joint_states'))
        last = stamp_s(probe.messages('/joint_states')[n_before - 1])
        # a reset after it: the run restarts; no recording segment is claimed
        assert probe.call(Trigger, '/umbrella_node/reset', Trigger.Request()).success
        node.wait_for_log('reset: simulation restarted')
        # the topics go on after the error: states of the new run (sim time went back; one
        # writer, in order) reach the probe
        poll(lambda: any(stamp_s(m) < last for m in probe.messages('/joint_states')[n_before:]),
             30, lambda: f'no state of the run after the reset within 30 s (the last before it '
                         f"at {last:.6f} s; {len(probe.messages('/joint_states'))} in all)")
        assert node.proc.wait(timeout=60) == 4
        out = node.output()
    assert 'recording segment' not in out
    assert out.count('recording stopped') == 1 and 'Traceback' not in out
    assert 'duration 15 s reached' in out                      # the simulation went on
    assert len(probe.messages('/joint_states')) > n_at_error
    log = read_log(str(bag))
    assert 'No space left' in log.ended_early
    r = run('umbrella_sim.tools.replay', str(bag), '--resimulate')
    assert r.returncode == 0 and 'recording ended early' in r.stdout, r.stdout + r.stderr
    from umbrella_sim.tools.compare import load_run      # and compare says why it has no summary
    why = load_run(str(bag)).figures()['figures_from']
    assert 'recording ended early (' in why and 'No space left' in why, why


@pytest.mark.slow
def test_output_paths_checked_before_any_work(tmp_path):
    (tmp_path / 'exists.csv').write_text('x')
    (tmp_path / 'full').mkdir()
    (tmp_path / 'full' / 'compare.json').write_text('{}')
    for args, words in [(['--csv', str(tmp_path / 'nodir' / 'x.csv')], 'does not exist'),
                        (['--csv', str(tmp_path / 'exists.csv')], 'not overwriting'),
                        (['--mcap', str(tmp_path / 'full')], 'not overwriting'),
                        (['--csv', ''], "--csv '': empty path"),
                        (['--mcap', ''], "--mcap '': empty path")]:
        # 10^6 s of physics could not end within run()'s timeout: a refusal came first
        r = run('umbrella_sim', 'simulate', '--duration', '1e6', '--long-run', *args)
        assert r.returncode == 2 and words in r.stderr and 'Traceback' not in r.stderr
    r = run('umbrella_sim.tools.compare', 'a', 'b', '--out', str(tmp_path / 'full'))
    assert r.returncode == 2 and 'not empty' in r.stderr
    assert (tmp_path / 'full' / 'compare.json').read_text() == '{}'
    r = run('umbrella_sim.tools.compare', 'a', 'b', '--out', str(tmp_path / 'exists.csv'))
    assert r.returncode == 2 and 'not overwriting' in r.stderr
    r = run('umbrella_sim.tools.compare', 'a', 'b', '--out', '')
    assert r.returncode == 2 and "--out '': empty path" in r.stderr


@pytest.mark.slow
def test_overwrite_replaces_an_earlier_output_and_nothing_else(tmp_path):
    """--overwrite (never the default) replaces a file, a recording, a comparison's outputs."""
    csv, bag, out = tmp_path / 'run.csv', tmp_path / 'bag', tmp_path / 'cmp'
    csv.write_text('old')

    def simulate_to(*extra):
        return run('umbrella_sim', 'simulate', '--duration', '0.05', '--csv', str(csv),
                   '--mcap', str(bag), *extra)
    r = simulate_to()
    assert r.returncode == 2 and '--overwrite' in r.stderr and csv.read_text() == 'old'
    assert not bag.exists()
    assert simulate_to('--overwrite').returncode == 0
    assert csv.read_text().startswith('t') and read_log(str(bag)).count('/joint_states') > 0
    first = (bag / 'metadata.yaml').read_text()
    r = simulate_to('--overwrite', '--set', 'v0=-1.0')        # a new run replaces both
    assert r.returncode == 0, r.stderr
    assert read_log(str(bag)).parameters()['v0'] == -1.0 and first != (
        bag / 'metadata.yaml').read_text()
    # the comparison's outputs, and only those
    assert run('umbrella_sim.tools.compare', str(bag), str(bag), '--out', str(out),
               '--no-plots').returncode == 0
    r = run('umbrella_sim.tools.compare', str(bag), str(bag), '--out', str(out), '--no-plots')
    assert r.returncode == 2 and '--overwrite' in r.stderr
    assert run('umbrella_sim.tools.compare', str(bag), str(bag), '--out', str(out),
               '--no-plots', '--overwrite').returncode == 0
    # what is not an output of ours is never removed
    (out / 'notes.txt').write_text('mine')
    r = run('umbrella_sim.tools.compare', str(bag), str(bag), '--out', str(out), '--no-plots',
            '--overwrite')
    assert r.returncode == 2 and 'other than' in r.stderr
    (bag / 'notes.txt').write_text('mine')
    r = simulate_to('--overwrite')
    assert r.returncode == 2 and 'not a recording' in r.stderr
    assert (bag / 'notes.txt').read_text() == 'mine' and (out / 'notes.txt').exists()
    r = run('umbrella_sim', 'simulate', '--duration', '0.05', '--csv', str(tmp_path),
            '--overwrite')
    assert r.returncode == 2 and 'not a regular file' in r.stderr
    # --out at a file: refused, with or without --overwrite, and the hint is not --overwrite
    for extra in ((), ('--overwrite',)):
        r = run('umbrella_sim.tools.compare', str(bag), '--out', str(csv), '--no-plots',
                *extra)
        assert r.returncode == 2 and 'is not a directory' in r.stderr, r.stderr
        assert 'replaces it' not in r.stderr and csv.read_text().startswith('t')


# ------------------------------------------------------------------ solver faults
def test_offline_fault_recorded_and_reproduced(tmp_path):
    bag = tmp_path / 'fault'
    # at a 2 ms step Newton cannot follow 2.3 kN (at a 50 us step it can)
    r = run('umbrella_sim', 'simulate', '--v0', '0', '--force', '2300', '--duration', '0.5',
            '--time-step', '0.002', '--mcap', str(bag))
    assert r.returncode == 3
    log = read_log(str(bag))
    assert 'Newton' in log.metadata['umbrella_sim.events']['fault']
    r = run('umbrella_sim.tools.replay', str(bag), '--resimulate')
    assert r.returncode == 0 and 'fault reproduced at t = ' in r.stdout, r.stdout + r.stderr


def test_compare_says_a_run_ended_in_a_fault(tmp_path):
    """
    Its figures are of the time before the fault: umbrella_compare says so, as --info does.

    flexible-nonlinear from the default V0 with 300 N: the solver fails at t = 0.0705 s,
    15 ms into stage 2, whose 'amplitude' is then of those 15 ms.
    """
    bag = tmp_path / 'fault'
    r = run('umbrella_sim', 'simulate', '--model', 'flexible-nonlinear', '--force', '300',
            '--duration', '0.2', '--mcap', str(bag))
    assert r.returncode == 3, r.stderr
    out = tmp_path / 'cmp'
    r = run('umbrella_sim.tools.compare', str(bag), '--out', str(out), '--no-plots')
    assert r.returncode == 0, r.stderr
    assert re.search(r'fault: the run ended in a solver fault at t = 0\.0705 s \(its figures '
                     r'are of the time before it\): solver failed in the step after', r.stdout), \
        r.stdout
    fault = json.loads((out / 'compare.json').read_text())['runs'][0]['fault']
    assert fault['time'] == pytest.approx(0.0705) and 'singular' in fault['reason']


def test_summary_from_recording_names_the_fault_that_cut_stage_2_short(tmp_path):
    """Its warning of a short stage 2 names the fault, not a longer recording to make."""
    from umbrella_sim.testing import summary_from_recording

    bag = tmp_path / 'fault'
    r = run('umbrella_sim', 'simulate', '--model', 'flexible-nonlinear', '--force', '300',
            '--duration', '0.2', '--mcap', str(bag))
    assert r.returncode == 3, r.stderr
    with pytest.warns(UserWarning) as caught:
        summary_from_recording(str(bag))
    text = ' '.join(str(w.message) for w in caught if w.category is UserWarning)
    assert 'holds 0.0143167 s of stage 2 after the lock' in text, text
    assert 'the run ended in a solver fault at t = 0.0705 s' in text, text
    assert 'a longer recording' not in text, text


@pytest.mark.ros
@pytest.mark.slow
def test_commanded_fault_is_recorded_reproduced_and_ends_a_timed_run(tmp_path, probe):
    """
    Record, reproduce and end a run on a commanded solver fault.

    The force that faults the solver is in the log before it is applied, --resimulate
    faults at the same instant, nothing is republished after the fault, the run ends (3).
    """
    probe.subscribe('/joint_states', JointState)
    probe.subscribe('/deployment_phase', String, LATCHED)
    bag = tmp_path / 'commanded'
    with NodeProcess('-p', 'v0:=0.0', '-p', 'duration:=30.0', '-p', 'time_step:=0.002',
                     '-p', f'record_path:={bag}') as node:
        node.wait_for_log('recording to')
        pub = probe.publisher('/sleeve_force', Float64)
        probe.wait_for_subscribers(pub)
        pub.publish(Float64(data=2300.0))
        probe.wait_for('/deployment_phase', lambda m: m.data == 'fault', timeout=30)
        assert node.proc.wait(timeout=30) == 3
        out = node.output()
    assert 'the run ends' in out
    stamps = [stamp_s(m) for m in probe.messages('/joint_states')]
    assert len(stamps) == len(set(stamps))                    # no sample published twice
    log = read_log(str(bag))
    applied = [m.data for _, m in log.decoded('/sleeve_force/applied')]
    assert applied == [2300.0]
    assert log.metadata['umbrella_sim.events']['fault']
    r = run('umbrella_sim.tools.replay', str(bag), '--resimulate')
    assert r.returncode == 0 and 'fault reproduced' in r.stdout, r.stdout + r.stderr


@pytest.mark.ros
@pytest.mark.slow
def test_command_above_what_the_link_carries_is_refused(probe):
    probe.subscribe('/diagnostics', DiagnosticArray)
    limit = UmbrellaParams().sleeve_force_limit
    with NodeProcess('-p', 'v0:=0.0') as node:
        node.wait_for_log('physics step')
        pub = probe.publisher('/sleeve_force', Float64)
        probe.wait_for_subscribers(pub)
        pub.publish(Float64(data=limit * 1.01))
        probe.wait_for('/diagnostics', lambda m: diag_values(m)['refused_commands'] == '1')
        assert 'link can carry' in node.output()
    r = _node('-p', 'sleeve_force:=1e9')
    assert r.returncode == 2 and 'sleeve_force' in r.stderr and 'link can carry' in r.stderr


# ------------------------------------------------------------- bad configuration
def _node(*args, timeout=60):
    """Run a short node in a temporary directory (it records there by default)."""
    with tempfile.TemporaryDirectory() as cwd:
        r = subprocess.run([sys.executable, '-m', 'umbrella_sim.node', '--ros-args', *args,
                            '-p', 'duration:=0.1', '-p', 'real_time_factor:=0.0'],
                           capture_output=True, text=True, env=ros_env(), timeout=timeout,
                           cwd=cwd)
        r.left = os.listdir(cwd)
    return r


@pytest.mark.parametrize('content, args, words', [
    (None, ['-p', 'youngs_modulous:=1.0'], "did you mean 'youngs_modulus'"),
    (None, ['-p', 'foo:=1.0'], "unknown parameter 'foo'"),
    # an umbrella name misspelt: the node knows it, and says where the umbrella's are listed
    (None, ['-p', 'ribs:=3', '-p', 'hub_radious:=0.1'],
     "'hub_radious' (did you mean 'hub_radius'?); known parameters are listed by umbrella_node "
     "--help and in msg_docs/parameters.md (the umbrella of N ribs': "
     'msg_docs/umbrella3d_parameters.md)'),
    ('other_node:\n  ros__parameters:\n    l1: -5.0\n', [], 'no section for node /umbrella_node'),
    # (in a section naming the node: in a '/**' one they are another node's, a warning)
    ('umbrella_node:\n  ros__parameters:\n    l4: 1.0\n', [], "'l4' (did you mean 'l"),
    ('umbrella_node:\n  ros__parameters:\n    l1: {a: 1}\n', [], "'l1.a'"),
    ('/**:\n  ros__parameters: [1, 2\n', [], 'not valid YAML'),
    ('- 1\n- 2\n', [], 'expected a mapping'),
    ('/**:\n  l1: 0.5\n', [], 'has no ros__parameters'),
    (b'\x89PNG\r\n\x1a\n\x00\x00', [], 'binary data'),
    (None, ['--params-file', '/nonexistent/p.yaml'], 'No such file'),
    (None, ['-p', 'l1'], 'invalid ROS arguments'),
    (None, ['--bogus-flag'], 'unknown ROS arguments'),
    (None, ['-p', 'section_height:=1e-300'], 'section_height=1e-300'),
    ('/**:\n  ros__parameters:\n    v0:\n', [], 'no value for v0'),
    (None, ['-p', 'qos_overrides./clok.publisher.depth:=5'],
     "did you mean 'qos_overrides./clock.publisher.depth'"),
    ('/**:\n  ros__parameters:\n    qos_overrides:\n      /clock:\n        publisher:\n'
     '          depth: deep\n', [], 'qos_overrides./clock.publisher.depth'),
    ('/**:\n  ros__parameters:\n    v0: -0.5\n    v0: -1.0\n', [], 'given twice'),
    (None, ['-p', 'time_step:=1e-9'], 'time_step'),
    # ROS's own parameters, which rclpy declares itself (use_sim_time was a traceback)
    (None, ['-p', 'use_sim_time:=abc'],
     "parameter use_sim_time='abc': must be of type bool, got string"),
    (None, ['-p', 'qos_overrides./clock.publisher.depth:=deep'],
     "parameter qos_overrides./clock.publisher.depth='deep': must be of type integer"),
    # a value of the right type that no QoS takes: rclpy's own errors named neither the
    # parameter nor the topic ('invalid allocator', 'Unexpected QoS override')
    (None, ['-p', 'qos_overrides./clock.publisher.depth:=-3'],
     'parameter qos_overrides./clock.publisher.depth=-3: must be >= 0'),
    (None, ['-p', 'qos_overrides./sleeve_force.subscription.depth:=3000000000'],
     'parameter qos_overrides./sleeve_force.subscription.depth=3000000000: must be <= '),
    ('/**:\n  ros__parameters:\n    qos_overrides:\n      /joint_states:\n'
     '        publisher:\n          reliability: bogus\n', [],
     "parameter qos_overrides./joint_states.publisher.reliability='bogus': must be one of "),
    # a -p value of another type than a params file's: rcl keeps the file's without a word
    ('/**:\n  ros__parameters:\n    v0: -0.2\n', ['-p', 'v0:=abc'],
     "parameter v0='abc' (-p): not taken: rcl keeps v0's value -0.2 (a double"),
    ('/**:\n  ros__parameters:\n    damping_ratio: 0.0\n', ['-p', 'damping_ratio:=[0.02]'],
     'give damping_ratio a double'),
    # 'NaN' is rcl's double NaN (YAML's string): the value's own refusal, not a type's
    (None, ['-p', 'v0:=NaN'], 'parameter v0=nan: must be a finite number'),
    # a per-rib list of an int and doubles: rcl's own parse error, with what to write
    (None, ['-p', 'ribs:=3', '-p', 'rib.tip_mass:=[0,0.1,0]'],
     'a list of doubles needs every value written as a double, [0.0, 0.1] not [0, 0.1]'),
    # the umbrella's values are named before an existing record_path (/tmp): every
    # parameter's error first, not one after the other
    (None, ['-p', 'ribs:=6', '-p', 'rib9.tip_mass:=0.1', '-p', 'record_path:=/tmp'],
     'parameter rib9.tip_mass: there are ribs 0 .. 5'),
], ids=['typo', 'unknown', 'umbrella-typo', 'other-node', 'unknown-key', 'nested', 'malformed',
        'list', 'no-ros-parameters', 'binary', 'missing', 'no-assign', 'bogus-flag', 'no-model',
        'empty-value', 'qos-typo', 'qos-type', 'twice', 'tiny-step', 'ros-param-type',
        'qos-type-argument', 'qos-negative-depth', 'qos-huge-depth', 'qos-bad-policy',
        'argument-type-beside-file', 'argument-list-beside-file',
        'nan-word', 'mixed-list', 'rib-before-record-path'])
@pytest.mark.ros
def test_bad_configuration_exits_2_naming_culprit(tmp_path, content, args, words):
    if content is not None:
        path = tmp_path / 'p.yaml'
        (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
        args = ['--params-file', str(path), *args]
    r = _node(*args)
    assert r.returncode == 2, r.stderr
    assert r.left == []                             # a failed start leaves nothing behind
    assert words in r.stderr and 'Traceback' not in r.stderr, r.stderr
    if content is not None:
        assert 'p.yaml' in r.stderr


@pytest.mark.ros
def test_a_whole_double_beside_a_files_integer_is_the_integer(tmp_path):
    # msg_docs/node_parameters.md: -p elements_per_segment:=4.0 is 4, with a file or without
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    elements_per_segment: 1\n')
    r = _node('--params-file', str(path), '-p', 'elements_per_segment:=4.0', '-p',
              'record:=false')
    assert r.returncode == 0, r.stderr
    assert '4 element(s) a segment' in r.stderr + r.stdout


@pytest.mark.ros
def test_params_file_for_a_namespaced_node(tmp_path):
    path = tmp_path / 'ns.yaml'
    path.write_text('/a1/umbrella_node:\n  ros__parameters:\n    v0: -0.5\n')
    assert _node('--params-file', str(path), '-r', '__ns:=/a1').returncode == 0
    r = _node('--params-file', str(path))
    assert r.returncode == 2 and 'no section for node /umbrella_node' in r.stderr


def test_cli_set_and_params_file_typos_suggest(tmp_path):
    r = run('umbrella_sim', 'simulate', '--set', 'youngs_modulous=1')
    assert r.returncode == 2 and "did you mean 'youngs_modulus'" in r.stderr
    path = tmp_path / 'p.yaml'
    path.write_text('umbrella_node:\n  ros__parameters:\n    elements_per_segmnt: 2\n')
    r = run('umbrella_sim', 'simulate', '--params', str(path))
    assert r.returncode == 2 and "did you mean 'elements_per_segment'" in r.stderr
    assert str(path) in r.stderr


@pytest.mark.ros
def test_sigint_during_startup_is_quiet(tmp_path):
    """
    Stop quietly on SIGINT during start-up.

    SIGINT while the node is still starting (model built, recording not yet open or
    physics not yet started): a clean stop, no KeyboardInterrupt traceback.
    """
    bag = tmp_path / 'early'
    with NodeProcess('-p', f'record_path:={bag}', '-p', 'elements_per_segment:=8') as node:
        node.wait_for_log(r'umbrella_sim \S+: model flexible', timeout=30)
        assert node.stop(signal.SIGINT) == 0
        out = node.output()
    assert 'Traceback' not in out and 'KeyboardInterrupt' not in out, out
    if bag.exists():                       # whatever was created is a finalised recording
        assert not read_log(str(bag)).truncated


def _catches(pid: int, signum: int) -> bool:
    """Tell whether the process has its own handler of signum (umbrella_sim's first line ran)."""
    try:
        with open(f'/proc/{pid}/status') as fh:
            caught = next(line for line in fh if line.startswith('SigCgt:')).split()[1]
    except (OSError, StopIteration):
        return False
    return bool(int(caught, 16) & (1 << (signum - 1)))


def _catches_sigterm(pid: int) -> bool:
    """Tell whether the process has its own SIGTERM handler (umbrella_sim's first line ran)."""
    return _catches(pid, signal.SIGTERM)


@pytest.mark.parametrize('signum,delay,entry', [
    (signal.SIGINT, 0.0, 'module'), (signal.SIGINT, 0.15, 'module'),
    (signal.SIGINT, 0.4, 'module'), (signal.SIGINT, 0.8, 'script'),
    (signal.SIGINT, 1.5, 'module'), (signal.SIGTERM, 0.3, 'module'),
    (signal.SIGTERM, 0.6, 'script')])
@pytest.mark.ros
def test_stop_signal_at_any_instant_of_start_up_is_a_clean_exit(tmp_path, signum, delay, entry):
    """
    Stop cleanly on a signal at any instant of start-up.

    A stop signal at any instant of start-up (imports, rclpy.init, model, recording,
    first publication): exit 0, no traceback, nothing half-written left behind.  The
    instants count from when the entry point's handlers are in place (the interpreter's own
    start before that is Python's); on a loaded machine the later ones may reach a running
    node, which must stop just as cleanly.
    """
    bag = tmp_path / 'bag'
    args = ['--ros-args', '-p', f'record_path:={bag}', '-p', 'elements_per_segment:=4']
    script = os.path.join(os.path.dirname(sys.executable), 'umbrella_node')
    if entry == 'script' and not os.path.exists(script):
        entry = 'module'               # an install without console scripts next to python
    cmd = [script, *args] if entry == 'script' else \
        [sys.executable, '-m', 'umbrella_sim.node', *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=str(tmp_path), env=ros_env())
    try:
        deadline = time.monotonic() + 60
        while not _catches_sigterm(proc.pid) and proc.poll() is None:
            assert time.monotonic() < deadline, 'no SIGTERM handler after 60 s'
            time.sleep(0.002)
        # the instant under test, counted from the handlers observed in place: not a wait for
        # a condition (start-up has no marks of its own to aim at; whichever phase the signal
        # lands in, on a slow or a fast machine, the same clean exit is asserted)
        time.sleep(delay)
    finally:
        out, err = signal_and_collect(proc, signum)
    assert proc.returncode == 0, err
    assert 'Traceback' not in err + out and 'KeyboardInterrupt' not in err + out, err
    name = signal.Signals(signum).name
    if f'stopped by {name} during start-up; nothing was started' in err:
        assert not bag.exists()
    elif bag.exists():                       # it was running: a finalised recording
        log = read_log(str(bag))
        assert not log.truncated and not log.ended_early


@pytest.mark.ros
def test_stop_inside_a_long_period_ends_it_and_records_one_state(tmp_path):
    """
    A stop signal in a long publication period (1 Hz, 10^6 steps of 1 us) ends it early.

    The period goes in short calls (PublicationDriver.advance with should_stop); the node
    publishes nothing for the partial period, and its recording's events and summary are of
    the same state: every step taken, none in flight.
    """
    bag = tmp_path / 'long_period'
    with NodeProcess('-p', 'publish_rate:=1.0', '-p', 'time_step:=1e-6',
                     '-p', f'record_path:={bag}') as node:
        node.wait_for_log('recording to')
        # inside the first period (~10 s of steps): the node has computed for half a second
        # since it opened its recording (nothing but the physics thread computes then)
        cpu = cpu_seconds(node.pid)
        poll(lambda: cpu_seconds(node.pid) >= cpu + 0.5, 60,
             lambda: f'the node used {cpu_seconds(node.pid) - cpu:.2f} s of CPU in 60 s after '
                     "'recording to' (awaited 0.5 s: stepping inside the first period)")
        assert node.stop(signal.SIGTERM, timeout=60) == 0, node.output()
        out = node.output()
    assert 'recording finalised' in out and 'Traceback' not in out, out
    log = read_log(str(bag))
    assert not log.truncated and log.count('/joint_states') == 1     # t = 0 only
    summary = json.loads(log.metadata['umbrella_sim.summary']['figures'])
    steps = summary['steps']
    assert 0 < steps < 10 ** 6 and summary['final_time'] == pytest.approx(steps * 1e-6)
    events = log.metadata['umbrella_sim.events']      # (the lock comes at ~226 000 steps)
    assert (events['locked'] == 'true') == (summary['deploy_time'] is not None)
    if summary['deploy_time'] is not None:
        assert float(events['lock_time']) == summary['deploy_time']


@pytest.mark.parametrize('signum, background', [
    (signal.SIGINT, False), (signal.SIGTERM, False), (signal.SIGINT, True)],
    ids=['SIGINT', 'SIGTERM', 'SIGINT-background'])
def test_interrupted_offline_run_exits_130_with_its_recording_finalised(
        tmp_path, signum, background):
    """
    A run of the offline tool stopped by a signal: one line, exit 130, the bag finalised.

    Also when started as a background job of a script, which starts it with SIGINT ignored
    (`kill -INT` then did nothing, as the nodes do not).
    """
    bag = tmp_path / 'long'
    proc = subprocess.Popen([sys.executable, '-m', 'umbrella_sim', 'simulate', '--set',
                             'time_step=0.002', '--duration', '1e6', '--long-run', '--mcap',
                             str(bag)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, env=ros_env(), preexec_fn=(
                                (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
                                if background else None))
    try:
        deadline = time.monotonic() + 120
        mcap = bag / 'long_0.mcap'
        # under way: the first chunks of messages are on disk
        while not (mcap.exists() and mcap.stat().st_size > 100_000) and proc.poll() is None:
            assert time.monotonic() < deadline, 'the run did not start recording'
            time.sleep(0.05)
    finally:
        out, err = signal_and_collect(proc, signum)
    assert proc.returncode == 130, err
    assert 'Traceback' not in err and f'interrupted by {signal.Signals(signum).name}' in err
    log = read_log(str(bag))
    assert not log.truncated and log.count('/joint_states') > 100
    # its summary of every step computed (umbrella_compare's figures; it had none)
    figures = json.loads(log.metadata['umbrella_sim.summary']['figures'])
    last_state = max(t for t, _ in log.decoded(log.find_topic('joint_states')))
    assert last_state - 0.01 <= figures['final_time'] <= last_state + 0.01 + 1e-9
    assert figures['energy_drift'] < 1e-6


def test_a_stop_signal_while_a_tool_starts_is_taken(tmp_path):
    """
    SIGINT during the console script's imports, started as a background job (SIGINT ignored).

    The imports take ~0.5 s before main installs its handlers: the signal was lost and the
    run went to its end.  Now the entry point takes it first: exit 130 at once, one line.
    """
    tool = 'umbrella_sim'
    script = os.path.join(os.path.dirname(sys.executable), tool)
    proc = subprocess.Popen([script, 'simulate', '--time-step', '1e-5', '--duration', '1.0'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path, env=ros_env(),
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        # the entry point's SIGINT handler in place, its first line (SIGINT is ignored before
        # it, as by any program started so), the imports under way: one Ctrl-C
        poll(lambda: _catches(proc.pid, signal.SIGINT) or proc.poll() is not None, 60,
             lambda: 'no SIGINT handler in the tool within 60 s of its start', interval=0.002)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130 and 'Traceback' not in err, err
    assert f'{tool}: interrupted by SIGINT while starting; nothing was done' in err, err


@pytest.mark.slow
def test_output_read_by_a_closed_pipe_is_no_traceback_and_keeps_the_files(tmp_path):
    """`umbrella_compare ... | head -1`: exit 141 (SIGPIPE), no traceback, compare.json kept."""
    bags = []
    for name in ('a', 'b'):
        bags.append(str(tmp_path / name))
        r = run('umbrella_sim', 'simulate', '--set', 'time_step=0.001', '--duration', '0.3',
                '--mcap', bags[-1])
        assert r.returncode == 0, r.stderr
    out = tmp_path / 'cmp'
    for args in (['umbrella_sim', 'simulate', '--duration', '0.01'],
                 ['umbrella_sim.tools.compare', *bags, '--out', str(out), '--no-plots'],
                 ['umbrella_sim.tools.replay', bags[0], '--resimulate']):
        read_end, write_end = os.pipe()
        os.close(read_end)              # the reader is gone before the first line
        try:
            proc = subprocess.run([sys.executable, '-m', *args], stdout=write_end,
                                  stderr=subprocess.PIPE, text=True, cwd=ROOT, env=ros_env(),
                                  timeout=120)
        finally:
            os.close(write_end)
        assert proc.returncode == 141, (args, proc.stderr)
        assert 'Traceback' not in proc.stderr and 'Error' not in proc.stderr, proc.stderr
    assert json.loads((out / 'compare.json').read_text())['runs']


def test_compare_gives_every_run_a_label_of_its_own(tmp_path):
    """Runs given as .mcap files are named by their files; same names fall back to paths."""
    bag = tmp_path / 'run'
    r = run('umbrella_sim', 'simulate', '--set', 'time_step=0.001', '--duration', '0.05',
            '--mcap', str(bag))
    assert r.returncode == 0, r.stderr
    data = (bag / 'run_0.mcap').read_bytes()
    for rel in ('m/x.mcap', 'm/y.mcap', 'd1/z.mcap', 'd2/z.mcap'):
        (tmp_path / rel).parent.mkdir(exist_ok=True)
        (tmp_path / rel).write_bytes(data)
    for logs, labels in ((['m/x.mcap', 'm/y.mcap'], ['x', 'y']),
                         (['d1/z.mcap', 'd2/z.mcap'], ['d1/z.mcap', 'd2/z.mcap']),
                         ([str(bag), 'm/x.mcap'], ['run', 'x'])):
        out = tmp_path / f"cmp_{labels[0].replace('/', '_')}"
        r = subprocess.run([sys.executable, '-m', 'umbrella_sim.tools.compare', *logs, '--out',
                            str(out), '--no-plots'], capture_output=True, text=True,
                           cwd=tmp_path, env=ros_env(), timeout=120)
        assert r.returncode == 0, r.stderr
        assert [e['label'] for e in json.loads((out / 'compare.json').read_text())['runs']] \
            == labels
    r = run('umbrella_sim.tools.compare', str(bag), str(bag), '--names', 'a', 'a', '--out',
            str(tmp_path / 'cmp_names'))
    assert r.returncode == 2 and '--names a a' in r.stderr, r.stderr
    assert not (tmp_path / 'cmp_names').exists()


def test_compare_with_a_run_that_faulted_at_once_names_both_logs(tmp_path):
    """A log with one sample (a fault in the first step) has no time to compare over."""
    for name, args in (('fault', ['--set', 'v0=-1000', '--set', 'time_step=0.01']),
                       ('good', ['--set', 'time_step=0.001'])):
        r = run('umbrella_sim', 'simulate', '--duration', '0.05', *args,
                '--mcap', str(tmp_path / name))
        assert r.returncode == (3 if name == 'fault' else 0), r.stderr
    r = run('umbrella_sim.tools.compare', str(tmp_path / 'good'), str(tmp_path / 'fault'),
            '--out', str(tmp_path / 'cmp'), '--no-plots')
    assert r.returncode == 2 and 'do not overlap in time' in r.stderr, r.stderr
    assert 'fault_0.mcap (1 samples' in r.stderr and 'good_0.mcap' in r.stderr, r.stderr
    # alone, the run that faulted at once is shown (its figures): no other run
    # to compare (it was refused as not overlapping itself), no plot warning of an empty span
    r = run('umbrella_sim.tools.compare', str(tmp_path / 'fault'), '--out',
            str(tmp_path / 'alone'))
    assert r.returncode == 0 and 'UserWarning' not in r.stderr, r.stderr
    assert 'reference run: fault' in r.stdout, r.stdout


def test_chunk_index_is_kept_on_disk_and_the_file_stays_seekable(tmp_path, monkeypatch):
    """
    Keep the writer's chunk index out of memory while recording.

    The MCAP writer's chunk index (one entry per chunk, the recorder's only
    per-message-count growth) is kept on disk while recording: what stays in memory is
    bounded by the spill size whatever the length of the run, and the finished file's
    summary still indexes every chunk, so readers seek by time.
    """
    from mcap.reader import make_reader
    monkeypatch.setattr(mcap_stream.SpilledChunkIndex, 'SPILL_BYTES', 2048)
    rec = recording.BagRecorder(str(tmp_path / 'bag'), {'umbrella_sim.parameters': {}})
    rec.add_channel('/s', String, QoSProfile(depth=10))
    rec.add_channel('/x', Float64, QoSProfile(depth=10))
    index = rec._chunk_index
    assert rec._writer._Writer__chunk_indices is index     # the writer uses it
    in_memory = []
    n = 3000
    for i in range(n):
        # 2 kB of text that zstd cannot shrink to nothing: ~30 messages per 64 KiB chunk
        rec.write('/s', String(data=f'{i:08d}' * 250), i * 1_000_000)
        rec.write('/x', Float64(data=float(i)), i * 1_000_000)
        in_memory.append(index.in_memory_bytes())
    assert index.count > 50
    assert max(in_memory) < 2048 + 400          # one spill's worth, not one entry per chunk
    rec.close()
    chunks = index.count                        # the last chunk is written at close
    with open(rec.path, 'rb') as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count == chunks
        assert summary.statistics.message_count == 2 * n
        # a seek by time reads from the right chunk on
        t = (n // 2) * 1_000_000
        first = next(reader.iter_messages(topics=['/x'], starting_at=t))
        assert first[2].log_time == t
    log = read_log(str(tmp_path / 'bag'))
    assert not log.truncated and log.count('/x') == n
    assert [m.data for _, m in log.decoded('/x')] == [float(i) for i in range(n)]
    assert sorted(os.listdir(tmp_path / 'bag')) == ['bag_0.mcap', 'metadata.yaml']


# -------------------------------------------------------------------- bad logs
def _foreign(path, payload=None, parameters=None):
    from mcap.writer import Writer
    from rclpy.serialization import serialize_message
    with open(path, 'wb') as fh:
        w = Writer(fh)
        w.start('ros2', 'test')
        sid = w.register_schema('sensor_msgs/msg/JointState', 'ros2msg',
                                cdr.message_definition('sensor_msgs/msg/JointState')
                                .encode())
        cid = w.register_channel('/joint_states', 'cdr', sid)
        if parameters:
            w.add_metadata('umbrella_sim.parameters', parameters)
        for i in range(5):
            w.add_message(cid, i * 10**7, payload or serialize_message(JointState()), i * 10**7)
        w.finish()


@pytest.mark.slow
def test_foreign_damaged_and_special_logs_exit_2_naming_file(tmp_path):
    good = tmp_path / 'good'
    assert run('umbrella_sim', 'simulate', '--duration', '0.05', '--mcap',
               str(good)).returncode == 0
    foreign, garbage = tmp_path / 'foreign.mcap', tmp_path / 'garbage.mcap'
    _foreign(foreign)
    # an umbrella_sim parameters record, the right schema, payloads that are not CDR of it
    _foreign(garbage, payload=b'\x00\x01\x00\x00\xff\xff\xff\x7f',
             parameters=read_log(str(good)).metadata['umbrella_sim.parameters'])
    fifo = tmp_path / 'fifo.mcap'
    os.mkfifo(fifo)
    # cut inside its only chunk: the parameters (outside chunks) survive, no message does
    data = (good / 'good_0.mcap').read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) // 2])
    cases = [(foreign, 'not an umbrella_sim recording'),
             (garbage, 'payload does not decode as sensor_msgs/msg/JointState'),
             (fifo, 'not a regular file'), (tmp_path, 'needs metadata.yaml'),
             (cut, 'the file is truncated: only its complete chunks could be read')]
    for path, words in cases:
        for tool in (['umbrella_sim.tools.replay', str(path), '--resimulate'],
                     ['umbrella_sim.tools.compare', str(good), str(path), '--out',
                      str(tmp_path / 'out'), '--no-plots']) + (
                (['umbrella_sim.tools.replay', str(path)],) if path == cut else ()):
            r = run(*tool, timeout=60)
            assert r.returncode == 2, (tool, r.stdout, r.stderr)
            assert words in r.stderr and str(path) in r.stderr, (tool, r.stderr)
            assert 'Traceback' not in r.stderr
    for bad in ('nan', '-1', 'inf'):
        r = run('umbrella_sim.tools.replay', str(good), '--resimulate', '--tolerance', bad)
        assert r.returncode == 2 and '--tolerance' in r.stderr
    for option, value in (('--rate', '0'), ('--rate', '1e-12'), ('--start-offset', '1e300')):
        # (these overflowed: tracebacks)
        r = run('umbrella_sim.tools.replay', str(good), option, value)
        assert r.returncode == 2 and option in r.stderr and 'Traceback' not in r.stderr
    # republishing's options with --resimulate: refused, not ignored
    r = run('umbrella_sim.tools.replay', str(good), '--resimulate', '--rate', '2', '--topics',
            '/x')
    assert r.returncode == 2 and '--rate, --topics: options of republishing' in r.stderr
    # and --resimulate's option without it: refused, not ignored
    r = run('umbrella_sim.tools.replay', str(good), '--tolerance', '1e-6')
    assert r.returncode == 2 and '--tolerance: an option of --resimulate' in r.stderr


def test_binary_text_inputs_named(tmp_path):
    blob = tmp_path / 'blob.csv'
    blob.write_bytes(bytes(range(256)) * 4)
    r = run('umbrella_sim', 'simulate', '--force-profile', str(blob))
    assert r.returncode == 2 and str(blob) in r.stderr and 'binary' in r.stderr
    r = run('umbrella_sim', 'simulate', '--params', str(blob))
    assert r.returncode == 2 and str(blob) in r.stderr and 'Traceback' not in r.stderr


def test_log_messages_are_streamed_not_loaded(tmp_path):
    """Reading every message of a log holds about one chunk at a time, not the log."""
    import tracemalloc
    bag = tmp_path / 's'
    # 4 s: markers go out at 30 Hz, so a second of log is ~0.6 MB
    assert run('umbrella_sim', 'simulate', '--duration', '4.0', '--publish-rate', '1000',
               '--mcap', str(bag)).returncode == 0
    tracemalloc.start()
    log = read_log(str(bag))
    total = 0
    for m in log.iter_raw():
        total += len(m.data)
    for _ in log.iter_decoded('/markers'):
        pass
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert log.message_count == sum(log.count(t) for t in log.topics()) > 10_000
    assert total > 2_000_000
    assert peak < total / 4, (peak, total)


# ---------------------------------------------------- overload, peers, segments
@pytest.mark.ros
def test_overload_lag_bounded_by_re_anchoring(probe):
    probe.subscribe('/diagnostics', DiagnosticArray)
    with NodeProcess('-p', 'real_time_factor:=1000.0', '-p', 'elements_per_segment:=2') as node:
        node.wait_for_log('pacing re-anchored', timeout=30)
        msg = probe.wait_for('/diagnostics',
                             lambda m: int(diag_values(m)['re_anchors']) > 0, timeout=20)
    values = diag_values(msg)
    assert float(values['slip_s']) > MAX_LAG_S
    # the lag is measured once per publication and re-anchored past MAX_LAG_S: it exceeds
    # the bound by at most one publication's work
    assert float(values['lag_s']) < MAX_LAG_S + 1.0


@pytest.mark.ros
def test_two_nodes_in_one_namespace_are_warned():
    with NodeProcess('-p', 'v0:=0.0') as a, NodeProcess('-p', 'v0:=0.0') as b:
        a.wait_for_log('nodes named /umbrella_node|publishers on /clock', timeout=30)
        b.wait_for_log('nodes named /umbrella_node|publishers on /clock', timeout=30)


@pytest.mark.ros
@pytest.mark.slow
def test_reset_with_new_parameters_is_a_new_segment(tmp_path, probe):
    """
    Record a reset with new parameters as a new segment.

    Runtime parameter change + ~/reset while recording: the log holds two segments with
    their own parameters; --resimulate checks both, compare picks one; a flood of refused
    commands is counted but recorded at a bounded rate.
    """
    probe.subscribe('/deployment_phase', String, LATCHED)
    probe.subscribe('/diagnostics', DiagnosticArray)
    probe.subscribe('/joint_states', JointState)
    bag = tmp_path / 'segments'
    with NodeProcess('-p', 'v0:=-0.5', '-p', f'record_path:={bag}') as node:
        node.wait_for_log('locked at t', timeout=30)
        # keep-last 1000 on our side too: a reliable writer drops what its history cannot hold
        pub = probe.publisher('/sleeve_force', Float64, qos=1000)
        probe.wait_for_subscribers(pub)
        for _ in range(300):
            pub.publish(Float64(data=-1.0))
        # keep-all, reliable: none is lost, however fast they come (they queue)
        probe.wait_for('/diagnostics', lambda m: diag_values(m)['refused_commands'] == '300',
                       timeout=60)
        req = SetParameters.Request(parameters=[Parameter(
            name='v0', value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                            double_value=-1.0))])
        result = probe.call(SetParameters, '/umbrella_node/set_parameters', req)
        assert result.results[0].successful
        assert probe.call(Trigger, '/umbrella_node/reset', Trigger.Request()).success
        lock = float(node.wait_for_log(r'locked at t = ([0-9.]+) s', count=2,
                                       timeout=30).group(1))
        # the new segment runs 0.3 s of sim time past its lock (compare's stage-2 window)
        wait_for_stamp_in_last_run(probe, '/joint_states', lock + 0.3)
        assert node.stop() == 0
        out = node.output()
    assert 'recording segment 1' in out
    log = read_log(str(bag))
    segs = log.segments()
    assert [s.params['v0'] for s in segs] == [-0.5, -1.0]
    refused = log.count('/sleeve_force/refused')
    counts = log.metadata['umbrella_sim.counts']
    assert int(counts['commands_refused']) == 300
    assert refused + int(counts['refused_not_recorded']) == 300
    assert refused <= REFUSED_RECORD_RATE * 10
    times = [t for t, _ in log.decoded('/joint_states')]
    assert times == sorted(times)                   # log time never goes backwards
    r = run('umbrella_sim.tools.replay', str(bag), '--resimulate')
    assert r.returncode == 0 and '2 segments' in r.stdout, r.stdout + r.stderr
    # --info: each segment's run, and the lock is the last segment's (the events record's)
    info = run('umbrella_sim.tools.replay', str(bag), '--info').stdout
    assert 'segment 0:     model flexible' in info
    assert re.search(r'segment 1:     from log time [0-9.]+ s \(~/reset\): model flexible, '
                     r'1 element\(s\) a segment, v0 -1.0 m/s', info), info
    assert f'locked:        at t = {lock:.9f} s (energy lock) (segment 1, the last)' in info
    deploy = {}
    for k in (0, 1):
        out_dir = tmp_path / f'cmp{k}'
        r = run('umbrella_sim.tools.compare', str(bag), '--out', str(out_dir), '--no-plots',
                '--segment', str(k))
        assert r.returncode == 0, r.stderr
        run0 = json.loads((out_dir / 'compare.json').read_text())['runs'][0]
        deploy[k] = run0['deploy_time']
        # each segment's own summary record (segment 0's written at the reset)
        assert run0['figures']['figures_from'] == 'every physics step (recording metadata)'
    # the segments are the two runs, each as the offline simulator runs its parameters
    for k, seg in enumerate(segs):
        model = UmbrellaParams.from_mapping({n: v for n, v in seg.params.items() if n in SPECS})
        offline = simulate(model, 0.2, stop_after_lock=0.0)
        assert deploy[k] == pytest.approx(offline.lock.time, abs=1e-9), k
    with pytest.raises(LogError, match='no segment 2'):
        log.segment(2)


@pytest.mark.parametrize('model', ['flexible', 'rigid-fe', 'rigid', 'flexible-nonlinear'])
def test_a_frame_folding_back_to_the_axle_is_a_fault(model):
    """
    v0 > 0 folds the frame back; at alpha1 = pi/2 the leaf lies along the axle: a fault.

    It used to swing through and 'deploy' at the mirror image of the deployed shape
    (alpha1 = pi - alpha_deployed), reported as a lock. Every model stops at the same step
    (on one grid: time_step given), the last good state before it; the compiled and the
    numpy paths agree.
    """
    import math

    from umbrella_sim.core.driver import simulate
    from umbrella_sim.core.params import UmbrellaParams

    h = 1e-4
    params = UmbrellaParams(v0=0.5, model=model, lock='plastic', time_step=h)
    r = simulate(params, 0.05)
    assert r.lock is None and r.error is not None and 'reached the axle' in r.error
    last = r.samples[-1]                     # the last good state: one step short of it
    assert last.alpha1 < math.pi / 2 <= last.alpha1 + 1.5 * last.alpha1_rate * h
    reference = simulate(UmbrellaParams(v0=0.5, time_step=h), 0.05)   # rigid's instant
    assert r.samples[-1].time == reference.samples[-1].time


def test_a_braking_force_folding_the_frame_back_is_a_fault():
    from umbrella_sim.core.driver import simulate
    from umbrella_sim.core.params import UmbrellaParams

    r = simulate(UmbrellaParams(v0=0.0, sleeve_force_min=-10.0, sleeve_force=-5.0), 1.0)
    assert r.lock is None and 'reached the axle' in r.error


def test_a_stop_signal_inside_message_decoding_is_an_interrupt_not_a_bad_log(
        tmp_path, monkeypatch, capsys):
    """
    Ctrl-C while rclpy converts a message: an interrupt (130), not 'payload does not decode'.

    The signal's KeyboardInterrupt raised inside rclpy's C conversion came back as its own
    error ("Unable to convert function return value..."), which read as a corrupt log.  The
    reader says the payload does not decode; the tools, which know the signals, make it the
    interrupt it was.
    """
    from umbrella_sim.bag import reader as logs
    from umbrella_sim.ros import signals as stop_signals
    from umbrella_sim.tools import compare, replay

    bag = tmp_path / 'short'
    assert run('umbrella_sim', 'simulate', '--duration', '0.02', '--mcap',
               str(bag)).returncode == 0

    def interrupted(data, cls):
        stop_signals.received.append(signal.SIGINT)      # the handler ran in the conversion
        raise TypeError('Unable to convert function return value to a Python type!')
    monkeypatch.setattr(logs, 'deserialize_message', interrupted)
    for main, args in ((replay.main, [str(bag), '--resimulate']),
                       (compare.main, [str(bag), '--out', str(tmp_path / 'cmp'), '--no-plots'])):
        assert main(args) == 130
        err = capsys.readouterr().err
        assert 'interrupted by SIGINT' in err and 'does not decode' not in err, err

    def corrupt(data, cls):
        raise TypeError('Unable to convert function return value to a Python type!')
    monkeypatch.setattr(logs, 'deserialize_message', corrupt)
    log = read_log(str(bag))
    with pytest.raises(LogError, match='payload does not decode'):   # no signal: the log
        log.decode(log.find_topic('joint_states'), next(log.iter_raw()).data)
    assert replay.main([str(bag), '--resimulate']) == 2
    assert 'payload does not decode' in capsys.readouterr().err
