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
The umbrella's co-rotational ribs (model flexible-nonlinear, umbrella3d/corotational3d.py).

(a) N identical ribs started alike are N copies of the planar flexible-nonlinear model
(same mesh, step and lock) through both stages, the links buckling (V0 = -1 m/s).  The two
codes solve the same discrete equations (the strain law is the planar element's to the
rounding of the chord length), but not with the same Newton iterates: the planar step
carries its iteration matrix by its own rules (nonlinear.ElasticMidpointDAE) and the
umbrella's by its own, so at the default Newton tolerance (1e-8 at 0.1 ms) the runs differ
by the Newton remainder, ~1e-7.  Both are therefore solved to 1e-14 (rad, m: a few units of
round-off in the coordinates), where the remainder is below round-off and what is left is
the rounding of sums taken in another order: 2.4e-12 seen (rad, m) over 800 steps through
the plastic lock (lock instants 3e-15 s apart), 5.8e-12 through the energy lock.  The
tolerance asserted, 1e-10, is the linear identity's (tests/test_umbrella3d.py): any term
that differed shows above it (a Newton tolerance of 1e-13 alone leaves 1.5e-9).

The compiled step (_kernel3d_nonlinear.h) takes the numpy reference's steps to round-off,
on the fixed hub and on a free bus, through the lock.

