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
umbrella_compare A B [...] --out DIR: compare recorded runs (live or offline).

Aligns the runs on the coarser run's publication times (where the rates are not multiples
of each other, the instants both runs published at), prints a table
and writes compare.json with: deployment time and its difference to the first run, max and
RMS difference of alpha1, its rate, the tip deflection and the peak stresses, the energy
drift of each run; writes PNG plots mirroring the thesis's figures (alpha1 and its rate and
acceleration, tip deflection in stage 1 and across the lock, stress at O'' on the leaf and at
mid-link, deformed shapes) over a window of time (--window; by default the deployment and
eight periods of the locked frame's vibration), with the thesis's values drawn where it
has them (its data at V0 = -0.2, -0.5, -1, -2 m/s).  --thesis adds them to the text and
JSON (a run they do not cover: a line saying why).  The text is in s, mm, MPa and rad;
compare.json in SI units, as each entry says.
Recordings of the umbrella of N ribs (ribs >= 2) are compared rib by rib: each run's lock,
each rib's deployment instant and its difference to the first run's, the lag of the latest
rib, each rib's largest leaf-angle difference and von Mises peak; plots of every rib's alpha1
and out-of-plane tip and a top view of the tips (ribs_alpha1.png, ribs_tip_out_of_plane.png,
ribs_top_view.png); --thesis, --physics-rate and --window are the planar rib's.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys

from .alignment import difference as _diff
from .arguments import ArgumentParser
from .compare_plots import plot
from .runs import (default_label, default_window, label_width, load_run, no_thesis_figures,
                   physics_figures, physics_run, Run, thesis_figures, THESIS_TABLE_6_1,
                   THESIS_V02)
from ..bag.reader import LogError, read_log
from ..ros.signals import EXIT_READER_GONE, interruptible, print_for_reader, raise_if_stopped


__all__ = ['compare', 'main', 'plot', 'print_table', 'load_run', 'THESIS_TABLE_6_1',
           'THESIS_V02']


#: (name, unit, (t, y) of a run, y is a peak-hold over each publication period)
SIGNALS = [('alpha1', 'rad', lambda r: (r.t, r.alpha1), False),
           ('alpha1_rate', 'rad/s', lambda r: (r.t, r.alpha1_rate), False),
           ('tip_deflection', 'm', lambda r: (r.tip_t, r.tip_v), False),
           ('peak_stress_leaf', 'Pa', lambda r: (r.stress_t, r.peak_leaf), True),
           ('peak_stress_link', 'Pa', lambda r: (r.stress_t, r.peak_link), True)]
#: the thesis's figures that are deployment times (of the lock, not of the samples)
THESIS_DEPLOY_TIMES = {'deploy_time', 'deploy_time_deformable_fea', 'deploy_time_rigid_fea'}
#: the text's unit of each SI unit of compare.json (one system: s, mm, MPa, rad)
TEXT_UNITS = {'m': ('mm', 1e3), 'Pa': ('MPa', 1e-6), 'rad': ('rad', 1.0),
              'rad/s': ('rad/s', 1.0), 's': ('s', 1.0)}


def compare(runs: list[Run], thesis: bool = False) -> dict:
    ref = runs[0]
    out = {'reference': ref.label, 'runs': []}
    for r in runs:
        entry = {'label': r.label, 'path': r.path, 'model': r.params.get('model'),
                 'elements_per_segment': r.params.get('elements_per_segment'),
                 'v0': r.params.get('v0'), 'deploy_time': r.deploy_time,
                 'deploy_start': r.deploy_start, 'lock_time': r.lock_time,
                 'deploy_time_difference': (None if r.deploy_time is None or ref.deploy_time
                                            is None else r.deploy_time - ref.deploy_time),
                 'energy_drift': r.energy_drift, 'differences': {}}
        for name, unit, get, peak_hold in SIGNALS:
            if r is ref:            # (the reference against itself: nothing to align)
                entry['differences'][name] = {'max': 0.0, 'rms': 0.0, 'unit': unit}
                continue
            rt, ry = get(ref)
            t, y = get(r)
            try:
                mx, rms = _diff(rt, ry, t, y, peak_hold)
            except LogError as exc:     # which runs, and what each holds
                raise LogError(f'{exc}: {ref.path} ({len(rt)} samples, t = {rt[0]:g} .. '
                               f'{rt[-1]:g} s) and {r.path} ({len(t)} samples, t = '
                               f'{t[0]:g} .. {t[-1]:g} s)') from None
            entry['differences'][name] = {'max': mx, 'rms': rms, 'unit': unit}
        entry['figures'] = r.figures()
        if r.fault:
            entry['fault'] = {'time': r.fault[0], 'reason': r.fault[1]}
        entry['warnings'] = r.validity()
        if r.not_judged():
            entry['not_judged'] = r.not_judged()
        if thesis:
            entry['thesis'] = thesis_figures(r.params)
            if not entry['thesis']:
                entry['thesis_none'] = no_thesis_figures(r.params)
            # figures of the samples (figures_from says why) beside the thesis's: a
            # deployment time alone is the exact lock's where the events record has it
            if r.summary is None and entry['thesis'] and (
                    not r.lock_time_exact or set(entry['thesis']) - THESIS_DEPLOY_TIMES):
                entry['thesis_note'] = (
                    "not comparable with the thesis's as they stand: this run's figures are "
                    f"of its recorded samples at {r.params.get('publish_rate')} Hz, not of "
                    'every physics step (--physics-rate re-runs the segment for those)')
        out['runs'].append(entry)
    return out


def print_table(result: dict, stream=None) -> None:
    w = (stream or sys.stdout).write
    L = label_width(result['runs'])       # (standard output when called, not when imported)
    w(f"reference run: {result['reference']}\n")
    w(f"{'run':<{L}} {'model':<9} {'N':>2} {'V0':>6} {'deploy (s)':>11} {'d deploy (s)':>13} "
      f"{'energy drift':>12}\n")
    for e in result['runs']:
        dt = e['deploy_time']
        dd = e['deploy_time_difference']
        w(f"{e['label']:<{L}} {str(e['model']):<9} {str(e['elements_per_segment']):>2} "
          f"{e['v0']:>6g} {('%.7f' % dt) if dt is not None else '-':>11} "
          f"{('%+.3e' % dd) if dd is not None else '-':>13} "
          f"{('%.2e' % e['energy_drift']) if e['energy_drift'] is not None else '-':>12}\n")
    w('\neach run against the reference run over the time both cover (the plots: --window), '
      'the largest and the rms difference (zero for the reference itself):\n')
    w(f"{'run':<{L}} " + ' '.join(f"{n + ' max/rms':>27}" for n, *_ in SIGNALS) + '\n')
    for e in result['runs']:
        cells = []
        for n, unit, *_ in SIGNALS:
            d = e['differences'][n]
            unit, scale = TEXT_UNITS[unit]
            cells.append(f"{d['max'] * scale:>11.3e}/{d['rms'] * scale:.3e} {unit:<5}"[:27]
                         .rjust(27))
        w(f"{e['label']:<{L}} " + ' '.join(cells) + '\n')
    w('\nfigures (stage-1 max tip deflection and time, stage-2 amplitude and period):\n')
    for e in result['runs']:
        f = e['figures']

        def fmt(key, scale=1.0, spec='.4g', figures=f):
            v = figures.get(key)
            return '-' if v is None else format(v * scale, spec)
        line = (f"{e['label']:<{L}} deploy {fmt('deploy_time', 1, '.5f')} s, tip max "
                f"{fmt('tip_deflection_max', 1e3)} mm at "
                f"{fmt('tip_deflection_max_time', 1, '.3f')} s, "
                f"stage 2 {fmt('stage2_tip_amplitude', 1e3)} mm / "
                f"{fmt('stage2_tip_period', 1, '.4f')} s")
        w(line + '\n')
        w(f"{'':<{L}} peak |sigma| leaf {fmt('peak_stress_leaf', 1e-6)} MPa at "
          f"{fmt('peak_stress_leaf_time', 1, '.3f')} s, link {fmt('peak_stress_link', 1e-6)} "
          f"MPa at {fmt('peak_stress_link_time', 1, '.3f')} s; from {f.get('figures_from')}\n")
        if 'fault' in e:
            w(f"{'':<{L}} fault: the run ended in a solver fault at t = "
              f"{e['fault']['time']:.4f} s (its figures are of the time before it): "
              f"{e['fault']['reason']}\n")
        for text in e.get('warnings', []):
            w(f"{'':<{L}} warning: {text}\n")
        for text in e.get('not_judged', []):
            w(f"{'':<{L}} not judged: {text}\n")
        th = e.get('thesis') or {}
        if 'deploy_time_deformable_fea' in th:
            w(f"{'':<{L}} thesis: deploy {th['deploy_time_deformable_fea']:.5f} s (deformable "
              f"FEA), {th['deploy_time_rigid_fea']:.5f} s (rigid FEA) (Table 6.1)\n")
        elif list(th) == ['deploy_time']:
            w(f"{'':<{L}} thesis: deploy {th['deploy_time']:.4f} s (ch. 6, its flexible "
              'model)\n')
        elif th:
            w(f"{'':<{L}} thesis: deploy {fmt('deploy_time', 1, '.4f', th)} s, tip max "
              f"{fmt('tip_deflection_max', 1e3, '.3f', th)} mm at "
              f"{fmt('tip_deflection_max_time', 1, '.3f', th)} s, stage 2 "
              f"~{fmt('stage2_tip_amplitude', 1e3, '.0f', th)} mm / "
              f"~{fmt('stage2_tip_period', 1, '.2f', th)} s (ch. 6, read off its plots)\n")
        elif 'thesis_none' in e:
            w(f"{'':<{L}} thesis: no figures for this run: {e['thesis_none']}\n")
        if 'thesis_note' in e:
            w(f"{'':<{L}} caveat: {e['thesis_note']}\n")


@interruptible('umbrella_compare', '--out may hold part of the outputs')
def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(prog='umbrella_compare', description=__doc__,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('logs', nargs='+', help='bag directories or .mcap files (first = reference)')
    ap.add_argument('--out', required=True,
                    help='new (or empty) directory for compare.json and the plots')
    ap.add_argument('--overwrite', action='store_true',
                    help='replace the outputs of an earlier umbrella_compare in --out (a '
                         'directory of compare.json and .png files only)')
    ap.add_argument('--segment', type=int, default=0,
                    help='which segment of each log (a ~/reset starts a new one; default 0)')
    ap.add_argument('--names', nargs='+', help='labels for the runs')
    ap.add_argument('--thesis', action='store_true', help="add the thesis's numbers")
    ap.add_argument('--no-plots', action='store_true')
    ap.add_argument('--physics-rate', action='store_true',
                    help="re-run each log's recorded commands (as umbrella_replay "
                         '--resimulate does) and draw the leaf angle, rate, acceleration, tip '
                         'deflection and peak stresses from every physics step instead of the '
                         'recorded samples; a segment the log has no summary record of takes '
                         'its figures from the re-run too')
    ap.add_argument('--magnification', type=float, nargs=2, default=(200.0, 5.0),
                    metavar=('STAGE1', 'STAGE2'),
                    help='deformation magnification of the shapes plot, at most (default '
                         '200 5; each is reduced to a round number that keeps the shapes '
                         'on the plot)')
    ap.add_argument('--window', type=float, nargs=2, metavar=('T0', 'T1'),
                    help='sim-time span of the plots, s (default: from the start of the '
                         "deployment to 8 periods of the locked frame's first mode after "
                         'the lock; a run that never locks, all of it).  The table and '
                         'compare.json are of the whole runs')
    args = ap.parse_args(argv)
    if not all(math.isfinite(m) and m > 0 for m in args.magnification):
        ap.error(f'--magnification {args.magnification}: must be finite numbers > 0')
    if args.window and not (all(math.isfinite(t) for t in args.window)
                            and args.window[0] < args.window[1]):
        ap.error(f'--window {args.window[0]:g} {args.window[1]:g}: two finite times, '
                 'T0 < T1')
    if args.segment < 0:
        ap.error(f'--segment {args.segment}: must be >= 0')
    if args.names and len(args.names) != len(args.logs):
        ap.error(f'--names: {len(args.names)} labels for {len(args.logs)} logs')
    if args.names and len(set(args.names)) != len(args.names):
        ap.error(f"--names {' '.join(args.names)}: each run needs a label of its own")
    names = args.names or [default_label(p) for p in args.logs]
    if len(set(names)) != len(names):      # same-named bags or files: their paths as given
        names = [p if names.count(n) > 1 else n for p, n in zip(args.logs, names)]
    try:
        out = _check_out_dir(args.out, args.overwrite)      # before reading any log
        if _ribs_logs(args):                # the umbrella of N ribs: its own comparison
            from .compare_ribs import compare_ribs, load_ribs_run, plot_ribs, print_ribs_table

            runs = [load_ribs_run(p, name, args.segment) for p, name in zip(args.logs, names)]
            result = compare_ribs(runs)
            table, draw, span = print_ribs_table, lambda: plot_ribs(runs, out), ''
        else:
            runs = [load_run(p, name, args.segment) for p, name in zip(args.logs, names)]
            window = tuple(args.window) if args.window else default_window(runs)
            if args.physics_rate:
                physics_runs(runs, args.segment, None if args.no_plots else window[1])
            result = compare(runs, thesis=args.thesis)
            if not args.no_plots:
                result['plot_window'] = list(window)
            table, span = print_table, f' of t = {window[0]:.4g} .. {window[1]:.4g} s (--window)'

            def draw():
                return plot(runs, out, tuple(args.magnification), window)
    except LogError as exc:
        raise_if_stopped()           # (a stop signal inside a decoding: an interrupt)
        print(f'umbrella_compare: error: {exc}', file=sys.stderr)
        return 2
    # (umbrella_compare ... | head): the outputs are still written
    reader_there = print_for_reader(lambda: table(result))
    try:
        os.makedirs(out, exist_ok=True)
        for name in _earlier_outputs(out) if args.overwrite else ():   # (now: replaced)
            os.unlink(os.path.join(out, name))
        if not args.no_plots:
            result['plots'] = draw()
        with open(os.path.join(out, 'compare.json'), 'x', encoding='utf-8') as fh:
            json.dump(result, fh, indent=2)
    except OSError as exc:
        print(f'umbrella_compare: error: writing to {out}: {exc.strerror or exc} (the table '
              'above is complete)', file=sys.stderr)
        return 4
    print(f"\nwrote {os.path.join(out, 'compare.json')}"
          + (f" and {len(result['plots'])} plots{span}" if 'plots' in result else ''))
    return 0 if reader_there else EXIT_READER_GONE


def physics_runs(runs: list[Run], segment: int, until: float | None) -> None:
    """
    --physics-rate: re-run each log's segment (its recorded parameters and commands).

    The signals at every physics step up to until for the plots (None: no plots); a run
    whose log has no summary record of the segment (an older recording's earlier segment,
    a killed recording) is re-run to the segment's end for its summary figures, so that
    they are of every physics step too.
    """
    for r in runs:
        if until is None and r.summary is not None:
            continue                # (its figures are the record's: nothing to re-run)
        rerun = physics_run(r.path, segment, 0.0 if until is None else until,
                            figures=r.summary is None)
        if until is not None:
            r.physics = rerun
        if r.summary is None:
            physics_figures(r, rerun['figures'])


def _ribs_logs(args) -> bool:
    """Say whether the logs are of the umbrella of N ribs (LogError: a mix, or its options)."""
    from .compare_ribs import is_ribs_log

    ribs = [is_ribs_log(read_log(p).segment(args.segment).params) for p in args.logs]
    if any(ribs) and not all(ribs):
        raise LogError(f"{', '.join(p for p, r in zip(args.logs, ribs) if r)}: recordings of "
                       'the umbrella of N ribs among planar ones: compare like with like')
    given = [o for o, on in (('--thesis', args.thesis), ('--physics-rate', args.physics_rate),
                             ('--window', args.window)) if on]
    if any(ribs) and given:
        raise LogError(f"{', '.join(given)}: options of the planar comparison; recordings of "
                       'the umbrella of N ribs are compared over every publication (leave '
                       f"{', '.join(given)} out)")
    return any(ribs)


def _earlier_outputs(path: str) -> list[str] | None:
    """Return the files of an earlier comparison in path, or None if it holds others."""
    names = os.listdir(path)
    ours = [n for n in names if (n == 'compare.json' or n.endswith('.png'))
            and os.path.isfile(os.path.join(path, n))
            and not os.path.islink(os.path.join(path, n))]
    return names if len(ours) == len(names) else None


def _check_out_dir(path: str, overwrite: bool = False) -> str:
    """--out: a new directory, or an existing empty one (or, overwrite, an earlier --out)."""
    from ..bag.paths import check_new_output

    if os.path.isdir(path) and not os.path.islink(path):
        if os.listdir(path) and not overwrite:
            raise LogError(f'--out {path}: directory is not empty, not overwriting '
                           "(--overwrite replaces an earlier comparison's outputs)")
        if overwrite and _earlier_outputs(path) is None:
            raise LogError(f"--out {path}: holds files other than an earlier comparison's "
                           '(compare.json, .png), not overwriting them even with --overwrite')
        if not os.access(path, os.W_OK | os.X_OK):
            raise LogError(f'--out {path}: directory is not writable')
        return path
    if os.path.lexists(path):       # a file (or a link): --out is a directory of outputs
        raise LogError(f'--out {path}: exists and is not a directory, not overwriting it '
                       '(--out takes a directory for compare.json and the plots; --overwrite '
                       "replaces only an earlier comparison's directory): give a new path")
    try:
        return check_new_output(path, '--out')
    except ValueError as exc:
        raise LogError(str(exc)) from None


if __name__ == '__main__':
    sys.exit(main())
