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
``umbrella_sim simulate --set ribs=N --csv FILE``: every physics step of the umbrella, per rib.

The file is read back as a user would (the header's 'name (unit)' columns) and checked
against physics and against the run's own summary (Summary3D, every step): the energy
balance with the hinge's friction work holds on every row, the stuck hinge holds its rib,
mirror-image ribs have the same columns, and the summary's per-rib figures (deployment
instants, peaks, tips, friction work) are those of the rows.
"""
import csv
import errno
import json
import math
import pathlib

import numpy as np
import pytest

from umbrella_sim.core import UmbrellaParams, UmbrellaRibsParams, UmbrellaSimulator3D
from umbrella_sim.core.umbrella3d.outputs3d import _channels, first_reach, STRESS_NAMES
from umbrella_sim.tools import cli, csv_output

RELEASE = 0.02
RUN = ['simulate', '--set', 'ribs=3', '--set', f'rib.stick_until=[0.0, {RELEASE}, 0.0]',
       '--set', 'rib.hinge_coulomb=[0.0, 0.05, 0.0]', '--v0', '0', '--force', '40',
       '--time-step', '2e-4', '--duration', '0.3']


def read_csv(path) -> tuple[dict, dict]:
    """Return the columns by name (floats; stage as text) and each column's unit."""
    with open(path, newline='') as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    names, units = [], {}
    for h in header:
        name, _, unit = h.partition(' (')
        names.append(name)
        units[name] = unit.rstrip(')')
    cols = {n: [r[i] for r in body] for i, n in enumerate(names)}
    return {n: (v if n == 'stage' else np.array(v, dtype=float)) for n, v in cols.items()}, units


@pytest.fixture(scope='module')
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp('ribs_csv') / 'run.csv'
    import contextlib
    import io
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert cli.main([*RUN, '--csv', str(out), '--json']) == 0
    return read_csv(out), json.loads(text.getvalue())


def test_the_header_names_every_ribs_figures_with_their_units(run):
    (cols, units), figures = run
    assert list(cols)[:2] == ['time', 'stage'] and units['time'] == 's'
    for k in range(3):
        assert units[f'rib{k}_alpha1'] == 'rad' and units[f'rib{k}_alpha2_rate'] == 'rad/s'
        assert [units[f'rib{k}_tip_{c}'] for c in 'uvw'] == ['m'] * 3
        for name in STRESS_NAMES:
            assert units[f'rib{k}_stress_{name}'] == 'Pa'
        assert units[f'rib{k}_friction_work'] == 'J'
    assert units['sleeve_force'] == 'N' and units['energy_balance'] == 'J'
    assert not any(n.startswith('bus_') for n in cols)          # a fixed hub: no bus


def test_every_step_is_a_row_and_the_lock_its_own(run):
    (cols, _), figures = run
    # t = 0, every physics step, and the instant of the lock between two steps
    assert len(cols['time']) == figures['steps'] + 2
    assert np.all(np.diff(cols['time']) > 0)
    locked = np.array(cols['stage']) == 'locked'
    first = int(np.argmax(locked))
    assert cols['time'][first] == figures['lock_time'] and locked[first:].all()
    assert not locked[:first].any()


def test_the_rows_keep_the_energy_balance_with_the_friction_work(run):
    """T + V - (T + V)(0) = W_sleeve + W_friction - lock loss on every row, to round-off."""
    (cols, _), _ = run
    energy = cols['kinetic_energy'] + cols['strain_energy']
    friction = sum(cols[f'rib{k}_friction_work'] for k in range(3))
    balance = (energy - energy[0] - cols['work'] - friction - cols['drive_work']
               + cols['lock_energy_loss'])
    scale = np.abs(energy).max()
    assert np.abs(balance).max() < 1e-10 * scale
    assert np.allclose(cols['energy_balance'], balance, rtol=0, atol=1e-12 * scale)
    # only the rubbing rib's hinge takes energy out; the sleeve is pushed with N F
    assert cols['rib1_friction_work'][-1] < 0.0
    assert not cols['rib0_friction_work'].any() and not cols['rib2_friction_work'].any()
    assert np.all(cols['sleeve_force'] == 3 * 40.0)


