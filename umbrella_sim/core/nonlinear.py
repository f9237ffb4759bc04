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
Geometrically nonlinear beams (thesis §7.2) and structural damping, on the same DAE.

Formulation (model ``flexible-nonlinear``)
------------------------------------------
The same floating frames, coordinates, mass matrix M(q), joints, sleeve, stop and lock as
``flexible`` (model.py); only the strain energy changes.  Per body, with u, v the axial and
transverse displacements in the body frame,

    U = 1/2 int EA eps^2 dx + 1/2 int EI v''^2 dx,      eps = u' + 1/2 v'^2

(the von Karman / foreshortening strain, exact to second order in the rotation of a fibre
relative to its floating frame).  With the linear strain u' (thesis Eq. 4.37) the bending
and axial motions uncouple in U, and a beam spinning at omega sees only the centrifugal
softening -omega^2 m_ff of the kinetic energy: the classical "premature linearisation"
failure (Kane, Ryan & Banerjee, J. Guidance Control Dynamics 10(2), 1987) -- a cantilever
spun above its first bending frequency diverges.  With the quadratic term the axial force
N = EA eps (the centrifugal tension) multiplies v'^2/2 and supplies the geometric stiffness
int N v'^2 that balances the softening.  Why this and not a co-rotational or ANCF element:
it keeps the thesis's coordinates, outputs and mass invariants (the node, recording and
replay see the same q), the strains in this frame stay small (|v'| < 0.2 even at
V0 = -2 m/s), and U is a polynomial (quartic in q), for which an exact energy-consistent
discrete gradient exists.

Membrane locking: with the thesis's shape functions (u linear, v cubic in an element) u' is
constant in an element while v'^2/2 is quartic, so a pointwise eps cannot vanish when the
element bends and inextensional bending is charged spurious axial energy (the spin-up tip
deflection came out 40 % low at 4 elements).  The axial energy therefore uses the element's
mean membrane strain, 1/2 EA l_e eps_e^2 with eps_e = (1/l_e) int (u' + v'^2/2) dx (5-point
Gauss, exact for the quartic) -- the standard cure; for small motion eps_e = u' and U is the
linear model's 1/2 q.K q exactly.  U is a quartic polynomial in q.  Its discrete gradient over
a step is the average-vector-field (AVF) gradient int_0^1 grad U(q0 + s dq) ds, exact with
2-point Gauss in s because the integrand is cubic in s; dq . AVF = U(q1) - U(q0) exactly, so
the midpoint scheme of integrators.py keeps its energy balance with the nonlinear U.  Stress
recovery: sigma = E (eps_e -/+ c v'') at both ends of every element.

Validity: the strain is exact to second order in the rotation of a fibre relative to its
floating frame, good for |v'| up to ~0.3 rad (the error of eps grows like v'^4).  Stage 1
stays inside it at every V0 of the thesis (|v'| ~ 0.2 at V0 = -2 m/s); the stage-2
vibration at V0 <= -1 m/s (tip amplitudes of 0.2-0.3 m on the 0.5 m segment O''-G) leaves
it, and there a co-rotational or geometrically exact element is the next step;
docs/validation_nonlinear.md reports max |v'| beside the figures.

Time integration: the midpoint step of MidpointDAE (the same residual pieces,
integrators.midpoint_iterate) with the AVF gradient; full Newton with a backtracking line
search (a full update can overshoot when the stiff axial directions turn with v' inside a
step), steps split in halves where Newton still fails, and MidpointDAE's velocity
projection scaled to the kinetic energy of the step's discrete balance, so the nonlinear
model balances energy to round-off.  Its stage 2 needs a finer step than the linear model's
(energy flows between modes, the unresolved ones included): see the step study in
docs/validation_nonlinear.md.

Structural damping (parameter ``damping_ratio`` zeta, models ``flexible`` and
``flexible-nonlinear``)
------------------------------------------------------------------------------------------
Stiffness-proportional Rayleigh (Kelvin-Voigt) damping of the strain rates,
Q_d = -C(q) q', C = beta B(q)^T D B(q) (B = d strain / dq, D = diag(EA, EI); C = beta K for
the linear strain), beta = 2 zeta / omega_1, with omega_1 the first natural frequency of the
locked frame linearised about the undeformed deployed configuration (stage 2).  That mode
then has exactly the ratio zeta; mode i has zeta * omega_i / omega_1 (higher modes decay
faster); rigid motion (alpha, R) is not damped.  For the nonlinear strain C must follow B(q):
beta K would damp the axial rate u' of the foreshortening u' = -v'^2/2 of inextensional
bending through the huge EA and over-damp the bending (it did: the V0 = -0.2 stage-2
amplitude fell 4x in one cycle at zeta = 0.02).  In the midpoint step the damping force is
-C(q_m) dq/h, so the step dissipates exactly dq . C(q_m) dq / h >= 0; the state carries the
dissipated energy, and the energy balance reads T + V - (T0 + V0) - W + lock loss +
dissipation = 0.

