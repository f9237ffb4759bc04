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
ROS 2 message layer: topics, QoS, and Sample -> messages.

Shared by the live node and the offline MCAP writer so both produce the same topics and
layout.  Imports ROS message packages but not rclpy's node machinery; the physics core does
not import this module.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import struct

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PointStamped
import numpy as np
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSPolicyKind, QoSProfile,
                       ReliabilityPolicy)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Float64, Float64MultiArray, MultiArrayDimension, String
from visualization_msgs.msg import Marker, MarkerArray

from .robot_description import TIP
from ..bag.format import APPLIED_SUFFIX, REFUSED_SUFFIX
from ..core.outputs import energy_balance, Sample
from ..core.params import UmbrellaParams

INERTIAL_FRAME = 'umbrella_base'   # X toward the leaf, Y up the axle, origin at the hinge O
#: tip_deflection's frame: the URDF's undeformed tip G, the leaf frame's axes (origin O, x'
#: through O'') moved to x' = l1 + l2, so that the point (u_G, v_G, 0), G's elastic
#: displacement, is where the deformed tip is (a viewer draws it at the tip, not near O)
TIP_FRAME = TIP
JOINT_NAMES = ['leaf_hinge', 'link_hinge', 'sleeve_slider']
PHASES = ('deploying', 'locked', 'fault')

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /clock as rclpy's TimeSource (and rclcpp's ClockQoS) subscribes to it and as rosbag2 and
#: Gazebo publish it: best effort, keep last 1.  A reliable reader does not match it.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                       history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
#: the node's own services (~/reset, ~/pause): rclpy's parameter services' depth, 1000, not
#: the services' default 10, whose request reader kept the last 10 of a storm of calls (the
#: rest were never answered)
SERVICE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                         history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
#: a /clock reader that keeps every tick until its callback runs (tests, benchmarks)
CLOCK_READER_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT,
                              history=HistoryPolicy.KEEP_LAST,
                              durability=DurabilityPolicy.VOLATILE)


@dataclass(frozen=True)
class Topic:
    name: str          # relative names resolve under the node's namespace
    type: type  # noqa: A003 (the message type, as rclpy calls it)
    qos: QoSProfile


TOPICS = {
    'clock': Topic('clock', Clock, CLOCK_QOS),
    'joint_states': Topic('joint_states', JointState, RELIABLE),
    'tip_deflection': Topic('tip_deflection', PointStamped, RELIABLE),
    'peak_stress': Topic('peak_stress', Float64MultiArray, RELIABLE),
    'markers': Topic('markers', MarkerArray, RELIABLE),
    'deployment_phase': Topic('deployment_phase', String, LATCHED),
    'energy': Topic('energy', Float64MultiArray, RELIABLE),
    # absolute, as diagnostic_updater publishes: one aggregator sees every antenna
    'diagnostics': Topic('/diagnostics', DiagnosticArray, RELIABLE),
}
#: the node's topics that its namespace does not move
ABSOLUTE_TOPIC_NAMES = frozenset(t.name for t in TOPICS.values() if t.name.startswith('/'))
#: keep all: with a reliable publisher, a burst of commands faster than the node takes them
#: is held back by DDS flow control instead of being overwritten in the reader's history
#: (keep-last 10 lost ~4 % of a 5 kHz stream); every received value is counted and recorded.
#: The depth does not bound a keep-all reader in Fast DDS, its resource limits do (5000
#: samples by default): a reader that took nothing accepted 4000 commands and not all of 7000,
#: at depth 100 as at 10 000; past that, DDS refuses a command until its writer's next
#: heartbeat (every 3 s); the node takes 10 000-19 000 a second (bench/bench_commands.py).
COMMAND = Topic('sleeve_force', Float64, QoSProfile(
    depth=10000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_ALL,
    durability=DurabilityPolicy.VOLATILE))


#: <command>/applied (each value as it starts acting) and <command>/refused (each command
#: refused), published and recorded: reliable, keep last 100 (a reader keeps up with one a
#: publication at most; refused ones are published REFUSED_RECORD_RATE a second at most)
COMMAND_ECHO_SUFFIXES = {'applied': APPLIED_SUFFIX, 'refused': REFUSED_SUFFIX}
COMMAND_ECHO_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                              history=HistoryPolicy.KEEP_LAST,
                              durability=DurabilityPolicy.VOLATILE)

