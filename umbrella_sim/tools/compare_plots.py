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
umbrella_compare's figures: the runs' signals against time, the deformed shapes, the lock.

Drawn with matplotlib (Agg) from the runs.Run records the recordings gave, over a window of
sim time (runs.default_window unless told).  The leaf angle and the stresses are drawn in
two columns, stage 1 (deploying, up to each run's lock) and stage 2 (locked, from it), each
on its own scale: the stage-2 vibration is hundreds of times the stage-1 signal it would
otherwise flatten.  A signal swinging faster than a panel can show (every physics step with
--physics-rate) is drawn as its envelope: its range and mean over a running window of about
one cycle of its fastest swing.  With --physics-rate the leaf angle's stage-2 column is a
zoom on the first period of the locked frame's first mode, drawn as lines: the fast modes
the leaf angle swings in after the lock, which an envelope would hide.  The thesis's values
(runs.thesis_figures) are drawn where it has them.  The deformed shapes come from the
recorded markers (each element drawn by its own cubic), one row per run, stage 1 and
stage 2 side by side, each at one round magnification.
"""
from __future__ import annotations

import math
import os
import textwrap

import numpy as np

from .runs import default_window, Run, SHAPE_DISPLACEMENT_LIMIT, thesis_figures

#: a signal with more local extrema than this in a panel is drawn as its envelope
DENSE_EXTREMA = 60
#: the most points an envelope is drawn with
MAX_POINTS = 2000
THESIS_STYLE = {'color': 'k', 'lw': 1.0, 'ls': '--'}


def plot(runs: list[Run], out_dir: str, magnification=(200.0, 5.0),
         window: tuple[float, float] | None = None) -> list[str]:
    """
    PNG plots of the runs over window (t0, t1), s; return their paths.

    magnification = (stage 1, stage 2): the most the deformed shapes are magnified.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    window = tuple(window) if window is not None else default_window(runs)
    os.makedirs(out_dir, exist_ok=True)
    colours = {r.label: f'C{k % 10}' for k, r in enumerate(runs)}
    files = []
    for name, draw in (('alpha1.png', _alpha1_figure), ('tip_deflection.png', _tip_figure),
                       ('stress.png', _stress_figure)):
        fig = draw(plt, runs, window, colours)
        files.append(_save(plt, fig, out_dir, name))
    fig, axes = plt.subplots(len(runs), 2, figsize=(12, 4.9 * len(runs)), squeeze=False,
                             layout='constrained')
    for row, r in zip(axes, runs):
        _shapes(plt, row, r, shape_snapshots(r, magnification, window))
    files.append(_save(plt, fig, out_dir, 'shapes.png'))
    return files


def _save(plt, fig, out_dir, name) -> str:
    path = os.path.join(out_dir, name)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _alpha1_figure(plt, runs, window, colours):
    """Leaf angle, rate, acceleration, stage 1 and stage 2 (thesis Fig. 6.1, 6.12-6.17)."""
    columns = _columns(runs, window)
    periods = [r.locked_period() for r in runs if r.lock_time is not None]
    if any(r.physics for r in runs) and columns[-1][0] == 'locked' and all(periods):
        _, t0, t1 = columns[-1]
        columns[-1] = ('zoom', t0, min(t1, t0 + max(periods)))
    fig, axes = _grid(plt, 3, columns, height=2.7)
    spans = []
    for r in runs:
        t, a1, rate = ((r.physics['time'], r.physics['alpha1'], r.physics['alpha1_rate'])
                       if r.physics else (r.t, r.alpha1, r.alpha1_rate))
        acc = _stage_gradient(t, rate, r.lock_time)
        for row, y in enumerate((a1, rate, acc)):
            _by_stage(axes[row], columns, r, t, y, window, colours[r.label], r.label,
                      spans=spans)
    _thesis_deploy_lines(axes[0], columns, runs)
    _finish(fig, axes, columns, ('alpha1 (rad)', 'd alpha1/dt (rad/s)',
                                 'd2 alpha1/dt2 (rad/s²)'),
            'leaf angle alpha1, its rate and acceleration (thesis Fig. 6.1, 6.12–6.17)',
            'acceleration: the rate differenced at the '
            + ('physics step' if any(r.physics for r in runs) else 'recorded rate')
            + _envelope_note(spans))
    return fig


def _tip_figure(plt, runs, window, colours):
    """Transverse tip deflection in stage 1 and across the lock (Fig. 6.2, 6.4, 6.10)."""
    fig, axes = plt.subplots(2, 1, figsize=(9, 7.5), layout='constrained')
    spans = []
    for r in runs:
        tip_t, tip_v = ((r.physics['time'], r.physics['tip_transverse']) if r.physics
                        else (r.tip_t, r.tip_v))
        lock = r.lock_time if r.lock_time is not None else math.inf
        s1 = (tip_t <= lock) & _within(tip_t, window)
        _trace(axes[0], tip_t[s1], tip_v[s1] * 1e3, colours[r.label], r.label, spans=spans)
        keep = _within(tip_t, window)
        _trace(axes[1], tip_t[keep], tip_v[keep] * 1e3, colours[r.label], r.label,
               spans=spans)
        if r.lock_time is not None and window[0] <= r.lock_time <= window[1]:
            axes[1].axvline(r.lock_time, ls=':', lw=0.8, color=colours[r.label])
    _thesis_tip(axes, runs)
    locks = [r.lock_time for r in runs if r.lock_time is not None]
    end = max(locks) if len(locks) == len(runs) else window[1]
    if window[1] > window[0]:       # (a run that ended at once has no span to draw)
        axes[0].set_xlim(window[0], min(window[1], end) if end > window[0] else window[1])
        axes[1].set_xlim(*window)
    axes[0].set_title('transverse deflection of the tip G, stage 1 (thesis Fig. 6.2, 6.10)')
    axes[1].set_title("across the lock (dotted: each run's lock; thesis Fig. 6.4)")
    for ax in axes:
        ax.set_ylabel('v_G (mm)')
        ax.set_xlabel('t (s)')
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc='best')
    if spans:
        _note(fig, _envelope_note(spans))
    return fig


