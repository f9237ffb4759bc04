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
