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
The whole umbrella in 3D: N flexible ribs, one sleeve, a hub (fixed, driven, or a bus).

Rib k lies in the plane through the hub axis Y at azimuth psi_k = 2 pi k / N; its local frame
(e_r, e_Y, e_t) has e_r radial (rib 0: +X), e_t = e_r x e_Y tangential (rib 0: +Z), origin at
the leaf hinge O_k = a e_r (a the hub radius).  In that frame the rib is the planar model of
Hu, McGill 2006 (leaf O-O''-G, link O''-H, H on the axle: the link's sleeve hinge at the same
radius a), with every beam a 3D Euler-Bernoulli body (beam3d.py) in the same floating frames:

* leaf frame: origin O_k, turned by alpha1 about e_t (the hinge axis).  The hinge holds the
  root's out-of-plane displacement, slope and twist (w = w' = phi = 0 at O): they are
  removed, as are u = v = 0 at O and v = 0 at O'' (the chord frame of §3.5).
* link frame: origin R2 = (R2x, R2y, R2z) at O'', turned by alpha2 about e_t; u = v = w = 0 at
  O'', v = 0 at H; the sleeve hinge (axis e_t) holds the slope and twist at H.

Rib coordinates q_k = [alpha1, e_leaf, R2x, R2y, R2z, alpha2, e_link] (6 per free node:
u, v, theta, w, slope, twist); shared coordinates [y_s] (the sleeve on Y) and, with a moving
base, the bus [X (3), psi, beta, gamma] (R = Ry(psi) Rx(beta) Rz(gamma)).  Nine joint
equations a rib (the planar three, O'' out of plane, the O'' hinge's axis, H out of plane,
H on the sleeve, and a slot for a stuck hinge) and shared ones (the stop; the drive):

    (l1 + u1) (cos a1, sin a1) - (R2x, R2y) = 0        w1 - R2z = 0
    A(a1) (w1', phi1) - A(a2) (w2'(O''), phi2(O'')) = 0  (the hinge axes stay parallel)
    R2x + (l3 + uH) cos a2 = 0,  R2z + wH = 0,  R2y + (l3 + uH) sin a2 - y_s = 0

The kinetic energy is the sum over every body's quadrature points of w |r'|^2 / 2 with r the
point's inertial position (Shabana, Dynamics of Multibody Systems, 3rd ed., ch. 5: the
floating frame of reference), evaluated per point and vectorised over ribs; per rib the mass
matrix is block diagonal in the bodies, and the bus couples to every rib only through a few
columns (the arrow border).  With the hub fixed the out-of-plane coordinates enter neither the
mass matrix nor the in-plane joint equations, and a rib whose out-of-plane state is zero is
the planar model exactly (tests/test_umbrella3d.py).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .beam3d import BeamBody3D
from .params3d import (rib_deployed_angle, rib_start_angle, rigid_rib_angle,
                       UmbrellaRibsParams)

N_RIB_ROWS = 9
ROW_STICK = 8


def _rot_z(c, s, v):
    """Rotate v (..., 3) about z by the angle of (c, s) (broadcast over leading axes)."""
    x, y = v[..., 0], v[..., 1]
    out = np.empty(np.broadcast_shapes(np.shape(c), x.shape) + (3,))
    out[..., 0] = c * x - s * y
    out[..., 1] = s * x + c * y
    out[..., 2] = v[..., 2]
    return out


def _cross(a, b):
    """
    Return a x b over the last axis (3), broadcast: np.cross's arithmetic, bit for bit.

    np.cross spends ~50 us a call on axis handling at these small sizes; the numpy reference
    step calls it ~180 times.
    """
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.result_type(a, b))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.multiply(a1, b2, out=out[..., 0])
    out[..., 0] -= a2 * b1
    np.multiply(a2, b0, out=out[..., 1])
    out[..., 1] -= a0 * b2
    np.multiply(a0, b1, out=out[..., 2])
    out[..., 2] -= a1 * b0
    return out


def _ez_cross(v):
    """Return e_z x v."""
    out = np.empty(v.shape)
    np.negative(v[..., 1], out=out[..., 0])
    out[..., 1] = v[..., 0]
    out[..., 2] = 0.0
    return out


def _ez_cross_t(v):
    """Return (e_z x)^T v = -(e_z x v)."""
    out = np.empty(v.shape)
    out[..., 0] = v[..., 1]
    np.negative(v[..., 0], out=out[..., 1])
    out[..., 2] = 0.0
    return out


