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
``umbrella_sim sweep SPEC.yaml --out DIR``: parameter sweeps on a Dask cluster.

A SPEC (YAML) names the cases; each case is one offline run (the same path and the same JSON
summary as ``umbrella_sim simulate --json``), executed as a Dask task: on a local cluster with
one worker process per core, or on an existing cluster (``--scheduler tcp://HOST:PORT``)
started the usual way with ``dask scheduler`` and ``dask worker``.

The SPEC and its checks: sweep_spec.py; the store, the table and the plots: sweep_results.py.

DIR keeps an append-only store, ``DIR/cases/<case_id>.json``, one file per finished case,
written atomically the moment its result arrives; ``case_id`` hashes the case's full parameter
set, run options and the package version.  Re-running the same SPEC into the same DIR skips
the cases whose file is there (a case that raised, or whose worker was lost, is retried).
From the store: ``results.csv`` and ``results.parquet`` (one row per case: status, error, every
parameter, every key of the summary) and the plots.  Ctrl-C (or SIGTERM) stops the sweep,
keeps every finished case and writes the table of those.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import json
import os
import queue
import signal
import socket
import sys
import time
import traceback
from typing import Callable

from .progress import Progress
from .sweep_results import (CaseStore, is_finished, make_record, OutputError, plot,
                            STATUS_DIVERGED, STATUS_ERROR, STATUS_OK, table_rows, write_csv,
                            write_parquet)
from .sweep_spec import case_id, case_key, case_models, load_spec, SpecError, Sweep
from .. import __version__
from ..bag.paths import absolute_path, check_new_output
from ..core.registry import NODE_PARAMETERS
from ..ros.signals import deferred, name as signal_name, waking

#: the publication rate of a case's --mcap recording: the node's default, as simulate --mcap
MCAP_PUBLISH_RATE = NODE_PARAMETERS['publish_rate'].default
CONNECT_TIMEOUT = 10.0      # s to reach a --scheduler
WORKER_TIMEOUT = 30.0       # s for a first worker to join it


# ------------------------------------------------------------------ one case (on a worker)
def worker_version() -> str:
    """
    Return the umbrella_sim version a worker runs, after importing the physics core.

    Checked, and the import paid, before any case is sent.
    """
    from ..core import solver  # noqa: F401

    return __version__


def run_case(task: dict) -> dict:
    """
    Run one case offline, as ``umbrella_sim simulate`` does.

    Never raises: an exception becomes the case's error so the other cases go on.
    """
    out = {'case_id': task['case_id'], 'worker': f'{socket.gethostname()}:{os.getpid()}',
           'umbrella_sim': __version__, 'summary': {}, 'error': None, 'mcap': None,
           'started_at': time.time()}      # the worker's clock (gaps between its cases)
    t0 = time.perf_counter()
    try:
        params, umbrella, run = case_models(task['params'])
        profile = [tuple(row) for row in task['force_profile']] if task['force_profile'] else None
        if task['mcap_dir']:
            from ..ros.recording import record_offline

            bag = os.path.join(task['mcap_dir'], task['case_id'])
            if os.path.exists(bag):     # left by an unfinished earlier attempt of this case
                import shutil
                shutil.rmtree(bag)
            result = record_offline(params, bag, _mcap_duration(task), profile,
                                    publish_rate=MCAP_PUBLISH_RATE, what='recording',
                                    umbrella=umbrella)
            out['mcap'] = bag
            if result.recording_error:      # not finished: a resumed sweep runs it again
                out['summary'] = result.summary()
                out['error'] = result.recording_error      # names the bag
                out['status'] = STATUS_ERROR
                return _finished(out, t0)
        else:
            from ..core.driver import simulate

            result = simulate(run, task['duration'], force_profile=profile,
                              stop_after_lock=task['stop_after_lock'], keep_samples=False)
        out['summary'] = result.summary()
        out['error'] = result.error
        out['status'] = STATUS_DIVERGED if result.error else STATUS_OK
    except Exception as exc:  # noqa: BLE001 - the case's row carries it
        tb = traceback.format_exc(limit=-3).strip().splitlines()
        out['error'] = f"{type(exc).__name__}: {exc} [{' | '.join(tb[-3:-1])}]"
        out['status'] = STATUS_ERROR
    return _finished(out, t0)


def _finished(out: dict, t0: float) -> dict:
    out['case_wall_time'] = time.perf_counter() - t0
    out['finished_at'] = time.time()
    return out


def _mcap_duration(task: dict) -> float:
    """
    Return the recording length: the duration, or up to stop_after_lock past the lock.

    The lock is found first by the plain run, which costs a fraction of the recording.  A
    plain run that failed stopped at its fault, not at the end: the recording then takes
    the whole duration, so that it meets the same fault and the case reports it.
    """
    if task['stop_after_lock'] is None:
        return task['duration']
    from ..core.driver import simulate

    params = case_models(task['params'])[2]
    profile = [tuple(row) for row in task['force_profile']] if task['force_profile'] else None
    probe = simulate(params, task['duration'], force_profile=profile,
                     stop_after_lock=task['stop_after_lock'], keep_samples=False)
    if probe.error is not None:
        return task['duration']
    return min(task['duration'], probe.figures['final_time'])


# ------------------------------------------------------------------ progress
def case_progress(total: int, stream=None) -> Progress:
    """Return the sweep's progress line: bar, cases done of total, failures, elapsed, ETA."""
    return Progress(total, lambda done: f'{done:.0f}/{total} cases', stream)


# ------------------------------------------------------------------ running
@dataclass
class SweepReport:
    total: int
    skipped: int
    ran: int = 0
    failed: int = 0             # rows of the table whose status is not ok
    interrupted: bool = False
    csv: str = ''
    parquet: str = ''
    plots: list = field(default_factory=list)
    setup_s: float = 0.0        # wall time to start or reach the cluster and check its workers
    run_s: float = 0.0          # wall time from the first submission to the last result
    compute_s: float = 0.0      # sum of the cases' own wall times on the workers


def check_scheduler_address(address: str) -> str:
    """
    Return a --scheduler address if it has the form of one, else raise SpecError.

    [tcp:// | tls://]HOST:PORT, the addresses ``dask scheduler`` prints; checked before any
    work, where distributed would raise a ValueError from deep inside its client.
    """
    scheme, sep, rest = address.rpartition('://')
    host, colon, port = rest.rpartition(':')
    if (sep and scheme not in ('tcp', 'tls')) or not colon or not host.strip('[]') \
            or not port.isdigit() or not 0 < int(port) < 65536:
        raise SpecError(f'--scheduler {address!r}: not a scheduler address: expected '
                        'tcp://HOST:PORT (as `dask scheduler` prints it)')
    return address


def _client(workers: int | None, scheduler: str | None, log: Callable[[str], None]):
    import logging

    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise SpecError(f'umbrella_sim sweep needs dask and distributed ({exc}); '
                        'install requirements.txt') from None

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, ValueError) as exc:
            raise SpecError(f'--scheduler {scheduler}: cannot connect ({exc})') from None
        return client, None
    n = workers or os.cpu_count() or 1
    # loopback only, every port (scheduler, its HTTP server, workers) picked free by the OS
    from distributed.deploy.spec import SpecCluster

    before = set(SpecCluster._instances)
    try:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               host='127.0.0.1', scheduler_port=0,
                               dashboard_address='127.0.0.1:0', silence_logs=logging.ERROR)
    except KeyboardInterrupt:
        _drop_unstarted_clusters(set(SpecCluster._instances) - before)
        raise
    log(f"local Dask cluster: {n} worker process{'es' if n > 1 else ''} at "
        f'{cluster.scheduler_address}')
    return Client(cluster), cluster


