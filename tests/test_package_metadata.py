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
The package's declarations, as a ROS package's: its license, and every import declared.

package.xml declares every module the package imports (a ROS package by its name, a Python
distribution by its rosdep key, python3-<name>), and setup.py's install_requires every
Python distribution among them, so rosdep and pip install what it needs.
"""
import ast
import importlib.metadata
import os
import sys
import xml.etree.ElementTree as ET

from tests.test_docs_commands import ROOT, setup_distribution

#: rosdep keys that are not python3-<distribution, lower case>
ROSDEP_KEYS = {'PyYAML': 'python3-yaml'}


def _package_xml():
    return ET.parse(os.path.join(ROOT, 'package.xml')).getroot()


def _imported_modules() -> dict[str, str]:
    """Return {top-level module: a file importing it} of umbrella_sim and launch/."""
    found = {}
    for top in ('umbrella_sim', 'launch'):
        for dirpath, _, files in os.walk(os.path.join(ROOT, top)):
            for name in files:
                if not name.endswith('.py'):
                    continue
                path = os.path.join(dirpath, name)
                for node in ast.walk(ast.parse(open(path, encoding='utf-8').read(), path)):
                    if isinstance(node, ast.Import):
                        names = [a.name for a in node.names]
                    elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                        names = [node.module]
                    else:
                        continue
                    for module in names:
                        found.setdefault(module.split('.')[0], os.path.relpath(path, ROOT))
    return {m: p for m, p in found.items()
            if m not in sys.stdlib_module_names and m != 'umbrella_sim'}


def test_every_import_is_declared():
    xml = _package_xml()
    run_depends = {e.text for tag in ('exec_depend', 'depend') for e in xml.iter(tag)}
    test_depends = {e.text for e in xml.iter('test_depend')}
    dist = setup_distribution()
    requires = {r.split('[')[0].split('>')[0].split('=')[0].split('<')[0].strip().lower()
                for r in (*dist.install_requires,
                          *(r for rs in (dist.extras_require or {}).values() for r in rs))}
    distributions = importlib.metadata.packages_distributions()
    missing = []
    for module, where in sorted(_imported_modules().items()):
        if module in run_depends:           # a ROS package: its package name is its module's
            continue
        names = [d for d in distributions.get(module, []) if not d.startswith('ros-')]
        if not names:
            missing.append(f'{module} ({where}): not in package.xml, and no installed '
                           'distribution provides it')
            continue
        dist_name = names[0]
        key = ROSDEP_KEYS.get(dist_name, f'python3-{dist_name.lower()}')
        if key not in run_depends | test_depends:
            missing.append(f'{module} ({where}): package.xml lacks <exec_depend>{key}')
        if dist_name.lower() not in requires:
            missing.append(f"{module} ({where}): setup.py's install_requires lacks {dist_name}")
    assert not missing, '\n'.join(missing)


def test_license_file_is_the_declared_license():
    """package.xml and setup.py say Apache-2.0; LICENSE holds the Apache License 2.0 text."""
    assert [e.text for e in _package_xml().iter('license')] == ['Apache-2.0']
    assert setup_distribution().get_license() == 'Apache-2.0'
    with open(os.path.join(ROOT, 'LICENSE'), encoding='utf-8') as fh:
        text = ' '.join(fh.read().split())
    assert text.startswith('Apache License Version 2.0, January 2004')
    assert 'TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION' in text
    assert 'END OF TERMS AND CONDITIONS' in text
