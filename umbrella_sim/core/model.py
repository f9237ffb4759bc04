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
Floating-frame finite-element model of the planar leaf + link umbrella frame.

Model layer: parameters -> geometry, mesh, constant shape-function integrals, and the
state-dependent matrices of the constrained Lagrangian DAE (thesis ch. 3-4)

    M(q) q'' + K q = Qv(q, q') + Qe(q, F_H) + J(q)^T lambda,     Phi(q) = 0      (4.87)

Generalised coordinates (3.25), generalised to N elements per segment:

    q = [alpha1, e_leaf (6N), R2x, R2y, alpha2, e_link (3N)]

The leaf frame has its origin at O and its X' axis through O'' (u = v = 0 at O, v = 0 at O''),
the link frame its origin at O'' and its X'' axis through H (u = v = 0 at O'', v = 0 at H)
(3.9, 3.13).  Every matrix is derived from its definition (M = int rho C^T C dx, Eq. 4.7;
K from Eq. 4.37) by exact Gauss quadrature of the Hermite/linear shape functions, so none of
the printed errata of the thesis enters.  Nothing here imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass
import enum
from functools import cached_property
import math

import numpy as np

from .beam import BeamBody, shape_pieces_per_element
from .params import UmbrellaParams


class Stage(enum.StrEnum):
    """Stage of the deployment; compares equal to its name string ("deploying", "locked")."""

    DEPLOYING = 'deploying'     # Case 1: the sleeve slides down the axle
    LOCKED = 'locked'           # Case 2: the sleeve held at the stop S

    @property
    def code(self) -> int:
        """0 deploying, 1 locked (StepBlock.stage, the compiled kernel)."""
        return 0 if self is Stage.DEPLOYING else 1


DEFORMING, LOCKED = Stage.DEPLOYING, Stage.LOCKED


def _cos_sin(alpha):
    if isinstance(alpha, complex) or np.iscomplexobj(alpha):
        return np.cos(alpha), np.sin(alpha)
    return math.cos(alpha), math.sin(alpha)


def rotation(alpha):
    """Return [A] of Eq. 3.6 (works for complex alpha, for complex-step tests)."""
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[c, -s], [s, c]])


def band_form(a: np.ndarray, bw: int) -> np.ndarray:
    """Return the square matrix a (zero beyond half bandwidth bw) as band[p, k] = a[p, p+k-bw]."""
    ne = len(a)
    band = np.zeros((ne, 2 * bw + 1))
    for k in range(-bw, bw + 1):
        d = np.diagonal(a, k)
        if k >= 0:
            band[:ne - k, bw + k] = d
        else:
            band[-k:, bw + k] = d
    return band


@dataclass(frozen=True)
class ConstraintSet:
    """
    Which constraints hold.

    Phi1-3 always (4.60), Phi4 when locked (4.63),
    Phi5-6 (all elastic coordinates) in the rigid-FE mode (4.71).
    """

    locked: bool
    rigid: bool


