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

"""Parameter validation and the offline CLI."""
import json
import math
import os
import subprocess
import sys

import pytest

from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.rigid import deployment_time_by_quadrature
from umbrella_sim.ros.params_file import load_params_file

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, 'config', 'umbrella.yaml')


@pytest.mark.parametrize('changes, culprit, rule', [
    ({'l1': 0.0}, 'l1', '> 0'),
    ({'l2': -0.1}, 'l2', '> 0'),
    ({'youngs_modulus': -1.0}, 'youngs_modulus', '> 0'),
    ({'density': 0.0}, 'density', '> 0'),
    ({'section_height': 0.0}, 'section_height', '> 0'),
    ({'area': 1e-4}, 'area', 'both or neither'),
    ({'l3': 0.01}, 'parameter l3=0.01', 'cannot close'),
    ({'l1': 0.6}, 'parameter l3=0.5 with l1=0.6', 'lengthen l3 or shorten l1'),
    ({'alpha0': 0.2}, 'alpha0', 'above alpha_deployed'),
    ({'alpha0': 1.5707963}, 'alpha0', '<= 1.5697963'),    # the toggle: no lever, v0 -> inf
    ({'alpha0': 1.5698}, 'alpha0', '<= 1.5697963'),       # (the bound read 1.5698)
    ({'sleeve_force_min': -1e6}, 'sleeve_force_min', 'link in tension'),   # squash: 50 kN
    ({'area': 1e-4, 'second_moment_of_area': 1e-8}, 'second_moment_of_area',
     'no section of height section_height=0.01'),           # I > A (b/2)^2 = 2.5e-9
    ({'elements_per_segment': 0}, 'elements_per_segment', 'between'),
    ({'v0': math.nan}, 'v0', 'finite'),
    ({'l1': math.inf}, 'l1', 'finite'),
    ({'model': 'elastic'}, 'model', 'one of'),
    ({'lock': 'sticky'}, 'lock', 'one of'),
    ({'sleeve_force': -3.0}, 'sleeve_force', '>= 0'),
])
def test_bad_parameters_name_culprit_and_rule(changes, culprit, rule):
    with pytest.raises(ValueError) as exc:
        UmbrellaParams().replace(**changes).validated()
    assert culprit in str(exc.value) and rule in str(exc.value)


