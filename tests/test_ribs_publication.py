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


#: a free bus, rib 1 kicked out of its plane: the bus moves and turns in reaction
FREE_BUS = {'ribs': 3, 'base': 'free', 'bus_mass': 5.0, 'bus_inertia': 0.2, 'v0': -0.2,
            'time_step': 2e-4, 'rib1.out_of_plane_rate': 0.5}
#: a prescribed base: a jolt along X and a spin-up about Y
DRIVEN = {'ribs': 3, 'base': 'prescribed', 'base_accel_x': 20.0, 'base_spin_rate': 3.0,
          'v0': -0.2, 'time_step': 2e-4}


@pytest.mark.parametrize('values', [FREE_BUS, DRIVEN], ids=['free', 'prescribed'])
def test_bus_state_bytes_are_the_built_odometry_of_the_bus(values):
    """
    A moving base's bus_state: cdr_bytes of the built Odometry, and the bus's own motion.

    The pose is the sample's bus position and attitude (the quaternion's rotation is R =
    Ry(psi) Rx(beta) Rz(gamma) to 1e-15), the twist the bus's velocity and angular velocity in
    its own frame: R^T X' and the omega of R' = R [omega]x, R' the derivative of R along the
    attitude's rates (a central difference of 1e-6 s: to 1e-8 of omega).
    """
    from nav_msgs.msg import Odometry

    from umbrella_sim.core.umbrella3d.model3d import BusFrame

    driver = RunDriver(UmbrellaRibsParams.from_mapping(values), 1000.0)
    encoder = RibsPublicationEncoder(driver)
    moved, turned = 0.0, 0.0
    s = driver.publication()
    for _ in range(30):
        msgs = encoder.messages(s, 'umbrella', 1.0, 'a/')
        ref = rib_messages(s, encoder.yield_strength, encoder.initial_energy, 'a/')['bus_state']
        assert msgs['bus_state'] == cdr_bytes(ref)
        odo = deserialize_message(msgs['bus_state'], Odometry)
        assert (odo.header.frame_id, odo.child_frame_id) == ('a/world', 'a/umbrella_base')
        p, o = odo.pose.pose.position, odo.pose.pose.orientation
        assert [p.x, p.y, p.z] == s.bus_q[:3].tolist()
        x, y, z, w = o.x, o.y, o.z, o.w
        rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        frame = BusFrame.of(s.bus_q[3:6])
        assert np.abs(rot - frame.rot).max() < 1e-15 and w >= 0.0
        lin, ang = odo.twist.twist.linear, odo.twist.twist.angular
        assert [lin.x, lin.y, lin.z] == pytest.approx(frame.rot.T @ s.bus_v[:3], abs=1e-15)
        assert [ang.x, ang.y, ang.z] == pytest.approx(frame.basis @ s.bus_v[3:6], abs=1e-15)
        dt, rates = 1e-6, s.bus_v[3:6]
        skew = frame.rot.T @ (BusFrame.of(s.bus_q[3:6] + dt * rates).rot
                              - BusFrame.of(s.bus_q[3:6] - dt * rates).rot) / (2 * dt)
        omega = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        assert np.linalg.norm(omega - [ang.x, ang.y, ang.z]) <= 1e-8 * np.linalg.norm(omega)
        moved = max(moved, float(np.linalg.norm(s.bus_q[:3])))
        turned = max(turned, float(np.linalg.norm(omega)))
        assert driver.advance_period()[-1].error is None
        s = driver.publication()
    assert moved > 1e-5 and turned > 1e-3          # (a bus that moves and turns)


def test_a_fixed_hub_advertises_no_bus_state():
    """bus_state is the moving base's: a fixed hub has no bus (and the planar rib none)."""
    from umbrella_sim.ros.ribs_messages import node_topics

    assert 'bus_state' not in node_topics(3) and 'bus_state' not in node_topics(1, 'free')
    assert node_topics(3, 'free')['bus_state'].name == 'bus_state'
    driver = RunDriver(UmbrellaRibsParams.from_mapping({'ribs': 3}), 100.0)
    assert 'bus_state' not in RibsPublicationEncoder(driver).messages(driver.publication())


