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
The locked umbrella's vibration modes, linearised at full deployment (validation and figures).

K x = omega^2 M x on the null space of the locked joints' Jacobian, about the undeformed
deployed configuration (each rib at its deployed angle, the sleeve at the stop), the
planar ``UmbrellaModel.locked_modes`` for the whole umbrella.  Dense (its cost is cubic in
the coordinates): for validation and for figures, not for the step.  Each mode is labelled
by where its energy is: the share of its strain energy in the out-of-plane bending and in
the twist, the rest in-plane.
"""
from __future__ import annotations

import weakref

import numpy as np

from .model3d import UmbrellaModel3D


def dense(model: UmbrellaModel3D, blocks_rr, blocks_rs=None, blocks_ss=None):
    """Return the full square matrix of arrow blocks (ribs first, shared coordinates last)."""
    nr, n, ns = model.n_ribs, model.n_rib, model.n_shared
    out = np.zeros((nr * n + ns, nr * n + ns))
    for k in range(nr):
        out[k * n:(k + 1) * n, k * n:(k + 1) * n] = blocks_rr[k]
        if blocks_rs is not None:
            out[k * n:(k + 1) * n, nr * n:] = blocks_rs[k]
            out[nr * n:, k * n:(k + 1) * n] = blocks_rs[k].T
    if blocks_ss is not None:
        out[nr * n:, nr * n:] = blocks_ss
    return out


def deployed_configuration(model: UmbrellaModel3D):
    """Return (qr, qs) of the undeformed umbrella at full deployment (hub at rest)."""
    qr = np.array([model.rigid_rib(k, model.alpha_deployed[k]) for k in range(model.n_ribs)])
    qs = np.zeros(model.n_shared)
    qs[0] = model.y_stop
    return qr, qs


def locked_modes(model: UmbrellaModel3D):
    """
    Return (omega (rad/s, ascending), shapes (coordinates, modes), labels) of the locked frame.

    The bus (a moving base) is held.  labels[i] = (in-plane, out-of-plane bending, twist)
    shares of mode i's strain energy.
    """
    from scipy.linalg import eigh, null_space

    m = model
    qr, qs = deployed_configuration(m)
    mass = dense(m, *m.mass_matrix(m.kinematics(qr, qs)))
    stiff = dense(m, m.stiffness)
    nr, n, ns = m.n_ribs, m.n_rib, m.n_shared
    stuck = np.full(nr, np.nan)
    j_rr, j_rs, j_ss, _ = m.constraint_jacobian(qr, stuck, True)
    rows = _joint_rows(m, j_rr, j_rs)
    fixed = np.zeros((ns, nr * n + ns))
    fixed[:, nr * n:] = np.eye(ns)          # the sleeve at the stop, the bus held
    z = null_space(np.vstack(rows + [fixed]))
    w2, psi = eigh(z.T @ stiff @ z, z.T @ mass @ z)
    shapes = z @ psi
    return np.sqrt(np.maximum(w2, 0.0)), shapes, mode_shares(m, shapes, stiff)


def mode_shares(model: UmbrellaModel3D, shapes: np.ndarray, stiff=None) -> list[tuple]:
    """
    Return each mode's (in-plane, out-of-plane bending, twist) shares of its strain energy.

    shapes: (coordinates, modes) over every coordinate (the ribs', rib-major, then the
    shared ones); stiff: the dense stiffness (None: assembled here).
    """
    stiff = dense(model, model.stiffness) if stiff is None else stiff
    return [_shares(model, stiff, shapes[:, i]) for i in range(shapes.shape[1])]


def rib_energies(model: UmbrellaModel3D, x: np.ndarray) -> np.ndarray:
    """Return each rib's strain energy x_k^T K_k x_k / 2 in a shape x over every coordinate."""
    n = model.n_rib
    return np.array([0.5 * x[k * n:(k + 1) * n] @ model.stiffness[k] @ x[k * n:(k + 1) * n]
                     for k in range(model.n_ribs)])


#: each model's mode analyses, which no step length changes: computed once a model (read-only
#: arrays).  A lock's stage-2 substeps fit the modes again at their step (stage2fit.py): at 24
#: ribs on a free bus the analyses were 0.13 of that refit's 0.31 CPU s (profiled)
_ANALYSES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _once(model: UmbrellaModel3D, key, compute):
    """Return compute()'s arrays for this model and key, computed at the first call only."""
    done = _ANALYSES.setdefault(model, {})
    if key not in done:
        out = compute()
        for a in (out if isinstance(out, list) else [out]):
            for x in a:
                x.flags.writeable = False
        done[key] = out
    return done[key]


def rib_locked_modes(model: UmbrellaModel3D) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """
    Return each rib's (omega, phi, mass) of the locked umbrella, the sleeve at the stop.

    With the sleeve stopped and the hub fixed the ribs are decoupled: rib k's modes are
    K_k x = omega^2 M_k x on the null space of its joints (a stuck hinge's row left out) at
    its undeformed deployed configuration, omega ascending, phi (n_rib, modes) mass-
    normalised in M_k = mass: the planar ``UmbrellaModel.locked_modes`` of one rib.
    Computed once a model (read-only arrays).
    """
    return _once(model, 'ribs', lambda: _rib_locked_modes(model))