(b) The law: its Hessian at q = 0 is the linear 3D beam's K, its discrete gradient gives
the energy increment exactly, the O'' hinge's turned rows' Jacobian and bias are their
derivatives.  (c) Energy balance to round-off with F = 0 and with hinge friction; an
asymmetric umbrella (a kicked rib, a rubbing hinge, a tip mass) through the plastic lock
with the joints held; a free bus's momentum; small motion equals the linear umbrella, the
difference shrinking with the amplitude.
"""
import math

import numpy as np
import pytest

from tests.test_umbrella3d_kernel import assert_compiled_figures_are_record3ds
from umbrella_sim.core import UmbrellaParams, UmbrellaSimulator
from umbrella_sim.core.driver import RunDriver
from umbrella_sim.core.kernel import load_kernel
from umbrella_sim.core.umbrella3d.corotational3d import (CorotationalUmbrellaModel3D,
                                                         OUT_OF_PLANE_LIMIT,
                                                         out_of_plane_warnings, umbrella_model)
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import SimulationFailed, UmbrellaSimulator3D

IDENTITY_TOLERANCE = 1e-10
#: the Newton tolerance both codes are solved to in the identity (module docstring)
TIGHT_NEWTON = 1e-14
BALANCE_TOLERANCE = 1e-10      # relative to the largest T + V: the discrete balance's round-off
NONLINEAR = {'model': 'flexible-nonlinear'}


def ribs_params(values: dict) -> UmbrellaRibsParams:
    return UmbrellaRibsParams.from_mapping({**NONLINEAR, **values})


# ---------------------------------------------------------------- (a) the planar model
@pytest.mark.slow      # numpy ~8 s (800 umbrella steps at 7 ms, Newton to 1e-14); compiled 0.3 s
@pytest.mark.parametrize('lock, kernel', [('plastic', 'compiled'), ('plastic', 'numpy'),
                                          ('energy', 'compiled')])
def test_identical_ribs_are_each_the_planar_nonlinear_model(lock, kernel):
    """Three ribs, V0 = -1 (the links buckle), either lock, 0.035 s of stage 2; either path."""
    assert_ribs_equal_planar_nonlinear({'lock': lock}, kernel)


def assert_ribs_equal_planar_nonlinear(extra: dict, kernel: str, duration: float = 0.08):
    """
    Assert three ribs at V0 = -1 (and extra) are each the planar flexible-nonlinear model.

    Both solved to TIGHT_NEWTON, through the lock and into stage 2 (module docstring);
    returns the umbrella's and the planar simulator.
    """
    values = {**NONLINEAR, 'v0': -1.0, 'time_step': 1e-4, **extra}
    planar_sim = UmbrellaSimulator(UmbrellaParams(**values))
    planar_sim.engine.integrator.tolerance = TIGHT_NEWTON
    planar = []
    while planar_sim.time < duration - 1e-12:
        s = planar_sim.step()[-1]
        planar.append((s.time, s.alpha1, s.alpha2, s.sleeve_position, s.tip_axial,
                       s.tip_transverse, s.kinetic_energy + s.strain_energy))
    planar = np.array(planar)
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({'ribs': 3, **values}),
                              tolerance=TIGHT_NEWTON, kernel=kernel)
    assert isinstance(sim.model, CorotationalUmbrellaModel3D)
    assert sim.integrator.backend == kernel and not sim.mode_fit
    assert sim.h == planar_sim.h
    a = sim.run(duration).arrays()
    assert len(a['time']) - 1 == len(planar)
    assert sim.lock_time == pytest.approx(planar_sim.lock_event.time, abs=1e-11)
    assert sim.lock_time < duration - 0.03                   # through both stages
    for name, column in (('alpha1', 1), ('alpha2', 2)):
        np.testing.assert_allclose(a[name][1:], np.repeat(planar[:, column:column + 1], 3, 1),
                                   rtol=0, atol=IDENTITY_TOLERANCE, err_msg=name)
    np.testing.assert_allclose(a['sleeve_position'][1:], planar[:, 3], rtol=0,
                               atol=IDENTITY_TOLERANCE)
    for d, column in ((0, 4), (1, 5)):
        np.testing.assert_allclose(a['tip'][1:, :, d],
                                   np.repeat(planar[:, column:column + 1], 3, 1),
                                   rtol=0, atol=IDENTITY_TOLERANCE)
    assert np.max(np.abs(a['tip'][:, :, 2])) < 1e-15         # nothing leaves the planes
    energy = a['kinetic_energy'] + a['strain_energy']
    np.testing.assert_allclose(energy[1:], 3 * planar[:, 6], rtol=1e-9)
    # the stresses of the last state: the planar fibres' E (eps -/+ c kappa) are the axial
    # and in-plane bending components; no torsion, no out-of-plane bending
    for (top, bottom), blocks in zip(planar_sim.model.stresses(planar_sim.state.q),
                                     sim.model.stress_blocks(sim.state.qr)):
        scale = np.max(np.abs(top))
        for rib in range(3):
            axial, bend_z, bend_y, shear = blocks[rib]
            np.testing.assert_allclose(axial - bend_z, top, rtol=0, atol=1e-8 * scale)
            np.testing.assert_allclose(axial + bend_z, bottom, rtol=0, atol=1e-8 * scale)
            # (the energy lock leaves round-off out of the planes: 1e-17 m)
            assert max(np.max(np.abs(bend_y)), np.max(np.abs(shear))) < 1e-12 * scale
    return sim, planar_sim


@pytest.mark.slow      # ~4 s and ~6 s (the numpy reference: ~6 and ~12 ms a step)
@pytest.mark.parametrize('base, elements, duration', [('fixed', 2, 0.07), ('free', 1, 0.05)])
def test_compiled_step_equals_the_numpy_reference_through_the_lock(base, elements, duration):
    """
    _kernel3d_nonlinear.h takes numpy's steps: an asymmetric umbrella through the plastic lock.

    Three ribs, V0 = -1, a kicked rib and a rubbing hinge, on the fixed hub (2 elements a
    segment) and on a free bus (_kernel3d_base.h's step, 1 element): the same algorithm
    (predictor, matrices, stopping rule), so the same iterates up to the rounding of sums
    taken in another order: 3.5e-13 and 2.9e-13 (rad, m) seen over 700 and 500 steps (a driven
    base: 5.2e-13); 1e-10 asserted, the planar identity's tolerance.
    """
    values = {'ribs': 3, 'elements_per_segment': elements, 'v0': -1.0, 'lock': 'plastic',
              'time_step': 1e-4, 'base': base, 'rib1.out_of_plane_rate': 0.5,
              'rib2.hinge_coulomb': 0.2}
    runs = {}
    for kernel in ('compiled', 'numpy'):
        sim = UmbrellaSimulator3D(ribs_params(values), kernel=kernel)
        assert sim.integrator.backend == kernel
        runs[kernel] = (sim, sim.run(duration).arrays())
    (compiled, a), (numpy_sim, b) = runs['compiled'], runs['numpy']
    assert compiled.lock_time == pytest.approx(numpy_sim.lock_time, abs=1e-11)
    for name in ('alpha1', 'alpha2', 'tip', 'sleeve_position'):
        np.testing.assert_allclose(a[name], b[name], rtol=0, atol=IDENTITY_TOLERANCE,
                                   err_msg=name)
    scale = np.max(a['kinetic_energy'] + a['strain_energy'])
    np.testing.assert_allclose(a['strain_energy'], b['strain_energy'], rtol=0,
                               atol=1e-9 * scale)
    assert compiled.model.max_out_of_plane == pytest.approx(numpy_sim.model.max_out_of_plane,
                                                            rel=1e-9)


#: the compiled stress figures against Record3D's numpy ones, value by value: the recovery's
#: sums taken in another order (9.8e-16 relative seen, fixed hub; 8.8e-16 free bus); and the
#: floor of a value that cancels (its component's largest times round-off)
FIGURES_RTOL = 4e-15
FIGURES_FLOOR = 1e-15


@pytest.mark.skipif(load_kernel() is None, reason='compiled kernel not built')
@pytest.mark.parametrize('base, elements', [('fixed', 2), ('free', 1)])
def test_compiled_stress_figures_equal_record3d_numpy(base, elements):
    """
    The co-rotational ribs' stress figures computed in the compiled step are Record3D's.

    Two compiled runs through the plastic lock and 5 ms past it (three ribs, V0 = -1, a
    kicked rib, a rubbing hinge): one whose rows carry the figures (_kernel3d_figures.h with
    nl_stress_components: the components from the co-rotated strains), one whose Record3D
    computes them in numpy from the rows' states (corotational3d's stress_blocks).  Every
    other row equal bit for bit; each rib's largest of every component and von Mises (the
    Hermite crest of every step) equal to round-off, their places, the peaks' places and
    instants equal.
    """
    values = {'ribs': 3, 'elements_per_segment': elements, 'v0': -1.0, 'lock': 'plastic',
              'time_step': 1e-4, 'base': base, 'rib1.out_of_plane_rate': 0.5,
              'rib2.hinge_coulomb': 0.2}
    assert_compiled_figures_are_record3ds(ribs_params(values), deploying=400, rtol=FIGURES_RTOL,
                                          floor=FIGURES_FLOOR, peak_rtol=FIGURES_RTOL)


# ---------------------------------------------------------------- (b) the law
@pytest.fixture(scope='module')
def model():
    return umbrella_model(ribs_params({'ribs': 3, 'elements_per_segment': 2}).validated())


def perturbed(model, size, seed=1):
    return size * np.random.default_rng(seed).standard_normal((model.n_ribs, model.n_rib))


def test_small_motion_law_is_the_linear_beam(model):
    """The Hessian of U at q = 0 is the linear 3D element's K (beam3d.py), every rib."""
    law = model.strain
    tangent = law.tangent(np.zeros((model.n_ribs, model.n_rib)))
    scale = np.abs(model.stiffness).max()
    np.testing.assert_allclose(tangent, model.stiffness, rtol=0, atol=1e-14 * scale)


