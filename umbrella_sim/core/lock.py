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
    fixed = np.setdiff1d(np.arange(m.n), free)
    jac = m.constraint_jacobian(q, cs)
    a_free = jac[:, free]
    rhs = -jac[:, fixed] @ qd[fixed]
    particular = np.linalg.lstsq(a_free, rhs, rcond=None)[0]
    null = np.linalg.svd(a_free)[2][-1]
    base = qd.copy()
    base[free] = particular
    z = np.zeros(m.n)
    z[free] = null
    mass = m.mass_matrix(q)
    t_target = 0.5 * qd @ mass @ qd
    a = 0.5 * z @ mass @ z
    b = z @ mass @ base
    c = 0.5 * base @ mass @ base - t_target
    disc = b * b - 4 * a * c
    if disc < 0.0:
        raise LockImpossible('energy lock impossible: the kinetic energy before the lock is '
                             'below the least energy compatible with the lock '
                             f'({c + t_target - b * b / (4 * a):.6g} J > {t_target:.6g} J)')
    roots = [(-b + sgn * math.sqrt(disc)) / (2 * a) for sgn in (1.0, -1.0)]
    candidates = [base + r * z for r in roots]
    best = min(candidates, key=lambda v: (v - qd) @ mass @ (v - qd))
    labels = m.coordinate_labels()
    return best, tuple(labels[i] for i in free)