#: the policies a qos_overrides.<topic>.publisher|subscription.<policy> parameter sets, for
#: every topic of TOPICS and COMMAND (rclpy's default set, plus durability: a late joiner
#: may want /clock or markers transient local)
QOS_OVERRIDE_POLICIES = (QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH,
                         QoSPolicyKind.RELIABILITY, QoSPolicyKind.DURABILITY)


def own_qos(qos: QoSProfile) -> QoSProfile:
    """Return a copy of a profile (rclpy applies qos_overrides to the profile it is given)."""
    return QoSProfile(history=qos.history, depth=qos.depth, reliability=qos.reliability,
                      durability=qos.durability, lifespan=qos.lifespan, deadline=qos.deadline,
                      liveliness=qos.liveliness,
                      liveliness_lease_duration=qos.liveliness_lease_duration,
                      avoid_ros_namespace_conventions=qos.avoid_ros_namespace_conventions)


# ------------------------------------------------------------------------ messages
def stamp_ns(t: float) -> int:
    return int(round(float(t) * 1e9))      # (a numpy scalar's arithmetic: slower, the same)


def stamp_parts(t: float) -> tuple[int, int]:
    """Return (sec, nanosec) of sim time t, as builtin_interfaces/Time holds it."""
    return divmod(stamp_ns(t), 1_000_000_000)


def stamp(t: float) -> Time:
    sec, nanosec = stamp_parts(t)
    return Time(sec=sec, nanosec=nanosec)


#: a builtin_interfaces/Time in CDR (int32 sec, uint32 nanosec), as the encoders pack it
_STAMP = struct.Struct('<iI')


def marker_every(publish_rate: float | None, marker_rate: float) -> int:
    """Return k: markers on every k-th publication (t = 0 included), round(rate / marker_rate)."""
    return max(1, round(publish_rate / marker_rate)) if publish_rate else 1


def clock_msg(t: float) -> Clock:
    return Clock(clock=stamp(t))


def joint_state_values(s: Sample) -> tuple:
    """Return position, velocity, effort of JOINT_NAMES (relative link angle, sleeve along Y)."""
    return ((s.alpha1, s.alpha2 - s.alpha1, s.sleeve_position),
            (s.alpha1_rate, s.alpha2_rate - s.alpha1_rate, s.sleeve_velocity),
            (0.0, 0.0, s.sleeve_force))


def joint_state_msg(s: Sample, frame_prefix: str = '') -> JointState:
    msg = JointState()
    msg.header.stamp = stamp(s.time)
    msg.header.frame_id = frame_prefix + INERTIAL_FRAME
    msg.name = list(JOINT_NAMES)
    position, velocity, effort = joint_state_values(s)
    msg.position, msg.velocity, msg.effort = list(position), list(velocity), list(effort)
    return msg


def tip_deflection_values(s: Sample) -> tuple:
    """Return G's elastic displacement along the leaf's axes: axial u, transverse v, 0 (m)."""
    return (s.tip_axial, s.tip_transverse, 0.0)


def tip_deflection_msg(s: Sample, frame_prefix: str = '') -> PointStamped:
    msg = PointStamped()
    msg.header.stamp = stamp(s.time)
    msg.header.frame_id = frame_prefix + TIP_FRAME
    x, y, z = tip_deflection_values(s)
    msg.point = Point(x=x, y=y, z=z)
    return msg


PEAK_STRESS_LABELS = ('body: leaf,link',
                      'field: peak_abs_stress_Pa,position_m,stress_ratio,reference_stress_Pa')
ENERGY_LABEL = 'field: kinetic_J,strain_J,work_J,lock_loss_J,balance_error_J,damping_J'


#: the peak_stress data, in order: per body, peak |sigma|, where, ratio to yield, and the
#: reference stress (top fibre; leaf at O'', link at mid-span: the thesis's Fig. 6.5, 6.6)
PEAK_STRESS_FIELDS = ('peak_stress_leaf', 'peak_stress_leaf_x', 'stress_ratio_leaf',
                      'stress_leaf_joint', 'peak_stress_link', 'peak_stress_link_x',
                      'stress_ratio_link', 'stress_link_mid')
#: the energy data, in order (ENERGY_LABEL)
ENERGY_FIELDS = ('kinetic_energy', 'strain_energy', 'work', 'lock_energy_loss',
                 'energy_balance', 'damping_dissipation')
