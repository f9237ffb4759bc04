"""
umbrella_compare A B [...] --out DIR: compare recorded runs (live or offline).

Aligns the runs on the first run's publication times (linear interpolation), prints a table
and writes compare.json with: deployment time and its difference to the first run, max and
RMS difference of alpha1, its rate, the tip deflection and the peak stresses, the energy
drift of each run; writes PNG plots mirroring the thesis's figures (alpha1 and its rate and
acceleration, tip deflection in stage 1 and across the lock, stress at O'' on the leaf and at
mid-link, deformed shapes).  --thesis adds the thesis's quoted numbers.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
import json
import math
import os
import sys

import numpy as np

from .arguments import ArgumentParser
from ..bag.reader import LogError, read_log
from ..core.summary import deploy_start_of, relative_drift, stage2_figures, validity_warnings
from ..ros.messages import (energy_figures, joint_state_figures, peak_stress_figures,
                            tip_deflection_figures)
from ..ros.signals import EXIT_READER_GONE, interruptible, print_for_reader, raise_if_stopped

#: the figures compared between runs (outputs.SummaryAccumulator names)
FIGURE_KEYS = ("deploy_time", "deploy_start", "lock_time", "tip_deflection_max",
               "tip_deflection_max_time", "stage2_tip_amplitude", "stage2_tip_period",
               "stage2_window",
               "peak_stress_leaf", "peak_stress_leaf_x", "peak_stress_leaf_time",
               "peak_stress_link", "peak_stress_link_x", "peak_stress_link_time",
               "stress_ratio_max", "tip_deflection_ratio_max")
RIGID_MODELS = ("rigid", "rigid-fe")
#: the shapes plot draws the largest elastic displacement of a stage at most this fraction
#: of the leaf length l1 + l2: --magnification is reduced to it (the legend says by how much)
SHAPE_DISPLACEMENT_LIMIT = 0.2

#: Table 6.1 (deformable FEA, rigid FEA) and the V0 = -0.2 figures quoted in ch. 6
THESIS_TABLE_6_1 = {-0.5: (0.09040, 0.09033), -1.0: (0.04525, 0.04517), -2.0: (0.02343, 0.02259)}
THESIS_V02 = {"deploy_time": 0.2259, "tip_deflection_max": 0.665e-3,
              "tip_deflection_max_time": 0.08, "stage2_tip_amplitude": 0.060,
              "stage2_tip_period": 0.05}


@dataclass
class Run:
    label: str
    path: str
    params: dict
    t: np.ndarray
    alpha1: np.ndarray
    alpha1_rate: np.ndarray
    tip_t: np.ndarray
    tip_v: np.ndarray
    stress_t: np.ndarray
    peak_leaf: np.ndarray
    peak_link: np.ndarray
    stress_joint: np.ndarray
    stress_mid: np.ndarray
    lock_time: float | None        # the lock instant (sim time)
    energy_drift: float | None
    shapes: list = field(default_factory=list)      # [(t, leaf_xy, link_xy)]
    magnification: float = 1.0
    alpha2: np.ndarray | None = None
    leaf_node_x: np.ndarray | None = None
    link_node_x: np.ndarray | None = None
    summary: dict | None = None       # umbrella_sim.summary metadata: every physics step
    warnings: list | None = None
    lock_kind: str | None = None
    # every physics step of a re-run of the log (--physics-rate): replay.physics_series
    physics: dict | None = None
    # lock_time is the exact lock instant (the events record); False: the time of the
    # first publication after it (the "locked" phase message of a log without that record),
    # whose samples are already of stage 2
    lock_time_exact: bool = True
    deploy_start: float | None = 0.0     # outputs.deploy_start of the recorded run
    segment: int | None = None           # a segment before the log's last (its own record)
    ended_early: str | None = None       # the recording's write error, if it stopped on one

    @property
    def deploy_time(self) -> float | None:
        """Return the deploy time: the lock less the start of the deployment (one rule)."""
        if self.lock_time is None:
            return None
        return self.lock_time - (self.deploy_start or 0.0)

    @property
    def rigid(self) -> bool:
        """Say whether the model has no elastic field (its zero stress is not a result)."""
        return self.params.get("model") in RIGID_MODELS

    def shape(self, t: float, magnification: float):
        """
        Return the deformed shape nearest to t at another magnification.

        The elastic part is re-scaled from the recorded
        marker magnification to another one (undeformed frames from the joint angles).
        """
        tm, leaf, link = min(self.shapes, key=lambda s: abs(s[0] - t))
        if self.leaf_node_x is None or self.magnification <= 0:
            return tm, leaf, link
        a1 = np.interp(tm, self.t, self.alpha1)
        a2 = np.interp(tm, self.t, self.alpha2)
        leaf_u = np.outer(self.leaf_node_x, [math.cos(a1), math.sin(a1)])
        link_u = link[0] + np.outer(self.link_node_x, [math.cos(a2), math.sin(a2)])
        scale = magnification / self.magnification
        return tm, leaf_u + scale * (leaf - leaf_u), link_u + scale * (link - link_u)

    def figures(self) -> dict:
        """
        Return the summary figures, saying where they come from (figures_from).

        From the recording's metadata (every physics step) when the log has it, else from
        the recorded samples (older or killed recordings), which depend on the rate.
        """
        if self.summary is not None:
            out = {k: self.summary.get(k) for k in FIGURE_KEYS}
            out["figures_from"] = "every physics step (recording metadata)"
            return out
        out = {"deploy_time": self.deploy_time, "deploy_start": self.deploy_start,
               "lock_time": self.lock_time}
        lock = self.lock_time if self.lock_time is not None else math.inf
        s1 = self.tip_t <= lock if self.lock_time_exact else self.tip_t < lock
        if s1.any():
            i = int(np.argmax(np.abs(self.tip_v[s1])))
            out["tip_deflection_max"] = float(abs(self.tip_v[s1][i]))
            out["tip_deflection_max_time"] = float(self.tip_t[s1][i])
        out.update(stage2_figures(self.tip_t, self.tip_v, self.lock_time))
        for body, peaks in (("leaf", self.peak_leaf), ("link", self.peak_link)):
            i = int(np.argmax(peaks))
            out[f"peak_stress_{body}"] = float(peaks[i])
            out[f"peak_stress_{body}_time"] = float(self.stress_t[i])
        rate = self.params.get("publish_rate")
        why = (f"the summary record is of the log's last run, not of segment {self.segment}"
               if self.segment is not None else
               f"the recording ended early ({self.ended_early}) before its summary record"
               if self.ended_early else
               "the log has no summary record (an older recording, or its writer was killed)")
        out["figures_from"] = (f"recorded samples at {rate} Hz: {why}, so these figures "
                               "depend on the recording rate")
        return out

    def validity(self) -> list:
        """Return the recorded validity warnings, or the same rule applied to the samples."""
        if self.warnings is not None:
            return list(self.warnings)
        tip = float(np.abs(self.tip_v).max()) if len(self.tip_v) else 0.0
        peak = float(max(self.peak_leaf.max(), self.peak_link.max()))
        try:
            return validity_warnings(self.params, self.lock_kind, peak, tip,
                                     locked=self.lock_time is not None,
                                     energy_drift=self.energy_drift)
        except (KeyError, TypeError):
            return []


def _series(log, topic, fn, segment, width: int, stride: int = 1):
    """
    Return (t, values) of one topic of one segment.

    (t, values) of one topic of one segment, streamed: only the extracted numbers are kept
    (every stride-th message).
    """
    t, rows = [], []
    for i, (tm, m) in enumerate(log.iter_decoded(topic, segment)):
        if i % stride:
            continue
        try:
            row = fn(m)
        except (IndexError, KeyError, AttributeError, TypeError) as exc:
            raise LogError(f"{log.path}: topic {topic}: message {i} lacks the fields "
                           f"umbrella_sim writes ({exc})") from None
        t.append(tm)
        rows.append(row)
    if not t and width:
        raise LogError(f"{log.path}: topic {topic} has no messages"
                       + (f" in segment {segment.index}" if segment.index else "")
                       + log.truncation_note())
    order = np.argsort(np.array(t), kind="stable")
    return np.array(t)[order], [rows[i] for i in order]


def default_label(path: str) -> str:
    """Return a run's label: its bag directory's name, or its .mcap file's without .mcap."""
    name = os.path.basename(os.path.normpath(path)) or path
    return name[:-len(".mcap")] if name.endswith(".mcap") and len(name) > 5 else name


