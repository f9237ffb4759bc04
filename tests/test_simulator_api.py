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

"""The stepping API: same results however it is driven; inputs validated; failures keep data."""
import math

import numpy as np
import pytest

from umbrella_sim.core.driver import simulate
from umbrella_sim.core.engines import SimulationDiverged
from umbrella_sim.core.integrators import PHI_TOLERANCE
from umbrella_sim.core.params import UmbrellaParams
from umbrella_sim.core.solver import UmbrellaSimulator


def trajectory(samples):
    return np.array([np.concatenate([[s.time], s.q, s.qd]) for s in samples])


# API behaviour, not accuracy: a coarse step keeps these fast (the grid arithmetic is the same)
API_STEP = 2e-3


def test_step_advance_to_and_simulate_agree():
    p = UmbrellaParams(v0=-1.0, time_step=API_STEP)
    by_run = simulate(p, 0.1).samples
    sim = UmbrellaSimulator(p)
    by_step = [sim.sample()]
    while sim.time < 0.1 - 1e-12:
        by_step += sim.step()
    sim2 = UmbrellaSimulator(p)
    by_chunks = [sim2.sample()]
    for t in np.cumsum([0.0031, 0.017, 0.0005, 0.04, 0.0394]):   # uneven wall-clock ticks
        by_chunks += sim2.advance_to(t)
    assert len(by_run) == len(by_step) == len(by_chunks)
    assert np.array_equal(trajectory(by_run), trajectory(by_step))
    assert np.array_equal(trajectory(by_run), trajectory(by_chunks))


@pytest.mark.parametrize('ribs', [1, 2])
def test_a_duration_between_grid_steps_ends_at_the_last_step_before_it(ribs):
    """
    simulate(p, 0.05) at a 0.3 ms step ends at 0.0498 s, as advance_to(0.05) does.

    The run takes every step that ends by its duration (the CLI's words, RunDriver.run's):
    it rounded 166.7 steps to 167 and ended at 0.0501 s, past the duration it was given.
    """
    step, duration = 3e-4, 0.05
    p = UmbrellaParams(time_step=step)
    if ribs == 1:
        end = simulate(p, duration).samples[-1].time
        sim = UmbrellaSimulator(p)
        sim.advance_to(duration)
        assert end == pytest.approx(sim.time, abs=1e-12)
    else:
        from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
        from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
        ribs = UmbrellaRibsParams.from_mapping({'ribs': 2, 'time_step': step})
        end = simulate(ribs, duration).summary()['final_time']
        sim = UmbrellaSimulator3D(ribs)          # its own run(), by the same rule
        sim.run(duration)
        assert end == pytest.approx(sim.time, abs=1e-12)
    assert duration - step < end <= duration


def test_force_profile_is_a_zero_order_hold_from_the_next_step():
    p = UmbrellaParams(v0=0.0, time_step=API_STEP)
    profile = [(0.0, 0.0), (0.0101, 4.0), (0.05, 1.0)]
    r = simulate(p, 0.08, force_profile=profile)
    sim = UmbrellaSimulator(p)
    manual = [sim.sample()]
    for t, f in [(0.012, 4.0), (0.05, 1.0), (0.08, None)]:
        manual += sim.advance_to(t - 1e-12 if f is not None else t)
        if f is not None:
            sim.set_sleeve_force(f)
    manual += sim.advance_to(0.08)
    assert np.array_equal(trajectory(r.samples), trajectory(manual))
    forces = [s.sleeve_force for s in r.samples]
    assert forces[:7] == [0.0] * 7 and forces[7] == 4.0     # 0.0101 s acts from t = 0.012 s
    # before the command, nothing moves
    assert all(s.alpha1 == p.alpha0 for s in r.samples[:7])


def test_reset_reproduces_the_run():
    p = UmbrellaParams(v0=-0.5, time_step=API_STEP)
    sim = UmbrellaSimulator(p)
    first = sim.advance_to(0.12)
    sim.reset()
    assert sim.time == 0.0 and sim.stage == 'deploying' and sim.lock_event is None
    assert np.array_equal(trajectory(first), trajectory(sim.advance_to(0.12)))


@pytest.mark.parametrize('bad', [-1.0, math.nan, math.inf, -math.inf, 'abc'])
def test_bad_force_refused_and_not_applied(bad):
    sim = UmbrellaSimulator(UmbrellaParams())
    sim.set_sleeve_force(2.0)
    with pytest.raises(ValueError, match='sleeve force'):
        sim.set_sleeve_force(bad)
    assert sim.sleeve_force == 2.0


def test_bad_force_profile_refused():
    with pytest.raises(ValueError, match='sleeve force'):
        simulate(UmbrellaParams(), 0.01, force_profile=[(0.0, 1.0), (0.005, -2.0)])