#: what recordings made before the stage-2 mode fit carry after ENERGY_FIELDS: the earlier
#: phase correction's term, in the energy that integrator kept (T + V + it)
LEGACY_ENERGY_FIELDS = ('phase_correction_energy',)


def peak_stress_values(s: Sample, yield_strength: float) -> tuple:
    """Return the peak_stress data (PEAK_STRESS_FIELDS)."""
    return (s.peak_stress_leaf, s.peak_stress_leaf_x, s.peak_stress_leaf / yield_strength,
            s.stress_leaf_joint,
            s.peak_stress_link, s.peak_stress_link_x, s.peak_stress_link / yield_strength,
            s.stress_link_mid)


def peak_stress_msg(s: Sample, yield_strength: float) -> Float64MultiArray:
    """Build the peak_stress message (peak_stress_values, labelled layout)."""
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=PEAK_STRESS_LABELS[0], size=2, stride=8),
                      MultiArrayDimension(label=PEAK_STRESS_LABELS[1], size=4, stride=4)]
    msg.layout.data_offset = 0
    msg.data = list(peak_stress_values(s, yield_strength))
    return msg


def energy_values(s: Sample, initial_energy: float) -> tuple:
    """Return the energy data (ENERGY_FIELDS, J)."""
    return (s.kinetic_energy, s.strain_energy, s.work, s.lock_energy_loss,
            energy_balance(s, initial_energy), s.damping_dissipation)


def energy_msg(s: Sample, initial_energy: float) -> Float64MultiArray:
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=ENERGY_LABEL, size=len(ENERGY_FIELDS),
                                          stride=len(ENERGY_FIELDS))]
    msg.data = list(energy_values(s, initial_energy))
    return msg


# --------------------------------------------------------- reading them back
# The figures a publication's messages carry, by the Sample's names: the inverse of the
# *_values builders above, for every reader of a recording or a live topic (replay,
# compare, the test API, the deploy controller)
def joint_state_figures(msg) -> dict:
    """
    Return the figures of a joint state, by the Sample's names.

    alpha1, the link's joint angle alpha2 - alpha1 (link_angle), their rates, alpha2, and
    the sleeve's position, velocity and force.
    """
    position, velocity, effort = msg.position, msg.velocity, msg.effort
    return {'alpha1': position[0], 'link_angle': position[1],
            'alpha2': position[0] + position[1], 'sleeve_position': position[2],
            'alpha1_rate': velocity[0], 'link_angle_rate': velocity[1],
            'sleeve_velocity': velocity[2], 'sleeve_force': effort[2]}


def tip_deflection_figures(msg) -> dict:
    """Return tip_axial and tip_transverse (m, leaf frame)."""
    return {'tip_axial': msg.point.x, 'tip_transverse': msg.point.y}


def peak_stress_figures(msg) -> dict:
    """Return PEAK_STRESS_FIELDS by name."""
    return dict(zip(PEAK_STRESS_FIELDS, msg.data))


def energy_figures(msg) -> dict:
    """Return ENERGY_FIELDS by name (J), and LEGACY_ENERGY_FIELDS where a recording has them."""
    return dict(zip(ENERGY_FIELDS + LEGACY_ENERGY_FIELDS, msg.data))