Compiled path: the kernel of integrators.py (_kernel.c, bound by kernel.py) with this
module's elastic law attached (_kernel_nonlinear.c, ``CompiledElasticLaw``): the same
arithmetic as the numpy step here, which stays as the reference the tests compare it with
step by step (UMBRELLA_SIM_KERNEL=numpy selects it).  With zeta = 0 the model ``flexible``
keeps the plain linear kernel.  Nothing here imports rclpy.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
import math

import numpy as np

from .engines import FiniteElementEngine
from .integrators import (iteration_blocks, midpoint_iterate, MidpointDAE,
                          NEWTON_TOLERANCE, PHI_TOLERANCE, project_keeping_energy)
from .kernel import ConvergenceError, DynamicState, ElasticData
from .model import (band_form, BeamBody, ConstraintSet, GAUSS_POINTS, GAUSS_WEIGHTS,
                    shape_functions, UmbrellaModel)
from .params import UmbrellaParams

NONLINEAR_MODEL = "flexible-nonlinear"
#: Newton contraction rate above which the nonlinear step re-factors its iteration matrix
#: (_kernel_elastic.h ELASTIC_REFRESH_RATE)
REFRESH_RATE = 0.1
#: A step's last iteration matrix goes on to the next step if it starts where this one
#: ended; one factored this many steps ago or less serves that step whole, an older one its
#: first iteration only (_kernel_elastic.h ELASTIC_CARRY_STEPS)
CARRY_STEPS = 2
#: 2-point Gauss-Legendre on [0, 1]: exact AVF integral of the cubic s -> grad U(q0 + s dq)
_AVF_S = 0.5 + np.array([-0.5, 0.5]) / math.sqrt(3.0)


# ------------------------------------------------------------------ strain energy
@dataclass
class _BodyDerivatives:
    du: np.ndarray     # (npts, ne): u' at points
    dv: np.ndarray     # (npts, ne): v' at points
    d2v: np.ndarray    # (npts, ne): v'' at points


def _derivatives(body: BeamBody, eta: np.ndarray) -> _BodyDerivatives:
    du, dv, d2v = [], [], []
    for j, le in enumerate(body.element_length):
        _, dn, d2n = shape_functions(eta, le)
        b = body.element_dof_maps[j]
        du.append(dn[:, 0] @ b)
        dv.append(dn[:, 1] @ b)
        d2v.append(d2n[:, 1] @ b)
    return _BodyDerivatives(np.concatenate(du), np.concatenate(dv), np.concatenate(d2v))


