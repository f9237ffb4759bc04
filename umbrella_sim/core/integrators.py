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
Time integrator for the constrained equations of motion: ``MidpointDAE``.

An implicit midpoint rule with discrete gradients on the index-3 DAE (4.87 / 4.118 / 4.119).
Why this scheme:
  * the axial and high bending modes of the beam elements (up to ~3e5 rad/s at N = 8) make
    any explicit scheme, including the thesis's Runge-Kutta-Nystrom (5.7-5.9), step at
    ~1e-5 s; the midpoint rule is A-stable, so the step is set by the accuracy of the modes
    that matter (deployment, first bending modes at ~20-130 Hz), not by the stiffest one;
  * it adds no numerical damping, and with Gonzalez discrete gradients of the kinetic
    energy, the constraints and the sleeve height it conserves T + V (or balances it
    against the exact work of F_H) for any step, also when the stiff axial modes are not
    resolved.  A plain trapezoidal Newmark rule drifted by 0.4 % over 1 s of stage 2 here,
    the plain midpoint rule by 0.1 %: the unresolved stiff modes drive alpha' through
    the constraints and the kinetic energy is not quadratic in q;
  * positions satisfy Phi(q) = 0 at every step (index 3), and the velocities are projected
    onto J q' = 0 in the mass metric and scaled to the kinetic energy of the discrete energy
    balance (``project_keeping_energy``), so both residuals stay at round-off without
    Baumgarte parameters, and energy is balanced to round-off, not to the Newton tolerance.
Each step solves the nonlinear residual with Newton's method; the iteration matrix
M + h^2/4 K + h/2 G (G the gyroscopic tangent) is factored once per step.

In stage 2 the midpoint rule's one systematic error, the period of every mode lengthened by
~(omega h)^2 / 12 (and its damping ratio scaled by sin(Omega h) / (Omega h), Omega h =
2 arctan(omega h / 2) its turn a step), is removed from the locked frame's resolved modes
(``LockedModeFit``: each mode exact in phase, amplitude and damping, the physical energy
still conserved): over 0.5 s of stage 2 the modes at 1-5e3 rad/s (a few mm at the tip)
otherwise drift out of phase at any real-time step.

The product path is the compiled kernel (``_kernel.c``, bound by kernel.py; installation
requires a C compiler): ``CompiledKernel.advance`` runs many steps and their outputs per call,
on banded + arrow linear algebra whose cost grows linearly with the mesh.
``UMBRELLA_SIM_KERNEL=numpy`` selects the numpy implementation below, the reference the tests
compare the kernel against step by step; so does a library that does not match its header
(kernel.load_kernel refuses it, with a warning).

``rk4`` for the closed-form rigid model lives in ``rigid.RigidMechanism.rk4_step``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
import os

import numpy as np

from .kernel import (CompiledKernel, ConvergenceError, DynamicState, kernel_error, kernel_refusal,
                     LIBRARY, load_kernel)
from .lock import plastic_velocity
from .model import ConstraintSet, UmbrellaModel

#: constraint residual the Newton iteration must reach before it stops (m)
PHI_TOLERANCE = 1e-11

#: Newton stops when the estimated remaining error of q (max norm: m, rad) is below the
#: tolerance: NEWTON_TOLERANCE unless the engine sets newton_tolerance(h) for its step
NEWTON_TOLERANCE = 1e-10


def newton_tolerance(h: float) -> float:
    """
    Return the Newton tolerance for the step h (s): 1e-8 (h / 1e-4)^3 within [1e-10, 1e-8].

    It follows a step's own error, which grows like h^3 (the midpoint rule's local error,
    ~(omega h)^3 / 12 of a mode's amplitude: ~1e-7 m at 0.1 ms), and stays an order below it;
    1e-10, the floor, is the tolerance of the fine-step studies (below ~22 us).  What
    decides it is the error it leaves in a run, which tests/test_time_step.py measures: a
    0.35 s tip series through the lock moves by ~1e-3 of what halving the step changes,
    the same with 1e-9 or 1e-8 (the lock instant and round-off set that floor), while 1e-8
    spares the third Newton iteration in most stage-2 steps that needed one (N = 2,
    V0 = -0.2: 2.16 -> 2.04 a step; 1e-10 needed one in 40 % of them).  The energy balance
    is exact to round-off whatever the Newton error (the velocity scaling).
    """
    return min(1e-8, max(NEWTON_TOLERANCE, 1e-8 * (h / 1e-4) ** 3))


