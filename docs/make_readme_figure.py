#!/usr/bin/env python3
"""
Regenerate docs/deployment.png.

Deformed shapes through a deployment and the tip
deflection across the lock (flexible model, thesis data, V0 = -0.2 m/s, N = 2).  Each
element is drawn by its own shape functions (UmbrellaModel.deformed_shape), its nodes as dots.
"""
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from umbrella_sim.core.driver import simulate  # noqa: E402
from umbrella_sim.core.model import UmbrellaModel  # noqa: E402
from umbrella_sim.core.params import UmbrellaParams  # noqa: E402

p = UmbrellaParams(v0=-0.2, elements_per_segment=2, time_step=5e-4)
r = simulate(p, 0.45)
m = UmbrellaModel(p)
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [1, 1.4]})
times = [0.0, 0.08, 0.16, r.lock.time, 0.2405, 0.2515]
for t in times:
    s = min(r.samples, key=lambda s: abs(s.time - t))
    mag = 200.0 if s.stage == "deploying" else 5.0
    leaf, link = m.deformed_shape(s.q, mag)
    nodes, _ = m.node_positions(s.q, mag)
    c = "tab:blue" if s.stage == "deploying" else "tab:red"
    ax1.plot(leaf[:, 0], leaf[:, 1], "-", color=c, lw=1.5)
    ax1.plot(nodes[:, 0], nodes[:, 1], "o", color=c, ms=3)
    ax1.plot(link[:, 0], link[:, 1], "-", color=c, lw=1, alpha=0.7)
    ax1.plot([0], [s.sleeve_position], "s", color=c, ms=5)
ax1.axvline(0, color="k", lw=0.8)
ax1.set_aspect("equal")
ax1.set_xlabel("X (m)")
ax1.set_ylabel("Y, axle (m)")
ax1.set_title("deformed shapes (stage 1 x200 blue, stage 2 x5 red)", fontsize=9)
t = r.column("time")
v = r.column("tip_transverse") * 1e3
ax2.plot(t, v, lw=1)
ax2.axvline(r.lock.time, color="k", ls="--", lw=0.8)
ax2.text(r.lock.time + 0.005, v.min() * 0.9, f"lock {r.lock.time:.4f} s", fontsize=8)
ax2.set_xlabel("t (s)")
ax2.set_ylabel("transverse deflection of tip G (mm)")
ax2.set_title("V0 = -0.2 m/s, N = 2 (thesis Fig. 6.4)", fontsize=9)
fig.tight_layout()
out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "deployment.png")
fig.savefig(out, dpi=110)
print(out, file=sys.stderr)