def _elem_rot(axis: int, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@dataclass
class BusFrame:
    """The bus attitude: R, the body-frame rate basis B = [b_psi b_beta b_gamma] and dB."""

    rot: np.ndarray
    basis: np.ndarray          # columns b_i: omega_body = B theta'
    dbasis: np.ndarray         # dbasis[j, :, i] = d b_i / d theta_j

    @classmethod
    def of(cls, theta) -> 'BusFrame':
        ry, rx, rz = (_elem_rot(1, theta[0]), _elem_rot(0, theta[1]), _elem_rot(2, theta[2]))
        ex, ey, ez = np.eye(3)
        b_psi = rz.T @ rx.T @ ey
        b_beta = rz.T @ ex
        basis = np.column_stack([b_psi, b_beta, ez])
        d = np.zeros((3, 3, 3))
        d[1, :, 0] = -rz.T @ _cross(ex, rx.T @ ey)
        d[2, :, 0] = -_cross(ez, b_psi)
        d[2, :, 1] = -_cross(ez, b_beta)
        return cls(ry @ rx @ rz, basis, d)


class _BodyStack:
    """One body (leaf or link) of every rib, stacked: points, shapes, constant matrices."""

    def __init__(self, bodies: list[BeamBody3D], extra, n_trans: int, offset: int):
        self.n_trans, self.offset = n_trans, offset
        ne = bodies[0].n_elastic
        self.n = n_trans + 1 + ne
        self.slice = slice(offset, offset + self.n)
        xs, ss, ws = [], [], []
        for body, pts in zip(bodies, extra):
            x = np.column_stack([body.quad_x, np.zeros((len(body.quad_x), 2))])
            s, w = body.quad_shape, body.quad_w
            for xp, sp, wp in pts:
                x, s, w = np.vstack([x, xp]), np.concatenate([s, sp[None]]), np.r_[w, wp]
            xs.append(x)
            ss.append(s)
            ws.append(w)
        self.x, self.shape, self.w = np.array(xs), np.array(ss), np.array(ws)
        self.sqrt_w = np.sqrt(self.w)
        n_ribs = len(bodies)
        self.stiffness = np.zeros((n_ribs, self.n, self.n))
        self.twist_mass = np.zeros((n_ribs, self.n, self.n))
        e = slice(n_trans + 1, self.n)
        for k, body in enumerate(bodies):
            self.stiffness[k, e, e] = body.stiffness
            self.twist_mass[k, e, e] = body.twist_mass

    def kin(self, qb: np.ndarray) -> dict:
        """Positions and Jacobians of the points for body coordinates qb (R, n)."""
        t = self.n_trans
        alpha, e = qb[:, t], qb[:, t + 1:]
        c, s = np.cos(alpha)[:, None], np.sin(alpha)[:, None]
        y = self.x + np.einsum('rpie,re->rpi', self.shape, e)
        qy = _rot_z(c, s, y)
        rho = qy + qb[:, None, :3] if t else qy
        cs = c[..., None]
        ss = s[..., None]
        sh = self.shape
        qs = np.empty(np.broadcast_shapes(cs.shape, sh[:, :, 0].shape)[:2] + (3,)
                      + sh.shape[3:])
        qs[:, :, 0] = cs * sh[:, :, 0] - ss * sh[:, :, 1]
        qs[:, :, 1] = ss * sh[:, :, 0] + cs * sh[:, :, 1]
        qs[:, :, 2] = sh[:, :, 2]
        jac = np.zeros(qb.shape[:1] + self.x.shape[1:] + (self.n,))
        if t:
            jac[:, :, :, :3] = np.eye(3)
        jac[:, :, :, t] = _ez_cross(qy)
        jac[:, :, :, t + 1:] = qs
        return {'rho': rho, 'jac': jac, 'qs': qs, 'c': c, 's': s}

    def velocity(self, kin, vb):
        """Return the points' velocities in the rib frame for body velocities vb (R, n)."""
        return np.einsum('rpin,rn->rpi', kin['jac'], vb)

    def dv_t(self, kin, ab, vrel_a, vother):
        """Return sum_p w (d(J a)/dq)^T V (R, n): the kinetic energy's geometric gradient."""
        t = self.n_trans
        out = np.zeros(ab.shape)
        qz = vrel_a - ab[:, None, :3] if t else vrel_a            # Q Z_a
        out[:, t] = np.einsum('rp,rpi,rpi->r', self.w, _ez_cross(qz), vother)
        out[:, t + 1:] = ab[:, t, None] * np.einsum('rp,rpie,rpi->re', self.w, kin['qs'],
                                                    _ez_cross_t(vother))
        return out

    def mass(self, kin):
        jw = kin['jac'] * self.sqrt_w[:, :, None, None]
        jw = jw.reshape(jw.shape[0], -1, self.n)
        return np.matmul(jw.transpose(0, 2, 1), jw) + self.twist_mass

    def gyroscopic(self, kin, vb, vrel):
        """Return 2 sum w J^T d(J v)/dq (R, n, n) without the elastic-elastic block."""
        t = self.n_trans
        dv = np.zeros_like(kin['jac'])
        qz = vrel - vb[:, None, :3] if t else vrel
        dv[:, :, :, t] = _ez_cross(qz)
        dv[:, :, :, t + 1:] = vb[:, t, None, None, None] * _ez_cross(
            kin['qs'].transpose(0, 1, 3, 2)).transpose(0, 1, 3, 2)
        g = 2.0 * np.einsum('rp,rpia,rpib->rab', self.w, kin['jac'], dv)
        g[:, t + 1:, t + 1:] = 0.0
        return g


class UmbrellaModel3D:
    """The assembled umbrella: layout, mass, gradients, joints, energies, per-rib figures."""

    def __init__(self, params: UmbrellaRibsParams):
        p = params.validated()
        self.params = p
        ribs = p.ribs_list()
        self.ribs = ribs
        self.n_ribs = nr = len(ribs)
        n = p.planar.elements_per_segment
        self.elements = n
        leaves, links, tips = [], [], []
        #: each rib's section constants (BeamBody3D's section dict)
        self.sections = []
        for rib in ribs:
            q = rib.planar
            area, inertia, e_mod = q.cross_section_area, q.cross_section_inertia, q.youngs_modulus
            shear = e_mod * rib.shear_modulus_factor
            section = {'rho_a': q.mass_per_length, 'rho_ip': q.density * 2.0 * inertia,
                       'ea': e_mod * area, 'ei_z': e_mod * inertia, 'ei_y': e_mod * inertia,
                       'gj': shear * rib.torsion_j, 'youngs': e_mod, 'shear': shear,
                       'fibre': q.fibre_distance, 'torsion_fibre': rib.torsion_fibre}
            self.sections.append(section)
            leaf = BeamBody3D('leaf', [(q.l1, n), (q.l2, n)],
                              [(0, 'u'), (0, 'v'), (0, 'w'), (0, 'slope'), (0, 'twist'),
                               (n, 'v')], section)
            link = BeamBody3D('link', [(q.l3, n)],
                              [(0, 'u'), (0, 'v'), (0, 'w'), (n, 'v'), (n, 'slope'),
                               (n, 'twist')], section)
            x_tip, s_tip = leaf.attached_point(
                2 * n, (rib.tip_offset_x, rib.tip_offset_y, rib.tip_offset_z))
            tips.append([(x_tip, s_tip, rib.tip_mass)])
            leaves.append(leaf)
            links.append(link)
        self.leaf_bodies, self.link_bodies = leaves, links
        lf, lk = leaves[0], links[0]
        nl, nk = lf.n_elastic, lk.n_elastic
        self.leaf = _BodyStack(leaves, tips, 0, 0)
        self.link = _BodyStack(links, [[] for _ in ribs], 3, 1 + nl)
        self.bodies = (self.leaf, self.link)
        self.n_rib = 5 + nl + nk
        self.i_a1, self.i_rx, self.i_ry, self.i_rz, self.i_a2 = 0, 1 + nl, 2 + nl, 3 + nl, 4 + nl
        self.s_leaf_e, self.s_link_e = slice(1, 1 + nl), slice(5 + nl, 5 + nl + nk)
        self.i_u1, self.i_w1 = 1 + lf.index(n, 'u'), 1 + lf.index(n, 'w')
        self.i_t0 = 1 + lf.index(0, 'theta')      # the leaf root's slope at O
        self.i_s1, self.i_p1 = 1 + lf.index(n, 'slope'), 1 + lf.index(n, 'twist')
        self.i_s2, self.i_p2 = 5 + nl + lk.index(0, 'slope'), 5 + nl + lk.index(0, 'twist')
        self.i_uh, self.i_wh = 5 + nl + lk.index(n, 'u'), 5 + nl + lk.index(n, 'w')
        tip = 2 * n
        self.i_tip = tuple(1 + lf.index(tip, d) for d in ('u', 'v', 'w'))
        self.l1 = np.array([r.planar.l1 for r in ribs])
        self.l3 = np.array([r.planar.l3 for r in ribs])
        self.alpha_deployed = np.array([rib_deployed_angle(r.planar, p.planar) for r in ribs])
        self.y_stop = p.planar.sleeve_stop_height
        self.y_start = p.planar.sleeve_start_height
        self.azimuth = np.array([r.azimuth for r in ribs])
        c, s = np.cos(self.azimuth), np.sin(self.azimuth)
        z = np.zeros(nr)
        # columns e_r, e_Y, e_t of every rib's frame, in the bus frame
        self.psi = np.stack([np.stack([c, z, -s], -1), np.tile([0.0, 1.0, 0.0], (nr, 1)),
                             np.stack([s, z, c], -1)], -1)
        self.hub_radius = p.hub_radius
        self.sleeve_mass = p.sleeve_mass
        self.moving_base = p.base != 'fixed'
        self.n_shared = 7 if self.moving_base else 1
        self.n_shared_rows = 1 + (6 if p.base == 'prescribed' else 0)
        self.stiffness = np.zeros((nr, self.n_rib, self.n_rib))
        for b in self.bodies:
            self.stiffness[:, b.slice, b.slice] = b.stiffness
        bus_iy = p.bus_inertia_y if p.bus_inertia_y > 0.0 else p.bus_inertia
        self.bus_mass = p.bus_mass if self.moving_base else 0.0
        self.bus_inertia = (np.diag([p.bus_inertia, bus_iy, p.bus_inertia])
                            if self.moving_base else np.zeros((3, 3)))
        self.total_mass = (sum(float(b.w.sum()) for b in self.bodies) + self.sleeve_mass
                           + self.bus_mass)

    # -------------------------------------------------------------- kinematics
    def kinematics(self, qr: np.ndarray, qs: np.ndarray) -> dict:
        """Every body's point kinematics at (qr (R, n_rib), qs) and the bus frame."""
        out = {'bodies': [b.kin(qr[:, b.slice]) for b in self.bodies], 'qr': qr, 'qs': qs}
        if self.moving_base:
            out['bus'] = BusFrame.of(qs[4:7])
        return out

    def _hub_point(self, rho):
        """Rib-frame positions of points from the bus origin: a e_r + rho."""
        return rho + np.array([self.hub_radius, 0.0, 0.0])

    def _full_velocities(self, kin, vr, vs):
        """Per body: (relative velocity, full velocity, omega) in each rib's frame."""
        out = []
        for b, bk in zip(self.bodies, kin['bodies']):
            vrel = b.velocity(bk, vr[:, b.slice])
            if not self.moving_base:
                out.append((vrel, vrel, None))
                continue
            bus = kin['bus']
            om = np.einsum('rji,j->ri', self.psi, bus.basis @ vs[4:7])
            vx = np.einsum('rji,j->ri', self.psi, bus.rot.T @ vs[1:4])
            full = vx[:, None] + _cross(om[:, None], self._hub_point(bk['rho'])) + vrel
            out.append((vrel, full, om))
        return out

    # -------------------------------------------------------------- inertia
    def mass_matrix(self, kin):
        """Return the mass matrix in arrow blocks (M_rr (R, n, n), M_rs (R, n, s), M_ss)."""
        nr, n, ns = self.n_ribs, self.n_rib, self.n_shared
        m_rr = np.zeros((nr, n, n))
        m_rs = np.zeros((nr, n, ns))
        m_ss = np.zeros((ns, ns))
        m_ss[0, 0] = self.sleeve_mass
        for b, bk in zip(self.bodies, kin['bodies']):
            m_rr[:, b.slice, b.slice] = b.mass(bk)
        if not self.moving_base:
            return m_rr, m_rs, m_ss
        bus, ys = kin['bus'], kin['qs'][0]
        s1 = np.array([0.0, self.sleeve_mass * ys, 0.0])
        ic = self.bus_inertia + self.sleeve_mass * ys * ys * np.diag([1.0, 0.0, 1.0])
        for b, bk in zip(self.bodies, kin['bodies']):
            sp = self._hub_point(bk['rho'])
            g = np.einsum('rki,rp,rpin->rkn', self.psi, b.w, bk['jac'])
            lm = np.einsum('rki,rp,rpin->rkn', self.psi, b.w,
                           _cross(sp[..., None, :], bk['jac'].transpose(0, 1, 3, 2))
                           .transpose(0, 1, 3, 2))
            m_rs[:, b.slice, 1:4] = np.einsum('rkn,jk->rnj', g, bus.rot)
            m_rs[:, b.slice, 4:7] = np.einsum('rkn,kj->rnj', lm, bus.basis)
            s1 += np.einsum('rki,rp,rpi->k', self.psi, b.w, sp)
            second = np.einsum('rp,rpi,rpj->rij', b.w, sp, sp)
            local = np.trace(second, axis1=1, axis2=2)[:, None, None] * np.eye(3) - second
            ic += np.einsum('rki,rij,rlj->kl', self.psi, local, self.psi)
        m_ss[0, 1:4] = m_ss[1:4, 0] = self.sleeve_mass * bus.rot[:, 1]
        m_ss[1:4, 1:4] = self.total_mass * np.eye(3)
        m_ss[1:4, 4:7] = bus.rot @ _cross(bus.basis.T, s1).T
        m_ss[4:7, 1:4] = m_ss[1:4, 4:7].T
        m_ss[4:7, 4:7] = bus.basis.T @ ic @ bus.basis
        return m_rr, m_rs, m_ss

    @staticmethod
    def matvec(mass, vr, vs):
        m_rr, m_rs, m_ss = mass
        return (np.einsum('rij,rj->ri', m_rr, vr) + m_rs @ vs,
                np.einsum('rij,ri->j', m_rs, vr) + m_ss @ vs)

    def kinetic_gradient(self, kin, ar, as_, br, bs):
        """Return d/dq [1/2 a^T M(q) b] as (rib part (R, n), shared part)."""
        gr = np.zeros_like(kin['qr'])
        gs = np.zeros(self.n_shared)
        va = self._full_velocities(kin, ar, as_)
        vb = self._full_velocities(kin, br, bs)
        for b, bk, (rel_a, full_a, om_a), (rel_b, full_b, om_b) in zip(
                self.bodies, kin['bodies'], va, vb):
            g = (b.dv_t(bk, ar[:, b.slice], rel_a, full_b)
                 + b.dv_t(bk, br[:, b.slice], rel_b, full_a))
            if self.moving_base:
                jt = np.einsum('rp,rpin,rpi->rn', b.w, bk['jac'],
                               _cross(full_b, om_a[:, None]) + _cross(full_a, om_b[:, None]))
                g = g + jt
                gs[4:7] += self._theta_gradient(kin['bus'], b.w, self._hub_point(bk['rho']),
                                                rel_a, rel_b, full_a, full_b, om_a, om_b,
                                                as_[4:7], bs[4:7])
            gr[:, b.slice] = 0.5 * g
        if self.moving_base:
            gs += self._sleeve_and_bus_gradient(kin, as_, bs)
        return gr, gs

    def _theta_gradient(self, bus, w, sp, rel_a, rel_b, full_a, full_b, om_a, om_b, ta, tb):
        """Return d/d theta of 1/2 sum w V_a . V_b over a body's points (rib frames)."""
        b_loc = np.einsum('rki,kj->rji', self.psi, bus.basis)          # (R, j, 3)
        ca = np.einsum('rki,jkl,l->rji', self.psi, bus.dbasis, ta)
        cb = np.einsum('rki,jkl,l->rji', self.psi, bus.dbasis, tb)
        u_a = _cross(om_a[:, None], sp) + rel_a
        u_b = _cross(om_b[:, None], sp) + rel_b
        a_ab = np.einsum('rp,rpi->ri', w, _cross(u_a, full_b) + _cross(u_b, full_a))
        sv_a = np.einsum('rp,rpi->ri', w, _cross(sp, full_a))
        sv_b = np.einsum('rp,rpi->ri', w, _cross(sp, full_b))
        return 0.5 * (np.einsum('rji,ri->j', b_loc, a_ab) + np.einsum('rji,ri->j', ca, sv_b)
                      + np.einsum('rji,ri->j', cb, sv_a))

    def _sleeve_and_bus_gradient(self, kin, as_, bs):
        """Return the sleeve point's and the bus body's share of the gradient (shared part)."""
        bus = kin['bus']
        out = np.zeros(self.n_shared)
        ey = np.array([0.0, 1.0, 0.0])
        sp = kin['qs'][0] * ey
        vels = []
        for v in (as_, bs):
            om = bus.basis @ v[4:7]
            rel = v[0] * ey
            vels.append((om, rel, bus.rot.T @ v[1:4] + _cross(om, sp) + rel))
        (om_a, rel_a, va), (om_b, rel_b, vb) = vels
        m = self.sleeve_mass
        out[0] = 0.5 * m * (ey @ _cross(vb, om_a) + ey @ _cross(va, om_b))
        out[4:7] = self._theta_gradient_single(bus, m, sp, rel_a, rel_b, va, vb, om_a, om_b,
                                               as_[4:7], bs[4:7])
        ca = np.einsum('jkl,l->jk', bus.dbasis, as_[4:7])
        cb = np.einsum('jkl,l->jk', bus.dbasis, bs[4:7])
        ib = self.bus_inertia
        out[4:7] += 0.5 * (ca @ (ib @ om_b) + cb @ (ib @ om_a))
        return out

    @staticmethod
    def _theta_gradient_single(bus, m, sp, rel_a, rel_b, va, vb, om_a, om_b, ta, tb):
        u_a, u_b = _cross(om_a, sp) + rel_a, _cross(om_b, sp) + rel_b
        a_ab = m * (_cross(u_a, vb) + _cross(u_b, va))
        ca = np.einsum('jkl,l->jk', bus.dbasis, ta)
        cb = np.einsum('jkl,l->jk', bus.dbasis, tb)
        return 0.5 * (bus.basis.T @ a_ab + ca @ (m * _cross(sp, vb))
                      + cb @ (m * _cross(sp, va)))

    def gyroscopic(self, kin, vr):
        """Return -dQv/dq' of the rib frames' own motion (R, n, n), Newton matrix only."""
        g = np.zeros((self.n_ribs, self.n_rib, self.n_rib))
        for b, bk in zip(self.bodies, kin['bodies']):
            vb = vr[:, b.slice]
            g[:, b.slice, b.slice] = b.gyroscopic(bk, vb, b.velocity(bk, vb))
        return g

    def kinetic_energy(self, kin, vr, vs) -> float:
        pr, ps = self.matvec(self.mass_matrix(kin), vr, vs)
        return 0.5 * float(np.sum(pr * vr) + ps @ vs)

    def strain_energy(self, qr) -> float:
        return 0.5 * float(np.einsum('ri,rij,rj->', qr, self.stiffness, qr))

    def strain_energy_per_rib(self, qr) -> np.ndarray:
        return 0.5 * np.einsum('ri,rij,rj->r', qr, self.stiffness, qr)

    # the elastic law's pieces the step takes (corotational3d.py: the co-rotational beams')
    def elastic_force(self, qr) -> np.ndarray:
        """Return dU/dq of every rib (R, n): K q."""
        return np.einsum('rij,rj->ri', self.stiffness, qr)

    def elastic_step_force(self, qr0, qr1, qm) -> np.ndarray:
        """Return the step's discrete gradient of U (R, n): K q_m (qm: the midpoint)."""
        return np.einsum('rij,rj->ri', self.stiffness, qm)

    def elastic_step_matrix(self, qr0, qr1, h: float) -> np.ndarray:
        """Return the Newton matrix's elastic block h^2/2 dG/dq1 (R, n, n): h^2/4 K."""
        return 0.25 * h * h * self.stiffness

    def material_tangent(self, qm) -> np.ndarray:
        """Return B^T D B at the midpoint qm (R, n, n), C / beta (damping3d.py): K."""
        return self.stiffness

    def compiled_law(self):
        """Return the compiled step's elastic law fields (Model3D.nl_*), None: the linear K."""
        return None

    def note_state(self, qr) -> None:
        """Note a stepped state (a model's validity measures; the linear beams have none)."""

    # -------------------------------------------------------------- joints
    def sleeve_heights(self, qr) -> np.ndarray:
        """Return y_H of every rib's link end (R,)."""
        return qr[:, self.i_ry] + (self.l3 + qr[:, self.i_uh]) * np.sin(qr[:, self.i_a2])

    def hinge_angle(self, qr) -> np.ndarray:
        """Return alpha1 + theta(O) (R,): each leaf root's turn, what a stuck hinge clamps."""
        return qr[..., self.i_a1] + qr[..., self.i_t0]

    def constraints(self, qr, qs, stuck, locked: bool, drive=None):
        """
        Return (Phi_r (R, 9), Phi_s) at (qr, qs).

        stuck: (R,) the hinge_angle a stuck hinge holds (the co-rotational ribs: theta(O) that
        turn's sine), NaN where free (its row is then 0; its multiplier: the root's moment);
        drive: the bus coordinates the prescribed base imposes (prescribed base only).
        """
        a1, a2 = qr[:, self.i_a1], qr[:, self.i_a2]
        c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
        r1 = self.l1 + qr[:, self.i_u1]
        r3 = self.l3 + qr[:, self.i_uh]
        sl1, tw1, sl2, tw2 = (qr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        phi = np.stack([
            r1 * c1 - qr[:, self.i_rx], r1 * s1 - qr[:, self.i_ry],
            qr[:, self.i_w1] - qr[:, self.i_rz],
            c1 * sl1 - s1 * tw1 - c2 * sl2 + s2 * tw2,
            s1 * sl1 + c1 * tw1 - s2 * sl2 - c2 * tw2,
            qr[:, self.i_rx] + r3 * c2, qr[:, self.i_rz] + qr[:, self.i_wh],
            qr[:, self.i_ry] + r3 * s2 - qs[0],
            np.where(np.isnan(stuck), 0.0, self.hinge_angle(qr) - np.nan_to_num(stuck))], -1)
        shared = [qs[0] - self.y_stop if locked else 0.0]
        if self.n_shared_rows > 1:
            shared += list(qs[1:7] - drive)
        return phi, np.array(shared)

    def constraint_jacobian(self, qr, stuck, locked: bool):
        """Return (J_rr (R, 9, n), J_rs (R, 9, s), J_ss (c_s, s), active shared rows)."""
        nr, n = self.n_ribs, self.n_rib
        a1, a2 = qr[:, self.i_a1], qr[:, self.i_a2]
        c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
        r1 = self.l1 + qr[:, self.i_u1]
        r3 = self.l3 + qr[:, self.i_uh]
        sl1, tw1, sl2, tw2 = (qr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        j = np.zeros((nr, N_RIB_ROWS, n))
        j[:, 0, self.i_a1], j[:, 0, self.i_u1], j[:, 0, self.i_rx] = -r1 * s1, c1, -1.0
        j[:, 1, self.i_a1], j[:, 1, self.i_u1], j[:, 1, self.i_ry] = r1 * c1, s1, -1.0
        j[:, 2, self.i_w1], j[:, 2, self.i_rz] = 1.0, -1.0
        j[:, 3, self.i_a1] = -s1 * sl1 - c1 * tw1
        j[:, 4, self.i_a1] = c1 * sl1 - s1 * tw1
        j[:, 3, self.i_s1], j[:, 4, self.i_s1] = c1, s1
        j[:, 3, self.i_p1], j[:, 4, self.i_p1] = -s1, c1
        j[:, 3, self.i_a2] = s2 * sl2 + c2 * tw2
        j[:, 4, self.i_a2] = -c2 * sl2 + s2 * tw2
        j[:, 3, self.i_s2], j[:, 4, self.i_s2] = -c2, -s2
        j[:, 3, self.i_p2], j[:, 4, self.i_p2] = s2, -c2
        j[:, 5, self.i_rx], j[:, 5, self.i_a2], j[:, 5, self.i_uh] = 1.0, -r3 * s2, c2
        j[:, 6, self.i_rz], j[:, 6, self.i_wh] = 1.0, 1.0
        j[:, 7, self.i_ry], j[:, 7, self.i_a2], j[:, 7, self.i_uh] = 1.0, r3 * c2, s2
        j[:, 8, self.i_a1] = j[:, 8, self.i_t0] = np.where(np.isnan(stuck), 0.0, 1.0)
        j_rs = np.zeros((nr, N_RIB_ROWS, self.n_shared))
        j_rs[:, 7, 0] = -1.0
        j_ss = np.zeros((self.n_shared_rows, self.n_shared))
        j_ss[0, 0] = 1.0 if locked else 0.0
        active = np.zeros(self.n_shared_rows, dtype=bool)
        active[0] = locked
        if self.n_shared_rows > 1:
            j_ss[1:, 1:7] = np.eye(6)
            active[1:] = True
        return j, j_rs, j_ss, active

    def constraint_bias(self, qr, vr) -> np.ndarray:
        """Return -Jdot v of the rib rows (R, 9) (the stuck row and shared rows: 0)."""
        a1, a2 = qr[:, self.i_a1], qr[:, self.i_a2]
        w1, w2 = vr[:, self.i_a1], vr[:, self.i_a2]
        c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
        r1, r3 = self.l1 + qr[:, self.i_u1], self.l3 + qr[:, self.i_uh]
        d1, d3 = vr[:, self.i_u1], vr[:, self.i_uh]
        sl1, tw1, sl2, tw2 = (qr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        vs1, vt1, vs2, vt2 = (vr[:, i] for i in (self.i_s1, self.i_p1, self.i_s2, self.i_p2))
        jd = np.zeros((self.n_ribs, N_RIB_ROWS))
        jd[:, 0] = -2 * d1 * w1 * s1 - r1 * w1 * w1 * c1
        jd[:, 1] = 2 * d1 * w1 * c1 - r1 * w1 * w1 * s1
        jd[:, 3] = (w1 * w1 * (-c1 * sl1 + s1 * tw1) + 2 * w1 * (-s1 * vs1 - c1 * vt1)
                    + w2 * w2 * (c2 * sl2 - s2 * tw2) + 2 * w2 * (s2 * vs2 + c2 * vt2))
        jd[:, 4] = (w1 * w1 * (-s1 * sl1 - c1 * tw1) + 2 * w1 * (c1 * vs1 - s1 * vt1)
                    + w2 * w2 * (s2 * sl2 + c2 * tw2) + 2 * w2 * (-c2 * vs2 + s2 * vt2))
        jd[:, 5] = -2 * d3 * w2 * s2 - r3 * w2 * w2 * c2
        jd[:, 7] = 2 * d3 * w2 * c2 - r3 * w2 * w2 * s2
        return -jd

    def rib_quadratic_forces(self, kin, vr) -> np.ndarray:
        """
        Return Qv of the rib frames' own motion (R, n): -sum w J^T a_p.

        a_p = w^2 e_z x (e_z x Q Y) + 2 w e_z x (Q S e'), the points' centripetal and
        Coriolis accelerations (hub fixed; with a moving base the bus terms are left out:
        this serves the consistent multipliers of a start, Newton's first guess).
        """
        out = np.zeros_like(vr)
        for b, bk in zip(self.bodies, kin['bodies']):
            vb = vr[:, b.slice]
            t = b.n_trans
            w = vb[:, t, None, None]
            qy = bk['jac'][:, :, :, t]                     # e_z x Q Y
            acc = w * w * _ez_cross(qy) + 2.0 * w * _ez_cross(
                np.einsum('rpie,re->rpi', bk['qs'], vb[:, t + 1:]))
            out[:, b.slice] = -np.einsum('rp,rpin,rpi->rn', b.w, bk['jac'], acc)
        return out

    # -------------------------------------------------------------- configurations
    def rigid_rib(self, k: int, alpha1: float) -> np.ndarray:
        """Return rib k's coordinates undeformed at leaf angle alpha1."""
        q = np.zeros(self.n_rib)
        l1, l3 = self.l1[k], self.l3[k]
        q[self.i_a1] = alpha1
        q[self.i_rx], q[self.i_ry] = l1 * math.cos(alpha1), l1 * math.sin(alpha1)
        q[self.i_a2] = math.acos(-l1 / l3 * math.cos(alpha1))
        return q

    def rigid_rib_velocity(self, k: int, q: np.ndarray, alpha1_rate: float) -> np.ndarray:
        l1, l3 = self.l1[k], self.l3[k]
        a1, a2 = q[self.i_a1], q[self.i_a2]
        v = np.zeros(self.n_rib)
        v[self.i_a1] = alpha1_rate
        v[self.i_rx] = -l1 * math.sin(a1) * alpha1_rate
        v[self.i_ry] = l1 * math.cos(a1) * alpha1_rate
        v[self.i_a2] = -l1 * math.sin(a1) * alpha1_rate / (l3 * math.sin(a2))
        return v

    def sleeve_height_gradient(self, q: np.ndarray, k: int) -> np.ndarray:
        g = np.zeros(self.n_rib)
        a2, lu = q[self.i_a2], self.l3[k] + q[self.i_uh]
        g[self.i_ry], g[self.i_a2], g[self.i_uh] = 1.0, lu * math.cos(a2), math.sin(a2)
        return g

    def rib_angle_at_height(self, k: int, y: float) -> float:
        """Return the leaf angle at which rib k's rigid link puts H at height y."""
        rib = self.ribs[k].planar
        if y == self.y_start:
            return rib_start_angle(rib, self.params.planar)
        return rigid_rib_angle(rib.l1, rib.l3, y)

    # -------------------------------------------------------------- figures
    def momentum(self, kin, vr, vs):
        """Return (linear momentum P, angular momentum H about the origin), inertial."""
        if not self.moving_base:
            raise ValueError('momentum: the hub is fixed (the base takes any momentum)')
        bus = kin['bus']
        x = kin['qs'][1:4]
        h_body = self.bus_inertia @ (bus.basis @ vs[4:7])
        p_body = self.bus_mass * (bus.rot.T @ vs[1:4])
        for b, bk, (_, full, _) in zip(self.bodies, kin['bodies'],
                                       self._full_velocities(kin, vr, vs)):
            sp = self._hub_point(bk['rho'])
            p_body = p_body + np.einsum('rki,rp,rpi->k', self.psi, b.w, full)
            h_body = h_body + np.einsum('rki,rp,rpi->k', self.psi, b.w, _cross(sp, full))
        ey = np.array([0.0, 1.0, 0.0])
        sp = kin['qs'][0] * ey
        v_s = bus.rot.T @ vs[1:4] + _cross(bus.basis @ vs[4:7], sp) + vs[0] * ey
        p_body = p_body + self.sleeve_mass * v_s
        h_body = h_body + self.sleeve_mass * _cross(sp, v_s)
        p = bus.rot @ p_body
        # about the inertial origin: H = X x P + R (sum s x m v, in the bus frame)
        return p, _cross(x, p) + bus.rot @ h_body

    def stress_components(self, qr):
        """Per body: (axial, bending z, bending y, torsion shear) (..., R, points) each, Pa."""
        return [tuple(b[..., i, :] for i in range(4)) for b in self.stress_blocks(qr)]

    def stress_rate_blocks(self, qr, vr):
        """Return d/dt of stress_blocks along vr (linear in q: stress_blocks of vr)."""
        return self.stress_blocks(vr)

    def stress_blocks(self, qr):
        """Per body the four components of stress_components stacked: (..., R, 4, points), Pa."""
        if not hasattr(self, '_stress_rows'):
            # per body, every rib's four recovery matrices stacked: (R, 4 points, elastic)
            self._stress_rows = [
                (np.concatenate([np.array([getattr(b, name) for b in bodies]) for name in (
                    'stress_axial', 'stress_bend_z', 'stress_bend_y', 'stress_shear')], 1), s_e)
                for bodies, s_e in ((self.leaf_bodies, self.s_leaf_e),
                                    (self.link_bodies, self.s_link_e))]
        out = []
        for rows, s_e in self._stress_rows:
            stress = np.einsum('rpe,...re->...rp', rows, qr[..., s_e])
            out.append(stress.reshape(stress.shape[:-1] + (4, -1)))
        return out
