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
The locked umbrella's vibration modes on a base spinning steadily about Y (base: prescribed).

In the bus's frame, which turns at Omega = base_spin_rate about the hub axis Y (the bus
coordinates held at psi' = Omega, every other bus rate 0, the sleeve at the stop), each rib
first finds its spun equilibrium: the ribs deflected by the centrifugal load, the static
equations of the rotating frame with the locked joints,

    dT/dq (q, v0) - dU/dq (q) - J(q)^T lambda = 0,    Phi(q) = 0

(v0: the bus's spin alone; T = 1/2 v^T M(q) v the model's kinetic energy, whose gradient at
v0 is the centrifugal load; U the co-rotational strain energy of flexible-nonlinear), solved
by Newton from the undeformed deployed rib.  About it the equations of motion linearise to

    M x'' + G x' + (K_t + K_sigma + K_joint - K_spin) x = 0    on J x = 0

with M the mass matrix at the equilibrium; K_t + K_sigma = d^2 U / dq^2 there, the
co-rotational beams' Hessian (corotational3d.RibCorotationalStrain.tangent: the material
stiffness and the geometric stiffness of the preload, the centrifugal stiffening, which the
linear beams lack: at q = 0 it is their K); K_joint = sum_i lambda_i d^2 Phi_i / dq^2, the
joints' share of the preload (the rigid links' and hinges' geometric stiffness); K_spin =
d^2 T / dq^2 at v0 = Omega^2 d^2 (1/2 M_psi psi) / dq^2, the spin softening (Omega^2 M_c);
and G = D - D^T, D = d(M v0) / dq, the gyroscopic (Coriolis) matrix.  Every matrix is built
from the model's own functions, none hand-written: d^2 T / dq^2 and d(J^T lambda) / dq by
central differences of UmbrellaModel3D.kinetic_gradient and constraint_jacobian (a step of
DIFFERENCE_STEP times the rib's span; their truncation error is that step squared, ~1e-12,
their round-off ~1e-10 relative), D column by column from kinetic_gradient(e_j, v0), which
is 1/2 d(e_j^T M v0) / dq exactly.  On the null space Z of the locked joints' rows at the
equilibrium, the quadratic eigenproblem is solved in its state-space form, y = (x', x):
[[M, 0], [0, K]] y' + [[G, K], [-K, 0]] y = 0, whose matrix A is skew and B symmetric, so
y = z e^(i omega t) gives omega B z = i A z, a Hermitian problem (scipy.linalg.eigh): its
omega come in +- pairs and are real to the last bit wherever K > 0, where the general
eigensolver's round-off (~1e-6 of a mode at a stiff axial mode's 1e6 rad/s) put real parts
on them.

With the hub held at its spin and the sleeve at the stop the ribs are decoupled (as
modes3d.rib_locked_modes), so each rib is solved on its own, all ribs at once.  Coriolis
couples each rib's in-plane motion (its radial part) with its out-of-plane bending: a mode
is then complex, its points orbiting about the spin axis; ``whirl`` = Im(phi^H G phi) /
(2 |Omega| phi^H M phi), in [-1, 1] (its orbit's angular momentum about Y relative to the
spin's, over that of a circular orbit of the same kinetic energy): > 0 forward (with the
spin; Coriolis lowers its frequency in the rotating frame), < 0 backward, 0 a mode that
moves along a line.  Frequencies are the rotating frame's, about the spun equilibrium.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .corotational3d import CorotationalUmbrellaModel3D, NONLINEAR_MODEL
from .modes3d import mode_shares, rib_energies

#: the central differences' step, times the rib's span l1 + l2 (coordinates are metres and
#: radians): truncation ~ step^2, round-off ~ 1e-16 / step relative
DIFFERENCE_STEP = 1e-6
#: Newton on the spun equilibrium: converged when the joints hold to this times the span and
#: the largest coordinate update was below it times the span (the next error, quadratic in
#: it, is far below round-off; the update's own floor ~1e-12 at a nearly flat leaf)
EQUILIBRIUM_TOLERANCE = 1e-10
EQUILIBRIUM_ITERATIONS = 60
#: Newton's matrix is kept while each update shrinks by this factor at least, else formed
#: anew at the iterate (modified Newton: the matrix's differences are its cost)
KEEP_TANGENT = 0.05
#: where Newton from the undeformed ribs does not converge (its basin shrinks as the spin
#: deflects them: 36 rad/s and up with the thesis's section), the spin is raised from rest in
#: this many steps, each solved from the last; a step that fails is halved, at most
#: CONTINUATION_HALVINGS times
CONTINUATION_STEPS = 8
CONTINUATION_HALVINGS = 10
#: the locked rib rows: every joint but the stuck-hinge slot (model3d.N_RIB_ROWS - 1)
JOINT_ROWS = slice(0, 8)