def test_yield_strength_in_mpa_is_refused_and_soft_metals_are_not():
    """
    A yield strength typed in MPa (500 for Al 7075-T6) is refused, naming the unit.

    It was taken as 500 Pa: the run's stress ratio came out 4.4e5 and any sleeve force above
    A * 500 Pa = 0.05 N was refused as more than 'the load the link can carry', naming
    sleeve_force.  Yield strains sigma_y / E of real metals stay accepted: lead (5 MPa /
    16 GPa, 3e-4) and annealed pure aluminium (10 MPa / 69 GPa, 1.4e-4).
    """
    with pytest.raises(ValueError) as exc:
        UmbrellaParams(yield_strength=500.0).validated()
    assert 'yield_strength=500' in str(exc.value) and 'not MPa' in str(exc.value)
    for modulus, strength in ((16e9, 5e6), (69e9, 10e6), (72e9, 500e6)):
        UmbrellaParams(youngs_modulus=modulus, yield_strength=strength).validated()
    run = subprocess.run([sys.executable, '-m', 'umbrella_sim', 'simulate', '--duration',
                          '0.01', '--force', '5', '--set', 'yield_strength=500'],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 2 and 'yield_strength=500' in run.stderr, run.stderr


@pytest.mark.parametrize('name, degrees', [('alpha_deployed', 15.0), ('alpha0', 88.2)])
def test_an_angle_in_degrees_is_refused_naming_the_radians(name, degrees):
    """alpha_deployed 15 (pi/12 in degrees) was refused as 'must be < π/2', no unit said."""
    with pytest.raises(ValueError) as exc:
        UmbrellaParams().replace(**{name: degrees}).validated()
    radians = math.radians(degrees)
    assert f'{name}={degrees}' in str(exc.value) and f'{radians:.7g} rad' in str(exc.value)
    UmbrellaParams().replace(**{name: radians}).validated()      # the same angle in rad runs
    with pytest.raises(ValueError) as exc:
        UmbrellaParams(alpha0=200.0).validated()                # no angle in range: no hint
    assert 'degrees' not in str(exc.value)


def test_integers_for_doubles_are_the_doubles():
    """UmbrellaParams(v0=-1) as -p v0:=-1 and --set v0=-1: the double, and validated."""
    p = UmbrellaParams(v0=-1, sleeve_force_min=-8).validated()
    assert p == UmbrellaParams(v0=-1.0, sleeve_force_min=-8.0)
    assert type(p.v0) is float and type(p.sleeve_force_min) is float
    with pytest.raises(ValueError, match='elements_per_segment=1.5'):
        UmbrellaParams(elements_per_segment=1.5).validated()      # not the other way round
    with pytest.raises(ValueError, match='v0=True'):
        UmbrellaParams(v0=True).validated()                      # nor a boolean


def test_non_numeric_value_names_parameter():
    with pytest.raises(ValueError, match="parameter l1='abc'"):
        UmbrellaParams().replace(l1='abc')


def test_default_config_is_the_thesis_data():
    p = UmbrellaParams.from_mapping(load_params_file(CONFIG)).validated()
    assert p == UmbrellaParams()
    assert p.cross_section_area == pytest.approx(1e-4)
    assert p.cross_section_inertia == pytest.approx(1e-8 / 12)
    assert p.mass_per_length == pytest.approx(0.277)
    assert p.sleeve_stop_height == pytest.approx(2 * 0.5 * math.sin(math.pi / 12))


def test_bad_params_file(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('foo: [1, 2\n')
    with pytest.raises(ValueError, match='not valid YAML'):
        load_params_file(str(bad))
    empty = tmp_path / 'empty.yaml'
    empty.write_text('other_node:\n  ros__parameters: {a: 1}\n')
    with pytest.raises(ValueError, match='no section for node /umbrella_node'):
        load_params_file(str(empty))
    for text, words in (('/**:\n  ros__parameters:\n    v0:\n', 'no value for v0'),
                        ('/**:\n  ros__parameters:\n    v0: -0.5\n    v0: -1.0\n',
                         "key 'v0' given twice")):
        bad.write_text(text)        # YAML would give None, or the last value, silently
        with pytest.raises(ValueError, match=words):
            load_params_file(str(bad))


@pytest.mark.parametrize('line, words', [
    ('v0: "-0.5"', "v0='-0.5': must be of type double, got string"),
    ("step_follows_mesh: 'yes'", "step_follows_mesh='yes': must be of type bool"),
    ('elements_per_segment: 2.5', 'elements_per_segment=2.5: must be of type integer, got double'),
    ('lock: 1', 'lock=1: must be of type string, got integer'),
    ('publish_rate: "50"', "publish_rate='50': must be of type double, got string"),
])
def test_a_params_file_value_of_another_type_is_refused_as_the_node_does(tmp_path, line, words):
    """A quoted number in a params file is a string: the node refuses it, and so does simulate."""
    path = tmp_path / 'typed.yaml'
    path.write_text(f'/**:\n  ros__parameters:\n    {line}\n')
    r = cli('simulate', '--params', str(path), '--duration', '0.01')
    assert r.returncode == 2 and words in r.stderr and str(path) in r.stderr, r.stderr


def test_params_file_numbers_are_typed_as_rcl_types_them(tmp_path):
    """72.0e9 is a double to rcl (strtod), a string to YAML 1.1; quoted numbers are strings."""
    from umbrella_sim.ros.params_file import load_params_file

    path = tmp_path / 'typed.yaml'
    path.write_text('/**:\n  ros__parameters:\n    youngs_modulus: 72.0e9\n    v0: -5e-1\n'
                    "    l1: .5\n    elements_per_segment: 2\n    lock: '1'\n"
                    '    host: 10.0.0.1\n    name: 3d\n    dir: 2024_runs\n')
    assert load_params_file(str(path)) == {'youngs_modulus': 72e9, 'v0': -0.5, 'l1': 0.5,
                                           'elements_per_segment': 2, 'lock': '1',
                                           'host': '10.0.0.1', 'name': '3d',   # (text that
                                           'dir': '2024_runs'}   # starts with a number)


def test_a_bad_value_in_a_params_file_names_the_file(tmp_path):
    bad = tmp_path / 'fast.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    v0: "fast"\n')
    r = cli('simulate', '--params', str(bad), '--duration', '0.01')
    assert r.returncode == 2 and 'fast.yaml' in r.stderr and 'v0' in r.stderr, r.stderr
    a_file = tmp_path / 'a_file'
    a_file.write_text('')
    r = cli('simulate', '--duration', '0.01', '--csv', str(a_file / 'x.csv'))
    assert r.returncode == 2 and f'{a_file} is not a directory' in r.stderr, r.stderr


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, '-m', 'umbrella_sim', *args], capture_output=True,
                          text=True, cwd=cwd or ROOT, timeout=300)


