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
Stage 2's mode fit on a moving base (umbrella3d/stage2fit.py), on both paths.

A free-floating bus: the fit is of the whole free system's elastic modes
(modes3d.free_locked_modes: bus + locked ribs, the rigid-body modes left out).  A free mode
started alone turns at the eigenproblem's frequency with the amplitude started (Prony's
method on its modal coordinate, step_study.mode_flow_of), where the plain midpoint rule's
period is longer by the Cayley map's tan(Omega h / 2) = omega h / 2; T + V conserved to
round-off; the modes carry no momentum, and the free system's linear momentum is kept to
round-off (a cyclic coordinate whose scheme momentum is the physical one), its angular
momentum to the Newton tolerance (the discrete gradient's, as without the fit:
tests/test_umbrella3d.py).  The modes are those of the whole system: with a light bus
(5 kg against 6 ribs of 0.9 kg) the modes that move the bus are 5 to 25 % stiffer than
a rib's on a fixed hub, which a fit of the ribs' own modes would leave off.  The step takes
that fit as the ribs' own fits with low-rank corrections (stage2fit.BusFit): its maps are the
whole fit's (WholeFit), and a run from one lock with either is the same to the Newton
tolerance.

A driven hub: the ribs' locked modes in the hub's frame, as the fixed hub's; with a drive
that is zero, the run is the fixed hub's, through the lock and stage 2 (to the Newton
tolerance: the bus's coordinates are unknowns of the driven step, held at 0 by its joints).

The compiled step (_kernel3d_base.h base_fit_map) equals the numpy reference's fitted
locked steps as test_umbrella3d_kernel.py asserts for the others (1e-10 relative).
"""
from dataclasses import replace
import math

import numpy as np
import pytest

from umbrella_sim.core.integrators import newton_tolerance
from umbrella_sim.core.kernel import load_kernel
from umbrella_sim.core.step_study import mode_flow_of
from umbrella_sim.core.umbrella3d.integrator3d import MidpointUmbrella
from umbrella_sim.core.umbrella3d.model3d import UmbrellaModel3D
from umbrella_sim.core.umbrella3d.modes3d import (deployed_configuration, free_locked_modes,
                                                  rib_locked_modes)
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.core.umbrella3d.stage2fit import (_low_rank, BUS_TOLERANCE, BusFit, RANGE_START,
                                                    stage2_fit, whole_fit)
from umbrella_sim.core.umbrella3d.state3d import State3D

H = 1e-4
#: three ribs, one unlike the others, on a light free bus (the bus's share of the modes large)
FREE = {'ribs': 3, 'time_step': H, 'rib1.l2': 0.6, 'rib1.tip_mass': 0.02, 'base': 'free',
        'bus_mass': 5.0, 'bus_inertia': 0.2}
#: the same on a driven hub: a jolt in X-Z and a spin-up about Y
DRIVEN = {'ribs': 3, 'time_step': H, 'rib1.l2': 0.6, 'rib1.tip_mass': 0.02,
          'base': 'prescribed', 'base_accel_x': 20.0, 'base_accel_z': -10.0,
          'base_accel_start': 0.0, 'base_accel_duration': 0.01, 'base_spin_rate': 3.0,
          'base_spin_ramp': 0.01}
KERNELS = ['numpy', pytest.param('compiled', marks=pytest.mark.skipif(
    load_kernel() is None, reason='the compiled kernel is not built'))]
needs_kernel = pytest.mark.skipif(load_kernel() is None, reason='the compiled kernel is not built')


def locked_state(integ: MidpointUmbrella, vr, vs, t: float = 0.0) -> State3D:
    """Return the deployed, locked state with velocities (vr, vs), consistent."""
    m = integ.model
    qr, qs = deployed_configuration(m)
    if integ.drive is not None:
        qs[1:7], vs = integ.drive(t)[0], np.concatenate([[0.0], integ.drive(t)[1]])
    return integ.consistent(State3D(t, qr, qs, vr, vs, np.zeros((m.n_ribs, 9)),
                                    np.zeros(m.n_shared_rows), np.full(m.n_ribs, np.nan)),
                            0.0, True)


def energy(m, s) -> float:
    return m.kinetic_energy(m.kinematics(s.qr, s.qs), s.vr, s.vs) + m.strain_energy(s.qr)


def free_mode_flow(kernel: str, k: int, fitted: bool, periods: float):
    """Return the ModeFlow of the free system's mode k started alone, and the momenta."""
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(FREE))
    integ = MidpointUmbrella(m, 1e-12, kernel=kernel)
    assert integ.backend == kernel
    if fitted:
        integ.fit_stage2_modes(H)
        integ.lock_at()
        assert integ.mode_fit.whole
    omega, phi, mass = free_locked_modes(m)
    nr, n = m.n_ribs, m.n_rib
    started = 1e-7
    v = started * omega[k] * phi[:, k]
    s = locked_state(integ, v[:nr * n].reshape(nr, n), v[nr * n:])
    e0 = energy(m, s)
    q0 = np.concatenate([s.qr.ravel(), s.qs])
    eta, momenta = [0.0], [m.momentum(m.kinematics(s.qr, s.qs), s.vr, s.vs)]
    for _ in range(round(periods * 2 * math.pi / omega[k] / H)):
        s, _ = integ.step(s, H, 0.0, True)
        eta.append(phi[:, k] @ mass @ (np.concatenate([s.qr.ravel(), s.qs]) - q0))
        momenta.append(m.momentum(m.kinematics(s.qr, s.qs), s.vr, s.vs))
    flow = mode_flow_of(np.array(eta), H, float(omega[k]), started, (energy(m, s) - e0) / e0)
    return flow, np.array(momenta), m, s


