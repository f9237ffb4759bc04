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
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from ..bag.format import EVENTS_RECORD
from ..bag.reader import read_log
from ..core.summary import (amplitude, deploy_start, deploy_start_of, in_stage2_window,
                            STAGE2_WINDOW)
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
    #                                 missed (100 Hz: up to 6.4 % low at V0 = -0.2; 1 kHz: < 0.9 %;
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
                  after_lock: float | None = None) -> RunSummary:
    """
    Return the run summary: the one place these figures are defined.

    From the applied force history [(t, F)], the lock time, whether the frame moved from
    t = 0 (v0 != 0 or an initial force), tip [(t, transverse deflection)] and stress
    [(t, max(peak leaf, peak link))].  Stage 2 is core.summary.in_stage2_window with
    after_lock as the window (None: every sample after the lock); the deploy time starts at
    core.summary.deploy_start.
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
    (None: to the end of the recording), so neither depends on when the node was stopped.
    A RunSummary; of a recording of the umbrella of N ribs (``ribs`` >= 2), a
    RibsRunSummary (ribs_summary.py: each rib's figures, from its rib topics).
    """
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
        from .ribs_summary import ribs_summary_of_log

        return ribs_summary_of_log(log, seg, applied, lock_time, started_moving, after_lock)
    tip = [(t, tip_deflection_figures(m)['tip_transverse'])
           for t, m in log.decoded(log.find_topic('tip_deflection'), seg)]
    stress = [(t, peak_stress(m)) for t, m in log.decoded(log.find_topic('peak_stress'), seg)]
    return summarize_run(applied, lock_time, started_moving, tip, stress, after_lock)
