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
* a free-floating bus (``BusFit``): the bus couples the locked ribs, so the modes made exact
  are the whole free system's (modes3d.free_locked_modes: bus + locked ribs, the six rigid-
  body modes left out, which the midpoint rule integrates exactly), linearised at the bus's
  attitude at the lock (``at_attitude``: the modes at rest turned to it, exactly, without an
  eigenproblem in the run).  Their fit over every coordinate (``WholeFit``) has U zero on the
  bus's rows (each elastic mode carries no linear or angular momentum), so the scheme's
  momentum of the bus's coordinates is the physical one: the step keeps the free system's
  momentum as without the fit, and its energy T + V (S w is the physical velocity).  It is
  dense (its modes span every rib: cost as the square of the ribs), so the step takes it as
  the ribs' own fits (``RibFits``, the clamped modes) composed with corrections of low rank
  to it (``bus_correction``: S = S_ribs S_bus, S_bus = S_ribs^-1 S_whole = I + A B^T, the
  Newton update and a damped fit's damping share the same way), which the two fits need
  only where the bus takes part: 18 to 34 directions at 3 to 24 ribs against 14 modes a rib,
  the maps the whole fit's to 1e-11, the cost linear in the ribs (stage 2 at 6 / 12 / 24
  ribs x 1, the compiled step alone: 132 / 264 / 531 us against the whole fit's 152 / 417 /
  1164 us).  The ribs' fits alone keep the momentum and T + V but leave the free modes'
  phase off by what the bus shifts them: at the default bus (100 kg, ribs a fortieth of it)
  up to 8.4e-4 of a frequency (a pair at omega h 1.03, 1.7 % stiffer than a rib's clamped
  mode; unfitted 7.7e-2), the tips of a run as near a converged one as the whole fit's
  (within 0.1 mm of 130 mm); at 5 kg 1.8e-2, the tips 14.5 mm off where the whole fit's are
  6.3 mm (docs/umbrella3d.md): a light bus needs the correction.

Each fit's maps take (rib rows (R, n), shared coordinates (n_shared,)) and return the pair
mapped: integrator3d.MidpointUmbrella._step's pieces; kernel3d.CompiledStep3D.set_mode_fit
hands their arrays to _kernel3d.c (fit_map) and _kernel3d_base.h (base_fit_map, every_map).
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
        return WholeFit(_turned(self.fit, attitude, self.shape), *self.shape)


class BusFit:
    """
    A free bus's fit at a rib's cost: the ribs' fits composed with the bus's correction.

    S = S_ribs S_bus equals the whole free system's S_whole (WholeFit) to BUS_TOLERANCE:
    S_bus = S_ribs^-1 S_whole = I + A B^T over every coordinate, of the few directions (the
    modes the bus takes part in) where the two fits differ (bus_correction).  Its maps: S w =
    S_ribs (S_bus w), S^-1 v = S_bus^-1 (S_ribs^-1 v), S^T p = S_bus^T (S_ribs^T p); the Newton
    update the whole fit's, (I + A_n B_n^T) the ribs' (``newton``); a damped fit's damping
    share the ribs' plus the difference to the whole fit's (``damping``: Y diag(e) Y^T dq / h).
    """

    whole = True            # (the whole free system's modes made exact, as WholeFit)

    def __init__(self, ribs: RibFits, bus: 'LowRankMap', newton: 'LowRankMap',
                 damping: 'LowRankMap | None' = None):
        self.ribs, self.bus, self.newton, self.damping = ribs, bus, newton, damping

    def to_scheme(self, vr, vs):
        """Return w = S^-1 v."""
        return self.bus.to_scheme(*self.ribs.to_scheme(vr, vs))

    def to_physical(self, wr, ws):
        """Return v = S w."""
        return self.ribs.to_physical(*self.bus.to_physical(wr, ws))

    def transpose(self, pr, ps):
        """Return S^T p."""
        return self.bus.transpose(*self.ribs.transpose(pr, ps))

    def newton_update(self, dr, ds, h: float):
        """Return the whole fit's Newton update: (I + A_n B_n^T) the ribs' (h: the fit's)."""
        return self.newton.to_physical(*self.ribs.newton_update(dr, ds, h))

    def damping_force(self, dr, ds, h: float):
        """Return the fit's share of the damping force: the whole fit's (class docstring)."""
        fr, fs = self.ribs.damping_force(dr, ds, h)
        if self.damping is None:
            return fr, fs
        cr, cs = self.damping.damping_force(dr, ds, h)
        return fr + cr, fs + cs

    def at_attitude(self, attitude) -> 'BusFit':
        """
        Return this fit for the bus at attitude (WholeFit.at_attitude: S turns to J^-1 S J).

        The damping share's difference is zero on the bus's rows and columns (both fits' U
        are), where alone J differs from I: it stays as it is.
        """
        return BusFit(self.ribs, self.bus.at_attitude(attitude), self.newton.at_attitude(attitude),
                      self.damping)

    @classmethod
    def of(cls, ribs: RibFits, whole: WholeFit) -> 'BusFit':
        """Return the ribs' fits with the correction that makes them the whole fit."""
        return cls(ribs, *bus_correction(ribs, whole))