def test_the_free_systems_modes_carry_no_momentum_and_couple_the_bus():
    """The elastic modes: M-orthonormal, no momentum on the bus's rows, stiffer than a rib's."""
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(FREE))
    omega, phi, mass = free_locked_modes(m)
    np.testing.assert_allclose(phi.T @ mass @ phi, np.eye(len(omega)), atol=1e-9)
    nr, n = m.n_ribs, m.n_rib
    assert np.max(np.abs((mass @ phi)[nr * n + 1:])) < 1e-12 * np.max(np.abs(mass @ phi))
    # 6 rigid-body modes fewer than the coordinates the locked joints and the stop leave
    fixed = np.concatenate([w for w, _, _ in rib_locked_modes(m)])
    assert len(omega) == len(fixed) and omega[0] > 10.0
    # the lowest modes that move the bus are stiffer than any rib's on a fixed hub near them
    bus = np.max(np.abs(phi[nr * n + 1:]), axis=0) > 1e-3 * np.max(np.abs(phi), axis=0)
    lowest = omega[bus][0]
    assert np.min(np.abs(fixed - lowest)) > 0.02 * lowest


#: free modes (FREE): omega h 0.010 (the bus's largest share, 0.29 of the largest
#: coordinate), 0.015, 0.16, 0.52, 1.08 (h = 0.1 ms); the numpy reference (~5 ms a step)
#: the two of fewest steps
FREE_MODES = [('compiled', 3), ('compiled', 5), ('compiled', 20), ('compiled', 35),
              ('compiled', 41), ('numpy', 20), ('numpy', 41)]


@pytest.mark.parametrize('values', [
    {'ribs': 6}, {'ribs': 6, 'bus_mass': 5.0, 'bus_inertia': 0.2},
    {'ribs': 6, 'elements_per_segment': 2}], ids=['6x1', '6x1-light-bus', '6x2'])