class StrainEnergy:
    """
    U(q) of both bodies over the whole coordinate vector q (zero on alpha, R).

    nonlinear=False gives the linear model's 1/2 q.K q through the same interface.
    """

    def __init__(self, bodies, n: int, ea: float, nonlinear: bool):
        """bodies: [(BeamBody, slice of its elastic coordinates in q)]; n = len(q)."""
        self.nonlinear = nonlinear
        du, dv, w, lengths = [], [], [], []
        self.k_linear = np.zeros((n, n))
        for body, s_e in bodies:
            d = _derivatives(body, GAUSS_POINTS)
            for src, dst in ((d.du, du), (d.dv, dv)):
                full = np.zeros((len(src), n))
                full[:, s_e] = src
                dst.append(full)
            w.append(np.outer(body.element_length, GAUSS_WEIGHTS).ravel())
            lengths.append(body.element_length)
            self.k_linear[s_e, s_e] = body.stiffness
        self.du = np.vstack(du)
        self.dv = np.vstack(dv)
        w = np.concatenate(w)
        self.element_length = np.concatenate(lengths)
        n_el, n_gauss = len(self.element_length), len(GAUSS_POINTS)
        # element mean over its Gauss points: (n_el, nq), rows w_q / l_e
        self.mean = np.zeros((n_el, n_el * n_gauss))
        for j in range(n_el):
            self.mean[j, j * n_gauss:(j + 1) * n_gauss] = w[j * n_gauss:(j + 1) * n_gauss]
        self.mean /= self.element_length[:, None]
        self.ea_l = ea * self.element_length           # EA l_e per element
        self.w_ea = ea * w                              # EA w_q per point
        self.point_element = np.repeat(np.arange(n_el), n_gauss)
        # bending (and nothing axial): K minus the axial part int EA u'^2
        self.k_bending = self.k_linear - self.du.T @ (self.w_ea[:, None] * self.du)

    def membrane_strain(self, q) -> np.ndarray:
        """Element-mean axial strain (1/l_e) int (u' + v'^2/2) dx, per element."""
        b = self.dv @ q
        return self.mean @ (self.du @ q + 0.5 * b * b)

    def energy(self, q) -> float:
        if not self.nonlinear:
            return 0.5 * q @ self.k_linear @ q
        eps = self.membrane_strain(q)
        return 0.5 * q @ self.k_bending @ q + 0.5 * float(self.ea_l @ (eps * eps))

    def _point_forces(self, q):
        b = self.dv @ q
        eps = self.mean @ (self.du @ q + 0.5 * b * b)
        return b, self.w_ea * eps[self.point_element]   # EA eps_mean w_q at every point

    def gradient(self, q) -> np.ndarray:
        if not self.nonlinear:
            return self.k_linear @ q
        b, nw = self._point_forces(q)
        return self.k_bending @ q + self.du.T @ nw + self.dv.T @ (nw * b)

    def material_tangent(self, q) -> np.ndarray:
        """
        Return B(q)^T D B(q), the tangent without the geometric stiffness.

        B(q)^T D B(q): the tangent without the geometric stiffness; the strain-rate
        (Kelvin-Voigt) damping is beta times this, so it acts on d eps/dt, never on the
        foreshortening u' = -v'^2/2 of inextensional bending.
        """
        if not self.nonlinear:
            return self.k_linear
        b = self.dv @ q
        g = self.mean @ (self.du + b[:, None] * self.dv)
        return self.k_bending + g.T @ (self.ea_l[:, None] * g)

    def tangent(self, q) -> np.ndarray:
        """
        Return the tangent d grad U / dq.

        d grad U / dq: material part g^T EA l g (g = d eps_mean / dq per element) plus
        the geometric stiffness int N v' v' (N = EA eps_mean).
        """
        if not self.nonlinear:
            return self.k_linear
        b, nw = self._point_forces(q)
        g = self.mean @ (self.du + b[:, None] * self.dv)
        return (self.k_bending + g.T @ (self.ea_l[:, None] * g)
                + self.dv.T @ (nw[:, None] * self.dv))

    def discrete_gradient(self, q0, q1) -> np.ndarray:
        """AVF gradient: dq . G = U(q1) - U(q0) exactly (2-point Gauss in s is exact)."""
        if not self.nonlinear:
            return self.k_linear @ (0.5 * (q0 + q1))
        dq = q1 - q0
        return 0.5 * (self.gradient(q0 + _AVF_S[0] * dq) + self.gradient(q0 + _AVF_S[1] * dq))

    def discrete_gradient_jacobian(self, q0, q1) -> np.ndarray:
        """
        Return d AVF / d q1.

        d AVF / d q1 = int_0^1 s H(q0 + s dq) ds (exact with the same 2 points).
        """
        if not self.nonlinear:
            return 0.5 * self.k_linear
        dq = q1 - q0
        return 0.5 * sum(s * self.tangent(q0 + s * dq) for s in _AVF_S)


