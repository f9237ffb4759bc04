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

"""The compiled stepping (_kernel.c) against the numpy reference path."""
import os

import numpy as np
import pytest

from umbrella_sim.core.integrators import load_kernel, MidpointDAE
from umbrella_sim.core.model import ConstraintSet, Stage
from umbrella_sim.core.nonlinear import ElasticMidpointDAE
from umbrella_sim.core.outputs import state_row, STEP_FIELDS, StepBlock
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.solver import nonlinear_model_needed, UmbrellaSimulator

needs_kernel = pytest.mark.skipif(load_kernel() is None, reason='compiled kernel not built')


def test_kernel_is_built_unless_numpy_is_asked_for():
    """Installation requires a C compiler: a missing kernel is an install defect, not a skip."""
    if os.environ.get('UMBRELLA_SIM_KERNEL') == 'numpy':
        pytest.skip('numpy path forced by UMBRELLA_SIM_KERNEL=numpy')
    assert load_kernel() is not None
    assert UmbrellaSimulator(UmbrellaParams()).engine.backend == 'compiled'


def simulator(kernel, params):
    sim = UmbrellaSimulator(params)
    integrator = ElasticMidpointDAE if nonlinear_model_needed(params) else MidpointDAE
    sim.engine.integrator = integrator(sim.model, kernel=kernel)
    return sim


def run(kernel, params, duration):
    sim = simulator(kernel, params)
    samples = sim.advance_to(duration)
    traj = np.array([np.concatenate([[s.time], s.q, s.qd, s.multipliers[:3]]) for s in samples])
    return traj, sim


def blocks(sim, sizes):
    out = [sim.advance(k) for k in sizes]
    return np.hstack([np.array([getattr(b, f) for f in STEP_FIELDS]) for b in out]), out


@needs_kernel
@pytest.mark.parametrize('model, n_el, lock, force', [
    ('flexible', 1, 'energy', 0.0), ('flexible', 2, 'plastic', 2.0),
    ('flexible', 4, 'energy', 0.0), ('rigid-fe', 2, 'energy', 1.0)])
def test_compiled_step_matches_numpy_reference(model, n_el, lock, force):
    p = UmbrellaParams(v0=-0.5, model=model, elements_per_segment=n_el, lock=lock,
                       sleeve_force=force, time_step=2e-3)
    ref, sim_ref = run('numpy', p, 0.3)
    fast, sim_fast = run('compiled', p, 0.3)
    assert sim_ref.lock_event is not None
    assert sim_fast.lock_event.time == pytest.approx(sim_ref.lock_event.time, abs=1e-12)
    # a step at the stopping threshold may take one iteration more or less in round-off
    assert abs(sim_fast.engine.newton_iterations() - sim_ref.engine.newton_iterations()) \
        <= 0.02 * sim_ref.engine.newton_iterations()
    assert ref.shape == fast.shape
    scale = np.maximum(1.0, np.abs(ref).max(axis=0))
    assert np.max(np.abs(ref - fast) / scale) < 1e-7


@needs_kernel
@pytest.mark.parametrize('n_el, t0', [(3, 0.02), pytest.param(2, 0.12, marks=pytest.mark.slow)])
def test_compiled_single_step_matches_to_roundoff(n_el, t0):
    """From the same state, one step of either path agrees to round-off (stage 1 and 2)."""
    p = UmbrellaParams(v0=-1.0, elements_per_segment=n_el)
    sim = UmbrellaSimulator(p)
    sim.advance_to(t0, record=False)
    cs = ConstraintSet(locked=sim.stage == Stage.LOCKED, rigid=False)
    a = MidpointDAE(sim.model, kernel='numpy').step(sim.state, 1e-3, 0.5, cs)
    b = MidpointDAE(sim.model, kernel='compiled').step(sim.state, 1e-3, 0.5, cs)
    assert np.abs(a.q - b.q).max() < 1e-13
    assert np.abs(a.qd - b.qd).max() < 1e-12 * max(1.0, np.abs(a.qd).max())
    assert np.abs(a.momentum - b.momentum).max() < 1e-12 * max(1.0, np.abs(a.momentum).max())
    assert np.abs(a.multipliers - b.multipliers).max() < 1e-12 * np.abs(a.multipliers).max()


