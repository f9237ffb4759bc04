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

"""The umbrella's publication without DDS: the encoder's bytes are the builders' messages."""
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from umbrella_sim.bag.cdr import cdr_bytes
from umbrella_sim.core.driver import RunDriver
from umbrella_sim.core.umbrella3d.outputs3d import energy_balance3d, STRESS_NAMES
from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
from umbrella_sim.ros.ribs_messages import (rib_array_figures, rib_energy_figures,
                                            rib_joint_figures, rib_messages,
                                            RibsPublicationEncoder)

#: rib 1 stuck for 20 ms and rubbing in its hinge, rib 2 stiffer, from rest, pushed hard
STUCK = {'ribs': 3, 'sleeve_force': 60.0, 'time_step': 2e-4, 'v0': 0.0,
         'rib1.stick_until': 0.02, 'rib1.hinge_coulomb': 0.05, 'rib1.hinge_viscous': 0.01,
         'rib2.youngs_modulus': 2.2e11}


@pytest.mark.parametrize('frame_prefix', ['', 'a/', 'abc/', 'antenna_12/'])
def test_encoded_rib_bytes_are_the_built_messages(frame_prefix):
    """
    Every per-publication topic of the umbrella: cdr_bytes of rib_messages's message, exactly.

    Samples with rib 1 stuck, deploying after its release, and locked (stage 2), the peak
    stresses held over each period as the node publishes them; the readers (rib_joint_figures,
    rib_array_figures, rib_energy_figures) find in the bytes the sample's own figures.
    """
    driver = RunDriver(UmbrellaRibsParams.from_mapping(STUCK), 500.0)
    encoder = RibsPublicationEncoder(driver)
    seen = set()
    s = driver.publication()
    for period in range(200):
        if period % 7 == 0 or s.time < 0.006:
            msgs = encoder.messages(s, 'umbrella', 1.0, frame_prefix)
            seen.add((str(s.stage), bool(np.any(s.stuck))))
            reference = rib_messages(s, encoder.yield_strength, encoder.initial_energy,
                                     frame_prefix)
            assert set(msgs) - {'markers'} == set(reference)
            for key, ref in reference.items():
                data = msgs[key]
                assert isinstance(data, bytes), key
                assert data == cdr_bytes(ref), key     # exact size, zero padding, every value
                assert deserialize_message(data, type(ref)) == ref, key
            read_back(msgs, s, encoder)
        chunks = driver.advance_period()
        assert chunks[-1].error is None
        s = driver.publication()
        if s.stage == 'locked' and s.time > driver.sim.lock_time + 0.05:
            break
    assert seen == {('deploying', True), ('deploying', False), ('locked', False)}


def read_back(msgs, s, encoder):
    """Check that the readers find the sample's own figures in the encoded bytes."""
    ribs = len(s.alpha1)
    joints = rib_joint_figures(deserialize_message(msgs['joint_states'], JointState))
    assert joints['alpha1'] == s.alpha1.tolist()
    assert joints['link_angle'] == (s.alpha2 - s.alpha1).tolist()
    assert joints['link_angle_rate'] == (s.alpha2_rate - s.alpha1_rate).tolist()
    assert (joints['sleeve_position'], joints['sleeve_velocity'], joints['sleeve_force']) == (
        s.sleeve_position, s.sleeve_velocity, s.sleeve_force)
    tips = rib_array_figures(deserialize_message(msgs['rib_tip_deflection'], Float64MultiArray))
    assert [list(t.values()) for t in tips] == s.tip.tolist()
    stress = rib_array_figures(deserialize_message(msgs['rib_peak_stress'], Float64MultiArray))
    assert len(stress) == ribs
    for k, rib in enumerate(stress):
        for name in STRESS_NAMES:
            assert rib[f'{name}_Pa'] == s[f'stress_{name}'][k]
        assert [rib['von_mises_body'], rib['von_mises_x_m']] == s.stress_von_mises_at[k].tolist()
        assert rib['von_mises_ratio'] == s.stress_von_mises[k] / encoder.yield_strength
    energy = rib_energy_figures(deserialize_message(msgs['energy'], Float64MultiArray))
    assert energy['balance_error_J'] == energy_balance3d(s, encoder.initial_energy)
    assert energy['friction_work_J'] == sum(s.friction_work.tolist())     # every hinge's