#: what integrates a run, for its recording: a re-simulation by an integrator of another
#: revision differs in the physics (here: stage 2, whose modified modal masses of earlier
#: revisions became the mode fit; the umbrella's moving bases, which took no fit and the
#: unfitted step before; a step whose joints did not hold after the update that converged in
#: q, which took a whole iteration more before the joints' correction: within the Newton
#: tolerance, above --resimulate's; the umbrella's stage-2 velocity projected in the metric
#: of M(q) at every step before its projection was kept with the iteration matrix: ~1e-6 of
#: the stage-2 tips and peaks), not in round-off
INTEGRATOR_REVISION = ('midpoint-dae, stage-2 locked-mode fit (on a moving base too), stage-2 '
                       'substeps past the coupling deflection (the umbrella of N ribs too), '
                       "a correction of the joints alone after Newton's convergence in q (the "
                       "hub fixed), the umbrella's stage-2 projection kept with its iteration "
                       'matrix (the hub fixed)')

#: modes the stage-2 fit makes exact: omega h at most this, i.e. modes the step samples at
#: least ~4 times a period (pi / 2 = 1.57).  Beyond, the scheme's modal mass s^2 that makes
#: the period exact falls fast (to 0 at omega h = pi, the Nyquist limit): s^2 = 0.65 at 1.5,
#: 0.17 at 2.5.  A mode past it is not resolved by the step, whatever the scheme: the
#: stage-2 stress check (summary.stage2_resolution) says how much of the stage-2 stress such
#: modes carry.
PHASE_CORRECTION_LIMIT = 1.5

#: a step this near the mode fit's own (relative) is it, for the Newton shrinks
#: (LockedModeFit.newton_shrink): the round-off of a grid step's length t_next - t
SAME_STEP = 1e-9


