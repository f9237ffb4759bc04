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
The whole umbrella's URDF (N ribs) against the 3D model.

The URDF is read back with xml.etree and its forward kinematics computed here from the
URDF's own rules (origin xyz, fixed-axis rpy, a revolute joint's axis-angle rotation, a
prismatic joint's translation), independently of the generator; the model's geometry is
that of core.umbrella3d (its rigid-rib configurations, its body points' kinematics).
"""
import math
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.umbrella3d.model3d import UmbrellaModel3D
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.ros import robot_description as rd
from umbrella_sim.ros.messages import JOINT_NAMES

#: five ribs of unequal lengths, sections and masses on a hub of 5 cm
UNEQUAL = {'ribs': 5, 'hub_radius': 0.05, 'sleeve_mass': 0.2, 'rib1.l2': 0.6,
           'rib2.l1': 0.55, 'rib2.l3': 0.55, 'rib3.density': 5400.0,
           'rib3.section_height': 0.012, 'rib4.tip_mass': 0.1, 'rib4.tip_offset_z': 0.02}


def _vector(text: str | None, default=(0.0, 0.0, 0.0)) -> np.ndarray:
    return np.array([float(v) for v in text.split()]) if text else np.array(default)


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    """Return the rotation of URDF's fixed-axis rpy: Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _axis_angle(axis: np.ndarray, q: float) -> np.ndarray:
    """Rodrigues' rotation by q about the unit vector axis."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(q) * k + (1 - math.cos(q)) * k @ k


def forward_kinematics(robot, positions: dict) -> dict:
    """Return {link: 4x4 transform umbrella_base <- link} of the URDF at joint positions."""
    joints = {j.find('child').get('link'): j for j in robot.iter('joint')}
    out = {}

    def pose(link):
        if link in out:
            return out[link]
        if link not in joints:
            out[link] = np.eye(4)
            return out[link]
        j = joints[link]
        origin = j.find('origin')
        t = np.eye(4)
        t[:3, :3] = _rpy(*_vector(origin.get('rpy')))
        t[:3, 3] = _vector(origin.get('xyz'))
        q = positions.get(j.get('name'), 0.0)
        motion = np.eye(4)
        if j.get('type') == 'revolute':
            motion[:3, :3] = _axis_angle(_vector(j.find('axis').get('xyz')), q)
        elif j.get('type') == 'prismatic':
            motion[:3, 3] = q * _vector(j.find('axis').get('xyz'))
        out[link] = pose(j.find('parent').get('link')) @ t @ motion
        return out[link]

    for link in robot.iter('link'):
        pose(link.get('name'))
    return out


def _point(frame: np.ndarray, xyz) -> np.ndarray:
    return frame[:3, :3] @ np.asarray(xyz, dtype=float) + frame[:3, 3]


# --------------------------------------------------------------------------- one rib
def test_one_rib_is_the_planar_urdf_and_its_names():
    """ribs: 1 is today's URDF, of rib 0's values, and the planar joint names."""
    assert rd.urdf(UmbrellaRibsParams.from_mapping({'ribs': 1})) == rd.urdf()
    assert rd.urdf(UmbrellaRibsParams.from_mapping({'ribs': 1, 'rib0.l2': 0.6})) == \
        rd.urdf(UmbrellaParams(l2=0.6))
    assert rd.joint_names(1) == JOINT_NAMES == rd.MOVING_JOINTS
    with pytest.raises(ValueError, match='ribs=0'):
        rd.joint_names(0)


# --------------------------------------------------------------------------- the tree
@pytest.mark.parametrize('ribs', [2, 3, 6])
def test_urdf_of_n_ribs_is_one_tree_with_the_published_joint_names(ribs):
    robot = ET.fromstring(rd.urdf(UmbrellaRibsParams.from_mapping({'ribs': ribs})))
    links = [link.get('name') for link in robot.iter('link')]
    joints = list(robot.iter('joint'))
    names = [j.get('name') for j in joints]
    assert len(links) == len(set(links)) == 2 + 3 * ribs       # base, sleeve; leaf, link, tip
    assert len(names) == len(set(names)) == 1 + 3 * ribs
    children = [j.find('child').get('link') for j in joints]
    parents = {j.find('child').get('link'): j.find('parent').get('link') for j in joints}
    assert sorted(children) == sorted(set(links) - {'umbrella_base'})     # one parent each
    for link in links:              # every link reaches the root without a cycle
        seen = [link]
        while seen[-1] != 'umbrella_base':
            seen.append(parents[seen[-1]])
            assert len(seen) <= len(links)
    moving = [j.get('name') for j in joints if j.get('type') != 'fixed']
    assert sorted(moving) == sorted(rd.joint_names(ribs))
    expected = {'sleeve_slider': ('prismatic', 'umbrella_base', 'sleeve')}
    for k in range(ribs):
        expected[f'rib{k}/leaf_hinge'] = ('revolute', 'umbrella_base', f'rib{k}/leaf')
        expected[f'rib{k}/link_hinge'] = ('revolute', f'rib{k}/leaf', f'rib{k}/link')
        expected[f'rib{k}/leaf_tip'] = ('fixed', f'rib{k}/leaf', f'rib{k}/tip')
    assert {j.get('name'): (j.get('type'), j.find('parent').get('link'),
                            j.find('child').get('link')) for j in joints} == expected


def test_urdf_masses_are_the_models_rib_masses():
    """Each rib's leaf (with its tip mass) and link, and the sleeve, weigh what the model's do."""
    params = UmbrellaRibsParams.from_mapping(UNEQUAL)
    model = UmbrellaModel3D(params)
    robot = ET.fromstring(rd.urdf(params))
    mass = {link.get('name'): float(link.find('inertial/mass').get('value'))
            for link in robot.iter('link') if link.find('inertial') is not None}
    for k in range(model.n_ribs):
        leaf = mass[f'rib{k}/leaf'] + mass.get(f'rib{k}/tip', 0.0)
        assert leaf == pytest.approx(model.leaf.w[k].sum(), rel=1e-8)
        assert mass[f'rib{k}/link'] == pytest.approx(model.link.w[k].sum(), rel=1e-8)
    assert mass['sleeve'] == pytest.approx(model.sleeve_mass, rel=1e-8)
    assert sum(mass.values()) == pytest.approx(model.total_mass, rel=1e-8)
    assert len({mass[f'rib{k}/leaf'] for k in range(5)}) == 4       # ribs 1, 2, 3 their own


# --------------------------------------------------------------------------- geometry
def _rigid_state(model: UmbrellaModel3D, y: float):
    """Every rib rigid with its link's end at sleeve height y (the model's own closure)."""
    qr = np.array([model.rigid_rib(k, model.rib_angle_at_height(k, y))
                   for k in range(model.n_ribs)])
    qs = np.zeros(model.n_shared)
    qs[0] = y
    return qr, qs


def _joint_positions(model: UmbrellaModel3D, qr, qs) -> dict:
    """Return the joint_states values the node publishes for a 3D state (URDF names)."""
    out = {'sleeve_slider': qs[0]}
    for k in range(model.n_ribs):
        out[f'rib{k}/leaf_hinge'] = qr[k, model.i_a1]
        out[f'rib{k}/link_hinge'] = qr[k, model.i_a2] - qr[k, model.i_a1]
    return out


def _model_points(model: UmbrellaModel3D, qr, qs) -> list[np.ndarray]:
    """Each body's quadrature points in the hub frame, (R, P, 3): the model's kinematics."""
    kin = model.kinematics(qr, qs)
    return [np.einsum('rij,rpj->rpi', model.psi, bk['rho'] + [model.hub_radius, 0.0, 0.0])
            for bk in kin['bodies']]


@pytest.mark.parametrize('height_fraction', [0.0, 0.4, 1.0])
def test_urdf_forward_kinematics_is_the_models_rigid_geometry(height_fraction):
    """
    The URDF's frames at the rigid ribs' joint values put every body where the model does.

    At sleeve heights from the start to the stop: each rib's leaf and link points (the
    model's quadrature points: hub radius, azimuth, floating frames) on the URDF's leaf and
    link x axes, each rib's link end on the sleeve's rim at a e_r (the loop the URDF leaves
    out closes), and every hinge axis along the rib's tangential e_t: orthogonal to the
    rib's plane (e_r, Y) at its azimuth.
    """
    params = UmbrellaRibsParams.from_mapping(UNEQUAL)
    model = UmbrellaModel3D(params)
    robot = ET.fromstring(rd.urdf(params))
    y = model.y_start + height_fraction * (model.y_stop - model.y_start)
    qr, qs = _rigid_state(model, y)
    frames = forward_kinematics(robot, _joint_positions(model, qr, qs))
    leaf_pts, link_pts = _model_points(model, qr, qs)
    joints = {j.get('name'): j for j in robot.iter('joint')}
    links = {link.get('name'): link for link in robot.iter('link')}
    sleeve = _point(frames['sleeve'], (0.0, 0.0, 0.0))
    np.testing.assert_allclose(sleeve, [0.0, y, 0.0], atol=1e-15)
    for k, rib in enumerate(model.ribs):
        psi = 2.0 * math.pi * k / model.n_ribs
        e_r = np.array([math.cos(psi), 0.0, -math.sin(psi)])
        e_t = np.cross(e_r, [0.0, 1.0, 0.0])
        n_quad = len(model.leaf_bodies[k].quad_x)
        for body, pts, xs in ((f'rib{k}/leaf', leaf_pts, model.leaf_bodies[k].quad_x),
                              (f'rib{k}/link', link_pts, model.link_bodies[k].quad_x)):
            urdf_pts = np.array([_point(frames[body], (x, 0.0, 0.0)) for x in xs])
            np.testing.assert_allclose(urdf_pts, pts[k, :len(xs)], rtol=0, atol=1e-12,
                                       err_msg=body)
        # the tip mass: the model's attached point, the URDF tip link's inertial origin
        inertial = links[f'rib{k}/tip'].find('inertial/origin')
        offset = _vector(None if inertial is None else inertial.get('xyz'))
        np.testing.assert_allclose(_point(frames[f'rib{k}/tip'], offset), leaf_pts[k, n_quad],
                                   rtol=0, atol=1e-12)
        link_end = _point(frames[f'rib{k}/link'], (rib.planar.l3, 0.0, 0.0))
        np.testing.assert_allclose(link_end, sleeve + model.hub_radius * e_r, atol=1e-12)
        tip = _point(frames[f'rib{k}/tip'], (0.0, 0.0, 0.0))
        np.testing.assert_allclose(tip, _point(frames[f'rib{k}/leaf'],
                                               (rib.planar.l1 + rib.planar.l2, 0, 0)))
        for name in ('leaf_hinge', 'link_hinge'):
            j = joints[f'rib{k}/{name}']
            parent = frames[j.find('parent').get('link')]
            axis = parent[:3, :3] @ _rpy(*_vector(j.find('origin').get('rpy'))) @ _vector(
                j.find('axis').get('xyz'))
            np.testing.assert_allclose(axis, e_t, atol=1e-15, err_msg=name)
            assert abs(axis @ e_r) < 1e-15 and abs(axis[1]) < 1e-15


def test_mujoco_reads_the_urdf_with_the_models_bodies_and_masses():
    """
    Read by MuJoCo, a URDF parser of its own, the URDF puts every body where the model does.

    At a rigid state of five unequal ribs: each leaf's and link's points from MuJoCo's
    forward kinematics are the model's, and each body's mass and centre of mass (MuJoCo
    fuses the fixed tip, with rib 4's tip mass off the rib's plane, into its leaf) are the
    model's mass-weighted points'.  MuJoCo refuses a massless moving body: the thesis's
    massless sleeve is given a microgram for the check.
    """
    mujoco = pytest.importorskip('mujoco')
    params = UmbrellaRibsParams.from_mapping({**UNEQUAL, 'sleeve_mass': 0.0})
    model = UmbrellaModel3D(params)
    spec = mujoco.MjSpec.from_string(rd.urdf(params))
    spec.body('sleeve').mass, spec.body('sleeve').inertia = 1e-9, [1e-12] * 3
    mj = spec.compile()
    data = mujoco.MjData(mj)
    qr, qs = _rigid_state(model, 0.5 * (model.y_start + model.y_stop))
    for name, value in _joint_positions(model, qr, qs).items():
        data.qpos[mj.jnt_qposadr[mj.joint(name).id]] = value
    mujoco.mj_kinematics(mj, data)
    mujoco.mj_comPos(mj, data)
    points = _model_points(model, qr, qs)
    for k in range(model.n_ribs):
        for i, body in enumerate((f'rib{k}/leaf', f'rib{k}/link')):
            b = mj.body(body).id
            x = (model.leaf_bodies, model.link_bodies)[i][k].quad_x
            frame = data.xmat[b].reshape(3, 3)
            np.testing.assert_allclose(data.xpos[b] + np.outer(x, frame[:, 0]),
                                       points[i][k, :len(x)], rtol=0, atol=1e-12)
            w = (model.leaf, model.link)[i].w[k]
            assert mj.body_mass[b] == pytest.approx(w.sum(), rel=1e-8)
            np.testing.assert_allclose(data.xipos[b], w @ points[i][k] / w.sum(), rtol=0,
                                       atol=1e-8)
    np.testing.assert_allclose(data.xpos[mj.body('sleeve').id], [0.0, qs[0], 0.0],
                               atol=1e-15)


def test_urdf_of_a_flexible_state_misses_the_sleeve_by_the_elastic_displacement():
    """
    With flexible ribs the URDF's rigid frames miss each pin by the elastic displacements.

    An asymmetric run (a rib kicked out of its plane, one with a tip mass): from the
    published joint values the URDF puts rib k's link end at l1 e_x(leaf) + l3 e_x(link),
    the model pins its deformed end, R2 + (l3 + u_H) e_x(link) + w_H e_t, to the sleeve's
    rim; their difference is the leaf's (u, w) at O'' and the link's (u, w) at H, exactly.
    """
    params = UmbrellaRibsParams.from_mapping({**UNEQUAL, 'v0': -0.5,
                                              'rib2.out_of_plane_rate': 0.5})
    sim = UmbrellaSimulator3D(params)
    m = sim.model
    robot = ET.fromstring(rd.urdf(params))
    largest = 0.0
    for _ in range(4):
        for _ in range(40):
            sim.step()
        qr, qs = sim.state.qr, sim.state.qs
        frames = forward_kinematics(robot, _joint_positions(m, qr, qs))
        sleeve = _point(frames['sleeve'], (0.0, 0.0, 0.0))
        for k, rib in enumerate(m.ribs):
            e_r = m.psi[k][:, 0]
            leaf, link = frames[f'rib{k}/leaf'][:3, :3], frames[f'rib{k}/link'][:3, :3]
            urdf_end = _point(frames[f'rib{k}/link'], (rib.planar.l3, 0.0, 0.0))
            elastic = (leaf @ [qr[k, m.i_u1], 0.0, qr[k, m.i_w1]]
                       + link @ [qr[k, m.i_uh], 0.0, qr[k, m.i_wh]])
            rim = sleeve + m.hub_radius * e_r
            np.testing.assert_allclose(urdf_end + elastic, rim, rtol=0, atol=1e-10)
            largest = max(largest, float(np.linalg.norm(urdf_end - rim)))
    assert largest > 1e-7          # the floating frames do not close the loops themselves


# --------------------------------------------------------------------------- launch
def test_launch_passes_the_whole_umbrellas_urdf_to_robot_state_publisher(tmp_path):
    """
    The params file's ribs, hub, per-rib lists and overrides make robot_description.

    Tested through launch_description.plan (launch and robot_state_publisher are not on
    PyPI: the test says where they would be installed); without robot_state_publisher the
    plan logs that it is missing and starts the node alone.
    """
    from umbrella_sim.ros import launch_description as ld

    params_file = tmp_path / 'ribs.yaml'
    # (the node's forms: a rib's own values as rib.<name> lists or rib<k>.<name>)
    params_file.write_text('/**:\n  ros__parameters:\n    ribs: 4\n    hub_radius: 0.05\n'
                           '    rib:\n      tip_mass: [0.0, 0.0, 0.1, 0.0]\n'
                           '    rib1:\n      l2: 0.6\n    publish_rate: 200.0\n')
    values = {a.name: a.default for a in ld.arguments()}
    values.update(params_file=str(params_file), namespace='a3')
    actions = ld.plan(values, installed=lambda pkg: f'/opt/share/{pkg}')
    rsp = next(a for a in actions if isinstance(a, ld.NodeAction)
               and a.package == 'robot_state_publisher')
    (given,) = rsp.parameters
    robot = ET.fromstring(given['robot_description'])
    assert given['robot_description'] == rd.urdf(UmbrellaRibsParams.from_mapping(
        {'ribs': 4, 'hub_radius': 0.05, 'tip_mass': [0.0, 0.0, 0.1, 0.0], 'rib1.l2': 0.6}))
    moving = [j.get('name') for j in robot.iter('joint') if j.get('type') != 'fixed']
    assert moving == rd.joint_names(4)[-1:] + rd.joint_names(4)[:-1]   # sleeve first
    tips = {j.get('name'): float(j.find('origin').get('xyz').split()[0])
            for j in robot.iter('joint') if j.get('name').endswith('leaf_tip')}
    assert tips == {'rib0/leaf_tip': 1.0, 'rib1/leaf_tip': 1.1, 'rib2/leaf_tip': 1.0,
                    'rib3/leaf_tip': 1.0}
    assert given['frame_prefix'] == 'a3/'
    # no robot_state_publisher: the node alone and a log line saying so
    actions = ld.plan(values, installed=lambda pkg: None)
    assert [a.executable for a in actions if isinstance(a, ld.NodeAction)] == ['umbrella_node']
    assert any('robot_state_publisher is not installed' in a.msg for a in actions
               if isinstance(a, ld.LogAction))
    # a bad umbrella value is refused, naming it, before anything is started
    params_file.write_text('/**:\n  ros__parameters:\n    ribs: 3\n'
                           '    rib:\n      tip_mass: [0.0, 0.0, 0.1, 0.0]\n')
    for installed in (None, '/opt/share'):
        with pytest.raises(ValueError, match='tip_mass: a list of 4 values for 3 ribs'):
            ld.plan(values, installed=lambda pkg: installed)


def test_the_command_line_prints_the_urdf_of_the_values_given(capsys):
    # without launch (a PyPI-only install) the N-rib URDF still comes from the same values
    assert rd.main([]) == 0
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with open(os.path.join(root, 'urdf', 'umbrella.urdf'), encoding='utf-8') as fh:
        assert capsys.readouterr().out == fh.read()           # (the shipped file is it)
    assert rd.main(['ribs=3', 'rib1.tip_mass=0.1']) == 0
    assert capsys.readouterr().out == rd.urdf(UmbrellaRibsParams.from_mapping(
        {'ribs': 3, 'rib1.tip_mass': 0.1}))
    for bad, words in ((['ribs'], "'ribs': give name=value pairs"),
                       (['l1=-1'], 'l1=-1.0: must be > 0'),
                       (['youngs_modulous=7e10'], "did you mean 'youngs_modulus'"),
                       (['ribs=3', 'rib.l2=[0.5,0.6'], "'rib.l2=[0.5,0.6': not a value"),
                       (['l1=0.5', 'l1=0.6'], 'l1 given twice')):
        assert rd.main(bad) == 2
        assert words in capsys.readouterr().err


def test_a_misspelt_per_rib_name_is_refused_not_left_out_of_the_urdf(tmp_path, capsys):
    """
    rib1.tip_mas, rib.tip_mas, rib99.tip_mass: the URDF tools refuse them, as the node does.

    Left out, the URDF was printed (exit 0) without the tip mass the user meant to give,
    and the launch file would have passed robot_state_publisher that URDF.
    """
    from umbrella_sim.ros import launch_description as ld

    for bad, words in ((['ribs=6', 'rib1.tip_mas=0.1'], "per-rib parameter 'rib1.tip_mas'"),
                       (['ribs=6', 'rib.tip_mas=[0, 0, 0, 0, 0, 0.1]'],
                        "per-rib parameter 'rib.tip_mas'"),
                       (['ribs=6', 'rib99.tip_mass=0.1'], 'rib99.tip_mass: there are ribs')):
        assert rd.main(bad) == 2
        captured = capsys.readouterr()
        assert captured.out == '' and words in captured.err
    # the launch file: a params file's misspelt rib value, and a launch argument's
    params_file = tmp_path / 'ribs.yaml'
    params_file.write_text('/**:\n  ros__parameters:\n    ribs: 3\n'
                           '    rib1:\n      tip_mas: 0.1\n')
    values = {a.name: a.default for a in ld.arguments()}
    values.update(params_file=str(params_file))
    with pytest.raises(ValueError, match="per-rib parameter 'rib1.tip_mas'"):
        ld.plan(values, installed=lambda pkg: '/opt/share')
    with pytest.raises(ValueError, match="per-rib parameter 'rib.tip_mas'"):
        ld.overrides({'rib.tip_mas': '[0.0, 0.1, 0.0]'})
