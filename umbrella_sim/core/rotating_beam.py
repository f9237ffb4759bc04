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
The geometric-stiffening benchmark of the nonlinear beam: a cantilever in prescribed rotation.

A beam of the umbrella's own elements (beam_strain.CorotationalStrainEnergy: the same
co-rotational strain energy and discrete gradient as flexible-nonlinear) clamped to a hub
that turns at a prescribed angle: spun up and left turning, it vibrates in the plane of
rotation at the frequency the published rotating-cantilever tables give (Wright, Smith,
Thresher & Wang 1982; Yoo & Shin 1998: lambda_f against gamma, in-plane sqrt(lambda_f^2 -
gamma^2)), and its spin-up follows Kane, Ryan & Banerjee's (1987) beam, where the linear
model diverges.  tests/test_nonlinear.py and docs/make_validation_nonlinear.py use
it; the simulator does not.
"""
from __future__ import annotations

import math

import numpy as np

from .beam import BeamBody
from .beam_strain import CorotationalStrainEnergy, LinearStrainEnergy
from .summary import oscillation_period


# ------------------------------------------------- benchmark: beam on a driven hub
class PrescribedRotationBeam:
    """
    Cantilever on a hub whose angle theta(t) is prescribed.

    A cantilever BeamBody clamped to a hub whose angle theta(t) is prescribed, in the
    hub's floating frame (u = v = theta = 0 at the root), stepped by the implicit midpoint
    rule with the discrete gradient of U.  The elastic equations are the e-rows of the frame's
    equations of motion (model.py invariants):

        M_ff e'' = w^2 (c + M_ff e) + 2 w W e' - theta'' (g + W^T e) - grad U(e)

    (centrifugal, Coriolis, Euler terms).  Used for the spin-up benchmark of Kane, Ryan &
    Banerjee (J. Guidance Control Dynamics 10(2), 1987): with the linear strain the beam
    diverges once w exceeds its first bending frequency; with the co-rotational strain it does
    not.
    """

    def __init__(self, length: float, n_elements: int, mass_per_length: float, ea: float,
                 ei: float, youngs_modulus: float, fibre: float, nonlinear: bool):
        self.body = BeamBody('beam', [(length, n_elements)], [(0, 'u'), (0, 'v'), (0, 'theta')],
                             mass_per_length=mass_per_length, ea=ea, ei=ei,
                             youngs_modulus=youngs_modulus, fibre=fibre)
        ne = self.body.n_elastic
        bodies = ((self.body, slice(0, ne)),)
        self.strain = (CorotationalStrainEnergy(bodies, ne, ea, ei, youngs_modulus, fibre)
                       if nonlinear else LinearStrainEnergy(bodies, ne))
        self.i_tip_u = self.body.elastic_index(n_elements, 'u')
        self.i_tip_v = self.body.elastic_index(n_elements, 'v')

    def simulate(self, angle_rate, angle_accel, duration: float, h: float,
                 tolerance: float = 1e-10, max_iterations: int = 30):
        """
        Step through the hub motion; return times, tip u and tip v.

        Returns times, tip u, tip v (m, in the hub frame); stops early (returning what it
        has) if the Newton iteration fails or |v_tip| exceeds 10 beam lengths.
        """
        b = self.body
        mff, w_sk, c, g = b.m_ff, b.w_skew, b.c, b.g
        ne = b.n_elastic
        e, ed = np.zeros(ne), np.zeros(ne)
        times, tip_u, tip_v = [0.0], [0.0], [0.0]
        for k in range(int(round(duration / h))):
            tm = (k + 0.5) * h
            w, wd = angle_rate(tm), angle_accel(tm)
            e1 = e + h * ed
            for _ in range(max_iterations):
                v1 = 2.0 * (e1 - e) / h - ed
                em, vm = 0.5 * (e + e1), 0.5 * (ed + v1)
                force = (w * w * (c + mff @ em) + 2.0 * w * (w_sk @ vm) - wd * (g + w_sk.T @ em)
                         - self.strain.discrete_gradient(e, e1))
                resid = mff @ (v1 - ed) - h * force
                jac = (2.0 / h) * mff - h * (0.5 * w * w * mff + (2.0 / h) * w * w_sk
                                             - 0.5 * wd * w_sk.T
                                             - self.strain.discrete_gradient_jacobian(e, e1))
                de = np.linalg.solve(jac, -resid)
                e1 = e1 + de
                if np.max(np.abs(de)) < tolerance * max(1.0, np.max(np.abs(e1))):
                    break
            else:
                break
            ed = 2.0 * (e1 - e) / h - ed
            e = e1
            times.append((k + 1) * h)
            tip_u.append(e[self.i_tip_u])
            tip_v.append(e[self.i_tip_v])
            if abs(e[self.i_tip_v]) > 10.0 * b.length or not np.all(np.isfinite(e)):
                break
        return np.array(times), np.array(tip_u), np.array(tip_v)


def spin_up_angle(t: float, omega: float = 6.0, ramp: float = 15.0):
    """
    Return the spin-up hub angle and its rates (Kane, Ryan & Banerjee 1987).

    Kane, Ryan & Banerjee (1987) spin-up: theta = (W/T)[t^2/2 + (T/2pi)^2 (cos(2pi t/T) - 1)]
    for t <= T, W (t - T/2) after; returns (theta, theta', theta'').
    """
    if t <= ramp:
        a = 2.0 * math.pi / ramp
        return ((omega / ramp) * (0.5 * t * t + (math.cos(a * t) - 1.0) / (a * a)),
                (omega / ramp) * (t - math.sin(a * t) / a),
                (omega / ramp) * (1.0 - math.cos(a * t)))
    return omega * (t - 0.5 * ramp), omega, 0.0


#: the spin-up beam of Kane, Ryan & Banerjee (1987): L = 10 m, A = 4e-4 m^2, I = 2e-7 m^4,
#: E = 7e10 Pa, rho = 3000 kg/m^3 (EA, EI, rho A as in the AeroBeams.jl spinupRobotArm example)
KANE_BEAM = {'length': 10.0, 'mass_per_length': 1.2, 'ea': 2.8e7, 'ei': 1.4e4,
             'youngs_modulus': 7e10, 'fibre': 0.01}


def spin_up(n_elements: int, nonlinear: bool, duration: float, h: float):
    """Return times, tip u, tip v of the Kane spin-up beam on our beam element (hub frame)."""
    beam = PrescribedRotationBeam(n_elements=n_elements, nonlinear=nonlinear, **KANE_BEAM)
    return beam.simulate(lambda t: spin_up_angle(t)[1], lambda t: spin_up_angle(t)[2],
                         duration, h)


def spin_up_quasi_static_tip(t: float) -> float:
    """
    Return the quasi-static tip deflection of the spinning Kane beam at time t (m).

    The cantilever under its Euler load rho A theta'' x with the exact centrifugal tension
    N = rho A w^2 (L^2 - x^2) / 2, EI v'''' - (N v')' - rho A w^2 v = -rho A theta'' x,
    solved by scipy's boundary-value solver (no finite elements): the independent reference
    of the spin-up benchmark.
    """
    from scipy.integrate import solve_bvp
    length, rho_a, ei = KANE_BEAM['length'], KANE_BEAM['mass_per_length'], KANE_BEAM['ei']
    _, w, wd = spin_up_angle(t)

    def rhs(x, y):
        tension = 0.5 * rho_a * w * w * (length ** 2 - x * x)
        return np.vstack([y[1], y[2], y[3], (-rho_a * w * w * x * y[1] + tension * y[2]
                                             + rho_a * w * w * y[0] - rho_a * wd * x) / ei])

    x = np.linspace(0.0, length, 60)
    sol = solve_bvp(rhs, lambda a, b: np.array([a[0], a[1], b[2], b[3]]), x, np.zeros((4, 60)),
                    tol=1e-8)
    if sol.status != 0:
        raise RuntimeError(f'quasi-static spin-up reference at t = {t:g} s: {sol.message}')
    return float(sol.sol(length)[0])


#: first flapwise natural frequency of a rotating uniform cantilever (hub radius 0), as
#: omega_f / sqrt(EI / (rho A L^4)) against the spin rate gamma = Omega sqrt(rho A L^4 / EI):
#: Wright, Smith, Thresher & Wang (J. Appl. Mech. 49, 1982) and Yoo & Shin (J. Sound Vib.
#: 212(5), 1998), the published table of centrifugal stiffening
ROTATING_CANTILEVER_FLAPWISE = {0: 3.5160, 1: 3.6816, 2: 4.1373, 3: 4.7973, 4: 5.5850,
                                5: 6.4495, 10: 11.2023}


def rotating_cantilever_chordwise(gamma: float) -> float:
    """
    Return the published first in-plane (chordwise) frequency of the rotating cantilever.

    Dimensionless, hub radius 0: the in-plane bending equation is the flapwise one plus the
    centrifugal softening -rho A Omega^2 v, so its eigenvalues are the flapwise ones less
    gamma^2 (exact for the linearised, inextensible beam): sqrt(lambda_f^2 - gamma^2).  A
    model without geometric stiffening gives sqrt(3.5160^2 - gamma^2) instead, and diverges
    once gamma passes 3.516 (the spin-up failure).
    """
    return math.sqrt(ROTATING_CANTILEVER_FLAPWISE[gamma] ** 2 - gamma * gamma)


def rotating_cantilever_frequency(gamma: float, n_elements: int, nonlinear: bool,
                                  ramp: float = 8.0, after: float = 12.0,
                                  h: float = 0.005) -> tuple[float, float]:
    """
    Return the measured in-plane frequency of our spinning beam, and the amplitude.

    The Kane beam (KANE_BEAM) is spun up smoothly (spin_up_angle) to Omega = gamma
    sqrt(EI / (rho A L^4)) over `ramp` s and then turns at constant Omega: the small free
    vibration the ramp leaves (millimetres on 10 m) oscillates at the first in-plane
    frequency, measured as outputs.oscillation_period of the tip deflection in the hub frame
    over the next `after` s (the stage-2 period's rule).  Returns
    (frequency / sqrt(EI / (rho A L^4)), max |v_tip| (m)).
    """
    length, rho_a, ei = KANE_BEAM['length'], KANE_BEAM['mass_per_length'], KANE_BEAM['ei']
    scale = math.sqrt(ei / (rho_a * length ** 4))
    omega = gamma * scale
    beam = PrescribedRotationBeam(n_elements=n_elements, nonlinear=nonlinear, **KANE_BEAM)
    t, _, v = beam.simulate(lambda s: spin_up_angle(s, omega, ramp)[1],
                            lambda s: spin_up_angle(s, omega, ramp)[2], ramp + after, h)
    if t[-1] < ramp + after - h / 2:
        raise RuntimeError(f'rotating cantilever at gamma = {gamma:g}: the run stopped at '
                           f't = {t[-1]:g} s')
    keep = t > ramp
    period = oscillation_period(t[keep], v[keep])
    if not math.isfinite(period):
        raise RuntimeError(f'rotating cantilever at gamma = {gamma:g}: fewer than two periods')
    return 2.0 * math.pi / period / scale, float(np.abs(v[keep]).max())
