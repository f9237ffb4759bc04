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
The flexible model: thesis numbers, energy balance, constraints, the lock, mesh convergence.

Tolerances (stated in the closing note of the physics issue):
  * deployment time, N = 1: within 0.5 % of Table 6.1 (0.09040 / 0.04525 / 0.02343 s);
  * V0 = -0.2 stage-1 peak tip deflection within 3 % of 0.665 mm, its time within 5 ms of
    0.08 s (the thesis reads it off a plot);
  * stage-2 tip amplitude within 10 % of "about 60 mm", period within 10 % of "about 0.05 s".
"""
import numpy as np
import pytest

from umbrella_sim.core.driver import simulate
from umbrella_sim.core.integrators import PHI_TOLERANCE
from umbrella_sim.core.model import ConstraintSet, Stage
from umbrella_sim.core.outputs import mechanical_energy
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.rigid import deployment_time_by_quadrature
from umbrella_sim.core.solver import UmbrellaSimulator
from umbrella_sim.core.summary import energy_balance_error

THESIS_DEFORMABLE = {-0.5: 0.09040, -1.0: 0.04525, -2.0: 0.02343}


@pytest.fixture(scope='module')
def thesis_run():
    """
    V0 = -0.2, N = 1, energy lock, through the lock and 1 s of stage 2.

    At 0.25 ms: the
    thesis tolerances (>= 0.5 %) hold at any step up to that (tests/test_time_step.py and
    docs/validation.md measure the step error), and simulate() builds a Sample per step.
    """
    p = UmbrellaParams(v0=-0.2, time_step=2.5e-4)
    r = simulate(p, 1.0 + 0.2260)
    assert r.error is None
    return r


@pytest.mark.parametrize('v0', sorted(THESIS_DEFORMABLE))
def test_deployment_time_matches_table_6_1(v0):
    p = UmbrellaParams(v0=v0)
    r = simulate(p, 0.2, stop_after_lock=0.0)
    assert r.lock.time == pytest.approx(THESIS_DEFORMABLE[v0], rel=5e-3)
    # deformation delays deployment: never earlier than the rigid mechanism
    assert r.lock.time > deployment_time_by_quadrature(p)


def test_three_and_six_element_models_agree_at_v0_minus_1():
    times = [simulate(UmbrellaParams(v0=-1.0, elements_per_segment=n), 0.1,
                      stop_after_lock=0.0).lock.time for n in (1, 2)]
    for t in times:
        assert t == pytest.approx(0.0452, abs=0.00005)   # the thesis: "0.0452 s" for both
    # at the default step; the mesh-convergence test below checks 1e-4 at a fine step
    assert times[0] == pytest.approx(times[1], rel=5e-4)


def test_stage_one_tip_deflection(thesis_run):
    s = thesis_run.summary()
    assert s['tip_deflection_max'] == pytest.approx(0.665e-3, rel=0.03)
    assert s['tip_deflection_max_time'] == pytest.approx(0.08, abs=0.005)


def test_stage_two_vibration(thesis_run):
    s = thesis_run.summary()
    assert s['stage2_tip_amplitude'] == pytest.approx(0.060, rel=0.10)
    assert s['stage2_tip_period'] == pytest.approx(0.05, rel=0.10)


def test_peak_stresses_leaf_above_link(thesis_run):
    """Fig. 6.3 / 6.5: the leaf carries the higher stress, its peak at O''."""
    s = thesis_run.summary()
    assert s['peak_stress_leaf'] > s['peak_stress_link'] > 0
    assert s['peak_stress_leaf_x'] == pytest.approx(0.5, abs=1e-12)   # O'' = l1 along the leaf


def test_energy_conserved_without_force(thesis_run):
    """F_H = 0: total energy drifts < 1e-9 through stage 1 and 1 s of stage 2 (energy lock)."""
    assert thesis_run.lock.kind == 'energy'
    assert thesis_run.samples[-1].time >= thesis_run.lock.time + 1.0 - 1e-9
    assert thesis_run.summary()['energy_drift'] < 1e-9
    # (with stage 2's phase correction the integrator keeps T + V + its term)
    e = np.array([mechanical_energy(s) for s in thesis_run.samples])
    assert np.abs(e - e[0]).max() / e[0] < 1e-9


def test_constraint_residuals_over_one_second(thesis_run):
    assert thesis_run.summary()['constraint_residual_max'] < 1e-10


def test_energy_equals_work_with_force():
    p = UmbrellaParams(v0=-0.2, sleeve_force=3.0)
    r = simulate(p, 0.4)
    assert r.error is None and r.lock is not None
    err = energy_balance_error(r)
    work = r.column('work')
    assert work.max() > 0.1                              # the force did real work
    assert np.abs(err).max() / (2.107 + work.max()) < 1e-4


def test_lock_is_found_on_the_trajectory_not_at_the_next_step():
    sim = UmbrellaSimulator(UmbrellaParams(v0=-0.5))
    while sim.lock_event is None:
        sim.step()
    t_lock = sim.lock_event.time
    assert t_lock % sim.h > 1e-6          # not a grid point: the crossing was root-found
    # re-run to the lock instant with a step ending exactly there: the sleeve is at S
    sim2 = UmbrellaSimulator(UmbrellaParams(v0=-0.5))
    k = int(t_lock / sim2.h)
    sim2.advance_to(k * sim2.h, record=False)
    s = sim2.engine.step(sim2.state, t_lock - k * sim2.h, 0.0, 'deploying')
    gap = sim2.model.sleeve_height(s.q) - sim2.model.y_stop
    speed = abs(sim2.model.sleeve_height_gradient(s.q) @ s.qd)
    assert abs(gap) / speed < 1e-9                      # crossing time error, seconds


@pytest.mark.parametrize('lock', ['energy', 'plastic'])
def test_lock_velocity_redistribution(lock):
    p = UmbrellaParams(v0=-0.5, lock=lock)
    sim = UmbrellaSimulator(p)
    out = []
    while sim.lock_event is None:
        out = sim.step()
    ev = sim.lock_event
    locked_sample = out[0]
    m = sim.model
    cs = ConstraintSet(locked=True, rigid=False)
    assert np.abs(m.constraint_jacobian(locked_sample.q, cs) @ locked_sample.qd).max() < 1e-12
    assert abs(locked_sample.sleeve_velocity) < 1e-12
    if lock == 'energy':
        assert ev.energy_after == pytest.approx(ev.energy_before, rel=1e-12)
        assert set(ev.free_velocities) == {'alpha1', 'alpha2', 'R2x', 'R2y', 'link.u1'}
    else:
        assert ev.energy_after < ev.energy_before
    # after the lock the sleeve stays at S at every step, within the solver's constraint
    # tolerance, and a force has no effect on the motion: the stop takes it (a twin run
    # without the force moves the same to the Newton tolerance)
    twin = UmbrellaSimulator(p)
    while twin.lock_event is None:
        twin.step()
    sim.set_sleeve_force(50.0)
    steps = round(0.05 / sim.h)
    block = sim.advance(steps)
    assert block.error is None and len(block) == steps
    assert np.abs(block.sleeve_position - m.y_stop).max() < PHI_TOLERANCE
    twin_block = twin.advance(steps)
    assert twin_block.error is None and twin_block.sleeve_force.max() == 0.0
    assert block.sleeve_force.min() == 50.0
    assert np.abs(sim.state.q - twin.state.q).max() < 1e-8


def test_mesh_convergence_of_deployment_time_and_period():
    """N = 1, 2, 4, 8 (small step to isolate the spatial error)."""
    deploy, period = {}, {}
    for n in (1, 2, 4, 8):
        deploy[n] = simulate(UmbrellaParams(v0=-1.0, elements_per_segment=n, time_step=2.5e-4),
                             0.1, stop_after_lock=0.0).lock.time
        r = simulate(UmbrellaParams(v0=-0.2, elements_per_segment=n, time_step=5e-4),
                     0.6, stop_after_lock=0.35)
        period[n] = r.summary()['stage2_tip_period']
    for n in (1, 2, 4):
        assert deploy[n] == pytest.approx(deploy[8], rel=1e-4)
        assert period[n] == pytest.approx(period[8], rel=5e-3)
    assert abs(period[4] - period[8]) < abs(period[1] - period[8])


def test_scheme_balances_energy_before_the_energy_scaling(monkeypatch):
    """
    Check the scheme's own energy balance, before the energy scaling.

    The velocity projection is scaled to the discrete energy balance (exact by
    construction); the scaling only corrects the Newton tolerance and the projection's
    O(h^4) sliver.  Without it the scheme itself must still balance energy closely:
    numpy reference, scaling disabled, F_H = 2 N, through the lock and 0.1 s of stage 2.
    """
    from umbrella_sim.core import integrators
    monkeypatch.setattr(integrators, 'ENERGY_RESTORE_LIMIT', 1.0 - 1e-300)   # never scale
    p = UmbrellaParams(v0=-0.5, sleeve_force=2.0, time_step=5e-4)
    sim = UmbrellaSimulator(p)
    sim.engine.integrator = integrators.MidpointDAE(sim.model, kernel='numpy')
    b = sim.advance(380)
    assert b.lock is not None and b.error is None
    err = mechanical_energy(b) - b.work + b.lock_energy_loss
    e0 = sim.engine.kinetic_energy(sim.engine.initial(2.0), Stage.DEPLOYING)
    # the scheme alone: ~3e-5 here (Newton tolerance and projection); the scaling makes it
    # round-off (test_energy_conserved_without_force, test_energy_equals_work_with_force)
    assert abs(err - err[0]).max() / (e0 + b.work.max()) < 1e-4


def test_stress_recovery_sign_and_fibres():
    """Top and bottom fibres carry u' -/+ c v'': their mean is the axial stress E u'."""
    r = simulate(UmbrellaParams(v0=-0.5), 0.05)
    s = r.samples[-1]
    top, bottom = s.leaf_stress
    mean = 0.5 * (top + bottom)
    m = UmbrellaSimulator(UmbrellaParams()).model
    e = s.q[m.s_leaf]
    # axial stress of the element O-O'' from its end displacements
    u_joint = e[m.leaf.elastic_index(1, 'u')]
    assert mean[0] == pytest.approx(72e9 * u_joint / 0.5, rel=1e-9)
    assert s.peak_stress_leaf == pytest.approx(np.abs(s.leaf_stress).max())


@pytest.mark.slow      # 9 s: the step chosen for 48 elements is 1.6 us
def test_sixteen_elements_per_segment():
    """The largest mesh (48 elements, 148 coordinates) through the lock and 20 ms past it."""
    r = simulate(UmbrellaParams(v0=-0.2, elements_per_segment=16), 0.4, stop_after_lock=0.02)
    s = r.summary()
    assert r.error is None and len(r.q_labels) == 148
    # mesh convergence: the deploy time of the one-element mesh, and near the rigid closed form
    coarse = simulate(UmbrellaParams(v0=-0.2), 0.4, stop_after_lock=0.0).lock.time
    assert s['deploy_time'] == pytest.approx(coarse, rel=1e-5)
    assert s['deploy_time'] == pytest.approx(
        deployment_time_by_quadrature(UmbrellaParams(v0=-0.2)), rel=1e-3)
    assert s['constraint_residual_max'] < 1e-10 and s['energy_drift'] < 1e-4


@pytest.mark.slow      # ~2.5 s
def test_a_damped_frame_at_rest_has_dissipated_the_energy_it_had_after_the_lock():
    """
    Damping brings the locked frame to rest: T and V go to zero, whatever the integration.

    In stage 2 the damping takes exactly the energy T + V the frame had just after the lock
    (no force acts), with stage 2's mode fit as without it: the fit's energy is the physical
    one.  The earlier phase correction changed the modal masses and kept a term of its own
    (0.59 J of a V0 = -1 run like this one): the damping took 1.2-1.6 % less than the energy
    at the lock.
    """
    for pc in (True, False):
        r = simulate(UmbrellaParams(v0=-1.0, damping_ratio=0.3, lock='plastic',
                                    phase_correction=pc), 1.0)
        end = r.samples[-1]
        assert end.strain_energy < 1e-12 and end.kinetic_energy < 1e-12      # at rest
        assert r.summary()['energy_drift'] < 1e-10                           # balance closes
        at_lock = r.column('time') <= r.lock.time
        stage2 = end.damping_dissipation - r.column('damping_dissipation')[at_lock][-1]
        assert r.column('work')[-1] == r.column('work')[at_lock][-1]         # F_H = 0
        assert stage2 == pytest.approx(r.lock.energy_after, rel=1e-9)
