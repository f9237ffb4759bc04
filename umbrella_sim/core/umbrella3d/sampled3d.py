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
The umbrella's per-rib summary figures of samples (publications) instead of every step.

Summary3D's definitions (driven3d) applied to the instants a recording or a live subscriber
has: each rib's deployment instant where its leaf angle first reaches its deployed angle,
linear between samples, the lock's instant between the samples the lock falls in
(outputs3d.first_reach), the lag and the latest rib
(outputs3d.deployment_spread), the largest out-of-plane tip (outputs3d.
largest_out_of_plane_tip) and each rib's largest in-plane one, each stress component's peak
(StepBlock3D.peaks: the first sample holding the largest).  The keys and shapes are
Summary3D.figures' (JSON-ready), so that a reader takes either.  Sampled: a peak-hold
stress (each publication the largest of every step since the previous one) gives the
every-step peak exactly, at the publication that held it; the angles and tips are those
of the samples (a crossing or a crest between two is missed).
"""
from __future__ import annotations

import numpy as np

from .blocks3d import StepBlock3D
from .outputs3d import (BODIES, deployment_spread, first_reach, largest_leaf_angle_spread,
                        largest_out_of_plane_tip, STRESS_NAMES)


def sampled_figures(alpha_deployed, t: np.ndarray, alpha1: np.ndarray, tip_t: np.ndarray,
                    tip: np.ndarray, stress_t: np.ndarray, stress: dict,
                    von_mises_at: np.ndarray | None = None,
                    lock_time: float | None = None) -> dict:
    """
    Return Summary3D's per-rib figures of samples (SI units; lists per rib, rib 0 first).

    alpha_deployed: each rib's deployed leaf angle (the model's); t, alpha1 (T, ribs): the
    leaf angles' samples; tip_t, tip (T', ribs, 3): the tips' (u, v, w); stress_t, stress
    {component: (T'', ribs)}: each rib's held peak of every component (outputs3d.
    STRESS_NAMES), von_mises_at (T'', ribs, 2) where (body code, x) if known, lock_time
    the lock's instant (None: the run did not lock, or it is not known).  Returns
    rib_deploy_time, deployment_lag, latest_rib, max_leaf_angle_spread (_time: of the
    samples before lock_time, all without it), max_out_of_plane_tip (_rib, _time),
    max_in_plane_tip and peak_stress {component: {value, body, x, time}} (body and x None
    where the samples do not say).
    """
    alpha_deployed = np.asarray(alpha_deployed, dtype=float)
    alpha1 = np.asarray(alpha1, dtype=float)
    tip = np.asarray(tip, dtype=float)
    ribs = len(alpha_deployed)
    if alpha1.shape[1:] != (ribs,) or tip.shape[1:] != (ribs, 3):
        raise ValueError(f'samples of {alpha1.shape[1:]} / {tip.shape[1:]} ribs for a model '
                         f'of {ribs}')
    deployed = [first_reach(np.asarray(t), alpha1[:, k] - alpha_deployed[k], lock=lock_time)
                for k in range(ribs)]
    w, w_rib, w_time = largest_out_of_plane_tip(np.asarray(tip_t), tip)
    rows = {'time': np.asarray(stress_t, dtype=float)}
    for name in STRESS_NAMES:
        rows[f'stress_{name}'] = np.asarray(stress[name], dtype=float)
        rows[f'stress_{name}_at'] = np.full(rows[f'stress_{name}'].shape + (2,), np.nan)
    if von_mises_at is not None:
        rows['stress_von_mises_at'] = np.asarray(von_mises_at, dtype=float)
    peaks = {}
    for name, (top, at, when) in StepBlock3D(rows, None).peaks.items():
        known = np.isfinite(at[:, 0])
        peaks[name] = {'value': top.tolist(),
                       'body': [BODIES[int(b)] if ok else None for b, ok in zip(at[:, 0], known)],
                       'x': [float(x) if ok else None for x, ok in zip(at[:, 1], known)],
                       'time': when.tolist()}
    deploying = np.asarray(t) < (np.inf if lock_time is None else lock_time)
    angles, angles_when = largest_leaf_angle_spread(np.asarray(t)[deploying], alpha1[deploying])
    return {**deployment_spread(deployed), 'max_leaf_angle_spread': angles,
            'max_leaf_angle_spread_time': angles_when, 'max_out_of_plane_tip': w,
            'max_out_of_plane_tip_rib': w_rib, 'max_out_of_plane_tip_time': w_time,
            'max_in_plane_tip': np.abs(tip[:, :, 1]).max(0).tolist(), 'peak_stress': peaks}