#: the corrections' directions kept: singular values above this (S_bus - I = S_ribs^-1 S_whole
#: - I is small: what is left out moves a mode's frequency by about this, relatively)
BUS_TOLERANCE = 1e-10


def bus_correction(ribs: RibFits, whole: WholeFit
                   ) -> tuple['LowRankMap', 'LowRankMap', 'LowRankMap | None']:
    """
    Return BusFit's corrections of the ribs' fits to the whole fit: S_bus, Newton's, damping's.

    S_bus = S_ribs^-1 S_whole and N_whole N_ribs^-1 (N: a fit's Newton update, a linear map)
    differ from I by maps of low rank: where the two fits differ, in the modes the bus takes
    part in (3 to 24 ribs, identical or each with its own tip mass: 18 to 34 singular values
    above BUS_TOLERANCE, then a drop to round-off); their singular vectors above
    BUS_TOLERANCE give each as I + A B^T (LowRankMap).  Not as modes: S_bus is not
    self-adjoint in any metric the two share (each rib's fit is in its own block of the
    mass, the whole fit in the whole mass), and its eigenvectors are ill-conditioned
    (measured 8e5).  S_bus's B is zero on the bus's rows (S_bus - I vanishes on the bus
    coordinates' unit vectors: U_whole is zero on their rows, S_ribs is I there), set to
    zero exactly, so the scheme's momentum of the bus's coordinates is the physical one.
    The damping's (None undamped): U_whole diag(dc) U_whole^T less each rib's U diag(dc) U^T
    (dc: the damping changes), symmetric, as Y diag(e) Y^T of its eigenvectors with |e|
    above BUS_TOLERANCE of the largest.
    """
    nr, n = whole.shape
    f = whole.fit
    size = f.shapes.shape[1]
    shrink = f.newton_shrink(f.step)
    s_whole = np.eye(size) + f.shapes.T @ ((f.scale - 1.0)[:, None] * f.modes)
    n_whole = np.eye(size) - f.shapes.T @ (shrink[:, None] * f.modes)
    to_rib_scheme, from_rib_newton = np.eye(size), np.eye(size)
    rib_damping = np.zeros((size, size))
    for k, g in enumerate(ribs.fits):
        rows = slice(k * n, (k + 1) * n)
        to_rib_scheme[rows, rows] += g.shapes.T @ ((1.0 / g.scale - 1.0)[:, None] * g.modes)
        d = g.newton_shrink(g.step)               # (N^-1 = I + Phi diag(d / (1 - d)) U^T)
        from_rib_newton[rows, rows] += g.shapes.T @ ((d / (1.0 - d))[:, None] * g.modes)
        rib_damping[rows, rows] = g.modes.T @ (g.damping_change[:, None] * g.modes)
    bus = _low_rank(to_rib_scheme @ s_whole - np.eye(size), nr, n, nr * n + 1)
    newton = _low_rank(n_whole @ from_rib_newton - np.eye(size), nr, n)
    if not np.any(f.damping_change):
        return bus, newton, None
    change = f.modes.T @ (f.damping_change[:, None] * f.modes) - rib_damping
    e, y = np.linalg.eigh(0.5 * (change + change.T))
    keep = np.abs(e) > BUS_TOLERANCE * np.max(np.abs(e))
    return bus, newton, LowRankMap(y[:, keep].T * e[keep, None], y[:, keep].T, nr, n)


#: the directions a randomised range of a correction starts with (its rank: 18 to 34 at 3 to 24
#: ribs), and the seed of its test vectors (the same maps every run)
RANGE_START, RANGE_SEED = 64, 20061


def _low_rank(x: np.ndarray, n_ribs: int, n_rib: int, zero_from: int | None = None
              ) -> 'LowRankMap':
    """
    Return I + x as I + A B^T, x's singular vectors above BUS_TOLERANCE (B 0 from zero_from).

    The singular vectors of x's range, found by random test vectors (Halko, Martinsson &
    Tropp, SIAM Review 53, 2011: x Omega's orthonormal basis Q, then the SVD of Q^T x),
    taken where x - Q Q^T x leaves less than BUS_TOLERANCE / 100 (Frobenius), with twice the
    vectors until it does, and x's full SVD where they would be half its size: the same
    singular values above BUS_TOLERANCE as the full SVD (24 ribs: the two corrections 16 ms
    against 109 ms, profiled).
    """
    size = x.shape[1]
    rng = np.random.default_rng(RANGE_SEED)
    k = RANGE_START
    while 2 * k <= size:
        q = np.linalg.qr(x @ rng.standard_normal((size, k)))[0]
        small = q.T @ x
        if np.linalg.norm(x - q @ small) < 0.01 * BUS_TOLERANCE:
            left, sv, right = np.linalg.svd(small, full_matrices=False)
            left = q @ left
            break
        k *= 2
    else:
        left, sv, right = np.linalg.svd(x)
    keep = sv > BUS_TOLERANCE
    b = right[keep].copy()
    if zero_from is not None:
        b[:, zero_from:] = 0.0
    return LowRankMap((left[:, keep] * sv[keep]).T, b, n_ribs, n_rib)