class LockedModeFit:
    """
    Stage 2 with the locked frame's resolved modes exact in phase, amplitude and damping.

    The midpoint rule turns an undamped mode x'' = -omega^2 x by Omega h per step, with
    tan(Omega h / 2) = omega h / 2: the period grows by ~(omega h)^2 / 12 (2e-3 at
    1.6e3 rad/s and 0.1 ms, a radian of phase over 0.5 s).  The fit integrates with a
    velocity w whose map to the physical velocity is, mode by mode, v = s w:

        S = I + Phi diag(s - 1) U^T,   U = M0 Phi,   v = S w,

    and takes the energy-consistent midpoint step (Gonzalez discrete gradients) of the
    Lagrangian 1/2 w^T S^T M(q) S w - V(q) with q' = w.  Its discrete energy is
    1/2 (S w)^T M(q) (S w) + V = T + V, the physical energy, conserved to round-off with
    F_H = 0 (and balanced against the work otherwise), for the full nonlinear frame.  On a
    mode of the locked frame the step is the midpoint rule of a modal mass s^2, stiffness
    omega^2 and damping c_w, whose eigenvalues are those of the exact flow over h when

        s^2 = (omega h)^2 / (mu+ mu-),   c_w = -s^2 (mu+ + mu-) / h,   mu = 2 tanh(lambda h / 2)

    (the midpoint rule is the Cayley map z = (1 + mu/2) / (1 - mu/2) of mu = h lambda;
    lambda+- the roots of lambda^2 + 2 zeta omega lambda + omega^2, zeta the mode's damping
    ratio c / (2 omega), c = phi^T C phi of the elastic law's damping).  Undamped:
    s = omega / omega', omega' = 2 / h tan(omega h / 2): the frequency pre-warping of the
    bilinear transform (Tustin), here put into the modal mass, with the velocity mapped back
    so that the mode's energy, hence its amplitude, is the physical one.  Damped: the decay
    per step is exactly exp(-zeta omega h) too (the plain midpoint rule scales a damping
    ratio by sin(Omega h) / (Omega h) to first order in zeta, Omega h = 2 arctan(omega h / 2)
    its turn a step: -14 % at omega h = 1).  The state the step hands on is
    physical (q, v = S w, M(q) v): the lock, the outputs and every consumer see physical
    velocities; w lives inside a step.

    The modes are those of the locked frame linearised at full deployment
    (``UmbrellaModel.locked_modes``, mass-normalised phi) with omega h <=
    PHASE_CORRECTION_LIMIT; elsewhere S = I.  Far from the linearisation the fit is still an
    energy-consistent scheme of the same order (S is constant); the closer the frame stays to
    it, the closer each mode is to exact.  The grid step h is the simulator's: the lock's
    part step uses it too.  For the linear strain only (engines' ``phase_correctable``): with
    the co-rotational strain of flexible-nonlinear the axial coordinates follow the
    foreshortening of the bending, and its large-motion stage 2 (the links buckle at V0 <= -1)
    is far from the linearisation; its step rule takes the plain limit (step_rule).
    ``of_modes`` fits given modes (the 3D umbrella's, rib by rib: umbrella3d/integrator3d.py).
    """

    def __init__(self, model: UmbrellaModel, h: float, damping: np.ndarray | None = None):
        self._fit(*model.locked_modes, h, damping)

    @classmethod
    def of_modes(cls, omega: np.ndarray, phi: np.ndarray, mass: np.ndarray, h: float,
                 damping: np.ndarray | None = None) -> 'LockedModeFit':
        """Return the fit of the modes (omega ascending, phi mass-normalised in mass)."""
        fit = cls.__new__(cls)
        fit._fit(omega, phi, mass, h, damping)
        return fit

    def _fit(self, omega, phi, mass, h, damping):
        keep = omega * h <= PHASE_CORRECTION_LIMIT
        self.step = h
        self.omega = omega[keep]
        phi = phi[:, keep]
        # rows u_i = (M0 phi_i)^T and phi_i^T, C-contiguous for the kernel
        self.modes = np.ascontiguousarray((mass @ phi).T)
        self.shapes = np.ascontiguousarray(phi.T)
        # each mode's damping coefficient (mass-normalised: 2 zeta omega)
        c = np.zeros_like(self.omega) if damping is None else np.einsum(
            'ji,jk,ki->i', phi, damping, phi)
        self.damping_ratio = c / (2.0 * self.omega)
        zeta = self.damping_ratio.astype(complex)
        root = np.sqrt(zeta ** 2 - 1.0)
        mu = [2.0 * np.tanh(0.5 * h * self.omega * (-zeta + sign * root)) for sign in (1, -1)]
        self.scale = np.sqrt((self.omega * h) ** 2 / (mu[0] * mu[1]).real)     # s
        #: the scheme's modal damping less the law's: c_w - c (0 undamped)
        self.damping_change = -self.scale ** 2 * (mu[0] + mu[1]).real / h - c
        self.mass_change = self.scale ** 2 - 1.0            # s^2 - 1, in (-1, 0]
        self.active = False                                 # from the lock on

    def to_scheme(self, v: np.ndarray) -> np.ndarray:
        """Return w = S^-1 v."""
        return v + self.shapes.T @ ((1.0 / self.scale - 1.0) * (self.modes @ v))

    def to_physical(self, w: np.ndarray) -> np.ndarray:
        """Return v = S w."""
        return w + self.shapes.T @ ((self.scale - 1.0) * (self.modes @ w))

    def transpose(self, p: np.ndarray) -> np.ndarray:
        """Return S^T p (a physical momentum as the scheme's)."""
        return p + self.modes.T @ ((self.scale - 1.0) * (self.shapes @ p))

    def damping_force(self, dq: np.ndarray, h: float) -> np.ndarray:
        """Return the fit's share of the damping force at w_m = dq / h: U diag(c_w - c) U^T w_m."""
        return self.modes.T @ (self.damping_change * (self.modes @ dq)) / h

    def newton_update(self, dq: np.ndarray, h: float) -> np.ndarray:
        """
        Return the Newton update dq with the fit's share of the tangent put back, mode by mode.

        The iteration matrix leaves S^T M S - M and the damping change out; in the modes'
        coordinates its block is 1 + h^2 omega^2 / 4 (+ h c / 2 damped) where the tangent's
        adds d = s^2 - 1 + h (c_w - c) / 2, so each modal component of dq is scaled by their
        ratio (newton_shrink).  Only how Newton converges changes, not to what.  The exact
        Woodbury correction of the factored matrix by U diag(d) U^T, which the modal-mass
        correction this replaced used, converges more slowly here: 2.6 Newton iterations a
        stage-2 step against 2.06 (N = 1; 2.0 without the fit).  _kernel.c mode_fit_update
        does the same.
        """
        return dq - self.shapes.T @ (self.newton_shrink(h) * (self.modes @ dq))

    def newton_shrink(self, h: float) -> np.ndarray:
        """
        Return each mode's Newton shrink d / (block + d) for a step h (newton_update).

        The step's (block and the damping's share are h's), not the fit's own: a step of
        another length (a lock's part step; a fit of substeps at the grid's step) shrunk as
        the fit's step took up to twice the iterations.  A step within SAME_STEP of the
        fit's (a grid step's length as t_next - t) takes the fit's step's shrinks, whichever
        way a run counts its steps (the compiled kernels' ``_shrink_at`` the same).
        """
        if abs(h - self.step) <= SAME_STEP * self.step:
            h = self.step
        d = self.mass_change + 0.5 * h * self.damping_change
        block = 1.0 + 0.25 * (h * self.omega) ** 2 + h * self.damping_ratio * self.omega
        return d / (block + d)


