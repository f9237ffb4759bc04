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
Stuck hinges against the mechanism's statics: a stuck hinge clamps the leaf's root.

Every rib stuck at the folded angle, the sleeve pushed with F a rib and the vibration damped
out.  Each link is a two-force member along its chord d (H -> O''), so its compression C is
what its axial stress recovers (sigma A), the holding torque is the moment about O of that
force at O'', |r x d| C (r = O - O'', taken at the deformed chords: the folded leaf and link
are nearly aligned, so the lever follows the clamped leaf's bending), and the sleeve's N F
is the sum of the links' C |d_y|.  The hold clamps the root section (alpha1 + the root's
slope), so the leaf carries the hold at O as its bending moment: the in-plane bending stress
recovered there is M c / I.  (Held on the chord angle alpha1 alone, as before, the root
stayed a pin: < 0.001 MPa there where M c / I is 13-18 MPa.)
"""
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
    arrays = UmbrellaSimulator3D(params).run(1.5).arrays()
    return params, {k: v[-1] for k, v in arrays.items()}     # the settled state


def _link_forces(params, end):
    """Each link's compression from its axial stress, its chord d and the lever |r x d|."""
    area = np.array([r.planar.cross_section_area for r in params.ribs_list()])
    assert np.all(end['stress_axial_at'][:, 0] == 1)             # the link's: uniform
    a1, a2 = end['alpha1'], end['alpha2']
    r = params.planar.l1 * np.stack([np.cos(a1), np.sin(a1)], -1)
    d = np.stack([np.cos(a2), np.sin(a2)], -1)
    return end['stress_axial'] * area, d, np.abs(r[:, 0] * d[:, 1] - r[:, 1] * d[:, 0])


def test_the_holding_torques_are_the_statics_of_the_sleeve_force(stuck):
    params, end = stuck
    compression, d, lever = _link_forces(params, end)
    held = np.abs(end['holding_torque'])
    np.testing.assert_allclose(held, lever * compression, rtol=1e-3)
    assert float(np.sum(compression * np.abs(d[:, 1]))) == pytest.approx(
        params.ribs * FORCE, rel=1e-3)
    # the stiffer rib takes more of the sleeve: its clamped leaf bends less
    assert held[1] > 1.5 * held[0] and held[0] == pytest.approx(held[2], rel=1e-9)
    # the sign the docs give: the hinge holds the deploying push toward folding, positive
    doc = (pathlib.Path(__file__).parents[1] / 'msg_docs' / 'topic_ribs.md').read_text()
    assert 'positive turning it toward folding' in doc and np.all(end['holding_torque'] > 0.0)


def test_a_stuck_hinge_clamps_the_root_and_its_hold_is_the_roots_moment(stuck):
    params, end = stuck
    held = np.abs(end['holding_torque'])
    clamped = np.array([m * r.planar.fibre_distance / r.planar.cross_section_inertia
                        for m, r in zip(held, params.ribs_list())])
    assert clamped.min() > 1e7                                   # > 10 MPa at the root
    np.testing.assert_allclose(end['stress_bending_in_plane'], clamped, rtol=1e-3)
    assert np.all(end['stress_bending_in_plane_at'] == 0.0)      # the leaf (0) at O (x 0)
    doc = (pathlib.Path(__file__).parents[1] / 'msg_docs'
           / 'umbrella3d_parameters.md').read_text()
    assert "A stuck hinge clamps the leaf's root" in ' '.join(doc.split())