def markers_msg(s: Sample, positions, ns: str, frame_prefix: str = '',
                hub_radius: float | None = None) -> MarkerArray:
    """
    LINE_STRIPs of the deformed bodies (id i: positions[i]), the sleeve, the hub.

    positions: each body's points, leaf then link: (X, Y) of the planar model, as
    UmbrellaModel.deformed_shape gives them (each element drawn by its own shape functions,
    not a straight line between nodes), or (X, Y, Z) of every rib in turn
    (umbrella_markers.UmbrellaShapes).  hub_radius None: the planar sleeve, a SPHERE on the
    axle (id len(positions)); a radius: the whole umbrella's sleeve and hub, rings of that
    radius about the hub axis Y (CYLINDERs at y_H and at 0, ids len(positions) and + 1).
    """
    out = MarkerArray()
    colours = (ColorRGBA(r=0.9, g=0.6, b=0.1, a=1.0), ColorRGBA(r=0.2, g=0.5, b=0.9, a=1.0))
    header = (stamp(s.time), frame_prefix + INERTIAL_FRAME)

    def marker(i: int, kind: int) -> Marker:
        m = Marker()
        m.header.stamp, m.header.frame_id = header
        m.ns = ns
        m.id = i
        m.type = kind
        m.action = Marker.ADD
        m.pose.orientation.w = 1.0
        return m

    for i, pts in enumerate(positions):
        m = marker(i, Marker.LINE_STRIP)
        m.scale.x = 0.01
        m.color = colours[i % 2]
        pts = np.asarray(pts, dtype=float)
        z = pts[:, 2] if pts.shape[1] > 2 else np.zeros(len(pts))
        m.points = [Point(x=float(x), y=float(y), z=float(zz))
                    for x, y, zz in zip(pts[:, 0], pts[:, 1], z)]
        out.markers.append(m)
    n = len(positions)
    if hub_radius is None:
        m = marker(n, Marker.SPHERE)
        m.pose.position = Point(x=0.0, y=s.sleeve_position, z=0.0)
        m.scale.x = m.scale.y = m.scale.z = 0.03
        m.color = ColorRGBA(r=0.8, g=0.1, b=0.1, a=1.0)
        out.markers.append(m)
        return out
    for i, y, colour in ((n, s.sleeve_position, ColorRGBA(r=0.8, g=0.1, b=0.1, a=1.0)),
                         (n + 1, 0.0, ColorRGBA(r=0.4, g=0.4, b=0.4, a=1.0))):
        m = marker(i, Marker.CYLINDER)
        m.pose.position = Point(x=0.0, y=y, z=0.0)
        # the cylinder's axis (z) onto +Y: a quarter turn about -X
        m.pose.orientation.x, m.pose.orientation.w = -math.sqrt(0.5), math.sqrt(0.5)
        m.scale.x = m.scale.y = 2.0 * hub_radius + 0.03
        m.scale.z = 0.03
        m.color = colour
        out.markers.append(m)
    return out


def phase_msg(phase: str) -> String:
    assert phase in PHASES
    return String(data=phase)


def diagnostic_name(node_fqn: str) -> str:
    """Return the status name, 'NAMESPACE/umbrella_node: physics' (diagnostic_updater style)."""
    return f"{node_fqn.lstrip('/')}: physics"