def test_the_stop_reaction_is_the_stops_push_on_the_sleeve_along_plus_y(tmp_path):
    """Settled on the stop under N F along -Y (damped), the stop pushes the sleeve up: +N F."""
    path = tmp_path / 'settled.csv'
    assert cli.main(['simulate', '--set', 'ribs=3', '--v0', '0', '--force', '40', '--set',
                     'damping_ratio=0.5', '--duration', '0.4', '--csv', str(path)]) == 0
    cols, units = read_csv(path)
    locked = np.array(cols['stage']) == 'locked'
    assert units['stop_reaction'] == 'N' and locked[-1]
    assert not cols['stop_reaction'][~locked].any()                # no stop before the lock
    assert cols['stop_reaction'][-1] == pytest.approx(3 * 40.0, rel=2e-3)
    doc = (pathlib.Path(__file__).parents[1] / 'msg_docs' / 'topic_ribs.md').read_text()
    row = next(line for line in doc.splitlines() if line.startswith('| `stop_reaction`'))
    assert 'along +Y' in row and '+ pushes up' in row


def test_the_stuck_hinge_holds_its_rib_and_mirror_ribs_agree(run):
    (cols, _), _ = run
    t = cols['time']
    stuck = t < RELEASE - 1e-9
    assert cols['rib1_stuck'][stuck].all() and not cols['rib1_stuck'][~stuck].any()
    # clamped at its root: its chord alpha1 turns only by the leaf's bending under the
    # hold M, at the most M l1 / (3 E I) (the leaf's moment falls linearly from O to O'')
    p = UmbrellaParams()
    bend = (np.max(np.abs(cols['rib1_holding_torque'][stuck])) * p.l1
            / (3.0 * p.youngs_modulus * p.cross_section_inertia))
    assert 0.0 < np.ptp(cols['rib1_alpha1'][stuck]) <= 1.03 * bend
    # ribs 0 and 2 are mirror images about rib 1's plane (azimuths 0, 120, 240 degrees)
    for name in ('alpha1', 'alpha2_rate', 'tip_v', 'stress_von_mises'):
        assert np.array_equal(cols[f'rib0_{name}'], cols[f'rib2_{name}'])


def test_the_summary_is_the_rows_figures(run):
    """
    Summary3D took the same steps: its per-rib figures are the rows' (first_reach's rule).

    Its deployment instants are interpolated between the physics steps (the lock's own row
    left out: the summary takes steps), the lock's own instant for a rib that reaches its
    deployed angle in the lock's step.
    """
    (cols, _), figures = run
    steps = np.array(cols['time']) != figures['lock_time']
    t = cols['time'][steps]
    alpha_deployed = math.pi / 12
    for k in range(3):
        deployed = first_reach(t, cols[f'rib{k}_alpha1'][steps] - alpha_deployed,
                               lock=figures['lock_time'])
        assert deployed == pytest.approx(figures['rib_deploy_time'][k], rel=1e-14)
        assert abs(deployed - figures['lock_time']) < 2e-4
        assert cols[f'rib{k}_stress_von_mises'].max() == \
            figures['peak_stress']['von_mises']['value'][k]
        assert np.abs(cols[f'rib{k}_tip_v']).max() == figures['max_in_plane_tip'][k]
        assert cols[f'rib{k}_friction_work'][-1] == figures['friction_work'][k]
    tip_w = np.max([np.abs(cols[f'rib{k}_tip_w']).max() for k in range(3)])
    assert tip_w == figures['max_out_of_plane_tip']


