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
The whole umbrella's markers against the 3D model's deformed positions.

The drawn points are checked against the model's own kinematics (its quadrature points'
positions, through its floating frames, azimuths and hub), and at the nodes against the
nodal coordinates read directly (no shape function); the message and its CDR bytes against
each other; one rib against the planar model's markers of the same run (the 3D model with
one rib is the planar model to round-off: tests/test_umbrella3d.py).
"""
import math

import numpy as np
import pytest

from umbrella_sim.bag.cdr import cdr_bytes
from umbrella_sim.core import UmbrellaParams, UmbrellaSimulator
from umbrella_sim.core.beam import shape_pieces_per_element
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.ros.messages import MarkerEncoder, markers_msg
from umbrella_sim.ros.umbrella_markers import UmbrellaMarkers, UmbrellaShapes
from visualization_msgs.msg import Marker

#: three unequal ribs on a 5 cm hub, two elements a segment, one kicked out of its plane
ASYMMETRIC = {'ribs': 3, 'hub_radius': 0.05, 'elements_per_segment': 2, 'v0': -0.5,
              'rib1.l2': 0.6, 'rib2.l1': 0.55, 'rib2.l3': 0.55, 'rib2.out_of_plane_rate': 0.5,
              'rib0.tip_mass': 0.05}


@pytest.fixture(scope='module')
def deformed():
    """Return an asymmetric 3D state 4 ms into the deployment: (simulator, qr, qs)."""
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(ASYMMETRIC))
    for _ in range(120):
        sim.step()
    return sim, sim.state.qr.copy(), sim.state.qs.copy()


def _in_hub_frame(model, rho):
    """Rib-frame points (R, P, 3) in umbrella_base: a e_r + rho at each rib's azimuth."""
    return np.einsum('rij,rpj->rpi', model.psi, rho + [model.hub_radius, 0.0, 0.0])


def test_points_are_the_models_deformed_positions(deformed):
    """At the model's quadrature abscissae the drawn points are its points, to round-off."""
    sim, qr, qs = deformed
    m = sim.model
    quad = [np.array([b.quad_x for b in bodies]) for bodies in (m.leaf_bodies, m.link_bodies)]
    drawn = UmbrellaShapes(m, abscissae=quad).positions(qr)
    kin = m.kinematics(qr, qs)
    for body, points, x in zip(('leaf', 'link'), drawn, quad):
        exact = _in_hub_frame(m, kin['bodies'][0 if body == 'leaf' else 1]['rho'])
        np.testing.assert_allclose(points, exact[:, :x.shape[1]], rtol=0, atol=1e-14,
                                   err_msg=body)
    # the state is deformed, in and out of the rib planes (the check is not of rigid frames)
    rigid = UmbrellaShapes(m, abscissae=quad).positions(qr, 0.0)
    elastic = drawn[0] - rigid[0]
    out_of_plane = np.einsum('rpi,ri->rp', elastic, m.psi[:, :, 2])
    assert np.abs(elastic).max() > 1e-5 and np.abs(out_of_plane[2]).max() > 1e-5


def test_drawn_nodes_are_the_nodal_coordinates_and_magnification_scales_them(deformed):
    """
    Every element's ends, in the default drawing, are its nodes' displaced positions.

    Read directly from the elastic coordinates (u, v, w of each node; 0 where a joint or
    the frame fixes it), turned by the body's angle about e_t, the link's moved to R2; the
    magnification multiplies the displacement in the body's frame only.
    """
    sim, qr, qs = deformed
    m = sim.model
    shapes = UmbrellaShapes(m)
    magnification = 30.0
    drawn = shapes.positions(qr, magnification)
    for i, (bodies, elastic, angle) in enumerate(((m.leaf_bodies, m.s_leaf_e, m.i_a1),
                                                  (m.link_bodies, m.s_link_e, m.i_a2))):
        per = shape_pieces_per_element(len(bodies[0].element_length))
        for k, body in enumerate(bodies):
            e = qr[k, elastic]
            nodes = np.zeros((len(body.node_x), 3))
            for j, x in enumerate(body.node_x):
                nodes[j, 0] = x
                for d, dof in enumerate(('u', 'v', 'w')):
                    at = body.maybe_index(j, dof)
                    nodes[j, d] += magnification * e[at] if at >= 0 else 0.0
            c, s = math.cos(qr[k, angle]), math.sin(qr[k, angle])
            rho = nodes @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
            if i == 1:
                rho = rho + qr[k, [m.i_rx, m.i_ry, m.i_rz]]
            exact = (rho + [m.hub_radius, 0.0, 0.0]) @ m.psi[k].T
            np.testing.assert_allclose(drawn[i][k, ::per], exact, rtol=0, atol=1e-13)
    rigid = shapes.positions(qr, 0.0)
    once = shapes.positions(qr, 1.0)
    for d, r, o in zip(drawn, rigid, once):
        np.testing.assert_allclose(d, r + magnification * (o - r), rtol=0, atol=1e-13)


