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
A moving bus's transform on /tf: world -> umbrella_base, where tf2_msgs is installed.

With a moving base (``base: prescribed`` or ``free``) the bus frame ``umbrella_base``, in
which joint_states, the markers and robot_state_publisher's rib frames are, moves in the
inertial ``world``.  A full ROS 2 install has tf2_msgs: the node then broadcasts that
transform at every publication on ``/tf`` (tf2_msgs/TFMessage, as tf2_ros's
TransformBroadcaster: reliable, volatile, depth 100), stamped with the sim time, the same
pose as ``bus_state``'s (outputs3d.bus_odometry), so that RViz with fixed frame ``world``
shows the umbrella moving with its bus.  PyPI has no tf2_msgs: there the node says once
that it broadcasts no /tf and runs on; ``bus_state`` carries the same pose.  /tf is not
recorded (a recording's bus_state holds it): umbrella_replay broadcasts it again from each
bus_state it replays.
"""
from __future__ import annotations

from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from .messages import INERTIAL_FRAME, stamp
from .ribs_messages import WORLD_FRAME
from ..core.umbrella3d.outputs3d import bus_odometry

#: tf2's topic (absolute, as tf2_ros's broadcasters: one tree whatever the node's namespace)
TF_TOPIC = '/tf'
#: tf2_ros's DynamicBroadcasterQoS
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
#: what the node says once where tf2_msgs is missing
NO_TF = ('tf2_msgs is not installed (a PyPI-only install): no /tf of the moving bus '
         '(world -> umbrella_base); bus_state carries its pose')


def tf_message_type():
    """Return tf2_msgs' TFMessage, or None where tf2_msgs is not installed."""
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


def bus_transform(s, frame_prefix: str = '') -> TransformStamped:
    """
    Return the transform world -> umbrella_base of a Sample3D of a moving base.

    The bus origin's position and R's quaternion in ``world`` (bus_state's pose), stamped
    with the sample's sim time; frames with frame_prefix.
    """
    return _transform(stamp(s.time), frame_prefix + WORLD_FRAME,
                      frame_prefix + INERTIAL_FRAME, bus_odometry(s.bus_q, s.bus_v)[:7].tolist())


def odometry_transform(odometry) -> TransformStamped:
    """Return the transform of a bus_state message (a replay's): its pose, stamp and frames."""
    p, o = odometry.pose.pose.position, odometry.pose.pose.orientation
    return _transform(odometry.header.stamp, odometry.header.frame_id, odometry.child_frame_id,
                      [p.x, p.y, p.z, o.x, o.y, o.z, o.w])


def _transform(when, frame_id: str, child: str, pose: list) -> TransformStamped:
    """Return a TransformStamped: pose = translation x, y, z, then quaternion x, y, z, w."""
    out = TransformStamped()
    out.header.stamp = when
    out.header.frame_id, out.child_frame_id = frame_id, child
    t, r = out.transform.translation, out.transform.rotation
    t.x, t.y, t.z, r.x, r.y, r.z, r.w = pose
    return out


class BusTransformBroadcaster:
    """
    Broadcast a moving bus's transform on /tf at every publication (if tf2_msgs is installed).

    node: the publishing node (create_publisher); message_type: TFMessage (None: none, then
    ``available`` is False and ``publish`` does nothing).
    """

    def __init__(self, node, frame_prefix: str = '', message_type=None):
        self.message_type = message_type
        self.frame_prefix = frame_prefix
        self.publisher = (None if message_type is None
                          else node.create_publisher(message_type, TF_TOPIC, TF_QOS))

    @property
    def available(self) -> bool:
        return self.publisher is not None

    def message(self, s):
        """Return the TFMessage of a Sample3D, or None without tf2_msgs."""
        if self.message_type is None:
            return None
        return self.message_type(transforms=[bus_transform(s, self.frame_prefix)])

    def replayed(self, odometry):
        """Return the TFMessage of a replayed bus_state, or None without tf2_msgs."""
        if self.message_type is None:
            return None
        return self.message_type(transforms=[odometry_transform(odometry)])

    def publish(self, msg) -> None:
        """Publish a message ``message`` made (None: nothing)."""
        if msg is not None and self.publisher is not None:
            self.publisher.publish(msg)
