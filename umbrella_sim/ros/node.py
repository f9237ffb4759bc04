"""
umbrella_node: the ROS 2 face of the simulator (a thin adapter around UmbrellaSimulator).

Threads, chosen deliberately:
  * the physics thread steps the DAE and publishes; it is paced against time.monotonic()
    (not a ROS timer: this node is the /clock source, and a timer on sim time would wait on
    itself).  Sim time is anchored to the wall time of the last (re)start, so it does not
    accumulate drift;
  * a two-thread executor serves the sleeve_force subscription (its own callback group)
    and, independently, the ~/reset and ~/pause services and parameter sets.  The
    compiled step is a ctypes call, which releases the GIL, so commands are taken while
    physics runs.  A command is handed
    over under a lock and applied at the next step boundary; every applied value is logged
    with its sim time, which is the exact force history for an offline re-run.
Each message is serialized once: the same bytes go to the publisher and to the recorder.
Markers go out at their own display rate (marker_rate).
With ``lockstep`` the physics thread waits, while deploying, for a command answering each
joint_states before it steps on (the co-simulation handshake of SITL simulators), so a
closed loop does not depend on how the operating system schedules the controller.
Everything published and every command received (accepted, refused, applied) is recorded to
MCAP when ``record_path`` is set (see recording.py), by a writer thread of the recorder's own:
the publishing thread only queues the bytes it published.
"""
from __future__ import annotations

import contextlib
import gc
import math
import os
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticStatus
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_srvs.srv import SetBool, Trigger

from . import messages as ros_io, signals as stop_signals
from .parameters import coerce_parameter, declare_from_registry, parameter_defaults
from .params_file import check_parameter_sources, params_files_in, QOS_OVERRIDES, USE_SIM_TIME
from .publication import PublicationEncoder
from .recording import RunRecording
from .share import package_path
from .. import __version__
from ..bag.cdr import cdr_bytes
from ..bag.provenance import run_metadata
from ..bag.writer import BagRecorder, check_record_path, new_bag_recorder
from ..core.driver import RunDriver
from ..core.engines import SimulationDiverged
from ..core.forcing import command_force
from ..core.params import shortened_step_note, UmbrellaParams
from ..core.registry import (check_known_names, check_node_parameters, CONTROLLER_PARAMETERS,
                             NODE_PARAMETERS, parameter_help, REGISTRY, RESET, SPECS)

SIM_TIME_REASON = ("umbrella_node publishes /clock (the sim time every message carries) and "
                   "paces it by the system clock; a node does not follow the clock it drives "
                   "(use_sim_time stays false here; set it for the other nodes)")
#: overload policy: the physics may fall this far behind wall time x real_time_factor; past
#: it the pacing is re-anchored (the backlog is dropped, not caught up) and the slip reported
MAX_LAG_S = 0.5
#: refused commands recorded per wall second at most (the rest are counted only)
REFUSED_RECORD_RATE = 10
#: pacing waits up to this long are a plain sleep (_sleep_until)
PLAIN_SLEEP_S = 0.005
#: exit codes (also in usage())
EXIT_OK, EXIT_USAGE, EXIT_FAULT, EXIT_RECORDING = 0, 2, 3, 4


class StartupError(RuntimeError):
    pass


