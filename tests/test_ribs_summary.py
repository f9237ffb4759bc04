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
The test API's summary of a recording of the umbrella of N ribs (summary_from_recording).

Recorded offline (``umbrella_sim simulate --mcap``) and compared with the run's Summary3D
figures (every physics step; the recording's metadata holds them): with a publication every
physics step the recording's figures are the summary's, figure for figure; at a coarser rate
the peaks are still exact (each publication holds the peak of every step since the last
one) and the deployment instants and tips are the summary's within what sampling allows.
"""
import json

import numpy as np
import pytest

from umbrella_sim.bag.format import SUMMARY_RECORD
from umbrella_sim.bag.reader import read_log
from umbrella_sim.core.umbrella3d.outputs3d import STRESS_NAMES
from umbrella_sim.testing import RibsRunSummary, RunSummary, summary_from_recording
from umbrella_sim.tools import cli

STEP = 2e-4
RUN = ['simulate', '--set', 'ribs=3', '--set', 'rib.stick_until=[0.0, 0.02, 0.0]',
       '--set', 'rib.hinge_coulomb=[0.0, 0.05, 0.0]', '--set', 'rib.tip_mass=[0.0, 0.0, 0.01]',
       '--v0', '0', '--force', '40', '--time-step', str(STEP), '--duration', '0.3']


def record(tmp_path, rate: float) -> tuple[str, dict]:
    """Record the run at rate Hz; return the bag and its Summary3D figures (metadata)."""
    bag = str(tmp_path / f'ribs_{rate:g}')
    assert cli.main([*RUN, '--mcap', bag, '--publish-rate', str(rate)]) == 0
    return bag, json.loads(read_log(bag).metadata[SUMMARY_RECORD]['figures'])


@pytest.fixture(scope='module')
def every_step(tmp_path_factory):
    return record(tmp_path_factory.mktemp('every_step'), 1.0 / STEP)


def test_with_a_publication_every_step_the_figures_are_the_summarys(every_step):
    """
    The same definitions on the same samples: Summary3D's figures.

    Exactly, but for what a recording's times (integer nanoseconds) change: an instant
    interpolated between two of them, to 1e-9 s.
    """
    bag, figures = every_step
    s = summary_from_recording(bag, after_lock=None)
    assert isinstance(s, RibsRunSummary) and s.ribs == 3
    assert s.samples == figures['steps'] + 1
    assert s.lock_time == figures['lock_time'] and s.deploy_time == figures['deploy_time']
    assert s.first_push_time == figures['deploy_start'] == 0.0
    # the spread between ribs (rib 2 carries a tip mass, rib 1 was stuck): every rib
    # reaches its deployed angle in the lock's step, so each deploys at the lock
    # (outputs3d.first_reach), from the samples as in the summary
    assert list(s.rib_deploy_time) == pytest.approx(figures['rib_deploy_time'], abs=1e-9)
    assert s.deployment_lag == pytest.approx(figures['deployment_lag'], abs=2e-9)
    assert figures['rib_deploy_time'] == [figures['lock_time']] * 3
    assert figures['deployment_lag'] == 0.0
    assert s.latest_rib == figures['latest_rib']
    assert s.max_leaf_angle_spread == figures['max_leaf_angle_spread'] > 0.0
    assert s.max_leaf_angle_spread_time == pytest.approx(
        figures['max_leaf_angle_spread_time'], abs=1e-9)
    for name in STRESS_NAMES:
        peak = figures['peak_stress'][name]
        assert list(s.peak_stress[name]) == peak['value']
        assert list(s.peak_stress_time[name]) == pytest.approx(peak['time'], abs=1e-9)
    vm = figures['peak_stress']['von_mises']
    assert list(s.peak_von_mises_at) == list(zip(vm['body'], vm['x']))
    assert list(s.max_in_plane_tip) == figures['max_in_plane_tip']
    assert (s.max_out_of_plane_tip, s.max_out_of_plane_tip_rib) == (
        figures['max_out_of_plane_tip'], figures['max_out_of_plane_tip_rib'])
    assert s.friction_work == pytest.approx(sum(figures['friction_work']), rel=1e-15)
    assert s.friction_work < 0.0
    assert s.energy_balance_residual == figures['energy_balance_residual']
    # each rib's stage 2, by the planar summary's rule on the same rows
    assert [r.stage2_tip_amplitude for r in s.stage2] == pytest.approx(
        figures['stage2_tip_amplitude'], rel=1e-12)


def test_at_a_coarser_rate_the_peaks_stay_exact_and_the_rest_within_a_period(tmp_path):
    rate = 500.0
    period = 1.0 / rate
    bag, figures = record(tmp_path, rate)
    s = summary_from_recording(bag, after_lock=None)
    assert s.samples == round(0.3 * rate) + 1
    for name in STRESS_NAMES:
        peak = figures['peak_stress'][name]
        assert list(s.peak_stress[name]) == peak['value']
        # held by the first publication at or after the step it happened in
        late = np.array(s.peak_stress_time[name]) - np.array(peak['time'])
        assert np.all(late > -1e-12) and np.all(late < period)
    # a deployment instant from samples: the leaf angle reached its deployed angle by the
    # first sample past it (the summary's instant is never later), and not before the
    # period it is interpolated in (the leaf vibrates about that angle once locked: a
    # crossing between two samples may go unseen, and the sampled one come later)
    for got, want in zip(s.rib_deploy_time, figures['rib_deploy_time']):
        sample_past = np.ceil(got / period - 1e-9) * period
        assert -period < got - want and want <= sample_past + 1e-12
    # the tips of the samples: never beyond the every-step maxima
    assert np.all(np.array(s.max_in_plane_tip) <= np.array(figures['max_in_plane_tip']))
    assert s.max_out_of_plane_tip <= figures['max_out_of_plane_tip']


def test_each_ribs_stage_2_is_the_planar_test_summarys_rule(every_step):
    """Per rib, summarize_run of its in-plane tip and von Mises peak after the lock."""
    bag, figures = every_step
    # stage 2 over the default window after the lock, of which the recording holds less
    with pytest.warns(UserWarning, match='of stage 2 after the lock'):
        s = summary_from_recording(bag)
    assert len(s.stage2) == 3 and all(isinstance(r, RunSummary) for r in s.stage2)
    for k, rib in enumerate(s.stage2):
        assert rib.lock_time == s.lock_time and rib.stage2_samples > 0
        # the window's von Mises peak is at most the run's, and here the run's (the peak
        # stress comes after the lock)
        assert rib.stage2_peak_stress == s.peak_stress['von_mises'][k]
        assert 0.0 < rib.stage2_tip_amplitude <= s.max_in_plane_tip[k]
    assert s.stage2_peak_stress == tuple(r.stage2_peak_stress for r in s.stage2)
    # rib 2 carries a tip mass: it swings wider than rib 0 after the lock
    assert s.stage2_tip_amplitude[2] > s.stage2_tip_amplitude[0]


def test_a_planar_recording_still_gives_a_run_summary(tmp_path):
    bag = str(tmp_path / 'planar')
    assert cli.main(['simulate', '--duration', '0.3', '--mcap', bag]) == 0
    assert type(summary_from_recording(bag, after_lock=0.05)) is RunSummary


def test_compare_takes_a_torn_recordings_figures_from_its_samples(every_step, tmp_path):
    """
    umbrella_compare of a recording whose writer was killed (no summary record).

    Its figures are those of its samples, and say so; with a publication every step they are
    the summary's of the same run stopped at its last sample (each series' own end).
    """
    import os

    from umbrella_sim.core.driver import simulate
    from umbrella_sim.core.umbrella3d.params3d import node_model
    from umbrella_sim.tools.compare_ribs import compare_ribs, load_ribs_run

    bag, figures = every_step
    log = read_log(bag)
    torn = tmp_path / 'torn.mcap'
    with open(log.path, 'rb') as fh:
        data = fh.read()
    # a killed writer: its last chunks lost, and the summary record (written at the close,
    # ahead of the chunk still buffered: where it sits moves with the messages' sizes)
    torn.write_bytes(data[:min(int(len(data) * 0.93), data.index(SUMMARY_RECORD.encode()))])
    run = load_ribs_run(str(torn), 'torn')
    got = run.figures
    assert 'no summary record' in got['figures_from'] and '5000.0 Hz' in got['figures_from']
    assert len(run.t) < figures['steps'] + 1 and os.path.getsize(torn) < len(data)
    params = node_model(read_log(str(torn)).segment(0).params)

    def summary_to(t_end):
        return simulate(params, t_end + STEP / 2, keep_samples=False).figures

    assert run.t[-1] > figures['lock_time']             # (it deployed before the cut)
    # the lock: the events record's, or with it lost the 'locked' phase message's time, the
    # publication that followed the lock (here the next step)
    assert 0.0 <= got['lock_time'] - figures['lock_time'] < STEP
    # each rib deployed at the lock (in its step), the lock as the recording has it
    assert got['rib_deploy_time'] == [got['lock_time']] * 3
    assert figures['rib_deploy_time'] == [figures['lock_time']] * 3
    stress_end = float(read_log(str(torn)).decoded(
        read_log(str(torn)).find_topic('rib_peak_stress'))[-1][0])
    want = summary_to(stress_end)
    for name in STRESS_NAMES:
        assert got['peak_stress'][name]['value'] == want['peak_stress'][name]['value']
    assert got['peak_stress']['von_mises']['body'] == want['peak_stress']['von_mises']['body']
    assert got['max_in_plane_tip'] == summary_to(float(run_tip_end(torn)))['max_in_plane_tip']
    table = compare_ribs([run])['runs'][0]
    assert table['figures_from'] == got['figures_from']
    assert table['peak_von_mises'] == want['peak_stress']['von_mises']['value']


def run_tip_end(path) -> float:
    log = read_log(str(path))
    return log.decoded(log.find_topic('rib_tip_deflection'))[-1][0]


def test_the_sleeve_work_is_the_energy_a_run_from_rest_took_in(capsys):
    """
    From rest (V0 0, no friction, no damping) T + V at the end is the sleeve force's work.

    A free bus: its state and momenta end the text summary, each component with its unit.
    """
    assert cli.main(['simulate', '--set', 'ribs=3', '--set', 'base=free', '--set',
                     'lock=plastic', '--set', 'sleeve_force=6', '--set', 'v0=0',
                     '--duration', '0.05', '--json']) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures['sleeve_work'] > 0.0
    assert figures['sleeve_work'] == pytest.approx(figures['energy_scale'], rel=1e-9)
    text = cli.format_summary(figures)
    assert 'bus_q                        X ' in text and ' rad, beta ' in text
    assert 'linear_momentum              X ' in text and ' kg m/s' in text
