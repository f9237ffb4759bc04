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
umbrella_node: the ROS 2 face of the simulator, a thin adapter around the run driver.

Threads, chosen deliberately:
  * the physics thread steps the run driver (core/driver.py) a chunk at a time, giving up
    the sim lock between chunks, and publishes at each publication instant, paced against
    the wall clock (pacing.py: this node is the /clock source);
  * a two-thread executor serves the sleeve_force subscription (its own callback group)
    and, independently, the ~/reset and ~/pause services and parameter sets.  The compiled
    step is a ctypes call, which releases the GIL, so commands are taken while physics
    runs.  A command is checked, counted and recorded as it comes, a burst drained in
    batches (commands.py); the latest accepted value is held under a lock and acts from the
    next publication instant; every applied value is logged and recorded with its sim time,
    which is the exact force history for an offline re-run.
Each message is serialized once (publication.py): the same bytes go to the publisher and to
the recorder.  With ``lockstep`` the physics thread waits for a command answering each
joint_states (lockstep.py).  Everything published and every command received (accepted,
refused, applied) is recorded to MCAP (recording.py), by a writer thread of the recorder's
own: the publishing thread only queues the bytes it published.
"""
from __future__ import annotations

import contextlib
import gc
import os
import shlex
import sys
import threading
import time

from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.task import Future
from std_srvs.srv import SetBool, Trigger

from . import messages as ros_io
from .bus_tf import BusTransformBroadcaster, NO_TF, tf_message_type
from .commands import CommandIntake
from .lockstep import Lockstep
from .pacing import lag_advice, LAG_WARN_PERIOD, MAX_LAG_S, Pacer, RateWindow
from .parameters import (coerce_parameter, declare_from_registry, declare_umbrella,
                         known_parameter_names, NamedRefusals, parameter_defaults,
                         wrong_type_text)
from .params_file import (check_parameter_sources, check_qos_override_sources,
                          check_qos_override_values, ParameterSources, QOS_OVERRIDES,
                          QoSOverrideValueError, USE_SIM_TIME)
from .publication import PublicationEncoder, run_driver
from .recording import RunRecording
from .ribs_messages import node_topics
from .status import node_status
from .throttled_log import ThrottledWarnings
from .. import __version__
from ..bag.cdr import cdr_bytes
from ..bag.provenance import run_metadata
from ..bag.writer import BagRecorder, check_record_path, new_bag_recorder
from ..core.driver import RunDriver
from ..core.engines import SimulationDiverged
from ..core.params import shortened_step_note, UmbrellaParams
from ..core.registry import (check_node_parameters, CONTROLLER_PARAMETERS, NODE_PARAMETERS,
                             REGISTRY, RESET, SPECS)
from ..core.step_rule import physics_step_of, stage2_step_text
from ..core.umbrella3d.params3d import names_a_rib, umbrella_model

SIM_TIME_REASON = ('umbrella_node publishes /clock (the sim time every message carries) and '
                   'paces it by the system clock; a node does not follow the clock it drives '
                   '(use_sim_time stays false here; set it for the other nodes)')
#: exit codes (also in usage())
EXIT_OK, EXIT_USAGE, EXIT_FAULT, EXIT_RECORDING = 0, 2, 3, 4


class StartupError(RuntimeError):
    pass


class UmbrellaNode(NamedRefusals, Node):

    def __init__(self, params_files: tuple = (), param_rules: dict | None = None, **kwargs):
        try:
            super().__init__('umbrella_node', **kwargs)
        except InvalidParameterTypeException as exc:    # -p use_sim_time:=abc: ROS's own
            raise StartupError(wrong_type_text(self, exc)) from None
        qos_given = self._check_parameter_sources(params_files, param_rules or {})
        if self.get_parameter(USE_SIM_TIME).value:
            # a '/**' params file may set it: this node drives /clock by the system clock;
            # following it would cost a callback a publication (several fold slower)
            self.set_parameters([Parameter(USE_SIM_TIME, Parameter.Type.BOOL, False)])
            self.get_logger().info(f'{USE_SIM_TIME}:=true not taken: {SIM_TIME_REASON}')
        try:
            values = declare_from_registry(self, parameter_defaults())
            self.umbrella = declare_umbrella(self)      # (N ribs, ribs >= 2: fixed at start)
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        self.ribs = self.umbrella.get('ribs', 1)
        try:
            self.model_params = UmbrellaParams.from_mapping(
                {k: v for k, v in values.items() if k in SPECS}).validated()
            # the umbrella's values too, before the record path: every parameter's error first
            umbrella_model(self.model_params, self.umbrella)
            self.node_cfg = check_node_parameters(
                {k: v for k, v in values.items() if k in NODE_PARAMETERS})
            if self.node_cfg['record']:         # before any work ('': the working directory)
                check_record_path(self.node_cfg['record_path'])
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        self.pending_params = self.model_params
        self._sim_lock = threading.RLock()
        self._epoch = 0                     # counts resets; samples of an older epoch are dropped
        self.lockstep = Lockstep()            # the handshake of lockstep:=true
        self._warn_throttled = ThrottledWarnings(self.get_logger()).warn
        self.commands = CommandIntake(lambda: self.sim, self._recording_on, self._warn_throttled,
                                      self.lockstep)
        self.fault: str | None = None
        self.paused = bool(self.node_cfg['start_paused'])     # ~/pause false starts it
        self.finished = Future()
        self._stop = threading.Event()
        self._wake = threading.Event()
        self.pacer = Pacer(self._stop, self._wake)
        self.recording: RunRecording | None = None
        self.recording_error: str | None = None
        self._service_waiting = threading.Event()
        self._peers_warned = ''
        self._measured_rtf: float | None = None     # of the last diagnostics

        # QoS as documented, or as qos_overrides.<topic>.<side>.<policy> set (the ROS 2
        # convention; read-only), each its own copy (topics share ros_io's profiles)
        try:
            topics = node_topics(self.ribs, self.umbrella.get('base', 'fixed'))
            check_qos_override_values(self._parameter_overrides, self.resolve_topic_name(
                ros_io.COMMAND.name), [self.resolve_topic_name(t.name) for t in topics.values()])
            self.pub = {key: self.create_publisher(
                t.type, t.name, ros_io.own_qos(t.qos),
                qos_overriding_options=QoSOverridingOptions(ros_io.QOS_OVERRIDE_POLICIES))
                for key, t in topics.items()}
            # commands and services in their own callback groups, served by 2 threads
            # (executor.py): a slow ~/reset never delays a command, a flood never ~/pause
            self.command_sub = self.create_subscription(
                ros_io.COMMAND.type, ros_io.COMMAND.name, self.commands.on_message,
                ros_io.own_qos(ros_io.COMMAND.qos),
                callback_group=MutuallyExclusiveCallbackGroup(),
                event_callbacks=self.commands.event_callbacks(),
                qos_overriding_options=QoSOverridingOptions(ros_io.QOS_OVERRIDE_POLICIES))
        except Exception as exc:  # rclpy's errors name the parameter
            files = f" (params files: {', '.join(params_files)})" if params_files else ''
            text = (wrong_type_text(self, exc) if isinstance(exc, InvalidParameterTypeException)
                    else str(exc) if isinstance(exc, QoSOverrideValueError)
                    else f"qos_overrides: {' '.join(str(exc).split())}")
            raise StartupError(text + files) from None
        self._check_qos_overrides(qos_given)
        self.bus_tf = None          # a moving bus: world -> umbrella_base on /tf (bus_tf.py)
        if 'bus_state' in self.pub:
            self.bus_tf = BusTransformBroadcaster(self, self.node_cfg['frame_prefix'],
                                                  tf_message_type())
            if not self.bus_tf.available:
                self.get_logger().info(NO_TF)
        self._topic_name = {key: pub.topic_name for key, pub in self.pub.items()}
        self.command_topic = self.command_sub.topic_name
        self.commands.subscription = self.command_sub
        self.commands.connect(self, self.command_topic)
        g, qos = MutuallyExclusiveCallbackGroup(), ros_io.SERVICE_QOS     # (a storm: deep)
        self.create_service(Trigger, '~/reset', self._on_reset, qos_profile=qos, callback_group=g)
        self.create_service(SetBool, '~/pause', self._on_pause, qos_profile=qos, callback_group=g)
        # rclpy's three stages: convert exact int/double literals, validate, then apply
        self.add_pre_set_parameters_callback(self._coerce_parameters)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._marker_ns = self.get_namespace().strip('/') or 'umbrella'
        try:
            self._install_driver(self._make_driver(self.model_params))
        except ValueError as exc:     # a ModelError names the parameters
            raise StartupError(str(exc)) from None
        self._thread = threading.Thread(target=self._physics_loop, name='physics', daemon=True)

    # ------------------------------------------------------------------ config
    def _check_parameter_sources(self, params_files, param_rules: dict) -> ParameterSources:
        """Check the files, names and -p values given (param_rules_in's) (StartupError)."""
        try:
            found = check_parameter_sources(
                self.get_fully_qualified_name(), params_files, self._parameter_overrides,
                known_parameter_names(), rules=param_rules, own=names_a_rib,
                shared=CONTROLLER_PARAMETERS)   # a '/**' file may serve both nodes
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        for text in found.warnings:       # another node's, in a '/**' section
            self.get_logger().warning(text)
        for name, value in found.taken.items():     # (a -p value rcl set aside: the user's)
            self._parameter_overrides[name] = Parameter(name, value=value)
        return found

    def _check_qos_overrides(self, given: ParameterSources) -> None:
        """Refuse a qos_overrides.* name given for this node that none of its topics has."""
        fqn, prefix = self.get_fully_qualified_name(), QOS_OVERRIDES
        declared = {prefix + n for n in self.get_parameters_by_prefix(prefix[:-1])}
        try:        # (a '/**' section's: another node's topics, a warning)
            for text in check_qos_override_sources(fqn, given, declared):
                self.get_logger().warning(text)
        except ValueError as exc:
            raise StartupError(str(exc)) from None

    def _make_driver(self, p: UmbrellaParams) -> tuple[RunDriver, PublicationEncoder]:
        """Build the model, its run driver and encoder (ValueError if it cannot be)."""
        cfg = self.node_cfg                 # a publish_rate set applies here
        return run_driver(p, self.umbrella, cfg['publish_rate'], cfg['marker_rate'])

    def _install_driver(self, made: tuple[RunDriver, PublicationEncoder]) -> None:
        driver, self.encoder = made
        p = self.model_params = driver.params.planar if self.ribs > 1 else driver.params
        self.driver_rate = driver.publish_rate
        self.driver = driver
        self.sim = self.driver.sim
        self.commands.hold(p.sleeve_force)
        self.fault = None
        self._phase = 'deploying'
        self.get_logger().info(
            f'umbrella_sim {__version__}: model {p.model}, {p.elements_per_segment} '
            f'element(s) a segment, {f"{self.ribs} ribs (3D umbrella), " * (self.ribs > 1)}'
            f'v0 = {p.v0:g} m/s, physics step {self.driver.step:.9g} s{stage2_step_text(p)} '
            f'({self.driver.period_steps} per publication at '
            f'{self.driver_rate:g} Hz), kernel {self.driver.backend}')
        note = shortened_step_note(physics_step_of(p), self.driver_rate)
        if note:
            self.get_logger().info(note)

    def _metadata(self, source: str, **cfg) -> dict:
        """Return the run's metadata records (every parameter, the umbrella's too)."""
        return run_metadata(self.model_params, dict(self.node_cfg, **self.umbrella, **cfg),
                            self.driver.step, self.sim.model, self.driver.backend, source)

    def _open_recording(self, path: str) -> None:
        def metadata(bag_dir):
            return self._metadata(f'umbrella_node {self.get_fully_qualified_name()}',
                                  record_path=bag_dir)
        try:
            # compression and file writes on the recorder's own thread, not the publishing one
            if path:
                recorder = BagRecorder(path, metadata(path), on_error=self._on_recording_error,
                                       background=True)
            else:   # as ros2 bag record: a new timestamped directory in the working directory
                recorder = new_bag_recorder(self.get_namespace(), metadata,
                                            on_error=self._on_recording_error, background=True)
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        self.recording = RunRecording(
            recorder, {key: pub.topic_name for key, pub in self.pub.items()},
            self.command_topic, {key: pub.qos_profile for key, pub in self.pub.items()},
            self.command_sub.qos_profile)
        self.get_logger().info(f'recording to {self.recording.path}')

    def _on_recording_error(self, reason: str) -> None:
        """Report a write error of the recorder (called once)."""
        self.recording_error = reason
        self._log('error', f'recording stopped: {reason}; {self.recording.path} keeps what was '
                           'written before (readable, marked as ended early); the simulation '
                           f'and its topics go on; exit code {EXIT_RECORDING} at the end')

    def _log(self, level: str, text: str) -> None:
        if self.context.ok():
            getattr(self.get_logger(), level)(text)
        else:  # after SIGINT/SIGTERM the context is gone: /rosout cannot take it any more
            print(f'[{level.upper()}] [{self.get_name()}]: {text}', file=sys.stderr, flush=True)

    def drain_commands(self) -> None:
        """Take the commands still queued at the stop (ros.commands: none left uncounted)."""
        text = self.commands.drain_at_stop()
        if text:
            self._log('info', text)

    def close_recording(self) -> None:
        rec = self.recording
        if rec is None:
            return
        had_error = rec.error is not None
        # the events and the summary of one state: not while the physics is in a chunk
        held = self._sim_lock.acquire(timeout=60.0)
        try:
            rec.close(self.sim, self.commands.accepted, self.commands.refused,
                      self.driver.summary.figures(), fault=self.fault, extra={
                          **self.commands.counts_record(),
                          'segments': str(rec.recorder.segment + 1)})
        finally:
            if held:
                self._sim_lock.release()
        if not had_error and rec.error is None:
            bag = os.path.dirname(rec.path)
            self._log('info', f'recording finalised: {rec.path} '
                              f'({sum(rec.recorder.counts.values())} messages; its figures: '
                              f'umbrella_compare {shlex.quote(bag)} '
                              f'--out {shlex.quote(bag + "_compare")})')

    def _recording_on(self) -> RunRecording | None:
        """Return the recording if it is being written (not off, not stopped by an error)."""
        rec = self.recording
        return rec if rec is not None and rec.error is None else None

    def _publish(self, msgs: dict, t: float) -> None:
        """Publish messages (key -> message or its exact CDR), then record the same bytes."""
        # (the encoders' bytes are exact and zero-padded; a message: serialized once)
        msgs = {key: m if isinstance(m, bytes) else cdr_bytes(m) for key, m in msgs.items()}
        for key, msg in msgs.items():
            self.pub[key].publish(msg)
        rec = self._recording_on()
        if rec is not None:             # (a publication's messages in one go, in order)
            rec.publish_all(msgs, t)

    # ---------------------------------------------------------------- callbacks
    @contextlib.contextmanager
    def _locked(self):
        """
        Take the sim lock for a service.

        The sim lock for a service: the physics thread steps aside at its next
        publication boundary (Python locks are not fair: without this a busy physics loop
        could re-take the lock for seconds).
        """
        self._service_waiting.set()
        with self._sim_lock:
            self._service_waiting.clear()
            yield

    def _on_reset(self, request, response):
        # the new model first, outside the lock: parameters that cannot make one (the pair
        # rule, a singular mass matrix) refuse the reset, and the run goes on as it was
        try:
            driver = self._make_driver(self.pending_params.validated())
        except ValueError as exc:
            response.success = False
            response.message = (f'reset refused: {exc}; the run goes on (set other values '
                                'and call ~/reset again)')
            self.get_logger().error(response.message)
            return response
        with self._locked():
            ended, fault = self.driver, self.fault
            self._install_driver(driver)
            self._epoch += 1
            self._anchor()
            self.lockstep.restart()
            rec = self._recording_on()
            if rec is not None:
                k = rec.start_segment(self._metadata('~/reset'), self.driver, ended.sim,
                                      ended.summary.figures(), fault)
                self.get_logger().info(f'recording segment {k} (reset; log time offset '
                                       f'{rec.recorder.offset_ns * 1e-9:.9f} s)')
            self._publish_phase('deploying')
            # the new run's t = 0 state, as at start (paused or not): every run, and every
            # recording segment, begins with its initial state; then its starting force, if
            # news, on the applied history (before the solver's first step)
            self._publish_sample(self._sample_messages())
            self.commands.start_run(self.model_params.sleeve_force)
        self._wake.set()
        response.success = True
        response.message = 'reset to t = 0'
        self.get_logger().info('reset: simulation restarted at t = 0 s')
        return response

    def _on_pause(self, request, response):
        with self._locked():
            self.paused = bool(request.data)
            self._anchor()
        self._wake.set()
        response.success = True
        response.message = 'paused' if self.paused else 'running'
        self.get_logger().info(f'{response.message} at t = {self.sim.time:.9f} s')
        return response

    @staticmethod
    def _coerce_parameters(params: list) -> list:
        return [coerce_parameter(p) for p in params]

    def _parameter_candidate(self, params) -> tuple[dict, dict, UmbrellaParams, dict]:
        core = {p.name: p.value for p in params if p.name in SPECS}
        node = {p.name: p.value for p in params if p.name in NODE_PARAMETERS}
        # one parameter at a time (a SetParameters request): the pair rule waits for ~/reset
        candidate = (self.pending_params.replace(**core).validated(pairs=False) if core
                     else self.pending_params)
        cfg = dict(self.node_cfg)
        cfg.update(check_node_parameters(node))
        return core, node, candidate, cfg

    def _validate_parameters(self, params) -> SetParametersResult:
        """Accept or refuse a set (on-set callback); changes nothing."""
        if any(p.name == USE_SIM_TIME and p.value is True for p in params):
            return SetParametersResult(successful=False,
                                       reason=f'parameter {USE_SIM_TIME}=true: {SIM_TIME_REASON}')
        try:
            self._parameter_candidate(params)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params) -> None:
        """Apply a set that was accepted (post-set callback)."""
        core, node, candidate, cfg = self._parameter_candidate(params)
        self.pending_params = candidate
        with self._locked():
            changed = cfg['marker_magnification'] != self.node_cfg['marker_magnification']
            self.node_cfg = cfg
            if 'real_time_factor' in node:
                self._anchor()
            # the markers built from now on (after this sim time) carry the new value: the
            # recording says so, for the tools that undo it (umbrella_compare's shapes)
            since = self.sim.time
        if changed and self.recording is not None:
            self.recording.marker_magnification(cfg['marker_magnification'], since)
        on_reset = sorted(n for n in {**core, **node} if REGISTRY[n].applies == RESET)
        if on_reset:
            self.get_logger().info(f"parameters {', '.join(on_reset)} set; they apply on "
                                   '~/reset')

    # --------------------------------------------------------------- physics
    def start(self) -> None:
        """Open the recording (StartupError if it cannot be) and start the physics thread."""
        if self.node_cfg['record']:     # not before: a stop during start-up creates nothing
            self._open_recording(self.node_cfg['record_path'])
        self._publish_phase('deploying')
        self.commands.start_run(self.model_params.sleeve_force)
        self._anchor()
        self._thread.start()

    def request_stop(self) -> None:
        """Ask the physics thread to finish its publication and end (signal-safe)."""
        self._stop.set()
        self._wake.set()
        self.lockstep.answered.set()       # (a lockstep wait ends too)

    def stop(self) -> None:
        self.request_stop()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def _anchor(self) -> None:
        self.pacer.anchor(self.sim.time)

    def _publish_phase(self, phase: str) -> None:
        self._phase = phase
        self._publish({'deployment_phase': ros_io.phase_msg(phase)}, self.sim.time)

    def _sample_messages(self) -> tuple:
        """Build the publication's messages under the sim lock, to be published later."""
        cfg, s = self.node_cfg, self.driver.publication()
        return self._epoch, self.sim.time, self.encoder.messages(
            s, self._marker_ns, cfg['marker_magnification'],
            cfg['frame_prefix']), self.bus_tf.message(s) if self.bus_tf else None

    def _publish_sample(self, sample: tuple) -> None:
        epoch, t, msgs, tf = sample
        with self._sim_lock:
            if epoch != self._epoch:          # a reset came in meanwhile: the sample is stale
                return
            if 'joint_states' in msgs:
                self.lockstep.published()
            self._publish(msgs, t)
            if tf is not None:                # (not recorded: bus_state holds the pose)
                self.bus_tf.publish(tf)

    def _waiting_for_command(self) -> bool:
        """Lockstep: no command has answered the last joint_states yet (sim lock held)."""
        return self.lockstep.waiting(self.node_cfg['lockstep'], self.driver.at_publication,
                                     self.sim.stage == 'deploying')

    def _take_command(self) -> None:
        """At a publication instant: the latest command acts from this step on (sim lock held)."""
        force = self.commands.force
        t = self.driver.command(force)
        if t is None:
            return
        # logged, recorded and published BEFORE the solver sees it: a fault it causes is in
        # the log and --resimulate reproduces it
        self.commands.applied(force, t, self.sim.stage == 'locked')

    def _advance_chunk(self) -> bool:
        """Step the next chunk (sim lock held); True if the run is at a publication after it."""
        if self.driver.at_publication:
            self._take_command()
        try:
            chunk = self.driver.advance()
            ev = chunk.lock
            if ev is not None:          # (before the warnings the lock's chunk brings)
                self.get_logger().info(
                    f'locked at t = {ev.time:.9f} s (energy {ev.energy_before:.6g} J -> '
                    f'{ev.energy_after:.6g} J, {ev.kind} lock)')
                self._publish_phase('locked')
        finally:
            for text in self.driver.summary.new_warnings():   # each logged once
                self.get_logger().warning(f't = {self.sim.time:.6f} s: {text}')
        if chunk.error is not None:
            raise SimulationDiverged(chunk.error)
        return chunk.at_publication

    def _physics_loop(self) -> None:
        # everything allocated so far (modules, model, publishers) lives for the whole run:
        # keep it out of the collector's full passes, which otherwise stall this loop by
        # ~20 ms now and then (measured with bench/bench_node.py)
        gc.freeze()
        log = self.get_logger()
        rate, diag_epoch = RateWindow(time.monotonic(), self.sim.time, self.paused), self._epoch
        lag = 0.0
        try:
            with self._sim_lock:
                self._publish_sample(self._sample_messages())
            while not self._stop.is_set():
                if self._service_waiting.is_set():
                    time.sleep(0.0005)        # a service waits for the lock: let it in
                sample = None
                with self._sim_lock:
                    waiting = not self.paused and self._waiting_for_command()
                    idle = self.paused or self.fault is not None or waiting
                    duration = self.node_cfg['duration']
                    if waiting:
                        self._lockstep_wait()
                    elif not idle:
                        on, at = self.node_cfg['lockstep'], self.driver.at_publication
                        if self.lockstep.go(on, at):        # (the wait counts: pacing.py)
                            self.pacer.after_wait(self.sim.time, 1.0 / self.driver_rate,
                                                  self.node_cfg['real_time_factor'])
                        try:
                            # a chunk of steps, at most to the next publication: the lock
                            # is given up between chunks, for a service or a stop
                            if self._advance_chunk():
                                sample = self._sample_messages()
                        except SimulationDiverged as exc:
                            # the state stays at the last good step (maybe between
                            # publications): nothing more is published from it
                            self.fault = str(exc)
                            log.error(f'simulation fault: {exc}; ' + (
                                f'the run ends (duration {duration:g} s is set; exit code '
                                f'{EXIT_FAULT})' if duration > 0 else 'call ~/reset to restart'))
                            self._publish_phase('fault')
                    sim_t = self.sim.time
                    target = self.pacer.target(sim_t, self.node_cfg['real_time_factor'])
                    epoch = self._epoch
                now = time.monotonic()
                if target is not None and sample is not None:
                    lag = self.pacer.lag(target, now)
                    if lag < 0:               # publish the state of sim time t at wall time t
                        self.pacer.sleep_until(target)
                    elif lag > MAX_LAG_S:
                        self._re_anchor(epoch, now, sim_t, lag)
                    elif lag > max(0.05, 2.0 / self.driver_rate):
                        self._warn_throttled('behind', LAG_WARN_PERIOD, lambda: (
                            f'physics cannot keep up: {lag * 1e3:.1f} ms behind wall time x '
                            f'real_time_factor; {self._lag_advice()}'))
                elif target is not None and not idle:
                    # between publications (a long period: many chunks), how far behind the
                    # physics is now, so that diagnostics say so before the period ends
                    lag = max(lag, self.pacer.lag(target, now))
                if idle:
                    lag = 0.0                 # paused or waiting: not behind (anchored anew)
                if sample is not None:
                    self._publish_sample(sample)
                rate.pause(now, self.paused)      # (a pause's wall time is not measured)
                if epoch != diag_epoch:     # a reset: sim time restarted, measure from here
                    rate.restart(now, sim_t)
                    diag_epoch = epoch
                if rate.due(now):
                    measured = self._measured_rtf = rate.factor(now, sim_t)
                    self._check_namespace_peers()
                    self._publish_diagnostics(sim_t, measured, lag)
                    rate.restart(now, sim_t)
                    self.pacer.max_lag = 0.0
                if duration > 0 and self.fault is not None:
                    break
                if duration > 0 and sample is not None and sim_t >= duration - 1e-12:
                    log.info(f'duration {duration:g} s reached at t = {sim_t:.9f} s')
                    if now > rate.wall:     # (the run's last status: a short run's only one)
                        self._publish_diagnostics(sim_t, rate.factor(now, sim_t), lag)
                    break
                if waiting:
                    self.lockstep.answered.wait(0.05)
                elif idle:
                    if self.paused and self.fault is None:   # as Gazebo: the time, unchanged
                        self.pub['clock'].publish(ros_io.clock_msg(sim_t))   # (not recorded)
                    self._wake.wait(0.05)
                    self._wake.clear()
        except Exception as exc:  # keep the process informative, never silent
            log.error(f'physics thread stopped: {exc!r}')
            self.fault = repr(exc)
        finally:
            if not self.finished.done():
                self.finished.set_result(self.fault is None)

    def _lockstep_wait(self) -> None:
        """Take one idle turn of a lockstep wait (sim lock held; no lag: Pacer.after_wait)."""
        waited = self.lockstep.wait_turn()
        if waited >= 5.0:
            self._warn_throttled('lockstep', 5.0, lambda: (
                f'lockstep: no sleeve_force command for {waited:.0f} s (wall) since the '
                f'joint_states of t = {self.sim.time:.6f} s; the simulation waits for it'))

    def _re_anchor(self, epoch: int, now: float, sim_t: float, lag: float) -> None:
        """Re-anchor the pacing (pacing.py's overload policy), unless a reset came meanwhile."""
        with self._sim_lock:
            if epoch != self._epoch:
                return
            self.pacer.re_anchor(now, sim_t, lag)
        self._warn_throttled('re-anchor', LAG_WARN_PERIOD, lambda: (
            f'physics cannot keep real time: {lag * 1e3:.0f} ms behind at t = {sim_t:.3f} s; '
            f'pacing re-anchored (lag bounded by {MAX_LAG_S:g} s; total slip '
            f'{self.pacer.slip:.3f} s in {self.pacer.re_anchors} re-anchors); '
            f'{self._lag_advice()}'))

    def _lag_advice(self) -> str:
        return lag_advice(self.node_cfg['real_time_factor'], self._measured_rtf)

    def _check_namespace_peers(self) -> None:
        """Two simulators in one namespace mix their /clock, commands and resets: warn."""
        try:
            clocks = self.count_publishers(self.pub['clock'].topic_name)
            same = sum(1 for n, ns in self.get_node_names_and_namespaces()
                       if (n, ns) == (self.get_name(), self.get_namespace()))
        except Exception:             # the graph is gone (shutting down)
            return
        self.clock_publishers = clocks
        text = ''
        if same > 1:
            text = (f'{same} nodes named {self.get_fully_qualified_name()}: their topics, '
                    'commands and ~/reset mix; give each its own namespace (-r __ns:=/NAME)')
        elif clocks > 1:
            text = (f"{clocks} publishers on {self.pub['clock'].topic_name}: another simulator "
                    'or a replay in this namespace; sim time will jump')
        if text and text != self._peers_warned:
            self.get_logger().warning(text)
        self._peers_warned = text

    def _publish_diagnostics(self, sim_t: float, measured: float, lag: float) -> None:
        level, message, values = node_status(self, sim_t, measured, lag)
        # the status name carries the namespace: every antenna publishes on /diagnostics
        self._publish({'diagnostics': ros_io.diagnostics_msg(
            sim_t, ros_io.diagnostic_name(self.get_fully_qualified_name()), level, message,
            values)}, sim_t)
