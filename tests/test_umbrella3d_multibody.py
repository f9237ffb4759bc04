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
An asymmetric deployment against an independent multibody code: (d) of the umbrella's validation.

Three ribs on a free-floating bus; rib 1's hinge is stiff (Coulomb and viscous friction), rib
0 carries a tip mass.  The reference is MuJoCo (DeepMind, PyPI ``mujoco``; Todorov, Erez &
Tassa, IROS 2012): rigid leaves and links as hinged bodies in a kinematic tree under a free
joint, each link's end tied to the sleeve by a ``connect`` equality, the friction as the
joint's ``damping`` and ``frictionloss``, RK4 at 10 us with the constraints' time constant
20 us (halving both moves the figures below by < 1e-6 relative).  The umbrella model's ribs
are made 100 times stiffer than the default (E = 7.2 TPa) so they are nearly rigid: on the
planar model, that stiffness moves the lock instant 1.6 us from the rigid model's.

Compared: the lock instant (tolerance 1e-5 s), and at 50 ms and 100 ms the sleeve height on
the bus, the bus's displacement and its rotation about the hub axis's normal (tolerance 1e-3
relative: the asymmetry's effect itself is what is compared, the bus moving 0.6 mm sideways
and turning 0.05 rad in reaction to the tip mass).  Measured: 2.1 us, and 1e-5 to 1.3e-4
relative.
"""
import math

import numpy as np
import pytest

from umbrella_sim.core import UmbrellaParams
from umbrella_sim.core.umbrella3d.model3d import BusFrame
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D

from .test_umbrella3d import DRIVE

mujoco = pytest.importorskip('mujoco')

RIBS, FORCE, SLEEVE_MASS, BUS_MASS, BUS_INERTIA = 3, 10.0, 1e-3, 5.0, 0.2
VISCOUS, COULOMB, TIP_MASS = (0.0, 0.05, 0.0), (0.0, 0.2, 0.0), (0.05, 0.0, 0.0)
STIFF = 7.2e12
MARKS = (0.05, 0.1)
#: MuJoCo's driven bus: heavy enough that the ribs' reactions (~30 N, ~1 N m) leave its
#: motion the prescribed one to 1e-6; much heavier (1e8) spoils MuJoCo's own solution
DRIVEN_MASS = 1e6


def umbrella_mjcf(p: UmbrellaParams, dt: float, time_constant: float,
                  driven: bool = False) -> str:
    """
    Return the MJCF of the rigid umbrella on a bus (hub axis Y, rib 0 in X-Y).

    A free bus, or (driven) a bus of DRIVEN_MASS on slides along X and Z and a hinge about
    Y, whose actuators impose the base's accelerations.
    """
    l1, l2, l3 = p.l1, p.l2, p.l3
    rho_a, rho_ip = p.mass_per_length, p.density * 2.0 * p.cross_section_inertia
    ribs = []
    for k in range(RIBS):
        psi = 2 * math.pi * k / RIBS
        ml, mk = rho_a * (l1 + l2), rho_a * l3
        il, ik = ml * (l1 + l2) ** 2 / 12, mk * l3 ** 2 / 12
        tip = (f'<body pos="{l1 + l2} 0 0"><inertial pos="0 0 0" mass="{TIP_MASS[k]}" '
               'diaginertia="1e-9 1e-9 1e-9"/></body>' if TIP_MASS[k] > 0 else '')
        ribs.append(f"""
      <body name="leaf{k}" quat="{math.cos(psi / 2)} 0 {math.sin(psi / 2)} 0">
        <joint name="leaf_hinge{k}" type="hinge" axis="0 0 1" damping="{VISCOUS[k]}"
               frictionloss="{COULOMB[k]}"/>
        <inertial pos="{(l1 + l2) / 2} 0 0" mass="{ml}"
                  diaginertia="{rho_ip * (l1 + l2)} {il} {il}"/>
        {tip}
        <body name="link{k}" pos="{l1} 0 0">
          <joint name="link_hinge{k}" type="hinge" axis="0 0 1"/>
          <inertial pos="{l3 / 2} 0 0" mass="{mk}" diaginertia="{rho_ip * l3} {ik} {ik}"/>
          <site name="H{k}" pos="{l3} 0 0"/>
        </body>
      </body>""")
    ties = ''.join(f'\n    <connect site1="H{k}" site2="S" solref="{time_constant} 1"/>'
                   for k in range(RIBS))
    if driven:
        joints = ('<joint name="base_x" type="slide" axis="1 0 0"/>'
                  '<joint name="base_z" type="slide" axis="0 0 1"/>'
                  '<joint name="base_spin" type="hinge" axis="0 1 0"/>')
        mass = inertia = DRIVEN_MASS
        drives = ''.join(f'\n    <motor name="{j}" joint="{j}" gear="1"/>'
                         for j in ('base_x', 'base_z', 'base_spin'))
    else:
        joints, mass, inertia, drives = '<freejoint/>', BUS_MASS, BUS_INERTIA, ''
    return f"""<mujoco>
  <option timestep="{dt}" gravity="0 0 0" integrator="RK4"/>
  <worldbody>
    <body name="bus">
      {joints}
      <inertial pos="0 0 0" mass="{mass}" diaginertia="{inertia} {inertia} {inertia}"/>
      {''.join(ribs)}
      <body name="sleeve">
        <joint name="sleeve_slider" type="slide" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="{SLEEVE_MASS}" diaginertia="1e-9 1e-9 1e-9"/>
        <site name="S"/>
      </body>
    </body>
  </worldbody>
  <equality>{ties}
  </equality>
  <actuator>
    <motor name="sleeve_force" joint="sleeve_slider" gear="1"/>{drives}
  </actuator>
