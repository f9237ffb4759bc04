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
umbrella_compare of recordings of the umbrella of N ribs: per-rib series, figures, top view.

A recording of ``ribs`` >= 2 (msg_docs/topic_ribs.md) is read as each rib's series: the leaf
angle alpha1 (joint_states), the tip's in-plane and out-of-plane deflection
(rib_tip_deflection, published with the joint states of the same instant) and the held von
Mises peak (rib_peak_stress); its summary figures (every physics step's: each rib's
deployment instant, the lag of the latest, the largest out-of-plane tip, the energy balance)
come from the recording's metadata.  Compared with the first run: the difference of each
rib's deployment instant and the largest difference of each rib's leaf angle on the first
run's publication times.  Plots: alpha1 of every rib, the out-of-plane tip of every rib, and
a top view of the tips (X-Z plane) at the end of each run.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import os
import sys

import numpy as np

from .alignment import difference
from .runs import label_width, recorded_lock
from ..bag.reader import LogError, read_log
from ..core.umbrella3d.outputs3d import STRESS_NAMES
from ..core.umbrella3d.sampled3d import sampled_figures


@dataclass
class RibsRun:
    """One recording of the umbrella, as per-rib series (steps first, then ribs)."""

    label: str
    path: str
    params: dict
    figures: dict
    t: np.ndarray               # publication times (s)
    alpha1: np.ndarray          # (T, N) rad
    tip: np.ndarray             # (T', N, 3) axial, in-plane, out-of-plane (m)
    von_mises: np.ndarray       # (T', N) Pa, held over each period

    @property
    def ribs(self) -> int:
        return self.alpha1.shape[1]


def is_ribs_log(params: dict) -> bool:
    """Say whether a recording's parameters are those of the umbrella of N ribs (N >= 2)."""
    ribs = params.get('ribs', 1)
    return isinstance(ribs, int) and ribs > 1


def load_ribs_run(path: str, label: str, segment: int = 0) -> RibsRun:
    """
    Read a recording of the umbrella of N ribs (LogError naming what it lacks).

    Its figures are the summary record's (every physics step), or, of a recording without
    one (its writer killed) or of a segment before the last (the record is the last run's),
    the same figures of the recorded samples (sampled3d.sampled_figures), which says so.
    """
    from ..ros.ribs_messages import rib_array_figures, rib_joint_figures

    log = read_log(path)
    seg = log.segment(segment)

    def series(key, fn):
        rows = [(t, fn(m)) for t, m in log.decoded(log.find_topic(key), seg)]
        if not rows:
            raise LogError(f'{log.path}: topic {key} has no messages' + log.truncation_note())
        return np.array([t for t, _ in rows]), np.array([r for _, r in rows], dtype=float)

    t, alpha1 = series('joint_states', lambda m: rib_joint_figures(m)['alpha1'])
    tip_t, tip = series('rib_tip_deflection', lambda m: [
        [r['axial_m'], r['in_plane_m'], r['out_of_plane_m']] for r in rib_array_figures(m)])
    stress_t, stress = series('rib_peak_stress', lambda m: [
        [r[f] for f in STRESS_FIELDS] for r in rib_array_figures(m)])
    last = segment == len(log.segments()) - 1
    figures = (log.summary(segment) or (None,))[0]
    if figures is None:
        figures = _sampled(log, seg, t, alpha1, tip_t, tip, stress_t, stress)
        why = (f'the log has no summary record of segment {segment} (a recording made '
               "before a ~/reset wrote the ended run's)" if not last else
               f'the recording ended early ({log.ended_early}) before its summary record'
               if log.ended_early else
               'the log has no summary record (its writer was killed)')
        figures['figures_from'] = (f"recorded samples at {seg.params.get('publish_rate')} "
                                   f'Hz: {why}, so these figures depend on the recording rate')
    return RibsRun(label, log.path, seg.params, figures, t, alpha1, tip, stress[:, :, 4])


#: what load_ribs_run reads of rib_peak_stress: every component's peak, von Mises's place
STRESS_FIELDS = tuple(f'{name}_Pa' for name in STRESS_NAMES) + ('von_mises_body',
                                                                'von_mises_x_m')


def _sampled(log, seg, t, alpha1, tip_t, tip, stress_t, stress) -> dict:
    """Return a segment's figures of its samples, with its lock (runs.recorded_lock)."""
    from ..core.umbrella3d.model3d import UmbrellaModel3D
    from ..core.umbrella3d.params3d import node_model

    try:
        model = UmbrellaModel3D(node_model(seg.params))     # (each rib's deployed angle)
    except ValueError as exc:
        raise LogError(f"{log.path}: the recording's parameters cannot be used ({exc})") \
            from None
    lock_time = recorded_lock(log, seg.index)[1]
    figures = sampled_figures(
        model.alpha_deployed, t, alpha1, tip_t, tip, stress_t,
        {name: stress[:, :, i] for i, name in enumerate(STRESS_NAMES)}, stress[:, :, 5:7],
        lock_time)
    figures['lock_time'] = lock_time
    return figures


