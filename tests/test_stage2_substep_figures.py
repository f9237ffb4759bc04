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
The summary's stage-2 figures are those of every physics step, stage 2's substeps included.

Where the step follows the lock (step_rule.follows_lock) stage 2 takes k physics steps a grid
step and the run's rows are the grid's (one a grid step); the summary's stage-2 tip
amplitude and period (summary.Stage2Series, the planar and the umbrella's) take the tip of
every physics step (the blocks' physics_tips), so that a coarse grid (5 ms, step_follows_mesh:
stage 2 in 50 substeps of the mesh's 0.1 ms) gives the figures of a run that steps its grid at
0.1 ms, and its period is the locked frame's first mode's (UmbrellaModel.locked_modes): the
vibration of V0 = -0.05 (a tip of 3 % of the leaf) is linear.  The grid rows alone do not:
their amplitude misses the crests between them (0.9 % low here) and their period is 2e-4 off
(the higher modes alias onto a grid of ten rows a period).  What the coarse grid's stage 1
leaves (its lock state) is the tolerance: its amplitude moved by 1.5e-4, its period by 1e-7.
"""
import math

import numpy as np
import pytest

from tests.test_compiled_kernel import needs_kernel
from umbrella_sim.core import simulate, UmbrellaModel, UmbrellaParams
from umbrella_sim.core.driver import RunDriver
from umbrella_sim.core.summary import stage2_figures, STAGE2_WINDOW
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D

#: the run: a small deployment whose stage 2 vibrates linearly, on a coarse grid whose
#: stage 2 takes the mesh's step in substeps, and the run at that step throughout
V0 = -0.05
COARSE = {'v0': V0, 'time_step': 5e-3, 'step_follows_mesh': True}
FINE = {'v0': V0, 'time_step': 1e-4}
#: how far the coarse grid's figures may be from the fine grid's (its stage 1 moves them)
AMPLITUDE_TOLERANCE = 5e-4
PERIOD_TOLERANCE = 1e-6
#: how far the stage-2 period may be from the locked frame's first mode's (measured 2.5e-5)
MODE_PERIOD_TOLERANCE = 5e-5


def first_mode_period() -> float:
    """Return the period of the locked frame's first mode (s), linearised at deployment."""
    omega = UmbrellaModel(UmbrellaParams(v0=V0)).locked_modes[0]
    return 2.0 * math.pi / omega[0]


def run(params, after_lock=STAGE2_WINDOW + COARSE['time_step'], **kwargs):
    """Return a run through stage 2's window (after_lock past its lock): figures and samples."""
    result = simulate(params, 5.0, stop_after_lock=after_lock, **kwargs)
    assert result.error is None
    return result


def grid_row_figures(result, tip) -> list[dict]:
    """Return stage2_figures of the run's grid rows alone, each column of tip(sample)."""
    t = np.array([s.time for s in result.samples])
    v = np.array([tip(s) for s in result.samples])
    return [stage2_figures(t, v[:, j], result.figures['lock_time']) for j in range(v.shape[1])]


def assert_figures_of_the_physics(figures, fine, grid_rows, period):
    """Assert the coarse grid's figures are the fine grid's, not those of its rows alone."""
    amplitude, fine_amplitude = figures['stage2_tip_amplitude'], fine['stage2_tip_amplitude']
    assert amplitude == pytest.approx(fine_amplitude, rel=AMPLITUDE_TOLERANCE)
    assert figures['stage2_tip_period'] == pytest.approx(fine['stage2_tip_period'],
                                                         rel=PERIOD_TOLERANCE)
    assert figures['stage2_tip_period'] == pytest.approx(period, rel=MODE_PERIOD_TOLERANCE)
    # the grid rows alone: crests missed, the period off the mode's
    assert grid_rows['stage2_tip_amplitude'] < (1 - 10 * AMPLITUDE_TOLERANCE) * fine_amplitude
    assert abs(grid_rows['stage2_tip_period'] / period - 1) > 2 * MODE_PERIOD_TOLERANCE


@needs_kernel
def test_the_planar_stage2_figures_are_those_of_every_substep():
    """
    The planar frame at V0 = -0.05: a 5 ms grid (50 substeps) against a 0.1 ms one.

    Measured: amplitude 1.5e-4 from the fine grid's, period 4e-8, 2.5e-5 from the first
    mode's; the grid rows 8.7e-3 low and 2.0e-4 off.  Chunked a grid step at a time the
    figures are the same (the series is every block's physics steps).
    """
    coarse = run(UmbrellaParams(**COARSE))
    fine = run(UmbrellaParams(**FINE), keep_samples=False)
    driver = RunDriver(UmbrellaParams(**COARSE), period_steps=1, chunk_steps=1)
    assert driver.sim.h / 50 == pytest.approx(1e-4, rel=1e-12)
    chunked = run(UmbrellaParams(**COARSE), keep_samples=False, driver=driver)
    assert driver.sim.stage2_substeps == 50
    assert_figures_of_the_physics(coarse.figures, fine.figures,
                                  grid_row_figures(coarse, lambda s: [s.tip_transverse])[0],
                                  first_mode_period())
    for name in ('stage2_tip_amplitude', 'stage2_tip_period', 'stage2_window'):
        assert chunked.figures[name] == coarse.figures[name], name


@needs_kernel
def test_the_planar_paths_take_the_same_substeps(monkeypatch):
    """
    The compiled and numpy paths' stage-2 figures of the 5 ms grid agree, to round-off.

    Over 0.15 s of stage 2 (three periods: the numpy path's 1500 substeps); the period to
    the golden-section search's 1e-9.
    """
    figures = {}
    for kernel in ('compiled', 'numpy'):
        monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
        figures[kernel] = run(UmbrellaParams(**COARSE), after_lock=0.15,
                              keep_samples=False).figures
    # (the lock to the root find's round-off; the window's end the same physics step)
    assert figures['compiled']['stage2_window'][1] == figures['numpy']['stage2_window'][1]
    for name in ('stage2_tip_amplitude', 'stage2_tip_period'):
        assert figures['compiled'][name] == pytest.approx(figures['numpy'][name], rel=1e-8)


@needs_kernel
def test_each_ribs_stage2_figures_are_those_of_every_substep():
    """
    Three ribs at V0 = -0.05 (each the planar frame): the 5 ms grid against 0.1 ms.

    Each rib's in-plane amplitude and period as the planar frame's (the same measures).
    """
    ribs = {'ribs': 3}
    coarse = run(UmbrellaRibsParams.from_mapping({**ribs, **COARSE}))
    fine = run(UmbrellaRibsParams.from_mapping({**ribs, **FINE}), keep_samples=False)
    grid_rows = grid_row_figures(coarse, lambda s: s.tip[:, 1])
    period = first_mode_period()
    for k in range(3):
        assert_figures_of_the_physics(
            *({name: f[name][k] for name in ('stage2_tip_amplitude', 'stage2_tip_period')}
              for f in (coarse.figures, fine.figures)), grid_rows[k], period)


@needs_kernel
def test_the_umbrellas_kernel_keeps_the_tips_its_fold_drops():
    """
    The compiled advance's fold (Advance3DCall.tips) against its rows folded in Python.

    Three ribs, rib 2 kicked out of its plane, on the 5 ms grid: the physics steps' tips
    (Record3D.taken_tips: in-plane v and out-of-plane w) are the same with the kernel folding
    the substeps as with Record3D folding the kernel's every row (its stress figures off),
    the same steps; every grid step's last is its row's.
    """
    params = UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib2.out_of_plane_rate': 0.05,
                                              **COARSE})
    runs = [UmbrellaSimulator3D(params, kernel='compiled') for _ in range(2)]
    runs[1].integrator.compiled.set_figures(False)
    tips = []
    for sim in runs:
        sim.run(5.0, after_lock=0.05)
        rows = sim.record.take()
        tips.append(sim.record.taken_tips)
    assert runs[0].integrator.compiled.figures and runs[0].stage2_substeps == 50
    (t, v), (t_python, v_python) = tips
    np.testing.assert_array_equal(t, t_python)
    np.testing.assert_array_equal(v, v_python)
    assert np.abs(v[:, 2, 1]).max() > 1e-4             # (the kick's out-of-plane vibration)
    ends = np.searchsorted(t, rows['time'])
    np.testing.assert_array_equal(t[ends], rows['time'])
    np.testing.assert_array_equal(v[ends], rows['tip'][:, :, 1:])
    lock = runs[0].lock_time            # (stage 1: the grid's steps; stage 2: its substeps)
    assert np.sum(t < lock) == np.sum(rows['time'] < lock)
    assert np.diff(t[t > lock]).max() <= COARSE['time_step'] / 50 * (1 + 1e-9)
