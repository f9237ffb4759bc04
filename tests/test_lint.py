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
ament lint tests, as every ROS 2 Python package has them (ament_flake8, ament_pep257).

flake8 runs with ament_flake8's stock configuration, as a ROS package's test runs it (line
length 99, the google import order, flake8-builtins/-comprehensions/-class-newline/
-docstrings/-quotes with its single quotes); setup.cfg's [flake8] section is a copy of it for
a plain ``flake8``.  pep257 runs with ament_pep257's own "ament" convention, unchanged.  Each
test skips where its linter is not installed.  ``python -m tests.test_lint --single-quotes``
rewrites the one-line "strings" of every linted file with single quotes (flake8-quotes'
Q000; one holding a single quote keeps its double quotes, which spare the escaping).
"""
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# every Python file of the repository (ament's walk would also enter .venv and colcon's build/)
PATHS = ['umbrella_sim', 'tests', 'examples', 'bench', 'docs', 'launch', 'bootstrap.py',
         'setup.py']


def _paths():
    return [os.path.join(ROOT, p) for p in PATHS if os.path.exists(os.path.join(ROOT, p))]


@pytest.mark.flake8
@pytest.mark.linter
@pytest.mark.slow
def test_flake8(monkeypatch, tmp_path):
    flake8_main = pytest.importorskip('ament_flake8.main').main_with_errors
    monkeypatch.chdir(tmp_path)   # ament_flake8 walks the working directory for AMENT_IGNORE
    rc, errors = flake8_main(argv=_paths())           # its own configuration, as it ships
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    pep257_main = pytest.importorskip('ament_pep257.main').main
    rc = pep257_main(argv=_paths())
    assert rc == 0, 'Found code style errors / warnings (see the captured output)'


def _python_files() -> list[str]:
    out = []
    for path in _paths():
        if os.path.isfile(path):
            out.append(path)
        for dirpath, _, files in os.walk(path):
            out += [os.path.join(dirpath, f) for f in files if f.endswith('.py')]
    return sorted(out)


def single_quotes(text: str) -> str:
    """
    Return Python source with its one-line "strings" written with single quotes.

    Those without a single quote or an escaped double quote inside (flake8-quotes' Q000; the
    others keep double quotes, which spare the escaping); any prefix (r, b, f, rb...).
    Triple-quoted strings and docstrings are left as they are.
    """
    import io
    import tokenize

    lines = text.splitlines(keepends=True)
    edits = []
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type != tokenize.STRING or tok.start[0] != tok.end[0]:
            continue
        prefix = tok.string[:len(tok.string) - len(tok.string.lstrip('rRbBuUfF'))]
        body = tok.string[len(prefix):]
        if body[:3] in ('"""', "'''") or not (body.startswith('"') and body.endswith('"')):
            continue
        inner = body[1:-1]
        if "'" in inner or '\\"' in inner:
            continue
        edits.append((tok.start, tok.end[1], f"{prefix}'{inner}'"))
    for (row, col), end, new in reversed(edits):
        lines[row - 1] = lines[row - 1][:col] + new + lines[row - 1][end:]
    return ''.join(lines)


if __name__ == '__main__':
    if sys.argv[1:] != ['--single-quotes']:
        sys.exit('usage: python -m tests.test_lint --single-quotes')
    for path in _python_files():
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
        if single_quotes(text) != text:
            with open(path, 'w', encoding='utf-8') as fh:
                fh.write(single_quotes(text))
            print('rewritten:', os.path.relpath(path, ROOT))
