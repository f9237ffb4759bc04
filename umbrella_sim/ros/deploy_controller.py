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
deploy_controller: closed-loop deployment of the umbrella frame over ROS topics.

Subscribes ``joint_states`` and ``deployment_phase`` of an ``umbrella_node`` and publishes
``sleeve_force``, one command per joint state, from the law of ``core.control.DeployLaw``
(planned on the rigid model of the same frame, or of the whole umbrella of N ribs: see that
module for the law and msg_docs/deploy_controller.md for the node).  Of the umbrella of N
ribs it reads the ribs' mean leaf angle and the sleeve's effort, N F, and commands F, the
node's force per rib (:func:`drive_state`).  Its parameters are the registry's
(``core.params.CONTROLLER_PARAMETERS``: typed, ranged, read-only) and the model's, the
umbrella's (ribs, rib.<name>, rib<k>.<name>) included, which a params file shared with
umbrella_node gives.
"""
from __future__ import annotations

import collections
import math
import statistics
import sys
import time


from . import signals as stop_signals
from .parameters import declare_from_registry, declare_umbrella, NamedRefusals, wrong_type_text
from .params_file import (check_parameter_sources, check_qos_override_sources, init_ros,
                          param_rules_in)
from ..core.control import DeployLaw
from ..core.params import ControllerConfig, UmbrellaParams
from ..core.registry import CONTROLLER_PARAMETERS, defaults, parameter_help
from ..core.rigid import mean_leaf_angle
from ..core.umbrella3d.params3d import (names_a_rib, umbrella_model, umbrella_parameter_help,
                                        umbrella_parameter_names)


#: at rest for the plan: rate and angle from the start within this fraction of the plan's
#: cruise rate and of its span
REST_FRACTION = 0.05
#: wall time after a command that no new joint_states followed, at which it is sent once
#: more.  A reliable writer's first sample can reach a reader that has not yet matched it
#: (its side of the discovery lags the writer's by 3-24 ms, measured): the reader drops it
#: and DDS repairs it only at the writer's next heartbeat, 3 s later (Fast DDS), a 3 s stall
#: of a node in lockstep, which waits for the answer.  Sent again, with the same value, it
#: arrives; a node that got both applies the same force twice.
RESEND_S = 0.25
CONTROLLER_PARAMETERS_LISTED = ('deploy_controller --help and in msg_docs/deploy_controller.md '
                                "(and umbrella_node's, for the model and the umbrella)")


# ======================================================================= ROS node
def drive_state(msg) -> dict:
    """
    Return what the law reads of a joint state: alpha1, its rate, ribs and sleeve_force.

    The planar frame's (ros_io.joint_state_figures), or of the umbrella of N ribs (2 N + 1
    joints, ribs_messages.rib_joint_figures) the ribs' mean leaf angle and rate
    (rigid.mean_leaf_angle: the coordinate the law plans the whole umbrella in; N identical
    ribs each follow the planar frame).  ``sleeve_force`` is the sleeve's effort as
    published: F on the planar frame, the whole sleeve's N F on the umbrella, whose command
    F is per rib.
    """
    from . import messages as ros_io

    if len(msg.position) <= 3:
        state = ros_io.joint_state_figures(msg)
        return {'alpha1': state['alpha1'], 'alpha1_rate': state['alpha1_rate'], 'ribs': 1,
                'sleeve_force': state['sleeve_force']}
    from .ribs_messages import rib_joint_figures

    state = rib_joint_figures(msg)
    return {'alpha1': mean_leaf_angle(state['alpha1']),
            'alpha1_rate': mean_leaf_angle(state['alpha1_rate']), 'ribs': len(state['alpha1']),
            'sleeve_force': state['sleeve_force']}


def _make_node_class():
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64, String

    from . import messages as ros_io

    class DeployControllerNode(NamedRefusals, Node):
        """joint_states + deployment_phase -> sleeve_force, one command per joint state."""

        def __init__(self, params_files: tuple = (), param_rules: dict | None = None):
            super().__init__('deploy_controller')
            # a misspelt name is an error, never a silent default; the node's own names are
            # taken (and not used: the numerics), so one params file can serve both nodes
            known = (set(CONTROLLER_PARAMETERS) | set(defaults())
                     | umbrella_parameter_names())
            fqn = self.get_fully_qualified_name()
            try:
                found = check_parameter_sources(fqn, params_files, self._parameter_overrides,
                                                known, CONTROLLER_PARAMETERS_LISTED,
                                                rules=param_rules, own=names_a_rib)
                warnings = found.warnings + check_qos_override_sources(
                    fqn, found, (), CONTROLLER_PARAMETERS_LISTED, ' (its topics take none)')
            except ValueError as exc:
                raise StartupError(str(exc)) from None
            for text in warnings:      # another node's, in a '/**' section
                self.get_logger().warning(text)
            try:
                values = declare_from_registry(self, CONTROLLER_PARAMETERS)
            except ValueError as exc:
                raise StartupError(str(exc)) from None
            # the frame the law's rigid model describes: umbrella_node's own parameter names
            model = {}
            for name, default in UmbrellaParams().as_dict().items():
                if name in ('model', 'lock', 'time_step', 'step_follows_mesh',
                            'elements_per_segment', 'v0'):
                    continue    # the numerics do not enter the law; it plans from rest
                model[name] = self.declare_parameter(name, default, ParameterDescriptor(
                    name=name, read_only=True, dynamic_typing=True,
                    description='model parameter: give the value umbrella_node has')).value
            try:
                # the umbrella of N ribs (ribs >= 2, each rib's own values): planned whole
                umbrella = declare_umbrella(self)
                # (the ribs the plan is for; _node_ribs: those the node's states show)
                self.planned_ribs = umbrella.get('ribs', 1)
                cfg = ControllerConfig(**values).validated()
                self.law = DeployLaw(umbrella_model(
                    UmbrellaParams.from_mapping(model).validated(), umbrella), cfg)
            except ValueError as exc:
                raise StartupError(str(exc)) from None
            self.pub = self.create_publisher(Float64, ros_io.COMMAND.name, ros_io.COMMAND.qos)
            # depth 1: after a stall the law works on the newest state, never on a backlog
            latest = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                history=HistoryPolicy.KEEP_LAST,
                                durability=DurabilityPolicy.VOLATILE)
            self.create_subscription(JointState, ros_io.TOPICS['joint_states'].name,
                                     self._on_state, latest)
            self.create_subscription(String, ros_io.TOPICS['deployment_phase'].name,
                                     self._on_phase, ros_io.TOPICS['deployment_phase'].qos)
            self.phase: str | None = None
            self.commanding = False
            self.done = False
            self._last_stamp: float | None = None
            self._period: float | None = None
            self._last_effort = 0.0
            self._node_ribs = 1       # the node's ribs (its joint states say): effort N F
            self._last_wall: float | None = None
            self._sent: collections.deque = collections.deque(maxlen=400)  # (stamp, F)
            self._delays: collections.deque = collections.deque(maxlen=15)
            self._not_ours = 0        # consecutive states applying none of our commands
            self._publishers_checked = -math.inf     # wall time of the last check
            # the last command and its wall time, until a state answers it or it is resent
            self._unanswered: tuple | None = None
            self.create_timer(RESEND_S / 2, self._resend_unanswered)
            planned = (f'planned on the umbrella of {self.planned_ribs} ribs, each its own'
                       if self.planned_ribs > 1 else 'planned on one rib (N identical ribs alike)')
            self.get_logger().info(
                f'target {cfg.target_time:g} s, force in [{cfg.min_force:g}, '
                f'{cfg.max_force:g}] N a rib, lock rate {self.law.lock_rate:.4g} rad/s, '
                f'deceleration {self.law.deceleration:.4g} rad/s^2, {planned}; waiting for '
                'joint_states')

        def _restart(self, why: str) -> None:
            """Deploy a new run of the simulation (~/reset, a restarted node) afresh."""
            if self.commanding or self.done:
                self.get_logger().info(f'{why}: a new run; deploying it from its start')
            self.law.t_start = None
            self.commanding = self.done = False
            self._last_stamp = None
            self._last_wall = None
            self._last_effort = 0.0
            self._sent.clear()
            self._not_ours = 0
            self._unanswered = None

        def _on_phase(self, msg) -> None:
            if msg.data == 'deploying' and self.phase in ('locked', 'fault'):
                self._restart(f'phase {self.phase} -> deploying')
            self.phase = msg.data
            if msg.data != 'deploying' and self.commanding and not self.done:
                self.done = True
                self.pub.publish(Float64(data=0.0))
                delays = sorted(self._delays)
                spread = (f'{1e3 * delays[0]:.1f}..{1e3 * delays[-1]:.1f} ms' if delays
                          else 'not measured')
                self.get_logger().info(f'phase {msg.data} (last state t = '
                                       f'{self._last_stamp or 0.0:.6f} s): deployment over, '
                                       f'commanding 0 N; command delay {spread} (last 15)')

        def _on_state(self, msg) -> None:
            t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            if self._last_stamp is not None and t < self._last_stamp - 1e-9:
                # sim time went back: the simulation restarted (its plan and its time base
                # are no longer this run's; a stale plan latched hard at 100x the energy)
                self._restart(f'sim time went back from {self._last_stamp:.6f} s to '
                              f'{t:.6f} s')
            if self.done or self.phase != 'deploying':
                if self.done:               # (sim time going back then means a new run)
                    self._last_stamp = t
                return
            self._unanswered = None             # (a state came: the command was taken)
            now = time.monotonic()
            if self._last_wall is not None and self.commanding and now - self._last_wall > 0.05:
                self.get_logger().warn(
                    f'no joint_states for {1e3 * (now - self._last_wall):.0f} ms (wall) up to '
                    f't = {t:.3f} s: the command was held meanwhile', throttle_duration_sec=1.0)
            self._last_wall = now
            if self._last_stamp is not None and t > self._last_stamp:
                # the publication period: the smallest spacing seen (states may be skipped)
                self._period = min(self._period or math.inf, t - self._last_stamp)
            self._last_stamp = t
            state = drive_state(msg)
            self._node_ribs, effort = state['ribs'], state['sleeve_force']
            if effort != self._last_effort and self._period:
                self._measure_delay(t, effort)
            self._last_effort = effort
            if self.law.t_start is None:
                if self.commanding and effort != 0.0 and self._period:
                    # the first state carrying our push: it acted from one period before
                    self.law.start(t - self._period)
                    self.get_logger().info(f'first push acting from t = '
                                           f'{self.law.t_start:.6f} s')
                elif not self.commanding and not (self._ribs_match(t, state['ribs'])
                                                  and self._at_rest(t, state)):
                    self.done = True        # idle until a new run
                    return
                else:
                    self.commanding = True
                    self._send(t, self.law.cfg.max_force)
                    return
            self._check_commands_applied(t, effort)
            self._send(t, self.law.force(t, state['alpha1'], state['alpha1_rate'], self.lead()))

        def _ribs_match(self, t: float, ribs: int) -> bool:
            """
            Tell whether the node runs the ribs the plan is for; else log why not.

            Given ribs (>= 2), the plan is that umbrella's, each rib its own values: another
            number of ribs is another umbrella.  Not given, it is one rib's, which N identical
            ribs each follow.
            """
            if self.planned_ribs < 2 or ribs == self.planned_ribs:
                return True
            self.get_logger().error(
                f'the node runs {ribs} rib{"s" if ribs > 1 else ""} (its joint_states at '
                f't = {t:.6f} s) and the plan is for the umbrella of '
                f'ribs:={self.planned_ribs}: give both nodes the same ribs and rib values (one '
                'params file); not commanding this run')
            return False

        def _at_rest(self, t: float, state: dict) -> bool:
            """
            Tell whether the frame is folded and at rest, where the plan starts.

            Else log why not (the node's v0, or another command moved it) and stay idle
            for this run: pushing a frame already deploying faster than the plan only makes
            its lock harder.
            """
            law = self.law
            rate, angle = state['alpha1_rate'], state['alpha1']
            if abs(rate) <= REST_FRACTION * law.cruise and \
                    abs(angle - law.alpha0) <= REST_FRACTION * law.span:
                return True
            self.get_logger().error(
                f'the frame is not folded at rest at t = {t:.6f} s (alpha1 = {angle:.6g} rad, '
                f"alpha1' = {rate:.6g} rad/s; the plan starts at alpha0 = {law.alpha0:.6g} rad "
                f'at rest and cruises at {law.cruise:.4g} rad/s): give umbrella_node v0:=0.0 '
                '(and no other sleeve_force command); not commanding this run (a ~/reset '
                'starts a new one)')
            return False

        def _check_commands_applied(self, t: float, effort: float) -> None:
            """
            Warn when the node applies none of our recent commands, or others command it.

            The node echoes the force it applies in its joint state (the sleeve's effort): a
            value none of our commands of the last round trip had (the latest measured delay
            plus three periods: a free-running node under load took commands 0.2 s late
            where the median was one period; an older spike no longer widens it, or a
            refused braking command went unnoticed), three states running, means it refuses
            them
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
                        f'{n} publishers on {self.pub.topic_name}: the node applies '
                        'whichever command came last, so another node commanding the sleeve '
                        'fights this one; stop it', throttle_duration_sec=5.0)
            period = self._period or 0.0
            window = (self._delays[-1] if self._delays else period) + 3 * period
            ours = {self._echo(f) for ts, f in self._sent if ts >= t - window - 1e-9}
            self._not_ours = 0 if effort in ours else self._not_ours + 1
            if self._not_ours >= 3:
                rib = ' a rib' if self._node_ribs > 1 else ''
                self.get_logger().warn(
                    f'the node applies {effort / self._node_ribs:.6g} N{rib} at t = {t:.6f} s, '
                    f'none of our commands of the last {window:g} s (latest '
                    f'{self._sent[-1][1]:.6g} N{rib}): it refuses them (its sleeve_force_min / '
                    'sleeve_force_limit; see its log) or another node commands it',
                    throttle_duration_sec=2.0)

        def _send(self, t: float, force: float) -> None:
            self._sent.append((t, float(force)))
            self._unanswered = (float(force), time.monotonic())
            self.pub.publish(Float64(data=float(force)))

        def _resend_unanswered(self) -> None:
            """Send the last command once more if no state followed it in RESEND_S."""
            last = self._unanswered
            if last is None or self.done or time.monotonic() - last[1] < RESEND_S:
                return
            self._unanswered = None             # (once: a paused node is not flooded)
            self.pub.publish(Float64(data=last[0]))

        def _measure_delay(self, t: float, effort: float) -> None:
            """
            Measure the delay of the command behind a new applied force.

            The state at t shows it acting since t - period: the command that set it is the
            first of the latest run of that value we sent.
            """
            sent = list(self._sent)
            for i in range(len(sent) - 1, -1, -1):
                if self._echo(sent[i][1]) == effort and \
                        (i == 0 or self._echo(sent[i - 1][1]) != effort):
                    delay = (t - self._period) - sent[i][0]
                    if delay >= -1e-9:
                        self._delays.append(delay)
                    return

        def _echo(self, force: float) -> float:
            """Return the sleeve's effort the node echoes for our command (N F of N ribs)."""
            return force * self._node_ribs

        def lead(self) -> float:
            """How long after a state its command acts, on average over its hold."""
            period = self._period or 0.0
            delay = statistics.median(self._delays) if self._delays else period
            return delay + 0.5 * period

    return DeployControllerNode


class StartupError(RuntimeError):
    pass


def main(argv: list[str] | None = None) -> int:
    # SIGINT/SIGTERM only ask for a stop (stop_signals.py), as in umbrella_node.  With rclpy's
    # own handlers a signal shut the context down from the signal handler while the executor
    # could be building its next wait set: rclpy.spin then raised RCLError ("failed to
    # initialize wait set: the given context is not valid") and the process exited 1.
    stop_signals.install()
    argv = list(sys.argv if argv is None else argv)
    if any(a in ('-h', '--help') for a in argv[1:argv.index('--ros-args')
                                               if '--ros-args' in argv else len(argv)]):
        stop_signals.print_for_reader(lambda: print(usage()))   # | head: no traceback
        return 0
    if stop_signals.received:           # during the imports: nothing started yet
        return 0
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException
    from rclpy.executors import SingleThreadedExecutor

    def fail(text: str) -> int:
        print(f'deploy_controller: error: {text}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2

    try:
        files = init_ros(argv)
    except ValueError as exc:
        return fail(str(exc))
    try:
        node = _make_node_class()(tuple(files), param_rules_in(argv))
    except StartupError as exc:
        return fail(str(exc))
    except InvalidParameterTypeException as exc:    # ROS's own (-p use_sim_time:=abc)
        return fail(wrong_type_text(None, exc))
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
    lines = ['usage: deploy_controller [--help] [--ros-args -p name:=value ... '
             '-r __ns:=/NAMESPACE]', '',
             'Closed-loop deployment: joint_states -> sleeve_force (see msg_docs/'
             'deploy_controller.md).', '', 'controller parameters (read-only):']
    lines += parameter_help(CONTROLLER_PARAMETERS.values())
    lines.append("model parameters: the same names and values as umbrella_node's "
                 '(l1, alpha0, ...)')
    lines += umbrella_parameter_help()
    lines.append("  given ribs >= 2, the plan is the whole umbrella's (each rib its own "
                 "inertia, lengths, tip mass, hinge friction); not given, one rib's")
    return '\n'.join(lines)
