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
~(omega h)^2 / 12, is removed from the locked frame's resolved modes
(``ModalPhaseCorrection``: the frequency pre-warping of the bilinear transform): over 0.5 s of
stage 2 the modes at 1-5e3 rad/s (a few mm at the tip) otherwise drift out of phase at any
real-time step.

The product path is the compiled kernel (``_kernel.c``, loaded with ctypes; installation
requires a C compiler): ``CompiledKernel.advance`` runs many steps and their outputs per call,
on banded + arrow linear algebra whose cost grows linearly with the mesh.
``UMBRELLA_SIM_KERNEL=numpy`` selects the numpy implementation below, the reference the tests
compare the kernel against step by step.

``rk4`` for the closed-form rigid model lives in ``rigid.RigidMechanism.rk4_step``.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass, replace
import glob
import math
import os

import numpy as np
from scipy.linalg.lapack import dgetrf, dgetrs, dpotrf, dpotrs

from .model import ConstraintSet, UmbrellaModel
from .outputs import build_frozen

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


#: modes whose period the stage-2 correction makes exact: omega h at most this, i.e. modes the
#: step samples at least ~4 times a period (pi / 2 = 1.57).  Beyond, the modal mass that makes
#: the period exact falls fast (to 0 at omega h = pi): 65 % of the mode's at 1.5, 17 % at 2.5.
#: A sampling rule, not a fit: over the 12 cases of the step study (docs/validation.md) at
#: 0.1 ms, limits 0.5, 0.7, 1.0 put the tip series at up to 2-4 mm, and the number of cases
#: whose stage-2 peaks are within 3 % moves non-monotonically with the limit (0.5 .. 3.0:
#: 5, 6, 6, 9 at 1.5, then 7, 7, 11, 8, 8), as a crest of modes the step does not resolve
#: happens to line up or not.
PHASE_CORRECTION_LIMIT = 1.5


class ModalPhaseCorrection:
    """
    The stage-2 midpoint rule with the locked frame's resolved modes at their exact period.

    The midpoint rule turns a mode x'' = -omega^2 x by Omega h per step, with
    tan(Omega h / 2) = omega h / 2: the period grows by ~(omega h)^2 / 12 (2e-3 at 1.6e3 rad/s
    and 0.1 ms, a radian of phase over 0.5 s).  Giving the mode the modal mass
    (omega / omega')^2, omega' = 2 / h tan(omega h / 2), instead of 1 (mass-normalised) makes
    Omega = omega: the frequency pre-warping of the bilinear transform (Tustin), put into the
    mass rather than the stiffness, so that a mode's quasi-static response (what the frame's
    large, nonlinear motion drives at low frequency) keeps its stiffness; pre-warping the
    stiffness instead stiffens it by (omega' / omega)^2 - 1, which at 0.1 ms put the tip series
    of V0 = -0.5 off by up to 2.3 mm where the mass version keeps 1.2 mm (docs/validation.md).
    The modes are those of the locked frame linearised at full deployment
    (``UmbrellaModel.locked_modes``, mass-normalised phi), for omega h <=
    PHASE_CORRECTION_LIMIT; the kinetic energy gains

        1/2 v^T D v,   D = U diag(d) U^T,   U = M0 phi,   d_i = (omega_i / omega'_i)^2 - 1,

    d_i in (-1, 0], ~ -(omega_i h)^2 / 6: the momentum is (M(q) + D) v, and the scheme keeps
    its exact balance of T + 1/2 v^T D v + V (the correction vanishes as h -> 0: consistent,
    still second order).  Reported: the kinetic energy T, and the correction's 1/2 v^T D v
    less its value just after the lock in the strain energy, so that the energy figures are
    continuous through the lock.  The grid step h is the simulator's: the lock's part step
    uses it too.  For the linear strain only (engines' ``phase_correctable``): with the von
    Karman strain the axial coordinates follow the foreshortening of the bending, far from the
    linearisation.
    """

    def __init__(self, model: UmbrellaModel, h: float):
        omega, phi, mass = model.locked_modes
        keep = omega * h <= PHASE_CORRECTION_LIMIT
        self.omega = omega[keep]
        # rows u_i = (M0 phi_i)^T and phi_i^T, C-contiguous for the kernel
        self.modes = np.ascontiguousarray((mass @ phi[:, keep]).T)
        self.shapes = np.ascontiguousarray(phi[:, keep].T)
        self.mass_change = (self.omega / (2.0 / h * np.tan(0.5 * h * self.omega))) ** 2 - 1.0
        self.lock_energy: float | None = None   # 1/2 v^T D v just after the lock; None: inactive

    def start(self, v_lock: np.ndarray) -> None:
        self.lock_energy = self.energy(v_lock)

    def momentum(self, v: np.ndarray) -> np.ndarray:
        """Return D v, the correction's share of the momentum."""
        return self.modes.T @ (self.mass_change * (self.modes @ v))

    def energy(self, v: np.ndarray) -> float:
        """Return 1/2 v^T D v (<= 0)."""
        eta = self.modes @ v
        return float(0.5 * (self.mass_change * eta) @ eta)

    def newton_update(self, dq: np.ndarray, h: float) -> np.ndarray:
        """
        Return the Newton update dq with the correction's share of the tangent put back.

        The iteration matrix leaves D out; in the modes' coordinates its block is
        1 + h^2 omega^2 / 4 where the tangent's is 1 + d + h^2 omega^2 / 4, so each modal
        component of dq is scaled by their ratio (Woodbury for M0-orthonormal modes).  Only
        how Newton converges changes, not to what.  The compiled kernel does the Woodbury on
        its factored matrix of a recent step instead (_kernel.c phase_correction_prepare):
        where the frame has moved from the linearisation the modes alone cost ~0.6 Newton
        iterations a stage-2 step more at omega h ~ 1.5.
        """
        quarter = 0.25 * h * h
        d = self.mass_change
        shrink = d / (1.0 + quarter * self.omega ** 2 + d)
        return dq - self.shapes.T @ (shrink * (self.modes @ dq))


