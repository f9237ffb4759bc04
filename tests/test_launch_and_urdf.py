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
The launch files and the robot description, checked without ROS 2's launch.

launch / launch_ros are not on PyPI: the launch files are loaded here against small stand-ins
that record what they are given, and the planning module they wrap is tested directly.
"""
import importlib.util
import math
import os
import re
import sys
import types
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.registry import NODE_PARAMETERS, SPECS
from umbrella_sim.core.solver import UmbrellaSimulator
from umbrella_sim.core.umbrella3d.params3d import names_a_rib
from umbrella_sim.ros import launch_description as ld, robot_description as rd
from umbrella_sim.ros.messages import JOINT_NAMES, joint_state_msg
from umbrella_sim.ros.share import share_dir

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
URDF = os.path.join(ROOT, 'urdf', 'umbrella.urdf')


# ------------------------------------------------------------------------------- URDF
def test_urdf_file_is_the_generated_one():
    """Regenerate: .venv/bin/python -m umbrella_sim.ros.robot_description > urdf/umbrella.urdf."""
    with open(URDF, encoding='utf-8') as fh:
        assert fh.read() == rd.urdf()


def test_urdf_joints_are_the_published_joint_names():
    robot = ET.parse(URDF).getroot()
    links = {link.get('name') for link in robot.iter('link')}
    assert {'umbrella_base', 'leaf', 'link', 'sleeve', 'tip'} <= links
    moving = [j.get('name') for j in robot.iter('joint') if j.get('type') != 'fixed']
    assert moving == JOINT_NAMES == rd.MOVING_JOINTS
    for j in robot.iter('joint'):
        assert j.find('parent').get('link') in links and j.find('child').get('link') in links
    children = [j.find('child').get('link') for j in robot.iter('joint')]
    assert len(children) == len(set(children)) == len(links) - 1      # a tree from the base


def _urdf_frames_along(p: UmbrellaParams, duration: float, steps_between: int):
    """
    Yield (simulator, sample, frames) every steps_between steps of the planar run up to duration.

    frames: _forward_kinematics of the URDF of p from the sample's published joint_states.
    """
    robot = ET.fromstring(rd.urdf(p))
    sim = UmbrellaSimulator(p)
    while sim.time < duration:
        s = sim.sample()
        msg = joint_state_msg(s)
        yield sim, s, _forward_kinematics(robot, dict(zip(msg.name, msg.position)))
        for _ in range(steps_between):
            sim.step(record=False)


def _forward_kinematics(robot, positions: dict) -> dict:
    """Return 3x3 planar homogeneous transforms base <- link from the URDF's joints."""
    joints = {j.find('child').get('link'): j for j in robot.iter('joint')}

    def pose(link):
        if link not in joints:
            return np.eye(3)
        j = joints[link]
        xyz = [float(v) for v in j.find('origin').get('xyz').split()]
        t = np.array([[1.0, 0.0, xyz[0]], [0.0, 1.0, xyz[1]], [0.0, 0.0, 1.0]])
        q = positions.get(j.get('name'), 0.0)
        if j.get('type') == 'revolute':
            assert j.find('axis').get('xyz') == '0 0 1'
            c, s = math.cos(q), math.sin(q)
            t = t @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        elif j.get('type') == 'prismatic':
            axis = [float(v) for v in j.find('axis').get('xyz').split()]
            t = t @ np.array([[1.0, 0.0, q * axis[0]], [0.0, 1.0, q * axis[1]], [0, 0, 1.0]])
        return pose(j.find('parent').get('link')) @ t
    return {name: pose(name) for name in
            [link.get('name') for link in robot.iter('link')]}


