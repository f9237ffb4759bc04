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
The whole umbrella's compiled step (_kernel3d.c) against its numpy reference (integrator3d).

The two paths compute the same iterates of the same algorithm; they differ in the order of
sums (and LU solves where numpy inverts a rib's block), about 1e-16 relative per operation.
How far that carries over a run is the run's own sensitivity: a hinge stuck on its joint
(whose multiplier, the holding torque, is the step's Newton increment divided by h^2 / 2;
it clamps the leaf's root, whose bending then carries the sleeve), Coulomb friction
regularised over 1e-3 rad/s (a torque slope of 50 N m s at 0.05 N m), stage 2's vibration.
The test measures it: the numpy path against itself with its initial rates and leaf angles
moved by one unit in the last place.  Asserted: every figure of the compiled run within ten
times that spread of the reference (plus 1e-12 of the figure's scale, the round-off of
figures the run does not amplify), and the positions (angles times the rib's lengths, the
sleeve, the tips) within 1e-10 of the rib's length, two orders below the Newton tolerance
(1e-8 at h = 1e-4 s): a term computed differently or a stopping decision taken differently
shows above both.  A run may amplify round-off past that cap by itself: the driven hub's
deployment from rest to the lock (0.47 s, spun at 3 rad/s) spreads the reference's sleeve
by 5.0e-11 m at the lock from one ulp of its initial rates (2.7e-11 at 25 N a rib, 0.3 s);
there the positions' cap is twice the reference's own spread (the compiled run: 5.4e-11).

The same holds with a moving base (_kernel3d_base.h): a driven hub (a jolt in X-Z, a spin-up
about Y) and a free-floating bus, whose run also keeps the bus's momenta (rows compared as
the others; the momenta's round-off scale is their largest value or, for a momentum that
stays 0, the ribs' mass times their speed).

The lock instant is found by the Illinois root find to EVENT_TIME_TOLERANCE (1e-12 s) on
either path; its bracket may close on either side of the root, so the two lock instants
agree to that tolerance (and the sleeve's difference before it over its speed), not to
round-off.  The locked steps are therefore compared from one locked state, taken by both.
"""
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
import math
import multiprocessing
import re

import numpy as np
import pytest

from umbrella_sim.core.engines import EVENT_TIME_TOLERANCE
from umbrella_sim.core.integrators import PHI_TOLERANCE
from umbrella_sim.core.kernel import load_kernel
from umbrella_sim.core.umbrella3d import integrator3d
from umbrella_sim.core.umbrella3d.integrator3d import MidpointUmbrella
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import SimulationFailed, UmbrellaSimulator3D

AGREEMENT = 1e-10
needs_kernel = pytest.mark.skipif(load_kernel() is None,
                                  reason='the compiled kernel is not built')

#: an asymmetric umbrella from rest: a hinge stuck until 4 ms, one until its torque reaches
#: 0.2 N m, Coulomb and viscous friction, an out-of-plane kick, a tip mass off the plane
#: (rib 3's hold, the moment at its clamped root, passes 0.2 N m in 9-15 ms on every base)
ASYMMETRIC = {'ribs': 4, 'elements_per_segment': 1, 'time_step': 1e-4, 'sleeve_force': 10.0,
              'v0': 0.0, 'rib1.stick_until': 0.004, 'rib3.stick_torque': 0.2,
              'rib2.hinge_coulomb': 0.05, 'rib0.hinge_viscous': 0.01,
              'rib2.out_of_plane_rate': 0.3, 'rib0.tip_mass': 0.01, 'rib0.tip_offset_z': 0.02}
#: the bases: the hub fixed, driven (a half-sine jolt in X-Z from 5 ms, spun up about Y in
#: 10 ms: integrator3d.BaseDrive), a free-floating bus
BASES = {'fixed': {},
         'prescribed': {'base': 'prescribed', 'base_accel_x': 20.0, 'base_accel_z': -10.0,
                        'base_accel_start': 0.005, 'base_accel_duration': 0.01,
                        'base_spin_rate': 3.0, 'base_spin_ramp': 0.01},
         'free': {'base': 'free', 'bus_mass': 5.0, 'bus_inertia': 0.2}}
#: how a deployment through the lock starts: from rest (4 800 steps to the lock), or at
#: V0 = -0.5 (790-840 steps; a moving base's jolt, spin-up and both releases happen in them),
#: which spares the numpy reference's ~2 ms a step (~6 ms with a moving base) over the rest
FROM_REST, AT_SPEED = {}, {'v0': -0.5}
#: the simulated time of the compared deployment: 40 ms with the hub fixed, 20 ms with a
#: moving base (the numpy reference's step is ~6 ms at 4 ribs; both releases happen by then)
DEPLOYMENT = {'fixed': 0.04, 'prescribed': 0.02, 'free': 0.02}


def both(values: dict):
    """Return the compiled and the numpy simulator of values."""
    p = UmbrellaRibsParams.from_mapping(values)
    compiled = UmbrellaSimulator3D(p, kernel='compiled')
    assert compiled.integrator.backend == 'compiled'
    return compiled, UmbrellaSimulator3D(p, kernel='numpy')


#: positions, compared on the rib's length: (figure, the length it is multiplied by)
POSITIONS = (('alpha1', 'l1'), ('alpha2', 'l3'), ('sleeve_position', None), ('tip', None))


def perturbed_reference(values: dict) -> UmbrellaSimulator3D:
    """
    Return the numpy simulator of values with its initial rates and leaf angles one ulp up.

    The angles too: from rest the rates are 0 (but a kick's), whose ulp perturbs nothing a
    run can carry; a from-rest deployment with stuck hinges to the lock (4 800 steps)
    spreads the sleeve by 1.4e-12 m from the rates' ulp, 9.0e-12 m from the angles'.
    """
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values), kernel='numpy')
    s = sim.state
    qr = s.qr.copy()
    qr[:, sim.model.i_a1] = np.nextafter(qr[:, sim.model.i_a1], np.inf)
    sim.state = replace(s, qr=qr, vr=np.nextafter(s.vr, np.inf), pr=None, ps=None)
    return sim


def _spread_run(values: dict, duration: float, after_lock: float | None):
    """Return the perturbed reference's rows and run peaks after run(duration, after_lock)."""
    sim = perturbed_reference(values)
    record = sim.run(duration) if after_lock is None else sim.run(duration, after_lock=after_lock)
    return record.arrays(), dict(sim.record.peak)


def spread_in_background(values: dict, duration: float, after_lock: float | None = None):
    """
    Start the perturbed reference's run in a process of its own; return its future.

    Its numpy run is as long as the compared one's: on a 2-core machine the two run side by
    side (the rows and peaks come back pickled, the same arrays).
    """
    pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context('spawn'))
    try:
        return pool.submit(_spread_run, values, duration, after_lock)
    finally:
        pool.shutdown(wait=False)


def assert_rows_agree(a: dict, b: dict, spread: dict, model, rows=slice(None)):
    """Assert a agrees with b within 10 x the reference's ulp spread (module docstring)."""
    assert a.keys() == b.keys()
    # a free bus's momenta may stay 0 (the linear one from rest): their round-off is on the
    # scale of the ribs' momentum, m v (and m v L)
    rib_mass = sum(float(body.w.sum()) for body in model.bodies)
    speed = np.max(np.abs(np.asarray(b['sleeve_velocity'])[rows]))
    length = max(np.max(model.l1), np.max(model.l3))
    scales = {'linear_momentum': rib_mass * speed, 'angular_momentum': rib_mass * speed * length}

    def floor(name):
        return scales.get(name, 0.0)

    for name in a:
        x, y = np.asarray(a[name], float)[rows], np.asarray(b[name], float)[rows]
        z = np.asarray(spread[name], float)[rows]
        assert x.shape == y.shape, name
        bound = 10.0 * np.max(np.abs(z - y)) + 1e-12 * max(np.max(np.abs(y)), floor(name))
        assert np.max(np.abs(x - y)) <= bound, name
    for name, lever in POSITIONS:
        x, y = np.asarray(a[name])[rows], np.asarray(b[name])[rows]
        z = np.asarray(spread[name])[rows]
        arm = 1.0 if lever is None else getattr(model, lever)
        cap = max(AGREEMENT * length, 2.0 * np.max(np.abs((z - y) * arm)))
        assert np.max(np.abs((x - y) * arm)) <= cap, name


def assert_states_agree(s, t, u=None):
    """Assert s agrees with t: to 1e-10 relative, or within 10 x its ulp spread u - t."""
    assert s.t == t.t
    np.testing.assert_array_equal(np.isnan(s.stuck), np.isnan(t.stuck))
    for name in ('qr', 'qs', 'vr', 'vs', 'lam_r', 'lam_s', 'pr', 'ps'):
        x, y = getattr(s, name), getattr(t, name)
        bound = AGREEMENT * max(np.max(np.abs(y)), 1e-300)
        if u is not None:
            bound = max(bound, 10.0 * np.max(np.abs(getattr(u, name) - y)))
        assert np.max(np.abs(x - y)) <= bound, name


def assert_on_the_joints(sim: UmbrellaSimulator3D):
    """Assert the state's joints hold: Phi to Newton's residual, J v to round-off (drive's)."""
    m, s = sim.model, sim.state
    drive = sim.integrator.drive
    place, rates = (None, np.zeros(0)) if drive is None else drive(s.t)[:2]
    phi_r, phi_s = m.constraints(s.qr, s.qs, s.stuck, sim.locked, place)
    assert max(np.max(np.abs(phi_r)), np.max(np.abs(phi_s))) < PHI_TOLERANCE
    j_rr, j_rs, j_ss, active = m.constraint_jacobian(s.qr, s.stuck, sim.locked)
    jv = np.einsum('rij,rj->ri', j_rr, s.vr) + j_rs @ s.vs
    assert np.max(np.abs(jv)) < 1e-12 * np.max(np.abs(s.vr))
    target = np.concatenate([[0.0], rates])
    scale = max(np.max(np.abs(s.vr)), np.max(np.abs(target)))
    assert np.all(np.abs((j_ss @ s.vs - target)[active]) < 1e-12 * scale)


@needs_kernel
@pytest.mark.parametrize('base', [pytest.param(base, marks=[pytest.mark.slow] if base != 'fixed'
                                               else []) for base in BASES])   # numpy ~2.3 s
def test_compiled_equals_numpy_while_hinges_stick_and_rub(base):
    """A stuck hinge released by time, one by its torque, friction, a kick; each base."""
    values = dict(ASYMMETRIC, **BASES[base])
    duration = DEPLOYMENT[base]
    background = spread_in_background(values, duration)
    compiled, numpy_sim = both(values)
    a = compiled.run(duration).arrays()
    b = numpy_sim.run(duration).arrays()
    spread, spread_peaks = background.result()
    if base != 'fixed':       # the bus moved (driven; in reaction)
        assert np.max(np.abs(b['bus_q'][-1, :3])) > 1e-6
    stuck = b['stuck']
    assert stuck[0, 1] and stuck[0, 3] and not stuck[-1, 1]      # both rules happened
    assert not stuck[-1, 3] and stuck[len(stuck) // 4, 3]
    assert_rows_agree(a, b, spread, compiled.model)
    assert_on_the_joints(compiled)
    assert compiled.record.friction[2] < 0.0 and compiled.record.friction[0] < 0.0
    for name, peak in compiled.record.peak.items():
        want = numpy_sim.record.peak[name]
        # as the rows: the figure's largest spread (over the ribs)
        bound = 10.0 * np.max(np.abs(spread_peaks[name] - want)) + 1e-12 * want
        assert np.all(np.abs(peak - want) <= bound), name
        assert compiled.record.peak_where[name] == numpy_sim.record.peak_where[name]


#: the discrete energy balance's residual, relative to the largest T + V: round-off where the
#: step scales the velocity to the balance; on a driven base (the velocity projected onto the
#: prescribed rates, not scaled) what the projection changes (tests/test_umbrella3d.py)
BALANCE = {'fixed': 1e-9, 'free': 1e-9, 'prescribed': 1e-6}


@pytest.mark.slow
@needs_kernel
@pytest.mark.parametrize('lock, base, start', [
    ('plastic', 'fixed', FROM_REST), ('energy', 'fixed', AT_SPEED),
    ('plastic', 'free', AT_SPEED), ('energy', 'prescribed', AT_SPEED)],
    ids=['plastic-fixed-from-rest', 'energy-fixed', 'plastic-free', 'energy-prescribed'])
def test_compiled_equals_numpy_through_the_lock(lock, base, start):
    """A deployment to the lock and 5 ms past it, each lock rule, each base."""
    values = dict(ASYMMETRIC, lock=lock, **BASES[base], **start)
    background = spread_in_background(values, 1.0, after_lock=0.005)
    compiled, numpy_sim = both(values)
    a = compiled.run(1.0, after_lock=0.005).arrays()
    b = numpy_sim.run(1.0, after_lock=0.005).arrays()
    spread, _ = background.result()
    deploying = ~b['locked']
    assert 700 < np.count_nonzero(deploying) < len(deploying) - 40
    stuck = b['stuck'][:np.count_nonzero(deploying)]
    assert stuck[0, 1] and stuck[0, 3] and not stuck[-1, 1] and not stuck[-1, 3]  # released
    n = np.count_nonzero(deploying)
    assert_rows_agree(*({k: v[:n] for k, v in r.items()} for r in (a, b, spread)),
                      compiled.model)
    # the root find closes its bracket within EVENT_TIME_TOLERANCE; the sleeve's paths to
    # the stop differ by what they differ before, which moves the root by that / its speed
    last = np.count_nonzero(deploying) - 1
    gap = abs(a['sleeve_position'][last] - b['sleeve_position'][last])
    shift = gap / abs(b['sleeve_velocity'][last])
    assert abs(compiled.lock_time - numpy_sim.lock_time) <= 2 * (EVENT_TIME_TOLERANCE + shift)
    # the compiled run's own balances, through the lock
    for sim in (compiled, numpy_sim):
        s = sim.record.summary()
        assert s['energy_balance_residual'] < BALANCE[base] * s['energy_scale']
        assert_on_the_joints(sim)
    # locked steps from one state (and the reference's from it moved by one ulp), each by an
    # integrator of its own (an iteration matrix is kept along the trajectory it served)
    s_c = s_n = numpy_sim.state
    s_u = replace(s_n, vr=np.nextafter(s_n.vr, np.inf), pr=None, ps=None)
    h = numpy_sim.h
    step_c, step_n, step_u = (MidpointUmbrella(numpy_sim.model, numpy_sim.integrator.tolerance,
                                               kernel=k).step
                              for k in ('compiled', 'numpy', 'numpy'))
    for _ in range(20):
        s_c, w_c = step_c(s_c, h, compiled.force, True)
        s_n, w_n = step_n(s_n, h, numpy_sim.force, True)
        s_u, _ = step_u(s_u, h, numpy_sim.force, True)
        assert (w_c.iterations, w_c.factorisations) == (w_n.iterations, w_n.factorisations)
        assert w_c.force == pytest.approx(w_n.force, abs=AGREEMENT * abs(a['work'][-1]))
    assert_states_agree(s_c, s_n, s_u)


@needs_kernel
@pytest.mark.parametrize('base', BASES)
def test_runs_of_steps_equal_steps_one_at_a_time(base):
    """Runs of grid steps (advance: one compiled call) are step's steps, figures alike."""
    p = UmbrellaRibsParams.from_mapping(dict(ASYMMETRIC, **BASES[base]))
    runs, single = UmbrellaSimulator3D(p), UmbrellaSimulator3D(p)
    runs.advance(150)
    for _ in range(150):
        single.step()
    assert runs.k == single.k == 150
    a = single.record.arrays()
    assert_rows_agree(runs.record.arrays(), a, a, runs.model)
    assert_states_agree(runs.state, single.state)
    assert runs.integrator.iterations == single.integrator.iterations


@needs_kernel
def test_a_call_steps_from_the_state_given_whichever_its_buffers_hold():
    """
    A compiled call starts from the state it is given, bit for bit, whatever its buffers hold.

    The buffers keep the state the last call reached, which the next call of a run starts
    from without copying it in again; a call from another state (a copy of that one, an
    earlier one: the lock's root find steps from one state again and again) loads it.  Two
    identical runs, one stepping on from the state its buffers hold, the other from a copy;
    then both from an earlier state: the same rows and states.
    """
    p = UmbrellaRibsParams.from_mapping(ASYMMETRIC)
    own = UmbrellaSimulator3D(p, kernel='compiled')
    copied = UmbrellaSimulator3D(p, kernel='compiled')
    own.advance(30)
    copied.advance(30)
    earlier = own.state
    own.advance(20)
    copied.advance(20)
    outcomes = []
    for sim, start in ((own, own.state), (copied, replace(copied.state, t=copied.state.t)),
                       (own, earlier), (copied, replace(earlier, t=earlier.t))):
        status, done, rows, state = sim.integrator.compiled.advance(
            start, round(start.t / sim.h), sim.h, 10, sim.force, False)
        outcomes.append((status, done, {k: v.copy() for k, v in rows.items()}, state))
    for first, second in (outcomes[:2], outcomes[2:]):
        assert first[:2] == second[:2]
        for name in first[2]:
            np.testing.assert_array_equal(first[2][name], second[2][name], err_msg=name)
        for name in ('qr', 'qs', 'vr', 'vs', 'lam_r', 'lam_s', 'stuck', 'pr', 'ps'):
            np.testing.assert_array_equal(getattr(first[3], name), getattr(second[3], name),
                                          err_msg=name)
    # (and from the earlier state, not from where the buffers were: the run's own step 40,
    # to the Newton tolerance its kept iteration matrix allows)
    alpha1 = own.record.arrays()['alpha1'][40]
    np.testing.assert_allclose(outcomes[2][3].qr[:, own.model.i_a1], alpha1, rtol=0, atol=1e-9)


@needs_kernel
@pytest.mark.parametrize('base', BASES)
def test_compiled_stress_figures_equal_record3d_numpy(base):
    """
    The compiled step's stress figures are Record3D's (numpy) of the same steps, to round-off.

    Two compiled runs through the lock and 5 ms past it, one whose rows carry the figures
    (_kernel3d_figures.h), one whose Record3D computes them from the rows' states: the
    states are the same bit for bit; each rib's largest of every component and von Mises,
    the Hermite crest of every step, agree to the round-off of the recovery's sums (1e-12 of
    the component's largest), the places (body, x) and the peaks' places and instants equal.
    """
    p = UmbrellaRibsParams.from_mapping(dict(ASYMMETRIC, **BASES[base], **AT_SPEED))
    assert_compiled_figures_are_record3ds(p, deploying=700, rtol=0.0, floor=1e-12,
                                          peak_rtol=1e-12)


def assert_compiled_figures_are_record3ds(p: UmbrellaRibsParams, deploying: int, rtol: float,
                                          floor: float, peak_rtol: float):
    """
    Assert two compiled runs of p through the lock and 5 ms past it agree, figures aside.

    The first run's rows carry the compiled step's stress figures, the second's Record3D
    computes them from the rows' states: every other row equal bit for bit (more than
    `deploying` steps before the lock, 40 after), each stress channel within rtol and floor
    times its largest, the run's peaks within peak_rtol, their places and instants equal.
    """
    runs = UmbrellaSimulator3D(p, kernel='compiled'), UmbrellaSimulator3D(p, kernel='compiled')
    runs[1].integrator.compiled.set_figures(False)
    assert runs[0].integrator.compiled.figures and not runs[1].integrator.compiled.figures
    a, b = (sim.run(1.0, after_lock=0.005).arrays() for sim in runs)
    assert np.count_nonzero(b['locked']) > 40 and np.count_nonzero(~b['locked']) > deploying
    assert a.keys() == b.keys()
    for name in a:
        if name.startswith('stress_') and not name.endswith('_at') or name == 'von_mises':
            scale = np.max(np.abs(b[name]))
            assert scale > 0.0, name
            np.testing.assert_allclose(a[name], b[name], rtol=rtol, atol=floor * scale,
                                       err_msg=name)
        else:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    for name, peak in runs[1].record.peak.items():
        np.testing.assert_allclose(runs[0].record.peak[name], peak, rtol=peak_rtol,
                                   err_msg=name)
        assert runs[0].record.peak_where[name] == runs[1].record.peak_where[name]


def test_numpy_path_when_the_library_is_absent(monkeypatch, capfd):
    """No library: the numpy reference steps, and says so once; 'compiled' is an error."""
    monkeypatch.setattr(integrator3d, 'load_kernel', lambda: None)
    monkeypatch.setattr(integrator3d, 'kernel_refusal', lambda: None)
    monkeypatch.setattr(integrator3d, '_SAID', set())
    p = UmbrellaRibsParams.from_mapping({'ribs': 2, 'time_step': 1e-4})
    for _ in range(2):
        sim = UmbrellaSimulator3D(p)
        assert sim.integrator.backend == 'numpy'
    err = capfd.readouterr().err
    assert err.count('not built') == 1 and 'numpy reference path' in err
    sim.run(0.001)
    assert sim.k == 10
    with pytest.raises(RuntimeError, match='not built'):
        UmbrellaSimulator3D(p, kernel='compiled')


@needs_kernel
@pytest.mark.parametrize('base', ['prescribed', 'free'])
def test_a_moving_base_steps_compiled_without_a_word(base, capfd):
    """A driven hub or a free bus take the compiled step (auto), with the stage-2 fit."""
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': 2, 'time_step': 1e-4, **BASES[base]}))
    assert sim.integrator.backend == 'compiled' and sim.mode_fit
    assert sim.integrator.mode_fit.whole == (base == 'free')
    assert capfd.readouterr().err == ''
    with pytest.raises(ValueError, match="kernel='fast': must be auto, compiled or numpy"):
        MidpointUmbrella(sim.model, kernel='fast')


def test_a_bad_kernel_choice_in_the_environment_is_named(monkeypatch):
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', 'fast')
    with pytest.raises(ValueError, match="UMBRELLA_SIM_KERNEL='fast': must be auto"):
        UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({'ribs': 2}))


@needs_kernel
def test_a_failed_compiled_step_is_a_clear_error_that_keeps_the_steps_done():
    """Newton allowed one iteration: the run stops naming the step and why; the rows stay."""
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(ASYMMETRIC))
    sim.advance(3)
    sim.integrator.compiled.call.max_iter = 1
    with pytest.raises(SimulationFailed, match=r'after t = 0\.0003 s failed: Newton did not '
                       r'converge at t = 0\.0004 s'):
        sim.advance(5)
    assert sim.k == 3 and len(sim.record.arrays()['time']) == 4
    assert sim.state.t == pytest.approx(3e-4, abs=1e-15)


@needs_kernel
def test_a_failed_stage2_substep_is_named_at_its_own_end():
    """
    Stage 2 in substeps (0.2 ms grid, 0.1 ms physics steps): the failed step's end is named.

    Not the grid step's end: the step that failed is a physics step of h / substeps.
    """
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({'ribs': 2}))
    sim.run(1.0, after_lock=0.01)
    sub = sim.stage2_substeps
    assert sub == 2 and sim.h == pytest.approx(2e-4)
    sim.integrator.compiled.call.max_iter = 1
    t = sim.state.t
    with pytest.raises(SimulationFailed) as info:
        sim.advance(3)
    said = re.search(r'after t = ([0-9.]+) s failed: Newton did not converge at t = '
                     r'([0-9.]+) s', str(info.value))
    assert said and float(said[1]) == pytest.approx(sim.state.t, abs=1e-9)
    assert float(said[2]) == pytest.approx(sim.state.t + sim.h / sub, abs=1e-9)
    assert sim.state.t == pytest.approx(t, abs=1e-12)


@needs_kernel
def test_kept_iteration_matrix_reaches_the_fresh_matrix_solution():
    """
    The iteration matrix kept across steps changes how Newton converges, not to what.

    The compiled run (the matrix kept) against the numpy run that factors it every step
    (carry_steps 1, the planar scheme's rule): each step's solution differs by the Newton
    tolerance at most, so after k steps the positions agree within k times it; both runs
    balance energy and hold the joints.
    """
    p = UmbrellaRibsParams.from_mapping(ASYMMETRIC)
    kept = UmbrellaSimulator3D(p, kernel='compiled')
    a = kept.run(0.02).arrays()
    fresh = UmbrellaSimulator3D(p, kernel='numpy', carry_steps=1)
    b = fresh.run(0.02).arrays()
    steps = kept.k
    assert fresh.integrator.factorisations >= steps
    assert kept.integrator.factorisations < steps / 2
    length = max(np.max(kept.model.l1), np.max(kept.model.l3))
    bound = steps * kept.integrator.tolerance * length
    for name, lever in POSITIONS:
        arm = 1.0 if lever is None else getattr(kept.model, lever)
        assert np.max(np.abs((np.asarray(a[name]) - b[name]) * arm)) <= bound, name
    for sim in (kept, fresh):
        s = sim.record.summary()
        assert s['energy_balance_residual'] < 1e-9 * s['energy_scale']
        assert_on_the_joints(sim)


@needs_kernel
def test_a_leaf_at_the_axle_before_the_lock_is_a_fault_naming_the_rib():
    """
    The planar rule (a stage-1 leaf at alpha1 = pi/2 is a fault) holds for every rib.

    Started 2 deg from the fold with the sleeve moving and rib 1's hinge stuck: the stuck
    hinge clamps its leaf's root, the umbrella's momentum, through the sleeve and rib 1's
    link, bends that leaf (the hold, the root's moment, reaches ~60 N m) and the frame
    springs back past its start; rib 1's chord (alpha1), turned by the bending beyond the
    root it holds, reaches the axle first.  Both paths stop at the same step with the state
    of the last good one, and name the rib by it.
    """
    p = UmbrellaRibsParams.from_mapping({'ribs': 3, 'v0': -0.2, 'stick_until': [0.0, 0.2, 0.0]})
    ends = []
    for kernel in ('compiled', 'numpy'):
        sim = UmbrellaSimulator3D(p, kernel=kernel)
        with pytest.raises(SimulationFailed, match=r'rib 1: the leaf reached the axle'):
            sim.run(0.2)
        alpha1 = sim.state.qr[:, sim.model.i_a1]
        assert np.all(alpha1 < math.pi / 2) and alpha1[1] > alpha1[0]    # rib 1 bent
        assert alpha1[0] == pytest.approx(alpha1[2], abs=1e-12)          # 0 and 2: mirrors
        assert not np.isnan(sim.state.stuck[1])                          # still stuck
        assert len(sim.record.arrays()['time']) == sim.k + 1           # every good step kept
        ends.append((sim.k, alpha1))
    assert ends[0][0] == ends[1][0]
    assert ends[0][1] == pytest.approx(ends[1][1], abs=1e-9)
