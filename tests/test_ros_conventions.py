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
What a ROS 2 user relies on.

Static parameter types, descriptors from the one registry, diagnostics on /diagnostics named
by namespace, /clock QoS, and recording by default.
"""
import os
import re
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from tests.ros_helpers import NodeProcess, parameter_calls, poll, Probe, ros_env
from umbrella_sim.bag.reader import read_log
from umbrella_sim.core.registry import (CONTROLLER_PARAMETERS, NODE_PARAMETERS, REGISTRY, SPECS,
                                        START)
from umbrella_sim.ros import messages as ros_io
from umbrella_sim.ros.parameters import descriptor


@pytest.fixture
def probe():
    p = Probe('conventions_probe')
    yield p
    p.close()


def test_descriptors_come_from_the_registry():
    for name, p in REGISTRY.items():
        d = descriptor(name)
        assert not d.dynamic_typing
        assert d.type == {float: ParameterType.PARAMETER_DOUBLE,
                          int: ParameterType.PARAMETER_INTEGER,
                          str: ParameterType.PARAMETER_STRING,
                          bool: ParameterType.PARAMETER_BOOL}[p.type]
        assert d.read_only == (p.applies == START)
        assert p.unit in d.description
        if p.type is float and p.low is not None and p.high is not None:
            assert (d.floating_point_range[0].from_value,
                    d.floating_point_range[0].to_value) == (p.low, p.high)
    # what started this check: publish_rate changes the physics step, built on reset
    assert '~/reset' in descriptor('publish_rate').additional_constraints
    assert 'at once' in descriptor('marker_magnification').additional_constraints


@pytest.mark.ros
def test_live_node_conventions(probe, tmp_path):
    """
    One namespaced node, started the plain `ros2 run` way (no record_path).

    Integer literals for doubles are taken as doubles and the type never changes, a string
    is refused; diagnostics arrive on the absolute /diagnostics named by namespace; /clock
    reaches a reader with rclpy TimeSource's QoS; the run is recorded into a new
    timestamped bag directory in the working directory.
    """
    probe.subscribe('/diagnostics', DiagnosticArray)
    time_source_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    probe.subscribe('/a1/clock', Clock, time_source_qos)
    with NodeProcess('-r', '__ns:=/a1', '-p', 'v0:=0', '-p', 'real_time_factor:=2',
                     cwd=str(tmp_path)) as node:
        node.wait_for_log('physics step')
        srv = '/a1/umbrella_node'
        set_param, get = parameter_calls(probe, srv)

        # started with -p v0:=0 and real_time_factor:=2 (integers): declared as doubles
        assert get('v0').type == ParameterType.PARAMETER_DOUBLE and get('v0').double_value == 0
        assert get('real_time_factor').type == ParameterType.PARAMETER_DOUBLE
        r = set_param('marker_magnification', ParameterType.PARAMETER_INTEGER, 100)
        assert r.successful, r.reason
        got = get('marker_magnification')
        assert got.type == ParameterType.PARAMETER_DOUBLE and got.double_value == 100.0
        r = set_param('marker_magnification', ParameterType.PARAMETER_STRING, 'big')
        assert not r.successful and 'type' in r.reason.lower()
        assert get('marker_magnification').double_value == 100.0
        r = set_param('elements_per_segment', ParameterType.PARAMETER_DOUBLE, 2.5)
        assert not r.successful
        assert get('elements_per_segment').type == ParameterType.PARAMETER_INTEGER
        r = set_param('record_path', ParameterType.PARAMETER_STRING, '/tmp/elsewhere')
        assert not r.successful and 'read-only' in r.reason
        desc = probe.call(DescribeParameters, f'{srv}/describe_parameters',
                          DescribeParameters.Request(names=['publish_rate'])).descriptors[0]
        assert '~/reset' in desc.additional_constraints and not desc.dynamic_typing

        msg = probe.wait_for('/diagnostics', lambda m: m.status[0].name.startswith('a1/'))
        assert msg.status[0].name == 'a1/umbrella_node: physics'
        # OK while it keeps pace, WARN when a loaded machine holds it back
        assert msg.status[0].level in (DiagnosticStatus.OK, DiagnosticStatus.WARN)
        assert msg.status[0].hardware_id == 'umbrella_sim'
        probe.wait_for_count('/a1/clock', 1)
        assert node.stop() == 0
        assert 'recording finalised' in node.output()
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert bag.name.startswith('umbrella_a1_') and len(bag.name) == len('umbrella_a1_') + 19
    log = read_log(str(bag))
    assert log.count('/a1/joint_states') > 0 and log.count('/diagnostics') > 0


@pytest.mark.ros
def test_qos_overrides_apply_and_are_recorded(probe, tmp_path):
    """
    The ROS 2 convention: qos_overrides.<topic>.publisher.<policy> set the QoS.

    Here /clock made reliable (ClockQoS is best effort), joint_states' depth 7 and the
    command's subscription keep last 20: the publisher offers them, and the recording's
    offered_qos_profiles say so.
    """
    from rcl_interfaces.srv import ListParameters
    from rclpy.qos import DurabilityPolicy

    from umbrella_sim.bag.reader import qos_from_yaml
    bag = tmp_path / 'bag'
    with NodeProcess('-p', 'qos_overrides./clock.publisher.reliability:=reliable',
                     '-p', 'qos_overrides./clock.publisher.durability:=transient_local',
                     '-p', 'qos_overrides./joint_states.publisher.depth:=7',
                     '-p', 'qos_overrides./sleeve_force.subscription.history:=keep_last',
                     '-p', 'qos_overrides./sleeve_force.subscription.depth:=20',
                     '-p', 'v0:=-0.5', '-p', f'record_path:={bag}') as node:
        node.wait_for_log('recording to')

        def clock_publisher():
            return [e for e in probe.node.get_publishers_info_by_topic('/clock')
                    if e.node_name == 'umbrella_node']
        poll(clock_publisher, 20, lambda: "the node's /clock publisher was not discovered")
        assert clock_publisher()[0].qos_profile.reliability == ReliabilityPolicy.RELIABLE
        assert clock_publisher()[0].qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        # the overrides declared are the documented ones: every topic, every policy
        listed = probe.call(ListParameters, '/umbrella_node/list_parameters',
                            ListParameters.Request(prefixes=['qos_overrides'])).result.names
        assert set(listed) == _documented_qos_overrides(), sorted(listed)
        node.wait_for_log('locked at')
        assert node.stop() == 0
    log = read_log(str(bag))
    assert qos_from_yaml(log.channels['/clock'][1]).reliability == ReliabilityPolicy.RELIABLE
    assert qos_from_yaml(log.channels['/joint_states'][1]).depth == 7
    assert qos_from_yaml(log.channels['/tip_deflection'][1]).depth == \
        ros_io.TOPICS['tip_deflection'].qos.depth
    # the command's channel: the subscription's QoS as overridden, not the default keep all
    command = qos_from_yaml(log.channels['/sleeve_force'][1])
    assert (command.history, command.depth) == (HistoryPolicy.KEEP_LAST, 20)


@pytest.mark.ros
def test_recording_can_be_turned_off_and_never_overwrites(tmp_path):
    def run(*args):
        return subprocess.run([sys.executable, '-m', 'umbrella_sim.node', '--ros-args',
                               '-p', 'duration:=0.05', '-p', 'real_time_factor:=0.0', *args],
                              capture_output=True, text=True, env=ros_env(), timeout=120,
                              cwd=str(tmp_path))

    off = run('-p', 'record:=false')
    assert off.returncode == 0, off.stderr
    assert os.listdir(tmp_path) == []
    # two runs in the same second get two directories: NAME and NAME_1
    first, second = run(), run()
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    names = sorted(os.listdir(tmp_path))
    assert len(names) == 2 and all(n.startswith('umbrella_2') for n in names)
    assert len({read_log(str(tmp_path / n)).count('/joint_states') for n in names}) == 1


@pytest.mark.ros
def test_record_path_with_a_tilde_records_under_home(tmp_path):
    """``-p record_path:=~/bags/run``: no shell expands that ``~``; the node does."""
    home, cwd = tmp_path / 'home', tmp_path / 'cwd'
    (home / 'bags').mkdir(parents=True)
    cwd.mkdir()
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.node', '--ros-args',
                        '-p', 'duration:=0.05', '-p', 'real_time_factor:=0.0',
                        '-p', 'record_path:=~/bags/run'], capture_output=True, text=True,
                       env=dict(ros_env(), HOME=str(home)), timeout=120, cwd=str(cwd))
    assert r.returncode == 0, r.stderr
    assert os.listdir(cwd) == []                    # no directory named '~'
    assert read_log(str(home / 'bags' / 'run')).count('/joint_states') > 0
    assert str(home / 'bags' / 'run') in r.stderr    # the log names where it went


@pytest.mark.parametrize('args, words', [
    (['-p', 'v0:=fast'], ['v0', 'double']),
    (['-p', 'elements_per_segment:=2.5'], ['elements_per_segment', 'integer']),
    (['-p', 'record:=maybe'], ['record', 'bool']),
])
@pytest.mark.ros
def test_wrong_parameter_type_at_start_is_refused(args, words):
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.node', '--ros-args', *args],
                       capture_output=True, text=True, env=ros_env(), timeout=60)
    assert r.returncode == 2
    assert all(w in r.stderr for w in words) and 'Traceback' not in r.stderr, r.stderr


def _documented_qos_overrides(namespace: str = '') -> set[str]:
    """Return the qos_overrides.* names msg_docs/node_parameters.md promises a node."""
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
    with open(os.path.join(root, 'msg_docs', 'node_parameters.md'), encoding='utf-8') as fh:
        text = ' '.join(fh.read().split())
    policies = re.search(r"with policies: ((?:`\w+`, )*`\w+`), set a topic's QoS", text)
    assert policies, 'node_parameters.md no longer lists the qos_overrides policies'
    names = re.findall(r'`(\w+)`', policies.group(1))
    topics = [(f'{namespace}/{t.name}' if not t.name.startswith('/') else t.name, 'publisher')
              for t in ros_io.TOPICS.values()]
    topics.append((f'{namespace}/{ros_io.COMMAND.name}', 'subscription'))
    return {f'qos_overrides.{topic}.{side}.{p}' for topic, side in topics for p in names}


def test_the_documented_qos_overrides_are_the_declared_policies():
    """The policies the docs list are the ones the node declares overrides for."""
    declared = {p.name.lower() for p in ros_io.QOS_OVERRIDE_POLICIES}
    assert {n.rpartition('.')[2] for n in _documented_qos_overrides()} == declared
    assert 'durability' in declared     # the docs' example of a late joiner's /clock


@pytest.mark.parametrize('section', ['    rib1.tipmass: 0.1\n', '    rib1:\n      tipmass: 0.1\n',
                                     '    rib.tipmass: [0.0, 0.1, 0.0]\n'])
def test_a_per_rib_typo_in_a_wildcard_section_is_the_nodes_error(tmp_path, section):
    """
    A per-rib name (rib<k>.<name>, rib.<name>) is the umbrella's alone, in a '/**' section too.

    The node reads every section's per-rib values: a typo there was said to be "ignored
    here", then refused by another check; now both umbrella_node's check and the offline
    tools' refuse it at once, naming it with a "did you mean"; a correct one is taken
    silently.
    """
    from umbrella_sim.core.umbrella3d.params3d import names_a_rib
    from umbrella_sim.ros.params_file import check_parameter_sources
    from umbrella_sim.ros.parameters import known_parameter_names
    from umbrella_sim.tools.inputs import params_file_warnings

    path = tmp_path / 'ribs.yaml'
    path.write_text('/**:\n  ros__parameters:\n    ribs: 3\n' + section)
    name = 'rib.tipmass' if section.startswith('    rib.') else 'rib1.tipmass'
    with pytest.raises(ValueError, match=re.escape(f"'{name}' (did you mean")):
        check_parameter_sources('/umbrella_node', [str(path)], [], known_parameter_names(),
                                shared=CONTROLLER_PARAMETERS, own=names_a_rib)
    with pytest.raises(ValueError, match=re.escape(f"'{name}' (did you mean")):
        params_file_warnings(str(path))
    path.write_text(path.read_text().replace('tipmass', 'tip_mass'))
    assert params_file_warnings(str(path)) == []


def test_a_nodes_existing_record_path_names_no_option_it_lacks(tmp_path):
    """umbrella_node has no --overwrite: its record_path error says what to do instead."""
    from umbrella_sim.bag.writer import check_record_path

    with pytest.raises(ValueError, match='not overwriting') as refused:
        check_record_path(str(tmp_path))
    assert '--overwrite' not in str(refused.value)
    assert 'give a new path, or move or remove it' in str(refused.value)


def test_a_wildcard_section_may_hold_other_nodes_parameters(tmp_path):
    """
    A '/**' params file is shared by every node of a launch: a name this node does not know.

    (robot_state_publisher's publish_frequency, another topic's qos_overrides) is a warning
    naming it, with a "did you mean"; in a section naming the node it is an error.
    """
    from umbrella_sim.ros.params_file import (check_parameter_sources,
                                              check_qos_override_sources)
    from umbrella_sim.ros.parameters import parameter_defaults

    known = set(parameter_defaults())
    shared = tmp_path / 'shared.yaml'
    shared.write_text('/**:\n  ros__parameters:\n    publish_frequency: 30.0\n    v0: 0.0\n'
                      '    youngs_modulous: 7.0e10\n    target_time: 1.5\n'
                      '    qos_overrides:\n      /robot_description:\n        publisher:\n'
                      '          depth: 1\n      /clock:\n        publisher:\n'
                      '          depth: 2\n')
    found = check_parameter_sources('/a1/umbrella_node', [str(shared)], [], known,
                                    shared=CONTROLLER_PARAMETERS)
    (warning,) = found.warnings
    assert "'publish_frequency'" in warning and str(shared) in warning
    assert "'youngs_modulous' (did you mean 'youngs_modulus'?)" in warning
    assert 'target_time' not in warning          # the deploy controller's: taken silently
    (qos_warning,) = check_qos_override_sources(
        '/a1/umbrella_node', found, {'qos_overrides./clock.publisher.depth'})
    assert "gives 'qos_overrides./robot_description.publisher.depth' (" in qos_warning
    assert 'not a parameter of /a1/umbrella_node' in qos_warning    # that one only
    for section in ('a1/umbrella_node', '/a1/umbrella_node', '/**/umbrella_node'):
        own = tmp_path / 'own.yaml'
        own.write_text(shared.read_text().replace('/**:', f'{section}:'))
        with pytest.raises(ValueError, match="unknown parameters 'publish_frequency'"):
            check_parameter_sources('/a1/umbrella_node', [str(own)], [], known,
                                    shared=CONTROLLER_PARAMETERS)
        found = check_parameter_sources('/a1/umbrella_node', [str(own)], [],
                                        known | {'publish_frequency', 'youngs_modulous',
                                                 'target_time'})
        with pytest.raises(ValueError, match='robot_description'):
            check_qos_override_sources('/a1/umbrella_node', found,
                                       {'qos_overrides./clock.publisher.depth'})