class UmbrellaModel:
    """Assembled system: M(q), K, Qv, Qe, constraints and outputs, for any mesh."""

    def __init__(self, params: UmbrellaParams):
        p = params.validated()
        self.params = p
        n = p.elements_per_segment
        area, inertia = p.cross_section_area, p.cross_section_inertia
        rho_a, e_mod = p.mass_per_length, p.youngs_modulus
        common = {'mass_per_length': rho_a, 'ea': e_mod * area, 'ei': e_mod * inertia,
                  'youngs_modulus': e_mod, 'fibre': p.fibre_distance}
        self.leaf = BeamBody('leaf', [(p.l1, n), (p.l2, n)],
                             [(0, 'u'), (0, 'v'), (n, 'v')], **common)
        self.link = BeamBody('link', [(p.l3, n)], [(0, 'u'), (0, 'v'), (n, 'v')], **common)
        n1, n2 = self.leaf.n_elastic, self.link.n_elastic
        self.i_alpha1 = 0
        self.s_leaf = slice(1, 1 + n1)
        self.i_r2x, self.i_r2y, self.i_alpha2 = 1 + n1, 2 + n1, 3 + n1
        self.s_link = slice(4 + n1, 4 + n1 + n2)
        self.n = 4 + n1 + n2
        # coordinates used by the joints
        self.i_u_joint = 1 + self.leaf.elastic_index(n, 'u')        # leaf u at O''
        self.i_u_sleeve = 4 + n1 + self.link.elastic_index(n, 'u')  # link u at H
        tip = 2 * n
        self.i_tip_u = 1 + self.leaf.elastic_index(tip, 'u')
        self.i_tip_v = 1 + self.leaf.elastic_index(tip, 'v')
        self.elastic_indices = np.r_[np.arange(1, 1 + n1), np.arange(4 + n1, 4 + n1 + n2)]
        self.y_stop = p.sleeve_stop_height

        self.stiffness = np.zeros((self.n, self.n))
        self.stiffness[self.s_leaf, self.s_leaf] = self.leaf.stiffness
        self.stiffness[self.s_link, self.s_link] = self.link.stiffness
        m0 = np.zeros((self.n, self.n))
        m0[self.s_leaf, self.s_leaf] = self.leaf.m_ff
        m0[self.s_link, self.s_link] = self.link.m_ff
        m0[self.i_r2x, self.i_r2x] = m0[self.i_r2y, self.i_r2y] = self.link.mass
        self._mass_template = m0
        # full-length (n) copies of the body invariants, so the hot kernels are a few
        # vector operations whatever the mesh: zero outside each body's elastic slice
        n_all = self.n
        self._c_full = np.zeros(n_all)
        self._g_full = np.zeros(n_all)
        self._mff_full = np.zeros((n_all, n_all))
        self._w_full = np.zeros((n_all, n_all))
        self._body_rows = np.zeros((2, n_all))
        self._body_angle = np.zeros(n_all, dtype=int)
        for row, (s_e, ia, body) in enumerate(((self.s_leaf, 0, self.leaf),
                                               (self.s_link, self.i_alpha2, self.link))):
            self._c_full[s_e] = body.c
            self._g_full[s_e] = body.g
            self._mff_full[s_e, s_e] = body.m_ff
            self._w_full[s_e, s_e] = body.w_skew
            self._body_rows[row, s_e] = 1.0
            self._body_angle[s_e] = ia
        self._j0 = np.array([self.leaf.j0, self.link.j0])
        self._link_sbar = self.link.s_bar
        self._link_isbar = np.array([-self.link.s_bar[1], self.link.s_bar[0]])  # I~ S_bar
        self._link_pbar = self.link.p_bar
        self._shape_maps: dict = {}      # (body, pieces per element) -> deformed_shape's maps

    def coordinate_labels(self) -> list[str]:
        """Names of the entries of q, e.g. 'leaf.u2' = axial displacement of leaf node 2."""
        labels = ['alpha1']
        for body in (self.leaf, self.link):
            names = [''] * body.n_elastic
            for node in range(len(body.node_x)):
                for dof in ('u', 'v', 'theta'):
                    try:
                        names[body.elastic_index(node, dof)] = f'{body.name}.{dof}{node}'
                    except KeyError:
                        pass
            labels += names
            if body is self.leaf:
                labels += ['R2x', 'R2y', 'alpha2']
        return labels

    # ------------------------------------------------- structure (compiled kernel)
    def banded_invariants(self):
        """
        Return the constant elastic matrices in band form.

        The constant matrices on the elastic coordinates (leaf then link, node by node),
        in band form: (half_bandwidth, mass Mff, stiffness K, coupling W), each of shape
        (n_elastic, 2 bw + 1) with entry [p, k] = A[e_p, e_(p + k - bw)].  An element couples
        the coordinates of two neighbouring nodes, so bw <= 5 whatever the mesh.
        """
        idx = self.elastic_indices
        mats = [self._mff_full[np.ix_(idx, idx)], self.stiffness[np.ix_(idx, idx)],
                self._w_full[np.ix_(idx, idx)]]
        rows, cols = np.nonzero(np.any([a != 0.0 for a in mats], axis=0))
        bw = int(np.max(np.abs(rows - cols))) if len(rows) else 0
        bands = [band_form(a, bw) for a in mats]
        return bw, bands[0], bands[1], bands[2]

    def stress_rows(self):
        """
        Return the fibre-stress recovery as sparse rows over q.

        Fibre stress at the stress points of both bodies (leaf first, then link) as
        sparse rows over q: (q indices, top coefficients, bottom coefficients) each of shape
        (points, width), plus the points' abscissae and the point count per body.
        """
        rows = []
        for body, s_e in ((self.leaf, self.s_leaf), (self.link, self.s_link)):
            for top, bottom in zip(body.stress_top, body.stress_bottom):
                nz = np.nonzero((top != 0.0) | (bottom != 0.0))[0]
                rows.append((nz + s_e.start, top[nz], bottom[nz]))
        width = max(1, max(len(r[0]) for r in rows))
        idx = np.zeros((len(rows), width), dtype=np.intc)
        top = np.zeros((len(rows), width))
        bottom = np.zeros((len(rows), width))
        for k, (i, t, b) in enumerate(rows):
            idx[k, :len(i)], top[k, :len(i)], bottom[k, :len(i)] = i, t, b
        x = np.concatenate([self.leaf.stress_x, self.link.stress_x])
        return idx, top, bottom, x, (len(self.leaf.stress_x), len(self.link.stress_x))

    # ---------------------------------------------------------------- inertia
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """
        Return M(q) = int rho C^T C dx (4.7, 4.35), from the invariants.

        per body M_aa = J0 + 2 c.e + e.Mff e, M_af = g + e W (rotation-deformation),
        link M_Ra = A I~ (p_bar + S_bar e), M_Rf = A S_bar (translation couplings).
        """
        h = self._c_full + self._mff_full @ q
        m_aa = self._j0 + self._body_rows @ ((self._c_full + h) * q)
        m_af = self._g_full + q @ self._w_full
        m = self._mass_template.astype(m_af.dtype, copy=True)
        sl, sk, ia, ix, iy = self.s_leaf, self.s_link, self.i_alpha2, self.i_r2x, self.i_r2y
        m[0, 0] = m_aa[0]
        m[ia, ia] = m_aa[1]
        m[0, sl] = m[sl, 0] = m_af[sl]
        m[ia, sk] = m[sk, ia] = m_af[sk]
        c, s = _cos_sin(q[ia])
        ub = self._link_pbar + self._link_sbar @ q[sk]
        m[ix, ia] = m[ia, ix] = -c * ub[1] - s * ub[0]          # A I~ u_bar
        m[iy, ia] = m[ia, iy] = -s * ub[1] + c * ub[0]
        m_rf = c * self._link_sbar + s * self._link_isbar          # A S_bar
        m[ix:iy + 1, sk] = m_rf
        m[sk, ix:iy + 1] = m_rf.T
        return m

    def quadratic_velocity_forces(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Qv = -Mdot q' + (dT/dq)^T (4.84), in closed form from the invariants."""
        lf, lk = self.leaf, self.link
        out = np.zeros(self.n, dtype=np.result_type(q, qd, float))
        e1, ed1, w1 = q[self.s_leaf], qd[self.s_leaf], qd[0]
        h1 = lf.c + lf.m_ff @ e1
        out[0] = -2.0 * w1 * (h1 @ ed1)
        out[self.s_leaf] = w1 * w1 * h1 + 2.0 * w1 * (lf.w_skew @ ed1)
        e2, ed2, w2 = q[self.s_link], qd[self.s_link], qd[self.i_alpha2]
        h2 = lk.c + lk.m_ff @ e2
        a2 = rotation(q[self.i_alpha2])
        ubar = lk.p_bar + lk.s_bar @ e2
        sd = lk.s_bar @ ed2
        out[self.i_r2x:self.i_r2y + 1] = a2 @ (w2 * w2 * ubar
                                               - 2.0 * w2 * np.array([-sd[1], sd[0]]))
        out[self.i_alpha2] = -2.0 * w2 * (h2 @ ed2)
        out[self.s_link] = w2 * w2 * h2 + 2.0 * w2 * (lk.w_skew @ ed2)
        return out

    def kinetic_bilinear_gradient(self, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """d/dq [1/2 a^T M(q) b]; with a = b = q' it is (dT/dq)^T of Eq. 4.86."""
        h = self._c_full + self._mff_full @ q
        wa, wb = a[self._body_angle], b[self._body_angle]
        out = wa * wb * h + 0.5 * (wa * (self._w_full @ b) + wb * (self._w_full @ a))
        sk, ia, i2 = self.s_link, self.i_alpha2, slice(self.i_r2x, self.i_r2y + 1)
        c, s = _cos_sin(q[ia])
        ub = self._link_pbar + self._link_sbar @ q[sk]
        a_ub = np.array([c * ub[0] - s * ub[1], s * ub[0] + c * ub[1]])   # A u_bar
        a_is = c * self._link_isbar - s * self._link_sbar                  # A I~ S_bar
        ar, br = a[i2], b[i2]
        ar_is, br_is = ar @ a_is, br @ a_is
        out[ia] = (-0.5 * ((ar @ a_ub) * b[ia] + (br @ a_ub) * a[ia])
                   + 0.5 * (ar_is @ b[sk] + br_is @ a[sk]))
        out[sk] += 0.5 * (b[ia] * ar_is + a[ia] * br_is)
        return out

    def gyroscopic_matrix(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """-dQv/dq' (used only in the Newton iteration matrix)."""
        lf, lk = self.leaf, self.link
        g = np.zeros((self.n, self.n))
        for s_e, ia, body in ((self.s_leaf, 0, lf), (self.s_link, self.i_alpha2, lk)):
            e, ed, w = q[s_e], qd[s_e], qd[ia]
            h = body.c + body.m_ff @ e
            g[ia, ia] = 2.0 * (h @ ed)
            g[ia, s_e] = 2.0 * w * h
            g[s_e, ia] = -2.0 * w * h - 2.0 * (body.w_skew @ ed)
            g[s_e, s_e] = -2.0 * w * body.w_skew
        a2 = rotation(q[self.i_alpha2])
        w2 = qd[self.i_alpha2]
        ubar = lk.p_bar + lk.s_bar @ q[self.s_link]
        sd = lk.s_bar @ qd[self.s_link]
        i2 = slice(self.i_r2x, self.i_r2y + 1)
        g[i2, self.i_alpha2] = -a2 @ (2.0 * w2 * ubar - 2.0 * np.array([-sd[1], sd[0]]))
        g[i2, self.s_link] = 2.0 * w2 * a2 @ np.array([-lk.s_bar[1], lk.s_bar[0]])
        return g

    # reference path (tests only): analytic directional derivative of M
    def mass_matrix_derivative(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """dM(q + eps dq)/deps at eps = 0; Mdot = this with dq = q'."""
        lf, lk = self.leaf, self.link
        dm = np.zeros((self.n, self.n))
        for s_e, ia, body in ((self.s_leaf, 0, lf), (self.s_link, self.i_alpha2, lk)):
            e, de = q[s_e], dq[s_e]
            dm[ia, ia] = 2.0 * body.c @ de + 2.0 * e @ body.m_ff @ de
            dm[ia, s_e] = de @ body.w_skew
            dm[s_e, ia] = de @ body.w_skew
        a2, da = rotation(q[self.i_alpha2]), dq[self.i_alpha2]
        ubar = lk.p_bar + lk.s_bar @ q[self.s_link]
        dubar = lk.s_bar @ dq[self.s_link]
        i2 = slice(self.i_r2x, self.i_r2y + 1)
        d_ra = a2 @ np.array([-dubar[1], dubar[0]]) - da * (a2 @ ubar)
        d_rf = da * (a2 @ np.array([-lk.s_bar[1], lk.s_bar[0]]))
        dm[i2, self.i_alpha2] = d_ra
        dm[self.i_alpha2, i2] = d_ra
        dm[i2, self.s_link] = d_rf
        dm[self.s_link, i2] = d_rf.T
        return dm

    def kinetic_energy_gradient(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """(dT/dq)^T = 1/2 q'^T dM/dq_k q' (4.86), reference path (tests only)."""
        eye = np.eye(self.n)
        return np.array([0.5 * qd @ self.mass_matrix_derivative(q, eye[k]) @ qd
                         for k in range(self.n)])

    # ---------------------------------------------------------------- energy
    def kinetic_energy(self, q, qd) -> float:
        return 0.5 * qd @ self.mass_matrix(q) @ qd

    def strain_energy(self, q) -> float:
        return 0.5 * q @ self.stiffness @ q

    # ----------------------------------------------------------- constraints
    def sleeve_height(self, q) -> float:
        """y_H (4.58)."""
        return q[self.i_r2y] + (self.params.l3 + q[self.i_u_sleeve]) * np.sin(q[self.i_alpha2])

    def sleeve_height_gradient(self, q) -> np.ndarray:
        g = np.zeros(self.n)
        a2, lu = q[self.i_alpha2], self.params.l3 + q[self.i_u_sleeve]
        g[self.i_r2y] = 1.0
        g[self.i_alpha2] = lu * math.cos(a2)
        g[self.i_u_sleeve] = math.sin(a2)
        return g

    def applied_forces(self, q, sleeve_force: float) -> np.ndarray:
        """Q^{appl} for F = (0, -F_H) at H (4.81)."""
        return -sleeve_force * self.sleeve_height_gradient(q)

    def n_constraints(self, cs: ConstraintSet) -> int:
        return 3 + int(cs.locked) + (len(self.elastic_indices) if cs.rigid else 0)

    def constraint_residual(self, q, cs: ConstraintSet) -> np.ndarray:
        """Phi(q): joint O'' (4.53-4.54), H on the axle (4.59), H at S (4.63), e = 0 (4.71)."""
        l1, l3 = self.params.l1, self.params.l3
        a1, a2 = q[0], q[self.i_alpha2]
        r1 = l1 + q[self.i_u_joint]
        r3 = l3 + q[self.i_u_sleeve]
        phi = [r1 * np.cos(a1) - q[self.i_r2x], r1 * np.sin(a1) - q[self.i_r2y],
               q[self.i_r2x] + r3 * np.cos(a2)]
        if cs.locked:
            phi.append(q[self.i_r2y] + r3 * np.sin(a2) - self.y_stop)
        out = np.array(phi)
        if cs.rigid:
            out = np.concatenate([out, q[self.elastic_indices]])
        return out

    def constraint_jacobian(self, q, cs: ConstraintSet) -> np.ndarray:
        l1, l3 = self.params.l1, self.params.l3
        a1, a2 = q[0], q[self.i_alpha2]
        c1, s1, c2, s2 = math.cos(a1), math.sin(a1), math.cos(a2), math.sin(a2)
        r1, r3 = l1 + q[self.i_u_joint], l3 + q[self.i_u_sleeve]
        j = np.zeros((self.n_constraints(cs), self.n))
        j[0, 0], j[0, self.i_u_joint], j[0, self.i_r2x] = -r1 * s1, c1, -1.0
        j[1, 0], j[1, self.i_u_joint], j[1, self.i_r2y] = r1 * c1, s1, -1.0
        j[2, self.i_r2x], j[2, self.i_alpha2], j[2, self.i_u_sleeve] = 1.0, -r3 * s2, c2
        row = 3
        if cs.locked:
            j[3, self.i_r2y], j[3, self.i_alpha2], j[3, self.i_u_sleeve] = 1.0, r3 * c2, s2
            row = 4
        if cs.rigid:
            j[row + np.arange(len(self.elastic_indices)), self.elastic_indices] = 1.0
        return j

    def constraint_bias(self, q, qd, cs: ConstraintSet) -> np.ndarray:
        """-Jdot q' (right-hand side of J q'' = -Jdot q', Eq. 4.62)."""
        l1, l3 = self.params.l1, self.params.l3
        a1, a2 = q[0], q[self.i_alpha2]
        w1, w2 = qd[0], qd[self.i_alpha2]
        c1, s1, c2, s2 = math.cos(a1), math.sin(a1), math.cos(a2), math.sin(a2)
        r1, r3 = l1 + q[self.i_u_joint], l3 + q[self.i_u_sleeve]
        d1, d3 = qd[self.i_u_joint], qd[self.i_u_sleeve]
        jd = [-2 * d1 * w1 * s1 - r1 * w1 * w1 * c1, 2 * d1 * w1 * c1 - r1 * w1 * w1 * s1,
              -2 * d3 * w2 * s2 - r3 * w2 * w2 * c2]
        if cs.locked:
            jd.append(2 * d3 * w2 * c2 - r3 * w2 * w2 * s2)
        out = -np.array(jd)
        if cs.rigid:
            out = np.concatenate([out, np.zeros(len(self.elastic_indices))])
        return out

    # ------------------------------------------------------- initial state
    def rigid_configuration(self, alpha1: float) -> np.ndarray:
        """Return q of the undeformed mechanism at leaf angle alpha1 (5.21)."""
        p = self.params
        q = np.zeros(self.n)
        q[0] = alpha1
        q[self.i_r2x] = p.l1 * math.cos(alpha1)
        q[self.i_r2y] = p.l1 * math.sin(alpha1)
        q[self.i_alpha2] = math.acos(-p.l1 / p.l3 * math.cos(alpha1))
        return q

    @cached_property
    def locked_modes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Return (omega, phi, mass) of the locked frame linearised at full deployment.

        K x = omega^2 M x on the null space of the locked constraint Jacobian, about the
        undeformed deployed configuration: omega ascending (rad/s), phi (n, modes) mass-
        normalised (phi^T M phi = I), mass = M there.
        """
        from scipy.linalg import eigh, null_space

        q = self.rigid_configuration(self.params.alpha_deployed)
        z = null_space(self.constraint_jacobian(q, ConstraintSet(locked=True, rigid=False)))
        mass = self.mass_matrix(q)
        w2, psi = eigh(z.T @ self.stiffness @ z, z.T @ mass @ z)
        omega = np.sqrt(np.maximum(w2, 0.0))
        if not omega[0] > 0.0:         # (a section too slender for double precision)
            p = self.params
            raise ValueError(
                f'the locked frame has {int(np.sum(omega <= 0.0))} mode(s) without stiffness: '
                f'its bending stiffness E I = {p.youngs_modulus * p.cross_section_inertia:.3g} '
                'N m^2 is lost in the round-off of its mass; give a larger section '
                f'(section_height={p.section_height:g} m, second_moment_of_area)')
        return omega, z @ psi, mass

    def rigid_velocity(self, q: np.ndarray, alpha1_rate: float) -> np.ndarray:
        p = self.params
        a1, a2 = q[0], q[self.i_alpha2]
        qd = np.zeros(self.n)
        qd[0] = alpha1_rate
        qd[self.i_r2x] = -p.l1 * math.sin(a1) * alpha1_rate
        qd[self.i_r2y] = p.l1 * math.cos(a1) * alpha1_rate
        qd[self.i_alpha2] = -p.l1 * math.sin(a1) * alpha1_rate / (p.l3 * math.sin(a2))
        return qd

    def initial_state(self, v0: float | None = None):
        """Undeformed at alpha0 with the sleeve moving at v0 along Y (5.21, 5.30-5.33)."""
        p = self.params
        v0 = p.v0 if v0 is None else v0
        q = self.rigid_configuration(p.alpha0)
        unit = self.rigid_velocity(q, 1.0)
        qd = unit * (v0 / (self.sleeve_height_gradient(q) @ unit))
        return q, qd

    # --------------------------------------------------------------- outputs
    def tip_displacement(self, q) -> tuple[float, float]:
        """(axial, transverse) displacement of G in the leaf frame."""
        return float(q[self.i_tip_u]), float(q[self.i_tip_v])

    def stresses(self, q):
        """Top/bottom fibre stress at both ends of every element, per body (Pa)."""
        e1, e2 = q[self.s_leaf], q[self.s_link]
        return ((self.leaf.stress_top @ e1, self.leaf.stress_bottom @ e1),
                (self.link.stress_top @ e2, self.link.stress_bottom @ e2))

    def stress_rates(self, q, qd):
        """d/dt of ``stresses`` at (q, qd) (Pa/s): linear in q, so ``stresses`` of qd."""
        return UmbrellaModel.stresses(self, qd)

    @cached_property
    def reference_stress_points(self) -> tuple[int, int, float]:
        """(leaf stress point at O'', link element holding l3/2, where in it)."""
        n = self.params.elements_per_segment
        x_mid = 0.5 * self.params.l3
        j = min(int(np.searchsorted(self.link.node_x, x_mid, side='right')) - 1, n - 1)
        frac = float((x_mid - self.link.node_x[j]) / self.link.element_length[j])
        return 2 * n - 1, j, frac

    def reference_stresses(self, leaf_top, link_top) -> tuple[float, float]:
        """
        Return the reference top-fibre stresses.

        On the leaf at O'' (end of the inner segment) and at mid-link
        (linear within the element holding l3/2).  The compiled twin: _kernel.c
        sample_vector, on reference_stress_points.
        """
        joint, j, frac = self.reference_stress_points
        # plain floats (.item): once per publication
        return (float(leaf_top.item(joint)),
                (1.0 - frac) * link_top.item(2 * j) + frac * link_top.item(2 * j + 1))

    def deformed_shape(self, q, magnification: float = 1.0, per_element: int | None = None):
        """
        Inertial (X, Y) of points along the leaf and the link, deformation magnified.

        Each element drawn by its own shape functions (3.4: transverse displacement cubic,
        axial linear), split into per_element equal pieces: by default
        shape_pieces_per_element (at least SHAPE_PIECES a body), 1 = the nodes only.  A
        body's points lie at shape_abscissae(body.node_x, per_element).  The one rule of
        every drawn shape: markers, umbrella_compare's shapes, the docs' figures.
        """
        q = np.asarray(q)
        out = []
        for body, s_e, origin, alpha in (
                (self.leaf, self.s_leaf, np.zeros(2), q[0]),
                (self.link, self.s_link, q[[self.i_r2x, self.i_r2y]], q[self.i_alpha2])):
            k = per_element or shape_pieces_per_element(len(body.element_length))
            if (body.name, k) not in self._shape_maps:
                x, s = body.shape_matrix(k)
                self._shape_maps[body.name, k] = (np.column_stack([x, np.zeros_like(x)]), s)
            rest, s = self._shape_maps[body.name, k]
            out.append(origin + (rest + magnification * (s @ q[s_e])) @ rotation(alpha).T)
        return out

    def node_positions(self, q, magnification: float = 1.0):
        """Inertial (X, Y) of the leaf and link nodes, deformation magnified."""
        return self.deformed_shape(q, magnification, per_element=1)
