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
The command lines with the umbrella of N ribs: simulate, --mcap, re-simulation, sweeps.

``umbrella_sim simulate --set ribs=N --set rib.<name>=[...]`` runs the umbrella through the
run driver and prints its figures; ``--mcap`` records it as umbrella_node does; re-running a
recording (``umbrella_replay --resimulate``) from its parameters and applied forces gives
every published value of every rib again, exactly on this build; a sweep varies the rib
parameters as any other; what the tools do not offer for it (``--csv-state``) is refused
naming why.
"""
import json
import os
import re

import pytest

from umbrella_sim.bag.format import (EVENTS_RECORD, MESH_RECORD, PARAMETERS_RECORD,
                                     SUMMARY_RECORD)
from umbrella_sim.bag.reader import LogError, read_log
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.umbrella3d.params3d import node_model
from umbrella_sim.tools import cli, compare, sweep_results
from umbrella_sim.tools.replay import resimulate, RIB_SIGNALS
from umbrella_sim.tools.runs import load_run
from umbrella_sim.tools.sweep import run_case
from umbrella_sim.tools.sweep_spec import load_spec, SpecError

RUN = ['simulate', '--set', 'ribs=2', '--set', 'rib.stick_until=[0.0, 0.01]',
       '--set', 'rib.hinge_coulomb=[0.0, 0.05]', '--v0', '0', '--force', '40',
       '--time-step', '2e-4', '--duration', '0.04']


def test_simulate_records_the_umbrella_and_replay_resimulates_it_exactly(tmp_path, capsys):
    bag = tmp_path / 'ribs'
    assert cli.main([*RUN, '--json', '--mcap', str(bag), '--publish-rate', '500']) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures['ribs'] == 2 and figures['steps'] == 200
    # the rubbing rib's hinge took energy out; the balance holds with it
    assert figures['friction_work'][1] < 0.0 == figures['friction_work'][0]
    assert figures['energy_drift'] < 1e-10
    log = read_log(str(bag))
    assert log.metadata[MESH_RECORD]['ribs'] == '2'
    assert json.loads(log.metadata[PARAMETERS_RECORD]['rib.stick_until']) == [0.0, 0.01]
    assert log.count(log.find_topic('rib_peak_stress')) == 21       # t = 0 and 20 periods
    # markers of every rib (2N + 2: leaf and link of each, the sleeve and the hub) every
    # round(500 / 30) = 17th publication, t = 0 included
    markers = log.decoded(log.find_topic('markers'))
    assert [t for t, _ in markers] == [0.0, pytest.approx(17 * 0.002)]
    assert [m.id for m in markers[-1][1].markers] == list(range(6))
    res = resimulate(log)
    assert res['compared'] == 21 and not res['problems']
    assert set(res['max_abs_diff']) == set(RIB_SIGNALS)
    assert max(res['max_abs_diff'].values()) == 0.0     # the same run, on the same build
    with pytest.raises(LogError, match='umbrella of 2 ribs.*compare_ribs.load_ribs_run'):
        load_run(str(bag))
    # umbrella_compare: per-rib figures and differences against the first run; a free hinge
    # (no stick) deploys the frame earlier than the stuck one
    free = tmp_path / 'free'
    assert cli.main([*[a if a != 'rib.stick_until=[0.0, 0.01]' else 'rib.stick_until=[0.0, 0.0]'
                       for a in RUN], '--duration', '0.3', '--mcap', str(free),
                     '--publish-rate', '500']) == 0
    out = tmp_path / 'cmp'
    capsys.readouterr()
    assert compare.main([str(bag), str(free), '--out', str(out)]) == 0
    assert 'rib1' in capsys.readouterr().out
    result = json.loads((out / 'compare.json').read_text())
    ref, other = result['runs']
    assert ref['alpha1_max_difference'] == [0.0, 0.0] and ref['ribs'] == 2
    assert min(other['alpha1_max_difference']) > 0.0
    # the summary's figures of each run (the ribs apart before the lock: the stuck rib's)
    assert ref['max_leaf_angle_spread'] == figures['max_leaf_angle_spread'] > 0.0
    assert other['stage2_tip_amplitude'] == json.loads(
        read_log(str(free)).metadata[SUMMARY_RECORD]['figures'])['stage2_tip_amplitude']
    assert None not in other['stage2_tip_amplitude']
    assert sorted(p.rsplit('/', 1)[1] for p in result['plots']) == [
        'ribs_alpha1.png', 'ribs_tip_out_of_plane.png', 'ribs_top_view.png']
    planar = tmp_path / 'planar'
    assert cli.main(['simulate', '--duration', '0.01', '--mcap', str(planar)]) == 0
    assert compare.main([str(bag), str(planar), '--out', str(tmp_path / 'mixed')]) == 2
    capsys.readouterr()
    assert compare.main([str(bag), '--thesis', '--out', str(tmp_path / 'thesis')]) == 2
    assert '(leave --thesis out)' in capsys.readouterr().err


def test_compare_of_one_umbrella_recorded_at_two_rates_finds_no_leaf_angle_difference(
        tmp_path, capsys):
    """
    The same run at 100 Hz, 40 Hz and 1 kHz: each rib's alpha1 difference is zero, any order.

    As the planar runs' (alignment.difference): on the coarser run's publications, or
    the instants both published at; interpolating one run's samples at the other's instants
    made 0.012 rad of a locked frame's vibration.
    """
    bags = {}
    for rate in ('100', '40', '1000'):
        bags[rate] = tmp_path / f'r{rate}'
        assert cli.main(['simulate', '--set', 'ribs=2', '--duration', '0.3', '--mcap',
                         str(bags[rate]), '--publish-rate', rate]) == 0
    for a, b in (('100', '40'), ('40', '100'), ('100', '1000'), ('1000', '100')):
        out = tmp_path / f'cmp_{a}_{b}'
        assert compare.main([str(bags[a]), str(bags[b]), '--out', str(out), '--no-plots']) == 0
        other = json.loads((out / 'compare.json').read_text())['runs'][1]
        assert other['alpha1_max_difference'] == [0.0, 0.0], (a, b)
    capsys.readouterr()


@pytest.mark.parametrize('args, culprit', [
    (['simulate', '--set', 'rib.tip_mass=[0.1]', '--duration', '0.01'], 'rib.tip_mass'),
    ([*RUN, '--set', 'rib.tip_mass=0.1'], 'rib.tip_mass'),
    ([*RUN, '--set', 'rib.tip_mass=[0.1, 0.0, 0.0]'], 'rib.tip_mass'),
    ([*RUN, '--set', 'rib.tip_mass=[0.0 0.1]'], '--set rib.tip_mass: a list of numbers'),
    ([*RUN, '--set', 'rib.tip_mas=[0.0, 0.1]'], "(did you mean 'rib.tip_mass'?)"),
    # a rib's own value without its prefix (was 'hinge_regularisation', and nothing)
    ([*RUN, '--set', 'hinge_viscous=0.5'], "'hinge_viscous' (did you mean 'rib.hinge_viscous'?)"),
    ([*RUN, '--set', 'tip_mass=0.1'], "'tip_mass' (did you mean 'rib.tip_mass'?)"),
    ([*RUN, '--set', 'hinge_colomb=0.5'], "(did you mean 'rib.hinge_coulomb'?)"),
    # [] given is no rib's value (the node and a params file refuse it): not left out unsaid
    ([*RUN, '--set', 'rib.tip_mass=[]'], 'parameter rib.tip_mass: an empty list: give one '
                                         'value per rib'),
    ([*RUN, '--csv', 'out.csv', '--csv-state'], '--csv-state'),
])
def test_simulate_refuses_what_the_umbrella_cannot_take_naming_it(
        args, culprit, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        cli.main(args)
    assert exc.value.code == 2
    assert culprit in capsys.readouterr().err


@pytest.mark.parametrize('rib, said', [
    ('{tip_mass: 0.2}', 'parameter rib.tip_mass=0.2: a list of one value per rib'),
    ('{tip_mass: []}', 'parameter rib.tip_mass: an empty list: give one value per rib'),
    ('{tip_mass: null}', "section 'umbrella_node': no value for rib.tip_mass"),
])
def test_a_params_files_rib_list_that_is_none_is_refused_naming_the_file(
        rib, said, tmp_path, capsys):
    """A number, [] or null for rib.<name> in a params file: exit 2 naming file and value."""
    path = tmp_path / 'ribs.yaml'
    path.write_text(f'umbrella_node:\n  ros__parameters:\n    ribs: 4\n    rib: {rib}\n')
    with pytest.raises(SystemExit) as exc:
        cli.main(['simulate', '--params', str(path), '--duration', '0.01'])
    assert exc.value.code == 2
    assert f'params file {path}: {said}' in capsys.readouterr().err


@pytest.mark.parametrize('lines, said', [
    ('    base: free\n    bus_mass: "5"\n',
     "parameter bus_mass='5': must be of type double, got string"),
    ('    rib2:\n      tip_mass: "0.1"\n',
     "parameter rib2.tip_mass='0.1': must be of type double, got string"),
    ('    rib1:\n      l2: "0.6"\n', "parameter rib1.l2='0.6': must be of type double"),
    ("    rib:\n      tip_mass: ['0', '0.1', '0', '0']\n",
     "parameter rib.tip_mass=['0', '0.1', '0', '0']: must be of type double[], got the "
     "string '0' in it"),
    ('    rib:\n      tip_mass: [0, 0.1, 0, 0]\n',
     'parameter rib.tip_mass=[0, 0.1, 0, 0]: a list of doubles needs every value written as '
     'a double'),
])
def test_a_params_files_umbrella_value_the_node_refuses_is_refused_offline(
        lines, said, tmp_path, capsys):
    """
    A params file shared with the node: what the node refuses by its type, simulate too.

    A quoted number is a string to the node (as v0: "-0.5" is to both), and rcl refuses a
    list mixing integers and doubles; simulate took them as numbers, so the file that ran
    offline failed on the node.
    """
    path = tmp_path / 'ribs.yaml'
    path.write_text('umbrella_node:\n  ros__parameters:\n    ribs: 4\n' + lines)
    with pytest.raises(SystemExit) as exc:
        cli.main(['simulate', '--params', str(path), '--duration', '0.01'])
    assert exc.value.code == 2
    assert f'params file {path}: {said}' in capsys.readouterr().err
    # the same values typed as the node reads them run
    typed = lines.replace('"', '').replace("'", '').replace('0, 0.1, 0, 0', '0.0, 0.1, 0.0, 0.0')
    path.write_text('umbrella_node:\n  ros__parameters:\n    ribs: 4\n' + typed)
    assert cli.main(['simulate', '--params', str(path), '--duration', '0.002']) == 0


def test_a_params_files_rib_beyond_its_ribs_is_refused_naming_the_file(tmp_path, capsys):
    """rib7.<name> in a file of ribs 4: exit 2 naming the file, the value and the ribs."""
    path = tmp_path / 'ribs.yaml'
    path.write_text('umbrella_node:\n  ros__parameters:\n    ribs: 4\n'
                    '    rib7:\n      hinge_viscous: 0.1\n')
    with pytest.raises(SystemExit) as exc:
        cli.main(['simulate', '--params', str(path), '--duration', '0.01'])
    assert exc.value.code == 2
    assert (f'params file {path}: parameter rib7.hinge_viscous: there are ribs 0 .. 3'
            in capsys.readouterr().err)


@pytest.mark.parametrize('spec, said', [
    ('base: {ribs: 3, rib.tip_mass: 0.2}\ncases:\n  - {v0: -0.2}\n',
     'parameter rib.tip_mass=0.2: a list'),
    ('base: {ribs: 3}\ncases:\n  - {rib.tip_mass: null}\n', 'parameter rib.tip_mass: null'),
    ('base: {ribs: 3}\ncases:\n  - {rib.tip_mass: []}\n', 'rib.tip_mass: an empty list'),
    # a grid axis that the base sets too: the case's own value is named with the other
    ('base: {ribs: 3}\ngrid: {ribs: [2, 3], rib.tip_mass: [[0, 0.1, 0]]}\n',
     '(grid: ribs=2, rib.tip_mass=[0, 0.1, 0]): parameter rib.tip_mass: a list of 3 values '
     'for 2 ribs'),
    # a misspelt rib name: the name meant and where they are listed, as simulate --set says
    ('base: {ribs: 3}\ngrid:\n  rib1.hinge_colomb: [0.1]\n',
     "'rib1.hinge_colomb' (did you mean 'rib1.hinge_coulomb'?); known parameters are listed "
     "by umbrella_node --help and in msg_docs/parameters.md (the umbrella of N ribs': "
     'msg_docs/umbrella3d_parameters.md)'),
    ('base: {ribs: 3}\ngrid:\n  rib.tip_mas: [[0, 0.1, 0]]\n',
     "'rib.tip_mas' (did you mean 'rib.tip_mass'?)"),
])
def test_a_sweeps_rib_list_that_is_none_is_refused_naming_the_case(spec, said, tmp_path):
    path = tmp_path / 'spec.yaml'
    path.write_text(spec + 'duration: 0.1\n')
    with pytest.raises(SpecError, match=re.escape(said)) as exc:
        load_spec(str(path))
    assert f'sweep spec {path}: case 1' in str(exc.value)


def test_an_umbrella_spelled_two_ways_is_one_case(tmp_path):
    """A rib's value as rib<k>.<name> or in a rib.<name> list, or its default given: one case."""
    path = tmp_path / 'spec.yaml'
    path.write_text(
        'base: {ribs: 3}\n'
        'cases:\n  - {rib1.hinge_coulomb: 0.5}\n  - {rib.hinge_coulomb: [0, 0.5, 0]}\n'
        '  - {rib1.hinge_coulomb: 0.5, rib0.hinge_coulomb: 0.0}\n'
        '  - {rib1.hinge_coulomb: 0.0}\n  - {hub_radius: 0.0}\n  - {rib.l1: [0.5, 0.5, 0.5]}\n'
        '  - {ribs: 3}\n  - {rib.hinge_coulomb: [0, 0, 0.5]}\nduration: 0.01\n')
    spec = load_spec(str(path))
    assert spec.duplicates == [(2, 1), (3, 1), (5, 4), (6, 4), (7, 4)]
    assert [c.index for c in spec.cases] == [1, 4, 8]       # rib 2's is another umbrella


