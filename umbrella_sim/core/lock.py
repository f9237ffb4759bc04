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
The lock's velocity rules: what the frame's velocity becomes when the sleeve reaches the stop.

``plastic_velocity``: the closest velocity in the mass metric that satisfies the locked
constraints (a perfectly plastic impact, thesis 5.22); ``energy_velocity``: the thesis's
redistribution (5.2.2) that keeps the kinetic energy.  The engines apply them at the lock;
step_rule judges a mesh's step on the stage-2 vibration they start.
"""
from __future__ import annotations

import math

import numpy as np

from .model import ConstraintSet, UmbrellaModel


class LockImpossible(ArithmeticError):
    """The energy lock has no velocity keeping the kinetic energy (the frame is too slow)."""


def plastic_velocity(model: UmbrellaModel, q, qd, cs: ConstraintSet) -> np.ndarray:
    """Return the closest velocity to qd (mass metric) with J qd = 0: a plastic impact (5.22)."""
    jac = model.constraint_jacobian(q, cs)
    metric = model.mass_matrix(q)
    n, nc = model.n, jac.shape[0]
    kkt = np.zeros((n + nc, n + nc))
    kkt[:n, :n] = metric
    kkt[:n, n:] = jac.T
    kkt[n:, :n] = jac
    sol = np.linalg.solve(kkt, np.concatenate([metric @ qd, np.zeros(nc)]))
    return sol[:n]


def energy_velocity(model: UmbrellaModel, q, qd, cs: ConstraintSet) -> tuple[np.ndarray, tuple]:
    """
    Redistribute the velocities at the lock, keeping the kinetic energy: (qd, names changed).

    Thesis 5.2.2 for any mesh: only the rigid velocities (R2x', R2y', alpha1', alpha2') and
    the link's axial velocity at H change; they satisfy J2 qd = 0 (5.36-5.39) and keep the
    kinetic energy (5.35).  Of the two energy roots, the one closest to the pre-lock
    velocities in the mass metric is taken.  Raises LockImpossible if there is none.
    """
    m = model
    free = [m.i_alpha1, m.i_r2x, m.i_r2y, m.i_alpha2, m.i_u_sleeve]
    best = velocity_keeping_energy(m.constraint_jacobian(q, cs), m.mass_matrix(q), qd, free)
    labels = m.coordinate_labels()
    return best, tuple(labels[i] for i in free)


def locked_velocity_base(jac: np.ndarray, v: np.ndarray, free) -> np.ndarray:
    """
    Return v with its `free` entries set to satisfy jac v = 0 (least squares).

    The other entries keep their values: the particular solution of the energy lock, to which
    a multiple of the free entries' null direction is added (velocity_keeping_energy).
    """
    fixed = np.setdiff1d(np.arange(len(v)), free)
    a_free = jac[:, free]
    rhs = -jac[:, fixed] @ v[fixed]
    base = v.copy()
    base[free] = np.linalg.lstsq(a_free, rhs, rcond=None)[0]
    return base


def velocity_keeping_energy(jac: np.ndarray, mass: np.ndarray, v: np.ndarray,
                            free) -> np.ndarray:
    """
    Return the velocity after an energy lock: jac v' = 0, v' M v' = v M v (thesis 5.2.2).

    Only the `free` entries change: locked_velocity_base plus r times the null direction of
    jac's free columns, r a root of the kinetic energy's quadratic; of the two roots, the one
    closest to v in the mass metric.  Raises LockImpossible if there is none.
    """
    base = locked_velocity_base(jac, v, free)
    z = np.zeros(len(v))
    z[free] = np.linalg.svd(jac[:, free])[2][-1]
    t_target = 0.5 * v @ mass @ v
    a = 0.5 * z @ mass @ z
    b = z @ mass @ base
    c = 0.5 * base @ mass @ base - t_target
    disc = b * b - 4 * a * c
    if disc < 0.0:
        raise LockImpossible('energy lock impossible: the kinetic energy before the lock is '
                             'below the least energy compatible with the lock '
                             f'({c + t_target - b * b / (4 * a):.6g} J > {t_target:.6g} J)')
    roots = [(-b + sgn * math.sqrt(disc)) / (2 * a) for sgn in (1.0, -1.0)]
    return min((base + r * z for r in roots), key=lambda w: (w - v) @ mass @ (w - v))
