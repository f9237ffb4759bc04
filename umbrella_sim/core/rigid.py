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
Closed-form rigid two-angle model and a work-energy quadrature.

The model of thesis 4.6 (Eq. 4.120-4.125, re-derived) and the
independent work-energy quadrature of its deployment time.

Leaf: uniform bar O-G of length l1 + l2 hinged at O; link: uniform bar O''-H of length l3.
Coordinates (alpha1, alpha2), one constraint Phi = l1 cos(alpha1) + l3 cos(alpha2) = 0 (4.123).

    T = 1/2 (I1' + m2 l1^2) a1'^2 + 1/2 I2' a2'^2 + 1/2 m2 l1 l3 a1' a2' cos(a1 - a2)   (4.120)

with I1' = rho A (l1+l2)^3 / 3, I2' = m2 l3^2 / 3 (so the printed (3/2)(l1/l3) I2' is
1/2 m2 l1 l3, and the (2,2) entry of 4.125 is I2', not I2'(l2/l3)^3).
"""
from __future__ import annotations

import math

import numpy as np

from .params import UmbrellaParams


class RigidMechanism:

    def __init__(self, params: UmbrellaParams):
        p = params.validated()
        self.params = p
        rho_a = p.mass_per_length
        self.m2 = rho_a * p.l3
        self.i1 = rho_a * (p.l1 + p.l2) ** 3 / 3.0
        self.i2 = self.m2 * p.l3 ** 2 / 3.0
        self.coupling = 0.5 * self.m2 * p.l1 * p.l3

    def alpha2(self, alpha1: float) -> float:
        p = self.params
        return math.acos(-p.l1 / p.l3 * math.cos(alpha1))

    def alpha2_rate_ratio(self, alpha1: float, alpha2: float) -> float:
        """Return d alpha2 / d alpha1 from the velocity constraint J q' = 0 (4.124)."""
        p = self.params
        return -p.l1 * math.sin(alpha1) / (p.l3 * math.sin(alpha2))

    def sleeve_height(self, alpha1: float, alpha2: float) -> float:
        p = self.params
        return p.l1 * math.sin(alpha1) + p.l3 * math.sin(alpha2)

    def mass_matrix(self, alpha1: float, alpha2: float) -> np.ndarray:
        m12 = self.coupling * math.cos(alpha1 - alpha2)
        return np.array([[self.i1 + self.m2 * self.params.l1 ** 2, m12], [m12, self.i2]])

    def kinetic_energy(self, a1, a2, w1, w2) -> float:
        """T of (4.120), on floats (a step evaluates it; numpy costs more than the sum)."""
        m12 = self.coupling * math.cos(a1 - a2)
        m11 = self.i1 + self.m2 * self.params.l1 ** 2
        return 0.5 * (m11 * w1 * w1 + 2.0 * m12 * w1 * w2 + self.i2 * w2 * w2)

    def accelerations(self, a1, a2, w1, w2, force: float) -> tuple[float, float, float]:
        """
        Solve Eq. 4.125 (corrected) for (alpha1'', alpha2'', lambda).

        [[M, -j], [j^T, 0]] (a, lambda) = (r, c) with one constraint row j: by the Schur
        complement of the 2 x 2 M, on floats (five solves a step: numpy's solve of the 3 x 3
        system cost ~45 us each, the step ~0.5 ms).
        """
        p = self.params
        s12 = math.sin(a1 - a2)
        m11 = self.i1 + self.m2 * p.l1 ** 2
        m12 = self.coupling * math.cos(a1 - a2)
        m22 = self.i2
        j1, j2 = -p.l1 * math.sin(a1), -p.l3 * math.sin(a2)
        r1 = -self.coupling * w2 * w2 * s12 - force * p.l1 * math.cos(a1)
        r2 = self.coupling * w1 * w1 * s12 - force * p.l3 * math.cos(a2)
        c = p.l1 * w1 * w1 * math.cos(a1) + p.l3 * w2 * w2 * math.cos(a2)
        det = m11 * m22 - m12 * m12
        # M^-1 r and M^-1 j
        u1, u2 = (m22 * r1 - m12 * r2) / det, (m11 * r2 - m12 * r1) / det
        v1, v2 = (m22 * j1 - m12 * j2) / det, (m11 * j2 - m12 * j1) / det
        lam = (c - (j1 * u1 + j2 * u2)) / (j1 * v1 + j2 * v2)
        return u1 + lam * v1, u2 + lam * v2, lam

    def initial_state(self, v0: float) -> np.ndarray:
        p = self.params
        a1 = p.alpha0
        a2 = self.alpha2(a1)
        ratio = self.alpha2_rate_ratio(a1, a2)
        dy = p.l1 * math.cos(a1) + p.l3 * math.cos(a2) * ratio
        w1 = v0 / dy
        return np.array([a1, a2, w1, ratio * w1])

    def project(self, y) -> tuple[float, float, float, float]:
        """Back onto Phi = 0 and J q' = 0 (alpha1 is the independent coordinate)."""
        a1, w1 = y[0], y[2]
        a2 = self.alpha2(a1)
        return a1, a2, w1, self.alpha2_rate_ratio(a1, a2) * w1

    def rk4_step(self, y, h: float, force: float) -> tuple[float, float, float, float]:
        """One classical Runge-Kutta step of (alpha1, alpha2, rates), then project."""
        def f(a1, a2, w1, w2):
            acc1, acc2, _ = self.accelerations(a1, a2, w1, w2, force)
            return w1, w2, acc1, acc2

        y = tuple(float(v) for v in y)
        k1 = f(*y)
        k2 = f(*(yi + 0.5 * h * ki for yi, ki in zip(y, k1)))
        k3 = f(*(yi + 0.5 * h * ki for yi, ki in zip(y, k2)))
        k4 = f(*(yi + h * ki for yi, ki in zip(y, k3)))
        return self.project([yi + h / 6.0 * (a + 2 * b + 2 * c + d)
                             for yi, a, b, c, d in zip(y, k1, k2, k3, k4)])


def deployment_time_by_quadrature(params: UmbrellaParams, v0: float | None = None,
                                  sleeve_force: float | None = None) -> float:
    """
    Return t = int d(alpha1) / |alpha1'(alpha1)|, alpha1' from work-energy.

        1/2 m(alpha1) alpha1'^2 = T0 + F_H (y_H(alpha0) - y_H(alpha1)).

    Independent of any time integrator; handles V0 = 0 (inverse-square-root start).
    """
    p = params.validated()
    v0 = p.v0 if v0 is None else v0
    force = p.sleeve_force if sleeve_force is None else sleeve_force
    # (here, not at the module's top: scipy.integrate costs a fifth of a second to import,
    # which every command line would pay; only the quadrature needs it)
    from scipy import integrate

    mech = RigidMechanism(p)
    a0, ad = p.alpha0, p.alpha_deployed
    y0 = mech.initial_state(v0)
    t0 = mech.kinetic_energy(*y0)
    h0 = mech.sleeve_height(a0, mech.alpha2(a0))

    def generalized_mass(a1):
        a2 = mech.alpha2(a1)
        r = mech.alpha2_rate_ratio(a1, a2)
        return 2.0 * mech.kinetic_energy(a1, a2, 1.0, r)

    def energy(a1):
        return t0 + force * (h0 - mech.sleeve_height(a1, mech.alpha2(a1)))

    if t0 > 0.0:
        val, _ = integrate.quad(lambda a: math.sqrt(generalized_mass(a) / (2.0 * energy(a))),
                                ad, a0, epsabs=0.0, epsrel=1e-12, limit=200)
        return val
    if force <= 0.0:
        return math.inf
    # energy ~ F dy_H/da (a0 - a) near the start: integrate g(a) (a0 - a)^(-1/2), alg weight
    a20 = mech.alpha2(a0)
    dy0 = p.l1 * math.cos(a0) + p.l3 * math.cos(a20) * mech.alpha2_rate_ratio(a0, a20)

    def g(a):
        if a0 - a < 1e-12:
            return math.sqrt(generalized_mass(a0) / (2.0 * force * dy0))
        return math.sqrt(generalized_mass(a) * (a0 - a) / (2.0 * energy(a)))

    val, _ = integrate.quad(g, ad, a0, weight='alg', wvar=(0.0, -0.5),
                            epsabs=0.0, epsrel=1e-12, limit=200)
    return val