# ------------------------------------------------------------------------- model
class NonlinearUmbrellaModel(UmbrellaModel):
    """
    UmbrellaModel with the nonlinear (or linear) strain energy and damping.

    UmbrellaModel with the strain energy of ``StrainEnergy`` (nonlinear or linear) and
    the matching stress recovery; the strain-rate damping of ``damping_ratio``.
    """

    def __init__(self, params: UmbrellaParams):
        super().__init__(params)
        p = self.params
        self.strain = StrainEnergy(((self.leaf, self.s_leaf), (self.link, self.s_link)), self.n,
                                   p.youngs_modulus * p.cross_section_area,
                                   nonlinear=p.model == NONLINEAR_MODEL)
        self.first_frequency = locked_first_frequency(self)
        self.damping_beta = 2.0 * p.damping_ratio / self.first_frequency
        # undamped, or damped with the linear strain: C does not depend on q
        self._constant_damping = (self.damping_beta * self.stiffness
                                  if self.damping_beta == 0.0 or not self.strain.nonlinear
                                  else None)

    def damping_matrix(self, q) -> np.ndarray:
        """
        Return C(q), the Kelvin-Voigt damping of the strain rates.

        C(q) = beta B(q)^T D B(q): Kelvin-Voigt damping of the strain rates (beta K for the
        linear strain; zero on alpha and R).
        """
        if self._constant_damping is not None:
            return self._constant_damping
        return self.damping_beta * self.strain.material_tangent(q)

    def strain_energy(self, q) -> float:
        return self.strain.energy(q)

    def elastic_force(self, q) -> np.ndarray:
        return self.strain.gradient(q)

    def stresses(self, q):
        """
        Return the top/bottom fibre stresses at both ends of every element.

        Top/bottom fibre stress E (eps -/+ c v'') with the element's membrane strain
        eps = (1/l_e) int (u' + v'^2/2) dx (the strain the energy uses) at both its ends.
        """
        (lt, lb), (kt, kb) = super().stresses(q)
        if not self.strain.nonlinear:
            return (lt, lb), (kt, kb)
        b = self.strain.dv @ q
        extra = np.repeat(self.params.youngs_modulus * (self.strain.mean @ (0.5 * b * b)), 2)
        n_leaf = len(lt)
        return ((lt + extra[:n_leaf], lb + extra[:n_leaf]),
                (kt + extra[n_leaf:], kb + extra[n_leaf:]))

    def stress_rates(self, q, qd):
        """d/dt of ``stresses``: the linear part of qd, plus E (1/l_e) int v' v'_t dx."""
        (lt, lb), (kt, kb) = super().stress_rates(q, qd)
        if not self.strain.nonlinear:
            return (lt, lb), (kt, kb)
        rate = self.strain.mean @ ((self.strain.dv @ q) * (self.strain.dv @ qd))
        extra = np.repeat(self.params.youngs_modulus * rate, 2)
        n_leaf = len(lt)
        return ((lt + extra[:n_leaf], lb + extra[:n_leaf]),
                (kt + extra[n_leaf:], kb + extra[n_leaf:]))


