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
Structural damping of the umbrella's 3D beams: the planar model's, C = beta K.

The planar model's definition (registry ``damping_ratio``; nonlinear.py, 'Structural
damping'): stiffness-proportional Rayleigh (Kelvin-Voigt) damping of the strain rates,
C = beta K over every rib's elastic coordinates (axial, both bendings and the twist), with
beta = 2 zeta / omega_1 (nonlinear.damping_beta_of), omega_1 the first natural frequency
of the planar rib of the umbrella's planar record locked and linearised at full deployment.
One beta for the umbrella: C = beta K is a property of the material (its loss over its
stiffness), which every rib shares; a rib of its own section or lengths keeps it, its modes
then damped by zeta omega_i / omega_1.  The planar rib's omega_1 (not the umbrella's own
first locked mode) is what makes N identical ribs each the damped planar model; it is each
rib's first in-plane mode, which carries ~92 % of the stage-2 tip crest, so that mode has
exactly zeta; the out-of-plane bending and torsion modes, zeta omega_i / omega_1
(tests/test_umbrella3d_damping.py measures both decays).

The co-rotational ribs (model flexible-nonlinear, corotational3d.py) damp their co-rotated
strain rates alike, as the planar co-rotational model (nonlinear.py): C(q) = beta B(q)^T D
B(q), B = ds/dq of the elements' strains (axial, both bendings, twist), with the same beta:
its material tangent (model.material_tangent; K for the linear beams, which is its value at
q = 0, so small motion is the linear ribs' damping).  In the midpoint step the damping
force is -C(q_m) dq / h (dq the step's increment of a rib's coordinates, q_m its midpoint;
h/2 C(q_m) in the iteration matrix, at the iterate it is factored at), so the step
dissipates exactly dq . C(q_m) dq / h >= 0 (with the stage-2 mode fit, linear beams only,
plus its share, integrators.LockedModeFit.damping_force); the step's energy target takes
it off and StepWork.damping carries it to Record3D, whose energy balance adds it back
(tests/test_umbrella3d_damping.py, tests/test_umbrella3d_corotational_damping.py).
"""
from __future__ import annotations

import numpy as np

from .substeps3d import planar_model
from ..nonlinear import damping_beta_of


def damping_beta(params) -> float:
    """Return the umbrella's beta (s): nonlinear.damping_beta_of its planar record (0 undamped)."""
    planar = params.planar
    if planar.damping_ratio == 0.0:
        return 0.0
    return damping_beta_of(planar_model(planar))


def damping_force(tangent: np.ndarray, beta: float, dqr: np.ndarray, h: float) -> np.ndarray:
    """
    Return each rib's damping force -beta B^T D B dq / h over a step (R, n).

    tangent: each rib's B^T D B at the step's midpoint (R, n, n): K for the linear beams.
    """
    return -beta / h * np.einsum('rij,rj->ri', tangent, dqr)