@needs_kernel
@pytest.mark.parametrize('zeta', [0.0, 0.02])
def test_compiled_fitted_stage2_steps_match_to_roundoff(zeta):
    """
    Stage 2 with the mode fit (integrators.LockedModeFit): 20 steps of either path agree.

    From the same locked state (N = 2, V0 = -1, undamped and damped: the fit's damping change
    too), Newton to 1e-13 on both paths: the compiled kernel's modal sums (S w with the
    precomputed Mff phi, W phi; S^T M S w; the damping change) are the numpy reference's
    equations.
    """
    p = UmbrellaParams(v0=-1.0, elements_per_segment=2, time_step=1e-4, damping_ratio=zeta)
    sim = UmbrellaSimulator(p)
    sim.advance_to(0.06, record=False)
    assert sim.stage == Stage.LOCKED
    cs = ConstraintSet(locked=True, rigid=False)
    out = {}
    for kernel in ('numpy', 'compiled'):
        integ = (ElasticMidpointDAE if zeta else MidpointDAE)(sim.model, kernel=kernel)
        integ.tolerance = 1e-13
        integ.fit_stage2_modes(1e-4)
        integ.lock_at()
        assert integ.mode_fit is not None and (np.any(integ.mode_fit.damping_change) == bool(zeta))
        s = sim.state
        for _ in range(20):
            s = integ.step(s, 1e-4, 0.0, cs)
        out[kernel] = s
    a, b = out['numpy'], out['compiled']
    assert np.abs(a.q - b.q).max() < 1e-12
    assert np.abs(a.qd - b.qd).max() < 1e-10 * np.abs(a.qd).max()
    assert np.abs(a.momentum - b.momentum).max() < 1e-10 * np.abs(a.momentum).max()
    assert a.dissipation == pytest.approx(b.dissipation, rel=1e-9, abs=1e-15)


@needs_kernel
@pytest.mark.parametrize('zeta', [0.0, 0.02])
def test_compiled_fitted_steps_of_another_length_take_the_numpy_iterations(zeta):
    """
    A fit made for half the step, 20 steps: both paths shrink each mode as the step's.

    LockedModeFit.newton_shrink(h) (the step's block and damping share, as a lock's part
    steps need): the same Newton iterations step by step at the default tolerance, and the
    same states to the tolerance's spread.
    """
    p = UmbrellaParams(v0=-1.0, elements_per_segment=2, time_step=1e-4, damping_ratio=zeta)
    sim = UmbrellaSimulator(p)
    sim.advance_to(0.06, record=False)
    cs = ConstraintSet(locked=True, rigid=False)
    out = {}
    for kernel in ('numpy', 'compiled'):
        integ = (ElasticMidpointDAE if zeta else MidpointDAE)(sim.model, kernel=kernel)
        integ.fit_stage2_modes(0.5e-4)
        integ.lock_at()
        s, its = sim.state, []
        for _ in range(20):
            before = integ.iterations
            s = integ.step(s, 1e-4, 0.0, cs)
            its.append(integ.iterations - before)
        out[kernel] = s, its
    (a, its_a), (b, its_b) = out['numpy'], out['compiled']
    assert its_a == its_b
    assert np.abs(a.q - b.q).max() < 1e-9


#: what a row holds as a Sample does, but over the step: the peak stresses and where they are
STEP_PEAK_FIELDS = ('peak_stress_leaf', 'peak_stress_leaf_x', 'peak_stress_link',
                    'peak_stress_link_x')
#: rates over the step that ended at the row (accelerations, the multipliers' reactions): the
#: state's error divided by that step's length, which the lock's step shortens
STEP_RATE_FIELDS = ('alpha1_accel', 'sleeve_reaction_x', 'sleeve_reaction_y')


@needs_kernel
@pytest.mark.parametrize('model, n_el, lock, force, zeta', [
    ('flexible', 1, 'energy', 0.0, 0.0), ('flexible', 1, 'plastic', 1.5, 0.0),
    ('flexible', 2, 'plastic', 1.5, 0.0), ('flexible', 2, 'energy', 0.0, 0.0),
    ('flexible', 4, 'energy', 0.0, 0.0), ('rigid-fe', 2, 'energy', 0.5, 0.0),
    ('flexible', 2, 'energy', 0.0, 0.02),
    pytest.param('flexible-nonlinear', 2, 'plastic', 1.0, 0.0, marks=pytest.mark.slow),
    ('flexible-nonlinear', 2, 'energy', 0.0, 0.02)])