def test_marker_array_of_n_ribs_and_its_bytes(deformed):
    """Rib k's leaf is id 2k and its link 2k + 1; then the sleeve and the hub; bytes = message."""
    sim, qr, qs = deformed
    m = sim.model
    markers = UmbrellaMarkers(m, 'a1', 'a1/')
    msg = markers.message(sim.time, qr, qs, 20.0)
    leaf, link = markers.shapes.positions(qr, 20.0)
    assert [x.id for x in msg.markers] == list(range(2 * m.n_ribs + 2))
    for k in range(m.n_ribs):
        for body, points in ((msg.markers[2 * k], leaf[k]), (msg.markers[2 * k + 1], link[k])):
            assert body.type == Marker.LINE_STRIP
            np.testing.assert_array_equal([(p.x, p.y, p.z) for p in body.points], points)
    sleeve, hub = msg.markers[-2:]
    assert sleeve.type == hub.type == Marker.CYLINDER
    assert (sleeve.pose.position.y, hub.pose.position.y) == (qs[0], 0.0)
    assert sleeve.scale.x == pytest.approx(2 * m.hub_radius + 0.03)
    # the ring's axis is +Y: the orientation turns z onto +Y
    q = sleeve.pose.orientation
    z_axis = (2 * (q.x * q.z + q.w * q.y), 2 * (q.y * q.z - q.w * q.x),
              1 - 2 * (q.x * q.x + q.y * q.y))
    np.testing.assert_allclose(z_axis, (0.0, 1.0, 0.0), atol=1e-15)
    for x in msg.markers:
        assert x.header.frame_id == 'a1/umbrella_base' and x.ns == 'a1'
        assert x.header.stamp.sec * 1e9 + x.header.stamp.nanosec == round(sim.time * 1e9)
    assert markers.encode(sim.time, qr, qs, 20.0) == cdr_bytes(msg)
    # and again at another state and time (the template's offsets hold)
    qr2 = qr.copy()
    qr2[:, m.i_a1] += 0.01
    assert markers.encode(1.25, qr2, qs * 0.9, 3.0) == cdr_bytes(
        markers.message(1.25, qr2, qs * 0.9, 3.0))


def test_one_rib_markers_are_the_planar_markers():
    """
    ribs: 1 draws what the planar model draws: same ids, types, frame, sleeve sphere, points.

    The 3D model with one rib on a hub of 5 cm and the planar model, run side by side: the
    markers agree to the identity's round-off (x magnification); the hub radius only moves
    the hub axis, which the planar frame (from O) leaves out.
    """
    values = {'time_step': 1e-4, 'sleeve_force': 10.0, 'phase_correction': False}
    planar = UmbrellaSimulator(UmbrellaParams(**values))
    # (the iteration matrix factored every step, the planar scheme's rule: test_umbrella3d.py)
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': 1, 'hub_radius': 0.05, **values}), carry_steps=1)
    markers = UmbrellaMarkers(sim.model, 'umbrella')
    magnification = 50.0
    for _ in range(3):
        for _ in range(60):
            sim.step()
            planar.step(record=False)
        s = planar.sample()
        assert s.time == pytest.approx(sim.time, abs=1e-15)
        positions = planar.model.deformed_shape(s.q, magnification)
        expected = markers_msg(s, positions, 'umbrella')
        got = markers.message(sim.time, sim.state.qr, sim.state.qs, magnification)
        assert len(got.markers) == len(expected.markers) == 3
        for g, e in zip(got.markers, expected.markers):
            assert (g.id, g.type, g.header.frame_id, g.scale, g.color, g.pose.orientation) == \
                (e.id, e.type, e.header.frame_id, e.scale, e.color, e.pose.orientation)
            assert g.header.stamp == e.header.stamp
            np.testing.assert_allclose([(p.x, p.y, p.z) for p in g.points],
                                       [(p.x, p.y, p.z) for p in e.points], rtol=0,
                                       atol=magnification * 1e-10)
        assert got.markers[2].pose.position.y == pytest.approx(s.sleeve_position, abs=1e-10)
        # the bytes the node would publish: the planar encoder's layout
        assert markers.encode(sim.time, sim.state.qr, sim.state.qs, magnification)[:64] == \
            MarkerEncoder(positions, 'umbrella').encode(s.time, s.sleeve_position,
                                                        positions)[:64]
