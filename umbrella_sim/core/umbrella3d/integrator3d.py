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
The energy-consistent midpoint step of the whole umbrella, on block-arrow linear algebra.

The planar integrator's scheme (``core.integrators.MidpointDAE``) for the umbrella's
coordinates, step for step the same algorithm so that a rib whose out-of-plane state is zero
takes the planar model's steps: predictor q0 + h v0, modified Newton on

    M(q1) v1 - M(q0) v0 = h [ G_T - K q_m + Q + G_Phi^T lambda ],   Phi(q1) = 0

(G_T, G_Phi Gonzalez discrete gradients of 1/2 v0^T M(q) v1 and of each joint row; Q the
sleeve force on y_s, the hinges' friction at the step's mean rate, exact work), the
iteration matrix M + h^2/4 K + h/2 G (at the iterate it is factored at; the elastic
gyroscopic block and the Gonzalez columns left out, as the planar one) kept across steps:
a step that starts where the step before ended, with its length, lock and stuck hinges,
takes that step's matrix, which serves at most CARRY_STEPS steps and is factored anew at
the iterate after an iteration that contracts the update by less than REFRESH_RATE
(``_kept_factor``; the same rule in _kernel3d.c), the same stopping rule, then
the velocity projected onto the joints in the mass metric and scaled to the kinetic energy
of the step's discrete energy balance

    T1 = T0 + V0 - V1 + F (y_s0 - y_s1) + W_friction + W_drive.

