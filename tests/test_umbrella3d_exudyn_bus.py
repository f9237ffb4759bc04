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
The co-rotational ribs on a free-floating bus against Exudyn's geometrically exact 3D beams.

docs/exudyn_umbrella_ribs.py --bus models three ribs (V0 = -1 m/s, plastic lock) on a free
rigid bus (10 kg, 0.5 kg m^2 about X and Z, 0.1 about the hub axis Y; its mass centre at the
hub), the massless sleeve sliding on the bus's axle, rib 1 carrying a tip mass off its plane
(0.1 kg at 0.05 m along e_t), the whole system's momentum zero at t = 0 (the bus takes the
rigid velocity that cancels the ribs').  The bus moves in reaction: 53.6 mm up the hub axis,
3 and 4.4 mm across it, a tilt of the hub axis of 0.129 rad (the tip mass moves the mass
centre off the axis) and a turn about it of up to 0.025 rad (the offset swings about it) by
the lock at 43.48 ms; the bus's rotation bends every rib out of its plane (rib 0 by 52 mm).
Its figures at three meshes and steps (n = 4, 8, 16 elements a segment at 20, 10, 5 us), and
the same tip mass in rib 1's plane at n = 8 and 16, are in docs/exudyn_umbrella_bus.json;
this test reads them (no Exudyn needed) and runs the umbrella (flexible-nonlinear, 2
elements a segment, 25 us, compiled: ~0.7 CPU s a run) on the same cases.

Compared over stage 1 (to the lock), where every rib stays inside the co-rotational ribs'
range (out-of-plane rotation below 0.1 rad: 0.078 at most, asserted on the reference); after
the lock both models pass 0.4 rad within 6 ms and the bus's turn parts from the reference's
(3.5 % at 8 ms; over the 20 ms of stage 2 14 % of its peak, where the reference moved 3.4 %
from n = 8 to 16): not asserted.
Tolerances (TOLERANCES; docs/umbrella3d_nonlinear.md has the table) from the convergence:
each at least 1.4x the reference's change n = 8 -> 16 (asserted: below 0.7 of it), and above
the difference of our coarse mesh (ours moved up to 0.64 % from 2 to 4 elements a segment):

* deploy time: seen +0.002 %, the reference moved 0.006 %: 0.02 % asserted;
* the bus's histories (X, Y, Z, turn, tilt; the largest difference / the peak): seen 0.12,
  0.004, 0.047, 0.20, 0.034 %, the reference moved 0.094, 0.006, 0.048, 0.19, 0.030 %: 0.3,
  0.03, 0.2, 1 and 0.2 % asserted;
* every rib's largest in-plane and out-of-plane tip in stage 1: seen up to 0.64 and 0.73 %,
  the reference moved up to 0.19 and 0.08 %: 1 % asserted;
* every rib's out-of-plane history w(t): seen 0.12, 0.34, 1.10 %, the reference moved 0.16,
  0.31, 0.45 %: 1.5 % asserted.

Not explained by the convergence of either model: our converged figures (8 elements a
segment, 6.25 us) stay 0.45-0.92 % off the out-of-plane figures (rib 1's largest out-of-plane
tip +0.79 %, its history 0.92 %, the bus's turn 0.45 %) where the reference moved 0.03-0.31
%.  The same tip mass in rib 1's plane (rib 1 and the bus's turn stay 0) leaves 0.05 % (rib
0's largest out-of-plane tip) and 0.13 % (its history); half the tip mass off the plane
(n = 8) leaves relative differences of the same size (rib 1's tip, its history, the turn:
0.59, 1.6, 0.62 % against 0.75, 1.06, 0.63 %): a difference that goes with the tip mass's
offset, in proportion, as in the fixed-hub comparison (+0.92 %, tests/
test_umbrella3d_exudyn.py).  A share of it, measured (docs/umbrella3d_nonlinear.md): the
co-rotational ribs carry the offset by the section's linear small rotation (beam3d.BeamBody3D.
attached_point); the finite one brings rib 1's out-of-plane tip to +0.24 % and the in-plane
tips within 0.21 %, but leaves ribs 1 and 2's out-of-plane histories, rib 2's tip and the
bus's turn 0.5-1.1 % off.
The tolerances above include it.

