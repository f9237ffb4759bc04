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
The run driver steps the umbrella of N ribs as the umbrella's own loop does.

``RunDriver`` over ``UmbrellaRibsParams`` (umbrella3d.driven3d) takes the steps a chunk at a
time, with the sleeve force from a ForceSchedule, stops its chunks at the lock, holds each
rib's peak stresses over a publication period and sums the run up.  Its steps are the
simulator's own (``advance``: compiled runs of steps with a fixed hub, else ``step``), so its
record must be ``UmbrellaSimulator3D.run``'s with the same force changes: every figure
exactly (the same arithmetic in the same order), the running sums of work to round-off
(ACCUMULATED).  The summary is checked against ``Record3D.summary`` of the whole
record (the same rules, fed in parts), and the physics it reports: the energy balance with
the hinges' friction work, a stuck rib held at its angle until its release time.
"""
import json
import math

import numpy as np
import pytest

from umbrella_sim.core.driver import RunDriver
from umbrella_sim.core.umbrella3d.blocks3d import RibPeaks
from umbrella_sim.core.umbrella3d.driven3d import DrivenSimulator3D
from umbrella_sim.core.umbrella3d.outputs3d import deployment_spread, first_reach, STRESS_NAMES
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
from umbrella_sim.core.umbrella3d.summary3d import SUMMARY_BATCH_ROWS

#: rib 1 stuck for 20 ms and rubbing in its hinge, from rest, pushed hard (locks at ~0.21 s)
STUCK = {'ribs': 2, 'sleeve_force': 60.0, 'time_step': 2e-4, 'v0': 0.0,
         'rib1.stick_until': 0.02, 'rib1.hinge_coulomb': 0.05, 'rib1.hinge_viscous': 0.01}
#: the force per rib from 30 ms on
PUSH = (0.03, 80.0)
BALANCE_TOLERANCE = 1e-10      # relative to the largest T + V (tests/test_umbrella3d.py)


def reference(params, duration: float, push=None, after_lock=None):
    """Return UmbrellaSimulator3D's own run (F per rib changed at push), and its record."""
    sim = UmbrellaSimulator3D(params)
    if push is not None:
        sim.advance(round(push[0] / sim.h))
        sim.force = push[1] * sim.model.n_ribs
    sim.run(duration, after_lock)
    return sim, sim.record.arrays()


def ref_backend(params) -> str:
    """Return the backend UmbrellaSimulator3D takes for params (the compiled step, or numpy)."""
    return 'numpy' if UmbrellaSimulator3D(params).integrator.compiled is None else 'compiled'


def driven(params, duration: float, push=None, after_lock=None, **kwargs):
    """Return a RunDriver's run of params: the driver, every chunk and every publication."""
    driver = RunDriver(params, force_profile=[push] if push else None, **kwargs)
    chunks, publications = [], []
    driver.run(duration, stop_after_lock=after_lock, on_chunk=chunks.append,
               on_publication=publications.append)
    return driver, chunks, publications


def stacked(driver, chunks) -> dict:
    """Return the driven run's rows, its initial sample's first (Record3D.arrays' form)."""
    first = driver.initial.fields()
    rows = [c.block.rows for c in chunks if len(c.block)]
    out = {}
    for name in rows[0]:
        start = np.asarray(first['stage'] == 'locked') if name == 'locked' else first[name]
        out[name] = np.concatenate([np.asarray(start)[None], *(r[name] for r in rows)])
    return out


#: the running sums of work: the compiled step's record adds a run of steps' work to the
#: total by a cumulative sum, so where its runs start (the driver's chunks, a force change)
#: moves their last bit; every other figure is the same arithmetic on the same states
ACCUMULATED = ('work', 'friction_work', 'drive_work')