@pytest.mark.parametrize('model', ['rigid-fe', 'flexible'])
def test_urdf_with_published_joint_states_closes_the_loop(model):
    """
    The URDF's frames are the beams' floating frames, and the sleeve is where H is.

    From the published joint positions alone, robot_state_publisher's frames put the sleeve
    exactly where the deformed link's end H is, and the link's end (x'' = l3) and the tip G
    (x' = l1 + l2) where the model has them up to the elastic displacements the rigid URDF
    leaves out: exactly (1e-9 m) with rigid-fe, within the largest nodal elastic
    displacement (twice, for the link, which hangs on the leaf at O'') with the elastic
    model.  At every publication through the deployment and the lock.
    """
    p = UmbrellaParams(model=model, v0=-0.5)
    checked = 0
    for sim, s, frames in _urdf_frames_along(p, 0.12, 5):
        rigid = sim.model.node_positions(s.q, 0.0)         # floating frames, undeformed
        (leaf, link) = sim.model.node_positions(s.q, 1.0)   # deformed
        elastic = max(float(np.abs(d - r).max()) for d, r in zip((leaf, link), rigid))
        assert model == 'flexible' or elastic < 1e-12
        link_end = (frames['link'] @ np.array([p.l3, 0.0, 1.0]))[:2]
        sleeve = (frames['sleeve'] @ np.array([0.0, 0.0, 1.0]))[:2]
        tip = (frames['tip'] @ np.array([0.0, 0.0, 1.0]))[:2]
        assert np.abs(sleeve - link[-1]).max() < 1e-9, (sim.time, sleeve)
        assert np.abs(link_end - link[-1]).max() <= 2 * elastic + 1e-9, (sim.time, link_end)
        assert np.abs(tip - leaf[-1]).max() <= elastic + 1e-9, (sim.time, tip)
        checked += 1
    assert checked > 10 and sim.lock_event is not None     # through the lock


def test_tip_deflection_is_the_deformed_tip_in_its_header_frame():
    """
    A viewer draws tip_deflection's point where the deformed tip G is.

    RViz and Foxglove place a PointStamped at its point in its header's frame, which
    robot_state_publisher's TF puts where the URDF's forward kinematics from joint_states
    does: that must be the deformed mesh's G (a point (u_G, v_G) in the leaf frame, origin
    O, would be drawn near the hinge, a leaf length away).  Every header frame of the
    sample's messages is a link of the URDF, with robot_state_publisher's frame_prefix.
    """
    from umbrella_sim.ros.messages import sample_messages, tip_deflection_msg

    p = UmbrellaParams(v0=-0.5)
    links = {link.get('name') for link in ET.fromstring(rd.urdf(p)).iter('link')}
    largest = 0.0
    for sim, s, frames in _urdf_frames_along(p, 0.3, 10):
        tip = tip_deflection_msg(s)
        assert tip.point.z == 0.0
        drawn = (frames[tip.header.frame_id] @ np.array([tip.point.x, tip.point.y, 1.0]))[:2]
        leaf, _ = sim.model.node_positions(s.q, 1.0)        # deformed, G its last node
        assert np.abs(drawn - leaf[-1]).max() < 1e-12, (sim.time, drawn, leaf[-1])
        largest = max(largest, math.hypot(tip.point.x, tip.point.y))
    assert sim.lock_event is not None and largest > 1e-3   # stage 2's vibration included
    messages = sample_messages(s, p, [leaf], 'a1', 0.0, 'a1/')
    headers = [m.header for m in messages.values() if hasattr(m, 'header')]
    headers += [m.header for m in messages['markers'].markers]
    assert {h.frame_id for h in headers} <= {f'a1/{link}' for link in links}


# ------------------------------------------------------------------------------ launch
class _Recorder:

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


@pytest.fixture
def launch_stubs(monkeypatch):
    """Minimal stand-ins for launch and launch_ros (not on PyPI)."""
    mods = {}
    for name in ('launch', 'launch.actions', 'launch_ros', 'launch_ros.actions'):
        mods[name] = types.ModuleType(name)
        monkeypatch.setitem(sys.modules, name, mods[name])
    for cls in ('LaunchDescription',):
        setattr(mods['launch'], cls, type(cls, (_Recorder,), {}))
    for cls in ('DeclareLaunchArgument', 'LogInfo', 'OpaqueFunction'):
        setattr(mods['launch.actions'], cls, type(cls, (_Recorder,), {}))
    mods['launch_ros.actions'].Node = type('Node', (_Recorder,), {})
    return mods