class _Logger:

    def __init__(self):
        self.lines = []

    def warning(self, text):
        self.lines.append(('WARN', text))

    def info(self, text):
        self.lines.append(('INFO', text))

    def debug(self, text):
        self.lines.append(('DEBUG', text))


def test_throttled_warnings_say_how_many_were_held_back(monkeypatch):
    from umbrella_sim.ros import throttled_log

    now = [100.0]
    monkeypatch.setattr(throttled_log.time, 'monotonic', lambda: now[0])
    log = _Logger()
    warn = throttled_log.ThrottledWarnings(log).warn
    for _ in range(3):
        warn('behind', 60.0, lambda: 'physics cannot keep up')
        now[0] += 10.0
    warn('other', 60.0, lambda: 'another kind')
    now[0] += 40.0
    warn('behind', 60.0, lambda: 'physics cannot keep up')
    assert log.lines == [('WARN', 'physics cannot keep up'), ('WARN', 'another kind'),
                         ('WARN', 'physics cannot keep up (the same said 2 more time(s) in the 70 '
                                  's since it was last logged, not logged)')]


def test_applied_commands_log_at_debug_with_an_info_summary(monkeypatch):
    """A controller's 100 commands a second: one INFO line per period, each at DEBUG."""
    from umbrella_sim.ros import commands

    now = [0.0]
    monkeypatch.setattr(commands.time, 'monotonic', lambda: now[0])
    intake = commands.CommandIntake(lambda: None, lambda: None, None, None)
    intake.logger = log = _Logger()
    for k in range(1001):                 # 10 s of wall time at 100 commands a second
        now[0] = k / 100
        intake.applied(7.4499167113638407 + k, k / 100, locked=False)
    infos = [text for level, text in log.lines if level == 'INFO']
    assert len(infos) == 3 and len(log.lines) == 1001
    assert infos[0] == 'sleeve force 7.44992 N applied from t = 0.000000000 s'
    assert infos[1].startswith('sleeve force 507.45 N applied from t = 5.000000000 s; 499 more')
    assert ('DEBUG', 'sleeve force 8.4499167113638407 N applied from t = 0.010000000 s') \
        in log.lines


