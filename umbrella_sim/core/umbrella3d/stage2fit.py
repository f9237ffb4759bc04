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
Stage 2's mode fit of the whole umbrella, for each base: which modes, and its maps.

integrators.LockedModeFit makes each resolved mode of a locked frame exact in phase,
amplitude and damping (its docstring): the scheme's velocity w = S^-1 v, momentum S^T p,
each Newton update shrunk mode by mode, S = I + Phi diag(s - 1) U^T (U = M0 Phi).  Which
modes, by base:

* the hub fixed or driven (``RibFits``): with the sleeve at the stop the ribs are decoupled
  in the hub's frame, so each rib's locked modes relative to the hub
  (modes3d.rib_locked_modes) are fitted rib by rib; a driven hub's coordinates are the
  drive's (its joints), not the modes', so S leaves them as they are, and a run whose drive
  is zero takes the fixed hub's steps.  The drive acts on the ribs as a base excitation
  (the bus's acceleration and rate through M_rs and the centrifugal terms): a forcing
  the midpoint rule integrates, the modes' own flow the fit makes exact.
* a free-floating bus (``WholeFit``): the bus couples the locked ribs, so the modes are the
  whole free system's (modes3d.free_locked_modes: bus + locked ribs, the six rigid-body
  modes left out, which the midpoint rule integrates exactly), one fit over every
  coordinate, linearised at the bus's attitude at the lock (``at_attitude``: the modes at
  rest turned to it, exactly, without an eigenproblem in the run).  Its U is zero on the bus's
  rows (each elastic mode carries no linear or angular momentum), so the scheme's momentum
  of the bus's coordinates is the physical one: the step keeps the free system's momentum
  as without the fit, and its energy T + V (S w is the physical velocity).  The cost is the
  whole system's modes times its coordinates a map (dense: the free bus's modes span every
  rib), against a rib's a rib for ``RibFits``.

Both take (rib rows (R, n), shared coordinates (n_shared,)) and return the pair mapped:
integrator3d.MidpointUmbrella._step's pieces; kernel3d.CompiledStep3D.set_mode_fit hands
their arrays to _kernel3d.c (fit_map) and _kernel3d_base.h (base_fit_map).
"""
from __future__ import annotations

from copy import copy

import numpy as np

from .model3d import BusFrame, UmbrellaModel3D
from .modes3d import free_locked_modes, rib_locked_modes
from ..integrators import LockedModeFit


class RibFits:
    """Each rib's LockedModeFit of its locked modes in the hub's frame (shared: S = I)."""

    whole = False

    def __init__(self, fits: list[LockedModeFit]):
        self.fits = fits

    def _each(self, rule, rows):
        return np.array([rule(f, row) for f, row in zip(self.fits, rows)])

    def to_scheme(self, vr, vs):
        """Return w = S^-1 v."""
        return self._each(LockedModeFit.to_scheme, vr), vs

    def to_physical(self, wr, ws):
        """Return v = S w."""
        return self._each(LockedModeFit.to_physical, wr), ws

    def transpose(self, pr, ps):
        """Return S^T p."""
        return self._each(LockedModeFit.transpose, pr), ps

    def newton_update(self, dr, ds, h: float):
        """Return the Newton update shrunk mode by mode (LockedModeFit.newton_update)."""
        return np.array([f.newton_update(d, h) for f, d in zip(self.fits, dr)]), ds

    def damping_force(self, dr, ds, h: float):
        """Return the fit's share of the damping force (LockedModeFit.damping_force)."""
        return np.array([f.damping_force(d, h) for f, d in zip(self.fits, dr)]), 0.0 * ds


class WholeFit:
    """One LockedModeFit of the free system's elastic modes over every coordinate."""

    whole = True

    def __init__(self, fit: LockedModeFit, n_ribs: int, n_rib: int):
        self.fit, self.shape = fit, (n_ribs, n_rib)

    def _apply(self, rule, ar, as_, *args):
        out = rule(self.fit, np.concatenate([ar.ravel(), as_]), *args)
        k = ar.size
        return out[:k].reshape(self.shape), out[k:]

    def to_scheme(self, vr, vs):
        """Return w = S^-1 v."""
        return self._apply(LockedModeFit.to_scheme, vr, vs)

    def to_physical(self, wr, ws):
        """Return v = S w."""
        return self._apply(LockedModeFit.to_physical, wr, ws)

    def transpose(self, pr, ps):
        """Return S^T p."""
        return self._apply(LockedModeFit.transpose, pr, ps)

    def newton_update(self, dr, ds, h: float):
        """Return the Newton update shrunk mode by mode (LockedModeFit.newton_update)."""
        return self._apply(LockedModeFit.newton_update, dr, ds, h)

    def damping_force(self, dr, ds, h: float):
        """Return the fit's share of the damping force (LockedModeFit.damping_force)."""
        return self._apply(LockedModeFit.damping_force, dr, ds, h)

    def at_attitude(self, attitude) -> 'WholeFit':
        """
        Return this fit (of the bus at rest at attitude 0) for the bus at attitude.

        The kinetic energy is the body frame's: T(q, v) = T0(J v) (T0 at attitude 0), J =
        diag(I, R^T, B0^-1 B) on (the ribs' and y_s, the bus's X', its angles' rates; B the
        rate basis, omega_body = B theta'), so M(attitude) = J^T M0 J (to round-off): each
        mode turns to J^-1 phi, mass-normalised in M(attitude) with the same frequency, and
        U = M phi to J^T U (zero on the bus's rows, as at rest).
        """
        bus, rest = BusFrame.of(np.asarray(attitude, dtype=float)), BusFrame.of(np.zeros(3))
        turn = np.linalg.solve(rest.basis, bus.basis)            # B0^-1 B
        k = self.shape[0] * self.shape[1] + 1
        x, theta = slice(k, k + 3), slice(k + 3, k + 6)
        fit = copy(self.fit)
        fit.shapes, fit.modes = self.fit.shapes.copy(), self.fit.modes.copy()
        # (rows of modes: phi^T J^-T, u^T J)
        fit.shapes[:, x] = self.fit.shapes[:, x] @ bus.rot.T
        fit.shapes[:, theta] = np.linalg.solve(turn, self.fit.shapes[:, theta].T).T
        fit.modes[:, x] = self.fit.modes[:, x] @ bus.rot.T
        fit.modes[:, theta] = self.fit.modes[:, theta] @ turn
        return WholeFit(fit, *self.shape)


def stage2_fit(model: UmbrellaModel3D, h: float, beta: float = 0.0,
               attitude=None) -> RibFits | WholeFit:
    """
    Return the stage-2 fit of the model's base for grid step h (module docstring).

    beta: the beams' damping C = beta K (damping3d.py), each mode fitted with its own
    damping phi^T C phi (LockedModeFit: exact decay too).
    """
    if model.params.base == 'free':
        n = model.n_ribs * model.n_rib
        damping = None
        if beta:
            damping = np.zeros((n + model.n_shared,) * 2)
            for k in range(model.n_ribs):
                rows = slice(k * model.n_rib, (k + 1) * model.n_rib)
                damping[rows, rows] = beta * model.stiffness[k]
        return WholeFit(LockedModeFit.of_modes(*free_locked_modes(model, attitude), h, damping),
                        model.n_ribs, model.n_rib)
    return RibFits([LockedModeFit.of_modes(*modes, h, beta * model.stiffness[k] if beta else None)
                    for k, modes in enumerate(rib_locked_modes(model))])