The momentum: ours stays zero to round-off (linear 2e-13 N s; angular, to the Newton
tolerance, 1e-7 N m s), the reference's to its integrator's error (1.2e-8 at the lock at n =
16, the plastic lock keeping it to 1e-10): asserted 1e-6 of m v (and m v L).  The linear
umbrella (model flexible) misses by 5x more or worse (asserted) on every figure but rib 0's
largest out-of-plane tip (+0.46 % against +0.31 %): deploy time +0.53 %, the bus's turn 23 %
and tilt 2.7 %, the in-plane tips 23-36 %, rib 1's out-of-plane history 56 %.
"""
import json
import os

import numpy as np
import pytest

from umbrella_sim.core.umbrella3d.corotational3d import OUT_OF_PLANE_LIMIT
from umbrella_sim.core.umbrella3d.model3d import BusFrame
from umbrella_sim.core.umbrella3d.outputs3d import bus_attitude
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D

REFERENCE = os.path.join(os.path.dirname(__file__), '..', 'docs', 'exudyn_umbrella_bus.json')
ELEMENTS, STEP = 2, 2.5e-5
FINEST, COARSER = 16, 8
#: the bus series' columns (docs/exudyn_umbrella_ribs.py: t, X, Y, Z, turn, tilt)
BUS_COLUMNS = {'bus.X': 1, 'bus.Y': 2, 'bus.Z': 3, 'bus.turn': 4, 'bus.tilt': 5}


#: rib 1's tip mass offset along e_t (m): the case, and the same mass in the rib's plane
OFFSET, IN_PLANE = 0.05, 0.0


def reference(n: int, offset: float = OFFSET) -> dict:
    with open(REFERENCE, encoding='utf-8') as fh:
        cases = json.load(fh)['cases']
    return next(c for c in cases if c['elements_per_segment'] == n
                and c['tip_offset_z_rib1'] == offset)


def umbrella_run(model: str, ref: dict) -> dict:
    """Return our run of the reference's case in the reference's terms (series, figures)."""
    ribs = ref['ribs']
    sim = UmbrellaSimulator3D(UmbrellaRibsParams.from_mapping({
        'ribs': ribs, 'model': model, 'v0': ref['v0'], 'lock': 'plastic', 'time_step': STEP,
        'elements_per_segment': ELEMENTS, 'base': 'free', 'bus_mass': ref['bus_mass'],
        'bus_inertia': ref['bus_inertia'], 'bus_inertia_y': ref['bus_inertia_y'],
        'sleeve_mass': ref['sleeve_mass'], 'rib1.tip_mass': ref['tip_mass_rib1'],
        'rib1.tip_offset_z': ref['tip_offset_z_rib1']}))
    rec = sim.run(1.0, after_lock=ref['stage2'])
    a = rec.arrays()
    rot = np.array([BusFrame.of(theta).rot for theta in a['bus_q'][:, 3:6]])
    turn, tilt = bus_attitude(rot)
    rib_mass = sim.model.total_mass - sim.model.bus_mass - sim.model.sleeve_mass
    return {'deploy_time': sim.lock_time, 't': a['time'], 'tip': a['tip'],
            'bus': np.column_stack([a['time'], a['bus_q'][:, 0:3], turn, tilt]),
            'linear_momentum': a['linear_momentum'], 'angular_momentum': a['angular_momentum'],
            'momentum_scale': rib_mass * abs(ref['v0']),
            'leaf_length': sim.params.planar.l1 + sim.params.planar.l2,
            'lock_energy_loss': float(a['lock_energy_loss'][-1]),
            'max_out_of_plane': getattr(sim.model, 'max_out_of_plane', None)}


def as_run(ref: dict) -> dict:
    """Return a reference case in umbrella_run's terms (its series at its samples)."""
    series = [np.array(ref[f'rib{r}']['tip_series']) for r in range(ref['ribs'])]
    tip = np.zeros((len(series[0]), ref['ribs'], 3))
    for r, s in enumerate(series):
        tip[:, r, 1:] = s[:, 1:]
    return {'deploy_time': ref['deploy_time'], 't': series[0][:, 0], 'tip': tip,
            'bus': np.array(ref['bus_series'])}


