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


"""The console scripts' start: a Python without the dependencies says where they are."""
import os
import subprocess
import sys

import pytest

from umbrella_sim.ros import signals
from umbrella_sim.tools import entry

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize('tool, module', [('umbrella_sim', 'cli'),
                                          ('umbrella_replay', 'replay')])
def test_a_missing_dependency_names_itself_and_the_venv(monkeypatch, capsys, tool, module):
    """python3 outside the venv: exit 2 naming the module and the venv's tool, no traceback."""
    def no_numpy(name):
        raise ModuleNotFoundError("No module named 'numpy'", name='numpy')
    monkeypatch.setattr(entry.importlib, 'import_module', no_numpy)
    assert entry._offline_tool(module, tool) == 2
    err = capsys.readouterr().err
    assert f"{tool}: error: no module 'numpy'" in err and f'.venv/bin/{tool}' in err, err


def test_a_missing_module_of_our_own_is_not_hidden(monkeypatch):
    """A module that is not a dependency (our own code broken) still raises, as it is."""
    def broken(name):
        raise ModuleNotFoundError("No module named 'umbrella_sim.tools.gone'",
                                  name='umbrella_sim.tools.gone')
    monkeypatch.setattr(entry.importlib, 'import_module', broken)
    with pytest.raises(ModuleNotFoundError):
        entry._offline_tool('gone', 'umbrella_sim')


@pytest.mark.parametrize('tool, main', [('umbrella_node', 'node_main'),
                                        ('deploy_controller', 'controller_main')])
def test_once_a_node_s_main_has_returned_a_stop_signal_cannot_kill_its_exit(tool, main):
    """
    A second Ctrl-C, or a supervisor's SIGTERM after its SIGINT, during the teardown.

    CPython's teardown puts the default handlers back, and the node, its recording
    finalised, died of the signal there (exit 130 / 143 for a clean stop, 0.2 s after the
    first signal): once its main has returned the stop signals are ignored.
    """
    code = ('import signal, sys; from umbrella_sim.tools import entry; '
            f"sys.argv = ['{tool}', '--help']; status = entry.{main}(); "
            'print(status, [signal.getsignal(s) == signal.SIG_IGN '
            'for s in (signal.SIGINT, signal.SIGTERM)])')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=ROOT,
                       env=dict(os.environ, PYTHONPATH=ROOT), timeout=120)
    assert r.stdout.splitlines()[-1] == '0 [True, True]', (r.stdout[-300:], r.stderr)


WATCHER = """
import sys, threading
from umbrella_sim.ros import signals
signals.install()
stopped = threading.Event()
signals.add_listener(lambda signum: stopped.set())
signals.stop_with(sys.argv[1])
print('watching', flush=True)
print(signals.name(signals.received[0]) if stopped.wait(60) else 'no stop', flush=True)
"""


def test_a_node_takes_the_end_of_the_process_that_started_it_as_a_stop():
    """
    A test runner killed with no cleanup (a CI timeout) must not leave its nodes running.

    The watched process ends, and is not reaped yet (a zombie, as a killed runner stays
    until its own parent waits for it): the watcher sends itself SIGTERM, the stop request
    the node acts on.
    """
    holder = subprocess.Popen([sys.executable, '-c', 'import sys; sys.stdin.read()'],
                              stdin=subprocess.PIPE)
    watcher = subprocess.Popen([sys.executable, '-c', WATCHER, str(holder.pid)],
                               stdout=subprocess.PIPE, text=True, cwd=ROOT,
                               env=dict(os.environ, PYTHONPATH=ROOT))
    try:
        assert watcher.stdout.readline() == 'watching\n'
        assert signals.process_alive(holder.pid)
        holder.stdin.close()                # the holder ends; not reaped: a zombie
        out, _ = watcher.communicate(timeout=60)
        assert not signals.process_alive(holder.pid)
        assert out.split() == ['SIGTERM'], out
    finally:
        holder.wait()
        if watcher.poll() is None:
            watcher.kill()
            watcher.wait()


def test_a_bad_stop_with_variable_names_itself(monkeypatch, capsys):
    monkeypatch.setenv(signals.STOP_WITH_ENV, 'parent')
    monkeypatch.setattr(signals, 'install', lambda: None)   # (this process's handlers kept)
    monkeypatch.setattr(signals, 'ignore_from_now', lambda: None)
    assert entry.node_main() == 2
    assert f"{signals.STOP_WITH_ENV}='parent'" in capsys.readouterr().err


def test_a_missing_ros_package_outside_a_checkout_names_the_ros_extra(monkeypatch, capsys):
    """A pip install of the package into a user's venv brings no ROS 2 package: say how."""
    def no_rclpy(name):
        raise ModuleNotFoundError("No module named 'rclpy'", name='rclpy')
    monkeypatch.setattr(entry.importlib, 'import_module', no_rclpy)
    monkeypatch.setattr(entry, 'checkout', lambda: None)     # installed, no bootstrap.py
    assert entry.node_main() == 2
    err = capsys.readouterr().err
    assert "umbrella_node: error: no module 'rclpy'" in err, err
    assert "pip install 'umbrella_sim[ros]'" in err and 'bootstrap.py' not in err, err


def test_the_test_api_without_rclpy_says_how_to_install_it():
    """Importing umbrella_sim.testing where rclpy is missing: the error says what to install."""
    code = "import sys; sys.modules['rclpy'] = None; import umbrella_sim.testing"
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=ROOT,
                       env=dict(os.environ, PYTHONPATH=ROOT), timeout=120)
    assert r.returncode == 1
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("ModuleNotFoundError: umbrella_sim.testing: no module 'rclpy'"), last
    assert "pip install 'umbrella_sim[ros]'" in last, last
