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
The deployed frame's natural frequencies (``umbrella_sim modes``, core/modal.py).

Checked against the physics they speak for: the simulated stage-2 period, the identity of N
identical ribs with the planar rib, the square-root law of a stiffer rib, the interlacing
of a free-floating bus with the held hub, the modal damping of C = beta K.
"""
import json
import math

import pytest

from umbrella_sim.core.driver import simulate
from umbrella_sim.core.modal import deployed_modes
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.tools.cli import main


def cli_rows(capsys, *args) -> list[dict]:
    """Return the rows of ``umbrella_sim modes ... --json``."""
    assert main(['modes', *args, '--json']) == 0
    return json.loads(capsys.readouterr().out)


def test_the_first_period_is_the_simulated_stage2_period(capsys):
    """The table's first mode is the one the locked frame vibrates in: its period to 0.5 %."""
    rows = cli_rows(capsys, '--count', '3')
    assert [r['multiplicity'] for r in rows] == [1, 1, 1]
    assert rows[0]['frequency_hz'] < rows[1]['frequency_hz'] < rows[2]['frequency_hz']
    run = simulate(UmbrellaParams(v0=-0.5), 0.6, keep_samples=False).figures
    assert rows[0]['period_s'] == pytest.approx(run['stage2_tip_period'], rel=5e-3)


def test_identical_ribs_repeat_the_planar_ribs_in_plane_modes(capsys):
    """
    N identical ribs on the stopped sleeve are N planar ribs: each in-plane frequency N times.

    The planar rib's frequencies appear among the umbrella's with multiplicity 3, all their
    strain energy in-plane, to 1e-9; the out-of-plane modes between them are the umbrella's own.
    """
    planar = [r['omega'] for r in cli_rows(capsys, '--count', '4')]
    rows = cli_rows(capsys, '--set', 'ribs=3', '--count', '30')
    in_plane = [r for r in rows if r['in_plane'] > 0.5]
    assert [r['omega'] for r in in_plane[:4]] == pytest.approx(planar, rel=1e-9)
    for r in in_plane[:4]:
        assert r['multiplicity'] == 3 and r['in_plane'] == pytest.approx(1.0, abs=1e-9)
        assert r['rib_share'] == pytest.approx(1 / 3, rel=1e-6)     # (one copy a rib)
    out = [r for r in rows if r['out_of_plane'] > 0.5]
    assert out and out[0]['omega'] < planar[0] and out[0]['multiplicity'] == 3


def test_a_stiffer_rib_has_its_own_modes_at_root_two(capsys):
    """Rib 1 at twice Young's modulus, the same mass: its modes sqrt(2) x the others', its own."""
    e = UmbrellaParams().youngs_modulus
    rows = cli_rows(capsys, '--set', 'ribs=3', '--set', f'rib1.youngs_modulus={2 * e!r}',
                    '--count', '8')
    others = [r for r in rows if r['multiplicity'] == 2]
    own = [r for r in rows if r['multiplicity'] == 1]
    assert len(own) >= 3
    for r in own[:3]:
        assert r['rib'] == 1 and r['rib_share'] > 0.999
        twin = min(others, key=lambda o: abs(o['omega'] * math.sqrt(2) - r['omega']))
        assert r['omega'] == pytest.approx(math.sqrt(2) * twin['omega'], rel=1e-9)
        assert r['out_of_plane'] == pytest.approx(twin['out_of_plane'], abs=1e-9)


def test_a_free_bus_raises_each_elastic_frequency_and_a_heavy_one_holds_the_hub():
    """
    The free-floating bus's elastic modes interlace above the held hub's (Rayleigh).

    Holding the bus adds constraints: the k-th frequency of the held umbrella is at most the
    k-th elastic one of the free umbrella; a bus of 1e9 kg (and inertia) is held, to 1e-6.
    """
    ribs = {'ribs': 3}
    held = deployed_modes(UmbrellaRibsParams.from_mapping(ribs))
    free = deployed_modes(UmbrellaRibsParams.from_mapping({**ribs, 'base': 'free'}))

    def each(rows):
        return [r.omega for r in rows for _ in range(r.multiplicity)]
    for h, f in zip(each(held)[:12], each(free)[:12]):
        assert f >= h * (1 - 1e-9)
    assert each(free)[0] > each(held)[0] * (1 + 1e-4)           # (a light bus moves)
    heavy = deployed_modes(UmbrellaRibsParams.from_mapping(
        {**ribs, 'base': 'free', 'bus_mass': 1e9, 'bus_inertia': 1e9}))
    assert each(heavy)[:12] == pytest.approx(each(held)[:12], rel=1e-6)


