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
The figures an actuation test asserts on, from a live run's topics or from a recording.

One definition: the deploy time from the first push (core.summary.deploy_start), the
stage-2 peak stress and tip amplitude over the same window after the lock as the offline
summary (core.summary.STAGE2_WINDOW), so that a live and a recorded summary of one run agree
however long the node ran on.

The umbrella of N ribs (RibsRunSummary, of its rib topics): the run summary's definitions
(core.umbrella3d's Summary3D) applied to the publications instead of every physics step
(sampled3d.sampled_figures: each rib's deployment instant, linear between samples, the lag
and the latest rib, the largest tips, each stress component's peak); the deploy time and
each rib's stage-2 figures are summarize_run's, of the rib's in-plane tip and von Mises
peak.  From sampling: the peaks are exact (each publication holds the largest value of every
step since the previous one), their times the publication's that held them (up to a period
late); the deployment instants and the tips are of the samples (with a publication every
physics step, Summary3D's figures).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import warnings

import numpy as np

from ..bag.format import EVENTS_RECORD
from ..bag.reader import read_log
from ..core.summary import (amplitude, deploy_start, deploy_start_of, in_stage2_window,
                            STAGE2_WINDOW)
from ..core.umbrella3d.outputs3d import STRESS_NAMES
from ..core.umbrella3d.sampled3d import sampled_figures
from ..ros.messages import peak_stress_figures, tip_deflection_figures


@dataclass(frozen=True)
class RunSummary:
    """What an actuation test asserts on (SI units, sim time)."""

    first_push_time: float | None   # sim time the first non-zero force acted from
    lock_time: float | None         # sim time the sleeve reached the stop
    deploy_time: float | None       # lock_time - first_push_time (from 0 if it moved at start)
    stage2_peak_stress: float       # max over leaf and link of peak |sigma| after the lock (Pa)
    stage2_tip_amplitude: float     # half peak-to-peak transverse tip deflection after it (m),
    #                                 of the samples at publish_rate: a crest between two is
    #                                 missed (100 Hz: 0.3 % low at V0 = -0.2, 7.3 % after a 10 N
    #                                 push from rest; 1 kHz: < 0.5 %;
    #                                 the offline summary takes every physics step)
    stage2_samples: int             # samples the stage-2 figures come from
    stage2_span: float              # sim time those samples cover (s)


#: the stage-2 window of a run summary (s of sim time after the lock), live or recorded:
#: the offline summary's
SUMMARY_AFTER_LOCK = STAGE2_WINDOW


def peak_stress(msg) -> float:
    """Return the larger of the leaf's and the link's peak |sigma| of a peak_stress message."""
    figures = peak_stress_figures(msg)
    return max(figures['peak_stress_leaf'], figures['peak_stress_link'])


def summarize_run(applied: list[tuple[float, float]], lock_time: float | None,
                  started_moving: bool, tip: list[tuple[float, float]],
                  stress: list[tuple[float, float]],
                  after_lock: float | None = None, model: str | None = None) -> RunSummary:
    """
    Return the run summary: the one place these figures are defined.

    From the applied force history [(t, F)], the lock time, whether the frame moved from
    t = 0 (v0 != 0 or an initial force), tip [(t, transverse deflection)] and stress
    [(t, max(peak leaf, peak link))].  Stage 2 is core.summary.in_stage2_window with
    after_lock as the window (None: every sample after the lock); the deploy time starts at
    core.summary.deploy_start.  model 'rigid-fe': its stage-2 tip and stresses are the zero
    its constraints hold (the messages carry their round-off, ~1e-320), as the core's.
    """
    first_push = 0.0 if started_moving else deploy_start(0.0, applied)
    deploy = (lock_time - first_push if lock_time is not None and first_push is not None
              else None)
    window = math.inf if after_lock is None else after_lock

    def stage2(series):
        if lock_time is None or not series:
            return np.zeros(0), np.zeros(0)
        t, y = np.array(series, dtype=float).T
        keep = in_stage2_window(t, lock_time, window)
        return t[keep], y[keep]

    t2, tip2 = stage2(tip)
    stress2 = stage2(stress)[1]
    if model == 'rigid-fe':     # (its elastic field, held at zero: core.summary.RIGID_FE_ZEROS)
        tip2, stress2 = np.zeros_like(tip2), np.zeros_like(stress2)
    return RunSummary(
        first_push_time=first_push, lock_time=lock_time, deploy_time=deploy,
        stage2_peak_stress=float(stress2.max()) if len(stress2) else math.nan,
        stage2_tip_amplitude=amplitude(tip2) if len(tip2) else math.nan,
        stage2_samples=len(tip2),
        stage2_span=float(t2[-1] - lock_time) if len(t2) else 0.0)


def summary_from_recording(path: str, after_lock: float | None = SUMMARY_AFTER_LOCK):
    """
    Return the run summary of a finalised (or torn) MCAP recording of umbrella_node.

    Of its last run (a ~/reset starts a new segment); every figure is on that run's sim
    time, stage 2 over ``after_lock`` s after the lock as :meth:`SimulatedAntenna.summary`
    (None: to the end of the recording), so neither depends on when the node was stopped;
    ValueError for another after_lock than None or a number > 0; a UserWarning where the
    recording holds less of stage 2 than after_lock (the figures are of what it holds).
    A RunSummary; of a recording of the umbrella of N ribs (``ribs`` >= 2), a
    RibsRunSummary (each rib's figures, from its rib topics: summarize_ribs).
    """
    if after_lock is not None and not (isinstance(after_lock, (int, float))
                                       and not isinstance(after_lock, bool)
                                       and math.isfinite(after_lock) and after_lock > 0):
        raise ValueError(f'after_lock={after_lock!r}: seconds of sim time after the lock '
                         '(a number > 0), or None for the whole of stage 2 recorded')
    log = read_log(path)
    seg = log.segments()[-1]
    params = seg.params
    events = log.metadata.get(EVENTS_RECORD, {})      # the last segment's
    lock_time = float(events['lock_time']) if events.get('lock_time') else None
    applied_topic = log.find_topic('sleeve_force/applied', required=False)
    applied = ([(t, m.data) for t, m in log.decoded(applied_topic, seg)]
               if applied_topic else [])
    if lock_time is None:          # a torn recording: the first 'locked' phase message
        locked = [t for t, m in log.decoded(log.find_topic('deployment_phase'), seg)
                  if m.data == 'locked']
        lock_time = locked[0] if locked else None
    started_moving = deploy_start_of(params, applied) == 0.0
    ribs = params.get('ribs', 1)
    if isinstance(ribs, int) and ribs > 1:
        summary = ribs_summary_of_log(log, seg, applied, lock_time, started_moving, after_lock)
        span = min((s.stage2_span for s in summary.stage2), default=0.0)
    else:
        tip = [(t, tip_deflection_figures(m)['tip_transverse'])
               for t, m in log.decoded(log.find_topic('tip_deflection'), seg)]
        stress = [(t, peak_stress(m))
                  for t, m in log.decoded(log.find_topic('peak_stress'), seg)]
        summary = summarize_run(applied, lock_time, started_moving, tip, stress, after_lock,
                                params.get('model'))
        span = summary.stage2_span
    period = 1.0 / float(params.get('publish_rate') or math.inf)
    if after_lock is not None and lock_time is not None and span < after_lock - 1.5 * period:
        why = (f"the run ended in a solver fault at t = {float(events['fault_time']):g} s: "
               f"{events['fault']}" if 'fault' in events
               else 'a shorter after_lock, or a longer recording')
        warnings.warn(f'{path}: after_lock={after_lock:g} s, but the recording holds '
                      f'{span:.6g} s of stage 2 after the lock: the stage-2 figures are of '
                      f'those ({why})', stacklevel=2)
    return summary


# ------------------------------------------------------------ the umbrella of N ribs
@dataclass(frozen=True)
class RibsRunSummary:
    """What a test of the umbrella of N ribs asserts on (SI units, sim time; ribs from 0)."""

    ribs: int
    first_push_time: float | None       # as RunSummary: the sleeve's
    lock_time: float | None
    deploy_time: float | None
    rib_deploy_time: tuple              # each rib's deployment instant (None: not reached)
    deployment_lag: float | None        # the latest rib's after the earliest's
    latest_rib: int | None
    max_leaf_angle_spread: float        # largest difference of two ribs' alpha1 published
    #                                     before the lock (rad), and when
    max_leaf_angle_spread_time: float | None
    peak_stress: dict                   # component -> each rib's peak |stress| (Pa): axial,
    #                                     bending_in_plane, bending_out_of_plane, torsion,
    #                                     von_mises (outputs3d.STRESS_NAMES)
    peak_stress_time: dict              # component -> the publication that held each peak (s)
    peak_von_mises_at: tuple            # each rib's (body 'leaf' or 'link', x along it in m)
    max_out_of_plane_tip: float         # largest |w| of any rib's tip (m), its rib and when
    max_out_of_plane_tip_rib: int
    max_out_of_plane_tip_time: float
    max_in_plane_tip: tuple             # each rib's largest |v| (m)
    friction_work: float | None         # the hinges' friction work at the end (J, <= 0)
    energy_balance_residual: float      # largest |balance error| published (J)
    stage2: tuple                       # each rib's RunSummary: stage-2 von Mises peak, tip
    #                                     amplitude (in-plane), samples and span
    samples: int                        # publications the figures come from

    @property
    def stage2_peak_stress(self) -> tuple:
        """Return each rib's stage-2 von Mises peak (Pa; RunSummary.stage2_peak_stress)."""
        return tuple(s.stage2_peak_stress for s in self.stage2)

    @property
    def stage2_tip_amplitude(self) -> tuple:
        """Return each rib's stage-2 in-plane tip amplitude (m; half peak-to-peak)."""
        return tuple(s.stage2_tip_amplitude for s in self.stage2)


def summarize_ribs(alpha_deployed, applied: list, lock_time: float | None,
                   started_moving: bool, joints: list, tips: list, stresses: list,
                   energy: list, after_lock: float | None = None) -> RibsRunSummary:
    """
    Return the umbrella's summary of its publications: the one place these figures are made.

    alpha_deployed: each rib's deployed leaf angle (the model's); applied, lock_time,
    started_moving, after_lock: as summarize_run; joints [(t, rib_joint_figures)], tips
    and stresses [(t, rib_array_figures)], energy [(t, rib_energy_figures)], in time order
    (ribs_messages' readers of joint_states, rib_tip_deflection, rib_peak_stress, energy).
    """
    ribs = len(alpha_deployed)
    if not joints or not tips or not stresses:
        raise ValueError('no publications of the umbrella (joint_states, rib_tip_deflection, '
                         'rib_peak_stress) to summarise')
    t_tip = np.array([t for t, _ in tips])
    tip = np.array([[(r['axial_m'], r['in_plane_m'], r['out_of_plane_m']) for r in rows]
                    for _, rows in tips], dtype=float)
    t_stress = np.array([t for t, _ in stresses])
    vm = np.array([[r['von_mises_Pa'] for r in rs] for _, rs in stresses])
    f = sampled_figures(
        alpha_deployed, np.array([t for t, _ in joints]), [j['alpha1'] for _, j in joints],
        t_tip, tip, t_stress,
        {name: [[r[f'{name}_Pa'] for r in rs] for _, rs in stresses] for name in STRESS_NAMES},
        [[(r['von_mises_body'], r['von_mises_x_m']) for r in rs] for _, rs in stresses],
        lock_time)
    stage2 = tuple(summarize_run(applied, lock_time, started_moving,
                                 list(zip(t_tip.tolist(), tip[:, k, 1].tolist())),
                                 list(zip(t_stress.tolist(), vm[:, k].tolist())), after_lock)
                   for k in range(ribs))
    sleeve, peaks = stage2[0], f['peak_stress']
    return RibsRunSummary(
        ribs=ribs, first_push_time=sleeve.first_push_time, lock_time=lock_time,
        deploy_time=sleeve.deploy_time, rib_deploy_time=tuple(f['rib_deploy_time']),
        deployment_lag=f['deployment_lag'], latest_rib=f['latest_rib'],
        max_leaf_angle_spread=f['max_leaf_angle_spread'],
        max_leaf_angle_spread_time=f['max_leaf_angle_spread_time'],
        peak_stress={name: tuple(p['value']) for name, p in peaks.items()},
        peak_stress_time={name: tuple(p['time']) for name, p in peaks.items()},
        peak_von_mises_at=tuple(zip(peaks['von_mises']['body'], peaks['von_mises']['x'])),
        max_out_of_plane_tip=f['max_out_of_plane_tip'],
        max_out_of_plane_tip_rib=f['max_out_of_plane_tip_rib'],
        max_out_of_plane_tip_time=f['max_out_of_plane_tip_time'],
        max_in_plane_tip=tuple(f['max_in_plane_tip']),
        friction_work=energy[-1][1]['friction_work_J'] if energy else None,
        energy_balance_residual=max((abs(e['balance_error_J']) for _, e in energy),
                                    default=0.0),
        stage2=stage2, samples=len(joints))


def ribs_summary_of_log(log, seg, applied: list, lock_time: float | None,
                        started_moving: bool, after_lock: float | None) -> RibsRunSummary:
    """Return the RibsRunSummary of one segment of a recording of the umbrella (bag.reader)."""
    from ..core.umbrella3d.model3d import UmbrellaModel3D
    from ..core.umbrella3d.params3d import node_model
    from ..ros.ribs_messages import rib_array_figures, rib_energy_figures, rib_joint_figures

    model = UmbrellaModel3D(node_model(seg.params))   # (each rib's deployed angle)

    def read(key, reader):
        return [(t, reader(m)) for t, m in log.decoded(log.find_topic(key), seg)]

    return summarize_ribs(model.alpha_deployed, applied, lock_time, started_moving,
                          read('joint_states', rib_joint_figures),
                          read('rib_tip_deflection', rib_array_figures),
                          read('rib_peak_stress', rib_array_figures),
                          read('energy', rib_energy_figures), after_lock)