class ConvergenceError(RuntimeError):
    pass


@dataclass(frozen=True)
class DynamicState:
    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    multipliers: np.ndarray
    momentum: np.ndarray | None = None   # M(q) qd, carried to the next step when known
    dissipation: float = 0.0    # energy removed by structural damping since t = 0 (J)


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
    v1: np.ndarray       # 2 dq / h - v0
    mass1: np.ndarray    # M(q)
    phi: np.ndarray      # Phi(q)
    g_t: np.ndarray      # Gonzalez gradient of 1/2 v0^T M(q) v1
    g_y: np.ndarray      # Gonzalez gradient of the sleeve height y_H
    jac_m: np.ndarray    # Gonzalez constraint Jacobian between q0 and q


def midpoint_iterate(m: UmbrellaModel, cs: ConstraintSet, q0, v0, p0, phi0, y0, q,
                     h: float) -> MidpointIterate:
    """
    Return the pieces of the midpoint residual at the iterate q.

    The residual of the step is M(q) v1 - M(q0) v0 - h [G_T - G_U - F_H G_y + G_Phi^T lam]
    (+ damping); G_T, G_y, G_Phi are Gonzalez discrete gradients of f(q) = 1/2 v0^T M(q) v1,
    y_H(q) and Phi(q) between q0 and q (dq . G_f = f(q) - f(q0) exactly).  p0 = M(q0) v0
    also gives f(q0) = 1/2 p0 . v1.  One place for MidpointDAE and the elastic integrator.
    """
    dq = q - q0
    dd = dq @ dq
    qm = q0 + 0.5 * dq
    v1 = 2.0 * dq / h - v0
    mass1 = m.mass_matrix(q)
    phi = m.constraint_residual(q, cs)
    g_t = _gonzalez(m.kinetic_bilinear_gradient(qm, v0, v1), 0.5 * (v0 @ mass1 - p0) @ v1,
                    dq, dd)
    g_y = _gonzalez(m.sleeve_height_gradient(qm), m.sleeve_height(q) - y0, dq, dd)
    jac_m = m.constraint_jacobian(qm, cs)
    if dd > 0.0:
        jac_m += np.outer((phi - phi0 - jac_m @ dq) / dd, dq)
    return MidpointIterate(dq, qm, v1, mass1, phi, g_t, g_y, jac_m)


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


def corrected_momentum(mass: np.ndarray, v: np.ndarray,
                       pc: "ModalPhaseCorrection | None") -> np.ndarray:
    """Return the step's momentum M v, plus the stage-2 phase correction's D v if pc."""
    p = mass @ v
    return p if pc is None else p + pc.momentum(v)


