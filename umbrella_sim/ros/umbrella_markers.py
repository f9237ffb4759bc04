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
The whole umbrella's ``markers``: every rib's deformed leaf and link, the sleeve, the hub.

``UmbrellaShapes`` places the drawn points of every rib of a 3D state (the rib coordinates,
the simulator's ``state.qr``) in ``umbrella_base``: each body's points at abscissae x of its
floating frame, x + m S(x) e (S the 3D element's shape functions of the element holding x:
axial linear, both bendings cubic; e the body's elastic coordinates; m the magnification),
turned by the body's angle about the rib's tangential axis, the link's moved to its origin
R2, then set at the rib's azimuth on the hub radius.  The drawing rule is the planar
model's (UmbrellaModel.deformed_shape): each element in shape_pieces_per_element equal
pieces, only the elastic displacement in the body's own frame magnified.  Every matrix is
built once; a state costs a few einsums over all ribs at once.

``UmbrellaMarkers`` turns them and the sleeve's height (``state.qs[0]``) into the
MarkerArray (messages.markers_msg: rib k's leaf id 2k, link 2k + 1, then the sleeve and the
hub) or straight into its CDR bytes (messages.MarkerEncoder), which the node publishes.
With one rib the markers are the planar ones, unchanged: the frame from the hinge O (where
the planar model has it, the hub radius left out) and the sleeve a sphere, no hub.

``umbrella_base`` is the hub (the 3D model's bus frame): with a moving base the markers
move with the bus, whose motion is reported apart.
"""
from __future__ import annotations

import numpy as np

from .messages import MarkerEncoder, markers_msg, SleeveAt
from ..core.beam import shape_abscissae, shape_pieces_per_element
from ..core.umbrella3d.beam3d import shape_functions_3d


def shape_matrix_3d(body, x) -> np.ndarray:
    """
    Return S (len(x), 3, n_elastic): (u, v, w) at body abscissae x are S e.

    Each x in the element that holds it (the last one for the body's end), by the 3D
    element's shape functions and the body's element maps.
    """
    x = np.asarray(x, dtype=float)
    element = np.clip(np.searchsorted(body.node_x, x, side='right') - 1, 0,
                      len(body.element_length) - 1)
    out = np.zeros((len(x), 3, body.n_elastic))
    for j in np.unique(element):
        at = element == j
        le = body.element_length[j]
        n = shape_functions_3d((x[at] - body.node_x[j]) / le, le)[0]
        out[at] = n @ body.element_maps[j]
    return out


class UmbrellaShapes:
    """
    The drawn points of every rib of a 3D model's state, in umbrella_base (m).

    abscissae: per body (leaf, link), the points' abscissae of each rib, (R, P) arrays;
    default each element in per_element pieces (default shape_pieces_per_element).
    """

    def __init__(self, model, per_element: int | None = None, abscissae=None):
        self.model = m = model
        if abscissae is None:
            abscissae = []
            for bodies in (m.leaf_bodies, m.link_bodies):
                k = per_element or shape_pieces_per_element(len(bodies[0].element_length))
                abscissae.append(np.array([shape_abscissae(b.node_x, k) for b in bodies]))
        self.abscissae = [np.asarray(x, dtype=float) for x in abscissae]
        self._rest, self._shape = [], []
        for bodies, x in zip((m.leaf_bodies, m.link_bodies), self.abscissae):
            rest = np.zeros(x.shape + (3,))
            rest[..., 0] = x
            self._rest.append(rest)
            self._shape.append(np.array([shape_matrix_3d(b, xk) for b, xk in zip(bodies, x)]))
        self._elastic = (m.s_leaf_e, m.s_link_e)
        self._angle = (m.i_a1, m.i_a2)
        self._origin = [m.i_rx, m.i_ry, m.i_rz]
        # rib frame -> umbrella_base: columns e_r, e_Y, e_t of each rib; one rib: its own
        self.planar = m.n_ribs == 1
        self._frames = np.eye(3)[None] if self.planar else m.psi
        self._hub = np.array([0.0 if self.planar else m.hub_radius, 0.0, 0.0])

    def positions(self, qr, magnification: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Return (leaf, link) points of every rib, (R, P, 3) each, at rib coordinates qr."""
        qr = np.asarray(qr)
        out = []
        for i, (rest, shape, elastic, angle) in enumerate(
                zip(self._rest, self._shape, self._elastic, self._angle)):
            y = rest + magnification * np.einsum('rpie,re->rpi', shape, qr[:, elastic])
            c, s = np.cos(qr[:, angle])[:, None], np.sin(qr[:, angle])[:, None]
            rho = np.stack([c * y[..., 0] - s * y[..., 1], s * y[..., 0] + c * y[..., 1],
                            y[..., 2]], -1)
            if i == 1:
                rho = rho + qr[:, None, self._origin]
            out.append(np.einsum('rij,rpj->rpi', self._frames, rho + self._hub))
        return out[0], out[1]

    def bodies(self, qr, magnification: float = 1.0) -> list[np.ndarray]:
        """Return the points body by body, rib by rib: [leaf 0, link 0, leaf 1, ...]."""
        leaf, link = self.positions(qr, magnification)
        return [body for k in range(len(leaf)) for body in (leaf[k], link[k])]


class UmbrellaMarkers:
    """
    The ``markers`` topic of a 3D model's states: the MarkerArray, or its CDR bytes.

    ns: the marker namespace (the node's namespace, or 'umbrella'); frame_prefix as the
    node's other messages.
    """

    def __init__(self, model, ns: str, frame_prefix: str = '',
                 per_element: int | None = None):
        self.shapes = UmbrellaShapes(model, per_element)
        self.ns, self.frame_prefix = ns, frame_prefix
        self.hub_radius = None if self.shapes.planar else model.hub_radius
        self._encoder: MarkerEncoder | None = None

    def message(self, time: float, qr, qs, magnification: float = 1.0):
        """Return the visualization_msgs/MarkerArray of the state (qr, qs) at sim time."""
        bodies = self.shapes.bodies(qr, magnification)
        return markers_msg(SleeveAt(time, float(qs[0])), bodies, self.ns, self.frame_prefix,
                           self.hub_radius)

    def encode(self, time: float, qr, qs, magnification: float = 1.0) -> bytes:
        """Return the CDR bytes of message(time, qr, qs, magnification) (what is published)."""
        leaf, link = self.shapes.positions(qr, magnification)
        if self._encoder is None:
            self._encoder = MarkerEncoder(self.shapes.bodies(qr), self.ns,
                                          self.frame_prefix, self.hub_radius)
        # rib by rib, leaf then link: the bodies' order, as one array
        return self._encoder.encode_points(time, float(qs[0]),
                                           np.concatenate([leaf, link], axis=1))
