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
ament_copyright, as every ROS 2 package has it: each source file starts with the license.

Every Python and C file of the repository opens (after a shebang line) with the copyright
notice and the Apache License 2.0 header that package.xml's ``Apache-2.0`` and LICENSE name,
as ``ament_copyright --add-missing "umbrella_sim developers" apache2`` writes it.  The check
below holds that rule; ament_copyright itself runs too where it is installed (it is not on
PyPI: ``test_ament_copyright`` skips without it).  ``python -m tests.test_lint_copyright
--add-missing`` adds the header to the files that lack it.
"""
import os
import re
import sys

import pytest

from tests.test_lint import _paths, ROOT

HOLDER = 'umbrella_sim developers'
LICENSE_LINES = (
    'Licensed under the Apache License, Version 2.0 (the "License");',
    'you may not use this file except in compliance with the License.',
    'You may obtain a copy of the License at',
    '',
    '    http://www.apache.org/licenses/LICENSE-2.0',
    '',
    'Unless required by applicable law or agreed to in writing, software',
    'distributed under the License is distributed on an "AS IS" BASIS,',
    'WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.',
    'See the License for the specific language governing permissions and',
    'limitations under the License.',
)
EXTENSIONS = {'.py': '#', '.c': '//', '.h': '//'}


def _sources() -> list[str]:
    """Return every Python and C file of the linted paths."""
    out = []
    for path in _paths():
        if os.path.isfile(path):
            out.append(path)
            continue
        for dirpath, dirnames, files in os.walk(path):
            dirnames[:] = [d for d in dirnames if not d.startswith(('.', '_'))]
            out += [os.path.join(dirpath, f) for f in files
                    if os.path.splitext(f)[1] in EXTENSIONS]
    return sorted(out)


def header(path: str, year: int) -> str:
    """Return the comment block a file of this kind starts with."""
    mark = EXTENSIONS[os.path.splitext(path)[1]]
    lines = [f'Copyright {year} {HOLDER}', '', *LICENSE_LINES]
    return ''.join(f'{mark} {line}'.rstrip() + '\n' for line in lines)


def _split(text: str) -> tuple[str, str]:
    """Split a file's text into its shebang/coding lines and the rest."""
    lines = text.splitlines(keepends=True)
    n = 0
    while n < min(len(lines), 2) and re.match(r'#!|#.*coding[:=]', lines[n]):
        n += 1
    return ''.join(lines[:n]), ''.join(lines[n:])


def has_header(path: str, text: str) -> bool:
    """Tell whether a file's text starts (after a shebang) with the header, any year(s)."""
    first, _, body = _split(text)[1].lstrip('\n').partition('\n')
    mark = re.escape(EXTENSIONS[os.path.splitext(path)[1]])
    return (re.fullmatch(rf'{mark} Copyright \d{{4}}(-\d{{4}})? {re.escape(HOLDER)}', first)
            is not None and body.startswith(header(path, 0).partition('\n')[2]))


def test_every_source_file_starts_with_the_license_header():
    missing = []
    for path in _sources():
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
        if text.strip() and not has_header(path, text):      # (ament skips empty files)
            missing.append(os.path.relpath(path, ROOT))
    assert not missing, ('no Apache-2.0 copyright header (python -m tests.test_lint_copyright '
                         '--add-missing adds it):\n' + '\n'.join(missing))


@pytest.mark.linter
def test_ament_copyright(monkeypatch):
    main = pytest.importorskip('ament_copyright.main',
                               reason='ament_copyright is not installed (not on PyPI)').main
    monkeypatch.chdir(ROOT)
    assert main(argv=[os.path.relpath(p, ROOT) for p in _paths()]) == 0


def add_missing(year: int) -> list[str]:
    """Add the header to every source file that lacks it; return their paths."""
    added = []
    for path in _sources():
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
        if not text.strip() or has_header(path, text):
            continue
        head, rest = _split(text)
        with open(path, 'w', encoding='utf-8') as fh:
            fh.write(head + ('\n' if head else '') + header(path, year) + '\n'
                     + rest.lstrip('\n'))
        added.append(path)
    return added


if __name__ == '__main__':
    if sys.argv[1:] != ['--add-missing']:
        sys.exit('usage: python -m tests.test_lint_copyright --add-missing')
    import time

    for path in add_missing(int(time.strftime('%Y'))):
        print('added:', os.path.relpath(path, ROOT))
