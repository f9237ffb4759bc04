#!/usr/bin/env python3

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
Two ribs of the umbrella with geometrically exact 3D beams in Exudyn: the 3D reference.

An independent model of the umbrella of two ribs (azimuths 0 and pi about Y, hub radius 0,
sleeve mass 0) for the co-rotational ribs (model flexible-nonlinear, docs/
umbrella3d_nonlinear.md): every leaf O-O''-G and link O''-H of Exudyn's geometrically exact
3D beam elements (ObjectBeamGeometricallyExact: two rigid-body nodes with Euler parameters,
finite rotations, axial, shear, bending in both planes and torsion; Simo-Reissner's strain
measures), n elements a segment.  The leaf hinged at O about its rib's tangential axis e_t
(a revolute joint to the ground), the link hinged to the leaf at O'' about the sections'
common e_t axis (a revolute joint between the two nodes), the link's end H on the axle
(x = z = 0) hinged to the sleeve about e_t (the sleeve does not turn: the hub is fixed), the
two H's at one height y (the sleeve).  Rib 1 carries a point mass m at its leaf tip G
offset by d along e_t (an Exudyn rigid body sharing G's node, its centre of mass at d along
the section's z axis), so that the leaf's in-plane acceleration twists and bends it out of
its plane.  Started as the rigid mechanism at alpha0 with the sleeve at V0, no gravity, no
sleeve force.  Stage 1 to the instant the sleeve reaches the stop (found from the run, then
run again to exactly that instant), the plastic lock (the velocities projected onto the
locked joints in the mass metric, Exudyn's own mass matrix and constraint Jacobian at the
lock), then stage 2 with the sleeve held.  Time integration: Newmark beta = 1/4,
gamma = 1/2 (the trapezoidal rule), index-3 constraints.

The section is the thesis's square (E, rho, b = 0.01 m) with the umbrella's torsion
constant J = 0.1406 b^4 and G = E / 2(1 + nu), nu = 0.33; shear stiffness G A (5/6): the
shear a slender beam's (b / l = 0.02) bending barely feels; the rotary inertia rho I of the
sections (the Euler-Bernoulli model has none of bending: ~(b / l)^2 of the mass).

A free-floating bus (--bus): three ribs (azimuths 2 pi k / 3) on a rigid bus (BUS: 10 kg,
0.5 kg m^2 about X and Z, 0.1 about the hub axis Y; its mass centre at the hub, the origin),
the leaf hinges O joined to the bus, the sleeve a body (massless, as the umbrella's default)
sliding on the bus's Y axis and turning with it, each H hinged to it about e_t, the stop the
sleeve's joint holding its height on the bus.  Rib 1 carries the tip mass (BUS_TIP: 0.1 kg at
0.05 m along e_t), so the bus tilts (the mass centre moves off the axis) and turns about the
hub axis (the offset swings about it) in reaction.  At t = 0 the whole system takes the rigid
velocity that makes its momentum zero (the umbrella's rule for a free bus: the bus's own).
The momentum is the discrete model's, Exudyn's mass matrix applied to the rigid motions'
velocities (translations, turns about the origin: every node's w x r and Euler-parameter
rates); the bus's turn and tilt by outputs3d.bus_attitude, the tips in the bus's frame.

Needs Exudyn (``pip install exudyn``; never a dependency of umbrella_sim).  Writes
docs/exudyn_umbrella_ribs.json (tests/test_umbrella3d_exudyn.py compares with it) or, with
--bus, docs/exudyn_umbrella_bus.json (tests/test_umbrella3d_exudyn_bus.py); progress on
stderr.

    python docs/exudyn_umbrella_ribs.py [--cases n:h:m:d ...] [--append] [--out FILE]
    python docs/exudyn_umbrella_ribs.py --bus [--cases n:h[:m:d] ...] [--append] [--out FILE]

The default cases (tip masses 0.01 kg at 0.01 m and 0.1 kg at 0.07 m; n = 4, 8, and 16 for
the second) take 22, 47, 22, 49 and 307 CPU s on a loaded 2-core machine; the bus's (n = 4,
8, 16) 165 CPU s together (n = 8: 34 s), the tip mass in the plane (8, 16) 159 (load 2.3).
"""
import argparse
import json
import math
import os
import re
import sys

import exudyn as exu
from exudyn.itemInterface import (CoordinateConstraint, GenericJoint, MarkerBodyRigid,
                                  MarkerNodeCoordinate, MarkerNodeRigid, NodePointGround,
                                  NodeRigidBodyEP, ObjectBeamGeometricallyExact, ObjectGround,
                                  ObjectRigidBody, SensorNode)
from exudyn.rigidBodyUtilities import (AngularVelocity2EulerParameters_t,
                                       RotationMatrix2EulerParameters)
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))
sys.path.insert(0, HERE)

from exudyn_umbrella_frame import trapezoidal_settings  # noqa: E402, I100
from umbrella_sim.core.params import UmbrellaParams  # noqa: E402
from umbrella_sim.core.summary import stage2_figures  # noqa: E402
from umbrella_sim.core.umbrella3d.outputs3d import bus_attitude  # noqa: E402

OUT = os.path.join(HERE, 'exudyn_umbrella_ribs.json')
#: the case: two ribs, V0 = -1 m/s, rib 1's tip mass and its offset out of the plane
V0 = -1.0
POISSON = 0.33
STAGE2 = 0.13
SERIES_STEP = 2e-4
#: the free bus's case (--bus): three ribs, rib 1's tip mass off its plane, a light bus
BUS_OUT = os.path.join(HERE, 'exudyn_umbrella_bus.json')
BUS_RIBS = 3
#: bus mass (kg), moments about its X and Z (kg m^2), about the hub axis Y
BUS = (10.0, 0.5, 0.1)
BUS_TIP = (0.1, 0.05)
BUS_STAGE2 = 0.02
#: n:h[:m:d], elements a segment, step (s) and rib 1's tip mass and offset (default BUS_TIP);
#: the tip mass in the rib's plane (d = 0) sets the offset's share of the difference apart
BUS_CASES = ('4:2e-5', '8:1e-5', '16:5e-6', '8:1e-5:0.1:0', '16:5e-6:0.1:0')
#: n:h:m:d, elements a segment, step (s), rib 1's tip mass (kg) and its offset along e_t (m)
DEFAULT_CASES = ('4:2e-5:0.01:0.01', '8:1e-5:0.01:0.01', '4:2e-5:0.1:0.07', '8:1e-5:0.1:0.07',
                 '16:5e-6:0.1:0.07')


def rib_axes(azimuth):
    """Return e_r, e_Y, e_t of the rib at this azimuth (model3d's frame)."""
    c, s = math.cos(azimuth), math.sin(azimuth)
    return np.array([c, 0.0, -s]), np.array([0.0, 1.0, 0.0]), np.array([s, 0.0, c])


class Ribs:
    """
    The ribs' Exudyn system: on the ground (bus None), or on a free bus.

    bus: (mass, inertia, inertia about Y) of a rigid bus, its centre of mass at the hub
    (the origin), its axes the inertial ones at t = 0; the sleeve is then a body (sleeve_mass)
    sliding on the bus's Y axis and turning with it, each link's end H hinged to it.
    """

    def __init__(self, p: UmbrellaParams, n: int, locked: bool, tip: tuple, ribs: int = 2,
                 bus: tuple | None = None, sleeve_mass: float = 0.0):
        self.sc = exu.SystemContainer()
        mbs = self.mbs = self.sc.AddSystem()
        self.p, self.n, self.tip = p, n, tip
        b = p.section_height
        area, inertia = p.cross_section_area, p.cross_section_inertia
        youngs, shear = p.youngs_modulus, p.youngs_modulus / (2.0 * (1.0 + POISSON))
        torsion = 0.1406 * b ** 4
        section = exu.BeamSection()
        section.stiffnessMatrix = np.diag([youngs * area, shear * area * 5 / 6,
                                           shear * area * 5 / 6, shear * torsion,
                                           youngs * inertia, youngs * inertia])
        section.inertia = p.density * np.diag([2 * inertia, inertia, inertia])
        section.massPerLength = p.mass_per_length
        self.section = section
        a1 = p.alpha0
        a2 = math.acos(-p.l1 / p.l3 * math.cos(a1))
        da2 = -p.l1 * math.sin(a1) / (p.l3 * math.sin(a2))
        w1 = p.v0 / (p.l1 * math.cos(a1) + p.l3 * math.cos(a2) * da2)
        w2 = da2 * w1
        ground_node = mbs.AddNode(NodePointGround(referenceCoordinates=[0, 0, 0]))
        self.m_ground = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=ground_node,
                                                           coordinate=0))
        self.ground = mbs.AddObject(ObjectGround())
        self.base, self.bus, self.sleeve = self.ground, None, None
        if bus is not None:
            self._bus_and_sleeve(bus, sleeve_mass, locked, a1, a2)
        self.ribs, self.sensors = [], []
        h_nodes = []
        for k in range(ribs):
            er, ey, et = rib_axes(2.0 * math.pi * k / ribs)
            frame = np.column_stack([er, ey, et])
            d1 = math.cos(a1) * er + math.sin(a1) * ey
            d2 = math.cos(a2) * er + math.sin(a2) * ey
            r2 = p.l1 * d1
            leaf = self._chain(np.zeros(3), d1, et, w1 * et, np.zeros(3), p.l1 + p.l2, 2 * n)
            link = self._chain(r2, d2, et, w2 * et, w1 * np.cross(et, r2), p.l3, n)
            # O: the leaf hinged to the ground about e_t
            self._hinge(None, leaf[0], frame, [1, 1, 1, 1, 1, 0])
            # O'': the link hinged to the leaf about e_t
            self._hinge(leaf[n], link[0], frame, [1, 1, 1, 1, 1, 0])
            if bus is None:
                # H on the axle, hinged to the (non-turning) sleeve about e_t
                self._hinge(None, link[n], frame, [1, 0, 1, 1, 1, 0])
            else:
                # H hinged about e_t to the sleeve (which slides on the bus's axle)
                self._hinge(self.sleeve, link[n], frame, [1, 1, 1, 1, 1, 0])
            h_nodes.append(link[n])
            if k == 1:
                self._tip_mass(leaf[2 * n])
            self.ribs.append({'leaf': leaf, 'link': link, 'axes': (er, ey, et)})
            self.sensors.append({
                key: [mbs.AddSensor(SensorNode(nodeNumber=nd, outputVariableType=var,
                                               storeInternal=True, writeToFile=False))
                      for nd in nodes]
                for key, var, nodes in (
                    ('G', exu.OutputVariableType.Position, [leaf[2 * n]]),
                    ('J', exu.OutputVariableType.Position, [leaf[n]]),
                    ('H', exu.OutputVariableType.Position, [link[n]]),
                    ('R', exu.OutputVariableType.RotationMatrix, leaf + link))})
        if bus is None:
            ma = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=h_nodes[0], coordinate=1))
            mb = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=h_nodes[1], coordinate=1))
            mbs.AddObject(CoordinateConstraint(markerNumbers=[ma, mb]))      # one sleeve
            h_ref = r2 + p.l3 * d2
            mh = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=h_nodes[0], coordinate=1))
            mbs.AddObject(CoordinateConstraint(markerNumbers=[self.m_ground, mh],
                                               offset=p.sleeve_stop_height - h_ref[1],
                                               activeConnector=locked))       # the stop
        mbs.Assemble()

    def _bus_and_sleeve(self, bus, sleeve_mass, locked, a1, a2):
        """Add the bus (a rigid body at the origin) and the sleeve sliding on its Y axis."""
        mbs, p = self.mbs, self.p
        mass, inertia, inertia_y = bus
        ep0 = RotationMatrix2EulerParameters(np.eye(3))
        node = mbs.AddNode(NodeRigidBodyEP(referenceCoordinates=[0.0] * 3 + list(ep0)))
        self.bus_node = node
        self.base = self.bus = mbs.AddObject(ObjectRigidBody(
            nodeNumber=node, physicsMass=mass,
            physicsInertia=[inertia, inertia_y, inertia, 0.0, 0.0, 0.0]))
        y_h = p.l1 * math.sin(a1) + p.l3 * math.sin(a2)
        self.sleeve = mbs.AddNode(NodeRigidBodyEP(
            referenceCoordinates=[0.0, y_h, 0.0] + list(ep0),
            initialVelocities=[0.0, p.v0, 0.0, 0.0, 0.0, 0.0, 0.0]))
        if sleeve_mass > 0.0:
            mbs.AddObject(ObjectRigidBody(nodeNumber=self.sleeve, physicsMass=sleeve_mass,
                                          physicsInertia=[1e-12] * 3 + [0.0] * 3))
        # the sleeve on the bus's axle, turning with the bus; its height at the stop (the
        # joint's marker on the bus at the stop height) held once locked
        ma = mbs.AddMarker(MarkerBodyRigid(bodyNumber=self.bus,
                                           localPosition=[0.0, p.sleeve_stop_height, 0.0]))
        mb = mbs.AddMarker(MarkerNodeRigid(nodeNumber=self.sleeve))
        mbs.AddObject(GenericJoint(markerNumbers=[ma, mb],
                                   constrainedAxes=[1, int(locked), 1, 1, 1, 1]))
        self.bus_sensors = {
            key: mbs.AddSensor(SensorNode(nodeNumber=nd, outputVariableType=var,
                                          storeInternal=True, writeToFile=False))
            for key, nd, var in (('X', node, exu.OutputVariableType.Position),
                                 ('R', node, exu.OutputVariableType.RotationMatrix),
                                 ('S', self.sleeve, exu.OutputVariableType.Position))}

    def _chain(self, origin, direction, et, omega, base_velocity, length, count):
        """Nodes and beam elements of a straight body turning at omega (a vector), rigidly."""
        le = length / count
        rot = np.column_stack([direction, np.cross(et, direction), et])
        ep = RotationMatrix2EulerParameters(rot)
        ep_t = AngularVelocity2EulerParameters_t(omega, ep)
        nodes = []
        for k in range(count + 1):
            r = origin + direction * le * k
            v = base_velocity + np.cross(omega, direction * le * k)
            nodes.append(self.mbs.AddNode(NodeRigidBodyEP(
                referenceCoordinates=list(r) + list(ep),
                initialVelocities=list(v) + list(ep_t))))
        for k in range(count):
            self.mbs.AddObject(ObjectBeamGeometricallyExact(
                nodeNumbers=[nodes[k], nodes[k + 1]], physicsLength=le,
                sectionData=self.section))
        return nodes

    def _rotation(self, node):
        return np.array(self.mbs.GetNodeOutput(node, exu.OutputVariableType.RotationMatrix,
                                               configuration=exu.ConfigurationType.Reference)
                        ).reshape(3, 3)

    def _hinge(self, node_a, node_b, frame, axes):
        """Join node_b to node_a (None: the ground) in the joint frame, z = e_t free."""
        mbs = self.mbs
        pos = mbs.GetNodeOutput(node_b, exu.OutputVariableType.Position,
                                configuration=exu.ConfigurationType.Reference)
        if node_a is None:
            # the ground, or the bus (at the origin, its axes the inertial ones at t = 0)
            ma = mbs.AddMarker(MarkerBodyRigid(bodyNumber=self.base, localPosition=list(pos)))
            rot_a = frame
        else:
            ma = mbs.AddMarker(MarkerNodeRigid(nodeNumber=node_a))
            rot_a = self._rotation(node_a).T @ frame
        mb = mbs.AddMarker(MarkerNodeRigid(nodeNumber=node_b))
        mbs.AddObject(GenericJoint(markerNumbers=[ma, mb], constrainedAxes=axes,
                                   rotationMarker0=rot_a.tolist(),
                                   rotationMarker1=(self._rotation(node_b).T @ frame).tolist()))

    def _tip_mass(self, node):
        """Add a point mass at d along the section's z (= e_t) from G, on G's node."""
        mass, offset = self.tip
        c = np.array([0.0, 0.0, offset])
        j = mass * (c @ c * np.eye(3) - np.outer(c, c))      # about the node (a point)
        j += 1e-12 * np.eye(3)
        self.mbs.AddObject(ObjectRigidBody(
            nodeNumber=node, physicsMass=mass, physicsCenterOfMass=list(c),
            physicsInertia=[j[0, 0], j[1, 1], j[2, 2], j[1, 2], j[0, 2], j[0, 1]]))

    def solve(self, h, t_end, t_start=0.0):
        s = trapezoidal_settings(h, t_end, t_start, index2=True)
        ti = s.timeIntegration
        ti.newton.relativeTolerance = 1e-8
        ti.newton.absoluteTolerance = 1e-6
        s.linearSolverType = exu.LinearSolverType.EigenSparse
        self.mbs.SolveDynamic(s)

    def series(self, rib, key, i=0):
        return np.array(self.mbs.GetSensorStoredData(self.sensors[rib][key][i]))

    def bus_series(self):
        """Return t, the bus's position X (N, 3), its rotation R (N, 3, 3), the sleeve's."""
        x = np.array(self.mbs.GetSensorStoredData(self.bus_sensors['X']))
        r = np.array(self.mbs.GetSensorStoredData(self.bus_sensors['R']))[:, 1:10]
        s = np.array(self.mbs.GetSensorStoredData(self.bus_sensors['S']))[:, 1:4]
        return x[:, 0], x[:, 1:4], r.reshape(-1, 3, 3), s

    def in_bus_frame(self, points):
        """Return a sensor's series [t, x, y, z] in the bus frame (as is on the ground)."""
        if self.bus is None:
            return points
        _, x, r, _ = self.bus_series()
        return np.column_stack([points[:, 0], np.einsum('nji,nj->ni', r, points[:, 1:4] - x)])

    def sleeve_height(self):
        """Return t and the sleeve's height on the hub axis (in the bus frame)."""
        if self.bus is None:
            yh = self.series(0, 'H')
            return yh[:, 0], yh[:, 2]
        t, x, r, s = self.bus_series()
        return t, np.einsum('nj,nj->n', r[:, :, 1], s - x)

    def tips(self, rib):
        """Return t, the in-plane tip deflection v (leaf frame O-O'') and the out-of-plane w."""
        er, ey, et = self.ribs[rib]['axes']
        g, j = self.in_bus_frame(self.series(rib, 'G')), self.in_bus_frame(self.series(rib, 'J'))
        gx, gy = g[:, 1:4] @ er, g[:, 1:4] @ ey
        jx, jy = j[:, 1:4] @ er, j[:, 1:4] @ ey
        norm = np.hypot(jx, jy)
        return g[:, 0], (-gx * jy + gy * jx) / norm, g[:, 1:4] @ et

    def out_of_plane_rotation(self, rib):
        """Return the largest |asin| of the sections' axis and in-plane normal along e_t."""
        et = self.ribs[rib]['axes'][2]
        worst = 0.0
        bus = None if self.bus is None else self.bus_series()[2]
        for i in range(len(self.sensors[rib]['R'])):
            r = self.series(rib, 'R', i)[:, 1:10].reshape(-1, 3, 3)
            if bus is not None:
                r = bus.transpose(0, 2, 1) @ r
            worst = max(worst, float(np.abs(np.arcsin(np.clip(r[:, :, 0:2].transpose(
                0, 2, 1) @ et, -1, 1))).max()))
        return worst

    def rigid_fields(self, q):
        """
        Return the velocities (n2, 6) of the whole system's rigid motions at q.

        Columns: translations along X, Y, Z, turns about X, Y, Z through the origin (every
        node's point at w x r, its Euler parameters' rates of w); p = fields^T M q' is then
        the linear and angular momentum (about the origin) of the discrete model.
        """
        mbs = self.mbs
        fields = np.zeros((len(q), 6))
        for node in range(mbs.systemData.NumberOfNodes()):
            if mbs.GetNode(node)['nodeType'] != 'RigidBodyEP':
                continue
            i = mbs.GetNodeODE2Index(node)
            ref = np.array(mbs.GetNode(node)['referenceCoordinates'])
            r, ep = ref[:3] + q[i:i + 3], ref[3:] + q[i + 3:i + 7]
            for axis in range(3):
                e = np.eye(3)[axis]
                fields[i:i + 3, axis] = e
                fields[i:i + 3, 3 + axis] = np.cross(e, r)
                fields[i + 3:i + 7, 3 + axis] = AngularVelocity2EulerParameters_t(e, ep)
        return fields

    def mass_matrix(self):
        """Return Exudyn's mass matrix (ODE2) at the initial configuration."""
        return self._matrices(jacobian=False)[0]

    def momentum_zeroed(self):
        """Give the whole system the rigid velocity that makes its momentum zero (the bus's)."""
        data, initial = self.mbs.systemData, exu.ConfigurationType.Initial
        q = np.array(data.GetODE2Coordinates(configuration=initial))
        qd = np.array(data.GetODE2Coordinates_t(configuration=initial))
        mass, fields = self.mass_matrix(), self.rigid_fields(q)
        qd -= fields @ np.linalg.solve(fields.T @ mass @ fields, fields.T @ mass @ qd)
        data.SetODE2Coordinates_t(qd.tolist(), configuration=initial)

    def momentum(self, q, qd, mass):
        """Return the linear and the angular momentum about the origin, at q and q'."""
        p = self.rigid_fields(q).T @ mass @ qd
        return p[:3], p[3:]

    def _matrices(self, jacobian=True):
        """Return M and the rows of the constraint Jacobian at the initial configuration."""
        solver = exu.MainSolverStatic()
        s = exu.SimulationSettings()
        s.solution.file.write = False
        solver.InitializeSolver(self.mbs, s)
        n2 = solver.GetODE2size()
        solver.ComputeMassMatrix(self.mbs)
        mass = np.array(solver.GetSystemMassMatrix())[:n2, :n2]
        if not jacobian:
            solver.FinalizeSolver(self.mbs, s)
            return mass, None
        solver.ComputeJacobianODE2RHS(self.mbs, scalarFactor_ODE2=-1, scalarFactor_ODE2_t=0,
                                      scalarFactor_ODE1=0)
        solver.ComputeJacobianAE(self.mbs, scalarFactor_ODE2=1., scalarFactor_ODE2_t=0.,
                                 scalarFactor_ODE1=0., velocityLevel=False)
        rows = np.array(solver.GetSystemJacobian())[:n2, n2:].T
        solver.FinalizeSolver(self.mbs, s)
        return mass, rows[np.abs(rows).max(1) > 0]

    def lock_projection(self):
        """Return the velocities projected onto the locked joints (Exudyn's M and C_q)."""
        mass, rows = self._matrices()
        qd = np.array(self.mbs.systemData.GetODE2Coordinates_t(
            configuration=exu.ConfigurationType.Initial))
        # the Euler parameters' normalisation leaves M singular: the metric M + a G0^T G0
        # with G0 the rows the velocities keep already (all but the stop) is M on the
        # velocities that keep them, so the projection is M's
        kept = rows[np.abs(rows @ qd) < 1e-6 * np.abs(qd).max()]
        metric = mass + np.mean(np.diag(mass)) * kept.T @ kept
        m_inv_gt = np.linalg.solve(metric, rows.T)
        lam = np.linalg.lstsq(rows @ m_inv_gt, rows @ qd, rcond=None)[0]
        return qd - m_inv_gt @ lam, mass


