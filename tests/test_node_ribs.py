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
umbrella_node with ribs >= 2: its parameters, joint names, per-rib topics, lockstep, recording.

The physics of the umbrella is the core's (tests/test_umbrella3d*.py) through the run driver
(tests/test_umbrella3d_driver.py); here the node's face of it: the umbrella's parameters
refused at start naming the culprit, 2N + 1 joints named rib<k>/..., the per-rib arrays as
their layouts say, the lockstep handshake, and an MCAP recording of all of it with the
umbrella's summary figures, which re-runs offline to the same values.
"""
import json
import subprocess
import sys

import pytest

from umbrella_sim.bag.format import MESH_RECORD, PARAMETERS_RECORD, SUMMARY_RECORD
from umbrella_sim.bag.reader import read_log
from umbrella_sim.ros.ribs_messages import STRESS_FIELDS, TIP_FIELDS
from umbrella_sim.ros.robot_description import joint_names
from umbrella_sim.testing import ros_env, SimulatedAntenna
from umbrella_sim.tools.replay import DEFAULT_TOLERANCE, resimulate

pytestmark = pytest.mark.ros


@pytest.mark.parametrize('args, culprit', [
    (['-p', 'rib.tip_mass:=[0.1]'], 'rib.tip_mass'),         # ribs 1 is the planar model
    (['-p', 'hub_radius:=0.1'], 'hub_radius'),
    (['-p', 'ribs:=3', '-p', 'rib.tip_mass:=[0.0, 0.1]'], 'tip_mass'),
    (['-p', 'ribs:=3', '-p', 'base:=wobbly'], 'base'),
    (['-p', 'ribs:=3', '-p', 'rib.stick_until:=[0.0, -1.0, 0.0]'], 'stick_until'),
    (['-p', 'ribs:=3', '-p', 'rib.stick_until:=[a, b, c]'], 'rib.stick_until'),
    (['-p', 'ribs:=3', '-p', 'rib5.l2:=0.6'], 'rib5.l2'),           # ribs 0 .. 2
    (['-p', 'ribs:=3', '-p', 'rib1.lx:=0.6'], 'rib1.lx'),
    (['-p', 'ribs:=3', '-p', 'rib1.l2:=-0.6'], 'l2'),
    (['-p', 'ribs:=3', '-p', 'rib.tip_mass:=[]'], 'rib.tip_mass: an empty list'),
])
def test_invalid_umbrella_parameters_exit_2_naming_them(args, culprit):
    r = subprocess.run([sys.executable, '-m', 'umbrella_sim.node', '--ros-args', *args],
                       capture_output=True, text=True, env=ros_env(), timeout=60)
    assert r.returncode == 2, r.stderr
    assert culprit in r.stderr and 'Traceback' not in r.stderr


def stalled_at(antenna, at: float | None = None) -> float:
    """Return the sim time (at, if given) the node waits for a command at (its diagnostics)."""
    def stalled(m):
        values = {kv.key: kv.value for kv in m.status[0].values}
        return values['waiting_for_command'] == 'True' and (
            at is None or abs(float(values['sim_time_s']) - at) < 1e-6)
    msg = antenna.wait_for('diagnostics', stalled, timeout=30, what='waiting_for_command')
    t = float({kv.key: kv.value for kv in msg.status[0].values}['sim_time_s'])
    antenna.wait_for('joint_states', lambda m: abs(m.header.stamp.sec
                                                   + 1e-9 * m.header.stamp.nanosec - t) < 1e-6,
                     timeout=30, what=f'the state of t = {t:.6f} s')
    return t


def test_the_umbrella_node_in_lockstep_publishes_and_records_every_rib(tmp_path):
    """
    Two ribs in lockstep: each publication waits for its command; everything is recorded.

    Once the first command armed the handshake and the node waits, commands answer 10 joint
    states one by one; the node takes exactly one publication period per answer (lockstep,
    whatever the step costs), the sleeve joint's effort is the
    whole sleeve's force 2 F, each rib topic carries one row per rib as its layout says, and
    the bag holds every publication of every rib topic with the umbrella's figures.
    """
    bag = tmp_path / 'ribs'
    period = 1.0 / 500.0
    with SimulatedAntenna({'ribs': 2, 'v0': 0.0, 'time_step': 2e-4, 'publish_rate': 500.0,
                           'lockstep': True, 'rib.tip_mass': [0.0, 0.05],
                           'start_paused': True}, record_path=str(bag)) as antenna:
        antenna.resume()
        antenna.publish_force(10.0)         # the first command arms the handshake
        t0 = stalled_at(antenna)            # ... which then waits for an answer
        # (the t = 0 state of a paused start may go out before the probe matched)
        first = antenna.messages('joint_states')[0]
        assert list(first.name) == joint_names(2) == [
            'rib0/leaf_hinge', 'rib0/link_hinge', 'rib1/leaf_hinge', 'rib1/link_hinge',
            'sleeve_slider']
        for i in range(1, 11):
            antenna.publish_force(10.0 + i)
            antenna.wait_for_sim_time(t0 + i * period - 1e-9)
        # one period per command, no more: stalled again ten periods on
        stalled_at(antenna, t0 + 10 * period)
        states = antenna.rib_states()
        assert max(s['time'] for s in states) == pytest.approx(t0 + 10 * period, abs=1e-9)
        assert antenna.applied_forces()[-1] == (pytest.approx(t0 + 9 * period, abs=1e-9), 20.0)
        assert states[-1]['sleeve_force'] == 2 * 20.0
        # the rib arrays: one row a rib, the fields of the layouts
        tips = antenna.rib_arrays('rib_tip_deflection')
        stresses = antenna.rib_arrays('rib_peak_stress')
        assert len(tips[-1]) == len(stresses[-1]) == 2
        assert list(tips[-1][0]) == list(TIP_FIELDS)
        assert list(stresses[-1][1]) == list(STRESS_FIELDS)
        # the push bends every leaf in its plane; nothing excites them out of it (the tip
        # mass sits on its rib's axis), so each rib stays in its plane to round-off
        for rib in tips[-1]:
            assert abs(rib['in_plane_m']) > 1e-6 and abs(rib['out_of_plane_m']) < 1e-12
        # von Mises bounds each component (it is their upper bound's combination)
        for row in stresses[-1]:
            assert row['von_mises_Pa'] >= max(row['axial_Pa'], row['bending_in_plane_Pa'],
                                              row['torsion_Pa'])
        published = len(antenna.messages('joint_states'))
        assert antenna.stop() == 0
    log = read_log(str(bag))
    for key in ('joint_states', 'rib_tip_deflection', 'rib_peak_stress', 'energy'):
        assert log.count(log.find_topic(key)) >= published, key
    assert log.metadata[MESH_RECORD]['ribs'] == '2'
    params = {k: json.loads(v) for k, v in log.metadata[PARAMETERS_RECORD].items()}
    assert params['ribs'] == 2 and params['rib.tip_mass'] == [0.0, 0.05]
    figures = json.loads(log.metadata[SUMMARY_RECORD]['figures'])
    assert figures['ribs'] == 2 and len(figures['peak_stress']['von_mises']['value']) == 2
    assert figures['energy_drift'] < 1e-9
    # the recording re-runs offline from its parameters and applied forces: every rib's
    # published values again (umbrella_replay --resimulate)
    res = resimulate(log)
    assert res['compared'] == log.count(log.find_topic('joint_states')) and not res['problems']
    assert max(res['relative_diff'].values()) <= DEFAULT_TOLERANCE


def test_a_reset_restarts_the_umbrella_with_the_planar_parameters_set():
    """
    A planar parameter set at run time applies to every rib on ~/reset; ribs stays fixed.

    sleeve_force 30 N per rib, set while the umbrella runs at 10 N: after ~/reset the new
    run starts at t = 0 with the same 2N + 1 joints and the sleeve pushed with 2 x 30 N; a
    set of ribs is refused (read-only: it sets the topics and joint names), and so is one of
    a rib's own value (rib<k>.<name>, declared only where given at start).
    """
    with SimulatedAntenna({'ribs': 2, 'v0': 0.0, 'time_step': 2e-4, 'publish_rate': 500.0,
                           'sleeve_force': 10.0, 'start_paused': True}) as antenna:
        antenna.resume()
        antenna.wait_for_sim_time(0.01)
        with pytest.raises(AssertionError, match='ribs is read-only'):
            antenna.set_parameters(ribs=3)
        # a rib's own value, not given at start: read-only too, not unknown
        with pytest.raises(AssertionError, match="rib1.tip_mass is read-only: a rib's own"):
            antenna.set_parameters(**{'rib1.tip_mass': 0.2})
        with pytest.raises(AssertionError, match=r'rib5.tip_mass: there are ribs 0 \.\. 1'):
            antenna.set_parameters(**{'rib5.tip_mass': 0.2})
        antenna.set_parameters(sleeve_force=30.0)
        antenna.reset()
        first = antenna.messages('joint_states')[0]
        assert first.header.stamp.sec == first.header.stamp.nanosec == 0
        assert list(first.name) == joint_names(2)
        state = antenna.wait_for('joint_states', lambda m: m.header.stamp.nanosec > 0)
        assert state.effort[-1] == 2 * 30.0
        # the new run's starting force is on sleeve_force/applied (at t = 0), not a command
        antenna.wait_for('sleeve_force_applied', lambda m: m.data == 30.0)
        assert antenna.applied_forces() == []


def test_a_free_bus_publishes_its_state_as_the_offline_run_computes_it():
    """
    A free-floating bus: bus_state over DDS, each message the offline run's bus at its stamp.

    Two ribs, rib 1 kicked out of its plane: the bus moves and turns in reaction.  Every
    received bus_state (nav_msgs/Odometry, world -> umbrella_base) holds the position and
    attitude the run driver computes offline at its stamp, to 1e-12.  Without tf2_msgs (PyPI)
    the node says once that it broadcasts no /tf of the bus, and runs on.
    """
    import numpy as np

    from umbrella_sim.core.driver import RunDriver
    from umbrella_sim.core.umbrella3d.outputs3d import bus_odometry
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
    from umbrella_sim.ros.bus_tf import NO_TF, tf_message_type

    values = {'ribs': 2, 'base': 'free', 'bus_mass': 5.0, 'bus_inertia': 0.2,
              'rib.out_of_plane_rate': [0.0, 0.5], 'time_step': 2e-4}
    # (held at t = 0 until the probe hears it: at real_time_factor 0 the node could run its
    # 0.05 s and exit before a loaded machine's discovery matched the probe)
    with SimulatedAntenna({**values, 'real_time_factor': 0.0, 'duration': 0.05,
                           'start_paused': True}) as antenna:
        antenna.resume()
        antenna.wait_for_sim_time(0.05)
        antenna.wait_for('bus_state', lambda m: m.header.stamp.nanosec >= 49_000_000,
                         what='the bus state at t = 0.05 s')
        states = antenna.bus_states()
        if tf_message_type() is None:       # (PyPI: said once, and the node runs on)
            assert antenna.node.output().count(NO_TF) == 1
    assert len(states) >= 2 and states[-1]['time'] == pytest.approx(0.05, abs=1e-9)
    driver = RunDriver(UmbrellaRibsParams.from_mapping(values), 100.0)
    s = driver.publication()
    offline = {0.0: bus_odometry(s.bus_q, s.bus_v)}
    while s.time < 0.05 - 1e-9:
        assert driver.advance_period()[-1].error is None
        s = driver.publication()
        offline[round(s.time, 6)] = bus_odometry(s.bus_q, s.bus_v)
    moved = 0.0
    for state in states:
        want = offline[round(state['time'], 6)]
        got = state['position'] + state['orientation'] + state['linear'] + state['angular']
        assert got == pytest.approx(want.tolist(), rel=1e-12, abs=1e-15), state['time']
        moved = max(moved, float(np.linalg.norm(state['position'])))
    assert moved > 1e-5


def test_a_command_above_what_a_weaker_ribs_link_carries_is_refused():
    """
    Rib 1 of its own 4 mm section buckles its link at ~61 N: the node refuses more, a rib.

    As it refuses that sleeve_force at start (rib 1's planar record); the test API's check
    says so before sending.  The node once applied such a command (the planar record's
    2369 N bound), and the antenna's check let it through.
    """
    from umbrella_sim.core.params import UmbrellaParams

    weak = UmbrellaParams(section_height=0.004).sleeve_force_limit
    with SimulatedAntenna({'ribs': 3, 'v0': 0.0, 'rib.section_height': [0.01, 0.004, 0.01],
                           'start_paused': True}) as antenna:
        with pytest.raises(ValueError, match='link can carry'):
            antenna.publish_force(2 * weak)
        antenna.publish_force(2 * weak, check=False)
        antenna.publish_force(0.5 * weak)
        antenna.resume()
        antenna.wait_for('sleeve_force_refused', lambda m: m.data == 2 * weak)
        antenna.wait_for('sleeve_force_applied', lambda m: m.data == 0.5 * weak)
        assert all(m.data <= weak for m in antenna.messages('sleeve_force_applied'))
