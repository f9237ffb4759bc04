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
The umbrella of N ribs on ROS topics: joint states per rib, per-rib tip and stress arrays.

With ``ribs`` >= 2 the node publishes, at every publication (msg_docs/topic_ribs.md):

* ``joint_states`` (sensor_msgs/JointState): ``rib<k>/leaf_hinge`` (alpha1 of rib k),
  ``rib<k>/link_hinge`` (its link's angle relative to the leaf, alpha2 - alpha1) for k = 0 ..
  N - 1, rib 0 at azimuth 0 on +X, then ``sleeve_slider`` (the sleeve's height on +Y; its
  effort the whole sleeve's force N F, along -Y);
* ``rib_tip_deflection`` (std_msgs/Float64MultiArray, N x 3): each rib's tip G in its leaf
  frame: axial u, in-plane transverse v, out-of-plane w (tangential, the rib's +Z turned by
  its azimuth), m;
* ``rib_peak_stress`` (std_msgs/Float64MultiArray, N x 8): each rib's largest |stress| since
  the previous publication of every component (axial, in-plane bending, out-of-plane bending,
  torsion shear, the combined von Mises figure; Pa), then where the von Mises peak is (body
  0 leaf from O, 1 link from O''; x in m) and its ratio to ``yield_strength``;
* ``energy`` (std_msgs/Float64MultiArray, 7): T, V, the sleeve force's work, the lock's loss,
  the balance error, the hinges' friction work (<= 0) and a driven base's work, J;
* ``clock``.

Labels in the layouts name the dimensions and fields, as the planar topics' do.  The message
builders and their readers (``rib_figures``) are here, and the encoder of the node and the
offline recorder (publication.py's role for the planar model): the builders' bytes, packed on
templates as the planar topics' (messages.SampleEncoder).
"""
from __future__ import annotations

import json

from nav_msgs.msg import Odometry
import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from .messages import (clock_msg, group_starts, INERTIAL_FRAME, marker_every, pack_stamp,
                       RELIABLE, stamp, stamp_parts, Topic, TOPICS)
from .robot_description import joint_names
from ..core.registry import NODE_PARAMETERS
from ..core.umbrella3d.blocks3d import VON_MISES
from ..core.umbrella3d.outputs3d import bus_odometry, energy_balance3d, STRESS_NAMES

#: the topics of the umbrella's ribs (besides messages.TOPICS' joint_states, energy, clock)
RIB_TOPICS = {
    'rib_tip_deflection': Topic('rib_tip_deflection', Float64MultiArray, RELIABLE),
    'rib_peak_stress': Topic('rib_peak_stress', Float64MultiArray, RELIABLE),
}
RIB_LABEL = 'rib'
#: a moving base's (base prescribed or free): the bus's pose and twist
BUS_TOPIC = Topic('bus_state', Odometry, RELIABLE)
#: the frame the bus moves in (bus_state's header.frame_id; with frame_prefix); the bus's
#: own is INERTIAL_FRAME, umbrella_base, which moves with it
WORLD_FRAME = 'world'
#: bus_state's doubles: pose (position 3, orientation 4, covariance 36), twist (linear 3,
#: angular 3, covariance 36), the message's last 85, contiguous
_POSE, _TWIST = slice(0, 7), slice(43, 49)


#: the planar rib's own topics, which the umbrella of ribs >= 2 carries per rib in RIB_TOPICS
PLANAR_ONLY = ('tip_deflection', 'peak_stress')


def node_topics(ribs: int, base: str = 'fixed') -> dict[str, Topic]:
    """
    Return umbrella_node's topics: messages.TOPICS, and with ribs >= 2 RIB_TOPICS.

    With ribs >= 2, RIB_TOPICS instead of the planar rib's tip_deflection and peak_stress
    (not advertised: nothing would come), and with a moving base (base prescribed or free)
    BUS_TOPIC.
    """
    if ribs == 1:
        return dict(TOPICS)
    bus = {'bus_state': BUS_TOPIC} if base != 'fixed' else {}
    return {**{k: t for k, t in TOPICS.items() if k not in PLANAR_ONLY}, **RIB_TOPICS, **bus}


TIP_FIELDS = ('axial_m', 'in_plane_m', 'out_of_plane_m')
STRESS_FIELDS = tuple(f'{name}_Pa' for name in STRESS_NAMES) + (
    'von_mises_body', 'von_mises_x_m', 'von_mises_ratio')
ENERGY_FIELDS = ('kinetic_J', 'strain_J', 'work_J', 'lock_loss_J', 'balance_error_J',
                 'friction_work_J', 'drive_work_J', 'damping_dissipation_J')
#: the sleeve's joint: the last of joint_states (robot_description.joint_names)
SLEEVE_JOINT = joint_names(2)[-1]


def _array(values: np.ndarray, fields) -> Float64MultiArray:
    """Return a rib array of values (ribs, len(fields)), its layout labelled."""
    msg = Float64MultiArray()
    n, m = values.shape
    msg.layout.dim = [MultiArrayDimension(label=RIB_LABEL, size=n, stride=n * m),
                      MultiArrayDimension(label='field: ' + ','.join(fields), size=m, stride=m)]
    msg.data = values.ravel().tolist()
    return msg


def rib_joint_values(s) -> tuple[list, list, list]:
    """
    Return joint_states' position, velocity and effort of a Sample3D: 3 lists of 2 N + 1.

    Per rib alpha1 and the link's angle relative to the leaf (alpha2 - alpha1), their rates,
    no effort; then the sleeve's height, velocity and the whole sleeve's force.
    """
    v = s.fields()
    alpha1, rate1 = v['alpha1'], v['alpha1_rate']
    position = [x for pair in zip(alpha1.tolist(), (v['alpha2'] - alpha1).tolist())
                for x in pair]
    velocity = [x for pair in zip(rate1.tolist(), (v['alpha2_rate'] - rate1).tolist())
                for x in pair]
    position.append(float(v['sleeve_position']))
    velocity.append(float(v['sleeve_velocity']))
    return position, velocity, [0.0] * (2 * len(alpha1)) + [float(v['sleeve_force'])]


def rib_stress_values(s, yield_strength: float, out: np.ndarray | None = None) -> np.ndarray:
    """Return rib_peak_stress's data of a Sample3D: (ribs, STRESS_FIELDS) (into out if given)."""
    value, at = s.stress_figures()                   # (ribs, components), (.., 2)
    if out is None:
        out = np.empty((len(value), len(STRESS_FIELDS)))
    out[:, :len(STRESS_NAMES)] = value
    out[:, -3:-1] = at[:, VON_MISES]
    np.divide(value[:, VON_MISES], yield_strength, out=out[:, -1])
    return out


def rib_energy_values(s, initial_energy: float) -> list[float]:
    """Return the umbrella's energy data of a Sample3D (ENERGY_FIELDS, J)."""
    v = s.fields()
    return [float(v['kinetic_energy']), float(v['strain_energy']), float(v['work']),
            float(v['lock_energy_loss']), float(energy_balance3d(v, initial_energy)),
            sum(v['friction_work'].tolist()), float(v['drive_work']),
            float(v['damping_dissipation'])]


def rib_messages(s, yield_strength: float, initial_energy: float,
                 frame_prefix: str = '') -> dict:
    """Return the per-publication messages of a Sample3D, keyed as the node's topics."""
    joints = JointState()
    joints.header.stamp = stamp(s.time)
    joints.header.frame_id = frame_prefix + INERTIAL_FRAME
    joints.name = joint_names(len(s.alpha1))
    joints.position, joints.velocity, joints.effort = rib_joint_values(s)
    energy = Float64MultiArray()
    energy.layout.dim = [MultiArrayDimension(label='field: ' + ','.join(ENERGY_FIELDS),
                                             size=len(ENERGY_FIELDS), stride=len(ENERGY_FIELDS))]
    energy.data = rib_energy_values(s, initial_energy)
    out = {'clock': clock_msg(s.time), 'joint_states': joints, 'energy': energy,
           'rib_tip_deflection': _array(np.asarray(s.tip, dtype=float), TIP_FIELDS),
           'rib_peak_stress': _array(rib_stress_values(s, yield_strength), STRESS_FIELDS)}
    if 'bus_q' in s.fields():
        out['bus_state'] = bus_message(s, frame_prefix)
    return out


def bus_message(s, frame_prefix: str = '') -> Odometry:
    """
    Return bus_state of a Sample3D of a moving base: the bus's pose and twist.

    header.frame_id the inertial WORLD_FRAME, child_frame_id the bus's umbrella_base (both
    with frame_prefix); the pose in the first, the twist in the second (outputs3d.bus_odometry);
    no covariance (all 0: a simulation's state is exact).
    """
    x = bus_odometry(s.bus_q, s.bus_v).tolist()
    msg = Odometry()
    msg.header.stamp = stamp(s.time)
    msg.header.frame_id = frame_prefix + WORLD_FRAME
    msg.child_frame_id = frame_prefix + INERTIAL_FRAME
    pose, twist = msg.pose.pose, msg.twist.twist
    pose.position.x, pose.position.y, pose.position.z = x[0:3]
    o = pose.orientation
    o.x, o.y, o.z, o.w = x[3:7]
    twist.linear.x, twist.linear.y, twist.linear.z = x[7:10]
    twist.angular.x, twist.angular.y, twist.angular.z = x[10:13]
    return msg


class RibsSampleEncoder:
    """
    The per-publication topics of a Sample3D straight to CDR bytes (SampleEncoder's rule).

    The bytes of ``rib_messages``'s messages, serialized as ``cdr_bytes`` does: a copy of
    each, serialized once (a template), holds the constant part (the joint names, layouts,
    labels, frame id) and each publication writes the stamp and the doubles in place, through
    numpy views of the copy's groups of doubles (messages.group_starts), then takes its bytes.
    The values are those of ``rib_joint_values``, ``rib_energy_values`` and
    ``rib_stress_values``, written as float64: the same bits as the builders' messages.
    """

    @staticmethod
    def groups(ribs: int, bus: bool = False) -> dict:
        """
        Return topic key -> the groups of doubles of its message for ribs (template_layout).

        bus: a moving base's bus_state too.
        """
        joints = 2 * ribs + 1
        return {'clock': (), 'joint_states': (joints, joints, joints),
                'energy': (len(ENERGY_FIELDS),),
                'rib_tip_deflection': (ribs * len(TIP_FIELDS),),
                'rib_peak_stress': (ribs * len(STRESS_FIELDS),),
                **({'bus_state': (85,)} if bus else {})}

    #: topics with a stamp right after the 4-byte CDR header
    STAMPED = ('clock', 'joint_states', 'bus_state')

    def __init__(self, first, yield_strength: float, initial_energy: float,
                 frame_prefix: str = ''):
        from ..bag.cdr import cdr_bytes  # the exact-size rule, one place
        self.yield_strength, self.initial_energy = yield_strength, initial_energy
        ribs = len(first.alpha1)
        templates = rib_messages(first, yield_strength, initial_energy, frame_prefix)
        self._buffers, views = {}, {}
        self._bus = 'bus_state' in templates
        for key, groups in self.groups(ribs, self._bus).items():
            buffer = self._buffers[key] = bytearray(cdr_bytes(templates[key]))
            views[key] = [np.frombuffer(buffer, '<f8', k, start)
                          for start, k in zip(group_starts(len(buffer), groups), groups)]
        self._position, self._velocity, self._effort = views['joint_states']
        (self._energy,) = views['energy']
        self._tip = views['rib_tip_deflection'][0].reshape(ribs, len(TIP_FIELDS))
        self._stress = views['rib_peak_stress'][0].reshape(ribs, len(STRESS_FIELDS))
        # rib_joint_values' order: per rib alpha1 and the link's angle, then the sleeve's
        self._leaf, self._link = slice(0, 2 * ribs, 2), slice(1, 2 * ribs, 2)
        if self._bus:
            (self._odometry,) = views['bus_state']

    def encode(self, s) -> dict[str, bytes]:
        """Return the CDR bytes of every per-publication topic of s, keyed as the node's."""
        sec, nsec = stamp_parts(s.time)
        b = self._buffers
        pack_stamp(b['clock'], sec, nsec)
        pack_stamp(b['joint_states'], sec, nsec)
        v = s.fields()
        leaf, link = self._leaf, self._link
        position, velocity = self._position, self._velocity
        alpha1, rate1 = v['alpha1'], v['alpha1_rate']
        position[leaf] = alpha1
        np.subtract(v['alpha2'], alpha1, out=position[link])
        position[-1] = v['sleeve_position']
        velocity[leaf] = rate1
        np.subtract(v['alpha2_rate'], rate1, out=velocity[link])
        velocity[-1] = v['sleeve_velocity']
        self._effort[-1] = v['sleeve_force']          # (the ribs' efforts: the template's 0)
        self._energy[:] = rib_energy_values(s, self.initial_energy)
        self._tip[...] = v['tip']
        rib_stress_values(s, self.yield_strength, self._stress)
        if self._bus:
            pack_stamp(b['bus_state'], sec, nsec)
            odometry = bus_odometry(v['bus_q'], v['bus_v'])
            self._odometry[_POSE] = odometry[:7]
            self._odometry[_TWIST] = odometry[7:]
        return {key: bytes(buffer) for key, buffer in b.items()}


class RibsPublicationEncoder:
    """
    What a publication of the umbrella carries, as CDR bytes (PublicationEncoder's role).

    The per-publication topics above (RibsSampleEncoder), and on every marker_every-th
    publication (t = 0 included) the markers of every rib (umbrella_markers.UmbrellaMarkers,
    of the simulator's state: a publication is always of the current state).
    """

    def __init__(self, driver, marker_rate: float = NODE_PARAMETERS['marker_rate'].default):
        self.driver = driver
        first = driver.initial
        self.initial_energy = float(first.kinetic_energy + first.strain_energy)
        self.yield_strength = driver.params.planar.yield_strength
        self.marker_every = marker_every(driver.publish_rate, marker_rate)
        self.count = 0
        self._encoders: dict[str, RibsSampleEncoder] = {}   # by frame_prefix
        self._markers: dict = {}        # by (marker namespace, frame_prefix)

    def messages(self, s, marker_ns: str = 'umbrella', magnification: float = 1.0,
                 frame_prefix: str = '') -> dict[str, bytes]:
        """Return what the publication of s (RunDriver.publication()) publishes."""
        encoder = self._encoders.get(frame_prefix)
        if encoder is None:
            encoder = self._encoders[frame_prefix] = RibsSampleEncoder(
                self.driver.initial, self.yield_strength, self.initial_energy, frame_prefix)
        out = encoder.encode(s)
        if self.count % self.marker_every == 0:
            from .umbrella_markers import UmbrellaMarkers

            sim = self.driver.sim
            if sim.time != s.time:
                raise ValueError(f'markers of t = {s.time} s asked with the simulator at '
                                 f't = {sim.time} s (a publication is of the current state)')
            markers = self._markers.get((marker_ns, frame_prefix))
            if markers is None:
                markers = self._markers[marker_ns, frame_prefix] = UmbrellaMarkers(
                    sim.model, marker_ns, frame_prefix)
            out['markers'] = markers.encode(s.time, sim.state.qr, sim.state.qs, magnification)
        self.count += 1
        return out


#: the umbrella's summary figures (Summary3D.figures) diagnostics carry: key -> figure
DIAGNOSTIC_FIGURES = {'ribs': 'ribs', 'rib_deploy_time_s': 'rib_deploy_time',
                      'deployment_lag_s': 'deployment_lag', 'latest_rib': 'latest_rib',
                      'max_leaf_angle_spread_rad': 'max_leaf_angle_spread',
                      'max_out_of_plane_tip_m': 'max_out_of_plane_tip',
                      'max_out_of_plane_tip_rib': 'max_out_of_plane_tip_rib',
                      'energy_balance_residual_J': 'energy_balance_residual',
                      'energy_scale_J': 'energy_scale', 'friction_work_J': 'friction_work',
                      'peak_von_mises_Pa': None}
#: a free bus's figures diagnostics carry too (the system's momentum at the latest step)
BUS_DIAGNOSTIC_FIGURES = {'linear_momentum_kg_m_s': 'linear_momentum',
                          'angular_momentum_kg_m2_s': 'angular_momentum'}


def ribs_diagnostics(figures: dict) -> dict[str, str]:
    """
    Return the diagnostics values of the umbrella's summary figures so far (JSON text each).

    Every physics step's (Summary3D): each rib's deployment instant (null: not yet), the lag
    of the latest rib after the earliest, the largest out-of-plane tip and its rib, the energy
    balance's largest residual and scale, each rib's friction work and von Mises peak; a
    free bus's linear and angular momentum at the latest step (X, Y, Z; inertial, about the
    origin).
    """
    out = {}
    for key, name in DIAGNOSTIC_FIGURES.items():
        value = (figures['peak_stress']['von_mises']['value'] if name is None
                 else figures.get(name))
        out[key] = json.dumps(value)
    for key, name in BUS_DIAGNOSTIC_FIGURES.items():
        if name in figures:
            out[key] = json.dumps(figures[name])
    return out


# --------------------------------------------------------- reading them back
def rib_array_figures(msg) -> list[dict]:
    """Return a rib_tip_deflection or rib_peak_stress message as one {field: value} a rib."""
    fields = msg.layout.dim[1].label.split(': ', 1)[1].split(',')
    m = len(fields)
    return [dict(zip(fields, msg.data[k * m:(k + 1) * m])) for k in range(msg.layout.dim[0].size)]


def rib_joint_figures(msg) -> dict:
    """
    Return the joint state of an umbrella by the Sample3D's names, per rib (lists).

    alpha1, link_angle, alpha2, their rates, and the sleeve's position, velocity and force.
    """
    names = list(msg.name)
    ribs = (len(names) - 1) // 2
    pos, vel = list(msg.position), list(msg.velocity)
    a1, link = pos[0:2 * ribs:2], pos[1:2 * ribs:2]
    r1, link_rate = vel[0:2 * ribs:2], vel[1:2 * ribs:2]
    i = names.index(SLEEVE_JOINT)
    return {'alpha1': a1, 'link_angle': link, 'alpha2': [a + b for a, b in zip(a1, link)],
            'alpha1_rate': r1, 'link_angle_rate': link_rate, 'sleeve_position': pos[i],
            'sleeve_velocity': vel[i], 'sleeve_force': list(msg.effort)[i]}


def rib_energy_figures(msg) -> dict:
    """Return the umbrella's energy message by field name (J)."""
    return dict(zip(ENERGY_FIELDS, msg.data))


def bus_figures(msg) -> dict:
    """
    Return a bus_state message's figures: time (s), position, orientation, linear, angular.

    position (m, in world), orientation (the quaternion x, y, z, w), linear (m/s) and
    angular (rad/s) velocity in the bus frame, each a list (msg_docs/topic_ribs.md).
    """
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    return {'time': msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec,
            'position': [p.x, p.y, p.z], 'orientation': [o.x, o.y, o.z, o.w],
            'linear': [lin.x, lin.y, lin.z], 'angular': [ang.x, ang.y, ang.z]}
