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
deploy_controller: the law against the physics core offline, then over DDS in real time.

Every figure is compared with the constant sleeve force that deploys in the same time on the
same model, found or run in the same test (no stored numbers).
"""
import contextlib
import signal
import subprocess
import sys
import threading
import time

import pytest
from rcl_interfaces.msg import ParameterType

from tests.ros_helpers import parameter_calls
from umbrella_sim.core.control import constant_force_for, DeployLaw, simulate_closed_loop
from umbrella_sim.core.driver import simulate
from umbrella_sim.core.params import ControllerConfig, physics_step, UmbrellaParams
from umbrella_sim.core.step_rule import physics_step_of
from umbrella_sim.testing import NodeProcess, poll, ros_env, summarize_run, summary_from_recording

TARGET = 1.0            # s, deploy time asked of the controller
LIMIT = 8.0             # N, the controller's force limits: [-LIMIT, LIMIT]
RATE = 100.0            # Hz, joint_states rate = the control rate (the node default)
AFTER = 0.5             # s of stage 2 observed (~10 periods of the leaf's vibration)
# a 2 ms physics step (the thesis's; deploy time within 1e-5 of finer steps): at the 50 us
# default the node's 200 compiled steps a publication, sharing the GIL with its executor on a
# loaded 2-core machine, delayed the commands by up to the whole deployment
STEP = 0.002
STATE_INTERVAL = 0.0005  # s, between the joint_states of the stop test's stream
MODEL = UmbrellaParams(v0=0.0, sleeve_force_min=-LIMIT, time_step=STEP)


def command_gap(bag: str, start: float, end: float) -> float:
    """Return the longest sim-time gap between commands the node received in [start, end]."""
    from umbrella_sim.bag.reader import read_log

    log = read_log(bag)
    times = [start] + [t for t, _ in log.decoded(log.find_topic('sleeve_force'))
                       if start < t < end] + [end]
    return max(b - a for a, b in zip(times, times[1:]))


@contextlib.contextmanager
def controller_on(ctl, ros_domain_id: int):
    """Yield (deploy_controller at TARGET and +-LIMIT on ctl, matched; ctl's command topic)."""
    from std_msgs.msg import Float64

    commands = ctl.topics['sleeve_force']
    ctl.probe.subscribe(commands, Float64)
    with NodeProcess(module='umbrella_sim.deploy_controller', domain_id=ros_domain_id,
                     parameters={'target_time': TARGET, 'max_force': LIMIT,
                                 'min_force': -LIMIT}) as controller:
        wait_for_controller(ctl, controller)
        yield controller, commands


def run_controlled(ctl, ros_domain_id: int) -> str:
    """
    Run deploy_controller (TARGET, +-LIMIT) on ctl, a paused lockstep node; return its log.

    To AFTER past the lock and the controller's 'deployment over'; both stopped (code 0).
    """
    with controller_on(ctl, ros_domain_id) as (controller, commands):
        start_answered(ctl, commands)
        ctl.wait_for_phase('locked', timeout=60)
        ctl.wait_for_sim_time(ctl.lock_time() + AFTER, timeout=30)
        controller.wait_for_log('deployment over')
        log = controller.output()
        assert controller.stop() == 0, log
    assert ctl.stop() == 0
    return log


def wait_for_controller(antenna, controller, publishers: int = 1,
                        timeout: float = 60.0) -> None:
    """
    Wait until the controller is up and in the antenna's graph.

    Its subscriptions to the antenna's topics, and ``publishers`` on sleeve_force in all.
    """
    controller.wait_for_log('waiting for joint_states', timeout=timeout)
    graph = antenna.probe.node
    topics = [antenna.topics[name] for name in ('joint_states', 'deployment_phase')]
    poll(lambda: all(graph.count_subscribers(t) >= 2 for t in topics)
         and graph.count_publishers(antenna.topics['sleeve_force']) >= publishers, timeout,
         lambda: f'the controller never appeared on {topics} and sleeve_force')


def start_answered(antenna, commands: str) -> None:
    """
    Reset the paused antenna until the controller answers its t = 0 state, then resume.

    The run then goes in lockstep from its first period: no state is skipped (a free-running
    start let the controller's depth-1 subscription skip the first state showing its push,
    and its first command act a varying fraction of a period late on a loaded machine).
    The first time, the graph shows the controller ~1 s before DDS delivers it data.
    """
    for _ in range(20):
        sent = len(antenna.probe.messages(commands))
        antenna.reset()
        try:
            poll(lambda: len(antenna.probe.messages(commands)) > sent, 3.0, str)
            break
        except AssertionError:
            continue
    assert antenna.probe.messages(commands)[-1].data == LIMIT   # its full first push
    antenna.resume()


def run_summary(result, first_push: float):
    """
    Return the run summary of an offline RunResult (the same figures as over DDS).

    Its tip samples at the publication instants only, as a recording has them (the
    amplitude of every step's samples is the larger by a crest between publications); the
    stress, a peak-hold, from every step.
    """
    published = [s for s in result.samples if abs(s.time * RATE - round(s.time * RATE)) < 1e-6]
    return summarize_run([(first_push, 1.0)], result.lock.time, False,
                         [(s.time, s.tip_transverse) for s in published],
                         [(s.time, max(s.peak_stress_leaf, s.peak_stress_link))
                          for s in result.samples], AFTER)


@pytest.fixture(scope='module')
def constant():
    """Return the constant force deploying in TARGET on the node's grid, and its summary."""
    params = MODEL.replace(time_step=physics_step(physics_step_of(MODEL), RATE))
    force = constant_force_for(params, TARGET)
    run = simulate(params.replace(sleeve_force=force), 3 * TARGET, stop_after_lock=AFTER)
    return force, run_summary(run, 0.0)


@pytest.mark.parametrize('delay', [1, 3])
def test_law_on_the_physics_core_locks_five_times_softer_in_the_target_time(constant, delay):
    """Commands act `delay` publications after the state they answer (the DDS round trip)."""
    _, ref = constant
    cfg = ControllerConfig(target_time=TARGET, max_force=LIMIT, min_force=-LIMIT)
    run, first = simulate_closed_loop(MODEL, cfg, RATE, delay, after_lock=AFTER)
    s = run_summary(run, first)
    assert ref.deploy_time == pytest.approx(TARGET, rel=1e-4)
    assert abs(s.deploy_time - ref.deploy_time) <= 0.05 * ref.deploy_time
    assert s.stage2_peak_stress * 5 <= ref.stage2_peak_stress
    assert s.stage2_tip_amplitude * 5 <= ref.stage2_tip_amplitude
    forces = run.column('sleeve_force')
    assert forces.min() >= -LIMIT and forces.max() <= LIMIT
    assert forces.min() < 0.0                                  # it did hold the sleeve back


def test_push_only_cannot_lock_five_times_softer(constant):
    """
    Push-only: softer than the constant force, but not 5x.

    With F_H >= 0 the kinetic energy never drops before the lock, so the softest lock in a
    given time is a coast (rigid estimate ~3x below the constant force).
    """
    _, ref = constant
    cfg = ControllerConfig(target_time=TARGET, max_force=LIMIT, min_force=0.0)
    run, first = simulate_closed_loop(MODEL, cfg, RATE, 1, after_lock=AFTER)
    s = run_summary(run, first)
    assert run.column('sleeve_force').min() >= 0.0
    assert abs(s.deploy_time - ref.deploy_time) <= 0.05 * ref.deploy_time
    ratio = ref.stage2_tip_amplitude / s.stage2_tip_amplitude
    assert 1.5 < ratio < 5.0


def test_infeasible_target_is_refused_naming_the_parameter():
    with pytest.raises(ValueError, match='target_time=0.1: too short for max_force=8'):
        DeployLaw(MODEL, ControllerConfig(target_time=0.1, max_force=LIMIT))
    with pytest.raises(ValueError, match='min_force=1'):
        DeployLaw(MODEL, ControllerConfig(min_force=1.0))


#: an umbrella of 3 ribs whose ribs differ: rib 1's leaf and link 3x as dense, a 50 g tip
#: mass on rib 2, a rubbing hinge on rib 0 (1.5 s: the 1 s of the planar frame is beyond
#: LIMIT for it, as its whole plan says)
UNEQUAL = {'ribs': 3, 'v0': 0.0, 'sleeve_force_min': -LIMIT, 'time_step': STEP,
           'rib1.density': 3 * UmbrellaParams().density, 'rib2.tip_mass': 0.05,
           'rib0.hinge_coulomb': 0.05}
UNEQUAL_TARGET = 1.5
#: the plan alone (no feedback) on flexible ribs lands within this of its target time: the
#: rigid plan on the 3 identical ribs' flexible umbrella misses 1 s by 2.4 % (offline, the
#: physics of this file's settings)
PLAN_ALONE_TOLERANCE = 0.03


def plan_alone_lock(params, law, duration: float):
    """Return the lock time of params driven by the law's plan alone (None: no lock)."""
    from umbrella_sim.core.driver import RunDriver

    driver = RunDriver(params, force_profile=law.open_loop_profile(STEP))
    driver.run(duration, stop_after_lock=0.0)
    return driver.sim.lock_event.time if driver.sim.lock_event else None


def test_identical_ribs_plan_as_the_planar_frame():
    """N identical ribs: the whole umbrella's plan is the planar frame's (to round-off)."""
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams

    cfg = ControllerConfig(target_time=TARGET, max_force=LIMIT, min_force=-LIMIT)
    planar = DeployLaw(MODEL, cfg)
    ribs = DeployLaw(UmbrellaRibsParams.of_node({'ribs': 3}, MODEL), cfg)
    assert ribs.span == planar.span and ribs.cruise == pytest.approx(planar.cruise, rel=1e-12)
    # (round-off: the sum of 3 ribs' M; the force's M' is a difference over 1e-6 rad, which
    # magnifies it a million times)
    for name in ('plan_t', 'plan_alpha', 'plan_rate', 'plan_accel', 'plan_force'):
        ours, theirs = getattr(ribs, name), getattr(planar, name)
        scale = abs(theirs).max()
        assert abs(ours - theirs).max() <= 1e-9 * scale, name
    planar.start(0.0)
    ribs.start(0.0)
    state = (0.4, 1.2, -1.5, 0.01)
    assert ribs.force(*state) == pytest.approx(planar.force(*state), rel=1e-9)


@pytest.mark.parametrize('min_force', [-LIMIT, 0.0])
def test_the_plan_alone_deploys_unequal_ribs_in_the_target_time(min_force):
    """
    Planned on the whole umbrella, the force schedule alone deploys unequal ribs on time.

    Each rib's own inertia, tip mass and hinge friction, summed through the sleeve: the
    plan alone (no feedback) locks within PLAN_ALONE_TOLERANCE of the target.  Planned on
    the shared (planar) values, it pushes an umbrella heavier than it plans for: it is late
    (push-only) or, braking as for the lighter frame, stops it short of the lock.  The
    feedback then makes up the difference, planned on the whole umbrella within 1 %.
    """
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams

    params = UmbrellaRibsParams.from_mapping(UNEQUAL)
    cfg = ControllerConfig(target_time=UNEQUAL_TARGET, max_force=LIMIT, min_force=min_force)
    whole = plan_alone_lock(params, DeployLaw(params, cfg), 3 * UNEQUAL_TARGET)
    shared = plan_alone_lock(params, DeployLaw(params.planar, cfg), 3 * UNEQUAL_TARGET)
    assert whole is not None
    miss = abs(whole - UNEQUAL_TARGET)
    assert miss <= PLAN_ALONE_TOLERANCE * UNEQUAL_TARGET, whole
    # the shared-values plan undersizes the force for the heavier umbrella: late, or never
    assert shared is None or shared - UNEQUAL_TARGET > max(
        miss, PLAN_ALONE_TOLERANCE * UNEQUAL_TARGET), shared
    run, first = simulate_closed_loop(params, cfg, RATE, 0, after_lock=0.0)
    assert run.lock.time - first == pytest.approx(UNEQUAL_TARGET, rel=0.01)


@pytest.mark.parametrize('args, culprit', [
    (['-p', 'target_time:=-1.0'], 'target_time'),
    (['-p', 'target_time:=0.05'], 'too short'),
    (['-p', 'max_force:=fast'], 'max_force'),
    (['-p', 'l1:=-1.0'], 'l1'),
    (['-p', 'targt_time:=1.0'], "unknown parameter 'targt_time' (did you mean 'target_time'?)"),
    # the umbrella's values, which the plan takes (the node's names and rules)
    (['-p', 'ribs:=3', '-p', 'rib1.tip_mas:=0.1'], "(did you mean 'rib1.tip_mass'?)"),
    (['-p', 'rib1.tip_mass:=0.1'], 'parameter rib1.tip_mass: set with ribs 1'),
    (['-p', 'ribs:=3', '-p', 'rib1.density:=-1.0'], 'parameter rib1.density=-1.0'),
    (['-p', 'qos_overrides./sleeve_force.publisher.depth:=5'], 'its topics take none'),
    # the process's own checks (they were tracebacks, exit 1)
    (['--bogus-flag'], "unknown ROS arguments ['--bogus-flag']"),
    (['-p', 'use_sim_time:=abc'], "parameter use_sim_time='abc': must be of type bool"),
])
@pytest.mark.ros
def test_controller_refuses_bad_parameters_with_exit_2(args, culprit):
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.deploy_controller', '--ros-args',
                        *args], capture_output=True, text=True, env=ros_env(), timeout=60)
    assert r.returncode == 2, r.stderr
    assert culprit in r.stderr and 'Traceback' not in r.stderr