class UmbrellaNode(Node):

    def __init__(self, params_files: tuple = (), **kwargs):
        super().__init__("umbrella_node", **kwargs)
        qos_given = self._check_parameter_sources(params_files,
                                                  set(parameter_defaults()))
        if self.get_parameter(USE_SIM_TIME).value:
            # a params file for every node ('/**') may set it: this node drives /clock and
            # paces it by the system clock; following its own /clock would only cost a
            # callback a publication (rclpy's time source), which slowed it several fold
            self.set_parameters([Parameter(USE_SIM_TIME, Parameter.Type.BOOL, False)])
            self.get_logger().info(f"{USE_SIM_TIME}:=true not taken: {SIM_TIME_REASON}")
        try:
            values = declare_from_registry(self, parameter_defaults())
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        try:
            self.model_params = UmbrellaParams.from_mapping(
                {k: v for k, v in values.items() if k in SPECS}).validated()
            self.node_cfg = check_node_parameters(
                {k: v for k, v in values.items() if k in NODE_PARAMETERS})
            if self.node_cfg["record"] and self.node_cfg["record_path"]:   # before any work
                check_record_path(self.node_cfg["record_path"])
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        self.pending_params = self.model_params
        self._sim_lock = threading.RLock()
        self._epoch = 0                     # counts resets; samples of an older epoch are dropped
        self._cmd_lock = threading.Lock()
        # lockstep: armed when the first command (after start or ~/reset) starts acting; then
        # a command since the last joint_states lets the next period start (set by _on_force,
        # cleared when joint_states is published)
        self._lockstep_armed = False
        self._answered = threading.Event()
        self.lockstep_waits = 0               # periods that waited for their command
        self._lockstep_waiting_since = 0.0    # monotonic start of the current wait, 0 = none
        self.accepted_commands = 0
        self.refused_commands = 0
        self.fault: str | None = None
        self.paused = bool(self.node_cfg["start_paused"])     # ~/pause false starts it
        self.finished = Future()
        self._stop = threading.Event()
        self._wake = threading.Event()
        self.recording: RunRecording | None = None
        self.recording_error: str | None = None
        self.refused_not_recorded = 0
        self._refused_window = (0.0, 0)       # (wall start, recorded in this 1 s window)
        self.slip = 0.0                       # wall seconds dropped by re-anchoring (overload)
        self.re_anchors = 0
        self._service_waiting = threading.Event()
        self._peers_warned = ""
        self._warned_at: dict[str, float] = {}

        # QoS as documented, or as qos_overrides.<topic>.publisher.<policy> parameters set
        # (history, depth, reliability, durability: the ROS 2 convention; read-only)
        try:
            # (own copies: topics share ros_io's profiles)
            self.pub = {key: self.create_publisher(
                t.type, t.name, ros_io.own_qos(t.qos),
                qos_overriding_options=QoSOverridingOptions.with_default_policies())
                for key, t in ros_io.TOPICS.items()}
            # commands and services in their own callback groups, served by a 2-thread
            # executor: a slow ~/reset never delays a command and a command flood never
            # delays ~/pause
            self.command_sub = self.create_subscription(
                ros_io.COMMAND.type, ros_io.COMMAND.name, self._on_force,
                ros_io.own_qos(ros_io.COMMAND.qos),
                callback_group=MutuallyExclusiveCallbackGroup(),
                qos_overriding_options=QoSOverridingOptions.with_default_policies())
        except Exception as exc:  # rclpy's errors name the parameter
            files = f" (params files: {', '.join(params_files)})" if params_files else ""
            raise StartupError(f"qos_overrides: {' '.join(str(exc).split())}{files}") from None
        self._check_qos_overrides(qos_given)
        self._topic_name = {key: pub.topic_name for key, pub in self.pub.items()}
        self.command_topic = self.command_sub.topic_name
        services = MutuallyExclusiveCallbackGroup()
        self.create_service(Trigger, "~/reset", self._on_reset, callback_group=services)
        self.create_service(SetBool, "~/pause", self._on_pause, callback_group=services)
        # rclpy's three stages: convert exact int/double literals, validate, then apply
        self.add_pre_set_parameters_callback(self._coerce_parameters)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._marker_ns = self.get_namespace().strip("/") or "umbrella"
        try:
            self._install_driver(self._make_driver(self.model_params))
        except ValueError as exc:     # a ModelError names the parameters
            raise StartupError(str(exc)) from None
        self._thread = threading.Thread(target=self._physics_loop, name="physics", daemon=True)

    # ------------------------------------------------------------------ config
    def _check_parameter_sources(self, params_files, known: set) -> set:
        """Check the params files and names given for this node (StartupError: which)."""
        try:
            return check_parameter_sources(
                self.get_fully_qualified_name(), params_files,
                list(self._parameter_overrides), known,
                shared=CONTROLLER_PARAMETERS)   # a '/**' file may serve both nodes
        except ValueError as exc:
            raise StartupError(str(exc)) from None

    def _check_qos_overrides(self, given: set) -> None:
        """Refuse a qos_overrides.* name given for this node that none of its topics has."""
        fqn = self.get_fully_qualified_name()
        declared = {QOS_OVERRIDES + n
                    for n in self.get_parameters_by_prefix(QOS_OVERRIDES.rstrip("."))}
        try:
            check_known_names(given, declared, f"qos_overrides for {fqn}")
        except ValueError as exc:
            raise StartupError(str(exc)) from None

    def _make_driver(self, p: UmbrellaParams) -> tuple[RunDriver, PublicationEncoder]:
        """Build the model, its run driver and encoder (ValueError if it cannot be)."""
        cfg = self.node_cfg                 # a publish_rate set applies here
        driver = RunDriver(p, cfg["publish_rate"])
        return driver, PublicationEncoder(driver, cfg["marker_rate"])

    def _install_driver(self, made: tuple[RunDriver, PublicationEncoder]) -> None:
        driver, self.encoder = made
        p = self.model_params = driver.params
        self.driver_rate = driver.publish_rate
        self.driver = driver
        self.sim = self.driver.sim
        with self._cmd_lock:
            self._commanded_force = p.sleeve_force
        self.fault = None
        self._phase = "deploying"
        self.get_logger().info(
            f"umbrella_sim {__version__}: model {p.model}, N = {p.elements_per_segment}, "
            f"v0 = {p.v0:g} m/s, physics step {self.driver.step:.9g} s "
            f"({self.driver.period_steps} per publication at "
            f"{self.driver_rate:g} Hz), kernel {self.driver.backend}")
        note = shortened_step_note(p.physics_time_step, self.driver_rate)
        if note:
            self.get_logger().info(note)

    def _open_recording(self, path: str) -> None:
        def metadata(bag_dir):
            cfg = dict(self.node_cfg, record_path=bag_dir)
            return run_metadata(self.model_params, cfg, self.driver.step, self.sim.model,
                                self.driver.backend,
                                source=f"umbrella_node {self.get_fully_qualified_name()}")
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
            self.command_topic, {key: pub.qos_profile for key, pub in self.pub.items()})
        self.get_logger().info(f"recording to {self.recording.path}")

    def _on_recording_error(self, reason: str) -> None:
        """Report a write error of the recorder (called once)."""
        self.recording_error = reason
        self._log("error", f"recording stopped: {reason}; {self.recording.path} keeps what was "
                           "written before (readable, marked as ended early); the simulation "
                           f"and its topics go on; exit code {EXIT_RECORDING} at the end")

    def _log(self, level: str, text: str) -> None:
        if self.context.ok():
            getattr(self.get_logger(), level)(text)
        else:  # after SIGINT/SIGTERM the context is gone: /rosout cannot take it any more
            print(f"[{level.upper()}] [{self.get_name()}]: {text}", file=sys.stderr, flush=True)

    def close_recording(self) -> None:
        rec = self.recording
        if rec is None:
            return
        had_error = rec.error is not None
        # the events and the summary of one state: not while the physics thread is in a
        # chunk of steps
        held = self._sim_lock.acquire(timeout=60.0)
        try:
            rec.close(self.sim, self.accepted_commands, self.refused_commands,
                      self.driver.summary.figures(), fault=self.fault, extra={
                          "refused_not_recorded": str(self.refused_not_recorded),
                          "segments": str(rec.recorder.segment + 1)})
        finally:
            if held:
                self._sim_lock.release()
        if not had_error and rec.error is None:
            self._log("info", f"recording finalised: {rec.path} "
                              f"({sum(rec.recorder.counts.values())} messages)")

    def _recording_on(self) -> RunRecording | None:
        """Return the recording if it is being written (not off, not stopped by an error)."""
        rec = self.recording
        return rec if rec is not None and rec.error is None else None

    def _publish(self, key: str, msg, t: float) -> None:
        """Publish a message, or the exact CDR bytes of one, and record the same bytes."""
        if not isinstance(msg, bytes):  # (the encoders' bytes are exact and zero-padded)
            msg = cdr_bytes(msg)        # once: the publisher and the recorder share it
        self.pub[key].publish(msg)
        rec = self._recording_on()
        if rec is not None:
            rec.publish(key, msg, t)

    # ---------------------------------------------------------------- callbacks
    def _on_force(self, msg) -> None:
        t = self.sim.time
        try:
            force = command_force(msg.data, self.sim.params)
        except ValueError as exc:
            reason = str(exc)
            self.refused_commands += 1
            now = time.monotonic()
            start, n = self._refused_window
            if now - start >= 1.0:
                start, n = now, 0
            rec = self._recording_on()
            if n < REFUSED_RECORD_RATE:       # a flood of bad commands cannot fill the disk
                if rec is not None:
                    rec.refused(msg, t)
                n += 1
            else:
                self.refused_not_recorded += 1
            self._refused_window = (start, n)
            self._warn_throttled("refused", 1.0, lambda: f"refused sleeve_force command: {reason} "
                                 f"(refused so far: {self.refused_commands})")
        else:
            self.accepted_commands += 1
            rec = self._recording_on()
            if rec is not None:
                rec.command(msg, t)
            with self._cmd_lock:
                self._commanded_force = force
        self._answered.set()              # any command answers the last state (lockstep)

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
            response.message = (f"reset refused: {exc}; the run goes on (set other values "
                                "and call ~/reset again)")
            self.get_logger().error(response.message)
            return response
        with self._locked():
            ended, fault = self.sim, self.fault
            self._install_driver(driver)
            self._epoch += 1
            self._anchor()
            self._lockstep_armed = False      # the next command starts the handshake again
            self._answered.clear()
            rec = self._recording_on()
            if rec is not None:
                meta = run_metadata(self.model_params, self.node_cfg, self.driver.step,
                                    self.sim.model, self.driver.backend, source="~/reset")
                k = rec.start_segment(meta, self.driver, ended, fault)
                self.get_logger().info(f"recording segment {k} (reset; log time offset "
                                       f"{rec.recorder.offset_ns * 1e-9:.9f} s)")
            self._publish_phase("deploying")
            # the new run's t = 0 state, as at start (paused or not): every run, and every
            # recording segment, begins with its initial state
            self._publish_sample(self._sample_messages())
        self._wake.set()
        response.success = True
        response.message = "reset to t = 0"
        self.get_logger().info("reset: simulation restarted at t = 0 s")
        return response

    def _on_pause(self, request, response):
        with self._locked():
            self.paused = bool(request.data)
            self._anchor()
        self._wake.set()
        response.success = True
        response.message = "paused" if self.paused else "running"
        self.get_logger().info(f"{response.message} at t = {self.sim.time:.9f} s")
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
            return SetParametersResult(successful=False, reason=SIM_TIME_REASON)
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
            self.node_cfg = cfg
            if "real_time_factor" in node:
                self._anchor()
        on_reset = sorted(n for n in {**core, **node} if REGISTRY[n].applies == RESET)
        if on_reset:
            self.get_logger().info(f"parameters {', '.join(on_reset)} set; they apply on "
                                   "~/reset")

    # --------------------------------------------------------------- physics
    def start(self) -> None:
        """Open the recording (StartupError if it cannot be) and start the physics thread."""
        if self.node_cfg["record"]:     # not before: a stop during start-up creates nothing
            self._open_recording(self.node_cfg["record_path"])
        self._publish_phase("deploying")
        self._anchor()
        self._thread.start()

    def request_stop(self) -> None:
        """Ask the physics thread to finish its publication and end (signal-safe)."""
        self._stop.set()
        self._wake.set()
        self._answered.set()

    def stop(self) -> None:
        self.request_stop()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    def _anchor(self) -> None:
        self._wall_anchor = time.monotonic()
        self._sim_anchor = self.sim.time

    def _publish_phase(self, phase: str) -> None:
        self._phase = phase
        self._publish("deployment_phase", ros_io.phase_msg(phase), self.sim.time)

    def _sample_messages(self) -> tuple[int, float, dict]:
        """Build the publication's messages under the sim lock, to be published later."""
        cfg = self.node_cfg
        return self._epoch, self.sim.time, self.encoder.messages(
            self.driver.publication(), self._marker_ns, cfg["marker_magnification"],
            cfg["frame_prefix"])

    def _publish_sample(self, sample: tuple[int, float, dict]) -> None:
        epoch, t, msgs = sample
        with self._sim_lock:
            if epoch != self._epoch:          # a reset came in meanwhile: the sample is stale
                return
            if "joint_states" in msgs and self._lockstep_armed:
                self._answered.clear()        # a command from now on answers this state
            for key, msg in msgs.items():
                self._publish(key, msg, t)

    def _waiting_for_command(self) -> bool:
        """Lockstep: no command has answered the last joint_states yet (sim lock held)."""
        return (self.node_cfg["lockstep"] and self._lockstep_armed
                and self.driver.at_publication and self.sim.stage == "deploying"
                and not self._answered.is_set())

    def _take_command(self) -> None:
        """At a publication instant: the latest command acts from this step on (sim lock held)."""
        with self._cmd_lock:
            force = self._commanded_force
        t = self.driver.command(force)
        if t is None:
            return
        # logged and recorded BEFORE the solver sees it: a fault it causes is in the log and
        # --resimulate reproduces it
        note = " (locked: no effect on motion)" if self.sim.stage == "locked" else ""
        self.get_logger().info(f"sleeve force {force:.17g} N applied from t = {t:.9f} s{note}")
        rec = self._recording_on()
        if rec is not None:
            rec.applied(force, t)

    def _advance_chunk(self) -> bool:
        """Step the next chunk (sim lock held); True if the run is at a publication after it."""
        if self.driver.at_publication:
            self._take_command()
        try:
            chunk = self.driver.advance()
        finally:
            for text in self.driver.summary.new_warnings():   # each logged once
                self.get_logger().warning(f"t = {self.sim.time:.6f} s: {text}")
        ev = chunk.lock
        if ev is not None:
            self.get_logger().info(
                f"locked at t = {ev.time:.9f} s (energy {ev.energy_before:.6g} J -> "
                f"{ev.energy_after:.6g} J, {ev.kind} lock)")
            self._publish_phase("locked")
        if chunk.error is not None:
            raise SimulationDiverged(chunk.error)
        return chunk.at_publication

    def _physics_loop(self) -> None:
        # everything allocated so far (modules, model, publishers) lives for the whole run:
        # keep it out of the collector's full passes, which otherwise stall this loop by
        # ~20 ms now and then (measured with bench/bench_node.py)
        gc.freeze()
        log = self.get_logger()
        diag_wall, diag_sim, diag_epoch = time.monotonic(), self.sim.time, self._epoch
        lag = 0.0
        self._max_lag = 0.0
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
                    duration = self.node_cfg["duration"]
                    if waiting:
                        self._lockstep_wait()
                    elif not idle:
                        if self._lockstep_waiting_since:   # the command came: pace from now
                            self._lockstep_waiting_since = 0.0
                            self._anchor()
                        if self.node_cfg["lockstep"] and self._answered.is_set():
                            self._lockstep_armed = True   # the handshake starts (or goes on)
                        try:
                            # a chunk of steps, at most to the next publication: the lock
                            # is given up between chunks, for a service or a stop
                            if self._advance_chunk():
                                sample = self._sample_messages()
                        except SimulationDiverged as exc:
                            # the state stays at the last good step (maybe between
                            # publications): nothing more is published from it
                            self.fault = str(exc)
                            log.error(f"simulation fault: {exc}; " + (
                                f"the run ends (duration {duration:g} s is set; exit code "
                                f"{EXIT_FAULT})" if duration > 0 else "call ~/reset to restart"))
                            self._publish_phase("fault")
                    sim_t, rtf = self.sim.time, self.node_cfg["real_time_factor"]
                    target = (self._wall_anchor + (sim_t - self._sim_anchor) / rtf) if rtf > 0 \
                        else None
                    epoch = self._epoch
                now = time.monotonic()
                if target is not None and sample is not None:
                    lag = now - target
                    self._max_lag = max(self._max_lag, lag)
                    if lag < 0:               # publish the state of sim time t at wall time t
                        self._sleep_until(target)
                    elif lag > MAX_LAG_S:
                        self._re_anchor(epoch, now, sim_t, lag)
                    elif lag > max(0.05, 2.0 / self.driver_rate):
                        self._warn_throttled("behind", 5.0, lambda: (
                            f"physics cannot keep up: {lag * 1e3:.1f} ms behind wall "
                            "time x real_time_factor (see diagnostics)"))
                if sample is not None:
                    self._publish_sample(sample)
                if epoch != diag_epoch:     # a reset: sim time restarted, measure from here
                    diag_wall, diag_sim, diag_epoch = now, sim_t, epoch
                if now - diag_wall >= 1.0:
                    measured = (sim_t - diag_sim) / (now - diag_wall)
                    self._check_namespace_peers()
                    self._publish_diagnostics(sim_t, measured, lag)
                    diag_wall, diag_sim = now, sim_t
                    self._max_lag = 0.0
                if duration > 0 and self.fault is not None:
                    break
                if duration > 0 and sample is not None and sim_t >= duration - 1e-12:
                    log.info(f"duration {duration:g} s reached at t = {sim_t:.9f} s")
                    break
                if waiting:
                    self._answered.wait(0.05)
                elif idle:
                    self._wake.wait(0.05)
                    self._wake.clear()
        except Exception as exc:  # keep the process informative, never silent
            log.error(f"physics thread stopped: {exc!r}")
            self.fault = repr(exc)
        finally:
            if not self.finished.done():
                self.finished.set_result(self.fault is None)

    def _lockstep_wait(self) -> None:
        """
        Take one idle turn of a lockstep wait (sim lock held).

        The pace restarts from the moment the command comes (the anchor follows the wait),
        so waiting for a controller is neither lag nor slip.
        """
        if not self._lockstep_waiting_since:
            self._lockstep_waiting_since = time.monotonic()
            self.lockstep_waits += 1
        waited = time.monotonic() - self._lockstep_waiting_since
        if waited >= 5.0:
            self._warn_throttled("lockstep", 5.0, lambda: (
                f"lockstep: no sleeve_force command for {waited:.0f} s (wall) since the "
                f"joint_states of t = {self.sim.time:.6f} s; the simulation waits for it"))

    def _re_anchor(self, epoch: int, now: float, sim_t: float, lag: float) -> None:
        """
        Re-anchor the pacing (the overload policy).

        Overload policy: more than MAX_LAG_S behind, the pacing restarts from now (the
        backlog is dropped, never caught up in a burst); the sim then runs at the speed the
        machine allows, reported as measured_real_time_factor, and the dropped wall time
        accumulates in slip_s (diagnostics).
        """
        with self._sim_lock:
            if epoch != self._epoch:
                return
            self._wall_anchor, self._sim_anchor = now, sim_t
        self.slip += lag
        self.re_anchors += 1
        self._warn_throttled("re-anchor", 5.0, lambda: (
            f"physics cannot keep real time: {lag * 1e3:.0f} ms behind at t = {sim_t:.3f} s; "
            f"pacing re-anchored (lag bounded by {MAX_LAG_S:g} s; total slip "
            f"{self.slip:.3f} s in {self.re_anchors} re-anchors, see diagnostics)"))

    def _warn_throttled(self, key: str, period: float, text) -> None:
        """
        Log a WARN at most once per period (s) per key.

        A WARN at most once per period (s) per key.  rclpy's own throttle_duration_sec
        inspects the caller's frame on every call (~3.5 ms measured), which throttled the
        command callback to ~130 commands/s during a flood.
        """
        now = time.monotonic()
        if now - self._warned_at.get(key, -math.inf) >= period:
            self._warned_at[key] = now
            self.get_logger().warning(text())

    def _check_namespace_peers(self) -> None:
        """Two simulators in one namespace mix their /clock, commands and resets: warn."""
        try:
            clocks = self.count_publishers(self.pub["clock"].topic_name)
            same = sum(1 for n, ns in self.get_node_names_and_namespaces()
                       if (n, ns) == (self.get_name(), self.get_namespace()))
        except Exception:             # the graph is gone (shutting down)
            return
        self.clock_publishers = clocks
        text = ""
        if same > 1:
            text = (f"{same} nodes named {self.get_fully_qualified_name()}: their topics, "
                    "commands and ~/reset mix; give each its own namespace (-r __ns:=/NAME)")
        elif clocks > 1:
            text = (f"{clocks} publishers on {self.pub['clock'].topic_name}: another simulator "
                    "or a replay in this namespace; sim time will jump")
        if text and text != self._peers_warned:
            self.get_logger().warning(text)
        self._peers_warned = text

    def _sleep_until(self, target: float) -> None:
        """
        Sleep until the wall time target (or a stop).

        No spinning: a spin of the last 0.3 ms cost up to 0.3 core at 1 kHz; the kernel's
        wake-up latency (~0.1 ms) is well inside a publication period.  A wait of up to
        PLAIN_SLEEP_S is a plain sleep: an Event wait costs ~15 us of CPU against ~5 us
        (its lock and condition), and a stop or reset then waits at most that long.
        """
        while not self._stop.is_set():
            remaining = target - time.monotonic()
            if remaining <= 0:
                return
            if remaining <= PLAIN_SLEEP_S:
                time.sleep(remaining)
                return
            self._wake.wait(remaining - PLAIN_SLEEP_S)
            self._wake.clear()

    def _publish_diagnostics(self, sim_t: float, measured: float, lag: float) -> None:
        rtf = self.node_cfg["real_time_factor"]
        if self.fault:
            level, message = DiagnosticStatus.ERROR, f"fault: {self.fault}"
        elif self.recording_error:
            level, message = DiagnosticStatus.ERROR, f"recording stopped: {self.recording_error}"
        elif self._peers_warned:
            level, message = DiagnosticStatus.WARN, self._peers_warned
        elif rtf > 0 and lag > max(0.05, 2.0 / self.driver_rate):
            level, message = (DiagnosticStatus.WARN,
                              f"behind real time: measured {measured:.3f}x of {rtf:g}x")
        elif self.driver.summary.warnings():
            level, message = DiagnosticStatus.WARN, "outside the model's validity: " + "; ".join(
                w.split(":")[0] for w in self.driver.summary.warnings())
        else:
            level, message = DiagnosticStatus.OK, self._phase
        values = {"sim_time_s": f"{sim_t:.6f}", "measured_real_time_factor": f"{measured:.4f}",
                  "requested_real_time_factor": rtf, "lag_s": f"{max(lag, 0.0):.6f}",
                  "max_lag_s": f"{max(self._max_lag, 0.0):.6f}",
                  "phase": self._phase, "paused": self.paused,
                  "accepted_commands": self.accepted_commands,
                  "refused_commands": self.refused_commands, "steps": self.sim.steps,
                  "lockstep": self.node_cfg["lockstep"],
                  "waiting_for_command": bool(self._lockstep_waiting_since),
                  "lockstep_waits": self.lockstep_waits,
                  "physics_step_s": self.sim.h, "slip_s": f"{self.slip:.6f}",
                  "re_anchors": self.re_anchors,
                  "refused_not_recorded": self.refused_not_recorded,
                  "clock_publishers": getattr(self, "clock_publishers", 1),
                  "recording": ("off" if self.recording is None else
                                f"stopped: {self.recording_error}" if self.recording_error
                                else "ok")}
        for i, text in enumerate(self.driver.summary.warnings()):
            values[f"warning_{i}"] = text
        # the status name carries the namespace: every antenna publishes on /diagnostics
        self._publish("diagnostics", ros_io.diagnostics_msg(
            sim_t, ros_io.diagnostic_name(self.get_fully_qualified_name()), level, message,
            values), sim_t)