def test_a_free_bus_runs_at_the_fixed_hubs_step_with_the_same_modes_resolved(values):
    """
    The step follows the fit (UmbrellaSimulator3D.fits_modes): the free system resolves there.

    At the planar rule's fitted step (0.1 ms at 1 element, 33 us at 2) the free system's
    modes past the fit's limit (omega h > 1.5) are as many as the ribs' on a fixed hub (the
    links' and leaves' axial modes, which barely move the bus), so the modes that carry the
    stage-2 stresses, which the rule judges on a rib, are resolved on a free bus too.
    """
    p = UmbrellaRibsParams.from_mapping(dict(values, base='free'))
    h = UmbrellaSimulator3D.grid_step(p)
    hub = {k: v for k, v in values.items() if not k.startswith('bus_')}  # (no bus: refused)
    assert h == UmbrellaSimulator3D.grid_step(UmbrellaRibsParams.from_mapping(hub))
    m = UmbrellaModel3D(p)
    free = free_locked_modes(m)[0]
    fixed = np.concatenate([omega for omega, _, _ in rib_locked_modes(m)])
    assert np.count_nonzero(free * h > 1.5) == np.count_nonzero(fixed * h > 1.5) > 0
    assert len(free) == len(fixed)


@pytest.mark.parametrize('kernel, k', [
    (kernel, k) if kernel == 'numpy' else pytest.param(
        kernel, k, marks=KERNELS[1].marks + ((pytest.mark.slow,) if k == 3 else ()))
    for kernel, k in FREE_MODES])
def test_the_fit_gives_each_free_mode_its_exact_period_and_amplitude(kernel, k):
    """
    Free modes that move the bus, omega h 0.01 to 1.08 (h = 0.1 ms).

    Plain: the midpoint rule's period; fitted: the eigenproblem's, the amplitude started;
    T + V conserved either way, the linear momentum to round-off, the angular momentum to
    the Newton tolerance (1e-12 here: 1e-7 of the motion's own m v L measured, 1e-6
    asserted, with or without the fit).
    """
    periods = 10.5 if kernel == 'compiled' and k > 5 else 2.5
    plain, _, _, _ = free_mode_flow(kernel, k, False, periods)
    omega_h = plain.omega * H
    assert plain.frequency_error == pytest.approx(2 * math.atan(0.5 * omega_h) / omega_h - 1,
                                                  rel=2e-2)
    fitted, momenta, m, s = free_mode_flow(kernel, k, True, periods)
    assert abs(fitted.frequency_error) < 1e-7
    assert fitted.amplitude == pytest.approx(1.0, abs=1e-6)
    assert max(abs(fitted.energy_change), abs(plain.energy_change)) < 1e-9
    # momentum: 0 at the start (the mode carries none); the scale m v of the ribs' motion
    speed = float(np.max(np.abs(s.vr)))
    rib_mass = m.total_mass - m.bus_mass - m.sleeve_mass
    linear = [p for p, _ in momenta]
    angular = [h for _, h in momenta]
    assert np.max(np.abs(linear)) < 1e-12 * rib_mass * speed
    assert np.max(np.abs(angular)) < 1e-6 * rib_mass * speed * float(np.max(m.l1))
    # the bus moves with the mode (it is the free system's)
    assert np.max(np.abs(s.vs[1:])) > 1e-3 * speed


