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
The deployed antenna's natural frequencies: the modal table a structural engineer reads first.

The locked frame linearised at full deployment (the undeformed frame at its deployed angle,
the sleeve at the stop, K x = omega^2 M x on the null space of the locked joints): the
planar rib's ``UmbrellaModel.locked_modes``; the umbrella of N ribs' ``modes3d.locked_modes``
(the bus held; on a free-floating bus, ``modes3d.free_locked_modes``: the elastic modes,
the six rigid-body ones left out).  These are the modes stage 2 vibrates in (its tip
period is the first's, tests/test_summary.py) and the ones the stage-2 mode fit makes exact.
flexible-nonlinear linearises to the same beams.  Equal frequencies (the N identical ribs'
modes, decoupled by the stopped sleeve) are one row with their multiplicity.

On a prescribed base spinning at base_spin_rate the modes are the spinning antenna's
(``spun_modes3d.spun_locked_modes``): in the frame turning with the hub, about the ribs'
spun equilibrium, with the centrifugal stiffening of the co-rotational beams, the spin
softening and the Coriolis coupling, each mode's whirl (forward, backward) with them.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math

import numpy as np

from .model import UmbrellaModel
from .nonlinear import damping_beta_of
from .params import UmbrellaParams

#: the models with elastic modes (beams)
BEAM_MODELS = ('flexible', 'flexible-nonlinear')
#: frequencies within this relative distance are one repeated frequency (the identical
#: ribs' copies of a mode differ by round-off, ~1e-12)
REPEATED = 1e-7
#: a rib holds part of a mode when it has more than this share of the mode's strain energy
#: (a rib outside a held hub's rib-local mode: round-off, ~1e-30)
HOLDS = 1e-6


@dataclass(frozen=True)
class ModeRow:
    """A natural frequency of the locked frame, and where its mode's strain energy is."""

    #: omega (rad/s)
    omega: float
    #: how many modes have it (N identical ribs: N)
    multiplicity: int
    #: shares of the modes' strain energy in in-plane bending and stretching, in
    #: out-of-plane bending and in twist (the planar rib: 1, 0, 0)
    in_plane: float
    out_of_plane: float
    twist: float
    #: the rib holding the largest share of the modes' strain energy, and that share
    rib: int
    rib_share: float
    #: the modal damping ratio of the beams' C = beta K (beta omega / 2; 0 undamped)
    damping_ratio: float
    #: the modes are one copy a rib, each in a rib of its own: a repeated mode of identical
    #: ribs on the held hub (which decouples the ribs), not one the ribs move in together
    one_a_rib: bool = False
    #: on a spinning base, the modes' whirl about the spin axis (spun_modes3d): > 0 forward
    #: (with the spin), < 0 backward, 0 along a line (and without a spin)
    whirl: float = 0.0

    @property
    def frequency(self) -> float:
        """Return f = omega / 2 pi (Hz)."""
        return self.omega / (2.0 * math.pi)

    @property
    def period(self) -> float:
        """Return T = 2 pi / omega (s)."""
        return 2.0 * math.pi / self.omega

    def as_dict(self) -> dict:
        """Return the row as plain numbers (JSON)."""
        return {'frequency_hz': self.frequency, 'period_s': self.period, 'omega': self.omega,
                'multiplicity': self.multiplicity, 'in_plane': self.in_plane,
                'out_of_plane': self.out_of_plane, 'twist': self.twist, 'rib': self.rib,
                'rib_share': self.rib_share, 'damping_ratio': self.damping_ratio,
                'one_a_rib': self.one_a_rib, 'whirl': self.whirl}


def base_spin(params) -> float:
    """Return the steady spin of a prescribed base (rad/s): base_spin_rate; else 0."""
    if getattr(params, 'base', 'fixed') != 'prescribed':
        return 0.0
    return float(params.base_spin_rate)


def deployed_modes(params, count: int | None = None) -> list[ModeRow]:
    """
    Return the locked frame's natural frequencies, ascending, repeated ones as one row.

    params: the planar record (UmbrellaParams) or the umbrella's (UmbrellaRibsParams), of a
    model with beams (flexible, flexible-nonlinear); count: the first rows only (None: all).
    A prescribed base spinning (base_spin_rate): the spinning antenna's modes in the hub's
    frame about its spun equilibrium (module docstring).  ValueError for a rigid model,
    which has no elastic modes, or a spin the ribs do not survive.
    """
    planar = params if isinstance(params, UmbrellaParams) else params.planar
    if planar.model not in BEAM_MODELS:
        raise ValueError(f'model {planar.model}: a rigid frame has no elastic modes; give '
                         'model flexible (or flexible-nonlinear: the same linearised beams)')
    model = UmbrellaModel(planar.replace(model='flexible'))
    # beta of C = beta K: the planar rib's (umbrella3d/damping3d.py takes its planar record's)
    beta = damping_beta_of(model)
    if isinstance(params, UmbrellaParams):
        rows = [(w, (1.0, 0.0, 0.0), np.ones(1)) for w in model.locked_modes[0]]
        held = False
    else:
        rows = _umbrella_rows(params)
        held = params.base != 'free'
    out = []
    for group in _repeated_groups([r[0] for r in rows]):
        shares = np.mean([rows[i][1] for i in group], axis=0)
        by_rib = np.sum([rows[i][2] for i in group], axis=0)
        whirl = float(np.mean([rows[i][3] if len(rows[i]) > 3 else 0.0 for i in group]))
        rib = int(np.argmax(by_rib))
        omega = float(np.mean([rows[i][0] for i in group]))
        # the held hub decouples the ribs: the group is a sum of each rib's own modes, so as
        # many ribs holding its energy as it has modes means one a rib
        holding = int(np.count_nonzero(by_rib > HOLDS * by_rib.sum()))
        out.append(ModeRow(omega, len(group), *(max(0.0, float(s)) for s in shares), rib,
                           float(by_rib[rib] / by_rib.sum()), float(beta * omega / 2.0),
                           held and len(group) > 1 and holding == len(group), whirl))
        if count is not None and len(out) == count:
            break
    return out


def _umbrella_rows(params) -> list[tuple]:
    """
    Return (omega, (in-plane, out-of-plane, twist), strain energy by rib[, whirl]) of each mode.

    The whirl only where the base spins.
    """
    from .umbrella3d.model3d import UmbrellaModel3D
    from .umbrella3d.modes3d import free_locked_modes, locked_modes, mode_shares, rib_energies
    from .umbrella3d.spun_modes3d import spun_locked_modes

    if base_spin(params):
        spun = spun_locked_modes(params)
        return list(zip(spun.omega, spun.shares, spun.rib_energy, spun.whirl))
    model = UmbrellaModel3D(replace(params, planar=params.planar.replace(model='flexible')))
    if model.params.base == 'free':
        omega, shapes, _ = free_locked_modes(model)
        shares = mode_shares(model, shapes)
    else:
        omega, shapes, shares = locked_modes(model)
    return [(w, s, rib_energies(model, shapes[:, i]))
            for i, (w, s) in enumerate(zip(omega, shares)) if w > 0.0]


def _repeated_groups(omega: list[float]) -> list[list[int]]:
    """Return the indices of ascending omega grouped where they repeat (REPEATED)."""
    groups: list[list[int]] = []
    for i, w in enumerate(omega):
        if groups and w - omega[groups[-1][0]] <= REPEATED * w:
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups
