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
Geometrically exact beams (thesis §7.2) and structural damping, on the same DAE.

Formulation (model ``flexible-nonlinear``)
------------------------------------------
The same floating frames, coordinates, mass matrix M(q), joints, sleeve, stop and lock as
``flexible`` (model.py): the kinetic energy is that of the interpolated field (u linear, v
cubic in an element, exact kinematics of that field in the moving frames); only the strain
energy, its discrete gradient, its Newton matrix and the stress recovery change.  They are
those of a co-rotational Euler-Bernoulli element (Crisfield, Non-linear Finite Element
Analysis of Solids and Structures vol. 1, ch. 7; Felippa & Haugen, Comput. Methods Appl.
Mech. Engrg. 194, 2005; Battini & Pacoste, ibid. 191, 2002) in its body's frame: the chord
d = (l_e + u_b - u_a, v_b - v_a) of an element gives its stretch lambda = |d| / l_e and the
angle beta = atan2(d) of its co-rotated frame, the nodal slopes theta_i = v'(x_i) the angles
psi_i = asin(theta_i) of its end sections, and in the co-rotated frame the local linear beam
with the element mean of its shallow-arch axial strain (Crisfield's shallow-arch local
element):

    tb_i = psi_i - beta,   eps = lambda - 1 + (2 tb_a^2 - tb_a tb_b + 2 tb_b^2) / 30,
    U_e = 1/2 EA l_e eps^2 + 2 EI / l_e (tb_a^2 + tb_a tb_b + tb_b^2).

