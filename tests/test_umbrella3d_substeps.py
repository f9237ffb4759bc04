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
The umbrella's stage 2 in the substeps its lock needs: the planar rule, on the worst rib.

Past the modes' coupling (a stage-2 tip deflection above step_rule.COUPLING_DEFLECTION) the
planar model's stage 2 takes, where the step is chosen for the run (time_step 0), k physics
steps a grid step (step_rule.stage2_step_needed); the umbrella judges the same rule on each
rib's in-plane state at the lock (substeps3d.py) and takes the worst rib's.  (a) N identical
ribs are then each the planar model at time_step 0, substeps included, to the identity's
tolerance (test_umbrella3d.py's module docstring); (b) the compiled advance (physics steps
folded into grid rows, _kernel3d.c's steps at h / k) and the numpy step take the same grid
rows from one locked state, to the round-off spread of the numpy reference itself (its
state one ulp off: test_umbrella3d_kernel.py's rule), on every base; (c) a recording made
at time_step 0 keeps the rule (replay re-simulates at the recorded step, following the
lock: step_rule.follows_lock of the umbrella's planar record) and its re-simulation is the
run, figure for figure.
"""
from dataclasses import replace
import json

import numpy as np
import pytest

from tests.test_umbrella3d import assert_ribs_equal_planar
from tests.test_umbrella3d_kernel import (assert_rows_agree, ASYMMETRIC, AT_SPEED, BASES,
                                          needs_kernel)
from umbrella_sim.bag.format import PARAMETERS_RECORD
from umbrella_sim.bag.reader import read_log
from umbrella_sim.core.step_rule import COUPLING_DEFLECTION
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.tools import cli
from umbrella_sim.tools.replay import resimulate


@pytest.mark.parametrize('kernel', [
    pytest.param('compiled', marks=needs_kernel),
    pytest.param('numpy', marks=pytest.mark.slow)])       # numpy ~9 s
def test_identical_ribs_take_the_planar_models_stage2_substeps(kernel, monkeypatch):
    """
    Three ribs at time_step 0, default V0, 10 N a rib: the planar model, substeps included.

    The planar model's lock (13 % of the leaf) needs 6 physics steps a 0.2 ms grid step.
    """
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
    sim, planar_sim = assert_ribs_equal_planar(3, {'sleeve_force': 10.0}, 0.19, kernel, fit=True)
    assert planar_sim.stage2_substeps == sim.stage2_substeps == 6
    assert sim.stage2_resolution['deflection'] > COUPLING_DEFLECTION
    assert sim.stage2_resolution['needed_step'] == pytest.approx(sim.h / 6, rel=1e-12)


def continued(sim: UmbrellaSimulator3D, kernel: str, ulp: bool = False) -> UmbrellaSimulator3D:
    """Return a simulator on the kernel's path from sim's locked state (ulp: its rates up)."""
    new = UmbrellaSimulator3D(sim.params, kernel=kernel)
    s = sim.state
    if ulp:
        s = replace(s, vr=np.nextafter(s.vr, np.inf), pr=None, ps=None)
    new.state, new.k, new.locked, new.lock_time = s, sim.k, True, sim.lock_time
    new.lock_loss, new.stage2_substeps = sim.lock_loss, sim.stage2_substeps
    new.integrator.take_substeps(sim.h / sim.stage2_substeps, sim.integrator.tolerance)
    new.integrator.lock_at(s)
    new.record = type(sim.record)(sim.model)
    new.record.add(s, True, new.force, None, new.lock_loss)      # (the crests start there)
    return new


@needs_kernel
@pytest.mark.parametrize('base', [pytest.param(base, marks=[pytest.mark.slow] if base != 'fixed'
                                               else []) for base in BASES])
def test_compiled_substeps_equal_numpy_from_one_locked_state(base):
    """
    40 stage-2 grid steps of 10 physics steps each from one state, compiled and numpy.

    Four ribs, asymmetric (test_umbrella3d_kernel.ASYMMETRIC), at V0 = -0.5 and time_step
    0: the lock's worst rib needs 10 physics steps a 0.2 ms grid step.  The grid rows (the
    last physics step's figures, the stresses' crests the largest over the physics steps)
    agree within 10 x the numpy reference's ulp spread, the peaks and their places too, the
    rows on the grid exactly, the same Newton iterations.
    """
    values = dict(ASYMMETRIC, time_step=0.0, **AT_SPEED, **BASES[base])
    start = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values), kernel='compiled')
    start.run(1.0, after_lock=0.001)
    # (stage 1's 0.2 ms grid; a driven base that moves keeps the mesh's 0.1 ms)
    assert start.stage2_substeps > 1 and start.h == (1e-4 if base == 'prescribed' else 2e-4)
    runs = [continued(start, kernel, ulp) for kernel, ulp in (
        ('compiled', False), ('numpy', False), ('numpy', True))]
    for sim in runs:
        sim.advance(40)
        assert sim.k == start.k + 40 and sim.state.t == sim.k * sim.h
    a, b, spread = (sim.record.arrays() for sim in runs)
    np.testing.assert_array_equal(a['time'][1:], (start.k + 1 + np.arange(40)) * start.h)
    assert_rows_agree(a, b, spread, start.model)
    assert runs[0].integrator.iterations == runs[1].integrator.iterations
    for name, peak in runs[0].record.peak.items():
        want = runs[1].record.peak[name]
        bound = 10.0 * np.max(np.abs(runs[2].record.peak[name] - want)) + 1e-12 * want
        assert np.all(np.abs(peak - want) <= bound), name
        assert runs[0].record.peak_where[name] == runs[1].record.peak_where[name]
    # the substeps' crests: a grid row's peak is at least its end's own stress
    m = start.model
    end = np.abs(np.concatenate(m.stress_blocks(runs[1].state.qr[None]), -1)).max(-1)[0]
    assert np.all(b['stress_axial'][-1] >= end[:, 0] * (1 - 1e-12))
    # every physics step's tips (the summary's stage-2 series, Record3D.taken_tips): the
    # compiled fold's, kept apart from its rows, are the numpy steps'; a grid step's last
    # is its row's (the start's row first: its own)
    tips = []
    for sim in runs:
        sim.record.take()
        tips.append(sim.record.taken_tips)
    (t, v), (t_numpy, v_numpy), (_, v_spread) = tips
    sub = start.stage2_substeps
    assert v.shape == (1 + 40 * sub, 4, 2)
    np.testing.assert_allclose(t, t_numpy, rtol=0, atol=1e-15)
    assert np.max(np.abs(v - v_numpy)) <= (10.0 * np.max(np.abs(v_spread - v_numpy))
                                           + 1e-12 * np.max(np.abs(v_numpy)))
    np.testing.assert_array_equal(t[sub::sub], a['time'][1:])
    np.testing.assert_array_equal(v[sub::sub], a['tip'][1:, :, 1:])


def test_a_recording_at_time_step_0_keeps_the_substeps_and_resimulates_exactly(
        tmp_path, capsys):
    """
    The driver's rule (RunDriver, replay: with_physics_step(step, follows_lock)).

    Two ribs at 10 N, time_step 0, published at 500 Hz: the run's stage 2 takes its
    substeps (no 'coarse step', which the grid step alone would say: the tip deflection at
    the lock is 13 % of the leaf), and its re-simulation from the recording is the run.
    """
    bag = tmp_path / 'ribs'
    assert cli.main(['simulate', '--set', 'ribs=2', '--force', '10', '--duration', '0.19',
                     '--json', '--mcap', str(bag), '--publish-rate', '500']) == 0
    figures = json.loads(capsys.readouterr().out)
    assert not [w for w in figures['warnings'] if w.startswith('coarse step')]
    log = read_log(str(bag))
    assert float(log.metadata[PARAMETERS_RECORD]['time_step']) == 0.0
    res = resimulate(log)
    assert res['compared'] > 90 and not res['problems']
    assert max(res['max_abs_diff'].values()) == 0.0     # the same run, on the same build


@needs_kernel
@pytest.mark.slow       # (a 2.5 us reference through a 0.75 s deployment, ~9 s)
def test_stage1_on_its_grid_leaves_the_lock_and_stage2_where_the_meshs_step_does():
    """
    Three ribs deploying from rest at 6 N a rib, one stuck until 0.1 s, one with a tip mass.

    time_step 0 (stage 1 on its 0.2 ms grid, stage 2 in the substeps its lock needs) against
    the run whose stage 1 takes 0.1 ms (step_follows_mesh: the same stage-2 step) and a
    2.5 us reference: the lock instant within 2e-5 s and the in-plane tips of 0.1 s of stage
    2 (on a 1 ms grid every run steps on) within 1 % of their amplitude, as 0.1 ms leaves
    them (measured: 1.1e-5 s and 0.24 % on the grid, 1.5e-5 s and 0.30 % at 0.1 ms).  The
    jump of the stuck hinge's release is in stage 1, which the grid takes.
    """
    values = {'ribs': 3, 'v0': 0.0, 'sleeve_force': 6.0, 'rib1.stick_until': 0.1,
              'rib2.tip_mass': 0.05}

    def run(time_step, follows=False):
        sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
            dict(values, time_step=time_step, step_follows_mesh=follows)), kernel='compiled')
        sim.run(5.0, after_lock=0.1)
        a = sim.record.arrays()
        grid = (np.ceil(sim.lock_time / 1e-3) + np.arange(1, 99)) * 1e-3
        rows = np.searchsorted(a['time'], grid - 1e-9)
        assert np.abs(a['time'][rows] - grid).max() < 1e-9
        return sim, a['tip'][rows, :, 1]

    default, tips = run(0.0)
    finer, finer_tips = run(1e-4, follows=True)
    assert default.h == 2e-4 and finer.h == 1e-4
    assert default.stage2_substeps == 2 * finer.stage2_substeps      # the same stage-2 step
    ref, ref_tips = run(2.5e-6)
    amplitude = np.abs(ref_tips).max()
    errors = {}
    for name, sim, series in (('grid', default, tips), ('0.1 ms', finer, finer_tips)):
        errors[name] = (abs(sim.lock_time - ref.lock_time),
                        np.abs(series - ref_tips).max() / amplitude)
    for lock, tip in errors.values():
        assert lock < 2e-5 and tip < 0.01