def _drop_unstarted_clusters(clusters) -> None:
    """
    Close what a cluster interrupted while starting had started, and forget it.

    distributed closes every cluster at exit, and asserted on one a Ctrl-C had left
    half-made ('Exception ignored in atexit callback ... Status.init' after the exit line).
    clusters: the ones that start made (a caller's own are left alone).
    """
    for cluster in clusters:
        try:
            cluster.close(timeout=5)
        except BaseException:  # noqa: BLE001 - half-made: close what can be closed
            pass
        _forget_cluster(cluster)


def _forget_cluster(cluster) -> None:
    """Keep distributed from closing a cluster again at exit (we closed it, or tried)."""
    from distributed.deploy.spec import SpecCluster

    SpecCluster._instances.discard(cluster)


def _ignore_sigint() -> None:
    """
    Ignore SIGINT on a local cluster's workers.

    Ctrl-C reaches the whole process group; the sweep process handles it and closes the
    workers, which would otherwise each print a traceback.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _check_workers(client, scheduler: str | None, log) -> None:
    """Every worker imports this umbrella_sim version, or nothing is sent."""
    if scheduler:
        try:
            client.wait_for_workers(1, timeout=WORKER_TIMEOUT)
        except Exception:  # noqa: BLE001 - distributed raises its own TimeoutError
            raise SpecError(f'--scheduler {scheduler}: no worker joined within '
                            f'{WORKER_TIMEOUT:g} s') from None
    try:
        versions = client.run(worker_version)
    except Exception as exc:  # noqa: BLE001 - e.g. ModuleNotFoundError on a worker
        raise SpecError(f'workers cannot run umbrella_sim: {type(exc).__name__}: {exc}') from None
    wrong = {w: v for w, v in versions.items() if v != __version__}
    if wrong:
        raise SpecError(f'workers run other umbrella_sim versions than {__version__}: {wrong}')
    if scheduler:
        log(f'Dask cluster {scheduler}: {len(versions)} worker(s)')
    else:
        client.run(_ignore_sigint)


def _mcap_step_cases(sweep: Sweep, log) -> None:
    """
    Give --mcap cases whose recording shortens the step a case id of their own, and say so.

    A recording's physics step divides its publication period (as the node's), so at a
    time_step that does not divide it the recorded run is another computation than the
    plain one: it must not take (or replace) the plain case's result.
    """
    from ..core.driver import simulator_class
    from ..core.params import shortened_step_note

    rate = MCAP_PUBLISH_RATE
    for case in sweep.cases:
        run = case_models(case.params)[2]
        step = simulator_class(run).grid_step(run)
        note = shortened_step_note(step, rate)
        if note:
            case.case_id = case_id(dict(case_key(run), mcap_publish_rate=rate), case.duration,
                                   case.stop_after_lock, case.force_profile)
            log(f'case {case.index}: the --mcap recording takes a {note}')


def run_sweep(sweep: Sweep, out_dir: str, workers: int | None = None,
              scheduler: str | None = None, mcap: bool = False,
              stream=None) -> SweepReport:
    """
    Run the cases not yet in DIR's store, writing each result as it arrives.

    Then write the table and the plots (also after Ctrl-C, from the finished cases).
    """
    stream = stream or sys.stderr

    def log(msg):
        stream.write(msg + '\n')
        stream.flush()

    store = CaseStore(out_dir)
    mcap_dir = os.path.join(os.path.abspath(out_dir), 'mcap') if mcap else None
    if mcap:
        _mcap_step_cases(sweep, log)
    todo = [c for c in sweep.cases if not is_finished(store.load(c.case_id), mcap)]
    report = SweepReport(total=len(sweep.cases), skipped=len(sweep.cases) - len(todo))
    for index, same in sweep.duplicates:
        log(f'case {index} has the same parameters as case {same}: run once')
    if report.skipped:
        log(f'{report.skipped} of {report.total} cases already in {out_dir}: skipped')
    client = cluster = None
    futures = []
    made_dir = False
    write_error = None
    try:
        if todo:    # the cluster first: if it cannot be had, DIR is left as it was
            t0 = time.perf_counter()
            client, cluster = _client(workers, scheduler, log)
            _check_workers(client, scheduler, log)
        _prepare_dir(sweep, store, out_dir, mcap_dir)
        made_dir = True
        if todo:
            t1 = time.perf_counter()
            report.setup_s = t1 - t0
            by_key = {}
            # finished futures (put by distributed's callback thread) and stop signals (ints,
            # put by the handler): a Ctrl-C is acted on here, between two results, never
            # inside distributed's own waits (signals.waking)
            arrived = queue.SimpleQueue()
            with waking(arrived.put):
                for case in todo:
                    fut = client.submit(run_case, case.task(mcap_dir), pure=False,
                                        key=f'umbrella-case-{case.case_id}-{os.getpid()}')
                    by_key[fut.key] = case
                    futures.append(fut)
                    fut.add_done_callback(arrived.put)
                progress = case_progress(len(todo), stream)
                try:
                    for _ in futures:
                        fut = arrived.get()
                        if isinstance(fut, int):
                            raise KeyboardInterrupt(signal_name(fut))
                        case = by_key[fut.key]
                        try:
                            result = fut.result()
                        except Exception as exc:  # noqa: BLE001 - lost workers, cancelled
                            result = {'case_id': case.case_id, 'status': STATUS_ERROR,
                                      'error': f'{type(exc).__name__}: {exc}', 'summary': {},
                                      'worker': None, 'mcap': None}
                        store.save(make_record(case, result))
                        report.ran += 1
                        report.run_s = time.perf_counter() - t1
                        report.compute_s += result.get('case_wall_time') or 0.0
                        failed = result['status'] != STATUS_OK
                        progress.update(progress.done + 1, failed,
                                        f'case {case.index}: {case.label(sweep.swept)}'
                                        + (f": {result['status']}" if failed else ''))
                        fut.release()
                finally:
                    progress.close()
            log(f'{report.ran} case(s) in {report.run_s:.1f} s '
                f'({report.ran / max(report.run_s, 1e-9):.2f} cases/s, '
                f'{report.compute_s:.1f} s of computing; cluster ready in '
                f'{report.setup_s:.1f} s)')
    except KeyboardInterrupt:
        report.interrupted = True
        if made_dir:
            log(f'interrupted: {report.ran} case(s) of {len(todo)} finished in this run are '
                f'kept in {out_dir}; run the same command again to finish the rest')
        else:
            log(f'interrupted before any case ran; {out_dir} left as it was')
    except OutputError as exc:      # DIR cannot take results: stop, keep what the store has
        write_error = exc
        log(f'cannot write the results: {exc.strerror}; stopping the sweep')
    finally:
        if client is not None:
            # a stop signal while closing: after it (not inside distributed's waits)
            with deferred():
                try:
                    if futures:
                        client.cancel(futures)
                    client.close(timeout=10)
                    if cluster is not None:
                        cluster.close(timeout=10)
                except Exception:  # noqa: BLE001 - closing after an interrupt: best effort
                    pass
            if cluster is not None:
                _forget_cluster(cluster)
        if made_dir:
            try:
                _write_outputs(sweep, store, out_dir, report, log)
            except OutputError as exc:
                write_error = write_error or exc
    if write_error is not None:
        write_error.cases_kept = report.skipped + (report.ran if made_dir else 0)
        raise write_error
    return report


def _prepare_dir(sweep, store, out_dir, mcap_dir) -> None:
    try:
        os.makedirs(store.dir, exist_ok=True)
        if mcap_dir:
            os.makedirs(mcap_dir, exist_ok=True)
        with open(os.path.join(out_dir, 'spec.yaml'), 'w', encoding='utf-8') as fh:
            fh.write(sweep.text)
    except OSError as exc:
        raise OutputError(exc.errno, f'{exc.filename}: {exc.strerror}') from None


def _write_outputs(sweep, store, out_dir, report, log) -> None:
    columns, rows = table_rows(sweep, store)
    report.csv = os.path.join(out_dir, 'results.csv')
    report.parquet = os.path.join(out_dir, 'results.parquet')
    path = report.csv
    try:
        with deferred():        # a stop signal while the table is written: after it
            write_csv(report.csv, columns, rows)
            path = report.parquet
            try:
                write_parquet(report.parquet, columns, rows)
            except ImportError:
                report.parquet = ''
                log('results.parquet not written: pyarrow is not installed')
            ok = sum(r['status'] == STATUS_OK for r in rows)
            report.failed = len(rows) - ok
            # (a finished case past the model's range, yield or small deflections: said here,
            # as simulate says it on stderr, not only in the table)
            warned = sum(r['status'] == STATUS_OK and bool(r.get('warnings')) for r in rows)
            keys = sorted({w.split(':')[0] for r in rows if r['status'] == STATUS_OK
                           for w in _warning_list(r.get('warnings'))})
            log(f'{len(rows)} of {len(sweep.cases)} cases in {report.csv}: {ok} ok'
                + (f" ({warned} with warnings: {', '.join(keys)}; see the warnings column)"
                   if warned else '')
                + (f', {report.failed} failed (see the error column)' if report.failed
                   else ''))
        path = out_dir
        report.plots = plot(sweep, rows, out_dir)
    except OSError as exc:
        raise OutputError(exc.errno, f'{path}: {exc.strerror}') from None


# ------------------------------------------------------------------ command line
def check_out_dir(path: str) -> str:
    """
    Return the absolute results directory, or SpecError why it cannot be used.

    A new directory, or one to resume into.
    """
    try:
        path = absolute_path(path, '--out')
        if not os.path.lexists(path):
            return check_new_output(path, '--out', overwrite_option=None)
    except ValueError as exc:
        raise SpecError(str(exc)) from None
    if not os.path.isdir(path):
        raise SpecError(f'--out {path}: exists and is not a directory')
    if not os.access(path, os.W_OK | os.X_OK):
        raise SpecError(f'--out {path}: directory is not writable')
    cases = os.path.join(path, 'cases')
    if os.path.lexists(cases) and not os.path.isdir(cases):
        raise SpecError(f'--out {path}: {cases} exists and is not a directory')
    return path


def add_parser(sub) -> argparse.ArgumentParser:
    sp = sub.add_parser('sweep', help='run a parameter sweep on Dask',
                        description='Run every case of SPEC.yaml (base / grid / cases, see '
                                    'docs/sweeps.md) offline, in parallel on Dask; write '
                                    'DIR/results.csv, DIR/results.parquet and plots.')
    sp.add_argument('spec', metavar='SPEC.yaml', help='the sweep: base, grid, cases, run options')
    sp.add_argument('--out', required=True, metavar='DIR',
                    help='results directory; re-running into it skips finished cases')
    sp.add_argument('--workers', type=int, metavar='N',
                    help='local worker processes (default: one per core)')
    sp.add_argument('--scheduler', metavar='tcp://HOST:PORT',
                    help='run on this existing Dask cluster instead of a local one')
    sp.add_argument('--mcap', action='store_true',
                    help='keep a recording per case in DIR/mcap/<case_id>/')
    return sp


def main(args, ap: argparse.ArgumentParser) -> int:
    try:
        if args.workers is not None and args.workers < 1:
            raise SpecError(f'--workers {args.workers}: must be >= 1')
        if args.workers is not None and args.scheduler:
            raise SpecError("--workers and --scheduler: the cluster's workers are its own; "
                            'give one of them')
        if args.scheduler is not None:
            check_scheduler_address(args.scheduler)
        args.out = check_out_dir(args.out)
        checking = []           # the progress line of a large spec's checking, made once

        def checked(done, total):
            if not checking:
                checking.append(Progress(total, lambda d: f'checked {d:.0f}/{total} cases'))
            checking[0].update(done)

        try:
            sweep = load_spec(args.spec, progress=checked)
        finally:
            if checking:
                checking[0].close()
    except SpecError as exc:
        ap.exit(2, f'{ap.prog}: error: {exc}\n')

    def stop(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        report = run_sweep(sweep, args.out, workers=args.workers, scheduler=args.scheduler,
                           mcap=args.mcap)
    except SpecError as exc:
        ap.exit(2, f'{ap.prog}: error: {exc}\n')
    except OutputError as exc:
        kept = getattr(exc, 'cases_kept', 0)
        ap.exit(4, f'{ap.prog}: error: cannot write the results: {exc.strerror}; '
                   + (f'the {kept} case(s) finished before it are kept in '
                      f"{os.path.join(args.out, 'cases')}\n" if kept else
                      'no case result was kept\n'))
    except KeyboardInterrupt:       # a second stop, while the table or the plots were made
        print(f'{ap.prog}: interrupted; every finished case is kept in '
              f"{os.path.join(args.out, 'cases')} (and in results.csv if it was written: "
              'it is written whole); run the same command again to finish',
              file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    if report.interrupted:
        return 130
    return 3 if report.failed else 0


def _warning_list(value) -> list[str]:
    """Return a result row's validity warnings: its list, or the JSON text the CSV holds."""
    if isinstance(value, str):
        return json.loads(value) if value else []
    return list(value or [])