def test_gradient_tangent_and_discrete_gradient(model):
    """dU/dq and its Hessian by central differences; dq . G = U(q1) - U(q0) to round-off."""
    law = model.strain
    q = perturbed(model, 0.02)
    g = law.gradient(q)
    step = 1e-7
    fd = np.zeros_like(q)
    fdh = np.zeros((model.n_ribs, model.n_rib, model.n_rib))
    for i in range(model.n_rib):
        dq = np.zeros_like(q)
        dq[:, i] = step
        fd[:, i] = (law.energy_per_rib(q + dq) - law.energy_per_rib(q - dq)) / (2 * step)
        fdh[:, :, i] = (law.gradient(q + dq) - law.gradient(q - dq)) / (2 * step)
    assert np.abs(fd - g).max() < 1e-8 * np.abs(g).max()
    tangent = law.tangent(q)
    assert np.abs(fdh - tangent).max() < 1e-8 * np.abs(tangent).max()
    q1 = q + perturbed(model, 0.01, seed=2)
    increment = law.energy_per_rib(q1) - law.energy_per_rib(q)
    balance = np.sum((q1 - q) * law.discrete_gradient(q, q1), 1) - increment
    assert np.abs(balance).max() < 1e-13 * law.energy_per_rib(q1).max()


def test_rigid_motions_of_an_element_strain_nothing(model):
    """
    An element moved rigidly stores no energy: a large turn in its rib's plane, a tilt, a roll.

    The turn beta, then the tilt eps about the turned element's in-plane normal, then the roll
    phi about its axis: chord l (cos eps cos beta, cos eps sin beta, sin eps), slopes v' =
    cos eps sin beta, w' = sin eps, twists phi (an element inside the leaf: every coordinate
    free).
    """
    law = model.strain
    lin, length = law.lin[1], law.length[0, 1]
    for beta, eps, roll in ((0.3, 0.0, 0.0), (1.2, 0.0, 0.0), (-1.4, 0.0, 0.0),
                            (0.0, 0.1, 0.0), (1.2, 0.1, 0.05), (-0.8, -0.3, 0.2)):
        slope, out = math.cos(eps) * math.sin(beta), math.sin(eps)
        z = np.array([length * (math.cos(eps) * math.cos(beta) - 1.0),
                      length * math.cos(eps) * math.sin(beta), length * out,
                      slope, slope, out, out, roll, roll])
        q = np.linalg.lstsq(lin, z, rcond=None)[0]
        assert np.abs(lin @ q - z).max() < 1e-14
        s = law.strains(np.tile(q, (model.n_ribs, 1)))[0, 1]
        assert np.abs(s).max() < 1e-13, (beta, eps, roll)


