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
One force schedule, one offline driver: every path gives the same states.

``umbrella_sim simulate``, ``simulate --mcap``, the live node fed the same commands and
``umbrella_replay --resimulate`` all hold F_H by forcing.ForceSchedule and step through
UmbrellaSimulator.advance_schedule; for a force switching between publications (4 N at
t = 0.0101 s, acting from the next physics step, 0.011 s at a 1 ms step) they must agree
to the last bit.
"""
import math
import subprocess
import sys

import numpy as np
import pytest

from umbrella_sim.bag.reader import read_log
from umbrella_sim.core.driver import simulate
from umbrella_sim.core.forcing import command_force, ForceSchedule
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.solver import UmbrellaSimulator
from umbrella_sim.ros.recording import record_offline

# a 1 ms step keeps these fast; the schedule's grid arithmetic is the same at any step
STEP = 1e-3
PROFILE = [(0.0101, 4.0)]           # between steps: acts from step 11, t = 0.011 s
PARAMS = UmbrellaParams(v0=-0.5, time_step=STEP)
DURATION = 0.15                     # past the lock (~0.09 s)


# ---------------------------------------------------------------- the rule itself
def test_value_acts_from_the_first_step_starting_at_or_after_its_time():
    s = ForceSchedule(1e-3, 1.0, [(0.0101, 4.0), (0.02, 2.0)])
    assert [s.force_at(k) for k in (0, 10, 11, 19, 20, 500)] == [1.0, 1.0, 4.0, 4.0, 2.0, 2.0]
    assert s.changes() == [(pytest.approx(0.011), 4.0), (pytest.approx(0.02), 2.0)]
    assert s.next_change(0) == 11 and s.next_change(11) == 20 and s.next_change(20) is None


def test_grid_times_within_a_nanosecond_count_as_on_the_grid():
    """A recorded time (ns stamps) of a grid point, rounded either way, is that step."""
    s = ForceSchedule(5e-5)
    for k in (1, 202, 6000, 123457):
        t = k * 5e-5
        assert s.step_index(t) == k
        assert s.step_index(t + 0.5e-9) == k and s.step_index(t - 0.5e-9) == k
        assert s.step_index(t + 2e-9) == k + 1


def test_last_value_on_a_step_wins_and_time_cannot_go_back():
    s = ForceSchedule(1e-3, 0.0, [(0.0101, 4.0), (0.0105, 5.0)])
    assert s.force_at(11) == 5.0 and s.changes() == [(pytest.approx(0.011), 5.0)]
    with pytest.raises(ValueError, match='goes backwards'):
        s.add(0.005, 1.0)
    with pytest.raises(ValueError, match='finite'):
        s.add(math.nan, 1.0)


def test_values_checked_by_the_models_rule():
    p = UmbrellaParams()
    with pytest.raises(ValueError, match='sleeve force'):
        ForceSchedule(1e-3, 0.0, [(0.1, -1.0)], check=lambda f: command_force(f, p))
    with pytest.raises(ValueError, match='physics step'):
        ForceSchedule(0.0)


def test_splitting_a_run_anywhere_gives_the_same_states():
    """advance_schedule in any chunks = one call: the node's periods = the offline chunks."""
    sched = ForceSchedule(STEP, 0.0, PROFILE)
    whole = UmbrellaSimulator(PARAMS)
    a, applied_a = whole.advance_schedule(sched, 150)
    parts = UmbrellaSimulator(PARAMS)
    blocks, applied_b = [], []
    for n in (3, 8, 1, 27, 111):
        b, app = parts.advance_schedule(sched, n)
        blocks.append(b)
        applied_b += app
    for f in ('time', 'alpha1', 'alpha1_rate', 'tip_transverse', 'sleeve_force'):
        assert np.array_equal(getattr(a, f), np.concatenate([getattr(b, f) for b in blocks]))
    assert applied_a == applied_b == [(pytest.approx(0.011), 4.0)]
    assert whole.lock_event.time == parts.lock_event.time


# ---------------------------------------------------------------- four paths
def states_at(samples, times):
    by_t = {round(s.time, 9): s for s in samples}
    rows = []
    for t in times:
        s = by_t[round(t, 9)]
        rows.append([s.alpha1, s.alpha2 - s.alpha1, s.sleeve_position, s.alpha1_rate,
                     s.sleeve_velocity, s.sleeve_force, s.tip_axial, s.tip_transverse])
    return np.array(rows)


