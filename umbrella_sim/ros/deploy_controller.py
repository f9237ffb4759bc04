"""
deploy_controller: closed-loop deployment of the umbrella frame over ROS topics.

Subscribes ``joint_states`` and ``deployment_phase`` of an ``umbrella_node`` and publishes
``sleeve_force``.  Starting from rest it deploys the frame in ``target_time`` (sim seconds from
the first push to the lock) and brings the leaf to the stop slowly, at ``lock_rate``, within
the force limits [``min_force``, ``max_force``].

Why braking.  The speed at the lock sets the stage-2 vibration: the lock keeps the kinetic
energy (thesis 5.2.2) and turns it into vibration, so the tip amplitude and the stage-2
stress grow like |alpha1'| at the lock.  A push-only drive (F_H >= 0, the thesis's sleeve)
never takes kinetic energy out in stage 1, so for a given deploy time the softest push-only
lock is a coast at constant kinetic energy; with the thesis frame that lowers the stage-2
amplitude only ~3x below the constant force deploying in the same time.  A real deployment
drive (a lead screw, a motor) can also hold the sleeve back: ``min_force`` < 0 allows it, and
the node must then accept such commands (its ``sleeve_force_min`` parameter).  With
``min_force = 0`` the plan has no braking and ends in a coast.

The law, in the leaf angle alpha1 (the natural coordinate: the sleeve's lever dy_H/dalpha1
vanishes near the folded state, so a sleeve-position loop would be badly scaled):

* at the first push a reference alpha1_ref(t) is planned on the rigid two-angle model
  (rigid.py: same geometry and masses): full push from rest, cruise, a constant
  deceleration down to ``lock_rate`` at the stop (optionally a last ``creep_angle`` at
  ``lock_rate``); the cruise rate is solved so that the whole plan takes ``target_time``;
* the force is the plan's inverse dynamics, m(a) a'' + 1/2 m'(a) a'^2 = -F_H y_H'(a), at the
  commanded acceleration a''_ref + kv (a'_ref - a') + kp (a_ref - a), clipped to the limits.
  The feed-forward carries the motion, so the gains stay low: the frame's bending modes
  (20-35 Hz, undamped in the model) sit inside the loop with a DDS round trip of 5-100 ms,
  and a stiff loop would pump them.  The position term keeps the deploy time.

The law itself (``DeployLaw``) is plain Python on the physics core's rigid model, tested
offline against the simulator (``simulate_closed_loop``) as well as over DDS; rclpy is
imported only by the node part.
"""
from __future__ import annotations

import collections
from dataclasses import dataclass
import math
import statistics
import sys
import time

import numpy as np

from . import signals as stop_signals
from ..core.params import (check_known_names, check_parameter_sources, params_files_in,
                           UmbrellaParams)
from ..core.rigid import RigidMechanism

#: controller parameters: name -> (default, description with units)
CONTROLLER_PARAMETERS = {
    "target_time": (1.0, "deploy time to reach, from the first push to the lock (s, sim time)"),
    "max_force": (20.0, "largest sleeve force commanded (N, > 0, pushes along -Y); the plan "
                  "starts with it"),
    "min_force": (0.0, "smallest sleeve force commanded (N, <= 0); < 0 lets the controller "
                  "hold the sleeve back (the node must accept it: sleeve_force_min <= "
                  "min_force); 0 = push-only"),
    "lock_rate": (0.0, "leaf angular speed |alpha1'| at the stop (rad/s); 0 = a quarter of "
                  "the mean rate (alpha0 - alpha_deployed) / target_time"),
    "creep_angle": (0.0, "last stretch of alpha1 before the stop planned at lock_rate (rad); "
                    "0 = brake right up to the stop, which keeps the needed force steady "
                    "there: a command held through a stall of the loop then stays right"),
    "deceleration": (0.0, "planned leaf deceleration before the creep (rad/s^2); 0 = "
                     "4 (alpha0 - alpha_deployed) / target_time^2, capped at half of what "
                     "min_force can do near the stop (the rest is kept for feedback)"),
    "velocity_gain": (8.0, "feedback gain on the leaf rate error (1/s)"),
    "position_gain": (36.0, "feedback gain on the leaf angle error (1/s^2); it keeps the "
                      "deploy time"),
}