def test_cli_json_summary():
    r = cli('simulate', '--params', CONFIG, '--v0', '-1.0', '--duration', '0.1', '--json')
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    for key in ('deploy_time', 'tip_deflection_max', 'tip_deflection_max_time',
                'stage2_tip_amplitude', 'stage2_tip_period', 'peak_stress_leaf',
                'peak_stress_link', 'energy_drift', 'constraint_residual_max', 'steps',
                'wall_time', 'real_time_factor'):
        assert key in s
    # the frame is stiff in stage 1: the rigid closed form (work-energy quadrature) is close
    rigid = deployment_time_by_quadrature(
        UmbrellaParams.from_mapping(load_params_file(CONFIG)).replace(v0=-1.0))
    assert s['deploy_time'] == pytest.approx(rigid, rel=5e-3)


def test_cli_takes_negative_numbers_in_exponent_form():
    """``--v0 -5e-1`` is the value -0.5, as ``--v0=-0.5``, not an unknown option."""
    runs = [cli('simulate', *v0, '--duration', '0.02', '--time-step', '0.001', '--json')
            for v0 in (['--v0', '-5e-1'], ['--v0=-0.5'], ['--v0', '-0.5'])]
    assert all(r.returncode == 0 for r in runs), [r.stderr for r in runs]
    summaries = [json.loads(r.stdout) for r in runs]
    for s in summaries:
        s.pop('wall_time'), s.pop('real_time_factor')
    assert summaries[0] == summaries[1] == summaries[2]


@pytest.mark.parametrize('argv, message', [
    (['--v0', '-0.3'], 'the command comes first: umbrella_sim simulate --v0 -0.3 '
                       '(--v0 is an option of simulate)'),
    (['--duration=0.5'], 'the command comes first: umbrella_sim simulate --duration=0.5'),
    (['simulat', '--v0', '-0.3'], "'simulat' is not a command (commands: simulate, sweep, modes): "
                                  "did you mean 'simulate'?"),
    (['-0.3'], "'-0.3' is not a command (commands: simulate, sweep, modes)"),
    (['--bogus', '1'], '--bogus: not an option of umbrella_sim; the command comes first'),
])
def test_cli_names_a_missing_or_misspelt_command(argv, message, capsys):
    """An option before its command is named as that, not as an invalid command '-0.3'."""
    from umbrella_sim.tools.cli import make_parser
    with pytest.raises(SystemExit) as exc:
        make_parser().parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert message in err and 'invalid choice' not in err, err


def test_cli_command_first_still_parses():
    from umbrella_sim.tools.cli import make_parser
    args = make_parser().parse_args(['simulate', '--v0', '-0.3'])
    assert (args.command, args.v0) == ('simulate', -0.3)


