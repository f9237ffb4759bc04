"""
umbrella_compare's figures: the runs' signals against time, the deformed shapes, the lock.

Drawn with matplotlib (Agg) from the runs.Run records the recordings gave; the deformed
shapes from the recorded markers (each element drawn by its own cubic), magnified (stage 1
and stage 2 each its own factor).
"""
from __future__ import annotations

import math
import os

import numpy as np

from .runs import Run, SHAPE_DISPLACEMENT_LIMIT


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
            ax.plot(leaf[:, 0], leaf[:, 1], "-", color=c, lw=1,
                    label=f"t = {tm:.4f} s (x{mag:.3g})")
            nodes = r.nodes(leaf, "leaf")
            ax.plot(nodes[:, 0], nodes[:, 1], "o", ms=2, color=c)
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