@pytest.mark.parametrize('beta', [0.0, 1e-5], ids=['undamped', 'damped'])
def test_the_free_fit_turned_to_an_attitude_is_the_fit_at_that_attitude(beta):
    """BusFit.at_attitude (the lock's, in the run) against the eigenproblem solved there."""
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(FREE))
    attitude = np.array([0.7, 0.2, -0.3])
    turned = stage2_fit(m, H, beta).at_attitude(attitude)
    solved = stage2_fit(m, H, beta, attitude=attitude)
    rng = np.random.default_rng(1)
    vr, vs = rng.standard_normal((m.n_ribs, m.n_rib)), rng.standard_normal(m.n_shared)
    for name in ('to_scheme', 'to_physical', 'transpose'):
        for x, y in zip(getattr(turned, name)(vr, vs), getattr(solved, name)(vr, vs)):
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-9, err_msg=name)
    for x, y in zip(turned.newton_update(vr, vs, H), solved.newton_update(vr, vs, H)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)
    if beta:        # (the damping share, of the order of 1 / h: 1e-9 of its largest)
        pairs = list(zip(turned.damping_force(vr, vs, H), solved.damping_force(vr, vs, H)))
        scale = max(np.max(np.abs(y)) for _, y in pairs)
        for x, y in pairs:
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize('values', [
    dict(FREE, time_step=0.0),
    {'ribs': 12, 'base': 'free', 'tip_mass': [0.005 * k for k in range(12)]}],
    ids=['3-light-bus', '12-each-its-tip-mass'])
def test_the_free_bus_fit_is_the_whole_fit_through_a_low_rank_correction(values):
    """
    The free bus's fit (BusFit: the ribs' fits, the bus's corrections) maps as WholeFit.

    Each map (S^-1, S, S^T, the Newton update, the damping share) of a random vector within
    1e-9 of the largest entry (measured 1e-11: the corrections' singular values are cut at
    BUS_TOLERANCE = 1e-10); each correction's rank (the directions the bus takes part in)
    stays under 40 (measured 18 to 34 at 3 to 24 ribs, identical or each with its own tip
    mass) where the whole fit has 14 modes a rib (168 at 12 ribs); S^T leaves the bus's
    momenta as they are, exactly.
    """
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(values))
    beta = 1e-5
    bus, whole = stage2_fit(m, H, beta), whole_fit(m, H, beta)
    assert isinstance(bus, BusFit) and len(whole.fit.scale) >= 14 * m.n_ribs
    assert max(len(bus.bus.a), len(bus.newton.a), len(bus.damping.a)) < 40
    rng = np.random.default_rng(3)
    vr, vs = rng.standard_normal((m.n_ribs, m.n_rib)), rng.standard_normal(m.n_shared)
    for name, args in (('to_scheme', ()), ('to_physical', ()), ('transpose', ()),
                       ('newton_update', (H,)), ('damping_force', (H,))):
        x, y = getattr(bus, name)(vr, vs, *args), getattr(whole, name)(vr, vs, *args)
        scale = max(np.max(np.abs(y[0])), np.max(np.abs(y[1])))
        for a, b in zip(x, y):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * scale, err_msg=name)
    np.testing.assert_array_equal(bus.transpose(vr, vs)[1][1:], vs[1:])


@needs_kernel
@pytest.mark.parametrize('values', [
    {'ribs': 6, 'rib1.tip_mass': 0.02, 'rib2.out_of_plane_rate': 0.2},
    {'ribs': 3, 'rib1.tip_mass': 0.02, 'rib2.out_of_plane_rate': 0.2, 'bus_mass': 5.0,
     'bus_inertia': 0.2}], ids=['6-default-bus', '3-light-bus'])
def test_stage2_with_the_bus_fit_is_the_run_with_the_whole_fit(values):
    """
    From one plastic lock at V0 = -0.5, 1000 steps (0.1 s) compiled with each fit.

    The same steps (Newton iterations) and figures to the Newton tolerance: tips within
    1e-9 m (measured 1e-12 m over 0.3 s, of 130 to 210 mm amplitude), the bus's rates
    within 1e-7 rad/s (measured 2e-8 at 5 kg, where they reach 6 rad/s).
    """
    p = UmbrellaRibsParams.from_mapping(dict(values, base='free', v0=-0.5, lock='plastic'))
    sim = UmbrellaSimulator3D(p, kernel='compiled')
    sim.run(1.0, after_lock=0.0)
    start = replace(sim.lock_state[0], t=0.0)
    runs = []
    for fit in (stage2_fit(sim.model, sim.h), whole_fit(sim.model, sim.h)):
        integ = MidpointUmbrella(sim.model, newton_tolerance(sim.h), kernel='compiled')
        integ.mode_fit = fit
        integ.lock_at(start)
        status, done, rows, _ = integ.compiled.advance(start, 0, sim.h, 1000, 0.0, True)
        assert status == 0 and done == 1000
        runs.append({k: np.array(v) for k, v in rows.items()})
    a, b = runs
    np.testing.assert_array_equal(a['iterations'], b['iterations'])
    np.testing.assert_allclose(a['qr'], b['qr'], rtol=0, atol=1e-9)
    np.testing.assert_allclose(a['vs'][:, 4:], b['vs'][:, 4:], rtol=0, atol=1e-7)
    assert np.max(np.abs(b['qr'][:, :, sim.model.i_tip[1]])) > 0.05


