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
The reliability suite, continued: the command lines under OS errors and careless input.

* A deleted working directory: every output given as a relative path (simulate --csv and
  --mcap, sweep --out, compare --out) and the node's default recording directory give one
  line naming the option and the path, exit 2, before any work (os.path.abspath raised
  FileNotFoundError: a traceback).
* A closed output pipe (``umbrella_node --help | true``): no BrokenPipeError traceback.
* A full disk under ``umbrella_sim simulate --mcap``: the error names ``--mcap`` and its path.
* Bad files: plain ``umbrella_replay`` skips and names payloads that do not decode (it
  republished them, exit 0), as --resimulate refuses them.
* Careless settings: ``--duration 1e9`` needs ``--long-run`` (a sweep's cases, ``long_run:
  true``); ``--csv X --mcap X`` is refused
  before any step; ``sweep --out`` that cannot be made does not claim results were kept; a
  large sweep's checking reports its progress and reads the params file once.

tests/test_reliability.py holds the long periods, the command bursts, the runtime refusals and
the damaged recordings.
"""
import errno
import os
import subprocess
import sys

from mcap.writer import Writer
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from tests.ros_helpers import ros_env
from umbrella_sim.bag import cdr
from umbrella_sim.bag.reader import LogError, read_log
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.ros import params_file
from umbrella_sim.ros.pacing import behind_text
from umbrella_sim.ros.recording import record_offline
from umbrella_sim.tools import inputs, sweep_spec

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = dict(ros_env(), PYTHONPATH=ROOT)


def python(code: str, *args: str, cwd=None, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-c', code, *args], capture_output=True, text=True,
                          cwd=cwd or ROOT, env=ENV, timeout=timeout)


@pytest.fixture(scope='module')
def small_bag(tmp_path_factory):
    """Record 0.1 s offline; return its bag directory."""
    bag = tmp_path_factory.mktemp('bags') / 'run'
    record_offline(UmbrellaParams(v0=-0.5), str(bag), 0.1)
    return bag


# ------------------------------------------------------------ a deleted working directory
#: runs a module as its console script would, from a working directory it first deletes
IN_DELETED_CWD = ('import os, runpy, sys; os.rmdir(os.getcwd()); '
                  "sys.argv = sys.argv[1:]; runpy.run_module(sys.argv[0], run_name='__main__')")


@pytest.mark.parametrize('args, option', [
    (['umbrella_sim', 'simulate', '--duration', '0.01', '--csv', 'out.csv'], '--csv out.csv'),
    (['umbrella_sim', 'simulate', '--duration', '0.01', '--mcap', 'bag'], '--mcap bag'),
    (['umbrella_sim', 'sweep', '--out', 'sw', 'SPEC'], '--out sw'),
    (['umbrella_sim.tools.compare', '--out', 'cmp', '--no-plots', 'BAG', 'BAG'], '--out cmp'),
])
def test_a_deleted_working_directory_is_one_line_naming_the_path(
        args, option, tmp_path, small_bag):
    """A relative output in a deleted working directory: exit 2 naming it, no traceback."""
    spec = tmp_path / 'spec.yaml'
    spec.write_text('grid:\n  v0: [-1.0]\nduration: 0.01\n')
    args = [{'SPEC': str(spec), 'BAG': str(small_bag)}.get(a, a) for a in args]
    gone = tmp_path / 'gone'
    gone.mkdir()
    r = python(IN_DELETED_CWD, *args, cwd=gone)
    assert r.returncode == 2, r.stderr
    assert 'Traceback' not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and option in lines[0], r.stderr
    assert 'the working directory no longer exists' in lines[0]


@pytest.mark.ros
def test_the_node_recording_in_a_deleted_working_directory_says_so(tmp_path):
    """umbrella_node records in its working directory by default: gone, exit 2 naming it."""
    gone = tmp_path / 'gone'
    gone.mkdir()
    r = python(IN_DELETED_CWD, 'umbrella_sim.node', '--ros-args', '-p', 'record:=true',
               cwd=gone)
    assert r.returncode == 2, r.stderr
    assert 'Traceback' not in r.stderr, r.stderr
    assert ("umbrella_node: error: record_path '' (a new bag in the working directory): the "
            'working directory no longer exists') in r.stderr, r.stderr


# ------------------------------------------------------------------ a closed output pipe
@pytest.mark.parametrize('module', ['umbrella_sim.node', 'umbrella_sim.deploy_controller',
                                    'umbrella_sim'])
def test_help_into_a_closed_pipe_is_not_a_traceback(module):
    """``umbrella_node --help | true``: the reader is gone before the text is written."""
    proc = subprocess.Popen([sys.executable, '-m', module, '--help'], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=ROOT, env=ENV)
    proc.stdout.close()             # before the child has imported anything
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert proc.wait(timeout=120) in (0, 141), err
    assert 'Traceback' not in err and 'BrokenPipe' not in err, err


# ------------------------------------------------------------------ a full disk
FULL_DISK_SIMULATE = ('import errno, os, sys; from tests.disk_faults import full_disk_write; '
                      'os.write = full_disk_write(int(sys.argv[1]), errno.ENOSPC); '
                      'from umbrella_sim.tools.cli import main; '
                      "sys.exit(main(['simulate', '--duration', sys.argv[2], '--mcap', "
                      'sys.argv[3]]))')


@pytest.mark.parametrize('room, duration, status, words', [
    (100, '0.1', 2, 'cannot start the recording: ' + os.strerror(errno.ENOSPC)),
    (5000, '1.0', 4, 'output incomplete: --mcap'),
])
def test_simulate_on_a_full_disk_names_mcap(tmp_path, room, duration, status, words):
    """The disk fills at the start or during the run: --mcap and its path are named."""
    bag = tmp_path / 'bag'
    r = python(FULL_DISK_SIMULATE, str(room), duration, str(bag))
    assert r.returncode == status, r.stderr
    assert words in r.stderr and f'--mcap {bag}' in r.stderr, r.stderr
    assert 'record_path' not in r.stderr and 'Traceback' not in r.stderr, r.stderr
    if status == 4:     # the run finished: its summary is printed whole
        assert 'deploy_time' in r.stdout


# ------------------------------------------------------------------ bad files
@pytest.mark.ros
def test_replay_skips_and_names_payloads_that_do_not_decode(tmp_path, small_bag):
    """Two of five joint_states do not decode: the three others go out, exit 2 naming it."""
    bag = tmp_path / 'mixed.mcap'
    parameters = read_log(str(small_bag)).metadata['umbrella_sim.parameters']
    with open(bag, 'wb') as fh:
        w = Writer(fh)
        w.start('ros2', 'test')
        sid = w.register_schema('sensor_msgs/msg/JointState', 'ros2msg',
                                cdr.message_definition('sensor_msgs/msg/JointState').encode())
        cid = w.register_channel('/joint_states', 'cdr', sid)
        w.add_metadata('umbrella_sim.parameters', parameters)
        for i in range(5):
            payload = (b'\x00\x01\x00\x00\xff\xff\xff\x7f' if i in (1, 3)
                       else serialize_message(JointState(name=['leaf_hinge'], position=[i])))
            w.add_message(cid, i * 10**7, payload, i * 10**7)
        w.finish()
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.tools.replay', str(bag),
                        '--rate', '100'], capture_output=True, text=True, cwd=ROOT, env=ENV,
                       timeout=120)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert 'replayed 3 messages' in r.stdout, r.stdout
    assert (f'umbrella_replay: skipped: {bag}: topic /joint_states message 1 (log time '
            '10000000 ns): payload does not decode as sensor_msgs/msg/JointState') in r.stderr
    assert 'umbrella_replay: error: 2 message(s) skipped' in r.stderr, r.stderr
    assert 'Traceback' not in r.stderr


def test_a_recording_cut_before_its_channels_says_it_is_truncated(tmp_path, small_bag):
    """Its first records (the parameters) are whole, the next one torn: not 'empty'."""
    log = read_log(str(small_bag))
    cut = tmp_path / 'cut.mcap'
    with open(log.path, 'rb') as fh:
        cut.write_bytes(fh.read(2000))      # (the parameters whole, the first schema not)
    with pytest.raises(LogError) as err:
        read_log(str(cut))
    assert str(err.value) == (f'{cut}: no channels (the file is truncated: it ends after 2000 '
                              'bytes, before its first channel record)')
    magic = tmp_path / 'magic.mcap'
    with open(log.path, 'rb') as fh:
        magic.write_bytes(fh.read(8))
    with pytest.raises(LogError, match='ends after 8 bytes'):
        read_log(str(magic))


def _damaged_copy(bag, to, which: int):
    """Copy bag's .mcap to `to`, a metadata record's map length overwritten (which: 0, -1)."""
    data = bytearray(open(read_log(str(bag)).path, 'rb').read())
    at, metadata = 8, []
    while data[at] != 0x0f:                     # the records up to DataEnd
        if data[at] == 0x0c:
            metadata.append(at)
        at += 9 + int.from_bytes(data[at + 1:at + 9], 'little')
    at = metadata[which]
    name_length = int.from_bytes(data[at + 9:at + 13], 'little')
    data[at + 13 + name_length:at + 17 + name_length] = b'\xff' * 4
    to.write_bytes(bytes(data))
    return to


def test_a_finished_recording_damaged_in_its_middle_says_so(tmp_path, small_bag):
    """Its footer and end magic are there: the reader stops at the bad record, and says why."""
    from umbrella_sim.tools.replay_info import info_text

    log = read_log(str(_damaged_copy(small_bag, tmp_path / 'late.mcap', -1)))
    assert log.truncated and log.damaged
    text = info_text(log)
    assert '(damaged: only the records before one that does not parse read)' in text, text
    assert 'truncated' not in text
    assert 'damaged' in log.truncation_note() and log.cut_short == 'damaged log'
    first_channel = 'the file is damaged: a record before its first channel does not parse'
    with pytest.raises(LogError, match=first_channel):
        read_log(str(_damaged_copy(small_bag, tmp_path / 'early.mcap', 0)))
    cut = tmp_path / 'cut.mcap'                 # a cut file is truncated, not damaged
    cut.write_bytes(open(log.path, 'rb').read()[:-100])
    cut_log = read_log(str(cut))
    assert cut_log.truncated and not cut_log.damaged and cut_log.cut_short == 'truncated log'


# ------------------------------------------------------------------ careless settings
def cli(*args, cwd, timeout=120):
    return subprocess.run([sys.executable, '-m', 'umbrella_sim', *args], capture_output=True,
                          text=True, cwd=cwd, env=ENV, timeout=timeout)


def test_a_run_of_years_needs_consent(tmp_path):
    """``--duration 1e9`` (5 x 10^12 steps) is refused before any step; --long-run consents."""
    r = cli('simulate', '--duration', '1e9', '--csv', 'run.csv', cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert '--duration 1e+09: 5e+12 physics steps' in r.stderr and '--long-run' in r.stderr
    assert not os.listdir(tmp_path)                 # nothing written
    r = cli('simulate', '--duration', '0.01', '--long-run', cwd=tmp_path)
    assert r.returncode == 0, r.stderr              # (a short run needs no consent)


def test_a_sweep_of_cases_of_years_needs_consent(tmp_path):
    """A spec whose duration is 10^13 steps a case: refused unless it says long_run: true."""
    spec = tmp_path / 'spec.yaml'
    grid = 'base: {model: rigid}\ngrid:\n  v0: [-1.0, -2.0]\nduration: 1.0e9\n'
    spec.write_text(grid)
    with pytest.raises(sweep_spec.SpecError, match=r'case 1 .*duration 1e\+09: 1e\+13 physics '
                       r'steps .*give long_run: true'):
        sweep_spec.load_spec(str(spec))
    spec.write_text(grid + 'long_run: true\n')
    assert len(sweep_spec.load_spec(str(spec)).cases) == 2
    spec.write_text(grid + 'long_run: yes please\n')
    with pytest.raises(sweep_spec.SpecError, match='long_run: expected true or false'):
        sweep_spec.load_spec(str(spec))


def test_one_path_for_csv_and_mcap_is_refused_before_the_run(tmp_path):
    """--csv X --mcap X: exit 2 at once, nothing created (it ran the whole simulation first)."""
    r = cli('simulate', '--duration', '1e3', '--csv', 'X', '--mcap', 'X', cwd=tmp_path,
            timeout=60)
    assert r.returncode == 2 and '--csv and --mcap name the same path X' in r.stderr, r.stderr
    assert not os.listdir(tmp_path)


@pytest.mark.slow
def test_a_sweep_out_that_cannot_be_made_keeps_nothing_and_says_so(tmp_path):
    """--out under /proc: the error says no result was kept (it said every case was)."""
    spec = tmp_path / 'spec.yaml'
    spec.write_text('base: {model: rigid}\ngrid:\n  v0: [-1.0]\nduration: 0.01\n')
    r = cli('sweep', '--out', '/proc/umbrella_sweep', '--workers', '1', str(spec),
            cwd=tmp_path, timeout=300)
    assert r.returncode in (2, 4), r.stderr
    assert 'no case result was kept' in r.stderr or '--out /proc' in r.stderr, r.stderr
    assert 'finished before it are kept' not in r.stderr and 'Traceback' not in r.stderr


def test_a_large_sweep_reports_its_checking_and_reads_the_params_file_once(tmp_path,
                                                                           monkeypatch):
    """Each case read the params file anew (10^6 cases: hours, silent); now once, reported."""
    monkeypatch.setattr(sweep_spec, 'CHECK_PROGRESS_CASES', 10)
    reads = []
    load = params_file.load_params_file

    def counted(path, *args, **kwargs):
        reads.append(path)
        return load(path, *args, **kwargs)

    monkeypatch.setattr(params_file, 'load_params_file', counted)   # (sweep_spec's import)
    monkeypatch.setattr(inputs, 'load_params_file', counted)
    spec = tmp_path / 'spec.yaml'
    spec.write_text('base: {model: rigid}\nduration: 0.01\ngrid:\n'
                    '  v0: [-1.0, -1.1, -1.2, -1.3, -1.4]\n  l1: [0.30, 0.31, 0.32, 0.33]\n')
    seen = []
    sweep = sweep_spec.load_spec(str(spec), progress=lambda done, total: seen.append(
        (done, total)))
    assert len(sweep.cases) == 20
    assert seen and seen[-1] == (20, 20) and all(t == 20 for _, t in seen)
    assert len(reads) == 1, reads


# ------------------------------------------------------------------ status texts
def test_behind_real_time_says_how_far_and_whether_it_is_catching_up():
    """A run 0.3 s behind but going at 1.064x of 1x was 'measured 1.064x of 1x' (behind?)."""
    assert behind_text(0.3, 1.064, 1.0) == ('behind real time by 0.300 s (catching up: '
                                            '1.064x of 1x over the last second)')
    assert 'falling behind: 0.500x of 1x' in behind_text(0.3, 0.5, 1.0)
    assert 'keeping pace: 2.000x of 2x' in behind_text(0.3, 2.0004, 2.0)
