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
The umbrella's ribs as co-rotational beams (model flexible-nonlinear, ribs >= 2).

Deployment is a large motion in each rib's plane (the links buckle at V0 <= -1 m/s, the
sections turn by up to ~1.3 rad from their body frames); out of the plane the ribs see
perturbations (a kicked rib, a jolt of the base, unequal ribs).  So each element is the
planar co-rotational Euler-Bernoulli element of core/nonlinear.py (Crisfield, Non-linear
Finite Element Analysis of Solids and Structures vol. 1, ch. 7: the planar element in its
co-rotated frame) in its rib's plane, exactly, with its out-of-plane bending and torsion
measured in the same element's co-rotated frame as small rotations.  Per element, from its
chord d = (l_e + u_b - u_a, v_b - v_a, w_b - w_a) in its body's frame, the nodal slopes
theta_i = v'_i and w'_i and the twists phi_i (the body's coordinates, beam3d.DOFS):

    lambda = |d| / l_e                 (the 3D chord: an out-of-plane tilt stretches it)
    beta = atan2(d_y, d_x)             (the co-rotated frame's turn in the rib plane)
    psi_i = asin(theta_i / sqrt(1 - w'_i^2))
                                       (the section's turn in the rib plane: the planar
                                        element's asin(theta), the unit tangent's
                                        out-of-plane part taken out of its in-plane length)
    tb_i = psi_i - beta                (the planar element's local in-plane rotations)
    c_i = w'_i - d_z / |d|             (local out-of-plane rotations: the section's
                                        out-of-plane slope less the chord's, both sines)
    tau = phi_b - phi_a                (the twist: phi is the section's rotation about its
                                        own axis, the material twist)
    eps = lambda - 1 + (Q(tb_a, tb_b) + Q(c_a, c_b)) / 30,   Q(a, b) = 2a^2 - ab + 2b^2
    U_e = 1/2 EA l_e eps^2 + 2 EI_z / l_e (tb_a^2 + tb_a tb_b + tb_b^2)
          + 2 EI_y / l_e (c_a^2 + c_a c_b + c_b^2) + GJ / (2 l_e) tau^2

With the out-of-plane state zero (d_z = w' = phi = 0) this is the planar element to the
last bit but the chord length's rounding (sqrt against hypot), and its out-of-plane
gradient vanishes: a rib that stays in its plane is the planar flexible-nonlinear rib.  Its
Hessian at q = 0 is the linear 3D element's K (beam3d.py), so small motion is the linear
umbrella.  Any rigid motion of an element strains nothing: a turn beta in the rib's plane
(however large), a tilt eps out of it and a roll (v' = cos eps sin beta, w' = sin eps,
equal twists give tb = c = tau = 0 and lambda = 1 exactly; tests/test_umbrella3d_nonlinear.py).
The 3D chord keeps a tilt from straining the element and gives a compressed link its
out-of-plane P-delta stiffness, as the in-plane chord does in the plane.

What the choice leaves out, and so its limit: the deformation out of the plane is measured
as small rotations (c_i, tau: sine differences and a twist difference, about the turned
section's own axes), so the couplings of bending in two planes with torsion that finite
rotations bring (the products of c, tb and tau: second order in the local rotations,
small by the co-rotational split) are dropped, as Crisfield's local element drops them in
the plane; the kinetic field is the body's (the
twist's rotary inertia about the body's x axis, the tip mass's offset by the linear small
rotation, beam3d.BeamBody3D.attached_point).  Past OUT_OF_PLANE_LIMIT (0.1 rad) of any node's
turn out of the plane, asin |w'|, or twist |phi| the run's summary warns
(out_of_plane_warnings, with the planar model's geometric validity warnings of summary.py).
The joints follow the
material twist: the O'' hinge keeps the two sections' hinge axes parallel, each section's
small rotation turned by its body's angle plus the section's own angle asin(theta) (the
linear model's rows with alpha + psi for alpha; the same rows when theta = 0; w'^2 left out
of psi there, third order in a row of small rotations).

Energy balance: the midpoint step's elastic force is the element's discrete gradient G_e =
B~^T D (s0 + s1) / 2 with B~ (q1 - q0) = s1 - s0 exactly (the planar element's: lambda by
(d0 + d1) / ((|d0| + |d1|) l_e), beta by Gonzalez's gradient in (d_x, d_y), psi by its
secant in theta, here Gonzalez's gradient in (theta, w'), the same when w' does not move;
d_z / |d| by Gonzalez's gradient in d, Q at the mean rotations), so
dq . G = U(q1) - U(q0) to round-off; the Newton matrix takes h^2/2 of 1/2 [B^T D B + sum_k
(D s)_k d^2 s_k / dq^2] at the midpoint.  Stress recovery at both ends of every element, in
its co-rotated frame: axial E eps, bending E c kappa (kappa = (-4 t_a - 2 t_b) / l_e and
(2 t_a + 4 t_b) / l_e of tb or c), torsion G c_t tau / l_e.

Structural damping (damping_ratio zeta; damping3d.py): C(q) = beta B(q)^T D B(q), the
Kelvin-Voigt damping of the co-rotated strain rates s' = B q' (B = ds/dq, D the elements'
EA l, EI / l blocks and GJ / l), the planar co-rotational model's (nonlinear.py), with the
linear ribs' beta; its force -C(q_m) dq / h in the midpoint step
(RibCorotationalStrain.material_tangent at the step's midpoint).  A rigid motion of an
element has s' = 0 and is not damped.

Compiled: _kernel3d_nonlinear.h does the same arithmetic element by element in the
compiled step (hooks in _kernel3d.c and _kernel3d_base.h), which
tests/test_umbrella3d_nonlinear.py holds equal to this numpy reference through the lock;
and the per-step stress figures (stress_blocks' components, _kernel3d_figures.h's crests and
places), which the same tests hold equal to Record3D's numpy ones.
No stage-2 mode fit, as the planar flexible-nonlinear model (step_rule.py).  Nothing here
imports rclpy.
"""
from __future__ import annotations

import math

import numpy as np

from .model3d import UmbrellaModel3D
from ..beam_strain import (angle_gradient, angle_hessian, angle_increment, gonzalez,
                           section_angle_increment, slope_end_reason, wrap_angle)

NONLINEAR_MODEL = 'flexible-nonlinear'
#: the ribs take out-of-plane bending and torsion as small rotations in each element's
#: co-rotated frame: the largest out-of-plane turn asin |w'| or twist |phi| (rad) of any node
#: they are held valid for (their squares are dropped: ~angle^2 / 6 relative in the sines,
#: 0.2 % here, and products with the elements' local in-plane rotations of the same order)
OUT_OF_PLANE_LIMIT = 0.1
#: what the ribs' out-of-plane model is, said where a run leaves OUT_OF_PLANE_LIMIT
_SMALL_ROTATIONS = ("the umbrella's flexible-nonlinear ribs take out-of-plane bending and "
                    "torsion as small rotations in each element's co-rotated frame "
                    '(docs/umbrella3d_nonlinear.md)')
_Q = np.array([[4.0, -1.0], [-1.0, 4.0]])          # Hessian of Q(a, b)
# the element's z = (d_x, d_y, d_z, theta_a, theta_b, w'_a, w'_b, phi_a, phi_b) from its
# 12 coordinates (u, v, theta, w, slope, twist of node a, then of node b)
_Z_ROWS = ((6, 0), (7, 1), (9, 3), (2, None), (8, None), (4, None), (10, None), (5, None),
           (11, None))


def _grad_sine(d: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Return d (d_z / |d|) / dd (..., 3)."""
    g = -d[..., 2, None] * d / length[..., None] ** 3
    g[..., 2] += 1.0 / length
    return g


def _hess_sine(d: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Return d^2 (d_z / |d|) / dd^2 (..., 3, 3)."""
    l3 = length[..., None, None] ** 3
    ez = np.zeros(d.shape)
    ez[..., 2] = 1.0
    outer = ez[..., :, None] * d[..., None, :]
    eye = np.eye(3) * d[..., 2, None, None]
    return (-(outer + outer.swapaxes(-1, -2) + eye) / l3
            + 3.0 * d[..., 2, None, None] * d[..., :, None] * d[..., None, :]
            / length[..., None, None] ** 5)


def _gonzalez3(grad_mid, dd, df):
    """Gonzalez's midpoint discrete gradient of f(d), d in R^3 (beam_strain.gonzalez's)."""
    dd2 = np.sum(dd * dd, -1)
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = np.where(dd2 > 0.0, (df - np.sum(grad_mid * dd, -1)) / dd2, 0.0)
    return grad_mid + corr[..., None] * dd


class RibCorotationalStrain:
    """
    The strain energy of every rib's elements (module docstring), vectorised over ribs.

    The elements of the leaf then of the link, the same pattern in every rib (its
    coordinates' places in the rib's vector); lengths and sections per rib.
    """

    def __init__(self, model: UmbrellaModel3D):
        m = model
        lin, lengths, places = [], [], []
        for bodies, s_e in ((m.leaf_bodies, m.s_leaf_e), (m.link_bodies, m.s_link_e)):
            for maps in bodies[0].element_maps:          # (12, n_elastic)
                rows = np.zeros((9, m.n_rib))
                for k, (b, a) in enumerate(_Z_ROWS):
                    rows[k, s_e] = maps[b] - (maps[a] if a is not None else 0.0)
                lin.append(rows)
                places.append(np.where(maps.any(1), s_e.start + maps.argmax(1), m.n_rib))
            lengths.append(np.array([b.element_length for b in bodies]))
        self.lin = np.array(lin)                               # (E, 9, n_rib)
        #: each element's 12 coordinates' places in the rib's vector (n_rib: a fixed one)
        self.places = np.array(places)
        self.to_z = np.zeros((9, 12))                          # z - offset = to_z x_e
        for k, (b, a) in enumerate(_Z_ROWS):
            self.to_z[k, b] = 1.0
            if a is not None:
                self.to_z[k, a] = -1.0
        self.length = np.concatenate(lengths, 1)               # (R, E)
        #: each element's z entries 3-8 (nodal slopes theta, w' and twists phi: one
        #: coordinate each, at its place; n_rib where it is fixed, 0)
        self.node_places = self.places[:, [b for b, _ in _Z_ROWS[3:]]]
        self.n_leaf = len(m.leaf_bodies[0].element_length)
        sec = m.sections
        per_rib = {name: np.array([s[name] for s in sec])[:, None]
                   for name in ('ea', 'ei_z', 'ei_y', 'gj', 'youngs', 'shear', 'fibre',
                                'torsion_fibre')}
        self.section = per_rib
        le = self.length
        bend = np.array([[4.0, 2.0], [2.0, 4.0]])
        d = np.zeros(le.shape + (6, 6))
        d[..., 0, 0] = per_rib['ea'] * le
        d[..., 1:3, 1:3] = (per_rib['ei_z'] / le)[..., None, None] * bend
        d[..., 3:5, 3:5] = (per_rib['ei_y'] / le)[..., None, None] * bend
        d[..., 5, 5] = per_rib['gj'] / le
        self.stiffness = d                                     # (R, E, 6, 6)

    # ------------------------------------------------------------ kinematics
    def chords(self, qr: np.ndarray) -> np.ndarray:
        """Return z of every element (..., R, E, 9) (module docstring): linear in q."""
        z = np.einsum('eiq,...rq->...rei', self.lin, qr)
        z[..., 0] += self.length
        return z

    def strains(self, qr) -> np.ndarray:
        """Return s = (eps, tb_a, tb_b, c_a, c_b, tau) of every element (R, E, 6)."""
        z = self.chords(qr)
        beta = np.arctan2(z[..., 1], z[..., 0])
        psi = np.arcsin(_section_sine(z))
        return self._strains_from(z, wrap_angle(psi - beta[..., None]))

    def _strains_from(self, z, tb):
        length = np.sqrt(np.sum(z[..., 0:3] ** 2, -1))
        c = z[..., 5:7] - (z[..., 2] / length)[..., None]
        eps = length / self.length - 1.0 + (_quad(tb) + _quad(c)) / 30.0
        return np.concatenate([eps[..., None], tb, c, (z[..., 8] - z[..., 7])[..., None]], -1)

    def _jacobian(self, z, s, hessians: bool = False):
        """Return ds/dz (R, E, 6, 9), with hessians also d^2 s_k / dz^2 (R, E, 6, 9, 9)."""
        d = z[..., 0:3]
        length = np.sqrt(np.sum(d * d, -1))
        jac = np.zeros(z.shape[:-1] + (6, 9))
        g_beta = angle_gradient(d[..., 0:2])
        g_sine = _grad_sine(d, length)
        sec = _section_derivatives(z)
        for k in range(2):
            jac[..., 1 + k, 0:2] = -g_beta
            jac[..., 1 + k, 3 + k] = sec[0][..., k]
            jac[..., 1 + k, 5 + k] = sec[1][..., k]
            jac[..., 3 + k, 0:3] = -g_sine
            jac[..., 3 + k, 5 + k] = 1.0
        jac[..., 5, 7], jac[..., 5, 8] = -1.0, 1.0
        dq_tb = s[..., 1:3] @ _Q / 30.0
        dq_c = s[..., 3:5] @ _Q / 30.0
        jac[..., 0, 0:3] = d / (length * self.length)[..., None]
        jac[..., 0, :] += (dq_tb[..., 0:1] * jac[..., 1, :] + dq_tb[..., 1:2] * jac[..., 2, :]
                           + dq_c[..., 0:1] * jac[..., 3, :] + dq_c[..., 1:2] * jac[..., 4, :])
        if not hessians:
            return jac
        hes = np.zeros(z.shape[:-1] + (6, 9, 9))
        h_beta = angle_hessian(d[..., 0:2])
        h_sine = _hess_sine(d, length)
        for k in range(2):
            hes[..., 1 + k, 0:2, 0:2] = -h_beta
            hes[..., 1 + k, 3 + k, 3 + k] = sec[2][..., k]
            hes[..., 1 + k, 3 + k, 5 + k] = hes[..., 1 + k, 5 + k, 3 + k] = sec[3][..., k]
            hes[..., 1 + k, 5 + k, 5 + k] = sec[4][..., k]
            hes[..., 3 + k, 0:3, 0:3] = -h_sine
        unit = d / length[..., None]
        j_tb, j_c = jac[..., 1:3, :], jac[..., 3:5, :]
        hes[..., 0, :, :] = (np.einsum('...ai,ab,...bj->...ij', j_tb, _Q, j_tb)
                             + np.einsum('...ai,ab,...bj->...ij', j_c, _Q, j_c)) / 30.0
        for k in range(2):
            hes[..., 0, :, :] += (dq_tb[..., k, None, None] * hes[..., 1 + k, :, :]
                                  + dq_c[..., k, None, None] * hes[..., 3 + k, :, :])
        hes[..., 0, 0:3, 0:3] += ((np.eye(3) - unit[..., :, None] * unit[..., None, :])
                                  / (length * self.length)[..., None, None])
        return jac, hes

    def _step_strains(self, z0, z1):
        """Return s0, s1 (s1 from s0 and the accurate angle increments) and d beta."""
        beta0 = np.arctan2(z0[..., 1], z0[..., 0])
        g0 = _section_sine(z0)
        tb0 = wrap_angle(np.arcsin(g0) - beta0[..., None])
        s0 = self._strains_from(z0, tb0)
        dpsi = section_angle_increment(g0, _section_sine(z1))
        dbeta = angle_increment(z0[..., 0:2], z1[..., 0:2])
        s1 = self._strains_from(z1, tb0 + dpsi - dbeta[..., None])
        return s0, s1, dbeta, dpsi

    def _discrete_jacobian(self, z0, z1, s0, s1, dbeta, dpsi):
        """Return B~ (R, E, 6, 9): B~ (z1 - z0) = s1 - s0 exactly (module docstring)."""
        d0, d1 = z0[..., 0:3], z1[..., 0:3]
        l0, l1 = np.sqrt(np.sum(d0 * d0, -1)), np.sqrt(np.sum(d1 * d1, -1))
        jac = np.zeros(z0.shape[:-1] + (6, 9))
        g_beta = gonzalez(angle_gradient(0.5 * (d0[..., 0:2] + d1[..., 0:2])),
                          d1[..., 0:2] - d0[..., 0:2], dbeta)
        dm = 0.5 * (d0 + d1)
        g_sine = _gonzalez3(_grad_sine(dm, np.sqrt(np.sum(dm * dm, -1))), d1 - d0,
                            d1[..., 2] / l1 - d0[..., 2] / l0)
        sec = _section_derivatives(0.5 * (z0 + z1), hessians=False)
        for k in range(2):
            # psi of (theta, w'): Gonzalez's gradient in the pair (the planar element's secant
            # in theta when w' does not move)
            pair = [3 + k, 5 + k]
            g_psi = gonzalez(np.stack([sec[0][..., k], sec[1][..., k]], -1),
                             z1[..., pair] - z0[..., pair], dpsi[..., k])
            jac[..., 1 + k, 0:2] = -g_beta
            jac[..., 1 + k, 3 + k], jac[..., 1 + k, 5 + k] = g_psi[..., 0], g_psi[..., 1]
            jac[..., 3 + k, 0:3] = -g_sine
            jac[..., 3 + k, 5 + k] = 1.0
        jac[..., 5, 7], jac[..., 5, 8] = -1.0, 1.0
        dq_tb = 0.5 * (s0[..., 1:3] + s1[..., 1:3]) @ _Q / 30.0
        dq_c = 0.5 * (s0[..., 3:5] + s1[..., 3:5]) @ _Q / 30.0
        jac[..., 0, 0:3] = (d0 + d1) / ((l0 + l1) * self.length)[..., None]
        jac[..., 0, :] += (dq_tb[..., 0:1] * jac[..., 1, :] + dq_tb[..., 1:2] * jac[..., 2, :]
                           + dq_c[..., 0:1] * jac[..., 3, :] + dq_c[..., 1:2] * jac[..., 4, :])
        return jac

    # ------------------------------------------------------------ energy and forces
    def energy_per_rib(self, qr) -> np.ndarray:
        s = self.strains(qr)
        return 0.5 * np.einsum('rei,reij,rej->r', s, self.stiffness, s)

    def _assemble(self, jac, sigma):
        return np.einsum('eiq,rei->rq', self.lin, np.einsum('reki,rek->rei', jac, sigma))

    def _assemble_matrix(self, zmat):
        """sum_e L_e^T zmat_e L_e (R, n_rib, n_rib): each element's 12 x 12 block added."""
        blocks = self.to_z.T @ zmat @ self.to_z                # (R, E, 12, 12)
        n = self.lin.shape[-1]
        out = np.zeros((len(zmat), n + 1, n + 1))             # (the last: fixed ones)
        for e, at in enumerate(self.places):
            out[:, at[:, None], at[None, :]] += blocks[:, e]
        return out[:, :n, :n]

    def gradient(self, qr) -> np.ndarray:
        """Return dU/dq of every rib (R, n_rib)."""
        z = self.chords(qr)
        s = self.strains(qr)
        return self._assemble(self._jacobian(z, s), np.einsum('reij,rej->rei',
                                                              self.stiffness, s))

    def tangent(self, qr) -> np.ndarray:
        """Return d^2 U / dq^2 of every rib (R, n_rib, n_rib)."""
        z = self.chords(qr)
        s = self.strains(qr)
        jac, hes = self._jacobian(z, s, hessians=True)
        return self._assemble_matrix(self._tangent_blocks(jac, hes, s))

    def material_tangent(self, qr) -> np.ndarray:
        """
        Return B^T D B of every rib (R, n_rib, n_rib), B = ds/dq: the material tangent.

        The Kelvin-Voigt damping of the co-rotated strain rates is beta times it
        (damping3d.py; nonlinear.py's planar CorotationalStrainEnergy.material_tangent).
        """
        z = self.chords(qr)
        jac = self._jacobian(z, self.strains(qr))
        return self._assemble_matrix(np.einsum('reki,rekl,relj->reij', jac, self.stiffness,
                                               jac))

    def _tangent_blocks(self, jac, hes, s):
        sigma = np.einsum('reij,rej->rei', self.stiffness, s)
        return (np.einsum('reki,rekl,relj->reij', jac, self.stiffness, jac)
                + np.einsum('rek,rekij->reij', sigma, hes))

    def discrete_gradient(self, qr0, qr1) -> np.ndarray:
        """Return G (R, n_rib): (q1 - q0) . G = U(q1) - U(q0) rib by rib, to round-off."""
        z0, z1 = self.chords(qr0), self.chords(qr1)
        s0, s1, dbeta, dpsi = self._step_strains(z0, z1)
        jac = self._discrete_jacobian(z0, z1, s0, s1, dbeta, dpsi)
        return self._assemble(jac, np.einsum('reij,rej->rei', self.stiffness, 0.5 * (s0 + s1)))

    def discrete_gradient_jacobian(self, qr0, qr1) -> np.ndarray:
        """
        Return the Newton matrix's dG/dq1 (R, n_rib, n_rib): the planar law's approximation.

        1/2 [B^T D B + sum_k sigma_k d^2 s_k / dz^2] at the midpoint chord, sigma = D (s0 +
        s1) / 2 and Q's pieces at the mean rotations (nonlinear.CorotationalStrainEnergy's).
        """
        z0, z1 = self.chords(qr0), self.chords(qr1)
        s0, s1, _, _ = self._step_strains(z0, z1)
        s_mean = 0.5 * (s0 + s1)
        jac, hes = self._jacobian(0.5 * (z0 + z1), s_mean, hessians=True)
        return 0.5 * self._assemble_matrix(self._tangent_blocks(jac, hes, s_mean))

    # ------------------------------------------------------------ stresses
    def stress_blocks(self, qr, vr=None):
        """
        Return per body (leaf, link) the stresses (..., R, 4, points) and, with vr, their rates.

        The four components of UmbrellaModel3D.stress_blocks (axial, bending z, bending y,
        torsion shear) at both ends of every element, in its co-rotated frame.
        """
        lead = qr.shape[:-2]
        q2 = qr.reshape((-1,) + qr.shape[-2:])
        flat = q2.reshape(-1, q2.shape[-1])
        n_ribs = qr.shape[-2]
        big = _tiled(self, len(q2))
        s = big.strains(flat)
        out = [self._components(s.reshape(len(q2), n_ribs, *s.shape[1:]), lead)]
        if vr is not None:
            z = big.chords(flat)
            jac = big._jacobian(z, s)
            rate = np.einsum('reki,rei->rek', jac, np.einsum(
                'eiq,rq->rei', big.lin, vr.reshape(-1, vr.shape[-1])))
            out.append(self._components(rate.reshape(len(q2), n_ribs, *rate.shape[1:]), lead))
        return out

    def _components(self, s, lead):
        """Stresses of strains s (K, R, E, 6) at both element ends, per body."""
        sec, le = self.section, self.length
        youngs, fibre = sec['youngs'][..., None], sec['fibre'][..., None]
        shear = sec['shear'] * sec['torsion_fibre']

        def ends(a, b):
            return np.stack([(-4.0 * a - 2.0 * b) / le, (2.0 * a + 4.0 * b) / le], -1)

        comp = np.stack([
            np.repeat(sec['youngs'] * s[..., 0], 2, -1).reshape(s.shape[:-2] + (-1, 2)),
            youngs * fibre * ends(s[..., 1], s[..., 2]),
            youngs * fibre * ends(s[..., 3], s[..., 4]),
            np.repeat(shear * s[..., 5] / le, 2, -1).reshape(s.shape[:-2] + (-1, 2))], -3)
        comp = comp.reshape(comp.shape[:-2] + (-1,))            # (K, R, 4, 2 E)
        n = 2 * self.n_leaf
        return [comp[..., :n].reshape(lead + comp.shape[1:-1] + (n,)),
                comp[..., n:].reshape(lead + comp.shape[1:-1] + (-1,))]

    def _nodal(self, qr) -> np.ndarray:
        """Return z's entries 3-8 of every element (..., R, E, 6): chords' without products."""
        return np.concatenate([qr, np.zeros(qr.shape[:-1] + (1,))], -1)[..., self.node_places]

    def out_of_plane_rotation(self, qr) -> float:
        """
        Return the largest out-of-plane angle of any node (rad): OUT_OF_PLANE_LIMIT's measure.

        A node's turn out of its rib's plane, asin |w'| (w' the unit tangent's out-of-plane
        part: a sine), or its twist |phi|, whichever is larger.
        """
        nodal = np.abs(self._nodal(qr))
        tilt = math.asin(min(float(np.max(nodal[..., 2:4], initial=0.0)), 1.0))
        return max(tilt, float(np.max(nodal[..., 4:6], initial=0.0)))

    def section_slope(self, qr) -> float:
        """Return the largest |sin psi| of any section's turn in its rib's plane (planar's)."""
        nodal = self._nodal(qr)
        return float(np.max(np.abs(_turned_sine(nodal[..., 0:2], nodal[..., 2:4])),
                            initial=0.0))


def _section_sine(z):
    """
    Return sin psi = theta / sqrt(1 - w'^2) at both ends (..., 2): psi the section's turn.

    The planar element's sin psi = v' with the unit tangent's out-of-plane part w' taken out
    of its in-plane length (|r'| = 1): so a rigid tilt of a turned element turns none of its
    sections; theta itself where w' = 0.
    """
    return _turned_sine(z[..., 3:5], z[..., 5:7])


def _turned_sine(theta, slope):
    """Return sin psi = theta / sqrt(1 - w'^2) of slopes theta, w' (_section_sine's)."""
    return theta / np.sqrt(1.0 - slope ** 2)


def _section_derivatives(z, hessians: bool = True):
    """
    Return d psi / d theta, d psi / d w' and (hessians) the second derivatives of psi.

    psi = asin(g), g = theta s, s = (1 - w'^2)^(-1/2), at both ends (..., 2) each: psi_t,
    psi_w, psi_tt, psi_tw, psi_ww.
    """
    th, w = z[..., 3:5], z[..., 5:7]
    s = 1.0 / np.sqrt(1.0 - w * w)
    g = th * s
    pg = 1.0 / np.sqrt(1.0 - g * g)
    g_w = th * w * s ** 3
    if not hessians:
        return pg * s, pg * g_w
    pgg = g * pg ** 3
    return (pg * s, pg * g_w, pgg * s * s, pgg * s * g_w + pg * w * s ** 3,
            pgg * g_w * g_w + pg * th * (s ** 3 + 3.0 * w * w * s ** 5))


def _quad(x):
    """Q(a, b) = 2 a^2 - a b + 2 b^2 of x (..., 2)."""
    return 2.0 * x[..., 0] ** 2 - x[..., 0] * x[..., 1] + 2.0 * x[..., 1] ** 2


def _tiled(law: RibCorotationalStrain, k: int) -> RibCorotationalStrain:
    """Return the law over k stacked copies of its ribs (rows of many states at once)."""
    if k == 1:
        return law
    out = object.__new__(RibCorotationalStrain)
    out.lin, out.n_leaf, out.places, out.to_z = law.lin, law.n_leaf, law.places, law.to_z
    out.node_places = law.node_places
    out.length = np.tile(law.length, (k, 1))
    out.stiffness = np.tile(law.stiffness, (k, 1, 1, 1))
    out.section = {name: np.tile(v, (k, 1)) for name, v in law.section.items()}
    return out


class CorotationalUmbrellaModel3D(UmbrellaModel3D):
    """
    UmbrellaModel3D with co-rotational beams (module docstring): U, forces, joints, stresses.

    The linear ``stiffness`` stays as the Hessian at q = 0 (the locked modes of modes3d).
    """

    def __init__(self, params):
        super().__init__(params)
        self.strain = RibCorotationalStrain(self)
        lf, lk, n = self.leaf_bodies[0], self.link_bodies[0], self.elements
        nl = lf.n_elastic
        self.i_t1 = 1 + lf.index(n, 'theta')             # the leaf's slope at O''
        self.i_t2 = 5 + nl + lk.index(0, 'theta')        # the link's slope at O''
        #: the largest out-of-plane rotation and section slope of the states noted so far
        self.max_out_of_plane = 0.0
        self.max_section_slope = 0.0

    # ------------------------------------------------------------ energy
    def strain_energy(self, qr) -> float:
        return float(np.sum(self.strain.energy_per_rib(qr)))

    def strain_energy_per_rib(self, qr) -> np.ndarray:
        return self.strain.energy_per_rib(qr)

    def elastic_force(self, qr) -> np.ndarray:
        return self.strain.gradient(qr)

    def elastic_step_force(self, qr0, qr1, qm) -> np.ndarray:
        return self.strain.discrete_gradient(qr0, qr1)

    def elastic_step_matrix(self, qr0, qr1, h: float) -> np.ndarray:
        return 0.5 * h * h * self.strain.discrete_gradient_jacobian(qr0, qr1)

    def material_tangent(self, qm) -> np.ndarray:
        """Return B(q_m)^T D B(q_m) (R, n, n): the damping C / beta (damping3d.py)."""
        return self.strain.material_tangent(qm)

    def compiled_law(self) -> dict:
        """Return Model3D's nl_* fields of this law (_kernel3d_nonlinear.h)."""
        st, n = self.strain, self.n_rib
        k = st.stiffness
        d = np.stack([k[..., 0, 0], k[..., 1, 1] / 4.0, k[..., 3, 3] / 4.0, k[..., 5, 5]], -1)
        pattern = (self.stiffness != 0.0).astype(float)
        for at in st.places:
            at = at[at < n]
            pattern[:, at[:, None], at[None, :]] = 1.0
        return {'nl_elements': len(st.places), 'nl_i_t1': self.i_t1, 'nl_i_t2': self.i_t2,
                'nl_places': st.places, 'nl_length': st.length, 'nl_stiffness': d,
                'nl_pattern': pattern}

    def note_state(self, qr) -> None:
        self.max_out_of_plane = max(self.max_out_of_plane,
                                    self.strain.out_of_plane_rotation(qr))
        self.max_section_slope = max(self.max_section_slope, self.strain.section_slope(qr))

    def failure_reason(self, qr) -> str | None:
        """
        Return why a step from the state qr failed where the ribs had left their range.

        The in-plane slope coordinates' end at 90 deg (the planar model's reason,
        beam_strain.slope_end_reason), else an out-of-plane turn or twist past
        OUT_OF_PLANE_LIMIT (the out-of-plane slopes w' end at 90 deg too); None inside both.
        """
        reason = slope_end_reason(self.strain.section_slope(qr))
        rotation = self.strain.out_of_plane_rotation(qr)
        if reason is not None or rotation <= OUT_OF_PLANE_LIMIT:
            return reason
        return (f"a section had turned {math.degrees(rotation):.1f} deg out of its rib's "
                f'plane or twisted (limit {math.degrees(OUT_OF_PLANE_LIMIT):.1f} deg): '
                + _SMALL_ROTATIONS)

    # ------------------------------------------------------------ stresses
    def stress_blocks(self, qr):
        return self.strain.stress_blocks(qr)[0]

    def stress_rate_blocks(self, qr, vr):
        return self.strain.stress_blocks(qr, vr)[1]

    # ------------------------------------------------------------ the O'' hinge
    def _turned(self, qr):
        """Return the O'' sections' angles alpha + psi and dpsi/dtheta of leaf and link."""
        t1, t2 = qr[..., self.i_t1], qr[..., self.i_t2]
        return (qr[..., self.i_a1] + np.arcsin(t1), qr[..., self.i_a2] + np.arcsin(t2),
                1.0 / np.sqrt(1.0 - t1 * t1), 1.0 / np.sqrt(1.0 - t2 * t2))

    def _hinge_values(self, qr):
        a1, a2, _, _ = self._turned(qr)
        c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
        sl1, tw1, sl2, tw2 = (qr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        return (c1 * sl1 - s1 * tw1 - c2 * sl2 + s2 * tw2,
                s1 * sl1 + c1 * tw1 - s2 * sl2 - c2 * tw2)

    def constraints(self, qr, qs, stuck, locked: bool, drive=None):
        """UmbrellaModel3D.constraints with the O'' hinge rows of the turned sections."""
        phi, shared = super().constraints(qr, qs, stuck, locked, drive)
        phi[:, 3], phi[:, 4] = self._hinge_values(qr)
        return phi, shared

    def constraint_jacobian(self, qr, stuck, locked: bool):
        j, j_rs, j_ss, active = super().constraint_jacobian(qr, stuck, locked)
        a1, a2, g1, g2 = self._turned(qr)
        c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
        sl1, tw1, sl2, tw2 = (qr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        d3_1, d4_1 = -s1 * sl1 - c1 * tw1, c1 * sl1 - s1 * tw1
        d3_2, d4_2 = s2 * sl2 + c2 * tw2, -c2 * sl2 + s2 * tw2
        j[:, 3, self.i_a1], j[:, 4, self.i_a1] = d3_1, d4_1
        j[:, 3, self.i_t1], j[:, 4, self.i_t1] = d3_1 * g1, d4_1 * g1
        j[:, 3, self.i_s1], j[:, 4, self.i_s1] = c1, s1
        j[:, 3, self.i_p1], j[:, 4, self.i_p1] = -s1, c1
        j[:, 3, self.i_a2], j[:, 4, self.i_a2] = d3_2, d4_2
        j[:, 3, self.i_t2], j[:, 4, self.i_t2] = d3_2 * g2, d4_2 * g2
        j[:, 3, self.i_s2], j[:, 4, self.i_s2] = -c2, -s2
        j[:, 3, self.i_p2], j[:, 4, self.i_p2] = s2, -c2
        return j, j_rs, j_ss, active

    def constraint_bias(self, qr, vr) -> np.ndarray:
        bias = super().constraint_bias(qr, vr)
        a1, a2, g1, g2 = self._turned(qr)
        t1, t2 = qr[:, self.i_t1], qr[:, self.i_t2]
        w1 = vr[:, self.i_a1] + g1 * vr[:, self.i_t1]           # the turned angles' rates
        w2 = vr[:, self.i_a2] + g2 * vr[:, self.i_t2]
        k1 = t1 * g1 ** 3 * vr[:, self.i_t1] ** 2               # their d^2/dtheta^2 terms
        k2 = t2 * g2 ** 3 * vr[:, self.i_t2] ** 2
        c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
        sl1, tw1, sl2, tw2 = (qr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        vs1, vt1, vs2, vt2 = (vr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        jd3 = (w1 * w1 * (-c1 * sl1 + s1 * tw1) + k1 * (-s1 * sl1 - c1 * tw1)
               + 2 * w1 * (-s1 * vs1 - c1 * vt1)
               + w2 * w2 * (c2 * sl2 - s2 * tw2) - k2 * (-s2 * sl2 - c2 * tw2)
               + 2 * w2 * (s2 * vs2 + c2 * vt2))
        jd4 = (w1 * w1 * (-s1 * sl1 - c1 * tw1) + k1 * (c1 * sl1 - s1 * tw1)
               + 2 * w1 * (c1 * vs1 - s1 * vt1)
               + w2 * w2 * (s2 * sl2 + c2 * tw2) - k2 * (c2 * sl2 - s2 * tw2)
               + 2 * w2 * (-c2 * vs2 + s2 * vt2))
        bias[:, 3], bias[:, 4] = -jd3, -jd4
        return bias


def out_of_plane_warnings(params: dict, rotation: float | None) -> list[str]:
    """
    Return the warning of an umbrella run whose out-of-plane rotations left its model.

    rotation: the largest out-of-plane turn asin |w'| or twist |phi| of any node over every
    step (rad; None: not known, or a model without the limit); flexible-nonlinear only (the
    linear beams' limit is the 'large deflection' one).
    """
    if (params.get('model') != 'flexible-nonlinear' or rotation is None
            or rotation <= OUT_OF_PLANE_LIMIT):
        return []
    return [f'out-of-plane rotation: a section turned {math.degrees(rotation):.1f} deg out of '
            f"its rib's plane or twisted (asin |w'| or |phi| = {rotation:.3g} rad; limit "
            f'{math.degrees(OUT_OF_PLANE_LIMIT):.1f} deg): ' + _SMALL_ROTATIONS]


def umbrella_model(params) -> UmbrellaModel3D:
    """Return the umbrella model of validated parameters: co-rotational or linear beams."""
    if params.planar.model == NONLINEAR_MODEL:
        return CorotationalUmbrellaModel3D(params)
    return UmbrellaModel3D(params)
