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
Block-arrow linear algebra: N rib blocks coupled only through a few shared unknowns.

One sleeve couples the ribs: every rib's unknowns (its coordinates and joint multipliers)
touch only their own block and the shared ones (the sleeve, the bus, the stop's and the
drive's multipliers).  The system

    [ B_1           C_1 ] [x_1]   [r_1]
    [      ...      ... ] [...] = [...]
    [           B_N C_N ] [x_N]   [r_N]
    [ D_1  ...  D_N  E  ] [x_s]   [r_s]

is solved by the Schur complement of the shared block, S = E - sum_k D_k B_k^-1 C_k (at
most 15 x 15), so its cost grows linearly with the number of ribs.  Blocks are stacked in
arrays of shape (ribs, m, m): one batched LAPACK call factors them all (the layout a compiled
kernel takes over: each rib's block contiguous, ribs the outer index).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ArrowFactor:
    """A factored block-arrow matrix: rib blocks' inverses, B^-1 C, D and the Schur LU."""

    b_inv: np.ndarray          # (R, m, m)
    b_inv_c: np.ndarray        # (R, m, s)
    d: np.ndarray              # (R, s, m)
    schur_lu: tuple

    def solve(self, r_ribs: np.ndarray, r_shared: np.ndarray):
        """Return (x_ribs (R, m), x_shared (s,)) of the system for the right-hand side."""
        from scipy.linalg import lu_solve

        y = np.einsum('rij,rj->ri', self.b_inv, r_ribs)
        x_s = lu_solve(self.schur_lu, r_shared - np.einsum('rij,rj->i', self.d, y))
        return y - np.einsum('rij,j->ri', self.b_inv_c, x_s), x_s


def factor(b: np.ndarray, c: np.ndarray, d: np.ndarray, e: np.ndarray) -> ArrowFactor:
    """Factor the block-arrow matrix of rib blocks b (R, m, m), borders c, d and corner e."""
    from scipy.linalg import lu_factor

    b_inv = np.linalg.inv(b)
    b_inv_c = b_inv @ c
    schur = e - np.einsum('rij,rjk->ik', d, b_inv_c)
    return ArrowFactor(b_inv, b_inv_c, d, lu_factor(schur))