def assert_same_record(got: dict, want: dict) -> None:
    """Assert two records equal: exactly, the running sums of work to their round-off."""
    assert set(got) == set(want)
    for name in want:
        if name in ACCUMULATED:
            scale = float(np.max(np.abs(want[name]))) or 1.0
            np.testing.assert_allclose(got[name], want[name], rtol=0, atol=1e-14 * scale,
                                       err_msg=name)
        else:
            np.testing.assert_array_equal(got[name], want[name], err_msg=name)


def test_run_driver_takes_the_umbrellas_own_steps():
    """
    Step for step the record of the simulator's own loop, exactly, through a force change.

    Every figure of every step (joint angles and rates per rib, tip deflections, stresses,
    energies, friction work, the stuck flag and holding torque) equals the loop's; the
    force the schedule gave acts from its step; each publication holds, per rib, the largest
    stress of every component over the steps since the previous one; the stuck rib stays
    clamped at its root until its release time; the energy balance with the friction work holds.
    """
    params = UmbrellaRibsParams.from_mapping(STUCK)
    driver, chunks, publications = driven(params, 0.06, PUSH, period_steps=10)
    assert isinstance(driver.sim, DrivenSimulator3D)
    assert driver.backend == ref_backend(params)
    ref, a = reference(params, 0.06, PUSH)
    got = stacked(driver, chunks)
    assert len(got['time']) == len(a['time']) == ref.k + 1
    assert_same_record(got, a)
    # the push: acting from its step, as the schedule's one rule says
    applied = [tf for c in chunks for tf in c.applied]
    assert applied == [(pytest.approx(PUSH[0], abs=1e-12), PUSH[1])]
    assert driver.sim.sleeve_force == PUSH[1]
    assert got['sleeve_force'][-1] == PUSH[1] * 2
    # publications every 10 steps, each holding the largest stress since the previous one
    assert len(publications) == ref.k // 10
    for i, pub in enumerate(publications):
        assert pub.time == pytest.approx(a['time'][10 * (i + 1)], abs=1e-12)
        period = slice(10 * i + 1, 10 * (i + 1) + 1)
        for name in STRESS_NAMES:
            np.testing.assert_array_equal(getattr(pub, f'stress_{name}'),
                                          a[f'stress_{name}'][period].max(0))
    # the stuck rib clamped at its root until 20 ms: its chord alpha1 turns only by the
    # clamped leaf's bending under the hold M, M l1 / (3 E I) at the most; then free
    stuck = got['stuck'][:, 1]
    last = np.nonzero(stuck)[0].max()
    assert got['time'][last] < 0.02 <= got['time'][last + 1]
    p = params.planar
    bend = (np.max(np.abs(got['holding_torque'][:last + 1, 1])) * p.l1
            / (3.0 * p.youngs_modulus * p.cross_section_inertia))
    assert 0.0 < np.ptp(got['alpha1'][:last + 1, 1]) <= 1.03 * bend
    assert abs(got['alpha1'][-1, 1] - got['alpha1'][0, 1]) > 3.0 * bend
    figures = driver.summary.figures()
    assert figures['energy_drift'] < BALANCE_TOLERANCE
    assert figures['friction_work'][1] < -1e-3 * got['work'][-1]
    assert figures['friction_work'][0] == 0.0
    assert figures['steps'] == ref.k and figures['lock_time'] is None


@pytest.mark.parametrize('kernel', ['compiled', pytest.param('numpy', marks=pytest.mark.slow)])
def test_each_chunks_peaks_are_those_of_its_rows(kernel, monkeypatch):
    """
    A chunk's peaks, kept by Record3D as its steps come, are RibPeaks.of_rows of its rows.

    Every chunk of a run through a release and the lock (the compiled step's runs of steps
    and the lock's step; the numpy path's steps one at a time): each rib's largest of every
    component, where and when, the first step holding it.
    """
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
    params = UmbrellaRibsParams.from_mapping(STUCK)
    driver, chunks, _ = driven(params, 1.0, after_lock=0.004, period_steps=7)
    assert driver.backend == kernel and driver.sim.locked
    for chunk in chunks:
        block = chunk.block
        if not len(block):
            continue
        want = RibPeaks.of_rows(block.rows)
        got = block.peaks
        assert got is not None and got is not want
        for a, b in ((got.value, want.value), (got.at, want.at), (got.when, want.when)):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize('grow', [False, True])