def _gonzalez(grad_mid: np.ndarray, delta_f: float, dq: np.ndarray, dd: float) -> np.ndarray:
    """Discrete gradient: grad f(q_m) corrected along dq so that dq . G = f(q1) - f(q0)."""
    if dd == 0.0:
        return grad_mid
    return grad_mid + ((delta_f - grad_mid @ dq) / dd) * dq


@dataclass(frozen=True)
class MidpointIterate:
    """The discrete-gradient pieces of the midpoint residual at a Newton iterate q."""

    dq: np.ndarray       # q - q0
    qm: np.ndarray       # midpoint q0 + dq / 2
    v1: np.ndarray       # the physical velocity at q: S w1, w1 = 2 dq / h - w0
    momentum1: np.ndarray   # the scheme's momentum S^T M(q) v1 (M(q) v1 without a fit)
    mass1: np.ndarray    # M(q)
    phi: np.ndarray      # Phi(q)
    g_t: np.ndarray      # Gonzalez gradient of 1/2 v0^T M(q) v1
    g_y: np.ndarray      # Gonzalez gradient of the sleeve height y_H
    jac_m: np.ndarray    # Gonzalez constraint Jacobian between q0 and q


@dataclass(frozen=True)
class StepStart:
    """What a step needs of its start state: v0, M(q0) v0, and the scheme's w0, S^T M v0."""

    v0: np.ndarray
    p0: np.ndarray
    w0: np.ndarray
    scheme_p0: np.ndarray
    fit: LockedModeFit | None

    def end_velocity(self, dq: np.ndarray, h: float) -> np.ndarray:
        """Return the physical velocity v1 = S w1 at the end of a step dq: w1 = 2 dq / h - w0."""
        w1 = 2.0 * dq / h - self.w0
        return w1 if self.fit is None else self.fit.to_physical(w1)

    def damping_force(self, dq: np.ndarray, h: float) -> np.ndarray | float:
        """Return the fit's share of the damping force over the step dq (0 without)."""
        return 0.0 if self.fit is None else self.fit.damping_force(dq, h)

    def newton_update(self, dq: np.ndarray, h: float) -> np.ndarray:
        """Return the Newton update with the fit's share of the tangent (LockedModeFit)."""
        return dq if self.fit is None else self.fit.newton_update(dq, h)


def step_start(v0: np.ndarray, p0: np.ndarray, fit: LockedModeFit | None) -> StepStart:
    """Return the start of a step from the physical v0 and p0 = M(q0) v0, with the fit if any."""
    if fit is None:
        return StepStart(v0, p0, v0, p0, None)
    return StepStart(v0, p0, fit.to_scheme(v0), fit.transpose(p0), fit)


