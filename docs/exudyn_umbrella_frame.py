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
The umbrella frame with geometrically exact ANCF cable elements in Exudyn: the reference.

An independent model of the thesis frame (the figures tests/test_nonlinear.py compares
flexible-nonlinear with were made with it): the leaf O-G and the link O''-H of ANCF cable
elements (Exudyn's ANCFCable2D: axial strain |r'| - 1, curvature r' x r'' / |r'|^2, cubic
position and slope fields; Gerstmayr & Irschik, J. Sound Vib. 318, 2008), n elements a
segment, pinned at O, a revolute joint at O'', H on the axle x = 0, started as the rigid
mechanism at alpha0 with the sleeve moving at V0, no gravity, no sleeve force.  Stage 1 to
the instant y_H reaches the stop (found from the run, then run again to exactly that
instant), the plastic lock (the velocities projected onto the locked constraints in the mass
metric: every constraint is linear in the absolute coordinates and the mass matrix constant),
then 0.3 s of stage 2 with the sleeve held.  Time integration: Newmark beta = 1/4,
gamma = 1/2 (the trapezoidal rule), index-3 constraints (--index2: index 2).  Figures by
umbrella_sim's own rules (summary.stage2_figures, the tip deflection in the leaf frame O-O'').

Needs Exudyn (``pip install exudyn``; never a dependency of umbrella_sim).  Writes
docs/exudyn_umbrella_frame.json, which docs/make_validation_nonlinear.py tabulates;
progress on stderr.

    python docs/exudyn_umbrella_frame.py [--cases 4:-1:5e-6 8:-2:2.5e-6 ...] [--index2]
                                         [--append]

