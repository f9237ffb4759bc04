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
The strain energies of the elastic laws of nonlinear.py, in numpy: the reference.

``CorotationalStrainEnergy``, the co-rotational Euler-Bernoulli beam of model
flexible-nonlinear (its formulation, discrete gradient and limits: nonlinear.py's docstring),
and ``LinearStrainEnergy``, the linear model's 1/2 q.K q through the same interface (a damped
flexible model, the benchmark's linear beam).  Each gives U(q), its gradient and tangent,
the material tangent B^T D B of the Kelvin-Voigt damping, and the discrete gradient over a
step with the Newton matrix's approximation of its derivative; the co-rotational one also
the fibre stresses and their rates.  _kernel_nonlinear.c does the same arithmetic, and the
tests compare the two step by step.  Vectorised over the elements; complex-step safe where
the tests differentiate (the fibre stresses).  Nothing here imports rclpy.
"""
from __future__ import annotations

import math

import numpy as np

#: a step that fails from a state whose largest section slope |v'| = |sin psi| is this or
#: more has met the slope coordinates' end at 90 deg (slope_end_reason)
SLOPE_COORDINATE_END = 0.99


def slope_end_reason(slope: float) -> str | None:
    """
    Return why a step failed from a state of this largest section slope, if it is the 90 deg end.

    The slope coordinates theta = sin psi cannot turn a section through 90 deg from its body
    frame; None below SLOPE_COORDINATE_END.
    """
    if slope < SLOPE_COORDINATE_END:
        return None
    return (f'a fibre has turned {math.degrees(math.asin(min(slope, 1.0))):.1f} deg from its '
            f"body frame (slope |v'| = {slope:.4f}); flexible-nonlinear's slope coordinates end "
            'at 90 deg (docs/validation_nonlinear.md)')


# ------------------------------------------------------------------ linear strain
class LinearStrainEnergy:
    """
    U = 1/2 q.K q (thesis Eq. 4.37), the linear model's, through the interface of the law.

    For the damped linear model (C = beta K) and the benchmark's linear beam.
    """

    nonlinear = False

    def __init__(self, bodies, n: int):
        """bodies: [(BeamBody, slice of its elastic coordinates in q)]; n = len(q)."""
        self.stiffness = np.zeros((n, n))
        for body, s_e in bodies:
            self.stiffness[s_e, s_e] = body.stiffness

    def energy(self, q) -> float:
        return 0.5 * q @ self.stiffness @ q

    def gradient(self, q) -> np.ndarray:
        return self.stiffness @ q

    def tangent(self, q) -> np.ndarray:
        return self.stiffness

    material_tangent = tangent

    def discrete_gradient(self, q0, q1) -> np.ndarray:
        """K (q0 + q1) / 2: dq . G = U(q1) - U(q0) exactly."""
        return self.stiffness @ (0.5 * (q0 + q1))

    def discrete_gradient_jacobian(self, q0, q1) -> np.ndarray:
        return 0.5 * self.stiffness


# ------------------------------------------------- co-rotational (geometrically exact) beam
def _perp(w: np.ndarray) -> np.ndarray:
    """Return (-w_y, w_x) of every 2-vector w (..., 2)."""
    return np.stack([-w[..., 1], w[..., 0]], axis=-1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def angle_gradient(w: np.ndarray) -> np.ndarray:
    """Return d atan2(w_y, w_x) / dw = (-w_y, w_x) / |w|^2."""
    return _perp(w) / _dot(w, w)[..., None]


def angle_hessian(w: np.ndarray) -> np.ndarray:
    """Return d^2 atan2(w_y, w_x) / dw^2 = [[2xy, y^2 - x^2], [y^2 - x^2, -2xy]] / |w|^4."""
    x, y = w[..., 0], w[..., 1]
    r4 = (x * x + y * y) ** 2
    off = (y * y - x * x) / r4
    return np.stack([np.stack([2 * x * y / r4, off], -1),
                     np.stack([off, -2 * x * y / r4], -1)], -2)


def angle_increment(w0: np.ndarray, w1: np.ndarray) -> np.ndarray:
    """Return the principal angle from w0 to w1, atan2(w0 x w1, w0 . w1): accurate when small."""
    return np.arctan2(w0[..., 0] * w1[..., 1] - w0[..., 1] * w1[..., 0], _dot(w0, w1))


def gonzalez(grad_mid: np.ndarray, dw: np.ndarray, df: np.ndarray) -> np.ndarray:
    """
    Return Gonzalez's midpoint discrete gradient of a function f of w (..., 2).

    grad f(w_m) + (df - grad f(w_m) . dw) dw / |dw|^2 (Gonzalez, J. Nonlinear Sci. 6, 1996),
    so that its product with dw = w1 - w0 is the increment df = f(w1) - f(w0) exactly;
    grad f(w_m) for dw = 0.
    """
    dd = _dot(dw, dw)
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = np.where(dd > 0.0, (df - _dot(grad_mid, dw)) / dd, 0.0)
    return grad_mid + corr[..., None] * dw


def section_angle_increment(x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Return asin(x1) - asin(x0) as asin(x1 sqrt(1 - x0^2) - x0 sqrt(1 - x1^2)): accurate."""
    return np.arcsin(x1 * np.sqrt(1.0 - x0 * x0) - x0 * np.sqrt(1.0 - x1 * x1))


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Return the angle a in (-pi, pi] (a complex a: by its real part, for complex steps)."""
    return a - 2.0 * np.pi * np.floor((np.real(a) + np.pi) / (2.0 * np.pi))


def _atan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """atan2, also of complex-step arguments (real parts' angle + i times its derivative)."""
    if not (np.iscomplexobj(y) or np.iscomplexobj(x)):
        return np.arctan2(y, x)
    yr, xr = np.real(y), np.real(x)
    return np.arctan2(yr, xr) + 1j * (xr * np.imag(y) - yr * np.imag(x)) / (xr * xr + yr * yr)


def _hypot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """hypot, also of complex-step arguments (sqrt(x^2 + y^2) is analytic there)."""
    if np.iscomplexobj(x) or np.iscomplexobj(y):
        return np.sqrt(x * x + y * y)
    return np.hypot(x, y)


#: Q(a, b) = 2 a^2 - a b + 2 b^2: 30 x the element mean of w'^2 / 2 for the local cubic w with
#: end slopes a, b (the shallow-arch part of the element's mean axial strain), and its Hessian
_Q_HESSIAN = np.array([[4.0, -1.0], [-1.0, 4.0]])


class CorotationalStrainEnergy:
    """
    Strain energy of the co-rotational Euler-Bernoulli beam in the floating frames.

    U(q) of the bodies' elements (module docstring): per element z = (d_x, d_y, theta_a,
    theta_b), its chord and nodal slopes, linear in q (z = offset + lin q); lambda = |d| / l_e,
    beta = atan2(d), the section angles psi_i = asin(theta_i / lambda), the local strains
    s = (eps, tb_a, tb_b) and U_e = 1/2 s.D s, D = diag(EA l_e, EI / l_e [[4, 2], [2, 4]]).
    Vectorised over the elements; the reference of _kernel_nonlinear.c.
    """

    nonlinear = True

    def __init__(self, bodies, n: int, ea: float, ei: float, youngs_modulus: float,
                 fibre: float):
        """bodies: [(BeamBody, slice of its elastic coordinates in q)]; n = len(q)."""
        lin, lengths = [], []
        for body, s_e in bodies:
            maps = body.element_dof_maps       # rows u_a v_a theta_a u_b v_b theta_b
            for m in maps:
                rows = np.zeros((4, n))
                rows[0, s_e] = m[3] - m[0]            # d_x - l_e
                rows[1, s_e] = m[4] - m[1]            # d_y
                rows[2, s_e], rows[3, s_e] = m[2], m[5]
                lin.append(rows)
            lengths.append(body.element_length)
        self.lin = np.array(lin)                      # (n_el, 4, n)
        self.element_length = np.concatenate(lengths)
        l0 = self.element_length
        self.offset = np.zeros((len(l0), 4))
        self.offset[:, 0] = l0
        self.youngs_modulus, self.fibre = youngs_modulus, fibre
        self.stiffness = np.zeros((len(l0), 3, 3))    # D of every element
        self.stiffness[:, 0, 0] = ea * l0
        self.stiffness[:, 1:, 1:] = (ei / l0)[:, None, None] * np.array([[4.0, 2.0],
                                                                         [2.0, 4.0]])

    # ---------------------------------------------------------------- kinematics
    def chords_and_slopes(self, q) -> np.ndarray:
        """Return z = (d_x, d_y, theta_a, theta_b) of every element, (n_el, 4): linear in q."""
        return self.offset + self.lin @ q

    def section_slopes(self, q) -> np.ndarray:
        """Return the slopes theta = sin psi at both ends of every element, (n_el, 2)."""
        return self.chords_and_slopes(q)[:, 2:]

    def admissible(self, q) -> bool:
        """Say whether q is inside the slope coordinates: every |theta| < 1 (psi < 90 deg)."""
        return bool(np.all(np.abs(self.section_slopes(q)) < 1.0))

    def local_strains(self, q) -> np.ndarray:
        """Return s = (eps, tb_a, tb_b) of every element, (n_el, 3)."""
        return self._strains(self.chords_and_slopes(q))

    def _stretch(self, z):
        return _hypot(z[:, 0], z[:, 1]) / self.element_length

    def _strains(self, z):
        beta = _atan2(z[:, 1], z[:, 0])
        psi = np.arcsin(z[:, 2:])
        return self._strains_from(self._stretch(z), wrap_angle(psi[:, 0] - beta),
                                  wrap_angle(psi[:, 1] - beta))

    @staticmethod
    def _strains_from(lam, tba, tbb):
        eps = lam - 1.0 + (2.0 * tba * tba - tba * tbb + 2.0 * tbb * tbb) / 30.0
        return np.stack([eps, tba, tbb], axis=-1)

    def _step_strains(self, z0, z1):
        """
        Return s0, s1 and the angle increments (beta, psi_a, psi_b) of a step z0 -> z1.

        s0 from the angles of z0; s1 from those plus the accurate increments (the compiled
        law's iterations need no angle of their own), equal to the strains of z1 to round-off.
        """
        s0 = self._strains(z0)
        dpsi = section_angle_increment(z0[:, 2:], z1[:, 2:])
        dbeta = angle_increment(z0[:, 0:2], z1[:, 0:2])
        s1 = self._strains_from(self._stretch(z1), s0[:, 1] + dpsi[:, 0] - dbeta,
                                s0[:, 2] + dpsi[:, 1] - dbeta)
        return s0, s1, np.column_stack([dbeta, dpsi])

    def _strain_jacobian(self, z, s, hessians: bool = False):
        """
        Return ds/dz (n_el, 3, 4), and with hessians d^2 s_k / dz^2 (n_el, 3, 4, 4).

        z = (d, theta_a, theta_b); the pieces of Q at the angles of s.
        """
        n_el, l0 = len(z), self.element_length
        d = z[:, 0:2]
        ln = np.hypot(d[:, 0], d[:, 1])
        jac = np.zeros((n_el, 3, 4))
        g_beta = angle_gradient(d)
        for k in range(2):                                  # tb = asin(theta) - beta
            jac[:, 1 + k, 0:2] = -g_beta
            jac[:, 1 + k, 2 + k] = 1.0 / np.sqrt(1.0 - z[:, 2 + k] ** 2)
        dq = s[:, 1:] @ _Q_HESSIAN / 30.0                   # dQ/dtb / 30
        jac[:, 0, 0:2] = d / (ln * l0)[:, None]
        jac[:, 0] += dq[:, 0:1] * jac[:, 1] + dq[:, 1:2] * jac[:, 2]
        if not hessians:
            return jac
        hes = np.zeros((n_el, 3, 4, 4))
        h_beta = angle_hessian(d)
        for k in range(2):
            th = z[:, 2 + k]
            hes[:, 1 + k, 0:2, 0:2] = -h_beta
            hes[:, 1 + k, 2 + k, 2 + k] = th / (1.0 - th * th) ** 1.5
        unit = d / ln[:, None]
        ang = jac[:, 1:]
        hes[:, 0] = (np.einsum('eai,ab,ebj->eij', ang, _Q_HESSIAN, ang) / 30.0
                     + dq[:, 0, None, None] * hes[:, 1] + dq[:, 1, None, None] * hes[:, 2])
        hes[:, 0, 0:2, 0:2] += ((np.eye(2) - unit[:, :, None] * unit[:, None, :])
                                / (ln * l0)[:, None, None])
        return jac, hes

    def _discrete_strain_jacobian(self, z0, z1, s0, s1, inc):
        """
        Return B~ in z (n_el, 3, 4): B~ (z1 - z0) = s1 - s0 exactly (inc: _step_strains').

        |d| by (d0 + d1) / (|d0| + |d1|); beta by Gonzalez's gradient in d; psi = asin(theta)
        by its secant dpsi / dtheta (1 / sqrt(1 - theta^2) for dtheta = 0); Q at the mean
        angles.
        """
        n_el, l0 = len(z0), self.element_length
        d0, d1 = z0[:, 0:2], z1[:, 0:2]
        l_sum = np.hypot(d0[:, 0], d0[:, 1]) + np.hypot(d1[:, 0], d1[:, 1])
        g_beta = gonzalez(angle_gradient(0.5 * (d0 + d1)), d1 - d0, inc[:, 0])
        jac = np.zeros((n_el, 3, 4))
        for k in range(2):
            th0, th1 = z0[:, 2 + k], z1[:, 2 + k]
            dth = th1 - th0
            moved = dth != 0.0
            jac[:, 1 + k, 0:2] = -g_beta
            jac[:, 1 + k, 2 + k] = np.where(moved, inc[:, 1 + k] / np.where(moved, dth, 1.0),
                                            1.0 / np.sqrt(1.0 - th0 * th0))
        dq = 0.5 * (s0[:, 1:] + s1[:, 1:]) @ _Q_HESSIAN / 30.0
        jac[:, 0, 0:2] = (d0 + d1) / (l_sum * l0)[:, None]
        jac[:, 0] += dq[:, 0:1] * jac[:, 1] + dq[:, 1:2] * jac[:, 2]
        return jac

    # -------------------------------------------------------------------- energy
    def energy(self, q) -> float:
        s = self.local_strains(q)
        return 0.5 * float(np.einsum('ei,eij,ej->', s, self.stiffness, s))

    def _stress_resultants(self, s):
        return np.einsum('eij,ej->ei', self.stiffness, s)   # D s = (N l_e, M-like, M-like)

    def gradient(self, q) -> np.ndarray:
        z = self.chords_and_slopes(q)
        s = self._strains(z)
        return self._assemble_vector(self._strain_jacobian(z, s), self._stress_resultants(s))

    def _assemble_vector(self, jac, sigma):
        """sum_e L_e^T jac_e^T sigma_e."""
        return np.einsum('eiq,ei->q', self.lin, np.einsum('eki,ek->ei', jac, sigma))

    def _assemble_matrix(self, zmat):
        """sum_e L_e^T zmat_e L_e for per-element 6 x 6 matrices."""
        return np.einsum('eip,eij,ejq->pq', self.lin, zmat, self.lin)

    def material_tangent(self, q) -> np.ndarray:
        """B(q)^T D B(q): the Kelvin-Voigt damping is beta times this (strain rates)."""
        z = self.chords_and_slopes(q)
        jac = self._strain_jacobian(z, self._strains(z))
        return self._assemble_matrix(np.einsum('eki,ekl,elj->eij', jac, self.stiffness, jac))

    def tangent(self, q) -> np.ndarray:
        """Return d grad U / dq = B^T D B + sum_k (D s)_k d^2 s_k / dq^2."""
        z = self.chords_and_slopes(q)
        s = self._strains(z)
        jac, hes = self._strain_jacobian(z, s, hessians=True)
        sigma = self._stress_resultants(s)
        return self._assemble_matrix(np.einsum('eki,ekl,elj->eij', jac, self.stiffness, jac)
                                     + np.einsum('ek,ekij->eij', sigma, hes))

    def discrete_gradient(self, q0, q1) -> np.ndarray:
        """G = sum_e L_e^T B~_e^T D (s0 + s1) / 2: dq . G = U(q1) - U(q0) to round-off."""
        z0, z1 = self.chords_and_slopes(q0), self.chords_and_slopes(q1)
        s0, s1, inc = self._step_strains(z0, z1)
        jac = self._discrete_strain_jacobian(z0, z1, s0, s1, inc)
        return self._assemble_vector(jac, self._stress_resultants(0.5 * (s0 + s1)))

    def discrete_gradient_jacobian(self, q0, q1) -> np.ndarray:
        """
        Return the Newton matrix's approximation of d G / d q1.

        1/2 [B^T D B + sum_k sigma_k d^2 s_k / dq^2] at the midpoint z_m, with sigma = D (s0 +
        s1) / 2 and Q's pieces at the mean angles: d G / d q1 to O(dq^2), the compiled law's
        same approximation (Newton converges to the same step whatever the matrix).
        """
        z0, z1 = self.chords_and_slopes(q0), self.chords_and_slopes(q1)
        s0, s1, _ = self._step_strains(z0, z1)
        s_mean = 0.5 * (s0 + s1)
        jac, hes = self._strain_jacobian(0.5 * (z0 + z1), s_mean, hessians=True)
        sigma = self._stress_resultants(s_mean)
        return 0.5 * self._assemble_matrix(
            np.einsum('eki,ekl,elj->eij', jac, self.stiffness, jac)
            + np.einsum('ek,ekij->eij', sigma, hes))

    # -------------------------------------------------------------------- stress
    def fibre_stresses(self, q):
        """
        Return the top and bottom fibre stress at both ends of every element.

        E (eps -/+ c kappa) in the co-rotated frame, kappa = w'' of the local cubic at the
        ends: (-4 tb_a - 2 tb_b) / l_e and (2 tb_a + 4 tb_b) / l_e.  Each (2 n_el,), element
        by element (a, b).
        """
        return self._fibre(self.local_strains(q))

    def _fibre(self, s):
        l0 = self.element_length
        kappa = np.stack([(-4.0 * s[:, 1] - 2.0 * s[:, 2]) / l0,
                          (2.0 * s[:, 1] + 4.0 * s[:, 2]) / l0], axis=-1).ravel()
        eps = np.repeat(s[:, 0], 2)
        e, c = self.youngs_modulus, self.fibre
        return e * (eps - c * kappa), e * (eps + c * kappa)

    def fibre_stress_rates(self, q, qd):
        """d/dt of fibre_stresses along qd: the same map of s' = B(q) q'."""
        z = self.chords_and_slopes(q)
        jac = self._strain_jacobian(z, self._strains(z))
        rate = np.einsum('eki,ei->ek', jac, self.lin @ qd)
        return self._fibre(rate)


def static_equilibrium(law, force: np.ndarray, load_steps: int = 40, iterations: int = 50,
                       tolerance: float = 1e-13) -> np.ndarray:
    """
    Return the elastic coordinates where the law's restoring force equals `force`.

    The load applied in `load_steps` equal increments from zero, Newton's method on
    gradient(q) = force at each (a large-deflection static solution: the elastica of a
    clamped beam under a tip load, against which the co-rotational law is checked).
    """
    q = np.zeros(len(force))
    for frac in np.linspace(0.0, 1.0, load_steps + 1)[1:]:
        for _ in range(iterations):
            dq = np.linalg.solve(law.tangent(q), frac * force - law.gradient(q))
            q += dq
            if np.abs(dq).max() < tolerance:
                break
    return q
