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
What one publication carries, as the CDR bytes the node publishes and the recorders record.

The run driver (core/driver.py) says when a publication is due and gives its Sample (the
state, with the peak stresses held over the period); ``PublicationEncoder`` turns it into
the per-publication topics (messages.SampleEncoder: one ``struct`` call a topic on a
template's constant bytes) and, on every ``marker_every``-th publication (t = 0 included), the
markers (messages.MarkerEncoder).  The live node and the offline recorder share it, so that
both produce the same bytes at the same sim times.
"""
from __future__ import annotations

from . import messages
from .ribs_messages import RibsPublicationEncoder
from ..core.driver import RunDriver
from ..core.outputs import mechanical_energy, Sample
from ..core.params import UmbrellaParams
from ..core.registry import NODE_PARAMETERS
from ..core.umbrella3d.params3d import umbrella_model, UmbrellaRibsParams


class PublicationEncoder:
    """The messages of a run's publications, keyed as messages.TOPICS (CDR bytes)."""

    def __init__(self, driver: RunDriver,
                 marker_rate: float = NODE_PARAMETERS['marker_rate'].default):
        self.driver = driver
        self.initial_energy = mechanical_energy(driver.initial)
        self.marker_every = messages.marker_every(driver.publish_rate, marker_rate)
        self.count = 0                   # publications encoded so far
        self._encoders: dict[str, messages.SampleEncoder] = {}     # by frame_prefix
        self._marker_encoders: dict = {}            # by (marker namespace, frame_prefix)

    def messages(self, s: Sample, marker_ns: str, magnification: float,
                 frame_prefix: str = '') -> dict[str, bytes]:
        """Return what the publication of s (RunDriver.publication()) publishes."""
        encoder = self._encoders.get(frame_prefix)
        if encoder is None:
            encoder = self._encoders[frame_prefix] = messages.SampleEncoder(
                self.driver.initial, self.driver.params, self.initial_energy, frame_prefix)
        out: dict = encoder.encode(s)
        if self.count % self.marker_every == 0:
            positions = self.driver.sim.model.deformed_shape(s.q, magnification)
            markers = self._marker_encoders.get((marker_ns, frame_prefix))
            if markers is None:
                markers = self._marker_encoders[marker_ns, frame_prefix] = \
                    messages.MarkerEncoder(positions, marker_ns, frame_prefix)
            out['markers'] = markers.encode(s.time, s.sleeve_position, positions)
        self.count += 1
        return out


def run_driver(planar: UmbrellaParams, umbrella: dict, publish_rate: float | None,
               marker_rate: float = NODE_PARAMETERS['marker_rate'].default,
               force_profile=None):
    """
    Return the run driver of a node's parameters and the encoder of its publications.

    planar: the planar record; umbrella: the umbrella's values (params3d.umbrella_values):
    with ribs >= 2 the umbrella of N ribs, each rib taking planar unless it has its own value
    (ribs_messages.RibsPublicationEncoder), else the planar model.  ValueError if the model
    cannot be made; force_profile: RunDriver's.
    """
    driver = RunDriver(umbrella_model(planar, umbrella), publish_rate,
                       force_profile=force_profile)
    encoder = (RibsPublicationEncoder if isinstance(driver.params, UmbrellaRibsParams)
               else PublicationEncoder)
    return driver, encoder(driver, marker_rate)
