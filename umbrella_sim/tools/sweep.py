"""
``umbrella-sim sweep SPEC.yaml --out DIR``: parameter sweeps on a Dask cluster.

A SPEC (YAML) names the cases; each case is one offline run (the same path and the same JSON
summary as ``umbrella-sim simulate --json``), executed as a Dask task: on a local cluster with
one worker process per core, or on an existing cluster (``--scheduler tcp://HOST:PORT``)
started the usual way with ``dask scheduler`` and ``dask worker``.

SPEC keys (every parameter name is the one of ``config/umbrella.yaml`` / the node)::

    params: other.yaml         # optional ROS 2 params file, default config/umbrella.yaml
    base: {name: value}        # overrides applied to every case
    grid: {name: [v1, v2]}     # cartesian product, first axis outermost (and the plots' x axis)
    cases: [{name: value}]     # explicit cases, added after the grid's
    duration: 1.0              # simulated time per case (s), the cap when stop_after_lock is set
    stop_after_lock: 0.2       # end a case this long after its lock (s)
    force: 5.0                 # constant sleeve force F_H (N), = base sleeve_force
    force_profile: f.csv       # or a CSV of t,F rows (path relative to the SPEC)

The whole SPEC is checked before any case runs (names, values, every case's parameters through
the same validation as the CLI); errors name the case and the parameter.

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
import csv
from dataclasses import dataclass, field
import hashlib
import itertools
import json
import math
import os
import signal
import socket
import sys
import time
import traceback
from typing import Any, Callable

import yaml

from .. import __version__
from ..bag.paths import check_new_output, read_text_input
from ..core.registry import NODE_PARAMETERS
from ..ros.signals import deferred

SPEC_KEYS = ("params", "base", "grid", "cases", "duration", "stop_after_lock", "force",
             "force_profile")
DEFAULT_DURATION = 1.0      # s, as `umbrella-sim simulate`
STATUS_OK, STATUS_DIVERGED, STATUS_ERROR = "ok", "diverged", "error"
#: the publication rate of a case's --mcap recording: the node's default, as simulate --mcap
MCAP_PUBLISH_RATE = NODE_PARAMETERS["publish_rate"].default
#: statuses of a case that is done: re-running the sweep skips it
FINISHED = (STATUS_OK, STATUS_DIVERGED)
PLOTS = ("deploy_time.png", "peak_stress.png", "tip_deflection.png")
CONNECT_TIMEOUT = 10.0      # s to reach a --scheduler
WORKER_TIMEOUT = 30.0       # s for a first worker to join it


class SpecError(ValueError):
    """The SPEC cannot be run; the message names the key, case and parameter."""


class OutputError(OSError):
    """DIR cannot be written; the message names the file (finished cases stay in the store)."""


@dataclass
class Case:
    index: int                  # 1-based position in the SPEC (grid first, then cases)
    overrides: dict             # what the SPEC sets for this case (base + grid/case values)
    params: dict                # every parameter, validated (UmbrellaParams.as_dict())
    duration: float
    stop_after_lock: float | None
    force_profile: list | None  # [(t, F)] read from the CSV, or None
    force_profile_path: str | None
    case_id: str = ""

    def label(self, names) -> str:
        return ", ".join(f"{n}={self.overrides[n]}" for n in names if n in self.overrides)

    def task(self, mcap_dir: str | None) -> dict:
        """Return what a worker needs (plain data, pickles anywhere)."""
        return {"case_id": self.case_id, "params": self.params, "duration": self.duration,
                "stop_after_lock": self.stop_after_lock, "force_profile": self.force_profile,
                "mcap_dir": mcap_dir}


@dataclass
class Sweep:
    path: str
    cases: list
    axes: list                  # grid parameter names, in SPEC order
    swept: list                 # every parameter name the grid or the cases set
    duplicates: list = field(default_factory=list)   # (index, index of the same case)
    text: str = ""              # the SPEC as read (copied to DIR/spec.yaml)


# ------------------------------------------------------------------ the SPEC
def _number(where: str, value: Any, low: float, low_open: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or (value <= low if low_open else value < low):
        raise SpecError(f"{where}: {value!r} must be a finite number "
                        f"{'>' if low_open else '>='} {low:g}")
    return float(value)


def case_id(params: dict, duration: float, stop_after_lock, force_profile) -> str:
    """Key of a case in the store: its full parameters, run options and package version."""
    doc = {"umbrella_sim": __version__, "params": params, "duration": duration,
           "stop_after_lock": stop_after_lock, "force_profile": force_profile}
    blob = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode("utf-8")).hexdigest()[:16]


def load_spec(path: str) -> Sweep:
    """Read and check the whole SPEC; every case's parameters validated as the CLI does."""
    from .inputs import check_lock_given, read_force_profile, resolve_params
    from ..core.forcing import command_force
    from ..core.params import UmbrellaParams
    from ..core.registry import check_types
    from ..ros.params_file import load_yaml_as_ros

    try:
        text = read_text_input(path, "sweep spec")
        doc = load_yaml_as_ros(text)        # typed as a params file is
    except ValueError as exc:       # missing, not a regular file, unreadable, not text
        raise SpecError(str(exc)) from None
    except yaml.YAMLError as exc:
        raise SpecError(f"sweep spec {path}: not valid YAML ({exc})") from None
    if not isinstance(doc, dict):
        raise SpecError(f"sweep spec {path}: expected a mapping with base/grid/cases")
    unknown = sorted(set(doc) - set(SPEC_KEYS))
    if unknown:
        raise SpecError(f"sweep spec {path}: unknown key(s) {', '.join(map(str, unknown))}; "
                        f"known: {', '.join(SPEC_KEYS)}")
    here = os.path.dirname(os.path.abspath(path))

    def rel(p):
        return p if os.path.isabs(p) else os.path.join(here, p)

    params_file = doc.get("params")
    if params_file is not None and not isinstance(params_file, str):
        raise SpecError(f"sweep spec {path}: params: expected a file name")
    base = doc.get("base") or {}
    grid = doc.get("grid") or {}
    explicit = doc.get("cases") or []
    if not isinstance(base, dict):
        raise SpecError(f"sweep spec {path}: base: expected a mapping of parameter overrides")
    if not isinstance(grid, dict):
        raise SpecError(f"sweep spec {path}: grid: expected a mapping name -> list of values")
    for name, values in grid.items():
        if not isinstance(values, list) or not values:
            raise SpecError(f"sweep spec {path}: grid: {name}: "
                            "expected a non-empty list of values")
    if not isinstance(explicit, list) or not all(isinstance(c, dict) for c in explicit):
        raise SpecError(f"sweep spec {path}: cases: expected a list of mappings of overrides")
    if not grid and not explicit:
        raise SpecError(f"sweep spec {path}: no cases: give grid and/or cases")
    duration = _number(f"sweep spec {path}: duration", doc.get("duration", DEFAULT_DURATION),
                       0.0, True)
    stop_after_lock = doc.get("stop_after_lock")
    if stop_after_lock is not None:
        stop_after_lock = _number(f"sweep spec {path}: stop_after_lock", stop_after_lock, 0.0,
                                  False)
    base = dict(base)
    if doc.get("force") is not None:
        if doc.get("force_profile") is not None:
            raise SpecError(f"sweep spec {path}: give force or force_profile, not both")
        # force is every case's sleeve_force: no part of the SPEC may set its own
        for where, c in (("base", base), ("grid", grid), *(("cases", c) for c in explicit)):
            if "sleeve_force" in c:
                raise SpecError(f"sweep spec {path}: force and {where}: sleeve_force both set "
                                "(force is every case's sleeve_force; sweep sleeve_force "
                                "without it)")
        if isinstance(doc["force"], bool) or not isinstance(doc["force"], (int, float)):
            raise SpecError(f"sweep spec {path}: force: {doc['force']!r} is not a number")
        base["sleeve_force"] = doc["force"]     # its range is checked with each case's model
    profile = profile_path = None
    if doc.get("force_profile") is not None:
        if not isinstance(doc["force_profile"], str):
            raise SpecError(f"sweep spec {path}: force_profile: expected a CSV file name")
        profile_path = rel(doc["force_profile"])
        try:
            profile = [list(row) for row in read_force_profile(profile_path)]
        except ValueError as exc:
            raise SpecError(f"sweep spec {path}: force_profile: {exc}") from None
    if params_file is not None:
        params_file = rel(params_file)

    axes = list(grid)
    overrides_list = [dict(base, **dict(zip(axes, combo)))
                      for combo in itertools.product(*grid.values())] if grid else []
    overrides_list += [dict(base, **c) for c in explicit]
    swept = list(axes)
    for c in explicit:
        swept += [n for n in c if n not in swept]
    sweep = Sweep(path=os.path.abspath(path), cases=[], axes=axes, swept=swept, text=text)
    seen: dict[str, int] = {}
    for index, overrides in enumerate(overrides_list, start=1):
        source = "grid" if index <= len(overrides_list) - len(explicit) else "cases"
        try:
            check_types(overrides)          # typed YAML, as a params file (the node's rule)
            resolved = resolve_params(overrides, params_file)
            check_lock_given(resolved, f"lock={overrides['lock']}" if "lock" in overrides
                             else None)
            params = resolved.as_dict()
        except ValueError as exc:
            shown = ", ".join(f"{k}={v!r}" for k, v in overrides.items() if k not in base
                              or source == "cases")
            raise SpecError(f"sweep spec {path}: case {index} ({source}: {shown}): "
                            f"{exc}") from None
        for t, f in profile or []:
            try:
                command_force(f, UmbrellaParams(**params))
            except ValueError as exc:
                raise SpecError(f"sweep spec {path}: case {index}: force_profile at t = {t:g} s: "
                                f"{exc}") from None
        case = Case(index=index, overrides=overrides, params=params, duration=duration,
                    stop_after_lock=stop_after_lock, force_profile=profile,
                    force_profile_path=profile_path)
        case.case_id = case_id(params, duration, stop_after_lock, profile)
        if case.case_id in seen:
            sweep.duplicates.append((index, seen[case.case_id]))
            continue
        seen[case.case_id] = index
        sweep.cases.append(case)
    return sweep


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
    Run one case offline, as ``umbrella-sim simulate`` does.

    Never raises: an exception becomes the case's error so the other cases go on.
    """
    from ..core.params import UmbrellaParams

    out = {"case_id": task["case_id"], "worker": f"{socket.gethostname()}:{os.getpid()}",
           "umbrella_sim": __version__, "summary": {}, "error": None, "mcap": None,
           "started_at": time.time()}      # the worker's clock (gaps between its cases)
    t0 = time.perf_counter()
    try:
        params = UmbrellaParams.from_mapping(task["params"]).validated()
        profile = [tuple(row) for row in task["force_profile"]] if task["force_profile"] else None
        if task["mcap_dir"]:
            from ..ros.recording import record_offline

            bag = os.path.join(task["mcap_dir"], task["case_id"])
            if os.path.exists(bag):     # left by an unfinished earlier attempt of this case
                import shutil
                shutil.rmtree(bag)
            result = record_offline(params, bag, _mcap_duration(task), profile,
                                    publish_rate=MCAP_PUBLISH_RATE)
            out["mcap"] = bag
            if result.recording_error:      # not finished: a resumed sweep runs it again
                out["summary"] = result.summary()
                out["error"] = f"recording {bag}: {result.recording_error}"
                out["status"] = STATUS_ERROR
                return _finished(out, t0)
        else:
            from ..core.driver import simulate

            result = simulate(params, task["duration"], force_profile=profile,
                              stop_after_lock=task["stop_after_lock"], keep_samples=False)
        out["summary"] = result.summary()
        out["error"] = result.error
        out["status"] = STATUS_DIVERGED if result.error else STATUS_OK
    except Exception as exc:  # noqa: BLE001 - the case's row carries it
        tb = traceback.format_exc(limit=-3).strip().splitlines()
        out["error"] = f"{type(exc).__name__}: {exc} [{' | '.join(tb[-3:-1])}]"
        out["status"] = STATUS_ERROR
    return _finished(out, t0)


def _finished(out: dict, t0: float) -> dict:
    out["case_wall_time"] = time.perf_counter() - t0
    out["finished_at"] = time.time()
    return out


def _mcap_duration(task: dict) -> float:
    """
    Return the recording length: the duration, or up to stop_after_lock past the lock.

    The lock is found first by the plain run, which costs a fraction of the recording.  A
    plain run that failed stopped at its fault, not at the end: the recording then takes
    the whole duration, so that it meets the same fault and the case reports it.
    """
    if task["stop_after_lock"] is None:
        return task["duration"]
    from ..core.driver import simulate
    from ..core.params import UmbrellaParams

    params = UmbrellaParams.from_mapping(task["params"]).validated()
    profile = [tuple(row) for row in task["force_profile"]] if task["force_profile"] else None
    probe = simulate(params, task["duration"], force_profile=profile,
                     stop_after_lock=task["stop_after_lock"], keep_samples=False)
    if probe.error is not None:
        return task["duration"]
    return min(task["duration"], probe.figures["final_time"])


# ------------------------------------------------------------------ the store
class CaseStore:
    """DIR/cases/<case_id>.json: one file per case result, each written atomically."""

    def __init__(self, out_dir: str):
        self.dir = os.path.join(out_dir, "cases")     # made by the first save

    def path(self, cid: str) -> str:
        return os.path.join(self.dir, cid + ".json")

    def load(self, cid: str) -> dict | None:
        try:
            with open(self.path(cid), encoding="utf-8") as fh:
                return json.load(fh)
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return None             # unreadable: the case runs again

    def save(self, record: dict) -> None:
        tmp = self.path(record["case_id"]) + f".{os.getpid()}.tmp"
        try:
            os.makedirs(self.dir, exist_ok=True)
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(record, fh, indent=1, default=_jsonable)     # summary keys in order
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path(record["case_id"]))
        except OSError as exc:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise OutputError(exc.errno, f"{self.path(record['case_id'])}: "
                                         f"{exc.strerror}") from None


def _jsonable(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    return str(value)


def is_finished(record: dict | None, mcap: bool) -> bool:
    if record is None or record.get("status") not in FINISHED:
        return False
    return not mcap or bool(record.get("mcap")) and os.path.isdir(record["mcap"])


def make_record(case: Case, result: dict) -> dict:
    return dict(result, case=case.index, overrides=case.overrides, params=case.params,
                duration=case.duration, stop_after_lock=case.stop_after_lock,
                force_profile=case.force_profile_path)


# ------------------------------------------------------------------ results table
def table_rows(sweep: Sweep, store: CaseStore) -> tuple[list[str], list[dict]]:
    """One row per case of the SPEC that has a result: case, status, parameters, summary."""
    rows, summary_keys = [], []
    for case in sweep.cases:
        rec = store.load(case.case_id)
        if rec is None:
            continue
        row = {"case": case.index, "case_id": case.case_id, "status": rec.get("status"),
               "error": rec.get("error")}
        row.update({name: case.params.get(name, case.overrides.get(name)) for name in sweep.swept})
        row.update(case.params)
        row.update(duration=case.duration, stop_after_lock=case.stop_after_lock,
                   force_profile=case.force_profile_path)
        used = row["_same"] = set()     # summary keys that repeat their parameter's value
        for key, value in (rec.get("summary") or {}).items():
            if key == "error":
                continue
            if key in case.params:      # the parameter's column, unless the run took another
                if value == case.params[key]:     # (a rigid model's lock is plastic)
                    used.add(key)
                    continue
                key = f"{key}_used"
            if key not in summary_keys:
                summary_keys.append(key)
            row[key] = value
        row.update(worker=rec.get("worker"), mcap=rec.get("mcap"))
        rows.append(row)
    for key in [k for k in summary_keys if k.endswith("_used")]:   # in every row, then:
        for row in rows:        # the value the run took (none for a run that has no summary)
            name = key[:-len("_used")]
            row.setdefault(key, row.get(name) if name in row["_same"] else None)
    for row in rows:
        del row["_same"]
    columns = ["case", "case_id", "status"] + list(sweep.swept)
    columns += [n for n in (rows[0] if rows else {}) if n not in columns and n not in
                ("error", "worker", "mcap") and n not in summary_keys]
    columns += summary_keys + ["error", "worker", "mcap"]
    return columns, rows


def _cell(value):
    if isinstance(value, (list, dict, tuple)):
        return json.dumps(value)
    return value


def write_csv(path: str, columns: list[str], rows: list[dict]) -> None:
    tmp = path + ".tmp"
    try:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(columns)
            for row in rows:
                w.writerow(["" if row.get(c) is None else _cell(row.get(c)) for c in columns])
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
    tmp = path + ".tmp"
    pq.write_table(pa.table(arrays), tmp)
    os.replace(tmp, path)


# ------------------------------------------------------------------ plots
def _series(sweep: Sweep, rows: list[dict]):
    """Group the rows: x = the first grid axis, a series per combination of the others."""
    x_name = sweep.axes[0] if sweep.axes else "case"
    others = [n for n in sweep.swept if n != x_name]
    groups: dict[tuple, list[dict]] = {}
    for row in rows:
        if row.get("status") not in FINISHED:
            continue
        groups.setdefault(tuple(row.get(n) for n in others), []).append(row)

    def label(key):
        parts = []
        closed_form = dict(zip(others, key)).get("model") == "rigid"
        for name, value in zip(others, key):
            if name == "model":
                parts.insert(0, str(value))
            elif name == "elements_per_segment":
                if not closed_form:             # the closed-form rigid model has no mesh
                    parts.append(f"N = {value}")
            else:
                parts.append(f"{name} = {value}")
        return ", ".join(parts) or "all cases"

    return x_name, [(label(k), sorted(g, key=lambda r: _sort_key(r.get(x_name))))
                    for k, g in groups.items()]


def _sort_key(v):
    return (0, v, "") if isinstance(v, (int, float)) else (1, 0, str(v))


def _reference_series(series):
    """
    Return the series the deployment-time difference is taken to.

    The rigid model's if swept (Table 6.1's "time prolonged"), else the first.
    """
    for label, g in series:
        if g and all(r.get("model") == "rigid" for r in g):
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
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..core.registry import REGISTRY

    x_name, series = _series(sweep, rows)
    if not series:
        return []
    xs_all = sorted({r.get(x_name) for _, g in series for r in g}, key=_sort_key)
    numeric = all(isinstance(x, (int, float)) for x in xs_all)
    pos = {x: (x if numeric else i) for i, x in enumerate(xs_all)}
    unit = REGISTRY[x_name].unit if x_name in REGISTRY else "-"
    xlabel = x_name if unit == "-" else f"{x_name} ({unit})"
    colours = {label: f"C{i % 10}" for i, (label, _) in enumerate(series)}
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
                                       gridspec_kw={"height_ratios": [3, 2]})
    else:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        ax_d = None
    ref_label, ref_rows = _reference_series(series)
    ref = {r.get(x_name): r["deploy_time"] for r in ref_rows
           if isinstance(r.get("deploy_time"), (int, float))}
    for label, g in series:
        pts = points(g, "deploy_time", 1.0)
        if pts:
            ax.plot(*zip(*pts), "o-", color=colours[label], label=label)
        diff = [(pos[r.get(x_name)], (r["deploy_time"] - ref[r.get(x_name)]) * 1e3) for r in g
                if isinstance(r.get("deploy_time"), (int, float)) and r.get(x_name) in ref]
        if diff and label != ref_label and ax_d is not None:
            ax_d.plot(*zip(*diff), "o-", color=colours[label], label=label)
    for i, (label, values) in enumerate((reference or {}).items()):
        pts = sorted((pos[x], t) for x, t in values.items() if x in pos and t is not None)
        style = {"marker": "Dx+^v"[i % 5], "ms": 9, "ls": "none", "color": "k", "mfc": "none",
                 "label": label}
        if pts:
            ax.plot(*zip(*pts), **style)
            diff = [(pos[x], (t - ref[x]) * 1e3) for x, t in values.items()
                    if x in ref and x in pos and t is not None]
            if diff and ax_d is not None:
                ax_d.plot(*zip(*sorted(diff)), **style)
    ax.set_ylabel("deployment time (s)")
    if ax_d is not None:
        ax_d.set_ylabel(f"minus {ref_label} (ms)")
        ax_d.axhline(0.0, color="k", lw=0.8)
    finish(fig, [a for a in (ax, ax_d) if a is not None], "deploy_time.png",
           f"deployment time vs {x_name} (thesis Table 6.1)")

    def elastic(keys):
        """Series with elastic deformation: rigid models (zero up to round-off) left out."""
        top = max([abs(r[k]) for _, g in series for r in g for k in keys
                   if isinstance(r.get(k), (int, float))] or [0.0])
        return [(label, g) for label, g in series
                if any(abs(r[k]) > 1e-6 * top for r in g for k in keys
                       if isinstance(r.get(k), (int, float)))]

    # peak stresses with the yield line
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, g in elastic(["peak_stress_leaf", "peak_stress_link"]):
        for key, style, body in (("peak_stress_leaf", "o-", "leaf"),
                                 ("peak_stress_link", "s--", "link")):
            pts = points(g, key, 1e-6)
            if pts:
                ax.plot(*zip(*pts), style, color=colours[label], label=f"{label}: {body}")
    for y in sorted({r["yield_strength"] for _, g in series for r in g
                     if isinstance(r.get("yield_strength"), (int, float))}):
        ax.axhline(y * 1e-6, color="r", lw=1.2, ls="-.", label=f"yield strength {y * 1e-6:g} MPa")
    ax.set_ylabel("peak |stress| (MPa)")
    finish(fig, [ax], "peak_stress.png", f"peak stress vs {x_name}")

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, g in elastic(["tip_deflection_max"]):
        pts = points(g, "tip_deflection_max", 1e3)
        if pts:
            ax.plot(*zip(*pts), "o-", color=colours[label], label=label)
    ax.set_ylabel("stage-1 max transverse deflection of G (mm)")
    finish(fig, [ax], "tip_deflection.png", f"stage-1 max tip deflection vs {x_name}")
    return written


# ------------------------------------------------------------------ progress
class SweepProgress:
    """
    Progress of a sweep in one line: bar, done/total, failures, elapsed and ETA.

    The line is rewritten on a terminal; otherwise one line per finished case.
    """

    def __init__(self, total: int, stream=None):
        self.total, self.done, self.failed = total, 0, 0
        self.stream = stream or sys.stderr     # (at call time: a redirected stderr)
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.t0 = time.monotonic()

    @staticmethod
    def _hms(s: float) -> str:
        s = int(round(s))
        return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"

    def update(self, failed: bool, what: str = "") -> None:
        self.done += 1
        self.failed += bool(failed)
        elapsed = time.monotonic() - self.t0
        eta = elapsed / self.done * (self.total - self.done)
        frac = self.done / self.total
        line = (f"[{'#' * int(25 * frac):<25}] {self.done}/{self.total} cases"
                f"{f', {self.failed} failed' if self.failed else ''}  elapsed "
                f"{self._hms(elapsed)}  ETA {self._hms(eta)}")
        if self.tty:
            self.stream.write("\r" + line)
        else:
            self.stream.write(line + (f"  ({what})" if what else "") + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty and self.done:
            self.stream.write("\n")
            self.stream.flush()


# ------------------------------------------------------------------ running
@dataclass
class SweepReport:
    total: int
    skipped: int
    ran: int = 0
    failed: int = 0             # rows of the table whose status is not ok
    interrupted: bool = False
    csv: str = ""
    parquet: str = ""
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
    scheme, sep, rest = address.rpartition("://")
    host, colon, port = rest.rpartition(":")
    if (sep and scheme not in ("tcp", "tls")) or not colon or not host.strip("[]") \
            or not port.isdigit() or not 0 < int(port) < 65536:
        raise SpecError(f"--scheduler {address!r}: not a scheduler address: expected "
                        "tcp://HOST:PORT (as `dask scheduler` prints it)")
    return address


def _client(workers: int | None, scheduler: str | None, log: Callable[[str], None]):
    import logging

    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise SpecError(f"umbrella-sim sweep needs dask and distributed ({exc}); "
                        "install requirements.txt") from None

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, ValueError) as exc:
            raise SpecError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        return client, None
    n = workers or os.cpu_count() or 1
    # loopback only, every port (scheduler, its HTTP server, workers) picked free by the OS
    from distributed.deploy.spec import SpecCluster

    before = set(SpecCluster._instances)
    try:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               host="127.0.0.1", scheduler_port=0,
                               dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
    except KeyboardInterrupt:
        _drop_unstarted_clusters(set(SpecCluster._instances) - before)
        raise
    log(f"local Dask cluster: {n} worker process{'es' if n > 1 else ''} at "
        f"{cluster.scheduler_address}")
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
            raise SpecError(f"--scheduler {scheduler}: no worker joined within "
                            f"{WORKER_TIMEOUT:g} s") from None
    try:
        versions = client.run(worker_version)
    except Exception as exc:  # noqa: BLE001 - e.g. ModuleNotFoundError on a worker
        raise SpecError(f"workers cannot run umbrella_sim: {type(exc).__name__}: {exc}") from None
    wrong = {w: v for w, v in versions.items() if v != __version__}
    if wrong:
        raise SpecError(f"workers run other umbrella_sim versions than {__version__}: {wrong}")
    if scheduler:
        log(f"Dask cluster {scheduler}: {len(versions)} worker(s)")
    else:
        client.run(_ignore_sigint)


def _mcap_step_cases(sweep: Sweep, log) -> None:
    """
    Give --mcap cases whose recording shortens the step a case id of their own, and say so.

    A recording's physics step divides its publication period (as the node's), so at a
    time_step that does not divide it the recorded run is another computation than the
    plain one: it must not take (or replace) the plain case's result.
    """
    from ..core.params import shortened_step_note, UmbrellaParams

    rate = MCAP_PUBLISH_RATE
    for case in sweep.cases:
        step = UmbrellaParams.from_mapping(case.params).physics_time_step
        note = shortened_step_note(step, rate)
        if note:
            case.case_id = case_id(dict(case.params, mcap_publish_rate=rate), case.duration,
                                   case.stop_after_lock, case.force_profile)
            log(f"case {case.index}: the --mcap recording takes a {note}")


def run_sweep(sweep: Sweep, out_dir: str, workers: int | None = None,
              scheduler: str | None = None, mcap: bool = False,
              stream=None) -> SweepReport:
    """
    Run the cases not yet in DIR's store, writing each result as it arrives.

    Then write the table and the plots (also after Ctrl-C, from the finished cases).
    """
    stream = stream or sys.stderr

    def log(msg):
        stream.write(msg + "\n")
        stream.flush()

    store = CaseStore(out_dir)
    mcap_dir = os.path.join(os.path.abspath(out_dir), "mcap") if mcap else None
    if mcap:
        _mcap_step_cases(sweep, log)
    todo = [c for c in sweep.cases if not is_finished(store.load(c.case_id), mcap)]
    report = SweepReport(total=len(sweep.cases), skipped=len(sweep.cases) - len(todo))
    for index, same in sweep.duplicates:
        log(f"case {index} has the same parameters as case {same}: run once")
    if report.skipped:
        log(f"{report.skipped} of {report.total} cases already in {out_dir}: skipped")
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
            from distributed import as_completed

            t1 = time.perf_counter()
            report.setup_s = t1 - t0
            by_key = {}
            for case in todo:
                fut = client.submit(run_case, case.task(mcap_dir), pure=False,
                                    key=f"umbrella-case-{case.case_id}-{os.getpid()}")
                by_key[fut.key] = case
                futures.append(fut)
            progress = SweepProgress(len(todo), stream)
            try:
                for fut in as_completed(futures):
                    case = by_key[fut.key]
                    try:
                        result = fut.result()
                    except Exception as exc:  # noqa: BLE001 - lost workers, cancelled tasks
                        result = {"case_id": case.case_id, "status": STATUS_ERROR,
                                  "error": f"{type(exc).__name__}: {exc}", "summary": {},
                                  "worker": None, "mcap": None}
                    store.save(make_record(case, result))
                    report.ran += 1
                    report.run_s = time.perf_counter() - t1
                    report.compute_s += result.get("case_wall_time") or 0.0
                    failed = result["status"] != STATUS_OK
                    progress.update(failed, f"case {case.index}: {case.label(sweep.swept)}"
                                    + (f": {result['status']}" if failed else ""))
                    fut.release()
            finally:
                progress.close()
            log(f"{report.ran} case(s) in {report.run_s:.1f} s "
                f"({report.ran / max(report.run_s, 1e-9):.2f} cases/s, "
                f"{report.compute_s:.1f} s of computing; cluster ready in "
                f"{report.setup_s:.1f} s)")
    except KeyboardInterrupt:
        report.interrupted = True
        if made_dir:
            log(f"interrupted: {report.ran} case(s) of {len(todo)} finished in this run are "
                f"kept in {out_dir}; run the same command again to finish the rest")
        else:
            log(f"interrupted before any case ran; {out_dir} left as it was")
    except OutputError as exc:      # DIR cannot take results: stop, keep what the store has
        write_error = exc
        log(f"cannot write the results: {exc.strerror}; stopping the sweep")
    finally:
        if client is not None:
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
        raise write_error
    return report


def _prepare_dir(sweep, store, out_dir, mcap_dir) -> None:
    try:
        os.makedirs(store.dir, exist_ok=True)
        if mcap_dir:
            os.makedirs(mcap_dir, exist_ok=True)
        with open(os.path.join(out_dir, "spec.yaml"), "w", encoding="utf-8") as fh:
            fh.write(sweep.text)
    except OSError as exc:
        raise OutputError(exc.errno, f"{exc.filename}: {exc.strerror}") from None


def _write_outputs(sweep, store, out_dir, report, log) -> None:
    columns, rows = table_rows(sweep, store)
    report.csv = os.path.join(out_dir, "results.csv")
    report.parquet = os.path.join(out_dir, "results.parquet")
    path = report.csv
    try:
        with deferred():        # a stop signal while the table is written: after it
            write_csv(report.csv, columns, rows)
            path = report.parquet
            try:
                write_parquet(report.parquet, columns, rows)
            except ImportError:
                report.parquet = ""
                log("results.parquet not written: pyarrow is not installed")
            ok = sum(r["status"] == STATUS_OK for r in rows)
            report.failed = len(rows) - ok
            log(f"{len(rows)} of {len(sweep.cases)} cases in {report.csv}: {ok} ok"
                + (f", {report.failed} failed (see the error column)" if report.failed
                   else ""))
        path = out_dir
        report.plots = plot(sweep, rows, out_dir)
    except OSError as exc:
        raise OutputError(exc.errno, f"{path}: {exc.strerror}") from None


# ------------------------------------------------------------------ command line
def check_out_dir(path: str) -> None:
    """Refuse a results directory that cannot be used (a new one, or one to resume into)."""
    if not os.path.lexists(path):
        try:
            check_new_output(path, "--out")
        except ValueError as exc:
            raise SpecError(str(exc)) from None
        return
    if not os.path.isdir(path):
        raise SpecError(f"--out {path}: exists and is not a directory")
    if not os.access(path, os.W_OK | os.X_OK):
        raise SpecError(f"--out {path}: directory is not writable")
    cases = os.path.join(path, "cases")
    if os.path.lexists(cases) and not os.path.isdir(cases):
        raise SpecError(f"--out {path}: {cases} exists and is not a directory")


def add_parser(sub) -> argparse.ArgumentParser:
    sp = sub.add_parser("sweep", help="run a parameter sweep on Dask",
                        description="Run every case of SPEC.yaml (base / grid / cases, see "
                                    "docs/sweeps.md) offline, in parallel on Dask; write "
                                    "DIR/results.csv, DIR/results.parquet and plots.")
    sp.add_argument("spec", metavar="SPEC.yaml", help="the sweep: base, grid, cases, run options")
    sp.add_argument("--out", required=True, metavar="DIR",
                    help="results directory; re-running into it skips finished cases")
    sp.add_argument("--workers", type=int, metavar="N",
                    help="local worker processes (default: one per core)")
    sp.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                    help="run on this existing Dask cluster instead of a local one")
    sp.add_argument("--mcap", action="store_true",
                    help="keep a recording per case in DIR/mcap/<case_id>/")
    return sp


def main(args, ap: argparse.ArgumentParser) -> int:
    try:
        if args.workers is not None and args.workers < 1:
            raise SpecError(f"--workers {args.workers}: must be >= 1")
        if args.workers is not None and args.scheduler:
            raise SpecError("--workers and --scheduler: the cluster's workers are its own; "
                            "give one of them")
        if args.scheduler is not None:
            check_scheduler_address(args.scheduler)
        check_out_dir(args.out)
        sweep = load_spec(args.spec)
    except SpecError as exc:
        ap.exit(2, f"{ap.prog}: error: {exc}\n")

    def stop(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        report = run_sweep(sweep, args.out, workers=args.workers, scheduler=args.scheduler,
                           mcap=args.mcap)
    except SpecError as exc:
        ap.exit(2, f"{ap.prog}: error: {exc}\n")
    except OutputError as exc:
        ap.exit(4, f"{ap.prog}: error: cannot write the results: {exc.strerror}; every case "
                   f"finished before it is kept in {os.path.join(args.out, 'cases')}\n")
    except KeyboardInterrupt:       # a second stop, while the table or the plots were made
        print(f"{ap.prog}: interrupted; every finished case is kept in "
              f"{os.path.join(args.out, 'cases')} (and in results.csv if it was written: "
              "it is written whole); run the same command again to finish",
              file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    if report.interrupted:
        return 130
    return 3 if report.failed else 0