def test_a_sweeps_umbrella_value_of_the_wrong_type_is_refused(tmp_path):
    """A SPEC is typed YAML as a params file: a quoted number is a string, as for v0."""
    path = tmp_path / 'spec.yaml'
    path.write_text('base: {ribs: 3, base: free}\ncases:\n  - {bus_mass: "5"}\n'
                    'duration: 0.1\n')
    with pytest.raises(SpecError, match=re.escape(
            "parameter bus_mass='5': must be of type double, got string")):
        load_spec(str(path))
    params = tmp_path / 'ribs.yaml'
    params.write_text('umbrella_node:\n  ros__parameters:\n    rib1:\n      tip_mass: "0.1"\n')
    path.write_text(f'params: {params}\nbase: {{ribs: 3}}\ncases:\n  - {{v0: -0.2}}\n'
                    'duration: 0.1\n')
    with pytest.raises(SpecError, match=re.escape(
            f"sweep spec {path}: params: parameter rib1.tip_mass='0.1': must be of type "
            'double, got string')):
        load_spec(str(path))


def test_a_sweep_over_rib_parameters(tmp_path, monkeypatch):
    """
    A grid over a rib's stick time: every case runs the umbrella; the stuck one locks later.

    Each case's parameters hold the umbrella's (rib.<name> lists in the case id); a hinge
    stuck for 10 ms while the others push holds the whole umbrella back (one sleeve), so its
    lock comes after the free case's; both keep the energy balance with friction work.
    """
    spec = tmp_path / 'spec.yaml'
    spec.write_text('base: {ribs: 2, v0: 0.0, time_step: 0.0002, '
                    'rib.hinge_coulomb: [0.0, 0.05]}\n'
                    'grid: {rib.stick_until: [[0.0, 0.0], [0.0, 0.01]]}\n'
                    'duration: 0.3\nstop_after_lock: 0.005\nforce: 60.0\n')
    sweep = load_spec(str(spec))
    assert [c.params['rib.stick_until'] for c in sweep.cases] == [[0.0, 0.0], [0.0, 0.01]]
    assert len({c.case_id for c in sweep.cases}) == 2
    free, stuck = (run_case(c.task(None)) for c in sweep.cases)
    assert free['status'] == stuck['status'] == 'ok'
    assert free['summary']['ribs'] == 2
    assert stuck['summary']['lock_time'] > free['summary']['lock_time']
    for case in (free, stuck):
        assert case['summary']['energy_drift'] < 1e-10
        assert case['summary']['friction_work'][1] < 0.0
    # the plots draw each case's worst rib (its von Mises peak, its in-plane tip) and the
    # largest out-of-plane tip, against the swept rib parameter
    drawn = plotted_lines(monkeypatch)
    rows = [{**c.params, 'rib.stick_until': tuple(c.params['rib.stick_until']),
             'case': c.index, 'status': r['status'], **r['summary']}
            for c, r in zip(sweep.cases, (free, stuck))]     # (as table_rows gives them)
    written = sweep_results.plot(sweep, rows, str(tmp_path))
    assert sorted(os.path.basename(p) for p in written) == sorted(sweep_results.PLOTS)
    peaks = drawn['all cases: von Mises, worst rib']
    assert peaks == [pytest.approx(max(r['peak_stress']['von_mises']['value']) * 1e-6)
                     for r in rows]
    assert drawn['all cases: in-plane |v|, widest rib'] == [
        pytest.approx(max(r['max_in_plane_tip']) * 1e3) for r in rows]
    assert len(drawn['all cases: out-of-plane |w|, any rib']) == 2
    assert min(drawn['deploy_time']) > 0.0
    spec.write_text('base: {ribs: 2}\ngrid: {rib.stick_until: [[0.0, 0.01, 0.0]]}\n')
    with pytest.raises(SpecError, match='case 1.*stick_until'):
        load_spec(str(spec))