#: at rest for the plan: rate and angle from the start within this fraction of the plan's
#: cruise rate and of its span
REST_FRACTION = 0.05
CONTROLLER_PARAMETERS_LISTED = ("deploy_controller --help and in msg_docs/deploy_controller.md "
                                "(and umbrella_node's, for the model)")


def _check(name: str, value: float, ok: bool, rule: str) -> float:
    if not (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value) and ok):
        raise ValueError(f"parameter {name}={value!r}: {rule}")
    return float(value)


@dataclass(frozen=True)
class ControllerConfig:
    target_time: float = CONTROLLER_PARAMETERS["target_time"][0]
    max_force: float = CONTROLLER_PARAMETERS["max_force"][0]
    min_force: float = CONTROLLER_PARAMETERS["min_force"][0]
    lock_rate: float = CONTROLLER_PARAMETERS["lock_rate"][0]
    creep_angle: float = CONTROLLER_PARAMETERS["creep_angle"][0]
    deceleration: float = CONTROLLER_PARAMETERS["deceleration"][0]
    velocity_gain: float = CONTROLLER_PARAMETERS["velocity_gain"][0]
    position_gain: float = CONTROLLER_PARAMETERS["position_gain"][0]

    def validated(self) -> "ControllerConfig":
        v = self
        _check("target_time", v.target_time, 0 < v.target_time <= 1e4, "must be in (0, 1e4] s")
        _check("max_force", v.max_force, 0 < v.max_force <= 1e9, "must be in (0, 1e9] N")
        _check("min_force", v.min_force, -1e9 <= v.min_force <= 0, "must be in [-1e9, 0] N")
        _check("lock_rate", v.lock_rate, v.lock_rate >= 0, "must be >= 0 rad/s (0 = auto)")
        _check("creep_angle", v.creep_angle, v.creep_angle >= 0, "must be >= 0 rad")
        _check("deceleration", v.deceleration, v.deceleration >= 0,
               "must be >= 0 rad/s^2 (0 = auto)")
        _check("velocity_gain", v.velocity_gain, v.velocity_gain >= 0, "must be >= 0 1/s")
        _check("position_gain", v.position_gain, v.position_gain >= 0, "must be >= 0 1/s^2")
        return self