def _rib_locked_modes(model: UmbrellaModel3D) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    from scipy.linalg import eigh, null_space

    m = model
    qr, qs = deployed_configuration(m)
    mass = m.mass_matrix(m.kinematics(qr, qs))[0]
    j_rr = m.constraint_jacobian(qr, np.full(m.n_ribs, np.nan), True)[0]
    out = []
    for k in range(m.n_ribs):
        z = null_space(j_rr[k, :-1])
        w2, psi = eigh(z.T @ m.stiffness[k] @ z, z.T @ mass[k] @ z)
        out.append((np.sqrt(np.maximum(w2, 0.0)), z @ psi, mass[k]))
    return out


def free_locked_modes(model: UmbrellaModel3D, attitude=None):
    """
    Return (omega, phi, mass) of the locked umbrella on a free-floating bus: its elastic modes.

    K x = omega^2 M x over every coordinate (the ribs', rib-major, then the shared ones:
    y_s and the bus's), on the null space of the locked joints (a stuck hinge's row left out)
    and the stop, at the undeformed deployed configuration with the bus at rest at its
    attitude (psi, beta, gamma; None: 0).  Any change of the bus coordinates alone moves
    the whole umbrella rigidly, so the rigid-body modes span the bus coordinates' unit
    vectors, and the elastic modes are the eigenvectors M-orthogonal to them: the rows
    e_b^T M of the bus coordinates b are imposed with the joints, which leaves the six
    rigid-body modes out (omega 0: the midpoint rule integrates them exactly) and makes each
    elastic mode carry no linear or angular momentum, U = M phi zero on the bus's rows.
    omega ascending, phi (coordinates, modes) mass-normalised in mass (dense, the whole
    system's): the modes the stage-2 fit of a free bus makes exact (stage2fit.BusFit).
    Computed once a model and attitude (read-only arrays).
    """
    key = ('free', None if attitude is None else tuple(float(a) for a in attitude))
    return _once(model, key, lambda: _free_locked_modes(model, attitude))


def _free_locked_modes(model: UmbrellaModel3D, attitude):
    from scipy.linalg import eigh, null_space

    m = model
    if m.params.base != 'free':
        raise ValueError('free_locked_modes: the bus is not free-floating (base: free)')
    qr, qs = deployed_configuration(m)
    if attitude is not None:
        qs[4:7] = attitude
    mass = dense(m, *m.mass_matrix(m.kinematics(qr, qs)))
    stiff = dense(m, m.stiffness)
    nr, n, ns = m.n_ribs, m.n_rib, m.n_shared
    j_rr, j_rs, _, _ = m.constraint_jacobian(qr, np.full(nr, np.nan), True)
    rows = _joint_rows(m, j_rr, j_rs)
    stop = np.zeros((1, nr * n + ns))
    stop[0, nr * n] = 1.0
    momenta = mass[nr * n + 1:]            # e_b^T M of the bus's six coordinates
    z = null_space(np.vstack(rows + [stop, momenta]))
    w2, psi = eigh(z.T @ stiff @ z, z.T @ mass @ z)
    return np.sqrt(np.maximum(w2, 0.0)), z @ psi, mass


def _shares(m: UmbrellaModel3D, stiff, x):
    """Return the (in-plane, out-of-plane bending, twist) shares of x's strain energy."""
    total = x @ stiff @ x
    parts = []
    for dofs in (('w', 'slope'), ('twist',)):
        mask = np.zeros(m.n_rib, dtype=bool)
        for bodies, s_e in ((m.leaf_bodies, m.s_leaf_e), (m.link_bodies, m.s_link_e)):
            body = bodies[0]
            for node in range(len(body.node_x)):
                for d in dofs:
                    i = body.maybe_index(node, d)
                    if i >= 0:
                        mask[s_e.start + i] = True
        sel = np.concatenate([np.tile(mask, m.n_ribs), np.zeros(m.n_shared, dtype=bool)])
        xs = np.where(sel, x, 0.0)
        parts.append(float(xs @ stiff @ xs / total) if total > 0 else 0.0)
    return (1.0 - parts[0] - parts[1], parts[0], parts[1])


def _joint_rows(m, j_rr: np.ndarray, j_rs: np.ndarray) -> list[np.ndarray]:
    """Return each rib's locked joint rows over every coordinate (the sleeve's row left out)."""
    nr, n, ns = m.n_ribs, m.n_rib, m.n_shared
    rows = []
    for k in range(nr):
        r = np.zeros((j_rr.shape[1] - 1, nr * n + ns))
        r[:, k * n:(k + 1) * n] = j_rr[k, :-1]
        r[:, nr * n:] = j_rs[k, :-1]
        rows.append(r)
    return rows