def differences(ours: dict, ref: dict) -> dict:
    """
    Return the differences ours - the reference's of the compared figures.

    The deploy time (relative) and, over stage 1, each rib's largest in-plane and
    out-of-plane tip (relative), each rib's out-of-plane history and the bus's histories
    (the largest difference at the reference's samples, relative to its peak).
    """
    with np.errstate(divide='ignore', invalid='ignore'):    # (a figure the case leaves 0)
        return _differences(ours, ref)


def _differences(ours: dict, ref: dict) -> dict:
    out = {'deploy_time': (ours['deploy_time'] - ref['deploy_time']) / ref['deploy_time']}
    t_end = min(ours['deploy_time'], ref['deploy_time'])
    s_ours, s_ref = ours['t'] <= ours['deploy_time'], ref['t'] <= ref['deploy_time']
    common = ref['t'] <= t_end
    for r in range(ref['tip'].shape[1]):
        for name, i in (('in_plane', 1), ('out_of_plane', 2)):
            a = np.abs(ours['tip'][s_ours, r, i]).max()
            b = np.abs(ref['tip'][s_ref, r, i]).max()
            out[f'rib{r}.stage1_max_{name}_tip'] = (a - b) / b
        w = np.interp(ref['t'][common], ours['t'], ours['tip'][:, r, 2])
        w_ref = ref['tip'][common, r, 2]
        out[f'rib{r}.stage1_out_of_plane_history'] = float(
            np.abs(w - w_ref).max() / np.abs(w_ref).max())
    bus = ref['bus'][ref['bus'][:, 0] <= t_end]
    for key, col in BUS_COLUMNS.items():
        x = np.interp(bus[:, 0], ours['bus'][:, 0], ours['bus'][:, col])
        out[f'{key}_history'] = float(np.abs(x - bus[:, col]).max() / np.abs(bus[:, col]).max())
    return out


#: relative, from the convergence (module docstring; docs/umbrella3d_nonlinear.md's table)
TOLERANCES = {'deploy_time': 2e-4, 'bus.X_history': 3e-3, 'bus.Y_history': 3e-4,
              'bus.Z_history': 2e-3, 'bus.turn_history': 0.01, 'bus.tilt_history': 2e-3,
              **{f'rib{r}.{key}': tol for r in range(3) for key, tol in (
                  ('stage1_max_in_plane_tip', 0.01), ('stage1_max_out_of_plane_tip', 0.01),
                  ('stage1_out_of_plane_history', 0.015))}}
#: where the linear umbrella (model flexible) misses by 5x more: all but rib 0's largest
#: out-of-plane tip (1.5x: its history is 10 % off, but its peak near the lock meets it)
FURTHER_OFF = tuple(k for k in TOLERANCES if k != 'rib0.stage1_max_out_of_plane_tip')
#: the figures of the case with rib 1's tip mass in its plane (rib 1 stays in its plane,
#: the bus does not turn: those figures are 0 there)
IN_PLANE_FIGURES = tuple(k for k in TOLERANCES if not k.startswith('rib1.stage1_max_out')
                         and not k.startswith('rib1.stage1_out') and k != 'bus.turn_history')
#: the momentum kept zero: linear (N s) / m v, angular (N m s) / m v L; m the ribs' mass,
#: v = |V0|, L = l1 + l2
MOMENTUM_TOLERANCE = 1e-6


@pytest.fixture(scope='module')
def runs():
    ref = reference(FINEST)
    return {model: umbrella_run(model, ref) for model in ('flexible-nonlinear', 'flexible')}


@pytest.fixture(scope='module')
def in_plane_run():
    return umbrella_run('flexible-nonlinear', reference(FINEST, IN_PLANE))


def test_the_bus_reference_is_converged_within_the_tolerances():
    """The reference's change n = 8 -> 16 is below 0.7 of each tolerance; the case's range."""
    fine, coarse = reference(FINEST), reference(COARSER)
    change = differences(as_run(coarse), as_run(fine))
    for key, tol in TOLERANCES.items():
        assert abs(change[key]) < 0.7 * tol, (key, change[key])
    for r in range(fine['ribs']):
        # every rib inside the co-rotational ribs' stated range over the compared stage 1
        assert fine[f'rib{r}']['max_out_of_plane_rotation_stage1'] < OUT_OF_PLANE_LIMIT
    # the bus moves in reaction: it tilts and turns about the hub axis by a measurable angle
    bus = np.array(fine['bus_series'])
    bus = bus[bus[:, 0] <= fine['deploy_time']]
    assert np.abs(bus[:, BUS_COLUMNS['bus.turn']]).max() > 0.02
    assert np.abs(bus[:, BUS_COLUMNS['bus.tilt']]).max() > 0.05


