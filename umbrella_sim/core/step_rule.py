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
The physics step a mesh's stage-2 stresses need, and what a step leaves unresolved.

How much of a run's stage-2 stress a step leaves to modes it does not resolve: one rule for
the step chosen for the mesh (``time_step`` 0, or ``step_follows_mesh``) and for the 'coarse
step' warning.

At the lock the frame stops within a step: its velocity jumps onto the locked constraints and
every mode of the locked frame (``UmbrellaModel.locked_modes``, linearised at full deployment)
starts vibrating with the amplitude a_i = |eta_i + i eta_i' / omega_i| of its share of the
post-lock state (eta = phi^T M0 (q - q_deployed)).  The stage-2 peak stress is a crest where
these modes' stresses add up: at the fibre point where sum_i a_i |sigma_i(x)| is largest, the
share of that sum carried by modes the step does not resolve (omega_i h above the scheme's
limit: 1.5 with stage 2's mode fit, which makes a mode exact up to there; 0.35, a 1 % period
error, without it) is what the step can get wrong of the crest.  Measured against converged
runs (docs/validation.md, step convergence): at shares of 2-3 % the stage-2 peaks came out 2
to 6 % off, at 1 % or less within 1 %.

Past a stage-2 tip deflection of COUPLING_DEFLECTION the floating frames' nonlinearity
couples the modes, which the fit does not make exact: the step stage 2 needs is then finer
(``stage2_step_needed``), judged on the run's own lock state, and where the step is chosen
for the run (``follows_lock``) stage 2 takes it, k physics steps a grid step
(solver.UmbrellaSimulator.stage2_substeps); elsewhere 'coarse step' names it.

The step a mesh needs is judged on the lock of the rigid deployment (the undeformed frame
reaching full deployment, its velocity changed by the run's lock rule, lock.py): it depends
on the mesh, geometry, material and lock rule, not on V0 (the amplitudes scale with it), and
matched the share of the simulated runs' own lock states to 0.1 % (plastic lock; the energy
lock's redistribution depends more on the elastic state at the lock, whose own share the
'coarse step' warning judges).