def locked_first_frequency(model: UmbrellaModel) -> float:
    """Return omega_1 (rad/s) of the locked frame linearised at full deployment."""
    return float(model.locked_modes[0][0])


# ------------------------------------------------------------ compiled elastic law
class CompiledElasticLaw:
    """
    The strain energy and damping of a NonlinearUmbrellaModel, handed to _kernel_nonlinear.c.

    Element by element: the q indices of an element's (up to) six coordinates, u' and v' at
    its Gauss points (rows of StrainEnergy.du / dv), the element-mean weights, EA l_e, and
    the bending stiffness in the band form of the kernel.  Attached to a CompiledKernel, it
    replaces the kernel's constant K (umbrella_set_law).
    """

    def __init__(self, lib, model: "NonlinearUmbrellaModel"):
        st, p = model.strain, model.params
        idx = np.asarray(model.elastic_indices)
        bw = model.banded_invariants()[0]
        n_el, n_gauss = len(st.element_length), len(GAUSS_POINTS)
        n_leaf_points = model.stress_rows()[4][0]
        if n_leaf_points != 2 * len(model.leaf.element_length):
            raise ValueError("compiled elastic law: the leaf's stress points are not the two "
                             "ends of each element")
        el_q = -np.ones((n_el, 6), dtype=np.intc)
        du = np.zeros((n_el, n_gauss, 6))
        dv = np.zeros((n_el, n_gauss, 6))
        for e in range(n_el):
            rows = slice(e * n_gauss, (e + 1) * n_gauss)
            cols = np.nonzero(np.any(st.du[rows] != 0.0, axis=0)
                              | np.any(st.dv[rows] != 0.0, axis=0))[0]
            el_q[e, :len(cols)] = cols
            du[e, :, :len(cols)] = st.du[rows][:, cols]
            dv[e, :, :len(cols)] = st.dv[rows][:, cols]
        el_pos = np.where(el_q >= 0, np.searchsorted(idx, np.maximum(el_q, 0)), -1)
        mean_w = np.array([st.mean[e, e * n_gauss:(e + 1) * n_gauss] for e in range(n_el)])
        arrays = {"elastic_idx": np.ascontiguousarray(idx, dtype=np.intc),
                  "kb_band": band_form(st.k_bending[np.ix_(idx, idx)], bw),
                  "el_q": el_q, "el_pos": np.ascontiguousarray(el_pos, dtype=np.intc),
                  "du": du, "dv": dv, "mean_w": mean_w,
                  "ea_l": np.ascontiguousarray(st.ea_l, dtype=float)}
        arrays = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
        self._arrays = arrays   # the struct points into these
        self.struct = ElasticData(
            n=model.n, ne=len(idx), bw=bw, n_el=n_el, n_gauss=n_gauss,
            nonlinear=int(st.nonlinear), beta=model.damping_beta,
            youngs_modulus=p.youngs_modulus,
            **{k: v.ctypes.data_as(ctypes.POINTER(
                ctypes.c_int if v.dtype == np.intc else ctypes.c_double))
               for k, v in arrays.items()})
        self.lib = lib
        ptr = lib.elastic_new(ctypes.byref(self.struct))
        if not ptr:
            raise MemoryError("the compiled elastic law could not allocate its buffers")
        self.ptr = ctypes.c_void_p(ptr)

    def attach(self, kernel) -> None:
        """Make kernel (a CompiledKernel of the same model) step with this law."""
        kernel.set_elastic_law(self, self.ptr)

    def last_dissipation(self) -> float:
        return float(self.lib.elastic_last_dissipation(self.ptr))

    def __del__(self):
        ptr = getattr(self, "ptr", None)
        if ptr is not None and ptr.value:
            self.lib.elastic_free(ptr)
            self.ptr = None