def usage() -> str:
    lines = ["usage: umbrella_node [--help] [--ros-args -p name:=value ... --params-file FILE",
             "                      -r __ns:=/NAMESPACE]", "",
             "Real-time flexible umbrella-frame deployment simulator (ROS 2 node).", "",
             "model parameters (a runtime set applies on ~/reset):"]
    lines += parameter_help(SPECS.values())
    lines.append("node parameters:")
    lines += parameter_help(NODE_PARAMETERS.values())
    lines += ["", "topics: " + ", ".join(t.name for t in ros_io.TOPICS.values())
              + f"; subscribes {ros_io.COMMAND.name} (std_msgs/Float64, N >= "
              "sleeve_force_min, 0 by default)",
              "services: ~/reset (std_srvs/Trigger), ~/pause (std_srvs/SetBool)",
              "exit: SIGINT/SIGTERM stop the physics, then finalise the recording (during "
              f"start-up: nothing is started); code {EXIT_OK} on a clean stop or when duration "
              f"is reached, {EXIT_USAGE} for "
              "invalid arguments, parameters or params files, "
              f"{EXIT_FAULT} if the simulation ended in a fault, {EXIT_RECORDING} if the "
              "recording stopped on a write error (the run itself went on)",
              f"details: {msg_docs_location()}"]
    return "\n".join(lines)