def test_compiled_advance_outputs_match_reference_per_step(model, n_el, lock, force, zeta):
    """
    Compare every per-step output of the compiled block loop with the reference.

    Every per-step output of the compiled block loop (through the lock) against the
    reference: numpy steps and outputs from sample(), all of STEP_FIELDS.  The trajectories
    agree to round-off amplified over ~150 steps, so 1e-10 of each field's scale; a rate over
    the step (STEP_RATE_FIELDS) to that over the step's length: the lock's step, which the
    lock instant shortens (to ~1 us at F_H = 1.5 N), divides the same state error by its length.
    """
    p = UmbrellaParams(v0=-0.5, model=model, elements_per_segment=n_el, lock=lock,
                       sleeve_force=force, time_step=1e-3, damping_ratio=zeta)
    sizes = [7, 30, 1, 45, 50, 17]           # uneven blocks, one of them holding the lock
    ref, ref_blocks = blocks(simulator('numpy', p), sizes)
    fast, fast_blocks = blocks(simulator('compiled', p), sizes)
    assert [b.lock is not None for b in ref_blocks] == [b.lock is not None for b in fast_blocks]
    assert sum(b.lock is not None for b in fast_blocks) == 1
    assert ref.shape == fast.shape == (len(STEP_FIELDS), sum(sizes))
    assert_same_rows(ref, fast, ref_blocks, p.time_step)
    if model == 'flexible' and zeta == 0:
        assert not fast[STEP_FIELDS.index('damping_dissipation')].any()
    if zeta > 0:
        assert fast[STEP_FIELDS.index('damping_dissipation')][-1] > 0.0
    last_ref, last_fast = ref_blocks[-1].last, fast_blocks[-1].last
    assert np.abs(last_ref.q - last_fast.q).max() < 1e-10


@needs_kernel
def test_stage2_substeps_give_the_same_grid_rows_on_both_paths():
    """
    Compare the grid rows of a stage 2 taken in substeps (its lock past the modes' coupling).

    N = 1, V0 = -0.5, time_step 0: the grid stays at stage 1's 0.2 ms and stage 2 takes 8
    physics steps a grid step (step_rule.stage2_step_needed, judged at 0.1 ms).  The
    compiled loop runs the physics steps and folds their rows (outputs.fold_substeps); the
    reference steps them one by one with the peak stresses over them
    (UmbrellaSimulator._physics_steps): the same rows, to round-off.
    """
    p = UmbrellaParams(v0=-0.5)
    sizes = [250, 200, 3, 20, 1, 28]     # the lock in the second block; stage 2 after it
    ref_sim, fast_sim = simulator('numpy', p), simulator('compiled', p)
    ref, ref_blocks = blocks(ref_sim, sizes)
    fast, fast_blocks = blocks(fast_sim, sizes)
    assert ref_sim.h == fast_sim.h == 2e-4
    assert ref_sim.stage2_substeps == fast_sim.stage2_substeps == 8
    assert fast_sim.lock_event.stage2_resolution['step'] == pytest.approx(2.5e-5)
    time = fast[STEP_FIELDS.index('time')]
    assert np.allclose(np.diff(time), 2e-4, rtol=1e-9, atol=0)     # one row a grid step
    assert_same_rows(ref, fast, ref_blocks, ref_sim.h)
    last_ref, last_fast = ref_blocks[-1].last, fast_blocks[-1].last
    assert np.abs(last_ref.q - last_fast.q).max() < 1e-10


def assert_same_rows(ref: np.ndarray, fast: np.ndarray, ref_blocks: list, step: float) -> None:
    """
    Check two paths' rows of the same steps to round-off amplified over the run.

    1e-10 of each field's scale; a rate over the step (STEP_RATE_FIELDS) to that over the
    step's length (the lock's step, which the lock instant shortens, divides the same state
    error by its length); where a peak is, only where it is defined.
    """
    assert np.array_equal(ref[STEP_FIELDS.index('stage')], fast[STEP_FIELDS.index('stage')])
    energy = np.abs(ref[STEP_FIELDS.index('kinetic_energy')]).max() + \
        np.abs(ref[STEP_FIELDS.index('strain_energy')]).max()
    time = ref[STEP_FIELDS.index('time')]
    lock_time = next(b.lock.time for b in ref_blocks if b.lock is not None)
    step_length = np.minimum(step, np.where(time > lock_time, time - lock_time, np.inf))
    for i, name in enumerate(STEP_FIELDS):
        if name in STEP_PEAK_FIELDS and name.endswith('_x'):   # where the peak is: compare
            peak = ref[i - 1]                                    # only where it is defined
            defined = peak > max(1e-6 * peak.max(), 1.0)     # Pa; not round-off
            assert np.array_equal(ref[i][defined], fast[i][defined]), name
            continue
        scale = np.abs(ref[i]).max()
        if name in ('work', 'lock_energy_loss', 'damping_dissipation'):   # round-off of the
            scale = max(scale, energy)                                     # energy, when ~0
        if name in STEP_RATE_FIELDS:
            scale = scale * step / step_length
        # the elastic fields of the rigid-FE mode are round-off around 0: floor 1e-12 m,
        # 1e-6 Pa (a strain of 1e-17); the constraint residual is round-off: floor 1e-12 m
        floor = 1e-6 if name.startswith(('peak_stress', 'stress_', 'axial_stress')) else 1e-12
        assert np.all(np.abs(ref[i] - fast[i]) <= 1e-10 * scale + floor), name