@pytest.mark.ros
def test_controller_refuses_a_runtime_set_naming_the_parameter(probe, ros_domain_id):
    """
    ``ros2 param set`` on the controller: refused as umbrella_node refuses it, named.

    rclpy's own reasons said 'Invalid access to undeclared parameter(s): []' for a
    misspelt name and did not say why a parameter is read-only.
    """
    with NodeProcess(module='umbrella_sim.deploy_controller', domain_id=ros_domain_id) as c:
        c.wait_for_log('waiting for joint_states', timeout=60)
        set_param, get = parameter_calls(probe, '/deploy_controller')
        d = ParameterType.PARAMETER_DOUBLE
        r = set_param('targt_time', d, 2.0)
        assert not r.successful
        assert "'targt_time' (did you mean 'target_time'?)" in r.reason, r.reason
        r = set_param('target_time', d, 2.0)
        assert not r.successful
        assert 'target_time is read-only' in r.reason, r.reason
        assert '-p target_time:=' in r.reason, r.reason
        assert get('target_time').double_value == 1.0
        assert 'Traceback' not in c.output()


@pytest.mark.ros
@pytest.mark.slow
def test_controller_shares_the_node_params_file_and_names_a_typo_in_it(tmp_path):
    """
    One '/**' params file serves every node of a launch.

    Both nodes take it; a name neither knows there (robot_state_publisher's, or a typo) is
    a warning naming it with a "did you mean"; in a section naming the node, exit 2.
    """
    shared = tmp_path / 'shared.yaml'
    shared.write_text('/**:\n  ros__parameters:\n    v0: 0.0\n    publish_rate: 100.0\n'
                      '    record: false\n    target_time: 1.5\n    max_force: 8.0\n'
                      '    publish_frequency: 30.0\n')
    with NodeProcess('--params-file', str(shared),
                     module='umbrella_sim.deploy_controller') as controller:
        controller.wait_for_log('waiting for joint_states', timeout=60)
        assert 'target 1.5 s' in controller.output()
        assert "section '/**' gives 'publish_frequency'" in controller.output()
        assert controller.stop() == 0
    # and the node, which takes the controller's names there silently
    with NodeProcess('--params-file', str(shared)) as node:
        node.wait_for_log('physics step', timeout=60)
        assert "section '/**' gives 'publish_frequency'" in node.output()
        assert node.stop() == 0, node.output()
    # and the offline tools, which read the node's file (they refused the controller's names)
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim', 'simulate', '--params',
                        str(shared), '--duration', '0.01'], capture_output=True, text=True,
                       env=ros_env(), timeout=60)
    assert r.returncode == 0, r.stderr
    assert 'warning: params file' in r.stderr and "gives 'publish_frequency'" in r.stderr
    # a section naming the node alone is the node's: a controller name there is a mistake
    own = tmp_path / 'own.yaml'
    own.write_text('umbrella_node:\n  ros__parameters:\n    target_time: 1.5\n')
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.node', '--ros-args',
                        '--params-file', str(own)], capture_output=True, text=True,
                       env=ros_env(), timeout=60)
    assert r.returncode == 2 and "unknown parameter 'target_time'" in r.stderr, r.stderr
    typo = tmp_path / 'typo.yaml'
    typo.write_text(shared.read_text().replace('max_force', 'max_forse'))
    with NodeProcess('--params-file', str(typo),
                     module='umbrella_sim.deploy_controller') as controller:
        controller.wait_for_log('waiting for joint_states', timeout=60)
        assert "'max_forse' (did you mean 'max_force'?)" in controller.output()
        assert controller.stop() == 0
    own_typo = tmp_path / 'own_typo.yaml'
    own_typo.write_text('deploy_controller:\n  ros__parameters:\n    max_forse: 8.0\n')
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.deploy_controller', '--ros-args',
                        '--params-file', str(own_typo)], capture_output=True, text=True,
                       env=ros_env(), timeout=60)
    assert r.returncode == 2 and str(own_typo) in r.stderr, r.stderr
    assert "'max_forse' (did you mean 'max_force'?)" in r.stderr