def test_cli_models_and_csv(tmp_path):
    out = tmp_path / 'run.csv'
    r = cli('simulate', '--model', 'rigid', '--v0', '-2', '--duration', '0.03',
            '--time-step', '0.002', '--csv', str(out), '--csv-state', '--json')
    assert r.returncode == 0, r.stderr
    lines = out.read_text().splitlines()
    header = lines[0].split(',')
    # every column with its SI unit, the stage (text) without
    assert header[:3] == ['time (s)', 'stage', 'alpha1 (rad)']
    assert 'q[alpha1] (rad)' in header and 'qd[link.u1] (m/s)' in header
    assert 'q[leaf.theta1] (rad)' in header and 'qd[leaf.theta1] (rad/s)' in header
    assert 'q[R2x] (m)' in header and 'alpha1_accel (rad/s^2)' in header
    assert 'sigma_top[leaf@0.5-] (Pa)' in header and 'sigma_bottom[link@0.5] (Pa)' in header
    assert 'tip_transverse (m)' in header and 'kinetic_energy (J)' in header
    assert all(h == 'stage' or h.endswith(')') for h in header)
    assert len(set(header)) == len(header), "a column name twice (leaf@0.5: two elements')"
    assert len(lines) == 1 + 1 + 15 + 1    # header, t = 0, 15 steps, the lock instant
    again = cli('simulate', '--duration', '0.01', '--csv', str(out))
    assert again.returncode == 2 and 'exists' in again.stderr


def test_csv_rows_are_the_grid_steps_with_stage_2_substeps_folded(tmp_path):
    """
    The --csv rows are the grid's, as --help says: stage 2's substeps fold into their grid step.

    At time_step 0 the thesis's frame deploys on a grid step of twice its stage-2 physics step
    (the summary's stage2_resolution step, 0.1 ms at 1 element a segment): the stage-2 rows
    come a grid step apart, not a physics step.
    """
    out = tmp_path / 'run.csv'
    r = cli('simulate', '--duration', '0.24', '--csv', str(out), '--json')
    assert r.returncode == 0, r.stderr
    figures = json.loads(r.stdout)
    grid = figures['final_time'] / figures['steps']
    assert figures['stage2_resolution']['step'] == pytest.approx(grid / 2)
    rows = [row.split(',') for row in out.read_text().splitlines()[1:]]
    locked = [float(row[0]) for row in rows if row[1] == 'locked'][1:]   # (the lock's own row)
    assert len(locked) > 10
    assert all(b - a == pytest.approx(grid) for a, b in zip(locked, locked[1:]))
    usage = ' '.join(cli('simulate', '--help').stdout.split())
    assert '--csv FILE write the time series of every grid step' in usage
    assert 'physics step' not in usage.split('--csv FILE')[1].split('--csv-state')[0]


def test_cli_force_profile(tmp_path):
    prof = tmp_path / 'force.csv'
    prof.write_text('t,F\n0.0,0.0\n0.01,20.0\n')
    r = cli('simulate', '--v0', '0', '--force-profile', str(prof), '--duration', '0.6',
            '--time-step', '0.002', '--json')
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)['deploy_time'] > 0.01
    prof.write_text('t,F\n0.0,1.0\n0.01,-5.0\n')
    bad = cli('simulate', '--force-profile', str(prof))
    assert bad.returncode == 2 and 'force.csv:3' in bad.stderr and '>= 0' in bad.stderr


def test_cli_force_profile_above_a_ribs_link_names_the_row(tmp_path):
    """
    A profile's force above the umbrella's bound (its weakest link's) names file and line.

    The profile was checked against the planar record, whose link carries 39x rib 1's 4 mm
    section here: the run's own check then refused the force without the file or its row.
    """
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams

    weak = UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib1.section_height': 0.004})
    assert weak.sleeve_force_limit < weak.planar.sleeve_force_limit
    prof = tmp_path / 'force.csv'
    prof.write_text(f't,F\n# a comment\n0.0,1.0\n0.1,{1.01 * weak.sleeve_force_limit:.6f}\n')
    r = cli('simulate', '--set', 'ribs=3', '--set', 'rib1.section_height=0.004',
            '--force-profile', str(prof), '--duration', '0.01')
    assert r.returncode == 2, r.stderr
    assert f'force profile {prof}:4: sleeve force' in r.stderr, r.stderr
    assert "rib 1's link can carry" in r.stderr, r.stderr


