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
The umbrella's figures as the run driver hands them on: an instant's, a chunk's, its peaks.

``Sample3D`` is one instant's figures, per rib where the rib has its own (arrays of N);
``StepBlock3D`` the rows of a chunk's steps (Record3D's), the planar StepBlock's role;
``RibPeaks`` each rib's largest of every stress component over steps, where and when.
"""
from __future__ import annotations

import numpy as np

from .outputs3d import any_of, STRESS_NAMES, STRESS_ROWS
from ..model import Stage
from ..outputs import LockEvent


class Sample3D:
    """
    The umbrella's figures at one instant (read-only): Record3D's row names as attributes.

    time, stage (model.Stage), sleeve_position, sleeve_velocity, sleeve_force (the whole
    sleeve's, N), alpha1, alpha2, alpha1_rate, alpha2_rate (per rib, rad, rad/s), tip (ribs,
    3: u, v, w of G in the leaf frame, m), kinetic_energy, strain_energy, work, friction_work
    (per rib), drive_work, damping_dissipation, lock_energy_loss (J), holding_torque, stuck
    (per rib), stop_reaction, stress_<component> (per rib, Pa) and stress_<component>_at
    (ribs, 2: body 0 leaf / 1 link, x along it), and with a moving base bus_q, bus_v (and
    the momenta of a free bus).
    """

    __slots__ = ('_values', '_held')

    def __init__(self, values: dict, held: 'RibPeaks | None' = None):
        object.__setattr__(self, '_values', values)
        #: the RibPeaks its stress figures are (with_peaks), else None: the rows' own
        object.__setattr__(self, '_held', held)

    def __getattr__(self, name: str):
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name, value):
        raise AttributeError(f'Sample3D is read-only (cannot set {name!r})')

    def __getitem__(self, name: str):
        """Return a figure by name, as a Record3D row holds it (energy_balance3d)."""
        return self._values[name]

    def fields(self) -> dict:
        """Return every figure by name (a copy of the mapping; the arrays are shared)."""
        return dict(self._values)

    @classmethod
    def of_row(cls, row: dict, i: int | None = None) -> 'Sample3D':
        """
        Return the sample of a Record3D row (its 'locked' flag as the stage).

        i: the row is the i-th of Record3D rows (steps first) instead.
        """
        values = dict(row) if i is None else {name: v[i] for name, v in row.items()}
        values['stage'] = Stage.LOCKED if values.pop('locked') else Stage.DEPLOYING
        return cls(values)

    def with_peaks(self, hold: 'RibPeaks') -> 'Sample3D':
        """Return this sample with each rib's stress figures the held ones (merge_peaks)."""
        values = dict(self._values)
        # (a component's values and places: the rows of the held arrays turned)
        for (name, name_at), value, at in zip(STRESS_ROWS, hold.value.T, hold.at.swapaxes(0, 1)):
            values[name], values[name_at] = value, at
        return Sample3D(values, hold)

    def stress_figures(self) -> tuple[np.ndarray, np.ndarray]:
        """
        Return each rib's stress figures as arrays: values (ribs, 5) and where (ribs, 5, 2).

        The components in STRESS_NAMES' order, stress_<component> and stress_<component>_at
        (the held RibPeaks' own arrays where with_peaks made the sample: not to be written).
        """
        if self._held is not None:
            return self._held.value, self._held.at
        v = self._values
        return (np.stack([v[name] for name, _ in STRESS_ROWS], -1),
                np.stack([v[name_at] for _, name_at in STRESS_ROWS], -2))


#: the stress components' columns, and von Mises's
COMPONENTS = np.arange(len(STRESS_NAMES))[None]
VON_MISES = STRESS_NAMES.index('von_mises')