def midpoint_iterate(m: UmbrellaModel, cs: ConstraintSet, q0, start: StepStart, phi0, y0, q,
                     h: float) -> MidpointIterate:
    """
    Return the pieces of the midpoint residual at the iterate q.

    The residual of the step is S^T M(q) v1 - S^T M(q0) v0 - h [G_T - G_U - F_H G_y +
    G_Phi^T lam] (+ damping), v = S w, q1 - q0 = h (w0 + w1) / 2 (S = I without
    ``LockedModeFit``); G_T, G_y, G_Phi are Gonzalez discrete gradients of
    f(q) = 1/2 v0^T M(q) v1, y_H(q) and Phi(q) between q0 and q (dq . G_f = f(q) - f(q0)
    exactly).  p0 = M(q0) v0 also gives f(q0) = 1/2 p0 . v1.  One place for MidpointDAE and
    the elastic integrator.
    """
    dq = q - q0
    dd = dq @ dq
    qm = q0 + 0.5 * dq
    fit = start.fit
    v1 = start.end_velocity(dq, h)
    mass1 = m.mass_matrix(q)
    mv1 = mass1 @ v1
    phi = m.constraint_residual(q, cs)
    g_t = _gonzalez(m.kinetic_bilinear_gradient(qm, start.v0, v1),
                    0.5 * (start.v0 @ mass1 - start.p0) @ v1, dq, dd)
    g_y = _gonzalez(m.sleeve_height_gradient(qm), m.sleeve_height(q) - y0, dq, dd)
    jac_m = m.constraint_jacobian(qm, cs)
    if dd > 0.0:
        jac_m += np.outer((phi - phi0 - jac_m @ dq) / dd, dq)
    return MidpointIterate(dq, qm, v1, mv1 if fit is None else fit.transpose(mv1), mass1, phi,
                           g_t, g_y, jac_m)


def iteration_blocks(m: UmbrellaModel, cs: ConstraintSet, x: MidpointIterate, h: float,
                     elastic_tangent: np.ndarray):
    """
    Return (A, Jc) of the Newton iteration matrix [[A, -Jc^T], [J(q), 0]] at the iterate x.

    elastic_tangent: the elastic forces' part, h^2/4 K for the linear law (the elastic
    integrator of nonlinear.py passes its own).  The exact tangent is A = M(q) +
    elastic_tangent + h/2 G(qm, dq/h), Jc = the Gonzalez Jacobian (J(qm) + corr dq^T).
    For the flexible model two small terms are left out: the gyroscopic elastic-elastic
    blocks G_ee = -2 w W (w = alpha' of the body; |h w| ~ 1e-3 against the unit scale of
    M + h^2/4 K) and the Gonzalez correction corr dq^T (|dq| ~ h q').  That changes how
    Newton converges, not to what, and leaves the elastic block of the linear law's
    iteration matrix constant and its constraint columns sparse, so the compiled kernel
    factors it once per step length (SolvedBand in _kernel.c; the same matrix).  The
    rigid-FE mode keeps the exact tangent.
    """
    g = m.gyroscopic_matrix(x.qm, x.dq / h)
    if cs.rigid:
        return x.mass1 + elastic_tangent + 0.5 * h * g, x.jac_m
    for s_e in (m.s_leaf, m.s_link):
        g[s_e, s_e] = 0.0
    return x.mass1 + elastic_tangent + 0.5 * h * g, m.constraint_jacobian(x.qm, cs)


#: largest kinetic-energy ratio (before / after the projection) that is restored by scaling
ENERGY_RESTORE_LIMIT = 1.01


def project_keeping_energy(mass: np.ndarray, jac: np.ndarray, v: np.ndarray,
                           t_target: float):
    """
    Project v onto J v = 0 (mass metric) and scale it to the balance's energy.

    v projected onto J v = 0 in the mass metric, then scaled to the kinetic energy
    t_target that the discrete energy balance of the step prescribes,

    T1 = T0 + V(q0) - V(q1) + F_H (y_H(q0) - y_H(q1))      (V = 1/2 q.K q).

    After a converged step J(q1) v1 = O(h^2): the mass-metric projection removes the
    violation and with it an O(h^4) sliver of kinetic energy, every step; that sliver was the
    energy drift of the scheme (-2.3e-5 per simulated second at N = 1, 2 ms).  The scheme
    itself balances energy only to the Newton tolerance, an error per step that grows like
    1/h (the momentum residual is divided by h): at 5e-5 s it drifted 3e-6 per second.
    Scaling by sqrt(t_target / T(projected v)) keeps J v = 0 (it is linear) and makes the
    balance exact to round-off; the change of v is of the order of the projection and the
    Newton error.  Scaling is skipped when it would change T by more than 1 % (never after a
    converged step; such a state is left to the divergence checks) or T is zero.
    v and T are physical (with ``LockedModeFit``: v = S w).  None if M is not positive
    definite.
    """
    from scipy.linalg.lapack import dpotrf, dpotrs     # (the numpy path's: see _step)

    jv = jac @ v
    vp = v
    if np.max(np.abs(jv)) > 0.0:
        chol, info = dpotrf(mass, lower=False)
        if info != 0:
            return None
        x = dpotrs(chol, jac.T)[0]
        vp = v - x @ np.linalg.solve(jac @ x, jv)
    t_after = 0.5 * (vp @ (mass @ vp))
    limit = ENERGY_RESTORE_LIMIT
    if t_after > 0.0 and t_after / limit <= t_target <= limit * t_after:
        vp = vp * math.sqrt(t_target / t_after)
    return vp


