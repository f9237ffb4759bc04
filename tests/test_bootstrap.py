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
Test the README's main command, `python3 bootstrap.py run`.

It runs the node on the default config,
records MCAP, and a signal sent to the bootstrap process (not only Ctrl-C in a terminal, which
reaches the whole process group) stops the node cleanly with a finalised recording.
"""
import os
import re
import signal
import subprocess
import sys
import time

from bootstrap import ROOT, STAMP_NAME
import pytest
from sensor_msgs.msg import JointState
from tests.ros_helpers import Probe, ros_env, stamp
from umbrella_sim.bag.reader import read_log

STAMP = os.path.join(sys.prefix, STAMP_NAME)
pytestmark = pytest.mark.ros


@pytest.mark.skipif(not os.path.exists(STAMP),
                    reason='not running in a venv made by bootstrap.py (CI always is)')
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_main_command_records_and_forwards_signals(tmp_path, sig):
    # a relative runs directory is the caller's working directory's, as the user means it
    # (the node runs in the repository: it failed there, "parent directory ... does not exist")
    env = dict(ros_env(), UMBRELLA_VENV=sys.prefix, UMBRELLA_RUNS_DIR='runs')
    out = tmp_path / 'bootstrap.log'
    probe = Probe('bootstrap_probe')
    probe.subscribe('/joint_states', JointState)
    with open(out, 'w') as fh:
        proc = subprocess.Popen([sys.executable, os.path.join(ROOT, 'bootstrap.py'), 'run'],
                                stdout=fh, stderr=subprocess.STDOUT, env=env,
                                start_new_session=True, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 60
        while 'locked at t' not in out.read_text() and proc.poll() is None:
            assert time.monotonic() < deadline, out.read_text()
            time.sleep(0.1)
        lock = float(re.search(r'locked at t = ([0-9.]+) s', out.read_text()).group(1))
        # the node runs on, recording, for 0.5 s of sim time past the lock
        probe.wait_for('/joint_states', lambda m: stamp(m) > lock + 0.5, timeout=60,
                       what=f'a state past {lock + 0.5:.6f} s')
        proc.send_signal(sig)                 # to bootstrap.py alone
        assert proc.wait(30) == 0, out.read_text()
    finally:
        probe.close()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    text = out.read_text()
    assert 'recording finalised' in text and '[ERROR]' not in text, text
    (run,) = (tmp_path / 'runs').iterdir()
    # the node's own (rosbag2's) naming, the one convention: umbrella_YYYY_MM_DD-HH_MM_SS
    assert re.fullmatch(r'umbrella_\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d(_\d+)?', run.name), run.name
    log = read_log(str(run))
    assert not log.truncated
    # the closing line says how to read the run's figures, and that command works
    hint = re.search(r'its figures: umbrella_compare (\S+) --out (\S+)\)', text)
    assert hint and os.path.samefile(hint.group(1), run), text
    compare = subprocess.run([os.path.join(sys.prefix, 'bin', 'umbrella_compare'),
                              hint.group(1), '--out', hint.group(2), '--no-plots'],
                             capture_output=True, text=True, timeout=120)
    assert compare.returncode == 0 and 'deploy' in compare.stdout, compare.stderr
    # every joint_states publication of the run is in the file: the default 100 Hz over the
    # simulated time recorded (the node may run behind real time on a busy machine)
    stamps = [t for t, _ in log.decoded('/joint_states')]
    assert stamps[-1] > 0.15                      # past the lock (t ~ 0.19 s)
    assert len(stamps) >= int(100 * (stamps[-1] - stamps[0])) - 1
