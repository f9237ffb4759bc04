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
The figures a test of the umbrella of N ribs asserts on, from a recording of its rib topics.

The definitions are the run summary's (core.umbrella3d: Summary3D), applied to the
publications instead of every physics step: each rib's deployment instant is where its leaf
angle first reaches its deployed angle, linear between samples (outputs3d.first_reach), the
lag and the latest rib outputs3d.deployment_spread, the largest out-of-plane tip
outputs3d.largest_out_of_plane_tip, each stress component's peak StepBlock3D.peaks (the first
sample holding the largest).  The deploy time and each rib's stage-2 figures are the planar
test summary's (summary.summarize_run), of the rib's in-plane tip and von Mises peak.

What follows from sampling: the peaks are exact (each publication holds the largest value
of every step since the previous one), their times the publication's that held them (up to
a period late); the deployment instants and the tips are of the samples (with a publication
every physics step, Summary3D's figures exactly).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .summary import RunSummary, summarize_run
from ..core.umbrella3d.driven3d import StepBlock3D
from ..core.umbrella3d.outputs3d import (BODIES, deployment_spread, first_reach,
                                         largest_out_of_plane_tip, STRESS_NAMES)


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
    alpha_deployed = np.asarray(alpha_deployed, dtype=float)
    ribs = len(alpha_deployed)
    if not joints or not tips or not stresses:
        raise ValueError('no publications of the umbrella (joint_states, rib_tip_deflection, '
                         'rib_peak_stress) to summarise')
    t_joint = np.array([t for t, _ in joints])
    alpha1 = np.array([f['alpha1'] for _, f in joints], dtype=float)
    if alpha1.shape[1] != ribs:
        raise ValueError(f'joint_states of {alpha1.shape[1]} ribs for a model of {ribs}')
    deployed = [first_reach(t_joint, alpha1[:, k] - alpha_deployed[k]) for k in range(ribs)]
    t_tip = np.array([t for t, _ in tips])
    tip = np.array([[(r['axial_m'], r['in_plane_m'], r['out_of_plane_m']) for r in rows]
                    for _, rows in tips], dtype=float)
    w, w_rib, w_time = largest_out_of_plane_tip(t_tip, tip)
    rows = {'time': np.array([t for t, _ in stresses])}
    for name in STRESS_NAMES:
        rows[f'stress_{name}'] = np.array([[r[f'{name}_Pa'] for r in rs] for _, rs in stresses])
        rows[f'stress_{name}_at'] = np.full(rows[f'stress_{name}'].shape + (2,), np.nan)
    rows['stress_von_mises_at'] = np.array([[(r['von_mises_body'], r['von_mises_x_m'])
                                             for r in rs] for _, rs in stresses])
    peaks = StepBlock3D(rows, None).peaks          # Summary3D's peak rule, sample by sample
    stage2 = tuple(summarize_run(applied, lock_time, started_moving,
                                 list(zip(t_tip.tolist(), tip[:, k, 1].tolist())),
                                 list(zip(rows['time'].tolist(),
                                          rows['stress_von_mises'][:, k].tolist())),
                                 after_lock) for k in range(ribs))
    sleeve = stage2[0]
    return RibsRunSummary(
        ribs=ribs, first_push_time=sleeve.first_push_time, lock_time=lock_time,
        deploy_time=sleeve.deploy_time, **_spread(deployed),
        peak_stress={name: tuple(p[0].tolist()) for name, p in peaks.items()},
        peak_stress_time={name: tuple(p[2].tolist()) for name, p in peaks.items()},
        peak_von_mises_at=tuple((BODIES[int(b)], float(x))
                                for b, x in peaks['von_mises'][1]),
        max_out_of_plane_tip=w, max_out_of_plane_tip_rib=w_rib, max_out_of_plane_tip_time=w_time,
        max_in_plane_tip=tuple(np.abs(tip[:, :, 1]).max(0).tolist()),
        friction_work=energy[-1][1]['friction_work_J'] if energy else None,
        energy_balance_residual=max((abs(e['balance_error_J']) for _, e in energy),
                                    default=0.0),
        stage2=stage2, samples=len(joints))


def _spread(deployed) -> dict:
    spread = deployment_spread(deployed)
    spread['rib_deploy_time'] = tuple(spread['rib_deploy_time'])
    return spread


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