def newton_converged(step_norm: float, rate: float, tolerance: float,
                     constraint_residual, correct_joints=None) -> bool:
    """
    Return whether a Newton iteration of a midpoint step has converged.

    Converged in q when the update |dq| or the estimated remaining error rate/(1-rate)*|dq|
    (rate: the contraction of the last update) is below tolerance (update_converged), and
    the constraints hold at the iterate: constraint_residual() (called only then) below
    PHI_TOLERANCE.  Converged in q but not in the joints: correct_joints() (if given) takes
    one correction of the joints alone, the iteration matrix at hand solved for the joint
    rows' -Phi with the momentum rows' right-hand side 0, and the constraints are checked
    again.  In a stage-2 step the joint rows of the kept matrix (up to CARRY_STEPS old)
    leave about 1e-10 m in the joints after the update that converges in q: a whole
    iteration more for them took 2.83 iterations a step (ribs 6 x 1, 0.1 ms), the
    correction 2.10, within the tolerance's error (a 30 ms tip series 5.5e-6 of its
    amplitude from a run at tolerance 1e-13, 1.5e-6 with the whole iteration; halving the
    step moves it 1.2e-2).  The hub fixed only: a moving base's balances are Newton's
    accuracy (a prescribed base's energy is not scaled to its balance, a free bus's momentum
    is its momentum rows' residual: the correction left a co-rotational free bus's angular
    momentum 2.7e-6 of its scale off, twice the error the whole iteration leaves).
    """
    if not update_converged(step_norm, rate, tolerance):
        return False
    if constraint_residual() < PHI_TOLERANCE:
        return True
    if correct_joints is None:
        return False
    correct_joints()
    return bool(constraint_residual() < PHI_TOLERANCE)


def joint_correction(lu, piv, n: int, phi: np.ndarray, start, h: float):
    """
    Return newton_converged's correction of the joints alone: (the q update, the rows' rest).

    The factored iteration matrix (lu, piv) solved for the joint rows' -phi with the momentum
    rows' (the first n) right-hand side 0; start.newton_update maps the q rows as an update.
    """
    from scipy.linalg.lapack import dgetrs     # (as MidpointDAE._step)
    dx = dgetrs(lu, piv, np.concatenate([np.zeros(n), -phi]))[0]
    return start.newton_update(dx[:n], h), dx[n:]


def update_converged(step_norm: float, rate: float, tolerance: float) -> bool:
    """
    Return whether a Newton iterate has converged in q (newton_converged's first half).

    The update |dq| or the estimated remaining error rate/(1-rate)*|dq| below tolerance.
    """
    return step_norm < tolerance or (rate < 0.5 and rate / (1 - rate) * step_norm < tolerance)


