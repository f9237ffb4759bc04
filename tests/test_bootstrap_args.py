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


"""The node's arguments after `bootstrap.py run`: relative paths are the caller's."""
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