def deploy(p: UmbrellaParams, h: float, build, stage2: float) -> dict:
    """
    Stage 1 to the instant the sleeve reaches the stop, the plastic lock, stage 2.

    build(locked) returns a fresh system.  Returns the stage-1 system (second), the stage-2
    one (third), t_lock, the state at the lock (q, qd), the locked velocities and M there.
    """
    first = build(False)
    first.solve(h, 1.1 * 0.0459 / abs(p.v0))
    t, y = first.sleeve_height()
    k = int(np.argmax(y <= p.sleeve_stop_height))
    (t_a, y_a), (t_b, y_b) = (t[k - 1], y[k - 1]), (t[k], y[k])
    t_lock = t_a + (y_a - p.sleeve_stop_height) / (y_a - y_b) * (t_b - t_a)
    second = build(False)
    steps = math.ceil(t_lock / h)
    second.solve(t_lock / steps, t_lock)
    q = np.array(second.mbs.systemData.GetODE2Coordinates())
    qd = np.array(second.mbs.systemData.GetODE2Coordinates_t())
    third = build(True)
    initial = exu.ConfigurationType.Initial
    third.mbs.systemData.SetODE2Coordinates(q.tolist(), configuration=initial)
    third.mbs.systemData.SetODE2Coordinates_t(qd.tolist(), configuration=initial)
    qd_lock, mass = third.lock_projection()
    third.mbs.systemData.SetODE2Coordinates_t(qd_lock.tolist(), configuration=initial)
    third.solve(h, t_lock + stage2, t_lock)
    return {'second': second, 'third': third, 't_lock': t_lock, 'q': q, 'qd': qd,
            'qd_lock': qd_lock, 'mass': mass}


