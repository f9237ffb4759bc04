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
    onto J q' = 0 in the mass metric (energy changes only to second order in an O(h^2)
    violation), so both residuals stay at round-off without Baumgarte parameters.
Each step solves the nonlinear residual with Newton's method; the iteration matrix
M + h^2/4 K + h/2 G (G the gyroscopic tangent) is factored once per step.

The step runs in a compiled kernel (``_kernel.c``, loaded with ctypes) when it was built,
else in numpy; ``UMBRELLA_SIM_KERNEL=numpy`` forces the numpy path, which is the reference
the tests compare the kernel against.

``rk4`` for the closed-form rigid model lives in ``rigid.RigidMechanism.rk4_step``.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass, replace
import glob
import os

import numpy as np
from scipy.linalg.lapack import dgetrf, dgetrs, dpotrf, dpotrs

from .model import ConstraintSet, UmbrellaModel

#: constraint residual the Newton iteration must reach before it stops (m)
PHI_TOLERANCE = 1e-11


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


def _gonzalez(grad_mid: np.ndarray, delta_f: float, dq: np.ndarray, dd: float) -> np.ndarray:
    """Discrete gradient: grad f(q_m) corrected along dq so that dq . G = f(q1) - f(q0)."""
    if dd == 0.0:
        return grad_mid
    return grad_mid + ((delta_f - grad_mid @ dq) / dd) * dq


class MidpointDAE:
    def __init__(self, model: UmbrellaModel, tolerance: float = 1e-10, max_iterations: int = 25,
                 kernel: str | None = None):
        self.model = model
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.iterations = 0  # Newton iterations done, for diagnostics
        kernel = kernel or os.environ.get("UMBRELLA_SIM_KERNEL", "auto")
        if kernel not in ("auto", "compiled", "numpy"):
            raise ValueError(f"UMBRELLA_SIM_KERNEL={kernel!r}: must be auto, compiled or numpy")
        self._compiled = None
        if kernel != "numpy":
            lib = load_kernel()
            if lib is None and kernel == "compiled":
                raise RuntimeError("the compiled kernel umbrella_sim/_kernel*.so is not built")
            if lib is not None:
                self._compiled = _CompiledStep(lib, model)

    @property
    def backend(self) -> str:
        return "compiled" if self._compiled is not None else "numpy"

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
        p0 = s.momentum if s.momentum is not None else m.mass_matrix(q0) @ v0
        # p0 = M(q0) v0 also gives f(q0) = 1/2 p0 . v1
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
            dq = q - q0
            dd = dq @ dq
            qm = q0 + 0.5 * dq
            v1 = 2.0 * dq / h - v0
            mass1 = m.mass_matrix(q)
            phi = m.constraint_residual(q, cs)
            g_t = _gonzalez(m.kinetic_bilinear_gradient(qm, v0, v1),
                            0.5 * (v0 @ mass1 - p0) @ v1, dq, dd)
            g_y = _gonzalez(m.sleeve_height_gradient(qm), m.sleeve_height(q) - y0, dq, dd)
            jac_m = m.constraint_jacobian(qm, cs)
            if dd > 0.0:
                jac_m += np.outer((phi - phi0 - jac_m @ dq) / dd, dq)
            resid = (mass1 @ v1 - p0
                     - h * (g_t - stiff @ qm - force * g_y + jac_m.T @ lam))
            if lu is None:
                jac = m.constraint_jacobian(q, cs)
                it_mat = np.zeros((n + nc, n + nc))
                it_mat[:n, :n] = (mass1 + 0.25 * h * h * stiff
                                  + 0.5 * h * m.gyroscopic_matrix(qm, dq / h))
                it_mat[:n, n:] = -jac_m.T
                it_mat[n:, :n] = jac
                lu, piv, info = dgetrf(it_mat, overwrite_a=True)
                if info != 0:
                    raise ConvergenceError(f"singular iteration matrix at t = {s.t + h:.9g} s")
            rhs[:n] = -0.5 * h * resid
            rhs[n:] = -phi
            dx = dgetrs(lu, piv, rhs)[0]
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
        # velocity projection onto J(q1) v = 0 in the mass metric: the violation is O(h^2)
        # and the energy it removes second order in it (another metric would change the
        # energy to first order)
        jac = m.constraint_jacobian(q, cs)
        jv = jac @ v
        mass1 = m.mass_matrix(q)
        if np.max(np.abs(jv)) > 0.0:
            chol, info = dpotrf(mass1, lower=False)
            if info != 0:
                raise ConvergenceError(f"mass matrix not positive definite at t = {s.t + h:.9g} s")
            x = dpotrs(chol, jac.T)[0]
            v = v - x @ np.linalg.solve(jac @ x, jv)
        return DynamicState(s.t + h, q, v, (v - v0) / h, lam, mass1 @ v)

    def with_constraints(self, s: DynamicState, force: float, cs: ConstraintSet) -> DynamicState:
        """Keep q, qd; return consistent q'' and lambda for another constraint set."""
        qdd, lam = self.consistent_acceleration(s.q, s.qd, force, cs)
        return replace(s, qdd=qdd, multipliers=lam, momentum=None)