@dataclass(frozen=True)
class SpunEquilibrium:
    """The locked umbrella's steady state on the spinning base, in the bus's frame."""

    #: spin rate about Y (rad/s)
    spin: float
    #: rib coordinates (R, n_rib), shared ones (y_s at the stop, the bus at psi = 0)
    qr: np.ndarray
    qs: np.ndarray
    #: velocities: the ribs' 0, the bus's spin psi' = spin
    vs: np.ndarray
    #: the locked joints' multipliers (R, 8): dT/dq - dU/dq = J^T lambda
    lam: np.ndarray
    #: Newton iterations taken
    iterations: int


@dataclass(frozen=True)
class SpunModes:
    """The spun umbrella's modes: omega ascending, complex shapes over every coordinate."""

    equilibrium: SpunEquilibrium
    #: rad/s, ascending (the rotating frame's)
    omega: np.ndarray
    #: (coordinates, modes) complex, each phi^H M phi = 1 (ribs rib-major, then shared: 0)
    shapes: np.ndarray
    #: each mode's whirl (module docstring): > 0 forward, < 0 backward
    whirl: np.ndarray
    #: each mode's (in-plane, out-of-plane bending, twist) shares of its strain energy
    shares: list
    #: each mode's strain energy by rib (R,)
    rib_energy: list


def spun_model(params) -> CorotationalUmbrellaModel3D:
    """Return the co-rotational umbrella of these parameters (its beams' geometric stiffness)."""
    if params.base != 'prescribed':
        raise ValueError(f'spun modes: base {params.base}: a spin is prescribed (base: '
                         'prescribed, base_spin_rate)')
    return CorotationalUmbrellaModel3D(replace(params, planar=params.planar.replace(
        model=NONLINEAR_MODEL)))


def _state(model, spin: float):
    """Return (qs, vs) of the bus spinning at psi' = spin, psi = 0, the sleeve at the stop."""
    qs, vs = np.zeros(model.n_shared), np.zeros(model.n_shared)
    qs[0] = model.y_stop
    vs[4] = spin
    return qs, vs


def _span(model) -> np.ndarray:
    """Return each rib's leaf span l1 + l2 (the differences' length scale)."""
    return np.array([r.planar.l1 + r.planar.l2 for r in model.ribs])


def _by_coordinate(f, qr: np.ndarray, step: np.ndarray) -> np.ndarray:
    """
    Return df/dq rib by rib (R, rows, n) by central differences, every rib's at once.

    f(qr) -> (R, rows): rib k's rows depend on rib k's coordinates alone (the hub held), so
    coordinate j of every rib moves together.
    """
    n = qr.shape[1]
    cols = []
    for j in range(n):
        dq = np.zeros_like(qr)
        dq[:, j] = step
        cols.append((f(qr + dq) - f(qr - dq)) / (2.0 * step[:, None]))
    return np.stack(cols, -1)


def _joints(model, qr, qs):
    """Return the locked joints' values (R, 8) and rows (R, 8, n) at qr."""
    stuck = np.full(model.n_ribs, np.nan)
    phi = model.constraints(qr, qs, stuck, True, qs[1:7])[0][:, JOINT_ROWS]
    jac = model.constraint_jacobian(qr, stuck, True)[0][:, JOINT_ROWS]
    return phi, jac


def _centrifugal(model, qs, vs):
    """Return f(qr) = dT/dq of the ribs at the bus's spin (their centrifugal load)."""
    zero = np.zeros((model.n_ribs, model.n_rib))

    def force(qr):
        return model.kinetic_gradient(model.kinematics(qr, qs), zero, vs, zero, vs)[0]
    return force