def test_a_recording_of_a_free_bus_holds_its_bus_state(tmp_path, capsys):
    """
    A --mcap recording holds bus_state as the node publishes it: its last pose the end's.

    The summary's bus_q at the run's end is the last recorded message's position, and the
    bus moved (the rib kicked out of its plane turns it); a fixed hub records no bus_state.
    """
    import json

    from nav_msgs.msg import Odometry

    from umbrella_sim.bag.reader import read_log
    from umbrella_sim.tools.cli import main

    args = [f'--set={k}={v}' for k, v in FREE_BUS.items()]
    assert main(['simulate', *args, '--duration', '0.02', '--json',
                 '--mcap', str(tmp_path / 'free')]) == 0
    summary = json.loads(capsys.readouterr().out)
    log = read_log(str(tmp_path / 'free'))
    (topic,) = [t for t in log.topics() if t.endswith('bus_state')]
    assert log.channels[topic][0] == 'nav_msgs/msg/Odometry'
    t, last = log.decoded(topic)[-1]
    assert isinstance(last, Odometry) and t == pytest.approx(0.02, abs=1e-12)
    p = last.pose.pose.position
    assert [p.x, p.y, p.z] == summary['bus_q'][:3] and np.linalg.norm(summary['bus_q'][:3]) > 0
    assert main(['simulate', '--set=ribs=3', '--duration', '0.01', '--json',
                 '--mcap', str(tmp_path / 'fixed')]) == 0
    assert not [t for t in read_log(str(tmp_path / 'fixed')).topics() if 'bus' in t]


def test_diagnostics_carry_a_free_buss_momentum_and_a_fixed_hub_none():
    """
    A free bus's diagnostics: the system's momentum at the latest step, zero as it started.

    The whole umbrella on a free bus starts with no momentum and no external force acts: the
    linear momentum the diagnostics carry stays 0 (to 1e-12 kg m/s) while the 5 kg bus moves
    at more than 1 mm/s in reaction to the ribs; a fixed hub's diagnostics have no such keys.
    """
    import json

    from umbrella_sim.core.driver import simulate
    from umbrella_sim.ros.ribs_messages import ribs_diagnostics

    run = simulate(UmbrellaRibsParams.from_mapping(FREE_BUS), 0.02, keep_samples=False)
    values = ribs_diagnostics(run.figures)
    linear = json.loads(values['linear_momentum_kg_m_s'])
    assert linear == run.figures['linear_momentum'] and len(linear) == 3
    assert np.linalg.norm(linear) < 1e-12 and np.linalg.norm(run.figures['bus_v'][:3]) > 1e-3
    assert json.loads(values['angular_momentum_kg_m2_s']) == run.figures['angular_momentum']
    fixed = simulate(UmbrellaRibsParams.from_mapping({'ribs': 3}), 0.004, keep_samples=False)
    assert not [k for k in ribs_diagnostics(fixed.figures) if 'momentum' in k]


@pytest.mark.parametrize('values', [FREE_BUS, DRIVEN], ids=['free', 'prescribed'])
def test_the_bus_transform_on_tf_is_bus_states_pose(values):
    """
    A moving bus's /tf transform world -> umbrella_base: bus_state's pose, at its stamp.

    bus_tf.bus_transform of each publication's sample carries bus_state's position and
    quaternion exactly, with its stamp and frames (frame_prefix on both); the broadcaster
    publishes one TFMessage a publication on /tf, reliable, volatile, depth 100 (tf2_ros's
    broadcasters'), through a stand-in node and message type where tf2_msgs is missing.
    """
    from nav_msgs.msg import Odometry
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    from umbrella_sim.ros.bus_tf import bus_transform, BusTransformBroadcaster

    class Stand:                           # (TFMessage's shape; a node's create_publisher)

        def __init__(self, transforms=None):
            self.transforms, self.sent = transforms, []

        def create_publisher(self, msg_type, topic, qos):
            self.created = (msg_type, topic, qos)
            return self

        def publish(self, msg):
            self.sent.append(msg)

    node = Stand()
    broadcaster = BusTransformBroadcaster(node, 'a/', Stand)
    msg_type, topic, qos = node.created
    assert (msg_type, topic, qos.depth) == (Stand, '/tf', 100) and broadcaster.available
    assert (qos.reliability, qos.durability) == (ReliabilityPolicy.RELIABLE,
                                                 DurabilityPolicy.VOLATILE)
    driver = RunDriver(UmbrellaRibsParams.from_mapping(values), 1000.0)
    encoder = RibsPublicationEncoder(driver)
    moved = 0.0
    for _ in range(10):
        assert driver.advance_period()[-1].error is None
        s = driver.publication()
        odo = deserialize_message(encoder.messages(s, 'umbrella', 1.0, 'a/')['bus_state'],
                                  Odometry)
        broadcaster.publish(broadcaster.message(s))
        (tf,) = node.sent[-1].transforms
        assert tf == bus_transform(s, 'a/')
        assert (tf.header, tf.child_frame_id) == (odo.header, odo.child_frame_id)
        p, r = tf.transform.translation, tf.transform.rotation
        pose = odo.pose.pose
        assert [p.x, p.y, p.z, r.x, r.y, r.z, r.w] == [
            pose.position.x, pose.position.y, pose.position.z, pose.orientation.x,
            pose.orientation.y, pose.orientation.z, pose.orientation.w]
        moved = max(moved, float(np.linalg.norm(s.bus_q[:3])))
    assert len(node.sent) == 10 and moved > 1e-6