class RibPeaks:
    """
    Each rib's largest |value| of every stress component, where and when (read-only).

    value (ribs, components), at (ribs, components, 2: body code and x, as Sample3D's),
    when (ribs, components) s; the components in STRESS_NAMES' order.
    """

    __slots__ = ('value', 'at', 'when')

    def __init__(self, value: np.ndarray, at: np.ndarray, when: np.ndarray):
        self.value, self.at, self.when = value, at, when

    @classmethod
    def of_rows(cls, rows: dict, i=None) -> 'RibPeaks':
        """
        Return the peaks of Record3D rows (steps first): the first step with the largest.

        i: the step of each rib and component to take instead ((ribs, components) indices;
        0 for a Sample3D's figures taken as one step's rows).
        """
        value = np.stack([rows[f'stress_{name}'] for name in STRESS_NAMES], -1)
        at = np.stack([rows[f'stress_{name}_at'] for name in STRESS_NAMES], -2)
        i = value.argmax(0) if i is None else np.broadcast_to(i, value.shape[1:])
        ribs, components = np.arange(value.shape[1])[:, None], COMPONENTS
        return cls(value[i, ribs, components], at[i, ribs, components],
                   np.asarray(rows['time'])[i])

    def __getitem__(self, name: str) -> tuple:
        """Return (value, at, when) of one component (STRESS_NAMES), rib by rib."""
        j = STRESS_NAMES.index(name)
        return self.value[:, j], self.at[:, j], self.when[:, j]

    def items(self):
        """Yield (component, (value, at, when)) in STRESS_NAMES' order."""
        return ((name, self[name]) for name in STRESS_NAMES)

    def merged(self, new: 'RibPeaks') -> 'RibPeaks':
        """Return, rib by rib and component by component, the larger (these held on a tie)."""
        better = new.value > self.value
        if not any_of(better, axis=None):
            return self
        return RibPeaks(np.where(better, new.value, self.value),
                        np.where(better[..., None], new.at, self.at),
                        np.where(better, new.when, self.when))

    def merged_all(self, news: list) -> 'RibPeaks':
        """
        Return these merged with each of news (RibPeaks) in turn, as ``merged`` one by one.

        Where none of news holds a larger value (their largest, a NaN never larger, is no
        larger anywhere: a run's peaks past their growth), these, at once.
        """
        if len(news) > 1 and not any_of(
                np.fmax.reduce(np.stack([new.value for new in news])) > self.value, axis=None):
            return self
        out = self
        for new in news:
            out = out.merged(new)
        return out


class StepBlock3D:
    """
    The steps of one ``advance_schedule``: Record3D's rows (steps first), as a StepBlock.

    ``last`` is the Sample3D of the final state, ``lock`` the LockEvent if the lock happened
    in these steps, ``error`` the fault that ended them early; ``states`` is None (the
    umbrella's state rows are not offered).  peaks: the rows' RibPeaks if known (Record3D's
    taken_peaks), else made from the rows when first asked.  physics_tips: None where the
    rows are the physics steps, else every physics step's time and each rib's tip v and w
    (Record3D's taken_tips: substeps3d.physics_tips3d), the planar StepBlock's.
    """

    states = None

    def __init__(self, rows: dict, last: Sample3D, lock: LockEvent | None = None,
                 error: str | None = None, peaks: 'RibPeaks | None' = None,
                 physics_tips: tuple | None = None):
        self.rows, self.lock, self.error = rows, lock, error
        self._last = last
        self._peaks = peaks
        self.physics_tips = physics_tips

    def __len__(self) -> int:
        return len(self.rows['time']) if self.rows else 0

    @property
    def time(self) -> np.ndarray:
        return self.rows['time'] if self.rows else np.zeros(0)

    @property
    def last(self) -> Sample3D:
        return self._last

    @property
    def peaks(self) -> RibPeaks | None:
        """Return each rib's largest stresses over the steps (RibPeaks; None: no steps)."""
        if self._peaks is None and len(self):
            self._peaks = RibPeaks.of_rows(self.rows)
        return self._peaks

    def merge_peaks(self, hold) -> RibPeaks:
        """Return the held peaks (RibPeaks, or {}: none yet) with this block's larger ones."""
        peaks = self.peaks
        if peaks is None:
            return hold
        return hold.merged(peaks) if hold else peaks