def plotted_lines(monkeypatch) -> dict:
    """Record what the plots draw: {legend label: the y values}; deploy times by curve."""
    from matplotlib.axes import Axes

    drawn = {}
    real = Axes.plot

    def plot(ax, *args, **kwargs):
        label = kwargs.get('label', '')
        ys = list(args[1]) if len(args) > 1 else []
        key = label if 'von Mises' in label or '|' in label else 'deploy_time'
        drawn.setdefault(key, []).extend(ys)
        return real(ax, *args, **kwargs)

    monkeypatch.setattr(Axes, 'plot', plot)
    return drawn


def test_a_nodes_parameters_make_the_model_by_one_rule():
    """
    params3d.node_model: what the node, the launch file's URDF and the tools build.

    rib.<name> lists give every rib a value, rib<k>.<name> one rib's over it; ribs 1 (the
    default) is the planar model, and refuses the umbrella's values, naming them.
    """
    model = node_model({'ribs': 3, 'l1': 0.5, 'rib.tip_mass': [0.0, 0.1, 0.2],
                        'rib2.tip_mass': 0.3, 'rib1.l2': 0.6, 'publish_rate': 200.0})
    ribs = model.ribs_list()
    assert [r.tip_mass for r in ribs] == [0.0, 0.1, 0.3]
    assert [r.planar.l2 for r in ribs] == [0.5, 0.6, 0.5]
    assert isinstance(node_model({'l2': 0.6}), UmbrellaParams)
    with pytest.raises(ValueError, match='rib1.l2'):
        node_model({'rib1.l2': 0.6})