def test_turned_hinge_rows_and_their_derivatives(model):
    """The O'' hinge's rows: Jacobian and bias (-Jdot v) by central differences."""
    q, v = perturbed(model, 0.05), perturbed(model, 1.0, seed=3)
    stuck = np.full(model.n_ribs, np.nan)
    ys = np.array([model.y_start])
    jac = model.constraint_jacobian(q, stuck, False)[0]
    step = 1e-7
    fd = np.zeros_like(jac)
    for i in range(model.n_rib):
        dq = np.zeros_like(q)
        dq[:, i] = step
        fd[:, :, i] = (model.constraints(q + dq, ys, stuck, False)[0]
                       - model.constraints(q - dq, ys, stuck, False)[0]) / (2 * step)
    assert np.abs(fd - jac).max() < 1e-8
    jp = model.constraint_jacobian(q + step * v, stuck, False)[0]
    jm = model.constraint_jacobian(q - step * v, stuck, False)[0]
    jdot_v = np.einsum('rij,rj->ri', (jp - jm) / (2 * step), v)
    assert np.abs(-jdot_v[:, :8] - model.constraint_bias(q, v)[:, :8]).max() < 1e-6


def test_stress_rates_are_the_stresses_derivatives(model):
    q, v = perturbed(model, 0.02), perturbed(model, 1.0, seed=4)
    rates = model.stress_rate_blocks(q, v)
    plus, minus = model.stress_blocks(q + 1e-7 * v), model.stress_blocks(q - 1e-7 * v)
    for r, p, m in zip(rates, plus, minus):
        assert np.abs((p - m) / 2e-7 - r).max() < 1e-7 * np.abs(r).max()


