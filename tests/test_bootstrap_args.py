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


"""`bootstrap.py`: the relative paths of the node and of pytest are the caller's; its notes."""
import os

from bootstrap import node_paths
import pytest


def test_relative_paths_are_the_working_directorys(tmp_path, monkeypatch):
    """The node runs in the runs directory; a user's relative path means their directory."""
    monkeypatch.chdir(tmp_path)
    args = ['-p', 'ribs:=6', '--params-file', 'six.yaml', '-p', 'record_path:=bags/a',
            '-p', 'v0:=-0.5', '--params-file', '/etc/abs.yaml', '-p', 'record_path:=/x/y']
    assert node_paths(args) == [
        '-p', 'ribs:=6', '--params-file', os.path.join(str(tmp_path), 'six.yaml'),
        '-p', f'record_path:={tmp_path}/bags/a', '-p', 'v0:=-0.5',
        '--params-file', '/etc/abs.yaml', '-p', 'record_path:=/x/y']
    # no path, nothing changed (record_path:= empty: the node's own naming)
    assert node_paths(['-p', 'record_path:=', '-p', 'duration:=2.0']) == [
        '-p', 'record_path:=', '-p', 'duration:=2.0']


def test_a_leading_tilde_is_the_home_directory(tmp_path, monkeypatch):
    """
    record_path:=~/bags records under the home directory, as the node takes it.

    A shell leaves that ~ as it is (it follows ':='); made the working directory's, the node
    recorded into a directory named '~' there.
    """
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv('HOME', str(tmp_path / 'home'))
    home = str(tmp_path / 'home')
    assert node_paths(['-p', 'record_path:=~/bags/a', '--params-file', '~/six.yaml']) == [
        '-p', f'record_path:={home}/bags/a', '--params-file', f'{home}/six.yaml']


def test_the_suite_note_says_what_the_readme_says(monkeypatch, capsys):
    """`bootstrap.py test` announces the README's duration of the whole suite and fast subset."""
    import re

    import bootstrap

    ran = []
    monkeypatch.setattr(bootstrap, 'setup', lambda: None)
    monkeypatch.setattr(bootstrap, 'run_tests', lambda commands, cwd, env: ran.append(commands))
    bootstrap.main(['test'])
    assert len(ran) == 1
    note = capsys.readouterr().out
    with open(os.path.join(os.path.dirname(bootstrap.__file__), 'README.md'),
              encoding='utf-8') as fh:
        readme = ' '.join(fh.read().split())
    quiet = r'~(\d+) min on a quiet 2-core machine'
    assert re.search(quiet, note)[1] == re.search(quiet, readme)[1], (note, readme)
    fast = re.search(r'python3 bootstrap\.py test -m "[^"]+" -n \d', note)[0]
    assert f'`{fast}`' in readme, fast


def test_a_test_file_given_is_what_pytest_runs(tmp_path, monkeypatch):
    """
    `bootstrap.py test tests/test_modes.py` runs that file, not the whole suite beside it.

    The paths are the working directory's (pytest runs in the repository), a node id is kept,
    an option's value that names a file (--ignore) stays a value, and without a path the
    suite's tests/ and examples/ are the paths, as before.
    """
    import bootstrap

    ran = []
    monkeypatch.setattr(bootstrap, 'setup', lambda: None)
    monkeypatch.setattr(bootstrap, 'run_tests', lambda commands, cwd, env: ran.append(commands))
    (tmp_path / 'mine').mkdir()
    for name in ('test_a.py', 'test_b.py'):
        (tmp_path / 'mine' / name).write_text('')
    monkeypatch.chdir(tmp_path)
    bootstrap.main(['test', 'mine/test_a.py::test_one', '-q', '--ignore', 'mine/test_b.py',
                    '-k', 'one'])
    (command,), = ran
    assert command[command.index('pytest') + 1:] == [
        '-q', f'{tmp_path}/mine/test_a.py::test_one', '-q', '--ignore', 'mine/test_b.py',
        '-k', 'one']
    ran.clear()
    bootstrap.main(['test', 'mine'])
    assert ran[0][0][-1] == f'{tmp_path}/mine'
    assert os.path.join(bootstrap.ROOT, 'tests') not in ran[0][0]
    ran.clear()
    bootstrap.main(['test', '-m', 'not ros and not slow', '-n', '2'])
    (command,), = ran
    assert command[-6:] == [os.path.join(bootstrap.ROOT, 'tests'),
                            os.path.join(bootstrap.ROOT, 'examples'),
                            '-m', 'not ros and not slow', '-n', '2']


def test_an_unknown_command_is_named(monkeypatch, capsys):
    """A misspelt command (`bootstrap.py rn`) says which word it did not take, exit 2."""
    import bootstrap

    monkeypatch.setattr(bootstrap, 'setup', lambda: pytest.fail('set up for a bad command'))
    assert bootstrap.main(['rn']) == 2
    err = capsys.readouterr().err
    assert err.rstrip().endswith("bootstrap.py: unknown command 'rn': give run, test or setup")
    assert bootstrap.main([]) == 2
    assert 'bootstrap.py: no command' in capsys.readouterr().err