def test_a_moving_base_adds_the_bus_and_its_momentum(tmp_path):
    """A free bus: its state and momentum columns; the momentum starts and stays at zero."""
    out = tmp_path / 'free.csv'
    assert cli.main(['simulate', '--set', 'ribs=2', '--set', 'base=free', '--v0', '-0.2',
                     '--duration', '0.002', '--csv', str(out)]) == 0
    cols, units = read_csv(out)
    assert units['bus_y'] == 'm' and units['bus_psi_rate'] == 'rad/s'
    assert units['linear_momentum_y'] == 'kg m/s'
    assert units['angular_momentum_z'] == 'kg m^2/s'
    # nothing pushes the free system from outside: its linear momentum stays at 0, and the
    # bus recoils along Y against the sleeve's motion
    p = np.stack([cols[f'linear_momentum_{c}'] for c in 'xyz'])
    scale = 1.0 + np.abs(cols['sleeve_velocity']).max()
    assert np.abs(p).max() < 1e-9 * scale
    assert cols['bus_y_rate'][-1] * cols['sleeve_velocity'][-1] < 0.0


def test_a_write_error_stops_the_file_not_the_run(tmp_path, monkeypatch, capsys):
    """
    A full disk: the file keeps its whole rows, the summary of every step printed, exit 4.

    The disk fills while the third write goes out, leaving half a row: the file keeps the
    header, the t = 0 row and the first chunk's rows, each whole, and the error says how
    many and up to when.
    """
    out = tmp_path / 'full.csv'
    real = csv_output.StepCsv._write_columns
    written = []

    def full_disk(self, columns):
        if len(written) == 2:
            self._fh.write(b'0.0123,deploying,0.4')        # (a row the disk cut)
            raise OSError(errno.ENOSPC, 'No space left on device')
        written.append((len(columns[0]), float(columns[0][-1])))
        real(self, columns)

    monkeypatch.setattr(csv_output.StepCsv, '_write_columns', full_disk)
    assert cli.main([*RUN, '--csv', str(out), '--json']) == 4
    captured = capsys.readouterr()
    figures = json.loads(captured.out)
    assert figures['ribs'] == 3 and figures['steps'] == 1500        # the whole run
    rows = sum(n for n, _ in written)
    last = written[-1][1]
    assert rows > 2 and written[0] == (1, 0.0)
    assert (f'--csv {out}: No space left on device (the file keeps its first {rows} rows '
            f'whole, to t = {last:g} s)') in captured.err
    assert 'the summary above is complete' in captured.err
    cols, _ = read_csv(out)
    assert len(cols['time']) == rows and cols['time'][-1] == last
    assert out.read_bytes().endswith(b'\n')


def test_both_outputs_failing_are_each_named(tmp_path, monkeypatch, capsys):
    """--mcap and --csv both stopped by the disk: each named, exit 4, the summary whole."""
    from umbrella_sim.ros import recording

    out, bag = tmp_path / 'full.csv', tmp_path / 'bag'
    real_record = recording.record_offline

    def recording_that_fails(*args, **kwargs):
        result = real_record(*args, **kwargs)
        result.recording_error = f'--mcap {bag}: No space left on device'
        return result

    def full_disk(self, columns):
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(recording, 'record_offline', recording_that_fails)
    monkeypatch.setattr(csv_output.StepCsv, '_write_columns', full_disk)
    assert cli.main([*RUN, '--duration', '0.01', '--csv', str(out), '--mcap', str(bag),
                     '--json']) == 4
    err = capsys.readouterr().err
    assert f'output incomplete: --mcap {bag}: No space left on device' in err
    assert (f'output incomplete: --csv {out}: No space left on device (removed: it held no '
            'whole row)') in err
    assert not out.exists()


