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
``umbrella_sim simulate --csv``: the time series of every grid step, streamed to a file.

Rows: the state at t = 0, the end of every grid step, and the instant of the lock (the state
right after it, at the exact lock time between two steps).  Where stage 2 takes k physics
steps a grid step (its substeps: solver.UmbrellaSimulator.stage2_substeps) a row is its grid
step's last physics step's state with the peaks the largest of its physics steps' (the
compiled advance's fold, outputs.fold_substeps' rule); elsewhere a grid step is one physics
step.  The header names each
column with its SI unit: ``time (s)``, ``alpha1 (rad)``, ``q[leaf.u2] (m)``, ``stage``.
The rows come from the run driver's chunks (the compiled loop's per-step rows, and with
``--csv-state`` its per-step state rows), written as each chunk ends: memory does not grow
with the run, and nothing a Python call per step.  The numbers are written by pyarrow's CSV
writer (C++, the shortest text that reads back as the same double), ~3 us a row against
~12 us for Python's formatting.

The umbrella of N ribs (``ribs`` >= 2) has its own columns (``UmbrellaStepCsv``): the
sleeve's and the energy's figures, then each rib's named by the rib (``rib0_alpha1 (rad)``,
``rib0_tip_w (m)``, ``rib0_stress_von_mises (Pa)``), then with a moving base the bus's, all
Sample3D figures (``UMBRELLA_FIGURES`` names them once).
"""
from __future__ import annotations

import numpy as np

from ..core.model import Stage
from ..core.outputs import Sample, state_row, STEP_FIELDS, step_row, StepBlock
from ..core.umbrella3d.outputs3d import energy_balance3d, STRESS_NAMES

#: the CSV's columns: every field of a step's row, stage as text first after time
CSV_COLUMNS = ['time', 'stage', 'alpha1', 'alpha2', 'alpha1_rate', 'alpha2_rate', 'alpha1_accel',
               'sleeve_position', 'sleeve_velocity', 'sleeve_force', 'tip_axial',
               'tip_transverse', 'peak_stress_leaf', 'peak_stress_leaf_x', 'peak_stress_link',
               'peak_stress_link_x', 'stress_leaf_joint', 'stress_link_mid',
               'sleeve_reaction_x', 'sleeve_reaction_y',
               'kinetic_energy', 'strain_energy', 'work', 'lock_energy_loss',
               'constraint_residual', 'damping_dissipation', 'axial_stress']
#: each column's unit, written in the header as 'name (unit)' (constraint_residual:
#: max(|Phi|, |J q'|), a position's and a velocity's constraints)
CSV_UNITS = {'time': 's', 'stage': '', 'alpha1': 'rad', 'alpha2': 'rad', 'alpha1_rate': 'rad/s',
             'alpha2_rate': 'rad/s', 'alpha1_accel': 'rad/s^2', 'sleeve_position': 'm',
             'sleeve_velocity': 'm/s', 'sleeve_force': 'N', 'tip_axial': 'm',
             'tip_transverse': 'm', 'peak_stress_leaf': 'Pa', 'peak_stress_leaf_x': 'm',
             'peak_stress_link': 'Pa', 'peak_stress_link_x': 'm', 'stress_leaf_joint': 'Pa',
             'stress_link_mid': 'Pa', 'sleeve_reaction_x': 'N', 'sleeve_reaction_y': 'N',
             'kinetic_energy': 'J', 'strain_energy': 'J', 'work': 'J', 'lock_energy_loss': 'J',
             'constraint_residual': 'm or m/s', 'damping_dissipation': 'J',
             'axial_stress': 'Pa'}
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

    'sigma_top[leaf@0]' = top-fibre stress at O, 0 m from it (Pa); at a node between two
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
    """A CSV file of every grid step; ``write`` each chunk's block as it comes."""

    def __init__(self, path: str, model=None):
        """Create the file (path checked by the caller) and write the header; model: states."""
        self.with_states = model is not None
        self.columns = CSV_COLUMNS + (state_columns(model) if model is not None else [])
        self._open(path, header_names(self.columns))

    def _open(self, path: str, header: list[str]) -> None:
        """Create the file and write its header (one name a column, with its unit)."""
        import pyarrow.csv      # (here: pyarrow's import costs a tenth of a second)

        self._csv = pyarrow.csv
        self.path = path
        self._names = [f'c{i}' for i in range(len(header))]
        self._options = pyarrow.csv.WriteOptions(include_header=False, quoting_style='none')
        self.rows = 0
        self._fh = open(path, 'wb')
        self._fh.write((','.join(header) + '\n').encode('utf-8'))

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
        columns = [rows[0], rows[_STAGE_ROW]] + [rows[i] for i in _ROWS[1:]]
        self._write_columns(columns + (list(states) if self.with_states else []))

    def _write_columns(self, columns: list) -> None:
        """Append rows: one array a column, in the header's order (stage: its codes)."""
        import pyarrow as pa

        stage = pa.DictionaryArray.from_arrays(
            pa.array(np.asarray(columns[1]).astype(np.int8)), pa.array(_STAGES))
        arrays = [pa.array(columns[0]), stage] + [pa.array(c) for c in columns[2:]]
        self._csv.write_csv(pa.Table.from_arrays(arrays, names=self._names), self._fh,
                            write_options=self._options)
        self.rows += len(columns[0])

    def close(self) -> None:
        self._fh.close()