# -------------------------------------------------------------------- integrator
class ElasticMidpointDAE(MidpointDAE):
    """
    Energy-consistent midpoint step with a general strain energy and damping.

    The energy-consistent midpoint step of MidpointDAE with a general strain energy
    (AVF discrete gradient) and the damping force -C dq/h: on the compiled kernel with
    ``CompiledElasticLaw`` attached, or in numpy (kernel="numpy", the reference).
    """

    def __init__(self, model: NonlinearUmbrellaModel, tolerance: float = NEWTON_TOLERANCE,
                 max_iterations: int = 25, kernel: str | None = None):
        super().__init__(model, tolerance, max_iterations, kernel)
        self.law = None
        if self._compiled is not None:   # the compiled step with this model's elastic law
            self.law = CompiledElasticLaw(self._compiled.lib, model)
            self.law.attach(self._compiled)
        self.strain_nonlinear = model.strain.nonlinear
        self.refreshes = 0   # iteration matrices re-factored inside a step, for diagnostics
        self.halvings = 0    # steps split in two because Newton failed
        self.backtracks = 0  # line-search step reductions
        # (q1, v1, nc, h, lu, piv, age) of the last step: its last iteration matrix and the
        # steps that matrix served whole since it was factored, for the next step if it
        # starts there (_step_numpy)
        self._carried = None

    def locked_damping(self):
        """Return C at full deployment for stage 2's mode fit (None: undamped)."""
        m = self.model
        if m.damping_beta == 0.0:
            return None
        return m.damping_matrix(m.rigid_configuration(m.params.alpha_deployed))

    def consistent_acceleration(self, q, qd, force: float, cs: ConstraintSet):
        m = self.model
        n, nc = m.n, m.n_constraints(cs)
        kkt = np.zeros((n + nc, n + nc))
        kkt[:n, :n] = m.mass_matrix(q)
        jac = m.constraint_jacobian(q, cs)
        kkt[:n, n:] = -jac.T
        kkt[n:, :n] = jac
        rhs = np.concatenate([m.quadratic_velocity_forces(q, qd) - m.elastic_force(q)
                              - m.damping_matrix(q) @ qd + m.applied_forces(q, force),
                              m.constraint_bias(q, qd, cs)])
        sol = np.linalg.solve(kkt, rhs)
        return sol[:n], sol[n:]

    #: a step whose Newton iteration fails is retaken as two half steps, down to h / 2**this
    max_halvings = 6

    def step(self, s: DynamicState, h: float, force: float, cs: ConstraintSet) -> DynamicState:
        with np.errstate(over="ignore", invalid="ignore"):
            return self._substeps(s, h, force, cs, 0)

    def _substeps(self, s, h, force, cs, depth):
        """
        Take the step, split in halves where Newton fails.

        With large bending the stiff axial directions turn with v' within a step, and
        Newton's basin around the predictor q0 + h v0 can be smaller than the step's
        motion: then the step is split (each half is energy-consistent, so the whole is).
        """
        try:
            return self._step(s, h, force, cs)
        except ConvergenceError:
            if depth >= self.max_halvings:
                raise
        self.halvings += 1
        mid = self._substeps(s, 0.5 * h, force, cs, depth + 1)
        return self._substeps(mid, 0.5 * h, force, cs, depth + 1)

    def _step(self, s, h, force, cs):
        """Take one step: compiled (_kernel_nonlinear.c hooks) or the numpy reference."""
        if self._compiled is None:
            return self._step_numpy(s, h, force, cs)
        out, its = self._compiled.step(s, h, force, cs, self.tolerance, self.max_iterations)
        self.iterations += its
        return DynamicState(out.t, out.q, out.qd, out.qdd, out.multipliers, out.momentum,
                            s.dissipation + self._compiled.last_dissipation())

    def _step_numpy(self, s, h, force, cs):
        """
        Take one energy-consistent midpoint step.

        M(q1) v1 - M(q0) v0 = h [G_T - G_U - C dq/h - F_H G_y + G_Phi^T lambda], Phi(q1) = 0;
        G_U the AVF gradient of U, the rest as in MidpointDAE._step (integrators.
        midpoint_iterate).  Nonlinear strain: the iteration matrix is re-factored after an
        iteration that contracted by less than REFRESH_RATE (the stiff axial directions turn
        with v' inside a large step, and a frozen matrix then converges slowly; at small
        steps one factorisation serves the whole step), and a backtracking line search on
        the residual norm guards against overshooting updates; a step already below the
        tolerance is taken whole.  A step that starts where the last step ended (same
        constraints and length) begins with that step's last matrix: the predictor's tangent
        is ~1e-3 off in stage 2, where Newton contracts by only ~1e-2 with it.  A matrix
        factored CARRY_STEPS steps ago or less serves the step whole; an older one its first
        iteration, and the step factors its own at the first iterate, which is close.  A
        factorisation costs about an iteration: 0.4 iterations more a step than factoring in
        every step, 12 % less time (N = 2 and 4).  _kernel.c with _kernel_nonlinear.c does
        the same arithmetic in the same order.
        """
        from scipy.linalg.lapack import dgetrf, dgetrs     # (as MidpointDAE._step)

        m = self.model
        n = m.n
        q0, v0 = s.q, s.qd
        start = self._step_start(s, cs)
        phi0 = m.constraint_residual(q0, cs)
        y0 = m.sleeve_height(q0)
        nc = len(phi0)
        lam_scale = 0.5 * h * h
        line_search = self.strain_nonlinear
        refresh = False
        carried, self._carried = self._carried, None
        lagged = (carried is not None and carried[2] == nc and abs(carried[3] - h) <= 1e-9 * h
                  and np.array_equal(carried[0], q0) and np.array_equal(carried[1], v0))

        def evaluate(q, lam):
            """Newton right-hand side -[h/2 R(q, lam); Phi(q)] and the residual's pieces."""
            x = midpoint_iterate(m, cs, q0, start, phi0, y0, q, h)
            damping = m.damping_matrix(x.qm)
            elastic = m.strain.discrete_gradient(q0, q)
            resid = (x.momentum1 - start.scheme_p0 + damping @ x.dq
                     + h * start.damping_force(x.dq, h)
                     - h * (x.g_t - elastic - force * x.g_y + x.jac_m.T @ lam))
            return np.concatenate([-0.5 * h * resid, -x.phi]), x, damping

        q = q0 + h * start.w0
        lam = s.multipliers.copy()
        lag_whole = lagged and carried[6] < CARRY_STEPS
        lu, piv = carried[4:6] if lagged else (None, None)
        refactored = False
        last_norm = f_base = np.inf
        alpha, base, dx = 1.0, None, None
        it = 0
        while it < self.max_iterations:
            f, x, damping = evaluate(q, lam)
            f_norm = np.linalg.norm(f)
            if line_search and base is not None and not f_norm < f_base and alpha >= 0.05:
                alpha *= 0.5                      # backtrack along the last Newton step
                self.backtracks += 1
                q = base[0] + alpha * dx[:n]
                lam = base[1] + alpha * dx[n:] / lam_scale
                continue
            it += 1
            if lu is None or refresh:
                it_mat = np.zeros((n + nc, n + nc))
                avf_jacobian = m.strain.discrete_gradient_jacobian(q0, q)
                it_mat[:n, :n], jac_c = iteration_blocks(
                    m, cs, x, h, 0.5 * h * h * avf_jacobian + 0.5 * h * damping)
                it_mat[:n, n:] = -jac_c.T
                it_mat[n:, :n] = m.constraint_jacobian(q, cs)
                lu, piv, info = dgetrf(it_mat, overwrite_a=True)
                if info != 0:
                    raise ConvergenceError(f"singular iteration matrix at t = {s.t + h:.9g} s")
                self.refreshes += int(it > 1)
                refactored = True
            dx = dgetrs(lu, piv, f)[0]
            dx[:n] = start.newton_update(dx[:n], h)
            step_norm = np.max(np.abs(dx[:n]))
            if not np.isfinite(step_norm):
                raise ConvergenceError(f"Newton iterate became non-finite at t = {s.t + h:.9g} s")
            base, f_base, alpha = (q, lam), f_norm, 1.0
            q = q + dx[:n]
            lam = lam + dx[n:] / lam_scale
            rate = step_norm / last_norm if it > 1 else 1.0
            refresh = self.strain_nonlinear and (
                (it == 1 and lagged and not lag_whole) or (it > 1 and rate > REFRESH_RATE))
            if step_norm < self.tolerance or (rate < 0.5 and rate / (1 - rate) * step_norm
                                              < self.tolerance):
                if np.max(np.abs(m.constraint_residual(q, cs))) < PHI_TOLERANCE:
                    break
            last_norm = step_norm
        else:
            raise ConvergenceError(f"Newton did not converge in {self.max_iterations} iterations "
                                   f"at t = {s.t + h:.9g} s (|dq| = {step_norm:.3g})")
        self.iterations += it
        dq = q - q0
        dissipated = float(dq @ (m.damping_matrix(q0 + 0.5 * dq) @ dq / h
                                 + start.damping_force(dq, h)))
        v = start.end_velocity(dq, h)
        mass1 = m.mass_matrix(q)
        # the projection onto J v = 0, scaled to the kinetic energy of the step's discrete
        # balance (net of the damping): energy is balanced to round-off, as in MidpointDAE
        t_target = (0.5 * (v0 @ start.p0) + self.strain_energy(q0, cs) - self.strain_energy(q, cs)
                    + force * (y0 - m.sleeve_height(q)) - dissipated)
        v = project_keeping_energy(mass1, m.constraint_jacobian(q, cs), v, t_target)
        if v is None:
            raise ConvergenceError(f"mass matrix not positive definite at t = {s.t + h:.9g} s")
        if self.strain_nonlinear:
            self._carried = (q, v, nc, h, lu, piv, 0 if refactored else carried[6] + 1)
        return DynamicState(s.t + h, q, v, (v - v0) / h, lam, mass1 @ v,
                            s.dissipation + dissipated)