def run(n: int, h: float, tip: tuple) -> dict:
    p = UmbrellaParams(v0=V0)
    d = deploy(p, h, lambda locked: Ribs(p, n, locked=locked, tip=tip), STAGE2)
    second, third, t_lock = d['second'], d['third'], d['t_lock']
    qd, qd_lock, mass = d['qd'], d['qd_lock'], d['mass']
    stage1 = [second.tips(r) for r in range(2)]
    rot1 = second.out_of_plane_rotation(1)
    out = {'elements_per_segment': n, 'time_step': h, 'v0': V0, 'ribs': 2,
           'tip_mass_rib1': tip[0], 'tip_offset_z_rib1': tip[1], 'stage2': STAGE2,
           'deploy_time': t_lock,
           'kinetic_energy_before_lock': 0.5 * qd @ mass @ qd,
           'kinetic_energy_after_lock': 0.5 * qd_lock @ mass @ qd_lock}
    rot2 = third.out_of_plane_rotation(1)
    for r in range(2):
        t1, v1, w1 = stage1[r]     # (rib 1's t1, w1 are kept for its series below)
        t2, v2, w2 = third.tips(r)
        fig_v = stage2_figures(t2, v2, t_lock)
        fig_w = stage2_figures(t2, w2, t_lock)
        out[f'rib{r}'] = {
            'stage1_max_in_plane_tip': float(np.abs(v1).max()),
            'stage1_max_out_of_plane_tip': float(np.abs(w1).max()),
            'stage2_in_plane_amplitude': fig_v['stage2_tip_amplitude'],
            'stage2_in_plane_period': fig_v['stage2_tip_period'],
            'stage2_max_out_of_plane_tip': float(np.abs(w2).max()),
            'stage2_out_of_plane_amplitude': fig_w['stage2_tip_amplitude'],
            'stage2_out_of_plane_period': fig_w['stage2_tip_period']}
    # rib 1's out-of-plane tip w(t) every SERIES_STEP (rib 0's stays in its plane)
    every = max(1, round(SERIES_STEP / h))
    out['rib1']['out_of_plane_tip_series'] = [
        [round(float(a), 9), round(float(b), 9)] for a, b in zip(
            np.concatenate([t1, t2])[::every], np.concatenate([w1, w2])[::every])]
    out['rib1']['max_out_of_plane_rotation_stage1'] = rot1
    out['rib1']['max_out_of_plane_rotation'] = max(rot1, rot2)
    return out