@pytest.mark.parametrize('args, words', [
    (['--set', 'l1=-1'], 'l1'),
    (['--set', 'alpha0=0.1'], 'alpha0'),
    (['--set', 'nonsense=1'], 'unknown parameter'),
    (['--force', 'nan'], 'sleeve_force'),
    (['--elements-per-segment', '0'], 'elements_per_segment'),
    (['--params', '/nonexistent.yaml'], '/nonexistent.yaml'),
    (['--duration', '5e-5'], 'shorter than one physics step (0.0002 s)'),   # ran 0 steps
    # one parameter given twice: the dedicated option used to win over --set silently
    (['--force', '5', '--set', 'sleeve_force=10'], '--force 5.0'),
    (['--model', 'rigid', '--set', 'model=flexible'], 'already given by --model rigid'),
    (['--set', 'v0=-1', '--set', 'v0=-2'], 'already given by --set v0=-1'),
    (['--v0', '0', '--v0', '-0.5'], '--v0 given twice'),
    (['--mcap', '/nonexistent/bag', '--publish-rate', '50', '--set', 'publish_rate=200'],
     'already given by --publish-rate 50.0'),
])
def test_cli_rejects_bad_input(args, words):
    r = cli('simulate', *args)
    assert r.returncode == 2
    assert words in r.stderr and 'Traceback' not in r.stderr


def test_cli_diverging_run_keeps_csv(tmp_path):
    out = tmp_path / 'div.csv'
    # 2300 N: below the link's buckling load (accepted) but the Newton iteration fails
    # (at a 2 ms step; at a 50 us step Newton follows 2.3 kN)
    r = cli('simulate', '--v0', '0', '--force', '2300', '--duration', '0.5', '--time-step',
            '0.002', '--csv', str(out))
    assert r.returncode == 3
    assert 'error' in r.stderr and 'kept' in r.stderr
    assert len(out.read_text().splitlines()) > 3


def test_braking_limit_admits_negative_force_down_to_it_and_no_further():
    """
    Check every command against sleeve_force_min, the one bound.

    sleeve_force_min < 0 is a drive that can hold the sleeve back; the default keeps the
    thesis's push-only sleeve.
    """
    from umbrella_sim.core.driver import simulate
    from umbrella_sim.core.solver import UmbrellaSimulator

    with pytest.raises(ValueError, match='sleeve_force_min.*<= 0'):
        UmbrellaParams(sleeve_force_min=1.0).validated()
    with pytest.raises(ValueError, match='sleeve_force=-3.*-2'):
        UmbrellaParams(sleeve_force_min=-2.0, sleeve_force=-3.0).validated()
    push_only = UmbrellaSimulator(UmbrellaParams(v0=-0.5))
    with pytest.raises(ValueError, match='>= 0'):
        push_only.set_sleeve_force(-1.0)
    braking = UmbrellaSimulator(UmbrellaParams(v0=-0.5, sleeve_force_min=-5.0))
    braking.set_sleeve_force(-5.0)
    with pytest.raises(ValueError, match='-5'):
        braking.set_sleeve_force(-5.5)
    with pytest.raises(ValueError, match='-1'):
        simulate(UmbrellaParams(v0=-0.5), 0.1, force_profile=[(0.0, -1.0)])
    # holding back slows the deployment: the lock comes later than coasting at v0
    coast = simulate(UmbrellaParams(v0=-0.5), 1.0, stop_after_lock=0.0)
    held = simulate(UmbrellaParams(v0=-0.5, sleeve_force_min=-5.0), 1.0,
                    force_profile=[(0.0, -0.5)], stop_after_lock=0.0)
    assert held.lock.time > coast.lock.time
    assert held.samples[-1].work < 0.0                  # the drive took energy out
    assert held.summary()['energy_drift'] < 1e-5        # and the balance still closes