def compare_ribs(runs: list[RibsRun]) -> dict:
    """Return the comparison: each run's figures, and its per-rib differences to the first."""
    ref = runs[0]
    out = {'reference': ref.label, 'runs': []}
    for r in runs:
        f = r.figures
        entry = {'label': r.label, 'path': r.path, 'ribs': r.ribs,
                 'lock_time': f.get('lock_time'), 'rib_deploy_time': f.get('rib_deploy_time'),
                 'deployment_lag': f.get('deployment_lag'), 'latest_rib': f.get('latest_rib'),
                 'max_leaf_angle_spread': f.get('max_leaf_angle_spread'),
                 'stage2_tip_amplitude': f.get('stage2_tip_amplitude'),
                 'stage2_tip_period': f.get('stage2_tip_period'),
                 'max_out_of_plane_tip': f.get('max_out_of_plane_tip'),
                 'max_out_of_plane_tip_rib': f.get('max_out_of_plane_tip_rib'),
                 'peak_von_mises': (f.get('peak_stress') or {}).get('von_mises', {}).get('value'),
                 'friction_work': f.get('friction_work'), 'energy_drift': f.get('energy_drift'),
                 'units': 'SI (s, m, Pa, J, rad)'}
        if f.get('figures_from'):
            entry['figures_from'] = f['figures_from']
        if f.get('error'):
            entry['fault'] = f['error']
        if r.ribs == ref.ribs:
            mine, theirs = entry['rib_deploy_time'] or [], ref.figures.get('rib_deploy_time') or []
            entry['rib_deploy_time_difference'] = [
                None if a is None or b is None else a - b for a, b in zip(mine, theirs)]
            entry['alpha1_max_difference'] = _alpha_differences(ref, r)
        out['runs'].append(entry)
    return out


def _alpha_differences(ref: RibsRun, r: RibsRun) -> list[float] | None:
    """
    Return each rib's largest |alpha1 - alpha1_ref| over the times both runs cover.

    Taken as the planar runs' differences are (alignment.difference): on the coarser run's
    publications, or where the rates are not multiples of each other on the instants both
    runs published at, never interpolated between two samples of a vibrating frame.
    """
    if len(r.t) < 2 or len(ref.t) < 2:
        return None
    try:
        return [difference(ref.t, ref.alpha1[:, k], r.t, r.alpha1[:, k])[0]
                for k in range(r.ribs)]
    except LogError:                # (the runs do not overlap in time)
        return None


def print_ribs_table(result: dict, stream=None) -> None:
    w = (stream or sys.stdout).write
    L = label_width(result['runs'])
    w(f"reference run: {result['reference']} (the umbrella of N ribs)\n")
    w('lag: how long after the earliest rib the latest one deployed (one sleeve deploys them '
      'together: 0 but for a rib that never reaches its angle); latest: that rib; spread: how '
      "far apart the ribs' leaf angles got before the lock; max w tip: the largest "
      'out-of-plane tip of any rib; the differences: of each run against the reference run '
      '(zero for the reference itself)\n')
    w(f"{'run':<{L}} {'ribs':>4} {'lock (s)':>11} {'lag (s)':>10} {'latest':>6} "
      f"{'spread (rad)':>12} {'max w tip (mm)':>14} {'energy drift':>12}\n")
    for e in result['runs']:
        w(f"{e['label']:<{L}} {e['ribs']:>4} {_num(e['lock_time'], '.7f'):>11} "
          f"{_num(e['deployment_lag'], '.3e'):>10} {_num(e['latest_rib'], 'd'):>6} "
          f"{_num(e.get('max_leaf_angle_spread'), '.3e'):>12} "
          f"{_num(e['max_out_of_plane_tip'] and e['max_out_of_plane_tip'] * 1e3, '.4g'):>14} "
          f"{_num(e['energy_drift'], '.2e'):>12}\n")
    for e in result['runs']:
        if e.get('figures_from'):
            w(f"{e['label']}: figures from {e['figures_from']}\n")
        if e.get('fault'):
            w(f"{e['label']}: ended in a fault: {e['fault']}\n")
    w('\nper rib: deployment instant (s), its difference to the reference (s), max |d alpha1| '
      '(rad), peak von Mises (MPa), friction work (J), stage-2 in-plane tip amplitude (mm) and '
      'period (ms) (- where the figures do not hold them)\n')
    for e in result['runs']:
        def rib(key):
            return (e.get(key) or [None] * e['ribs'])[k]

        deploy = e['rib_deploy_time'] or []
        for k in range(e['ribs']):
            vm, amplitude, period = (rib(key) for key in (
                'peak_von_mises', 'stage2_tip_amplitude', 'stage2_tip_period'))
            t = deploy[k] if k < len(deploy) else None
            w(f"{e['label']:<{L}} rib{k:<3} {_num(t, '.7f'):>11} "
              f"{_num(rib('rib_deploy_time_difference'), '+.3e'):>11} "
              f"{_num(rib('alpha1_max_difference'), '.3e'):>10} "
              f"{_num(vm and vm * 1e-6, '.4g'):>9} {_num(rib('friction_work'), '.4g'):>9} "
              f"{_num(amplitude and amplitude * 1e3, '.4g'):>9} "
              f"{_num(period and period * 1e3, '.4f'):>9}\n")