class DeployLaw:
    """
    Sleeve force from (sim time, alpha1, alpha1'); see the module docstring.

    ``start(t)`` marks the sim time the first push acts from (the plan's t = 0);
    ``force(t, alpha1, rate)`` is the command for the state sampled at t.
    """

    GRID = 4000        # plan resolution in alpha1

    def __init__(self, params: UmbrellaParams, cfg: ControllerConfig):
        self.params = params.validated()
        self.cfg = cfg.validated()
        self.mech = RigidMechanism(self.params)
        p, c = self.params, self.cfg
        self.span = p.alpha0 - p.alpha_deployed
        if c.creep_angle >= self.span:
            raise ValueError(f"parameter creep_angle={c.creep_angle}: must be below "
                             f"alpha0 - alpha_deployed = {self.span:.6g} rad")
        self.lock_rate = c.lock_rate if c.lock_rate > 0 else 0.25 * self.span / c.target_time
        near_stop = p.alpha_deployed + self.span * np.linspace(0.0, 0.5, 21)
        self.braking_authority = min(-c.min_force * self.lever(a) / self.inertia(a)
                                     for a in near_stop)
        if c.min_force < 0:
            wanted = c.deceleration or 4.0 * self.span / c.target_time ** 2
            self.deceleration = min(wanted, 0.5 * self.braking_authority)
        else:
            self.deceleration = 0.0       # push-only: no braking, the plan ends in a coast
        self._plan()
        self.t_start: float | None = None

    # ------------------------------------------------------------ rigid model
    def inertia(self, a1: float) -> float:
        """Generalised mass m(alpha1): T = 1/2 m alpha1'^2 on the constraint (4.120)."""
        a2 = self.mech.alpha2(a1)
        return 2.0 * self.mech.kinetic_energy(a1, a2, 1.0, self.mech.alpha2_rate_ratio(a1, a2))

    def lever(self, a1: float) -> float:
        """dy_H / d alpha1 (m/rad): F_H's generalised force on alpha1 is -F_H times this."""
        p = self.params
        a2 = self.mech.alpha2(a1)
        return p.l1 * math.cos(a1) + p.l3 * math.cos(a2) * self.mech.alpha2_rate_ratio(a1, a2)

    def _inverse_dynamics(self, a1: float, rate: float, accel: float) -> float:
        h = 1e-6
        dm = (self.inertia(a1 + h) - self.inertia(a1 - h)) / (2 * h)
        return -(self.inertia(a1) * accel + 0.5 * dm * rate * rate) / self.lever(a1)

    # ------------------------------------------------------------------- plan
    def _plan(self) -> None:
        """
        Tabulate alpha1_ref(t) and the feed-forward force.

        s(d) = min(full push from rest, cruise, braking curve, creep) over the remaining
        angle d, the cruise rate bisected to take target_time.
        """
        p, c = self.params, self.cfg
        d = np.linspace(self.span, 0.0, self.GRID + 1)          # remaining angle, decreasing
        alpha = p.alpha_deployed + d
        y = np.array([self.mech.sleeve_height(a, self.mech.alpha2(a)) for a in alpha])
        m = np.array([self.inertia(a) for a in alpha])
        push = np.sqrt(np.maximum(2.0 * c.max_force * (y[0] - y) / m, 0.0))  # 1/2 m s^2 = W
        s_e, d_c, dec = self.lock_rate, c.creep_angle, self.deceleration
        if dec > 0:
            brake = np.where(d > d_c, np.sqrt(s_e ** 2 + 2 * dec * np.maximum(d - d_c, 0.0)),
                             s_e)
        else:
            brake = np.full_like(d, np.inf)

        def profile(cruise):
            return np.minimum(np.minimum(push, brake), cruise)

        def duration(cruise):
            s = profile(cruise)
            mid = 0.5 * (s[1:] + s[:-1])
            return float(np.sum(np.diff(-d) / np.maximum(mid, 1e-300)))

        fastest = duration(np.inf)
        if fastest > c.target_time:
            raise ValueError(f"parameter target_time={c.target_time:g}: too short for "
                             f"max_force={c.max_force:g} N (and the braking at min_force="
                             f"{c.min_force:g} N): the fastest plan takes {fastest:.4g} s")
        lo, hi = 1e-6, float(np.max(np.minimum(push, brake)))
        if dec <= 0:
            lo = max(lo, s_e) if c.lock_rate > 0 else lo
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            if duration(mid) > c.target_time:
                lo = mid
            else:
                hi = mid
        self.cruise = hi
        s = profile(hi)
        mid = 0.5 * (s[1:] + s[:-1])
        t = np.concatenate([[0.0], np.cumsum(np.diff(-d) / np.maximum(mid, 1e-300))])
        rate = -s                                              # alpha1' < 0 deploys
        accel = np.gradient(rate, t, edge_order=1)
        self.plan_t, self.plan_alpha, self.plan_rate, self.plan_accel = t, alpha, rate, accel
        self.plan_force = np.array([self._inverse_dynamics(a, r, acc)
                                    for a, r, acc in zip(alpha, rate, accel)])

    def reference(self, t: float) -> tuple[float, float, float]:
        """
        Return (alpha1_ref, alpha1'_ref, alpha1''_ref) at sim time t.

        Past the plan's end the reference keeps creeping at lock_rate (a late frame is still
        brought in slowly).
        """
        tau = t - self.t_start
        end = self.plan_t[-1]
        if tau >= end:
            return self.params.alpha_deployed + self.plan_rate[-1] * (tau - end), \
                self.plan_rate[-1], 0.0
        tau = max(tau, 0.0)
        return (float(np.interp(tau, self.plan_t, self.plan_alpha)),
                float(np.interp(tau, self.plan_t, self.plan_rate)),
                float(np.interp(tau, self.plan_t, self.plan_accel)))

    # -------------------------------------------------------------------- law
    def start(self, t: float) -> None:
        self.t_start = t

    def force(self, t: float, a1: float, rate: float, lead: float = 0.0) -> float:
        """
        Return the command for the state (alpha1, alpha1') sampled at t.

        It acts about ``lead`` seconds later (the measured command delay): the state is
        predicted to then along the plan's acceleration, so the delay does not eat the
        loop's phase.
        """
        if self.t_start is None:
            self.start(t)
        a_ref, rate_ref, accel_ref = self.reference(t + lead)
        a1 = a1 + rate * lead + 0.5 * accel_ref * lead * lead
        rate = rate + accel_ref * lead
        accel = (accel_ref + self.cfg.velocity_gain * (rate_ref - rate)
                 + self.cfg.position_gain * (a_ref - a1))
        f = self._inverse_dynamics(a1, rate, accel)
        return min(max(f, self.cfg.min_force), self.cfg.max_force)


