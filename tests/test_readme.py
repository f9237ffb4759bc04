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

"""The README a new user reads: two commands, a sketch before the symbols, links that exist."""
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

    A hinge that sticks until its holding torque reaches a threshold holds the sleeve back:
    the lock comes later than the same umbrella's without it, and the stuck rib's peak von
    Mises stress is above the others'; the README's numbers are these, rounded.
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
    assert values['ribs'] == 6 and 'rib.stick_torque' in values

    def run(values):
        sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values))
        sim.run(0.9)
        return sim.lock_time, sim.record.summary()['peak_stress']['von_mises'][0]

    lock, peaks = run(values)
    free_lock, _ = run({'ribs': 6})
    stuck = values['rib.stick_torque'].index(max(values['rib.stick_torque']))
    others = max(p for k, p in enumerate(peaks) if k != stuck)
    assert lock > free_lock and peaks[stuck] > others
    said = re.search(r'locks at ([0-9.]+) s\s+instead of ([0-9.]+) s and rib (\d)\'s peak von '
                     r'Mises stress is (\d+) % above', text)
    assert said, 'the README no longer says what the example does'
    assert (float(said[1]), float(said[2]), int(said[3])) == (round(lock, 3),
                                                              round(free_lock, 3), stuck)
    assert int(said[4]) == round(100 * (peaks[stuck] / others - 1))