def test_corotational_ribs_on_a_free_bus_agree_with_the_reference(runs):
    """Deploy time, every rib's tips and out-of-plane history, the bus's position, attitude."""
    diff = differences(runs['flexible-nonlinear'], as_run(reference(FINEST)))
    for key, tol in TOLERANCES.items():
        assert abs(diff[key]) < tol, (key, diff[key])


def test_both_models_keep_the_momentum_zero(runs):
    """Ours over the run (through the lock); the reference's at the lock, before and after."""
    ref = reference(FINEST)
    ours = runs['flexible-nonlinear']
    scale, length = ours['momentum_scale'], ours['leaf_length']
    assert np.abs(ours['linear_momentum']).max() < MOMENTUM_TOLERANCE * scale
    assert np.abs(ours['angular_momentum']).max() < MOMENTUM_TOLERANCE * scale * length
    for when in ('before_lock', 'after_lock'):
        linear, angular = ref['momentum'][when]
        assert np.abs(linear).max() < MOMENTUM_TOLERANCE * scale, (when, linear)
        assert np.abs(angular).max() < MOMENTUM_TOLERANCE * scale * length, (when, angular)


def test_the_linear_umbrella_is_further_off_on_the_bus(runs):
    """Where the bus's motion bends the ribs out of plane the linear ribs miss by 5x more."""
    ref = as_run(reference(FINEST))
    nl = differences(runs['flexible-nonlinear'], ref)
    lin = differences(runs['flexible'], ref)
    for key in FURTHER_OFF:
        assert abs(lin[key]) > 5.0 * abs(nl[key]), (key, lin[key], nl[key])


def test_a_tip_mass_in_the_plane_agrees_too(in_plane_run):
    """
    The same tip mass in rib 1's plane: the bus tilts but does not turn; ribs 0 and 2 bend.

    The reference's change n = 8 -> 16 below 0.7 of each tolerance, ours within it; rib 1
    stays in its plane and the bus does not turn about the hub axis, in both models.
    """
    fine = as_run(reference(FINEST, IN_PLANE))
    change = differences(as_run(reference(COARSER, IN_PLANE)), fine)
    diff = differences(in_plane_run, fine)
    for key in IN_PLANE_FIGURES:
        assert abs(change[key]) < 0.7 * TOLERANCES[key], (key, change[key])
        assert abs(diff[key]) < TOLERANCES[key], (key, diff[key])
    for run in (fine, in_plane_run):
        assert np.abs(run['bus'][:, BUS_COLUMNS['bus.turn']]).max() < 1e-6
        assert np.abs(run['tip'][:, 1, 2]).max() < 1e-6


def test_bus_attitude_reads_the_turn_and_the_tilt():
    """A turn a about Y then a tilt b about X (either order): turn a, tilt |b|."""
    def rot(axis, angle):
        c, s = np.cos(angle), np.sin(angle)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        r = np.eye(3)
        r[i, i] = r[j, j] = c
        r[i, j], r[j, i] = -s, s
        return r
    for a, b in ((0.3, 0.0), (0.0, -0.2), (-0.7, 0.15), (2.5, 0.4)):
        for r in (rot(1, a) @ rot(0, b), rot(0, b) @ rot(1, a), rot(1, a) @ rot(2, b)):
            turn, tilt = bus_attitude(r)
            assert abs(turn - a) < 1e-12 and abs(tilt - abs(b)) < 1e-12
    # vectorised, and the umbrella's own attitude R = Ry(psi) Rx(beta) Rz(gamma)
    frames = np.array([BusFrame.of((0.1 * k, 0.0, 0.0)).rot for k in range(4)])
    turn, tilt = bus_attitude(frames)
    assert np.allclose(turn, 0.1 * np.arange(4), atol=1e-12) and np.allclose(tilt, 0.0)
