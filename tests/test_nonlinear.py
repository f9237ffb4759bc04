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
The geometrically nonlinear model (flexible-nonlinear) and structural damping.

Tolerances and why:
  * strain energy: gradient and tangent against central differences (1e-8 relative), the AVF
    discrete gradient's identity dq . G = U(q1) - U(q0) to round-off;
  * small motion: deployment time within 1e-5 of the linear model at V0 = -0.2 and -0.1; the
    stage-1 tip deflection differs by the von Karman terms the linear model lacks, which
    vanish with the motion: within 0.5 % at V0 = -0.1, 1 % at V0 = -0.2 (see the test);
  * energy: F = 0 drift < 1e-4 through the lock and stage 2, as the linear model;
  * damping: logarithmic decrement of the stage-2 tip vibration = zeta within 5 %;
  * spin-up benchmark (Kane, Ryan & Banerjee, J. Guidance Control Dynamics 10(2):139-151,
    1987; data as in the AeroBeams.jl "spinupRobotArm" example: L = 10 m, EA = 2.8e7 N,
    EI = 1.4e4 N m^2, rho A = 1.2 kg/m, Omega = 6 rad/s, T = 15 s): the published finding is
    that the conventional linear model diverges once the spin rate passes the first bending
    frequency (3.516 sqrt(EI / rho A L^4) = 3.80 rad/s, at t ~ 8.5 s) while a model with
    geometric stiffening stays bounded.  The digitised published curve was not available to
    us, so the nonlinear tip deflection is checked against an independent reference: the
    quasi-static deflection of the spinning cantilever under its Euler load rho A theta'' x
    with the exact centrifugal tension N = rho A w^2 (L^2 - x^2)/2, from a boundary-value
    solver (no finite elements) -- within 0.03 m (5 % of the 0.57 m peak; the difference is
    the small free vibration the ramp excites); after the spin-up the axial tip stretch
    equals rho W^2 L^3 / (3 E) (exact for the spinning bar) within 1 %.