# ------------------------------------------------------------------ compiled kernel
class _ModelStruct(ctypes.Structure):
    _fields_ = [(name, ctypes.c_int) for name in
                ("n", "n_link", "i_r2x", "i_r2y", "i_alpha2", "s_link", "i_u_joint",
                 "i_u_sleeve", "n_elastic")] + \
               [(name, ctypes.c_double) for name in
                ("l1", "l3", "y_stop", "j0_leaf", "j0_link", "pbar0")] + \
               [(name, ctypes.POINTER(ctypes.c_double)) for name in
                ("c_full", "g_full", "mff_full", "w_full")] + \
               [("body", ctypes.POINTER(ctypes.c_int))] + \
               [(name, ctypes.POINTER(ctypes.c_double)) for name in
                ("sbar", "isbar", "mass_template", "stiffness")] + \
               [("elastic_idx", ctypes.POINTER(ctypes.c_int))]


_KERNEL_ERRORS = {1: "Newton did not converge", 2: "Newton iterate became non-finite",
                  3: "singular iteration matrix", 4: "mass matrix not positive definite",
                  5: "out of memory"}
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
            dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
            lib.umbrella_step.restype = ctypes.c_int
            lib.umbrella_step.argtypes = [ctypes.POINTER(_ModelStruct), ctypes.c_int, ctypes.c_int,
                                          dp, dp, dp, dp, ctypes.c_double, ctypes.c_double,
                                          ctypes.c_double, ctypes.c_double, ctypes.c_int,
                                          dp, dp, dp, dp, ip]
            _kernel_lib = lib
            break
    return _kernel_lib or None


def _dptr(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class _CompiledStep:

    def __init__(self, lib, m: UmbrellaModel):
        self.lib = lib
        self.model = m
        body = -np.ones(m.n, dtype=np.intc)
        body[m.s_leaf] = 0
        body[m.s_link] = 1
        keep = dict(  # noqa: C408 (keyword names are the kernel's arguments)
            c_full=np.ascontiguousarray(m._c_full), g_full=np.ascontiguousarray(m._g_full),
            mff_full=np.ascontiguousarray(m._mff_full), w_full=np.ascontiguousarray(m._w_full),
            sbar=np.ascontiguousarray(m._link_sbar), isbar=np.ascontiguousarray(m._link_isbar),
            mass_template=np.ascontiguousarray(m._mass_template),
            stiffness=np.ascontiguousarray(m.stiffness))
        self._keep = keep  # the struct points into these arrays
        self._body = body
        self._elastic = np.ascontiguousarray(m.elastic_indices, dtype=np.intc)
        ip = ctypes.POINTER(ctypes.c_int)
        self.struct = _ModelStruct(
            n=m.n, n_link=m.link.n_elastic, i_r2x=m.i_r2x, i_r2y=m.i_r2y, i_alpha2=m.i_alpha2,
            s_link=m.s_link.start, i_u_joint=m.i_u_joint, i_u_sleeve=m.i_u_sleeve,
            n_elastic=len(self._elastic), l1=m.params.l1, l3=m.params.l3, y_stop=m.y_stop,
            j0_leaf=m.leaf.j0, j0_link=m.link.j0, pbar0=m.link.p_bar[0],
            body=body.ctypes.data_as(ip), elastic_idx=self._elastic.ctypes.data_as(ip),
            **{k: _dptr(v) for k, v in keep.items()})
        self._its = ctypes.c_int(0)

    def step(self, s: DynamicState, h, force, cs: ConstraintSet, tol, max_iter):
        n = self.model.n
        q0 = np.ascontiguousarray(s.q, dtype=float)
        v0 = np.ascontiguousarray(s.qd, dtype=float)
        lam0 = np.ascontiguousarray(s.multipliers, dtype=float)
        p0 = None if s.momentum is None else np.ascontiguousarray(s.momentum, dtype=float)
        q, v, p1 = np.empty(n), np.empty(n), np.empty(n)
        lam = np.empty(len(lam0))
        status = self.lib.umbrella_step(
            ctypes.byref(self.struct), int(cs.locked), int(cs.rigid), _dptr(q0), _dptr(v0),
            _dptr(lam0), None if p0 is None else _dptr(p0), h, force, tol, PHI_TOLERANCE,
            max_iter, _dptr(q), _dptr(v), _dptr(lam), _dptr(p1), ctypes.byref(self._its))
        if status != 0:
            raise ConvergenceError(f"{_KERNEL_ERRORS.get(status, status)} at t = {s.t + h:.9g} s")
        return DynamicState(s.t + h, q, v, (v - v0) / h, lam, p1), self._its.value