def test_csv_state_is_refused_for_the_umbrella_naming_it(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main([*RUN, '--csv', str(tmp_path / 'x.csv'), '--csv-state'])
    assert exc.value.code == 2 and '--csv-state' in capsys.readouterr().err
    assert not (tmp_path / 'x.csv').exists()


def test_the_text_summary_gives_each_ribs_figures_with_units(capsys):
    """The text of simulate: a figure a line, per-rib lists rib 0 first, each with its unit."""
    assert cli.main([*RUN[:-1], '0.05']) == 0
    lines = dict(line.split(None, 1) for line in capsys.readouterr().out.splitlines())
    assert lines['ribs'] == '3'
    assert lines['rib_deploy_time'] == '-, -, - s'            # not deployed by 0.05 s
    assert lines['friction_work'].endswith(' J') and len(lines['friction_work'].split(',')) == 3
    assert lines['max_in_plane_tip'].endswith(' mm')
    for name in STRESS_NAMES:
        values, unit = lines[f'peak_{name}'].rsplit(' ', 1)
        assert unit == 'MPa' and len(values.split(', ')) == 3
    assert lines['peak_von_mises_at'].count(' m at ') == 3
    assert not any('{' in text for text in lines.values())     # no Python dict written out


@pytest.mark.parametrize('model', [
    [], ['--set', 'ribs=3', '--set', 'rib.tip_mass=[0, 0, 0.01]'],
    # works that add up (the sleeve force's, a rubbing hinge's, the damping's): the running
    # totals summed alike whatever blocks the run is stepped in
    ['--set', 'ribs=3', '--set', 'rib.hinge_coulomb=[0, 0.5, 0]', '--v0', '0', '--force', '40',
     '--set', 'damping_ratio=0.02']], ids=['planar', 'ribs', 'ribs-with-works'])
def test_the_csv_is_every_step_with_or_without_a_recording(model, tmp_path, capsys):
    """--mcap steps the same run on the publication grid: the same summary, the same rows."""
    run = ['simulate', *model, '--time-step', '2e-4', '--duration', '0.3', '--json']
    plain, recorded = tmp_path / 'plain.csv', tmp_path / 'recorded.csv'
    assert cli.main([*run, '--csv', str(plain)]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert cli.main([*run, '--csv', str(recorded), '--mcap', str(tmp_path / 'bag'),
                     '--publish-rate', '500']) == 0
    again = json.loads(capsys.readouterr().out)
    assert recorded.read_bytes() == plain.read_bytes()
    assert len(plain.read_text().splitlines()) == figures['steps'] + 3   # header, t = 0, lock
    for key in ('deploy_time', 'energy_drift', 'constraint_residual_max', 'peak_stress',
                'sleeve_work', 'friction_work', 'damping_dissipation'):
        assert again.get(key) == figures.get(key)


def test_a_rows_stresses_are_the_largest_over_its_step_as_the_docs_say(tmp_path):
    # the row's stress columns hold each step's crest (rib_peak_stress's rule), not the
    # stress at the step's end: in stage 2 at V0 = -0.5 m/s the last row's crest lies
    # inside its step, above the end state's stresses, which bound it from below
    duration = 0.12
    path = tmp_path / 'r.csv'
    assert cli.main(['simulate', '--set', 'ribs=2', '--v0', '-0.5', '--duration',
                     str(duration), '--csv', str(path)]) == 0
    cols, _ = read_csv(path)
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({'ribs': 2, 'v0': -0.5}))
    sim.run(duration)
    assert cols['time'][-1] == pytest.approx(sim.time, abs=1e-12)
    m, s = sim.model, sim.state
    values, _ = _channels(np.concatenate(m.stress_blocks(s.qr[None]), -1),
                          np.concatenate(m.stress_rate_blocks(s.qr[None], s.vr[None]), -1))
    at_end = np.abs(values[0]).max(-1)                     # (rib, channel)
    for j, name in enumerate(STRESS_NAMES):
        for k in range(2):
            assert cols[f'rib{k}_stress_{name}'][-1] >= at_end[k, j] * (1 - 1e-12)
    assert cols['rib0_stress_von_mises'][-1] > 1.01 * at_end[0, -1]
    doc = (pathlib.Path(__file__).parents[1] / 'msg_docs' / 'topic_ribs.md').read_text()
    row = next(line for line in doc.splitlines() if line.startswith('| `rib<k>_stress_axial`'))
    assert 'over the step' in row and "at the step's end |" not in row