@pytest.mark.parametrize('kernel, model', [
    ('compiled', 'flexible'), ('compiled', 'rigid-fe'), ('compiled', 'flexible-nonlinear'),
    ('numpy', 'flexible'), ('compiled', 'rigid')])
def test_each_step_row_holds_its_states_sample(kernel, model, monkeypatch):
    """
    A step's row holds the figures of the Sample of the state it reached, to the bit.

    Step by step through the lock (its step taken in Python) into stage 2: every field of
    the row but the step's peak stresses (over the step, not the instant) equals the Sample
    of the state the step reached, made on its own (compiled: umbrella_sample_call, not
    the advance's row; the rigid model's closed form: fe_state's coordinates, but the sleeve
    velocity, from the angles' rates in the row and from the finite-element coordinates in a
    Sample, to round-off, as tests/test_rigid_models.py has it).
    """
    if kernel == 'compiled' and load_kernel() is None:
        pytest.skip('compiled kernel not built')
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
    p = UmbrellaParams(v0=-0.5, model=model, elements_per_segment=2, time_step=1e-3,
                       damping_ratio=0.02 if model == 'flexible-nonlinear' else 0.0,
                       sleeve_force=0.5)
    sim = UmbrellaSimulator(p)
    kernel_of = getattr(sim.engine, 'integrator', None)
    stages = set()
    for _ in range(120):
        block = sim.advance(1)
        compiled = getattr(kernel_of, 'kernel', None)
        if compiled is not None:
            compiled._final_of = None      # the Sample from umbrella_sample_call, not from the row
        last = block.last
        stages.add(last.stage)
        for i, name in enumerate(STEP_FIELDS):
            if name not in STEP_PEAK_FIELDS:
                want = float(last.stage.code) if name == 'stage' else getattr(last, name)
                tol = 1e-14 * max(1.0, abs(want)) if (model, name) == (
                    'rigid', 'sleeve_velocity') else 0.0
                assert abs(block.rows[i, 0] - want) <= tol, (name, last.time)
    assert stages == {Stage.DEPLOYING, Stage.LOCKED}


@pytest.mark.parametrize('kernel, model', [
    ('compiled', 'flexible'), ('compiled', 'flexible-nonlinear'), ('numpy', 'flexible'),
    ('compiled', 'rigid')])
def test_state_rows_are_the_samples_states(kernel, model, monkeypatch):
    """
    advance(n, states=True): each step's q, q' and fibre stresses, as its Sample has them.

    The blocks' state rows through the lock equal state_row of the Sample each step reaches
    when stepping one step at a time (the same trajectory to the bit); StepBlock.concatenate
    keeps them, and a block asked for none has None.
    """
    if kernel == 'compiled' and load_kernel() is None:
        pytest.skip('compiled kernel not built')
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
    p = UmbrellaParams(v0=-0.5, model=model, elements_per_segment=2, time_step=1e-3,
                       damping_ratio=0.02 if model == 'flexible-nonlinear' else 0.0)
    by_step = UmbrellaSimulator(p)
    want = [state_row(by_step.advance(1).last) for _ in range(150)]
    sim = UmbrellaSimulator(p)
    parts = [sim.advance(k, states=True) for k in (7, 30, 1, 45, 50, 17)]
    assert sum(b.lock is not None for b in parts) == 1
    m = sim.model
    rows = 2 * m.n + 2 * (m.leaf.n_stress_points + m.link.n_stress_points)
    assert all(b.states.shape == (rows, len(b)) for b in parts)
    joined = StepBlock.concatenate(parts)
    assert np.array_equal(joined.states, np.array(want).T)
    last = parts[-1].last
    assert np.array_equal(parts[-1].states[:, -1], state_row(last))
    assert np.array_equal(parts[-1].states[:m.n, -1], last.q)
    assert np.array_equal(parts[-1].states[m.n:2 * m.n, -1], last.qd)
    assert np.abs(joined.states[2 * m.n:]).max() > (1e6 if model != 'rigid' else -1.0)
    assert sim.advance(3).states is None
    assert StepBlock.concatenate([parts[-1], sim.advance(2)]).states is None
    assert sim.advance(0, states=True).states.shape == (rows, 0)