@pytest.mark.parametrize('text, rows', [
    ('t,F\n0,5\n0.3,0\n', [(0.0, 5.0), (0.3, 0.0)]),
    ('# my drive\n\nt [s], F [N]\n0,5\n', [(0.0, 5.0)]),     # a header after a comment
    ('0,5\n0.3,0,\n', [(0.0, 5.0), (0.3, 0.0)]),             # a trailing comma
    ('Time (s),Force (N)\n0,5\n', [(0.0, 5.0)]),
    ('t,sleeve_force\n0,5\n', [(0.0, 5.0)]),       # the topic's name
    ('\ufefft,F\n0,5\n', [(0.0, 5.0)]),             # a spreadsheet's UTF-8 byte-order mark
    ('t_s,F_H (N)\n0,5\n', [(0.0, 5.0)]),           # SI units, the force's own name
    ('tiem,froce\n0,5\n', [(0.0, 5.0)]),             # a typo: the columns by position
])
def test_force_profile_rows_and_header(tmp_path, text, rows):
    from umbrella_sim.tools.inputs import read_force_profile
    prof = tmp_path / 'f.csv'
    prof.write_text(text)
    assert read_force_profile(str(prof)) == rows


@pytest.mark.parametrize('text, where, words', [
    ('0,5 N\n0.3,0\n', 'f.csv:1', 'not numbers'),     # a bad first row is not a header
    ('t,F\n0,5 N\n', 'f.csv:2', 'not numbers'),
    ('t,5\n0,5\n', 'f.csv:1', 'not numbers'),         # half a number: not a header either
    ('0,1,2\n', 'f.csv:1', 'two columns'),            # a third column is not dropped
    ('t,F\nF\n', 'f.csv:2', 'two columns'),
    ('0,1\n0.5,2\n0.5,3\n', 'f.csv:3', 'time 0.5 given twice'),   # (the last one won)
    ('F,t\n0,0\n5,0.1\n', 'f.csv:1', 'time then force'),   # (was read as t,F)
    ('force,time\n0,0\n', 'f.csv:1', "['force', 'time']"),
    ('t,F\n0,1_0\n', 'f.csv:2', 'not numbers'),             # (was 10 N)
    ('sleeve_force,time\n0,0\n', 'f.csv:1', 'time then force'),   # (was read as t,F)
    ('t (ms),F (N)\n0,0\n50,5\n', 'f.csv:1', 'time in ms'),      # (50 ms was 50 s)
    ('t [s],F [kN]\n0,0.5\n', 'f.csv:1', 'force in kN'),        # (0.5 kN was 0.5 N)
    ('time_ms,F\n0,0\n', 'f.csv:1', 'time in ms'),
])
def test_force_profile_bad_rows_are_named(tmp_path, text, where, words):
    from umbrella_sim.tools.inputs import read_force_profile
    prof = tmp_path / 'f.csv'
    prof.write_text(text)
    with pytest.raises(ValueError) as exc:
        read_force_profile(str(prof))
    assert where in str(exc.value) and words in str(exc.value), exc.value


def test_mcap_recording_says_when_its_publications_shorten_the_step(tmp_path):
    """--mcap at a time_step that does not divide the period: the node's step, said so."""
    from umbrella_sim.bag.reader import read_log

    r = cli('simulate', '--time-step', '3e-4', '--duration', '0.05', '--mcap',
            str(tmp_path / 'short'), '--json')
    assert r.returncode == 0, r.stderr
    assert 'physics step 0.000294117647 s, not 0.0003 s' in r.stderr, r.stderr
    step = read_log(str(tmp_path / 'short')).metadata['umbrella_sim.parameters']['physics_step']
    assert float(step) == pytest.approx(0.01 / 34, rel=1e-12)
    r = cli('simulate', '--time-step', '2e-4', '--duration', '0.05', '--mcap',
            str(tmp_path / 'same'))
    assert r.returncode == 0 and 'note' not in r.stderr, r.stderr


def test_params_file_publish_rate_shapes_the_mcap_recording(tmp_path):
    """A params file shared with the node: its publish_rate is the recording's, unless given."""
    from umbrella_sim.bag.reader import read_log
    params = tmp_path / 'rate.yaml'
    params.write_text('/**:\n  ros__parameters:\n    publish_rate: 1000.0\n')
    counts = []
    for name, extra in (('file', []), ('flag', ['--publish-rate', '50']),
                        ('set', ['--set', 'publish_rate=200'])):
        bag = tmp_path / name
        r = cli('simulate', '--params', str(params), '--duration', '0.1', '--mcap', str(bag),
                *extra)
        assert r.returncode == 0, r.stderr
        counts.append(read_log(str(bag)).count('/joint_states'))
    assert counts == [101, 6, 21]       # t = 0 and every period of 0.1 s