# ================================================================== offline loop
def constant_force_for(params: UmbrellaParams, target_time: float, rtol: float = 1e-4) -> float:
    """
    Return the constant sleeve force that deploys from rest in target_time on this model.

    The physics core decides; secant steps on t ~ F^-1/2 from the rigid quadrature's guess.
    """
    from ..core.rigid import deployment_time_by_quadrature
    from ..core.solver import simulate

    p = params.replace(v0=0.0)
    force = deployment_time_by_quadrature(p, sleeve_force=1.0) ** 2 / target_time ** 2
    for _ in range(20):
        run = simulate(p.replace(sleeve_force=force), 20.0 * target_time, stop_after_lock=0.0)
        if run.lock is None:
            raise ValueError(f"no lock within {20 * target_time:g} s at F = {force:g} N")
        if abs(run.lock.time - target_time) <= rtol * target_time:
            return force
        force *= (run.lock.time / target_time) ** 2
    raise ValueError(f"no constant force found deploying in {target_time:g} s")


def simulate_closed_loop(params: UmbrellaParams, cfg: ControllerConfig,
                         publish_rate: float = 200.0, delay: int = 1, after_lock: float = 0.5):
    """
    Run the law against the physics core as the node runs it.

    States are sampled at publish_rate, each command acts ``delay`` publications later (the
    DDS round trip).  Returns (RunResult of every step, first push time).
    """
    from ..core.params import physics_step
    from ..core.solver import UmbrellaSimulator
    from ..core.summary import RunResult

    p = params.replace(v0=0.0).with_physics_step(
        physics_step(params.physics_time_step, publish_rate))
    sim = UmbrellaSimulator(p)
    law = DeployLaw(params, cfg)
    period = 1.0 / publish_rate
    result = RunResult(params=p.as_dict())
    result.samples.append(sim.sample())
    pending = [0.0] * delay
    law.start(delay * period)
    while sim.lock_event is None or sim.time < sim.lock_event.time + after_lock - 1e-12:
        s = sim.sample()
        pending.append(0.0 if sim.lock_event else
                       law.force(s.time, s.alpha1, s.alpha1_rate, (delay + 0.5) * period))
        sim.set_sleeve_force(pending.pop(0))
        result.samples.extend(sim.advance_to(sim.time + period))
        if sim.time > 20.0 * cfg.target_time:
            break
    result.lock, result.steps = sim.lock_event, sim.steps
    return result, delay * period


