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
What ``launch/umbrella.launch.py`` starts, as plain data (importable without ``launch``).

The launch files are thin wrappers: they declare ``ARGUMENTS`` and turn ``plan(...)`` into
``launch_ros.actions.Node`` / ``launch.actions.LogInfo`` actions.  Everything that decides
something lives here, so it is tested without ROS 2's launch (it is not on PyPI).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import os
import re
import tempfile

import yaml

from .params_file import load_yaml_as_ros
from .robot_description import BASE
from .share import PACKAGE, package_path, share_dir
from ..core.params import UmbrellaParams
from ..core.registry import REGISTRY, SPECS
from ..core.umbrella3d.params3d import (checked_umbrella_value, names_a_rib, node_model,
                                        RIB_LIST_PREFIX, rib_list_specs,
                                        umbrella_parameter_names, UMBRELLA_SPECS,
                                        UmbrellaRibsParams)


@dataclass(frozen=True)
class Argument:
    name: str
    default: str
    description: str


@dataclass
class NodeAction:
    package: str
    executable: str
    name: str
    namespace: str
    parameters: list = field(default_factory=list)    # params-file paths and dicts
    remappings: list = field(default_factory=list)
    arguments: list = field(default_factory=list)


@dataclass
class LogAction:
    msg: str


def default_params_file() -> str:
    """Return the package's config/umbrella.yaml (installed, or of the source checkout)."""
    return package_path('config', 'umbrella.yaml') or os.path.join('config', 'umbrella.yaml')


def arguments() -> list[Argument]:
    """Return the launch arguments: the node's setup, then one override per model parameter."""
    out = [
        Argument('namespace', '', "ROS namespace of the antenna (e.g. a1); '' = root"),
        Argument('params_file', default_params_file(), 'ROS 2 params file for umbrella_node'),
        Argument('record', 'true', 'record to an MCAP bag (true | false)'),
        Argument('record_path', '', "bag directory; '' = umbrella_<ns>_<date>-<time> in the "
                                    'working directory'),
        Argument('use_sim_time', 'true',
                 "robot_state_publisher and RViz follow the node's /clock (sim time)"),
        Argument('robot_state_publisher', 'true',
                 'start robot_state_publisher with the URDF, if it is installed'),
        Argument('rviz', 'false', 'start RViz with rviz/umbrella.rviz, if it is installed'),
    ]
    own = {a.name for a in out} | {'frame_prefix'}      # set from namespace
    for name, p in REGISTRY.items():
        if name in own:
            continue
        out.append(Argument(name, '', f'override {name} ({p.unit}, default from params_file): '
                                      f'{p.doc}'))
    # the umbrella of N ribs: its own values, and each rib's as a list (rib<k>.<name>:=value
    # sets rib k's alone: not declared, one per rib and name, but taken: launch_values)
    for name, p in UMBRELLA_SPECS.items():
        out.append(Argument(name, '', f'override {name} ({p.unit}, default from params_file): '
                                      f'{p.doc}'))
    for name, p in rib_list_specs().items():
        out.append(Argument(RIB_LIST_PREFIX + name, '',
                            f'per rib, a list of one value each, rib 0 first ({p.unit}; e.g. '
                            f"'[0.0, 0.1, 0.0]'): {p.doc}; rib<k>.{name}:=value sets rib "
                            "k's alone"))
    return out


def _truthy(value: str, name: str) -> bool:
    """Return a true/false launch argument by the registry's rule (a typo is an error)."""
    try:
        return REGISTRY['record'].coerce(value)
    except ValueError:
        raise ValueError(f'launch argument {name}:={value!r}: must be true or false') from None


