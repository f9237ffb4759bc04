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
Two recorded runs' difference: the runs' samples brought to common instants.

umbrella_compare's differences of the planar signals and of each rib's leaf angle: on the
coarser run's publications, or where the rates are not multiples of each other on the
instants both runs published at, a peak-hold re-held over the coarser periods.
"""
from __future__ import annotations

import math

import numpy as np

from ..bag.reader import LogError


def spacing(t) -> float:
    """Return a run's publication period: the median spacing of its instants t."""
    return float(np.median(np.diff(t))) if len(t) > 1 else math.inf


def on_grid(t, y, grid, peak_hold: bool):
    """
    Return series (t, y) on the instants grid, a coarser one.

    A value (linear interpolation), or for a peak-hold the largest of y over each grid
    period (grid[k-1], grid[k]], as the coarser run's own peak-hold holds.
    """
    if not peak_hold:
        return np.interp(grid, t, y)
    tol = 1e-9                      # stamps are exact to the recording's 1 ns
    period = grid[1] - grid[0] if len(grid) > 1 else 0.0     # (the first: one period too)
    hi = np.searchsorted(t, grid + tol, side='right')
    lo = np.searchsorted(t, np.concatenate(([grid[0] - period], grid[:-1])) + tol,
                         side='right')
    out = np.interp(grid, t, y)     # (a period with no sample of the finer run)
    for k in np.nonzero(hi > lo)[0]:
        out[k] = y[lo[k]:hi[k]].max()
    return out


def published_at(t, instants):
    """Return the mask of instants that are samples of t (to the recordings' 1 ns)."""
    tol = 1e-9
    i = np.minimum(np.searchsorted(t, instants - tol), len(t) - 1)
    return np.abs(t[i] - instants) <= tol


def difference(ref_t, ref_y, t, y, peak_hold: bool = False):
    """
    Return (max, rms) of y - ref_y over the span both runs cover.

    On the instants of the coarser run (its publications), the other one brought to them,
    so that runs recorded at two rates compare as they would at the coarser one, whichever
    is the reference: a value taken at them, a peak-hold re-held over their periods.  That
    needs the finer run's samples to include them, as when one rate is a multiple of the
    other; else (100 and 40 Hz) only the instants both runs published at compare (every
    0.05 s), each run's peak-hold re-held over the periods between two of them, which both
    runs' periods tile: a value interpolated between two samples differs from the run by up
    to (omega h)^2 / 8 of a vibration's amplitude (22 % for 47 ms at 100 Hz), and a
    peak-hold over a period that is not a union of the finer run's holds other instants.
    Where fewer than two instants are shared, the finer run is interpolated.
    """
    lo, hi = max(ref_t[0], t[0]), min(ref_t[-1], t[-1])
    if spacing(t) > spacing(ref_t) * (1 + 1e-6):        # the other run is the coarser
        ref_t, ref_y, t, y, sign = t, y, ref_t, ref_y, -1.0
    else:
        sign = 1.0
    keep = (ref_t >= lo - 1e-9) & (ref_t <= hi + 1e-9)
    if keep.sum() < 2:
        raise LogError('runs do not overlap in time')
    grid, ref_on_grid = ref_t[keep], ref_y[keep]
    shared = published_at(t, grid)
    if not shared.all() and shared.sum() >= 2:      # (the runs' instants differ)
        grid = grid[shared]
        ref_on_grid = (on_grid(ref_t, ref_y, grid, True) if peak_hold
                       else ref_on_grid[shared])
    d = sign * (on_grid(t, y, grid, peak_hold) - ref_on_grid)
    return float(np.abs(d).max()), float(np.sqrt(np.mean(d * d)))