def test_out_of_plane_warning_past_its_limit():
    params = {'model': 'flexible-nonlinear'}
    assert out_of_plane_warnings(params, 0.5 * OUT_OF_PLANE_LIMIT) == []
    assert out_of_plane_warnings({'model': 'flexible'}, 2 * OUT_OF_PLANE_LIMIT) == []
    said = out_of_plane_warnings(params, 2 * OUT_OF_PLANE_LIMIT)
    assert len(said) == 1 and said[0].startswith('out-of-plane rotation:')


def test_out_of_plane_rotation_is_the_angle_a_section_turned(model):
    """
    A node's w' is the sine of its turn out of the plane: the measure is asin |w'| (or |phi|).

    The unit tangent (cos psi cos e, sin psi cos e, sin e) of a section tilted by e out of
    its rib's plane has w' = sin e; the warning's degrees are e's.
    """
    law = model.strain
    qr = np.zeros((model.n_ribs, model.n_rib))
    tilt_at_g = law.node_places[law.n_leaf - 1, 3]      # w' at the leaf's tip G
    twist_at_g = law.node_places[law.n_leaf - 1, 5]     # phi there
    tilt = math.asin(0.95)
    qr[1, tilt_at_g] = math.sin(tilt)
    qr[2, twist_at_g] = 0.5 * tilt
    assert law.out_of_plane_rotation(qr) == pytest.approx(tilt, rel=1e-14)
    qr[2, twist_at_g] = 1.2 * tilt                      # a larger twist is the measure
    assert law.out_of_plane_rotation(qr) == pytest.approx(1.2 * tilt, rel=1e-14)
    said = out_of_plane_warnings({'model': 'flexible-nonlinear'}, tilt)
    assert f'turned {math.degrees(tilt):.1f} deg out of' in said[0]


@pytest.mark.parametrize('kernel', ['compiled', 'numpy'])
def test_a_step_that_fails_past_the_out_of_plane_range_says_so(kernel):
    """
    A rib kicked far out of its plane (1 km/s at its tip) fails within 1 ms, naming why.

    Both paths fail alike, the numpy step's non-finite residual a failure of the step (not
    scipy's ValueError), and the failure says how far out of its plane the rib had turned
    from the state the step started at, past OUT_OF_PLANE_LIMIT.
    """
    sim = UmbrellaSimulator3D(ribs_params({'ribs': 2, 'time_step': 1e-4,
                                           'rib1.out_of_plane_rate': 1000.0}), kernel=kernel)
    with pytest.raises(SimulationFailed) as failed:
        sim.run(0.01)
    rotation = sim.model.strain.out_of_plane_rotation(sim.state.qr)
    assert rotation > 10 * OUT_OF_PLANE_LIMIT
    text = str(failed.value)
    assert 'Newton iterate became non-finite' in text
    assert f"turned {math.degrees(rotation):.1f} deg out of its rib's plane" in text


def test_a_run_says_when_its_ribs_leave_the_out_of_plane_limit():
    """Through the run driver: a rib kicked hard out of its plane is named, a nudge is not."""
    for kick, said in ((0.5, False), (20.0, True)):
        driver = RunDriver(ribs_params({'ribs': 2, 'v0': -0.5, 'time_step': 1e-4,
                                        'rib1.out_of_plane_rate': kick}))
        driver.run(0.01)
        rotation = driver.sim.model.max_out_of_plane
        assert (rotation > OUT_OF_PLANE_LIMIT) == said
        warnings = driver.summary.figures()['warnings']
        assert any(w.startswith('out-of-plane rotation:') for w in warnings) == said


# ---------------------------------------------------------------- (c) balances
def test_energy_balance_with_no_force_and_with_friction():
    """T + V - (T + V)(0) = W_sleeve + W_friction to round-off: F = 0, then friction and F."""
    for extra in ({'v0': -1.0},
                  {'sleeve_force': 10.0, 'rib1.hinge_coulomb': 0.3, 'rib1.hinge_viscous': 0.05,
                   'rib2.out_of_plane_rate': 0.2}):
        rec = UmbrellaSimulator3D(ribs_params({'ribs': 3, 'time_step': 1e-4, **extra})).run(0.02)
        s = rec.summary()
        assert s['energy_balance_residual'] < BALANCE_TOLERANCE * s['energy_scale']
    friction = s['friction_work']
    assert friction[1] < -1e-3 * rec.arrays()['work'][-1]
    assert s['max_out_of_plane_tip_rib'] == 2


