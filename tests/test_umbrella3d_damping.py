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
The umbrella's damped beams (damping3d.py: the planar model's C = beta K) against the physics.

(a) N identical ribs with damping_ratio zeta > 0 are each the damped planar model (its
elastic law's step, nonlinear.py) to the identity's 1e-10 (test_umbrella3d.py's module
docstring; the planar model on the same path: the planar kernel's damped fitted steps and
its numpy reference differ by a Newton stopping decision, ~1e-10), the mode fit and stage 2's
substeps included, and dissipate N times its energy.  (b) The energy balance
T + V - (T + V)(0) = W_F + W_friction + W_drive - lock loss - dissipation closes to the
discrete balance's round-off with the dissipation of the order of the work, on every base.
(c) The compiled step (_kernel3d_damping.h) and the numpy reference take the same steps to
the reference's ulp spread.  (d) The locked umbrella's modes decay as Rayleigh damping says:
each rib's first in-plane mode (the planar rib's first, whose omega_1 sets beta) with ratio
zeta, its out-of-plane modes with zeta omega_i / omega_1, measured by the logarithmic
decrement of the mode's coordinate over six periods.
"""
import numpy as np
import pytest

from tests.test_umbrella3d import assert_ribs_equal_planar, BALANCE_TOLERANCE, momentum_scales
from tests.test_umbrella3d_base_fit import locked_state
from tests.test_umbrella3d_kernel import (assert_rows_agree, ASYMMETRIC, AT_SPEED, BASES,
                                          needs_kernel)
from tests.test_umbrella3d_substeps import continued
from umbrella_sim.core.nonlinear import locked_first_frequency
from umbrella_sim.core.umbrella3d.damping3d import damping_beta
from umbrella_sim.core.umbrella3d.modes3d import deployed_configuration, rib_locked_modes
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.core.umbrella3d.substeps3d import planar_model

ZETA = 0.05


@pytest.mark.parametrize('kernel', [
    pytest.param('compiled', marks=needs_kernel),
    pytest.param('numpy', marks=pytest.mark.slow)])        # numpy ~10 s
def test_damped_identical_ribs_are_the_damped_planar_model(kernel, monkeypatch):
    """Three ribs, zeta 0.05, time_step 0 (6 substeps in stage 2), the fit: one path both."""
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
    ribs = 3 if kernel == 'compiled' else 2
    sim, planar_sim = assert_ribs_equal_planar(
        ribs, {'sleeve_force': 10.0, 'damping_ratio': ZETA}, 0.19, kernel, fit=True)
    assert sim.stage2_substeps == planar_sim.stage2_substeps == 6
    dissipated = planar_sim.sample().damping_dissipation
    assert dissipated > 0.01 * sim.record.work
    assert sim.record.damping == pytest.approx(ribs * dissipated, rel=1e-9)
    assert sim.record.summary()['damping_dissipation'] == sim.record.damping


@pytest.mark.parametrize('base', BASES)
def test_the_energy_balance_closes_with_the_dissipation(base):
    """Asymmetric ribs (friction, a stuck hinge, a kick), damped, through the lock."""
    values = dict(ASYMMETRIC, time_step=0.0, damping_ratio=ZETA, **AT_SPEED, **BASES[base])
    assert_damped_run_balances(UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values)),
                               values, base)


def assert_damped_run_balances(sim: UmbrellaSimulator3D, values: dict, base: str) -> None:
    """
    Run sim through the lock (10 ms past it): its balance closes with the dissipation.

    The dissipation grows, is of the order of the work, the same run undamped dissipates
    nothing, and a free bus keeps its momentum (the damping is internal).
    """
    rec = sim.run(1.0, after_lock=0.01)
    s = rec.summary()
    tolerance = BALANCE_TOLERANCE if base != 'prescribed' else 1e-6   # (not scaled: kernel's)
    assert s['energy_balance_residual'] < tolerance * s['energy_scale']
    a = rec.arrays()
    # the dissipation is there, grows, and is of the order of the work (not a rounding)
    assert np.all(np.diff(a['damping_dissipation']) >= 0.0)
    assert s['damping_dissipation'] > 1e-3 * abs(a['work'][-1])
    # the same run undamped dissipates nothing and balances alike
    undamped = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        dict(values, damping_ratio=0.0))).run(1.0, after_lock=0.01).summary()
    assert undamped['damping_dissipation'] == 0.0
    if base == 'free':     # the damping is internal: the bus's momentum stays
        p = a['linear_momentum']
        assert np.max(np.abs(p - p[0])) < 1e-12 * momentum_scales(sim, a)[0]


@needs_kernel
@pytest.mark.parametrize('base', [pytest.param(base, marks=[pytest.mark.slow] if base != 'fixed'
                                               else []) for base in BASES])
def test_damped_compiled_steps_equal_numpy(base):
    """
    The damped step on both paths, within the numpy reference's ulp spread.

    150 deploying steps from t = 0, and 40 stage-2 grid steps (5 physics steps each, the
    damped fit) from one locked state.
    """
    values = dict(ASYMMETRIC, time_step=0.0, damping_ratio=ZETA, **AT_SPEED, **BASES[base])
    p = UmbrellaRibsParams.from_mapping(values)
    a, b, spread, model = advanced_with_spread(p, 150)
    assert a['damping_dissipation'][-1] > 0.0
    assert_rows_agree(a, b, spread, model)
    start = UmbrellaSimulator3D(p, kernel='compiled')
    start.run(1.0, after_lock=0.001)
    assert start.stage2_substeps > 1
    runs = [continued(start, kernel, ulp) for kernel, ulp in (
        ('compiled', False), ('numpy', False), ('numpy', True))]
    for sim in runs:
        sim.advance(40)
    a, b, spread = (sim.record.arrays() for sim in runs)
    assert a['damping_dissipation'][-1] > a['damping_dissipation'][1] > 0.0
    assert_rows_agree(a, b, spread, start.model)


def advanced_with_spread(p: UmbrellaRibsParams, steps: int):
    """
    Return the rows of steps grid steps compiled, numpy, and numpy from a velocity one ulp up.

    (a, b, spread: the compared runs and the reference's own round-off spread; the model.)
    """
    runs = [UmbrellaSimulator3D(p, kernel=k) for k in ('compiled', 'numpy', 'numpy')]
    s = runs[2].state
    runs[2].state = type(s)(s.t, s.qr, s.qs, np.nextafter(s.vr, np.inf), s.vs, s.lam_r,
                            s.lam_s, s.stuck)
    for sim in runs:
        sim.advance(steps)
    return (*(sim.record.arrays() for sim in runs), runs[0].model)


def first_locked_modes(sim: UmbrellaSimulator3D) -> tuple[float, int, int]:
    """
    Return omega_1 and rib 0's first in-plane and out-of-plane locked modes' indices.

    omega_1: the planar rib's first locked mode, whose 2 zeta / omega_1 is sim's beta.
    """
    m, p = sim.model, sim.params
    omega_1 = locked_first_frequency(planar_model(p.planar))
    assert sim.integrator.damping_beta == damping_beta(p) == pytest.approx(2 * ZETA / omega_1)
    phi = rib_locked_modes(m)[0][1]
    tip_v, tip_w = (np.abs(phi[i, :6]) for i in m.i_tip[1:])
    return omega_1, int(np.argmax(tip_v > tip_w)), int(np.argmax(tip_w > tip_v))


def decay_ratio(sim: UmbrellaSimulator3D, mode: int, periods: int = 6,
                amplitude: float = 1e-3) -> tuple[float, float]:
    """
    Return (omega, the measured damping ratio) of rib 0's locked mode started alone.

    Every rib at full deployment, locked, moving in the mode (a small amplitude: by default
    1e-3 of its modal coordinate's unit); the mode's coordinate u . (q - q_deployed) (u = M0 phi)
    stepped for periods periods; the ratio from the logarithmic decrement of its peaks
    (each the parabola through the sample at a maximum and its two neighbours):
    delta = ln(x_0 / x_k) / k, zeta = delta / sqrt(4 pi^2 + delta^2).
    """
    m, integ = sim.model, sim.integrator
    omega, phi, mass = rib_locked_modes(m)[0]
    vr = np.repeat((amplitude * omega[mode] * phi[:, mode])[None], m.n_ribs, 0)
    s = locked_state(integ, vr, np.zeros(m.n_shared))
    integ.lock_at(s)
    u, q_deployed = mass @ phi[:, mode], deployed_configuration(m)[0][0]
    eta = []
    for _ in range(int(periods * 2 * np.pi / omega[mode] / sim.h)):
        s, _ = integ.step(s, sim.h, 0.0, True)
        eta.append(u @ (s.qr[0] - q_deployed))
    eta = np.array(eta)
    i = np.nonzero((eta[1:-1] > eta[:-2]) & (eta[1:-1] >= eta[2:]))[0] + 1
    a, b, c = eta[i - 1], eta[i], eta[i + 1]
    peaks = b - 0.125 * (c - a) ** 2 / (a - 2 * b + c)
    assert len(peaks) >= periods - 1
    delta = np.log(peaks[0] / peaks[-1]) / (len(peaks) - 1)
    return float(omega[mode]), float(delta / np.sqrt(4 * np.pi ** 2 + delta ** 2))


@needs_kernel
@pytest.mark.parametrize('fit', [True, False], ids=['fitted', 'unfitted'])
def test_the_locked_modes_decay_as_rayleigh_damping_says(fit):
    """
    Rib 0's first in-plane mode decays with ratio zeta, its out-of-plane one with less.

    Its first out-of-plane mode, lower (70.6 against 133.7 rad/s), with zeta omega /
    omega_1 (0.0264), both to 1e-6: fitted exactly (the fit makes each mode's decay a step
    exact), unfitted scaled by the midpoint rule's sin(Omega h) / (Omega h), Omega h =
    2 arctan(omega h / 2) its turn a step (to first order in zeta: 3e-5 at 133.7 rad/s and
    0.1 ms).
    """
    p = UmbrellaRibsParams.from_mapping({'ribs': 3, 'damping_ratio': ZETA, 'time_step': 1e-4,
                                         'phase_correction': fit})
    sim = UmbrellaSimulator3D(p, kernel='compiled')
    omega_1, in_plane, out_of_plane = first_locked_modes(sim)

    def scheme_ratio(omega, ratio):
        """Return the damping ratio the step gives a mode of the law's ratio."""
        if fit:
            return ratio
        turn = 2.0 * np.arctan(0.5 * omega * sim.h)
        return ratio * np.sin(turn) / turn

    omega, zeta = decay_ratio(sim, in_plane)
    assert omega == pytest.approx(omega_1, rel=1e-9)      # the planar rib's first mode
    assert zeta == pytest.approx(scheme_ratio(omega, ZETA), rel=1e-6)
    omega, zeta = decay_ratio(sim, out_of_plane)
    assert omega < 0.6 * omega_1
    assert zeta == pytest.approx(scheme_ratio(omega, ZETA * omega / omega_1), rel=1e-6)