def run_bus(n: int, h: float, tip: tuple = BUS_TIP) -> dict:
    """Run the three ribs on the free bus (BUS): the bus's motion, the momentum, the tips."""
    p = UmbrellaParams(v0=V0)

    def build(locked):
        ribs = Ribs(p, n, locked=locked, tip=tip, ribs=BUS_RIBS, bus=BUS)
        if not locked:
            ribs.momentum_zeroed()
        return ribs

    d = deploy(p, h, build, BUS_STAGE2)
    second, third, t_lock, mass = d['second'], d['third'], d['t_lock'], d['mass']
    out = {'case': 'free bus', 'elements_per_segment': n, 'time_step': h, 'v0': V0,
           'ribs': BUS_RIBS, 'bus_mass': BUS[0], 'bus_inertia': BUS[1], 'bus_inertia_y': BUS[2],
           'sleeve_mass': 0.0, 'tip_mass_rib1': tip[0], 'tip_offset_z_rib1': tip[1],
           'stage2': BUS_STAGE2, 'deploy_time': t_lock,
           'kinetic_energy_before_lock': 0.5 * d['qd'] @ mass @ d['qd'],
           'kinetic_energy_after_lock': 0.5 * d['qd_lock'] @ mass @ d['qd_lock']}
    every = max(1, round(SERIES_STEP / h))
    for r in range(BUS_RIBS):
        (t1, v1, w1), (t2, v2, w2) = second.tips(r), third.tips(r)
        out[f'rib{r}'] = {
            'stage1_max_in_plane_tip': float(np.abs(v1).max()),
            'stage1_max_out_of_plane_tip': float(np.abs(w1).max()),
            'stage2_max_in_plane_tip': float(np.abs(v2).max()),
            'stage2_max_out_of_plane_tip': float(np.abs(w2).max()),
            'max_out_of_plane_rotation_stage1': second.out_of_plane_rotation(r),
            'max_out_of_plane_rotation': max(second.out_of_plane_rotation(r),
                                             third.out_of_plane_rotation(r)),
            'tip_series': [[round(float(a), 9), round(float(b), 9), round(float(c), 9)]
                           for a, b, c in zip(np.concatenate([t1, t2])[::every],
                                              np.concatenate([v1, v2])[::every],
                                              np.concatenate([w1, w2])[::every])]}
    rows = []
    for system in (second, third):
        t, x, rot, _ = system.bus_series()
        turn, tilt = bus_attitude(rot)
        rows.append(np.column_stack([t, x, turn, tilt]))
    rows = np.concatenate(rows)[::every]
    out['bus_series'] = [[round(float(v), 10) for v in row] for row in rows]
    data = third.mbs.systemData
    q_end, qd_end = np.array(data.GetODE2Coordinates()), np.array(data.GetODE2Coordinates_t())
    initial = exu.ConfigurationType.Initial
    data.SetODE2Coordinates(q_end.tolist(), configuration=initial)
    data.SetODE2Coordinates_t(qd_end.tolist(), configuration=initial)
    # (last: a solver's initialisation clears the stored sensors)
    momenta = {'before_lock': third.momentum(d['q'], d['qd'], mass),
               'after_lock': third.momentum(d['q'], d['qd_lock'], mass),
               'end': third.momentum(q_end, qd_end, third.mass_matrix())}
    out['momentum'] = {k: [list(map(float, lin)), list(map(float, ang))]
                       for k, (lin, ang) in momenta.items()}
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--cases', nargs='+',
                    help='n:h:m:d, elements a segment, step (s), tip mass (kg), offset (m); '
                    'with --bus n:h[:m:d] (default: %s; --bus: %s)'
                    % (' '.join(DEFAULT_CASES), ' '.join(BUS_CASES)))
    ap.add_argument('--bus', action='store_true',
                    help='the free bus case (three ribs) into docs/exudyn_umbrella_bus.json')
    ap.add_argument('--append', action='store_true',
                    help='keep the cases the JSON holds (replacing those run again)')
    ap.add_argument('--out', help='the JSON written (default: %s, --bus: %s)' % (OUT, BUS_OUT))
    args = ap.parse_args()
    if args.bus:
        return main_bus(args)
    args.out = args.out or OUT
    results = []
    if args.append and os.path.exists(args.out):
        with open(args.out, encoding='utf-8') as fh:
            results = json.load(fh)['cases']
    for case in args.cases or DEFAULT_CASES:
        n, h, m, d = case.split(':')
        print(f'n = {n}, h = {h}, m = {m}, d = {d}', file=sys.stderr, flush=True)
        new = run(int(n), float(h), (float(m), float(d)))
        key = ('elements_per_segment', 'time_step', 'tip_mass_rib1', 'tip_offset_z_rib1')
        results = [c for c in results if [c[k] for k in key] != [new[k] for k in key]]
        results.append(new)
        short = {k: v for k, v in new.items() if not k.startswith('rib')}
        print('  ' + json.dumps(short), file=sys.stderr, flush=True)
        for r in ('rib0', 'rib1'):
            print('  ' + r + ' ' + json.dumps({k: v for k, v in new[r].items()
                                              if not k.endswith('series')}),
                  file=sys.stderr, flush=True)
        with open(args.out, 'w', encoding='utf-8') as fh:
            json.dump({'exudyn': exu.config.Version(), 'cases': results}, fh, indent=1)
            fh.write('\n')