@pytest.mark.ros
@pytest.mark.slow
def test_controller_over_dds_locks_five_times_softer_than_constant_force(
        constant, antenna_factory, ros_domain_id, tmp_path):
    """
    Real DDS: the constant force and the controller, each on a fresh node.

    Both nodes record; the figures come from the recordings (sim time, every publication).
    The controlled node runs in lockstep: each period waits for the controller's answer to
    the last joint_states, so the loop is the offline law at a delay of zero periods,
    whatever CPU the controller process gets on a busy machine.
    """
    force, _ = constant
    node_params = {'v0': 0.0, 'sleeve_force_min': -LIMIT, 'publish_rate': RATE,
                   'time_step': STEP}

    cf = antenna_factory(node_params, record_path=str(tmp_path / 'constant'))
    cf.wait_for_phase('deploying')
    cf.publish_force(force)
    cf.wait_for_phase('locked', timeout=60)
    cf.wait_for_sim_time(cf.lock_time() + AFTER, timeout=30)
    assert cf.stop() == 0
    ref = summary_from_recording(str(tmp_path / 'constant'), after_lock=AFTER)

    bag = str(tmp_path / 'controlled')
    ctl = antenna_factory(dict(node_params, lockstep=True, start_paused=True), record_path=bag)
    log = run_controlled(ctl, ros_domain_id)
    s = summary_from_recording(bag, after_lock=AFTER)
    # the loop ran: a command every period from the first push to the lock
    assert command_gap(bag, s.first_push_time, s.lock_time) <= 1.0 / RATE + 1e-9
    cfg = ControllerConfig(target_time=TARGET, max_force=LIMIT, min_force=-LIMIT)
    offline = run_summary(*simulate_closed_loop(MODEL, cfg, RATE, 0, after_lock=AFTER))
    print(f'\nconstant {force:.4f} N: deploy {ref.deploy_time:.4f} s, stage-2 peak stress '
          f'{ref.stage2_peak_stress / 1e6:.2f} MPa, tip amplitude '
          f'{ref.stage2_tip_amplitude * 1e3:.2f} mm\ncontroller: deploy {s.deploy_time:.6f} s '
          f'(offline {offline.deploy_time:.6f} s), stage-2 peak stress '
          f'{s.stage2_peak_stress / 1e6:.3f} MPa (offline {offline.stage2_peak_stress / 1e6:.3f}),'
          f' tip amplitude {s.stage2_tip_amplitude * 1e3:.3f} mm (offline '
          f'{offline.stage2_tip_amplitude * 1e3:.3f})\n{log}')
    assert 'it refuses them' not in log and 'publishers on' not in log   # no false alarm
    assert ref.deploy_time == pytest.approx(TARGET, rel=1e-3)
    # both over the same stage-2 window (each recording went on for a while after it)
    assert AFTER - 1.0 / RATE <= s.stage2_span <= AFTER
    assert AFTER - 1.0 / RATE <= ref.stage2_span <= AFTER
    assert abs(s.deploy_time - ref.deploy_time) <= 0.05 * ref.deploy_time
    assert s.stage2_peak_stress * 5 <= ref.stage2_peak_stress
    assert s.stage2_tip_amplitude * 5 <= ref.stage2_tip_amplitude
    # lockstep from the first period (the run started from a paused reset the controller had
    # answered): the DDS loop is the offline law at a delay of zero periods
    for name in ('deploy_time', 'stage2_tip_amplitude', 'stage2_peak_stress'):
        assert getattr(s, name) == pytest.approx(getattr(offline, name), rel=1e-6), name


