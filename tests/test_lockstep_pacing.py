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
Lockstep's pace and arming (ros/pacing.py, ros/lockstep.py), without DDS or wall clock.

A wait for the controller counts toward the period it answers, all of it at most; the
handshake is armed where a command acts.  Wall times are given, never read: no timing.
"""
import threading

import pytest

from umbrella_sim.ros.pacing import lag_advice, Pacer, RateWindow

PERIOD = 1e-3           # sim s, 1 kHz


def pacer(rtf: float = 1.0) -> Pacer:
    """Return a pacer by which the state of t = 0.5 s was due at wall 10.0 (at rtf)."""
    p = Pacer(threading.Event(), threading.Event())
    p.anchor(0.0, 10.0 - 0.5 / rtf if rtf > 0 else 9.5)
    return p


def test_an_answer_within_the_period_costs_no_wall_time():
    """The state of t was due at 10.0, its answer came 0.4 ms later: t + P is due at 10.001."""
    p = pacer()
    p.after_wait(0.5, PERIOD, 1.0, now=10.0004)
    assert p.target(0.5 + PERIOD, 1.0) == pytest.approx(10.0 + PERIOD, abs=1e-12)
    p = pacer(0.5)
    p.after_wait(0.5, PERIOD, 0.5, now=10.0004)
    # (the period at half pace: 2 ms of wall time)
    assert p.target(0.5 + PERIOD, 0.5) == pytest.approx(10.0 + 2 * PERIOD, abs=1e-12)


def test_a_late_answer_makes_the_period_due_at_once_never_behind():
    """An answer 5 s late: the period is due when it comes, not 5 s in the past (no lag)."""
    p = pacer()
    p.after_wait(0.5, PERIOD, 1.0, now=15.0)
    assert p.target(0.5 + PERIOD, 1.0) == 15.0
    assert p.lag(p.target(0.5 + PERIOD, 1.0), now=15.0) == 0.0


def test_a_state_published_late_is_caught_up_by_one_period_at_most():
    """Out 30 ms late, answered at once: the next is due at once, the lag is not carried on."""
    p = pacer()
    p.after_wait(0.5, PERIOD, 1.0, now=10.0302)
    assert p.target(0.5 + PERIOD, 1.0) == 10.0302


def test_unpaced_lockstep_anchors_at_the_answer():
    p = pacer(0.0)
    p.after_wait(0.5, PERIOD, 0.0, now=10.0004)
    assert (p.sim_anchor, p.wall_anchor) == (0.5, 10.0004)
    assert p.target(0.5 + PERIOD, 0.0) is None


def test_a_command_between_publications_arms_the_handshake_where_it_acts():
    """
    A command that comes in a long period's middle is taken at its end, then answers.

    Armed mid-period, the period's own state cleared the answer of a command not yet taken:
    the node waited for a second command, the first never applied (a first command of the
    test API at 100 Hz, now and then).
    """
    from umbrella_sim.ros.lockstep import Lockstep

    lockstep = Lockstep()
    lockstep.command_came()                 # in a period's middle, the handshake not armed
    assert not lockstep.go(True, at_publication=False) and not lockstep.armed
    lockstep.published()                    # the period's end: its state goes out
    assert not lockstep.waiting(True, at_publication=True, deploying=True)
    lockstep.go(True, at_publication=True)  # the command is taken here: armed from now
    assert lockstep.armed
    lockstep.published()                    # the state after the period it acted in
    assert lockstep.waiting(True, at_publication=True, deploying=True)


@pytest.mark.parametrize('measured, quoted', [(0.24, ' (measured 0.24x)'), (1.0, ''),
                                              (None, '')])
def test_the_lag_advice_quotes_the_measured_factor_only_where_it_falls_short(measured, quoted):
    """A lag that began within the second follows one that kept up: its 1.00x says nothing."""
    text = lag_advice(1.0, measured)
    assert text.startswith(f'this machine cannot step this model at 1x real time{quoted}: ')


def test_the_measured_factor_leaves_a_pause_out():
    """
    A second of diagnostics: 0.1 s run at 1x, paused 0.85 s, 0.05 s run at 1x: 1x measured.

    Counting the pause it read 0.15x, and 'cannot keep up' after a ~/pause quoted that as
    the machine's pace.  Paused all the window long: 0 (sim time did not move).
    """
    w = RateWindow(10.0, 2.0)
    w.pause(10.1, True)                       # sim t = 2.1 then, and still at 10.95
    w.pause(10.95, False)
    assert not w.due(10.99)
    assert w.due(11.0) and w.factor(11.0, 2.15) == pytest.approx(1.0, abs=1e-12)
    w.restart(11.0, 2.15)
    w.pause(11.2, True)                       # paused at 2.35, over the window's end
    assert w.factor(12.0, 2.35) == pytest.approx(1.0, abs=1e-12)
    w.restart(12.0, 2.35)                     # a window that starts paused, stays so
    assert w.factor(13.0, 2.35) == 0.0
    w.pause(13.5, False)                      # resumed at 13.5; a half-speed half second
    assert w.factor(14.0, 2.6) == pytest.approx(0.5, abs=1e-12)
    assert RateWindow(0.0, 0.0, paused=True).factor(1.0, 0.0) == 0.0
