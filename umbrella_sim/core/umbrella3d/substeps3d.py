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
The umbrella's stage-2 step: the planar rule (step_rule.py) judged on its ribs at the lock.

At the lock every rib's in-plane state is a planar model's state (the rib's own planar
record, ``RibProperties.planar``: its mesh, section and lengths): ``stage2_resolution``
judges each rib with step_rule.stage2_resolution (its locked modes' amplitudes, the stage-2
tip crest they can add up to, the stress shares the step leaves unresolved, the step
needed past the modes' coupling) and returns the worst rib's: the smallest step needed
(None, no step the rule allows, the worst).  N identical ribs started alike are each the
planar model, so the umbrella's stage 2 takes the planar model's substeps (``substeps``,
step_rule.substeps_for) where the step is chosen for the run (step_rule.follows_lock of
the planar record).  The rule reads the in-plane modes: a rib's out-of-plane and torsion
modes (the in-plane rule's 'coarse step' does not see them) are resolved by the mode fit
at the step the in-plane ones need (their frequencies: docs/umbrella3d.md).

A stage-2 grid step taken in substeps keeps one row (``fold_substeps3d``: Record3D's, and the
compiled advance's fold) and, apart, every substep's tip deflections (``physics_tips3d``),
from which the summary's stage-2 figures come (summary.Stage2Series).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .model3d import UmbrellaModel3D
from ..model import UmbrellaModel
from ..outputs import first_largest_of_substeps, substep_ends
from ..params import UmbrellaParams
from ..step_rule import stage2_resolution as planar_resolution

_PLANAR_DOFS = ('u', 'v', 'theta')


def in_plane_coordinates(model: UmbrellaModel3D, planar: UmbrellaModel) -> np.ndarray:
    """
    Return, for each coordinate of the planar model, its index among a rib's 3D ones.

    The planar q = [alpha1, leaf (u, v, theta a node), R2x, R2y, alpha2, link]; the rib's
    [alpha1, leaf (u, v, theta, w, slope, twist a node), R2 x, y, z, alpha2, link], the same
    nodes and hinge conditions in the rib plane.
    """
    index = np.full(planar.n, -1)
    index[0], index[planar.i_r2x], index[planar.i_r2y] = 0, model.i_rx, model.i_ry
    index[planar.i_alpha2] = model.i_a2
    for body2, body3, s2, s3 in ((planar.leaf, model.leaf_bodies[0], planar.s_leaf,
                                  model.s_leaf_e),
                                 (planar.link, model.link_bodies[0], planar.s_link,
                                  model.s_link_e)):
        for node in range(len(body3.node_x)):
            for dof in _PLANAR_DOFS:
                try:
                    j = body2.elastic_index(node, dof)
                except KeyError:
                    continue
                index[s2.start + j] = s3.start + body3.index(node, dof)
    if np.any(index < 0):
        raise ValueError('a planar coordinate without its 3D one (the meshes differ)')
    return index


@lru_cache(maxsize=16)
def _planar_model(items: tuple) -> UmbrellaModel:
    return UmbrellaModel(UmbrellaParams.from_mapping(dict(items)))


def planar_model(params: UmbrellaParams) -> UmbrellaModel:
    """Return the planar model of a rib's planar record (one a record, kept)."""
    return _planar_model(tuple(sorted(params.as_dict().items())))


def stage2_resolution(model: UmbrellaModel3D, qr: np.ndarray, vr: np.ndarray,
                      h: float) -> dict:
    """
    Return the worst rib's step_rule.stage2_resolution of the post-lock state (qr, vr), at h.

    Each rib's in-plane coordinates are its planar model's (in_plane_coordinates); the worst
    rib needs the smallest step (None before any: the rule allows none), of those the one
    deflected most.  The dict is the planar one with "rib": which rib it is.
    """
    worst, key = None, None
    for k, rib in enumerate(model.ribs):
        planar = planar_model(rib.planar)
        index = in_plane_coordinates(model, planar)
        out = planar_resolution(planar, qr[k, index], vr[k, index], h)
        needed = out['needed_step']
        rank = (0, 0.0, -out['deflection']) if needed is None else (1, needed,
                                                                    -out['deflection'])
        if key is None or rank < key:
            worst, key = dict(out, rib=k), rank
    return worst


#: the rows of a run of steps that add up over a grid step's physics steps (the rest: its last)
_SUMMED_ROWS = ('work_force', 'work_friction', 'work_drive', 'work_damping', 'iterations',
                'factorisations')


def fold_substeps3d(rows: dict, m: int) -> dict:
    """
    Return the grid steps' rows of physics steps taken m to a grid step (kernel3d.row_layout).

    rows: consecutive physics steps, steps first, the first starting a grid step; each group
    of m ends a grid step (a last, shorter group: the steps a fault left).  A grid step's
    row is its last physics step's, with the works and counts summed over its steps and each
    stress channel's largest over them, with where (stress_top, stress_at: the first of the
    largest; outputs.fold_substeps' rule for the planar model).
    """
    steps = len(rows['t'])
    ends = substep_ends(steps, m)
    starts = np.arange(0, steps, m)
    out = {}
    for name, values in rows.items():
        if name in _SUMMED_ROWS:
            out[name] = np.add.reduceat(np.asarray(values), starts, axis=0)
        elif name not in ('stress_top', 'stress_at'):
            out[name] = np.array(values[ends])
    top = np.asarray(rows['stress_top'])                    # (step, rib, 5)
    pick = first_largest_of_substeps(np.where(np.isnan(top), np.inf, top), m)   # (NaN: largest)
    ribs, comps = np.indices(top.shape[1:])
    out['stress_top'] = top[pick, ribs[None], comps[None]]
    out['stress_at'] = np.asarray(rows['stress_at'])[pick, ribs[None], comps[None]]
    return out


def physics_tips3d(blocks: list[dict], tips: list) -> tuple | None:
    """
    Return the physics steps' tips of Record3D's blocks (StepBlock3D.physics_tips).

    tips: each block's, None where its rows are its physics steps, else (t, tips): the time
    and each rib's in-plane v and out-of-plane w of the leaf tip ((steps,), (steps, ribs,
    2)) at the end of every physics step its rows fold.  None if no block folds substeps;
    else (t, tips) of every block's physics steps, in order.
    """
    if len(tips) == 1:      # (one block, the usual take: its own, which nothing else holds)
        return tips[0]
    if all(t is None for t in tips):
        return None
    parts = [(b['time'], b['tip'][:, :, 1:]) if t is None else t for b, t in zip(blocks, tips)]
    return (np.concatenate([t for t, _ in parts]), np.concatenate([v for _, v in parts]))