@pytest.mark.ros
@pytest.mark.slow
def test_stop_signal_while_commands_flow_is_a_clean_exit(probe, ros_domain_id):
    """
    SIGTERM or SIGINT while the controller answers joint_states: exit 0, no traceback.

    With rclpy's own signal handlers, a signal shut the context down from the handler while
    the executor could be building its next wait set; spin then raised RCLError and the
    process exited 1 in about one stop of three here.  Eight stops, each at
    its own instant of a stream of states, alternately SIGTERM and SIGINT.
    """
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64, String

    from umbrella_sim.ros import messages as ros_io

    phase = probe.node.create_publisher(String, ros_io.TOPICS['deployment_phase'].name,
                                        ros_io.TOPICS['deployment_phase'].qos)
    states = probe.node.create_publisher(JointState, ros_io.TOPICS['joint_states'].name, 10)
    probe.subscribe(ros_io.COMMAND.name, Float64)
    phase.publish(String(data='deploying'))
    ended = threading.Event()
    folded = UmbrellaParams().alpha0

    def pump():
        k = 0
        while not ended.is_set():
            k += 1
            msg = JointState(position=[folded, 0.5, 0.0], velocity=[0.0, 0.0, 0.0],
                             effort=[0.0, 0.0, 0.0])     # folded at rest: the plan's start
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * 10**6, 10**9)
            states.publish(msg)
            time.sleep(STATE_INTERVAL)      # the stream's pace, not a wait for a condition

    pumper = threading.Thread(target=pump, daemon=True)
    pumper.start()
    try:
        for i in range(8):
            with NodeProcess(module='umbrella_sim.deploy_controller', domain_id=ros_domain_id,
                             parameters={'max_force': LIMIT, 'min_force': -LIMIT}) as c:
                c.wait_for_log('waiting for joint_states', timeout=60)
                sent = len(probe.messages(ros_io.COMMAND.name))
                # each stop at its own instant of the stream: after 20 + 10 i answers
                poll(lambda: len(probe.messages(ros_io.COMMAND.name)) > sent + 20 + 10 * i, 30,
                     lambda: f'controller {i} sent '
                             f'{len(probe.messages(ros_io.COMMAND.name)) - sent} commands '
                             f'in 30 s (awaited {21 + 10 * i})')
                sig = signal.SIGTERM if i % 2 == 0 else signal.SIGINT
                rc = c.stop(sig)
                out = c.output()
            assert rc == 0, f'controller {i} ({sig.name}): exit {rc}\n{out}'
            assert 'Traceback' not in out, out
    finally:
        ended.set()


