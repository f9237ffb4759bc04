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
A sweep's results: the store of finished cases, the table (CSV, parquet) and the plots.

DIR keeps an append-only store, ``DIR/cases/<case_id>.json``, one file per finished case,
written atomically the moment its result arrives, so that re-running the same SPEC into the
same DIR skips them.  From the store: ``results.csv`` and ``results.parquet`` (one row per
case: status, error, every parameter, every key of the summary) and the plots of deployment
time, peak stress and tip deflection against the swept parameter (of a case of the umbrella
of N ribs: its worst rib's von Mises peak, its widest rib's in-plane tip and the largest
out-of-plane tip, over the whole run).
"""
from __future__ import annotations

import csv
import json
import os

from .sweep_spec import Case, Sweep
from ..core.registry import REGISTRY
from ..core.umbrella3d.params3d import UMBRELLA_SPECS

#: a case's status in the table
STATUS_OK, STATUS_DIVERGED, STATUS_ERROR = 'ok', 'diverged', 'error'


class OutputError(OSError):
    """DIR cannot be written; the message names the file (finished cases stay in the store)."""


#: statuses of a case that is done: re-running the sweep skips it
FINISHED = (STATUS_OK, STATUS_DIVERGED)
#: the plots drawn into DIR
PLOTS = ('deploy_time.png', 'peak_stress.png', 'tip_deflection.png')


# ------------------------------------------------------------------ the store
class CaseStore:
    """DIR/cases/<case_id>.json: one file per case result, each written atomically."""

    def __init__(self, out_dir: str):
        self.dir = os.path.join(out_dir, 'cases')     # made by the first save

    def path(self, cid: str) -> str:
        return os.path.join(self.dir, cid + '.json')

    def load(self, cid: str) -> dict | None:
        try:
            with open(self.path(cid), encoding='utf-8') as fh:
                return json.load(fh)
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return None             # unreadable: the case runs again

    def save(self, record: dict) -> None:
        tmp = self.path(record['case_id']) + f'.{os.getpid()}.tmp'
        try:
            os.makedirs(self.dir, exist_ok=True)
            with open(tmp, 'w', encoding='utf-8') as fh:
                json.dump(record, fh, indent=1, default=_jsonable)     # summary keys in order
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path(record['case_id']))
        except OSError as exc:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise OutputError(exc.errno, f"{self.path(record['case_id'])}: "
                                         f'{exc.strerror}') from None


def _jsonable(value):
    if hasattr(value, 'tolist'):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    return str(value)


def is_finished(record: dict | None, mcap: bool) -> bool:
    if record is None or record.get('status') not in FINISHED:
        return False
    return not mcap or bool(record.get('mcap')) and os.path.isdir(record['mcap'])


def make_record(case: Case, result: dict) -> dict:
    return dict(result, case=case.index, overrides=case.overrides, params=case.params,
                duration=case.duration, stop_after_lock=case.stop_after_lock,
                force_profile=case.force_profile_path)


# ------------------------------------------------------------------ results table
def table_rows(sweep: Sweep, store: CaseStore) -> tuple[list[str], list[dict]]:
    """One row per case of the SPEC that has a result: case, status, parameters, summary."""
    rows, summary_keys = [], []
    # a sweep of the umbrella of N ribs: each case's umbrella parameters, given or default
    umbrella = ({name: spec.default for name, spec in UMBRELLA_SPECS.items()}
                if any(case.params.get('ribs', 1) > 1 for case in sweep.cases) else {})
    for case in sweep.cases:
        rec = store.load(case.case_id)
        if rec is None:
            continue
        row = {'case': case.index, 'case_id': case.case_id, 'status': rec.get('status'),
               'error': rec.get('error')}
        row.update({name: case.params.get(name, case.overrides.get(name)) for name in sweep.swept})
        row.update(umbrella)
        row.update(case.params)
        for name, value in row.items():     # a rib.<name> list: one value, for the plots
            if isinstance(value, list):
                row[name] = tuple(value)
        row.update(duration=case.duration, stop_after_lock=case.stop_after_lock,
                   force_profile=case.force_profile_path)
        used = row['_same'] = set()     # summary keys that repeat their parameter's value
        for key, value in (rec.get('summary') or {}).items():
            if key == 'error':
                continue
            if key in case.params:      # the parameter's column, unless the run took another
                if value == case.params[key]:     # (a rigid model's lock is plastic)
                    used.add(key)
                    continue
                if case.params[key] == 'auto':    # resolved by the run: its column says how
                    row[key] = value
                    used.add(key)
                    continue
                key = f'{key}_used'
            if key not in summary_keys:
                summary_keys.append(key)
            row[key] = value
        row.update(worker=rec.get('worker'), mcap=rec.get('mcap'))
        rows.append(row)
    for key in [k for k in summary_keys if k.endswith('_used')]:   # in every row, then:
        for row in rows:        # the value the run took (none for a run that has no summary)
            name = key[:-len('_used')]
            row.setdefault(key, row.get(name) if name in row['_same'] else None)
    for row in rows:
        del row['_same']
    columns = ['case', 'case_id', 'status'] + list(sweep.swept)
    columns += [n for n in (rows[0] if rows else {}) if n not in columns and n not in
                ('error', 'worker', 'mcap') and n not in summary_keys]
    columns += summary_keys + ['error', 'worker', 'mcap']
    return columns, rows


def _cell(value):
    if isinstance(value, (list, dict, tuple)):
        return json.dumps(value)
    return value


def write_csv(path: str, columns: list[str], rows: list[dict]) -> None:
    tmp = path + '.tmp'
    try:
        with open(tmp, 'w', newline='', encoding='utf-8') as fh:
            w = csv.writer(fh)
            w.writerow(columns)
            for row in rows:
                w.writerow(['' if row.get(c) is None else _cell(row.get(c)) for c in columns])
        os.replace(tmp, path)
    except BaseException:       # a full disk, an interrupt: no half table left beside it
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_parquet(path: str, columns: list[str], rows: list[dict]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {}
    for c in columns:
        values = [_cell(row.get(c)) for row in rows]
        kinds = {type(v) for v in values if v is not None}
        if kinds <= {int, float} and float in kinds:
            values = [None if v is None else float(v) for v in values]
        elif len(kinds) > 1:
            values = [None if v is None else str(v) for v in values]
        arrays[c] = pa.array(values) if kinds else pa.nulls(len(values), pa.string())
    tmp = path + '.tmp'
    pq.write_table(pa.table(arrays), tmp)
    os.replace(tmp, path)


# ------------------------------------------------------------------ plots
def _series(sweep: Sweep, rows: list[dict]):
    """Group the rows: x = the first grid axis, a series per combination of the others."""
    x_name = sweep.axes[0] if sweep.axes else 'case'
    others = [n for n in sweep.swept if n != x_name]
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        if row.get('status') not in FINISHED:
            continue
        groups.setdefault(tuple(row.get(n) for n in others), []).append(row)

    def label(key):
        parts = []
        closed_form = dict(zip(others, key)).get('model') == 'rigid'
        for name, value in zip(others, key):
            if name == 'model':
                parts.insert(0, str(value))
            elif name == 'elements_per_segment':
                if not closed_form:             # the closed-form rigid model has no mesh
                    parts.append(f'N = {value}')
            else:
                parts.append(f'{name} = {value}')
        return ', '.join(parts) or 'all cases'

    return x_name, [(label(k), sorted(g, key=lambda r: _sort_key(r.get(x_name))))
                    for k, g in groups.items()]


def _sort_key(v):
    return (0, v, '') if isinstance(v, (int, float)) else (1, 0, str(v))


def _reference_series(series):
    """
    Return the series the deployment-time difference is taken to.

    The rigid model's if swept (Table 6.1's "time prolonged"), else the first.
    """
    for label, g in series:
        if g and all(r.get('model') == 'rigid' for r in g):
            return label, g
    return series[0]


def plot(sweep: Sweep, rows: list[dict], out_dir: str,
         reference: dict | None = None) -> list[str]:
    """
    Plot deploy_time.png, peak_stress.png, tip_deflection.png against the first grid axis.

    One curve per combination of the other swept parameters.  reference: {label: {x: deploy
    time}} drawn as open markers (e.g. the thesis's Table 6.1).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    rows = [_plotted(r) for r in rows]
    x_name, series = _series(sweep, rows)
    if not series:
        return []
    umbrella = any(WORST_RIB_STRESS in r for r in rows)
    xs_all = sorted({r.get(x_name) for _, g in series for r in g}, key=_sort_key)
    numeric = all(isinstance(x, (int, float)) for x in xs_all)
    pos = {x: (x if numeric else i) for i, x in enumerate(xs_all)}
    unit = REGISTRY[x_name].unit if x_name in REGISTRY else '-'
    xlabel = x_name if unit == '-' else f'{x_name} ({unit})'
    colours = {label: f'C{i % 10}' for i, (label, _) in enumerate(series)}
    written = []

    def points(g, key, scale):
        return [(pos[r.get(x_name)], r[key] * scale) for r in g
                if isinstance(r.get(key), (int, float))]

    def finish(fig, axes, name, title):
        for ax in axes:
            if not numeric:
                ax.set_xticks(range(len(xs_all)), [str(x) for x in xs_all])
            ax.grid(True, alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=8)
        axes[-1].set_xlabel(xlabel)
        axes[0].set_title(title)
        fig.tight_layout()
        path = os.path.join(out_dir, name)
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)

    # deployment time, and its difference to the rigid model (Table 6.1 "time prolonged")
    if len(series) > 1 or reference:
        fig, (ax, ax_d) = plt.subplots(2, 1, figsize=(7, 6.5), sharex=True,
                                       gridspec_kw={'height_ratios': [3, 2]})
    else:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        ax_d = None
    ref_label, ref_rows = _reference_series(series)
    ref = {r.get(x_name): r['deploy_time'] for r in ref_rows
           if isinstance(r.get('deploy_time'), (int, float))}
    for label, g in series:
        pts = points(g, 'deploy_time', 1.0)
        if pts:
            ax.plot(*zip(*pts), 'o-', color=colours[label], label=label)
        diff = [(pos[r.get(x_name)], (r['deploy_time'] - ref[r.get(x_name)]) * 1e3) for r in g
                if isinstance(r.get('deploy_time'), (int, float)) and r.get(x_name) in ref]
        if diff and label != ref_label and ax_d is not None:
            ax_d.plot(*zip(*diff), 'o-', color=colours[label], label=label)
    for i, (label, values) in enumerate((reference or {}).items()):
        pts = sorted((pos[x], t) for x, t in values.items() if x in pos and t is not None)
        style = {'marker': 'Dx+^v'[i % 5], 'ms': 9, 'ls': 'none', 'color': 'k', 'mfc': 'none',
                 'label': label}
        if pts:
            ax.plot(*zip(*pts), **style)
            diff = [(pos[x], (t - ref[x]) * 1e3) for x, t in values.items()
                    if x in ref and x in pos and t is not None]
            if diff and ax_d is not None:
                ax_d.plot(*zip(*sorted(diff)), **style)
    ax.set_ylabel('deployment time (s)')
    if ax_d is not None:
        ax_d.set_ylabel(f'minus {ref_label} (ms)')
        ax_d.axhline(0.0, color='k', lw=0.8)
    finish(fig, [a for a in (ax, ax_d) if a is not None], 'deploy_time.png',
           f'deployment time vs {x_name}' + ('' if umbrella else ' (thesis Table 6.1)'))

    def elastic(keys):
        """Series with elastic deformation: rigid models (zero up to round-off) left out."""
        top = max([abs(r[k]) for _, g in series for r in g for k in keys
                   if isinstance(r.get(k), (int, float))] or [0.0])
        return [(label, g) for label, g in series
                if any(abs(r[k]) > 1e-6 * top for r in g for k in keys
                       if isinstance(r.get(k), (int, float)))]

    # peak stresses with the yield line
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, g in elastic(['peak_stress_leaf', 'peak_stress_link', WORST_RIB_STRESS]):
        for key, style, body in (('peak_stress_leaf', 'o-', 'leaf'),
                                 ('peak_stress_link', 's--', 'link'),
                                 (WORST_RIB_STRESS, 'D-', 'von Mises, worst rib')):
            pts = points(g, key, 1e-6)
            if pts:
                ax.plot(*zip(*pts), style, color=colours[label], label=f'{label}: {body}')
    for y in sorted({r['yield_strength'] for _, g in series for r in g
                     if isinstance(r.get('yield_strength'), (int, float))}):
        ax.axhline(y * 1e-6, color='r', lw=1.2, ls='-.', label=f'yield strength {y * 1e-6:g} MPa')
    ax.set_ylabel('peak |stress| (MPa)')
    finish(fig, [ax], 'peak_stress.png', f'peak stress vs {x_name}')

    fig, ax = plt.subplots(figsize=(7, 4.5))
    tips = (('tip_deflection_max', 'o-', 'stage 1' if umbrella else ''),
            (WIDEST_RIB_TIP, 'D-', 'in-plane |v|, widest rib'),
            ('max_out_of_plane_tip', '^:', 'out-of-plane |w|, any rib'))
    for label, g in elastic([key for key, _, _ in tips]):
        for key, style, what in tips:
            pts = points(g, key, 1e3)
            if pts:
                ax.plot(*zip(*pts), style, color=colours[label],
                        label=f'{label}: {what}' if what else label)
    if umbrella:        # (the umbrella's summary: the largest over the whole run)
        ax.set_ylabel('max tip deflection of G (mm)')
        finish(fig, [ax], 'tip_deflection.png', f'max tip deflection vs {x_name}')
    else:
        ax.set_ylabel('stage-1 max transverse deflection of G (mm)')
        finish(fig, [ax], 'tip_deflection.png', f'stage-1 max tip deflection vs {x_name}')
    return written


#: what the plots draw of a case of the umbrella of N ribs (its summary's per-rib figures):
#: the worst rib's von Mises peak (Pa) and the widest rib's in-plane tip (m), whole run
WORST_RIB_STRESS, WIDEST_RIB_TIP = 'peak_von_mises_worst_rib', 'max_in_plane_tip_widest_rib'


def _plotted(row: dict) -> dict:
    """Return a row as the plots read it: a case of the umbrella with its worst rib's figures."""
    peaks = row.get('peak_stress')
    if not isinstance(peaks, dict) or not isinstance(row.get('max_in_plane_tip'), list):
        return row
    try:
        return dict(row, **{WORST_RIB_STRESS: max(peaks['von_mises']['value']),
                            WIDEST_RIB_TIP: max(row['max_in_plane_tip'])})
    except (KeyError, TypeError, ValueError):       # (a summary of another shape: as is)
        return row
