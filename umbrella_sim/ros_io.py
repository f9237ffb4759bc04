"""
ROS 2 message layer: topics, QoS, parameter declarations, and Sample -> messages.

Shared by the live node and the offline MCAP writer so both produce the same topics and
layout.  Imports ROS message packages but not rclpy's node machinery; the physics core does
not import this module.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PointStamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Float64, Float64MultiArray, MultiArrayDimension, String
from visualization_msgs.msg import Marker, MarkerArray

from .outputs import Sample
from .params import NODE_PARAMETERS, SPECS, UmbrellaParams

INERTIAL_FRAME = "umbrella_base"   # X toward the leaf, Y up the axle, origin at the hinge O
LEAF_FRAME = "leaf"                # origin O, x' through O''
JOINT_NAMES = ["leaf_hinge", "link_hinge", "sleeve_slider"]
PHASES = ("deploying", "locked", "fault")

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     history=HistoryPolicy.KEEP_LAST, durability=DurabilityPolicy.TRANSIENT_LOCAL)


@dataclass(frozen=True)
class Topic:
    name: str          # relative: resolves under the node's namespace
    type: type  # noqa: A003 (the message type, as rclpy calls it)
    qos: QoSProfile


TOPICS = {
    "clock": Topic("clock", Clock, RELIABLE),
    "joint_states": Topic("joint_states", JointState, RELIABLE),
    "tip_deflection": Topic("tip_deflection", PointStamped, RELIABLE),
    "peak_stress": Topic("peak_stress", Float64MultiArray, RELIABLE),
    "markers": Topic("markers", MarkerArray, RELIABLE),
    "deployment_phase": Topic("deployment_phase", String, LATCHED),
    "energy": Topic("energy", Float64MultiArray, RELIABLE),
    "diagnostics": Topic("diagnostics", DiagnosticArray, RELIABLE),
}
#: recorded alongside the command topic: refused commands, and each value as applied
COMMAND_REFUSED_SUFFIX = "/refused"
COMMAND_APPLIED_SUFFIX = "/applied"
COMMAND = Topic("sleeve_force", Float64, RELIABLE)

# --------------------------------------------------------------------- parameters
_RANGES = {
    "l1": (1e-6, 1e3), "l2": (1e-6, 1e3), "l3": (1e-6, 1e3), "section_height": (0.0, 10.0),
    "area": (0.0, 100.0), "second_moment_of_area": (0.0, 100.0),
    "youngs_modulus": (1e-3, 1e15), "density": (1e-6, 1e6), "yield_strength": (1e-3, 1e15),
    "alpha0": (0.0, math.pi / 2), "alpha_deployed": (0.0, math.pi / 2), "v0": (-1e3, 1e3),
    "sleeve_force": (0.0, 1e9), "time_step": (1e-7, 0.01), "elements_per_segment": (1, 64),
}


def descriptor(name: str) -> ParameterDescriptor:
    """Descriptor with description, units, range and read_only flag for any parameter."""
    if name in NODE_PARAMETERS:
        _, text, rng, read_only = NODE_PARAMETERS[name]
        constraints = "applies immediately" if not read_only else "read-only"
    else:
        spec = SPECS[name]
        text = f"{spec.description} ({spec.units})"
        rng = _RANGES.get(name)
        read_only = False
        constraints = ("structural: a runtime set applies on ~/reset" if spec.structural
                       else "initial value; applies on ~/reset (use the sleeve_force topic)")
        constraints += "; cross-checked with the other parameters (msg_docs/parameters.md)"
    d = ParameterDescriptor(name=name, description=text, additional_constraints=constraints,
                            read_only=read_only)
    if rng is not None:
        if isinstance(rng[0], int) and isinstance(rng[1], int):
            d.integer_range = [IntegerRange(from_value=rng[0], to_value=rng[1], step=1)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(rng[0]),
                                                         to_value=float(rng[1]), step=0.0)]
    # numbers accept int or double literals (-p v0:=-1); UmbrellaParams coerces and checks
    d.dynamic_typing = name not in ("model", "lock", "record_path")
    return d


def parameter_defaults() -> dict:
    out = UmbrellaParams().as_dict()
    out.update({k: v[0] for k, v in NODE_PARAMETERS.items()})
    return out


# ------------------------------------------------------------------------ messages
def stamp(t: float) -> Time:
    ns = int(round(t * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_ns(t: float) -> int:
    return int(round(t * 1e9))


def clock_msg(t: float) -> Clock:
    return Clock(clock=stamp(t))


def joint_state_msg(s: Sample) -> JointState:
    msg = JointState()
    msg.header.stamp = stamp(s.time)
    msg.header.frame_id = INERTIAL_FRAME
    msg.name = list(JOINT_NAMES)
    msg.position = [s.alpha1, s.alpha2 - s.alpha1, s.sleeve_position]
    msg.velocity = [s.alpha1_rate, s.alpha2_rate - s.alpha1_rate, s.sleeve_velocity]
    msg.effort = [0.0, 0.0, s.sleeve_force]
    return msg


def tip_deflection_msg(s: Sample) -> PointStamped:
    msg = PointStamped()
    msg.header.stamp = stamp(s.time)
    msg.header.frame_id = LEAF_FRAME
    msg.point = Point(x=s.tip_axial, y=s.tip_transverse, z=0.0)
    return msg


PEAK_STRESS_LABELS = ("body: leaf,link",
                      "field: peak_abs_stress_Pa,position_m,stress_ratio,reference_stress_Pa")
ENERGY_LABEL = "field: kinetic_J,strain_J,work_J,lock_loss_J,balance_error_J"


def peak_stress_msg(s: Sample, yield_strength: float) -> Float64MultiArray:
    """
    Build the peak_stress message.

    Per body: peak |sigma|, where, ratio to yield, and the reference stress (top fibre;
    leaf at O'', link at mid-span: the thesis's Fig. 6.5 and 6.6).
    """
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=PEAK_STRESS_LABELS[0], size=2, stride=8),
                      MultiArrayDimension(label=PEAK_STRESS_LABELS[1], size=4, stride=4)]
    msg.layout.data_offset = 0
    msg.data = [s.peak_stress_leaf, s.peak_stress_leaf_x, s.peak_stress_leaf / yield_strength,
                s.stress_leaf_joint,
                s.peak_stress_link, s.peak_stress_link_x, s.peak_stress_link / yield_strength,
                s.stress_link_mid]
    return msg


def energy_msg(s: Sample, initial_energy: float) -> Float64MultiArray:
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=ENERGY_LABEL, size=5, stride=5)]
    balance = (s.kinetic_energy + s.strain_energy - initial_energy - s.work + s.lock_energy_loss)
    msg.data = [s.kinetic_energy, s.strain_energy, s.work, s.lock_energy_loss, balance]
    return msg


def markers_msg(s: Sample, positions, ns: str) -> MarkerArray:
    """LINE_STRIPs of the deformed leaf and link, a sphere at the sleeve."""
    out = MarkerArray()
    colours = (ColorRGBA(r=0.9, g=0.6, b=0.1, a=1.0), ColorRGBA(r=0.2, g=0.5, b=0.9, a=1.0))
    for i, (pts, colour) in enumerate(zip(positions, colours)):
        m = Marker()
        m.header.stamp = stamp(s.time)
        m.header.frame_id = INERTIAL_FRAME
        m.ns = ns
        m.id = i
        m.type = Marker.LINE_STRIP
        m.action = Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = 0.01
        m.color = colour
        m.points = [Point(x=float(x), y=float(y), z=0.0) for x, y in pts]
        out.markers.append(m)
    m = Marker()
    m.header.stamp = stamp(s.time)
    m.header.frame_id = INERTIAL_FRAME
    m.ns = ns
    m.id = 2
    m.type = Marker.SPHERE
    m.action = Marker.ADD
    m.pose.position = Point(x=0.0, y=s.sleeve_position, z=0.0)
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 0.03
    m.color = ColorRGBA(r=0.8, g=0.1, b=0.1, a=1.0)
    out.markers.append(m)
    return out


def phase_msg(phase: str) -> String:
    assert phase in PHASES
    return String(data=phase)


def diagnostics_msg(t: float, name: str, level: int, message: str,
                    values: dict) -> DiagnosticArray:
    msg = DiagnosticArray()
    msg.header.stamp = stamp(t)
    st = DiagnosticStatus(level=bytes([level]), name=name, message=message,
                          hardware_id="umbrella_sim")
    st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    msg.status = [st]
    return msg


def sample_messages(s: Sample, params: UmbrellaParams, positions, marker_ns: str,
                    initial_energy: float) -> dict:
    """Return the per-publication messages of one sample, keyed by topic key."""
    return {
        "energy": energy_msg(s, initial_energy),
        "clock": clock_msg(s.time),
        "joint_states": joint_state_msg(s),
        "tip_deflection": tip_deflection_msg(s),
        "peak_stress": peak_stress_msg(s, params.yield_strength),
        "markers": markers_msg(s, positions, marker_ns),
    }