</mujoco>"""


def base_acceleration(t: float):
    """Return the driven base's (acceleration along X, angular acceleration about Y)."""
    start, length = DRIVE['base_accel_start'], DRIVE['base_accel_duration']
    ax = (DRIVE['base_accel_x'] * math.sin(math.pi * (t - start) / length)
          if 0.0 < t - start < length else 0.0)
    ramp = DRIVE['base_spin_ramp']
    spin = DRIVE['base_spin_rate'] / ramp if t < ramp else 0.0
    return ax, spin


def mujoco_run(p: UmbrellaParams, dt: float = 1e-5, time_constant: float = 2e-5,
               marks=MARKS, driven: bool = False):
    """Return (lock instant, {mark: (sleeve height, bus position, bus rotation)})."""
    m = mujoco.MjModel.from_xml_string(umbrella_mjcf(p, dt, time_constant, driven))
    d = mujoco.MjData(m)
    a1, l1, l3 = p.alpha0, p.l1, p.l3
    a2 = math.acos(-l1 * math.cos(a1) / l3)        # H on the axis: l1 cos a1 + l3 cos a2 = 0
    ratio = -l1 * math.sin(a1) / (l3 * math.sin(a2))     # a2' / a1'
    a1_rate = p.v0 / (l1 * math.cos(a1) + l3 * math.cos(a2) * ratio)
    nq, nv = (3, 3) if driven else (7, 6)          # the bus's coordinates come first
    if not driven:
        d.qpos[3] = 1.0
    for k in range(RIBS):
        d.qpos[nq + 2 * k], d.qpos[nq + 1 + 2 * k] = a1, a2 - a1
        d.qvel[nv + 2 * k], d.qvel[nv + 1 + 2 * k] = a1_rate, a1_rate * (ratio - 1)
    d.qpos[-1] = l1 * math.sin(a1) + l3 * math.sin(a2)
    d.qvel[-1] = p.v0
    mujoco.mj_forward(m, d)
    if not driven:
        mass = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, mass)
        # the bus's velocity making the whole momentum zero (as the umbrella model starts)
        d.qvel[:6] = -np.linalg.solve(mass[:6, :6], mass[:6, 6:] @ d.qvel[6:])
    d.ctrl[m.actuator('sleeve_force').id] = -FORCE * RIBS
    y_stop = p.sleeve_stop_height
    marks, out = list(marks), {}
    while True:
        if marks and d.time >= marks[0] - 1e-12:
            rot = np.zeros(9)
            if driven:
                position = np.array([d.qpos[0], 0.0, d.qpos[1]])
                mujoco.mju_axisAngle2Quat(quat := np.zeros(4), np.array([0.0, 1.0, 0.0]),
                                          d.qpos[2])
            else:
                position, quat = d.qpos[:3].copy(), d.qpos[3:7]
            mujoco.mju_quat2Mat(rot, quat)
            out[marks.pop(0)] = (d.qpos[-1], position, rot.reshape(3, 3))
        if d.qpos[-1] <= y_stop:
            break
        t0, y0 = d.time, d.qpos[-1]
        if driven:              # the force the heavy bus needs, at the step's middle
            ax, spin = base_acceleration(d.time + 0.5 * dt)
            d.ctrl[m.actuator('base_x').id] = DRIVEN_MASS * ax
            d.ctrl[m.actuator('base_spin').id] = DRIVEN_MASS * spin
        mujoco.mj_step(m, d)
    return t0 + (d.time - t0) * (y0 - y_stop) / (y0 - d.qpos[-1]), out