def _stress_figure(plt, runs, window, colours):
    """Top-fibre stress at O'' and mid-link, peak |sigma| (Fig. 6.5, 6.6, 6.11)."""
    columns = _columns(runs, window)
    fig, axes = _grid(plt, 3, columns, height=2.9)
    spans = []
    for r in runs:
        if r.rigid:
            # a rigid model has no elastic field: its zero stress is not a result, so it is
            # named in the legend and not drawn
            for ax in axes.flat:
                ax.plot([], [], ls='none', label=f'{r.label}: rigid model, no stress')
            continue
        peak_t, leaf, link = ((r.physics['time'], r.physics['peak_stress_leaf'],
                               r.physics['peak_stress_link']) if r.physics
                              else (r.stress_t, r.peak_leaf, r.peak_link))
        for row, t, y, label, ls in (
                (0, r.stress_t, r.stress_joint, r.label, '-'),
                (1, r.stress_t, r.stress_mid, r.label, '-'),
                (2, peak_t, leaf, r.label, '-'),
                (2, peak_t, link, None, '--')):
            _by_stage(axes[row], columns, r, t, y / 1e6, window, colours[r.label], label,
                      ls=ls, spans=spans)
    for ls, body in (('-', 'leaf'), ('--', 'link')):
        axes[2][0].plot([], [], color='0.4', ls=ls, label=f'peak |σ| on the {body}')
    _yield_lines(axes, runs)
    _finish(fig, axes, columns, ("σ at O'' on the leaf (MPa)", 'σ at mid-link (MPa)',
                                 'peak |σ| (MPa)'),
            "top-fibre stress on the leaf at O'' (thesis Fig. 6.5, 6.11) and at mid-link "
            '(Fig. 6.6);\npeak |σ| on each body',
            "peak |σ|: at every physics step with --physics-rate, else each publication's "
            'peak since the previous one' + _envelope_note(spans))
    return fig


# ---------------------------------------------------------------- time series
def _stage_gradient(t, y, lock) -> np.ndarray:
    """Return dy/dt differenced within each stage (the rate jumps at the lock)."""
    out = np.zeros_like(y, dtype=float)
    for part in ((t <= lock, t > lock) if lock is not None else (t == t,)):
        if part.sum() > 1:
            out[part] = np.gradient(y[part], t[part])
    return out


def _within(t, window) -> np.ndarray:
    return (t >= window[0] - 1e-12) & (t <= window[1] + 1e-12)