def project_keeping_energy(mass: np.ndarray, jac: np.ndarray, v: np.ndarray,
                           t_target: float, pc: "ModalPhaseCorrection | None" = None):
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
    pc: the stage-2 phase correction acting, whose constant D the kinetic energy of the
    balance includes (corrected_momentum); the projection's metric stays M.
    None if M is not positive definite.
    """
    jv = jac @ v
    vp = v
    if np.max(np.abs(jv)) > 0.0:
        chol, info = dpotrf(mass, lower=False)
        if info != 0:
            return None
        x = dpotrs(chol, jac.T)[0]
        vp = v - x @ np.linalg.solve(jac @ x, jv)
    t_after = 0.5 * (vp @ corrected_momentum(mass, vp, pc))
    limit = ENERGY_RESTORE_LIMIT
    if t_after > 0.0 and t_after / limit <= t_target <= limit * t_after:
        vp = vp * math.sqrt(t_target / t_after)
    return vp


class MidpointDAE:
    def __init__(self, model: UmbrellaModel, tolerance: float = NEWTON_TOLERANCE,
                 max_iterations: int = 25,
                 kernel: str | None = None):
        self.model = model
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.iterations = 0  # Newton iterations done, for diagnostics
        self.phase_correction: ModalPhaseCorrection | None = None   # stage 2, once locked
        kernel = kernel or os.environ.get("UMBRELLA_SIM_KERNEL", "auto")
        if kernel not in ("auto", "compiled", "numpy"):
            raise ValueError(f"UMBRELLA_SIM_KERNEL={kernel!r}: must be auto, compiled or numpy")
        self._compiled = None
        if kernel != "numpy":
            lib = load_kernel()
            if lib is None:
                raise RuntimeError("the compiled kernel umbrella_sim/_kernel*.so is not built: "
                                   "reinstall (python3 bootstrap.py setup; it needs a C "
                                   "compiler), or set UMBRELLA_SIM_KERNEL=numpy for the slow "
                                   "numpy reference path")
            self._compiled = CompiledKernel(lib, model)

    @property
    def backend(self) -> str:
        return "compiled" if self._compiled is not None else "numpy"

    def correct_stage2_phase(self, h: float) -> None:
        """Use ``ModalPhaseCorrection`` for grid step h in stage 2 (from ``lock_at`` on)."""
        self.phase_correction = ModalPhaseCorrection(self.model, h)

    def lock_at(self, v: np.ndarray) -> None:
        """Start stage 2's phase correction (if any) from the velocity just after the lock."""
        pc = self.phase_correction
        if pc is not None:
            pc.start(v)
            if self._compiled is not None:
                self._compiled.set_phase_correction(pc)

    def stage2_correction(self, cs: ConstraintSet) -> "ModalPhaseCorrection | None":
        """Return the phase correction acting under cs (stage 2, from the lock), else None."""
        pc = self.phase_correction
        if pc is None or pc.lock_energy is None or not cs.locked or cs.rigid:
            return None
        return pc

    def momentum(self, q: np.ndarray, qd: np.ndarray, cs: ConstraintSet) -> np.ndarray:
        """Return the step's momentum: M(q) qd, plus D qd of the stage-2 phase correction."""
        return corrected_momentum(self.model.mass_matrix(q), qd, self.stage2_correction(cs))

    def _start_momenta(self, s: DynamicState, cs: ConstraintSet):
        """
        Return (pc, p0, M(q0) v0) at the start of a step from s.

        The phase correction acting, the step's momentum p0 (the state's, or computed), and
        p0 less the correction's constant D v0: M(q0) v0 gives f(q0) = 1/2 (M(q0) v0) . v1 of
        the Gonzalez gradient G_T.
        """
        pc = self.stage2_correction(cs)
        p0 = s.momentum if s.momentum is not None else self.momentum(s.q, s.qd, cs)
        return pc, p0, p0 if pc is None else p0 - pc.momentum(s.qd)

    def strain_energy(self, q: np.ndarray, cs: ConstraintSet) -> float:
        """1/2 q.K q (the balance's V)."""
        return float(self.model.strain_energy(q))

    @property
    def kernel(self) -> "CompiledKernel | None":
        """Return the compiled multi-step path, None on the numpy path."""
        return self._compiled

    @staticmethod
    def kernel_error(status: int, t: float) -> str:
        return f"{_KERNEL_ERRORS.get(status, f'kernel status {status}')} at t = {t:.9g} s"

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
        m = self.model
        jac = m.constraint_jacobian(q, cs)
        metric = m.mass_matrix(q)
        n, nc = m.n, jac.shape[0]
        kkt = np.zeros((n + nc, n + nc))
        kkt[:n, :n] = metric
        kkt[:n, n:] = jac.T
        kkt[n:, :n] = jac
        sol = np.linalg.solve(kkt, np.concatenate([metric @ qd, np.zeros(nc)]))
        return sol[:n]

    def step(self, s: DynamicState, h: float, force: float, cs: ConstraintSet) -> DynamicState:
        if self._compiled is not None:
            out, its = self._compiled.step(s, h, force, cs, self.tolerance, self.max_iterations)
            self.iterations += its
            return out
        with np.errstate(over="ignore", invalid="ignore"):
            return self._step(s, h, force, cs)

    def _step(self, s: DynamicState, h: float, force: float, cs: ConstraintSet) -> DynamicState:
        """
        Take one energy-consistent midpoint step.

        With q1 = q0 + h (v0 + v1)/2, dq = q1 - q0:

            M(q1) v1 - M(q0) v0 = h [ G_T - K q_m - F_H G_y + G_Phi^T lambda ],   Phi(q1) = 0

        G_T, G_y, G_Phi are Gonzalez discrete gradients of f(q) = 1/2 v0^T M(q) v1, y_H(q)
        and Phi(q) between q0 and q1 (dq . G_f = f(q1) - f(q0) exactly), so over a step
        T1 + V1 - T0 - V0 = F_H (y_H(q0) - y_H(q1)) to the Newton tolerance: the scheme
        conserves energy (F_H = 0) or balances it against the exact work for any step
        size, also when the stiff axial modes are not resolved.  v1 is then projected
        onto J(q1) v1 = 0.
        """
        m = self.model
        n = m.n
        q0, v0 = s.q, s.qd
        half_h2 = 0.5 * h * h
        pc, p0, mass_p0 = self._start_momenta(s, cs)
        phi0 = m.constraint_residual(q0, cs)
        y0 = m.sleeve_height(q0)
        # predictor: the previous step's velocity held
        q = q0 + h * v0
        lam = s.multipliers.copy()
        stiff = m.stiffness
        lu = piv = None
        nc = len(phi0)
        rhs = np.empty(n + nc)
        last_norm = np.inf
        for it in range(1, self.max_iterations + 1):
            x = midpoint_iterate(m, cs, q0, v0, mass_p0, phi0, y0, q, h)
            resid = (corrected_momentum(x.mass1, x.v1, pc) - p0
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
                    raise ConvergenceError(f"singular iteration matrix at t = {s.t + h:.9g} s")
            rhs[:n] = -0.5 * h * resid
            rhs[n:] = -phi
            dx = dgetrs(lu, piv, rhs)[0]
            if pc is not None:
                dx[:n] = pc.newton_update(dx[:n], h)
            q = q + dx[:n]
            lam = lam + dx[n:] / half_h2
            step_norm = np.max(np.abs(dx[:n]))
            if not np.isfinite(step_norm):
                raise ConvergenceError(f"Newton iterate became non-finite at t = {s.t + h:.9g} s")
            # stop when the estimated remaining error rate/(1-rate)*|dq| is below tolerance
            rate = step_norm / last_norm if it > 1 else 1.0
            if step_norm < self.tolerance or (rate < 0.5 and rate / (1 - rate) * step_norm
                                              < self.tolerance):
                # converged in q; make sure the constraints hold at the final iterate
                if np.max(np.abs(m.constraint_residual(q, cs))) < PHI_TOLERANCE:
                    break
            last_norm = step_norm
        else:
            raise ConvergenceError(f"Newton did not converge in {self.max_iterations} iterations "
                                   f"at t = {s.t + h:.9g} s (|dq| = {np.max(np.abs(dx[:n])):.3g})")
        self.iterations += it
        v = 2.0 * (q - q0) / h - v0
        mass1 = m.mass_matrix(q)
        t_target = (0.5 * (v0 @ p0) + self.strain_energy(q0, cs) - self.strain_energy(q, cs)
                    + force * (y0 - m.sleeve_height(q)))
        v = project_keeping_energy(mass1, m.constraint_jacobian(q, cs), v, t_target, pc)
        if v is None:
            raise ConvergenceError(f"mass matrix not positive definite at t = {s.t + h:.9g} s")
        return DynamicState(s.t + h, q, v, (v - v0) / h, lam, corrected_momentum(mass1, v, pc))

    def with_constraints(self, s: DynamicState, force: float, cs: ConstraintSet) -> DynamicState:
        """Keep q, qd; return consistent q'' and lambda for another constraint set."""
        qdd, lam = self.consistent_acceleration(s.q, s.qd, force, cs)
        return replace(s, qdd=qdd, multipliers=lam, momentum=None)


# ------------------------------------------------------------------ compiled kernel
_dp, _ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)


