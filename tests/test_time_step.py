"""
Test the time step: observed order, and the default step's accuracy.

The time step: observed order of convergence, and the default step's accuracy against a
fine-step run of the same code (the claims docs/validation.md tabulates in full).
"""
import pytest

from umbrella_sim.params import UmbrellaParams
from umbrella_sim.step_study import observed_order, run_steps, step_errors, TARGETS


@pytest.mark.parametrize("n_el", [1, 2])
@pytest.mark.parametrize("field", ["tip_transverse", "alpha1"])
def test_observed_order_is_two_in_the_asymptotic_range(n_el, field):
    """
    Check the observed order of convergence is two in the asymptotic range.

    Implicit midpoint: second order once every excited mode is resolved (the link's axial
    modes, ~3e5 rad/s, need h below ~1e-5 s): 4 ms of stage 1 at h = 8, 4, 2 us.
    """
    p = UmbrellaParams(v0=-0.5, elements_per_segment=n_el)
    assert observed_order(p, (8e-6, 4e-6, 2e-6), 0.004, field) == pytest.approx(2.0, abs=0.15)


@pytest.mark.parametrize("n_el, lock", [(1, "energy"), (2, "plastic")])
def test_default_step_against_a_fine_step_run(n_el, lock):
    """
    Check the default step against a fine-step run of the same code.

    V0 = -0.2 through the lock and 0.15 s of stage 2, default step vs 5 us: deploy time
    within 1e-5, stage-2 period within 0.05 %, stage-1 peak stresses within 3 %.
    """
    p = UmbrellaParams(v0=-0.2, elements_per_segment=n_el, lock=lock)
    window = 0.15
    fine = run_steps(p.replace(time_step=5e-6), window)
    default = run_steps(p, window)
    assert default.h == UmbrellaParams().time_step
    err = step_errors(default, fine, window)
    assert err["deploy_time"] < TARGETS["deploy_time"]
    assert err["stage2_period"] < TARGETS["stage2_period"]
    assert err["stage1_peak_leaf"] < TARGETS["peak_stress"]
    assert err["stage1_peak_link"] < TARGETS["peak_stress"]
    # and the step matters: at 40x the default step the period is off by more than that
    coarse = step_errors(run_steps(p.replace(time_step=2e-3), window), fine, window)
    assert coarse["stage2_period"] > TARGETS["stage2_period"]


@pytest.mark.parametrize("v0, needed", [(-0.5, 1e-5), (-2.0, 5e-6)])
def test_step_the_deploy_time_of_a_fast_deployment_needs(v0, needed):
    """
    Check the step a fast deployment's deploy time needs, against a fine-step run.

    N = 1: the deploy time moves with the phase of the link's axial vibration at the lock,
    which a step resolves from ~10 us down (docs/validation.md): within 1e-5 at the step
    the README names, against a 0.625 us run.
    """
    p = UmbrellaParams(v0=v0, elements_per_segment=1)
    ref = run_steps(p.replace(time_step=6.25e-7), 0.0).deploy_time
    err = abs(run_steps(p.replace(time_step=needed), 0.0).deploy_time - ref) / ref
    assert err < TARGETS["deploy_time"]
    if v0 == -2.0:   # the default step does not do it (README): 4.7e-5 when last measured
        default = run_steps(p, 0.0).deploy_time
        assert abs(default - ref) / ref > TARGETS["deploy_time"]


def test_step_the_stage2_targets_need():
    """
    Check the step the stage-2 tip series and peak stresses need.

    N = 1, V0 = -0.2, energy lock, 0.5 s of stage 2: with the link's axial modes resolved
    (5 us) the tip series is within 2 mm and (at N = 1; not in every case at N = 4, see
    docs/validation.md) the stage-2 peak stresses within 3 % of a
    2.5 us run, and the period within 0.05 %.
    """
    p = UmbrellaParams(v0=-0.2, elements_per_segment=1)
    window = 0.5
    fine = run_steps(p.replace(time_step=2.5e-6), window)
    err = step_errors(run_steps(p.replace(time_step=5e-6), window), fine, window)
    assert err["stage2_tip_series_m"] < TARGETS["stage2_tip_series_m"]
    assert err["stage2_peak_leaf"] < TARGETS["peak_stress"]
    assert err["stage2_peak_link"] < TARGETS["peak_stress"]
    assert err["stage2_period"] < TARGETS["stage2_period"]
