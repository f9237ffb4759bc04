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
Parameter tables of msg_docs/, generated from the registry (core.registry.REGISTRY).

    .venv/bin/python -m umbrella_sim.tools.param_docs          # rewrite the tables in place
    .venv/bin/python -m umbrella_sim.tools.param_docs --check  # exit 1 if a page is stale

Each page keeps its prose; only the text between ``<!-- BEGIN GENERATED: GROUP -->`` and
``<!-- END GENERATED: GROUP -->`` is replaced (GROUP: model, input, node or controller).
"""
from __future__ import annotations

import argparse
import os
import re
import sys

from ..core.registry import NOW, REGISTRY, RESET, START
from ..ros.share import package_path

PAGES = ('parameters.md', 'node_parameters.md', 'deploy_controller.md')
_APPLIES = {RESET: 'on `~/reset`', NOW: 'at once', START: 'read-only (at start)'}
_BLOCK = re.compile(r'(<!-- BEGIN GENERATED: (\w+) -->\n).*?(<!-- END GENERATED: \2 -->)',
                    re.S)


def _cell(text: str) -> str:
    return text.replace('|', '\\|')


def table(group: str) -> str:
    """Return the markdown table of one parameter group."""
    rows = ['| name | type | unit | default | range | applies | meaning |',
            '|---|---|---|---|---|---|---|']
    for p in REGISTRY.values():
        if p.group != group:
            continue
        rng = _cell(p.range_text()) + (f'; {_cell(p.rule)}' if p.rule else '')
        rows.append(f'| `{p.name}` | {p.type_name} | {p.unit} | {_cell(p.default_str)} | '
                    f'{rng} | {_APPLIES[p.applies]} | {_cell(p.doc)} |')
    return '\n'.join(rows) + '\n'


def render(text: str) -> str:
    """Return the page text with every generated block rebuilt from the registry."""
    return _BLOCK.sub(lambda m: m.group(1) + table(m.group(2)) + m.group(3), text)


def msg_docs_dir() -> str:
    """Return the msg_docs/ directory the tables are written in (the source checkout's)."""
    return package_path('msg_docs') or 'msg_docs'


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description='Regenerate the parameter tables of msg_docs/.')
    ap.add_argument('--check', action='store_true', help='only report stale pages')
    ap.add_argument('--dir', default=msg_docs_dir(), help='the msg_docs directory')
    args = ap.parse_args(argv)
    stale = []
    for page in PAGES:
        path = os.path.join(args.dir, page)
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
        new = render(text)
        if new != text:
            stale.append(path)
            if not args.check:
                with open(path, 'w', encoding='utf-8') as fh:
                    fh.write(new)
    for path in stale:
        print(('out of date: ' if args.check else 'rewrote ') + path)
    if not stale:
        print(f"up to date: {', '.join(os.path.join(args.dir, p) for p in PAGES)}")
    return 1 if stale and args.check else 0


if __name__ == '__main__':
    sys.exit(main())