def test_a_driven_hubs_fit_is_each_ribs_in_the_hubs_frame():
    """The driven hub's fit: the fixed hub's modes rib by rib; the bus's rows untouched."""
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(DRIVEN))
    integ = MidpointUmbrella(m, newton_tolerance(H), kernel='numpy')
    integ.fit_stage2_modes(H)
    fit = integ.mode_fit
    assert not fit.whole
    for f, (omega, _, _) in zip(fit.fits, rib_locked_modes(m)):
        np.testing.assert_array_equal(f.omega, omega[omega * H <= 1.5])
    vr, vs = np.ones((m.n_ribs, m.n_rib)), np.arange(7.0)
    wr, ws = fit.to_scheme(vr, vs)
    assert ws is vs and not np.allclose(wr, vr)


@pytest.mark.parametrize('kernel', KERNELS)
def test_a_driven_hubs_rib_mode_is_exact_with_the_drive_zero(kernel):
    """A rib's locked mode on a driven hub that does not move: exact, as on a fixed hub."""
    values = dict(DRIVEN, base_accel_x=0.0, base_accel_z=0.0, base_spin_rate=0.0)
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(values))
    integ = MidpointUmbrella(m, newton_tolerance(H), kernel=kernel)
    integ.fit_stage2_modes(H)
    integ.lock_at()
    omega, phi, mass = rib_locked_modes(m)[1]
    k = 6
    started = 1e-7
    vr = np.zeros((m.n_ribs, m.n_rib))
    vr[1] = started * omega[k] * phi[:, k]
    s = locked_state(integ, vr, np.zeros(m.n_shared))
    qr0, e0 = s.qr.copy(), energy(m, s)
    eta = [0.0]
    for _ in range(round((10.5 if kernel == 'compiled' else 3.5) * 2 * math.pi / omega[k] / H)):
        s, _ = integ.step(s, H, 0.0, True)
        eta.append(phi[:, k] @ mass @ (s.qr[1] - qr0[1]))
    flow = mode_flow_of(np.array(eta), H, float(omega[k]), started, (energy(m, s) - e0) / e0)
    assert abs(flow.frequency_error) < 1e-7
    assert flow.amplitude == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize('kernel', [KERNELS[1]])