def test_diverging_run_stops_with_clear_error_and_keeps_samples():
    # 2.3 kN on a 0.4 kg frame (just below the link's buckling load, so accepted): Newton
    # fails after a few steps
    r = simulate(UmbrellaParams(v0=0.0, sleeve_force=2300.0, time_step=API_STEP), 0.5)
    assert r.error is not None and 't = ' in r.error
    assert len(r.samples) >= 3
    assert all(np.all(np.isfinite(s.q)) for s in r.samples)
    assert r.samples[-1].time < 0.5
    # the simulator object is left at the last good state
    sim = UmbrellaSimulator(UmbrellaParams(v0=0.0, sleeve_force=2300.0, time_step=API_STEP))
    with pytest.raises(SimulationDiverged):
        for _ in range(300):
            sim.step()
    good = sim.sample()
    assert np.all(np.isfinite(good.q)) and good.constraint_residual < 1e-6


def test_outputs_are_consistent():
    p = UmbrellaParams(v0=-0.5, time_step=API_STEP)
    r = simulate(p, 0.15)
    for s in r.samples:
        # joint geometry: H on the axle, alpha2 of the link frame
        assert s.sleeve_position == pytest.approx(
            s.q[r.q_labels.index('R2y')] + (p.l3 + s.q[r.q_labels.index('link.u1')])
            * math.sin(s.alpha2), abs=1e-15)
        assert s.kinetic_energy > 0
    locked = [s for s in r.samples if s.stage == 'locked']
    # the sleeve is at the stop to the solver's constraint tolerance (1e-11 m, issue: 1e-10)
    assert locked and all(abs(s.sleeve_position - p.sleeve_stop_height) < PHI_TOLERANCE
                          for s in locked)
    assert all(s.sleeve_reaction[1] != 0.0 for s in locked)


def test_sleeve_force_bounded_by_what_the_link_carries():
    """
    Bound the sleeve force by the load the link can carry.

    The command range ends at the link's Euler buckling load pi^2 E I / l3^2 (a pinned-
    pinned column; the squash load A sigma_y is far higher for the thesis's section).
    """
    p = UmbrellaParams()
    euler = math.pi ** 2 * 72.0e9 * (0.01 ** 4 / 12) / 0.5 ** 2
    assert p.sleeve_force_limit == pytest.approx(euler, rel=1e-12)
    assert 2.3e3 < euler < 2.4e3
    stubby = UmbrellaParams(l1=0.05, l2=0.05, l3=0.06).validated()   # squash load governs
    assert stubby.sleeve_force_limit == pytest.approx(0.01 ** 2 * 500e6, rel=1e-12)
    sim = UmbrellaSimulator(p)
    sim.set_sleeve_force(euler)
    with pytest.raises(ValueError, match='link can carry'):
        sim.set_sleeve_force(euler * 1.001)
    with pytest.raises(ValueError, match='sleeve_force'):
        UmbrellaParams(sleeve_force=1e9).validated()


@pytest.mark.parametrize('kernel', ['compiled', 'numpy'])
def test_samples_and_states_cannot_be_changed(kernel, monkeypatch):
    """A Sample's arrays are read-only; the compiled path's share its states', read-only."""
    monkeypatch.setenv('UMBRELLA_SIM_KERNEL', kernel)
    sim = UmbrellaSimulator(UmbrellaParams(v0=-0.5, elements_per_segment=2))
    s = sim.advance(50).last
    before = s.q.copy()
    for name in ('q', 'qd', 'multipliers', 'leaf_stress', 'link_stress'):
        with pytest.raises(ValueError):
            getattr(s, name).flat[0] = 1.0
    if kernel == 'compiled':
        assert s.q is sim.state.q
        with pytest.raises(ValueError):
            sim.state.q[0] = 1.0
    sim.advance(50)
    assert np.array_equal(s.q, before) and not np.array_equal(sim.state.q, before)


def test_a_negative_block_or_a_time_already_past_is_refused_and_changes_nothing():
    """advance(-5) and advance_to(an earlier t) were silent no-ops."""
    sim = UmbrellaSimulator(UmbrellaParams())
    sim.advance(10)
    t = sim.time
    for call in (lambda: sim.advance(-5), lambda: sim.advance(2.5),
                 lambda: sim.advance_schedule(None, -1), lambda: sim.advance_to(t / 2),
                 lambda: sim.advance_to(math.nan)):
        with pytest.raises(ValueError, match="n_steps=|before the simulator's time"):
            call()
    assert sim.time == t and len(sim.advance(0)) == 0 and sim.advance_to(t) == []


def test_every_public_name_of_the_core_imports_from_it():
    # what the docs tell a script to import (the umbrella's names among them) is there, and
    # is the class itself, not a copy
    import umbrella_sim.core as core
    from umbrella_sim.core.umbrella3d.params3d import UmbrellaRibsParams
    from umbrella_sim.core.umbrella3d.simulator3d import UmbrellaSimulator3D
    for name in core.__all__:
        assert getattr(core, name) is not None, name
    assert core.UmbrellaRibsParams is UmbrellaRibsParams
    assert core.UmbrellaSimulator3D is UmbrellaSimulator3D
    with pytest.raises(AttributeError, match='no attribute'):
        core.UmbrellaSimulator4D