def recorded_states(bag):
    """Return (times, rows as states_at, lock time, log) of a recording."""
    log = read_log(str(bag))
    js = log.decoded(log.find_topic('joint_states'))
    tip = {round(t, 9): m for t, m in log.decoded(log.find_topic('tip_deflection'))}
    times = [t for t, _ in js]
    rows = [[m.position[0], m.position[1], m.position[2], m.velocity[0], m.velocity[2],
             m.effort[2], tip[round(t, 9)].point.x, tip[round(t, 9)].point.y] for t, m in js]
    lock = float(log.metadata['umbrella_sim.events']['lock_time'])
    return np.array(times), np.array(rows), lock, log


@pytest.fixture(scope='module')
def offline():
    """Run umbrella_sim simulate's driver (a sample every step)."""
    return simulate(PARAMS, DURATION, force_profile=PROFILE)


def test_simulate_applies_the_value_from_the_next_step(offline):
    forces = {round(s.time, 9): s.sleeve_force for s in offline.samples}
    assert forces[0.011] == 0.0 and forces[0.012] == 4.0      # the step 0.011 -> 0.012
    assert offline.lock is not None


@pytest.mark.parametrize('rate', [100.0, 1000.0])
def test_mcap_recording_has_the_states_of_simulate(tmp_path, offline, rate):
    bag = tmp_path / f'offline_{rate:g}'
    r = record_offline(PARAMS, str(bag), DURATION, PROFILE, publish_rate=rate)
    times, rows, lock, log = recorded_states(bag)
    assert len(times) == round(DURATION * rate) + 1
    assert np.array_equal(rows, states_at(offline.samples, times))
    assert lock == offline.lock.time == r.lock.time
    applied = log.decoded(log.find_topic('sleeve_force/applied'))
    assert [(round(t, 9), m.data) for t, m in applied] == [(0.011, 4.0)]


def resimulate_cli(bag):
    return subprocess.run([sys.executable, '-m', 'umbrella_sim.tools.replay', str(bag),
                           '--resimulate', '--tolerance', '0'],
                          capture_output=True, text=True, timeout=300)


def test_resimulation_of_an_offline_recording_is_exact(tmp_path):
    bag = tmp_path / 'offline'
    record_offline(PARAMS, str(bag), DURATION, PROFILE, publish_rate=100.0)
    out = resimulate_cli(bag)
    assert out.returncode == 0, out.stdout + out.stderr
    assert 'PASS: largest relative difference 0.000e+00' in out.stdout


def set_real_time_factor(antenna, value):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    req = SetParameters.Request(parameters=[Parameter(
        name='real_time_factor',
        value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value))])
    res = antenna.probe.call(SetParameters, '/umbrella_node/set_parameters', req)
    assert res.results[0].successful, res.results[0].reason


def live_run(antenna_factory, bag):
    """
    Run the node slowly until the command is in, then as fast as it can.

    At 1/1000 of real time a 1 ms period lasts 1 s of wall time: a command published when
    the t = 0.010 s state arrives is taken at the start of the period from 0.011 s, the
    step the schedule gives 0.0101 s (applied_forces tells if DDS was slower than that).
    """
    antenna = antenna_factory({'v0': -0.5, 'time_step': STEP, 'publish_rate': 1000.0,
                               'real_time_factor': 0.001, 'duration': DURATION},
                              record_path=str(bag))
    # the command publisher matched now (a command equal to the force in effect changes
    # nothing), so that the 4 N command later goes out at once
    antenna.publish_force(0.0)
    antenna.wait_for_sim_time(0.010 - 1e-9, timeout=60)
    antenna.publish_force(4.0)
    applied = antenna.node.wait_for_log(r'applied from t = ([0-9.]+) s', timeout=60)
    set_real_time_factor(antenna, 0.0)
    assert antenna.node.proc.wait(timeout=120) == 0, antenna.node.output()[-3000:]
    return float(applied.group(1))


@pytest.mark.ros
@pytest.mark.slow
def test_live_node_fed_the_same_command_has_the_same_states(antenna_factory, tmp_path,
                                                            offline):
    t_applied = None
    for attempt in range(2):          # once more if DDS took longer than a period (1 s)
        bag = tmp_path / f'live_{attempt}'
        t_applied = live_run(antenna_factory, bag)
        if abs(t_applied - 0.011) < 1e-9:
            break
    assert t_applied == pytest.approx(0.011, abs=1e-9), \
        'the command reached the node more than 1 s after it was published, twice'
    times, rows, lock, _ = recorded_states(bag)
    assert times[-1] == pytest.approx(DURATION, abs=1e-9) and len(times) > 100
    assert np.array_equal(rows, states_at(offline.samples, times))
    assert lock == offline.lock.time
    out = resimulate_cli(bag)
    assert out.returncode == 0, out.stdout + out.stderr
    assert 'PASS: largest relative difference 0.000e+00' in out.stdout