def test_identical_ribs_on_a_driven_hub_with_zero_drive_are_the_fixed_hub(kernel):
    """
    Through the lock and 20 ms of fitted stage 2: the same figures, to the steps' difference.

    On the compiled path; the numpy path's steps are the compiled ones' to round-off on both
    bases (test_the_compiled_fitted_steps_equal_the_numpy_references, and
    tests/test_umbrella3d_kernel.py through the lock), so its figures are these too.

    The two steps are not the same arithmetic: the driven step's bus coordinates are
    unknowns (held at 0 by the drive's joints), its velocity is projected onto the drive's
    rates and not scaled to the energy balance, and its kinetic energy's discrete gradient
    takes the sleeve's coordinate in its correction.  Both are the midpoint scheme to the
    Newton tolerance (1e-12 here): measured 1e-9 rad apart before the lock, the tips 1.5e-8 m
    after it (the impact amplifies the state at the lock), with or without the fit; the fit
    itself moves the tips by 2.6 mm over these 20 ms (0.12 m amplitude).  Asserted: 1e-8
    rad and m before and at the lock, 1e-7 m on the tips after.
    """
    common = {'ribs': 3, 'v0': -0.5, 'lock': 'plastic'}
    fixed = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(common), kernel=kernel,
                                tolerance=1e-12)
    driven = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(dict(
        common, base='prescribed', base_accel_x=0.0, base_spin_rate=0.0)), kernel=kernel,
        tolerance=1e-12)
    assert fixed.mode_fit and driven.mode_fit and fixed.h == driven.h == 2 * H   # stage 1's
    a = fixed.run(1.0, after_lock=0.02).arrays()
    b = driven.run(1.0, after_lock=0.02).arrays()
    assert driven.integrator.fit_active and fixed.lock_time == pytest.approx(
        driven.lock_time, abs=1e-10)
    assert len(a['time']) == len(b['time']) and np.count_nonzero(a['locked']) > 75  # 20 ms
    for name, tolerance in (('alpha1', 1e-8), ('alpha2', 1e-8), ('sleeve_position', 1e-8),
                            ('tip', 1e-7)):
        np.testing.assert_allclose(b[name], a[name], rtol=0, atol=tolerance, err_msg=name)
    assert np.max(np.abs(b['bus_q'])) < 1e-15          # (held by the drive's joints)


def excited_state(integ: MidpointUmbrella, t: float = 0.0) -> State3D:
    """Return a locked state with every rib's modes and (free) the bus's rates excited."""
    m = integ.model
    rng = np.random.default_rng(7)
    if m.params.base == 'free':
        omega, phi, _ = free_locked_modes(m)
        v = phi[:, :12] @ (1e-3 * omega[:12] * rng.standard_normal(12))
        nr, n = m.n_ribs, m.n_rib
        vr, vs = v[:nr * n].reshape(nr, n), v[nr * n:]
        vs[1:] += 1e-2 * rng.standard_normal(6)        # a rigid drift and spin besides
    else:
        vr = np.array([phi[:, :8] @ (1e-3 * omega[:8] * rng.standard_normal(8))
                       for omega, phi, _ in rib_locked_modes(m)])
        vs = np.zeros(m.n_shared)
    s = locked_state(integ, vr, vs, t)
    kin = m.kinematics(s.qr, s.qs)
    vr, vs = integ.project(kin, m.mass_matrix(kin), s.qr, s.vr, s.vs, s.stuck, True,
                           None if integ.drive is None else integ.drive(t)[1])
    return integ.consistent(State3D(t, s.qr, s.qs, vr, vs, s.lam_r, s.lam_s, s.stuck), 0.0,
                            True)


