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
Stuck hinges against the mechanism's statics, and where their torque acts.

Every rib stuck at the folded angle, the sleeve pushed with F a rib and the vibration damped
out: each link is a two-force member, the sleeve's N F shared among the ribs by their links'
axial stiffness E A (leaf and link in series, both of the rib's section), and the holding
torque is the moment about O of the link's force at O'', l1 C (cos a d_y - sin a d_x)
(C = share l3 / (y_H - y_O''), d the unit vector H -> O'').  The hold acts on the leaf's
chord angle alpha1 (msg_docs/umbrella3d_parameters.md says so): the leaf's root is not bent
by it, and the reported bending stays far below the M c / I a clamped root would carry.
"""
import math
import pathlib

import numpy as np
import pytest

from umbrella_sim.core import UmbrellaRibsParams, UmbrellaSimulator3D

FORCE = 100.0


@pytest.fixture(scope='module')
def stuck():
    params = UmbrellaRibsParams.from_mapping({
        'ribs': 3, 'v0': 0.0, 'sleeve_force': FORCE, 'rib.stick_until': [1e6] * 3,
        'rib1.section_height': 0.012, 'damping_ratio': 0.3})
    sim = UmbrellaSimulator3D(params)
    return params, sim.run(0.3)


def _hand_holding_torques(params):
    p = params.planar
    a, l1, l3 = p.alpha0, p.l1, p.l3
    y_h = p.sleeve_start_height
    joint = np.array([l1 * math.cos(a), l1 * math.sin(a)])
    d = (joint - np.array([0.0, y_h])) / l3
    stiffness = np.array([r.planar.youngs_modulus * r.planar.cross_section_area
                          for r in params.ribs_list()])
    share = params.ribs * FORCE * stiffness / stiffness.sum()
    compression = share * l3 / (y_h - joint[1])
    return np.abs(l1 * compression * (math.cos(a) * d[1] - math.sin(a) * d[0]))


def test_the_holding_torques_are_the_statics_of_the_shared_sleeve_force(stuck):
    params, record = stuck
    held = np.abs(record.arrays()['holding_torque'][-1])
    np.testing.assert_allclose(held, _hand_holding_torques(params), rtol=2e-3)


def test_the_hold_does_not_bend_the_root_as_the_docs_say(stuck):
    params, record = stuck
    bending = record.arrays()['stress_bending_in_plane']          # (step, rib)
    moments = _hand_holding_torques(params)
    clamped = [m * r.planar.fibre_distance / r.planar.cross_section_inertia
               for m, r in zip(moments, params.ribs_list())]
    assert min(clamped) > 1e7                     # > 10 MPa at a clamped root
    assert bending.max() < 1e-3 * min(clamped)
    doc = (pathlib.Path(__file__).parents[1] / 'msg_docs'
           / 'umbrella3d_parameters.md').read_text()
    assert "not on the slope of the leaf's root" in ' '.join(doc.split())