def main_bus(args):
    """Run the free bus's cases (n:h), write them to args.out (default BUS_OUT)."""
    out = args.out or BUS_OUT
    results = []
    if args.append and os.path.exists(out):
        with open(out, encoding='utf-8') as fh:
            results = json.load(fh)['cases']
    for case in args.cases or BUS_CASES:
        n, h, *tip = case.split(':')
        tip = tuple(map(float, tip)) if tip else BUS_TIP
        print(f'free bus: n = {n}, h = {h}, tip {tip}', file=sys.stderr, flush=True)
        new = run_bus(int(n), float(h), tip)
        key = ('elements_per_segment', 'time_step', 'tip_mass_rib1', 'tip_offset_z_rib1')
        results = [c for c in results if [c[k] for k in key] != [new[k] for k in key]]
        results.append(new)
        short = {k: v for k, v in new.items() if not k.startswith(('rib', 'bus_s'))}
        print('  ' + json.dumps(short), file=sys.stderr, flush=True)
        for r in range(BUS_RIBS):
            print(f'  rib{r} ' + json.dumps({k: v for k, v in new[f'rib{r}'].items()
                                            if not k.endswith('series')}),
                  file=sys.stderr, flush=True)
        with open(out, 'w', encoding='utf-8') as fh:
            fh.write(compact_json({'exudyn': exu.config.Version(), 'cases': results}) + '\n')


def compact_json(value) -> str:
    """Return value as indented JSON with every list of numbers on one line."""
    return re.sub(r'\[\s+([^\[\]{}"]*?)\s+\]', lambda m: '[' + ' '.join(m.group(1).split()) + ']',
                  json.dumps(value, indent=1))


if __name__ == '__main__':
    main()