flexible-nonlinear has no mode fit (integrators.LockedModeFit's modes are the undeformed
locked frame's, which its large-motion stage 2 leaves: the links buckle at V0 <= -1), so the
rule's limit for it is 0.35; its time_step 0 is the ceiling itself at every mesh
(NONLINEAR_AUTO_STEP), and step_follows_mesh takes the rule's step.  The rule would choose
4 us at N = 4 (plastic lock; 4.8 us energy), 25 times the cost of 0.1 ms, far below real
time at N = 4 where 0.1 ms runs above 5x (bench/bench_nonlinear.py); the model's targets, its
stage-2 period and amplitude at V0 = -1 and -2 against an independent geometrically exact
(ANCF) model, stage 1, are met at 0.1 ms (docs/validation_nonlinear.md), and a finer step
brings its large-motion stage 2 no closer: that motion amplifies any perturbation, and the
V0 = -2 period at N = 4 moves between 46.0 and 48.9 ms over steps of 2 us to 0.1 ms
(49.9 ms the reference).  What 0.1 ms leaves unresolved, the stage-2 peak stresses and the
small-motion amplitude (-1.7 % at V0 = -0.2, plastic lock, against the resolved step and
the ANCF model), the 'coarse step' warning says, with the step that resolves them.
"""
from __future__ import annotations

from functools import lru_cache
import math

import numpy as np

from .integrators import PHASE_CORRECTION_LIMIT
from .lock import energy_velocity, plastic_velocity
from .model import ConstraintSet, UmbrellaModel
from .params import UmbrellaParams
from .registry import MIN_PHYSICS_STEP

#: the share of a stage-2 stress crest that modes the step does not resolve may carry
STRESS_SHARE_LIMIT = 0.01
#: stage-2 tip deflection (a fraction of the leaf l1 + l2) past which the floating frames'
#: nonlinearity couples the locked modes: the mode fit makes each mode's linear part exact,
#: not that coupling, whose error in the crest follows the modes the step does not resolve.
#: In the step study (docs/validation.md, amplitude), N = 1 at its 0.1 ms step (the link's
#: axial mode, 26 600 rad/s, outside the fit) met every target up to 6.9 % (V0 = -0.22) and
#: missed the 3 % of the stage-2 peak stresses from 7.4 % on (3.2-4.9 % off at V0 = -0.25 to
#: -0.4, both locks), where 50 us, resolving every mode, met them all; finer meshes at their
#: chosen step met them up to 9.9 % and missed from 12.4 % (V0 = -0.4, energy lock)
COUPLING_DEFLECTION = 0.07
#: past COUPLING_DEFLECTION the coupling also moves the first mode's phase by an error that
#: grows like the amplitude squared times the step squared, so the tip series' error (the
#: amplitude times that phase) stays put when the step falls like the deflection to this
#: power: stage 2 takes at most AUTO_STEP_CEILING (COUPLING_DEFLECTION / d)^1.5, the step that
#: met every target up to COUPLING_DEFLECTION, besides resolving every mode carrying stress.
#: In the step study (docs/validation.md, amplitude) every mode resolved was not enough at
#: N = 1, V0 = -0.5, energy lock (d = 15.8 %: tip series 2.3 mm at 50 us); the rule's 25 us
#: gave 0.7 mm (3 of 4 steps a 0.1 ms: 1.2 mm)
COUPLING_EXPONENT = 1.5
#: the automatic step is ceiling / k for the smallest k = 1 .. MAX_STEP_DIVISOR that does it
MAX_STEP_DIVISOR = 64
#: the ceiling of the automatic step (time_step 0): the one-element mesh's step, chosen by
#: its accuracy against converged runs (docs/validation.md) and what keeps it ~15x real time
AUTO_STEP_CEILING = 1e-4
#: stage 1's step where the step is chosen for the run (time_step 0, the flexible model),
#: the grid's: stage 1 is a deployment whose own figures (the lock instant, each rib's
#: deployment, the stage-1 peaks, the state the lock starts stage 2 from) do not need the
#: stage-2 step, which resolves the modes the lock sets vibrating; stage 2 takes the mesh's
#: step as substeps (stage2_step_of).  Measured against runs at a quarter of the mesh's
#: step, stage 2 at the mesh's step in both (tests/test_time_step.py, docs/validation.md):
#: the thesis's deployment (V0 = -0.2) at 1 / 2 / 4 elements moved the lock by 3.1e-7 /
#: 3.1e-7 / 5.3e-7 s (0.1 ms and the mesh's own step: 5.2e-7 / 3.0e-8 / 4.3e-7) and the
#: stage-2 tips by 0.13 / 0.05 / 0.05 % of their amplitude (0.11 / 0.03 / 0.03 %); three
#: ribs, one stuck until 0.1 s, one with a tip mass, 1 / 2 elements: the lock by 5.3e-6 /
#: 4.4e-6 s (2.1e-5 / 1.8e-5) and the tips 0.54 / 0.11 % (0.67 / 0.35 %).  A driven base
#: that moves keeps the mesh's step in stage 1 (umbrella3d/simulator3d.py, grid_step):
#: its drive sets the modes vibrating before the lock (a jolt and a spin-up: the stage-2
#: tips 1.98 mm off of 140 mm at 0.2 ms against 0.89 mm at the mesh's step)
STAGE1_STEP_CEILING = 2e-4
#: the finest mesh (elements a segment) whose stage 1 takes STAGE1_STEP_CEILING; a finer one
#: keeps the mesh's step in stage 1 too.  Its elements' own modes carry the link's stage-1
#: peak stress (at 0.2 ms N = 4 and 8 came out up to 3.1 % and 2.3 % off, target 3 %; N = 1
#: and 2: 1.9 % and 0.9 %), and its stage-2 peaks, at the edge of their 3 % at N = 4,
#: V0 = -0.5, move by half a per cent with the state the lock starts from (2.6 % with stage
#: 1 at the mesh's 20 us or at 0.2 ms, 3.1 % at 40 us or 0.1 ms)
STAGE1_FINEST_MESH = 2
#: the coarsest stage-1 step at which the stage-1 peak stresses met the step study's 3 %
#: (docs/validation.md); a coarser stage 1 (a time_step given, or step_follows_mesh's grid)
#: says 'coarse stage-1 step' (summary.parameter_warnings).  Measured (flexible, the thesis's
#: frame, the largest of leaf and link against a 5-10 us run, N = 1 / 2 / 4 / 8 elements a
#: segment, V0 = -0.2 and -0.5): at most 0.9 / 1.4 / 1.7 / 2.4 % at 0.25 ms, 1.5 / 3.2 / 3.0 /
#: 4.1 % at 0.4 ms, 1.6 / 4.4 / 3.8 / 4.1 % at 0.5 ms, 4.1 / 9.1 / 13.0 / 15.4 % at 1 ms
#: (flexible-nonlinear at N = 1, V0 = -0.2: 4.1 % at 1 ms, 0.2 % at 0.2 ms)
STAGE1_STEP_LIMIT = 2.5e-4
#: omega h of a 1 % period error of the plain midpoint rule ((omega h)^2 / 12): the limit of a
#: resolved mode without the mode fit
UNFITTED_OMEGA_H = math.sqrt(12 * 0.01)


#: the model whose time_step 0 is AUTO_STEP_CEILING at every mesh (its real-time step; the
#: module's docstring says why); step_follows_mesh gives it the rule's step
NONLINEAR_AUTO_STEP = 'flexible-nonlinear'


def resolved_omega_h(params: UmbrellaParams) -> float:
    """Return the largest omega h of a mode the run's stage-2 integration resolves."""
    fitted = params.phase_correction and params.model == 'flexible'
    return PHASE_CORRECTION_LIMIT if fitted else UNFITTED_OMEGA_H


def modal_amplitudes(model: UmbrellaModel, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Return each locked mode's amplitude |eta_i + i eta_i' / omega_i| in the state (q, qd)."""
    omega, phi, mass = model.locked_modes
    u = phi.T @ mass
    q_deployed = model.rigid_configuration(model.params.alpha_deployed)
    return np.hypot(u @ (q - q_deployed), (u @ qd) / omega)


def lock_amplitudes(model: UmbrellaModel) -> np.ndarray:
    """
    Return the modal amplitudes the mesh's lock starts.

    The rigid deployment (alpha1' = 1) stopped at full deployment by the run's lock
    (params.lock_rule: plastic or energy).
    """
    q = model.rigid_configuration(model.params.alpha_deployed)
    cs = ConstraintSet(locked=True, rigid=False)
    qd = model.rigid_velocity(q, 1.0)
    qd = (energy_velocity(model, q, qd, cs)[0] if model.params.lock_rule == 'energy' else
          plastic_velocity(model, q, qd, cs))
    return modal_amplitudes(model, q, qd)


def mode_stresses(model: UmbrellaModel) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the top and bottom fibre stress of each locked mode, per body (leaf, link).

    Arrays (modes, 2 x stress points) for phi_i of ``locked_modes`` (stresses are linear in
    the elastic coordinates: those of the mode shape itself).
    """
    phi = model.locked_modes[1]
    return tuple(np.vstack([body.stress_top @ phi[s_e], body.stress_bottom @ phi[s_e]]).T
                 for body, s_e in ((model.leaf, model.s_leaf), (model.link, model.s_link)))


def unresolved_stress_share(model: UmbrellaModel, amplitudes: np.ndarray, h: float,
                            limit: float, stresses: tuple | None = None) -> dict:
    """
    Return, per body, the share of the stage-2 stress crest that unresolved modes carry.

    At the fibre point where sum_i a_i |sigma_i| is largest: the part of that sum from modes
    with omega_i h > limit (0.0 where every mode is resolved).  stresses: mode_stresses
    (computed if None).
    """
    omega = model.locked_modes[0]
    unresolved = omega * h > limit
    out = {}
    for body, sigma in zip(('leaf', 'link'), stresses or mode_stresses(model)):
        contribution = np.abs(amplitudes[:, None] * sigma)
        total = contribution.sum(axis=0)
        at = int(np.argmax(total))
        out[body] = float(contribution[unresolved, at].sum() / total[at]) if total[at] > 0 else 0.0
    return out


def resolving_divisor(model: UmbrellaModel, time_step: float, limit: float,
                      amplitudes: np.ndarray, share_limit: float = STRESS_SHARE_LIMIT,
                      stresses: tuple | None = None) -> int | None:
    """Return the smallest k whose step time_step / k meets share_limit, or None."""
    largest = min(MAX_STEP_DIVISOR, int(time_step / MIN_PHYSICS_STEP))
    stresses = stresses or mode_stresses(model)
    for k in range(1, largest + 1):
        shares = unresolved_stress_share(model, amplitudes, time_step / k, limit, stresses)
        if max(shares.values()) <= share_limit:
            return k
    return None


def physics_step_of(params: UmbrellaParams) -> float:
    """
    Return the integrator's step (s) of these parameters: the grid's, stage 1's.

    ``time_step`` if it is given (> 0) and ``step_follows_mesh`` is off.  Where stage 2
    takes the step its own lock needs (``follows_lock``: the flexible model with time_step
    0 or step_follows_mesh), stage 1's step (``stage1_step_of``), stage 2 then taking that
    lock's substeps.  flexible-nonlinear with step_follows_mesh: the mesh's step
    (``mesh_step_of``).  The rigid models, and flexible-nonlinear without
    step_follows_mesh: the ceiling (time_step, or AUTO_STEP_CEILING for time_step 0).
    """
    ceiling, fixed = _ceiling(params)
    if fixed:
        return ceiling
    if follows_lock(params):
        return stage1_step_of(params)
    return mesh_step_of(params)


def step_taken_now(sim) -> float:
    """
    Return the physics step (s) a simulator takes now: its grid step, over stage 2's substeps.

    sim: UmbrellaSimulator or the umbrella's (``h`` the grid step, ``stage``,
    ``stage2_substeps``, the physics steps a stage-2 grid step takes).
    """
    return sim.h / (sim.stage2_substeps if sim.stage == 'locked' else 1)


def mesh_step_of(params: UmbrellaParams) -> float:
    """
    Return the step the mesh's stage 2 needs (s): the step its lock needs.

    For the flexible models the largest ceiling / k (k = 1 .. MAX_STEP_DIVISOR; the
    ceiling is time_step, or AUTO_STEP_CEILING for time_step 0) whose unresolved modes
    carry at most STRESS_SHARE_LIMIT of the stage-2 stress crest of the mesh's lock
    (``lock_amplitudes``), or ceiling / MAX_STEP_DIVISOR if none does (the run then says
    so: 'coarse step'); the rigid models, and flexible-nonlinear without step_follows_mesh:
    the ceiling.
    """
    ceiling, fixed = _ceiling(params)
    if fixed:
        return ceiling
    return ceiling / _mesh_divisor(tuple(sorted(params.replace(time_step=ceiling)
                                                .as_dict().items())))


def stage1_step_of(params: UmbrellaParams) -> float:
    """
    Return stage 1's step where stage 2 takes the step its lock needs (``follows_lock``).

    time_step if given (step_follows_mesh), else STAGE1_STEP_CEILING up to
    STAGE1_FINEST_MESH elements a segment and the mesh's step above: the grid's step, stage 2
    taking it in substeps (``stage2_step_of``, ``substeps_for``).
    """
    if params.time_step > 0.0:
        return params.time_step
    if params.elements_per_segment > STAGE1_FINEST_MESH:
        return mesh_step_of(params)
    return STAGE1_STEP_CEILING


def stage2_step_of(params: UmbrellaParams, grid: float | None = None) -> float:
    """
    Return the step stage 2 takes on this grid short of its own lock's needs (s).

    Where it follows its lock (``follows_lock``): the largest grid step / k (grid: the run's,
    ``physics_step_of``) no coarser than the mesh's step (``mesh_step_of`` below 0.1 ms, or
    below time_step if finer): the step the rule was measured at (docs/validation.md), at
    which the lock is judged and which it divides further where the modes couple
    (``substeps_for``); else the grid's step.
    """
    grid = physics_step_of(params) if grid is None else grid
    if not follows_lock(params):
        return grid
    ceiling = min(params.time_step or AUTO_STEP_CEILING, AUTO_STEP_CEILING)
    mesh = mesh_step_of(params.replace(time_step=ceiling, step_follows_mesh=True))
    return grid / math.ceil(grid / mesh * (1.0 - 1e-9))


def stage2_step_text(params: UmbrellaParams) -> str:
    """Return what a run's step says of stage 2 where it takes its own step (else '')."""
    if not follows_lock(params):
        return ''
    return (f' in stage 1, {stage2_step_of(params):.3g} s in stage 2 (finer if its lock '
            'needs it)')


def smallest_step_of(params: UmbrellaParams) -> float:
    """Return a bound physics_step_of(params) never goes below, without the mesh's analysis."""
    ceiling, fixed = _ceiling(params)
    return ceiling if fixed else ceiling / MAX_STEP_DIVISOR


def _ceiling(params: UmbrellaParams) -> tuple[float, bool]:
    """Return the step's ceiling, and whether the step is that ceiling (no mesh divisor)."""
    ceiling = params.time_step if params.time_step > 0.0 else AUTO_STEP_CEILING
    given = params.time_step > 0.0 or params.model == NONLINEAR_AUTO_STEP
    fixed = params.model in ('rigid', 'rigid-fe') or (given and not params.step_follows_mesh)
    return ceiling, fixed


@lru_cache(maxsize=32)
def _mesh_divisor(items: tuple) -> int:
    p = UmbrellaParams.from_mapping(dict(items))
    try:
        with np.errstate(all='ignore'):
            model = UmbrellaModel(p)
            k = resolving_divisor(model, p.time_step, resolved_omega_h(p),
                                  lock_amplitudes(model))
    except (ArithmeticError, ValueError):
        # parameters that make no model: building the run's says why, naming them
        return 1
    return k or min(MAX_STEP_DIVISOR, int(p.time_step / MIN_PHYSICS_STEP))


def resolving_step_hint(params: dict, needed: float | None = None) -> str:
    """
    Return how a run of these parameters gets the step that resolves its stage 2, or ''.

    needed: the step its stage 2 needs (stage2_step_needed), None if not known.
    flexible-nonlinear's step_follows_mesh takes the mesh's step and no stage-2 substeps: it
    is named only where that step is as fine as needed (a run whose modes couple, past
    COUPLING_DEFLECTION, needs a finer one: time_step alone gives it).
    """
    if params.get('model') == NONLINEAR_AUTO_STEP:
        if params.get('step_follows_mesh') or not _mesh_step_meets(params, needed):
            return ''
        return 'step_follows_mesh takes it'
    if params.get('time_step') == 0.0 or params.get('step_follows_mesh'):
        return ''
    return ('time_step 0 takes the step chosen for the mesh, and in stage 2 the step its '
            'lock needs')


def _mesh_step_meets(params: dict, needed: float | None) -> bool:
    """Tell whether the step step_follows_mesh takes for these parameters is needed or finer."""
    p = beams_record(params)
    if needed is None or p is None:       # (no model to judge: the hint as before)
        return True
    return physics_step_of(p.replace(step_follows_mesh=True)) <= needed * (1.0 + 1e-9)


def beams_record(params: dict) -> UmbrellaParams | None:
    """
    Return the UmbrellaParams of a run's parameter record with beams (flexible models).

    The record's registry names only (a summary's or a recording's carry others); None for
    a rigid model or values that make no parameters.
    """
    from .registry import SPECS

    try:
        return _beams_record(tuple(sorted((k, v) for k, v in params.items() if k in SPECS)))
    except TypeError:     # (a value that cannot be a parameter: no model to judge)
        return None


@lru_cache(maxsize=32)
def _beams_record(items: tuple) -> UmbrellaParams | None:
    try:
        p = UmbrellaParams.from_mapping(dict(items))
    except ValueError:
        return None
    return p if p.model in ('flexible', 'flexible-nonlinear') else None


def stage2_resolution(model: UmbrellaModel, q: np.ndarray, qd: np.ndarray, h: float) -> dict:
    """
    Return how well the step h resolves the stage-2 stresses of the post-lock state (q, qd).

    ``resolution_of`` the modal amplitudes of that state, with "deflection": the stage-2 tip
    deflection they can reach (``tip_crest``) over the leaf length l1 + l2, and "needed_step"
    (``stage2_step_needed``): what the 'coarse step' warning reads (summary.py), and the
    step stage 2 takes where the step is chosen for the run (``follows_lock``).
    """
    amplitudes = modal_amplitudes(model, q, qd)
    p = model.params
    out = resolution_of(model, amplitudes, h)
    out['deflection'] = tip_crest(model, amplitudes) / (p.l1 + p.l2)
    out['needed_step'] = stage2_step_needed(out, out['deflection'])
    return out


def tip_crest(model: UmbrellaModel, amplitudes: np.ndarray) -> float:
    """
    Return the largest stage-2 tip deflection these modal amplitudes can add up to (m).

    sum_i a_i |v_G(phi_i)|: a bound the stage-2 motion comes within 1-3 % of (N = 1 to 8,
    V0 = -0.2 to -1, both locks: the first mode carries ~92 % of it).
    """
    return float(np.abs(model.locked_modes[1][model.i_tip_v]) @ amplitudes)


def stage2_step_needed(resolution: dict, deflection: float) -> float | None:
    """
    Return the largest step / k that stage 2 needs at this tip deflection (over l1 + l2).

    One rule for the step a run's stage 2 takes (``follows_lock``) and for the 'coarse step'
    warning.  resolution: ``resolution_of`` at the step h.  Up to COUPLING_DEFLECTION its
    "resolving_step" (at most STRESS_SHARE_LIMIT of the crest left to unresolved modes);
    past it the modes couple: every mode carrying stage-2 stress resolved ("coupled_step")
    and at most AUTO_STEP_CEILING (COUPLING_DEFLECTION / deflection)^COUPLING_EXPONENT.
    None if no k up to MAX_STEP_DIVISOR does it.
    """
    if deflection <= COUPLING_DEFLECTION:
        return resolution['resolving_step']
    h, modes = resolution['step'], resolution['coupled_step']
    if modes is None:
        return None
    phase = AUTO_STEP_CEILING * (COUPLING_DEFLECTION / deflection) ** COUPLING_EXPONENT
    k = max(round(h / modes), math.ceil(h / phase * (1.0 - 1e-9)))
    return None if k > min(MAX_STEP_DIVISOR, int(h / MIN_PHYSICS_STEP)) else h / k


def follows_lock(params: UmbrellaParams) -> bool:
    """
    Return whether the run's stage 2 takes the step its own lock needs.

    Where the step is chosen for the run (``time_step`` 0, or ``step_follows_mesh``) and the
    model is the linear one whose stage 2 the rule was measured on (flexible): its stage 2
    steps every grid step in k equal substeps, ``stage2_step_needed`` of the lock state
    (``substeps_for``).  params: the planar model's, or the umbrella's (its planar record:
    umbrella3d/substeps3d.py judges its ribs).
    """
    params = getattr(params, 'planar', params)     # (the umbrella's: its planar record's)
    return (isinstance(params, UmbrellaParams) and params.model == 'flexible'
            and not _ceiling(params)[1])


def stage2_substeps_for(grid: float, base: float, needed: float | None) -> int:
    """
    Return the physics steps a stage-2 grid step takes: its base's (``stage2_step_of``) ...

    ... times those the base step takes for the step its lock needs (``substeps_for``:
    needed, judged at the base step).
    """
    return round(grid / base) * substeps_for(base, needed)


def substeps_for(h: float, needed: float | None) -> int:
    """
    Return the physics steps a stage-2 grid step h takes for the step needed (1 or more).

    needed: ``stage2_step_needed`` (h / k, or None: no k up to MAX_STEP_DIVISOR does it,
    then the finest the rule allows).
    """
    if needed is not None:
        return max(1, round(h / needed))
    return max(1, min(MAX_STEP_DIVISOR, int(h / MIN_PHYSICS_STEP)))


def stage2_physics_steps(dt: float, h: float, substeps: int) -> int:
    """Return the fewest physics steps, none longer than h / substeps, that take dt (>= 1)."""
    return max(1, math.ceil(dt / (h / substeps) * (1.0 - 1e-9)))


def resolution_of(model: UmbrellaModel, amplitudes: np.ndarray, h: float) -> dict:
    """
    Return how well the step h resolves the stage-2 stresses of these modal amplitudes.

    {"step": h, "leaf": share, "link": share (unresolved_stress_share), "resolving_step":
    the largest h / k meeting STRESS_SHARE_LIMIT (h itself if it does; None if no k up to
    MAX_STEP_DIVISOR does), "coupled_step": the largest h / k that leaves no mode carrying
    stage-2 stress unresolved (what a stage 2 past COUPLING_DEFLECTION needs; None as
    resolving_step)}.
    """
    limit = resolved_omega_h(model.params)
    stresses = mode_stresses(model)
    k = resolving_divisor(model, h, limit, amplitudes, stresses=stresses)
    k_all = resolving_divisor(model, h, limit, amplitudes, share_limit=0.0, stresses=stresses)
    return {'step': h, **unresolved_stress_share(model, amplitudes, h, limit, stresses),
            'resolving_step': None if k is None else h / k,
            'coupled_step': None if k_all is None else h / k_all}