@pytest.mark.ros
@pytest.mark.slow
def test_controller_deploys_each_new_run_after_a_reset(antenna_factory, ros_domain_id):
    """
    A ~/reset after the lock starts a new run: the controller deploys it afresh.

    It notices by the phase (locked -> deploying) and by sim time going back, as it would
    a restarted node; the second deployment takes the same time as the first.  Each run
    starts from a reset made while paused, so the controller's first command (its answer to
    the run's t = 0 state) is in before the run goes: in lockstep from its first period,
    no state is skipped (a free-running start let the depth-1 subscription skip the first
    state showing the push, and put the plan a period off now and then).
    """
    ctl = antenna_factory({'v0': 0.0, 'sleeve_force_min': -LIMIT, 'publish_rate': RATE,
                           'time_step': STEP, 'lockstep': True, 'start_paused': True})
    with controller_on(ctl, ros_domain_id) as (controller, commands):
        deploy = []
        for run in range(2):
            start_answered(ctl, commands)
            ctl.wait_for_phase('locked', timeout=60)
            deploy.append(ctl.lock_time() - ctl.applied_forces()[0][0])
            controller.wait_for_log('deployment over', count=run + 1)
            ctl.pause()
        controller.wait_for_log('a new run; deploying it from its start')
        out = controller.output()
        assert controller.stop() == 0, out
    assert 'it refuses them' not in out and 'not folded at rest' not in out   # no false alarm
    assert deploy[0] == pytest.approx(TARGET, rel=0.05)
    assert deploy[1] == pytest.approx(deploy[0], rel=1e-6), deploy      # the same run again