def _joint_force(model, lam):
    """Return f(qr) = J(qr)^T lambda (R, n)."""
    stuck = np.full(model.n_ribs, np.nan)

    def force(qr):
        jac = model.constraint_jacobian(qr, stuck, True)[0][:, JOINT_ROWS]
        return np.einsum('rin,ri->rn', jac, lam)
    return force


def _tangent(model, qr, lam, centrifugal, step):
    """Return K_t + K_sigma + K_joint - K_spin at (qr, lam) (R, n, n), symmetrised."""
    k = (model.strain.tangent(qr) + _by_coordinate(_joint_force(model, lam), qr, step)
         - _by_coordinate(centrifugal, qr, step))
    return 0.5 * (k + k.transpose(0, 2, 1))


def _newton(model, spin: float, qr: np.ndarray, lam: np.ndarray) -> SpunEquilibrium | None:
    """Return the spun equilibrium Newton finds from (qr, lam), or None if it does not."""
    qs, vs = _state(model, spin)
    span = _span(model)
    step = DIFFERENCE_STEP * span
    nr, n = model.n_ribs, model.n_rib
    centrifugal = _centrifugal(model, qs, vs)
    matrix, last, contraction = None, np.inf, 1.0
    with np.errstate(invalid='ignore', over='ignore', divide='ignore'):  # (a diverging iterate)
        for it in range(1, EQUILIBRIUM_ITERATIONS + 1):
            phi, jac = _joints(model, qr, qs)
            resid = (centrifugal(qr) - model.elastic_force(qr)
                     - np.einsum('rin,ri->rn', jac, lam))
            if matrix is None or contraction > KEEP_TANGENT:
                k = _tangent(model, qr, lam, centrifugal, step)
                top = np.concatenate([k, jac.transpose(0, 2, 1)], 2)
                bottom = np.concatenate([jac, np.zeros((nr, jac.shape[1], jac.shape[1]))], 2)
                matrix = np.concatenate([top, bottom], 1)
            rhs = np.concatenate([resid, -phi], 1)
            try:
                delta = np.linalg.solve(matrix, rhs[..., None])[..., 0]
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(delta)):
                return None
            qr, lam = qr + delta[:, :n], lam + delta[:, n:]
            size = float(np.max(np.abs(delta[:, :n]) / span[:, None]))
            contraction, last = size / last, size
            if (size < EQUILIBRIUM_TOLERANCE
                    and np.max(np.abs(phi) / span[:, None]) < EQUILIBRIUM_TOLERANCE):
                return SpunEquilibrium(spin, qr, qs, vs, lam, it)
    return None


def spun_equilibrium(model, spin: float) -> SpunEquilibrium:
    """
    Return the locked ribs' equilibrium in the frame spinning at `spin` about Y (Newton).

    From the undeformed deployed ribs (the equilibrium at rest); where Newton does not
    converge from there, by continuation in the spin from rest (CONTINUATION_STEPS), the
    branch the lower spins are on. ValueError naming base_spin_rate and the highest spin
    reached if that fails too (a spin past a rib's stability).
    """
    from .modes3d import deployed_configuration

    rest, _ = deployed_configuration(model)
    lam0 = np.zeros((model.n_ribs, JOINT_ROWS.stop))
    eq = _newton(model, spin, rest, lam0)
    if eq is not None:
        return eq
    reached, qr, lam, iterations = 0.0, rest, lam0, 0
    increment = spin / CONTINUATION_STEPS
    while True:
        target = spin if abs(spin - reached) <= abs(increment) * (1 + 1e-12) else (
            reached + increment)
        eq = _newton(model, target, qr, lam)
        if eq is None:
            increment /= 2
            if abs(increment) < abs(spin) / CONTINUATION_STEPS / 2 ** CONTINUATION_HALVINGS:
                raise ValueError(
                    f'base_spin_rate {spin:g} rad/s: no steady spun equilibrium of the locked '
                    f'ribs (Newton did not converge in {EQUILIBRIUM_ITERATIONS} iterations, '
                    f'from rest nor continued in the spin: the last found at {reached:g} '
                    'rad/s)')
            continue
        iterations += eq.iterations
        if target == spin:
            return replace(eq, iterations=iterations)
        reached, qr, lam = target, eq.qr, eq.lam


