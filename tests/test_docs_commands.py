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
The command lines of the README and msg_docs, as a ROS user types them, and the code they name.

They run from a colcon workspace root, where the source tree's relative paths do not
exist: every file they hand to the node is the installed one, found through the ament
index (``$(ros2 pkg prefix --share umbrella_sim)/...``), and setup.py installs it there.
Every module, function or class (``umbrella_sim.bag.reader.read_log``) and every source file
(``umbrella_sim/core/forcing.py``) the README, msg_docs and docs name exists.
"""
import glob
import os
import shlex

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARE = '$(ros2 pkg prefix --share umbrella_sim)/'


def _documented_command_lines() -> list[tuple[str, str]]:
    """Return (file, command) of every indented command line, continuations joined."""
    out = []
    for path in [os.path.join(ROOT, 'README.md'),
                 *sorted(glob.glob(os.path.join(ROOT, 'msg_docs', '*.md')))]:
        with open(path, encoding='utf-8') as fh:
            text = fh.read().replace('\\\n', ' ')
        out += [(os.path.relpath(path, ROOT), line.strip()) for line in text.splitlines()
                if line.startswith('    ') and line.split()
                and line.split()[0] in ('ros2', 'umbrella_node', 'deploy_controller')]
    return out


def setup_distribution():
    """
    Return setup.py's Distribution, as setuptools reads it (nothing is built).

    setup.py runs with setuptools.setup replaced by a recorder of its arguments, which then
    make a setuptools Distribution: setuptools' private ``run_setup`` failed under a system
    Python whose stdlib still ships distutils (Debian's 3.11: 'MinimalDistribution' object has
    no attribute 'set_defaults').
    """
    import runpy
    from unittest import mock

    import setuptools
    from setuptools.dist import Distribution

    arguments = {}
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        with mock.patch.object(setuptools, 'setup', lambda **kw: arguments.update(kw)):
            runpy.run_path('setup.py', run_name='__main__')
    finally:
        os.chdir(cwd)
    return Distribution(arguments)


def _installed_share_files() -> set[str]:
    """Return the files setup.py installs under share/umbrella_sim/, relative to it."""
    dist = setup_distribution()
    share = 'share/umbrella_sim'
    return {os.path.join(target[len(share):].lstrip('/'), os.path.basename(f))
            for target, files in dist.data_files if target.startswith(share) for f in files}


def test_every_documented_params_file_is_the_installed_one():
    commands = _documented_command_lines()
    given = [(where, words[i + 1]) for where, line in commands
             for words in [shlex.split(line.replace(SHARE, '@SHARE@/'))]
             for i, w in enumerate(words[:-1]) if w == '--params-file']
    assert given, 'no documented --params-file (the README and msg_docs show one)'
    installed = _installed_share_files()
    assert 'config/umbrella.yaml' in installed, sorted(installed)
    prefix = '@SHARE@/'
    for where, path in given:
        assert path.startswith(prefix), (
            f'{where}: --params-file {path} exists only in the source tree; give '
            f"'{SHARE}...' so the command works from a workspace root")
        assert path[len(prefix):] in installed, (where, path, sorted(installed))
        assert os.path.exists(os.path.join(ROOT, path[len(prefix):])), (where, path)


def _markdown_pages() -> list[str]:
    """Return the README and every page of msg_docs/ and docs/ (paths from the root)."""
    return ['README.md'] + [os.path.relpath(p, ROOT) for folder in ('msg_docs', 'docs')
                            for p in sorted(glob.glob(os.path.join(ROOT, folder, '*.md')))]


def _resolves(dotted: str) -> bool:
    """Return whether a dotted name is a module of the package or an attribute of one."""
    import importlib

    parts = dotted.split('.')
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            if not hasattr(obj, part):
                return False
            obj = getattr(obj, part)
        return True
    return False


def test_every_module_and_source_file_the_docs_name_exists():
    """
    Each umbrella_sim.x.y name of the markdown imports, each umbrella_sim/... path exists.

    A recording's metadata records are named like modules (umbrella_sim.summary,
    umbrella_sim.segment.K): those the bag format defines are not modules.  A path under an
    install prefix (share/umbrella_sim/launch) is not the source tree's.
    """
    import re

    from umbrella_sim.bag import format as bag_format

    records = {value for name, value in vars(bag_format).items()
               if name.endswith('_RECORD') and isinstance(value, str)}
    missing = []
    for page in _markdown_pages():
        with open(os.path.join(ROOT, page), encoding='utf-8') as fh:
            text = fh.read()
        for name in set(re.findall(r'(?<![\w./])umbrella_sim(?:\.\w+)+', text)):
            if re.sub(r'\.(K|\d+)$', '', name) not in records and not _resolves(name):
                missing.append((page, name))
        for path in set(re.findall(r'(?<![\w./-])umbrella_sim/[\w./]*\w', text)):
            if not os.path.exists(os.path.join(ROOT, path)):
                missing.append((page, path))
    assert not missing, f'named in the docs, not in the package: {sorted(missing)}'