#: the stress figures of a Run, in the order of its fields
STRESS_FIGURES = ("peak_stress_leaf", "peak_stress_link", "stress_leaf_joint", "stress_link_mid")
#: the energy figures compare reads
ENERGY_FIGURES = ("kinetic_energy", "strain_energy", "work", "energy_balance",
                  "phase_correction_energy")


def _figures(figures: dict, *names: str) -> tuple:
    return tuple(figures[n] for n in names)


def load_run(path: str, label: str | None = None, segment: int = 0) -> Run:
    log = read_log(path)
    seg = log.segment(segment)
    params = seg.params
    t, js = _series(log, log.find_topic("joint_states"),
                    lambda m: _figures(joint_state_figures(m), "alpha1", "alpha1_rate",
                                       "alpha2"), seg, 3)
    tt, tip = _series(log, log.find_topic("tip_deflection"),
                      lambda m: tip_deflection_figures(m)["tip_transverse"], seg, 1)
    ts, st = _series(log, log.find_topic("peak_stress"),
                     lambda m: _figures(peak_stress_figures(m), *STRESS_FIGURES), seg,
                     len(STRESS_FIGURES))
    st = np.array(st)
    # umbrella_sim.events.K: segment K ended by a reset; umbrella_sim.events: the last one
    last = len(log.segments()) - 1
    events = log.metadata.get("umbrella_sim.events" if segment == last
                              else f"umbrella_sim.events.{segment}", {})
    deploy, exact = None, True
    if events.get("locked") == "true":
        deploy = float(events["lock_time"])
    else:
        phase = log.find_topic("deployment_phase", required=False)
        locked = [tm for tm, m in log.iter_decoded(phase, seg) if m.data == "locked"] \
            if phase else []
        deploy, exact = (min(locked), False) if locked else (None, True)
    drift = None
    energy = log.find_topic("energy", required=False)
    if energy:
        # (the phase correction's term is 0 where the recording does not have it)
        _, e = _series(log, energy, lambda m: _figures(
            {"phase_correction_energy": 0.0, **energy_figures(m)}, *ENERGY_FIGURES), seg, 0)
        e = dict(zip(ENERGY_FIGURES, np.array(e).reshape(-1, len(ENERGY_FIGURES)).T))
        if len(e["work"]):
            mechanical = (e["kinetic_energy"] + e["strain_energy"]
                          + e["phase_correction_energy"])
            drift = relative_drift(e["energy_balance"], mechanical, e["work"])
    shapes = []
    markers = log.find_topic("markers", required=False)
    if markers:           # at most ~2000 shapes kept, whatever the log's length
        stride = max(1, log.count(markers) // 2000)

        def shape(m):
            return [np.array([[p.x, p.y] for p in mk.points]) for mk in m.markers[:2]]
        tm_all, pts_all = _series(log, markers, shape, seg, 0, stride)
        shapes = [(tm, pts[0], pts[1]) for tm, pts in zip(tm_all, pts_all) if len(pts) == 2]
    if label is None:
        label = default_label(path)
    a = np.array(js)
    mesh = log.metadata.get("umbrella_sim.mesh", {})       # the first segment's
    leaf_x = np.array(json.loads(mesh["leaf_node_x"])) if "leaf_node_x" in mesh else None
    link_x = np.array(json.loads(mesh["link_node_x"])) if "link_node_x" in mesh else None
    if segment and leaf_x is not None:      # a later segment: its own mesh (a reset may change N)
        leaf_x, link_x = _segment_mesh(log, params)
    summary = warnings = None
    record = log.metadata.get("umbrella_sim.summary") if segment == last else None
    if record and "figures" in record:
        try:
            summary = json.loads(record["figures"])
            warnings = json.loads(record.get("warnings", "[]"))
        except ValueError:
            raise LogError(f"{log.path}: metadata umbrella_sim.summary is not valid JSON") \
                from None
    applied_topic = log.find_topic("sleeve_force/applied", required=False)
    applied = ([(tm, m.data) for tm, m in log.iter_decoded(applied_topic, seg)]
               if applied_topic else [])
    start = deploy_start_of(params, applied)
    return Run(label, log.path, params, t, a[:, 0], a[:, 1], tt, np.array(tip), ts,
               *st.T, deploy, drift, shapes,
               float(params.get("marker_magnification", 1.0)), a[:, 2], leaf_x, link_x,
               summary, warnings, events.get("lock_kind"), lock_time_exact=exact,
               deploy_start=start, segment=segment if segment != last else None,
               ended_early=log.ended_early or None)


def _segment_mesh(log, params: dict):
    """Return the leaf's and the link's node positions of a segment's own parameters."""
    from ..core.model import UmbrellaModel
    from ..core.params import recorded_params

    try:
        model = UmbrellaModel(recorded_params(params))
    except ValueError as exc:
        raise LogError(f"{log.path}: a segment's parameters cannot be used ({exc})") from None
    return np.array(model.leaf.node_x), np.array(model.link.node_x)


def physics_run(path: str, segment: int = 0) -> dict:
    """Return the signals of one log's segment at every physics step (a re-run of it)."""
    from .replay import physics_series

    log = read_log(path)
    return physics_series(log, log.segment(segment))


def _spacing(t) -> float:
    return float(np.median(np.diff(t))) if len(t) > 1 else math.inf


def _on_grid(t, y, grid, peak_hold: bool):
    """
    Return series (t, y) on the instants grid, a coarser one.

    A value (linear interpolation), or for a peak-hold the largest of y over each grid
    period (grid[k-1], grid[k]], as the coarser run's own peak-hold holds.
    """
    if not peak_hold:
        return np.interp(grid, t, y)
    tol = 1e-9                      # stamps are exact to the recording's 1 ns
    period = grid[1] - grid[0] if len(grid) > 1 else 0.0     # (the first: one period too)
    hi = np.searchsorted(t, grid + tol, side="right")
    lo = np.searchsorted(t, np.concatenate(([grid[0] - period], grid[:-1])) + tol,
                         side="right")
    out = np.interp(grid, t, y)     # (a period with no sample of the finer run)
    for k in np.nonzero(hi > lo)[0]:
        out[k] = y[lo[k]:hi[k]].max()
    return out


def _diff(ref_t, ref_y, t, y, peak_hold: bool = False):
    """
    Return (max, rms) of y - ref_y over the span both runs cover.

    On the instants of the coarser run (its publications), the other one brought to them,
    so that runs recorded at two rates compare as they would at the coarser one, whichever
    is the reference: a value interpolated at them (the finer run's samples include them
    when one rate is a multiple of the other), a peak-hold re-held over their periods.
    """
    lo, hi = max(ref_t[0], t[0]), min(ref_t[-1], t[-1])
    if _spacing(t) > _spacing(ref_t) * (1 + 1e-6):      # the other run is the coarser
        ref_t, ref_y, t, y, sign = t, y, ref_t, ref_y, -1.0
    else:
        sign = 1.0
    keep = (ref_t >= lo - 1e-9) & (ref_t <= hi + 1e-9)
    if keep.sum() < 2:
        raise LogError("runs do not overlap in time")
    d = sign * (_on_grid(t, y, ref_t[keep], peak_hold) - ref_y[keep])
    return float(np.abs(d).max()), float(np.sqrt(np.mean(d * d)))


#: (name, unit, (t, y) of a run, y is a peak-hold over each publication period)
SIGNALS = [("alpha1", "rad", lambda r: (r.t, r.alpha1), False),
           ("alpha1_rate", "rad/s", lambda r: (r.t, r.alpha1_rate), False),
           ("tip_deflection", "m", lambda r: (r.tip_t, r.tip_v), False),
           ("peak_stress_leaf", "Pa", lambda r: (r.stress_t, r.peak_leaf), True),
           ("peak_stress_link", "Pa", lambda r: (r.stress_t, r.peak_link), True)]


def compare(runs: list[Run], thesis: bool = False) -> dict:
    ref = runs[0]
    out = {"reference": ref.label, "runs": []}
    for r in runs:
        entry = {"label": r.label, "path": r.path, "model": r.params.get("model"),
                 "elements_per_segment": r.params.get("elements_per_segment"),
                 "v0": r.params.get("v0"), "deploy_time": r.deploy_time,
                 "deploy_start": r.deploy_start, "lock_time": r.lock_time,
                 "deploy_time_difference": (None if r.deploy_time is None or ref.deploy_time
                                            is None else r.deploy_time - ref.deploy_time),
                 "energy_drift": r.energy_drift, "differences": {}}
        for name, unit, get, peak_hold in SIGNALS:
            rt, ry = get(ref)
            t, y = get(r)
            try:
                mx, rms = _diff(rt, ry, t, y, peak_hold)
            except LogError as exc:     # which runs, and what each holds
                raise LogError(f"{exc}: {ref.path} ({len(rt)} samples, t = {rt[0]:g} .. "
                               f"{rt[-1]:g} s) and {r.path} ({len(t)} samples, t = "
                               f"{t[0]:g} .. {t[-1]:g} s)") from None
            entry["differences"][name] = {"max": mx, "rms": rms, "unit": unit}
        entry["figures"] = r.figures()
        entry["warnings"] = r.validity()
        if thesis:
            v0 = r.params.get("v0")
            th = {}
            if v0 in THESIS_TABLE_6_1:
                th["deploy_time_deformable_fea"], th["deploy_time_rigid_fea"] = \
                    THESIS_TABLE_6_1[v0]
            if v0 == -0.2:
                th.update(THESIS_V02)
            entry["thesis"] = th
        out["runs"].append(entry)
    return out


def print_table(result: dict, stream=sys.stdout) -> None:
    w = stream.write
    w(f"reference run: {result['reference']}\n")
    w(f"{'run':<18} {'model':<9} {'N':>2} {'V0':>6} {'deploy (s)':>11} {'d deploy (s)':>13} "
      f"{'energy drift':>12}\n")
    for e in result["runs"]:
        dt = e["deploy_time"]
        dd = e["deploy_time_difference"]
        w(f"{e['label']:<18} {str(e['model']):<9} {str(e['elements_per_segment']):>2} "
          f"{e['v0']:>6g} {('%.7f' % dt) if dt is not None else '-':>11} "
          f"{('%+.3e' % dd) if dd is not None else '-':>13} "
          f"{('%.2e' % e['energy_drift']) if e['energy_drift'] is not None else '-':>12}\n")
    w(f"\n{'run':<18} " + " ".join(f"{n + ' max/rms':>27}" for n, *_ in SIGNALS) + "\n")
    for e in result["runs"]:
        cells = []
        for n, unit, *_ in SIGNALS:
            d = e["differences"][n]
            cells.append(f"{d['max']:>11.3e}/{d['rms']:.3e} {unit:<5}"[:27].rjust(27))
        w(f"{e['label']:<18} " + " ".join(cells) + "\n")
    w("\nfigures (stage-1 max tip deflection and time, stage-2 amplitude and period):\n")
    for e in result["runs"]:
        f = e["figures"]

        def fmt(key, scale=1.0, spec=".4g"):
            v = f.get(key)
            return "-" if v is None else format(v * scale, spec)
        line = (f"{e['label']:<18} deploy {fmt('deploy_time', 1, '.5f')} s, tip max "
                f"{fmt('tip_deflection_max', 1e3)} mm at "
                f"{fmt('tip_deflection_max_time', 1, '.3f')} s, "
                f"stage 2 {fmt('stage2_tip_amplitude', 1e3)} mm / "
                f"{fmt('stage2_tip_period', 1, '.4f')} s")
        w(line + "\n")
        w(f"{'':<18} peak |sigma| leaf {fmt('peak_stress_leaf', 1e-6)} MPa at "
          f"{fmt('peak_stress_leaf_time', 1, '.3f')} s, link {fmt('peak_stress_link', 1e-6)} "
          f"MPa at {fmt('peak_stress_link_time', 1, '.3f')} s; from {f.get('figures_from')}\n")
        for text in e.get("warnings", []):
            w(f"{'':<18} warning: {text}\n")
        if e.get("thesis"):
            th = e["thesis"]
            w(f"{'':<18} thesis: " + ", ".join(f"{k} {v:g}" for k, v in th.items()) + "\n")


def plot(runs: list[Run], out_dir: str, magnification=(200.0, 5.0)) -> list[str]:
    """PNG plots; magnification = (stage 1, stage 2) for the deformed shapes."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    files = []

    def save(fig, name):
        path = os.path.join(out_dir, name)
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        files.append(path)

    def finish(fig, axes, ylabels, titles, name):
        for ax, ylabel, title in zip(axes, ylabels, titles):
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
            if title:
                ax.set_title(title)
        axes[-1].set_xlabel("t (s)")
        axes[0].legend(fontsize=8)
        save(fig, name)

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for r in runs:
        t, a1, rate = ((r.physics["time"], r.physics["alpha1"], r.physics["alpha1_rate"])
                       if r.physics else (r.t, r.alpha1, r.alpha1_rate))
        axes[0].plot(t, a1, label=r.label)
        axes[1].plot(t, rate, label=r.label)
        axes[2].plot(t, np.gradient(rate, t), label=r.label)
    finish(fig, axes, ("alpha1 (rad)", "d alpha1/dt (rad/s)", "d2 alpha1/dt2 (rad/s2)"),
           ("leaf angle, rate and acceleration (thesis Fig. 6.1, 6.12-6.17)", "",
            "acceleration: the rate differenced at the recorded rate (--physics-rate: at "
            "every step)"),
           "alpha1.png")

    fig, axes = plt.subplots(2, 1, figsize=(8, 6))
    for r in runs:
        tip_t, tip_v = ((r.physics["time"], r.physics["tip_transverse"]) if r.physics
                        else (r.tip_t, r.tip_v))
        lock = r.lock_time if r.lock_time is not None else tip_t[-1]
        s1 = tip_t <= lock
        axes[0].plot(tip_t[s1], tip_v[s1] * 1e3, label=r.label)
        axes[1].plot(tip_t, tip_v * 1e3, label=r.label)
        if r.lock_time is not None:
            axes[1].axvline(r.lock_time, ls="--", lw=0.7, color="gray")
    finish(fig, axes, ("v_G (mm)", "v_G (mm)"),
           ("transverse deflection of G, stage 1 (Fig. 6.2, 6.10)", "across the lock (Fig. 6.4)"),
           "tip_deflection.png")

    fig, axes = plt.subplots(3, 1, figsize=(8, 9), sharex=True)
    yields = sorted({float(r.params["yield_strength"]) for r in runs
                     if r.params.get("yield_strength")})
    for r in runs:
        if r.rigid:
            # a rigid model has no elastic field: its zero stress is not a result, so it is
            # named in the legend and not drawn
            for ax in axes:
                ax.plot([], [], ls="none", label=f"{r.label}: rigid model, no stress")
            continue
        axes[0].plot(r.stress_t, r.stress_joint / 1e6, label=r.label)
        axes[1].plot(r.stress_t, r.stress_mid / 1e6, label=r.label)
        peak_t, leaf, link = ((r.physics["time"], r.physics["peak_stress_leaf"],
                               r.physics["peak_stress_link"]) if r.physics
                              else (r.stress_t, r.peak_leaf, r.peak_link))
        axes[2].plot(peak_t, leaf / 1e6, label=f"{r.label} leaf")
        axes[2].plot(peak_t, link / 1e6, ls="--", label=f"{r.label} link")
    for ys in yields:
        for ax, signs in zip(axes, ((1, -1), (1, -1), (1,))):
            for k, sign in enumerate(signs):
                ax.axhline(sign * ys / 1e6, color="tab:red", lw=0.8, ls=":",
                           label=f"yield {ys / 1e6:g} MPa" if k == 0 else None)
    for ax in axes[1:]:
        ax.legend(fontsize=7)
    finish(fig, axes, ("sigma (MPa)", "sigma (MPa)", "max |sigma| (MPa)"),
           ("top-fibre stress on the leaf at O'' (Fig. 6.5, 6.11)",
            "top-fibre stress at mid-link (Fig. 6.6)",
            "peak |sigma| on each body (every physics step with --physics-rate,\n"
            "else each publication: the peak since the previous one)"),
           "stress.png")

    fig, axes = plt.subplots(1, len(runs), figsize=(4.5 * len(runs), 4.5), squeeze=False)
    for ax, r in zip(axes[0], runs):
        snaps = shape_snapshots(r, magnification)
        blues = plt.cm.Blues(np.linspace(0.45, 1.0, 5))
        reds = plt.cm.Reds(np.linspace(0.45, 1.0, 4))
        n1 = n2 = 0
        for stage, tm, mag, leaf, link in snaps:
            if stage == "deploying":
                c, n1 = blues[min(n1, 4)], n1 + 1
            else:
                c, n2 = reds[min(n2, 3)], n2 + 1
            ax.plot(leaf[:, 0], leaf[:, 1], "-o", ms=2, color=c, lw=1,
                    label=f"t = {tm:.4f} s (x{mag:.3g})")
            ax.plot(link[:, 0], link[:, 1], "-", color=c, lw=0.8, alpha=0.7)
        ax.axvline(0, color="k", lw=0.6)
        ax.set_aspect("equal")
        if snaps:
            ax.legend(fontsize=6, loc="best")
        lock_text = f"lock at {r.lock_time:.4f} s" if r.lock_time is not None else "no lock"
        ax.set_title(f"{r.label}: stage 1 (blue), stage 2 (red); {lock_text}", fontsize=8)
        ax.set_xlabel("X (m)")
    axes[0][0].set_ylabel("Y (m)")
    save(fig, "shapes.png")
    return files


def shape_snapshots(r: Run, magnification=(200.0, 5.0)) -> list:
    """
    Return the deformed shapes to draw: [(stage, t, magnification, leaf_xy, link_xy)].

    Five recorded shapes in stage 1 (strictly before the lock) and four after it; the
    magnification follows the stage of the shape actually drawn, and is reduced so that the
    stage's largest elastic displacement drawn is at most SHAPE_DISPLACEMENT_LIMIT of the
    leaf length (a V0 = -1 m/s run at x200 would draw its leaf metres away).
    """
    if not r.shapes:
        return []
    end = r.shapes[-1][0]
    lock = r.lock_time if r.lock_time is not None else math.inf
    times = np.array([s[0] for s in r.shapes])
    s1, s2 = times[times < lock], times[times > lock]
    wanted = []
    if len(s1):
        wanted += [("deploying", s1[np.argmin(np.abs(s1 - f * s1[-1]))])
                   for f in (0.0, 0.25, 0.5, 0.75, 1.0)]
    if len(s2):
        wanted += [("locked", s2[np.argmin(np.abs(s2 - tw))])
                   for tw in (lock + 0.01, lock + 0.02, lock + 0.04, min(end, lock + 0.06))]
    seen, picked = set(), []
    for stage, tw in wanted:
        if tw not in seen:
            seen.add(tw)
            picked.append((stage, float(tw)))
    length = float(r.params.get("l1", 0.5)) + float(r.params.get("l2", 0.5))
    scale = {}
    for k, stage in enumerate(("deploying", "locked")):
        biggest = 0.0
        for st, tw in picked:
            if st == stage:
                _, leaf1, _ = r.shape(tw, 1.0)
                _, leaf0, _ = r.shape(tw, 0.0)
                biggest = max(biggest, float(np.abs(leaf1 - leaf0).max()))
        limit = SHAPE_DISPLACEMENT_LIMIT * length / biggest if biggest > 0 else math.inf
        scale[stage] = min(magnification[k], limit)
    out = []
    for stage, tw in picked:
        tm, leaf, link = r.shape(tw, scale[stage])
        out.append((stage, tm, scale[stage], leaf, link))
    return out


@interruptible("umbrella_compare", "--out may hold part of the outputs")
def main(argv: list[str] | None = None) -> int:
    ap = ArgumentParser(prog="umbrella_compare", description=__doc__,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+", help="bag directories or .mcap files (first = reference)")
    ap.add_argument("--out", required=True,
                    help="new (or empty) directory for compare.json and the plots")
    ap.add_argument("--segment", type=int, default=0,
                    help="which segment of each log (a ~/reset starts a new one; default 0)")
    ap.add_argument("--names", nargs="+", help="labels for the runs")
    ap.add_argument("--thesis", action="store_true", help="add the thesis's numbers")
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument("--physics-rate", action="store_true",
                    help="re-run each log's recorded commands (as umbrella_replay "
                         "--resimulate does) and draw the leaf angle, rate, acceleration, tip "
                         "deflection and peak stresses from every physics step instead of the "
                         "recorded samples")
    ap.add_argument("--magnification", type=float, nargs=2, default=(200.0, 5.0),
                    metavar=("STAGE1", "STAGE2"),
                    help="deformation magnification of the shapes plot (default 200 5)")
    args = ap.parse_args(argv)
    if not all(math.isfinite(m) and m > 0 for m in args.magnification):
        ap.error(f"--magnification {args.magnification}: must be finite numbers > 0")
    if args.segment < 0:
        ap.error(f"--segment {args.segment}: must be >= 0")
    if args.names and len(args.names) != len(args.logs):
        ap.error(f"--names: {len(args.names)} labels for {len(args.logs)} logs")
    if args.names and len(set(args.names)) != len(args.names):
        ap.error(f"--names {' '.join(args.names)}: each run needs a label of its own")
    names = args.names or [default_label(p) for p in args.logs]
    if len(set(names)) != len(names):      # same-named bags or files: their paths as given
        names = [p if names.count(n) > 1 else n for p, n in zip(args.logs, names)]
    try:
        out = _check_out_dir(args.out)          # before reading any log
        runs = [load_run(p, name, args.segment) for p, name in zip(args.logs, names)]
        result = compare(runs, thesis=args.thesis)
        if args.physics_rate and not args.no_plots:
            for r in runs:
                r.physics = physics_run(r.path, args.segment)
    except LogError as exc:
        raise_if_stopped()           # (a stop signal inside a decoding: an interrupt)
        print(f"umbrella_compare: error: {exc}", file=sys.stderr)
        return 2
    # (umbrella_compare ... | head): the outputs are still written
    reader_there = print_for_reader(lambda: print_table(result))
    try:
        os.makedirs(out, exist_ok=True)
        if not args.no_plots:
            result["plots"] = plot(runs, out, tuple(args.magnification))
        with open(os.path.join(out, "compare.json"), "x", encoding="utf-8") as fh:
            json.dump(result, fh, indent=2)
    except OSError as exc:
        print(f"umbrella_compare: error: writing to {out}: {exc.strerror or exc} (the table "
              "above is complete)", file=sys.stderr)
        return 4
    print(f"\nwrote {os.path.join(out, 'compare.json')}"
          + (f" and {len(result['plots'])} plots" if "plots" in result else ""))
    return 0 if reader_there else EXIT_READER_GONE


def _check_out_dir(path: str) -> str:
    """--out: a new directory, or an existing empty one; never overwrites."""
    from ..bag.paths import check_new_output

    if os.path.isdir(path) and not os.path.islink(path):
        if os.listdir(path):
            raise LogError(f"--out {path}: directory is not empty, not overwriting")
        if not os.access(path, os.W_OK | os.X_OK):
            raise LogError(f"--out {path}: directory is not writable")
        return path
    try:
        return check_new_output(path, "--out")
    except ValueError as exc:
        raise LogError(str(exc)) from None


if __name__ == "__main__":
    sys.exit(main())
