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
One 3D Euler-Bernoulli beam body in its floating frame: mesh, quadrature points, stiffness.

The element is the 3D frame element of Przemieniecki (Theory of Matrix Structural Analysis,
1968, ch. 5) and Cook et al. (Concepts and Applications of Finite Element Analysis, 4th ed.,
§2.4): linear axial displacement u and twist phi, cubic Hermite bending v (in the rib plane)
and w (out of it).  Six coordinates a node, in the body's frame (x along the beam, y in the
rib plane, z tangential, out of it):

    u, v, theta = v' (rotation about z), w, slope = w' (the rotation about y is -w'), twist

Strain energy (Eq. 4.37 of Hu, McGill 2006 with the out-of-plane and torsion terms added):

    V = 1/2 int [ EA u'^2 + E I_z v''^2 + E I_y w''^2 + G J phi'^2 ] dx

Kinetic energy of the centre line, int rho A |r'|^2 / 2 (Euler-Bernoulli: no rotary inertia
of bending), plus the twist's rotary inertia int rho I_p phi'^2 / 2 (St-Venant torsion).
Every matrix comes from its definition by 5-point Gauss quadrature, exact for these
polynomials, as in the planar ``BeamBody``.
"""
from __future__ import annotations

import numpy as np

from ..beam import element_dof_maps, GAUSS_POINTS, GAUSS_WEIGHTS, shape_functions

DOFS = ('u', 'v', 'theta', 'w', 'slope', 'twist')
_DOF = {name: k for k, name in enumerate(DOFS)}


def shape_functions_3d(eta: np.ndarray, le: float):
    """
    Return N (displacement u, v, w), N' (u', v', w'), N'' and the twist's N_phi, N_phi'.

    Shapes (len(eta), 3, 12), (len(eta), 3, 12), (len(eta), 3, 12), (len(eta), 12),
    (len(eta), 12) over the element's coordinates (node i's six, node j's six).
    """
    planar = shape_functions(eta, le)       # the same axial/twist lines and Hermite cubics
    k = planar[0].shape[0]
    n, dn, d2n = (np.zeros((k, 3, 12)) for _ in range(3))
    for out, plane in zip((n, dn, d2n), planar):
        out[:, 0, [0, 6]] = plane[:, 0, [0, 3]]
        out[:, 1, [1, 2, 7, 8]] = plane[:, 1, [1, 2, 4, 5]]      # v and its slope
        out[:, 2, [3, 4, 9, 10]] = plane[:, 1, [1, 2, 4, 5]]     # w and its slope
    nphi = np.zeros((k, 12))
    dphi = np.zeros((k, 12))
    nphi[:, [5, 11]] = planar[0][:, 0, [0, 3]]
    dphi[:, [5, 11]] = planar[1][:, 0, [0, 3]]
    return n, dn, d2n, nphi, dphi


class BeamBody3D:
    """
    One body: segments [(length, n_elements)] end to end from the frame origin.

    fixed: [(node, dof name)] removed by the frame choice or by a hinge; the elastic
    coordinates e are the remaining nodal ones, node by node in DOFS order.
    section: dict of rho_a, rho_ip (rho I_p), ea, ei_z, ei_y, gj, youngs, shear, fibre
    (bending fibre distance), torsion_fibre (c_t: tau = G phi' c_t).
    """

    def __init__(self, name: str, segments, fixed, section: dict):
        self.name = name
        lengths = [seg / n for seg, n in segments for _ in range(n)]
        self.element_length = np.array(lengths)
        self.node_x = np.concatenate([[0.0], np.cumsum(lengths)])
        self.length = float(self.node_x[-1])
        n_full = 6 * len(self.node_x)
        removed = {6 * node + _DOF[d] for node, d in fixed}
        free = [d for d in range(n_full) if d not in removed]
        self.n_elastic = ne = len(free)
        full_to_e = -np.ones(n_full, dtype=int)
        full_to_e[free] = np.arange(ne)
        self._full_to_e = full_to_e
        n_el = len(lengths)
        self.element_maps = element_dof_maps(n_el, 6, full_to_e, ne)
        xs, ws, shapes = [], [], []
        k = np.zeros((ne, ne))
        m_twist = np.zeros((ne, ne))
        axial, bend_z, bend_y, twist, px = [], [], [], [], []
        s = section
        for j, le in enumerate(lengths):
            b = self.element_maps[j]
            n, dn, d2n, nphi, dphi = shape_functions_3d(GAUSS_POINTS, le)
            wq = le * GAUSS_WEIGHTS
            shapes.append(n @ b)
            xs.append(self.node_x[j] + le * GAUSS_POINTS)
            ws.append(wq)
            ke = (s['ea'] * np.einsum('q,qi,qj->ij', wq, dn[:, 0], dn[:, 0])
                  + s['ei_z'] * np.einsum('q,qi,qj->ij', wq, d2n[:, 1], d2n[:, 1])
                  + s['ei_y'] * np.einsum('q,qi,qj->ij', wq, d2n[:, 2], d2n[:, 2])
                  + s['gj'] * np.einsum('q,qi,qj->ij', wq, dphi, dphi))
            k += b.T @ ke @ b
            m_twist += b.T @ (s['rho_ip'] * np.einsum('q,qi,qj->ij', wq, nphi, nphi)) @ b
            _, dn2, d2n2, _, dphi2 = shape_functions_3d(np.array([0.0, 1.0]), le)
            axial.append(dn2[:, 0] @ b)
            bend_z.append(d2n2[:, 1] @ b)
            bend_y.append(d2n2[:, 2] @ b)
            twist.append(dphi2 @ b)
            px.append(self.node_x[j] + np.array([0.0, le]))
        self.quad_x = np.concatenate(xs)
        self.quad_w = np.concatenate(ws) * s['rho_a']
        self.quad_shape = np.concatenate(shapes)             # (P, 3, ne)
        self.stiffness = k
        self.twist_mass = m_twist
        self.mass = float(self.quad_w.sum())
        # stress recovery at both ends of every element (Pa per unit coordinate)
        self.stress_x = np.concatenate(px)
        self.stress_axial = s['youngs'] * np.concatenate(axial)
        self.stress_bend_z = s['youngs'] * s['fibre'] * np.concatenate(bend_z)
        self.stress_bend_y = s['youngs'] * s['fibre'] * np.concatenate(bend_y)
        self.stress_shear = s['shear'] * s['torsion_fibre'] * np.concatenate(twist)

    def index(self, node: int, dof: str) -> int:
        """Return the elastic index of a nodal coordinate (KeyError if it is removed)."""
        idx = int(self._full_to_e[6 * node + _DOF[dof]])
        if idx < 0:
            raise KeyError(f'{self.name} node {node} {dof} is fixed')
        return idx

    def maybe_index(self, node: int, dof: str) -> int:
        """Return the elastic index of a nodal coordinate, -1 if it is removed."""
        return int(self._full_to_e[6 * node + _DOF[dof]])

    def attached_point(self, node: int, offset) -> tuple[np.ndarray, np.ndarray]:
        """
        Return (X, S) of a point rigidly attached to a node's section at an offset d.

        Position X + S e in the body frame: the node's displacement plus theta x d, theta =
        (twist, -slope, theta) the section's small rotation (X = (x_node, 0, 0) + d).
        """
        d = np.asarray(offset, dtype=float)
        s = np.zeros((3, self.n_elastic))

        def add(row, dof, coef):
            i = self.maybe_index(node, dof)
            if i >= 0:
                s[row, i] += coef

        for row, dof in enumerate(('u', 'v', 'w')):
            add(row, dof, 1.0)
        # theta x d with theta = (tx, ty, tz) = (twist, -slope, theta)
        add(0, 'slope', -d[2])          # ty dz
        add(0, 'theta', -d[1])          # -tz dy
        add(1, 'theta', d[0])           # tz dx
        add(1, 'twist', -d[2])          # -tx dz
        add(2, 'twist', d[1])           # tx dy
        add(2, 'slope', d[0])           # -ty dx
        x = np.array([self.node_x[node], 0.0, 0.0]) + d
        return x, s