@needs_kernel
@pytest.mark.parametrize('fit_step', [H, H / 2], ids=['fit_of_the_step', 'fit_of_half_the_step'])
@pytest.mark.parametrize('values', [FREE, DRIVEN], ids=['free', 'driven'])
def test_the_compiled_fitted_steps_equal_the_numpy_references(values, fit_step):
    """
    40 fitted locked steps from one state, each path (the driven hub in its jolt).

    As test_umbrella3d_kernel.py's assert_states_agree: 1e-10 relative, or 10 times the
    reference's own spread from its start moved by one ulp (the multipliers, dq / (h^2 / 2),
    carry the positions' round-off times 2e8).  With the fit made for the step taken, and
    for half of it (a stage-2 fit of substeps at the grid's step; the lock's part steps):
    the Newton shrinks are the step's on both paths (LockedModeFit.newton_shrink(h)), so
    the iterations are the same.
    """
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(values))
    steps = {}
    for kernel, ulp in (('compiled', False), ('numpy', False), ('numpy', True)):
        integ = MidpointUmbrella(m, newton_tolerance(fit_step), kernel=kernel)
        integ.fit_stage2_modes(fit_step)
        integ.lock_at()
        s = excited_state(integ, 0.002)
        if ulp:
            s = replace(s, vr=np.nextafter(s.vr, np.inf), pr=None, ps=None)
        works = []
        for _ in range(40):
            s, w = integ.step(s, H, 0.0, True)
            works.append((w.iterations, w.factorisations))
        steps[kernel, ulp] = s, works
    (s_c, w_c), (s_n, w_n) = steps['compiled', False], steps['numpy', False]
    s_u = steps['numpy', True][0]
    assert w_c == w_n
    for name in ('qr', 'qs', 'vr', 'vs', 'lam_r', 'lam_s', 'pr', 'ps'):
        x, y, z = getattr(s_c, name), getattr(s_n, name), getattr(s_u, name)
        bound = max(1e-10 * max(np.max(np.abs(y)), 1e-300), 10.0 * np.max(np.abs(z - y)))
        assert np.max(np.abs(x - y)) <= bound, name


#: DRIVEN's ribs on a fixed hub
FIXED = {k: v for k, v in DRIVEN.items() if not k.startswith('base')}


def mean_iterations(values: dict, kernel: str, fit_step: float, steps: int = 200,
                    corrections: bool = False) -> float:
    """
    Return the Newton iterations a locked step of H takes, the fit made for fit_step.

    corrections: with the corrections of the joints alone a fixed hub's step takes where a
    moving base's takes a whole iteration (integrators.newton_converged; the numpy step's
    count: the compiled step takes the same iterates).
    """
    m = UmbrellaModel3D(UmbrellaRibsParams.from_mapping(values))
    integ = MidpointUmbrella(m, newton_tolerance(fit_step), kernel=kernel)
    integ.fit_stage2_modes(fit_step)
    integ.lock_at()
    s = excited_state(integ, 0.002)
    for _ in range(steps):
        s, _ = integ.step(s, H, 0.0, True)
    return (integ.iterations + corrections * integ.joint_corrections) / steps


@pytest.mark.parametrize('kernel', KERNELS)
@pytest.mark.parametrize('values', [FREE, DRIVEN], ids=['free', 'driven'])
def test_a_moving_bases_fitted_stage2_converges_as_the_fixed_hubs(values, kernel):
    """
    A moving base's fitted locked steps take the fixed hub's Newton iterations (+ 0.5).

    200 steps of H from an excited locked state (the driven hub in its jolt), the fit made
    for H and for H / 2 (a stage-2 fit of substeps stepped at the grid's step, as a caller
    may, and as the lock's part steps are), against the fixed hub's with its fit made for H.
    Each mode's Newton shrink is the step's (LockedModeFit.newton_shrink(h)); the compiled
    step's were the fit's own step's, which took a driven hub 3.75 iterations a step here
    against the fixed hub's 2.90 (and 4.7 to 4.9 at 12 ribs x 2 elements).  The fixed hub's
    count takes its corrections of the joints alone as iterations (a moving base's step
    takes a whole iteration there).
    """
    fixed = mean_iterations(FIXED, 'numpy', H, corrections=True)
    for fit_step in (H, H / 2):
        assert mean_iterations(values, kernel, fit_step) <= fixed + 0.5, fit_step


def tip_series_error(values: dict, reference) -> tuple[float, float]:
    """Return (the run's largest tip error after the lock against reference, its amplitude)."""
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values))
    sim.run(1.0, after_lock=0.1)
    a = sim.record.arrays()
    lock_ref, t_ref, tip_ref = reference
    keep = a['time'] > sim.lock_time + 1e-9
    err = max(np.max(np.abs(a['tip'][keep, k, c] - np.interp(
        a['time'][keep] - sim.lock_time, t_ref - lock_ref, tip_ref[:, k, c])))
        for k in range(sim.model.n_ribs) for c in (1, 2))
    return err, float(np.max(np.abs(tip_ref[:, :, 1:])))