With a prescribed base (rheonomic joints) the velocity is projected but not scaled, and the
drive's work counts, besides its multipliers times the bus's displacement, the projection's
impulse on the bus times the bus's mean velocity across it.  Every linear solve is
block-arrow (arrow.py): cost linear in the number of ribs.  The kinetic energy's discrete
gradient meets dq . G_T = f(q1) - f(q0) over the whole dq, the correction added along the
ribs' coordinates and the sleeve's only (not the bus's: its position is cyclic), so the bus's
linear momentum is conserved to round-off.

Stage 2 may take the planar stage-2 mode fit (``fit_stage2_modes``, ``lock_at``;
integrators.LockedModeFit: each resolved mode exact in phase and amplitude, T + V conserved):
the scheme's velocity w = S^-1 v, momentum S^T M v, each Newton update shrunk mode by mode.
Which modes, by base (stage2fit.py): the hub fixed or driven, each rib's locked modes in the
hub's frame, rib by rib (with the sleeve at the stop the ribs are decoupled there); a
free-floating bus, the elastic modes of the whole free system (bus + locked ribs), which
leaves the bus's momenta the physical ones: the ribs' fits with a low-rank correction
(stage2fit.BusFit), at a cost linear in the ribs.
"""
from __future__ import annotations

from dataclasses import replace
import math
import os
import sys

import numpy as np

from . import arrow
from .damping3d import damping_beta, damping_force
from .kernel3d import CompiledStep3D
from .model3d import N_RIB_ROWS, ROW_STICK, UmbrellaModel3D
from .stage2fit import BusFit, RibFits, stage2_fit, WholeFit
from .state3d import ConvergenceError3D, State3D, StepWork
from ..integrators import newton_converged, newton_tolerance, PHI_TOLERANCE
from ..kernel import kernel_error, kernel_refusal, LIBRARY, load_kernel, STATUS

#: steps an iteration matrix serves at most (the first included), and the contraction of a
#: Newton update above which the matrix is factored anew at the iterate (_kernel3d.c's
#: CARRY_STEPS, REFRESH_RATE).  Measured (ribs 6, 1 element, h = 0.1 ms, deployment): a
#: fresh matrix every step took 2.00 Newton iterations a step, kept 2.00 and 0.125
#: factorisations a step (2.03, 0.126 at ribs 12, 2 elements).  Stage 2 (the mode fit
#: acting), compiled step alone, us a step at carry_steps 1/2/4/8/16/32: ribs 6 x 1 61.8/54.1/
#: 52.2/50.3/50.2/50.5 (2.07-3.04 iterations a step), ribs 12 x 2 314/255/234/214/214/223.
CARRY_STEPS = 8
REFRESH_RATE = 0.1
#: stage 2's velocity projection kept with the iteration matrix (the hub fixed:
#: project_kept): a locked step that factors the iteration matrix factors the projection
#: [[M, J^T], [J, 0]] at its end; the steps the matrix serves correct v with that factor, in
#: passes each taking the residual J(q) v at their own q, until a pass's correction is below
#: PROJECTION_TOLERANCE of v's largest component (the residual left then is its contraction,
#: ~1e-3, times that: the round-off of J v = 0), PROJECTION_PASSES at most, else v as it
#: came projected by a pass of a projection factored at q (_kernel3d.c's constants).  The
#: correction of v then lies in the kept M's metric, not M(q)'s: ~1e-7 of v apart (a
#: correction ~3e-5 of v, M ~1e-3 from its value up to CARRY_STEPS steps before), an error of
#: the kept iteration matrix's order at Newton's default tolerance (test_umbrella3d_newton:
#: a 30 ms tip series 0.92 um from the one with both factored every step, 0.91 with the
#: projection factored every step; the energy is scaled to its balance after), so only from
#: a tolerance of PROJECTION_KEPT_FROM (the floor of newton_tolerance): a run asking for
#: Newton's iterates tighter than that takes M(q)'s metric every step (the identities with
#: the planar model hold to 1e-10 at tolerances 1e-12 to 1e-14).  Measured (ribs 6 x 1,
#: stage 2 at 0.1 ms, the compiled step alone, interleaved): 51.6 -> 48.2 us a step, 3.8
#: passes a step the matrix served, none falling back.
PROJECTION_PASSES = 4
PROJECTION_TOLERANCE = 1e-12
PROJECTION_KEPT_FROM = 1e-10
#: below this |rate| / hinge_regularisation a hinge's Coulomb secant is its tangent, 1
#: (_kernel3d.c's FRICTION_AT_REST)
FRICTION_AT_REST = 1e-6

#: Gonzalez's discrepancies (the kinetic energy's f(q1) - f(q0) - g.dq, each joint row's
#: phi(q1) - phi(q0) - J(q_m) dq) within this many ulps of their terms' scale are their
#: round-off, not the midpoint gradient's error: no correction then (_kernel3d.c's
#: GONZALEZ_NOISE).  A correction divides its discrepancy by |dq|^2: on a base spun at
#: 10 rad/s the kinetic terms are the bus's momentum, 100 kg m^2/s, while a settled rib's dq
#: is Newton's noise, and 1e-13 J of round-off over |dq|^2 = 1e-17 m^2 (the joints' 1e-16 m
#: over 1e-21 m^2) bent the gradients by 1e4 (1e6) times dq, which held Newton's update of
#: the leaf's twist at 1e-9 rad, past its tolerance: a damped umbrella spun at 5-10 rad/s
#: failed once settled (measured: the noise 0.2-1.1 ulps of the scale)
GONZALEZ_NOISE = 32.0


def gonzalez_discrepancy(discrepancy, scale):
    """
    Return Gonzalez's discrepancy, 0 where it is within GONZALEZ_NOISE ulps of scale.

    scale: the sum of the magnitudes of the terms the discrepancy is summed from (the same
    shape; numbers or arrays).
    """
    noise = GONZALEZ_NOISE * np.finfo(float).eps * np.asarray(scale)
    return np.where(np.abs(discrepancy) > noise, discrepancy, 0.0)


#: why a run steps on the numpy path although the compiled step was asked for ('auto'),
#: said once a process on stderr
_SAID: set = set()


def _largest(phi_r: np.ndarray, phi_s: np.ndarray) -> float:
    """Return the largest joint residual (the ribs' and the shared ones)."""
    return max(float(np.max(np.abs(phi_r))), float(np.max(np.abs(phi_s), initial=0.0)))


def _non_finite(t: float) -> ConvergenceError3D:
    """Return the failure of a step whose Newton iterate became non-finite (the kernel's)."""
    return ConvergenceError3D(kernel_error(STATUS['non_finite'], t))


class BaseDrive:
    """
    A prescribed bus motion: a half-sine acceleration pulse in X-Z and a spin-up about Y.

    Position, velocity and acceleration of the bus coordinates [X, Y, Z, psi, beta, gamma]
    in closed form: a(t) = A sin(pi (t - t0) / T) for t0 <= t <= t0 + T (A = (ax, 0, az)),
    psi'(t) = Omega min(t / T_r, 1).
    """

    def __init__(self, params):
        self.accel = np.array([params.base_accel_x, 0.0, params.base_accel_z])
        self.t0, self.duration = params.base_accel_start, params.base_accel_duration
        self.spin, self.ramp = params.base_spin_rate, params.base_spin_ramp

    def __call__(self, t: float):
        """Return (g, g', g'') of the bus coordinates at t."""
        g, gd, gdd = self.profile(np.array([t], dtype=float))
        return g[0], gd[0], gdd[0]

    def profile(self, t: np.ndarray):
        """Return (g, g', g'') of the bus coordinates at the instants t: (len(t), 6) each."""
        g, gd, gdd = (np.zeros((len(t), 6)) for _ in range(3))
        tau = np.clip(t - self.t0, 0.0, self.duration)
        w = math.pi / self.duration
        amp = self.accel
        pulse = (0.0 < t - self.t0) & (t - self.t0 < self.duration)
        gdd[:, :3] = np.where(pulse[:, None], amp * np.sin(w * tau)[:, None], 0.0)
        gd[:, :3] = amp / w * (1.0 - np.cos(w * tau))[:, None]
        g[:, :3] = (amp / w * (tau - np.sin(w * tau) / w)[:, None]
                    + gd[:, :3] * np.maximum(t - self.t0 - tau, 0.0)[:, None])
        r = self.ramp
        ramp = t <= r
        g[:, 3] = np.where(ramp, self.spin * t * t / (2 * r), self.spin * (r / 2 + t - r))
        gd[:, 3] = np.where(ramp, self.spin * t / r, self.spin)
        gdd[:, 3] = np.where(ramp, self.spin / r, 0.0)
        return g, gd, gdd


class MidpointUmbrella:
    """
    The step of module docstring for a model; friction and the drive from its parameters.

    kernel: 'auto' (UMBRELLA_SIM_KERNEL, else auto: the compiled step, _kernel3d.c and, for
    a driven or free base, _kernel3d_base.h, when the library is built, else this numpy
    reference with a note on stderr),
    'compiled' (an error if it cannot be), or 'numpy'.  ``backend`` says which steps.
    carry_steps: the steps an iteration matrix serves at most (1: factored every step, the
    planar scheme's rule).
    """

    def __init__(self, model: UmbrellaModel3D, tolerance: float = 1e-10,
                 max_iterations: int = 25, kernel: str | None = None,
                 carry_steps: int = CARRY_STEPS):
        if carry_steps < 1:
            raise ValueError(f'carry_steps={carry_steps}: must be 1 or more')
        self.model = model
        self.carry_steps = carry_steps
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        p = model.params
        self.coulomb = np.array([r.hinge_coulomb for r in model.ribs])
        self.viscous = np.array([r.hinge_viscous for r in model.ribs])
        self.regularisation = p.hinge_regularisation
        self.drive = BaseDrive(p) if p.base == 'prescribed' else None
        #: the beams' structural damping C = beta K (damping3d.py; 0: undamped)
        self.damping_beta = damping_beta(p)
        m = model
        # coordinates the kinetic energy depends on (Gonzalez correction), and those Newton's
        # error is measured on (y_s follows the ribs through the joints)
        self.kin_shared = np.zeros(m.n_shared, dtype=bool)
        self.norm_shared = np.zeros(m.n_shared, dtype=bool)
        if m.moving_base:
            self.kin_shared[0] = True
            self.norm_shared[1:] = True
        self.iterations = 0
        self.factorisations = 0     # of the iteration matrix
        #: the numpy step's corrections of the joints alone (newton_converged; the hub fixed)
        self.joint_corrections = 0
        #: stage 2's mode fit (fit_stage2_modes: stage2fit.RibFits or BusFit), acting
        #: from lock_at on
        self.mode_fit: RibFits | BusFit | WholeFit | None = None
        self.fit_active = False
        #: the last step's iteration matrix: (factor, uses, end q and v, h, locked, stuck)
        self._kept = None
        self.compiled = self._compiled_step(kernel)

    def _compiled_step(self, kernel: str | None):
        """Return the compiled step (kernel3d.CompiledStep3D) the kernel choice gives, or None."""
        name = 'kernel' if kernel else 'UMBRELLA_SIM_KERNEL'
        kernel = kernel or os.environ.get('UMBRELLA_SIM_KERNEL', 'auto')
        if kernel not in ('auto', 'compiled', 'numpy'):
            raise ValueError(f'{name}={kernel!r}: must be auto, compiled or numpy')
        if kernel == 'numpy':
            return None
        why = None
        lib = load_kernel()
        if lib is None:
            why = kernel_refusal() or (f'the compiled kernel {LIBRARY} is not built (python3 '
                                       'bootstrap.py setup; it needs a C compiler)')
        if why is None:
            return CompiledStep3D(lib, self.model, self.tolerance, PHI_TOLERANCE,
                                  self.max_iterations, self.carry_steps, self.drive,
                                  damping_beta=self.damping_beta)
        if kernel == 'compiled':
            raise RuntimeError(why)
        if why not in _SAID:
            _SAID.add(why)
            print(f'umbrella_sim: {why}; the 3D umbrella steps on the numpy reference path '
                  '(slow)', file=sys.stderr, flush=True)
        return None

    def fit_stage2_modes(self, h: float) -> None:
        """Fit the base's locked modes (stage2fit.stage2_fit) for grid step h, from lock_at on."""
        self.mode_fit = stage2_fit(self.model, h, self.damping_beta)
        self.fitted_step = h

    def take_substeps(self, h: float, tolerance: float | None = None) -> None:
        """
        Step stage 2 in physics steps of h (substeps3d.py): Newton's tolerance and the fit.

        The planar engine's rule at its substeps (engines.FiniteElementEngine._follow):
        the Newton tolerance (tolerance: given; None: the step h's, newton_tolerance), the
        modes fitted for h (kept if they are h's already).  Before ``lock_at``.
        """
        self.tolerance = newton_tolerance(h) if tolerance is None else tolerance
        if self.compiled is not None:
            self.compiled.set_tolerance(self.tolerance)
        if self.mode_fit is not None and h != self.fitted_step:
            self.fit_stage2_modes(h)

    def lock_at(self, state: State3D | None = None) -> None:
        """
        Start stage 2's mode fit (if any): the lock has happened (in state, if given).

        A free bus's modes are those at the bus's attitude at the lock (the state's:
        stage2fit.BusFit.at_attitude).
        """
        if self.mode_fit is not None:
            if state is not None and self.mode_fit.whole and np.any(state.qs[4:7] != 0.0):
                self.mode_fit = self.mode_fit.at_attitude(state.qs[4:7])
            self.fit_active = True
            if self.compiled is not None:
                self.compiled.set_mode_fit(self.mode_fit)

    def stage2_fits(self, locked: bool) -> RibFits | BusFit | WholeFit | None:
        """Return the mode fit acting on a step (stage 2, from the lock), else None."""
        return self.mode_fit if self.fit_active and locked else None

    @property
    def backend(self) -> str:
        """Return 'compiled' or 'numpy': what takes the steps."""
        return 'compiled' if self.compiled is not None else 'numpy'

    # ------------------------------------------------------------ pieces
    def friction(self, dq_a1: np.ndarray, h: float):
        """
        Return (torque at the step's mean rate (R,), the slope the iteration matrix takes).

        The slope in d alpha1 is the Coulomb torque's secant from rest, tanh(s) / s (s the
        rate over hinge_regularisation; its tangent, 1, at rest), not its tangent sech^2(s),
        which is 0 away from rest: with it a rate crossing 0 overshot the tanh's narrow ramp
        back and forth and Newton never converged (a 2 N m hinge in stage 2).  Newton's
        residual keeps the exact torque: the same solution.
        """
        w = dq_a1 / h
        eps = self.regularisation
        s = w / eps
        th = np.tanh(s)
        torque = -(self.viscous * w + self.coulomb * th)
        rest = np.abs(s) < FRICTION_AT_REST
        secant = np.where(rest, 1.0, th / np.where(rest, 1.0, s))
        slope = -(self.viscous + self.coulomb * secant / eps) / h
        return torque, slope

    def _blocks(self, mass, jac_c, jac_r, stuck, shared_active, extra_rr=None, sign=-1.0):
        """Return the arrow blocks of [[A, sign Jc^T], [Jr, Z]] (Z = 1 on inactive rows)."""
        m = self.model
        m_rr, m_rs, m_ss = mass
        j_rr_c, j_rs_c, j_ss_c = jac_c
        j_rr, j_rs, j_ss = jac_r
        nr, n, ns, cs = m.n_ribs, m.n_rib, m.n_shared, m.n_shared_rows
        a_rr = m_rr if extra_rr is None else m_rr + extra_rr
        b = np.zeros((nr, n + N_RIB_ROWS, n + N_RIB_ROWS))
        b[:, :n, :n] = a_rr
        b[:, :n, n:] = sign * j_rr_c.transpose(0, 2, 1)
        b[:, n:, :n] = j_rr
        b[:, n + ROW_STICK, n + ROW_STICK] = np.where(np.isnan(stuck), 1.0, 0.0)
        c = np.zeros((nr, n + N_RIB_ROWS, ns + cs))
        c[:, :n, :ns] = m_rs
        c[:, n:, :ns] = j_rs
        d = np.zeros((nr, ns + cs, n + N_RIB_ROWS))
        d[:, :ns, :n] = m_rs.transpose(0, 2, 1)
        d[:, :ns, n:] = sign * j_rs_c.transpose(0, 2, 1)
        e = np.zeros((ns + cs, ns + cs))
        e[:ns, :ns] = m_ss
        e[:ns, ns:] = sign * j_ss_c.T
        e[ns:, :ns] = j_ss
        e[ns:, ns:] = np.diag(np.where(shared_active, 0.0, 1.0))
        return b, c, d, e

    def project(self, kin, mass, qr, vr, vs, stuck, locked, target_vs=None,
                multipliers=False):
        """
        Return (vr, vs) projected onto J v = c in the mass metric (c: the drive's rates).

        With multipliers, also the shared rows' mu (the impulse on the shared coordinates is
        -J_ss^T mu: on the bus, -mu[1:] with a prescribed base).
        """
        m = self.model
        jac = m.constraint_jacobian(qr, stuck, locked)
        f = arrow.factor(*self._blocks(mass, jac[:3], jac[:3], stuck, jac[3], sign=1.0))
        vr1, vs1, mu = self._projection_pass(f, jac, vr, vs, target_vs)
        return (vr1, vs1, mu) if multipliers else (vr1, vs1)

    def _projection_pass(self, f, jac, vr, vs, target_vs=None):
        """Return (vr, vs, mu) corrected by the factored projection f (J: jac's at q)."""
        j_rr, j_rs, j_ss, active = jac
        rib_res = -(np.einsum('rij,rj->ri', j_rr, vr) + j_rs @ vs)
        sh_res = -(j_ss @ vs)
        if target_vs is not None:
            sh_res[1:] += target_vs
        sh_res[~active] = 0.0
        n, ns = self.model.n_rib, self.model.n_shared
        rr = np.concatenate([np.zeros_like(vr), rib_res], 1)
        xs_r, xs_s = f.solve(rr, np.concatenate([np.zeros(ns), sh_res]))
        return vr + xs_r[:, :n], vs + xs_s[:ns], xs_s[ns:]

    def project_kept(self, mass, qr, vr, vs, stuck, locked, kept):
        """
        Return (vr, vs) projected onto J(q) v = 0 and the projection to keep (the hub fixed).

        kept None: in the mass metric of M(q) (mass), one pass of the projection factored
        at q, which is kept; else passes of the kept projection (PROJECTION_PASSES'
        rule), or if they do not end, the velocity given projected by a pass of one
        factored at q (not kept).
        """
        m = self.model
        jac = m.constraint_jacobian(qr, stuck, locked)
        if kept is not None:
            size = max(float(np.max(np.abs(vr))), float(np.max(np.abs(vs))))
            wr, ws = vr, vs
            for _ in range(PROJECTION_PASSES):
                wr0, ws0 = wr, ws
                wr, ws, _ = self._projection_pass(kept, jac, wr, ws)
                step = max(float(np.max(np.abs(wr - wr0))), float(np.max(np.abs(ws - ws0))))
                if not step > PROJECTION_TOLERANCE * size:
                    return wr, ws, kept
        f = arrow.factor(*self._blocks(mass, jac[:3], jac[:3], stuck, jac[3], sign=1.0))
        vr, vs, _ = self._projection_pass(f, jac, vr, vs)
        return vr, vs, kept if kept is not None else f

    def consistent(self, s: State3D, force: float, locked: bool) -> State3D:
        """Return s with the multipliers of its consistent accelerations."""
        m = self.model
        kin = m.kinematics(s.qr, s.qs)
        mass = m.mass_matrix(kin)
        j_rr, j_rs, j_ss, active = m.constraint_jacobian(s.qr, s.stuck, locked)
        jac = (j_rr, j_rs, j_ss)
        f = arrow.factor(*self._blocks(mass, jac, jac, s.stuck, active))
        q_rib = m.rib_quadratic_forces(kin, s.vr) - m.elastic_force(s.qr)
        q_sh = np.zeros(m.n_shared)
        q_sh[0] = -force
        bias_r = m.constraint_bias(s.qr, s.vr)
        bias_s = np.zeros(m.n_shared_rows)
        if self.drive is not None:
            bias_s[1:] = self.drive(s.t)[2]
        x_r, x_s = f.solve(np.concatenate([q_rib, bias_r], 1), np.concatenate([q_sh, bias_s]))
        n, ns = m.n_rib, m.n_shared
        return replace(s, lam_r=x_r[:, n:], lam_s=x_s[ns:])

    # ------------------------------------------------------------ the step
    def step(self, s: State3D, h: float, force: float, locked: bool) -> tuple[State3D, StepWork]:
        """One step of length h; raises ConvergenceError3D."""
        if self.compiled is not None:
            state, work = self.compiled.step(s, h, force, locked)
            self.iterations += work.iterations
            self.factorisations += work.factorisations
            return state, work
        with np.errstate(over='ignore', invalid='ignore'):
            return self._step(s, h, force, locked)

    def _kept_factor(self, s: State3D, h: float, locked: bool):
        """
        Return (the kept iteration matrix, its uses) if it serves a step from s, else None.

        It serves when s is where the step that used it ended (bit for bit), with the same
        length (to 1e-9), lock and stuck hinges, and it has served fewer than carry_steps
        steps: a rule of the trajectory alone.
        """
        kept = self._kept
        if kept is None:
            return None
        factor, uses, qr, qs, vr, vs, h_kept, locked_kept, stuck, projection = kept
        if (uses >= self.carry_steps or locked_kept != locked or abs(h_kept - h) > 1e-9 * h
                or not np.array_equal(stuck, np.isnan(s.stuck))):
            return None
        pairs = ((qr, s.qr), (qs, s.qs), (vr, s.vr), (vs, s.vs))
        same = all(np.array_equal(a, b) for a, b in pairs)
        return (factor, uses, projection) if same else None

    def _step(self, s: State3D, h: float, force: float, locked: bool):
        m = self.model
        n, ns = m.n_rib, m.n_shared
        qr0, qs0, vr0, vs0, stuck = s.qr, s.qs, s.vr, s.vs, s.stuck
        if s.pr is None:
            pr0, ps0 = m.matvec(m.mass_matrix(m.kinematics(qr0, qs0)), vr0, vs0)
        else:
            pr0, ps0 = s.pr, s.ps
        drive = None
        if self.drive is not None:
            drive = self.drive(s.t + h)
        phi_r0, phi_s0 = m.constraints(qr0, qs0, stuck, locked,
                                       None if drive is None else drive[0])
        # the scheme's velocity w0 (the mode fit; else v0)
        fit = self.stage2_fits(locked)
        wr0, ws0 = vr0, vs0
        if fit is not None:
            wr0, ws0 = fit.to_scheme(vr0, vs0)
        qr, qs = qr0 + h * wr0, qs0 + h * ws0
        lam_r, lam_s = s.lam_r.copy(), s.lam_s.copy()
        half_h2 = 0.5 * h * h
        beta = self.damping_beta
        kept = self._kept_factor(s, h, locked)
        factored, uses, projection = kept if kept is not None else (None, 0, None)
        self._kept = None
        factorisations = 0
        last = np.inf
        kin_mask = self.kin_shared
        for it in range(1, self.max_iterations + 1):
            dqr, dqs = qr - qr0, qs - qs0
            qmr, qms = qr0 + 0.5 * dqr, qs0 + 0.5 * dqs
            vr1, vs1 = 2.0 * dqr / h - wr0, 2.0 * dqs / h - ws0
            if fit is not None:
                vr1, vs1 = fit.to_physical(vr1, vs1)
            kin1 = m.kinematics(qr, qs)
            mass1 = m.mass_matrix(kin1)
            pr1, ps1 = m.matvec(mass1, vr1, vs1)
            kinm = m.kinematics(qmr, qms)
            gtr, gts = m.kinetic_gradient(kinm, vr0, vs0, vr1, vs1)
            # Gonzalez: dq . G_T = f(q1) - f(q0), f = 1/2 v0^T M(q) v1, the whole dq (the bus
            # angles' midpoint share included), the correction along the coordinates in
            # kin_mask only
            p0v = m.matvec(mass1, vr0, vs0)
            delta = 0.5 * (np.sum(p0v[0] * vr1) + p0v[1] @ vs1 - np.sum(pr0 * vr1)
                           - ps0 @ vs1)
            dd = np.sum(dqr * dqr) + np.sum(dqs[kin_mask] ** 2)
            scale = (0.5 * (np.sum(np.abs(p0v[0] * vr1)) + np.sum(np.abs(p0v[1] * vs1))
                            + np.sum(np.abs(pr0 * vr1)) + np.sum(np.abs(ps0 * vs1)))
                     + np.sum(np.abs(gtr * dqr)) + np.sum(np.abs(gts * dqs)))
            corr = gonzalez_discrepancy(delta - np.sum(gtr * dqr) - gts @ dqs, scale)
            if dd > 0.0 and corr:
                corr = corr / dd
                gtr = gtr + corr * dqr
                gts = gts + corr * np.where(kin_mask, dqs, 0.0)
            # joints: each row's Gonzalez gradient along the rib's coordinates
            phi_r, phi_s = m.constraints(qr, qs, stuck, locked,
                                         None if drive is None else drive[0])
            jm_rr, jm_rs, jm_ss, active = m.constraint_jacobian(qmr, stuck, locked)
            ddr = np.sum(dqr * dqr, 1)
            lin = np.einsum('rij,rj->ri', jm_rr, dqr) + jm_rs @ dqs
            size = (np.einsum('rij,rj->ri', np.abs(jm_rr), np.abs(qmr)) + np.abs(jm_rs)
                    @ np.abs(qms) + np.abs(phi_r) + np.abs(phi_r0))
            disc = gonzalez_discrepancy(phi_r - phi_r0 - lin, size)
            safe = np.where(ddr > 0.0, ddr, 1.0)
            jg_rr = jm_rr + np.where(ddr[:, None, None] > 0.0, np.einsum(
                'ri,rj->rij', disc / safe[:, None], dqr), 0.0)
            torque, slope = self.friction(dqr[:, m.i_a1], h)
            applied_r = -m.elastic_step_force(qr0, qr, qmr)
            applied_r[:, m.i_a1] += torque
            applied_s = np.zeros(ns)
            applied_s[0] = -force
            tangent = m.material_tangent(qmr) if beta else None
            if beta:
                applied_r, applied_s = self._damped(applied_r, applied_s, tangent, dqr, dqs,
                                                    h, fit)
            cons_r = np.einsum('rji,rj->ri', jg_rr, lam_r)
            cons_s = np.einsum('rji,rj->i', jm_rs, lam_r) + jm_ss.T @ lam_s
            # the scheme's momentum change S^T (M(q1) v1 - p0) (S^T M(q1) v1 - S^T p0: a
            # map a step less)
            dpr, dps = pr1 - pr0, ps1 - ps0
            if fit is not None:
                dpr, dps = fit.transpose(dpr, dps)
            res_r = dpr - h * (gtr + applied_r + cons_r)
            res_s = dps - h * (gts + applied_s + cons_s)
            if not (np.isfinite(res_r).all() and np.isfinite(res_s).all()):
                raise _non_finite(s.t + h)      # (the iterate left the law's domain)
            if factored is None:
                j_r = m.constraint_jacobian(qr, stuck, locked)
                gyro = m.gyroscopic(kinm, dqr / h)
                extra = m.elastic_step_matrix(qr0, qr, h) + 0.5 * h * gyro
                if beta:
                    extra += 0.5 * h * beta * tangent
                extra[:, m.i_a1, m.i_a1] -= 0.5 * h * h * slope
                factored = arrow.factor(*self._blocks(
                    mass1, (jm_rr, jm_rs, jm_ss), j_r[:3], stuck, active, extra))
                uses = 0
                factorisations += 1

            def update(res_r, res_s, phi_r, phi_s):
                """Return q, lambda and |dq| after the Newton update of these residuals."""
                rhs_r = np.concatenate([-0.5 * h * res_r, -phi_r], 1)
                rhs_s = np.concatenate([-0.5 * h * res_s, -phi_s])
                rhs_s[ns:][~active] = 0.0
                x_r, x_s = factored.solve(rhs_r, rhs_s)
                if fit is not None:
                    x_r[:, :n], x_s[:ns] = fit.newton_update(x_r[:, :n], x_s[:ns], h)
                return (qr + x_r[:, :n], qs + x_s[:ns], lam_r + x_r[:, n:] / half_h2,
                        lam_s + x_s[ns:] / half_h2,
                        max(float(np.max(np.abs(x_r[:, :n]))),
                            float(np.max(np.abs(x_s[:ns][self.norm_shared]), initial=0.0))))

            def joints():
                return m.constraints(qr, qs, stuck, locked, None if drive is None else drive[0])

            def correct_joints():
                nonlocal qr, qs, lam_r, lam_s
                qr, qs, lam_r, lam_s, _ = update(0.0 * res_r, 0.0 * res_s, *joints())
                self.joint_corrections += 1
            qr, qs, lam_r, lam_s, norm = update(res_r, res_s, phi_r, phi_s)
            if not math.isfinite(norm):
                raise _non_finite(s.t + h)
            rate = norm / last if it > 1 else 1.0
            if newton_converged(norm, rate, self.tolerance, lambda: _largest(*joints()),
                                None if m.moving_base else correct_joints):
                break
            if it > 1 and rate > REFRESH_RATE:
                factored = None
            last = norm
        else:
            raise ConvergenceError3D(f'Newton did not converge in {self.max_iterations} '
                                     f'iterations at t = {s.t + h:.9g} s')
        self.iterations += it
        self.factorisations += factorisations
        dqr, dqs = qr - qr0, qs - qs0
        vr, vs = 2.0 * dqr / h - wr0, 2.0 * dqs / h - ws0
        if fit is not None:
            vr, vs = fit.to_physical(vr, vs)
        kin1 = m.kinematics(qr, qs)
        mass1 = m.mass_matrix(kin1)
        torque, _ = self.friction(dqr[:, m.i_a1], h)
        w_fric = torque * dqr[:, m.i_a1]
        w_force = force * (qs0[0] - qs[0])
        w_drive = float(lam_s[1:] @ dqs[1:7]) if drive is not None else 0.0
        # the damping's dissipation dq . C dq / h (+ the fit's share): the work it took
        w_damp = 0.0
        if beta:
            tangent = m.material_tangent(qr0 + 0.5 * dqr)
            fr, fs = self._damped(np.zeros_like(dqr), np.zeros(ns), tangent, dqr, dqs, h, fit)
            w_damp = -(float(np.sum(fr * dqr)) + float(fs @ dqs))
        t_target = (0.5 * (np.sum(vr0 * pr0) + vs0 @ ps0) + m.strain_energy(qr0)
                    - m.strain_energy(qr) + w_force + float(np.sum(w_fric)) + w_drive - w_damp)
        free_bus = m.params.base == 'free'
        if free_bus:
            # the bus position is cyclic: its momentum p_X (the linear momentum) is exactly
            # that of the step's start; Newton leaves its tolerance in it, which a uniform
            # translation velocity removes (p_X is m_total X' + terms without X')
            vs = vs.copy()
            vs[1:4] += (ps0[1:4] - m.matvec(mass1, vr, vs)[1][1:4]) / m.total_mass
        keeps = not m.moving_base and locked and self.tolerance >= PROJECTION_KEPT_FROM
        if factorisations:          # (a projection is kept with the matrix factored with it)
            projection = None
        if keeps:
            vr, vs, factored_here = self.project_kept(mass1, qr, vr, vs, stuck, locked,
                                                      projection)
            projection = factored_here if factorisations else projection
        elif drive is None:        # (the hub fixed, or a free bus)
            vr, vs = self.project(kin1, mass1, qr, vr, vs, stuck, locked)
        else:
            # the drive's impulse (-mu on the bus coordinates) that puts the bus at its rates
            # works at the mean of the bus velocities before and after it
            v_bus = vs[1:7]
            vr, vs, mu = self.project(kin1, mass1, qr, vr, vs, stuck, locked, drive[1], True)
            w_drive -= 0.5 * float(mu[1:] @ (v_bus + vs[1:7]))
        pr1, ps1 = m.matvec(mass1, vr, vs)
        if drive is None:
            # scale the velocity relative to the mass centre's (König: T = |P|^2 / 2m + T_rel),
            # so the linear momentum stays as it is
            drift = np.zeros(m.n_shared)
            if free_bus:
                drift[1:4] = ps0[1:4] / m.total_mass
            t_drift = 0.5 * m.total_mass * float(drift @ drift)
            t_after = 0.5 * (np.sum(vr * pr1) + vs @ ps1) - t_drift
            t_rel = t_target - t_drift
            if t_after > 0.0 and t_after / 1.01 <= t_rel <= 1.01 * t_after:
                scale = math.sqrt(t_rel / t_after)
                vr, vs = vr * scale, (vs - drift) * scale + drift
                pr1, ps1 = m.matvec(mass1, vr, vs)
        state = State3D(s.t + h, qr, qs, vr, vs, lam_r, lam_s, stuck, pr1, ps1)
        self._kept = (factored, uses + 1, qr, qs, vr, vs, h, locked, np.isnan(stuck),
                      projection)
        return state, StepWork(w_force, w_fric, w_drive, it, factorisations, w_damp)

    def _damped(self, applied_r, applied_s, tangent, dqr, dqs, h, fit):
        """
        Return the applied forces with the damping's over the step dq (damping3d.py).

        tangent: B^T D B at the step's midpoint (model.material_tangent: K, linear beams).
        """
        applied_r = applied_r + damping_force(tangent, self.damping_beta, dqr, h)
        if fit is not None:         # (the fit's share: its damped modes' exact decay)
            fr, fs = fit.damping_force(dqr, dqs, h)
            applied_r, applied_s = applied_r - fr, applied_s - fs
        return applied_r, applied_s