def test_a_params_file_is_parsed_once_per_text(tmp_path, monkeypatch):
    """Checked before rclpy.init and again by the node: the same text is parsed once."""
    from umbrella_sim.ros import params_file
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    v0: -0.5\n')
    parses = []
    real = params_file.load_yaml_as_ros
    monkeypatch.setattr(params_file, 'load_yaml_as_ros',
                        lambda text: parses.append(text) or real(text))
    first = params_file.read_params_file(str(path))
    first['/**']['v0'] = 99.0                        # a caller's copy: the cache keeps its own
    assert params_file.read_params_file(str(path)) == {'/**': {'v0': -0.5}}
    assert len(parses) == 1
    path.write_text('/**:\n  ros__parameters:\n    v0: -0.25\n')     # changed: read anew
    assert params_file.read_params_file(str(path)) == {'/**': {'v0': -0.25}}
    path.write_text('/**:\n  ros__parameters:\n    v0:\n')            # and checked anew
    with pytest.raises(ValueError, match='no value for v0'):
        params_file.read_params_file(str(path))
    assert len(parses) == 3


@pytest.mark.ros
def test_a_dropped_argument_value_is_refused_where_rcl_drops_it(tmp_path):
    """
    check_param_rules refuses exactly the -p values rcl drops beside a params file.

    rcl itself is the reference: each rule beside a file giving v0 -0.2, parsed by rclpy in
    a context of its own; a value rcl took (a double, an integer, a bool) passes, one it
    dropped for the file's (a string, a list) is refused naming the parameter.
    """
    import rclpy

    from umbrella_sim.ros.params_file import check_param_rules, param_rules_in

    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    v0: -0.2\n')
    outcomes = set()
    for text in ('-0.5', '-1', 'true', 'abc', '[1.0]', '"-0.5"'):
        argv = ['node', '--ros-args', '--params-file', str(path), '-p', f'v0:={text}']
        context = rclpy.Context()
        rclpy.init(args=argv, context=context)
        try:
            node = rclpy.create_node('umbrella_node', context=context)
            kept = node._parameter_overrides['v0'].value
            node.destroy_node()
        finally:
            rclpy.shutdown(context=context)
        dropped = kept == -0.2
        try:
            check_param_rules(param_rules_in(argv), {'v0': rclpy.parameter.Parameter(
                'v0', value=kept)})
            refused = False
        except ValueError as exc:
            refused = True
            assert f'parameter v0={text!r} (-p): not taken' in str(exc)
        assert refused == dropped, (text, kept)
        outcomes.add(dropped)
    assert outcomes == {True, False}        # (both kinds seen: rcl took some, dropped some)


def test_a_whole_double_for_a_files_integer_is_taken_and_nan_is_rcls_double():
    """
    -p elements_per_segment:=4.0 beside a file's integer: the node takes 4 (as without a file).

    rcl keeps the file's integer; a whole double is that integer to the node, which takes it
    (check_param_rules returns it); 2.5 is not one and is refused.  'NaN' (strtod's word) is a
    double to rcl and a string to YAML: the rule is the value the node was given, which its
    own check then refuses as not finite.
    """
    from rclpy.parameter import Parameter

    from umbrella_sim.ros.params_file import check_param_rules

    def given(name, value):
        return {name: Parameter(name, value=value)}

    assert check_param_rules({'elements_per_segment': '4.0'},
                             given('elements_per_segment', 1)) == {'elements_per_segment': 4}
    with pytest.raises(ValueError, match='an integer, from an earlier -p.*give '
                                         'elements_per_segment an integer'):
        check_param_rules({'elements_per_segment': '2.5'}, given('elements_per_segment', 1))
    assert check_param_rules({'v0': 'NaN'}, given('v0', math.nan)) == {}
    assert check_param_rules({'rib.hinge_coulomb': '[0.0, NaN]'},
                             given('rib.hinge_coulomb', [0.0, math.nan])) == {}
    with pytest.raises(ValueError, match="v0='abc'.*a string"):
        check_param_rules({'v0': 'abc'}, given('v0', -0.2))


