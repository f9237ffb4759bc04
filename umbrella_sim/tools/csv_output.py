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
``umbrella_sim simulate --csv``: the time series of every physics step, streamed to a file.

Rows: the state at t = 0, the end of every physics step, and the instant of the lock (the
state right after it, at the exact lock time between two steps).  The header names each
column with its SI unit: ``time (s)``, ``alpha1 (rad)``, ``q[leaf.u2] (m)``, ``stage``.
The rows come from the run driver's chunks (the compiled loop's per-step rows, and with
``--csv-state`` its per-step state rows), written as each chunk ends: memory does not grow
with the run, and nothing a Python call per step.  The numbers are written by pyarrow's CSV
writer (C++, the shortest text that reads back as the same double), ~3 us a row against
~12 us for Python's formatting.
"""
from __future__ import annotations

import numpy as np

from ..core.model import Stage
from ..core.outputs import Sample, state_row, STEP_FIELDS, step_row, StepBlock

#: the CSV's columns: every field of a step's row, stage as text first after time
CSV_COLUMNS = ['time', 'stage', 'alpha1', 'alpha2', 'alpha1_rate', 'alpha2_rate', 'alpha1_accel',
               'sleeve_position', 'sleeve_velocity', 'sleeve_force', 'tip_axial',
               'tip_transverse', 'peak_stress_leaf', 'peak_stress_leaf_x', 'peak_stress_link',
               'peak_stress_link_x', 'stress_leaf_joint', 'stress_link_mid',
               'sleeve_reaction_x', 'sleeve_reaction_y',
               'kinetic_energy', 'strain_energy', 'work', 'lock_energy_loss',
               'constraint_residual', 'damping_dissipation']
#: each column's unit, written in the header as 'name (unit)' (constraint_residual:
#: max(|Phi|, |J q'|), a position's and a velocity's constraints)
CSV_UNITS = {'time': 's', 'stage': '', 'alpha1': 'rad', 'alpha2': 'rad', 'alpha1_rate': 'rad/s',
             'alpha2_rate': 'rad/s', 'alpha1_accel': 'rad/s^2', 'sleeve_position': 'm',
             'sleeve_velocity': 'm/s', 'sleeve_force': 'N', 'tip_axial': 'm',
             'tip_transverse': 'm', 'peak_stress_leaf': 'Pa', 'peak_stress_leaf_x': 'm',
             'peak_stress_link': 'Pa', 'peak_stress_link_x': 'm', 'stress_leaf_joint': 'Pa',
             'stress_link_mid': 'Pa', 'sleeve_reaction_x': 'N', 'sleeve_reaction_y': 'N',
             'kinetic_energy': 'J', 'strain_energy': 'J', 'work': 'J', 'lock_energy_loss': 'J',
             'constraint_residual': 'm or m/s', 'damping_dissipation': 'J'}
_ROWS = [STEP_FIELDS.index(c) for c in CSV_COLUMNS if c != 'stage']
_STAGE_ROW = STEP_FIELDS.index('stage')
_STAGES = [str(s) for s in sorted(Stage, key=lambda s: s.code)]


def stress_point_labels(xs) -> list[str]:
    """
    Name stress points by position (m, 6 digits); a node two elements share gets - and +.

    Stresses are recovered at both ends of every element, so an inner node has two: the
    element ending there (x-) and the one starting there (x+).
    """
    texts = [f'{x:.6g}' for x in xs]
    out = list(texts)
    for i in range(len(texts) - 1):
        if texts[i] == texts[i + 1]:
            out[i], out[i + 1] = texts[i] + '-', texts[i + 1] + '+'
    return out


def state_columns(model) -> list[str]:
    """
    Return the --csv-state columns: q, q' by coordinate, then the fibre stresses.

    'sigma_top[leaf@0.25]' = top-fibre stress at 0.25 m from O (Pa); at a node between two
    elements, each element's own ('leaf@0.5-', 'leaf@0.5+'); top of every point, then bottom,
    as StepBlock.states holds them.  Names without units (header_names adds them).
    """
    labels = model.coordinate_labels()
    cols = [f'q[{lab}]' for lab in labels] + [f'qd[{lab}]' for lab in labels]
    for fibre in ('top', 'bottom'):
        for body, xs in (('leaf', model.leaf.stress_x), ('link', model.link.stress_x)):
            cols += [f'sigma_{fibre}[{body}@{x}]' for x in stress_point_labels(xs)]
    return cols


def column_unit(name: str) -> str:
    """Return the unit of a column of the CSV ('' for stage)."""
    if name in CSV_UNITS:
        return CSV_UNITS[name]
    if name.startswith('sigma_'):
        return 'Pa'
    kind, coordinate = name[:-1].split('[', 1)          # q[leaf.u2], qd[alpha1], ...
    angle = coordinate.startswith('alpha') or '.theta' in coordinate
    return ('rad' if angle else 'm') + ('/s' if kind == 'qd' else '')


def header_names(columns) -> list[str]:
    """Return the header's names: 'name (unit)', the stage column as its name."""
    return [f'{c} ({column_unit(c)})' if column_unit(c) else c for c in columns]


class StepCsv:
    """A CSV file of every physics step; ``write`` each chunk's block as it comes."""

    def __init__(self, path: str, model=None):
        """Create the file (path checked by the caller) and write the header; model: states."""
        import pyarrow.csv      # (here: pyarrow's import costs a tenth of a second)

        self._csv = pyarrow.csv
        self.path = path
        self.with_states = model is not None
        self.columns = CSV_COLUMNS + (state_columns(model) if model is not None else [])
        self._names = [f'c{i}' for i in range(len(self.columns))]
        self._options = pyarrow.csv.WriteOptions(include_header=False, quoting_style='none')
        self.rows = 0
        self._fh = open(path, 'wb')
        self._fh.write((','.join(header_names(self.columns)) + '\n').encode('utf-8'))

    def write_sample(self, s: Sample) -> None:
        """Append one state's row (t = 0, the instant of the lock)."""
        self._write(np.array(step_row(s))[:, None],
                    state_row(s)[:, None] if self.with_states else None)

    def write(self, block: StepBlock, lock_sample: Sample | None = None) -> None:
        """
        Append a block's steps (with their state rows, if the file has those columns).

        lock_sample: the state right after a lock inside the block, written in time order
        between the steps before the lock instant and the rest.
        """
        if lock_sample is None:
            self._write_steps(block, slice(None))
            return
        before = block.time < lock_sample.time
        self._write_steps(block, before)
        self.write_sample(lock_sample)
        self._write_steps(block, ~before)

    def _write_steps(self, block: StepBlock, which) -> None:
        rows = block.rows[:, which]
        if rows.shape[1]:
            self._write(rows, None if block.states is None else block.states[:, which])

    def _write(self, rows: np.ndarray, states: np.ndarray | None) -> None:
        import pyarrow as pa

        stage = pa.DictionaryArray.from_arrays(
            pa.array(rows[_STAGE_ROW].astype(np.int8)), pa.array(_STAGES))
        columns = [pa.array(rows[0]), stage] + [pa.array(rows[i]) for i in _ROWS[1:]]
        if self.with_states:
            columns += [pa.array(r) for r in states]
        self._csv.write_csv(pa.Table.from_arrays(columns, names=self._names), self._fh,
                            write_options=self._options)
        self.rows += rows.shape[1]

    def close(self) -> None:
        self._fh.close()