The section angle: with small strains |r'| = 1 + eps ~ 1, so the slope of a fibre in its body
frame is v' = sin psi (the inextensional beam's relation, Crespo da Silva & Glynn, J. Struct.
Mech. 6, 1978), and psi = asin(v') ties the energy to the slope the kinetic field itself
carries.  Exact for any rigid rotation of an element in its frame and for large rotations;
its approximations are those of small strains (|eps|, and the fibre strain c kappa, well
below 1 %: the summary warns past summary.STRAIN_LIMIT; a stretched section's angle is off by
eps tan psi).  For small motion it is the linear model (its Hessian at q = 0 is K exactly; to
second order it is the element-mean von Karman strain u' + v'^2/2, which it replaced: the
frame's fibres turn by up to ~1.3 rad from their body frame at V0 = -2 m/s, where a strain
exact to second order in the rotation fails).  Why this and not an ANCF cable or a
Simo-Reissner beam: both need other coordinates (global slopes, or nodal rotations) and so
another mass matrix, node, recording and replay; this element keeps the thesis's
coordinates and puts the whole geometric nonlinearity in U.  An element's energy depends on
its own 6 coordinates only, so the kernel's band stays as it was.  (A first variant took the
tangent angle atan2(theta_i, 1 + u'_i) with u'_i recovered from the nodes beside it: exact in
statics too, but at 4 elements a segment its stage 2 at V0 = -2 m/s ran 9 % slow, since
that tangent's x component need not agree with the slope the kinetic field carries.)

Limit: the slope coordinates cannot turn a section through 90 deg from its body frame
(theta = +-1); a step that gets there fails with that explanation, and the summary warns past
80 deg (summary.SECTION_SLOPE_LIMIT, from the largest slope of every step,
ElasticEngine.max_section_slope).  The frame's fibres reach ~75 deg at V0 = -2 m/s with the
plastic lock and ~85 deg with the energy lock (docs/validation_nonlinear.md).

Discrete gradient (exact energy balance): U_e = 1/2 s.D s in the local strains s = (eps,
tb_a, tb_b), and per element G_e = B~^T D (s0 + s1) / 2 (Simo & Tarnow, ZAMP 43, 1992) with
B~ a discrete derivative of s, B~ (q1 - q0) = s1 - s0 exactly: lambda by (d0 + d1) / ((|d0| +
|d1|) l_e), beta by Gonzalez's midpoint discrete gradient (J. Nonlinear Sci. 6, 1996),
asin(theta) by its secant, the quadratic Q at the mean angles.  So dq . G = U(q1) - U(q0) to
round-off, and the midpoint scheme of integrators.py keeps its energy balance.  The Newton
matrix takes 1/2 [B^T D B + sum_k (D s)_k d^2 s_k / dq^2] at the midpoint (d G / d q1 to
O(dq^2)).  Stress recovery: sigma = E (eps -/+ c kappa) in the element's rotated frame at both
its ends, kappa = w'' of the local cubic, (-4 tb_a - 2 tb_b) / l_e and (2 tb_a + 4 tb_b) / l_e.

Time integration: the midpoint step of MidpointDAE (the same residual pieces,
integrators.midpoint_iterate) with this discrete gradient; full Newton with a backtracking
line search (a full update can overshoot when the stiff axial directions turn within a
step; a predictor outside the slope coordinates starts from q0), steps split in halves where
Newton still fails, and MidpointDAE's velocity projection scaled to the kinetic energy of
the step's discrete balance, so that the model balances energy to round-off.

Structural damping (parameter ``damping_ratio`` zeta, models ``flexible`` and
``flexible-nonlinear``)
------------------------------------------------------------------------------------------
Stiffness-proportional Rayleigh (Kelvin-Voigt) damping of the strain rates,
Q_d = -C(q) q', C = beta B(q)^T D B(q) (B = d s / dq; C = beta K for the linear strain),
beta = 2 zeta / omega_1, with omega_1 the first natural frequency of the locked frame
linearised about the undeformed deployed configuration (stage 2).  That mode then has
exactly the ratio zeta; mode i has zeta * omega_i / omega_1 (higher modes decay faster);
rigid motion (alpha, R), and with the co-rotational strain any rigid rotation of an element,
is not damped.  In the midpoint step the damping force is -C(q_m) dq/h, so the step
dissipates exactly dq . C(q_m) dq / h >= 0; the state carries the dissipated energy, and the
energy balance reads T + V - (T0 + V0) - W + lock loss + dissipation = 0.

Compiled path: the kernel of integrators.py (_kernel.c, bound by kernel.py) with this
module's elastic law attached (_kernel_nonlinear.c, ``CompiledElasticLaw``): the same
arithmetic as the numpy step here, which stays as the reference the tests compare it with
step by step (UMBRELLA_SIM_KERNEL=numpy selects it).  With zeta = 0 the model ``flexible``
keeps the plain linear kernel.  Nothing here imports rclpy.
"""
from __future__ import annotations

import ctypes

import numpy as np

from .beam_strain import CorotationalStrainEnergy, LinearStrainEnergy, slope_end_reason
from .engines import FiniteElementEngine
from .integrators import (iteration_blocks, joint_correction, midpoint_iterate, MidpointDAE,
                          newton_converged, NEWTON_TOLERANCE, project_keeping_energy)
from .kernel import ConvergenceError, DynamicState, ElasticData
from .model import band_form, ConstraintSet, UmbrellaModel
from .params import UmbrellaParams

NONLINEAR_MODEL = 'flexible-nonlinear'
#: Newton contraction rate above which the nonlinear step re-factors its iteration matrix
#: (_kernel_elastic.h ELASTIC_REFRESH_RATE)
REFRESH_RATE = 0.1
#: A step's last iteration matrix goes on to the next step if it starts where this one
#: ended; one factored this many steps ago or less serves that step whole, an older one its
#: first iteration only (_kernel_elastic.h ELASTIC_CARRY_STEPS)
CARRY_STEPS = 2


# ------------------------------------------------------------------------- model
class NonlinearUmbrellaModel(UmbrellaModel):
    """
    UmbrellaModel with the co-rotational (or linear) strain energy and damping.

    The strain energy of ``CorotationalStrainEnergy`` (model flexible-nonlinear) or
    ``LinearStrainEnergy`` (a damped flexible model) and the matching stress recovery; the
    strain-rate damping of ``damping_ratio``.
    """

    def __init__(self, params: UmbrellaParams):
        super().__init__(params)
        p = self.params
        bodies = ((self.leaf, self.s_leaf), (self.link, self.s_link))
        if p.model == NONLINEAR_MODEL:
            self.strain = CorotationalStrainEnergy(
                bodies, self.n, p.youngs_modulus * p.cross_section_area,
                p.youngs_modulus * p.cross_section_inertia, p.youngs_modulus, p.fibre_distance)
        else:
            self.strain = LinearStrainEnergy(bodies, self.n)
        self.first_frequency = locked_first_frequency(self)
        self.damping_beta = damping_beta_of(self)
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

        The co-rotational beam's E (eps -/+ c kappa) in each element's rotated frame
        (CorotationalStrainEnergy.fibre_stresses); the linear model's for the linear strain.
        """
        if not self.strain.nonlinear:
            return super().stresses(q)
        return self._per_body(self.strain.fibre_stresses(q))

    def stress_rates(self, q, qd):
        """d/dt of ``stresses`` along qd."""
        if not self.strain.nonlinear:
            return super().stress_rates(q, qd)
        return self._per_body(self.strain.fibre_stress_rates(q, qd))

    def _per_body(self, top_bottom):
        top, bottom = top_bottom
        n_leaf = 2 * len(self.leaf.element_length)
        return (top[:n_leaf], bottom[:n_leaf]), (top[n_leaf:], bottom[n_leaf:])


def locked_first_frequency(model: UmbrellaModel) -> float:
    """Return omega_1 (rad/s) of the locked frame linearised at full deployment."""
    return float(model.locked_modes[0][0])


def damping_beta_of(model: UmbrellaModel) -> float:
    """
    Return beta (s) of C = beta K: 2 zeta / omega_1 (zeta: the model's damping_ratio).

    omega_1: locked_first_frequency, the planar frame's (the umbrella's 3D beams take its
    planar record's: umbrella3d/damping3d.py).
    """
    return 2.0 * model.params.damping_ratio / locked_first_frequency(model)


# ------------------------------------------------------------ compiled elastic law
class CompiledElasticLaw:
    """
    The strain energy and damping of a NonlinearUmbrellaModel, handed to _kernel_nonlinear.c.

    The co-rotational beam element by element: the q indices and elastic positions of each
    element's coordinates (u, v, theta of its two nodes; -1 where the frame fixes one), its
    length, EA, EI and the fibre distance; or the linear strain's K in the band form of the
    kernel.  Attached to a CompiledKernel, it replaces the kernel's constant K
    (umbrella_set_law).
    """

    def __init__(self, lib, model: 'NonlinearUmbrellaModel'):
        st, p = model.strain, model.params
        idx = np.asarray(model.elastic_indices)
        bw = model.banded_invariants()[0]
        n_leaf_points = model.stress_rows()[4][0]
        if n_leaf_points != 2 * len(model.leaf.element_length):
            raise ValueError("compiled elastic law: the leaf's stress points are not the two "
                             'ends of each element')
        el_q = []
        for body, s_e in ((model.leaf, model.s_leaf), (model.link, model.s_link)):
            for maps in body.element_dof_maps:             # (6, n_elastic): one 1 a row
                el_q.append(np.where(maps.any(axis=1), s_e.start + maps.argmax(axis=1), -1))
        el_q = np.array(el_q, dtype=np.intc)
        el_pos = np.where(el_q >= 0, np.searchsorted(idx, np.maximum(el_q, 0)), -1)
        lengths = np.concatenate([model.leaf.element_length, model.link.element_length])
        k = np.zeros_like(model.stiffness) if st.nonlinear else st.stiffness
        arrays = {'elastic_idx': np.asarray(idx, dtype=np.intc),
                  'k_band': band_form(k[np.ix_(idx, idx)], bw),
                  'el_q': el_q, 'el_pos': np.asarray(el_pos, dtype=np.intc),
                  'el_length': lengths}
        arrays = {name: np.ascontiguousarray(a) for name, a in arrays.items()}
        self._arrays = arrays   # the struct points into these
        self.struct = ElasticData(
            n=model.n, ne=len(idx), bw=bw, n_el=len(lengths), nonlinear=int(st.nonlinear),
            beta=model.damping_beta, youngs_modulus=p.youngs_modulus,
            ea=p.youngs_modulus * p.cross_section_area,
            ei=p.youngs_modulus * p.cross_section_inertia, fibre=p.fibre_distance,
            **{name: a.ctypes.data_as(ctypes.POINTER(
                ctypes.c_int if a.dtype == np.intc else ctypes.c_double))
               for name, a in arrays.items()})
        self.lib = lib
        ptr = lib.elastic_new(ctypes.byref(self.struct))
        if not ptr:
            raise MemoryError('the compiled elastic law could not allocate its buffers')
        self.ptr = ctypes.c_void_p(ptr)

    def attach(self, kernel) -> None:
        """Make kernel (a CompiledKernel of the same model) step with this law."""
        kernel.set_elastic_law(self, self.ptr)

    def last_dissipation(self) -> float:
        return float(self.lib.elastic_last_dissipation(self.ptr))

    def max_slope(self) -> float:
        """Return the largest |theta| = |sin psi| of the states the law has stepped through."""
        return float(self.lib.elastic_max_slope(self.ptr))

    def __del__(self):
        ptr = getattr(self, 'ptr', None)
        if ptr is not None and ptr.value:
            self.lib.elastic_free(ptr)
            self.ptr = None


# -------------------------------------------------------------------- integrator
class ElasticMidpointDAE(MidpointDAE):
    """
    Energy-consistent midpoint step with a general strain energy and damping.

    The energy-consistent midpoint step of MidpointDAE with a general strain energy
    (its discrete gradient) and the damping force -C dq/h: on the compiled kernel with
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
        # the largest |theta| = |sin psi| of the states the numpy path stepped from or to
        self._max_slope = 0.0
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
        with np.errstate(over='ignore', invalid='ignore'):
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
        except ConvergenceError as exc:
            if depth >= self.max_halvings:
                raise self._explained(exc, s) from None
        self.halvings += 1
        mid = self._substeps(s, 0.5 * h, force, cs, depth + 1)
        return self._substeps(mid, 0.5 * h, force, cs, depth + 1)

    def max_section_slope(self) -> float | None:
        """
        Return the co-rotational beam's largest |v'| = |sin psi| of every step so far.

        The largest turn of a section from its body frame (the summary's fibre-rotation
        warning); None for the linear strain.
        """
        if not self.strain_nonlinear:
            return None
        if self.law is not None:
            return self.law.max_slope()
        return self._max_slope

    def _explained(self, exc: ConvergenceError, s: DynamicState) -> ConvergenceError:
        """
        Return the step's failure, explained where the co-rotational beam met its limit.

        The slope coordinates theta = sin psi of the floating frames cannot turn a section
        through 90 deg from its body frame: a step that fails with a slope near 1 says so.
        """
        if not self.strain_nonlinear:
            return exc
        reason = slope_end_reason(float(np.max(np.abs(self.model.strain.section_slopes(s.q)))))
        return exc if reason is None else ConvergenceError(f'{exc}: {reason}')

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
        G_U the discrete gradient of U, the rest as in MidpointDAE._step (integrators.
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
        factorisation costs about an iteration: re-checked with (an earlier variant of) the
        co-rotational law, N = 4, V0 = -0.2 and -1 on a shared machine, re-factoring at a
        contraction rate of 0.03 or 0.01, or in every step, was no faster overall (-1 % to
        +24 % time) than these rules.  A predictor outside the slope coordinates
        (|theta| >= 1, on a coarse step) starts from q0.  _kernel.c with _kernel_nonlinear.c
        does the same arithmetic in the same order.
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
        if self.strain_nonlinear and not m.strain.admissible(q):
            q = q0.copy()           # a predictor outside the slope coordinates starts from q0
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
                gradient_jacobian = m.strain.discrete_gradient_jacobian(q0, q)
                it_mat[:n, :n], jac_c = iteration_blocks(
                    m, cs, x, h, 0.5 * h * h * gradient_jacobian + 0.5 * h * damping)
                it_mat[:n, n:] = -jac_c.T
                it_mat[n:, :n] = m.constraint_jacobian(q, cs)
                lu, piv, info = dgetrf(it_mat, overwrite_a=True)
                if info != 0:
                    raise ConvergenceError(f'singular iteration matrix at t = {s.t + h:.9g} s')
                self.refreshes += int(it > 1)
                refactored = True
            dx = dgetrs(lu, piv, f)[0]
            dx[:n] = start.newton_update(dx[:n], h)
            step_norm = np.max(np.abs(dx[:n]))
            if not np.isfinite(step_norm):
                raise ConvergenceError(f'Newton iterate became non-finite at t = {s.t + h:.9g} s')
            base, f_base, alpha = (q, lam), f_norm, 1.0
            q = q + dx[:n]
            lam = lam + dx[n:] / lam_scale
            rate = step_norm / last_norm if it > 1 else 1.0
            refresh = self.strain_nonlinear and (
                (it == 1 and lagged and not lag_whole) or (it > 1 and rate > REFRESH_RATE))

            def correct_joints():
                nonlocal q, lam
                dq, dlam = joint_correction(lu, piv, n, m.constraint_residual(q, cs), start, h)
                q = q + dq
                lam = lam + dlam / lam_scale
            if newton_converged(step_norm, rate, self.tolerance,
                                lambda: np.max(np.abs(m.constraint_residual(q, cs))),
                                correct_joints):
                break
            last_norm = step_norm
        else:
            raise ConvergenceError(f'Newton did not converge in {self.max_iterations} iterations '
                                   f'at t = {s.t + h:.9g} s (|dq| = {step_norm:.3g})')
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
            raise ConvergenceError(f'mass matrix not positive definite at t = {s.t + h:.9g} s')
        if self.strain_nonlinear:
            self._carried = (q, v, nc, h, lu, piv, 0 if refactored else carried[6] + 1)
            self._max_slope = max(self._max_slope,
                                  float(np.abs(m.strain.section_slopes(q0)).max()),
                                  float(np.abs(m.strain.section_slopes(q)).max()))
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

        Its axial coordinates follow the bending's foreshortening (inextensible bending
        shortens the chords), far from the lock's configuration and from the linearised
        modes the correction is built on (in its earlier, stiffness form, measured from the
        lock, it moved the von Karman model's stage-2 period at V0 = -0.2 by 1 % where its
        own size is 1e-5; the modal-mass form is not tried with a nonlinear strain, and the
        kernel leaves it out).  The linear strain (damped flexible) takes it.
        """
        return not self.rigid and not self.model.strain.nonlinear

    def max_section_slope(self) -> float | None:
        """Return the largest |v'| of a section over every step so far (None: linear strain)."""
        return self.integrator.max_section_slope()

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
        return state, rows, work, None if stop is None else 'crossing', state_rows


def build(params: UmbrellaParams):
    """(model, engine) for the nonlinear and/or damped flexible model."""
    model = NonlinearUmbrellaModel(params)
    return model, ElasticEngine(params, model)