def overrides(values: dict[str, str]) -> dict:
    """
    Typed parameter overrides from launch-argument strings ('' = not given).

    A node parameter is checked against its range here; the model's values are checked as
    a whole, on top of the params file's, by described_model (as the node will take them).
    """
    out = {}
    umbrella = umbrella_parameter_names()
    for name, text in values.items():
        if text in ('', None):
            continue
        if name in REGISTRY:
            out[name] = REGISTRY[name].coerce(text)
            if name not in SPECS:           # a node parameter: its range, as the node's
                REGISTRY[name].check(out[name])
        elif name in umbrella or names_a_rib(name):
            try:                            # (typed as a params file types it: a list too)
                value = load_yaml_as_ros(text)
            except yaml.YAMLError:
                value = text
            out[name] = checked_umbrella_value(name, value)
    return out


def antenna_values(values: dict[str, str], ns: str) -> dict[str, str]:
    """
    Return one antenna's launch values among several (multi_antenna.launch.py).

    A record_path given for all of them becomes record_path_<ns> each: one bag directory
    cannot take two recordings.
    """
    out = dict(values, namespace=ns)
    if values.get('record_path'):
        out['record_path'] = f"{values['record_path'].rstrip('/')}_{ns}"
    return out


def described_model(params_file: str,
                    node_params: dict) -> UmbrellaParams | UmbrellaRibsParams:
    """
    Return the model the node will run: its params file's values, then the overrides.

    Checked as a whole now, not after the node has started, by the node's own rule
    (params3d.node_model): the planar parameters, or with ribs >= 2 the whole umbrella's
    (hub_radius..., a rib's own values as rib.<name> lists or rib<k>.<name>): what
    robot_description.urdf describes.  ValueError naming a bad value.
    """
    from .params_file import load_params_file

    return node_model({**load_params_file(params_file), **node_params})


def rviz_config(config: dict, ns: str) -> dict:
    """
    Return RViz's config (rviz/umbrella.rviz, loaded) for the antenna in namespace ns.

    The installed config is the root namespace's: topics /markers and /robot_description,
    fixed frame umbrella_base.  In a namespace the node publishes /<ns>/markers,
    robot_state_publisher /<ns>/robot_description and the TF frames <ns>/<link> (its
    frame_prefix, as the node's headers): each display's absolute topic goes under /<ns>,
    the fixed frame is <ns>/umbrella_base and the robot model's TF Prefix ns (RViz joins it
    to a link name with a '/').  Unchanged, RViz showed nothing there ('Fixed Frame
    [umbrella_base] does not exist', no markers, no robot model).
    """
    ns = ns.strip('/')
    if not ns:
        return config
    out = yaml.safe_load(yaml.safe_dump(config))            # a deep copy
    manager = out['Visualization Manager']
    manager['Global Options']['Fixed Frame'] = f'{ns}/{BASE}'
    for display in manager['Displays']:
        for key in ('Topic', 'Description Topic'):
            topic = display.get(key, {}).get('Value', '')
            if topic.startswith('/'):
                display[key]['Value'] = f'/{ns}{topic}'
        if display.get('Class') == 'rviz_default_plugins/RobotModel':
            display['TF Prefix'] = ns
    return out


def _rviz_config_file(share: str, ns: str) -> str:
    """Return the RViz config file for namespace ns: the installed one, or a namespaced copy."""
    installed = os.path.join(share, 'rviz', 'umbrella.rviz')
    if not ns:
        return installed
    with open(installed, encoding='utf-8') as fh:
        config = rviz_config(yaml.safe_load(fh), ns)
    fd, path = tempfile.mkstemp(prefix=f"umbrella_{ns.replace('/', '_')}_", suffix='.rviz')
    with os.fdopen(fd, 'w', encoding='utf-8') as fh:
        fh.write(f'# rviz/umbrella.rviz for the antenna in namespace /{ns} '
                 '(umbrella_sim.ros.launch_description.rviz_config)\n')
        yaml.safe_dump(config, fh, sort_keys=False)
    return path


