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

"""The README a new user reads: two commands, a sketch before the symbols, links, --csv columns."""
import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def readme() -> str:
    with open(os.path.join(ROOT, 'README.md'), encoding='utf-8') as fh:
        return fh.read()


def code_lines(text: str) -> list[str]:
    """Return the lines of the indented code blocks (the README has no fenced ones), stripped."""
    assert '```' not in text
    return [line.strip() for line in text.splitlines() if line.startswith('    ')]


def test_two_commands_need_only_python3():
    """On a fresh machine with python3 alone: set up and run, set up and test; no other."""
    commands = [line for line in code_lines(readme()) if line.startswith('python3 ')]
    assert commands == ['python3 bootstrap.py run', 'python3 bootstrap.py test']


def test_the_sketch_names_the_symbols_before_the_topic_table_uses_them():
    text = readme()
    sketch = text.index('](docs/mechanism.png)')
    table = text.index('## Topics and parameters at a glance')
    assert sketch < table
    caption = text[sketch:text.index('\n## ', sketch)]
    for symbol in ("O''", 'G', 'H', 'stop S', 'alpha1', 'alpha2', 'y_H', 'F_H'):
        assert symbol in caption, symbol
    # and the look at the run comes right after the two commands
    sections = re.findall(r'^## (.+)$', text, flags=re.M)
    assert sections[:2] == ['Two commands', 'Look at your run']


def test_every_local_link_and_image_exists():
    links = re.findall(r'\]\(([^)#]+)\)', readme())
    local = [link for link in links if not re.match(r'[a-z]+://', link)]
    assert 'docs/mechanism.png' in local and 'config/umbrella.foxglove.json' in local
    missing = [link for link in local if not os.path.exists(os.path.join(ROOT, link))]
    assert not missing


def test_the_ribs_example_does_what_the_readme_says():
    """
    The README's umbrella example (its -p arguments, run offline): the figures it quotes.

    A rubbing hinge (Coulomb friction on one rib) takes energy out of the deployment, which
    locks later than the same umbrella's without it; the README's numbers are these figures,
    rounded (both converged: at a quarter of the step the lock moves 1e-6 s, the friction's
    work 0.2 %).
    """
    import json
    import shlex

    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
    from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D

    text = readme()
    (line,) = [line for line in code_lines(text) if 'umbrella_node' in line and 'ribs:=' in line]
    words = shlex.split(line)
    values = {}
    for flag, arg in zip(words, words[1:]):
        if flag == '-p':
            name, value = arg.split(':=')
            values[name] = json.loads(value)
    assert values['ribs'] == 6 and 'rib.hinge_coulomb' in values

    def run(values):
        sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values))
        sim.run(1.0, after_lock=0.0)            # (to the lock's grid step: the deployment)
        return sim.lock_time, sim.record.summary()['friction_work']

    lock, work = run(values)
    free_lock, _ = run({'ribs': 6})
    rubbing = values['rib.hinge_coulomb'].index(max(values['rib.hinge_coulomb']))
    assert lock > free_lock and work[rubbing] < 0.0
    assert all(w == 0.0 for k, w in enumerate(work) if k != rubbing)
    said = re.search(r'Rib (\d)\'s hinge rubs .*?takes ([0-9.]+) J out of the deployment, and the '
                     r'umbrella locks at ([0-9.]+) s\s+instead of ([0-9.]+) s', text, re.S)
    assert said, 'the README no longer says what the example does'
    assert int(said[1]) == rubbing and float(said[2]) == round(-work[rubbing], 2)
    assert (float(said[3]), float(said[4])) == (round(lock, 3), round(free_lock, 3))


def test_every_planar_csv_column_is_documented():
    """Each column of the planar model's ``simulate --csv`` has its row in the README's table."""
    from umbrella_sim.tools.csv_output import CSV_COLUMNS

    text = readme()
    table = text[text.index("**The planar model's `--csv`**"):text.index('## Parameter sweeps')]
    rows = [line for line in table.splitlines() if line.startswith('| `')]
    named = {name for line in rows for name in re.findall(r'`(\w+)`', line.split(' | ')[0])}
    assert set(CSV_COLUMNS) <= named, sorted(set(CSV_COLUMNS) - named)


def test_the_csv_state_columns_it_names_are_columns():
    """
    The ``--csv-state`` names the README gives are columns of the default run's CSV.

    It named ``sigma_top[leaf@0.25]``, which no mesh has: a node inside the leaf is two
    elements', ``leaf@0.25-`` and ``leaf@0.25+``.
    """
    from umbrella_sim.core.model import UmbrellaModel
    from umbrella_sim.core.params import UmbrellaParams
    from umbrella_sim.tools.csv_output import state_columns

    text = readme()
    start = text.index('`--csv-state` adds')
    paragraph = text[start:text.index('\n\n', start)]
    columns = state_columns(UmbrellaModel(UmbrellaParams()))
    named = [n for n in re.findall(r'`(\w+\[[^\]`]+\])`', paragraph)
             if '<' not in n and '...' not in n]
    points = re.findall(r'`(leaf@[0-9.]+[-+]?)`', paragraph)
    assert named and points, paragraph
    assert [n for n in named if n not in columns] == []
    assert [p for p in points if f'sigma_top[{p}]' not in columns] == []