@pytest.mark.ros
def test_clock_goes_on_with_the_unchanged_time_while_paused(probe):
    """As Gazebo: a paused simulator's /clock keeps coming, so use_sim_time nodes see it."""
    from umbrella_sim.ros.messages import CLOCK_READER_QOS

    probe.subscribe('/clock', Clock, CLOCK_READER_QOS)
    with NodeProcess('-p', 'start_paused:=true', '-p', 'record:=false') as node:
        probe.wait_for_count('/clock', 5, timeout=30)
        assert node.stop() == 0
    ticks = probe.messages('/clock')
    assert len(ticks) >= 5 and {(m.clock.sec, m.clock.nanosec) for m in ticks} == {(0, 0)}


def test_every_registry_entry_is_a_parameter_of_one_kind():
    kinds = (set(SPECS), set(NODE_PARAMETERS), set(CONTROLLER_PARAMETERS))
    assert set.union(*kinds) == set(REGISTRY)
    assert sum(map(len, kinds)) == len(REGISTRY)       # no name of two kinds


def test_the_interface_table_gives_each_topic_the_qos_it_has():
    """msg_docs/README.md's QoS column against ros_io (it said depth 10 for a keep-all)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy

    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
    with open(os.path.join(root, 'msg_docs', 'README.md'), encoding='utf-8') as fh:
        rows = {cells[1].strip().strip('`'): cells[5] for cells in
                (line.split('|') for line in fh if line.startswith('| `'))}
    topics = {t.name.lstrip('/'): t for t in (*ros_io.TOPICS.values(), ros_io.COMMAND)}
    topics.update({ros_io.COMMAND.name + suffix: ros_io.Topic('', None, ros_io.COMMAND_ECHO_QOS)
                   for suffix in ros_io.COMMAND_ECHO_SUFFIXES.values()})
    for name, topic in topics.items():
        q = topic.qos
        text = rows[name if name != 'diagnostics' else '/diagnostics'].replace('*', '').strip()
        want = ', '.join((
            'reliable' if q.reliability == ReliabilityPolicy.RELIABLE else 'best effort',
            'transient local' if q.durability == DurabilityPolicy.TRANSIENT_LOCAL
            else 'volatile',
            'keep all' if q.history == HistoryPolicy.KEEP_ALL else f'depth {q.depth}'))
        assert text == want, name