@pytest.mark.slow      # ~5 s each: the reference takes 76 000 steps
@needs_kernel
@pytest.mark.parametrize('base', [
    {'base': 'free', 'bus_mass': 5.0, 'bus_inertia': 0.2},
    {'base': 'prescribed', 'base_spin_rate': 3.0, 'base_spin_ramp': 0.05, 'base_accel_x': 20.0,
     'base_accel_duration': 0.02}], ids=['free', 'driven'])
def test_the_fitted_stage2_at_the_fixed_hubs_step_is_nearer_the_converged_run(base):
    """
    0.1 s past a plastic lock at V0 = -0.5 (a tip mass, a kicked rib), against 2.5 us.

    The tips (in and out of plane) at the fitted 0.1 ms step against the same code converged
    (2.5 us, no fit; times from each run's lock): measured 1.27 mm (free) and 1.17 mm (driven)
    of 195 / 140 mm amplitude, where the plain rule's 33 us step the bases took before gave
    4.07 / 2.46 mm and 0.1 ms without the fit 7.4 / 5.2 mm (the hub fixed: 0.96, 2.38, 5.22).
    Asserted: within 1 % of the amplitude, and nearer than the plain 33 us step (each
    stage-2 step given, both stages on it).  At time_step 0 stage 2 takes the substeps this
    lock needs
    (past the modes' coupling: substeps3d.py), nearer still: 0.93 / 0.89 mm.
    """
    values = {'ribs': 3, 'v0': -0.5, 'lock': 'plastic', 'rib1.tip_mass': 0.02,
              'rib2.out_of_plane_rate': 0.2, **base}
    ref = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        dict(values, phase_correction=False, time_step=2.5e-6)))
    ref.run(1.0, after_lock=0.1)
    reference = (ref.lock_time, ref.record.arrays()['time'], ref.record.arrays()['tip'])

    def on_its_stage2_step(v):
        return dict(v, time_step=UmbrellaSimulator3D.stage2_step(
            UmbrellaRibsParams.from_mapping(v)))

    fitted, amplitude = tip_series_error(on_its_stage2_step(values), reference)
    plain, _ = tip_series_error(on_its_stage2_step(dict(values, phase_correction=False)),
                                reference)
    assert fitted < 0.01 * amplitude and fitted < plain
    substeps, _ = tip_series_error(values, reference)
    assert substeps < fitted


@pytest.mark.parametrize('rank', [3, RANGE_START - 4, RANGE_START + 10, 200])
def test_a_corrections_low_rank_form_keeps_the_full_svds_directions(rank):
    """
    _low_rank's randomised range against the full SVD, on maps of known rank (size 300).

    Singular values 1e-9 to 1 (all above BUS_TOLERANCE) and round-off noise below it: the
    rank found is the map's, I + A B^T is I + x to the noise, and the singular values are
    the full SVD's; a rank past RANGE_START takes more test vectors, one past half the size
    the full SVD itself.
    """
    rng = np.random.default_rng(rank)
    size = 300
    u = np.linalg.qr(rng.standard_normal((size, rank)))[0]
    v = np.linalg.qr(rng.standard_normal((size, rank)))[0]
    sv = np.logspace(0.0, -9.0, rank)
    x = (u * sv) @ v.T + 1e-15 * rng.standard_normal((size, size))
    low = _low_rank(x, 1, size)
    assert len(low.a) == rank
    assert np.max(np.abs(low.a.T @ low.b - x)) < 1e-13
    full = np.linalg.svd(x, compute_uv=False)
    found = np.linalg.norm(low.a, axis=1)           # (A's rows: the singular values)
    np.testing.assert_allclose(found, full[full > BUS_TOLERANCE], rtol=1e-9, atol=1e-14)
