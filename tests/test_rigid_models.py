"""
Three independent rigid answers agree.

The closed-form two-angle model (Eq. 4.125,
corrected), the FE model with elastic coordinates constrained (Case 3), and the work-energy
quadrature t = int d(alpha1)/|alpha1'|.
"""
import math

import pytest

from umbrella_sim.params import UmbrellaParams
from umbrella_sim.rigid import deployment_time_by_quadrature, RigidMechanism
from umbrella_sim.solver import simulate

# rigid-model deployment times computed independently by energy quadrature of the closed-form
# rigid mechanism (Hu 2006, Eq. 4.120-4.125)
REFERENCE = {-0.2: 0.2258847, -0.5: 0.0903539, -1.0: 0.0451769, -2.0: 0.0225885}


@pytest.mark.parametrize("v0", sorted(REFERENCE))
def test_quadrature_reproduces_reference_table(v0):
    assert deployment_time_by_quadrature(UmbrellaParams(), v0) == \
        pytest.approx(REFERENCE[v0], abs=6e-8)


def test_initial_velocity_and_energy():
    mech = RigidMechanism(UmbrellaParams())
    y = mech.initial_state(-0.2)
    assert y[2] == pytest.approx(-6.367245, abs=1e-6)
    assert mech.kinetic_energy(*y) == pytest.approx(2.10703, abs=1e-5)


@pytest.mark.parametrize("model", ["rigid", "rigid-fe"])
@pytest.mark.parametrize("v0", sorted(REFERENCE))
def test_rigid_models_agree_with_quadrature(model, v0):
    p = UmbrellaParams(model=model, v0=v0)
    r = simulate(p, 0.3, stop_after_lock=0.0)
    assert r.error is None
    exact = deployment_time_by_quadrature(p)
    assert r.lock.time == pytest.approx(exact, rel=5e-4)          # 0.05 %
    assert r.summary()["constraint_residual_max"] < 1e-10


@pytest.mark.parametrize("model", ["rigid", "rigid-fe"])
def test_rigid_models_with_constant_force_from_rest(model):
    p = UmbrellaParams(model=model, v0=0.0, sleeve_force=2.0)
    exact = deployment_time_by_quadrature(p)
    r = simulate(p, 3.0, stop_after_lock=0.0)
    assert r.error is None
    assert r.lock.time == pytest.approx(exact, rel=5e-4)
    # work-energy along the way: T = W (the force's work) at every sample
    for s in r.samples[1:]:
        if s.stage == "deploying":
            assert s.kinetic_energy == pytest.approx(s.work, rel=1e-4, abs=1e-9)


def test_rigid_models_come_to_rest_at_the_lock():
    for model in ("rigid", "rigid-fe"):
        r = simulate(UmbrellaParams(model=model, v0=-1.0), 0.08)
        last = r.samples[-1]
        assert last.stage == "locked"
        assert last.alpha1 == pytest.approx(math.pi / 12, abs=1e-9)
        assert abs(last.alpha1_rate) < 1e-12
        assert r.lock.energy_after == pytest.approx(0.0, abs=1e-12)