def _columns(runs, window) -> list[tuple[str, float, float]]:
    """Return the stage columns drawn: [(stage, t0, t1)], stage 1 and/or stage 2."""
    locks = [r.lock_time for r in runs if r.lock_time is not None]
    unlocked = len(locks) < len(runs)
    cols = []
    if unlocked or min(locks) > window[0]:
        end = window[1]
        if not unlocked:     # a little past the last lock: what is drawn at it shows
            end = min(max(locks) + 0.03 * (max(locks) - window[0]), window[1])
        cols.append(('deploying', window[0], end))
    if locks and max(window[0], min(locks)) < window[1]:
        cols.append(('locked', max(window[0], min(locks)), window[1]))
    return cols or [('deploying', window[0], window[1])]


def _grid(plt, rows, columns, height):
    """Return a figure of rows x (stage columns) panels, each column its own time axis."""
    return plt.subplots(rows, len(columns), figsize=(4.5 + 4.5 * len(columns),
                                                     height * rows + 1.0),
                        squeeze=False, layout='constrained', sharex='col')


def _by_stage(axes_row, columns, r: Run, t, y, window, colour, label, ls='-', spans=None):
    """Draw (t, y) of one run: its stage 1 in the deploying column, stage 2 in the others."""
    lock = r.lock_time if r.lock_time is not None else math.inf
    for ax, (stage, t0, t1) in zip(axes_row, columns):
        keep = _within(t, (max(t0, window[0]), min(t1, window[1])))
        keep &= (t <= lock + 1e-12) if stage == 'deploying' else (t >= lock - 1e-12)
        _trace(ax, t[keep], y[keep], colour, label, ls=ls, spans=spans,
               envelope=stage != 'zoom')