# ======================================================================= ROS node
def _make_node_class():
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64, String

    from . import messages as ros_io

    class DeployControllerNode(Node):
        """joint_states + deployment_phase -> sleeve_force, one command per joint state."""

        def __init__(self, params_files: tuple = ()):
            super().__init__("deploy_controller")
            # a misspelt name is an error, never a silent default; the node's own names are
            # taken (and not used: the numerics), so one params file can serve both nodes
            known = set(CONTROLLER_PARAMETERS) | set(ros_io.parameter_defaults())
            fqn = self.get_fully_qualified_name()
            try:
                qos = check_parameter_sources(fqn, params_files, list(
                    self._parameter_overrides), known, CONTROLLER_PARAMETERS_LISTED)
                check_known_names(qos, (), f"qos_overrides for {fqn} (its topics take none)",
                                  CONTROLLER_PARAMETERS_LISTED)
            except ValueError as exc:
                raise StartupError(str(exc)) from None
            values = {}
            for name, (default, text) in CONTROLLER_PARAMETERS.items():
                values[name] = self.declare_parameter(name, default, ParameterDescriptor(
                    name=name, description=text, read_only=True, dynamic_typing=True)).value
            # the frame the law's rigid model describes: umbrella_node's own parameter names
            model = {}
            for name, default in UmbrellaParams().as_dict().items():
                if name in ("model", "lock", "time_step", "step_follows_mesh",
                            "elements_per_segment", "v0"):
                    continue    # the numerics do not enter the law; it plans from rest
                model[name] = self.declare_parameter(name, default, ParameterDescriptor(
                    name=name, read_only=True, dynamic_typing=True,
                    description="model parameter: give the value umbrella_node has")).value
            try:
                cfg = ControllerConfig(**{k: _number(k, v) for k, v in values.items()})
                self.law = DeployLaw(UmbrellaParams.from_mapping(model), cfg)
            except ValueError as exc:
                raise StartupError(str(exc)) from None
            self.pub = self.create_publisher(Float64, ros_io.COMMAND.name, ros_io.COMMAND.qos)
            # depth 1: after a stall the law works on the newest state, never on a backlog
            latest = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                history=HistoryPolicy.KEEP_LAST,
                                durability=DurabilityPolicy.VOLATILE)
            self.create_subscription(JointState, ros_io.TOPICS["joint_states"].name,
                                     self._on_state, latest)
            self.create_subscription(String, ros_io.TOPICS["deployment_phase"].name,
                                     self._on_phase, ros_io.TOPICS["deployment_phase"].qos)
            self.phase: str | None = None
            self.commanding = False
            self.done = False
            self._last_stamp: float | None = None
            self._period: float | None = None
            self._last_effort = 0.0
            self._last_wall: float | None = None
            self._sent: collections.deque = collections.deque(maxlen=400)  # (stamp, F)
            self._delays: collections.deque = collections.deque(maxlen=15)
            self._not_ours = 0        # consecutive states applying none of our commands
            self._publishers_checked = -math.inf     # wall time of the last check
            self.get_logger().info(
                f"target {cfg.target_time:g} s, force in [{cfg.min_force:g}, "
                f"{cfg.max_force:g}] N, lock rate {self.law.lock_rate:.4g} rad/s, "
                f"deceleration {self.law.deceleration:.4g} rad/s^2; waiting for joint_states")

        def _restart(self, why: str) -> None:
            """Deploy a new run of the simulation (~/reset, a restarted node) afresh."""
            if self.commanding or self.done:
                self.get_logger().info(f"{why}: a new run; deploying it from its start")
            self.law.t_start = None
            self.commanding = self.done = False
            self._last_stamp = None
            self._last_wall = None
            self._last_effort = 0.0
            self._sent.clear()
            self._not_ours = 0

        def _on_phase(self, msg) -> None:
            if msg.data == "deploying" and self.phase in ("locked", "fault"):
                self._restart(f"phase {self.phase} -> deploying")
            self.phase = msg.data
            if msg.data != "deploying" and self.commanding and not self.done:
                self.done = True
                self.pub.publish(Float64(data=0.0))
                delays = sorted(self._delays)
                spread = (f"{1e3 * delays[0]:.1f}..{1e3 * delays[-1]:.1f} ms" if delays
                          else "not measured")
                self.get_logger().info(f"phase {msg.data} (last state t = "
                                       f"{self._last_stamp or 0.0:.6f} s): deployment over, "
                                       f"commanding 0 N; command delay {spread} (last 15)")

        def _on_state(self, msg) -> None:
            t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            if self._last_stamp is not None and t < self._last_stamp - 1e-9:
                # sim time went back: the simulation restarted (its plan and its time base
                # are no longer this run's; a stale plan latched hard at 100x the energy)
                self._restart(f"sim time went back from {self._last_stamp:.6f} s to "
                              f"{t:.6f} s")
            if self.done or self.phase != "deploying":
                if self.done:               # (sim time going back then means a new run)
                    self._last_stamp = t
                return
            now = time.monotonic()
            if self._last_wall is not None and self.commanding and now - self._last_wall > 0.05:
                self.get_logger().warn(
                    f"no joint_states for {1e3 * (now - self._last_wall):.0f} ms (wall) up to "
                    f"t = {t:.3f} s: the command was held meanwhile", throttle_duration_sec=1.0)
            self._last_wall = now
            if self._last_stamp is not None and t > self._last_stamp:
                # the publication period: the smallest spacing seen (states may be skipped)
                self._period = min(self._period or math.inf, t - self._last_stamp)
            self._last_stamp = t
            effort = msg.effort[2]
            if effort != self._last_effort and self._period:
                self._measure_delay(t, effort)
            self._last_effort = effort
            if self.law.t_start is None:
                if self.commanding and effort != 0.0 and self._period:
                    # the first state carrying our push: it acted from one period before
                    self.law.start(t - self._period)
                    self.get_logger().info(f"first push acting from t = "
                                           f"{self.law.t_start:.6f} s")
                elif not self.commanding and not self._at_rest(t, msg):
                    self.done = True        # idle until a new run
                    return
                else:
                    self.commanding = True
                    self._send(t, self.law.cfg.max_force)
                    return
            self._check_commands_applied(t, effort)
            self._send(t, self.law.force(t, msg.position[0], msg.velocity[0], self.lead()))

        def _at_rest(self, t: float, msg) -> bool:
            """
            Tell whether the frame is folded and at rest, where the plan starts.

            Else log why not (the node's v0, or another command moved it) and stay idle
            for this run: pushing a frame already deploying faster than the plan only makes
            its lock harder.
            """
            p, law = self.law.params, self.law
            rate, angle = msg.velocity[0], msg.position[0]
            if abs(rate) <= REST_FRACTION * law.cruise and \
                    abs(angle - p.alpha0) <= REST_FRACTION * law.span:
                return True
            self.get_logger().error(
                f"the frame is not folded at rest at t = {t:.6f} s (alpha1 = {angle:.6g} rad, "
                f"alpha1' = {rate:.6g} rad/s; the plan starts at alpha0 = {p.alpha0:.6g} rad "
                f"at rest and cruises at {law.cruise:.4g} rad/s): give umbrella_node v0:=0.0 "
                "(and no other sleeve_force command); not commanding this run (a ~/reset "
                "starts a new one)")
            return False

        def _check_commands_applied(self, t: float, effort: float) -> None:
            """
            Warn when the node applies none of our recent commands, or others command it.

            The node echoes the force it applies in ``effort[2]``: a value none of our
            commands of the last round trip had (the latest measured delay plus three
            periods: a free-running node under load took commands 0.2 s late where the
            median was one period; an older spike no longer widens it, or a refused braking
            command went unnoticed), three states running, means it refuses them
            (its sleeve_force_min / sleeve_force_limit) or another publisher commands it.
            After a stall the first state may show an older command, once.  Publishers on
            the topic are counted once a second.
            """
            now = time.monotonic()
            if now - self._publishers_checked >= 1.0:
                self._publishers_checked = now
                n = self.count_publishers(self.pub.topic_name)
                if n > 1:
                    self.get_logger().warn(
                        f"{n} publishers on {self.pub.topic_name}: the node applies "
                        "whichever command came last, so another node commanding the sleeve "
                        "fights this one; stop it", throttle_duration_sec=5.0)
            period = self._period or 0.0
            window = (self._delays[-1] if self._delays else period) + 3 * period
            ours = {f for ts, f in self._sent if ts >= t - window - 1e-9}
            self._not_ours = 0 if effort in ours else self._not_ours + 1
            if self._not_ours >= 3:
                self.get_logger().warn(
                    f"the node applies {effort:.6g} N at t = {t:.6f} s, none of our commands "
                    f"of the last {window:g} s (latest {self._sent[-1][1]:.6g} N): it refuses "
                    "them (its sleeve_force_min / sleeve_force_limit; see its log) or another "
                    "node commands it", throttle_duration_sec=2.0)

        def _send(self, t: float, force: float) -> None:
            self._sent.append((t, float(force)))
            self.pub.publish(Float64(data=float(force)))

        def _measure_delay(self, t: float, effort: float) -> None:
            """
            Measure the delay of the command behind a new applied force.

            The state at t shows it acting since t - period: the command that set it is the
            first of the latest run of that value we sent.
            """
            sent = list(self._sent)
            for i in range(len(sent) - 1, -1, -1):
                if sent[i][1] == effort and (i == 0 or sent[i - 1][1] != effort):
                    delay = (t - self._period) - sent[i][0]
                    if delay >= -1e-9:
                        self._delays.append(delay)
                    return

        def lead(self) -> float:
            """How long after a state its command acts, on average over its hold."""
            period = self._period or 0.0
            delay = statistics.median(self._delays) if self._delays else period
            return delay + 0.5 * period

    return DeployControllerNode


