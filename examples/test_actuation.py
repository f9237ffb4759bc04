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
Topic-driven actuation tests of the simulated antenna: copy these to start your own.

Run (after `python3 bootstrap.py test` or `python3 bootstrap.py setup` made .venv):

    .venv/bin/python -m pytest examples/

Each test starts its own umbrella_node in a private ROS domain (UMBRELLA_TEST_DOMAIN_ID
picks it), talks to it over real DDS, and stops it afterwards.
"""
import math

import pytest
from std_msgs.msg import Float64

from umbrella_sim.testing import NodeProcess


def test_a_constant_sleeve_force_deploys_the_frame(antenna_factory):
    """
    Deploy from rest with 5 N: deploying -> locked, the leaf at the deployed angle.

    The stage-2 vibration stays below yield (20 N would not: ~580 MPa).
    """
    antenna = antenna_factory({'v0': 0.0, 'publish_rate': 200.0})
    antenna.wait_for_phase('deploying')
    antenna.publish_force(5.0)
    antenna.wait_for_phase('locked', timeout=30)
    summary = antenna.summary(after_lock=0.2)
    assert 0.6 < summary.deploy_time < 0.75                 # rigid estimate: 0.673 s
    final = antenna.messages('joint_states')[-1]
    assert abs(final.position[0] - math.pi / 12) < 5e-3     # leaf_hinge = alpha1, rad
    assert summary.stage2_peak_stress < 500e6                # yield of Al 7075-T6, Pa


def test_the_deploy_controller_latches_softly(antenna_factory, ros_domain_id):
    """
    Let deploy_controller bring the leaf to the stop slowly in the asked time.

    A drive that can brake (sleeve_force_min < 0) keeps the stage-2 vibration small.
    """
    # joint_states at the node's default 100 Hz: the controller answers each of them, and in
    # lockstep the node waits for that answer before it computes the next period, so a
    # controller process that gets no CPU for a while on a busy machine only slows the run
    # down, never changes it; a 2 ms physics step is the thesis's
    antenna = antenna_factory({'v0': 0.0, 'sleeve_force_min': -8.0, 'time_step': 0.002,
                               'lockstep': True})
    antenna.wait_for_phase('deploying')
    with NodeProcess(module='umbrella_sim.deploy_controller', domain_id=ros_domain_id,
                     parameters={'target_time': 1.0, 'max_force': 8.0, 'min_force': -8.0}):
        antenna.wait_for_phase('locked', timeout=90)
        summary = antenna.summary(after_lock=0.3)
    assert abs(summary.deploy_time - 1.0) < 0.05
    assert summary.stage2_tip_amplitude < 0.02               # m; 20 N gives ~0.16 m
    assert min(f for _, f in antenna.applied_forces()) < 0.0  # it did hold the sleeve back


def test_a_nan_command_is_refused_and_nothing_moves(antenna_factory):
    antenna = antenna_factory({'v0': 0.0})
    with pytest.raises(ValueError, match='sleeve force'):
        antenna.publish_force(float('nan'))     # the helper refuses what the node would
    # sent anyway (check=False), the node refuses it, counts it and nothing moves
    antenna.publish_force(float('nan'), check=False)
    antenna.wait_for('diagnostics', lambda m: any(
        kv.key == 'refused_commands' and kv.value == '1' for kv in m.status[0].values),
        timeout=10, what='refused_commands == 1')
    assert antenna.applied_forces() == []
    assert antenna.phases() == ['deploying']
    states = antenna.messages('joint_states')
    assert all(m.effort[2] == 0.0 for m in states)          # no force ever acted
    # at rest: alpha1 only creeps by round-off (~1e-9 rad a second at a 50 us step)
    assert all(abs(m.position[0] - states[0].position[0]) < 1e-6 for m in states)


def test_commands_on_the_topic_directly(probe, antenna_factory):
    """Do the same without the helpers: your own publisher on the probe node."""
    antenna = antenna_factory({'v0': 0.0}, probe=probe)
    pub = probe.publisher('/sleeve_force', Float64)
    probe.wait_for_subscribers(pub)
    pub.publish(Float64(data=30.0))
    antenna.wait_for_phase('locked', timeout=30)
    assert antenna.applied_forces()[0][1] == 30.0