def _trace(ax, t, y, colour, label, ls='-', spans=None, envelope=True):
    """
    Draw y(t): a line, or where it swings more than DENSE_EXTREMA times, its envelope.

    The envelope: the range of y over a running window of about one cycle of y's fastest
    swing (shaded) and its running mean over the same window (the line), at most MAX_POINTS
    points; the window's length (s) is added to spans.
    """
    y = np.asarray(y, dtype=float)
    swings = np.flatnonzero(np.diff(np.sign(np.diff(y))) != 0) if len(y) > 2 else []
    if len(swings) <= DENSE_EXTREMA or not envelope:
        ax.plot(t, y, color=colour, lw=1.1, ls=ls, label=label)
        return
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    dt = float(np.median(np.diff(t)))
    stride = max(1, len(t) // MAX_POINTS)
    k = 2 * int(np.median(np.diff(swings)))
    k = max(3, k + 1 - k % 2, stride)
    # the window truncated at the ends: nearest-value padding leaves a min or max as it is
    lo, hi = minimum_filter1d(y, k, mode='nearest'), maximum_filter1d(y, k, mode='nearest')
    # the mean where the whole window fits (a part of a cycle has no mean to show)
    mean = np.full(len(y), np.nan)
    if len(y) >= k:
        sums = np.concatenate(([0.0], np.cumsum(y)))
        mean[k // 2:len(y) - k // 2] = (sums[k:] - sums[:-k]) / k
    ax.fill_between(t[::stride], lo[::stride], hi[::stride], color=colour, alpha=0.25, lw=0)
    ax.plot(t[::stride], mean[::stride], color=colour, lw=1.1, ls=ls, label=label)
    if spans is not None:
        spans.append(k * dt)


def _envelope_note(spans) -> str:
    """Say how the envelopes drawn (their windows' lengths, s, from _trace) were taken."""
    if not spans:
        return ''
    lo, hi = min(spans) * 1e3, max(spans) * 1e3
    span = f'{lo:.2g} ms' if math.isclose(lo, hi, rel_tol=0.05) else f'{lo:.2g}–{hi:.2g} ms'
    return ('\nshaded: the range of a signal too fast for a line over a running window (about '
            f'one cycle of its fastest swing, {span}); line: its mean over the same window')


def _finish(fig, axes, columns, ylabels, title, note):
    heads = {'deploying': 'stage 1: deploying', 'locked': 'stage 2: locked',
             'zoom': 'stage 2: locked, zoom on the first period of its first mode'}
    for k, (stage, t0, t1) in enumerate(columns):
        axes[0][k].set_title(heads[stage], fontsize=10)
        axes[-1][k].set_xlabel('t (s)')
        for ax in axes[:, k]:
            ax.grid(alpha=0.3)
            if t1 > t0:
                ax.set_xlim(t0, t1)
    for ax, ylabel in zip(axes[:, 0], ylabels):
        ax.set_ylabel(ylabel)
    handles = {}                 # one legend for the figure, under its title: each label once
    for ax in axes.flat:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    if handles:
        fig.legend(handles.values(), handles.keys(), loc='outside upper center',
                   ncol=min(4, len(handles)), fontsize=9, title=title, title_fontsize=11,
                   frameon=False)
    else:
        fig.suptitle(title, fontsize=11)
    _note(fig, note)


def _note(fig, note: str) -> None:
    """Put note under the figure's panels, wrapped to its width."""
    width = int(fig.get_figwidth() * 15)
    fig.supxlabel('\n'.join(textwrap.fill(p, width) for p in note.strip().split('\n')),
                  fontsize=8)


def _yield_lines(axes, runs):
    """± yield_strength where a panel's stresses reach a fifth of it, else named off scale."""
    yields = sorted({float(r.params['yield_strength']) for r in runs
                     if r.params.get('yield_strength')})
    for row, ax in np.ndenumerate(axes):
        reach = max(abs(ax.dataLim.y0), abs(ax.dataLim.y1)) if ax.has_data() else 0.0
        signs = (1,) if row[0] == 2 else (1, -1)
        for ys in yields:
            label = f'yield {ys / 1e6:g} MPa'
            if reach >= 0.2 * ys / 1e6:
                for k, sign in enumerate(signs):
                    ax.axhline(sign * ys / 1e6, color='tab:red', lw=0.8, ls=':',
                               label=label if k == 0 else None)
            else:
                ax.text(0.99, 0.03, f'{label}: off this scale', transform=ax.transAxes,
                        ha='right', va='bottom', fontsize=8, color='tab:red')


def _thesis_deploy_lines(axes_row, columns, runs):
    """Draw the thesis's deployment times (Table 6.1, ch. 6) on the stage-1 alpha1 panel."""
    seen = set()
    for r in runs:
        th = thesis_figures(r.params)
        start = r.deploy_start or 0.0
        times = ([('thesis deployed (deformable FEA)', th['deploy_time_deformable_fea']),
                  ('thesis deployed (rigid FEA)', th['deploy_time_rigid_fea'])]
                 if 'deploy_time_deformable_fea' in th else
                 [('thesis deployed', th['deploy_time'])] if 'deploy_time' in th else [])
        for k, (label, t) in enumerate(times):
            if (label, t + start) in seen:
                continue
            seen.add((label, t + start))
            for ax, (stage, *_) in zip(axes_row, columns):
                if stage == 'deploying':
                    ax.axvline(t + start, **{**THESIS_STYLE, 'ls': ('-.', ':')[k]},
                               label=f'{label}: {t:g} s')


def _thesis_tip(axes, runs):
    """Draw the thesis's V0 = -0.2 m/s tip figures: stage-1 maximum, stage-2 amplitude."""
    done = False
    for r in runs:
        th = thesis_figures(r.params)
        if 'tip_deflection_max' not in th or done:
            continue
        done = True
        start = r.deploy_start or 0.0
        t_max = th['tip_deflection_max_time'] + start
        sign = np.sign(np.interp(t_max, r.tip_t, r.tip_v)) or 1.0
        axes[0].plot([t_max], [sign * th['tip_deflection_max'] * 1e3], 'kx', ms=9, mew=2,
                     label=f"thesis: {th['tip_deflection_max'] * 1e3:g} mm at "
                           f"{th['tip_deflection_max_time']:g} s")
        amp = th['stage2_tip_amplitude'] * 1e3
        for k, sign in enumerate((1, -1)):
            axes[1].axhline(sign * amp, **THESIS_STYLE,
                            label=(f'thesis: ±{amp:g} mm stage-2 amplitude, period '
                                   f"~{th['stage2_tip_period']:g} s") if k == 0 else None)
        axes[1].axvline(th['deploy_time'] + start, **{**THESIS_STYLE, 'ls': '-.'},
                        label=f"thesis deployed: {th['deploy_time']:g} s")


# ---------------------------------------------------------------- shapes
def round_magnification(m: float) -> float:
    """Return the largest of 1, 2, 5 x 10^k not above m (m itself below 1e-12)."""
    if not m > 1e-12 or math.isinf(m):
        return m
    k = math.floor(math.log10(m))
    for f in (5, 2, 1):
        if f * 10.0 ** k <= m * (1 + 1e-9):
            return float(f * 10.0 ** k)
    return float(10.0 ** k)


def shape_snapshots(r: Run, magnification=(200.0, 5.0), window=None) -> list:
    """
    Return the deformed shapes to draw: [(stage, t, magnification, leaf_xy, link_xy)].

    Five recorded shapes in stage 1 (strictly before the lock, within the window): at its
    start, its end and evenly between; after the lock, the first shape and, within the
    first three periods of the stage-2 vibration, those of the largest tip deflection
    either way.  Each stage at one magnification: the one asked for, reduced so that the
    stage's largest elastic displacement drawn is at most SHAPE_DISPLACEMENT_LIMIT of the
    leaf length (a V0 = -1 m/s run at x200 would draw its leaf metres away), rounded down
    to 1, 2 or 5 x 10^k.  A rigid model: magnification 1 (it has nothing to magnify).
    """
    if not r.shapes:
        return []
    window = window or (-math.inf, math.inf)
    lock = r.lock_time if r.lock_time is not None else math.inf
    times = np.array([s[0] for s in r.shapes])
    times = times[_within(times, window)]
    s1, s2 = times[times < lock], times[times > lock]
    wanted = []
    if len(s1):
        wanted += [('deploying', s1[np.argmin(np.abs(s1 - (s1[0] + f * (s1[-1] - s1[0]))))])
                   for f in (0.0, 0.25, 0.5, 0.75, 1.0)]
    if len(s2):
        period = r.locked_period() or 0.05
        early = s2[s2 <= s2[0] + 3 * period]
        tip = np.interp(early, r.tip_t, r.tip_v)
        wanted += [('locked', early[0]), ('locked', early[np.argmax(tip)]),
                   ('locked', early[np.argmin(tip)])]
    seen, picked = set(), []
    for stage, tw in wanted:
        if tw not in seen:
            seen.add(tw)
            picked.append((stage, float(tw)))
    picked.sort(key=lambda p: p[1])
    length = float(r.params.get('l1', 0.5)) + float(r.params.get('l2', 0.5))
    scale = {}
    for k, stage in enumerate(('deploying', 'locked')):
        biggest = 0.0
        for st, tw in picked:
            if st == stage:
                _, leaf1, link1 = r.shape(tw, 1.0)
                _, leaf0, link0 = r.shape(tw, 0.0)
                biggest = max(biggest, float(np.abs(leaf1 - leaf0).max()),
                              float(np.abs(link1 - link0).max()))
        limit = SHAPE_DISPLACEMENT_LIMIT * length / biggest if biggest > 1e-12 else math.inf
        scale[stage] = 1.0 if r.rigid else round_magnification(min(magnification[k], limit))
    out = []
    for stage, tw in picked:
        tm, leaf, link = r.shape(tw, scale[stage])
        out.append((stage, tm, scale[stage], leaf, link))
    return out


def _shapes(plt, row, r: Run, snaps):
    """One run's row of shapes.png: stage 1 (blues) and stage 2 (reds)."""
    for ax, stage, cmap in zip(row, ('deploying', 'locked'), (plt.cm.Blues, plt.cm.Reds)):
        mine = [s for s in snaps if s[0] == stage]
        tones = cmap(np.linspace(0.45, 1.0, max(len(mine), 1)))
        for (_, tm, mag, leaf, link), c in zip(mine, tones):
            ax.plot(leaf[:, 0], leaf[:, 1], '-', color=c, lw=1.6, label=f't = {tm:.4f} s')
            nodes = r.nodes(leaf, 'leaf')
            ax.plot(nodes[:, 0], nodes[:, 1], 'o', color=c, ms=3)
            ax.plot(link[:, 0], link[:, 1], '-', color=c, lw=1.1, alpha=0.75)
        if stage == 'locked' and mine and not r.rigid:
            _, leaf0, link0 = r.shape(mine[0][1], 0.0)
            ax.plot(leaf0[:, 0], leaf0[:, 1], color='0.5', lw=0.8, ls='--',
                    label='undeformed')
            ax.plot(link0[:, 0], link0[:, 1], color='0.5', lw=0.8, ls='--')
        ax.axvline(0, color='k', lw=0.6)
        ax.set_aspect('equal', adjustable='datalim')
        ax.grid(alpha=0.3)
        ax.set_xlabel('X (m)')
        ax.set_ylabel('Y, the axle (m)')
        if mine:
            ax.legend(fontsize=8, loc='upper right')
        head = ('stage 1, deploying' if stage == 'deploying' else
                f'stage 2, locked at {r.lock_time:.4f} s' if r.lock_time is not None
                else 'stage 2: no lock')
        how = ('rigid model: no deformation' if r.rigid else
               f'deformation ×{mine[0][2]:g}' if mine else 'no shape recorded')
        ax.set_title(f'{r.label}\n{head}; {how}', fontsize=10)
