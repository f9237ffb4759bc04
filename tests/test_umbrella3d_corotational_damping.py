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
The umbrella's damped co-rotational ribs (damping3d.py, corotational3d.py) against the physics.

Model flexible-nonlinear with damping_ratio zeta: C(q) = beta B(q)^T D B(q), the Kelvin-Voigt
damping of the co-rotated strain rates, the planar co-rotational model's (nonlinear.py).
(a) Three identical ribs are each the damped planar flexible-nonlinear model through the
lock (V0 = -1, the links buckle) to the undamped identity's 1e-10
(test_umbrella3d_nonlinear.py: both codes solved to 1e-14), on both paths, and dissipate 3
times its energy to 1e-9.  (b) The energy balance T + V - (T + V)(0) = W_F + W_friction +
W_drive - lock loss - dissipation closes to the linear damped ribs' tolerance (1e-10 of T +
V; a prescribed base 1e-6) with the dissipation of the order of the work, on every base, and
that dissipation is the steps' dq . C(q_m) dq / h with beta recomputed from zeta and
omega_1, to 1e-9.  (c) The compiled step (_kernel3d_nonlinear.h's damping) takes the numpy
reference's steps within 10 x the reference's ulp spread
(test_umbrella3d_kernel.assert_rows_agree).  (d) The locked umbrella's modes decay as the
discrete Rayleigh damping says: rib 0's first in-plane mode (the planar rib's first, whose
omega_1 sets beta) with zeta, its first out-of-plane mode with zeta omega / omega_1, each as
the midpoint rule maps them (midpoint_ratio: the linear ribs' measured ratios meet it to
5e-9). The co-rotational law's quadratic terms shift the modal coordinate's mean by a part
of its amplitude squared, which the logarithmic decrement of the peaks reads as a ratio 0.6
x amplitude higher (5.9e-4 relative at 1e-3 of the modal unit, 6.0e-6 at 1e-5); the first
in-plane ratio is therefore taken to vanishing amplitude (Richardson's from 2e-5 and 1e-5),
the out-of-plane one (a quadratic shift: 6e-12 at 1e-5) at 1e-5.
"""
import math

import numpy as np
import pytest

from tests.test_umbrella3d import BALANCE_TOLERANCE, momentum_scales
from tests.test_umbrella3d_damping import decay_ratio
from tests.test_umbrella3d_kernel import (assert_rows_agree, ASYMMETRIC, AT_SPEED, BASES,
                                          needs_kernel)
from tests.test_umbrella3d_nonlinear import assert_ribs_equal_planar_nonlinear
from umbrella_sim.core.nonlinear import locked_first_frequency
from umbrella_sim.core.umbrella3d.damping3d import damping_beta
from umbrella_sim.core.umbrella3d.modes3d import rib_locked_modes
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.core.umbrella3d.substeps3d import planar_model

ZETA = 0.05
NONLINEAR = {'model': 'flexible-nonlinear'}


# ---------------------------------------------------------------- (a) the planar model
@pytest.mark.parametrize('kernel', [
    pytest.param('compiled', marks=needs_kernel),
    pytest.param('numpy', marks=pytest.mark.slow)])        # numpy ~7 s; compiled ~1 s
def test_damped_identical_ribs_are_the_damped_planar_nonlinear_model(kernel):
    """Three ribs, zeta 0.05, V0 = -1, the plastic lock, 35 ms of stage 2; either path."""
    sim, planar_sim = assert_ribs_equal_planar_nonlinear(
        {'lock': 'plastic', 'damping_ratio': ZETA}, kernel)
    dissipated = planar_sim.sample().damping_dissipation
    assert dissipated > 0.1 * sim.record.work
    assert sim.record.damping == pytest.approx(3 * dissipated, rel=1e-9)
    assert sim.record.summary()['damping_dissipation'] == sim.record.damping


# ---------------------------------------------------------------- (b) the energy balance
@pytest.mark.parametrize('base', BASES)
def test_the_energy_balance_closes_with_the_dissipation(base):
    """
    Asymmetric ribs (friction, a stuck hinge, a kick), damped, through the lock.

    The dissipation the balance adds back is the steps' dq . C(q_m) dq / h with beta =
    2 zeta / omega_1 (to 1e-9 over the first 300 steps, a hinge's release in them): the
    step scales its velocity to the energy target net of the dissipation it reports, so the
    balance alone would close with any dissipation.  A prescribed base's step is not scaled
    to its energy target, so its balance is Newton's: at the default tolerance (1e-8) 2.0e-6
    of T + V, at 1e-10 5.0e-8 (the linear ribs': 1.6e-7 at 1e-8); the run is solved to 1e-10
    there.
    """
    values = dict(ASYMMETRIC, **NONLINEAR, damping_ratio=ZETA, **AT_SPEED, **BASES[base])
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values),
                              **({'tolerance': 1e-10} if base == 'prescribed' else {}))
    beta = 2.0 * ZETA / locked_first_frequency(planar_model(sim.params.planar))
    expected = 0.0
    for _ in range(300):
        s0 = sim.state
        sim.step()
        dq = sim.state.qr - s0.qr
        tangent = sim.model.material_tangent(s0.qr + 0.5 * dq)
        expected += beta / sim.h * float(np.einsum('ri,rij,rj->', dq, tangent, dq))
    assert sim.record.damping == pytest.approx(expected, rel=1e-9)
    rec = sim.run(1.0, after_lock=0.01)
    s = rec.summary()
    tolerance = BALANCE_TOLERANCE if base != 'prescribed' else 1e-6   # (not scaled: kernel's)
    assert s['energy_balance_residual'] < tolerance * s['energy_scale']
    a = rec.arrays()
    # the dissipation is there, grows, and is of the order of the work (not a rounding)
    assert np.all(np.diff(a['damping_dissipation']) >= 0.0)
    assert s['damping_dissipation'] > 1e-3 * abs(a['work'][-1])
    # the same run undamped dissipates nothing
    undamped = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        dict(values, damping_ratio=0.0))).run(1.0, after_lock=0.01).summary()
    assert undamped['damping_dissipation'] == 0.0
    if base == 'free':     # the damping is internal: the bus's momentum stays
        p = a['linear_momentum']
        assert np.max(np.abs(p - p[0])) < 1e-12 * momentum_scales(sim, a)[0]


# ---------------------------------------------------------------- (c) compiled = numpy
@needs_kernel
@pytest.mark.parametrize('base', [pytest.param(base, marks=[pytest.mark.slow] if base != 'fixed'
                                               else []) for base in BASES])
def test_damped_compiled_steps_equal_numpy(base):
    """The damped co-rotational step on both paths, within the numpy reference's ulp spread."""
    values = dict(ASYMMETRIC, **NONLINEAR, damping_ratio=ZETA, **AT_SPEED, **BASES[base])
    p = UmbrellaRibsParams.from_mapping(values)
    runs = [UmbrellaSimulator3D(p, kernel=k) for k in ('compiled', 'numpy', 'numpy')]
    s = runs[2].state
    runs[2].state = type(s)(s.t, s.qr, s.qs, np.nextafter(s.vr, np.inf), s.vs, s.lam_r,
                            s.lam_s, s.stuck)
    for sim in runs:
        sim.advance(150)
    a, b, spread = (sim.record.arrays() for sim in runs)
    assert a['damping_dissipation'][-1] > 1e-3 * abs(a['work'][-1])
    assert_rows_agree(a, b, spread, runs[0].model)


# ---------------------------------------------------------------- (d) the modes' decay
def midpoint_ratio(zeta: float, omega: float, h: float) -> float:
    """
    Return the damping ratio the midpoint rule gives a mode (zeta, omega) at step h.

    On a linear system the midpoint rule is the trapezoidal map z = (1 + h s / 2) / (1 - h s
    / 2) of each eigenvalue s = omega (-zeta + i sqrt(1 - zeta^2)); a step multiplies the
    amplitude by |z| and turns the phase by arg z, so the logarithmic decrement over a
    (discrete) period reads the ratio -ln|z| / |ln z|.
    """
    s = omega * complex(-zeta, math.sqrt(1.0 - zeta * zeta))
    z = (1.0 + 0.5 * h * s) / (1.0 - 0.5 * h * s)
    return -math.log(abs(z)) / abs(complex(math.log(abs(z)), math.atan2(z.imag, z.real)))


#: the decay's agreement: the peaks' parabolic interpolation and Newton's tolerance (the
#: linear ribs' ratios meet midpoint_ratio to 5e-9; a beta off by 1e-6 shows 1e-6)
DECAY_RTOL = 1e-7


@needs_kernel
def test_the_locked_modes_decay_as_rayleigh_damping_says():
    """
    Rib 0's first in-plane mode decays with zeta, its first out-of-plane one with less.

    Two ribs, 0.1 ms (the co-rotational ribs have no mode fit): each ratio the midpoint
    rule's of zeta omega / omega_1 to DECAY_RTOL (in-plane taken to vanishing amplitude,
    module docstring); at 1e-3 of the modal unit the in-plane one reads 6e-4 high.
    """
    p = UmbrellaRibsParams.from_mapping({**NONLINEAR, 'ribs': 2, 'damping_ratio': ZETA,
                                         'time_step': 1e-4})
    sim = UmbrellaSimulator3D(p, kernel='compiled', tolerance=1e-12)
    assert not sim.mode_fit
    m = sim.model
    omega_1 = locked_first_frequency(planar_model(p.planar))
    assert sim.integrator.damping_beta == damping_beta(p) == pytest.approx(2 * ZETA / omega_1)
    phi = rib_locked_modes(m)[0][1]
    tip_v, tip_w = (np.abs(phi[i, :6]) for i in m.i_tip[1:])
    in_plane, out_of_plane = int(np.argmax(tip_v > tip_w)), int(np.argmax(tip_w > tip_v))
    omega, coarse = decay_ratio(sim, in_plane, amplitude=2e-5)
    assert omega == pytest.approx(omega_1, rel=1e-9)      # the planar rib's first mode
    fine = decay_ratio(sim, in_plane, amplitude=1e-5)[1]
    expected = midpoint_ratio(ZETA, omega, sim.h)
    assert 2.0 * fine - coarse == pytest.approx(expected, rel=DECAY_RTOL)
    assert fine == pytest.approx(expected, rel=1e-5)      # (its amplitude's 6e-6)
    assert expected == pytest.approx(ZETA, rel=1e-4)      # (the midpoint rule's 3e-5)
    omega, zeta = decay_ratio(sim, out_of_plane, amplitude=1e-5)
    assert omega < 0.6 * omega_1
    assert zeta == pytest.approx(midpoint_ratio(ZETA * omega / omega_1, omega, sim.h),
                                 rel=DECAY_RTOL)
