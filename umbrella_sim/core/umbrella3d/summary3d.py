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
The umbrella run's figures from every step, taken a chunk at a time (``Summary3D``).

Each rib's deployment instant and the lag of the latest, the largest out-of-plane tip,
each rib's peak of every stress component (where, when), the energy balance with the
hinges' friction work, the bus state of a moving base; the validity warnings on the worst
rib's figures.  ``DrivenSimulator3D.new_summary`` makes one for the run driver.
"""
from __future__ import annotations

import numpy as np

from .blocks3d import RibPeaks, Sample3D, StepBlock3D, VON_MISES
from .corotational3d import out_of_plane_warnings
from .outputs3d import (any_of, BODIES, deployment_spread, energy_balance3d, first_reach,
                        hub_spin_rate, largest, largest_leaf_angle_spread,
                        largest_out_of_plane_tip)
from .simulator3d import UmbrellaSimulator3D
from .stall3d import StallWatch
from .substeps3d import physics_tips3d
from ..model import Stage
from ..outputs import LockEvent
from ..summary import (AXIAL_LOAD_LIMIT, CENTRIFUGAL_TENSION_LIMIT,
                       centrifugal_tension_per_rate, deploy_start, ENERGY_DRIFT_LIMIT,
                       ENERGY_SCALE_FLOOR, hub_spin_tension_per_rate, leaf_tension_ratio,
                       mesh_resolution, naming_rib, parameter_warnings, Stage2Series,
                       validity_warnings, WarningsSaid)

#: a rib's out-of-plane tip amplitude below this (m) has no vibration to time: its period is
#: not given (an unkicked rib's w is round-off, whose crossings are noise)
OUT_OF_PLANE_TIMED = 1e-9


def rib_parameter_warnings(params) -> list[str]:
    """
    Return each rib's own parameter warnings, 'key: rib k, text' (summary.naming_rib).

    Each rib's own section, lengths and material judged as the planar record's are
    (summary.parameter_warnings), where a rib's differ from the record's (whose own warnings
    the umbrella's validity_warnings give, unnamed).
    """
    return [naming_rib(w, k) for k, r in enumerate(params.ribs_list())
            if r.planar != params.planar for w in parameter_warnings(r.planar.as_dict())]


#: the rows of a stage-2 block the summary reads (Summary3D._take; the others are stage 1's)
STAGE2_NAMES = ('time', 'alpha1', 'locked', 'sleeve_position', 'sleeve_velocity', 'stuck',
                'tip', 'stress_axial', 'kinetic_energy', 'strain_energy', 'work',
                'friction_work', 'drive_work', 'lock_energy_loss', 'damping_dissipation')
#: stage-2 rows the summary takes at once.  Its figures of a block cost ~60 us of numpy
#: calls however few its rows, and a node publishing at 1 kHz brings blocks of 5 rows (10
#: physics steps of 6 x 1 ribs: ~500 us): stage-2 blocks wait until they hold this many rows
#: (10 such blocks), and are taken as one, which gives the same figures (each a largest, a
#: first instant or a series over the rows, as the blocks' order gives them).  Stage 1's
#: blocks, the lock's and a fault's are taken at once, and every reader of the figures takes
#: the blocks waiting first, except ``new_warnings``: a stage-2 warning comes up to that many
#: rows after its step (10 ms at a 0.2 ms grid).
SUMMARY_BATCH_ROWS = 50


class Summary3D:
    """
    The umbrella run's figures from every step (StepBlock3D), as SummaryAccumulator's.

    Record3D.summary's figures (each rib's deployment instant and the lag of the latest,
    the largest out-of-plane tip, each rib's peak stresses, the energy balance with friction
    work) for a run taken a chunk at a time, plus the lock and the bus state of a moving base;
    stage 2's blocks taken SUMMARY_BATCH_ROWS rows at a time.
    """

    def __init__(self, sim: UmbrellaSimulator3D, initial: Sample3D):
        """Start from the initial sample of sim (DrivenSimulator3D: its engine read too)."""
        self.sim = sim
        m = sim.model
        self.lock_kind = sim.engine.lock_kind
        self.lock: LockEvent | None = None
        self.error: str | None = None
        self.steps = 0
        self.final_time = float(initial.time)
        self._e0 = float(initial.kinetic_energy + initial.strain_energy)
        self._scale = max(abs(self._e0), ENERGY_SCALE_FLOOR)
        self._balance = 0.0
        self._last = (initial.time, np.array(initial.alpha1))
        self._deployed = np.array([first_reach(np.array([initial.time]),
                                               np.array([initial.alpha1[k] - m.alpha_deployed[k]]))
                                   for k in range(m.n_ribs)])
        self._undeployed = bool(np.isnan(self._deployed).any())
        self._oop = largest_out_of_plane_tip(np.array([initial.time]), initial.tip[None])
        self._angles = largest_leaf_angle_spread(np.array([initial.time]),
                                                 np.asarray(initial.alpha1)[None])
        self._in_plane = np.abs(initial.tip[:, 1])
        self._peaks = RibPeaks.of_rows(
            {name: np.asarray(v)[None] for name, v in initial.fields().items()
             if name.startswith('stress_') or name == 'time'}, 0)
        self._final = initial
        self._waiting: list = []           # (stage-2 blocks not taken yet, and their rows)
        self._waiting_rows = 0
        self._start = deploy_start(float(sim.params.planar.v0), ())
        ribs = sim.params.ribs_list()
        self._stall = StallWatch(float(initial.sleeve_position), m.y_stop,
                                 float(initial.sleeve_velocity), ribs)
        self._stage2 = Stage2Series(2 * m.n_ribs)      # (each rib's v, then each rib's w)
        self._said = WarningsSaid()
        self._warned_steps: int | None = None      # (steps taken at the last new_warnings)
        self._planar = sim.params.planar.as_dict()     # (a frozen record)
        # each rib's leaf tension at its hinge over its Euler load (summary.leaf_tension_ratio:
        # its own section, lengths and tip mass), per squared hinge rate and, with a moving
        # base, the hub circle's share per squared spin; the largest ratio over the ribs in
        # stage 1
        self._rib_parameter_warnings = rib_parameter_warnings(sim.params)
        self._per_rate = np.array([centrifugal_tension_per_rate(r.planar, r.tip_mass)
                                   for r in ribs])
        self._spins = m.moving_base
        # (a prescribed base turns about Y alone: untilted, its spin is psi')
        self._tilts = sim.params.base == 'free'
        self._per_hub = (np.array([hub_spin_tension_per_rate(r.planar, r.tip_mass,
                                                             sim.params.hub_radius)
                                   for r in ribs])
                         if self._spins and sim.params.hub_radius > 0.0 else None)
        self._tension, self._tension_rib = 0.0, 0       # (the largest, and its rib)
        # each rib's largest axial force in stage 2 over its link's Euler load (summary's
        # AXIAL_LOAD_LIMIT): its axial stress peak (leaf or link) times its section's area
        self._axial_per_stress = np.array([r.planar.cross_section_area
                                           / r.planar.link_euler_load for r in ribs])
        self._axial, self._axial_rib = None, 0          # (None: no stage 2 yet)
        # each rib's own E and leaf (l1 + l2): its strain and tip judged against its own
        self._youngs = np.array([r.planar.youngs_modulus for r in ribs])
        self._leaf = np.array([r.planar.l1 + r.planar.l2 for r in ribs])
        if initial.stage == Stage.DEPLOYING:
            self._hold_tension(self._tension_ratio(
                initial.alpha1_rate, initial.alpha1, getattr(initial, 'bus_q', None),
                getattr(initial, 'bus_v', None)))

    def _hold_tension(self, ratio: np.ndarray) -> None:
        """Keep the largest of the ratios (rows of (..., ribs)) and its rib, if larger."""
        top = float(largest(ratio, axis=None))
        if top > self._tension:
            self._tension = top
            self._tension_rib = int(np.unravel_index(np.argmax(ratio), ratio.shape)[-1])

    def _tension_ratio(self, rate, alpha1, bus_q, bus_v) -> np.ndarray:
        """Return each rib's leaf tension over its Euler load at rows of (steps, ribs)."""
        if not self._spins:             # (a fixed hub: the hinge rate's alone)
            return leaf_tension_ratio(self._per_rate, rate)
        spin = hub_spin_rate(bus_q, bus_v) if self._tilts else bus_v[..., 3]
        return leaf_tension_ratio(self._per_rate, rate, spin[..., None], alpha1,
                                  self._per_hub)

    def add(self, block: StepBlock3D) -> None:
        """Take the steps of one block (stage 2's SUMMARY_BATCH_ROWS rows at a time)."""
        if (self.lock is not None and block.lock is None and block.error is None and len(block)
                and block.rows['locked'][0]):
            self._waiting.append(block)
            self._waiting_rows += len(block)
            if self._waiting_rows >= SUMMARY_BATCH_ROWS:
                self._take_waiting()
            return
        self._take_waiting()
        self._take(block, (block,))

    def _take_waiting(self) -> None:
        """Take the stage-2 blocks waiting, as one."""
        blocks = self._waiting
        if not blocks:
            return
        self._waiting, self._waiting_rows = [], 0
        if len(blocks) == 1:
            self._take(blocks[0], blocks)
            return
        rows = [b.rows for b in blocks]
        joined = {name: np.concatenate([r[name] for r in rows]) for name in STAGE2_NAMES}
        self._take(StepBlock3D(joined, blocks[-1].last, physics_tips=physics_tips3d(
            rows, [b.physics_tips for b in blocks])), blocks)

    def _take(self, block: StepBlock3D, peaks: tuple) -> None:
        """Take the steps of a block (its rows; the peaks of those blocks, in order)."""
        if block.lock is not None and self.lock is None:
            self.lock = block.lock
        if block.error is not None:
            self.error = block.error
        if not len(block):
            return
        m, rows = self.sim.model, block.rows
        t = rows['time']
        if self._start is None:
            self._start = deploy_start(0.0, zip([self.final_time, *t[:-1].tolist()],
                                                rows['sleeve_force'].tolist()))
        t_before, alpha_before = self._last
        if self._undeployed and any_of(rows['alpha1'] <= m.alpha_deployed, axis=None):
            # (first_reach of the ribs whose leaf reached its angle)
            ribs = np.nonzero(np.isnan(self._deployed))[0]
            gap = rows['alpha1'][:, ribs] - m.alpha_deployed[ribs]
            for j in np.nonzero((gap <= 0.0).any(0))[0]:
                k = ribs[j]
                self._deployed[k] = first_reach(t, gap[:, j], (
                    t_before, alpha_before[k] - m.alpha_deployed[k]),
                    None if self.lock is None else self.lock.time)
            self._undeployed = bool(np.isnan(self._deployed).any())
        self._last = (float(t[-1]), rows['alpha1'][-1])
        locked = rows['locked']
        if not locked[0]:                          # (stage 1 in the block)
            ratio = self._tension_ratio(rows['alpha1_rate'], rows['alpha1'],
                                        rows.get('bus_q'), rows.get('bus_v'))
            self._hold_tension(ratio if not locked[-1] else ratio[~locked])
            deploying = slice(None) if not locked[-1] else ~locked
            angles = largest_leaf_angle_spread(t[deploying], rows['alpha1'][deploying])
            if angles[0] > self._angles[0]:
                self._angles = angles
        if self._start is not None:         # (a frame not pushed yet has not stalled)
            self._stall.add(t, rows['sleeve_position'], rows['sleeve_velocity'],
                            bool(locked[-1]), rows['stuck'][-1])
        # (each physics step's tips where stage 2 took substeps: the physics' figures)
        t2, tip = (t, None) if block.physics_tips is None else block.physics_tips
        if self.lock is not None and locked[-1] and t2[0] <= self._stage2.end(self.lock.time):
            tip = rows['tip'][:, :, 1:] if tip is None else tip
            self._stage2.add(t2, np.concatenate((tip[:, :, 0], tip[:, :, 1]), axis=1),
                             self.lock.time)
        if locked[-1]:                             # (stage 2 in the block)
            ratio = (rows['stress_axial'] if locked[0] else rows['stress_axial'][locked]) \
                * self._axial_per_stress
            top = float(largest(ratio, axis=None))
            if self._axial is None or top > self._axial:
                self._axial = top
                self._axial_rib = int(np.unravel_index(np.argmax(ratio), ratio.shape)[-1])
        energy = rows['kinetic_energy'] + rows['strain_energy']
        self._scale = max(self._scale, float(largest(np.abs(energy))))
        self._balance = max(self._balance,
                            float(largest(np.abs(energy_balance3d(rows, self._e0, energy)))))
        tip = rows['tip']
        if largest(np.abs(tip[:, :, 2]), axis=None) > self._oop[0]:
            self._oop = largest_out_of_plane_tip(t, tip)
        self._in_plane = np.maximum(self._in_plane, largest(np.abs(tip[:, :, 1])))
        self._peaks = self._peaks.merged_all([b.peaks for b in peaks if b.peaks is not None])
        self.steps += len(block)
        self.final_time = float(t[-1])
        self._final = block.last

    @property
    def energy_drift(self) -> float:
        self._take_waiting()
        return self._balance / self._scale

    def figures(self, stage2: bool = True) -> dict:
        """
        Return the run's figures so far, JSON-ready (lists per rib, ribs numbered from 0).

        stage2: with each rib's stage-2 amplitudes and periods (_stage2_figures: a period's
        search, ~1 ms a rib and direction, made again while the window takes rows), which a
        node's diagnostics every second leave out.
        """
        self._take_waiting()
        start = self._start if self._start is not None else 0.0
        out = {'ribs': self.sim.model.n_ribs,
               'lock_time': self.lock.time if self.lock else None,
               'deploy_time': self.lock.time - start if self.lock else None,
               'deploy_start': self._start,
               **deployment_spread(self._deployed),
               'max_leaf_angle_spread': self._angles[0],
               'max_leaf_angle_spread_time': self._angles[1],
               'max_out_of_plane_tip': self._oop[0],
               'max_out_of_plane_tip_rib': self._oop[1],
               'max_out_of_plane_tip_time': self._oop[2],
               'max_in_plane_tip': self._in_plane.tolist(),
               **(self._stage2_figures() if stage2 else {}),
               # (the lock's worst rib's, as the planar summary's: the step stage 2 takes)
               'stage2_resolution': self._stage2_resolution() if self.lock else None,
               'energy_balance_residual': self._balance,
               'energy_scale': self._scale,
               'energy_drift': self.energy_drift,
               'leaf_tension_ratio_max': self._tension,
               'axial_load_ratio_max': self._axial,
               'sleeve_work': float(self._final.work),
               'friction_work': np.asarray(self._final.friction_work).tolist(),
               'drive_work': float(self._final.drive_work),
               'damping_dissipation': float(self._final.damping_dissipation),
               'lock_energy_loss': float(self._final.lock_energy_loss),
               'peak_stress': {name: {'value': top.tolist(),
                                      'body': [BODIES[int(b)] for b in at[:, 0]],
                                      'x': at[:, 1].tolist(), 'time': when.tolist()}
                               for name, (top, at, when) in self._peaks.items()},
               'final_time': self.final_time, 'steps': self.steps}
        if self.lock:
            out.update(lock=self.lock.kind, lock_energy_before=self.lock.energy_before,
                       lock_energy_after=self.lock.energy_after)
        for name in ('bus_q', 'bus_v', 'linear_momentum', 'angular_momentum'):
            value = getattr(self._final, name, None)
            if value is not None:
                out[name] = np.asarray(value).tolist()
        out['warnings'] = self.warnings()
        if self.error:
            out['error'] = self.error
        return out

    def _stage2_figures(self) -> dict:
        """
        Return each rib's stage-2 tip amplitude and period, in-plane and out of its plane.

        The planar summary's rule (summary.stage2_figures, over its window after the lock),
        on each rib's v and w: lists per rib (None before the window, or for a w too small
        to time: OUT_OF_PLANE_TIMED), and the window.
        """
        n = self.sim.model.n_ribs
        f = self._stage2.figures(self.lock.time if self.lock else None)
        out_of_plane = [g['stage2_tip_amplitude'] for g in f[n:]]
        return {'stage2_window': f[0]['stage2_window'],
                'stage2_tip_amplitude': [g['stage2_tip_amplitude'] for g in f[:n]],
                'stage2_tip_period': [g['stage2_tip_period'] for g in f[:n]],
                'stage2_tip_w_amplitude': out_of_plane,
                'stage2_tip_w_period': [
                    g['stage2_tip_period'] if a is not None and a >= OUT_OF_PLANE_TIMED
                    else None for g, a in zip(f[n:], out_of_plane)]}

    def _geometry(self):
        """Return the co-rotational ribs' largest section slope and out-of-plane rotation."""
        m = self.sim.model
        return (getattr(m, 'max_section_slope', None), getattr(m, 'max_out_of_plane', None))

    def warnings(self) -> list[str]:
        """
        Return the validity warnings: summary's one rule, on the worst rib's figures.

        The yield, strain, deflection and centrifugal texts name that rib ('rib k, ' after
        the key: validity_warnings' ribs).

        'coarse step' judges the lock's worst rib at the step stage 2 takes
        (UmbrellaSimulator3D.stage2_resolution: substeps3d.py; silent where stage 2 takes
        the substeps its lock needs); the co-rotational ribs, which take no substeps, the
        planar rib's mesh at the umbrella's step and its largest in-plane tip deflection
        (summary.mesh_resolution).  The co-rotational ribs' 'fibre rotation' and
        'out-of-plane rotation' from their largest section slope and out-of-plane rotation
        (_geometry).
        """
        self._take_waiting()
        locked = self.lock is not None
        slope, out_of_plane = self._geometry()
        von_mises = self._peaks['von_mises'][0]
        stressed = int(np.argmax(von_mises))
        strained = int(np.argmax(von_mises / self._youngs))
        bent = int(np.argmax(self._in_plane / self._leaf))
        ribs = {'yield exceeded': stressed, 'large strain': strained,
                'large deflection': bent,
                'large out-of-plane deflection': self._oop[1],
                'centrifugal stiffening': self._tension_rib, 'axial load': self._axial_rib}
        return validity_warnings(self._planar, self.lock_kind, float(von_mises.max()),
                                 float(self._in_plane[bent]), locked=locked,
                                 strain=(float(von_mises[strained] / self._youngs[strained]),
                                         float(von_mises[strained])),
                                 leaf_lengths=(float(self._leaf[bent]),
                                               float(self._leaf[self._oop[1]])),
                                 energy_drift=self.energy_drift,
                                 stage2_resolution=self._stage2_resolution() if locked else None,
                                 section_slope=slope, centrifugal_tension=self._tension,
                                 link_axial_load=self._axial,
                                 ribs=ribs, out_of_plane_tip=abs(self._oop[0])
                                 ) + out_of_plane_warnings(self._planar, out_of_plane) + list(
            self._rib_parameter_warnings) + self._stall.warnings()

    def _stage2_resolution(self) -> dict | None:
        """Return the lock's stage-2 resolution (the worst rib's), else the mesh's."""
        own = self.sim.stage2_resolution
        return own if own is not None else mesh_resolution(self._planar, self.sim.h)

    def new_warnings(self) -> list[str]:
        """
        Return the warnings not returned by an earlier call (a log line each, once).

        Of the blocks taken (stage 2's waiting blocks not: SUMMARY_BATCH_ROWS): none new
        while no step was taken since the last call.
        """
        if self.steps == self._warned_steps:
            return []
        self._warned_steps = self.steps
        # the warnings depend on the run only through these
        vm = self._peaks.value[:, VON_MISES]
        return self._said.new((largest(vm), largest(vm / self._youngs),
                               largest(self._in_plane / self._leaf), self._oop[0],
                               self.lock is not None,
                               self._balance / self._scale > ENERGY_DRIFT_LIMIT,
                               self._tension > CENTRIFUGAL_TENSION_LIMIT,
                               (self._axial or 0.0) > AXIAL_LOAD_LIMIT, *self._geometry(),
                               self._stall.stall),
                              self.warnings)