@needs_kernel
def test_block_size_does_not_change_the_result():
    """Publication rate is free: 60 steps in one block or in five give identical bits."""
    p = UmbrellaParams(v0=-2.0, elements_per_segment=2, time_step=5e-4, sleeve_force=1.0)
    one, _ = blocks(UmbrellaSimulator(p), [60])
    split, parts = blocks(UmbrellaSimulator(p), [13, 1, 20, 6, 20])
    assert any(b.lock is not None for b in parts)
    assert np.array_equal(one, split)


@needs_kernel
@pytest.mark.parametrize('model, n_el, zeta', [
    ('flexible', 1, 0.0), ('flexible', 4, 0.0), ('rigid-fe', 2, 0.0), ('flexible', 2, 0.02),
    ('flexible-nonlinear', 2, 0.0), ('flexible-nonlinear', 4, 0.02)])
def test_compiled_sample_matches_numpy_outputs(model, n_el, zeta, monkeypatch):
    """
    The Sample built from one compiled call (stresses, peaks, energies, residual) vs numpy.

    The advance's own outputs of the state it reached and a separate umbrella_sample_call
    give the same bits.

    Also with an elastic law (_kernel_nonlinear.c): the membrane stress in the fibre
    stresses, the nonlinear strain energy, the damped model's energies.
    """
    from dataclasses import fields

    from umbrella_sim.core.engines import FiniteElementEngine
    # a 50 us step: the first two blocks end in stage 1 (deploy at ~0.09 s), the others in 2
    sim = UmbrellaSimulator(UmbrellaParams(v0=-0.5, model=model, elements_per_segment=n_el,
                                           damping_ratio=zeta, time_step=5e-5))
    stages = set()
    for block in (1000, 1000, 300, 2000):
        sim.advance(block)
        fast = sim.sample()
        kernel = sim.engine.integrator.kernel
        assert kernel._final_of is sim.state          # from what the advance computed
        kernel._final_of = None                        # from umbrella_sample_call: the same bits
        again = sim.sample()
        for f in fields(fast):
            assert np.array_equal(getattr(fast, f.name), getattr(again, f.name)), f.name
        with monkeypatch.context() as mp:
            mp.setattr(FiniteElementEngine, 'sample_outputs', lambda self, s, stage: None)
            ref = sim.sample()
        stages.add(ref.stage)
        for f in fields(ref):
            a, b = getattr(fast, f.name), getattr(ref, f.name)
            if f.name == 'constraint_residual':
                assert a < 1e-11 and b < 1e-11
            elif isinstance(b, (float, np.ndarray, tuple)):
                a, b = np.asarray(a, float), np.asarray(b, float)
                # velocities at rest in stage 2 are round-off: absolute floor 1e-14
                assert np.allclose(a, b, rtol=1e-12, atol=1e-14 + 1e-12 * np.abs(b).max()), f.name
            else:
                assert a == b, f.name
    assert stages == {Stage.DEPLOYING, Stage.LOCKED}


def test_install_names_a_missing_compiler_apart_from_a_failed_build(tmp_path):
    """No C compiler: one message saying to install one; a compiler that fails: not that."""
    import shutil
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    shutil.copytree(root, tmp_path / 'src', ignore=shutil.ignore_patterns(
        '.git', '.venv', 'build', '*.egg-info', '*.so', '__pycache__', '.pytest_cache',
        'tests', 'docs', 'bench'))

    def build(**env):
        return subprocess.run([sys.executable, 'setup.py', '-q', 'build_ext', '--inplace'],
                              cwd=tmp_path / 'src', capture_output=True, text=True,
                              env=dict(os.environ, **env), timeout=300)

    missing = build(CC=str(tmp_path / 'no-such-cc'))
    assert missing.returncode != 0 and 'needs a C compiler' in missing.stderr, missing.stderr
    kernel = tmp_path / 'src' / 'umbrella_sim' / 'core' / '_kernel.c'
    kernel.write_text(kernel.read_text() + '\nthis is not C;\n')
    failed = build()
    assert failed.returncode != 0 and 'did not build with' in failed.stderr, failed.stderr
    assert 'needs a C compiler' not in failed.stderr