class LowRankMap:
    """
    S = I + A B^T over every coordinate (rows a^T, b^T: (rank, coordinates)), and its maps.

    S^-1 = I - A C^T, C^T = (I + B^T A)^-1 B^T (Woodbury); S^T = I + B A^T.  Used as a
    damping share too, A B^T dq / h (A = Y diag(e), B = Y).
    """

    def __init__(self, a_rows: np.ndarray, b_rows: np.ndarray, n_ribs: int, n_rib: int):
        self.shape = (n_ribs, n_rib)
        self.a, self.b = np.ascontiguousarray(a_rows), np.ascontiguousarray(b_rows)
        small = np.eye(len(self.a)) + self.b @ self.a.T
        self.c = np.ascontiguousarray(np.linalg.solve(small, self.b))

    def _apply(self, out_rows, in_rows, sign, vr, vs, add: bool = True):
        v = np.concatenate([vr.ravel(), vs])
        change = sign * (out_rows.T @ (in_rows @ v))
        v = v + change if add else change
        k = vr.size
        return v[:k].reshape(self.shape), v[k:]

    def to_scheme(self, vr, vs):
        """Return S^-1 v."""
        return self._apply(self.a, self.c, -1.0, vr, vs)

    def to_physical(self, wr, ws):
        """Return S w."""
        return self._apply(self.a, self.b, 1.0, wr, ws)

    def transpose(self, pr, ps):
        """Return S^T p."""
        return self._apply(self.b, self.a, 1.0, pr, ps)

    def damping_force(self, dr, ds, h: float):
        """Return A B^T dq / h (a damping share)."""
        return self._apply(self.a, self.b, 1.0 / h, dr, ds, add=False)

    def at_attitude(self, attitude) -> 'LowRankMap':
        """Return this map for the bus at attitude: J^-1 S J (WholeFit.at_attitude's J)."""
        out = copy(self)
        out.a = _turn_rows(self.a, attitude, self.shape, False)
        out.b = _turn_rows(self.b, attitude, self.shape, True)
        out.c = _turn_rows(self.c, attitude, self.shape, True)
        return out


def _turned(fit: LockedModeFit, attitude, shape) -> LockedModeFit:
    """Return a fit over every coordinate (rows at attitude 0) at attitude (_turn_rows)."""
    out = copy(fit)
    out.shapes = _turn_rows(fit.shapes, attitude, shape, False)
    out.modes = _turn_rows(fit.modes, attitude, shape, True)
    return out


def _turn_rows(rows: np.ndarray, attitude, shape, covector: bool) -> np.ndarray:
    """
    Return rows over every coordinate (at attitude 0) turned to attitude: x^T J^-T, or u^T J.

    Vectors (a mode's shape phi) turn to J^-1 phi, covectors (its momentum row u = M phi) to
    J^T u (WholeFit.at_attitude's J).
    """
    bus, rest = BusFrame.of(np.asarray(attitude, dtype=float)), BusFrame.of(np.zeros(3))
    turn = np.linalg.solve(rest.basis, bus.basis)            # B0^-1 B
    k = shape[0] * shape[1] + 1
    x, theta = slice(k, k + 3), slice(k + 3, k + 6)
    out = rows.copy()
    out[:, x] = rows[:, x] @ bus.rot.T
    out[:, theta] = (rows[:, theta] @ turn if covector
                     else np.linalg.solve(turn, rows[:, theta].T).T)
    return np.ascontiguousarray(out)


def stage2_fit(model: UmbrellaModel3D, h: float, beta: float = 0.0,
               attitude=None) -> RibFits | BusFit:
    """
    Return the stage-2 fit of the model's base for grid step h (module docstring).

    beta: the beams' damping C = beta K (damping3d.py), each mode fitted with its own
    damping phi^T C phi (LockedModeFit: exact decay too).  A free bus's: the ribs' fits and
    the correction that makes them the whole free system's (BusFit).
    """
    ribs = RibFits([LockedModeFit.of_modes(*modes, h, beta * model.stiffness[k] if beta else None)
                    for k, modes in enumerate(rib_locked_modes(model))])
    if model.params.base != 'free':
        return ribs
    return BusFit.of(ribs, whole_fit(model, h, beta, attitude))


def whole_fit(model: UmbrellaModel3D, h: float, beta: float = 0.0,
              attitude=None) -> WholeFit:
    """Return a free bus's fit of the whole free system's modes (stage2_fit's arguments)."""
    n = model.n_ribs * model.n_rib
    damping = None
    if beta:
        damping = np.zeros((n + model.n_shared,) * 2)
        for k in range(model.n_ribs):
            rows = slice(k * model.n_rib, (k + 1) * model.n_rib)
            damping[rows, rows] = beta * model.stiffness[k]
    return WholeFit(LockedModeFit.of_modes(*free_locked_modes(model, attitude), h, damping),
                    model.n_ribs, model.n_rib)
