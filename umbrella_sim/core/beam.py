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
The Euler-Bernoulli beam element and body in a floating frame (thesis ch. 3).

A body is a chain of elements along its frame's X axis: Hermite cubic transverse and linear
axial shape functions (Eq. 3.17), the element maps [B_j] (Eq. 3.15), and the state-independent
integrals of mass and stiffness (M = int rho C^T C dx, Eq. 4.7; K, Eq. 4.37) by exact Gauss
quadrature.  The planar frame (model.py) and the 3D ribs (umbrella3d) build on it.
"""
from __future__ import annotations

import numpy as np

#: 5-point Gauss-Legendre on [0, 1] (exact to degree 9): the element integrals
GAUSS_POINTS, GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(5)
GAUSS_POINTS = 0.5 * (GAUSS_POINTS + 1.0)
GAUSS_WEIGHTS = 0.5 * GAUSS_WEIGHTS
_DOF = {'u': 0, 'v': 1, 'theta': 2}


def shape_functions(eta: np.ndarray, le: float):
    """
    [N] (3.4), d[N]/dx and d2[N]/dx2 (corrected Eq. 5.40) at local coordinates eta.

    Returns three arrays of shape (len(eta), 2, 6), element dofs (u_i v_i th_i u_j v_j th_j).
    """
    eta = np.asarray(eta, dtype=float)
    z = np.zeros_like(eta)
    one = np.ones_like(eta)
    n = np.stack([
        np.stack([1 - eta, z, z, eta, z, z], -1),
        np.stack([z, 1 - 3 * eta**2 + 2 * eta**3, le * (eta - 2 * eta**2 + eta**3),
                  z, 3 * eta**2 - 2 * eta**3, le * (eta**3 - eta**2)], -1)], -2)
    dn = np.stack([
        np.stack([-one / le, z, z, one / le, z, z], -1),
        np.stack([z, (-6 * eta + 6 * eta**2) / le, 1 - 4 * eta + 3 * eta**2,
                  z, (6 * eta - 6 * eta**2) / le, 3 * eta**2 - 2 * eta], -1)], -2)
    d2n = np.stack([
        np.stack([z, z, z, z, z, z], -1),
        np.stack([z, (-6 + 12 * eta) / le**2, (-4 + 6 * eta) / le,
                  z, (6 - 12 * eta) / le**2, (6 * eta - 2) / le], -1)], -2)
    return n, dn, d2n


#: a drawn body's least number of pieces (markers, plots), its elements split evenly
SHAPE_PIECES = 16


def shape_pieces_per_element(n_elements: int) -> int:
    """Return the pieces each element of a body of n_elements is drawn in (>= 1)."""
    return max(1, -(-SHAPE_PIECES // n_elements))


def shape_abscissae(node_x, per_element: int) -> np.ndarray:
    """Return the body abscissae of a drawn shape: each element in per_element equal pieces."""
    node_x = np.asarray(node_x, dtype=float)
    eta = np.arange(per_element) / per_element
    return np.append((node_x[:-1, None] + np.diff(node_x)[:, None] * eta).ravel(), node_x[-1])


def element_dof_maps(n_elements: int, node_dofs: int, full_to_e: np.ndarray,
                     n_elastic: int) -> np.ndarray:
    """
    Return each element's map from the body's elastic coordinates to its nodal ones.

    [B_j] of Eq. 3.15: (n_elements, 2 node_dofs, n_elastic) of ones and zeros; element j
    holds nodes j and j + 1, full_to_e maps a nodal dof to its elastic coordinate (-1 where
    the dof is fixed).
    """
    maps = np.zeros((n_elements, 2 * node_dofs, n_elastic))
    for j in range(n_elements):
        for k, full in enumerate(range(node_dofs * j, node_dofs * (j + 2))):
            if full_to_e[full] >= 0:
                maps[j, k, full_to_e[full]] = 1.0
    return maps


class BeamBody:
    """
    One Euler-Bernoulli body in its floating frame: mesh, invariants, stiffness, stress.

    segments: [(length, n_elements), ...] laid end to end from the frame origin;
    fixed: [(node, 'u'|'v'|'theta'), ...] nodal coordinates removed by the frame choice.
    The elastic coordinates e are the remaining nodal (u, v, theta), node by node.
    """

    def __init__(self, name: str, segments, fixed, mass_per_length: float, ea: float, ei: float,
                 youngs_modulus: float, fibre: float):
        self.name = name
        lengths = [seg_len / n for seg_len, n in segments for _ in range(n)]
        self.element_length = np.array(lengths)
        self.node_x = np.concatenate([[0.0], np.cumsum(lengths)])
        self.length = float(self.node_x[-1])
        n_nodes = len(self.node_x)
        removed = {3 * node + _DOF[c] for node, c in fixed}
        free = [d for d in range(3 * n_nodes) if d not in removed]
        self.n_elastic = len(free)
        full_to_e = -np.ones(3 * n_nodes, dtype=int)
        full_to_e[free] = np.arange(self.n_elastic)
        self._full_to_e = full_to_e
        ne = self.n_elastic
        self.element_dof_maps = element_dof_maps(len(lengths), 3, full_to_e, ne)

        # --- quadrature points of the whole body: S(x) maps e to (u, v) at x
        xs, ws, shapes = [], [], []
        for j, le in enumerate(lengths):
            n, _, _ = shape_functions(GAUSS_POINTS, le)
            shapes.append(n @ self.element_dof_maps[j])
            xs.append(self.node_x[j] + le * GAUSS_POINTS)
            ws.append(le * GAUSS_WEIGHTS)
        self.quad_x = np.concatenate(xs)
        self.quad_w = np.concatenate(ws) * mass_per_length      # rho A dx
        self.quad_shape = np.concatenate(shapes)                 # (nq, 2, ne)

        # --- invariants (state independent): kinetic energy is at most quadratic in e
        w, x, s = self.quad_w, self.quad_x, self.quad_shape
        su, sv = s[:, 0, :], s[:, 1, :]
        self.mass = float(w.sum())
        self.first_moment = float(w @ x)                          # int rho x
        self.j0 = float(w @ x**2)                                 # int rho x^2
        self.s_bar = np.einsum('q,qie->ie', w, s)                 # int rho S      (2, ne)
        self.c = np.einsum('q,q,qe->e', w, x, su)                 # int rho x S_u  (ne)
        self.g = np.einsum('q,q,qe->e', w, x, sv)                 # int rho x S_v  (ne)
        self.m_ff = np.einsum('q,qie,qif->ef', w, s, s)           # int rho S^T S  (ne, ne)
        self.w_skew = (np.einsum('q,qe,qf->ef', w, su, sv)
                       - np.einsum('q,qe,qf->ef', w, sv, su))     # int rho (Su^T Sv - Sv^T Su)
        self.p_bar = np.array([self.first_moment, 0.0])

        # --- stiffness (4.37, 4.42): EI v''^2 + EA u'^2, exact quadrature
        k = np.zeros((ne, ne))
        for j, le in enumerate(lengths):
            _, dn, d2n = shape_functions(GAUSS_POINTS, le)
            b = self.element_dof_maps[j]
            ke = (ei * np.einsum('q,qi,qj->ij', le * GAUSS_WEIGHTS, d2n[:, 1], d2n[:, 1])
                  + ea * np.einsum('q,qi,qj->ij', le * GAUSS_WEIGHTS, dn[:, 0], dn[:, 0]))
            k += b.T @ ke @ b
        self.stiffness = k

        # --- stress recovery at both ends of every element (sigma is linear in an element)
        axial, curvature, px = [], [], []
        for j, le in enumerate(lengths):
            _, dn, d2n = shape_functions(np.array([0.0, 1.0]), le)
            b = self.element_dof_maps[j]
            axial.append(dn[:, 0] @ b)
            curvature.append(d2n[:, 1] @ b)
            px.append(self.node_x[j] + np.array([0.0, le]))
        self.stress_x = np.concatenate(px)
        self.n_stress_points = len(self.stress_x)
        # sigma_top/bottom = E (u' -/+ c v'') (Eq. 5.43-5.44, y = +c is the top fibre)
        ax, cu = np.concatenate(axial), np.concatenate(curvature)
        self.stress_top = youngs_modulus * (ax - fibre * cu)
        self.stress_bottom = youngs_modulus * (ax + fibre * cu)

    def elastic_index(self, node: int, dof: str) -> int:
        idx = int(self._full_to_e[3 * node + _DOF[dof]])
        if idx < 0:
            raise KeyError(f'{self.name} node {node} {dof} is fixed by the frame')
        return idx

    def displacement(self, e: np.ndarray, x: np.ndarray) -> np.ndarray:
        """(u, v) at body abscissae x (Eq. 3.16): shape (len(x), 2)."""
        x = np.atleast_1d(np.asarray(x, dtype=float))
        j = np.clip(np.searchsorted(self.node_x, x, side='right') - 1, 0,
                    len(self.element_length) - 1)
        out = np.empty((len(x), 2))
        for i, (xi, ji) in enumerate(zip(x, j)):
            le = self.element_length[ji]
            n, _, _ = shape_functions(np.array([(xi - self.node_x[ji]) / le]), le)
            out[i] = (n[0] @ self.element_dof_maps[ji]) @ e
        return out

    def shape_matrix(self, per_element: int):
        """(shape_abscissae, S): S (points, 2, n_elastic) maps e to (u, v) at each point."""
        eta = np.arange(per_element) / per_element
        rows = [shape_functions(eta, le)[0] @ b
                for le, b in zip(self.element_length, self.element_dof_maps)]
        rows.append(shape_functions(np.ones(1), self.element_length[-1])[0]
                    @ self.element_dof_maps[-1])
        return shape_abscissae(self.node_x, per_element), np.concatenate(rows)