def test_without_tf2_msgs_the_bus_broadcasts_nothing():
    """Where tf2_msgs is missing (PyPI) the broadcaster is off: no publisher, no message."""
    import importlib.util

    from umbrella_sim.ros.bus_tf import BusTransformBroadcaster, tf_message_type

    assert (tf_message_type() is None) == (importlib.util.find_spec('tf2_msgs') is None)

    class Node:

        def create_publisher(self, *args):
            raise AssertionError('no publisher without tf2_msgs')

    off = BusTransformBroadcaster(Node(), '', None)
    driver = RunDriver(UmbrellaRibsParams.from_mapping(FREE_BUS), 1000.0)
    assert not off.available and off.message(driver.publication()) is None
    off.publish(None)


def test_a_replayed_bus_state_goes_on_tf_as_the_node_sent_it(tmp_path, monkeypatch, capsys):
    """
    umbrella_replay of a free bus: each bus_state's pose again on /tf, as the node sent it.

    The replay's broadcaster (a stand-in TFMessage where tf2_msgs is missing) turns each
    recorded bus_state into the transform bus_tf.bus_transform gives the run's sample at its
    stamp; without tf2_msgs the replay says that it broadcasts no /tf, and with no bus_state
    among the topics replayed says nothing.
    """
    from nav_msgs.msg import Odometry

    from umbrella_sim.bag.reader import read_log
    from umbrella_sim.ros import bus_tf
    from umbrella_sim.tools import replay
    from umbrella_sim.tools.cli import main

    class Stand:

        def __init__(self, transforms=None):
            self.transforms = transforms

        def create_publisher(self, msg_type, topic, qos):
            assert (msg_type, topic) == (Stand, '/tf')
            return self

    args = [f'--set={k}={v}' for k, v in FREE_BUS.items()]
    assert main(['simulate', *args, '--duration', '0.01', '--mcap', str(tmp_path / 'b')]) == 0
    capsys.readouterr()
    log = read_log(str(tmp_path / 'b'))
    topics = log.topics()
    monkeypatch.setattr(bus_tf, 'tf_message_type', lambda: None)
    assert replay._bus_broadcaster(Stand(), topics) == ({}, f'; {bus_tf.NO_TF}')
    assert replay._bus_broadcaster(Stand(), [t for t in topics if 'bus' not in t]) == ({}, '')
    monkeypatch.setattr(bus_tf, 'tf_message_type', lambda: Stand)
    bus, said = replay._bus_broadcaster(Stand(), topics)
    ((topic, broadcaster),) = bus.items()
    assert topic.endswith('bus_state') and '/tf' in said
    driver = RunDriver(UmbrellaRibsParams.from_mapping(FREE_BUS), 100.0)
    sent = 0
    for t, odometry in log.decoded(topic):
        assert isinstance(odometry, Odometry)
        while driver.time < t - 1e-12:
            assert driver.advance_period()[-1].error is None
        (tf,) = broadcaster.replayed(odometry).transforms
        assert tf == bus_tf.bus_transform(driver.publication())
        sent += 1
    assert sent == log.count(topic) >= 2