class _ModelStruct(ctypes.Structure):
    """Mirror of ``Model`` in _kernel.c (same order)."""

    _fields_ = [(name, ctypes.c_int) for name in
                ("n", "n_link", "i_r2x", "i_r2y", "i_alpha2", "s_link", "i_u_joint",
                 "i_u_sleeve", "i_tip_u", "i_tip_v", "n_elastic", "bw", "n_stress_leaf",
                 "n_stress_link", "stress_width")] + \
               [(name, ctypes.c_double) for name in
                ("l1", "l3", "y_stop", "j0_leaf", "j0_link", "pbar0", "link_mass")] + \
               [("c_full", _dp), ("g_full", _dp), ("body", _ip), ("elastic_idx", _ip),
                ("sbar", _dp), ("isbar", _dp), ("mff_band", _dp), ("k_band", _dp),
                ("w_band", _dp), ("stress_idx", _ip), ("stress_top", _dp),
                ("stress_bottom", _dp), ("stress_x", _dp)] + \
               [("ref_leaf_point", ctypes.c_int), ("ref_link_element", ctypes.c_int),
                ("ref_link_frac", ctypes.c_double)]


#: what a compiled Sample vector holds (_kernel.c sample_vector, S_* in this order), then the
#: fibre stress at every stress point (top of every point, then bottom; leaf points first);
#: the names are the Sample's, but the sleeve reaction's two components
SAMPLE_VECTOR = ("alpha1", "alpha2", "alpha1_rate", "alpha2_rate", "sleeve_position",
                 "sleeve_velocity", "tip_axial", "tip_transverse", "peak_stress_leaf",
                 "peak_stress_leaf_x", "peak_stress_link", "peak_stress_link_x",
                 "stress_leaf_joint", "stress_link_mid", "sleeve_reaction_x",
                 "sleeve_reaction_y", "kinetic_energy", "strain_energy",
                 "constraint_residual", "phase_correction_energy")