def spun_matrices(model, eq: SpunEquilibrium):
    """
    Return (M, G, K) of each rib (R, n, n) linearised about the spun equilibrium.

    M the mass matrix, G = D - D^T the gyroscopic matrix, K = K_t + K_sigma + K_joint -
    K_spin (module docstring), over each rib's coordinates (the joints not yet imposed).
    """
    nr, n = model.n_ribs, model.n_rib
    kin = model.kinematics(eq.qr, eq.qs)
    mass = model.mass_matrix(kin)[0]
    zero_s = np.zeros(model.n_shared)
    zero_r = np.zeros((nr, n))
    d = np.zeros((nr, n, n))
    for j in range(n):
        unit = np.zeros((nr, n))
        unit[:, j] = 1.0
        # 1/2 d(e_j^T M v0)/dq: row j of D = d(M v0)/dq, exactly
        d[:, j, :] = 2.0 * model.kinetic_gradient(kin, unit, zero_s, zero_r, eq.vs)[0]
    step = DIFFERENCE_STEP * _span(model)
    stiff = _tangent(model, eq.qr, eq.lam, _centrifugal(model, eq.qs, eq.vs), step)
    return mass, d - d.transpose(0, 2, 1), stiff


def spun_locked_modes(params, spin: float | None = None) -> SpunModes:
    """
    Return the locked umbrella's modes on the base spinning at `spin` (None: base_spin_rate).

    params: UmbrellaRibsParams with base prescribed; module docstring for the method.
    ValueError naming base_spin_rate where the spun equilibrium is unstable.
    """
    from scipy.linalg import eigh, null_space

    model = spun_model(params)
    spin = params.base_spin_rate if spin is None else float(spin)
    eq = spun_equilibrium(model, spin)
    mass, gyro, stiff = spun_matrices(model, eq)
    _, jac = _joints(model, eq.qr, eq.qs)
    nr, n, ns = model.n_ribs, model.n_rib, model.n_shared
    found = []                                  # (omega, rib, phi (n,) complex, whirl)
    for k in range(nr):
        z = null_space(jac[k])
        m, g, kk = (z.T @ a[k] @ z for a in (mass, gyro, stiff))
        # [[M, 0], [0, K]] y' + [[G, K], [-K, 0]] y = 0, y = (x', x): the skew A times i is
        # Hermitian, so omega B z = i A z has real omega (+-) where K > 0
        r = z.shape[1]
        zero = np.zeros((r, r))
        try:
            lam, vec = eigh(1j * np.block([[g, kk], [-kk, zero]]),
                            np.block([[m, zero], [zero, kk]]).astype(complex))
        except np.linalg.LinAlgError:
            raise ValueError(f'base_spin_rate {spin:g} rad/s: the spun rib {k} has lost its '
                             'stiffness (softened past zero: it diverges); no vibration '
                             'modes') from None
        for i in np.flatnonzero(lam > 0.0):
            phi = z @ vec[r:, i]
            phi = phi / np.sqrt((phi.conj() @ mass[k] @ phi).real)
            j = int(np.argmax(np.abs(phi)))
            phi = phi * (abs(phi[j]) / phi[j])                  # its largest entry real
            gamma = (phi.conj() @ gyro[k] @ phi).imag
            found.append((float(lam[i]), k, phi,
                          gamma / (2.0 * abs(spin)) if spin else 0.0))
    found.sort(key=lambda f: (f[0], f[1]))
    shapes = np.zeros((nr * n + ns, len(found)), dtype=complex)
    for i, (_, k, phi, _) in enumerate(found):
        shapes[k * n:(k + 1) * n, i] = phi
    shares, energy = [], []
    for i in range(len(found)):
        parts = (shapes[:, i].real, shapes[:, i].imag)
        by_rib = [rib_energies(model, x) for x in parts]
        weight = [float(e.sum()) for e in by_rib]
        total = sum(weight) or 1.0
        each = mode_shares(model, np.column_stack(parts))
        shares.append(tuple(sum(w * s[c] for w, s in zip(weight, each)) / total
                            for c in range(3)))
        energy.append(by_rib[0] + by_rib[1])
    return SpunModes(eq, np.array([f[0] for f in found]), shapes,
                     np.array([f[3] for f in found]), shares, energy)