def _load(name: str):
    path = os.path.join(ROOT, 'launch', name)
    spec = importlib.util.spec_from_file_location(name.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(description, given: dict):
    """
    Evaluate a description as ros2 launch would: arguments, then the OpaqueFunctions.

    ros2 launch sets every argument given as a launch configuration, declared or not
    (launch's IncludeLaunchDescription); here an undeclared one must be a rib's own value
    (rib<k>.<name>), the one kind the launch files read without declaring it.
    """
    actions = description.args[0]
    declared = {a.args[0]: a.kwargs['default_value'] for a in actions
                if type(a).__name__ == 'DeclareLaunchArgument'}
    unknown = {name for name in set(given) - set(declared) if not names_a_rib(name)}
    assert not unknown, f'not launch arguments: {unknown}'
    context = types.SimpleNamespace(launch_configurations={**declared, **given})
    out = []
    for a in actions:
        if type(a).__name__ == 'OpaqueFunction':
            out += a.kwargs['function'](context)
    return declared, out


def test_umbrella_launch_declares_the_arguments_and_starts_the_node(launch_stubs):
    module = _load('umbrella.launch.py')
    declared, actions = _run(module.generate_launch_description(),
                             {'namespace': 'a1', 'v0': '-0.5', 'elements_per_segment': '2',
                              'record': 'false', 'use_sim_time': 'true'})
    for name in ('namespace', 'params_file', 'record_path', 'use_sim_time', 'record', 'rviz',
                 *SPECS, *NODE_PARAMETERS):
        assert name in declared or name == 'frame_prefix'
    assert os.path.isfile(declared['params_file'])
    nodes = [a for a in actions if type(a).__name__ == 'Node']
    umbrella = next(n for n in nodes if n.kwargs['executable'] == 'umbrella_node')
    assert umbrella.kwargs['package'] == 'umbrella_sim' and umbrella.kwargs['namespace'] == 'a1'
    params_file, overrides = umbrella.kwargs['parameters']
    assert params_file == declared['params_file']
    assert overrides == {'v0': -0.5, 'elements_per_segment': 2, 'record': False,
                         'frame_prefix': 'a1/'}
    assert isinstance(overrides['v0'], float)
    assert isinstance(overrides['elements_per_segment'], int)
    if share_dir('robot_state_publisher') is None:     # always so with PyPI's ROS
        logs = [a.kwargs.get('msg', a.args[0] if a.args else '') for a in actions
                if type(a).__name__ == 'LogInfo']
        assert any('robot_state_publisher is not installed' in m for m in logs)


def test_the_umbrella_of_n_ribs_is_launched_with_its_values_and_urdf(launch_stubs):
    """
    ribs, hub_radius, a rib list and one rib's own value, as launch arguments.

    The node takes them typed (its params file's types), robot_state_publisher the N-rib
    URDF; a value the umbrella cannot take is refused before anything starts.
    """
    module = _load('umbrella.launch.py')
    given = {'ribs': '3', 'hub_radius': '0.1', 'rib.tip_mass': '[0.0, 0.1, 0.0]',
             'rib1.l2': '0.6', 'record': 'false'}
    declared, actions = _run(module.generate_launch_description(), given)
    for name in ('ribs', 'hub_radius', 'base', 'rib.tip_mass', 'rib.stick_until'):
        assert name in declared
    umbrella = next(a for a in actions if type(a).__name__ == 'Node'
                    and a.kwargs['executable'] == 'umbrella_node')
    overrides = umbrella.kwargs['parameters'][1]
    assert overrides == {'ribs': 3, 'hub_radius': 0.1, 'rib.tip_mass': [0.0, 0.1, 0.0],
                         'rib1.l2': 0.6, 'record': False, 'frame_prefix': ''}
    values = {a.name: a.default for a in ld.arguments()}
    actions = ld.plan(dict(values, **given), installed=lambda pkg: f'/opt/share/{pkg}')
    rsp = next(a for a in actions if isinstance(a, ld.NodeAction)
               and a.package == 'robot_state_publisher')
    robot = ET.fromstring(rsp.parameters[0]['robot_description'])
    joints = {j.get('name'): j for j in robot.iter('joint')}
    assert {f'rib{k}/leaf_hinge' for k in range(3)} <= set(joints)
    tip = joints['rib1/leaf_tip'].find('origin').get('xyz').split()[0]
    assert float(tip) == pytest.approx(1.1)                 # rib 1's l1 + l2
    for bad, words in (({'rib9.l2': '0.6'}, 'rib9.l2: there are ribs 0 .. 2'),
                       ({'rib1.l2': '-0.6'}, 'l2=-0.6'),
                       ({'rib.tip_mass': '0.2'}, 'rib.tip_mass=0.2: a list'),
                       ({'rib1.lx': '1'}, "'rib1.lx'"),
                       ({'ribs': '1'}, 'set with ribs 1')):
        with pytest.raises(ValueError, match=re.escape(words)):
            ld.plan({**values, **given, **bad}, installed=lambda pkg: None)


def test_plan_starts_robot_state_publisher_with_the_urdf_when_installed():
    values = {a.name: a.default for a in ld.arguments()}
    values.update(namespace='a2', l2='0.6')
    actions = ld.plan(values, installed=lambda pkg: f'/opt/share/{pkg}')
    rsp = next(a for a in actions if isinstance(a, ld.NodeAction)
               and a.package == 'robot_state_publisher')
    (params,) = rsp.parameters
    robot = ET.fromstring(params['robot_description'])
    leaf_tip = next(j for j in robot.iter('joint') if j.get('name') == 'leaf_tip')
    assert leaf_tip.find('origin').get('xyz').split()[0] == '1.1'    # l1 + l2 overridden
    assert params['frame_prefix'] == 'a2/' and params['use_sim_time'] is True
    assert rsp.namespace == 'a2' and rsp.remappings == [('/clock', '/a2/clock')]
    assert not any(isinstance(a, ld.LogAction) for a in actions)


@pytest.mark.parametrize('ns', ['', 'a1', 'a1/b_2'])
def test_rviz_shows_the_antennas_own_topics_and_frames(ns, tmp_path, monkeypatch):
    """
    RViz, started with an antenna, looks where that antenna's node and TF are.

    Its fixed frame is the node's header frame (frame_prefix + umbrella_base), the frame
    robot_state_publisher roots its TF at; its marker and robot-description topics are the
    ones published in the namespace; its robot model finds each URDF link under the prefix
    robot_state_publisher gives the TF frames (RViz joins TF Prefix and link with a '/').
    """
    import yaml

    from umbrella_sim.ros.messages import INERTIAL_FRAME, TOPICS

    monkeypatch.setattr('tempfile.tempdir', str(tmp_path))
    values = {a.name: a.default for a in ld.arguments()}
    actions = ld.plan(dict(values, namespace=ns, rviz='true'),
                      installed=lambda pkg: ROOT if pkg == 'umbrella_sim' else f'/opt/{pkg}')
    node, rsp, rviz = (next(a for a in actions if a.package == pkg)
                       for pkg in ('umbrella_sim', 'robot_state_publisher', 'rviz2'))
    prefix = node.parameters[1]['frame_prefix']
    assert rsp.parameters[0]['frame_prefix'] == prefix
    flag, path = rviz.arguments
    assert flag == '-d' and (ns or path == os.path.join(ROOT, 'rviz', 'umbrella.rviz'))
    with open(path, encoding='utf-8') as fh:
        manager = yaml.safe_load(fh)['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == prefix + INERTIAL_FRAME
    displays = {d['Class'].split('/')[-1]: d for d in manager['Displays']}
    rel = f'/{ns}' if ns else ''
    assert displays['MarkerArray']['Topic']['Value'] == f'{rel}/{TOPICS["markers"].name}'
    model = displays['RobotModel']
    assert model['Description Topic']['Value'] == f'{rel}/robot_description'
    tf_prefix = model.get('TF Prefix', '')
    links = [link.get('name') for link in ET.fromstring(rsp.parameters[0]['robot_description'])
             .iter('link')]
    assert [f'{tf_prefix}/{link}' if tf_prefix else link for link in links] == \
        [prefix + link for link in links]


def test_rviz_view_faces_the_plane_the_frame_moves_in():
    """
    The saved RViz view shows the planar frame face-on, the axle up, the frame in view.

    RViz's Orbit view (rviz_default_plugins' OrbitViewController.updateCamera) puts the
    camera at focal + d (cos yaw cos pitch, sin yaw cos pitch, sin pitch) looking at the
    focal point, its screen's up the part of +Z normal to the view.  The markers of the
    planar frame lie in z = 0: the view must look along Z (at pitch 0 it looked along Y and
    the frame was a line), with +Y, up the axle, up on the screen and +X to the right.
    """
    import yaml

    with open(os.path.join(ROOT, 'rviz', 'umbrella.rviz'), encoding='utf-8') as fh:
        view = yaml.safe_load(fh)['Visualization Manager']['Views']['Current']
    assert view['Class'] == 'rviz_default_plugins/Orbit'
    assert view['Target Frame'] == '<Fixed Frame>'
    yaw, pitch, distance = float(view['Yaw']), float(view['Pitch']), float(view['Distance'])
    assert abs(pitch) <= math.pi / 2 - 0.001                 # RViz's own clamp
    focal = np.array([float(view['Focal Point'][k]) for k in 'XYZ'])
    camera = focal + distance * np.array([math.cos(yaw) * math.cos(pitch),
                                          math.sin(yaw) * math.cos(pitch), math.sin(pitch)])
    forward = (focal - camera) / np.linalg.norm(focal - camera)
    up = np.array([0.0, 0.0, 1.0]) - forward[2] * forward
    up /= np.linalg.norm(up)
    right = np.cross(forward, up)
    assert forward @ np.array([0.0, 0.0, -1.0]) > 0.999            # face-on, from +Z
    assert up @ np.array([0.0, 1.0, 0.0]) > 0.999                  # the axle up
    assert right @ np.array([1.0, 0.0, 0.0]) > 0.999               # the leaf to the right
    # the folded and the deployed frame (O, O'', G, the axle's top) within a 45° view
    p = UmbrellaParams()
    corners = [(0.0, 0.0), (0.0, p.l1 + p.l3)] + [
        ((p.l1 + p.l2) * math.cos(a), (p.l1 + p.l2) * math.sin(a))
        for a in (p.alpha0, p.alpha_deployed)]
    for x, y in corners:
        ray = np.array([x, y, 0.0]) - camera
        assert math.degrees(math.acos(ray @ forward / np.linalg.norm(ray))) < 22.5, (x, y)


def test_plan_refuses_bad_overrides_before_starting_anything():
    values = {a.name: a.default for a in ld.arguments()}
    with pytest.raises(ValueError, match="parameter v0='fast'"):
        ld.plan(dict(values, v0='fast'), installed=lambda pkg: None)
    with pytest.raises(ValueError, match='alpha0'):
        ld.plan(dict(values, alpha0='0.1'), installed=lambda pkg: None)
    for flag in ('rviz', 'use_sim_time', 'robot_state_publisher'):     # a typo is no "false"
        with pytest.raises(ValueError, match=f"{flag}:='ture'"):
            ld.plan(dict(values, **{flag: 'ture'}), installed=lambda pkg: None)
    # node parameters and the namespace too, before the node is started (they failed there)
    for name, text, words in (('publish_rate', '0', 'publish_rate=0.0'),
                              ('duration', '-1', 'duration=-1.0'),
                              ('namespace', '1a', "'1a' is not a ROS name token")):
        with pytest.raises(ValueError, match=words):
            ld.plan(dict(values, **{name: text}), installed=lambda pkg: None)
    assert ld.plan(dict(values, namespace='a1/b_2'), installed=lambda pkg: None)


def test_plan_checks_overrides_on_top_of_the_params_file(tmp_path):
    """l1 = 0.6 with a params file's l3 = 0.9 closes; on the defaults (l3 = 0.5) it would not."""
    long_link = tmp_path / 'long.yaml'
    long_link.write_text('/**:\n  ros__parameters:\n    l1: 0.9\n    l3: 0.9\n')
    values = {a.name: a.default for a in ld.arguments()}
    (node, *_) = ld.plan(dict(values, params_file=str(long_link), l1='0.6'),
                         installed=lambda pkg: None)
    assert node.parameters[0] == str(long_link) and node.parameters[1]['l1'] == 0.6
    with pytest.raises(ValueError, match='l3'):
        ld.plan(dict(values, l1='0.6'), installed=lambda pkg: None)


def test_multi_antenna_launch_starts_one_namespaced_antenna_each(launch_stubs):
    module = _load('multi_antenna.launch.py')
    declared, actions = _run(module.generate_launch_description(),
                             {'namespaces': 'a1, a2,a3', 'v0': '0'})
    assert 'namespace' not in declared
    nodes = [a for a in actions if type(a).__name__ == 'Node'
             and a.kwargs['executable'] == 'umbrella_node']
    assert [n.kwargs['namespace'] for n in nodes] == ['a1', 'a2', 'a3']
    assert [n.kwargs['parameters'][1]['frame_prefix'] for n in nodes] == ['a1/', 'a2/', 'a3/']
    # one record_path for all: a bag directory each (one directory takes one recording)
    _, actions = _run(module.generate_launch_description(),
                      {'namespaces': 'a1,a2', 'record_path': '/tmp/bags/run/'})
    assert [a.kwargs['parameters'][1]['record_path'] for a in actions
            if type(a).__name__ == 'Node' and a.kwargs['executable'] == 'umbrella_node'] == \
        ['/tmp/bags/run_a1', '/tmp/bags/run_a2']
    with pytest.raises(ValueError, match='a1 given twice'):
        ld.split_namespaces('a1,a1')


def test_package_xml_declares_what_the_code_imports():
    """Every ROS package that the code, the launch files or the tests import is declared."""
    import re

    pkg = ET.parse(os.path.join(ROOT, 'package.xml')).getroot()
    exec_deps = {d.text for d in pkg.iter('exec_depend')}
    test_deps = {d.text for d in pkg.iter('test_depend')}
    ros_pkgs = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs', 'sensor_msgs',
                'geometry_msgs', 'visualization_msgs', 'rosgraph_msgs', 'std_srvs',
                'diagnostic_msgs', 'ament_index_python', 'launch', 'launch_ros',
                'ament_flake8', 'ament_pep257'}

    def imported(folder):
        found = set()
        for dirpath, _, files in os.walk(os.path.join(ROOT, folder)):
            for f in files:
                if f.endswith('.py'):
                    with open(os.path.join(dirpath, f), encoding='utf-8') as fh:
                        found |= set(re.findall(r'^\s*(?:from|import) (\w+)', fh.read(), re.M))
        return found & ros_pkgs

    assert imported('umbrella_sim') | imported('launch') <= exec_deps
    assert imported('tests') <= exec_deps | test_deps
    assert {'robot_state_publisher', 'python3-mcap', 'python3-yaml'} <= exec_deps
    assert pkg.find('export/build_type').text == 'ament_python'


@pytest.mark.parametrize('model', ['rigid', 'rigid-fe', 'flexible'])
def test_urdf_loop_closure_misses_the_sleeve_by_the_elastic_displacement(model):
    """
    Forward kinematics of the URDF from joint_states, against the deformed mesh.

    The rigid models close the loop to round-off; for the flexible one the URDF's link end
    misses the sleeve H by exactly the distance between it and the deformed link's end,
    which the solver pins to H (robot_description's docstring gives the measured miss).
    """
    from umbrella_sim.core.driver import simulate
    from umbrella_sim.ros.messages import joint_state_values

    p = UmbrellaParams(model=model, v0=-0.5)
    result = simulate(p, 0.2, output_every=20)
    sim = UmbrellaSimulator(p)
    misses = []
    for s in result.samples:
        (a1, relative, y_h), _, _ = joint_state_values(s)
        a2 = a1 + relative
        urdf_end = np.array([p.l1 * math.cos(a1) + p.l3 * math.cos(a2),
                             p.l1 * math.sin(a1) + p.l3 * math.sin(a2)])
        sleeve = np.array([0.0, y_h])
        deformed_end = sim.model.node_positions(s.q)[1][-1]
        tolerance = 1e-12 + 10 * s.constraint_residual
        assert np.linalg.norm(deformed_end - sleeve) <= tolerance, s.time   # the pin holds
        miss = np.linalg.norm(urdf_end - sleeve)
        assert miss == pytest.approx(np.linalg.norm(urdf_end - deformed_end), abs=tolerance)
        misses.append(miss)
    if model == 'flexible':
        assert max(misses) > 1e-5        # the floating frames do not close it
    else:
        assert max(misses) < 1e-12