@pytest.mark.ros
@pytest.mark.slow
def test_controller_deploys_the_umbrella_of_three_ribs_as_the_planar_frame(
        constant, antenna_factory, ros_domain_id, tmp_path):
    """
    The umbrella of 3 identical ribs (one sleeve, F a rib): the loop of the planar frame.

    Its joint_states have 2 N + 1 joints, the sleeve last with the whole sleeve's effort
    N F: the controller reads the ribs' leaf angle and commands F a rib.  N identical ribs
    each follow the planar frame, so in lockstep the run is the offline planar loop at zero
    delay (the controller once read rib 1's leaf hinge as the sleeve, never saw its push,
    and held max_force to a hard lock in half the target time).
    """
    _, ref = constant
    bag = str(tmp_path / 'ribs')
    ctl = antenna_factory({'ribs': 3, 'v0': 0.0, 'sleeve_force_min': -LIMIT,
                           'publish_rate': RATE, 'time_step': STEP, 'lockstep': True,
                           'real_time_factor': 0.0, 'start_paused': True}, record_path=bag)
    log = run_controlled(ctl, ros_domain_id)
    assert 'first push acting' in log and 'it refuses them' not in log, log
    s = summary_from_recording(bag, after_lock=AFTER)
    cfg = ControllerConfig(target_time=TARGET, max_force=LIMIT, min_force=-LIMIT)
    offline = run_summary(*simulate_closed_loop(MODEL, cfg, RATE, 0, after_lock=AFTER))
    assert s.ribs == 3 and s.deploy_time == pytest.approx(offline.deploy_time, rel=1e-4)
    for rib in s.stage2:
        assert rib.stage2_tip_amplitude == pytest.approx(offline.stage2_tip_amplitude, rel=1e-2)
        assert rib.stage2_peak_stress * 5 <= ref.stage2_peak_stress   # the soft latch