def test_replay_info_says_the_fault_that_ended_a_recording(tmp_path, capsys):
    """A stuck rib held from the default V0: the run ends in a fault, which --info names."""
    from umbrella_sim.tools import replay

    bag = tmp_path / 'fault'
    assert cli.main(['simulate', '--set', 'ribs=3', '--set', 'rib.stick_until=[0, 0.2, 0]',
                     '--duration', '0.3', '--mcap', str(bag)]) == 3
    capsys.readouterr()
    assert replay.main([str(bag), '--info']) == 0
    (line,) = [t for t in capsys.readouterr().out.splitlines() if t.startswith('fault:')]
    # the fault the run ended in, as its events record holds it, before the lock it never had
    events = read_log(str(bag)).metadata[EVENTS_RECORD]
    assert events['locked'] == 'false' and 'the leaf reached the axle' in events['fault']
    assert line == (f"fault:         at t = {float(events['fault_time']):.9f} s: "
                    f"{events['fault']}"), line
    # and umbrella_compare's table says so, beside the per-rib friction work
    assert compare.main([str(bag), str(bag), '--out', str(tmp_path / 'cmp')]) == 0
    out = capsys.readouterr().out
    assert f"{bag.name}: ended in a fault: {events['fault']}" in out
    assert 'peak von Mises (MPa), friction work (J)' in out