The default cases take hours on a shared machine (n = 16 at 2.5 us the longest); --append
keeps the cases the JSON already holds (a case run again replaces its entry), so they can be
run a few at a time.
"""
import argparse
import json
import math
import os
import sys

import exudyn as exu
from exudyn.itemInterface import (Cable2D, CoordinateConstraint, MarkerNodeCoordinate,
                                  NodePoint2DSlope1, NodePointGround, SensorNode)
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))

from umbrella_sim.core.params import UmbrellaParams  # noqa: E402
from umbrella_sim.core.summary import stage2_figures, STAGE2_WINDOW  # noqa: E402

OUT = os.path.join(HERE, 'exudyn_umbrella_frame.json')
DEFAULT_CASES = ('4:-0.2:5e-6', '8:-0.2:5e-6', '4:-1:5e-6', '8:-1:5e-6', '16:-1:5e-6',
                 '4:-2:2.5e-6', '8:-2:2.5e-6', '16:-2:2.5e-6')


def trapezoidal_settings(h, t_end, t_start=0.0, index2=False):
    """
    Return Exudyn's settings of a reference run from t_start to t_end at the step h.

    Newmark beta = 1/4, gamma = 1/2 (the trapezoidal rule), index-3 constraints (index2:
    index 2), every step's sensors kept, no solution file, quiet; Newton's tolerances the
    caller's.  Shared by docs/exudyn_umbrella_ribs.py.
    """
    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.numberOfSteps = max(1, int(round((t_end - t_start) / h)))
    ti.startTime, ti.endTime = t_start, t_end
    ga = ti.generalizedAlpha
    ga.useNewmark, ga.newmarkBeta, ga.newmarkGamma = True, 0.25, 0.5
    ga.useIndex2Constraints = index2
    ti.verboseMode = 0
    s.solution.file.write = False
    s.solution.sensors.writePeriod = (t_end - t_start) / ti.numberOfSteps
    s.show.statistics = s.show.computationTime = False
    return s


class Frame:
    """The frame's Exudyn system: nodes, elements, joints, the (inactive) lock, sensors."""

    def __init__(self, p: UmbrellaParams, n: int, locked: bool):
        self.sc = exu.SystemContainer()
        mbs = self.mbs = self.sc.AddSystem()
        ea = p.youngs_modulus * p.cross_section_area
        ei = p.youngs_modulus * p.cross_section_inertia
        a1 = p.alpha0
        a2 = math.acos(-p.l1 / p.l3 * math.cos(a1))
        da2 = -p.l1 * math.sin(a1) / (p.l3 * math.sin(a2))          # d alpha2 / d alpha1
        w1 = p.v0 / (p.l1 * math.cos(a1) + p.l3 * math.cos(a2) * da2)   # y_H' = v0
        w2 = da2 * w1
        e1 = np.array([math.cos(a1), math.sin(a1)])
        e2 = np.array([math.cos(a2), math.sin(a2)])
        r2 = p.l1 * e1
        self.nodes = {'leaf': self._chain(np.zeros(2), e1, w1, np.zeros(2), p.l1 + p.l2, 2 * n,
                                          p.mass_per_length, ea, ei),
                      'link': self._chain(r2, e2, w2, w1 * np.array([-r2[1], r2[0]]), p.l3, n,
                                          p.mass_per_length, ea, ei)}
        ground = mbs.AddNode(NodePointGround(referenceCoordinates=[0, 0, 0]))
        self.m_ground = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=ground, coordinate=0))
        leaf, link = self.nodes['leaf'], self.nodes['link']
        h_ref = r2 + p.l3 * e2
        self._fix(leaf[0], 0)                                  # O pinned
        self._fix(leaf[0], 1)
        for c in (0, 1):                                       # the revolute joint O''
            ma = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=leaf[n], coordinate=c))
            mb = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=link[0], coordinate=c))
            mbs.AddObject(CoordinateConstraint(markerNumbers=[ma, mb]))
        self._fix(link[n], 0, -h_ref[0])                       # H on the axle x = 0
        self._fix(link[n], 1, p.sleeve_stop_height - h_ref[1], active=locked)   # the stop
        self.sensors = {k: mbs.AddSensor(SensorNode(
            nodeNumber=nd, outputVariableType=exu.OutputVariableType.Position,
            storeInternal=True, writeToFile=False))
            for k, nd in (('H', link[n]), ('G', leaf[2 * n]), ('J', leaf[n]))}
        mbs.Assemble()
        self.n, self.p = n, p

    def _chain(self, origin, direction, omega, base_velocity, length, count, rho_a, ea, ei):
        """Nodes and cable elements of a straight body turning at omega, rigidly."""
        nodes, le = [], length / count
        normal = np.array([-direction[1], direction[0]])
        for k in range(count + 1):
            r = origin + direction * le * k
            v = base_velocity + omega * le * k * normal
            nodes.append(self.mbs.AddNode(NodePoint2DSlope1(
                referenceCoordinates=[r[0], r[1], direction[0], direction[1]],
                initialVelocities=[v[0], v[1], omega * normal[0], omega * normal[1]])))
        for k in range(count):
            self.mbs.AddObject(Cable2D(length=le, massPerLength=rho_a, bendingStiffness=ei,
                                       axialStiffness=ea, nodeNumbers=[nodes[k], nodes[k + 1]]))
        return nodes

    def _fix(self, node, coordinate, offset=0.0, active=True):
        m = self.mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=node, coordinate=coordinate))
        self.mbs.AddObject(CoordinateConstraint(markerNumbers=[self.m_ground, m], offset=offset,
                                                activeConnector=active))

    def solve(self, h, t_end, t_start=0.0, index2=False):
        s = trapezoidal_settings(h, t_end, t_start, index2)
        ti = s.timeIntegration
        ti.newton.relativeTolerance = ti.newton.absoluteTolerance = 1e-10
        self.mbs.SolveDynamic(s)

    def series(self, key):
        return self.mbs.GetSensorStoredData(self.sensors[key])

    def tip_in_leaf_frame(self):
        """Return t and v_G: G's distance from the line O-O'' (O at the origin), signed."""
        g, j = self.series('G'), self.series('J')
        u = j[:, 1:3] / np.linalg.norm(j[:, 1:3], axis=1)[:, None]
        return g[:, 0], -g[:, 1] * u[:, 1] + g[:, 2] * u[:, 0]

    def mass_matrix(self):
        """Return the constant ANCF mass matrix (rho A int S^T S dx, cubic Hermite)."""
        size = self.mbs.systemData.ODE2Size()
        mass = np.zeros((size, size))
        p = self.p
        for name, count, length in (('leaf', 2 * self.n, p.l1 + p.l2), ('link', self.n, p.l3)):
            L = length / count
            m = p.mass_per_length * L / 420.0 * np.array(
                [[156, 22 * L, 54, -13 * L], [22 * L, 4 * L * L, 13 * L, -3 * L * L],
                 [54, 13 * L, 156, -22 * L], [-13 * L, -3 * L * L, -22 * L, 4 * L * L]])
            for k in range(count):
                a = list(self.mbs.systemData.GetNodeLTGODE2(self.nodes[name][k]))
                b = list(self.mbs.systemData.GetNodeLTGODE2(self.nodes[name][k + 1]))
                for c in (0, 1):            # x: position, slope of each node; then y
                    idx = [a[c], a[2 + c], b[c], b[2 + c]]
                    mass[np.ix_(idx, idx)] += m
        return mass

    def constraint_rows(self):
        """Return the constraints' rows (all linear): O, O'', H on the axle, the stop."""
        size = self.mbs.systemData.ODE2Size()
        leaf, link, n = self.nodes['leaf'], self.nodes['link'], self.n

        def e(node, c):
            r = np.zeros(size)
            r[self.mbs.systemData.GetNodeLTGODE2(node)[c]] = 1.0
            return r
        return np.array([e(leaf[0], 0), e(leaf[0], 1), e(leaf[n], 0) - e(link[0], 0),
                         e(leaf[n], 1) - e(link[0], 1), e(link[n], 0), e(link[n], 1)])