def umbrella_run(marks=MARKS, driven: bool = False):
    """Return the same figures from the umbrella model."""
    values = {'ribs': RIBS, 'sleeve_force': FORCE, 'time_step': 1e-4,
              'sleeve_mass': SLEEVE_MASS, 'youngs_modulus': STIFF,
              'hinge_viscous': list(VISCOUS), 'hinge_coulomb': list(COULOMB),
              'tip_mass': list(TIP_MASS)}
    if driven:
        values.update(DRIVE, base='prescribed')
    else:
        values.update(base='free', bus_mass=BUS_MASS, bus_inertia=BUS_INERTIA)
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping(values))
    marks, out = list(marks), {}
    while not sim.locked:
        sim.step()
        if marks and sim.time >= marks[0] - 1e-12:
            s = sim.state
            out[marks.pop(0)] = (s.qs[0], s.qs[1:4].copy(), BusFrame.of(s.qs[4:7]).rot)
    return sim.lock_time, out


@pytest.mark.slow
def test_a_stiff_hinge_and_a_tip_mass_on_a_free_bus_agree_with_mujoco():
    p = UmbrellaParams()
    t_ref, ref = mujoco_run(p)
    t_lock, ours = umbrella_run()
    assert t_lock == pytest.approx(t_ref, abs=1e-5)
    for mark in MARKS:
        (y_r, x_r, rot_r), (y, x, rot) = ref[mark], ours[mark]
        assert y == pytest.approx(y_r, rel=1e-3)
        np.testing.assert_allclose(x, x_r, rtol=1e-3, atol=1e-3 * np.max(np.abs(x_r)))
        np.testing.assert_allclose(rot, rot_r, rtol=0, atol=1e-3 * abs(rot_r[0, 1]))
    # the asymmetry is what is compared: the bus turns and drifts sideways
    assert abs(ref[0.1][2][0, 1]) > 0.01 and abs(ref[0.1][1][0]) > 1e-4


@pytest.mark.slow
def test_a_driven_base_agrees_with_mujoco():
    """
    The same ribs on a base jolted along X (20 m/s^2 for 20 ms) while spun up to 3 rad/s.

    MuJoCo's bus is driven by forces on a heavy (1e6 kg) body; the umbrella model's base
    follows the prescribed motion exactly.  The drive moves the lock by -1.9 ms from the
    fixed hub's: compared to 1e-5 s (measured 4 us) and the sleeve to 1e-4 relative.
    """
    p = UmbrellaParams()
    t_ref, ref = mujoco_run(p, driven=True)
    t_lock, ours = umbrella_run(driven=True)
    assert t_lock == pytest.approx(t_ref, abs=1e-5)
    for mark in MARKS:
        (y_r, x_r, rot_r), (y, x, rot) = ref[mark], ours[mark]
        assert y == pytest.approx(y_r, rel=1e-4)
        np.testing.assert_allclose(x, x_r, rtol=0, atol=1e-6)          # the drive, tracked
        np.testing.assert_allclose(rot, rot_r, rtol=0, atol=1e-6)
