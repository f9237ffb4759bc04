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
The umbrella's outputs as plain data: every step's figures per rib, peaks, spread, balance.

``Record3D`` keeps, for every physics step, the joint angles and rates of every rib, the
sleeve, each rib's tip deflection in its leaf frame (axial u, in-plane v, out-of-plane w), the
energies and the work of the sleeve force, of each hinge's friction and of a prescribed base,
the energy lost at the lock, each stuck hinge's holding torque, the bus state and, with a
free-floating bus, the linear and angular momentum.  Stresses: at both ends of every element,
axial E u', bending E c v'' (in the rib plane) and E c w'' (out of it), the St-Venant shear
G c_t phi'; the combined figure is the von Mises stress of the worst corner fibre with the
largest torsion shear, sqrt((|sigma_a| + |sigma_bz| + |sigma_by|)^2 + 3 tau^2), an upper bound
of the section's von Mises stress.  Each rib's peak of every component over the run is kept
with where (body, abscissa) and when.
"""
from __future__ import annotations

import numpy as np

STRESS_NAMES = ('axial', 'bending_in_plane', 'bending_out_of_plane', 'torsion', 'von_mises')
#: the bodies of a rib, by the code a stress's place carries (stress_<name>_at)
BODIES = ('leaf', 'link')


class Record3D:
    """Per-step figures of one run (lists while running; ``arrays()`` stacks them)."""

    def __init__(self, model):
        self.model = model
        self.rows: dict[str, list] = {}
        nr = model.n_ribs
        self.peak = {name: np.zeros(nr) for name in STRESS_NAMES}
        self.peak_where = {name: [('', 0.0, 0.0)] * nr for name in STRESS_NAMES}
        self.work = 0.0
        self.friction = np.zeros(nr)
        self.drive = 0.0
        self.lock_events: list = []
        self.iterations = 0
        self._xs = (model.leaf_bodies[0].stress_x, model.link_bodies[0].stress_x)

    def add(self, s, locked: bool, force: float, work, lock_loss: float, lock_event=None):
        """Take the state at the end of a step (work: the step's StepWork, None at t = 0)."""
        if work is not None:
            self.work += work.force
            self.friction = self.friction + work.friction
            self.drive += work.drive
            self.iterations += work.iterations
        if lock_event is not None:
            self.lock_events.append(lock_event)
        row = self.row(s, locked, force, lock_loss, (self.work, self.friction, self.drive))
        for name in STRESS_NAMES:
            top, (body, x) = row[f'stress_{name}'], row[f'stress_{name}_at'].T
            better = top > self.peak[name]
            if np.any(better):
                self.peak[name] = np.where(better, top, self.peak[name])
                lst = list(self.peak_where[name])
                for k in np.nonzero(better)[0]:
                    lst[k] = (BODIES[int(body[k])], float(x[k]), float(s.t))
                self.peak_where[name] = lst
        rows = self.rows
        for name, value in row.items():
            rows.setdefault(name, []).append(value)

    def row(self, s, locked: bool, force: float, lock_loss: float, totals) -> dict:
        """
        Return the figures of the state s (no side effect): a row of the record.

        totals: the work of the sleeve force, each hinge's friction work and the drive's work
        from t = 0 to s.  Each stress component's figure is, per rib, the largest |value| over
        both bodies' stress points (the leaf's first on a tie) with where: (body, x), body 0
        the leaf (x from O), 1 the link (x from O'').
        """
        m = self.model
        work, friction, drive = totals
        kin = None
        if s.pr is None:
            kin = m.kinematics(s.qr, s.qs)
            pr, ps = m.matvec(m.mass_matrix(kin), s.vr, s.vs)
        else:
            pr, ps = s.pr, s.ps
        kinetic = 0.5 * (float(np.sum(pr * s.vr)) + float(ps @ s.vs))
        out = {
            'time': s.t, 'locked': locked, 'sleeve_position': s.qs[0],
            'sleeve_velocity': s.vs[0], 'sleeve_force': force,
            'alpha1': s.qr[:, m.i_a1].copy(), 'alpha2': s.qr[:, m.i_a2].copy(),
            'alpha1_rate': s.vr[:, m.i_a1].copy(), 'alpha2_rate': s.vr[:, m.i_a2].copy(),
            'tip': s.qr[:, list(m.i_tip)].copy(), 'kinetic_energy': kinetic,
            'strain_energy': m.strain_energy(s.qr), 'work': work,
            'friction_work': np.array(friction, dtype=float), 'drive_work': drive,
            'lock_energy_loss': lock_loss,
            'holding_torque': np.where(np.isnan(s.stuck), 0.0, s.lam_r[:, -1]),
            'stuck': ~np.isnan(s.stuck), 'stop_reaction': float(s.lam_s[0])}
        if m.moving_base:
            out['bus_q'] = s.qs[1:7].copy()
            out['bus_v'] = s.vs[1:7].copy()
            if m.params.base == 'free':
                kin = kin if kin is not None else m.kinematics(s.qr, s.qs)
                out['linear_momentum'], out['angular_momentum'] = m.momentum(kin, s.vr, s.vs)
        nr = m.n_ribs
        tops = {name: np.full((2, nr), -1.0) for name in STRESS_NAMES}
        at = {name: np.zeros((2, nr)) for name in STRESS_NAMES}
        for body, (comps, xs) in enumerate(zip(m.stress_components(s.qr), self._xs)):
            ax, bz, by, sh = comps
            vm = np.sqrt((np.abs(ax) + np.abs(bz) + np.abs(by)) ** 2 + 3.0 * sh * sh)
            for name, values in zip(STRESS_NAMES, (ax, bz, by, sh, vm)):
                a = np.abs(values)
                where = a.argmax(1)
                tops[name][body] = a[np.arange(nr), where]
                at[name][body] = xs[where]
        for name in STRESS_NAMES:
            body = tops[name].argmax(0)             # (the leaf on a tie)
            ribs = np.arange(nr)
            out[f'stress_{name}'] = tops[name][body, ribs]
            out[f'stress_{name}_at'] = np.stack([body.astype(float), at[name][body, ribs]], 1)
        out['von_mises'] = out['stress_von_mises']
        return out

    def take(self) -> dict:
        """Return the rows added since the last take as arrays (``arrays``), and drop them."""
        out = self.arrays()
        self.rows = {}
        return out

    def arrays(self) -> dict:
        """Return every per-step figure as an array (steps first, then ribs or components)."""
        return {name: np.array(values) for name, values in self.rows.items()}

    def summary(self) -> dict:
        """
        Return the run's figures: lock time, each rib's deployment, spread, peaks, balance.

        A rib's deployment instant is when its leaf angle first reaches its deployed angle
        (linear between steps); the lag is the latest rib's after the earliest.  The energy
        balance residual is max |T + V - (T + V)(0) - W_F - W_friction - W_drive + lock loss|.
        """
        m = self.model
        a = self.arrays()
        t = a['time']
        alpha = a['alpha1']
        deployed = np.array([first_reach(t, alpha[:, k] - m.alpha_deployed[k])
                             for k in range(m.n_ribs)])
        energy = a['kinetic_energy'] + a['strain_energy']
        balance = energy_balance3d(a, energy[0])
        tip_w = np.abs(a['tip'][:, :, 2])
        worst = np.unravel_index(np.argmax(tip_w), tip_w.shape)
        out = {
            'lock_time': self.lock_events[0][0] if self.lock_events else None,
            'rib_deploy_time': deployed,
            'deployment_lag': float(np.nanmax(deployed) - np.nanmin(deployed))
            if np.any(np.isfinite(deployed)) else np.nan,
            'max_out_of_plane_tip': float(tip_w[worst]),
            'max_out_of_plane_tip_rib': int(worst[1]),
            'max_out_of_plane_tip_time': float(t[worst[0]]),
            'max_in_plane_tip': np.abs(a['tip'][:, :, 1]).max(0),
            'energy_balance_residual': float(np.max(np.abs(balance))),
            'energy_scale': float(np.max(np.abs(energy))),
            'friction_work': a['friction_work'][-1],
            'newton_iterations': self.iterations,
            'peak_stress': {name: (self.peak[name].copy(), list(self.peak_where[name]))
                            for name in STRESS_NAMES},
        }
        return out


def first_reach(t: np.ndarray, gap: np.ndarray, before: tuple | None = None) -> float:
    """
    Return when gap first reaches 0 from above (linear between steps); nan if it does not.

    A rib's deployment instant (gap: its leaf angle less its deployed angle); t[0] if it
    starts there.  before: (t, gap) of the step before t[0], for a record taken in parts.
    """
    hit = np.nonzero(gap <= 0.0)[0]
    if len(hit) == 0:
        return np.nan
    i = hit[0]
    if i == 0:
        if before is None or before[1] <= 0.0:
            return float(t[0])
        t0, g0 = before
    else:
        t0, g0 = t[i - 1], gap[i - 1]
    return float(t0 + (t[i] - t0) * g0 / (g0 - gap[i]))


def energy_balance3d(rows: dict, initial_energy: float) -> np.ndarray:
    """
    Return T + V - (T + V)(0) - W_F - W_friction - W_drive + lock loss of rows (J).

    rows: a Record3D's arrays (one figure a step) or one row (a Sample3D).

    The umbrella's energy balance, one rule: 0 for a run that keeps its energy (friction
    work is negative: the hinges take energy out).
    """
    return (rows['kinetic_energy'] + rows['strain_energy'] - initial_energy - rows['work']
            - np.sum(rows['friction_work'], axis=-1) - rows['drive_work']
            + rows['lock_energy_loss'])