# ------------------------------------------------------------ the umbrella of N ribs
#: the umbrella's CSV, in its columns' order: (Sample3D figure, unit, its components' names)
#: of the sleeve and the energies, of each rib, of a moving base.  A figure of several
#: components writes one column each, its name with the component's ('bus_x'); each rib's
#: a column a rib, 'rib<k>_' before the name ('rib0_tip_u').  The tip is G in the rib's leaf
#: frame (axial u, in-plane v, out-of-plane w); a stress component the rib's largest |value|
#: over its stress points and over the step (each physics step's Hermite crest, Record3D's
#: rule), and von Mises's place its body (0 leaf, 1 link)
#: and x along it; stuck is 1 while the rib's hinge is held, holding_torque the multiplier
#: of that hold (N m), stop_reaction the multiplier of the stop's constraint y_H = y_stop
#: (N).  A moving base adds the bus (X, Y, Z, psi, beta, gamma and their rates), a free one
#: its linear and angular momentum.
SLEEVE_FIGURES = (
    ('sleeve_position', 'm', None), ('sleeve_velocity', 'm/s', None),
    ('sleeve_force', 'N', None), ('stop_reaction', 'N', None),
    ('kinetic_energy', 'J', None), ('strain_energy', 'J', None), ('work', 'J', None),
    ('drive_work', 'J', None), ('damping_dissipation', 'J', None),
    ('lock_energy_loss', 'J', None))
RIB_FIGURES = (
    ('alpha1', 'rad', None), ('alpha2', 'rad', None), ('alpha1_rate', 'rad/s', None),
    ('alpha2_rate', 'rad/s', None), ('tip', 'm', ('u', 'v', 'w')),
    *((f'stress_{name}', 'Pa', None) for name in STRESS_NAMES),
    ('stress_von_mises_at', ('', 'm'), ('body', 'x')),
    ('friction_work', 'J', None), ('holding_torque', 'N m', None), ('stuck', '', None))
BUS_FIGURES = (
    ('bus_q', ('m', 'm', 'm', 'rad', 'rad', 'rad'), ('x', 'y', 'z', 'psi', 'beta', 'gamma')),
    ('bus_v', ('m/s', 'm/s', 'm/s', 'rad/s', 'rad/s', 'rad/s'),
     ('x_rate', 'y_rate', 'z_rate', 'psi_rate', 'beta_rate', 'gamma_rate')),
    ('linear_momentum', 'kg m/s', ('x', 'y', 'z')),
    ('angular_momentum', 'kg m^2/s', ('x', 'y', 'z')))
#: the energy balance (outputs3d.energy_balance3d), after the energy terms
ENERGY_BALANCE = 'energy_balance'


def _figure_columns(figure: str, unit, components, rib: int | None) -> list[tuple]:
    units = unit if isinstance(unit, tuple) else (unit,) * len(components or '_')
    name = figure[:-len('_at')] if figure.endswith('_at') else figure
    name = 'bus' if figure in ('bus_q', 'bus_v') else name
    prefix, at = ('', ()) if rib is None else (f'rib{rib}_', (rib,))
    if components is None:
        return [(prefix + name, units[0], figure, at)]
    return [(f'{prefix}{name}_{c}', u, figure, at + (i,))
            for i, (c, u) in enumerate(zip(components, units))]


def umbrella_columns(sample) -> list[tuple[str, str, str, tuple]]:
    """
    Return the umbrella's CSV columns for the figures of a Sample3D: (name, unit, figure, at).

    at: the index of the column's value in a row of the figure (rib, component).  Time and
    stage, the sleeve's and the energies' figures with the energy balance, every figure of
    rib 0, of rib 1 ..., then the bus's if the sample has them (a fixed hub has none).
    """
    fields = sample.fields()
    out = [('time', 's', 'time', ()), ('stage', '', 'stage', ())]
    for figure in SLEEVE_FIGURES:
        out += _figure_columns(*figure, None)
    out.append((ENERGY_BALANCE, 'J', ENERGY_BALANCE, ()))
    for k in range(len(sample.alpha1)):
        for figure in RIB_FIGURES:
            out += _figure_columns(*figure, k)
    for figure in BUS_FIGURES:
        if figure[0] in fields:
            out += _figure_columns(*figure, None)
    return out


class UmbrellaStepCsv(StepCsv):
    """The CSV of every grid step of the umbrella of N ribs (StepBlock3D, Sample3D)."""

    def __init__(self, path: str, initial):
        """Create the file (path checked by the caller) and write the header; initial: t = 0."""
        self.with_states = False
        self._columns = umbrella_columns(initial)
        self.columns = [c[0] for c in self._columns]
        self.initial_energy = float(initial.kinetic_energy + initial.strain_energy)
        self._open(path, [f'{n} ({u})' if u else n for n, u, _, _ in self._columns])

    def write_sample(self, s) -> None:
        """Append one state's row (t = 0, the instant of the lock): a Sample3D."""
        rows = {name: np.asarray(value)[None] for name, value in s.fields().items()
                if name != 'stage'}
        rows['locked'] = np.array([s.stage == Stage.LOCKED])
        self._write_rows(rows)

    def _write_steps(self, block, which) -> None:
        if len(block):
            self._write_rows({name: values[which] for name, values in block.rows.items()})

    def _write_rows(self, rows: dict) -> None:
        if not len(rows['time']):
            return
        columns = []
        for _, _, figure, at in self._columns:
            if figure == 'stage':
                values = np.where(rows['locked'], Stage.LOCKED.code, Stage.DEPLOYING.code)
            elif figure == ENERGY_BALANCE:
                values = energy_balance3d(rows, self.initial_energy)
            else:
                values = rows[figure][(slice(None), *at)]
            columns.append(np.asarray(values, dtype=np.int8 if figure == 'stage' else float))
        self._write_columns(columns)