class _AdvanceCall(ctypes.Structure):
    """Mirror of ``AdvanceCall`` in _kernel.c: umbrella_advance's arguments, kept and updated."""

    _fields_ = [("locked", ctypes.c_int), ("rigid", ctypes.c_int), ("k0", ctypes.c_long),
                ("h", ctypes.c_double), ("n_steps", ctypes.c_int), ("force", ctypes.c_double),
                ("tol", ctypes.c_double), ("phi_tol", ctypes.c_double),
                ("max_iter", ctypes.c_int), ("div_tol", ctypes.c_double),
                ("q", _dp), ("v", _dp), ("lam", _dp), ("p", _dp), ("acc", _dp), ("out", _dp),
                ("cap", ctypes.c_int), ("n_done", ctypes.c_int), ("iterations", ctypes.c_int),
                ("residual", ctypes.c_double), ("accel", _dp), ("final", _dp)]


class _SampleCall(ctypes.Structure):
    """Mirror of ``SampleCall`` in _kernel.c: umbrella_sample's arguments."""

    _fields_ = [("locked", ctypes.c_int), ("rigid", ctypes.c_int), ("q", _dp), ("v", _dp),
                ("p", _dp), ("lam", _dp), ("out", _dp)]


#: the leaf angle at which the leaf lies along the axle: a stage-1 state there is a fault
#: (_kernel.c step_taken, UmbrellaSimulator._checked, RigidEngine._check)
ALPHA1_AXLE = math.pi / 2
AXLE_REASON = ("the leaf reached the axle (alpha1 = pi/2): the frame folded back past its "
               "start (v0 > 0 or a sleeve force below 0 drove it there), where the model has "
               "no stop")
_KERNEL_ERRORS = {1: "Newton did not converge", 2: "Newton iterate became non-finite",
                  3: "singular iteration matrix", 4: "mass matrix not positive definite",
                  5: "out of memory", 8: AXLE_REASON}
#: umbrella_advance status codes that are not failures
ADVANCE_DONE, ADVANCE_CROSSING, ADVANCE_DIVERGED = 0, 6, 7
_kernel_lib = None


def load_kernel():
    """Return the compiled step, or None when it was not built (then numpy does the work)."""
    global _kernel_lib
    if _kernel_lib is None:
        here = os.path.dirname(os.path.abspath(__file__))
        found = sorted(glob.glob(os.path.join(here, "_kernel*.so")))
        _kernel_lib = False
        for path in found:
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            vp, d, i = ctypes.c_void_p, ctypes.c_double, ctypes.c_int
            lib.umbrella_new.restype = vp
            lib.umbrella_new.argtypes = [ctypes.POINTER(_ModelStruct)]
            lib.umbrella_free.restype = None
            lib.umbrella_free.argtypes = [vp]
            lib.umbrella_step.restype = i
            lib.umbrella_step.argtypes = [vp, i, i, _dp, _dp, _dp, _dp, d, d, d, d, i,
                                          _dp, _dp, _dp, _dp, _ip]
            lib.umbrella_momentum.restype = None
            lib.umbrella_momentum.argtypes = [vp, _dp, _dp, _dp]
            lib.umbrella_set_phase_correction.restype = i
            lib.umbrella_set_phase_correction.argtypes = [vp, i, _dp, _dp, d]
            lib.umbrella_set_law.restype = None
            lib.umbrella_set_law.argtypes = [vp, vp]
            lib.umbrella_advance_call.restype = i
            lib.umbrella_advance_call.argtypes = [vp, ctypes.POINTER(_AdvanceCall)]
            lib.umbrella_sample_call.restype = None
            lib.umbrella_sample_call.argtypes = [vp, ctypes.POINTER(_SampleCall)]
            lib.umbrella_find_crossing.restype = i
            lib.umbrella_find_crossing.argtypes = [vp, i, _dp, _dp, _dp, _dp, d, d, d, d, i, d,
                                                   d, _dp, _dp, _dp, _dp, _dp, _dp, _ip]
            _kernel_lib = lib
            break
    return _kernel_lib or None