def run(n: int, v0: float, h: float, index2: bool) -> dict:
    p = UmbrellaParams(v0=v0)
    # stage 1 past the stop: the instant y_H reaches it, by linear interpolation
    first = Frame(p, n, locked=False)
    first.solve(h, 1.15 * 0.0459 / abs(v0), index2=index2)
    yh = first.series('H')
    k = int(np.argmax(yh[:, 2] <= p.sleeve_stop_height))
    (t_a, y_a), (t_b, y_b) = yh[k - 1, [0, 2]], yh[k, [0, 2]]
    t_lock = t_a + (y_a - p.sleeve_stop_height) / (y_a - y_b) * (t_b - t_a)
    t, v = first.tip_in_leaf_frame()
    tip1 = float(np.abs(v[t <= t_lock]).max())
    # stage 1 again, to the lock instant exactly; the plastic lock
    second = Frame(p, n, locked=False)
    steps = math.ceil(t_lock / h)
    second.solve(t_lock / steps, t_lock, index2=index2)
    q = np.array(second.mbs.systemData.GetODE2Coordinates())
    qd = np.array(second.mbs.systemData.GetODE2Coordinates_t())
    mass, rows = second.mass_matrix(), second.constraint_rows()
    m_inv_gt = np.linalg.solve(mass, rows.T)
    qd_lock = qd - m_inv_gt @ np.linalg.solve(rows @ m_inv_gt, rows @ qd)
    # stage 2
    third = Frame(p, n, locked=True)
    initial = exu.ConfigurationType.Initial
    third.mbs.systemData.SetODE2Coordinates(q.tolist(), configuration=initial)
    third.mbs.systemData.SetODE2Coordinates_t(qd_lock.tolist(), configuration=initial)
    third.solve(h, t_lock + STAGE2_WINDOW, t_lock, index2=index2)
    t2, v2 = third.tip_in_leaf_frame()
    figures = stage2_figures(t2, v2, t_lock)
    return {'elements_per_segment': n, 'v0': v0, 'time_step': h,
            'constraints': 'index 2' if index2 else 'index 3',
            'deploy_time': t_lock, 'tip_deflection_max': tip1,
            'kinetic_energy_before_lock': 0.5 * qd @ mass @ qd,
            'kinetic_energy_after_lock': 0.5 * qd_lock @ mass @ qd_lock,
            'stage2_tip_amplitude': figures['stage2_tip_amplitude'],
            'stage2_tip_period': figures['stage2_tip_period']}


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--cases', nargs='+', default=list(DEFAULT_CASES),
                    help='n:V0:h, elements a segment, m/s, s')
    ap.add_argument('--index2', action='store_true', help='index-2 constraints as well')
    ap.add_argument('--append', action='store_true',
                    help='keep the cases the JSON holds (replacing those run again)')
    args = ap.parse_args()
    results = []
    if args.append and os.path.exists(OUT):
        with open(OUT, encoding='utf-8') as fh:
            results = json.load(fh)['cases']
    for case in args.cases:
        n, v0, h = case.split(':')
        for index2 in ((False, True) if args.index2 else (False,)):
            print(f'n = {n}, V0 = {v0}, h = {h}, index {2 if index2 else 3}', file=sys.stderr,
                  flush=True)
            new = run(int(n), float(v0), float(h), index2)
            key = ('elements_per_segment', 'v0', 'time_step', 'constraints')
            results = [c for c in results if [c[k] for k in key] != [new[k] for k in key]]
            results.append(new)
            print('  ' + json.dumps(results[-1]), file=sys.stderr, flush=True)
            with open(OUT, 'w', encoding='utf-8') as fh:    # after each case: hours in all
                json.dump({'exudyn': exu.config.Version(), 'cases': results}, fh, indent=1)
                fh.write('\n')


if __name__ == '__main__':
    main()
