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
``SimulatedAntenna``: an ``umbrella_node`` under test plus a probe subscribed to its topics.

See the package's docstring (umbrella_sim.testing) for the rules every wait and summary
follows.
"""
from __future__ import annotations

import math
import numbers
import os
import re
from typing import Iterable
import weakref

from .processes import (_brief, DOMAIN_ID, NodeProcess, poll, Probe, processes_text,
                        python_value)
from .summary import peak_stress, RunSummary, summarize_run, SUMMARY_AFTER_LOCK
from ..ros.messages import PHASES, tip_deflection_figures


# ------------------------------------------------------------------ antenna
RESET_LINE = 'reset: simulation restarted'


LOCKED_RE = r'locked at t = ([0-9.]+) s'


class SimulatedAntenna:
    """
    An ``umbrella_node`` under test plus a probe subscribed to its topics.

    ``parameters``: node parameters by name (``{"v0": 0.0, "publish_rate": 200.0}``);
    ``namespace``: run the node under ``/namespace``; ``record_path``: record to that bag
    directory (see :func:`summary_from_recording`), else the node does not record;
    ``probe``: share one :class:`Probe` between several antennas (default: one of its own,
    closed with the antenna).  The constructor returns once the node has started and its
    first joint state arrived (its phase, with ``start_paused``: the node then holds t = 0
    until :meth:`resume`).
    """

    _count = 0          # probe node names stay unique within a process
    probe: Probe | None = None      # (set by the constructor)
    node: NodeProcess | None = None     # (set by the constructor)
    _live: dict = {}    # (domain, namespace) -> the NodeProcess of the last antenna there

    def __init__(self, parameters: dict | None = None, namespace: str = '',
                 record_path: str | None = None, domain_id: int | None = None,
                 probe: Probe | None = None, startup_timeout: float = 30.0):
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PointStamped
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64, Float64MultiArray, String

        from ..ros import messages as ros_io

        self.parameters = dict(parameters or {})
        if record_path is not None:
            # the node runs in a temporary directory of its own (NodeProcess): a relative
            # path means the test's working directory, where the test will look for it
            record_path = os.path.abspath(os.path.expanduser(str(record_path)))
            self.parameters['record_path'] = record_path
        else:                                  # recording is optional: off unless asked for
            self.parameters.setdefault('record', False)
        self.record_path = record_path
        self.namespace = namespace.strip('/')
        domain = (probe.domain_id if probe is not None
                  else DOMAIN_ID if domain_id is None else domain_id)
        self._key = (domain, self.namespace)
        other = SimulatedAntenna._live.get(self._key)
        if other is not None and other.running:
            raise ValueError(f"an antenna already runs in namespace '/{self.namespace}' on ROS "
                             f'domain {domain}: their topics would be one; give each antenna '
                             'its own namespace (namespace=...)')
        prefix = f'/{self.namespace}/' if self.namespace else '/'
        # relative names resolve under the namespace; absolute ones (/diagnostics) do not
        self.topics = {key: t.name if t.name.startswith('/') else prefix + t.name
                       for key, t in ros_io.TOPICS.items()}
        self.topics['sleeve_force'] = prefix + ros_io.COMMAND.name
        for key, suffix in ros_io.COMMAND_ECHO_SUFFIXES.items():   # sleeve_force/applied ...
            self.topics[f'sleeve_force_{key}'] = prefix + ros_io.COMMAND.name + suffix
        self._diag = ros_io.diagnostic_name(prefix + 'umbrella_node')   # its status name
        self._own_probe = probe is None
        SimulatedAntenna._count += 1
        self.probe = probe or Probe(f'antenna_probe_{SimulatedAntenna._count}',
                                    domain_id=domain_id)
        self.domain_id = self.probe.domain_id
        for key, msg_type in (('joint_states', JointState), ('tip_deflection', PointStamped),
                              ('peak_stress', Float64MultiArray),
                              ('diagnostics', DiagnosticArray)):
            self.probe.subscribe(self.topics[key], msg_type, ros_io.TOPICS[key].qos)
        self.probe.subscribe(self.topics['deployment_phase'], String, ros_io.LATCHED)
        if self.ribs > 1:          # the umbrella of N ribs: its per-rib topics and energy
            from ..ros.ribs_messages import RIB_TOPICS

            for key, t in {**RIB_TOPICS, 'energy': ros_io.TOPICS['energy']}.items():
                self.topics[key] = prefix + t.name
                self.probe.subscribe(self.topics[key], Float64MultiArray, t.qos)
            if self.parameters.get('base', 'fixed') != 'fixed':     # a moving base's bus
                from ..ros.ribs_messages import BUS_TOPIC

                self.topics['bus_state'] = prefix + BUS_TOPIC.name
                self.probe.subscribe(self.topics['bus_state'], BUS_TOPIC.type, BUS_TOPIC.qos)
        for key in ros_io.COMMAND_ECHO_SUFFIXES:
            self.probe.subscribe(self.topics[f'sleeve_force_{key}'], Float64,
                                 ros_io.COMMAND_ECHO_QOS)
        self._float64 = Float64
        self._command_pub = None
        self._runs = 0          # resets so far: waits and figures are of the current run
        self._marks: dict[str, int] = {}    # messages per key received before the last reset
        self._pending: dict = {}            # parameters set that apply on the next reset
        self.node = NodeProcess(parameters=self.parameters, namespace=self.namespace or None,
                                domain_id=self.domain_id)
        SimulatedAntenna._live[self._key] = self.node
        # a forgotten close(): the node and the probe still go, at the latest at exit
        self._finalizer = weakref.finalize(self, _close_antenna, self.node,
                                           self.probe if self._own_probe else None, self._key)
        try:
            self.physics_step = float(self.node.wait_for_log(
                r'physics step ([0-9.eE+-]+) s', timeout=startup_timeout).group(1))
            # (a node started paused published its t = 0 state before this probe matched:
            # the latched phase arrives late, a joint state would not)
            first = 'deployment_phase' if self.parameters.get('start_paused') else 'joint_states'
            # (a run that faulted before this probe matched publishes no more states: its
            # latched 'fault' phase says so, and the antenna is there to look at it)
            poll(lambda: self.probe.messages(self.topics[first]) or 'fault' in self.phases()
                 or not self.node.running,
                 startup_timeout,
                 lambda: f'no message on {self.topics[first]} within '
                         f"{startup_timeout} s of the node's start (node "
                         f"{'running' if self.node.running else 'exited'}); node output:\n"
                         f'{self.node.output()[-2000:]}')
            if not self.probe.messages(self.topics[first]) and 'fault' not in self.phases():
                raise AssertionError(f'the node exited (code {self.node.proc.returncode}) '
                                     f'before its first message on {self.topics[first]}; '
                                     f'node output:\n{self.node.output()[-2000:]}')
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------ commands
    def publish_force(self, force: float, timeout: float = 20.0, check: bool = True) -> None:
        """
        Publish one sleeve_force command (once the node's subscription and it matched).

        A force the node would refuse (solver.command_force: NaN, below sleeve_force_min,
        above what the link carries) raises ValueError here, with the node's reason;
        check=False sends it anyway (a test of the node's refusal).  A force that is no
        real number (a string, a bool) raises TypeError, check or not: '5' is no newton.
        """
        if isinstance(force, bool) or not isinstance(force, numbers.Real):
            raise TypeError(f'publish_force: force={force!r} is not a number (N)')
        if check:
            from ..core.forcing import command_force
            command_force(force, self._model_params())
        self._command_publisher(timeout).publish(self._float64(data=float(force)))

    def _model_params(self):
        """Return this antenna's model (UmbrellaParams; of ribs >= 2 UmbrellaRibsParams)."""
        from ..core.umbrella3d.params3d import node_model
        return node_model(self.parameters)

    def _command_publisher(self, timeout: float):
        """Return the sleeve_force publisher, made and matched with the node's subscription."""
        if self._command_pub is None:
            from ..ros import messages as ros_io
            from ..ros.commands import COMMANDER_LINE

            pattern = re.escape(f"{COMMANDER_LINE} matched on {self.topics['sleeve_force']} (")
            matched = len(re.findall(pattern, self.node.output()))
            self._command_pub = self.probe.publisher(self.topics['sleeve_force'], self._float64,
                                                     ros_io.COMMAND.qos)
            self.probe.wait_for_subscribers(self._command_pub, timeout=timeout)
            # this side matches the node's subscription first; the node's side matches this
            # publisher a few ms later, and a command sent in between would reach the node
            # only with the publisher's next heartbeat (3 s): its log says when it has
            self.node.wait_for_log(pattern, timeout=timeout, count=matched + 1)
        return self._command_pub

    def play_force_profile(self, profile: Iterable[tuple[float, float]],
                           timeout: float = 30.0) -> None:
        """
        Publish each (t, F) of a profile when the node's sim time reaches start + t.

        The start is sim_time() once the command publisher has matched the node (joint_states
        stamps; the run's first state is waited for); returns after the last command.
        Commands act from the next publication after they arrive, so each lands on the
        publication grid a little after its t; a profile exact in sim time is
        ``umbrella_sim simulate --force-profile`` (offline, the same physics).

        The whole profile is checked before its first command goes, by the offline
        profile's rule (forcing.check_profile_row: times finite, >= 0 and increasing, each
        force one the node accepts): ValueError naming the row, and nothing is sent.
        """
        rows = self._checked_profile(profile)
        self.wait_for('joint_states', lambda m: True, timeout, 'a first joint state')
        self._command_publisher(timeout)    # matched first: its ~0.4 s not inside the profile
        t0 = self.sim_time()
        for t_rel, force in rows:
            self.wait_for_sim_time(t0 + t_rel, timeout=timeout)
            self.publish_force(force)

    def _checked_profile(self, profile) -> list[tuple[float, float]]:
        """Return a (t, F) profile as floats, or ValueError naming its first bad row."""
        from ..core.forcing import checked_profile

        profile = list(profile)
        if not profile:
            raise ValueError('force profile: no (t, F) rows')
        return checked_profile(profile, self._model_params(),
                               lambda i: f'force profile row {i} {profile[i]!r}')

    def set_parameters(self, timeout: float = 20.0, **values) -> None:
        """
        Set node parameters at run time (SetParameters, as ``ros2 param set`` does).

        ``antenna.set_parameters(v0=-0.5, sleeve_force_min=-5.0)``: one request, each value
        checked and set on its own (AssertionError naming those refused, with the node's
        reasons; the others are set).  Model parameters apply on the next :meth:`reset`, as
        on the node, and from then on this antenna's figures and force checks
        (:meth:`publish_force`) use them; the node's own (``real_time_factor``,
        ``marker_magnification``...) apply at once.
        """
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        from ..core.registry import REGISTRY, RESET

        values, messages = {n: python_value(v) for n, v in values.items()}, []
        for name, value in values.items():
            try:
                messages.append(Parameter(name, value=value).to_parameter_msg())
            except TypeError:
                raise ValueError(f'parameter {name}={value!r}: not a ROS parameter value (a '
                                 'bool, int, float, str or a list of one of them)') from None
        request = SetParameters.Request(parameters=messages)
        results = self.probe.call(SetParameters, self._service('set_parameters'), request,
                                  timeout).results
        for (name, value), r in zip(values.items(), results):
            if r.successful:
                spec = REGISTRY.get(name)
                (self._pending if spec is not None and spec.applies == RESET
                 else self.parameters)[name] = value
        refused = [f'{name}: {r.reason}' for name, r in zip(values, results) if not r.successful]
        if refused:
            raise AssertionError(f"parameters refused: {'; '.join(refused)}")

    def pause(self, paused: bool = True) -> None:
        """Pause (or resume) the simulation: ``~/pause``; sim time holds while paused."""
        from std_srvs.srv import SetBool
        r = self.probe.call(SetBool, self._service('pause'), SetBool.Request(data=paused))
        if not r.success:
            raise AssertionError(f'~/pause {paused}: refused: {r.message}')

    def resume(self) -> None:
        """Resume a paused run (also the start of one made with ``start_paused``)."""
        self.pause(False)

    def reset(self, timeout: float = 20.0) -> None:
        """
        Restart the run at t = 0 (``~/reset``, with the parameters set since the start).

        Returns once the node has restarted (its log, the new run's "deploying" phase and
        its t = 0 joint state); from then on every wait, message list and figure (phases,
        sim_time, messages, applied_forces, lock_time, summary) is of the new run only, which
        begins with its t = 0 state (published at the reset, paused or not).  AssertionError
        with the node's reason if it refuses.
        """
        from std_srvs.srv import Trigger
        resets = self.node.output().count(RESET_LINE)
        topic = self.topics['deployment_phase']

        def runs_begun():
            return [m.data for m in self.probe.messages(topic)].count('deploying')
        begun = runs_begun()
        marks = {key: len(self._received(key)) for key, topic in self.topics.items()
                 if topic in self.probe.received}
        r = self.probe.call(Trigger, self._service('reset'), Trigger.Request(), timeout)
        if not r.success:
            raise AssertionError(f'~/reset refused: {r.message}')
        self._runs += 1
        self._marks = marks
        self.parameters.update(self._pending)     # the model parameters set apply now
        self._pending = {}
        poll(lambda: self.node.output().count(RESET_LINE) > resets, timeout,
             lambda: f"no '{RESET_LINE}' in the node's log within {timeout} s")
        poll(lambda: runs_begun() > begun, timeout,
             lambda: f"no new 'deploying' on {topic} within {timeout} s of ~/reset")
        poll(lambda: self.messages('joint_states'), timeout,
             lambda: f"no t = 0 state on {self.topics['joint_states']} within {timeout} s of "
                     '~/reset')

    def _service(self, name: str) -> str:
        return (f'/{self.namespace}' if self.namespace else '') + f'/umbrella_node/{name}'

    # --------------------------------------------------------------- waits
    def sim_time(self) -> float | None:
        """Stamp of the latest joint state of this run received (s); None before the first."""
        if self.probe is not None and not self._runs:   # (the first run: the latest, at once)
            latest = self.probe.last(self.topics['joint_states'])
            return None if latest is None else _stamp(latest[1])
        states = self.messages('joint_states')
        return _stamp(states[-1]) if states else None

    def _sim_time_text(self) -> str:
        t, d = self.sim_time(), self.diagnostics()
        if t is None:
            return 'no joint state yet'
        waits = d.get('waiting_for_command') == 'True' and float(d['sim_time_s']) >= t - 1e-6
        return f'latest stamp {t:.6f} s' + (': the node waits for a sleeve_force command '
                                            '(lockstep: one a joint state)' if waits else '')

    def phases(self) -> list[str]:
        """Return the deployment phases of this run, in order ("deploying" first)."""
        return [m.data for _, m in self._timed_run('deployment_phase')]

    def wait_for_phase(self, phase: str, timeout: float = 20.0) -> None:
        """Wait for this run's ``phase``; a run that faulted fails it at once, saying why."""
        if phase not in PHASES:
            raise ValueError(f"phase {phase!r}: must be one of {', '.join(PHASES)}")
        poll(lambda: phase in self.phases() or 'fault' in self.phases(), timeout,
             lambda: f'deployment_phase never became {phase!r} within {timeout} s on '
                     f"{self.topics['deployment_phase']} (saw {self.phases() or 'nothing'}; "
                     f'{self._sim_time_text()}; {processes_text(self.node)})')
        if phase not in self.phases():
            why = re.findall(r'simulation fault: .*', self._run_output())
            raise AssertionError(
                f"deployment_phase became 'fault', not {phase!r}, on "
                f"{self.topics['deployment_phase']} (saw {self.phases()}; "
                f"{self._sim_time_text()}): {why[-1] if why else 'see the node log'}")

    def wait_for_sim_time(self, t: float, timeout: float = 20.0) -> None:
        def reached():
            now = self.sim_time()
            return now is not None and now >= t

        topic = self.topics['joint_states']

        def failure():
            return (f'sim time never reached {t:.6f} s within {timeout} s on {topic} '
                    f'({self._sim_time_text()}; {processes_text(self.node)})')
        if self.probe is None:
            poll(reached, timeout, failure)
        else:       # woken by each state that comes
            self.probe.wait_until(reached, topic, timeout, failure)

    def wait_for(self, key: str, predicate, timeout: float = 20.0, what: str = 'the condition'):
        """Return this run's first message on a node topic (``"joint_states"``...) that fits."""
        topic = self._received_topic(key)

        def failure():
            msgs = self.messages(key)
            last = f'; last: {_brief(msgs[-1])}' if msgs else ''
            return (f'no message on {topic} satisfying {what} within {timeout} s '
                    f'(got {len(msgs)}{last}; {processes_text(self.node)})')
        return poll(lambda: [m for m in self.messages(key) if predicate(m)][:1], timeout,
                    failure)[0]

    def messages(self, key: str) -> list:
        """Return this run's messages on a node topic (after ``reset()``, the new run's)."""
        return [m for _, m in self._timed_run(key)]

    def _received(self, key: str) -> list:
        """Return [(arrival, message)] received on a key's topic, this node's only."""
        timed = self.probe.timed(self._received_topic(key))
        if key == 'diagnostics':            # /diagnostics is every node's: this node's only
            timed = [(a, m) for a, m in timed if m.status and m.status[0].name == self._diag]
        return timed

    def _timed_run(self, key: str) -> list:
        """Return [(arrival, message)] of this run on a topic the antenna receives."""
        timed = self._received(key)
        if key == 'deployment_phase':       # each run's phases start with "deploying"
            starts = [i for i, (_, m) in enumerate(timed) if m.data == 'deploying']
            return timed[starts[-1]:] if starts and self._runs else timed
        if not self._runs:
            return timed
        if key != 'diagnostics' and hasattr(timed[-1][1] if timed else None, 'header'):
            i = self._run_index(timed, self._marks.get(key, 0))
            return [] if i is None else timed[i:]
        # unstamped, or diagnostics (1 Hz: its first stamp of a new run need not fall below
        # the last of the old one): what arrived since the run's first joint state
        states = self._received('joint_states')
        i = self._run_index(states, self._marks.get('joint_states', 0))
        return [] if i is None else [(a, m) for a, m in timed if a >= states[i][0]]

    def _run_index(self, timed: list, mark: int) -> int | None:
        """
        Return where this run begins in [(arrival, stamped message)] (None: not yet).

        After a reset: the last message since the reset call (``mark`` messages came
        before it) that restarts sim time: its t = 0 state, or a stamp below the one before
        it.  The last: what the previous run still had in flight comes first, and may
        restart sim time itself (a paused start's t = 0 state that arrives late).  (Before
        any reset a run is every message: _timed_run.)
        """
        for i in range(len(timed) - 1, mark - 1, -1):
            t = _stamp(timed[i][1])
            if t == 0.0 or (i > 0 and t < _stamp(timed[i - 1][1])):
                return i
        return None

    def _received_topic(self, key: str) -> str:
        """Return the topic of a key the antenna receives (else ValueError: which it does)."""
        received = [k for k, name in self.topics.items() if name in self.probe.received]
        if key not in received:
            what = ('receives' if key not in self.topics
                    else 'does not subscribe to it; it receives')
            raise ValueError(f"topic key {key!r}: the antenna {what} {', '.join(received)} "
                             f'(subscribe to others with antenna.probe.subscribe'
                             f'(antenna.topics[key], type, qos))')
        return self.topics[key]

    # --------------------------------------------------------- the ribs
    @property
    def ribs(self) -> int:
        """Return the number of ribs the node runs (its ribs parameter; 1: the planar model)."""
        return int(self.parameters.get('ribs', 1))

    def rib_states(self) -> list[dict]:
        """
        Return this run's joint states of an umbrella of N ribs, by the Sample's names.

        One dict per joint_states message: time (s), then per rib (lists, rib 0 first)
        alpha1, link_angle, alpha2 and their rates, and the sleeve's position, velocity and
        force (ribs_messages.rib_joint_figures).  ValueError for an antenna of ribs 1.
        """
        from ..ros.ribs_messages import rib_joint_figures

        self._need_ribs()
        return [{'time': _stamp(m), **rib_joint_figures(m)}
                for m in self.messages('joint_states')]

    def rib_arrays(self, key: str) -> list[list[dict]]:
        """
        Return this run's rib_tip_deflection or rib_peak_stress messages, {field: value} a rib.

        Fields as the layout labels them (msg_docs/topic_ribs.md): axial_m, in_plane_m,
        out_of_plane_m; axial_Pa ... von_mises_Pa, von_mises_body, von_mises_x_m,
        von_mises_ratio.
        """
        from ..ros.ribs_messages import rib_array_figures

        self._need_ribs()
        return [rib_array_figures(m) for m in self.messages(key)]

    def bus_states(self) -> list[dict]:
        """Return this run's bus_state messages of a moving base (ribs_messages.bus_figures)."""
        from ..ros.ribs_messages import bus_figures

        if 'bus_state' not in self.topics:
            raise ValueError("bus_states: no bus: the node's base is fixed (ribs >= 2 and "
                             'base prescribed or free have one)')
        return [bus_figures(m) for m in self.messages('bus_state')]

    def energy_balance(self) -> list[dict]:
        """Return this run's energy messages of the umbrella by field name (J)."""
        from ..ros.ribs_messages import rib_energy_figures

        self._need_ribs()
        return [rib_energy_figures(m) for m in self.messages('energy')]

    def umbrella_figures(self, predicate=lambda figures: True, timeout: float = 20.0) -> dict:
        """
        Return the umbrella's summary figures of the first diagnostics that fits predicate.

        The figures of every physics step so far (ribs_messages.ribs_diagnostics, decoded):
        ribs, rib_deploy_time_s (None: not yet), deployment_lag_s, latest_rib,
        max_out_of_plane_tip_m, energy_balance_residual_J, energy_scale_J, friction_work_J,
        peak_von_mises_Pa, and sim_time_s.  Waits (timeout s) for one that fits.
        """
        import json

        from ..ros.ribs_messages import DIAGNOSTIC_FIGURES

        self._need_ribs()

        def figures(m):
            values = {kv.key: kv.value for kv in m.status[0].values}
            if not set(DIAGNOSTIC_FIGURES) <= set(values):
                return None
            out = {k: json.loads(values[k]) for k in DIAGNOSTIC_FIGURES}
            out['sim_time_s'] = float(values['sim_time_s'])
            return out

        return figures(self.wait_for('diagnostics', lambda m: (
            figures(m) is not None and predicate(figures(m))), timeout,
            'the umbrella figures asked for'))

    def _need_ribs(self) -> None:
        if self.ribs < 2:
            raise ValueError('this antenna runs the planar model (ribs 1): start it with '
                             "parameters {'ribs': N >= 2} for the umbrella's per-rib topics")

    # --------------------------------------------------------- what happened
    def _run_output(self) -> str:
        """Return the node's log since this run began (after the last reset line, if any)."""
        out = self.node.output()
        return out[out.rfind(RESET_LINE):] if self._runs else out

    def applied_forces(self) -> list[tuple[float, float]]:
        """
        [(sim time, F)] every commanded value the node applied in this run.

        Each as the node published it on ``sleeve_force/applied`` (the value, as it starts
        acting), at the instant it acts from: the stamp of the joint state before the first
        one whose effort (F_H over the step that ends at its stamp) it is.  A value is
        listed once that joint state has arrived, one publication after the applied
        message.  Exact (stamps to the nanosecond); the ``sleeve_force`` parameter's value,
        which acts from t = 0 (the node applies it there, where it is not 0), is not a command
        and is not listed.
        """
        values = [m.data for m in self.messages('sleeve_force_applied')]
        states = self.messages('joint_states')
        if values and states and _stamp(states[0]) == 0.0 \
                and states[0].effort[-1] == values[0] * self.ribs:
            values = values[1:]         # (the starting force, applied at t = 0: no command)
        out = []
        # the sleeve_slider's effort (the last joint): F, or N F on the sleeve of N ribs
        for before, after in zip(states, states[1:]):
            if len(out) < len(values) and after.effort[-1] != before.effort[-1]:
                if after.effort[-1] != values[len(out)] * self.ribs:
                    raise AssertionError(
                        f'joint_states effort {after.effort[-1]!r} N at {_stamp(after):.9f} s '
                        f'is not the applied command {values[len(out)]!r} N x {self.ribs} '
                        f'rib(s) (applied: {values})')
                out.append((_stamp(before), values[len(out)]))
        return out

    def lock_time(self) -> float | None:
        m = re.search(LOCKED_RE, self._run_output())
        return float(m.group(1)) if m else None

    def diagnostics(self) -> dict:
        """Return the key/values of the latest diagnostics message ({} before the first)."""
        msgs = self.messages('diagnostics')
        return {kv.key: kv.value for kv in msgs[-1].status[0].values} if msgs else {}

    def summary(self, after_lock: float = SUMMARY_AFTER_LOCK,
                timeout: float = 30.0) -> RunSummary:
        """
        Return the run summary from the topics, stage 2 over ``after_lock`` s after the lock.

        The tip figures are of the tip messages, each exact at its stamp: the amplitude
        is of those samples, so it reads a few per cent low at 100 Hz (RunSummary).  The
        stress figure is a peak-hold over each period.  AssertionError if none of the window's
        messages were received (a probe that subscribed after it).  The stress message has no
        stamp: stage-2 stress samples are those received after the 'locked' phase message
        and before the first tip message past the window, so a publication at either end may
        be left out or taken in; :func:`summary_from_recording` gives the exact figures.
        """
        if self.ribs > 1:
            raise ValueError("summary() reads the planar rib's topics; an umbrella of "
                             f'{self.ribs} ribs has umbrella_figures(), rib_states(), '
                             'rib_arrays() and energy_balance(), and its recording '
                             '(record_path) summary_from_recording(), a RibsRunSummary')
        if after_lock is None or not after_lock > 0:
            raise ValueError(f'after_lock={after_lock!r}: seconds of sim time after the lock '
                             '(> 0); a live run has no end to summarise to (None, the whole '
                             'run, is for summary_from_recording)')
        self.wait_for_phase('locked', timeout)
        lock = poll(self.lock_time, timeout, lambda: "no 'locked at' line in the node's log")
        end = lock + after_lock
        self.wait_for_sim_time(end, timeout)
        # joint_states sets the sim time; the tip and stress streams (one message each per
        # publication) may still be in flight behind it on a busy machine: wait for them too
        tips = poll(lambda: [m for m in self.messages('tip_deflection')
                             if _stamp(m) > end + 1e-9][:1] and
                    self.messages('tip_deflection'), timeout,
                    lambda: f'tip_deflection never reached sim time {lock + after_lock:.6f} s '
                            f'within {timeout} s')
        poll(lambda: len(self.messages('peak_stress')) >= len(tips), timeout,
             lambda: f"peak_stress lags tip_deflection ({len(self.messages('peak_stress'))} "
                     f'vs {len(tips)} messages) after {timeout} s')
        phase_arrival = next(t for t, m in self._timed_run('deployment_phase')
                             if m.data == 'locked')
        tip = [(_stamp(m), tip_deflection_figures(m)['tip_transverse'])
               for m in self.messages('tip_deflection')]
        cut = next(a for a, m in self._timed_run('tip_deflection') if _stamp(m) > end + 1e-9)

        def when(arrival):  # no stamp: before, in or after the window by when it arrived
            return -math.inf if arrival <= phase_arrival else end if arrival < cut else math.inf
        stress = [(when(arrival), peak_stress(m)) for arrival, m in self._timed_run('peak_stress')]
        from ..core.summary import deploy_start_of

        applied = self.applied_forces()
        out = summarize_run(applied, lock, deploy_start_of(self.parameters, applied) == 0.0,
                            tip, stress, after_lock, self.parameters.get('model'))
        window = f'({lock:.6f}, {end:.6f}] s of sim time'
        if out.stage2_samples == 0:
            first = min((t for t, _ in tip), default=math.inf)
            why = (f"its first tip message is at {first:.6f} s: this antenna's probe "
                   'subscribed after the window' if first > end else
                   'no publication falls in it: after_lock is shorter than a publication '
                   'period')
            raise AssertionError(f'no stage-2 tip samples in {window}: {why}; take a summary '
                                 'of a window it saw, or summary_from_recording')
        if not any(w == end for w, _ in stress):
            raise AssertionError(
                f"no peak_stress message of {window} received between the 'locked' phase "
                'message and the first tip message past the window (messages on different '
                'topics have no mutual order): take a longer after_lock, or '
                'summary_from_recording')
        return out

    # ------------------------------------------------------------- lifetime
    def stop(self, timeout: float = 10.0) -> int:
        """
        SIGTERM the node (it finalises its recording), wait; the exit code.

        The antenna's command publisher goes too: a controller started next to another
        antenna in the same namespace would otherwise count it as a second commander.
        """
        if self._command_pub is not None:
            self.probe.node.destroy_publisher(self._command_pub)
            self._command_pub = None
        return self.node.stop(timeout=timeout)

    def close(self) -> None:
        self._finalizer()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _close_antenna(node: NodeProcess, probe: Probe | None, key: tuple) -> None:
    try:
        node.close()
    finally:
        if SimulatedAntenna._live.get(key) is node:
            del SimulatedAntenna._live[key]
        if probe is not None:
            probe.close()


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