def test_replay_info_gives_the_grid_step_and_stage_2_s_physics_step(tmp_path, capsys):
    """--info's step is the grid step; stage 2's substeps of it, as the node's diagnostics."""
    from umbrella_sim.tools import replay

    bag = tmp_path / 'locked'
    assert cli.main(['simulate', '--set', 'ribs=2', '--duration', '0.3', '--mcap',
                     str(bag)]) == 0
    capsys.readouterr()
    log = read_log(str(bag))
    grid = log.parameters()['physics_step']
    stage2 = log.summary(0)[0]['stage2_resolution']['step']
    assert stage2 < grid            # (the default: stage 2 in substeps of the grid step)
    assert replay.main([str(bag), '--info']) == 0
    out = capsys.readouterr().out
    assert f"lock auto, grid step {grid:g} s (stage 2's physics step {stage2:.3g} s)" in out
    assert ', physics step' not in out


def test_replay_info_says_what_a_recording_holds(tmp_path, capsys):
    """umbrella_replay --info: topics, counts and QoS, and the run (no ros2 CLI needed)."""
    from umbrella_sim.tools import replay

    bag = tmp_path / 'ribs'
    assert cli.main([*RUN, '--mcap', str(bag), '--publish-rate', '500']) == 0
    capsys.readouterr()
    assert replay.main([str(bag), '--info']) == 0
    out = capsys.readouterr().out
    log = read_log(str(bag))
    for topic in log.topics():
        kind = log.channels[topic][0]
        assert f'{topic} ' in out and kind in out
    stresses = log.count(log.find_topic('rib_peak_stress'))
    assert stresses == 21
    assert re.search(r'/rib_peak_stress +std_msgs/msg/Float64MultiArray  21 msgs', out)
    assert '2 ribs' in out and 'grid step 0.0002 s' in out
    assert "stage 2's physics step" not in out              # (it never locked)
    # the planar rib's own topics are not there (a node of ribs does not advertise them)
    assert not {'/tip_deflection', '/peak_stress'} & set(log.topics())
    assert f'messages:      {log.message_count}' in out
    # republishing's and re-simulation's options: refused, not ignored
    for extra in (['--rate', '2'], ['--resimulate'], ['--tolerance', '1e-3']):
        with pytest.raises(SystemExit) as exc:
            replay.main([str(bag), '--info', *extra])
        assert exc.value.code == 2
    assert '--info' in capsys.readouterr().err