def test_peaks_merged_at_once_are_those_merged_one_by_one(grow):
    """
    RibPeaks.merged_all (the summary's blocks at once) is merged block after block.

    Each rib's and component's first largest, the held one's on a tie, a NaN never larger
    (nor a value larger than a held NaN): with blocks of ties, NaNs and smaller values only,
    and with one of them larger somewhere (grow).
    """
    rng = np.random.default_rng(3)
    ribs, parts = 4, len(STRESS_NAMES)

    def peaks(value):
        return RibPeaks(value, rng.random((ribs, parts, 2)), rng.random((ribs, parts)))

    held = peaks(rng.random((ribs, parts)) + 1.0)
    held.value[0, 0] = np.nan
    news = []
    for k in range(5):
        value = held.value - rng.random((ribs, parts))
        value[1, k] = held.value[1, k]                 # (a tie)
        value[2, k] = np.nan
        news.append(peaks(value))
    if grow:
        news[1].value[3, 2] = news[3].value[3, 2] = held.value[3, 2] + 1.0
        news[2].value[0, 0] = 5.0                      # (past a held NaN: not larger)
    want = held
    for new in news:
        want = want.merged(new)
    got = held.merged_all(news)
    assert (got is held) is not grow
    for a, b in ((got.value, want.value), (got.at, want.at), (got.when, want.when)):
        np.testing.assert_array_equal(a, b)
    if grow:        # (the first block holding the larger value)
        np.testing.assert_array_equal(got.at[3, 2], news[1].at[3, 2])


@pytest.mark.parametrize('kernel', ['compiled', pytest.param('numpy', marks=pytest.mark.slow)])
def test_the_runs_peaks_are_the_first_largest_of_every_step(kernel, monkeypatch):
    """
    Record3D's peaks of the run, kept as its steps come, are those of all its rows at once.

    A run through a release and the lock: each rib's largest of every component over every
    step (RibPeaks.of_rows of the whole record: the first step holding it), where and when;
    a component that never exceeds 0 keeps no place ('').
    """
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
    sim, rows = reference(UmbrellaRibsParams.from_mapping(STUCK), 1.0, after_lock=0.004)
    assert sim.locked and ref_backend(sim.params) == kernel
    want = RibPeaks.of_rows(rows)
    peaks = sim.record.summary()['peak_stress']
    for j, name in enumerate(STRESS_NAMES):
        value, where = peaks[name]
        reached = want.value[:, j] > 0.0
        assert reached.any()
        np.testing.assert_array_equal(value, np.where(reached, want.value[:, j], 0.0))
        for rib, (body, x, t) in enumerate(where):
            if not reached[rib]:
                assert (body, x, t) == ('', 0.0, 0.0)
                continue
            code, at = want.at[rib, j]
            assert (body, x, t) == (('leaf', 'link')[int(code)], at, want.when[rib, j])


def test_the_planar_path_is_unchanged_by_the_umbrella():
    """The planar parameters still drive the planar simulator, its block and its Sample."""
    from umbrella_sim.core import UmbrellaParams, UmbrellaSimulator

    driver = RunDriver(UmbrellaParams(time_step=1e-4), publish_rate=1000.0)
    assert type(driver.sim) is UmbrellaSimulator
    driver.advance_period()
    s = driver.publication()
    assert {'peak_stress_leaf', 'q', 'tip_transverse'} <= set(s.__dict__)


