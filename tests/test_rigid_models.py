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
Three independent rigid answers agree.

The closed-form two-angle model (Eq. 4.125,
corrected), the FE model with elastic coordinates constrained (Case 3), and the work-energy
quadrature t = int d(alpha1)/|alpha1'|.
"""
import math

import pytest

from umbrella_sim.core.driver import simulate
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.rigid import deployment_time_by_quadrature, RigidMechanism

# rigid-model deployment times computed independently by energy quadrature of the closed-form
# rigid mechanism (Hu 2006, Eq. 4.120-4.125)
REFERENCE = {-0.2: 0.2258847, -0.5: 0.0903539, -1.0: 0.0451769, -2.0: 0.0225885}


@pytest.mark.parametrize('v0', sorted(REFERENCE))
def test_quadrature_reproduces_reference_table(v0):
    assert deployment_time_by_quadrature(UmbrellaParams(), v0) == \
        pytest.approx(REFERENCE[v0], abs=6e-8)


def test_initial_velocity_and_energy():
    mech = RigidMechanism(UmbrellaParams())
    y = mech.initial_state(-0.2)
    assert y[2] == pytest.approx(-6.367245, abs=1e-6)
    assert mech.kinetic_energy(*y) == pytest.approx(2.10703, abs=1e-5)


@pytest.mark.parametrize('model', ['rigid', 'rigid-fe'])
@pytest.mark.parametrize('v0', sorted(REFERENCE))
def test_rigid_models_agree_with_quadrature(model, v0):
    p = UmbrellaParams(model=model, v0=v0)
    r = simulate(p, 0.3, stop_after_lock=0.0)
    assert r.error is None
    exact = deployment_time_by_quadrature(p)
    assert r.lock.time == pytest.approx(exact, rel=5e-4)          # 0.05 %
    assert r.summary()['constraint_residual_max'] < 1e-10


@pytest.mark.parametrize('model', ['rigid', 'rigid-fe'])
def test_rigid_models_with_constant_force_from_rest(model):
    p = UmbrellaParams(model=model, v0=0.0, sleeve_force=2.0)
    exact = deployment_time_by_quadrature(p)
    r = simulate(p, 3.0, stop_after_lock=0.0)
    assert r.error is None
    assert r.lock.time == pytest.approx(exact, rel=5e-4)
    # work-energy along the way: T = W (the force's work) at every sample
    for s in r.samples[1:]:
        if s.stage == 'deploying':
            assert s.kinetic_energy == pytest.approx(s.work, rel=1e-4, abs=1e-9)


def test_rigid_models_come_to_rest_at_the_lock():
    for model in ('rigid', 'rigid-fe'):
        r = simulate(UmbrellaParams(model=model, v0=-1.0), 0.08)
        last = r.samples[-1]
        assert last.stage == 'locked'
        assert last.alpha1 == pytest.approx(math.pi / 12, abs=1e-9)
        assert abs(last.alpha1_rate) < 1e-12
        assert r.lock.energy_after == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize('v0, force', [(-0.2, 0.0), (0.0, 50.0)])
def test_closed_form_fast_path_steps_as_the_generic_path(monkeypatch, v0, force):
    """
    The closed-form model's blocks (RigidEngine.advance) equal step-by-step stepping.

    Stage 1, the lock (taken by the simulator's own step in both) and stage 2: the same
    rows, lock and final state; the sleeve velocity comes from the angles' rates in the
    block and from the FE configuration in a Sample, so it agrees to round-off.
    """
    from umbrella_sim.core.engines import RigidEngine
    from umbrella_sim.core.outputs import STEP_FIELDS, step_row
    from umbrella_sim.core.solver import UmbrellaSimulator

    p = UmbrellaParams(model='rigid', v0=v0, sleeve_force=force)
    fast = UmbrellaSimulator(p)
    blocks = [fast.advance(100) for _ in range(30)]
    monkeypatch.setattr(RigidEngine, 'advance', lambda self, *args: None)   # generic path
    slow = UmbrellaSimulator(p)
    generic = [slow.advance(100) for _ in range(30)]
    assert fast.lock_event is not None and fast.lock_event == slow.lock_event
    for b, g in zip(blocks, generic):
        for i, field in enumerate(STEP_FIELDS):
            tol = 1e-14 * max(1.0, abs(g.rows[i]).max()) if field == 'sleeve_velocity' else 0.0
            assert abs(b.rows[i] - g.rows[i]).max() <= tol, field
    assert step_row(fast.sample()) == step_row(slow.sample())
    assert fast.state.t == slow.state.t and (fast.state.q == slow.state.q).all()


def test_the_rigid_umbrella_sums_its_ribs_through_the_sleeve():
    """
    RigidUmbrella: N rigid ribs on one sleeve, in the ribs' mean leaf angle q.

    Identical ribs are N planar frames (M and the lever N times the planar ones); a tip
    mass at G adds its moment m (l1 + l2)^2 to its rib; a rib of its own lengths stands at
    its own angle, every rib at the one sleeve height, their mean q, and dy/dq is the
    sleeve's own slope.
    """
    from umbrella_sim.core.rigid import RigidUmbrella
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams

    planar = UmbrellaParams()
    frame = RigidMechanism(planar)
    one = RigidUmbrella(planar)
    three = RigidUmbrella(UmbrellaRibsParams.from_mapping({'ribs': 3}))
    for q in (0.4, 1.0, 1.5):
        assert one.inertia(q) == frame.generalized_mass(q)
        assert one.lever(q) == frame.sleeve_lever(q)
        assert three.inertia(q) == pytest.approx(3 * frame.generalized_mass(q), rel=1e-14)
        assert three.lever(q) == pytest.approx(3 * frame.sleeve_lever(q), rel=1e-14)
    assert (three.alpha0, three.alpha_deployed) == (planar.alpha0, planar.alpha_deployed)
    tip = RigidUmbrella(UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib2.tip_mass': 0.05}))
    added = 0.05 * (planar.l1 + planar.l2) ** 2
    assert tip.inertia(1.0) - three.inertia(1.0) == pytest.approx(added, rel=1e-12)
    own = RigidUmbrella(UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib0.l3': 0.55}))
    for q in (own.alpha_deployed, 1.0, own.alpha0):
        y, angles = own.sleeve_and_angles(q)
        assert angles[0] < angles[1] == angles[2]   # the longer link: a lower leaf
        assert math.fsum(angles) / 3 == pytest.approx(q, abs=1e-14)
        for mech, a in zip(own.mechs, angles):
            assert mech.sleeve_height(a, mech.alpha2(a)) == pytest.approx(y, abs=1e-14)
        h = 1e-6
        slope = (own.sleeve_height(q + h) - own.sleeve_height(q - h)) / (2 * h)
        assert own.lever(q) == pytest.approx(3 * slope, rel=1e-7)
    for q, y in ((own.alpha0, planar.sleeve_start_height),
                 (own.alpha_deployed, planar.sleeve_stop_height)):
        assert own.sleeve_height(q) == pytest.approx(y, abs=1e-14)