@pytest.mark.parametrize('ribs', [1, 2])
def test_compare_tables_keep_their_columns_for_long_run_names(ribs, tmp_path, capsys):
    """The default run names (umbrella_YYYY_MM_DD-HH_MM_SS, 28 characters) pushed rows out."""
    bag = tmp_path / 'run'
    assert cli.main(['simulate', '--set', f'ribs={ribs}', '--duration', '0.02',
                     '--mcap', str(bag)]) == 0
    long_name = 'umbrella_2026_11_28-15_02_18_1'
    assert compare.main([str(bag), str(bag), '--names', 'a', long_name, '--no-plots',
                         '--out', str(tmp_path / 'cmp')]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(i for i, t in enumerate(lines) if t.startswith('run '))
    table = lines[header:header + 3]
    assert table[2].startswith(long_name + ' ') and table[1].startswith('a '), table
    assert len({len(t) for t in table}) == 1, table      # every row as wide as the header
    first_column = {t.index(' ', len(long_name)) for t in table}
    assert len(first_column) == 1, table


def test_a_sweeps_table_holds_every_umbrella_parameter_given_or_not(tmp_path):
    """results.csv: 'every other parameter', the umbrella's too (hub_radius, base, ...)."""
    from umbrella_sim.core.umbrella3d.params3d import UMBRELLA_SPECS

    spec = tmp_path / 'spec.yaml'
    spec.write_text('base: {ribs: 2, hub_radius: 0.05}\n'
                    'grid: {rib.stick_until: [[0.0, 0.0], [0.0, 0.01]]}\nduration: 0.1\n')
    sweep = load_spec(str(spec))

    class Store:

        def load(self, case_id):
            return {'status': 'ok', 'summary': {'ribs': 2, 'lock_time': 0.2}}
    columns, rows = sweep_results.table_rows(sweep, Store())
    for name, umbrella_spec in UMBRELLA_SPECS.items():
        assert name in columns, name
        want = 0.05 if name == 'hub_radius' else 2 if name == 'ribs' else umbrella_spec.default
        assert [row[name] for row in rows] == [want, want], name
    assert columns.index('rib.stick_until') == 3          # the swept one first