def _dptr(a: np.ndarray):
    return a.ctypes.data_as(_dp)


class CompiledKernel:
    """
    Hold the model handed to _kernel.c once, and every buffer the calls use.

    Each buffer is allocated once and its ctypes pointer cached: a call converts only scalars.
    """

    def __init__(self, lib, m: UmbrellaModel, capacity: int = 64):
        self.lib = lib
        self.model = m
        n = m.n
        body = -np.ones(n, dtype=np.intc)
        body[m.s_leaf] = 0
        body[m.s_link] = 1
        bw, mff_band, k_band, w_band = m.banded_invariants()
        s_idx, s_top, s_bot, s_x, (n_leaf, n_link) = m.stress_rows()
        elastic = np.ascontiguousarray(m.elastic_indices, dtype=np.intc)
        link = m.link
        keep = {"c_full": np.zeros(n), "g_full": np.zeros(n),
                "sbar": np.ascontiguousarray(link.s_bar),
                "isbar": np.ascontiguousarray([-link.s_bar[1], link.s_bar[0]]),
                "mff_band": np.ascontiguousarray(mff_band),
                "k_band": np.ascontiguousarray(k_band), "w_band": np.ascontiguousarray(w_band),
                "stress_top": np.ascontiguousarray(s_top),
                "stress_bottom": np.ascontiguousarray(s_bot),
                "stress_x": np.ascontiguousarray(s_x)}
        keep["c_full"][m.s_leaf], keep["c_full"][m.s_link] = m.leaf.c, link.c
        keep["g_full"][m.s_leaf], keep["g_full"][m.s_link] = m.leaf.g, link.g
        ints = {"body": body, "elastic_idx": elastic,
                "stress_idx": np.ascontiguousarray(s_idx)}
        self._keep = (keep, ints)  # the struct points into these arrays
        self.struct = _ModelStruct(
            n=n, n_link=link.n_elastic, i_r2x=m.i_r2x, i_r2y=m.i_r2y, i_alpha2=m.i_alpha2,
            s_link=m.s_link.start, i_u_joint=m.i_u_joint, i_u_sleeve=m.i_u_sleeve,
            i_tip_u=m.i_tip_u, i_tip_v=m.i_tip_v, n_elastic=len(elastic), bw=bw,
            n_stress_leaf=n_leaf, n_stress_link=n_link, stress_width=s_idx.shape[1],
            l1=m.params.l1, l3=m.params.l3, y_stop=m.y_stop, j0_leaf=m.leaf.j0,
            j0_link=link.j0, pbar0=link.p_bar[0], link_mass=link.mass,
            **dict(zip(("ref_leaf_point", "ref_link_element", "ref_link_frac"),
                       m.reference_stress_points)),
            **{k: _dptr(v) for k, v in keep.items()},
            **{k: v.ctypes.data_as(_ip) for k, v in ints.items()})
        ctx = lib.umbrella_new(ctypes.byref(self.struct))
        if not ctx:
            # (umbrella_new: its buffers, or the LU of the constant elastic mass band)
            raise MemoryError("the compiled kernel could not be set up: out of memory, or a "
                              "singular elastic mass matrix")
        self._ctx = ctypes.c_void_p(ctx)
        self._free = lib.umbrella_free
        nc_max = 4 + len(elastic)
        # the state advanced in place, the last step's acceleration, then umbrella_sample of
        # the state each advance reaches (made by that call): views of one buffer, so that a
        # DynamicState of it and its Sample vector are one copy (state(), sample())
        self._points = len(m.leaf.stress_x) + len(m.link.stress_x)
        self._n, self._state_len = n, 4 * n + nc_max
        self._state_buf = np.zeros(self._state_len + len(SAMPLE_VECTOR) + 2 * self._points)
        self.q, self.v, self.p, self.accel = (self._state_buf[k * n:(k + 1) * n]
                                              for k in range(4))
        self.lam = self._state_buf[4 * n:self._state_len]
        self._final = self._state_buf[self._state_len:]
        self.acc = np.zeros(3)                     # work, lock loss, damping dissipation (J)
        self._ptr = {k: _dptr(getattr(self, k)) for k in ("q", "v", "p", "lam", "acc", "accel")}
        self._its = ctypes.c_int(0)
        ptr = self._ptr
        # the state whose copy holds its Sample vector (the last advance's), that copy's
        # vector, and the constraint set it was made with
        self._final_cs = self._final_of = self._final_copy = None
        self._call = _AdvanceCall(phi_tol=PHI_TOLERANCE, q=ptr["q"], v=ptr["v"], lam=ptr["lam"],
                                  p=ptr["p"], acc=ptr["acc"], accel=ptr["accel"],
                                  final=_dptr(self._final))
        self._call_ref = ctypes.byref(self._call)
        self._setting = None     # what _call holds besides the state and k0, n_steps
        self._set_capacity(capacity)
        self._made = None        # the DynamicState the buffers hold (see load)
        self._sample_buf = None
        # single-step outputs
        self._q1, self._v1, self._p1 = np.zeros(n), np.zeros(n), np.zeros(n)
        self._lam1 = np.zeros(nc_max)

    def __del__(self):
        ctx = getattr(self, "_ctx", None)
        if ctx is not None and ctx.value:
            self._free(ctx)
            self._ctx = None

    def set_phase_correction(self, pc: ModalPhaseCorrection) -> None:
        """Hand stage 2's phase correction to the kernel (it keeps pointers to these arrays)."""
        self._phase_correction = arrays = tuple(
            np.ascontiguousarray(a, dtype=float)
            for a in (pc.modes, pc.mass_change))
        if self.lib.umbrella_set_phase_correction(self._ctx, len(pc.mass_change),
                                                  *(_dptr(a) for a in arrays), pc.lock_energy):
            raise MemoryError("the compiled kernel could not allocate the phase correction's "
                              "Newton buffers")

    def set_elastic_law(self, law, law_ptr) -> None:
        """
        Step with the elastic law of _kernel_nonlinear.c at law_ptr (nonlinear.CompiledLaw).

        The context points at it: the law object is kept alive as ``elastic_law``.
        """
        self.lib.umbrella_set_law(self._ctx, law_ptr)
        self.elastic_law = law

    def _set_capacity(self, cap: int) -> None:
        from .outputs import STEP_FIELDS
        self.out = np.zeros((len(STEP_FIELDS), cap))
        self._out_ptr = _dptr(self.out)
        self.capacity = cap
        self._call.out, self._call.cap = self._out_ptr, cap

    def load(self, s: DynamicState, work: float, lock_loss: float) -> None:
        """Take s as the state to advance from (nothing to copy if it is the last one made)."""
        self.acc[0], self.acc[1] = work, lock_loss
        self.acc[2] = s.dissipation   # accumulated with a damped elastic law (nonlinear.py)
        if s is self._made:
            return
        self._made = None
        self.q[:] = s.q
        self.v[:] = s.qd
        self.lam[:len(s.multipliers)] = s.multipliers
        if s.momentum is not None:
            self.p[:] = s.momentum
        else:
            self.lib.umbrella_momentum(self._ctx, self._ptr["q"], self._ptr["v"], self._ptr["p"])

    def advance(self, cs: ConstraintSet, k0: int, h: float, n_steps: int, force: float,
                tol: float, max_iter: int, div_tol: float):
        """
        Take n_steps grid steps from the loaded state.

        n_steps grid steps from the loaded state; returns (status, steps done, Newton
        iterations, residual of a diverged step).  Rows are in self.out[:, :steps].
        """
        if n_steps > self.capacity:
            self._set_capacity(max(n_steps, 2 * self.capacity))
        call = self._call
        call.k0, call.n_steps = k0, n_steps
        setting = (cs.locked, cs.rigid, h, force, tol, max_iter, div_tol)
        if setting != self._setting:    # usually the same as last time: no ctypes setattr
            self._setting = setting
            (call.locked, call.rigid, call.h, call.force, call.tol, call.max_iter,
             call.div_tol) = setting
        status = self.lib.umbrella_advance_call(self._ctx, self._call_ref)
        done = call.n_done
        if done:      # _final holds the Sample outputs of the state state() makes next
            self._final_cs, self._final_of, self._final_copy = cs, None, None
        return status, done, call.iterations, call.residual

    def state(self, t: float, nc: int) -> DynamicState:
        """Return the advanced state; advancing from it next time needs no load."""
        # a read-only copy (immutable: a Sample of it shares its arrays); via bytes: setting
        # a copy's writeable flag costs as much again as the copy
        b, n = np.frombuffer(self._state_buf.tobytes()), self._n
        # once per publication: the frozen dataclass's per-field __init__ costs 3 us
        self._made = build_frozen(DynamicState, {
            "t": t, "q": b[:n], "qd": b[n:2 * n], "qdd": b[3 * n:4 * n],
            "multipliers": b[4 * n:4 * n + nc], "momentum": b[2 * n:3 * n],
            "dissipation": self.acc.item(2)})
        if self._final_cs is not None and self._final_of is None:
            self._final_of, self._final_copy = self._made, b[self._state_len:]
        return self._made

    def sample(self, s: DynamicState, cs: ConstraintSet) -> np.ndarray:
        """
        Return the Sample vector of a state with its momentum (_kernel.c umbrella_sample).

        A read-only array of its own: SAMPLE_VECTOR, then the top and bottom fibre stress at
        every stress point (leaf first).  The state an advance reached has it from that call
        (in the copy that holds the state's arrays).
        """
        if s is self._final_of and cs is self._final_cs:   # the advance that made s left it
            return self._final_copy
        if self._sample_buf is None:
            out = np.zeros(len(self._final))
            ptr = self._ptr
            # one call struct on the buffers (the state last made), one for any other state
            calls = [_SampleCall(out=_dptr(out)) for _ in range(2)]
            calls[0].q, calls[0].v, calls[0].p, calls[0].lam = (ptr["q"], ptr["v"], ptr["p"],
                                                                ptr["lam"])
            self._sample_buf = (out, calls, [ctypes.byref(c) for c in calls], [None, None])
        out, calls, refs, flags = self._sample_buf
        which = 0 if s is self._made else 1          # the buffers hold it: no conversion
        call = calls[which]
        if which:
            lam = np.zeros(len(self.lam))
            lam[:len(s.multipliers)] = s.multipliers
            arrays = [np.ascontiguousarray(a, dtype=float) for a in (s.q, s.qd, s.momentum)]
            arrays.append(lam)
            call.q, call.v, call.p, call.lam = (_dptr(a) for a in arrays)
        if flags[which] is not cs:                   # (a ctypes setattr costs ~0.2 us)
            call.locked, call.rigid = cs.locked, cs.rigid
            flags[which] = cs
        self.lib.umbrella_sample_call(self._ctx, refs[which])
        out = out.copy()
        out.flags.writeable = False
        return out

    def find_crossing(self, s: DynamicState, h: float, force: float, cs: ConstraintSet,
                      tol: float, max_iter: int, div_tol: float, event_tol: float):
        """
        Return (status, state, step length, Newton iterations, residual) of the lock instant.

        The Illinois root find of y_H = y_stop over the step length in (0, h] from s (stage
        deploying), in compiled code (_kernel.c umbrella_find_crossing).  state is the best
        trial (status 0), else None and the step length / residual of the failing trial.
        """
        q0 = np.ascontiguousarray(s.q, dtype=float)
        v0 = np.ascontiguousarray(s.qd, dtype=float)
        lam0 = np.zeros(len(self.lam))
        lam0[:len(s.multipliers)] = s.multipliers
        p0 = np.empty(len(q0))
        if s.momentum is not None:
            p0[:] = s.momentum
        else:
            self.lib.umbrella_momentum(self._ctx, _dptr(q0), _dptr(v0), _dptr(p0))
        dt, res = ctypes.c_double(0.0), ctypes.c_double(0.0)
        status = self.lib.umbrella_find_crossing(
            self._ctx, int(cs.rigid), _dptr(q0), _dptr(v0), _dptr(lam0), _dptr(p0), h, force,
            tol, PHI_TOLERANCE, max_iter, div_tol, event_tol, _dptr(self._q1), _dptr(self._v1),
            _dptr(self._lam1), _dptr(self._p1), ctypes.byref(dt), ctypes.byref(res),
            ctypes.byref(self._its))
        if status != 0:
            return status, None, dt.value, self._its.value, res.value
        v = self._v1.copy()
        state = DynamicState(s.t + dt.value, self._q1.copy(), v, (v - v0) / dt.value,
                             self._lam1[:len(s.multipliers)].copy(), self._p1.copy())
        return status, state, dt.value, self._its.value, res.value

    def step(self, s: DynamicState, h, force, cs: ConstraintSet, tol, max_iter):
        q0 = np.ascontiguousarray(s.q, dtype=float)
        v0 = np.ascontiguousarray(s.qd, dtype=float)
        lam0 = np.ascontiguousarray(s.multipliers, dtype=float)
        p0 = None if s.momentum is None else np.ascontiguousarray(s.momentum, dtype=float)
        status = self.lib.umbrella_step(
            self._ctx, int(cs.locked), int(cs.rigid), _dptr(q0), _dptr(v0),
            _dptr(lam0), None if p0 is None else _dptr(p0), h, force, tol, PHI_TOLERANCE,
            max_iter, _dptr(self._q1), _dptr(self._v1), _dptr(self._lam1), _dptr(self._p1),
            ctypes.byref(self._its))
        if status != 0:
            raise ConvergenceError(f"{_KERNEL_ERRORS.get(status, status)} at t = {s.t + h:.9g} s")
        v = self._v1.copy()
        return (DynamicState(s.t + h, self._q1.copy(), v, (v - v0) / h,
                             self._lam1[:len(lam0)].copy(), self._p1.copy()), self._its.value)