class MidpointDAE:
    def __init__(self, model: UmbrellaModel, tolerance: float = NEWTON_TOLERANCE,
                 max_iterations: int = 25,
                 kernel: str | None = None):
        self.model = model
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.iterations = 0  # Newton iterations done, for diagnostics
        self.mode_fit: LockedModeFit | None = None   # stage 2, once locked
        kernel = kernel or os.environ.get('UMBRELLA_SIM_KERNEL', 'auto')
        if kernel not in ('auto', 'compiled', 'numpy'):
            raise ValueError(f'UMBRELLA_SIM_KERNEL={kernel!r}: must be auto, compiled or numpy')
        self._compiled = None
        if kernel != 'numpy':
            lib = load_kernel()
            refused = kernel_refusal()
            if lib is not None:
                self._compiled = CompiledKernel(lib, model, PHI_TOLERANCE)
            elif refused is None:
                raise RuntimeError(f'the compiled kernel {LIBRARY} is not built: reinstall '
                                   '(python3 bootstrap.py setup; it needs a C compiler), or set '
                                   'UMBRELLA_SIM_KERNEL=numpy for the slow numpy reference path')
            elif kernel == 'compiled':
                raise RuntimeError(refused)
            # else a library of another interface: the numpy path (load_kernel warned)

    @property
    def backend(self) -> str:
        return 'compiled' if self._compiled is not None else 'numpy'

    def fit_stage2_modes(self, h: float) -> None:
        """Use ``LockedModeFit`` for grid step h in stage 2 (from ``lock_at`` on)."""
        self.mode_fit = LockedModeFit(self.model, h, self.locked_damping())

    def locked_damping(self) -> np.ndarray | None:
        """Return the damping matrix at full deployment (None: undamped), for the fit."""
        return None

    def lock_at(self) -> None:
        """Start stage 2's mode fit (if any): the lock has happened."""
        fit = self.mode_fit
        if fit is not None:
            fit.active = True
            if self._compiled is not None:
                self._compiled.set_mode_fit(fit)

    def stage2_fit(self, cs: ConstraintSet) -> LockedModeFit | None:
        """Return the mode fit acting under cs (stage 2, from the lock), else None."""
        fit = self.mode_fit
        if fit is None or not fit.active or not cs.locked or cs.rigid:
            return None
        return fit

    def _step_start(self, s: DynamicState, cs: ConstraintSet) -> StepStart:
        """Return the start of a step from s: the state's momentum M(q0) v0, or computed."""
        p0 = s.momentum if s.momentum is not None else self.model.mass_matrix(s.q) @ s.qd
        return step_start(s.qd, p0, self.stage2_fit(cs))

    def strain_energy(self, q: np.ndarray, cs: ConstraintSet) -> float:
        """1/2 q.K q (the balance's V)."""
        return float(self.model.strain_energy(q))

    @property
    def kernel(self) -> 'CompiledKernel | None':
        """Return the compiled multi-step path, None on the numpy path."""
        return self._compiled

    @staticmethod
    def kernel_error(status: int, t: float) -> str:
        return kernel_error(status, t)

    def consistent_acceleration(self, q, qd, force: float, cs: ConstraintSet):
        """Solve for q'' and lambda from the index-1 form [[M, -J^T], [J, 0]] (4.87)."""
        m = self.model
        n, nc = m.n, m.n_constraints(cs)
        mass, jac = m.mass_matrix(q), m.constraint_jacobian(q, cs)
        kkt = np.zeros((n + nc, n + nc))
        kkt[:n, :n] = mass
        kkt[:n, n:] = -jac.T
        kkt[n:, :n] = jac
        rhs = np.concatenate([m.quadratic_velocity_forces(q, qd) - m.stiffness @ q
                              + m.applied_forces(q, force), m.constraint_bias(q, qd, cs)])
        sol = np.linalg.solve(kkt, rhs)
        return sol[:n], sol[n:]

    def project_velocity(self, q, qd, cs: ConstraintSet):
        """Closest qd (in the mass metric) with J qd = 0 (plastic impact, Eq. 5.22 form)."""
        return plastic_velocity(self.model, q, qd, cs)

    def step(self, s: DynamicState, h: float, force: float, cs: ConstraintSet) -> DynamicState:
        if self._compiled is not None:
            out, its = self._compiled.step(s, h, force, cs, self.tolerance, self.max_iterations)
            self.iterations += its
            return out
        with np.errstate(over='ignore', invalid='ignore'):
            return self._step(s, h, force, cs)

    def _step(self, s: DynamicState, h: float, force: float, cs: ConstraintSet) -> DynamicState:
        """
        Take one energy-consistent midpoint step.

        With q1 = q0 + h (v0 + v1)/2, dq = q1 - q0:

            M(q1) v1 - M(q0) v0 = h [ G_T - K q_m - F_H G_y + G_Phi^T lambda ],   Phi(q1) = 0

        (in stage 2 with ``LockedModeFit``: in the scheme's velocity w, v = S w, and momentum
        S^T M v; midpoint_iterate)
        G_T, G_y, G_Phi are Gonzalez discrete gradients of f(q) = 1/2 v0^T M(q) v1, y_H(q)
        and Phi(q) between q0 and q1 (dq . G_f = f(q1) - f(q0) exactly), so over a step
        T1 + V1 - T0 - V0 = F_H (y_H(q0) - y_H(q1)) to the Newton tolerance: the scheme
        conserves energy (F_H = 0) or balances it against the exact work for any step
        size, also when the stiff axial modes are not resolved.  v1 is then projected
        onto J(q1) v1 = 0.
        """
        # (imported here: scipy.linalg costs a sixth of a second to import, which every run
        # on the compiled kernel would pay for a path it does not take)
        from scipy.linalg.lapack import dgetrf, dgetrs

        m = self.model
        n = m.n
        q0, v0 = s.q, s.qd
        half_h2 = 0.5 * h * h
        start = self._step_start(s, cs)
        phi0 = m.constraint_residual(q0, cs)
        y0 = m.sleeve_height(q0)
        # predictor: the previous step's velocity held (the scheme's: w0)
        q = q0 + h * start.w0
        lam = s.multipliers.copy()
        stiff = m.stiffness
        lu = piv = None
        nc = len(phi0)
        rhs = np.empty(n + nc)
        last_norm = np.inf
        for it in range(1, self.max_iterations + 1):
            x = midpoint_iterate(m, cs, q0, start, phi0, y0, q, h)
            resid = (x.momentum1 - start.scheme_p0
                     - h * (x.g_t - stiff @ x.qm - force * x.g_y + x.jac_m.T @ lam))
            phi = x.phi
            if lu is None:
                jac = m.constraint_jacobian(q, cs)
                it_mat = np.zeros((n + nc, n + nc))
                it_mat[:n, :n], jac_c = iteration_blocks(m, cs, x, h, 0.25 * h * h * stiff)
                it_mat[:n, n:] = -jac_c.T
                it_mat[n:, :n] = jac
                lu, piv, info = dgetrf(it_mat, overwrite_a=True)
                if info != 0:
                    raise ConvergenceError(f'singular iteration matrix at t = {s.t + h:.9g} s')
            rhs[:n] = -0.5 * h * resid
            rhs[n:] = -phi
            dx = dgetrs(lu, piv, rhs)[0]
            dx[:n] = start.newton_update(dx[:n], h)
            q = q + dx[:n]
            lam = lam + dx[n:] / half_h2
            step_norm = np.max(np.abs(dx[:n]))
            if not np.isfinite(step_norm):
                raise ConvergenceError(f'Newton iterate became non-finite at t = {s.t + h:.9g} s')
            rate = step_norm / last_norm if it > 1 else 1.0

            def correct_joints():
                nonlocal q, lam
                dq, dlam = joint_correction(lu, piv, n, m.constraint_residual(q, cs), start, h)
                q = q + dq
                lam = lam + dlam / half_h2
            if newton_converged(step_norm, rate, self.tolerance,
                                lambda: np.max(np.abs(m.constraint_residual(q, cs))),
                                correct_joints):
                break
            last_norm = step_norm
        else:
            raise ConvergenceError(f'Newton did not converge in {self.max_iterations} iterations '
                                   f'at t = {s.t + h:.9g} s (|dq| = {np.max(np.abs(dx[:n])):.3g})')
        self.iterations += it
        v = start.end_velocity(q - q0, h)
        mass1 = m.mass_matrix(q)
        t_target = (0.5 * (v0 @ start.p0) + self.strain_energy(q0, cs)
                    - self.strain_energy(q, cs) + force * (y0 - m.sleeve_height(q)))
        v = project_keeping_energy(mass1, m.constraint_jacobian(q, cs), v, t_target)
        if v is None:
            raise ConvergenceError(f'mass matrix not positive definite at t = {s.t + h:.9g} s')
        return DynamicState(s.t + h, q, v, (v - v0) / h, lam, mass1 @ v)

    def with_constraints(self, s: DynamicState, force: float, cs: ConstraintSet) -> DynamicState:
        """Keep q, qd; return consistent q'' and lambda for another constraint set."""
        qdd, lam = self.consistent_acceleration(s.q, s.qd, force, cs)
        return replace(s, qdd=qdd, multipliers=lam, momentum=None)