@pytest.mark.slow      # ~5 s (numpy)
def test_an_asymmetric_umbrella_through_the_lock():
    """A kicked rib, a rubbing hinge, a tip mass; V0 = -1, plastic lock: balance and joints."""
    sim = UmbrellaSimulator3D(ribs_params({
        'ribs': 4, 'v0': -1.0, 'lock': 'plastic', 'time_step': 1e-4,
        'rib1.out_of_plane_rate': 0.5, 'rib2.hinge_coulomb': 0.2, 'rib3.tip_mass': 0.02}))
    m = sim.model
    worst = 0.0
    while sim.time < 0.07 - 1e-12:
        sim.step()
        s = sim.state
        phi_r, phi_s = m.constraints(s.qr, s.qs, s.stuck, sim.locked)
        worst = max(worst, np.abs(phi_r).max(), np.abs(phi_s).max())
    assert sim.locked and sim.lock_time < 0.06
    assert worst < 1e-9
    s = sim.record.summary()
    assert s['energy_balance_residual'] < BALANCE_TOLERANCE * s['energy_scale']
    a = sim.record.arrays()
    assert a['lock_energy_loss'][-1] > 0.0                  # (the plastic lock's loss)
    assert np.abs(a['tip'][:, 1, 2]).max() > 10 * np.abs(a['tip'][:, 0, 2]).max()
    # the kick stays a perturbation: inside the model's out-of-plane validity
    assert 0.0 < m.max_out_of_plane < OUT_OF_PLANE_LIMIT


def test_a_free_bus_keeps_its_momentum_and_energy():
    """A kicked rib on a free bus: linear momentum and energy to round-off."""
    sim = UmbrellaSimulator3D(ribs_params({
        'ribs': 3, 'v0': -1.0, 'lock': 'plastic', 'base': 'free', 'time_step': 1e-4,
        'rib1.out_of_plane_rate': 0.5}), tolerance=1e-12)
    rec = sim.run(0.03)
    s, a = rec.summary(), rec.arrays()
    assert s['energy_balance_residual'] < BALANCE_TOLERANCE * s['energy_scale']
    rib_mass = sim.model.total_mass - sim.model.bus_mass - sim.model.sleeve_mass
    scale = rib_mass * np.max(np.abs(a['sleeve_velocity']))
    drift = np.abs(a['linear_momentum'] - a['linear_momentum'][0]).max()
    assert drift < 1e-12 * scale
    assert np.abs(a['bus_v'][:, :3]).max() > 1e3 * drift     # (the bus does move)


def small_motion_difference(v0: float):
    """Return the largest in-plane and out-of-plane tip differences, nonlinear - linear."""
    arrays = {}
    for model in ('flexible', 'flexible-nonlinear'):
        values = {'ribs': 3, 'model': model, 'v0': v0, 'time_step': 1e-4,
                  'phase_correction': False, 'rib1.out_of_plane_rate': 2.0 * v0,
                  'rib2.alpha0_offset': 0.01 * v0}
        sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values), tolerance=1e-13,
                                  kernel='numpy')
        arrays[model] = sim.run(0.02).arrays()['tip']
    lin, nl = arrays['flexible'], arrays['flexible-nonlinear']
    return [np.abs(nl[:, :, d] - lin[:, :, d]).max() / np.abs(lin[:, :, d]).max()
            for d in (1, 2)]


@pytest.mark.slow      # ~5 s (numpy: six runs of 200 steps)
def test_small_motion_is_the_linear_umbrella():
    """V0 = -0.2 scaled down by 10 and 100: the relative difference shrinks with it."""
    coarse, fine = small_motion_difference(-0.02), small_motion_difference(-0.002)
    assert max(coarse) < 1e-2
    for c, f in zip(coarse, fine):
        assert f < c / 5.0        # first order in the amplitude, or better
