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
What makes a recording reproducible from the file alone: parameters, build, mesh, events.

The metadata records of a run (bag/format.py names them): every parameter and the physics
step used, the build (version, git revision, kernel, floating-point environment), the mesh,
and at close the exact lock instant, the fault and the summary figures.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

from .format import BUILD_RECORD, EVENTS_RECORD, MESH_RECORD, PARAMETERS_RECORD, SUMMARY_RECORD
from .. import __version__
from ..core.integrators import INTEGRATOR_REVISION


# ------------------------------------------------------------------- provenance
def git_revision() -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        out = subprocess.run(['git', '-C', here, 'rev-parse', 'HEAD'], capture_output=True,
                             text=True, timeout=5)
        if out.returncode == 0:
            dirty = subprocess.run(['git', '-C', here, 'status', '--porcelain', '--', '.'],
                                   capture_output=True, text=True, timeout=5).stdout.strip()
            return out.stdout.strip() + ('+dirty' if dirty else '')
    except (OSError, subprocess.SubprocessError):
        pass
    return 'unknown'


def build_environment() -> dict[str, str]:
    """
    Return what sets a run's floating-point round-off besides the code.

    numpy, its BLAS kernel (OpenBLAS picks one per CPU unless OPENBLAS_CORETYPE names it)
    and the CPU.  The model's matrices go through BLAS; another kernel rounds them
    differently in the last bit, so a re-simulation elsewhere agrees to round-off, not bit
    for bit.
    """
    import platform

    import numpy

    cpu = platform.machine()
    try:
        with open('/proc/cpuinfo', encoding='utf-8', errors='replace') as fh:
            cpu = next((line.split(':', 1)[1].strip() for line in fh
                        if line.startswith('model name')), cpu)
    except OSError:
        pass
    return {'numpy': numpy.__version__,
            'openblas_coretype': os.environ.get('OPENBLAS_CORETYPE', 'auto'), 'cpu': cpu}


def run_metadata(params, node_cfg: dict, physics_step: float, model, backend: str,
                 source: str) -> dict[str, dict[str, str]]:
    """Metadata records that make a log reproducible from the file alone."""
    all_params = dict(params.as_dict())
    all_params.update(node_cfg)
    all_params['physics_step'] = physics_step
    return {
        PARAMETERS_RECORD: {k: json.dumps(v) for k, v in all_params.items()},
        BUILD_RECORD: {'package_version': __version__, 'git_revision': git_revision(),
                       'kernel': backend, 'integrator': INTEGRATOR_REVISION, 'source': source,
                       'python': sys.version.split()[0], **build_environment()},
        MESH_RECORD: mesh_record(params, model),
    }


def mesh_record(params, model) -> dict[str, str]:
    """
    Return the mesh record: the model, its lock, its mesh and its coordinates.

    The umbrella of N ribs (a model without coordinate_labels) gives its number of ribs.
    """
    out = {'model': params.model, 'lock': params.lock,
           'elements_per_segment': str(params.elements_per_segment)}
    if not hasattr(model, 'coordinate_labels'):
        return {**out, 'ribs': str(model.n_ribs)}
    return {**out, 'coordinates': json.dumps(model.coordinate_labels()),
            'leaf_node_x': json.dumps(list(model.leaf.node_x)),
            'link_node_x': json.dumps(list(model.link.node_x))}


def events_metadata(sim, fault: str | None = None) -> dict[str, dict[str, str]]:
    """
    Return the events record: the exact lock instant and the fault, if any.

    The exact lock instant (the phase message comes at the next publication) and the
    solver fault that ended the run, if any (at the last good state's time).
    """
    ev = sim.lock_event
    out = {'locked': 'false'} if ev is None else {
        'locked': 'true', 'lock_time': repr(ev.time), 'lock_kind': ev.kind,
        'energy_before': repr(ev.energy_before), 'energy_after': repr(ev.energy_after)}
    if fault is not None:
        out.update(fault=fault, fault_time=repr(sim.time))
    return {EVENTS_RECORD: out}


def summary_metadata(figures: dict) -> dict[str, dict[str, str]]:
    """
    Return the summary metadata record: figures of every physics step and the warnings.

    From outputs.SummaryAccumulator.figures(), so that umbrella_compare reports the
    physics, not the recorded samples.
    """
    return {SUMMARY_RECORD: {
        'figures': json.dumps({k: v for k, v in figures.items() if k != 'warnings'}),
        'warnings': json.dumps(figures.get('warnings', [])),
        'source': 'every physics step'}}


def summary_of(record: dict[str, str]) -> tuple[dict, list] | None:
    """
    Return what a summary record (summary_metadata's) holds: (figures, warnings).

    None for a record without figures; ValueError if they are not JSON.
    """
    if 'figures' not in record:
        return None
    return json.loads(record['figures']), json.loads(record.get('warnings', '[]'))


def run_records(sim, figures: dict, fault: str | None = None) -> dict[str, dict[str, str]]:
    """
    Return the records of a run that ended: its events and its summary.

    Of the last segment at close, and of a segment a ~/reset ended (BagRecorder.start_segment
    names them for it): the same records either way.
    """
    return {**events_metadata(sim, fault), **summary_metadata(figures)}
