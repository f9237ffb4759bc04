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
The package's layers, held against its import graph.

    core   (parameters, model, solver, outputs: the physics; no ROS, no file format, no
            command line, no signal handling)
    bag    (the MCAP / rosbag2 recording format)           imports core
    ros    (node, messages, controller, launch)            imports bag, core
    tools  (the command lines)                             imports ros, bag, core
    testing (the actuation-test API)                       imports any of them

Every import counts, at module level or inside a function, and so does a module named to
importlib.  Besides the layers: the package's __init__ imports nothing of the package, and
the entry modules kept for ``python -m umbrella_sim[.node|.deploy_controller]`` import only
the tools' entry points.  No module imports itself back through others (no circle).
"""
import ast
import os
import re

import pytest

ROOT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'umbrella_sim')
LAYERS = ('core', 'bag', 'ros', 'tools', 'testing')
#: what each layer may import of the package (besides itself and the package's __init__)
ALLOWED = {'core': set(), 'bag': {'core'}, 'ros': {'bag', 'core'},
           'tools': {'ros', 'bag', 'core'}, 'testing': {'tools', 'ros', 'bag', 'core'},
           'entry': {'tools'}}
#: third-party and standard-library modules a layer must not import (the top name)
FORBIDDEN = {
    'core': {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs', 'sensor_msgs',
             'geometry_msgs', 'nav_msgs', 'visualization_msgs', 'rosgraph_msgs',
             'diagnostic_msgs',
             'std_srvs', 'mcap', 'yaml', 'argparse', 'signal', 'launch', 'launch_ros',
             'dask', 'distributed', 'matplotlib', 'csv'},
    'bag': {'argparse', 'signal', 'launch', 'launch_ros', 'dask', 'distributed',
            'matplotlib'},
}
#: rclpy modules of a running node: the format layer serialises messages, it runs no node
BAG_FORBIDDEN_RCLPY = ('rclpy.node', 'rclpy.executors', 'rclpy.init', 'rclpy.signals')


def _modules() -> dict[str, str]:
    """Return {dotted module name: path} of every module of the package."""
    out = {}
    for dirpath, _, files in os.walk(ROOT):
        for f in files:
            if f.endswith('.py'):
                path = os.path.join(dirpath, f)
                rel = os.path.relpath(path, os.path.dirname(ROOT))[:-3].replace(os.sep, '.')
                out[rel[:-len('.__init__')] if rel.endswith('.__init__') else rel] = path
    return out


def _imports(name: str, path: str) -> list[tuple[str, int]]:
    """Return (imported module, line) of every import in a module, resolved to absolute."""
    tree = ast.parse(open(path, encoding='utf-8').read(), path)
    package = name if path.endswith('__init__.py') else name.rpartition('.')[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = package.split('.')
                parts = parts[:len(parts) - node.level + 1]
                base = '.'.join(parts + ([base] if base else []))
            found.append((base, node.lineno))
            found += [(f'{base}.{a.name}', node.lineno) for a in node.names]
        elif (isinstance(node, ast.Call) and getattr(node.func, 'attr', '') == 'import_module'
              and node.args and isinstance(node.args[0], (ast.Constant, ast.JoinedStr))):
            arg = node.args[0]
            text = arg.value if isinstance(arg, ast.Constant) else ''.join(
                v.value for v in arg.values if isinstance(v, ast.Constant))
            found.append((text.rstrip('.'), node.lineno))
    return found


def _layer(module: str) -> str:
    parts = module.split('.')
    if len(parts) == 1:
        return 'package'
    if parts[1] in LAYERS:
        return parts[1]
    return 'entry'


MODULES = _modules()


def _graph() -> dict[str, set[tuple[str, int]]]:
    graph = {}
    for name, path in MODULES.items():
        edges = set()
        for target, line in _imports(name, path):
            while target and target not in MODULES:
                target = target.rpartition('.')[0]
            if target and target != name and target.startswith('umbrella_sim'):
                edges.add((target, line))
        graph[name] = edges
    return graph


GRAPH = _graph()


def test_every_module_is_in_a_layer():
    entry = sorted(m for m in MODULES if _layer(m) == 'entry')
    assert entry == ['umbrella_sim.__main__', 'umbrella_sim.deploy_controller',
                     'umbrella_sim.node'], entry


@pytest.mark.parametrize('module', sorted(MODULES))
def test_imports_point_down_the_layers(module):
    layer = _layer(module)
    bad = []
    for target, line in sorted(GRAPH[module]):
        to = _layer(target)
        if target == 'umbrella_sim' or to == layer and layer != 'entry':
            continue
        if to not in ALLOWED.get(layer, set()):
            bad.append(f'line {line}: {target} ({to})')
    assert not bad, f'{module} ({layer}) imports against the layers: ' + '; '.join(bad)


@pytest.mark.parametrize('module', sorted(m for m in MODULES if _layer(m) in FORBIDDEN))
def test_lower_layers_import_no_ros_node_format_or_command_line(module):
    layer = _layer(module)
    bad = []
    for target, line in _imports(module, MODULES[module]):
        top = target.split('.')[0]
        if top in FORBIDDEN[layer] or (layer == 'bag' and target.startswith(BAG_FORBIDDEN_RCLPY)):
            bad.append(f'line {line}: {target}')
    assert not bad, f'{module} ({layer}) imports: ' + '; '.join(bad)


def test_the_package_init_imports_nothing_of_the_package():
    assert not GRAPH['umbrella_sim']


def test_no_import_circles():
    """Tarjan's strongly connected components of the module graph: each one module."""
    index, low, stack, on, circles, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w, _ in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not circles, 'import circles: ' + '; '.join(' <-> '.join(c) for c in circles)


#: a module this long says why in its docstring ("Why one module:"); the license header
#: every file opens with (tests/test_lint_copyright.py) is not counted
LONG_MODULE = 650


@pytest.mark.parametrize('module', sorted(MODULES))
def test_long_modules_say_why(module):
    path = MODULES[module]
    text = open(path, encoding='utf-8').read()
    lines = text.count('\n') - len(re.match(r'(#[^\n]*\n)*\n?', text).group(0).splitlines())
    doc = ast.get_docstring(ast.parse(text)) or ''
    assert lines <= LONG_MODULE or 'Why one module:' in doc, (
        f'{module}: {lines} lines; split it, or say in its docstring why it is one module')