@pytest.mark.slow      # ~6 s: two runs of ~1100 steps through the lock
def test_run_driver_summary_of_the_umbrella_through_the_lock():
    """
    Through the lock: the chunk stops at it, the lock sample stands at the stop, the summary.

    The summary figures of the driven run (from its chunks) are Record3D.summary's of the
    loop's whole record: each rib's deployment instant, the lag of the latest, the largest
    out-of-plane tip, each rib's peak stress of every component with where and when.
    """
    params = UmbrellaRibsParams.from_mapping(STUCK)
    driver, chunks, _ = driven(params, 0.4, after_lock=0.01, publish_rate=1000.0)
    ref, a = reference(params.with_physics_step(driver.step), 0.4, after_lock=0.01)
    got = stacked(driver, chunks)
    assert_same_record(got, a)
    locks = [c for c in chunks if c.lock is not None]
    assert len(locks) == 1 and locks[0].block.time[-1] >= ref.lock_time
    assert locks[0].lock.time == ref.lock_time and locks[0].lock.kind == ref.params.lock_rule
    s = locks[0].lock_sample
    m = ref.model
    # right after the lock: the sleeve at the stop (the root find's 1e-12 s times its speed),
    # at rest (both lock rules stop it)
    assert s.time == ref.lock_time and s.stage == 'locked'
    assert s.sleeve_position == pytest.approx(m.y_stop, abs=1e-9)
    assert s.sleeve_velocity == 0.0
    figures, summary = driver.summary.figures(), ref.record.summary()
    assert figures['lock_time'] == ref.lock_time
    np.testing.assert_array_equal(figures['rib_deploy_time'], summary['rib_deploy_time'])
    assert figures['deployment_lag'] == summary['deployment_lag']
    assert figures['latest_rib'] == int(np.argmax(summary['rib_deploy_time']))
    assert figures['max_out_of_plane_tip'] == summary['max_out_of_plane_tip']
    assert figures['max_leaf_angle_spread'] == summary['max_leaf_angle_spread'] > 0.0
    assert figures['max_leaf_angle_spread_time'] == summary['max_leaf_angle_spread_time']
    # (the residual is round-off of the running sums of work: ACCUMULATED)
    assert figures['energy_balance_residual'] == pytest.approx(
        summary['energy_balance_residual'], rel=0, abs=1e-13 * summary['energy_scale'])
    assert figures['energy_drift'] < BALANCE_TOLERANCE
    for name in STRESS_NAMES:
        top, where = summary['peak_stress'][name]
        peak = figures['peak_stress'][name]
        np.testing.assert_array_equal(peak['value'], top)
        assert [(b, x, t) for b, x, t in zip(peak['body'], peak['x'], peak['time'])] == where
    # every rib deployed, in the lock's step: at the lock (outputs3d.first_reach)
    assert figures['rib_deploy_time'] == [ref.lock_time] * ref.model.n_ribs
    assert not math.isnan(figures['deployment_lag'])


@pytest.mark.parametrize('deployed, lag, latest', [
    ([0.2, 0.21, 0.205], 0.01, 1),              # every rib deployed: the last one's lag
    ([0.2, math.nan, 0.21], None, 1),           # rib 1 still to deploy: it lags the most
    ([math.nan, math.nan, 0.2], None, 0),
    ([math.nan] * 3, None, None),
])
def test_the_lag_waits_for_every_rib_and_the_latest_is_one_still_to_deploy(
        deployed, lag, latest):
    spread = deployment_spread(deployed)
    assert spread['latest_rib'] == latest
    assert spread['deployment_lag'] == (None if lag is None else pytest.approx(lag))
    assert spread['rib_deploy_time'] == [None if math.isnan(t) else t for t in deployed]


def test_a_rib_that_never_deploys_leaves_the_lag_open_and_is_the_latest():
    """
    A rib too soft to reach its angle (E = 1e5 Pa): the sleeve locks, the rib does not.

    Both summaries (the driver's, fed a chunk at a time, and Record3D's of every step) say
    that rib 1 has no deployment instant, leave the lag open and name rib 1 the latest.
    """
    params = UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib1.youngs_modulus': 1e5})
    driver, _, _ = driven(params, 0.26)
    figures = driver.summary.figures()
    lock = figures['lock_time']
    assert lock is not None and figures['rib_deploy_time'] == [lock, None, lock]
    assert figures['deployment_lag'] is None and figures['latest_rib'] == 1
    ref, _ = reference(params, 0.26)
    summary = ref.record.summary()
    assert math.isnan(summary['deployment_lag'])
    assert math.isnan(summary['rib_deploy_time'][1])