"""
import math

import numpy as np
import pytest

from umbrella_sim.core.driver import simulate
from umbrella_sim.core.integrators import load_kernel, newton_tolerance
from umbrella_sim.core.model import ConstraintSet, Stage
from umbrella_sim.core.nonlinear import ElasticMidpointDAE, NonlinearUmbrellaModel
from umbrella_sim.core.outputs import STEP_FIELDS
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.rotating_beam import (KANE_BEAM, rotating_cantilever_chordwise,
                                             ROTATING_CANTILEVER_FLAPWISE,
                                             rotating_cantilever_frequency, spin_up, spin_up_angle,
                                             spin_up_quasi_static_tip)
from umbrella_sim.core.solver import UmbrellaSimulator
from umbrella_sim.core.summary import energy_balance_error

NL = "flexible-nonlinear"
# these tests' figures were made at a 2 ms step: it keeps the suite short (the default 5e-5 s
# takes 40x the steps) and puts Newton's re-factoring and line search to work
STEP = 2e-3


def P(**kw):  # noqa: N802 (reads like the UmbrellaParams it builds)
    return UmbrellaParams(**{"time_step": STEP, **kw})


def test_strain_energy_gradient_tangent_and_discrete_gradient():
    m = NonlinearUmbrellaModel(UmbrellaParams(model=NL, elements_per_segment=2))
    rng = np.random.default_rng(1)
    q0 = m.rigid_configuration(0.7)
    q0[m.elastic_indices] = 2e-2 * rng.standard_normal(len(m.elastic_indices))
    q1 = q0.copy()
    q1[m.elastic_indices] += 2e-2 * rng.standard_normal(len(m.elastic_indices))
    u, eye, d = m.strain.energy, np.eye(m.n), 1e-7
    fd_grad = np.array([(u(q0 + d * e) - u(q0 - d * e)) / (2 * d) for e in eye])
    grad = m.elastic_force(q0)
    assert np.abs(grad - fd_grad).max() < 1e-8 * np.abs(grad).max()
    fd_tan = np.array([(m.elastic_force(q0 + d * e) - m.elastic_force(q0 - d * e)) / (2 * d)
                       for e in eye])
    tan = m.strain.tangent(q0)
    assert np.abs(tan - fd_tan).max() < 1e-8 * np.abs(tan).max()
    avf = m.strain.discrete_gradient(q0, q1)
    assert (q1 - q0) @ avf == pytest.approx(u(q1) - u(q0), rel=1e-12)
    # the nonlinear part is real here: U differs from the linear 1/2 q.K q
    assert abs(u(q1) - 0.5 * q1 @ m.stiffness @ q1) > 1e-3 * u(q1)
    # and vanishes to second order: at 1e-6 of the motion U is the linear one
    small = q0.copy()
    small[m.elastic_indices] *= 1e-6
    assert u(small) == pytest.approx(0.5 * small @ m.stiffness @ small, rel=1e-5)


@pytest.fixture(scope="module")
def runs_v02():
    """V0 = -0.2, N = 1, both models through the lock and 0.35 s of stage 2."""
    return {model: simulate(P(v0=-0.2, model=model), 0.6)
            for model in ("flexible", NL)}


def test_reduces_to_linear_model_for_small_motion(runs_v02):
    """
    The nonlinear model tends to the linear one as the motion gets small.

    Deploy time within 1e-5 (the tolerance asked).  Stage-1 tip deflection: the difference
    is the cubic and quartic terms of U (the von Karman coupling of the leaf's axial force,
    ~4 N at V0 = -0.2, with its bending), so it grows like the motion, ~V0^2: -0.54 % at
    V0 = -0.2 and -0.14 % at -0.1 at the default step (N = 8), -0.73 % / -0.24 % at this
    test's 2 ms (docs/validation_nonlinear.md, "Small motion").  The issue's 0.5 % holds at
    V0 = -0.1; at V0 = -0.2 the bound is 1 % (physics, not discretisation: the two models
    share every other term, and a discretisation mismatch would not vanish with V0).
    """
    lin, nl = (runs_v02[k].summary() for k in ("flexible", NL))
    assert runs_v02[NL].error is None
    assert nl["deploy_time"] == pytest.approx(lin["deploy_time"], rel=1e-5)
    diff_02 = nl["tip_deflection_max"] / lin["tip_deflection_max"] - 1.0
    assert -0.01 < diff_02 < 0.0                 # stiffening: less deflection, under 1 %
    slow = [simulate(P(v0=-0.1, model=model), 0.6, stop_after_lock=0.0).summary()
            for model in ("flexible", NL)]
    assert slow[1]["deploy_time"] == pytest.approx(slow[0]["deploy_time"], rel=1e-5)
    diff_01 = slow[1]["tip_deflection_max"] / slow[0]["tip_deflection_max"] - 1.0
    assert abs(diff_01) < 0.005                   # the 0.5 % asked
    assert 2.5 < diff_02 / diff_01 < 5.0          # ~V0^2: it vanishes with the motion
    # stage 2 at this amplitude is close to linear too
    assert nl["stage2_tip_period"] == pytest.approx(lin["stage2_tip_period"], rel=0.03)
    assert nl["stage2_tip_amplitude"] == pytest.approx(lin["stage2_tip_amplitude"], rel=0.03)


def test_energy_conserved_without_force(runs_v02):
    """F = 0: AVF gradient + energy-restoring projection balance every step (1e-6 shown)."""
    r = runs_v02[NL]
    assert r.lock.kind == "energy" and r.samples[-1].time > r.lock.time + 0.3
    s = r.summary()
    assert s["energy_drift"] < 1e-6
    assert s["constraint_residual_max"] < 1e-10
    fast = simulate(P(v0=-1.0, model=NL), 0.12).summary()   # large motion
    assert fast["energy_drift"] < 1e-6 and fast["constraint_residual_max"] < 1e-10


def test_energy_equals_work_with_force():
    r = simulate(P(v0=-0.2, sleeve_force=3.0, model=NL), 0.3)
    assert r.error is None and r.lock is not None
    work = r.column("work")
    assert work.max() > 0.1
    assert np.abs(energy_balance_error(r)).max() / (2.107 + work.max()) < 1e-4


def test_stress_recovery_uses_the_membrane_strain(runs_v02):
    """Mean of the fibres = E (1/l_e) int (u' + v'^2/2) dx of the element O-O''."""
    s = runs_v02[NL].samples[-1]
    m = NonlinearUmbrellaModel(UmbrellaParams(model=NL))
    eps = m.strain.membrane_strain(s.q)
    top, bottom = s.leaf_stress
    assert 0.5 * (top[0] + bottom[0]) == pytest.approx(72e9 * eps[0], rel=1e-9)
    u_joint = s.q[1 + m.leaf.elastic_index(1, "u")]
    assert abs(eps[0] - u_joint / 0.5) > 1e-3 * abs(eps[0])   # the v'^2/2 part is there


def _log_decrement_ratio(r):
    """
    Return the damping ratio from the decay of the stage-2 tip peaks.

    Both signs of peak (half cycles), parabolic peak interpolation, least-squares slope of
    ln|peak|; measured from v = 0, the equilibrium of the locked, unloaded frame (no gravity,
    and F_H no longer acts).
    """
    v = r.column("tip_transverse")
    locked = np.array([s.stage == "locked" for s in r.samples])
    v = v[locked][5:]
    peaks = []
    for i in range(1, len(v) - 1):
        for sign in (1.0, -1.0):
            a, b, c = sign * v[i - 1], sign * v[i], sign * v[i + 1]
            if b > a and b >= c and b > 0.3 * np.abs(v).max():
                peaks.append(b - 0.125 * (a - c) ** 2 / (a - 2 * b + c))
    assert len(peaks) >= 12
    delta = -2.0 * np.polyfit(np.arange(len(peaks)), np.log(peaks), 1)[0]   # per cycle
    return delta / math.sqrt(4 * math.pi ** 2 + delta ** 2)


@pytest.mark.parametrize("model", ["flexible", NL])
def test_damping_log_decrement_matches_ratio(model):
    """
    Log decrement of the stage-2 vibration equals zeta (first mode).

    zeta of the first stage-2 mode (at V0 = -0.2 the nonlinear model's stage-2 period is
    within 1 % of the linearised one the damping is defined on; at large amplitude the
    hardening raises the frequency, and a stiffness-proportional damping ratio with it).
    """
    zeta = 0.02
    p = P(v0=-0.2, model=model, damping_ratio=zeta)
    r = simulate(p, 2.0, stop_after_lock=0.4)
    assert r.error is None
    assert _log_decrement_ratio(r) == pytest.approx(zeta, rel=0.05)
    diss = r.column("damping_dissipation")
    assert diss[-1] > 0.3 * r.lock.energy_after            # damping took real energy
    assert np.all(np.diff(diss) >= 0.0)
    assert r.summary()["energy_drift"] < 1e-4              # ... and the balance reports it


def test_damping_zero_is_the_undamped_model():
    p = P(v0=-0.5)
    a = simulate(p, 0.12).samples[-1]
    b = simulate(p.replace(damping_ratio=1e-300), 0.12).samples[-1]   # numpy damped path
    assert np.abs(a.q - b.q).max() < 1e-9 and b.damping_dissipation < 1e-290


def test_phase_correction_is_the_linear_strains_only():
    """
    Stage 2's phase correction acts on the damped linear model, not on the nonlinear one.

    With the von Karman strain the axial coordinates follow the foreshortening of the bending,
    far from the linearised modes the correction is built on: there it stays off.
    """
    runs = {}
    for model, zeta in ((NL, 0.0), ("flexible", 0.01)):
        for pc in (True, False):
            r = simulate(P(v0=-0.5, model=model, damping_ratio=zeta, phase_correction=pc), 1.0,
                         stop_after_lock=0.05)
            runs[model, pc] = r.samples[-1].q
    assert np.array_equal(runs[NL, True], runs[NL, False])
    assert np.abs(runs["flexible", True] - runs["flexible", False]).max() > 1e-9


def test_bad_damping_ratio_is_refused_by_name():
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(ValueError, match="damping_ratio"):
            UmbrellaParams(damping_ratio=bad).validated()


def test_sixteen_elements_per_segment_nonlinear():
    r = simulate(P(v0=-0.5, model=NL, elements_per_segment=16), 0.1,
                 stop_after_lock=0.0)
    assert r.error is None and r.lock is not None
    assert r.summary()["energy_drift"] < 1e-4


# ------------------------------------------------------------ compiled path vs numpy
needs_kernel = pytest.mark.skipif(load_kernel() is None, reason="compiled kernel not built")


def _simulator(kernel, params):
    sim = UmbrellaSimulator(params)
    sim.engine.integrator = ElasticMidpointDAE(sim.model, kernel=kernel)
    return sim


@needs_kernel
@pytest.mark.parametrize("model, zeta, v0, t0, locked", [
    (NL, 0.0, -1.0, 0.02, False), (NL, 0.0, -2.0, 0.05, True), (NL, 0.02, -2.0, 0.01, False),
    (NL, 0.05, -1.0, 0.08, True), ("flexible", 0.02, -1.0, 0.02, False),
    ("flexible", 0.02, -1.0, 0.08, True)])
def test_compiled_elastic_step_matches_numpy_to_roundoff(model, zeta, v0, t0, locked):
    """
    From the same state, one step of the compiled path equals the numpy reference.

    _kernel.c with the law of _kernel_nonlinear.c against ElasticMidpointDAE's numpy step,
    in stage 1 and stage 2 (t0 past the lock), large steps (Newton with re-factoring and
    line search at work): q to 1e-13 m, velocities, momenta, multipliers and the dissipated
    energy to 1e-12 relative.
    """
    p = P(v0=v0, model=model, damping_ratio=zeta, elements_per_segment=2)
    sim = _simulator("numpy", p)
    sim.advance_to(t0, record=False)
    assert (sim.stage == Stage.LOCKED) == locked
    cs = ConstraintSet(locked=sim.stage == Stage.LOCKED, rigid=False)
    a = ElasticMidpointDAE(sim.model, kernel="numpy").step(sim.state, 2e-3, 0.5, cs)
    compiled = ElasticMidpointDAE(sim.model, kernel="compiled")
    assert compiled.backend == "compiled"
    b = compiled.step(sim.state, 2e-3, 0.5, cs)
    assert np.abs(a.q - b.q).max() < 1e-13
    assert np.abs(a.qd - b.qd).max() < 1e-12 * np.abs(a.qd).max()
    assert np.abs(a.momentum - b.momentum).max() < 1e-12 * np.abs(a.momentum).max()
    assert np.abs(a.multipliers - b.multipliers).max() < 1e-12 * np.abs(a.multipliers).max()
    assert b.dissipation == pytest.approx(a.dissipation, rel=1e-12, abs=1e-300)
    assert (a.dissipation > sim.state.dissipation) == (zeta > 0)


@needs_kernel
@pytest.mark.parametrize("zeta", [0.0, 0.02])
def test_compiled_elastic_blocks_match_numpy_run(zeta):
    """
    The compiled loop's StepBlocks equal the numpy path's per-step outputs.

    V0 = -1 through the lock: every STEP_FIELDS entry (strain energy and fibre stresses with
    the membrane strain included) and the dissipated energy of the final state.
    """
    p = P(v0=-1.0, model=NL, damping_ratio=zeta, elements_per_segment=2)
    runs = {}
    for kernel in ("numpy", "compiled"):
        sim = _simulator(kernel, p)
        blocks = [sim.advance(k) for k in (7, 13, 30)]
        assert all(b.error is None for b in blocks)
        rows = np.hstack([np.array([getattr(b, f) for f in STEP_FIELDS]) for b in blocks])
        runs[kernel] = (rows, blocks[-1].last, sim)
    (ref, ref_last, ref_sim), (fast, fast_last, fast_sim) = runs["numpy"], runs["compiled"]
    assert ref_sim.lock_event is not None and fast_sim.lock_event is not None
    assert fast_sim.lock_event.time == pytest.approx(ref_sim.lock_event.time, abs=1e-12)
    scale = np.maximum(1.0, np.abs(ref).max(axis=1))[:, None]
    assert np.max(np.abs(ref - fast) / scale) < 1e-7
    assert fast_last.damping_dissipation == pytest.approx(ref_last.damping_dissipation,
                                                          rel=1e-7, abs=1e-12)
    assert (fast_last.damping_dissipation > 1.0) == (zeta > 0)


@needs_kernel
def test_compiled_and_numpy_carry_the_same_iteration_matrices():
    """
    The carried-matrix rule is the same in the kernel and the numpy reference.

    Stage 2 at V0 = -1 and the default step and tolerance, where a step begins with a matrix
    up to CARRY_STEPS steps old and re-factors after a slow iteration: both paths take the
    same Newton iterations block by block, and the same steps to ~round-off.  (A rule that
    differed, e.g. by a step in the matrix's age, changes the counts.)  The states agree to
    the Newton tolerance (1e-8 m a step): the paths part at the lock at that level already
    (the compiled path's lock step is the single-step one), and stage 2 at V0 = -1 amplifies
    it.
    """
    p = P(v0=-1.0, model=NL, elements_per_segment=2, time_step=1e-4)
    runs = {}
    for kernel in ("numpy", "compiled"):
        sim = _simulator(kernel, p)
        integ = sim.engine.integrator
        integ.tolerance = newton_tolerance(p.time_step)
        sim.advance(500)                                   # through the lock (~0.045 s)
        assert sim.stage == Stage.LOCKED
        counts, rows = [], []
        for _ in range(4):
            before = integ.iterations
            block = sim.advance(60)
            rows.append(np.array([getattr(block, f) for f in STEP_FIELDS]))
            counts.append(integ.iterations - before)
        runs[kernel] = (counts, np.hstack(rows))
    (ref_counts, ref), (fast_counts, fast) = runs["numpy"], runs["compiled"]
    assert ref_counts == fast_counts
    assert sum(ref_counts) > 3 * 4 * 60    # ~4.6 iterations a step: the matrices age here
    for f in ("alpha1", "tip_axial", "tip_transverse"):          # rad, m
        i = STEP_FIELDS.index(f)
        assert np.max(np.abs(ref[i] - fast[i])) < 1e-7, f
    scale = np.maximum(1.0, np.abs(ref).max(axis=1))[:, None]
    assert np.max(np.abs(ref - fast) / scale) < 1e-5


@needs_kernel
def test_compiled_blocks_and_single_steps_agree_bit_for_bit():
    """
    The compiled loop and the single-step path give the same bits through the lock.

    The carried iteration matrix is a rule of the trajectory (a step starting where the
    last step ended, and how many steps that matrix served): the loop hands a step it cannot
    take (the crossing, a failed Newton solve, here at 2 ms with large motion) back with the
    carried matrix as it was, and the single-step path, which retakes it split in halves,
    sees what the loop saw.
    """
    p = P(v0=-1.0, model=NL, elements_per_segment=2)
    by_blocks = UmbrellaSimulator(p)
    blocks = [by_blocks.advance(k) for k in (7, 13, 30)]
    by_steps = UmbrellaSimulator(p)
    h = by_steps.h
    samples = by_steps.advance_to(50 * h)
    assert by_steps.engine.integrator.halvings > 0            # the fallback path was taken
    assert by_blocks.lock_event.time == by_steps.lock_event.time
    on_grid = [s for s in samples if abs(s.time / h - round(s.time / h))
               < 1e-9]
    assert len(on_grid) == 50
    assert np.array_equal(np.concatenate([b.tip_transverse for b in blocks]),
                          [s.tip_transverse for s in on_grid])
    assert np.array_equal(by_blocks.state.q, by_steps.state.q)


# ---------------------------------------------------------------- spin-up benchmark
def test_spin_up_benchmark_nonlinear_beam_stays_on_the_stiffened_response():
    t, u, v = spin_up(4, True, 18.0, 0.01)
    assert t[-1] == pytest.approx(18.0)
    for when in (2.0, 4.0, 6.0, 7.0, 8.0, 10.0, 12.0):
        i = int(np.searchsorted(t, when - 1e-9))
        assert v[i] == pytest.approx(spin_up_quasi_static_tip(when), abs=0.03)
    assert -0.65 < v.min() < -0.5                        # the lag peaks near t = 7 s
    after = t > 15.0
    stretch = 3000.0 * 36.0 * 10.0 ** 3 / (3 * 7e10)     # rho W^2 L^3 / (3 E)
    assert u[after].mean() == pytest.approx(stretch, rel=0.01)
    assert np.abs(v[after]).max() < 0.02                 # spun up: straight again


def test_spin_up_benchmark_linear_beam_diverges():
    """The known failure of the linear (premature-linearisation) model."""
    t, _, v = spin_up(4, False, 18.0, 0.01)
    first_bending = 3.516 * math.sqrt(KANE_BEAM["ei"] / (KANE_BEAM["mass_per_length"] * 10.0 ** 4))
    assert first_bending == pytest.approx(3.80, abs=0.01)
    assert np.abs(v).max() > 10.0 * KANE_BEAM["length"] or not np.all(np.isfinite(v))
    t_cross = next(tt for tt in np.arange(0, 15, 0.01) if spin_up_angle(tt)[1] > first_bending)
    assert t[-1] > t_cross                               # it left only after w > omega_1


def test_published_rotating_cantilever_table_is_transcribed_right():
    """
    Check the published flapwise table against an independent Rayleigh-Ritz solution.

    EI v'''' - (N v')' = omega^2 rho A v with N = rho A Omega^2 (L^2 - x^2) / 2, cantilever,
    dimensionless; polynomials x^2 .. x^10 (no finite elements): every tabulated value within
    5e-5 (the table's last digit).
    """
    from numpy.polynomial import legendre
    from scipy.linalg import eigh
    x, w = legendre.leggauss(40)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    powers = np.arange(2, 11)[:, None]
    phi, d1 = x ** powers, powers * x ** (powers - 1)
    d2 = powers * (powers - 1) * x ** (powers - 2)
    mass, bending = (phi * w) @ phi.T, (d2 * w) @ d2.T
    tension = (d1 * w * 0.5 * (1.0 - x * x)) @ d1.T
    for gamma, published in ROTATING_CANTILEVER_FLAPWISE.items():
        lam = eigh(bending + gamma ** 2 * tension, mass, eigvals_only=True)[0]
        assert math.sqrt(lam) == pytest.approx(published, abs=5e-5)


@pytest.mark.parametrize("gamma", [2, 4, 10])
def test_rotating_cantilever_nonlinear_beam_has_the_published_stiffened_frequency(gamma):
    """
    The nonlinear beam's in-plane frequency, spun at gamma, is the published stiffened one.

    N = 8 elements of our beam element on the Kane beam, dynamic run (spin-up, then free
    vibration at constant Omega): within 0.5 % of sqrt(lambda_f^2 - gamma^2), the published
    flapwise table less the in-plane centrifugal softening (rotating_cantilever_chordwise).
    """
    measured, amplitude = rotating_cantilever_frequency(gamma, 8, True)
    assert amplitude < 0.1                              # small vibration on a 10 m beam
    assert measured == pytest.approx(rotating_cantilever_chordwise(gamma), rel=5e-3)


@pytest.mark.parametrize("gamma", [2, 3])
def test_rotating_cantilever_linear_beam_misses_the_stiffening(gamma):
    """
    The linear strain (premature linearisation): softened, not stiffened.

    The linear model follows sqrt(3.516^2 - gamma^2) (no geometric stiffening), more than
    15 % below the published stiffened frequency; past gamma = 3.516 it diverges (spin-up).
    """
    measured, _ = rotating_cantilever_frequency(gamma, 8, False)
    softened = math.sqrt(ROTATING_CANTILEVER_FLAPWISE[0] ** 2 - gamma ** 2)
    assert measured == pytest.approx(softened, rel=5e-3)
    assert measured < 0.85 * rotating_cantilever_chordwise(gamma)


# ------------------------------------------------------------------ CLI and faults
def test_cli_runs_the_nonlinear_model_with_damping():
    import json
    import subprocess
    import sys
    r = subprocess.run([sys.executable, "-m", "umbrella_sim", "simulate", "--model", NL,
                        "--set", "damping_ratio=0.05", "--v0", "-1.0", "--duration", "0.1",
                        "--json"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["deploy_time"] == pytest.approx(0.0452, rel=5e-3) and s["energy_drift"] < 1e-4
    bad = subprocess.run([sys.executable, "-m", "umbrella_sim", "simulate", "--model", NL,
                          "--set", "damping_ratio=2"], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "damping_ratio" in bad.stderr and "Traceback" not in bad.stderr


def test_failed_nonlinear_solve_is_a_fault_that_keeps_the_log(monkeypatch):
    """
    Fault on a failed nonlinear solve, log kept.

    A force far beyond what the structure can carry (1 MN after 20 ms; the nonlinear model
    does survive 10 kN, which breaks the linear one): the solve fails, the samples before the
    failure are kept and the error names the time.  Commands are bounded by the link's
    buckling load (UmbrellaParams.sleeve_force_limit, 2.4 kN here); the bound is lifted so
    that the solver itself meets the force.
    """
    monkeypatch.setattr(UmbrellaParams, "sleeve_force_limit", property(lambda p: math.inf))
    r = simulate(P(v0=-0.2, model=NL), 0.1, force_profile=[(0.02, 1e6)])
    assert r.error is not None and "t = 0.02" in r.error
    assert len(r.samples) == 11 and r.samples[-1].time == pytest.approx(0.02)
    assert all(np.all(np.isfinite(s.q)) for s in r.samples)


@pytest.mark.ros
def test_node_runs_the_nonlinear_damped_model():
    """
    Node runs the nonlinear damped model over real DDS.

    model:=flexible-nonlinear damping_ratio:=0.05 over real DDS: it deploys and locks at the
    offline time, and the energy topic reports the dissipation inside a closed balance.
    """
    from std_msgs.msg import Float64MultiArray, String

    from tests.ros_helpers import NodeProcess, Probe
    from umbrella_sim.ros.messages import LATCHED
    probe = Probe()
    try:
        probe.subscribe("/deployment_phase", String, LATCHED)
        probe.subscribe("/energy", Float64MultiArray)
        with NodeProcess("-p", f"model:={NL}", "-p", "damping_ratio:=0.05",
                         "-p", "v0:=-1.0", "-p", f"time_step:={STEP}") as node:
            probe.wait_for("/deployment_phase", lambda m: m.data == "locked", timeout=60)
            lock_t = float(node.wait_for_log(r"locked at t = ([0-9.]+) s").group(1))
            msg = probe.wait_for("/energy", lambda m: m.data[5] > 0.01, timeout=60)
            assert node.stop() == 0
    finally:
        probe.close()
    offline = simulate(P(v0=-1.0, model=NL, damping_ratio=0.05), 0.1,
                       stop_after_lock=0.0)
    assert lock_t == pytest.approx(offline.lock.time, abs=1e-5)
    kinetic, strain, work, lock_loss, balance, damping = msg.data
    assert abs(balance) < 1e-4 * (kinetic + strain + damping)


def test_recording_and_resimulation_of_the_nonlinear_damped_model(tmp_path):
    """Record offline as the node would, then re-run the physics from the log: identical."""
    from umbrella_sim.bag.reader import read_log
    from umbrella_sim.ros.recording import record_offline
    from umbrella_sim.tools.replay import resimulate

    bag = tmp_path / "nl"
    p = UmbrellaParams(v0=-1.0, model=NL, damping_ratio=0.02)
    record_offline(p, str(bag), 0.08)
    log = read_log(str(bag))
    assert log.parameters()["model"] == NL and log.parameters()["damping_ratio"] == 0.02
    energy = [m.data for _, m in log.decoded("/energy")]
    assert len(energy[-1]) == 6 and energy[-1][5] > 0.0          # dissipated energy recorded
    res = resimulate(log)
    assert res["compared"] > 5
    assert max(res["max_abs_diff"].values()) < 1e-9
