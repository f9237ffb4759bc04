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
    from scipy.linalg.lapack import dpotrf, dpotrs     # (the numpy path's: see _step)

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
            refused = kernel_refusal()
            if lib is not None:
                self._compiled = CompiledKernel(lib, model, PHI_TOLERANCE)
            elif refused is None:
                raise RuntimeError(f"the compiled kernel {LIBRARY} is not built: reinstall "
                                   "(python3 bootstrap.py setup; it needs a C compiler), or set "
                                   "UMBRELLA_SIM_KERNEL=numpy for the slow numpy reference path")
            elif kernel == "compiled":
                raise RuntimeError(refused)
            # else a library of another interface: the numpy path (load_kernel warned)

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
        # (imported here: scipy.linalg costs a sixth of a second to import, which every run
        # on the compiled kernel would pay for a path it does not take)
        from scipy.linalg.lapack import dgetrf, dgetrs

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
