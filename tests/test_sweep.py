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
umbrella_sim sweep: SPEC checks, local and distributed Dask runs, failures and re-runs.

The distributed run is real: `dask scheduler` and two `dask worker` processes on 127.0.0.1; a
worker is killed mid-sweep, a sweep is interrupted as by Ctrl-C and re-run.

Every process a test starts runs in its own session and is killed (whole process group) in
teardown; every port is picked free by the OS.
"""
import csv
import json
import math
import os
import signal
import subprocess
import sys

import pytest


from umbrella_sim.core.driver import simulate
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.rigid import deployment_time_by_quadrature
from umbrella_sim.testing import poll
from umbrella_sim.tools import cli, sweep, sweep_results
from umbrella_sim.tools.compare import THESIS_TABLE_6_1

BIN = os.path.dirname(sys.executable)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: columns that depend on the machine and the moment, not on the physics
WALL_CLOCK = {'wall_time', 'real_time_factor', 'worker', 'mcap'}

SMALL_SPEC = """
grid:
  v0: [-1.0, -2.0]
  model: [flexible, rigid]
cases:
  - {v0: -2.0, model: rigid-fe}
  - {v0: -1000.0, time_step: 0.01}   # 1 km/s with a 10 ms step: the solver gives up
duration: 0.1
stop_after_lock: 0.01
"""


def write(path, text):
    path.write_text(text)
    return str(path)


def sweep_cmd(*args):
    return [sys.executable, '-m', 'umbrella_sim', 'sweep', *args]


class Processes:
    """Processes started by a test, each in its own session; all killed at teardown."""

    def __init__(self, log_dir):
        self.log_dir = log_dir
        self.procs = []

    def start(self, name, cmd):
        log = open(os.path.join(self.log_dir, name + '.log'), 'w')
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, cwd=self.log_dir)
        proc.log_path = log.name
        log.close()
        self.procs.append(proc)
        return proc

    @staticmethod
    def kill(proc, sig=signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass

    def stop_all(self):
        for proc in self.procs:
            self.kill(proc)
        for proc in self.procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass


def output(proc):
    with open(proc.log_path, encoding='utf-8', errors='replace') as fh:
        return fh.read()


def run_sweep(procs, name, *args, timeout=240):
    proc = procs.start(name, sweep_cmd(*args))
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f'sweep {name} did not finish in {timeout} s:\n{output(proc)}')
    return proc.returncode, output(proc)


def read_rows(out_dir):
    with open(os.path.join(out_dir, 'results.csv'), newline='') as fh:
        return list(csv.DictReader(fh))


def physics(rows):
    return [{k: v for k, v in row.items() if k not in WALL_CLOCK} for row in rows]


def wait_for(predicate, timeout, what):
    poll(predicate, timeout, lambda: f'timed out after {timeout} s waiting for {what}', 0.1)


def scheduler_address(path):
    """Return the address in a scheduler file (None: not there, or not written whole yet)."""
    try:
        with open(path) as fh:
            return json.load(fh)['address']
    except (OSError, ValueError, KeyError):
        return None


def finished_cases(out_dir):
    cases = os.path.join(out_dir, 'cases')
    return [f for f in os.listdir(cases) if f.endswith('.json')] if os.path.isdir(cases) else []


@pytest.fixture
def procs(tmp_path):
    p = Processes(str(tmp_path))
    yield p
    p.stop_all()


@pytest.fixture(scope='module')
def local_run(tmp_path_factory):
    """Run the small SPEC on a local cluster of two worker processes (module-wide)."""
    tmp = tmp_path_factory.mktemp('local')
    spec = write(tmp / 'small.yaml', SMALL_SPEC)
    out = str(tmp / 'out')
    procs = Processes(str(tmp))
    try:
        rc, log = run_sweep(procs, 'local', spec, '--out', out, '--workers', '2')
    finally:
        procs.stop_all()
    return {'spec': spec, 'out': out, 'rc': rc, 'log': log, 'rows': read_rows(out)}


def start_dask_cluster(procs, tmp_path):
    """Start `dask scheduler` and two `dask worker` processes on 127.0.0.1 (free ports)."""
    scheduler_file = str(tmp_path / 'scheduler.json')
    procs.start('scheduler', [os.path.join(BIN, 'dask'), 'scheduler', '--host', '127.0.0.1',
                              '--port', '0', '--dashboard-address', '127.0.0.1:0',
                              '--scheduler-file', scheduler_file])
    wait_for(lambda: scheduler_address(scheduler_file), 60,
             "the scheduler's address in its file")
    address = scheduler_address(scheduler_file)
    workers = [procs.start(f'worker{i}', [
        os.path.join(BIN, 'dask'), 'worker', address, '--host', '127.0.0.1', '--nworkers', '1',
        '--nthreads', '1', '--dashboard-address', '127.0.0.1:0',
        '--local-directory', str(tmp_path / f'worker{i}')]) for i in range(2)]
    from distributed import Client

    with Client(address, timeout='30s') as client:
        client.wait_for_workers(2, timeout=60)
    return address, workers


@pytest.fixture(scope='module')
def dask_cluster(tmp_path_factory):
    """Start a cluster shared by the tests that leave it as they found it (module-wide)."""
    tmp = tmp_path_factory.mktemp('cluster')
    procs = Processes(str(tmp))
    try:
        yield start_dask_cluster(procs, tmp)
    finally:
        procs.stop_all()


@pytest.fixture
def own_dask_cluster(procs, tmp_path):
    """Start a cluster for one test, which may break it (kill a worker)."""
    return start_dask_cluster(procs, tmp_path)


# ------------------------------------------------------------------ SPEC checks
@pytest.mark.parametrize('spec, culprits', [
    ('grid:\n  v0: [-1.0, -2.0]\n  speed: [1, 2]\n', ['case 1', 'speed', 'unknown parameter']),
    ('grid:\n  v0: [-1.0, fast]\n', ['case 2', 'v0', 'fast']),
    ('grid:\n  v0: [-1.0]\ncases:\n  - {model: flexible}\n  - {model: elastic}\n',
     ['case 3', 'model', 'elastic', 'one of']),
    ('base: {l3: 0.01}\ngrid:\n  v0: [-1.0]\n', ['case 1', 'cannot close']),
    ('grid:\n  model: [flexible, rigid]\nbase: {lock: energy}\n',       # as simulate's
     ['case 2', 'lock=energy', 'always plastic']),
    ('grid:\n  elements_per_segment: [1, 2.5]\n', ['case 2', 'elements_per_segment']),
    ('grid:\n  v0: []\n', ['grid', 'v0', 'non-empty list']),
    ('grid:\n  v0: [-1.0]\nduration: -1\n', ['duration', '-1']),
    ('grid:\n  v0: [-1.0]\nstop_after_lock: .nan\n', ['stop_after_lock']),
    ('grid:\n  v0: [-1.0]\nforce: -2\n', ['force', '>= 0']),
    ('grid:\n  sleeve_force: [5.0]\nforce: 3\n', ['force and grid: sleeve_force']),
    ('grid:\n  v0: [-1.0]\ncases:\n  - {sleeve_force: 2.0}\nforce: 3\n',
     ['force and cases: sleeve_force']),
    ("grid:\n  v0: ['-0.5']\n", ['case 1', "v0='-0.5'", 'must be of type double, got string']),
    ("base: {step_follows_mesh: 'yes'}\ngrid:\n  v0: [-1.0]\n",
     ['case 1', 'step_follows_mesh', 'got string']),
    ('grid:\n  v0: [-1.0]\nforce_profile: missing.csv\n', ['force_profile', 'missing.csv']),
    ('grid:\n  v0: [-1.0]\nrepeat: 3\n', ['unknown key', 'repeat']),
    ('base: {v0: -1.0}\n', ['no cases']),
    ('grid: [v0, -1.0]\n', ['grid', 'mapping']),
    ('grid:\n  v0: [-1.0\n', ['not valid YAML']),
])
def test_bad_spec_refused_before_any_work(tmp_path, capsys, spec, culprits):
    path = write(tmp_path / 'bad.yaml', spec)
    out = tmp_path / 'out'
    with pytest.raises(SystemExit) as exc:
        cli.main(['sweep', path, '--out', str(out)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    for culprit in culprits:
        assert culprit in err, err
    assert not out.exists(), 'a refused SPEC must not touch the results directory'


def test_missing_spec_and_bad_options_refused(tmp_path, capsys):
    spec = write(tmp_path / 'ok.yaml', 'grid:\n  v0: [-1.0]\n')
    a_file = write(tmp_path / 'a_file', '')
    out = str(tmp_path / 'out')
    for args, culprits in (
            (['nope.yaml', '--out', out], ['sweep spec', 'nope.yaml']),
            ([str(tmp_path), '--out', out], ['sweep spec', 'not a regular file']),
            ([spec, '--out', out, '--workers', '0'], ['--workers']),
            ([spec, '--out', out, '--workers', '2', '--scheduler', 'tcp://127.0.0.1:1'],
             ['--scheduler']),
            ([spec, '--out', out, '--scheduler', 'notaurl'], ["--scheduler 'notaurl'"]),
            ([spec, '--out', out, '--scheduler', 'tcp://127.0.0.1'], ['not a scheduler']),
            ([spec, '--out', out, '--scheduler', 'http://127.0.0.1:8786'], ['tcp://HOST']),
            ([spec, '--out', out, '--scheduler', 'tcp://127.0.0.1:99999'], ['--scheduler']),
            ([spec, '--out', out, '--scheduler', 'tcp://:8786'], ['--scheduler']),
            ([spec, '--out', a_file], ['--out', 'not a directory']),
            ([spec, '--out', ''], ["--out ''", 'empty path']),
            ([spec, '--out', str(tmp_path / 'no' / 'out')], ['--out', 'parent directory'])):
        with pytest.raises(SystemExit) as exc:
            cli.main(['sweep', *args])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert all(c in err for c in culprits), err
    assert not (tmp_path / 'out').exists() and not (tmp_path / 'no').exists()


def test_unreachable_scheduler_refused_before_dir_is_touched(tmp_path, capsys, monkeypatch):
    import socket

    with socket.socket() as sock:       # a port nobody listens on
        sock.bind(('127.0.0.1', 0))
        address = f'tcp://127.0.0.1:{sock.getsockname()[1]}'
    monkeypatch.setattr(sweep, 'CONNECT_TIMEOUT', 1.0)
    spec = write(tmp_path / 'ok.yaml', 'grid:\n  v0: [-1.0]\n')
    with pytest.raises(SystemExit) as exc:
        cli.main(['sweep', spec, '--out', str(tmp_path / 'out'), '--scheduler', address])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f'--scheduler {address}: cannot connect' in err, err
    assert not (tmp_path / 'out').exists(), 'no cluster, no results directory'


def test_spec_cases_ids_and_force_profile(tmp_path):
    """
    Check the grid product (first axis outermost) and the explicit cases after it.

    Duplicates run once, a force profile is read relative to the SPEC, and the case's run
    matches simulate().
    """
    write(tmp_path / 'push.csv', 't,F\n0.0,0.0\n0.01,4.0\n')
    spec = sweep.load_spec(write(tmp_path / 's.yaml', (
        'base: {elements_per_segment: 1}\n'
        'grid:\n  v0: [-0.5, -1.0]\n  model: [flexible, rigid]\n'
        'cases:\n  - {v0: -1.0, model: rigid}\n  - {v0: -1.0, lock: plastic}\n'
        'force_profile: push.csv\nduration: 0.12\nstop_after_lock: 0.0\n')))
    assert [(c.params['v0'], c.params['model']) for c in spec.cases[:4]] == [
        (-0.5, 'flexible'), (-0.5, 'rigid'), (-1.0, 'flexible'), (-1.0, 'rigid')]
    assert spec.duplicates == [(5, 4)]
    assert spec.cases[-1].index == 6 and spec.cases[-1].params['lock'] == 'plastic'
    assert spec.axes == ['v0', 'model'] and spec.swept == ['v0', 'model', 'lock']
    assert len({c.case_id for c in spec.cases}) == 5
    case = spec.cases[0]
    assert case.force_profile == [[0.0, 0.0], [0.01, 4.0]]
    got = sweep.run_case(case.task(None))
    assert got['status'] == 'ok', got['error']
    ref = simulate(UmbrellaParams(v0=-0.5), 0.12, force_profile=[(0.0, 0.0), (0.01, 4.0)],
                   stop_after_lock=0.0).summary()
    assert got['summary']['deploy_time'] == ref['deploy_time']
    free = simulate(UmbrellaParams(v0=-0.5), 0.12, stop_after_lock=0.0).summary()
    assert got['summary']['deploy_time'] < free['deploy_time'], 'F_H pushes toward deployment'
    # the key follows every parameter and the run options
    other = sweep.load_spec(write(tmp_path / 't.yaml', (
        'base: {elements_per_segment: 1}\ngrid:\n  v0: [-0.5]\n  model: [flexible]\n'
        'force_profile: push.csv\nduration: 0.12\n')))
    assert other.cases[0].case_id != case.case_id


def test_spec_force_profile_is_judged_by_each_cases_model_naming_its_row(tmp_path):
    """
    A SPEC's profile is read once and checked against each case's model, naming file:line.

    Above a case's bound (the umbrella's weakest link: rib 1's 4 mm section) the refusal
    names the case, the file and the line of the row (it said 'at t = 0.1 s', no file, and
    held the force to the planar record's link, 39x rib 1's); a braking row is the case's
    to take (its sleeve_force_min), not refused by the defaults' push-only bound.
    """
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams

    weak = UmbrellaRibsParams.from_mapping({'ribs': 3, 'rib1.section_height': 0.004})
    write(tmp_path / 'push.csv', f't,F\n0.0,1.0\n\n0.1,{1.01 * weak.sleeve_force_limit:.6f}\n')
    spec = write(tmp_path / 's.yaml', (
        'base: {elements_per_segment: 1}\n'
        'cases:\n  - {v0: -0.5}\n  - {ribs: 3, rib1.section_height: 0.004}\n'
        'force_profile: push.csv\nduration: 0.05\n'))
    with pytest.raises(sweep.SpecError) as exc:
        sweep.load_spec(spec)
    text = str(exc.value)
    assert 'case 2' in text and f"force profile {tmp_path / 'push.csv'}:4" in text, text
    assert "rib 1's link can carry" in text, text
    write(tmp_path / 'brake.csv', 't,F\n0.0,1.0\n0.05,-2.0\n')
    spec = write(tmp_path / 'b.yaml', (
        'base: {elements_per_segment: 1}\ngrid:\n  sleeve_force_min: [-5.0, 0.0]\n'
        'force_profile: brake.csv\nduration: 0.05\n'))
    with pytest.raises(sweep.SpecError) as exc:
        sweep.load_spec(spec)
    text = str(exc.value)
    assert 'case 2' in text and f"force profile {tmp_path / 'brake.csv'}:3" in text, text
    assert 'sleeve_force_min' in text, text


def test_table_takes_every_summary_key(tmp_path):
    """
    Check that the table follows the summary: a key the sweep has never heard of is a column.

    Lists (e.g. validity warnings) are JSON text in both files; a case without a result is no
    row; a summary key that repeats a parameter is not a second column, unless the run took
    another value (a rigid model's lock: the table said energy where the run stopped plastically);
    a parameter left to ``auto`` takes the value the run resolved.
    """
    import pyarrow.parquet as pq

    auto = sweep.load_spec(write(tmp_path / 'a.yaml', 'grid:\n  v0: [-0.5, -1.0]\n'))
    assert auto.cases[0].params['lock'] == 'auto'       # the default: resolved by the run,
    store = sweep.CaseStore(str(tmp_path / 'auto'))      # whose lock is the column
    for case, lock in zip(auto.cases, ('energy', 'plastic')):
        store.save(sweep.make_record(case, {'case_id': case.case_id, 'status': 'ok',
                                            'error': None, 'summary': {'lock': lock},
                                            'worker': 'w', 'mcap': None}))
    columns, rows = sweep.table_rows(auto, store)
    assert [r['lock'] for r in rows] == ['energy', 'plastic'] and 'lock_used' not in columns

    spec = sweep.load_spec(write(tmp_path / 's.yaml',
                                 'base: {lock: energy}\ngrid:\n  v0: [-0.5, -1.0, -2.0]\n'))
    store = sweep.CaseStore(str(tmp_path / 'out'))
    summaries = [{'deploy_time': 0.09, 'warnings': [], 'a_new_figure': 1.5, 'lock': 'energy'},
                 {'deploy_time': 0.045, 'warnings': ['step too coarse for the lock', 'x'],
                  'a_new_figure': 2, 'lock': 'energy'}]
    for case, summary in zip(spec.cases, summaries):
        store.save(sweep.make_record(case, {'case_id': case.case_id, 'status': 'ok',
                                            'error': None, 'summary': summary,
                                            'worker': 'w', 'mcap': None}))
    columns, rows = sweep.table_rows(spec, store)
    assert len(rows) == 2 and columns.count('lock') == 1 and 'lock_used' not in columns
    summaries[1]['lock'] = 'plastic'        # (as a rigid model's summary says)
    store.save(sweep.make_record(spec.cases[1], {'case_id': spec.cases[1].case_id,
                                                 'status': 'ok', 'error': None,
                                                 'summary': summaries[1], 'worker': 'w',
                                                 'mcap': None}))
    columns, rows = sweep.table_rows(spec, store)
    assert [(r['lock'], r['lock_used']) for r in rows] == [('energy', 'energy'),
                                                           ('energy', 'plastic')]
    assert columns.index('v0') < columns.index('deploy_time') < columns.index('a_new_figure')
    sweep.write_csv(str(tmp_path / 'r.csv'), columns, rows)
    sweep.write_parquet(str(tmp_path / 'r.parquet'), columns, rows)
    with open(tmp_path / 'r.csv', newline='') as fh:
        got = list(csv.DictReader(fh))
    parquet = pq.read_table(str(tmp_path / 'r.parquet')).to_pylist()
    for table in (got, parquet):
        assert [json.loads(r['warnings']) for r in table] == [s['warnings'] for s in summaries]
        assert [float(r['a_new_figure']) for r in table] == [1.5, 2.0]
    assert isinstance(parquet[1]['a_new_figure'], float), 'int and float cells: one float column'
    # a case that failed before its summary: no lock was used (it showed the one asked for)
    store.save(sweep.make_record(spec.cases[2], {'case_id': spec.cases[2].case_id,
                                                 'status': 'error', 'error': 'boom',
                                                 'summary': {}, 'worker': 'w',
                                                 'mcap': None}))
    columns, rows = sweep.table_rows(spec, store)
    assert rows[2]['lock'] == 'energy' and rows[2]['lock_used'] is None
    assert '_same' not in columns


def test_the_summary_line_says_how_many_finished_cases_warned(tmp_path, monkeypatch):
    """A case past the model's range (yield...) is said on the console, not only in the table."""
    from umbrella_sim.tools import sweep as sweep_tool

    spec = sweep.load_spec(write(tmp_path / 's.yaml', 'grid:\n  v0: [-0.5, -1.0, -2.0]\n'))
    store = sweep.CaseStore(str(tmp_path / 'out'))
    for case, warnings in zip(spec.cases, ([], ['yield exceeded: 1.2 x'], [])):
        store.save(sweep.make_record(case, {'case_id': case.case_id, 'status': 'ok',
                                            'error': None, 'summary': {'warnings': warnings},
                                            'worker': 'w', 'mcap': None}))
    monkeypatch.setattr(sweep_tool, 'plot', lambda *args: [])
    said = []
    report = sweep_tool.SweepReport(total=3, skipped=0)
    sweep_tool._write_outputs(spec, store, str(tmp_path / 'out'), report, said.append)
    assert '3 ok (1 with warnings' in said[-1] and 'warnings column' in said[-1], said
    assert 'with warnings: yield exceeded;' in said[-1], said     # (the keys the cases said)
    store.save(sweep.make_record(spec.cases[1], {'case_id': spec.cases[1].case_id,
                                                 'status': 'ok', 'error': None,
                                                 'summary': {'warnings': []}, 'worker': 'w',
                                                 'mcap': None}))
    sweep_tool._write_outputs(spec, store, str(tmp_path / 'out'), report, said.append)
    assert said[-1].endswith(': 3 ok'), said


def test_progress_line_counts_failures_and_eta(monkeypatch):
    import io

    from umbrella_sim.tools import progress as progress_module

    clock = [100.0]
    monkeypatch.setattr(progress_module.time, 'monotonic', lambda: clock[0])
    log = io.StringIO()
    progress = sweep.case_progress(4, log)
    clock[0] = 110.0
    progress.update(1, False, 'case 1: v0=-1.0')
    clock[0] = 130.0
    progress.update(2, True, 'case 2: v0=-2.0: diverged')
    lines = log.getvalue().splitlines()
    assert lines[0].endswith('1/4 cases  elapsed 0:00:10  ETA 0:00:30  (case 1: v0=-1.0)')
    assert '2/4 cases, 1 failed  elapsed 0:00:30  ETA 0:00:30' in lines[1]

    class Terminal(io.StringIO):

        def isatty(self):
            return True

    term = Terminal()
    progress = sweep.case_progress(2, term)
    clock[0] += 3725.0
    progress.update(1, False, 'case 1')
    progress.close()
    assert term.getvalue() == ('\r[############             ] 1/2 cases  elapsed 1:02:05  '
                               'ETA 1:02:05\n')


# ------------------------------------------------------------------ local cluster
@pytest.mark.slow
def test_local_sweep_table_physics_and_plots(local_run):
    assert local_run['rc'] == 3, local_run['log']          # one case fails, the rest go on
    rows = local_run['rows']
    assert [int(r['case']) for r in rows] == [1, 2, 3, 4, 5, 6]
    by = {(float(r['v0']), r['model']): r for r in rows}
    failed = rows[5]
    assert failed['status'] == 'diverged' and failed['error'], failed
    assert all(r['status'] == 'ok' and not r['error'] for r in rows[:5])
    for v0 in (-1.0, -2.0):
        t_flex = float(by[(v0, 'flexible')]['deploy_time'])
        t_rigid = float(by[(v0, 'rigid')]['deploy_time'])
        exact = deployment_time_by_quadrature(UmbrellaParams(), v0)
        assert t_rigid == pytest.approx(exact, rel=1e-4)
        # deformation delays the deployment (Table 6.1); the flexible time is the thesis's
        assert t_flex > t_rigid
        assert t_flex == pytest.approx(THESIS_TABLE_6_1[v0][0], rel=5e-3)
    assert float(by[(-2.0, 'rigid-fe')]['deploy_time']) == pytest.approx(
        deployment_time_by_quadrature(UmbrellaParams(), -2.0), rel=1e-3)
    # each row is the summary `umbrella_sim simulate` gives for the same case
    ref = simulate(UmbrellaParams(v0=-2.0), 0.1, stop_after_lock=0.01).summary()
    row = by[(-2.0, 'flexible')]
    for key, value in ref.items():
        if key in WALL_CLOCK or key == 'error':
            continue
        assert key in row, f'summary key {key} missing from results.csv'
        if isinstance(value, float):
            assert float(row[key]) == value, key
    assert float(row['duration']) == 0.1 and float(row['stop_after_lock']) == 0.01
    assert float(row['final_time']) == pytest.approx(ref['final_time'])
    # parquet holds the same table
    import pyarrow.parquet as pq

    table = pq.read_table(os.path.join(local_run['out'], 'results.parquet')).to_pylist()
    assert [r['case_id'] for r in table] == [r['case_id'] for r in rows]
    assert table[0]['deploy_time'] == float(rows[0]['deploy_time'])
    for name in sweep_results.PLOTS:
        with open(os.path.join(local_run['out'], name), 'rb') as fh:
            assert fh.read(8) == b'\x89PNG\r\n\x1a\n', name
    assert '6/6 cases' in local_run['log'] and 'ETA' in local_run['log']


@pytest.mark.slow           # (its module-wide sweep or cluster: seconds to start)
def test_rerun_skips_finished_cases(local_run, procs):
    store = os.path.join(local_run['out'], 'cases')
    before = {f: os.stat(os.path.join(store, f)).st_mtime_ns for f in os.listdir(store)}
    rc, log = run_sweep(procs, 'again', local_run['spec'], '--out', local_run['out'])
    assert rc == 3, log                 # still one failed case in the table
    assert '6 of 6 cases already' in log and 'Dask cluster' not in log, log
    assert {f: os.stat(os.path.join(store, f)).st_mtime_ns for f in os.listdir(store)} == before
    assert physics(read_rows(local_run['out'])) == physics(local_run['rows'])


@pytest.mark.slow
def test_ctrl_c_keeps_finished_cases_and_rerun_completes(tmp_path, procs):
    # (each case ~0.3 s of the compiled step: at 2 ms a case took 0.01 s, and the eight could
    # all finish before the first was seen, leaving no sweep to interrupt)
    spec = write(tmp_path / 'slow.yaml', (
        'base: {elements_per_segment: 4, v0: -1.0, time_step: 0.0002}\n'
        'grid:\n  section_height: [0.008, 0.009, 0.010, 0.011, 0.012, 0.013, 0.014, 0.015]\n'
        'duration: 2.0\n'))
    out = str(tmp_path / 'out')
    proc = procs.start('interrupted', sweep_cmd(spec, '--out', out, '--workers', '1'))
    wait_for(lambda: finished_cases(out) or proc.poll() is not None, 120, 'a finished case')
    os.killpg(proc.pid, signal.SIGINT)          # as Ctrl-C in a terminal: the whole group
    proc.wait(timeout=60)
    log = output(proc)
    assert proc.returncode == 130, log
    assert 'interrupted' in log and 'Traceback' not in log, log
    kept = finished_cases(out)
    rows = read_rows(out)
    assert 1 <= len(rows) == len(kept) < 8, log
    assert {r['case_id'] + '.json' for r in rows} == set(kept)
    rc, log2 = run_sweep(procs, 'finish', spec, '--out', out, '--workers', '1')
    assert rc == 0, log2
    assert f'{len(kept)} of 8 cases already' in log2
    rows2 = read_rows(out)
    assert len(rows2) == 8 and all(r['status'] == 'ok' for r in rows2)
    final = {r['case_id']: r for r in physics(rows2)}
    for row in physics(rows):
        assert final[row['case_id']] == row, 'a kept case changed'
    # a thicker section is stiffer: less stage-1 tip deflection (rows in SPEC order)
    tips = [float(r['tip_deflection_max']) for r in rows2]
    assert all(a > b for a, b in zip(tips, tips[1:])), tips


# ------------------------------------------------------------------ a real Dask cluster
@pytest.mark.slow
def test_distributed_run_equals_local_run(local_run, dask_cluster, procs, tmp_path):
    address, _ = dask_cluster
    out = str(tmp_path / 'dist')
    rc, log = run_sweep(procs, 'dist', local_run['spec'], '--out', out, '--scheduler', address)
    assert rc == 3, log
    assert f'Dask cluster {address}: 2 worker(s)' in log
    rows = read_rows(out)
    assert physics(rows) == physics(local_run['rows'])
    assert len({r['worker'] for r in rows}) == 2, 'both workers took cases'


@pytest.mark.slow
def test_worker_killed_mid_sweep_gives_complete_table(own_dask_cluster, procs, tmp_path):
    address, workers = own_dask_cluster
    spec = write(tmp_path / 'ten.yaml', (
        'base: {elements_per_segment: 4, time_step: 0.002}\n'
        'grid:\n  v0: [-0.3, -0.4, -0.5, -0.6, -0.7, -0.8, -0.9, -1.0, -1.1, -1.2]\n'
        'duration: 1.0\n'))
    out = str(tmp_path / 'out')
    proc = procs.start('killed', sweep_cmd(spec, '--out', out, '--scheduler', address))
    wait_for(lambda: finished_cases(out) or proc.poll() is not None, 120, 'a finished case')
    Processes.kill(workers[0])          # nanny and worker process, mid-sweep
    workers[0].wait(timeout=10)
    proc.wait(timeout=240)
    log = output(proc)
    assert proc.returncode == 0, log
    rows = read_rows(out)
    assert len(rows) == 10 and all(r['status'] == 'ok' for r in rows), log
    # stage-1 tip deflection grows with the deployment speed, whichever worker ran the case
    tips = [float(r['tip_deflection_max']) for r in rows]
    assert all(a < b for a, b in zip(tips, tips[1:])), tips
    assert math.isclose(float(rows[0]['deploy_time']),
                        simulate(UmbrellaParams(v0=-0.3, elements_per_segment=4,
                                                time_step=0.002), 1.0)
                        .summary()['deploy_time'], rel_tol=0, abs_tol=0)


def store_one_case(spec, index, out):
    """Run case `index` of the SPEC in-process and store it, as a sweep run does."""
    case = sweep.load_spec(spec).cases[index]
    sweep.CaseStore(out).save(sweep.make_record(case, sweep.run_case(case.task(None))))
    return case


def test_unwritable_table_exits_4_and_keeps_the_store(tmp_path, capsys):
    spec = write(tmp_path / 's.yaml', 'grid:\n  v0: [-2.0]\nbase: {model: rigid}\n'
                                      'duration: 0.05\n')
    out = tmp_path / 'out'
    case = store_one_case(spec, 0, str(out))
    (out / 'results.csv').mkdir()       # the table cannot be written (even by root)
    with pytest.raises(SystemExit) as exc:
        cli.main(['sweep', spec, '--out', str(out)])
    assert exc.value.code == 4
    err = capsys.readouterr().err
    assert 'cannot write the results' in err and str(out / 'results.csv') in err, err
    assert finished_cases(str(out)) == [case.case_id + '.json']


def test_ctrl_c_while_the_table_is_written_keeps_a_whole_table(tmp_path, capfd, monkeypatch):
    """A stop signal in the middle of writing results.csv: the table is finished, then 130."""
    spec = write(tmp_path / 's.yaml', 'grid:\n  v0: [-2.0, -1.0]\nbase: {model: rigid}\n'
                                      'duration: 0.05\n')
    out = tmp_path / 'out'
    cases = [store_one_case(spec, i, str(out)) for i in (0, 1)]
    write_csv = sweep.write_csv

    def interrupted_write(path, columns, rows):
        with open(path, 'w') as fh:
            fh.write(','.join(columns) + '\n')
        os.kill(os.getpid(), signal.SIGINT)     # Ctrl-C after the header line
        write_csv(path, columns, rows)

    monkeypatch.setattr(sweep, 'write_csv', interrupted_write)
    assert cli.main(['sweep', spec, '--out', str(out)]) == 130
    err = capfd.readouterr().err
    assert '2 of 2 cases in' in err and 'interrupted; every finished case is kept' in err, err
    assert {r['case_id'] for r in read_rows(str(out))} == {c.case_id for c in cases}
    assert os.path.exists(out / 'results.parquet')


@pytest.mark.slow           # (its module-wide sweep or cluster: seconds to start)
def test_store_write_error_stops_the_sweep_keeping_finished_cases(dask_cluster, tmp_path,
                                                                  capsys):
    address, _ = dask_cluster
    spec = write(tmp_path / 's.yaml', 'grid:\n  v0: [-1.0, -2.0]\nbase: {model: rigid}\n'
                                      'duration: 0.05\n')
    out = tmp_path / 'out'
    first = store_one_case(spec, 0, str(out))
    second = sweep.load_spec(spec).cases[1]
    (out / 'cases' / (second.case_id + '.json')).mkdir()   # its result cannot be stored
    with pytest.raises(SystemExit) as exc:     # in this process: no second start-up to pay
        cli.main(['sweep', spec, '--out', str(out), '--scheduler', address])
    log = capsys.readouterr().err
    assert exc.value.code == 4, log
    assert 'cannot write the results' in log and second.case_id in log, log
    assert [r['case_id'] for r in read_rows(str(out))] == [first.case_id]


@pytest.mark.slow
def test_mcap_keeps_a_recording_per_case(dask_cluster, tmp_path, procs):
    from umbrella_sim.tools.compare import load_run

    address, _ = dask_cluster
    spec = write(tmp_path / 'rec.yaml', ('grid:\n  model: [flexible, rigid]\nbase: {v0: -2.0}\n'
                                         'duration: 0.05\nstop_after_lock: 0.005\n'))
    out = str(tmp_path / 'out')
    store_one_case(spec, 0, out)    # the flexible case, finished by a run without --mcap
    # ... runs again under --mcap, to make its recording
    rc, log = run_sweep(procs, 'rec', spec, '--out', out, '--scheduler', address, '--mcap')
    assert rc == 0 and 'already' not in log, log
    rows = read_rows(out)
    for row in rows:
        bag = row['mcap']
        assert bag == os.path.join(out, 'mcap', row['case_id'])
        assert os.path.isfile(os.path.join(bag, row['case_id'] + '_0.mcap'))
        run = load_run(bag)
        # recorded at 100 Hz publications: the lock shows within one publication period
        assert run.deploy_time == pytest.approx(float(row['deploy_time']), abs=0.0101)
        assert run.params['model'] == row['model']
    rc, log = run_sweep(procs, 'rec2', spec, '--out', out, '--scheduler', address, '--mcap')
    assert rc == 0 and '2 of 2 cases already' in log, log


def test_mcap_case_that_diverges_is_reported_as_without_mcap(tmp_path):
    """A case that fails fails under --mcap too: its row, its error, its recording's fault."""
    from umbrella_sim.tools.replay import read_log

    spec = write(tmp_path / 'f.yaml', 'cases:\n  - {v0: -1000.0, time_step: 0.01}\n'
                                      'duration: 0.1\nstop_after_lock: 0.01\n')
    case = sweep.load_spec(spec).cases[0]
    plain = sweep.run_case(case.task(None))
    mcap_dir = tmp_path / 'mcap'
    mcap_dir.mkdir()
    recorded = sweep.run_case(case.task(str(mcap_dir)))
    assert plain['status'] == 'diverged' and plain['error'], plain
    assert recorded['status'] == plain['status'], recorded
    assert recorded['error'] == plain['error']
    assert recorded['summary']['steps'] == plain['summary']['steps']
    events = read_log(recorded['mcap']).metadata['umbrella_sim.events']
    assert events.get('fault') == plain['error'], events


def test_a_case_whose_recording_failed_is_not_finished(tmp_path, monkeypatch):
    """--mcap: a case whose recording hit a write error is an error, run again on resume."""
    from umbrella_sim.ros import recording

    spec = sweep.load_spec(write(tmp_path / 's.yaml',
                                 'grid:\n  v0: [-2.0]\nbase: {model: rigid}\nduration: 0.05\n'))
    record = recording.record_offline

    def full_disk(*args, **kwargs):     # what a full disk leaves: the run, a torn recording
        result = record(*args, **kwargs)
        result.recording_error = 'No space left on device'
        return result

    monkeypatch.setattr(recording, 'record_offline', full_disk)
    case = spec.cases[0]
    (tmp_path / 'mcap').mkdir()
    result = sweep.run_case(case.task(str(tmp_path / 'mcap')))
    assert result['status'] == 'error' and 'No space left on device' in result['error']
    assert result['summary']['deploy_time'] > 0          # what the run computed is kept
    store = sweep.CaseStore(str(tmp_path / 'out'))
    store.save(sweep.make_record(case, result))
    assert not sweep.is_finished(store.load(case.case_id), mcap=True)   # (it was 'ok')


def test_an_mcap_case_whose_recording_shortens_the_step_is_a_case_of_its_own(tmp_path):
    """3 ms does not divide the 10 ms publication period: the recorded run steps at 2.5 ms."""
    spec = sweep.load_spec(write(tmp_path / 's.yaml',
                                 'grid:\n  time_step: [3.0e-3, 2.0e-3]\nduration: 0.1\n'))
    plain = [c.case_id for c in spec.cases]
    notes: list = []
    sweep._mcap_step_cases(spec, notes.append)
    assert spec.cases[0].case_id != plain[0] and spec.cases[1].case_id == plain[1]
    assert notes == [notes[0]] and 'case 1' in notes[0] and '0.0025 s, not 0.003 s' in notes[0]
