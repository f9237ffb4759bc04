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
Accuracy of a physics step against a fine-step run of the same code (time-step study).

The figures a structural engineer reads off a run, computed from every physics step
(``RunDriver``'s chunks of ``UmbrellaSimulator.advance``), so they do not depend on an output
rate:
deploy (lock) time, stage-1 and stage-2 peak fibre stresses on leaf and link, the stage-2
tip period, and the stage-2 tip series.  ``step_errors`` compares a run with a candidate step
against a run with a much finer step (the same model, mesh and lock), which is how the
default ``time_step`` was chosen (docs/validation.md, docs/make_validation.py).
Nothing here imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .driver import RunDriver
from .params import UmbrellaParams
from .step_rule import stage2_step_of
from .summary import oscillation_period

#: issue-level accuracy targets for the default step (relative unless stated)
TARGETS = {'deploy_time': 1e-5, 'stage2_period': 5e-4, 'stage2_amplitude': 5e-3,
           'stage2_tip_series_m': 1e-3, 'peak_stress': 0.03}


def mesh_step(params: UmbrellaParams) -> float:
    """
    Return the stage-2 step chosen for the mesh (time_step 0, the default).

    step_rule.stage2_step_of: the largest 0.1 ms / k whose unresolved modes carry at most
    1 % of the stage-2 stress crest of the mesh's lock (stage 1's 0.2 ms over 2k).
    docs/validation.md (step convergence) measures it against converged runs, and
    tests/test_time_step.py checks it where the fixed 0.1 ms misses a target.
    """
    return stage2_step_of(params.replace(time_step=0.0))


#: the period of the dominant mode of x(t): the summary's estimator (outputs.py)
fundamental_period = oscillation_period


@dataclass
class StepRun:
    h: float
    deploy_time: float
    time: np.ndarray          # every step
    stage: np.ndarray
    tip_transverse: np.ndarray
    peak_stress_leaf: np.ndarray
    peak_stress_link: np.ndarray
    #: the physics step of stage 2 (h, or h / k where the lock needs it: step_rule)
    stage2_step: float = math.nan

    def stage_mask(self, code: int, window: float | None = None) -> np.ndarray:
        mask = self.stage == code
        if window is not None and code == 1:
            mask &= self.time <= self.deploy_time + window + 1e-12
        return mask

    def figures(self, window: float) -> dict:
        s1, s2 = self.stage_mask(0), self.stage_mask(1, window)
        out = {'deploy_time': self.deploy_time}
        for body in ('leaf', 'link'):
            peak = getattr(self, f'peak_stress_{body}')
            out[f'stage1_peak_{body}'] = float(peak[s1].max()) if s1.any() else math.nan
            out[f'stage2_peak_{body}'] = float(peak[s2].max()) if s2.any() else math.nan
        out['stage2_period'] = fundamental_period(self.time[s2], self.tip_transverse[s2])
        return out


def run_steps(params: UmbrellaParams, window: float) -> StepRun:
    """Deploy, then `window` seconds of stage 2, keeping every grid step's outputs."""
    driver = RunDriver(params)
    parts = []
    error = driver.run(10.0, stop_after_lock=window,
                       on_chunk=lambda chunk: parts.append(chunk.block))
    if error:
        raise RuntimeError(f'{driver.step:g} s step: {error}')
    if driver.sim.lock_event is None:
        raise RuntimeError('no lock within 10 s')

    def cat(name):
        return np.concatenate([getattr(p, name) for p in parts])
    lock = driver.sim.lock_event
    return StepRun(driver.step, lock.time, cat('time'), cat('stage'), cat('tip_transverse'),
                   cat('peak_stress_leaf'), cat('peak_stress_link'),
                   driver.step / getattr(driver.sim, 'stage2_substeps', 1))


def step_errors(run: StepRun, ref: StepRun, window: float) -> dict:
    """
    Return the errors of `run` against `ref`.

    Errors of `run` against `ref` (relative, except the tip series: max |difference| in m
    over the window, compared at the run's step times; the reference is interpolated
    linearly, so its step must be much finer).
    """
    a, b = run.figures(window), ref.figures(window)
    out = {'deploy_time': abs(a['deploy_time'] - b['deploy_time']) / b['deploy_time'],
           'stage2_period': abs(a['stage2_period'] - b['stage2_period']) / b['stage2_period']}
    for key in ('stage1_peak_leaf', 'stage1_peak_link', 'stage2_peak_leaf', 'stage2_peak_link'):
        out[key] = abs(a[key] - b[key]) / b[key]
    t_end = min(run.deploy_time, ref.deploy_time) + window
    mask = (run.stage_mask(1) & (run.time <= t_end)
            & (run.time >= max(run.deploy_time, ref.deploy_time)))
    ref2 = ref.stage_mask(1)
    tip_ref = np.interp(run.time[mask], ref.time[ref2], ref.tip_transverse[ref2])
    out['stage2_tip_series_m'] = float(np.max(np.abs(run.tip_transverse[mask] - tip_ref)))
    window_ref = ref2 & (ref.time <= t_end)
    amplitude = 0.5 * float(np.ptp(ref.tip_transverse[window_ref]))
    out['stage2_tip_amplitude_m'] = amplitude
    window_run = run.stage_mask(1) & (run.time <= t_end)
    out['stage2_amplitude'] = abs(0.5 * float(np.ptp(run.tip_transverse[window_run]))
                                  - amplitude) / amplitude
    return out


def sampled_peak_shortfall(ref: StepRun, h: float, window: float) -> dict:
    """
    Return how far the reference's own stage-2 peak stresses fall when it is seen every h.

    Per body, the worst over the grid's phases of 1 - max(stage-2 stress on a grid of step
    h) / max(stage-2 stress at every reference step), over the window.  The stage-2 peaks are
    narrow crests (modes up to the mesh's highest add up at an instant): a run with step h
    shows the stress on such a grid only, so this is how close any scheme at h can be
    promised to come, whatever its accuracy between the grid points.  h must be a multiple
    of the reference's step.
    """
    k = round(h / ref.h)
    if k < 1 or abs(k * ref.h - h) > 1e-9 * h:
        raise ValueError(f"step {h:g} s is not a multiple of the reference's {ref.h:g} s")
    mask = ref.stage_mask(1, window)
    out = {}
    for body in ('leaf', 'link'):
        stress = getattr(ref, f'peak_stress_{body}')[mask]
        out[body] = 1.0 - min(stress[j::k].max() for j in range(k)) / stress.max()
    return out


def within_targets(err: dict) -> bool:
    return (err['deploy_time'] <= TARGETS['deploy_time']
            and err['stage2_period'] <= TARGETS['stage2_period']
            and err['stage2_amplitude'] <= TARGETS['stage2_amplitude']
            and err['stage2_tip_series_m'] <= TARGETS['stage2_tip_series_m']
            and max(err[k] for k in err if '_peak_' in k) <= TARGETS['peak_stress'])


def observed_order(params: UmbrellaParams, steps: tuple[float, float, float], duration: float,
                   field: str = 'tip_transverse') -> float:
    """
    Return the observed order of convergence in the step.

    Observed order of convergence p from three runs with steps h, h/r, h/r^2 over
    `duration`: p = log(e1 / e2) / log r, e1 = max |x_h - x_(h/r)|, e2 = max |x_(h/r) -
    x_(h/r^2)| over the times of the coarsest grid, x = `field` of every step.  Meaningful in
    the asymptotic range only: every excited mode resolved (the link's axial modes reach
    ~3e5 rad/s, so h below ~1e-5 s) and no lock inside the horizon.
    """
    r = steps[0] / steps[1]
    series = []
    for k, h in enumerate(steps):
        driver = RunDriver(params.with_physics_step(h))
        parts = []
        error = driver.run(duration, on_chunk=lambda chunk: parts.append(getattr(chunk.block,
                                                                                 field)))
        if error or driver.sim.lock_event is not None:
            raise RuntimeError(error or 'the lock is inside the horizon')
        every = int(round(r ** k))
        series.append(np.concatenate(parts)[every - 1::every])
    e1 = float(np.max(np.abs(series[0] - series[1])))
    e2 = float(np.max(np.abs(series[1] - series[2])))
    return math.log(e1 / e2) / math.log(r)


@dataclass
class ModeFlow:
    """The discrete flow of one locked mode integrated alone (locked_mode_flow)."""

    omega: float            # the eigenproblem's (rad/s)
    frequency_error: float  # |discrete eigenvalue| / omega - 1
    damping_ratio: float    # -Re / |discrete eigenvalue|
    amplitude: float        # of the modal coordinate, over the amplitude it was started with
    energy_change: float    # relative change of T + V over the run


def locked_mode_flow(phase_correction: bool, k: int, damping_ratio: float = 0.0,
                     periods: float = 20.5, h: float = 1e-4) -> ModeFlow:
    """
    Return the discrete flow of the locked frame's mode k (N = 1), integrated alone.

    The undeformed deployed frame, locked, started with the velocity of the mode's
    oscillation of amplitude 1e-7 (mass-normalised, so linear): q' = 1e-7 omega_k phi_k, as
    the lock starts a mode (with a velocity).  `periods` periods at step h; the modal
    coordinate eta_n = phi_k^T M0 (q_n - q_deployed) of a linear two-dimensional flow obeys
    eta_(n+1) = a eta_n + b eta_(n-1) exactly, whose roots z give the discrete eigenvalue
    log(z) / h (Prony's method), and eta_n = Re(C z^n) its amplitude |C|.
    """
    from .kernel import DynamicState
    from .model import ConstraintSet, Stage
    from .solver import UmbrellaSimulator

    sim = UmbrellaSimulator(UmbrellaParams(phase_correction=phase_correction, time_step=h,
                                           damping_ratio=damping_ratio))
    engine, m = sim.engine, sim.model
    omega, phi, mass = m.locked_modes
    q_deployed = m.rigid_configuration(m.params.alpha_deployed)
    started = 1e-7
    s = engine.integrator.with_constraints(
        DynamicState(0.0, q_deployed, started * omega[k] * phi[:, k], np.zeros(m.n),
                     np.zeros(4)), 0.0, ConstraintSet(locked=True, rigid=False))
    engine.integrator.lock_at()     # what the lock does: the fit starts

    def energy(s):
        return engine.kinetic_energy(s, Stage.LOCKED) + engine.strain_energy(s, Stage.LOCKED)

    e0 = energy(s)
    eta = [0.0]
    for _ in range(round(periods * 2 * math.pi / omega[k] / h)):
        s = engine.step(s, h, 0.0, Stage.LOCKED)
        eta.append(phi[:, k] @ mass @ (s.q - q_deployed))
    return mode_flow_of(np.array(eta), h, float(omega[k]), started, (energy(s) - e0) / e0)


def mode_flow_of(eta: np.ndarray, h: float, omega: float, started: float,
                 energy_change: float) -> ModeFlow:
    """
    Return the ModeFlow of a modal coordinate's series eta (steps h) of a linear flow.

    eta_(n+1) = a eta_n + b eta_(n-1) exactly: its roots z give the discrete eigenvalue
    log(z) / h (Prony's method), eta_n = Re(C z^n) the amplitude |C| (over `started`).
    """
    a, b = np.linalg.lstsq(np.column_stack([eta[1:-1], eta[:-2]]), eta[2:], rcond=None)[0]
    z = np.roots([1.0, -a, -b])[0]
    lam = np.log(z) / h
    powers = z ** np.arange(len(eta))
    c = np.linalg.lstsq(np.column_stack([powers.real, -powers.imag]), eta, rcond=None)[0]
    return ModeFlow(omega, float(abs(lam) / omega - 1.0), float(-lam.real / abs(lam)),
                    math.hypot(*c) / started, float(energy_change))
