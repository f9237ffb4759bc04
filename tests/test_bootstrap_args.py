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


"""`bootstrap.py`: the node's relative paths are the caller's; its note on the test suite."""
import os

from bootstrap import node_paths


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