# ------------------------------------------------------------------------ engine
class ElasticEngine(FiniteElementEngine):
    """FiniteElementEngine (stages, lock kinds, residuals) on ElasticMidpointDAE."""

    @staticmethod
    def _integrator(model: NonlinearUmbrellaModel) -> ElasticMidpointDAE:
        return ElasticMidpointDAE(model)

    @property
    def phase_correctable(self) -> bool:
        """
        Not with the nonlinear strain.

        Its axial coordinates follow the bending's foreshortening (u' = -v'^2/2), far from the
        lock's configuration and from the linearised modes the correction is built on (in
        its earlier, stiffness form, measured from the lock, it moved the stage-2 period at
        V0 = -0.2 by 1 % where its own size is 1e-5; the modal-mass form is not tried with
        this strain, and the kernel leaves it out).  The linear strain (damped flexible)
        takes it.
        """
        return not self.rigid and not self.model.strain.nonlinear

    def advance(self, s, k0, h, n_steps, force, stage, work, lock_loss, states=False):
        """
        Take up to n_steps steps on the compiled path (FiniteElementEngine.advance).

        The state carries the dissipated energy (the kernel's accumulator); a step the
        compiled loop could not take is handed back as "crossing", i.e. to the simulator's
        single-step path, which retakes it split in halves (``ElasticMidpointDAE._substeps``)
        or reports the fault.
        """
        out = super().advance(s, k0, h, n_steps, force, stage, work, lock_loss, states)
        if out is None:
            return None
        state, rows, work, stop, state_rows = out
        return state, rows, work, None if stop is None else "crossing", state_rows


def build(params: UmbrellaParams):
    """(model, engine) for the nonlinear and/or damped flexible model."""
    model = NonlinearUmbrellaModel(params)
    return model, ElasticEngine(params, model)
