#!/usr/bin/env python3

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
Regenerate the README's figures: docs/mechanism.png and docs/deployment.png.

mechanism.png: the planar leaf + link frame, labelled with the names the topics and
parameters use (O, O'', G, H, the stop S, alpha1, alpha2, y_H, F_H), at a leaf angle
between folded and deployed, from the default parameters' geometry.
deployment.png: deformed shapes through a deployment and the tip deflection across the
lock (flexible model, thesis data, V0 = -0.2 m/s, N = 2).  Each element is drawn by its
own shape functions (UmbrellaModel.deformed_shape), its nodes as dots.
"""
import math
import os
import sys

import matplotlib
matplotlib.use('Agg')
from matplotlib.patches import Arc, FancyArrowPatch  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))
from umbrella_sim.core.driver import simulate  # noqa: E402
from umbrella_sim.core.model import UmbrellaModel  # noqa: E402
from umbrella_sim.core.params import UmbrellaParams  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def _angle(ax, centre, radius, start, end, text, text_radius, colour):
    """Draw the angle from start to end (rad, counter-clockwise) at centre, labelled."""
    ax.add_patch(Arc(centre, 2 * radius, 2 * radius, theta1=math.degrees(start),
                     theta2=math.degrees(end), color=colour, lw=1.2))
    mid = 0.5 * (start + end)
    ax.text(centre[0] + text_radius * math.cos(mid), centre[1] + text_radius * math.sin(mid),
            text, color=colour, ha='center', va='center', fontsize=12)


def mechanism_figure(path: str) -> None:
    """Write the labelled sketch of the mechanism (rigid geometry) to path."""
    p = UmbrellaParams()
    a1 = math.radians(40.0)
    o2 = (p.l1 * math.cos(a1), p.l1 * math.sin(a1))
    g = ((p.l1 + p.l2) * math.cos(a1), (p.l1 + p.l2) * math.sin(a1))
    y_h = o2[1] + math.sqrt(p.l3 ** 2 - o2[0] ** 2)
    a2 = math.atan2(y_h - o2[1], -o2[0])
    y_s = p.sleeve_stop_height
    fig, ax = plt.subplots(figsize=(7.0, 5.6), layout='constrained')
    ax.plot([0, 0], [-0.08, y_h + 0.25], color='0.35', lw=2.5, zorder=0)          # the axle
    ax.text(0.015, y_h + 0.22, 'axle (Y)', fontsize=10, color='0.35')
    ax.plot([-0.05, 0.85], [0, 0], color='0.6', lw=0.8, ls='--')
    ax.text(0.82, -0.045, 'X', fontsize=10, color='0.35')
    ax.plot([0, g[0]], [0, g[1]], color='tab:orange', lw=3.5, solid_capstyle='round')
    ax.plot([o2[0], 0], [o2[1], y_h], color='tab:blue', lw=3.0, solid_capstyle='round')
    ax.plot([0], [0], 'ko', ms=7)
    ax.plot([o2[0]], [o2[1]], 'ko', ms=6)
    ax.add_patch(plt.Rectangle((-0.035, y_h - 0.03), 0.07, 0.06, color='tab:blue'))  # sleeve
    ax.plot([-0.06, 0.06], [y_s, y_s], color='tab:red', lw=3)                      # the stop
    for name, (x, y), (dx, dy) in (('O', (0, 0), (-0.07, -0.02)),
                                   ("O''", o2, (0.02, -0.065)),
                                   ('G (tip)', g, (0.02, 0.0)),
                                   ('H (sleeve)', (0, y_h), (0.05, 0.01)),
                                   ('S (stop)', (0, y_s), (0.07, -0.01))):
        ax.text(x + dx, y + dy, name, fontsize=12, va='center')
    below = (0.06 * math.sin(a1), -0.06 * math.cos(a1))          # beside the leaf, under it
    ax.text(0.6 * o2[0] + below[0], 0.6 * o2[1] + below[1], 'leaf  $l_1$', color='tab:orange',
            fontsize=10, rotation=math.degrees(a1), ha='center', va='center')
    ax.text(0.5 * (o2[0] + g[0]) + below[0], 0.5 * (o2[1] + g[1]) + below[1], '$l_2$',
            color='tab:orange', fontsize=10, ha='center', va='center')
    ax.text(0.5 * o2[0] + 0.04, 0.5 * (o2[1] + y_h) + 0.03, 'link  $l_3$', color='tab:blue',
            fontsize=10, rotation=math.degrees(a2) - 180, ha='center')
    _angle(ax, (0, 0), 0.16, 0.0, a1, r'$\alpha_1$', 0.22, 'tab:orange')
    ax.plot([o2[0], o2[0] + 0.16], [o2[1], o2[1]], color='0.6', lw=0.8, ls='--')
    _angle(ax, o2, 0.09, 0.0, a2, r'$\alpha_2$', 0.14, 'tab:blue')
    ax.add_patch(FancyArrowPatch((-0.16, 0), (-0.16, y_h), arrowstyle='<->',
                                 mutation_scale=12, color='k', lw=1))
    ax.text(-0.19, 0.5 * y_h, '$y_H$', fontsize=12, ha='right', va='center')
    ax.add_patch(FancyArrowPatch((-0.09, y_h + 0.17), (-0.09, y_h + 0.04), arrowstyle='-|>',
                                 mutation_scale=14, color='tab:green', lw=2))
    ax.text(-0.11, y_h + 0.12, '$F_H$', color='tab:green', fontsize=12, ha='right')
    ax.set_aspect('equal')
    ax.set_xlim(-0.32, 1.0)
    ax.set_ylim(-0.12, y_h + 0.3)
    ax.axis('off')
    ax.set_title("the leaf O–O''–G and the link O''–H, hinged at O and O''; the sleeve H "
                 'slides down the axle\nuntil it meets the stop S (full deployment, '
                 f'alpha1 = π/12); folded: alpha1 = alpha0 = {p.alpha0 / math.pi:.2g}π',
                 fontsize=9)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def deployment_figure(path: str) -> None:
    """Write the deformed shapes and the tip deflection of a V0 = -0.2 m/s run to path."""
    p = UmbrellaParams(v0=-0.2, elements_per_segment=2, time_step=5e-4)
    r = simulate(p, 0.45)
    m = UmbrellaModel(p)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2),
                                   gridspec_kw={'width_ratios': [1, 1.4]})
    times = [0.0, 0.08, 0.16, r.lock.time, 0.2405, 0.2515]
    for t in times:
        s = min(r.samples, key=lambda s: abs(s.time - t))
        mag = 200.0 if s.stage == 'deploying' else 5.0
        leaf, link = m.deformed_shape(s.q, mag)
        nodes, _ = m.node_positions(s.q, mag)
        c = 'tab:blue' if s.stage == 'deploying' else 'tab:red'
        ax1.plot(leaf[:, 0], leaf[:, 1], '-', color=c, lw=1.5)
        ax1.plot(nodes[:, 0], nodes[:, 1], 'o', color=c, ms=3)
        ax1.plot(link[:, 0], link[:, 1], '-', color=c, lw=1, alpha=0.7)
        ax1.plot([0], [s.sleeve_position], 's', color=c, ms=5)
    ax1.axvline(0, color='k', lw=0.8)
    ax1.set_aspect('equal')
    ax1.set_xlabel('X (m)')
    ax1.set_ylabel('Y, axle (m)')
    ax1.set_title('deformed shapes (stage 1 x200 blue, stage 2 x5 red)', fontsize=9)
    t = r.column('time')
    v = r.column('tip_transverse') * 1e3
    ax2.plot(t, v, lw=1)
    ax2.axvline(r.lock.time, color='k', ls='--', lw=0.8)
    ax2.text(r.lock.time + 0.005, v.min() * 0.9, f'lock {r.lock.time:.4f} s', fontsize=8)
    ax2.set_xlabel('t (s)')
    ax2.set_ylabel('transverse deflection of tip G (mm)')
    ax2.set_title('V0 = -0.2 m/s, N = 2 (thesis Fig. 6.4)', fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == '__main__':
    for name, draw in (('mechanism.png', mechanism_figure),
                       ('deployment.png', deployment_figure)):
        draw(os.path.join(HERE, name))
        print(os.path.join(HERE, name), file=sys.stderr)