def test_each_mode_is_damped_as_the_beams_c_beta_k():
    """damping_ratio is the first mode's; mode i's is zeta omega_i / omega_1 (C = beta K)."""
    rows = deployed_modes(UmbrellaParams(damping_ratio=0.02), 5)
    assert rows[0].damping_ratio == pytest.approx(0.02, rel=1e-12)
    for r in rows:
        assert r.damping_ratio == pytest.approx(0.02 * r.omega / rows[0].omega, rel=1e-12)
    assert all(r.damping_ratio == 0.0 for r in deployed_modes(UmbrellaParams(), 5))


@pytest.mark.parametrize('args, culprit', [
    (['--count', '0'], '--count 0'),
    (['--model', 'rigid'], "--model: invalid choice: 'rigid'"),    # (beams' models only)
    (['--set', 'model=rigid'], 'model rigid: a rigid frame has no elastic modes'),
    (['--set', 'rib1.youngs_modulus=1e11'], 'rib1'),
])
def test_bad_input_is_refused_naming_the_culprit(capsys, args, culprit):
    with pytest.raises(SystemExit) as exit_:
        main(['modes', *args])
    assert exit_.value.code == 2
    assert culprit in capsys.readouterr().err


def test_the_text_table_counts_repeated_modes(capsys):
    """The text numbers modes as they come: a row of 3 repeated ones is modes k .. k+2."""
    assert main(['modes', '--set', 'ribs=3', '--count', '2']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert 'locked at full deployment' in lines[0] and 'the hub held' in lines[0]
    assert [line.split()[0] for line in lines[2:]] == ['1', '4']
    assert 'one in each of 3 ribs' in lines[2]


def test_the_json_names_a_rib_only_where_the_text_does(capsys):
    """
    --json's 'rib' is the text's: a rib number where one rib holds the mode, else null.

    Three identical ribs share each repeated mode equally (a third a rib): no rib holds it and
    the text says so; the JSON's rib then is null, not whichever third round-off made largest.
    Rib 1 made stiffer holds its own modes: the text's 'rib 1', the JSON's 1.
    """
    for r in cli_rows(capsys, '--set', 'ribs=3', '--count', '3'):
        assert r['rib_share'] == pytest.approx(1 / 3, rel=1e-6) and r['rib'] is None
    e = UmbrellaParams().youngs_modulus
    own = [r for r in cli_rows(capsys, '--set', 'ribs=3', '--set',
                               f'rib1.youngs_modulus={2 * e!r}', '--count', '6')
           if r['multiplicity'] == 1]
    assert own and all(r['rib'] == 1 for r in own)
    assert [r['rib'] for r in cli_rows(capsys, '--count', '2')] == [0, 0]   # (the planar rib)


def test_a_held_hubs_repeated_mode_is_one_a_rib_a_free_buss_spread(capsys):
    """
    The held hub decouples the ribs: a mode repeated over N identical ribs is one copy a rib.

    Its row says so (and the JSON's one_a_rib), not 'spread', which would read as a mode
    every rib moves in; with rib 1 of its own, the other two ribs' copies are one a rib too.
    On a free bus the ribs move together through the bus: its modes are spread.
    """
    assert main(['modes', '--set', 'ribs=3', '--count', '2']) == 0
    lines = capsys.readouterr().out.splitlines()[2:]
    assert all('one in each of 3 ribs' in line and 'spread' not in line for line in lines)
    e = UmbrellaParams().youngs_modulus
    rows = cli_rows(capsys, '--set', 'ribs=3', '--set', f'rib1.youngs_modulus={2 * e!r}',
                    '--count', '6')
    assert {(r['multiplicity'], r['one_a_rib']) for r in rows} == {(2, True), (1, False)}
    free = cli_rows(capsys, '--set', 'ribs=3', '--set', 'base=free', '--count', '4')
    assert not any(r['one_a_rib'] for r in free)
    assert main(['modes', '--set', 'ribs=3', '--set', 'base=free', '--count', '1']) == 0
    assert 'spread, <= 33 % a rib' in capsys.readouterr().out.splitlines()[2]


def test_an_overdamped_mode_is_said_to_be_one(capsys):
    """
    C = beta K damps mode i at zeta omega_i / omega_1: past 1 the mode does not oscillate.

    With damping_ratio 0.02 the thesis frame's modes 8 and 9 (1631 and 4239 Hz) have 1.53 and
    3.98: the table says they are overdamped, and that its frequencies are the undamped ones.
    """
    assert main(['modes', '--set', 'damping_ratio=0.02', '--count', '9']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert 'undamped' in lines[0]
    rows = deployed_modes(UmbrellaParams(damping_ratio=0.02), 9)
    assert [r.damping_ratio >= 1.0 for r in rows] == [False] * 7 + [True] * 2
    for r, line in zip(rows, lines[2:]):
        assert ('overdamped' in line) == (r.damping_ratio >= 1.0)
    assert main(['modes', '--count', '2']) == 0
    assert 'undamped' not in capsys.readouterr().out


def test_the_json_numbers_its_rows_as_the_text(capsys):
    """--json's 'mode' is the text's first column: the row's first mode, repeated ones counted."""
    args = ['--set', 'ribs=3', '--set', 'rib1.l2=0.6', '--count', '5']
    assert main(['modes', *args]) == 0
    text = [int(line.split()[0]) for line in capsys.readouterr().out.splitlines()[2:]]
    rows = cli_rows(capsys, *args)
    assert [r['mode'] for r in rows] == text == [1, 2, 4, 5, 7]


def test_a_spinning_base_gives_the_spinning_frames_modes(capsys):
    """
    A prescribed base spinning: the table is the spinning antenna's, and says what it is.

    The heading names the spin, the rotating frame and the spun equilibrium (no 'left out'
    note, on stdout or stderr); each row has its whirl, forward or backward, the JSON's
    'whirl' the same; the spin raises the first rows (centrifugal stiffening) and leaves
    their multiplicity (the held hub decouples the ribs); unspun, no spin in the heading.
    """
    spun = ['--set', 'ribs=3', '--set', 'base=prescribed', '--set', 'base_spin_rate=20',
            '--count', '2']
    assert main(['modes', *spun]) == 0
    out = capsys.readouterr()
    head, rows = out.out.splitlines()[0], out.out.splitlines()[2:]
    assert 'spinning at 20 rad/s' in head and out.err == ''
    assert 'turning with the hub' in head and 'spun equilibrium' in head
    assert 'left out' not in out.out + out.err
    assert rows[0].endswith('forward') and rows[1].endswith('backward')
    json_rows = cli_rows(capsys, *spun)
    assert json_rows[0]['whirl'] > 0.0 > json_rows[1]['whirl']
    still = cli_rows(capsys, '--set', 'ribs=3', '--count', '2')
    for r, s in zip(json_rows, still):
        assert r['omega'] > s['omega'] and r['multiplicity'] == s['multiplicity'] == 3
        assert s['whirl'] == 0.0
    assert main(['modes', '--set', 'ribs=3', '--set', 'base=prescribed', '--count', '1']) == 0
    assert 'spin' not in capsys.readouterr().out


@pytest.mark.parametrize('args, warned', [
    (['--set', 'youngs_modulus=72'], 'youngs_modulus: 72 Pa'),             # (GPa typed)
    (['--set', 'density=2.77'], 'density: 2.77 kg/m³'),                    # (g/cm³ typed)
    (['--set', 'l2=0.05'], 'thick beam: l2'),                   # (Euler-Bernoulli too stiff)
    (['--set', 'ribs=3', '--set', 'rib1.youngs_modulus=72'], 'youngs_modulus: rib 1, 72 Pa'),
])
def test_the_parameter_warnings_of_a_run_are_given_with_the_frequencies(capsys, args, warned):
    """
    A modulus in GPa, a density in g/cm³ or a stubby member: simulate warns, and so does modes.

    The table is printed all the same, its frequencies then 3e4 times too low, 32 times too
    high, or above the Timoshenko beam's; the warning names the parameter (and the rib).
    """
    assert main(['modes', *args, '--count', '1']) == 0
    out = capsys.readouterr()
    assert f'umbrella_sim: warning: {warned}' in out.err and 'f (Hz)' in out.out


def test_the_defaults_and_a_run_s_step_raise_no_warning(capsys):
    """The thesis frame warns of nothing; a coarse time_step is the run's, not the modes'."""
    for args in ([], ['--set', 'ribs=3'], ['--set', 'time_step=0.001']):
        assert main(['modes', *args, '--count', '1']) == 0
        assert capsys.readouterr().err == ''


def test_the_planar_table_says_it_holds_the_in_plane_modes_only(capsys):
    """
    The planar model has no out-of-plane coordinates: its table is the in-plane modes only.

    The same rib out of its plane (ribs >= 2) has a lower first mode (11.23 Hz against the
    planar table's first, 21.28 Hz): the planar heading says what it leaves out and where to
    find it; the umbrella's does not.
    """
    assert main(['modes', '--count', '1']) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert 'in-plane modes only' in head and 'ribs' in head
    first = deployed_modes(UmbrellaRibsParams.from_mapping({'ribs': 2}), 1)[0]
    assert first.out_of_plane > 0.9 and first.omega < deployed_modes(UmbrellaParams(), 1)[0].omega
    assert main(['modes', '--set', 'ribs=2', '--count', '1']) == 0
    assert 'in-plane modes only' not in capsys.readouterr().out


def test_mesh_check_gives_each_rows_change_on_twice_the_elements(capsys):
    """
    --mesh-check: each row's frequency against the same mode on twice the elements.

    A consistent-mass displacement model converges from above, mode by mode (Rayleigh-Ritz
    on nested meshes): every change is >= 0. The thesis's 3-element frame: its first mode
    0.23 % above six elements', its fourth 37 %, which the default table gives unremarked.
    """
    rows = cli_rows(capsys, '--mesh-check')
    coarse = [r.omega for r in deployed_modes(UmbrellaParams())]
    fine = [r.omega for r in deployed_modes(UmbrellaParams(elements_per_segment=2))]
    assert [r['mesh_change'] for r in rows] == pytest.approx(
        [c / f - 1.0 for c, f in zip(coarse, fine)], rel=1e-9)
    assert rows[0]['mesh_change'] == pytest.approx(2.28e-3, rel=1e-2)
    assert rows[3]['mesh_change'] == pytest.approx(0.369, rel=1e-2)
    for args in (['--set', 'ribs=3', '--set', 'rib1.l2=0.6'],
                 ['--set', 'ribs=3', '--set', 'base=free', '--elements-per-segment', '2']):
        assert all(r['mesh_change'] >= -1e-9 for r in cli_rows(capsys, *args, '--mesh-check'))
    assert cli_rows(capsys, '--count', '1')[0]['mesh_change'] is None      # (not asked)
    assert main(['modes', '--mesh-check', '--count', '4']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert '2N change' in lines[1] and '+0.228%' in lines[2] and '+36.9%' in lines[5]


def test_a_coarse_table_says_its_higher_rows_are_unchecked(capsys):
    """Without --mesh-check a mesh of 1 or 2 elements a segment says its rows are unchecked."""
    assert main(['modes', '--count', '2']) == 0
    assert '1 element a segment' in capsys.readouterr().out.splitlines()[0]
    for args in (['--elements-per-segment', '4'], ['--mesh-check']):
        assert main(['modes', *args, '--count', '2']) == 0
        assert 'a segment: past the first modes' not in capsys.readouterr().out


def test_mesh_check_past_32_elements_is_refused_naming_it(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(['modes', '--mesh-check', '--elements-per-segment', '33'])
    assert exit_.value.code == 2 and '--mesh-check' in capsys.readouterr().err
