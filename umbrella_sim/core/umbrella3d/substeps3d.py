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
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .model3d import UmbrellaModel3D
from ..model import UmbrellaModel
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