@pytest.mark.ros
@pytest.mark.slow
def test_controller_leaves_a_frame_that_is_not_at_rest_alone(antenna_factory, ros_domain_id):
    """
    The plan deploys from rest: a node started with v0 != 0 gets no command, and an error.

    Pushing a frame that already deploys faster than the plan only makes its lock harder
    (the controller once pushed the node's default V0 = -0.2 m/s run at full force).
    """
    antenna = antenna_factory({'v0': -0.2, 'publish_rate': RATE, 'time_step': STEP,
                               'start_paused': True})
    with NodeProcess(module='umbrella_sim.deploy_controller', domain_id=ros_domain_id,
                     parameters={'target_time': TARGET, 'max_force': LIMIT}) as controller:
        wait_for_controller(antenna, controller)
        # reset the paused antenna until the controller has a state of it (the graph shows the
        # controller ~1 s before DDS delivers it data): its t = 0 state, already at v0
        for _ in range(20):
            antenna.reset()
            try:
                controller.wait_for_log('the frame is not folded at rest', timeout=3.0)
                break
            except AssertionError:
                continue
        antenna.resume()
        controller.wait_for_log('the frame is not folded at rest', timeout=30)
        antenna.wait_for_phase('locked', timeout=30)
        out = controller.output()
        assert controller.stop() == 0, out
    assert 'give umbrella_node v0:=0.0' in out and 'deployment over' not in out
    assert antenna.applied_forces() == []
    offline = simulate(UmbrellaParams(v0=-0.2, time_step=STEP), 1.0, stop_after_lock=0.0)
    assert antenna.lock_time() == pytest.approx(offline.lock.time, abs=1e-9)   # on its own


@pytest.mark.ros
@pytest.mark.slow
def test_controller_warns_when_its_commands_are_refused_or_others_command(
        antenna_factory, ros_domain_id):
    """
    The node's echoed effort shows what it applies: braking commands it refuses are named.

    The node takes no force below its sleeve_force_min (0 by default) while the controller
    brakes down to -LIMIT; a second publisher on sleeve_force (the test's own) is named too.
    """
    from std_msgs.msg import Float64

    # in lockstep from a reset the controller answered (start_answered), as the tests above:
    # free-running, a loaded machine delayed its commands, its window of our own commands
    # grew with the delay it measured, and the refused braking went unnoticed
    antenna = antenna_factory({'v0': 0.0, 'publish_rate': RATE, 'time_step': STEP,
                               'start_paused': True, 'lockstep': True})
    antenna.publish_force(0.0)              # a second publisher on the topic, holding 0 N
    commands = antenna.topics['sleeve_force']
    antenna.probe.subscribe(commands, Float64)
    with NodeProcess(module='umbrella_sim.deploy_controller', domain_id=ros_domain_id,
                     parameters={'target_time': TARGET, 'max_force': LIMIT,
                                 'min_force': -LIMIT}) as controller:
        wait_for_controller(antenna, controller, publishers=2)
        start_answered(antenna, commands)
        antenna.wait_for_phase('locked', timeout=60)
        controller.wait_for_log('deployment over', timeout=30)
        out = controller.output()
        assert controller.stop() == 0, out
    assert '2 publishers on /sleeve_force' in out, out
    assert 'it refuses them (its sleeve_force_min' in out, out
    assert 'below' in antenna.node.output() or 'sleeve_force_min' in antenna.node.output()
    assert min(f for _, f in antenna.applied_forces()) >= 0.0