def msg_docs_location() -> str:
    """Return where the interface docs are here: the source tree's, or the installed ones."""
    found = package_path("msg_docs", "README.md")
    if found:
        return os.path.dirname(found) + os.sep
    return "msg_docs/ of the umbrella_sim sources (the package share directory of a colcon " \
           "install)"


def main(argv: list[str] | None = None) -> int:
    # SIGINT/SIGTERM only ask for a stop (stop_signals.py: the entry points install the
    # handlers before the heavy imports, so a signal during them is noted too, never a
    # KeyboardInterrupt traceback); rclpy's own handlers would shut the context down at once,
    # under the physics thread's feet; ours stop the physics first, then the recording is
    # closed, then rclpy.  A stop during start-up: exit 0, nothing started or left behind.
    stop_signals.install()
    running: list[UmbrellaNode] = []        # the node, once built: a signal asks it to stop

    def on_signal(signum):
        for node in running:
            node.request_stop()

    stop_signals.add_listener(on_signal)
    try:
        return _run(list(sys.argv if argv is None else argv), running)
    finally:
        stop_signals.remove_listener(on_signal)


def _stopped_during_start_up() -> int:
    """Exit quietly after a stop signal that came before the node was running."""
    print(f"umbrella_node: stopped by {stop_signals.name(stop_signals.received[0])} during "
          "start-up; nothing was started", file=sys.stderr)
    rclpy.try_shutdown()
    return EXIT_OK