def diagnostics_msg(t: float, name: str, level: bytes, message: str,
                    values: dict) -> DiagnosticArray:
    """Build a one-status array; level is DiagnosticStatus.OK, WARN, ERROR or STALE."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp(t)
    st = DiagnosticStatus(level=level, name=name, message=message,
                          hardware_id='umbrella_sim')
    st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    msg.status = [st]
    return msg


def template_layout(template: bytes, groups: tuple, stamped: bool) -> tuple:
    """
    Return (Struct of the whole message, its constant byte runs) for a template.

    template: a message's exact CDR bytes (``cdr_bytes``) whose variable part is a stamp
    (``stamped``: header.stamp or Clock.clock, right after the 4-byte CDR header) and
    groups of doubles (their counts, in order) that end the message.  CDR (XCDR1, 8-aligned
    doubles): the last group of doubles ends the message; before each later sequence of
    doubles sit its 4-byte count and 4 pad bytes, since every group of doubles ends
    8-aligned.  The Struct packs, in order: the constant bytes before the stamp (the CDR
    header), the stamp if any, then before each group the constant bytes up to it (``Ns``
    fields: the template's own bytes) and its doubles.
    """
    fields, consts, pos = ['<'], [], 0
    if stamped:
        fields += ['4s', _STAMP.format.lstrip('<')]
        consts.append(template[:STAMP_OFFSET])
        pos = STAMP_OFFSET + _STAMP.size
    for start, k in zip(group_starts(len(template), groups), groups):
        fields += [f'{start - pos}s', f'{k}d']
        consts.append(template[pos:start])
        pos = start + 8 * k
    if pos != len(template):
        fields.append(f'{len(template) - pos}s')
        consts.append(template[pos:])
    layout = struct.Struct(''.join(fields))
    if layout.size != len(template):
        raise ValueError(f'a {len(template)}-byte template, a {layout.size}-byte layout')
    return layout, tuple(consts)


def group_starts(size: int, groups: tuple) -> list[int]:
    """
    Return where each group of doubles starts in a message of size bytes (template_layout).

    The groups (their counts of doubles, in order) end the message; before each later one
    sit its sequence's 4-byte count and 4 pad bytes (CDR, XCDR1: 8-aligned doubles).
    """
    starts, end = [], size
    for k in reversed(groups):
        starts.append(end - 8 * k)
        end = starts[-1] - 8
    return starts[::-1]


#: where a stamp (header.stamp, Clock.clock) sits: right after the 4-byte CDR header
STAMP_OFFSET = 4


def pack_stamp(buffer: bytearray, sec: int, nsec: int) -> None:
    """Write a stamp into a stamped message's CDR bytes (at STAMP_OFFSET)."""
    _STAMP.pack_into(buffer, STAMP_OFFSET, sec, nsec)


def template_layouts(messages: dict, groups: dict, stamped) -> dict:
    """
    Return {key: template_layout of messages[key]} for every key of groups (its doubles).

    The templates are the builders' messages serialized by ``cdr_bytes`` (exact size, zero
    padding, as ``ros2 bag record`` writes them); stamped: the keys with a stamp.
    """
    from ..bag.cdr import cdr_bytes  # the exact-size rule, one place
    return {key: template_layout(cdr_bytes(messages[key]), g, key in stamped)
            for key, g in groups.items()}


class SampleEncoder:
    """
    The per-publication topics of a Sample straight to CDR bytes (the publication hot path).

    Each topic's bytes are those of rclpy's serializer for the message the builders above
    make (``sample_messages``), trimmed to the exact size as ``ros2 bag record`` writes
    them: a template serialized once from the builders' message holds the constant part
    (layout, labels, joint names, frame ids), and each publication packs only the stamp and
    the doubles between those constant bytes, one ``struct`` call a topic.  No message
    objects per publication: the node publishes these bytes (Publisher.publish takes
    serialized bytes) and the recorder writes them.
    """

    #: topic key -> doubles at the end of the message, as groups (a sequence or a struct)
    GROUPS = {'energy': (len(ENERGY_FIELDS),), 'clock': (), 'joint_states': (3, 3, 3),
              'tip_deflection': (3,), 'peak_stress': (len(PEAK_STRESS_FIELDS),)}
    #: topics with a stamp (header.stamp, Clock.clock) right after the 4-byte CDR header
    STAMPED = ('clock', 'joint_states', 'tip_deflection')

    def __init__(self, first: Sample, params: UmbrellaParams, initial_energy: float,
                 frame_prefix: str = ''):
        self.yield_strength = params.yield_strength
        self.initial_energy = initial_energy
        self._layouts = template_layouts(
            sample_messages(first, params, None, '', initial_energy, frame_prefix),
            self.GROUPS, self.STAMPED)

    def encode(self, s: Sample) -> dict[str, bytes]:
        """Return the CDR bytes of every per-publication topic of s, keyed as TOPICS."""
        sec, nsec = stamp_parts(s.time)
        layouts = self._layouts
        energy, energy_c = layouts['energy']
        clock, clock_c = layouts['clock']
        joints, joints_c = layouts['joint_states']
        tip, tip_c = layouts['tip_deflection']
        peak, peak_c = layouts['peak_stress']
        position, velocity, effort = joint_state_values(s)
        # each pack's arguments in template_layout's order: the header (and stamp) if
        # STAMPED, then for each of GROUPS[key] its constant bytes and its doubles
        return {
            'energy': energy.pack(energy_c[0], *energy_values(s, self.initial_energy)),
            'clock': clock.pack(clock_c[0], sec, nsec),
            'joint_states': joints.pack(joints_c[0], sec, nsec, joints_c[1], *position,
                                        joints_c[2], *velocity, joints_c[3], *effort),
            'tip_deflection': tip.pack(tip_c[0], sec, nsec, tip_c[1],
                                       *tip_deflection_values(s)),
            'peak_stress': peak.pack(peak_c[0], *peak_stress_values(s, self.yield_strength)),
        }


class MarkerEncoder:
    """
    ``markers_msg`` straight to CDR bytes: what it builds, serialized, without the messages.

    Building the MarkerArray and serializing it cost 0.3-0.5 ms at N = 2, at once, one
    publication in every ``marker_every``.  The layout is fixed for a mesh, a namespace, a
    frame prefix and a hub, so a template serialized once from ``markers_msg`` holds
    everything but the stamps, the bodies' points and the sleeve's position; their offsets
    are found by serializing the template with distinct sentinel values in those places.
    Each encode writes them all at once through index arrays (no loop over the bodies).
    """

    def __init__(self, positions, ns: str, frame_prefix: str = '',
                 hub_radius: float | None = None):
        from ..bag.cdr import cdr_bytes  # the exact-size rule, one place
        self._counts = tuple(len(p) for p in positions)
        total = sum(self._counts)
        sentinels = _sentinel_doubles(3 * total + 1)                # x, y, z; sleeve
        probe = np.array(sentinels[:3 * total]).reshape(total, 3)
        bodies = np.split(probe, np.cumsum(self._counts)[:-1])
        sleeve = sentinels[-1]
        msg = markers_msg(SleeveAt(0.0, sleeve), bodies, ns, frame_prefix, hub_radius)
        for i, m in enumerate(msg.markers):
            m.header.stamp = Time(sec=_SENTINEL_SEC + i, nanosec=_SENTINEL_NSEC + i)
        data = cdr_bytes(msg)
        self._template = bytes(data)
        # every stamp's sec and nsec as 4-byte words (CDR aligns them to 4)
        stamps = np.array([_unique_offset(data, _STAMP.pack(_SENTINEL_SEC + i,
                                                            _SENTINEL_NSEC + i))
                           for i in range(len(msg.markers))])
        self._stamp_words = (stamps[:, None] // 4 + np.arange(2)).ravel()
        # each strip's points: (x, y, z) doubles in a row from its first point's x; CDR
        # aligns doubles to 8 from the 4-byte header, so they are doubles of data[4:]
        firsts = [_unique_offset(data, struct.pack('<d', float(b[0, 0]))) for b in bodies]
        self._point_doubles = np.concatenate(
            [(f - 4) // 8 + np.arange(3 * n) for f, n in zip(firsts, self._counts)])
        self._sleeve_double = (_unique_offset(data, struct.pack('<d', sleeve)) - 4) // 8

    def encode(self, time: float, sleeve_position: float, positions) -> bytes:
        """Return the CDR bytes of markers_msg for these points ((X, Y) or (X, Y, Z) each)."""
        if tuple(len(p) for p in positions) != self._counts:
            raise ValueError(f'point counts {[len(p) for p in positions]}, the template has '
                             f'{list(self._counts)}')
        pts = np.concatenate(positions) if len(positions) > 1 else np.asarray(positions[0])
        if pts.shape[1] == 2:
            pts = np.column_stack([pts, np.zeros(len(pts))])
        return self.encode_points(time, sleeve_position, pts)

    def encode_points(self, time: float, sleeve_position: float, points) -> bytes:
        """Return encode's bytes for every body's (X, Y, Z) points in one (total, 3) array."""
        buf = bytearray(self._template)
        words = np.frombuffer(buf, dtype='<u4', count=len(buf) // 4)
        words[self._stamp_words] = np.tile(stamp_parts(time), len(self._stamp_words) // 2)
        doubles = np.frombuffer(buf, dtype='<f8', offset=4, count=(len(buf) - 4) // 8)
        doubles[self._point_doubles] = np.ravel(points)
        doubles[self._sleeve_double] = sleeve_position
        return bytes(buf)


_SENTINEL_SEC, _SENTINEL_NSEC = 0x5E7E_0000, 0x2A5E_0000


@dataclass(frozen=True)
class SleeveAt:
    """What markers_msg reads of a Sample: the sim time and the sleeve's height."""

    time: float
    sleeve_position: float


def _sentinel_doubles(n: int) -> list[float]:
    """Return n distinct doubles whose bytes are unlikely anywhere else in a message."""
    return [-1.2345678901234567e-77 * (1.0 + 1e-9 * k) for k in range(1, n + 1)]


def _unique_offset(data: bytes, pattern: bytes) -> int:
    at = data.find(pattern)
    if at < 0 or data.find(pattern, at + 1) >= 0:
        raise RuntimeError('marker template: a sentinel is missing or not unique')
    return at


def sample_messages(s: Sample, params: UmbrellaParams, positions, marker_ns: str,
                    initial_energy: float, frame_prefix: str = '') -> dict:
    """
    Return the per-publication messages of one sample, keyed by topic key.

    No markers when positions is None: they go out at their own (display) rate.
    """
    out = {
        'energy': energy_msg(s, initial_energy),
        'clock': clock_msg(s.time),
        'joint_states': joint_state_msg(s, frame_prefix),
        'tip_deflection': tip_deflection_msg(s, frame_prefix),
        'peak_stress': peak_stress_msg(s, params.yield_strength),
    }
    if positions is not None:
        out['markers'] = markers_msg(s, positions, marker_ns, frame_prefix)
    return out