def test_ribs_that_deploy_at_the_lock_deploy_at_its_instant():
    """
    Identical ribs at a 0.2 ms step: each rib's deployment instant is the lock's own.

    The sleeve at the stop is every rib at its deployed angle (each leaf angle 7e-6 rad past
    it at the lock: the rib's elastic deformation); a line between the steps around the
    lock, across which the velocity jumps, put the instant microseconds off.  Record3D's
    summary and the driver's Summary3D (fed a chunk at a time) alike.
    """
    params = UmbrellaRibsParams.from_mapping({'ribs': 3, 'time_step': 2e-4, 'v0': -0.5})
    driver, chunks, _ = driven(params, 0.2, after_lock=0.002)
    ref, a = reference(params, 0.2, after_lock=0.002)
    lock = ref.lock_time
    assert driver.summary.figures()['lock_time'] == lock
    assert driver.summary.figures()['rib_deploy_time'] == [lock] * 3
    np.testing.assert_array_equal(ref.record.summary()['rib_deploy_time'], lock)
    assert driver.summary.figures()['deployment_lag'] == 0.0
    # the steps around the lock: the line between them crosses microseconds off
    gap = a['alpha1'][:, 0] - ref.model.alpha_deployed[0]
    assert abs(first_reach(a['time'], gap) - lock) > 1e-6


def test_the_summary_reports_a_free_bus_and_its_momentum():
    """
    A free-floating bus: the summary gives its state and momenta, the momentum kept.

    The step keeps the linear momentum of a free bus to round-off (tests/test_umbrella3d.py);
    the driver's figures are those of the run's last state: the bus moved in reaction, the
    linear momentum is the initial one, and the energy balance with friction holds.
    """
    params = UmbrellaRibsParams.from_mapping(dict(STUCK, base='free', bus_mass=5.0,
                                                  bus_inertia=0.2))
    driver = RunDriver(params)
    driver.run(0.02)
    figures = driver.summary.figures()
    first = driver.initial
    assert len(figures['bus_q']) == len(figures['bus_v']) == 6
    assert max(abs(v) for v in figures['bus_v']) > 1e-6      # the bus moved in reaction
    scale = float(np.max(np.abs(first.linear_momentum))) + driver.sim.model.total_mass * max(
        abs(figures['bus_v'][0]), abs(figures['bus_v'][1]), abs(figures['bus_v'][2]))
    np.testing.assert_allclose(figures['linear_momentum'], first.linear_momentum, rtol=0,
                               atol=1e-12 * scale)
    assert figures['energy_drift'] < BALANCE_TOLERANCE


