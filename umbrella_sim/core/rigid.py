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
independent work-energy quadrature of its deployment time; ``RigidUmbrella``, the umbrella
of N such rigid ribs on one sleeve (each rib's own record, tip mass and hinge friction),
which the deployment law plans on.

Leaf: uniform bar O-G of length l1 + l2 hinged at O; link: uniform bar O''-H of length l3.
Coordinates (alpha1, alpha2), one constraint Phi = l1 cos(alpha1) + l3 cos(alpha2) = 0 (4.123).

    T = 1/2 (I1' + m2 l1^2) a1'^2 + 1/2 I2' a2'^2 + 1/2 m2 l1 l3 a1' a2' cos(a1 - a2)   (4.120)

with I1' = rho A (l1+l2)^3 / 3, I2' = m2 l3^2 / 3 (so the printed (3/2)(l1/l3) I2' is
1/2 m2 l1 l3, and the (2,2) entry of 4.125 is I2', not I2'(l2/l3)^3).
"""
from __future__ import annotations

import functools
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

    def sleeve_lever(self, alpha1: float) -> float:
        """Return dy_H / d alpha1 (m/rad): F_H's generalised force on alpha1 is -F_H times it."""
        p = self.params
        a2 = self.alpha2(alpha1)
        return p.l1 * math.cos(alpha1) + p.l3 * math.cos(a2) * self.alpha2_rate_ratio(alpha1, a2)

    def generalized_mass(self, alpha1: float) -> float:
        """Return m(alpha1), T = 1/2 m alpha1'^2 on the constraint (4.120 with 4.124)."""
        a2 = self.alpha2(alpha1)
        return 2.0 * self.kinetic_energy(alpha1, a2, 1.0, self.alpha2_rate_ratio(alpha1, a2))

    def alpha1_at(self, sleeve_height: float) -> float:
        """
        Return the leaf angle that puts the sleeve at this height.

        The triangle O, H and the link's hinge on the leaf: l3^2 = l1^2 + y^2 - 2 l1 y sin a,
        for a height within the rib's reach (params3d.rib_reach; at its top, l1 + l3, the
        sine is 1 but for round-off).
        """
        p, y = self.params, sleeve_height
        return math.asin(min((y * y + p.l1 ** 2 - p.l3 ** 2) / (2.0 * p.l1 * y), 1.0))

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
        w1 = v0 / self.sleeve_lever(a1)
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


def mean_leaf_angle(angles) -> float:
    """
    Return the ribs' mean leaf angle (or rate), the coordinate the deployment law reads.

    One rib: its own angle (the planar frame's alpha1).
    """
    angles = list(angles)
    return math.fsum(angles) / len(angles)


class RigidUmbrella:
    """
    The umbrella of N rigid ribs on the one sleeve, in the ribs' mean leaf angle q.

    Each rib is the rigid two-angle model of its own record (RigidMechanism: its lengths,
    section and density), with its tip mass at G (a point at l1 + l2 + tip_offset_x along
    the leaf and tip_offset_y across it: its moment about the hinge axis), and the friction
    of its leaf hinge (hinge_coulomb tanh(rate / hinge_regularisation) + hinge_viscous rate,
    as the simulator's); the sleeve (sleeve_mass) carries the N links.  Rigid, every rib's
    leaf angle a_k is a function of the sleeve's height y (RigidMechanism.alpha1_at) and q
    is their mean (mean_leaf_angle, what the controller reads of the joint states):

        T = 1/2 M(q) q'^2,   M = sum_k m_k(a_k) (da_k/dq)^2 + m_s (dy/dq)^2,

    the sleeve's N F doing the work -N F dy and each hinge's friction torque tau_k the work
    -tau_k da_k.  So M q'' + 1/2 M'(q) q'^2 = -F lever(q) - friction(q, q'), lever = N dy/dq.
    The planar record (UmbrellaParams) is one rib, with no tip mass and no friction: q is
    its alpha1 and M its m(alpha1); N identical ribs give N times its M and its lever.
    """

    def __init__(self, params):
        from .umbrella3d.params3d import rib_reach, UmbrellaRibsParams

        if isinstance(params, UmbrellaRibsParams):
            planar, ribs = params.planar, params.ribs_list()
            self.sleeve_mass = params.sleeve_mass
            self.regularisation = params.hinge_regularisation
            records = [rib.planar for rib in ribs]
            self.tip_inertia = [rib.tip_mass * ((rib.planar.l1 + rib.planar.l2
                                                 + rib.tip_offset_x) ** 2 + rib.tip_offset_y ** 2)
                                for rib in ribs]
            self.coulomb = [rib.hinge_coulomb for rib in ribs]
            self.viscous = [rib.hinge_viscous for rib in ribs]
        else:
            planar, records = params, [params]
            self.sleeve_mass, self.regularisation = 0.0, 1.0
            self.tip_inertia, self.coulomb, self.viscous = [0.0], [0.0], [0.0]
        self.planar = planar
        self.ribs = len(records)
        self.mechs = [RigidMechanism(r) for r in records]
        self.rubs = any(self.coulomb) or any(self.viscous)
        # every rib of the planar record's lengths has its leaf angle: q is it, y its height
        self.shared_lengths = all((r.l1, r.l3) == (planar.l1, planar.l3) for r in records)
        self._planar = RigidMechanism(planar)
        reach = [rib_reach(r.l1, r.l3) for r in records]
        self._last_height: float | None = None
        # (the plan asks each point's geometry several times: once solved, kept)
        self._geometry = functools.lru_cache(maxsize=1 << 15)(self._solve_geometry)
        self._reach = (max(r[1] for r in reach), min(r[2] for r in reach))
        self.alpha0 = self._coordinate_at(planar.sleeve_start_height, planar.alpha0)
        self.alpha_deployed = self._coordinate_at(planar.sleeve_stop_height,
                                                  planar.alpha_deployed)
        self._start_angles = self.sleeve_and_angles(self.alpha0)[1]

    def _coordinate_at(self, y: float, planar_angle: float) -> float:
        """Return q where the sleeve stands at y (planar_angle: the record's angle there)."""
        if self.shared_lengths:
            return planar_angle
        return mean_leaf_angle(m.alpha1_at(y) for m in self.mechs)

    def sleeve_and_angles(self, q: float) -> tuple[float, list[float]]:
        """Return the sleeve's height y and every rib's leaf angle a_k at the coordinate q."""
        if self.shared_lengths:         # every rib's angle is q
            mech = self._planar
            return mech.sleeve_height(q, mech.alpha2(q)), [q] * self.ribs
        return self._geometry(q)[:2]

    def sleeve_height(self, q: float) -> float:
        """Return the sleeve's height y (m) at the coordinate q."""
        return self.sleeve_and_angles(q)[0]

    def _jacobians(self, q: float) -> tuple[list[float], list[float], float]:
        """Return (a_k, da_k/dq, dy/dq) at q."""
        if self.shared_lengths:
            return [q] * self.ribs, [1.0] * self.ribs, self._planar.sleeve_lever(q)
        return self._geometry(q)[1:]

    def _solve_geometry(self, q: float) -> tuple[float, list[float], list[float], float]:
        """
        Return (y, a_k, da_k/dq, dy/dq) at q, of ribs of their own lengths.

        Newton on mean_k a_k(y) = q (each a_k rises with y, da_k/dy = 1 / the rib's lever),
        from the last answer (the plan walks its grid: three steps) or the record's height,
        kept within the heights every rib reaches (a step out of them bisects instead).
        """
        mech = self._planar
        lo, hi = self._reach
        y = min(max(self._last_height or mech.sleeve_height(q, mech.alpha2(q)), lo), hi)
        for _ in range(100):
            angles = [m.alpha1_at(y) for m in self.mechs]
            rates = [1.0 / m.sleeve_lever(a) for m, a in zip(self.mechs, angles)]
            error = mean_leaf_angle(angles) - q
            if error > 0.0:
                hi = y
            elif error < 0.0:
                lo = y
            slope = mean_leaf_angle(rates)
            y_next = y - error / slope
            if abs(y_next - y) <= 1e-15 * y:
                break
            y = y_next if lo <= y_next <= hi else 0.5 * (lo + hi)
        self._last_height = y
        return y, angles, [r / slope for r in rates], 1.0 / slope

    def inertia(self, q: float) -> float:
        """Return the generalised mass M(q): T = 1/2 M q'^2 (kg m^2)."""
        angles, jac, dy = self._jacobians(q)
        ribs = math.fsum((m.generalized_mass(a) + tip) * j * j for m, a, tip, j
                         in zip(self.mechs, angles, self.tip_inertia, jac))
        return ribs + self.sleeve_mass * dy * dy

    def lever(self, q: float) -> float:
        """Return N dy/dq (m/rad): F a rib's generalised force on q is -F times this."""
        return self.ribs * self._jacobians(q)[2]

    def friction(self, q: float, rate: float) -> float:
        """Return the hinges' friction on q at the rate q' as a resistance (its force is -this)."""
        if not self.rubs:
            return 0.0
        _, jac, _ = self._jacobians(q)
        eps = self.regularisation
        return math.fsum(j * (c * j * rate + tau * math.tanh(j * rate / eps))
                         for j, c, tau in zip(jac, self.viscous, self.coulomb))

    def friction_work(self, q: float) -> float:
        """Return the Coulomb friction's work from alpha0 to q, at speed (J, >= 0)."""
        if not any(self.coulomb):
            return 0.0
        _, angles = self.sleeve_and_angles(q)
        start = self._start_angles
        return math.fsum(tau * abs(a0 - a) for tau, a0, a in zip(self.coulomb, start, angles))

    def viscous_coefficient(self, q: float) -> float:
        """Return sum_k c_k (da_k/dq)^2: the viscous hinges' resistance is this times q'."""
        if not any(self.viscous):
            return 0.0
        _, jac, _ = self._jacobians(q)
        return math.fsum(c * j * j for c, j in zip(self.viscous, jac))


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

    generalized_mass = mech.generalized_mass

    def energy(a1):
        return t0 + force * (h0 - mech.sleeve_height(a1, mech.alpha2(a1)))

    if t0 > 0.0:
        val, _ = integrate.quad(lambda a: math.sqrt(generalized_mass(a) / (2.0 * energy(a))),
                                ad, a0, epsabs=0.0, epsrel=1e-12, limit=200)
        return val
    if force <= 0.0:
        return math.inf
    # energy ~ F dy_H/da (a0 - a) near the start: integrate g(a) (a0 - a)^(-1/2), alg weight
    dy0 = mech.sleeve_lever(a0)

    def g(a):
        if a0 - a < 1e-12:
            return math.sqrt(generalized_mass(a0) / (2.0 * force * dy0))
        return math.sqrt(generalized_mass(a) * (a0 - a) / (2.0 * energy(a)))

    val, _ = integrate.quad(g, ad, a0, weight='alg', wvar=(0.0, -0.5),
                            epsabs=0.0, epsrel=1e-12, limit=200)
    return val
