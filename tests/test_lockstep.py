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
Lockstep: with ``lockstep:=true`` the node waits for a command answering each joint_states.

Over real DDS: the node stalls while no command answers its last state, and each answer
(accepted or refused) lets exactly one publication period run, driven by that answer.
"""
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

PERIOD = 0.01           # s, publish_rate 100 Hz
STEP = 0.002            # s


def stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def status(msg) -> dict:
    return {kv.key: kv.value for kv in msg.status[0].values}


def wait_stalled(antenna, at: float | None = None, timeout: float = 20.0) -> tuple[int, float]:
    """
    Wait until the node waits for a command at its state of sim time `at` (None: any).

    Its own status (1 Hz, also while it waits) says so: waiting_for_command at a sim time.
    Return the count of joint_states once that state is received (no state follows it
    without a command) and its stamp.
    """
    def stalled(m):
        v = status(m)
        return v['waiting_for_command'] == 'True' and (
            at is None or abs(float(v['sim_time_s']) - at) < 1e-6)
    where = '' if at is None else f' at t = {at:.6f} s'
    msg = antenna.wait_for('diagnostics', stalled, timeout=timeout,
                           what=f'waiting_for_command{where} (one command, one period)')
    t = float(status(msg)['sim_time_s'])
    state = antenna.wait_for('joint_states', lambda m: abs(stamp(m) - t) < 1e-6,
                             timeout=timeout, what=f'the state of t = {t:.6f} s')
    return len(antenna.messages('joint_states')), stamp(state)


def test_lockstep_runs_one_period_per_command(antenna_factory):
    antenna = antenna_factory({'v0': 0.0, 'lockstep': True, 'publish_rate': 1 / PERIOD,
                               'time_step': STEP})
    antenna.wait_for_phase('deploying')
    antenna.wait_for_sim_time(0.05)           # before the first command it runs on its own
    antenna.publish_force(5.0)
    antenna.wait_for('diagnostics', lambda m: any(
        kv.key == 'waiting_for_command' and kv.value == 'True' for kv in m.status[0].values),
        timeout=10, what='waiting_for_command == True')
    n, t = wait_stalled(antenna)              # stalled: nothing answers its last state
    assert stamp(antenna.messages('joint_states')[-1]) == t
    for force in (6.0, float('nan'), 7.0):    # a refused command answers too (force held)
        antenna.publish_force(force, check=False)
        antenna.wait_for('joint_states', lambda m: stamp(m) > t + 1e-9, timeout=10,
                         what=f'the state after t = {t:.6f} s')
        assert wait_stalled(antenna, t + PERIOD)[0] == n + 1, \
            'one answer ran more than one period'
        state = antenna.messages('joint_states')[-1]
        assert stamp(state) == pytest.approx(t + PERIOD, abs=1e-9)
        assert state.effort[2] == (6.0 if force != 7.0 else 7.0)  # the force of that period
        n, t = n + 1, stamp(state)
    applied = antenna.applied_forces()
    assert [f for _, f in applied] == [5.0, 6.0, 7.0]
    # the first command acts for one period, then each answer from the state it answered
    assert applied[2][0] == pytest.approx(t - PERIOD, abs=1e-9)
    assert applied[1][0] == pytest.approx(t - 3 * PERIOD, abs=1e-9)
    assert applied[0][0] == pytest.approx(t - 4 * PERIOD, abs=1e-9)
    assert antenna.diagnostics()['lockstep'] == 'True'