def _run(argv: list[str], running: list) -> int:
    stop_requested = stop_signals.received      # every stop signal since the process began
    if stop_requested:          # during the imports: before any ROS or simulation work
        return _stopped_during_start_up()
    if any(a in ("-h", "--help") for a in argv[1:argv.index("--ros-args")
                                               if "--ros-args" in argv else len(argv)]):
        print(usage())
        return EXIT_OK

    def fail(text: str) -> int:
        print(f"umbrella_node: error: {text}", file=sys.stderr)
        rclpy.try_shutdown()
        return EXIT_USAGE

    try:                        # rcl's parse errors are tracebacks: check the files first
        files = params_files_in(argv)
    except ValueError as exc:
        return fail(str(exc))
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:    # RCLError, UnknownROSArgsError...: the arguments are wrong
        reason = " ".join(str(exc).split())
        if type(exc).__name__ == "UnknownROSArgsError":
            reason = f"unknown ROS arguments {reason}"
        return fail(f"invalid ROS arguments: {reason} (see --help)")
    if stop_requested:
        return _stopped_during_start_up()
    leftover = rclpy.utilities.remove_ros_args(argv)[1:]
    if leftover:
        return fail(f"unexpected arguments {leftover}; parameters go after --ros-args as "
                    "-p name:=value or --params-file FILE")
    try:
        node = UmbrellaNode(params_files=tuple(files))
    except StartupError as exc:
        return fail(str(exc))
    running.append(node)
    if stop_requested:          # a signal while the model was built: before any output
        node.destroy_node()
        return _stopped_during_start_up()
    try:
        node.start()
    except StartupError as exc:
        node.destroy_node()
        return fail(str(exc))
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    ok = True
    try:
        # the timeout lets a signal's Python handler run while the executor waits
        while not node.finished.done() and not stop_requested:
            executor.spin_once(timeout_sec=0.1)
        node.stop()
        ok = bool(node.finished.result()) if node.finished.done() else node.fault is None
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.stop()
        node.close_recording()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()
    if not ok:
        return EXIT_FAULT
    return EXIT_RECORDING if node.recording_error else EXIT_OK
