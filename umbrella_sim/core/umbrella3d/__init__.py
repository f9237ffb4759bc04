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
The whole umbrella in 3D: N flexible ribs around one sleeve (the planar model's extension).

    params3d      UmbrellaRibsParams: the planar record, the number of ribs, the hub, the
                  sleeve, the base, and each rib's own values (lists or rib<k>.<name>)
    beam3d        the 3D Euler-Bernoulli body in its floating frame (axial, two bendings,
                  St-Venant torsion)
    corotational3d  model flexible-nonlinear: each rib's beams co-rotational (the planar
                  element in the rib's plane, out-of-plane bending and torsion small in its
                  co-rotated frame); compiled: _kernel3d_nonlinear.h
    model3d       UmbrellaModel3D: layout, mass, gradients, joints of every rib and the bus
    arrow         block-arrow linear algebra (cost linear in the number of ribs)
    state3d       State3D, StepWork: the umbrella's state and what a step did
    integrator3d  the energy-consistent midpoint step (the planar scheme), friction, drive:
                  the numpy reference, and the choice of the compiled step
    kernel3d      CompiledStep3D: the binding of the compiled step (_kernel3d.c; a moving
                  base: _kernel3d_base.h)
    simulator3d   UmbrellaSimulator3D: the grid, the lock, stuck hinges
    outputs3d     Record3D: every step's figures per rib, peaks, spread, energy balance
    modes3d       the locked umbrella's vibration modes (validation and figures)
    spun_modes3d  its modes on a base spinning steadily: the spun equilibrium, centrifugal
                  stiffening, spin softening, Coriolis (``umbrella_sim modes``)

No ROS, no file format, no command line (the core layer's rules).  docs/umbrella3d.md
gives the formulation and its validation.
"""