@pytest.mark.ros
def test_a_command_taken_late_is_not_reported_as_refused(capfd):
    """
    A free-running node under load takes a command 0.2 s late: ours, not someone else's.

    The controller's own check (in this process, states made up): with a window of the
    median delay it warned 'none of our commands' in 2 of 3 runs of a user's trial.
    """
    import math

    import rclpy
    from sensor_msgs.msg import JointState

    from umbrella_sim.ros.deploy_controller import _make_node_class
    from umbrella_sim.testing import DOMAIN_ID

    rclpy.init(domain_id=DOMAIN_ID)    # (its publisher and subscriptions: no traffic)
    try:
        node = _make_node_class()()
        node.phase = 'deploying'
        period, alpha0 = 0.01, UmbrellaParams().alpha0

        def state(t, effort):
            # on its plan, the rate a little off it: each command its own value
            a, rate = ((alpha0, 0.0) if node.law.t_start is None else
                       node.law.reference(t)[:2])
            rate += 0.02 * math.sin(7 * t / period)
            msg = JointState(position=[a, 0.0, 0.0], velocity=[rate, 0.0, 0.0],
                             effort=[0.0, 0.0, effort])
            msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), round(t % 1 * 1e9)
            node._on_state(msg)

        for k in range(40):             # commands act one period late
            t = k * period
            state(t, node._sent[-2][1] if len(node._sent) > 1 else 0.0)
        for k in range(40, 46):         # then a stall: each state shows a command 0.2 s old
            t = k * period
            state(t, next(f for ts, f in reversed(node._sent) if ts <= t - 0.2 - 1e-9))
        assert len({f for _, f in node._sent}) > 30     # (commands told apart by value)
        node.destroy_node()
    finally:
        rclpy.shutdown()
    err = capfd.readouterr().err
    assert 'first push acting' in err and 'none of our commands' not in err, err


def test_a_command_no_state_followed_is_sent_once_more(monkeypatch):
    """
    The first command of a new publisher can be dropped by a reader not yet matched to it.

    DDS repairs it only at the next heartbeat (3 s): a node in lockstep, waiting for it,
    stalled that long.  The controller sends a command that no state followed in RESEND_S
    once more (in this process, the clock and the publisher made up): once, not again while
    no state comes (a paused node), and not at all when a state came.
    """
    import rclpy
    from sensor_msgs.msg import JointState

    from umbrella_sim.ros import deploy_controller as dc
    from umbrella_sim.testing import DOMAIN_ID

    now = [100.0]
    monkeypatch.setattr(dc.time, 'monotonic', lambda: now[0])
    rclpy.init(domain_id=DOMAIN_ID)    # (its publisher and subscriptions: no traffic)
    try:
        node = dc._make_node_class()()
        sent = []
        monkeypatch.setattr(node, 'pub', type('Pub', (), {
            'publish': lambda self, msg: sent.append(msg.data), 'topic_name': 'x'})())
        node.phase = 'deploying'
        msg = JointState(position=[UmbrellaParams().alpha0, 0.0, 0.0],
                         velocity=[0.0, 0.0, 0.0], effort=[0.0, 0.0, 0.0])
        node._on_state(msg)                          # t = 0, at rest: the first push
        assert sent == [node.law.cfg.max_force]
        now[0] += 0.5 * dc.RESEND_S
        node._resend_unanswered()
        assert len(sent) == 1                        # not yet
        now[0] += dc.RESEND_S
        node._resend_unanswered()
        assert sent == [node.law.cfg.max_force] * 2  # once more, the same value
        now[0] += 10 * dc.RESEND_S
        node._resend_unanswered()
        assert len(sent) == 2                        # once only
        # a state came: it answers the command before it, and the one it brings (the law's
        # next) is the one sent again if no state follows it
        msg.header.stamp.nanosec = 10_000_000
        msg.effort = [0.0, 0.0, node.law.cfg.max_force]
        node._on_state(msg)
        assert len(sent) == 3 and node._unanswered == (sent[-1], now[0])
        now[0] += 0.5 * dc.RESEND_S
        msg.header.stamp.nanosec = 20_000_000
        node._on_state(msg)                          # answered within RESEND_S: no resend
        now[0] += 0.5 * dc.RESEND_S
        node._resend_unanswered()
        assert len(sent) == 4
        now[0] += dc.RESEND_S
        node._resend_unanswered()
        assert len(sent) == 5 and sent[-1] == sent[-2]
        node.destroy_node()
    finally:
        rclpy.shutdown()