class StartupError(RuntimeError):
    pass


def _number(name: str, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"parameter {name}={value!r}: must be a number")
    return float(value)


def main(argv: list[str] | None = None) -> int:
    # SIGINT/SIGTERM only ask for a stop (stop_signals.py), as in umbrella_node.  With rclpy's
    # own handlers a signal shut the context down from the signal handler while the executor
    # could be building its next wait set: rclpy.spin then raised RCLError ("failed to
    # initialize wait set: the given context is not valid") and the process exited 1.
    stop_signals.install()
    argv = list(sys.argv if argv is None else argv)
    if any(a in ("-h", "--help") for a in argv[1:argv.index("--ros-args")
                                               if "--ros-args" in argv else len(argv)]):
        print(usage())
        return 0
    if stop_signals.received:           # during the imports: nothing started yet
        return 0
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    try:                        # rcl's parse errors are tracebacks: check the files first
        files = params_files_in(argv)
    except ValueError as exc:
        print(f"deploy_controller: error: {exc}", file=sys.stderr)
        return 2
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = _make_node_class()(tuple(files))
    except StartupError as exc:
        print(f"deploy_controller: error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        # the timeout lets a signal's Python handler run while the executor waits
        while not stop_signals.received:
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def usage() -> str:
    lines = ["usage: deploy_controller [--help] [--ros-args -p name:=value ... "
             "-r __ns:=/NAMESPACE]", "",
             "Closed-loop deployment: joint_states -> sleeve_force (see msg_docs/"
             "deploy_controller.md).", "", "controller parameters:"]
    for name, (default, text) in CONTROLLER_PARAMETERS.items():
        lines.append(f"  {name:<16} {default!r:<8} {text}")
    lines.append("model parameters: the same names and values as umbrella_node's "
                 "(l1, alpha0, ...)")
    return "\n".join(lines)
