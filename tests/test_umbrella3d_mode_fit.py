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
The 3D umbrella's stage-2 mode fit (integrator3d: each rib's integrators.LockedModeFit).

With the hub fixed and the sleeve at the stop the ribs are decoupled: each rib's locked
modes (modes3d.rib_locked_modes) are the whole locked umbrella's, and the fit makes each
resolved mode exact as the planar fit does: a mode integrated alone turns at the
eigenproblem's frequency with its amplitude (Prony's method on its modal coordinate,
step_study.mode_flow_of), T + V conserved to round-off, on either path.  The planar
identity with the fit is test_umbrella3d.py's.
"""
import math

import numpy as np
import pytest

from umbrella_sim.core.integrators import newton_tolerance
from umbrella_sim.core.kernel import load_kernel
from umbrella_sim.core.step_study import mode_flow_of
from umbrella_sim.core.umbrella3d.integrator3d import MidpointUmbrella
from umbrella_sim.core.umbrella3d.model3d import UmbrellaModel3D
from umbrella_sim.core.umbrella3d.modes3d import (deployed_configuration, locked_modes,
                                                  rib_locked_modes)
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.core.umbrella3d.state3d import State3D

H = 1e-4
#: two ribs, one unlike the other (a longer leaf tip, a tip mass): rib 1's modes are its own
VALUES = {'ribs': 2, 'time_step': H, 'rib1.l2': 0.6, 'rib1.tip_mass': 0.02}
KERNELS = ['numpy', pytest.param('compiled', marks=pytest.mark.skipif(
    load_kernel() is None, reason='the compiled kernel is not built'))]


def test_the_ribs_locked_modes_are_the_whole_umbrellas():
    """Rib by rib, the locked umbrella's frequencies (the sleeve at the stop decouples them)."""
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(VALUES))
    whole = locked_modes(m)[0]
    ribs = np.sort(np.concatenate([omega for omega, _, _ in rib_locked_modes(m)]))
    np.testing.assert_allclose(ribs, whole, rtol=1e-9)
    for omega, phi, mass in rib_locked_modes(m):
        np.testing.assert_allclose(phi.T @ mass @ phi, np.eye(len(omega)), atol=1e-9)


def mode_flow(kernel: str, rib: int, k: int, fitted: bool, periods: float):
    """Return the ModeFlow of rib's locked mode k started alone (step_study.locked_mode_flow)."""
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(VALUES))
    integ = MidpointUmbrella(m, newton_tolerance(H), kernel=kernel)
    assert integ.backend == kernel
    if fitted:
        integ.fit_stage2_modes(H)
        integ.lock_at()
    omega, phi, mass = rib_locked_modes(m)[rib]
    qr0, qs = deployed_configuration(m)
    started = 1e-7
    vr = np.zeros_like(qr0)
    vr[rib] = started * omega[k] * phi[:, k]
    s = integ.consistent(State3D(0.0, qr0, qs, vr, np.zeros(m.n_shared), np.zeros((m.n_ribs, 9)),
                                 np.zeros(m.n_shared_rows), np.full(m.n_ribs, np.nan)),
                         0.0, True)

    def energy(s):
        return m.kinetic_energy(m.kinematics(s.qr, s.qs), s.vr, s.vs) + m.strain_energy(s.qr)

    e0 = energy(s)
    eta = [0.0]
    for _ in range(round(periods * 2 * math.pi / omega[k] / H)):
        s, _ = integ.step(s, H, 0.0, True)
        eta.append(phi[:, k] @ mass @ (s.qr[rib] - qr0[rib]))
    return mode_flow_of(np.array(eta), H, float(omega[k]), started, (energy(s) - e0) / e0)


@pytest.mark.parametrize('kernel', KERNELS)
@pytest.mark.parametrize('rib, k', [(0, 2), (1, 3), (0, 6), (1, 9)])
def test_the_fit_gives_each_ribs_resolved_mode_its_exact_period_and_amplitude(kernel, rib, k):
    """
    Out-of-plane and in-plane modes of either rib, omega h 0.03 to 0.3 (h = 0.1 ms).

    Without the fit the period is the midpoint rule's, tan(Omega h / 2) = omega h / 2; with
    it the eigenproblem's, and the amplitude the one started; T + V conserved either way.
    """
    periods = 20.5 if kernel == 'compiled' else 4.5
    plain = mode_flow(kernel, rib, k, False, periods)
    omega_h = plain.omega * H
    assert plain.frequency_error == pytest.approx(2 * math.atan(0.5 * omega_h) / omega_h - 1,
                                                  rel=1e-2)
    fitted = mode_flow(kernel, rib, k, True, periods)
    assert abs(fitted.frequency_error) < 1e-7
    assert fitted.amplitude == pytest.approx(1.0, abs=1e-6)
    assert max(abs(fitted.energy_change), abs(plain.energy_change)) < 1e-11


@pytest.mark.skipif(load_kernel() is None, reason='the compiled kernel is not built')
def test_an_asymmetric_stage2_with_the_fit_conserves_energy_and_holds_the_joints():
    """A kicked rib, a tip mass: through the lock, then 30 ms locked with F = 0 on the ribs."""
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': 3, 'rib1.out_of_plane_rate': 0.3, 'rib2.tip_mass': 0.02, 'lock': 'plastic'}))
    assert sim.mode_fit and sim.h == 2e-4      # (stage 1's; stage 2 its substeps)
    sim.run(1.0, after_lock=0.03)
    assert sim.locked and sim.integrator.fit_active
    a = sim.record.arrays()
    locked = a['locked']
    energy = (a['kinetic_energy'] + a['strain_energy'])[locked][1:]
    assert np.ptp(energy) < 1e-12 * energy[0]
    m, s = sim.model, sim.state
    phi_r, phi_s = m.constraints(s.qr, s.qs, s.stuck, True)
    assert max(np.max(np.abs(phi_r)), np.max(np.abs(phi_s))) < 1e-11
    assert np.max(np.abs(a['tip'][locked][:, 1, 2])) > 1e-4      # out of its plane