def _num(value, spec: str) -> str:
    """Return a table's figure: '-' for None."""
    return '-' if value is None else format(value, spec)


def plot_ribs(runs: list[RibsRun], out_dir: str) -> list[str]:
    """Write ribs_alpha1.png, ribs_tip_out_of_plane.png and ribs_top_view.png; their paths."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    written = []
    for name, ylabel, get in (
            ('ribs_alpha1.png', 'leaf angle alpha1 (rad)', lambda r: (r.t, r.alpha1)),
            ('ribs_tip_out_of_plane.png', 'out-of-plane tip deflection w (mm)',
             lambda r: (r.t[:len(r.tip)], r.tip[:len(r.t), :, 2] * 1e3))):
        fig, axes = plt.subplots(len(runs), 1, figsize=(7, 2.8 * len(runs)), sharex=True,
                                 squeeze=False)
        for ax, r in zip(axes[:, 0], runs):
            t, y = get(r)
            for k in range(r.ribs):
                ax.plot(t, y[:, k], lw=1.0, label=f'rib{k}')
            ax.set_ylabel(ylabel)
            ax.set_title(r.label, fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, ncol=min(r.ribs, 6))
        axes[-1, 0].set_xlabel('sim time (s)')
        fig.tight_layout()
        written.append(_save(fig, plt, out_dir, name))
    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    tips = [top_view_tips(r) for r in runs]
    reach = 1.15 * max(max(float(np.abs(xz).max()) for xz in tips), 1e-3)
    ax.set_xlim(-reach, reach)          # (square and centred: two ribs lie on one line)
    ax.set_ylim(-reach, reach)
    for i, (r, xz) in enumerate(zip(runs, tips)):
        ax.plot(*np.vstack([xz, xz[:1]]).T, 'o-', color=f'C{i % 10}', label=r.label)
        for k, (x, z) in enumerate(xz):
            ax.annotate(f'{k}', (x, z), fontsize=7)
    ax.set_aspect('equal')
    ax.set_xlabel('X (m)')
    ax.set_ylabel('Z (m)')
    ax.set_title('tips G at the end of each run, seen from +Y (top view)', fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    written.append(_save(fig, plt, out_dir, 'ribs_top_view.png'))
    return written


def top_view_tips(r: RibsRun) -> np.ndarray:
    """
    Return each rib's tip G at the run's last publication in the X-Z plane (N, 2), m.

    Rib k at azimuth psi_k = 2 pi k / N about +Y: radial axis e_r = (cos psi, 0, -sin psi),
    tangential e_t = e_r x e_Y = (sin psi, 0, cos psi); G's radial distance from the axis is
    a + (l1 + l2 + u) cos alpha1 - v sin alpha1 (a the hub radius, u, v its deflection in
    the leaf frame), and w is along e_t.
    """
    p = r.params
    n = r.ribs
    psi = 2.0 * math.pi * np.arange(n) / n
    u, v, w = r.tip[-1].T
    a1 = r.alpha1[min(len(r.alpha1), len(r.tip)) - 1]
    radial = (p.get('hub_radius', 0.0) + (p.get('l1', 0.5) + p.get('l2', 0.5) + u) * np.cos(a1)
              - v * np.sin(a1))
    return np.stack([radial * np.cos(psi) + w * np.sin(psi),
                     -radial * np.sin(psi) + w * np.cos(psi)], 1)


def _save(fig, plt, out_dir: str, name: str) -> str:
    path = os.path.join(out_dir, name)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