def plan(values: dict[str, str], installed=share_dir) -> list:
    """
    Return the actions for one antenna, given the launch arguments' string values.

    installed(package) returns the package's share directory or None (tests pass their own).
    """
    ns = values.get('namespace', '').strip('/')
    bad = [t for t in ns.split('/') if ns and not re.fullmatch(r'[A-Za-z_][A-Za-z0-9_]*', t)]
    if bad:         # (ROS names: a token starts with a letter or _, then letters, digits, _)
        raise ValueError(f'launch argument namespace:={ns!r}: {bad[0]!r} is not a ROS name '
                         'token (a letter or _ first, then letters, digits or _)')
    rel = f'/{ns}' if ns else ''
    sim_time = _truthy(values.get('use_sim_time', 'true'), 'use_sim_time')
    params = [values.get('params_file') or default_params_file()]
    node_params = overrides(values)
    node_params['record'] = _truthy(values.get('record', 'true'), 'record')
    if values.get('record_path'):
        node_params['record_path'] = values['record_path']
    # one TF tree for every antenna: frames a1/umbrella_base, a1/leaf, ... (see frames in
    # msg_docs/README.md); the node's messages name the same frames
    prefix = f'{ns}/' if ns else ''
    node_params['frame_prefix'] = prefix
    params.append(node_params)
    model = described_model(params[0], node_params)     # a bad value: refused before starting
    actions: list = [NodeAction(PACKAGE, 'umbrella_node', 'umbrella_node', ns, params)]
    # TF consumers read sim time from this antenna's clock (relative: /<ns>/clock)
    clock = [('/clock', f'{rel}/clock')] if ns else []
    if _truthy(values.get('robot_state_publisher', 'true'), 'robot_state_publisher'):
        if installed('robot_state_publisher'):
            from .robot_description import urdf
            actions.append(NodeAction(
                'robot_state_publisher', 'robot_state_publisher', 'robot_state_publisher', ns,
                [{'robot_description': urdf(model), 'use_sim_time': sim_time,
                  'frame_prefix': prefix}], clock))
        else:
            actions.append(LogAction(
                'robot_state_publisher is not installed: no TF frames and no robot_description '
                f"for {rel or '/'}; RViz can still show {rel}/markers in frame "
                f'{prefix}umbrella_base (apt install ros-jazzy-robot-state-publisher)'))
    if _truthy(values.get('rviz', 'false'), 'rviz'):
        share = installed(PACKAGE)
        if installed('rviz2') and share:
            actions.append(NodeAction('rviz2', 'rviz2', 'rviz2', ns,
                                      [{'use_sim_time': sim_time}], clock,
                                      ['-d', _rviz_config_file(share, ns)]))
        else:
            actions.append(LogAction('rviz2 is not installed: not starting RViz'))
    return actions


def split_namespaces(text: str) -> list[str]:
    """Return the namespaces of 'a1,a2 a3' (commas or spaces), refusing duplicates."""
    names = [n.strip().strip('/') for n in text.replace(',', ' ').split()]
    if not names:
        raise ValueError('namespaces: give at least one, e.g. a1,a2')
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"namespaces: {', '.join(dup)} given twice")
    return names


def to_launch_actions(planned: list) -> list:
    """Turn planned NodeAction / LogAction records into ROS 2 launch actions."""
    from launch.actions import LogInfo
    from launch_ros.actions import Node

    out = []
    for a in planned:
        if isinstance(a, LogAction):
            out.append(LogInfo(msg=a.msg))
        else:
            out.append(Node(package=a.package, executable=a.executable, name=a.name,
                            namespace=a.namespace, parameters=a.parameters,
                            remappings=a.remappings, arguments=a.arguments, output='screen'))
    return out


def launch_values(context) -> dict[str, str]:
    """
    Return every argument's value from a launch context (its default when not given).

    With the rib<k>.<name> values given (ros2 launch takes an argument it does not declare
    as a launch configuration too): one rib's own, too many to declare.
    """
    given = context.launch_configurations
    out = {a.name: given.get(a.name, a.default) for a in arguments()}
    out.update({name: text for name, text in given.items()
                if name not in out and names_a_rib(name)})
    return out
