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
The locked umbrella's out-of-plane bending and torsion frequencies against independent models.

(b) of the umbrella's validation: the floating-frame model linearised at full deployment
(umbrella3d.modes3d) against a 3D frame model assembled here in global coordinates from the
textbook 12-coordinate beam element (Przemieniecki, Theory of Matrix Structural Analysis,
1968, Eq. 5.116 stiffness and Eq. 11.32 consistent mass; Cook, Malkus, Plesha & Witt,
Concepts and Applications of Finite Element Analysis, 2002, §2.4), its hinges as multi-point
constraints; the frame element itself against the published cantilever frequencies
(Blevins, Formulas for Natural Frequency and Mode Shape, 1979, Table 8-1: lambda_1 = 1.87510,
lambda_2 = 4.69409; torsion of a clamped-free shaft, omega = (2i - 1) pi / 2L sqrt(GJ / rho I_p)).
Both models use the same shape functions, so on the same mesh their frequencies agree to
round-off: what this checks is the floating frames, the joints (the hinge axes kept parallel at
O'', the hinges' held rotations at O and H) and the rib's orientation, not the discretisation.
"""
import math

import numpy as np
import pytest

from umbrella_sim.core import UmbrellaModel, UmbrellaParams
from umbrella_sim.core.umbrella3d.model3d import UmbrellaModel3D
from umbrella_sim.core.umbrella3d.modes3d import locked_modes
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams


def frame_element(length, ea, eiz, eiy, gj, rho_a, rho_ip):
    """Return the local 12 x 12 stiffness and consistent mass (u, v, w, rx, ry, rz per node)."""
    k, m = np.zeros((12, 12)), np.zeros((12, 12))
    L = length
    for i, j, a, b in ((0, 6, ea / L, rho_a * L / 6), (3, 9, gj / L, rho_ip * L / 6)):
        k[np.ix_([i, j], [i, j])] = a * np.array([[1, -1], [-1, 1]])
        m[np.ix_([i, j], [i, j])] = b * np.array([[2, 1], [1, 2]])
    kb = np.array([[12, 6 * L, -12, 6 * L], [6 * L, 4 * L * L, -6 * L, 2 * L * L],
                   [-12, -6 * L, 12, -6 * L], [6 * L, 2 * L * L, -6 * L, 4 * L * L]]) / L**3
    mb = rho_a * L / 420 * np.array([[156, 22 * L, 54, -13 * L],
                                     [22 * L, 4 * L * L, 13 * L, -3 * L * L],
                                     [54, 13 * L, 156, -22 * L],
                                     [-13 * L, -3 * L * L, -22 * L, 4 * L * L]])
    flip = np.diag([1, -1, 1, -1])          # bending in x-z: the rotation about y is -w'
    for dofs, ei, f in (([1, 5, 7, 11], eiz, np.eye(4)), ([2, 4, 8, 10], eiy, flip)):
        k[np.ix_(dofs, dofs)] = ei * f @ kb @ f
        m[np.ix_(dofs, dofs)] = f @ mb @ f
    return k, m


class Frame:
    """A 3D frame: nodes, elements in global coordinates, constraints C u = 0."""

    def __init__(self):
        self.nodes, self.elements, self.constraints = [], [], []

    def node(self, x):
        self.nodes.append(np.asarray(x, dtype=float))
        return len(self.nodes) - 1

    def beam(self, a, b, n, section, z_axis, first=None):
        """Add n elements from point a to b; return the node ids (first: an existing node)."""
        ids = [first if first is not None else self.node(a)]
        for i in range(1, n + 1):
            ids.append(self.node(a + (b - a) * i / n))
        ex = (b - a) / np.linalg.norm(b - a)
        ez = z_axis - (z_axis @ ex) * ex
        ez /= np.linalg.norm(ez)
        lam = np.array([ex, np.cross(ez, ex), ez])
        for i, j in zip(ids[:-1], ids[1:]):
            length = np.linalg.norm(self.nodes[j] - self.nodes[i])
            self.elements.append((i, j, lam, frame_element(length, **section)))
        return ids

    def fix(self, node, dofs):
        for d in dofs:
            row = np.zeros(6 * len(self.nodes))
            row[6 * node + d] = 1.0
            self.constraints.append((row, None))

    def tie(self, a, b, dofs):
        for d in dofs:
            self.constraints.append((a, b, d))

    def modes(self):
        from scipy.linalg import eigh, null_space

        n = 6 * len(self.nodes)
        k, m = np.zeros((n, n)), np.zeros((n, n))
        for i, j, lam, (ke, me) in self.elements:
            t = np.kron(np.eye(4), lam)
            dofs = list(range(6 * i, 6 * i + 6)) + list(range(6 * j, 6 * j + 6))
            k[np.ix_(dofs, dofs)] += t.T @ ke @ t
            m[np.ix_(dofs, dofs)] += t.T @ me @ t
        rows = []
        for c in self.constraints:
            if len(c) == 2:
                rows.append(np.resize(c[0], n))
            else:
                a, b, d = c
                row = np.zeros(n)
                row[6 * a + d], row[6 * b + d] = 1.0, -1.0
                rows.append(row)
        z = null_space(np.array(rows))
        w2 = eigh(z.T @ k @ z, z.T @ m @ z, eigvals_only=True)
        return np.sqrt(np.maximum(w2, 0.0))


def section_of(p: UmbrellaParams, nu=0.33):
    area, inertia, e = p.cross_section_area, p.cross_section_inertia, p.youngs_modulus
    shear = e / (2 * (1 + nu))
    return {'ea': e * area, 'eiz': e * inertia, 'eiy': e * inertia,
            'gj': shear * 0.8436 * 2 * inertia, 'rho_a': p.mass_per_length,
            'rho_ip': p.density * 2 * inertia}


def rib_frame(p: UmbrellaParams, n: int, hub: float = 0.0):
    """Return the locked rib 0 (plane X-Y, hinge axes along Z) as a 3D frame, deployed."""
    f = Frame()
    a = p.alpha_deployed
    ez = np.array([0.0, 0.0, 1.0])
    o = np.array([hub, 0.0, 0.0])
    d = np.array([math.cos(a), math.sin(a), 0.0])
    joint, tip = o + p.l1 * d, o + (p.l1 + p.l2) * d
    h = np.array([hub, p.sleeve_stop_height, 0.0])
    sec = section_of(p)
    leaf1 = f.beam(o, joint, n, sec, ez)
    f.beam(joint, tip, n, sec, ez, first=leaf1[-1])
    link = f.beam(joint, h, n, sec, ez)
    f.fix(leaf1[0], (0, 1, 2, 3, 4))          # hinge O: all but the rotation about Z
    f.tie(leaf1[-1], link[0], (0, 1, 2, 3, 4))    # hinge O'': the same, relative
    f.fix(link[-1], (0, 1, 2, 3, 4))          # sleeve at the stop, hinge H about Z
    return f


@pytest.mark.parametrize('n', [1, 2, 4])
def test_locked_frequencies_equal_an_independent_3d_frame_model(n):
    p = UmbrellaParams(elements_per_segment=n)
    model = UmbrellaModel3D(UmbrellaRibsParams.from_mapping({'elements_per_segment': n}))
    omega, _, labels = locked_modes(model)
    reference = rib_frame(p, n).modes()
    assert len(omega) == len(reference)
    np.testing.assert_allclose(omega, reference, rtol=1e-9)
    # the modes out of the plane are there: the first is out-of-plane bending, and a
    # torsion-dominated one exists
    assert labels[0][1] > 0.9
    assert any(lab[2] > 0.5 for lab in labels)
    # in-plane, the planar model's locked modes
    in_plane = omega[[lab[0] > 0.5 for lab in labels]]
    planar = UmbrellaModel(p).locked_modes[0]
    np.testing.assert_allclose(in_plane, planar, rtol=1e-9)


def test_several_ribs_and_a_hub_radius_repeat_the_rib_modes():
    """The sleeve held, the ribs decouple: each frequency N-fold, whatever the azimuth."""
    n = 1
    model = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(
        {'ribs': 3, 'elements_per_segment': n, 'hub_radius': 0.1, 'sleeve_mass': 0.5}))
    omega, _, _ = locked_modes(model)
    single = rib_frame(UmbrellaParams(elements_per_segment=n), n, hub=0.1).modes()
    np.testing.assert_allclose(omega, np.repeat(single, 3), rtol=1e-9)


def cantilever_check():
    """
    Return a 1 m cantilever of the thesis's section on 16 frame elements, and its references.

    (its frequencies, Blevins Table 8-1's first two bending ones, the clamped-free shaft's
    first torsion one pi/2L sqrt(GJ / rho I_p)), in rad/s.
    """
    sec = section_of(UmbrellaParams())
    f = Frame()
    ids = f.beam(np.zeros(3), np.array([1.0, 0.0, 0.0]), 16, sec, np.array([0.0, 0.0, 1.0]))
    f.fix(ids[0], range(6))
    bend = [lam**2 * math.sqrt(sec['eiz'] / sec['rho_a']) for lam in (1.87510, 4.69409)]
    return f.modes(), bend, math.pi / 2 * math.sqrt(sec['gj'] / sec['rho_ip'])


def test_the_frame_element_gives_the_published_cantilever_frequencies():
    """Blevins Table 8-1 (bending) and the clamped-free shaft (torsion), 16 elements."""
    omega, bend, torsion = cantilever_check()
    # bending: each frequency twice (both planes, square section)
    np.testing.assert_allclose(omega[[0, 1, 2, 3]], np.repeat(bend, 2), rtol=2e-4)
    assert np.min(np.abs(omega / torsion - 1)) < 2e-3
