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
Regenerate docs/umbrella3d.md and docs/umbrella3d/*.png: the whole umbrella's validation.

    .venv/bin/python docs/make_umbrella3d.py

(a) N identical ribs against the planar model, (b) locked frequencies against an independently
assembled 3D frame, (c) energy and momentum balances, (d) an asymmetric deployment against
MuJoCo, (e) mesh convergence.  The independent models are the tests' (tests/test_umbrella3d*):
one definition, used by the tests and by this page.  A few minutes on one core.
"""
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))

from tests.test_umbrella3d import ASYMMETRIC, DRIVE, planar_run  # noqa: E402
from tests.test_umbrella3d_modes import cantilever_check, rib_frame  # noqa: E402
from umbrella_sim.core import simulate, UmbrellaParams  # noqa: E402
from umbrella_sim.core.umbrella3d.model3d import UmbrellaModel3D  # noqa: E402
from umbrella_sim.core.umbrella3d.modes3d import locked_modes  # noqa: E402
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams  # noqa: E402
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D  # noqa: E402

OUT_DIR = os.path.join(HERE, 'umbrella3d')


def progress(what: str) -> None:
    print(f'make_umbrella3d: {what}', file=sys.stderr, flush=True)


def plt():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as pyplot
    return pyplot


def save(fig, name):
    fig.tight_layout()
    fig.savefig(os.path.join(OUT_DIR, name), dpi=110)
    return f'![{name[:-4]}](umbrella3d/{name})'


# ------------------------------------------------------------------ (a)
def identity(ribs, values, duration):
    p = UmbrellaParams(**values, phase_correction=False)
    planar_sim, planar = planar_run(p, duration)
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': ribs, **values, 'phase_correction': False}), carry_steps=1)
    a = sim.run(duration).arrays()
    d_alpha = np.max(np.abs(a['alpha1'][1:] - planar[:, 1:2]))
    d_sleeve = np.max(np.abs(a['sleeve_position'][1:] - planar[:, 3]))
    d_tip = np.max(np.abs(a['tip'][1:, :, 1] - planar[:, 5:6]))
    return (ribs, values.get('elements_per_segment', 1), values.get('lock', 'auto→energy'),
            sim.h, d_alpha, d_sleeve, d_tip, abs(sim.lock_time - planar_sim.lock_event.time))


def default_identity(carry_steps=None, ribs=6, duration=0.5):
    """Return the largest in-plane tip difference (stage 1, stage 2; m) of the default run."""
    planar = simulate(UmbrellaParams(), duration)
    t_planar = np.round(planar.column('time'), 9)
    lock = planar.lock.time
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({'ribs': ribs}),
                              **({} if carry_steps is None else {'carry_steps': carry_steps}))
    a = sim.run(duration).arrays()
    t = np.round(a['time'], 9)
    mine, theirs = np.isin(t, t_planar), np.isin(t_planar, t)
    d = np.abs(a['tip'][mine, :, 1] - planar.column('tip_transverse')[theirs][:, None]).max(1)
    amplitude = float(np.abs(planar.column('tip_transverse')).max())
    return float(d[t[mine] < lock].max()), float(d[t[mine] >= lock].max()), amplitude


def section_a(lines):
    progress('(a) identical ribs against the planar model')
    rows = [identity(1, {'time_step': 1e-4, 'sleeve_force': 10.0}, 0.19),
            identity(4, {'time_step': 5e-5, 'elements_per_segment': 2, 'lock': 'plastic',
                         'sleeve_force': 10.0}, 0.19)]
    same = default_identity(carry_steps=1)
    kept = default_identity()
    lines += ['## (a) N identical ribs are N planar models', '',
              'The same equations, so the same iterates where both codes take the same Newton '
              'steps: the 3D step factored afresh each step as the planar one (`carry_steps: '
              "1`), every rib's in-plane tip is the planar tip to round-off (6 ribs, the "
              f'default run, 0.5 s: {same[0]:.1e} m in stage 1, {same[1]:.1e} m in stage 2). '
              'At the defaults the 3D step keeps its iteration matrix over up to 8 steps '
              '(modified Newton: cheaper, the same solution to the Newton tolerance), in '
              "stage 2 with its velocity projection (its metric's error the kept matrix's "
              'order: `integrator3d.PROJECTION_PASSES`); the two differ by that '
              f"tolerance's share: {kept[0]:.1e} m in stage 1 and "
              f'{kept[1]:.1e} m in stage 2 ({kept[1] / kept[2]:.1e} of the '
              f'{1e3 * kept[2]:.0f} mm amplitude, grown through the lock instant), the ribs '
              'equal among themselves.', '',
              'Sleeve force 10 N a rib, V0 = −0.2 m/s, 30 ms past the lock; the planar model '
              '(`umbrella_sim.core.UmbrellaSimulator`) without its stage-2 mode fit '
              '(`phase_correction: false`; with it, tests/test_umbrella3d.py), the 3D '
              'iteration matrix factored every step as the planar one (`carry_steps: 1`). '
              'Largest '
              'difference over every step and every rib (tests/test_umbrella3d.py asserts '
              "1e-10, 100 times below Newton's increment tolerance):", '',
              '| ribs | elements a segment | lock | step (s) | alpha1 (rad) | sleeve (m) | '
              'tip, in-plane (m) | lock instant (s) |', '|---|---|---|---|---|---|---|---|']
    for r in rows:
        lines.append(f'| {r[0]} | {r[1]} | {r[2]} | {r[3]:g} | {r[4]:.1e} | {r[5]:.1e} | '
                     f'{r[6]:.1e} | {r[7]:.1e} |')
    lines.append('')


# ------------------------------------------------------------------ (b)
def section_b(lines):
    progress('(b) locked frequencies against a 3D frame')
    lines += ['## (b) Locked frequencies against an independent 3D frame model', '',
              'The floating-frame model linearised at full deployment (`modes3d.locked_modes`) '
              'against a frame assembled in global coordinates from the textbook 12-coordinate '
              'beam element (Przemieniecki 1968, stiffness Eq. 5.116, consistent mass '
              'Eq. 11.32), its hinges as multi-point constraints (tests/test_umbrella3d_modes.py).'
              ' Both use the same shape functions, so on one mesh they agree to round-off: this '
              "checks the floating frames, the joints and the rib's orientation. Rib 0, "
              "two elements a segment; the kind is where the mode's strain energy is.", '',
              '| mode | kind (in-plane / out-of-plane bending / twist share) | floating frames '
              '(Hz) | 3D frame (Hz) | relative difference |', '|---|---|---|---|---|']
    n = 2
    model = UmbrellaModel3D(UmbrellaRibsParams.from_mapping({'elements_per_segment': n}))
    omega, _, labels = locked_modes(model)
    ref = rib_frame(UmbrellaParams(elements_per_segment=n), n).modes()
    for i in range(8):
        lab = ' / '.join(f'{x:.2f}' for x in labels[i])
        lines.append(f'| {i + 1} | {lab} | {omega[i] / 2 / math.pi:.3f} | '
                     f'{ref[i] / 2 / math.pi:.3f} | {abs(omega[i] / ref[i] - 1):.1e} |')
    worst = np.max(np.abs(omega / ref - 1))
    cant, (bend, _), torsion = cantilever_check()
    lines += ['', f'All {len(omega)} modes: largest relative difference {worst:.1e}. The frame '
              'element itself against published formulas (a 1 m cantilever, 16 elements): '
              f"first bending {cant[0]:.4f} rad/s against Blevins's λ₁ = 1.87510, "
              f'{bend:.4f} rad/s ({abs(cant[0] / bend - 1):.1e}); first torsion of the '
              f"clamped-free shaft π/2L √(GJ/ρI_p) = {torsion:.1f} rad/s, the frame's nearest "
              f'{cant[np.argmin(np.abs(cant / torsion - 1))]:.1f} rad/s.', '']


# ------------------------------------------------------------------ (c)
def section_c(lines, pyplot) -> str:
    """Add (c); return its balance figures for the accuracy table."""
    progress('(c) energy and momentum')
    rec = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(ASYMMETRIC)).run(0.2)
    a, s = rec.arrays(), rec.summary()
    values = dict(ASYMMETRIC, base='free', bus_mass=5.0, bus_inertia=0.2)
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values), tolerance=1e-12)
    fr = sim.run(0.2)
    b, sb = fr.arrays(), fr.summary()
    driven = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        dict(ASYMMETRIC, base='prescribed', **DRIVE))).run(0.2)
    c, sc = driven.arrays(), driven.summary()
    rib_mass = sim.model.total_mass - sim.model.bus_mass - sim.model.sleeve_mass
    mv = rib_mass * np.max(np.abs(b['sleeve_velocity']))
    mvl = mv * (sim.params.planar.l1 + sim.params.planar.l2)
    dp = np.max(np.abs(b['linear_momentum'] - b['linear_momentum'][0]))
    dh = np.max(np.abs(b['angular_momentum'] - b['angular_momentum'][0]))
    lines += ['## (c) Energy and momentum', '',
              "Three ribs, rib 1's hinge with Coulomb (0.3 N m) and viscous (0.05 N m s) "
              'friction, rib 2 kicked out of its plane (0.2 m/s at the tip), a 50 g tip mass on '
              'rib 0; sleeve force 10 N a rib, 0.2 s (through the lock). The balance is '
              'T + V − (T + V)(0) − W_sleeve − W_friction + lock loss.', '',
              '| base | lock | largest T + V (J) | balance residual (J) | friction work (J) | '
              'lock loss (J) | linear momentum drift / m v | angular momentum drift / m v L |',
              '|---|---|---|---|---|---|---|---|',
              f"| fixed | energy | {s['energy_scale']:.3f} | {s['energy_balance_residual']:.1e}"
              f" | {np.sum(s['friction_work']):.4f} | {a['lock_energy_loss'][-1]:.1e} | – | – |",
              f"| free (5 kg, 0.2 kg m²) | plastic | {sb['energy_scale']:.3f} | "
              f"{sb['energy_balance_residual']:.1e} | {np.sum(sb['friction_work']):.4f} | "
              f"{b['lock_energy_loss'][-1]:.4f} | {dp / mv:.1e} | {dh / mvl:.1e} |",
              f"| driven (X jolt, Y spin-up) | energy | {sc['energy_scale']:.3f} | "
              f"{sc['energy_balance_residual']:.1e} | {np.sum(sc['friction_work']):.4f} | "
              f"{c['lock_energy_loss'][-1]:.1e} | – | – |", '',
              'The driven base (20 m/s² along X for 20 ms from 20 ms, spun up to 3 rad/s about '
              f"Y in 50 ms) does {c['drive_work'][-1]:.3f} J of work, counted in the balance "
              "as the drive joints' multipliers times the bus's displacement and the "
              "velocity projection's impulse on the bus times its mean velocity. There the "
              "velocity is projected but not scaled to the balance (the bus's rates are "
              "prescribed): the residual is what the projection onto the ribs' joints changes "
              "(1e-8 of T + V up to 80 ms, tests/test_umbrella3d.py; more in stage 2's "
              "vibration), and the energy lock, which keeps each rib's kinetic energy in its "
              'own velocities, changes the whole energy by the lock-loss column.', '',
              "The step keeps its discrete energy balance (the velocity scaled to the balance's "
              'kinetic energy, as the planar integrator) and the linear momentum exactly (a '
              'cyclic coordinate; projection and scaling act relative to the mass centre). The '
              "midpoint discrete gradient keeps the angular momentum only to the Newton solve's "
              'error: this run uses a Newton tolerance of 1e-12 (the tests assert 1e-8 before '
              'the lock, 1e-6 through it, relative to m v L).', '']
    fig, ax = pyplot.subplots(1, 2, figsize=(10, 3.6))
    t = a['time']
    e = a['kinetic_energy'] + a['strain_energy']
    ax[0].plot(t, e - e[0], label='T + V − (T + V)(0)')
    ax[0].plot(t, a['work'], '--', label='sleeve work')
    ax[0].plot(t, a['friction_work'].sum(1), label='friction work')
    ax[0].set(xlabel='t (s)', ylabel='J', title='fixed hub: energy')
    ax[0].legend()
    tb = b['time']
    ax[1].semilogy(tb[1:], np.abs(b['linear_momentum'] - b['linear_momentum'][0]).max(1)[1:]
                   / mv + 1e-20, label='|ΔP| / m v')
    ax[1].semilogy(tb[1:], np.abs(b['angular_momentum'] - b['angular_momentum'][0]).max(1)[1:]
                   / mvl + 1e-20, label='|ΔH| / m v L')
    ax[1].axvline(sim.lock_time, color='grey', lw=0.5)
    ax[1].set(xlabel='t (s)', title='free bus: momentum drift')
    ax[1].legend()
    lines += [save(fig, 'balance.png'), '']
    return (f"{s['energy_balance_residual']:.1e} J of {s['energy_scale']:.1f} J; "
            f"{sc['energy_balance_residual']:.1e} J of {sc['energy_scale']:.0f} J driven")


# ------------------------------------------------------------------ (d)
def section_d(lines, pyplot):
    try:
        from tests.test_umbrella3d_multibody import mujoco_run, umbrella_run
    except Exception as exc:          # pytest.importorskip raises its own exception type
        lines += ['## (d) An asymmetric deployment against MuJoCo', '',
                  f'Not generated: the MuJoCo comparison could not be imported '
                  f'({type(exc).__name__}: {exc}).', '']
        return
    progress('(d) the asymmetric deployment against MuJoCo')
    marks = tuple(np.round(np.arange(0.002, 0.158, 0.002), 6))
    t_ref, ref = mujoco_run(UmbrellaParams(), marks=marks)
    t_lock, ours = umbrella_run(marks=marks)
    lines += ['## (d) An asymmetric deployment against MuJoCo', '',
              "Three ribs on a free-floating bus (5 kg, 0.2 kg m²); rib 1's hinge stiff "
              '(Coulomb 0.2 N m, viscous 0.05 N m s), a 50 g tip mass on rib 0; sleeve force '
              '10 N a rib. The reference is MuJoCo (Todorov, Erez & Tassa, IROS 2012; PyPI '
              '`mujoco`): rigid leaves and links in a kinematic tree under a free joint, each '
              "link's end tied to the sleeve by a `connect` equality, the friction as the "
              "joints' `damping` and `frictionloss`, RK4 at 10 µs. The umbrella model's ribs "
              'are 100 times stiffer than the default, nearly rigid (tests/'
              'test_umbrella3d_multibody.py).', '',
              '| figure | MuJoCo (rigid) | umbrella3d | difference |', '|---|---|---|---|',
              f'| lock instant (s) | {t_ref:.7f} | {t_lock:.7f} | {abs(t_lock - t_ref):.1e} |']
    for mark in (0.05, 0.1):
        (y_r, x_r, r_r), (y, x, r) = ref[mark], ours[mark]
        lines += [f'| sleeve on the bus at {mark} s (m) | {y_r:.6f} | {y:.6f} | '
                  f'{abs(y - y_r):.1e} |',
                  f'| bus X at {mark} s (mm) | {1e3 * x_r[0]:.5f} | {1e3 * x[0]:.5f} | '
                  f'{abs(x[0] / x_r[0] - 1):.1e} rel. |',
                  f'| bus Y at {mark} s (mm) | {1e3 * x_r[1]:.4f} | {1e3 * x[1]:.4f} | '
                  f'{abs(x[1] / x_r[1] - 1):.1e} rel. |',
                  f'| bus turn about Z at {mark} s (rad) | {-r_r[0, 1]:.6f} | {-r[0, 1]:.6f} |'
                  f' {abs(r[0, 1] / r_r[0, 1] - 1):.1e} rel. |']
    t_dref, dref = mujoco_run(UmbrellaParams(), driven=True)
    t_dlock, dours = umbrella_run(driven=True)
    lines += [f'| driven base: lock instant (s) | {t_dref:.7f} | {t_dlock:.7f} | '
              f'{abs(t_dlock - t_dref):.1e} |']
    for mark in (0.05, 0.1):
        y_r, y = dref[mark][0], dours[mark][0]
        lines.append(f'| driven base: sleeve on the bus at {mark} s (m) | {y_r:.6f} | {y:.6f} |'
                     f' {abs(y - y_r):.1e} |')
    lines += ['', 'The driven base: the same ribs on a base jolted along X (20 m/s² for 20 ms) '
              "and spun up to 3 rad/s about Y, the umbrella's base following the prescribed "
              "motion, MuJoCo's a 10⁶ kg body driven by the forces of that motion (the ribs' "
              'reactions leave its motion the prescribed one to 1e-6).']
    fig, ax = pyplot.subplots(1, 3, figsize=(12, 3.4))
    ts = [m for m in marks if m in ref and m in ours]
    for i, (title, get) in enumerate((('sleeve height on the bus (m)', lambda v: v[0]),
                                      ('bus X (mm)', lambda v: 1e3 * v[1][0]),
                                      ('bus turn about Z (rad)', lambda v: -v[2][0, 1]))):
        ax[i].plot(ts, [get(ref[m]) for m in ts], 'k-', lw=2.5, alpha=0.4, label='MuJoCo')
        ax[i].plot(ts, [get(ours[m]) for m in ts], 'r--', label='umbrella3d')
        ax[i].set(xlabel='t (s)', title=title)
    ax[0].legend()
    lines += ['', save(fig, 'mujoco.png'), '']


# ------------------------------------------------------------------ (e)
def section_e(lines, pyplot):
    progress('(e) mesh convergence')
    res = {}
    for n in (1, 2, 4, 8, 16, 32):
        omega, _, labels = locked_modes(UmbrellaModel3D(UmbrellaRibsParams.from_mapping(
            {'elements_per_segment': n})))
        labels = np.array(labels)
        res[n] = [omega[labels[:, kind] > 0.5][0] / 2 / math.pi for kind in (1, 2, 0)]
    lines += ['## (e) Convergence with the mesh', '',
              'Lowest locked frequencies (Hz) by kind; the observed order is log₂ of the ratio '
              'of successive differences (Strang & Fix 1973, ch. 6: h⁴ for the cubic bending '
              'element with consistent mass, h² for the linear twist element); the order in row n '
              'is that of the meshes n/4, n/2, n. The twist-dominated modes are told apart '
              'from 8 elements a segment on (below, the lowest twist-dominated mode is not the '
              'same mode from mesh to mesh); their row 32 gives the order 2 of the element, '
              "and 2871.2 Hz is 1.00003 times the clamped-clamped shaft's π/L √(GJ/ρI_p) "
              '(Blevins), L = 0.5 m: a segment held in twist at both ends, from above as a '
              'displacement model converges; extrapolated at the order 2, 2870.1 Hz, 0.9996 '
              "times it: just below, its end at O'' held elastically.", '',
              '| elements a segment | out-of-plane bending | order | twist | order | in-plane '
              'bending | order |', '|---|---|---|---|---|---|---|']
    ns = sorted(res)
    for i, n in enumerate(ns):
        cells = []
        for kind in range(3):
            order = '–'
            if 2 <= i:
                a, b, c = (res[ns[j]][kind] for j in (i - 2, i - 1, i))
                order = f'{math.log2(abs(a - b) / abs(b - c)):.2f}'
            cells += [f'{res[n][kind]:.4f}', order]
        lines.append(f'| {n} | ' + ' | '.join(cells) + ' |')
    progress('(e) a lateral jolt on 1, 2, 4 elements')
    tips, series = [], []
    for n in (1, 2, 4):
        sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({
            'ribs': 2, 'sleeve_force': 10.0, 'time_step': 5e-5, 'elements_per_segment': n,
            'base': 'prescribed', 'base_accel_z': 50.0, 'base_accel_duration': 0.01,
            'rib1.hinge_coulomb': 0.3}))
        a = sim.run(0.03).arrays()
        tips.append(a['tip'][-1, 0, 2])
        series.append((n, a['time'], a['tip'][:, 0, 2]))
    lines += ['', 'A lateral jolt during the deployment (two ribs, the base accelerated along Z '
              "by a 10 ms half-sine of 50 m/s², step 50 µs): rib 0's out-of-plane tip "
              'deflection 30 ms in (mm):', '', '| elements a segment | w_tip (mm) | difference '
              'to the next mesh |', '|---|---|---|']
    for i, n in enumerate((1, 2, 4)):
        diff = f'{1e3 * abs(tips[i] - tips[i + 1]):.4f}' if i < 2 else '–'
        lines.append(f'| {n} | {1e3 * tips[i]:.4f} | {diff} |')
    fig, ax = pyplot.subplots(figsize=(6, 3.4))
    for n, t, w in series:
        ax.plot(t, 1e3 * w, label=f'{n} element(s) a segment')
    ax.set(xlabel='t (s)', ylabel='mm', title='rib 0: out-of-plane tip deflection')
    ax.legend()
    lines += ['', save(fig, 'mesh.png'), '']


#: the page's first table: each check, its reference, the agreement and where it is shown
ACCURACY = [
    ('N identical ribs from a symmetric start',
     'the planar model',
     '1.8e-11 m at most (1e-10 asserted) with the same Newton steps; 4.7e-6 m of 62 mm at '
     'the defaults (a kept iteration matrix)',
     '(a)'),
    ('locked frequencies: out-of-plane bending, torsion',
     "a 3D frame assembled independently; Blevins's cantilever",
     '4.2e-11; 4.5e-6',
     '(b)'),
    ('energy with hinge friction; momentum on a free bus; a driven base',
     'the balances',
     '{balance}',      # (section_c's figures)
     '(c)'),
    ('deployment with a stiff hinge on a free bus and on a driven base',
     'MuJoCo, rigid ribs (ours 100 x stiffer)',
     'lock instant 2-4 us, bus motion 1e-4 relative: the kinematics and the bus coupling, '
     'not the flexibility',
     '(d)'),
    ('the mesh',
     'the model itself',
     "order 4 in bending (the twist's settles to 2)",
     '(e)'),
    ('a fast deployment (V0 = -1) with an offset tip mass, fixed hub and free bus',
     "Exudyn's geometrically exact beams",
     '`flexible-nonlinear`: deploy time 0.03 %, tips within 0.9 % (histories 1.3 %), '
     'stage-2 amplitudes 2.2 %; `flexible`: out-of-plane tip +36 %, in-plane +45 %',
     'docs/umbrella3d_nonlinear.md'),
]


def accuracy_table(balance: str) -> str:
    """Return ACCURACY as a markdown table, with section_c's balance figures."""
    lines = ['| what | checked against | agreement | where |', '|---|---|---|---|']
    rows = ['| ' + ' | '.join(row).replace('{balance}', balance) + ' |' for row in ACCURACY]
    return '\n'.join(lines + rows)


HEADER = """# The whole umbrella in 3D: N flexible ribs on one sleeve

`umbrella_sim.core.umbrella3d` simulates N ribs at azimuths 2πk/N about the hub axis Y (N
counts ribs here, `ribs`; the planar pages' N, docs/validation.md, counts elements a segment,
here "elements a segment", `elements_per_segment`), all driven by one sleeve, with per-rib
asymmetry (section, material, lengths, tip mass, hinge friction, a hinge stuck until a time or
a torque, initial perturbations) and a hub that is fixed, driven (a lateral acceleration pulse,
a spin-up) or a free-floating bus. Rib k is the planar model of Hu (McGill, 2006) in its own
plane, every beam a 3D Euler–Bernoulli body with St-Venant torsion in the thesis's floating
frames (Shabana, *Dynamics of Multibody Systems*, 3rd ed., ch. 5; element of Przemieniecki,
*Theory of Matrix Structural Analysis*, 1968, and Cook, Malkus, Plesha & Witt, *Concepts and
Applications of FEA*, 2002). The hinges hold the roots' out-of-plane displacement, slope and
twist; a stuck one clamps its root (alpha1 and the root's slope: its holding torque is the
root's moment), and a hinge's friction acts on the leaf's chord angle alpha1; at O'' the two
hinge axes stay parallel. The step is the planar energy-consistent
midpoint scheme (Gonzalez's discrete gradients, J. Nonlinear Sci. 6, 1996) on block-arrow
linear algebra: one shared sleeve (and bus) couples the ribs only through a few unknowns, so a
step costs linearly in the number of ribs (bench/bench_umbrella3d.py). The lock acts on the
sleeve, plastic or energy (rib by rib, the thesis's §5.2.2); on a free bus `lock: auto` is
plastic (the energy lock would change the momentum).

## Using it

On the node, `python3 bootstrap.py run -p ribs:=6` (or `umbrella_node --ros-args -p ribs:=6`):
joint_states name `rib<k>/leaf_hinge`, `rib<k>/link_hinge` (k from 0) and `sleeve_slider`,
and `rib_tip_deflection` / `rib_peak_stress` carry each rib's tip and stresses
(msg_docs/topic_ribs.md). Offline, `umbrella_sim simulate --set ribs=6` (its deployed
frequencies, without a run: `umbrella_sim modes --set ribs=6`; spinning, with `--set
base=prescribed --set base_spin_rate=10`: the rotating frame's about the spun equilibrium,
umbrella_sim/core/umbrella3d/spun_modes3d.py); from Python,
`from umbrella_sim.core import UmbrellaRibsParams, UmbrellaSimulator3D, simulate`, then
`simulate(UmbrellaRibsParams.from_mapping({'ribs': 6}), 0.5)` for a whole run or
`UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({'ribs': 6}))` to step it. A rib's own
values are lists, one value a rib (`-p "rib.tip_mass:=[0.0, 0.1, 0.0, 0.0, 0.0, 0.0]"`), or
`rib<k>.<name>` overrides in a parameters file or `--set`: msg_docs/umbrella3d_parameters.md.
examples/test_umbrella_ribs.py tests an asymmetric deployment (a sticking hinge) through the
test API over DDS. What it costs, and how close to real time it runs: the last section.

{asymmetry}

## Which model, and how accurate

Every check is against another model: the planar model (itself checked against the thesis's
simulations: docs/validation.md), an independently assembled frame, MuJoCo, Exudyn. None is
against hardware.

{accuracy}

Which to take: `model: flexible` (the default: linear beams in each body's floating frame)
is the planar model for identical ribs, with the planar model's range: small
deformations in each body's frame. A fast deployment leaves it as the planar model's does
(docs/validation_nonlinear.md: in stage 1 a leaf's centrifugal tension stiffens it, which
the linear beams lack; from V0 = -1 m/s the links buckle in stage 2), and the ribs'
out-of-plane figures follow their in-plane ones: in the Exudyn case (V0 = -1, a 0.1 kg tip
mass on rib 1) `flexible` is 35 % off out of plane and 46 % in plane, the same at a tip-mass
offset of 5, 10, 20, 35, 50 or 70 mm (0.007 to 0.093 rad of out-of-plane rotation; measured
against `flexible-nonlinear`, 2 elements a segment, 25 us). It says so in stage 1:
'centrifugal stiffening' (the planar model's rule on each rib's leaf) warns once a leaf's
centrifugal tension at its hinge passes 2.5 % of its Euler load (on a spinning base, its hinge
rate's and the spin's: summary.leaf_tension_ratio; at V0 = -0.2 a base spun up over 0.05 s
warns from about 7.5 rad/s); rib 1's is 41 % from the
start, said after the first chunk (1.6 ms; the lock at 44.5 ms), where the other warnings
wait for the lock (its in-plane tip stays at 5.6 % of the leaf, below the 10 % of 'large
deflection'; 2.5 x yield and a 39 % tip deflection come in stage 2). In stage 2 the
planar model's 'axial load' rule judges each rib (its largest axial stress times its area
over its link's Euler load, limit 25 %: the linear beams leave out the geometric stiffness
that load brings into the link's bending; docs/validation_nonlinear.md): the default run's
ribs reach 157 % and say so at the lock, as the planar run does. For such runs (V0 of
about -0.3 m/s or faster with the thesis's data, a heavy tip, a jolt or spin of the base;
the calibration: docs/validation_nonlinear.md, "Where the linear model leaves its range"),
take `model:
flexible-nonlinear`, the co-rotational ribs (docs/umbrella3d_nonlinear.md: each rib's beams
co-rotational, the planar element in the rib's plane, out-of-plane bending and torsion
small rotations in its co-rotated frame; compiled too), at 1.2-1.8 times the cost a step
(6 ribs x 1 element, 0.1 ms). It has no stage-2 mode fit: at its default 0.1 ms its
stage-2 peak stresses are not resolved, and its 'coarse step' warning names the step that
resolves them (`step_follows_mesh` takes it, at a multiple of the cost).

## The model's details

The umbrella's stages take the planar model's steps: where the step is chosen for the run
(`time_step` 0, or `step_follows_mesh`: step_rule.follows_lock of the planar record),
stage 1 (the deployment) steps on a 0.2 ms grid at 1 and 2 elements a segment
(step_rule.STAGE1_STEP_CEILING, STAGE1_FINEST_MESH: its figures do not need the stage-2
step; finer meshes, and a driven base that moves, keep the mesh's step, a drive setting
the modes vibrating before the lock) and stage 2 takes the mesh's step as
substeps of it (step_rule.stage2_step_of: 2 of 0.1 ms at 1 element, 6 of 33 us at 2); a
lock whose stage-2 tip deflection passes 7 % of the leaf (the modes' coupling,
docs/validation.md, amplitude) divides the mesh's step further
(step_rule.stage2_step_needed and stage2_substeps_for, the planar engine's rule). The umbrella
judges it at the lock on each rib's in-plane state, mapped onto the planar model of the
rib's own planar record (umbrella_sim/core/umbrella3d/substeps3d.py: its locked modes'
amplitudes, the tip crest they add up to, the stress shares the step leaves), and takes the
worst rib's (the smallest step needed; on a tie the rib deflected most): N identical ribs
take the planar model's substeps and stay each the planar model at `time_step` 0
(tests/test_umbrella3d_substeps.py: 3 ribs at 10 N a rib, 6 physics steps a 0.2 ms grid
step, within the identity's 1e-10). The rule reads the in-plane modes only; the ribs'
out-of-plane and torsion modes take the mode fit at the step the in-plane ones need. The
numpy step takes a grid step's physics steps one by one (`UmbrellaSimulator3D.step`), the
compiled advance k of them per grid step in one call; either way Record3D keeps one row a
grid step, its last physics step's figures with each stress channel's largest over its
physics steps (each physics step's Hermite crest; substeps3d.fold_substeps3d, the planar
outputs.fold_substeps' rule, which the compiled advance applies itself: Advance3DCall.fold).
From one locked state (4 asymmetric ribs, V0 = -0.5, 10 physics steps a grid step) the two
paths' 40 grid rows agree within the numpy reference's own ulp spread on every base, with
the same Newton iterations (tests/test_umbrella3d_substeps.py). Every physics step's tip
deflections are kept apart from the rows (Advance3DCall.tips; Record3D.taken_tips, on both
paths, alike to the same spread), and each rib's stage-2 amplitude and period in the summary
are of them, not of the grid rows: on a 5 ms grid (step_follows_mesh, 50 substeps, three ribs
at V0 = -0.05) they are the 0.1 ms grid's to 1.5e-4 and 1e-7, the period 2.5e-5 from the
locked frame's first mode's, where the grid rows' amplitude was 0.9 % low and their period
2e-4 off (tests/test_stage2_substep_figures.py).
With a `time_step` given, stage 2 stays on it and its summary's 'coarse step' (the lock's
worst rib, judged at the step stage 2 takes) names the `time_step` that resolves it; the
node, the driver and replay pin the physics step by the planar model's rule
(`with_physics_step(step, follows_lock)`), so a recording made at `time_step` 0 is
re-simulated with its substeps. The co-rotational ribs (`flexible-nonlinear`) take none, as
the planar model. Stage 2 then costs about k times as much: ribs 6 x 1 at 10 N a rib (3
substeps of the 0.1 ms grid stage 1 then took too) 1.74 CPU s a simulated second of stage
2 against 0.61 on the 0.1 ms grid step alone,
12 x 2 (2 substeps of 33 us) 14.3 against 7.7 (compiled, Record3D's figures included, best of
two 20 ms runs at load ~5.4 on the 2 cores); the fit's modes refitted at the lock took 2-5 ms
(56 ms for a free bus at 12 x 2).

The 3D beams take the planar model's structural damping (`damping_ratio` ζ, model
`flexible`; umbrella_sim/core/umbrella3d/damping3d.py): stiffness-proportional Rayleigh
(Kelvin–Voigt) damping of every strain rate, axial, both bendings and the twist, C = βK over
each rib's elastic coordinates, its force −C dq/h in the midpoint step (h/2 C in the
iteration matrix), so a step dissipates exactly dq·C dq/h ≥ 0, which the step's energy
target takes off and the record carries (`damping_dissipation`: the `energy` topic, the
summary, the CSV; the energy balance adds it back). One β for the umbrella, 2ζ/ω1 with ω1
the first mode of its planar rib (the planar record's) locked at full deployment
(nonlinear.damping_beta_of, the planar model's one definition), not the umbrella's own first
locked mode: C = βK is the material's property, which every rib shares, and the planar rib's
ω1 is what makes N identical damped ribs each the damped planar model (within 1e-10, 3 ribs,
ζ = 0.05, the mode fit and stage 2's substeps included; N times its dissipation). The
umbrella's own first locked mode is out of plane (rib 0 of the default: 70.6 rad/s against the
in-plane ω1 = 133.7 rad/s): taking it would damp the deployment's dominant in-plane mode at
1.9ζ. Each rib's first in-plane mode then decays with exactly ζ (measured by the logarithmic
decrement over six periods: 0.0500000003 for ζ = 0.05 with the mode fit, 0.0499985 without,
whose midpoint rule scales a ratio by sin(Ωh)/(Ωh), Ωh = 2 arctan(ωh/2) its turn a step:
1 − 3·10⁻⁵ here), its out-of-plane ones with ζω_i/ω1
(0.0263863 measured, 0.0263863 expected). Stage 2's mode fit takes each mode's damping
φᵀCφ (integrators.LockedModeFit: exact decay a step), rib by rib or the free bus's whole
system. Compiled in _kernel3d_damping.h (the step and the moving base's step; equal to the
numpy reference within its ulp spread, on every base); the energy balance closes to 1e-10 of
T + V with the dissipation (tests/test_umbrella3d_damping.py). The co-rotational ribs
(`flexible-nonlinear`) damp their co-rotated strain rates with the same β, C(q) = βBᵀDB at
the step's midpoint, as the planar flexible-nonlinear model (docs/umbrella3d_nonlinear.md).

A moving base now takes the stage-2 mode fit too (umbrella_sim/core/umbrella3d/stage2fit.py,
tests/test_umbrella3d_base_fit.py), hence the fixed hub's step (0.1 ms at 1 element, 33 us at
2). A driven hub's ribs are fitted rib by rib in the hub's frame (their locked modes are the
fixed hub's there; the drive is a base excitation the midpoint rule integrates; with the drive
zero a run is the fixed hub's to the two steps' difference, 1.5e-8 m at the tips 20 ms
past the lock at Newton tolerance 1e-12, tests/test_umbrella3d_base_fit.py; at the default
tolerance they differ by Newton's error too, 2.6e-7 m at 20 ms and 4.5e-6 m at 0.17 s). A free bus
couples the locked ribs, so its fit is of the whole free system's elastic modes (bus + locked
ribs, modes3d.free_locked_modes: the six rigid-body modes left out, each elastic mode without
linear or angular momentum, so the scheme's momentum of the bus's coordinates is the physical
one), linearised at the bus's attitude at the lock: a free mode alone turns at the
eigenproblem's frequency (Prony, 1e-7) with its amplitude (1e-6), T + V and the linear momentum
kept to round-off, the angular momentum to the Newton tolerance; with a 5 kg bus the modes that
move it are up to 25 % stiffer than a rib's on a fixed hub, which a rib-by-rib fit would leave
off. Measured (bench/bench_umbrella3d.py --base, ribs 6 x 1, CPU time, load ~5 on the 2 cores;
before / after): the compiled step alone, driven 94.7 / 106.5 us deploying and 96.9 / 128.1 us in
stage 2, free 93.0 / 92.4 and 93.5 / 165.9 us (the whole fit's dense maps, 84 modes of 145
coordinates, about 70 us of it); CPU s a simulated second in 1 ms blocks with Record3D's
figures, driven 3.9 / 1.6 deploying and 4.0 / 1.8 in stage 2, free 3.6 / 1.7 and 3.7 / 2.6
(hub fixed 0.7 and 0.9-1.2). The free system's whole fit was dense: its cost grew as the square
of the ribs (12 x 2 at 33 us: 372 modes of 499 coordinates, 1.22 ms a stage-2 step against 0.42
unfitted; the driven hub's 0.51; ribs x 1 at 0.1 ms, the compiled step alone in stage 2, load
~3.3: 6 / 12 / 24 ribs 170 / 482 / 1581 us on the free bus, 49 / 97 / 193 us with the hub
fixed, whose cost a rib stays 8.0 us). The fitted stage 2 at 0.1 ms against the same code
converged (2.5 us, no fit), tips in and out of plane 0.1 s past a plastic lock at V0 = -0.5 (3
ribs, a tip mass, a kicked rib; times from each run's lock): free bus (5 kg) 1.27 mm, driven
1.17 mm (hub fixed 0.96 mm) of 195 / 140 mm amplitude, where the unfitted 33 us step the moving
bases took before gave 4.07 / 2.46 mm (2.38) and 0.1 ms unfitted 7.4 / 5.2 mm (5.22)
(tests/test_umbrella3d_base_fit.py, slow).

The free bus's fit is no longer dense: it is each rib's own fit (its clamped modes, as on a
fixed hub) composed with a correction of low rank, S = S_ribs S_bus with S_bus = S_ribs⁻¹
S_whole = I + ABᵀ (stage2fit.BusFit; the Newton update and a damped fit's damping share
corrected the same way): the two fits differ only where the bus takes part, 18 to 34
singular values above 1e-10 at 3 to 24 ribs, identical or each with its own tip mass, where
the whole fit has 14 modes a rib. Its maps are the whole fit's to 1e-11 and a run from one
lock is the same to 1e-12 m at the tips over 0.3 s, with the same Newton iterations
(tests/test_umbrella3d_base_fit.py), so every figure above holds at any bus. The ribs' fits
alone, without the correction, keep the momentum (their U has nothing on the bus's rows) and
T + V, but not the free modes' phase: at the default bus (100 kg, 10 kg m²; ribs of 0.42 kg)
the free modes' frequencies are off by up to 8.4e-4 (6 ribs: the pair at 10 301 rad/s,
ωh = 1.03, 1.7 % stiffer than a clamped rib's mode, 4.3 rad over 0.5 s; 1e-5 below
4 000 rad/s; the unfitted rule 7.7e-2, the whole fit 1e-11), with a 5 kg bus by 1.8e-2. In the
run (0.3 s past a plastic lock at V0 = -0.5 at 0.1 ms, from one post-lock state, against the
unfitted scheme at 1.56 us, which the whole fit at 6.25 us meets within 0.07 mm; the largest
tip error, in or out of plane), ribs' fits alone / whole fit / unfitted: default bus, 6
identical ribs 1.15 / 1.24 / 8.72 mm of 128 mm amplitude; 6 ribs, a tip mass and a kicked rib
2.06 / 1.94 / 8.62 mm of 143 mm (the bus's attitude 1e-5 rad off either way); a 5 kg bus
(0.2 kg m²), 6 ribs 14.5 / 6.31 / 17.1 mm of 183 mm (the bus's rate 3.7 / 1.3 / 5.2 rad/s off,
of 4.7) and 3 ribs 5.11 / 3.60 / 8.37 mm of 211 mm. The ribs' fits alone would do for a heavy
bus (ribs a fortieth of its mass), not a light one; with the correction the fit is the whole
system's at any bus. Its cost is linear in the ribs: the compiled step alone in stage 2, ribs
x 1 element at 0.1 ms, 6 / 12 / 24 ribs 131.7 / 263.5 / 530.9 us (22.0 us a rib) against the
whole fit's 151.9 / 417.2 / 1164.1 us (25.3 / 34.8 / 48.5 a rib), the hub fixed 47.5 / 95.1 /
190.5 us (7.9 a rib) (interleaved, best of 2 x 3, load 1.2-2.5). Of the free bus's 22 us a rib
the fit takes 4.6 (unfitted stage 2 105 / 209 / 419 us), the rest is the bus's own step (its
border of M(q), its gradient, the seven shared coordinates: 15 us a rib deploying). A moving
base's fitted stage 2 converges as the fixed hub's: at 12 x 2 its lock takes stage 2 in two
substeps of 16.7 us (the grid's 33 us; substeps3d.py), each 2.03 Newton iterations (driven) /
2.04 (free) and 0.125 factorisations, the hub fixed 2.20 at 33 us; at 6 x 1 driven 2.85 (two
substeps of 50 us), free 2.79, fixed 2.81. The compiled step alone there: 446 / 460 us a
substep (26.7 / 27.6 CPU s a simulated second), the hub fixed 171 us a step (5.1) (interleaved,
best of 3 x 1000 steps, load 1.1-2.2): what remains is a moving base's own step, 2.6 times
the fixed hub's at the same iterations. The 4.7-4.9 iterations and 0.31-0.32 factorisations a
step measured before (and 0.85 ms a step) were bench/bench_umbrella3d.py stepping stage 2 at
the grid's 33 us with the fit and Newton tolerance made for the substep, where the compiled
step's Newton shrinks were the fit's own step's: each mode's d / (block + d), block 1 +
(omega h)^2 / 4, is the step's (the numpy reference's newton_update took it so), and at twice
the fit's step the second update contracted by 0.12 instead of 0.007 (6 x 1, driven), past
the refresh rate 0.1 (5.7 iterations, 2.65 factorisations a step against 3.0 and 0.13). The
compiled steps take the step's shrinks now, the planar one too (a step within 1e-9 of the
fit's takes the fit's: SAME_STEP; at the grid's step 2.33 / 2.29 at 12 x 2; the bench steps
the run's substep), the runs the same to Newton's tolerance (the lock's part steps are
the only ones a run takes at a step other than its fit's; through the lock and 300 steps past
it, the tips before and after within 1.5e-6 of their amplitude at 6 x 1, each as far from a
run at Newton tolerance 1e-13, 3.6e-9 at 12 x 2; the energy balance and a free bus's momenta
as before). Not the cause: the iteration matrix's rib-bus blocks without the fit (M_rs where
the fitted tangent has S^T M_rs, M_sr for M_sr S): put in with the shrinks (U diag(s - 1)
Phi^T M_rs and M_sr Phi diag(s - 1 - s shrink) U^T added; the numpy step, driven hub, 6 x 1),
every one of 200 steps took the same iterations (the drive holds the bus; the shared rows feed
only its multipliers), and a free bus at its fit's step converges as the fixed hub already.

Where a moving base's 2.6 x went (perf record -g of the compiled step alone in stage 2, at
the step the run takes, the kernel built without inlining so each function keeps its
samples; shares of the samples and us a step). Both steps make the same calls: per Newton
iteration (2.03 driven / 2.04 free at 16.7 us, 2.20 fixed at 33 us at 12 x 2) one M(q), one
kinetic gradient, one arrow solve, two M v and three of the fit's maps; per step one more
M(q), the projection's factorisation and solve, 0.125 fresh Newton factorisations. Each is
dearer with the base. 12 x 2, free bus 565 us / hub fixed 208 us: the base's point loops
(base_mass_matrix, 3.0 a step, and base_kinetic_gradient, 2.0, with their cross products:
every Gauss point of both bodies of every rib, 31 a rib at 2 elements) 37 % / 210 us, where
the fixed hub's M(q) and gradient come from the inertia invariants (7.5 % / 16 us): 54 % of
the difference; the arrow algebra 28 % / 156 us against 28 % / 59 us, 27 % of the difference
(each factorisation, 1.125 a step, solves every rib's block for the six bus columns of M_rs
where the fixed hub's one column, J_rs = -1, needs the joints' rows only, and subtracts a 7 x
7 Schur block a rib: ef_solve 70 against 28 us); the fit's maps 74 against 58 us (the bus's
low-rank correction); M v with the border 34 against 14 us. Driven hub alike (point loops 38
%, arrow 29 %); at 6 x 1 free 169 / fixed 58 us: point loops 31 % (16 points a rib), arrow 28
% / 47 us against 30 % / 17 us. Two removals, states and Newton iterations bit for bit the
same (6 x 1 and 12 x 2, every base, to the lock and 300 steps past it): the point loops sum
y = x + S e, S a, S b and S^T U over each point's span of nonzero shape columns (one element's,
6-10 of a body's 24 at 2 elements; Base3D.span) instead of all of them, and the projection's
arrow solve skips the bodies' solves of its zero top as the fixed hub's does. The compiled
step alone in stage 2 (interleaved with the build before, best of 3 x 3 x 1000 steps, load
1.2-1.6): 12 x 2 free 458.7 -> 415.9 us a substep, driven 430.7 -> 389.3 (2.44 / 2.28 times
the fixed hub's 170.4, unchanged); 6 x 1 free 131.7 -> 127.3, driven 122.0 -> 117.0 (fixed
47.2). Solving the six bus columns as one six-column solve moved them 3-5 %, as much as the
fixed hub's step moved, whose arithmetic it leaves alone (load 3): not kept. What is left is
the point loops' own arithmetic (sum w s s^T and the angle's column of M_rs, the gradient's
point sums): taken from inertia invariants, as the fixed hub's M(q) and gradient are (16 us
a step at 12 x 2), a reformulation whose round-off differs from the numpy reference's point
sums (not measured here), and the six bus columns' solves, which the border needs.
"""

COST = """## Cost and real time

The step is compiled (umbrella_sim/core/_kernel3d.c, in the planar kernel's
library, its interface declared in _kernel.h and checked at load): the Newton iteration, each
rib's block factored through its two bodies, the arrow's Schur complement, the projection and
the energy scaling, and runs of grid steps in one call (`UmbrellaSimulator3D.advance`; the
lock itself stays in Python). The numpy step (integrator3d.py) is the reference it is tested
against (tests/test_umbrella3d_kernel.py) and steps any run
without the library (said once on stderr; `UMBRELLA_SIM_KERNEL=numpy` asks for it). Measured
on the 2 shared cores (bench/bench_umbrella3d.py, CPU per step at h = 0.1 ms, deployment):
compiled 3.4 us + 7.9 us x ribs at 1 element a segment, 0.8 us + 16.1 us x ribs at 2 (11.9 us
+ 6.6 us x ribs and 6.6 us + 14.6 us x ribs with the cheaper step below, at load ~4.6; numpy:
1.84 ms + 98 us x ribs, 1.88 ms + 276 us x ribs), 2.0 Newton iterations and 0.125
factorisations a step: the iteration matrix is kept across steps (modified Newton, at most 8
steps, re-factored after a slow iteration; `carry_steps`; a fresh one each step cost 17.2 and
48.8 us x ribs before the inertia invariants; in stage 2 too 8 is the best, 16 the same, 32
slower). M(q), M v and the kinetic gradient come from
each body's inertia invariants (the floating frame's S-bar and I-bar sums, taken over the
points once: M's frame rows are rotation combinations of constants, no point loop a step),
M v and K q run over the nonzeros (K and the elastic mass blocks are banded), the projection
factors M(q)'s blocks from the constant elastic block's LU: 15.2 -> 7.9 and 42.3 -> 16.1 us x
ribs. The compiled step alone (no Record3D, at the mesh's step; the bench's second table;
CPU us a step, best of two runs, before and after in turn at load 0.9-1.4 on the 2 cores):

| ribs x elements | step | stage 1 before | stage 1 after | stage 2 before | stage 2 after |
|---|---|---|---|---|---|
| 1 x 1 | 100 us | 7.4 | 5.7 | 12.5 | 9.4 |
| 3 x 1 | 100 us | 21.2 | 15.8 | 35.5 | 25.6 |
| 6 x 1 | 100 us | 42.2 | 31.3 | 70.0 | 49.9 |
| 12 x 1 | 100 us | 83.2 | 61.4 | 138.0 | 98.9 |
| 1 x 2 | 33.3 us | 14.5 | 10.3 | 25.7 | 17.1 |
| 3 x 2 | 33.3 us | 42.5 | 29.9 | 75.1 | 49.4 |
| 6 x 2 | 33.3 us | 84.9 | 59.1 | 150.3 | 98.3 |
| 12 x 2 | 33.3 us | 172.1 | 120.6 | 306.5 | 201.2 |

Linear in the ribs (fit over 1-12 ribs, intercepts within 2 us): 6.9 -> 5.1 us x ribs in stage
1 and 11.4 -> 8.2 in stage 2 at 1 element, 14.4 -> 10.0 and 25.6 -> 16.8-17.2 at 2 (2.0 Newton
iterations a step in stage 1, 2.81 and 2.20 in stage 2, 0.125 factorisations a step of the
iteration matrix and one of the projection's). What made it cheaper (perf): the joint
Jacobian's products over its nonzeros, no bodies' solves of a zero right-hand side (the shared
columns, the projection's solve), the iteration matrix factored elastic coordinates first as
the projection's (its elastic block M + h²/4 K is constant for a step length) and both bodies'
solves over the nonzeros of the elastic LUs, a Newton iteration's two mass products in one
pass, the Gonzalez joint term as J^T lambda + dq (f . lambda), the mode fit's sums in registers
(they had been a fifth of a stage-2 step). What remains a step (perf, 6 x 1 deploying): the
projection about 0.4 of it (its factorisation every step: the 9 right-hand sides M^-1 J^T, the
9 x 9 joint block), the Newton iterations' mass products, kinetic gradient and solves; in stage
2 the mode fit's modal passes (about 11 a step: a quarter of it) and the 2.81 iterations (a
fresh iteration matrix each step takes 2.07 but costs more).
Since: a body block's factor gathers only the frame rows and columns (the elastic block is
its constant LU's) and eliminates the frame rows over that LU's nonzeros, the dense LU is
inline (the 9 x 9 joint blocks factored by code compiled for that size), both bit for bit the
same runs (6 x 1, 12 x 2 and 3 x 2 in both stages, a prescribed base, a free bus, the
co-rotational ribs); and a fresh iteration matrix's gyroscopic term comes from the inertia
invariants instead of every point's kinematics and velocity (within 7.3e-16 relative of the
point sums; a run moves by what Newton's decisions make of that, at most 3e-8 relative over
100-300 steps). 6 x 1 deploying 496.6 -> 455.8 thousand instructions a step (callgrind, inside
umbrella3d_advance: the wall clock cannot resolve a few per cent on the loaded cores); the
bench's compiled step alone, before -> after, best of two runs in turn at load 4.8-5.0 (CPU us
a step, deploying / stage 2): 6 x 1 31.9 -> 29.7 / 50.9 -> 48.6, 12 x 1 62.7 -> 58.4 / 99.3 ->
95.6, 6 x 2 58.6 -> 51.5 / 97.9 -> 91.4, 12 x 2 119.2 -> 105.7 / 204.8 -> 191.7 (interleaved
best-of-10 runs: 0.95 / 0.955 of before at 6 x 1, 0.87-0.88 / 0.92-0.94 at 12 x 2). Still
0.30 and 0.49 core for 6 x 1, 3.2 and 5.8 cores for 12 x 2: the targets' ~22 and ~25 us (6 x 1)
are not reached, and what stands in the way was measured. The projection is 0.35-0.4 of a
step (the step without it, wrong but timed: 40 -> 24 us at 6 x 1, 150 -> 97 at 12 x 2): a full
factorisation of [[M(q1), J^T], [J, 0]] every step, already through the constant elastic LU;
what is left of it is spread over its gather, the 9 right-hand sides (about a third of it),
the 9 x 9 block and the shared column. Newton's second iteration is not a mere
confirmation: with the update tolerance a thousand times looser (1e-5) 6 x 1 still takes 1.88
iterations deploying and 2.815 in stage 2, since the constraints must hold to PHI_TOLERANCE
(1e-11 m) and the kept matrix's joint rows (up to 8 steps old) leave (J(q) - J_kept) dq in
them after an update (the second update deploying is 0.15-2.5e-8, about the tolerance, so a
contraction rate carried from the last step would stop at one iteration only in some steps,
and only with fresh rows). Fresh joint rows each iteration (the numpy step, 24 steps from
the same state) take stage 2 from 2.79 to 2.29 iterations and leave deploying at 2.0, but
refreshing them (the 9 x 9 block, its LU, the shared column, per rib and iteration) costs
about what the half iteration saves. -march=native changed nothing measurable; 12 x 2 in real
time needs 33 us a step, 3.2 (deploying) to 5.8 (stage 2) times today's CPU a step, which 2
threads on the 2 shared cores cannot give even perfectly parallel.
Since, with the hub fixed, an update that converges in q where the joints do not yet hold
is followed by a correction of the joints alone instead of a whole iteration: the kept
iteration matrix solved for the joint rows' -Phi with the momentum rows' right-hand side 0,
no residual evaluated (integrators.newton_converged, the planar step's rule too, so the
identity (a) holds through it). In the 6 x 1 run's stage 2 that iteration had been for the
joints in 155 of 170 steps that took one (the update about 1e-8, the joints 1e-11 to 1e-10
m). Stage 2 at 1 element a segment: 2.81 -> 2.09 iterations a step, 47.5-47.9 -> 41.4-41.5
us (6 x 1) and 93.5-93.8 -> 82.1-82.3 us (12 x 1), interleaved runs at load 0.5-1.3; at 2
elements a segment (2.20 iterations) and in stage 1 (2.00) nothing changes: their joints
hold after the update that converges in q. What it costs is Newton error within the
tolerance: tests/test_umbrella3d_newton.py (3 unequal ribs, 30 ms of stage 2) finds the tip
series 0.69 um from a run at tolerance 1e-13 (6.2e-3 um with the whole iteration), where
halving the step moves it 219 um. A moving base keeps the whole iteration: its balances are
Newton's accuracy (a prescribed base's energy is not scaled to its balance, and with the
correction a free co-rotational bus's angular momentum drifted 2.7e-6 of its scale, twice
what the whole iteration leaves).
With the hub fixed the 3D model takes the planar stage-2 mode fit rib by rib (the sleeve at
the stop decouples the ribs: each rib's locked modes exact in phase and amplitude, T + V
conserved; tests/test_umbrella3d_mode_fit.py), hence the planar rule's fitted
step: 0.1 ms at 1 element, 33 us at 2 (9.1 us without the fit). Ribs 6 x 1 in 1 ms blocks run
at 1.1-1.15 x real time deploying (0.9 CPU s a simulated second, with Record3D's figures and
each rib's stress rows: about 0.4 of them; the steps alone 0.5) and 0.87 x in stage 2 (1.2 CPU
s; 80 us a step); ribs 12 x 2 in 10 ms blocks at 0.167 x (6.0 CPU s) and 0.099 x (10.1 CPU
s). With the cheaper step (the same runs as the table): 6 x 1 at 1.41 x real time deploying
(1.16-1.24 x before; 0.7 CPU s a simulated second, of which the step 0.31 and Record3D's
figures about 0.37: a run's Record3D.add_steps in 10-step blocks, 37 us a step at load ~4),
0.50 core for the step alone in stage 2; 12 x 2 at 0.23 x deploying (0.16-0.17 x before; 4.3
CPU s, the step alone 3.6), the step alone 6.0 cores in stage 2. The real-time targets
(6 x 1 within 0.5 core, 12 x 2 in real time) are not reached: they need about 8 us (6 x 1,
the figures included) and 2.8 us (12 x 2) a rib and step at these steps.

Record3D's per-step figures are computed in the compiled advance
(umbrella_sim/core/_kernel3d_figures.h: at every stress point of every rib the four components
and von Mises with their rates, over the recovery rows' nonzeros, the Hermite crest of each step,
each rib's largest and where, as the rows' last 15 R doubles); Record3D's numpy rule stays the
reference (tests/test_umbrella3d_kernel.py, test_compiled_stress_figures_equal_record3d_numpy:
every base through the lock; the stress rows move by at most 1.5e-15 of their largest, every
other figure is the same bit for bit), and Record3D keeps each chunk's peaks as its steps come
(the summary and the publication no longer stack them). The same runs before and after in turn
(bench/bench_umbrella3d.py, load 1.5-1.7): 6 x 1 in 1 ms blocks 0.66-0.67 -> 0.44-0.45 CPU s a
simulated second deploying (1.49-1.51 -> 2.22-2.26 x real time) and 0.87-0.88 -> 0.65-0.67 in
stage 2 (1.14-1.15 -> 1.49-1.54 x); 12 x 2 in 10 ms blocks 5.6 -> 4.0 CPU s deploying (0.18 ->
0.25 x) and 8.2-8.3 -> 6.4 in stage 2 (0.12 -> 0.16 x). The node at 1 kHz with recording
(bench/bench_ribs_node.py --live, load 1.7-3.2, mostly stage 2): 1.32-1.39 -> 0.95-1.06 CPU s a
simulated second, 0.48-0.65 -> 0.71-1.00 x real time (real time over 8 s where the machine
gave it 0.95 core). A 1 ms block of the run driver (6 x 1, 0.4 s from rest: the lock at 0.23
s; bench_ribs_node's parts): the compiled steps and their figures 432-445 us, Record3D's rows
77-85, the summary 44-47, the publication's sample 9, its encoding 51-55. The step alone
(its figures included) 31.4-31.8 us in stage 1 and 50.3-51.0 in stage 2 at 6 x 1, 121-125 and
204 at 12 x 2 (a rib's W lambda summed along W's rows, the bodies' elastic-first order mapped
once: 32.6-33.1 -> 31.4 and 128 -> 121-122 us in stage 1, bit for bit the same). What
remains is the step itself (stage 2: of which the 2.81 Newton
iterations, the projection's factorisation and the mode fit's modal passes; a predictor from
the previous step's increment or a second-order extrapolation took 2.77-2.95 iterations a
step, no fewer: stage 2's iterations are set by the fitted modes at omega h near 1) and the
node's Python per publication.

The node's work per 1 ms publication beside the step (6 x 1, bench/bench_ribs_node.py, the
same runs of main and this change in turn at load 4.2; deploying / 10 ms after the lock):
Record3D's rows 105-112 -> 58-66 us / 99 -> 61-69 (the run's peaks kept as arrays, updated
with np.where where a rib's is larger, instead of a loop over ribs; the constant rows shared),
the summary 55-59 -> 30-35 / 46 -> 26-29 (the deployed ribs' search only in a block where a
leaf reached its angle, the out-of-plane tip's argmax only for a larger tip, T + V reused by
the energy balance, the held peaks kept when none is larger), the encoding 56-58 -> 37-43 /
59-64 -> 39-46 (the joint values as lists, a sample's figures from one mapping, the stress
rows in a reused buffer), and a whole 1 ms block with the compiled call stubbed
(bench_ribs_node's outside_kernel: every part but the step) 192-200 -> 123 us / 193-195 ->
121-124; all of it bit for bit the same rows, figures and CDR bytes. The node records a
publication's messages in one call (RunRecording.publish_all, BagRecorder.write_all) and checks
the acting force once per value. What the live node spends beside the step at real time
(threads over 4 s at load 3.6, per simulated second): the physics thread's Python about 0.12
CPU s and its DDS writes to a subscriber 0.07-0.10 (rclpy with a subscriber in another
process: 98 us a publication of the five topics against 33 without one; FastDDS's shared-memory
push and the reliable writer's timer notification, each a futex wake), FastDDS's event thread
0.02-0.05, the executor's 20 ms wait loop 0.02, the recorder's thread 0.015-0.03 (zstd and
the MCAP records, 24 us a publication): about 0.3 core beside the step, not yet the 0.15-0.2
that the 0.5-core target leaves beside a 0.25-0.3-core step.

Beside the step, a second pass (6 x 1, 1 kHz; the same runs of the previous state and this
one in turn, load 1.7-2.1): a 1 ms block with the compiled call stubbed (bench_ribs_node's
outside_kernel, best of 15 x 500 blocks) 109-112 -> 86-87 us deploying and 108-109 -> 84-85
us in stage 2 (the bench's own best of 9 x 200: 124 / 120 -> 96 / 95), bit for bit the same
rows, figures and CDR bytes (every chunk's rows, sample, held peaks, summary figures and
encoded message of three runs: hub fixed, a stuck and rubbing hinge, a free bus): Record3D
keeps a chunk's rows as one dict that take() hands over, its running sums by the ufuncs'
accumulate and reduce and its held peaks by ndarray.take; Summary3D's and the peaks'
maxima by np.maximum.reduce (ndarray.max's and np.sum's arithmetic without their dispatch,
which costs more than a block's reduction); the compiled call does not copy in again the
state its buffers hold (the run's next call starts from it), a sample of a block's last row
is one dict. The executor's wait for a stop signal went from 20 ms to 0.1 s: each wait
rebuilds rclpy's wait set, ~0.5 ms of CPU, 0.026 -> 0.006 core. The live node (bench_ribs_node
--live, 4 s windows, main and this change in turn): at load 1.3-1.8, where both kept real
time, 0.86-0.93 -> 0.85-0.87 core in stage 2 and 0.69-0.70 -> 0.66-0.70 deploying (the
executor's thread 0.017-0.022 -> 0.005-0.007 of it; the rest within the runs' spread); at
load 1.8-4.5, where it fell behind, 0.94-1.03 -> 0.84-0.94 and 0.74-0.82 -> 0.61-0.71 CPU s a
simulated second. What remains beside the step, measured in the node's own process with the
compiled call stubbed and paced at real time (stage 2, load ~2.2, CPU a simulated ms): the
physics thread 227 us (310 before) without a subscriber and 324 us (371) with one in another
process, the process 276 (361) and 409 (480): a subscriber's DDS writes cost the publishing
thread ~100 us a publication and FastDDS's other threads ~35; the pacing's sleep 25 us a
publication (a sleep's own CPU on this machine, 15-24 us however short: py-spy's 5-12 % in
Pacer.sleep_until was mostly a runnable thread's wall time); and the Python of a publication
costs ~1.4 times its hot figure when the thread wakes from that sleep (cold caches).

A driven hub and a free-floating bus step compiled too (umbrella_sim/core/_kernel3d_base.h: the
bus's border of M(q) (its elastic columns from invariants), its share of the kinetic energy's
gradient, the arrow's full border of seven shared coordinates, the drive's rows, the free bus's
linear momentum restored and its momenta in the rows; the drive's profile evaluated in Python
for a run of steps), equal to the numpy reference within its round-off spread
(tests/test_umbrella3d_kernel.py: an asymmetric deployment, runs of steps, through the lock;
tests/test_umbrella3d.py: the momentum and the drive's work balanced on both paths). Measured
(bench/bench_umbrella3d.py --base, CPU per step at h = 0.1 ms with Record3D's figures,
deployment, 1 element a segment, load ~0.8 on the 2 cores; 3 / 6 ribs): hub fixed 28 / 56 us,
driven (a jolt in X-Z, a spin-up about Y) 74 / 144 us (3.0 Newton iterations a step while the
base accelerates or spins up, 2.0 when it does not), free bus 61 / 121 us (numpy: 1.9 / 2.2 ms,
6.9 / 7.5 ms, 5.5 / 5.9 ms); the compiled step alone at a moving base's step 48 / 94 us
(driven), 48 / 92 us (free), 15 us a rib (hub fixed, 0.1 ms: 5.1). Those were at the planar
rule's step without the stage-2 mode fit, 33 us at 1 element: ribs 6 x 1 in 1 ms blocks took
3.6 (driven) and 3.5 (free) CPU s a simulated second, 0.28-0.29 x real time.

Stage 1 on its own grid (step_rule.STAGE1_STEP_CEILING: 0.2 ms at 1 and 2 elements a
segment, stage 2 the mesh's step as substeps, folded into the grid's rows by the compiled
advance itself) halves the steps of a deployment: on a slower day of the shared machine
(load 1.1-1.5 from other users; the previous code's compiled stage-2 step 78 us at 6 x 1
where it was 42 us below), best of interleaved runs, the run driver with 1 kHz
publications and their encoding (ribs 6 x 1, a slow deployment from rest) 287-290 us a
simulated ms against 398-416, stage 2 655-689 against 641-725 (the same physics steps);
the compiled step alone 0.26-0.28 core deploying against 0.43 (52.9-56.1 us a 0.2 ms
step, 2.02 Newton iterations), 0.73-0.78 in stage 2 against 0.78; ribs 12 x 2 deploy at
0.88 core (176 us a 0.2 ms step, 2.02 iterations) against 3.5 at 33 us, and in 10 ms
blocks 1.25 x real time (0.80 CPU s a simulated second) against 0.27 x (3.68); the live
node (6 x 1, 1 kHz, recording, a subscriber, 4 s) 0.915-0.938 core deploying against
0.962-0.991, and in stage 2 neither kept real time that day (1.24 and 1.17 CPU s a
simulated second). Stage 2 is where both targets stay missed: its step is the mesh's.

Where real time stood before that (the targets: ribs 6 x 1 at 1 kHz with recording within 0.5
core; 12 x 2 in real time at 100 Hz), measured on a quiet machine (load 0.4-1.4) with
everything above: the compiled step alone 32.0 / 47.6 us at 6 x 1 (0.32 / 0.48 core, stage 1 /
2) and 108.8 / 169.9 us at 12 x 2 (3.27 / 5.10 cores at its 33 us step; 0.30 x real time in
10 ms blocks, 3.31 CPU s a simulated second); the live node at 6 x 1, 1 kHz, recording, real
time held (bench_ribs_node --live, 5 s): 0.822-0.828 core in stage 2, 0.669-0.685 deploying.
Neither target is met: the step itself is past what 0.5 core allows in stage 2, and 12 x 2
needs 3-5 cores at the step its stresses need. A step of 0.125 ms (8 a 1 kHz publication:
`time_step: 1.25e-4`; the rule's unresolved stress share is the same 0.33 / 0.41 % as at
0.1 ms, every fitted mode within omega h 1.5) takes a fifth fewer steps: the live node 0.732
core in stage 2 and 0.631-0.638 deploying; against a 25 us run (6 x 1, 0.35 s through the
lock) its peak von Mises is 1.44 % off where 0.1 ms is 1.04 % off, its stage-2 tips 0.18 %
(0.12 %), the lock instant 5.2e-7 s (the same): a user's choice, not the default. Two ways to
spare stage 2's third Newton iteration were measured and not kept (6 x 1, 0.1 ms; error
against a run at Newton tolerance 1e-12 with a matrix factored every step, 0.6 s through the
lock): constraint corrections (an iterate converged in q but missing PHI_TOLERANCE moved by the
kept matrix solved for the joints' residual alone) took 2.82 -> 2.08 iterations and 50.8 ->
45.5 us a step, but move q without the momentum balance (the velocity 2 dq / h jumps with the
correction): alpha1 4.7e-6 rad off against 5.5e-8, a prescribed base's energy balance 1.4e-5
of its scale against 1.7e-7; a constraint tolerance of 1e-9 m instead of 1e-11 took 2.08
iterations and 42.9 us, alpha1 4.8e-6 rad off (1e-10: 2.34 iterations, 45.5 us, 7.5e-7).
The projection's factorisation kept across up to 8 steps like the iteration matrix, and
corrected by iterative refinement against the exact M(q) and J(q), was measured and not
kept (6 x 1, quiet machine, us a step deploying / stage 2): 29.8 / 47.5 with today's
projection, 26.1 / 43.5 with one refinement, 29.5 / 46.6 with two (a refinement's full
solves cost about what the factorisation does), 23.1 / 47.5 with none, which leaves J v at
the kept factor's error: at most a tenth of the step, for a projection exact only to the
refinement's contraction. The
mode fit's modal sums now run along contiguous rows (u and phi handed over transposed as well;
each sum in the same order, so bit for bit the same runs), which the free bus's dense whole fit
felt: its compiled stage-2 step at 6 / 12 / 24 ribs x 1 was 153 / 420 / 1203 us (25.5 / 35.0 /
50.1 us a rib; 170 / 482 / 1581 us before, at load ~3.3), growing as the square of the ribs.
With the ribs' fits and the bus's low-rank correction (stage 2's mode fit, above) it is 131.7 /
263.5 / 530.9 us (22.0 us a rib at each count; the whole fit 151.9 / 417.2 / 1164.1 us in the
same interleaved runs, load 1.2-2.5); the hub fixed 47.5 / 95.1 / 190.5 us. Lockstep through
the test API (a commander answering every joint_states, 1 kHz, 6 ribs) runs at 0.48-0.61 x real
time, a command to the state it lets out 1.26-1.52 ms (median), 2.6-6.0 ms at most; at 100 Hz at
1.00 x (runs interleaved, load 1.3-1.6; 0.33-0.37 x, 2.16-2.43 ms and 0.90-0.92 x with every
entity of the node in one wait set rebuilt at each turn and each period paced from the command's
coming: ros/executor.py, ros/pacing.py; 0.38-0.42 x and 1.85-2.16 ms on a quiet machine; before
that: 0.04-0.05 x, and up to 1.4 s a command: rclpy's MultiThreadedExecutor resubmitting a
callback that waits for a worker, ros2/rclpy#1452, and a first command lost until a 3 s
heartbeat: msg_docs/topic_sleeve_force.md). The node's CPU free-running at 1 kHz after the lock
is unchanged by it: 0.86-1.01 CPU s a sim s against 0.90-0.98 (3 runs each, interleaved, load
1.8-3.4).

Beside the step, a third pass (6 x 1, 1 kHz, recording, watched through the test API; main and
this change in turn, 6 runs each, load 2.3-4.0, where neither always held real time, so in CPU s
a simulated second, bench_ribs_node --live over 5 s): 0.88-1.04 -> 0.81-0.92 in stage 2 and
0.67-0.72 -> 0.59-0.64 deploying (two runs of this change that fell to 0.69-0.74 x real time,
0.78, left out), Fast DDS's event thread 0.030-0.051 -> 0.012-0.018 core; against main with the
lockstep changes above (3 runs each, load 2.0-2.8, mostly behind real time: 0.71-1.02 x)
0.94-1.04 -> 0.85-0.99 and 0.73-0.85 -> 0.69-0.70, the event thread 0.036-0.058 -> 0.018-0.026
core. Most of it is Fast DDS: a reliable writer restarted its NACK-suppression timer (0 s by
default) at every sample sent to a subscriber, which woke the event thread five times a
publication and had it wait for the writer's lock the publishing thread held; the node now sets
its own profile
(config/fastdds_node.xml: that duration 5 ms, nothing else; msg_docs/README.md says when it
applies and what it costs), which took the five topics to a subscriber in another process from
108-140 to 78-109 us of the process's CPU a publication. The ribs' encoder writes each topic's
doubles in place into a copy of its template through numpy views (29-31 us a publication
instead of 31-33, bench_ribs_node's outside_kernel 100-102 -> 96-98 us deploying, 94-96 -> 92-93
in stage 2), every recorded message and summary figure bit for bit the same (record_offline of
6 ribs, a stuck and rubbing rib, a free bus). Already so before: each message is serialized
once (the encoders' CDR bytes go to rclpy's publish and to the recorder alike). What remains,
measured in the node's own process at real time, deploying, a subscriber in another process,
load 2.5 (CPU a simulated ms): the process 699 us, of which the compiled step 287; beside it the
run driver's Python 136 (Record3D's rows 62, the summary 32, the compiled call's Python side
and the rest 42), the warnings' check 8, the publication's sample 11 and its encoding 38, the
DDS writes of the five topics 86 (28 without a subscriber), the recorder's queue 18, the pacing
sleep 14 (a sleep costs ~15 us of CPU on this machine however it is made: time.sleep, select,
an Event, nanosleep), the loop and the command's check ~40, the other threads 61 (the recorder
22, Fast DDS's ~15, the executor 6): ~0.41 core beside the step where 0.5 core leaves
0.18-0.21. Measured and not kept: Fast DDS without heartbeat piggybacks, with UDP alone (no
shared memory), both no cheaper; calling rclpy's publish_raw directly (0.35-0.8 us a topic).
One thing measured that a change of the loop could take: a 1 ms block woken from a 0.7 ms sleep
costs 80-90 us more than the same block run back to back (the sleep itself ~15, the rest cold
caches), so computing two periods before sleeping would save ~0.03-0.04 core; it would make a
command act one period later than msg_docs/topic_sleeve_force.md promises (from the next
period) and publish sleeve_force/applied before the joint_states it follows, so it was not done.

What a cheaper stage 2 would take. Stage 2 costs what its step count costs (6 x 1: ten 0.1 ms
steps a simulated ms, 0.38 core of the step alone at its cheapest, below; the live node at 1 kHz
with recording 1.0-1.4 CPU s a simulated second in stage 2 on this shared machine, 0.76-0.98
x real time in six runs; deploying 0.92 core and real time),
and each way of taking fewer steps measured so far fails a target (the thesis's frame, 0.5 s of
stage 2 against a 2.5 us run; the step study's targets):
- the mode fit up to omega h 2.5 instead of 1.5 (the step's Hermite crest sees a lone mode's
  crest as well up to 2.5: at least 0.73 of it over a period, 0.78 up to 1.5) lets the rule take
  50 us at N = 2 (25-33 us) and 12 x 2's stage 2 fall from 9.1 to 5.1-5.6 CPU s a simulated
  second, within every target; but the newly fitted modes (modal masses down to 0.17) slow the
  kept-matrix Newton iteration (6 x 1 at 0.1 ms: 2.20 -> 2.81 iterations a step, a free bus 2.04
  -> 3.46) and one free-bus lock's part step did not converge;
- stage 2 at 0.2 ms at N = 1: the stage-2 peaks 3.2-3.9 % off at V0 = -0.22 to -0.25 (plastic
  lock) and -0.2 (energy lock, with the lock's higher modes 10 250 and 26 600 rad/s taken out
  of the step and added back as exact free vibration), where 0.1 ms is within 1.5 %: what is
  off is the low modes' coupling (its phase error grows like the deflection squared times the
  step squared), not the modes above the step's reach;
- the lock's modes as exact linear free vibration (no step at all): the tip 2.7 % of its
  amplitude off by 0.5 s and the link's peak 7 % low: the floating frames' coupling is not
  small at the thesis's deflections;
- a correction of the joints alone on a moving base (as with the hub fixed): 25-30 % fewer
  iterations on a free bus, but its angular momentum drifted 2.0-2.5e-6 of m v L (the tests'
  bound 1e-6; 0.8-2.9e-7 with whole iterations), and a driven base's energy balance 10 times
  further from round-off.
A stage 2 several times cheaper needs an integration of the coupled modes of higher order than
the midpoint rule's, not only the higher modes made exact.
Real time without a cheaper step, by a second core: a publisher thread that sent and recorded
each publication while the physics thread stepped the next chunk (the compiled call releases
the GIL) was measured and not kept. The live node (6 x 1, 1 kHz, recording, stage 2, three
runs of each in turn at load 1.2-1.6): 0.78 / 0.78 / 0.94 x real time with it against 0.82 /
0.87 / 1.03 without; the physics thread's CPU a simulated second did not fall (0.94-1.14
against 0.93-1.17) and the new thread took 0.125-0.143 core more: what left the physics
thread came back to it, most likely as waits for the GIL the publishing thread held (rclpy's
publish and publish_raw call rcl_publish without releasing it).
What made the step cheaper, the same scheme (6 x 1, stage 2, the compiled step alone, CPU us a
step, interleaved with the code before, load 1-3): 51.6 -> 48.2-49.3 with the projection kept
with the iteration matrix (integrator3d.PROJECTION_PASSES: passes of the kept factor hold
J v = 0 to round-off; its metric's ~1e-7 of v is the kept matrix's order, so only from a Newton
tolerance of 1e-10); -> 37.4-37.6 with the mode fit's sums in vector registers, one map a step
less (the residual's S^T (M(q1) v1 - p0)), the iterates' velocities from tracked modal
coordinates (half a map each; round-off from the reference's maps) and a rib's joint solve by
columns (12 x 2: 191-201 -> 148-150). Iterations and factorisations a step are unchanged (2.09,
0.125). Beside the step, a 1 kHz publication's Python (bench_ribs_node's 1 ms block without the
compiled call): 133 -> 112 us (the summary taking stage 2's 5-row blocks 50 rows at once,
summary3d.SUMMARY_BATCH_ROWS; the compiled call's state built once at the grid's time; a block's
constant rows in one look-up; the stress figures of a publication from the held peaks' arrays),
every figure, row and message byte the same.
Where it stands (bench/bench_umbrella3d.py, the compiled step alone at the step the run takes,
CPU us a step, stage 1 / stage 2, the best of four runs at load ~1; single runs read up to 1.6
times that while the machine's other users ran): 6 x 1 34.9 / 37.6 (0.17 / 0.38 core), 12 x 1
67.7 / 74.3, 6 x 2 60.9 / 72.1, 12 x 2 120.3 / 147.7 (0.60 / 4.43 cores at stage 2's 33 us);
linear in the ribs, 6.2 us a rib at 1 element and 12.4 at 2 in stage 2. Neither target is
met: at 6 x 1 the step alone is 0.38 of the 0.5 core the node may use, whose publications
take 0.6-1.0 core more live at 1 kHz on this machine (offline, the run driver and the
encoding take 523-706 us of CPU a simulated ms of stage 2 at different hours, the step 379 of
it in calls of 10 steps; live, the node alone, recording, 0.95-1.06 CPU s a simulated second,
its step ~52 % of that: the same code runs ~1.3-1.7 times slower in the node's process, not
accounted for); 12 x 2 needs its 4.4 cores
of stage 2 cut about five times, a stage-2 integration of higher order (above), not a cheaper
step.
"""


#: rib 1 of 3 heavier, stiffer; a deployment from rest by the sleeve force (N a rib)
HEAVIER, STIFFER = {'rib1.tip_mass': 0.1}, {'rib1.youngs_modulus': 1.44e11}
FROM_REST = {'v0': 0.0, 'sleeve_force': 10.0}


def asymmetry_paragraph() -> str:
    """Return what an asymmetry does to the deployment: the ribs' spread, the stall."""
    spread = []
    for c in (0.5, 1.0, 2.0):
        rec = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
            {'ribs': 3, 'rib1.hinge_coulomb': c})).run(0.3)
        spread.append(f"{rec.summary()['max_leaf_angle_spread']:.1e}")
    base = UmbrellaRibsParams.from_mapping({'ribs': 3})
    kinetic = float(UmbrellaSimulator3D(base).record.arrays()['kinetic_energy'][0])
    stall = kinetic / (base.planar.alpha0 - base.planar.alpha_deployed)
    # the lock with rib 1 heavier or stiffer, from the default V0 without a sleeve force
    # and from rest under one
    ribs = {'alike': {}, 'heavier': HEAVIER, 'stiffer': STIFFER}
    drives = {'v0': {}, 'rest': FROM_REST}
    lock = {(r, d): UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(
        {'ribs': 3, **ribs[r], **drives[d]})).run(0.6).summary()['lock_time']
        for r in ribs for d in drives}
    heavier = {d: f"{lock['heavier', d]:.4f} s against {lock['alike', d]:.4f} s" for d in drives}
    stiffer = {d: f"{1e6 * (lock['stiffer', d] - lock['alike', d]):+.0f}".replace('-', '−')
               for d in drives}
    progress('asymmetry: spreads, locks and the stall torque')
    return (
        'What an asymmetry does to the deployment. One sleeve drives every rib through its '
        "link, so\neach leaf's angle follows the sleeve's height but for the frame's elastic "
        'deformation: the\nribs reach full deployment together, at the lock (`deployment_lag` '
        '0). An asymmetry moves the\nlock (`deploy_time`): a rubbing or sticking hinge '
        'later; a heavier rib later where the\nsleeve force drives the deployment, earlier '
        "where the start's velocity V0 does (rib 1 of\n3 with a "
        f"{HEAVIER['rib1.tip_mass']:g} kg tip mass: {heavier['rest']} from rest under "
        f"{FROM_REST['sleeve_force']:g} N a\nrib, {heavier['v0']} from V0 = −0.2 without "
        'force); a stiffer rib hardly at all\n(twice the modulus: '
        f"{stiffer['v0']} µs from V0 = −0.2, {stiffer['rest']} µs from rest). It shows as "
        'the ribs\napart on the way (`max_leaf_angle_spread`: rib 1 of 3 rubbing at 0.5 / 1 / '
        f"2 N m holds\nits leaf {' / '.join(spread)} rad behind, proportional to the "
        "torque) and in each rib's\nstage 2 (`stage2_tip_amplitude` and `_period` in its "
        'plane, `stage2_tip_w_amplitude` and\n`_period` out of it: a rib of '
        "Young's modulus E1 rings at sqrt(E0/E1) times the others'\nperiod). A hinge that "
        "takes more than the frame's kinetic energy can pay over the travel (rib\n1 of the "
        f"thesis's three from V0 = −0.2, no sleeve force: from {stall:.2f} N m) stops the "
        "deployment:\nthe run says 'stalled' (where and when), and never locks. "
        "umbrella_compare's table of the\numbrella shows these figures run against run.")


def main():
    os.makedirs(OUT_DIR, exist_ok=True)
    pyplot = plt()
    lines = [HEADER, 'Generated by `python docs/make_umbrella3d.py`. Thesis data: Al 7075-T6, '
             "l1 = l2 = l3 = 0.5 m, 10 mm square section, Poisson's ratio 0.33.", '']
    section_a(lines)
    section_b(lines)
    balance = section_c(lines, pyplot)
    section_d(lines, pyplot)
    section_e(lines, pyplot)
    lines.append(COST)
    lines[0] = lines[0].replace('{accuracy}', accuracy_table(balance)).replace(
        '{asymmetry}', asymmetry_paragraph())
    with open(os.path.join(HERE, 'umbrella3d.md'), 'w') as f:
        f.write('\n'.join(lines).rstrip() + '\n')
    progress('wrote docs/umbrella3d.md')


if __name__ == '__main__':
    main()