@pytest.mark.parametrize('extra', [[], ['--set', 'damping_ratio=0.02']])
def test_a_section_too_slender_for_the_solver_is_refused_naming_it(extra, capsys):
    """
    A 1 nm section: E I (6e-27 N m^2) is lost in the mass's round-off, two locked modes at 0.

    It ran with numpy's 'invalid value in divide' from the stage-2 mode fit (and failed
    with a ZeroDivisionError's text with damping); now refused before any step, naming it.
    """
    from umbrella_sim.tools import cli

    with pytest.raises(SystemExit) as exc:
        cli.main(['simulate', '--set', 'section_height=1e-9', '--duration', '0.01', *extra])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and 'RuntimeWarning' not in err
    assert 'the locked frame has 2 mode(s) without stiffness' in err
    assert 'section_height=1e-09' in err


def test_a_duration_that_is_not_a_whole_number_of_steps_says_where_the_run_ends(capsys):
    from umbrella_sim.tools import cli

    assert cli.main(['simulate', '--duration', '0.0301', '--time-step', '0.0003']) == 0
    err = capsys.readouterr().err
    assert 'note: the run ends at t = 0.03 s' in err and '--duration 0.0301 s' in err
    assert cli.main(['simulate', '--duration', '0.03', '--time-step', '0.0003']) == 0
    assert 'note' not in capsys.readouterr().err


def test_a_rib_list_takes_numbers_as_yaml_1_1_reads_them_as_text(capsys):
    # YAML 1.1 (PyYAML) reads 1e-4 as text; a list of them is numbers all the same
    from umbrella_sim.tools import cli

    assert cli.main(['simulate', '--duration', '0.002', '--set', 'ribs=3', '--set',
                     'rib.tip_mass=[1e-1, 0, 0]', '--json']) == 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli.main(['simulate', '--duration', '0.002', '--set', 'ribs=3', '--set',
                  'rib.tip_mass=[1e-1, abc, 0]'])
    assert exc.value.code == 2
    assert '--set rib.tip_mass: a list of numbers' in capsys.readouterr().err


def test_the_text_summary_gives_the_axial_load_in_per_cent_of_the_euler_load(capsys):
    from umbrella_sim.tools import cli

    assert cli.main(['simulate', '--duration', '0.3']) == 0
    lines = dict(line.split(None, 1) for line in capsys.readouterr().out.splitlines())
    assert lines['axial_load_ratio_max'].endswith("% of the link's Euler load")


def test_text_summary_gives_stage2_resolution_in_ms_and_percent():
    """The stage-2 step figures read as steps and shares, not as a Python dict."""
    from umbrella_sim.tools.cli import format_summary
    text = format_summary({'stage2_resolution': {
        'step': 1e-4, 'leaf': 0.0033, 'link': 0.004, 'resolving_step': 1e-4,
        'coupled_step': None, 'deflection': 0.063, 'needed_step': 5e-5}})
    assert text == ('stage2_resolution            step 0.1 ms (needed 0.05 ms: resolving '
                    '0.1 ms, coupled -); stress crest unresolved: leaf 0.33 %, link 0.4 %; '
                    "the lock's tip crest 6.3 % of l1+l2")


def test_a_params_files_node_duration_is_named_where_simulate_runs_another(tmp_path, capsys):
    """
    A params file's duration is umbrella_node's: simulate runs --duration, and says so.

    A file with duration 0.05 ran 1 s offline (--duration's default) without a word; the
    run now warns, naming the file and both durations, and says nothing where they agree.
    """
    from umbrella_sim.tools.cli import main

    path = tmp_path / 'node.yaml'
    path.write_text('umbrella_node:\n  ros__parameters:\n    duration: 0.05\n')
    assert main(['simulate', '--params', str(path), '--duration', '0.01', '--json']) == 0
    err = capsys.readouterr().err
    assert f'params file {path}: duration 0.05 is umbrella_node' in err
    assert 'offline the run takes --duration (0.01 s)' in err
    assert main(['simulate', '--params', str(path), '--duration', '0.05', '--json']) == 0
    assert 'duration' not in capsys.readouterr().err