def test_an_umbrella_past_the_coupling_deflection_takes_the_step_its_stage2_needs():
    """
    Three ribs pushed by 10 N: a stage-2 tip deflection of 13 % of the leaf at 0.1 ms.

    Past the modes' coupling (7 %) the umbrella's stage 2 takes the step its lock needs
    (step_rule.stage2_step_needed, the planar rule judged on the worst rib: substeps3d.py),
    in substeps of its 0.2 ms grid step, where the step is chosen for the run (time_step
    0): nothing is said.  With the grid step given, stage 2 stays on it and the summary says
    'coarse step' with the step stage 2 needs; at that step, given, nothing is said, nor at
    V0 = -0.2 alone (6.3 %).
    """
    def coarse(values, duration):
        driver = RunDriver(UmbrellaRibsParams.from_mapping(values))
        assert driver.run(duration) is None
        figures = driver.summary.figures()
        return driver.sim, figures, [w for w in figures['warnings']
                                     if w.startswith('coarse step')]

    sim, figures, said = coarse({'ribs': 3, 'sleeve_force': 10.0}, 0.25)
    assert max(figures['max_in_plane_tip']) > 0.07 * 1.0 and not said
    assert sim.h == 2e-4 and sim.stage2_substeps == 6
    assert sim.stage2_resolution['deflection'] > 0.07
    sim, figures, (text,) = coarse({'ribs': 3, 'sleeve_force': 10.0, 'time_step': 1e-4}, 0.25)
    assert sim.stage2_substeps == 1 and 'couples its modes' in text
    assert 'time_step 0 takes' in text      # (how the run gets it: resolving_step_hint)
    enough = float(text.rsplit('time_step <= ', 1)[1].split()[0])
    assert enough < 1e-4
    assert not coarse({'ribs': 3, 'sleeve_force': 10.0, 'time_step': enough}, 0.25)[2]
    assert not coarse({'ribs': 3}, 0.6)[2]


@pytest.mark.parametrize('kick, warned', [(10.0, False), (20.0, True)])
def test_a_large_out_of_plane_tip_is_named_as_the_in_plane_one(kick, warned):
    """
    A rib kicked out of its plane: past 10 % of the leaf its out-of-plane tip is named.

    The in-plane tip stays under 1 % of the leaf; the out-of-plane one reaches 6.7 % (10 m/s,
    quiet) or 13 % (20 m/s): 'large out-of-plane deflection', with its rib, as the in-plane
    tip's 'large deflection' (small-deformation beams, model flexible).
    """
    driver = RunDriver(UmbrellaRibsParams.from_mapping({'ribs': 3,
                                                        'rib1.out_of_plane_rate': kick}))
    assert driver.run(0.03) is None
    figures = driver.summary.figures()
    assert max(figures['max_in_plane_tip']) < 0.01 and figures['max_out_of_plane_tip_rib'] == 1
    said = [w for w in figures['warnings'] if w.startswith('large')]
    w = abs(figures['max_out_of_plane_tip'])
    assert (w > 0.1) == warned
    assert said == ([f'large out-of-plane deflection: rib 1, |w_G| reached {w * 1e3:.4g} mm = '
                     f'{100 * w:.3g} % of the leaf length 1 m (limit 10 %): small-deformation '
                     'theory no longer holds (compare model flexible-nonlinear)'] if warned
                    else [])


def test_stage2_blocks_taken_in_batches_give_the_figures_of_whole_chunks():
    """
    Stage 2 in a 1 kHz node's chunks (5 rows each), which the summary takes 50 rows at once.

    Summary3D takes stage-2 blocks SUMMARY_BATCH_ROWS rows at a time: every figure, the
    stage-2 tip amplitudes and periods of every physics step included, is that of the same
    run in the driver's own chunks (64 rows, each taken as it comes), read mid-batch; the
    warnings said along the run (new_warnings) are said by its end.
    """
    params = UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib1.tip_mass': 0.05,
                                              'rib2.out_of_plane_rate': 0.3})
    whole, _, _ = driven(params, 1.0, after_lock=0.2033)
    fine, chunks, _ = driven(params, 1.0, after_lock=0.2033, period_steps=5)
    rows = [len(c.block) for c in chunks if len(c.block) and c.block.rows['locked'][0]]
    assert max(rows) == 5 and sum(rows) > 10 * SUMMARY_BATCH_ROWS
    assert fine.summary._waiting                    # (read mid-batch)
    said = fine.summary.new_warnings()
    got, want = fine.summary.figures(), whole.summary.figures()
    assert not fine.summary._waiting
    assert all(p > 0.0 for p in got['stage2_tip_period'])
    assert got['stage2_tip_w_amplitude'][2] > 1e-3
    assert json.dumps(got, sort_keys=True) == json.dumps(want, sort_keys=True)
    assert set(said + fine.summary.new_warnings()) == set(whole.summary.warnings())
