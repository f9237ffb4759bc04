// Copyright 2026 umbrella_sim developers
//
// Licensed under the Apache License, Version 2.0 (the "License");
// you may not use this file except in compliance with the License.
// You may obtain a copy of the License at
//
//     http://www.apache.org/licenses/LICENSE-2.0
//
// Unless required by applicable law or agreed to in writing, software
// distributed under the License is distributed on an "AS IS" BASIS,
// WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
// See the License for the specific language governing permissions and
// limitations under the License.

/*
 * The compiled 3D step with a moving base: the hub driven by a prescribed bus motion, or a
 * free-floating bus (umbrella3d/model3d.py, the bus coordinates [X (3), psi, beta, gamma]
 * after y_s).  _kernel3d.c includes this file after its own step: these functions take
 * that file's helpers for what the base leaves as it is (each rib's own mass blocks and
 * kinetic gradient from the inertia invariants, the joints, the rib blocks of the arrow
 * factorisation, friction, the kept iteration matrix's rule) and add the base's terms as
 * the numpy reference defines them (model3d.UmbrellaModel3D: mass_matrix, kinetic_gradient,
 * _theta_gradient, _sleeve_and_bus_gradient; summed over the points, or for M_rs's elastic
 * columns from invariants): the rib-bus block M_rs and the shared block M_ss of M(q), their
 * share of the kinetic energy's gradient, the arrow algebra's full border (every shared
 * column), the drive's rows.  base_step is integrator3d.MidpointUmbrella._step for a moving
 * base, step for step the same algorithm (its states equal the reference's to round-off),
 * with stage 2's mode fit (base_fit_map: a driven hub's ribs' fits in the hub's frame, or a
 * free bus's: the ribs' fits with the bus's low-rank correction; umbrella3d/stage2fit.py).
 *
 * One file for the base: its functions serve base_step and one another, and leave
 * _kernel3d.c's (the hub fixed's step) as they are.
 *
 * Frames: psi_r (Model3D.rib_frames) maps rib r's frame to the bus frame; the bus frame's
 * attitude R = Ry(psi) Rx(beta) Rz(gamma) maps it to the inertial one; omega = B theta'
 * (bus frame).  A point's velocity in rib r's frame: psi^T R^T X' + omega_r x s + J v_b,
 * s = rho + a e_r its place from the bus origin.
 */
#define NB 7            /* shared coordinates with a moving base: y_s, X (3), the angles (3) */

/* The bus attitude (model3d.BusFrame): rot (row-major, R[i][k] = rot[3 i + k]), basis
 * (basis[3 k + i]: component k of b_i) and dbasis (dbasis[9 j + 3 k + i]: component k of
 * d b_i / d theta_j). */
typedef struct { double rot[9], basis[9], dbasis[27]; } BusFrame3;

struct Base3D {
    int prescribed, free_bus;
    double *xs[2], *ss[2];       /* per body, every rib's sum_p w x_p x S_pe (R x ne x 3) and
                                  * sum_p w S_pk x S_pe (R x ne x ne x 3, [k][e]): the
                                  * elastic columns of M_rs without a point loop */
    int *span[2];                /* per body and point (R x np x 2): the first and one past the
                                  * last elastic column its shape S_p touches (an element's
                                  * nodes): the point loops' sums over e skip S_p's zeros */
    double *mrs;                 /* R x n x NB: M_rs at the last base_mass_matrix */
    double mss[NB * NB];
    double *fmrs[3];             /* the M_rs each factorisation holds (slot 0, 1, pm) */
    const double *drive_q, *drive_v;   /* the step's drive: the bus's place and rates */
    double *fitv, *fitc, *fita;  /* a map over every coordinate (every_map): v gathered, the modal
                                  * sums, the change (N + NB each) */
    double work_drive;           /* the last step's drive work */
};

static void cross3(const double *a, const double *b, double *c) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot3(const double *a, const double *b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* y = A v, y = A^T v of a row-major 3 x 3 */
static void mv3(const double *A, const double *v, double *y) {
    for (int i = 0; i < 3; i++) y[i] = A[3 * i] * v[0] + A[3 * i + 1] * v[1] + A[3 * i + 2] * v[2];
}

static void mtv3(const double *A, const double *v, double *y) {
    for (int i = 0; i < 3; i++) y[i] = A[i] * v[0] + A[3 + i] * v[1] + A[6 + i] * v[2];
}

static void mm3(const double *A, const double *B, double *C) {
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            C[3 * i + k] = A[3 * i] * B[k] + A[3 * i + 1] * B[3 + k] + A[3 * i + 2] * B[6 + k];
}

/* model3d.BusFrame.of */
static void bus_frame(const double *theta, BusFrame3 *f) {
    double cp = cos(theta[0]), sp = sin(theta[0]), cb = cos(theta[1]), sb = sin(theta[1]);
    double cg = cos(theta[2]), sg = sin(theta[2]);
    const double ry[9] = {cp, 0, sp, 0, 1, 0, -sp, 0, cp};
    const double rx[9] = {1, 0, 0, 0, cb, -sb, 0, sb, cb};
    const double rz[9] = {cg, -sg, 0, sg, cg, 0, 0, 0, 1};
    const double ex[3] = {1, 0, 0}, ey[3] = {0, 1, 0}, ez[3] = {0, 0, 1};
    double t[9], rxey[3], bpsi[3], bbeta[3], c[3], d[3];
    mm3(ry, rx, t);
    mm3(t, rz, f->rot);
    mtv3(rx, ey, rxey);
    mtv3(rz, rxey, bpsi);
    mtv3(rz, ex, bbeta);
    for (int k = 0; k < 3; k++) {
        f->basis[3 * k] = bpsi[k];
        f->basis[3 * k + 1] = bbeta[k];
        f->basis[3 * k + 2] = ez[k];
    }
    memset(f->dbasis, 0, sizeof(f->dbasis));
    cross3(ex, rxey, c);
    mtv3(rz, c, d);
    for (int k = 0; k < 3; k++) f->dbasis[9 + 3 * k] = -d[k];
    cross3(ez, bpsi, c);
    for (int k = 0; k < 3; k++) f->dbasis[18 + 3 * k] = -c[k];
    cross3(ez, bbeta, c);
    for (int k = 0; k < 3; k++) f->dbasis[18 + 3 * k + 1] = -c[k];
}

/* d omega / d theta_j for rates t: sum_i t_i d b_i / d theta_j (out: 3 x 3, row j) */
static void dbasis_rates(const BusFrame3 *f, const double *t, double *out) {
    for (int j = 0; j < 3; j++)
        for (int k = 0; k < 3; k++) {
            const double *row = f->dbasis + 9 * j + 3 * k;
            out[3 * j + k] = row[0] * t[0] + row[1] * t[1] + row[2] * t[2];
        }
}

/* ------------------------------------------------------------------ context */
static void base_free(Base3D *B) {
    if (!B) return;
    for (int j = 0; j < 2; j++) { free(B->xs[j]); free(B->ss[j]); free(B->span[j]); }
    free(B->mrs);
    free(B->fitv);
    free(B->fitc);
    free(B->fita);
    for (int j = 0; j < 3; j++) free(B->fmrs[j]);
    free(B);
}

/* the moving base's buffers (NULL: out of memory, or the hub fixed: n_shared 1) */
static Base3D *base_new(Ctx3D *x) {
    const Model3D *m = x->m;
    Base3D *B = calloc(1, sizeof(Base3D));
    if (!B) return NULL;
    B->prescribed = m->n_shared_rows > 1;
    B->free_bus = !B->prescribed;
    size_t k = (size_t)x->R * x->n * NB;
    int ok = 1;
    for (int j = 0; j < 2; j++) {
        const Body *b = &x->b[j];
        int ne = b->ne;
        B->xs[j] = calloc((size_t)x->R * ne * 3 + 1, sizeof(double));
        B->ss[j] = calloc((size_t)x->R * ne * ne * 3 + 1, sizeof(double));
        B->span[j] = calloc((size_t)x->R * b->np * 2 + 1, sizeof(int));
        if (!B->xs[j] || !B->ss[j] || !B->span[j]) { ok = 0; continue; }
        for (int rp = 0; rp < x->R * b->np; rp++) {
            const double *S = b->shape + (size_t)rp * 3 * ne;
            int lo = ne, hi = 0;
            for (int e = 0; e < ne; e++)
                if (S[e] != 0.0 || S[ne + e] != 0.0 || S[2 * ne + e] != 0.0) {
                    if (e < lo) lo = e;
                    hi = e + 1;
                }
            B->span[j][2 * rp] = lo < hi ? lo : 0;
            B->span[j][2 * rp + 1] = hi;
        }
        for (int r = 0; r < x->R; r++)
            for (int pt = 0; pt < b->np; pt++) {
                int rp = r * b->np + pt;
                double w = b->w[rp], c[3];
                const double *xp = b->x + rp * 3, *S = b->shape + (size_t)rp * 3 * ne;
                for (int e = 0; e < ne; e++) {
                    double se[3] = {S[e], S[ne + e], S[2 * ne + e]};
                    cross3(xp, se, c);
                    for (int i = 0; i < 3; i++) B->xs[j][((size_t)r * ne + e) * 3 + i] += w * c[i];
                    for (int k2 = 0; k2 < ne; k2++) {
                        double sk[3] = {S[k2], S[ne + k2], S[2 * ne + k2]};
                        cross3(sk, se, c);
                        double *o = B->ss[j] + (((size_t)r * ne + k2) * ne + e) * 3;
                        for (int i = 0; i < 3; i++) o[i] += w * c[i];
                    }
                }
            }
    }
    ok = ok && (B->mrs = calloc(k, sizeof(double)));
    size_t len = (size_t)x->R * x->n + NB;
    ok = ok && (B->fitv = calloc(len, sizeof(double))) && (B->fitc = calloc(len, sizeof(double)))
        && (B->fita = calloc(len, sizeof(double)));
    for (int j = 0; j < 3; j++) ok = ok && (B->fmrs[j] = calloc(k, sizeof(double)));
    if (!ok) { base_free(B); return NULL; }
    return B;
}

/* ------------------------------------------------------------------ inertia */
/* M(q): the rib blocks (mass_matrix), M_rs (B->mrs) and M_ss (B->mss).  Per body and rib
 * (J = [I3 | e_z x R y | R S], s = R y + d, d = the body origin + a e_r): the points' sums
 * sum w s, sum w s s^T and the angle's column by a loop over y = x + S e; the elastic
 * columns sum w J_e = R Sb_e and sum w s x J_e = R (xs_e + sum_k e_k ss_ke) + d x R Sb_e
 * from the invariants. */
static void base_mass_matrix(Ctx3D *x, const double *q) {
    const Model3D *m = x->m;
    Base3D *B = x->base;
    int R = x->R, n = x->n, N = R * n;
    mass_matrix(x, q);
    BusFrame3 f;
    bus_frame(q + N + 4, &f);
    double ys = q[N], msl = m->sleeve_mass;
    double s1[3] = {0.0, msl * ys, 0.0}, ic[9];
    memcpy(ic, m->bus_inertia, sizeof(ic));
    ic[0] += msl * ys * ys;
    ic[8] += msl * ys * ys;
    memset(B->mrs, 0, sizeof(double) * N * NB);
    for (int j = 0; j < 2; j++) {
        const Body *b = &x->b[j];
        int nb = b->nb, ne = b->ne, t = b->t, L = INV_LEN(ne);
        for (int r = 0; r < R; r++) {
            const double *ps = m->rib_frames + 9 * r, *qb = q + r * n + b->off;
            const double *e = qb + t + 1, *inv = b->inv + (size_t)r * L, *Sb = inv + INV_SB;
            const double *xs = B->xs[j] + (size_t)r * ne * 3;
            const double *ss = B->ss[j] + (size_t)r * ne * ne * 3;
            double cs = cos(qb[t]), sn = sin(qb[t]);
            double d[3] = {m->hub_radius + (t ? qb[0] : 0.0), t ? qb[1] : 0.0, t ? qb[2] : 0.0};
            double gs[3 * nb], ls[3 * nb], sw[3] = {0, 0, 0}, sec[9] = {0};
            memset(gs, 0, sizeof(gs));
            memset(ls, 0, sizeof(ls));
            for (int pt = 0; pt < b->np; pt++) {
                int rp = r * b->np + pt;
                double w = b->w[rp], y[3], sp[3], jt[3], c[3];
                const double *xp = b->x + rp * 3, *S = b->shape + (size_t)rp * 3 * ne;
                const int lo = B->span[j][2 * rp], hi = B->span[j][2 * rp + 1];
                for (int i = 0; i < 3; i++) {
                    double acc = xp[i];
                    for (int a = lo; a < hi; a++) acc += S[i * ne + a] * e[a];
                    y[i] = acc;
                }
                jt[0] = -(sn * y[0] + cs * y[1]);             /* e_z x R y */
                jt[1] = cs * y[0] - sn * y[1];
                jt[2] = 0.0;
                sp[0] = jt[1] + d[0];
                sp[1] = -jt[0] + d[1];
                sp[2] = y[2] + d[2];
                cross3(sp, jt, c);
                for (int i = 0; i < 3; i++) {
                    gs[i * nb + t] += w * jt[i];
                    ls[i * nb + t] += w * c[i];
                    sw[i] += w * sp[i];
                    for (int k = 0; k < 3; k++) sec[3 * i + k] += w * sp[i] * sp[k];
                }
            }
            for (int i = 0; i < t; i++) {                /* the translations: I3 */
                double col[3] = {0, 0, 0}, c[3];
                col[i] = 1.0;
                gs[i * nb + i] = inv[INV_M];
                cross3(sw, col, c);
                for (int k = 0; k < 3; k++) ls[k * nb + i] = c[k];
            }
            for (int a = 0; a < ne; a++) {               /* the elastic columns */
                double v[3], rsb[3], rv[3], c[3];
                for (int i = 0; i < 3; i++) v[i] = xs[a * 3 + i];
                for (int k = 0; k < ne; k++)
                    for (int i = 0; i < 3; i++) v[i] += e[k] * ss[(k * ne + a) * 3 + i];
                rsb[0] = cs * Sb[a] - sn * Sb[ne + a];
                rsb[1] = sn * Sb[a] + cs * Sb[ne + a];
                rsb[2] = Sb[2 * ne + a];
                rv[0] = cs * v[0] - sn * v[1];
                rv[1] = sn * v[0] + cs * v[1];
                rv[2] = v[2];
                cross3(d, rsb, c);
                for (int i = 0; i < 3; i++) {
                    gs[i * nb + t + 1 + a] = rsb[i];
                    ls[i * nb + t + 1 + a] = rv[i] + c[i];
                }
            }
            double *Mr = B->mrs + (size_t)r * n * NB + b->off * NB;
            for (int a = 0; a < nb; a++) {
                double g[3] = {gs[a], gs[nb + a], gs[2 * nb + a]};
                double l[3] = {ls[a], ls[nb + a], ls[2 * nb + a]}, gb[3], lb[3], rg[3];
                mv3(ps, g, gb);
                mv3(ps, l, lb);
                mv3(f.rot, gb, rg);
                for (int i = 0; i < 3; i++) {
                    Mr[a * NB + 1 + i] = rg[i];
                    Mr[a * NB + 4 + i] = f.basis[i] * lb[0] + f.basis[3 + i] * lb[1]
                        + f.basis[6 + i] * lb[2];
                }
            }
            double swb[3], local[9], t1[9];
            mv3(ps, sw, swb);
            for (int i = 0; i < 3; i++) s1[i] += swb[i];
            double tr = sec[0] + sec[4] + sec[8];
            for (int i = 0; i < 9; i++) local[i] = (i % 4 == 0 ? tr : 0.0) - sec[i];
            mm3(ps, local, t1);
            for (int i = 0; i < 3; i++)           /* ic += psi local psi^T */
                for (int k = 0; k < 3; k++)
                    ic[3 * i + k] += t1[3 * i] * ps[3 * k] + t1[3 * i + 1] * ps[3 * k + 1]
                        + t1[3 * i + 2] * ps[3 * k + 2];
        }
    }
    double *S = B->mss;
    memset(S, 0, sizeof(double) * NB * NB);
    S[0] = msl;
    for (int i = 0; i < 3; i++) {
        S[1 + i] = S[(1 + i) * NB] = msl * f.rot[3 * i + 1];
        S[(1 + i) * NB + 1 + i] = m->total_mass;
    }
    for (int c = 0; c < 3; c++) {
        double bc[3] = {f.basis[c], f.basis[3 + c], f.basis[6 + c]}, bx[3], rb[3], ib[3];
        cross3(bc, s1, bx);
        mv3(f.rot, bx, rb);
        for (int i = 0; i < 3; i++)
            S[(1 + i) * NB + 4 + c] = S[(4 + c) * NB + 1 + i] = rb[i];
        mv3(ic, bc, ib);
        for (int i = 0; i < 3; i++)
            S[(4 + i) * NB + 4 + c] = f.basis[i] * ib[0] + f.basis[3 + i] * ib[1]
                + f.basis[6 + i] * ib[2];
    }
}

/* p = M v with the border (M as base_mass_matrix left it) */
static void base_matvec(Ctx3D *x, const double *v, double *p) {
    const Base3D *B = x->base;
    int R = x->R, n = x->n, N = R * n;
    matvec(x, v, p);
    const double *vs = v + N;
    double *pss = p + N;
    for (int i = 0; i < NB; i++) {
        double acc = 0.0;
        for (int c = 0; c < NB; c++) acc += B->mss[i * NB + c] * vs[c];
        pss[i] = acc;
    }
    for (int r = 0; r < R; r++) {
        const double *Mr = B->mrs + (size_t)r * n * NB, *vr = v + r * n;
        double *pr = p + r * n;
        for (int a = 0; a < n; a++) {
            double acc = 0.0;
            for (int c = 1; c < NB; c++) {
                acc += Mr[a * NB + c] * vs[c];
                pss[c] += Mr[a * NB + c] * vr[a];
            }
            pr[a] += acc;
        }
    }
}

/* d/dq [1/2 a^T M(q) b]: kinetic_gradient's rib part, then the base's terms, point by point
 * (model3d's dv_t with the base's share of the points' velocities, J^T (V_b x omega_a + V_a x
 * omega_b), _theta_gradient), each point's y = x + S e and S a_e, S b_e taken from its shape
 * (J = [I3 | e_z x R y | R S]: J^T u's elastic rows are S^T R^T u) */
static void base_kinetic_gradient(Ctx3D *x, const double *q, const double *a,
                                  const double *bv, double *g) {
    const Model3D *m = x->m;
    int R = x->R, n = x->n, N = R * n;
    kinetic_gradient(x, q, a, bv, g);
    BusFrame3 f;
    bus_frame(q + N + 4, &f);
    const double *ta = a + N + 4, *tb = bv + N + 4;
    double oma_bus[3], omb_bus[3], vxa_bus[3], vxb_bus[3], dba[9], dbb[9];
    mv3(f.basis, ta, oma_bus);
    mv3(f.basis, tb, omb_bus);
    mtv3(f.rot, a + N + 1, vxa_bus);
    mtv3(f.rot, bv + N + 1, vxb_bus);
    dbasis_rates(&f, ta, dba);
    dbasis_rates(&f, tb, dbb);
    double A[3] = {0, 0, 0}, sva[3] = {0, 0, 0}, svb[3] = {0, 0, 0};
    for (int j = 0; j < 2; j++) {
        const Body *b = &x->b[j];
        const int *span = x->base->span[j];
        int ne = b->ne, t = b->t;
        for (int r = 0; r < R; r++) {
            const double *ps = m->rib_frames + 9 * r, *qb = q + r * n + b->off;
            const double *ab = a + r * n + b->off, *bb = bv + r * n + b->off;
            const double *e = qb + t + 1, *ae = ab + t + 1, *be = bb + t + 1;
            double cs = cos(qb[t]), sn = sin(qb[t]);
            double d[3] = {m->hub_radius + (t ? qb[0] : 0.0), t ? qb[1] : 0.0, t ? qb[2] : 0.0};
            double om_a[3], om_b[3], vx_a[3], vx_b[3];
            mtv3(ps, oma_bus, om_a);
            mtv3(ps, omb_bus, om_b);
            mtv3(ps, vxa_bus, vx_a);
            mtv3(ps, vxb_bus, vx_b);
            double *o = g + r * n + b->off, *oe = o + t + 1;
            double ar[3] = {0, 0, 0}, sa[3] = {0, 0, 0}, sb[3] = {0, 0, 0};
            for (int pt = 0; pt < b->np; pt++) {
                int rp = r * b->np + pt;
                double w = b->w[rp];
                const double *xp = b->x + rp * 3, *S = b->shape + (size_t)rp * 3 * ne;
                const int lo = span[2 * rp], hi = span[2 * rp + 1];
                double y[3], Sa[3], Sb[3];
                for (int i = 0; i < 3; i++) {
                    const double *Si = S + i * ne;
                    double yi = xp[i], sai = 0.0, sbi = 0.0;
                    for (int k = lo; k < hi; k++) {
                        yi += Si[k] * e[k];
                        sai += Si[k] * ae[k];
                        sbi += Si[k] * be[k];
                    }
                    y[i] = yi; Sa[i] = sai; Sb[i] = sbi;
                }
                double ry[3] = {cs * y[0] - sn * y[1], sn * y[0] + cs * y[1], y[2]};
                double jt[3] = {-ry[1], ry[0], 0.0};           /* the angle's column */
                double s[3] = {ry[0] + d[0], ry[1] + d[1], ry[2] + d[2]};
                double qz_a[3], qz_b[3], rel_a[3], rel_b[3], ext_a[3], ext_b[3];
                double full_a[3], full_b[3], c[3], c1[3], c2[3];
                qz_a[0] = ab[t] * jt[0] + cs * Sa[0] - sn * Sa[1];
                qz_a[1] = ab[t] * jt[1] + sn * Sa[0] + cs * Sa[1];
                qz_a[2] = Sa[2];
                qz_b[0] = bb[t] * jt[0] + cs * Sb[0] - sn * Sb[1];
                qz_b[1] = bb[t] * jt[1] + sn * Sb[0] + cs * Sb[1];
                qz_b[2] = Sb[2];
                cross3(om_a, s, c1);
                cross3(om_b, s, c2);
                for (int i = 0; i < 3; i++) {
                    rel_a[i] = qz_a[i] + (t ? ab[i] : 0.0);
                    rel_b[i] = qz_b[i] + (t ? bb[i] : 0.0);
                    ext_a[i] = vx_a[i] + c1[i];
                    ext_b[i] = vx_b[i] + c2[i];
                    full_a[i] = rel_a[i] + ext_a[i];
                    full_b[i] = rel_b[i] + ext_b[i];
                }
                /* J^T (V_b x omega_a + V_a x omega_b) */
                cross3(full_b, om_a, c1);
                cross3(full_a, om_b, c2);
                for (int i = 0; i < 3; i++) c[i] = c1[i] + c2[i];
                double hw = 0.5 * w;
                for (int k = 0; k < t; k++) o[k] += hw * c[k];
                /* dv_t's share of the base's velocities, and the angle's row of J^T c */
                o[t] += hw * ((-qz_a[1] * ext_b[0] + qz_a[0] * ext_b[1])
                              + (-qz_b[1] * ext_a[0] + qz_b[0] * ext_a[1])
                              + jt[0] * c[0] + jt[1] * c[1]);
                /* the elastic rows: S^T R^T (P, Q, 0) (dv_t) + S^T R^T c */
                double P = ab[t] * ext_b[1] + bb[t] * ext_a[1];
                double Q = -(ab[t] * ext_b[0] + bb[t] * ext_a[0]);
                double u0 = P + c[0], u1 = Q + c[1];
                double U[3] = {hw * (cs * u0 + sn * u1), hw * (-sn * u0 + cs * u1), hw * c[2]};
                for (int k = lo; k < hi; k++)
                    oe[k] += S[k] * U[0] + S[ne + k] * U[1] + S[2 * ne + k] * U[2];
                /* the angles' share (_theta_gradient) */
                double u_a[3], u_b[3];
                cross3(om_a, s, u_a);
                cross3(om_b, s, u_b);
                for (int i = 0; i < 3; i++) { u_a[i] += rel_a[i]; u_b[i] += rel_b[i]; }
                cross3(u_a, full_b, c1);
                cross3(u_b, full_a, c2);
                for (int i = 0; i < 3; i++) ar[i] += w * (c1[i] + c2[i]);
                cross3(s, full_a, c1);
                cross3(s, full_b, c2);
                for (int i = 0; i < 3; i++) { sa[i] += w * c1[i]; sb[i] += w * c2[i]; }
            }
            double yv[3];
            mv3(ps, ar, yv);
            for (int i = 0; i < 3; i++) A[i] += yv[i];
            mv3(ps, sa, yv);
            for (int i = 0; i < 3; i++) sva[i] += yv[i];
            mv3(ps, sb, yv);
            for (int i = 0; i < 3; i++) svb[i] += yv[i];
        }
    }
    /* the sleeve point and the bus body (_sleeve_and_bus_gradient) */
    double msl = m->sleeve_mass, ey[3] = {0, 1, 0}, sp[3] = {0, q[N], 0};
    double va[3], vb[3], c[3], ua[3], ub[3], c1[3], c2[3];
    mtv3(f.rot, a + N + 1, va);
    mtv3(f.rot, bv + N + 1, vb);
    cross3(oma_bus, sp, ua);
    cross3(omb_bus, sp, ub);
    ua[1] += a[N];
    ub[1] += bv[N];
    for (int i = 0; i < 3; i++) { va[i] += ua[i]; vb[i] += ub[i]; }
    cross3(vb, oma_bus, c1);
    cross3(va, omb_bus, c2);
    g[N] += 0.5 * msl * (dot3(ey, c1) + dot3(ey, c2));
    cross3(ua, vb, c1);
    cross3(ub, va, c2);
    double sva_s[3], svb_s[3], ia[3], ibv[3];
    for (int i = 0; i < 3; i++) c[i] = msl * (c1[i] + c2[i]);
    cross3(sp, va, sva_s);
    cross3(sp, vb, svb_s);
    mv3(m->bus_inertia, oma_bus, ia);
    mv3(m->bus_inertia, omb_bus, ibv);
    for (int j = 0; j < 3; j++) {
        double bj[3] = {f.basis[j], f.basis[3 + j], f.basis[6 + j]};
        g[N + 4 + j] += 0.5 * (dot3(bj, A) + dot3(dba + 3 * j, svb) + dot3(dbb + 3 * j, sva));
        g[N + 4 + j] += 0.5 * (dot3(bj, c) + msl * dot3(dba + 3 * j, svb_s)
                               + msl * dot3(dbb + 3 * j, sva_s));
        g[N + 4 + j] += 0.5 * (dot3(dba + 3 * j, ibv) + dot3(dbb + 3 * j, ia));
    }
}

/* ------------------------------------------------------------------ joints */
/* Phi with the drive's rows (the bus at the drive's place) */
static void base_constraints(Ctx3D *x, const double *q, const double *stuck, int locked,
                             double *phi) {
    constraints(x, q, stuck, locked, phi);
    if (x->base->prescribed)
        for (int j = 0; j < 6; j++)
            phi[x->R * ROWS + 1 + j] = q[x->R * x->n + 1 + j] - x->base->drive_q[j];
}

/* ------------------------------------------------------------------ arrow algebra */
static double *base_fact_mrs(Ctx3D *x, const Fact *f) {
    return x->base->fmrs[f == &x->pm ? 2 : (int)(f - x->slot)];
}

/* arrow_factor with the base's border: C's columns M_rs and J_rs, the corner [[M_ss, sign
 * J_ss^T], [J_ss, 1 - active]] (the drive's rows active, the stop's when locked) */
static int base_arrow_factor(Ctx3D *x, Fact *f, const double *extra, const double *jc,
                             const double *jr, const double *stuck, int locked, double sign) {
    Base3D *B = x->base;
    int R = x->R, n = x->n, mb = x->mb, s = x->s, ns = x->ns;
    double *fm = base_fact_mrs(x, f), L = locked ? 1.0 : 0.0, *S = f->S;
    memcpy(fm, B->mrs, sizeof(double) * R * n * NB);
    memset(S, 0, sizeof(double) * s * s);
    for (int i = 0; i < ns; i++)
        for (int c = 0; c < ns; c++) S[i * s + c] = B->mss[i * NB + c];
    S[ns] = sign * L;
    S[ns * s] = L;
    S[ns * s + ns] = 1.0 - L;
    if (B->prescribed)
        for (int j = 1; j < 7; j++) {
            S[j * s + ns + j] = sign;
            S[(ns + j) * s + j] = 1.0;
        }
    for (int r = 0; r < R; r++) {
        if (rib_factor(x, f, r, extra, jc, jr, stuck, sign) != OK) return SINGULAR;
        double *Y = f->Y + (size_t)r * mb * s;
        const double *Mr = fm + (size_t)r * n * NB;
        for (int c = 0; c < s; c++) {
            memset(x->ycol, 0, sizeof(double) * mb);
            if (c < ns) {
                for (int a = 0; a < n; a++) x->ycol[a] = Mr[a * NB + c];
                if (c == 0) x->ycol[n + 7] = -1.0;
                rib_solve(x, f, r, x->ycol, c == 0);
            }
            for (int a = 0; a < mb; a++) Y[a * s + c] = x->ycol[a];
        }
        for (int i = 0; i < ns; i++)          /* S -= D Y, D = [M_rs^T, sign J_rs^T] */
            for (int c = 0; c < ns; c++) {
                double acc = i == 0 ? -sign * Y[(n + 7) * s + c] : 0.0;
                for (int a = 0; a < n; a++) acc += Mr[a * NB + i] * Y[a * s + c];
                S[i * s + c] -= acc;
            }
    }
    return lu_factor(s, S, f->spiv) == OK ? OK : SINGULAR;
}

/* (top_zero: every rib's first n right-hand sides are 0, rib_solve's: the projection's) */
static void base_arrow_solve(Ctx3D *x, const Fact *f, double *rr, double *rs, double sign,
                             int top_zero) {
    int R = x->R, n = x->n, mb = x->mb, s = x->s, ns = x->ns;
    const double *fm = base_fact_mrs(x, f);
    double z[MAXS];
    memcpy(z, rs, sizeof(double) * s);
    for (int r = 0; r < R; r++) {
        double *v = rr + r * mb;
        const double *Mr = fm + (size_t)r * n * NB;
        rib_solve(x, f, r, v, top_zero);
        z[0] += sign * v[n + 7];
        for (int a = 0; a < n; a++)
            for (int i = 0; i < ns; i++) z[i] -= Mr[a * NB + i] * v[a];
    }
    lu_solve(s, f->S, f->spiv, z);
    memcpy(rs, z, sizeof(double) * s);
    for (int r = 0; r < R; r++) {
        const double *Y = f->Y + (size_t)r * mb * s;
        for (int a = 0; a < mb; a++) {
            double acc = 0.0;
            for (int c = 0; c < s; c++) acc += Y[a * s + c] * z[c];
            rr[r * mb + a] -= acc;
        }
    }
}

/* v projected onto J v = c in the mass metric (M as base_mass_matrix left it; c: the
 * drive's rates, target); mu: the shared rows' multipliers (the bus's impulse -mu[1:]) */
static int base_project(Ctx3D *x, const double *q, double *v, const double *stuck, int locked,
                        const double *target, double *mu) {
    int R = x->R, n = x->n, mb = x->mb, ns = x->ns, N = R * n;
    jacobian(x, q, stuck, x->jr);
    if (base_arrow_factor(x, &x->pm, NULL, x->jr, x->jr, stuck, locked, 1.0) != OK)
        return SINGULAR;
    for (int r = 0; r < R; r++) {
        double *rr = x->rr + r * mb;
        const double *J = x->jr + r * ROWS * n;
        memset(rr, 0, sizeof(double) * n);
        for (int i = 0; i < ROWS; i++) {
            double acc = 0.0;
            for (int c = 0; c < n; c++) acc += J[i * n + c] * v[r * n + c];
            rr[n + i] = -acc;
        }
        rr[n + 7] += v[N];
    }
    double rs[MAXS] = {0.0};
    rs[ns] = locked ? -v[N] : 0.0;
    if (target)
        for (int j = 0; j < 6; j++) rs[ns + 1 + j] = target[j] - v[N + 1 + j];
    base_arrow_solve(x, &x->pm, x->rr, rs, 1.0, 1);   /* (M dv = -J^T mu: no top) */
    for (int r = 0; r < R; r++)
        for (int a = 0; a < n; a++) v[r * n + a] += x->rr[r * mb + a];
    for (int i = 0; i < ns; i++) v[N + i] += rs[i];
    if (mu) memcpy(mu, rs + ns, sizeof(double) * x->cs);
    return OK;
}

/* ------------------------------------------------------------------ the mode fit */
/* Stage 2's mode fit with a moving base (umbrella3d/stage2fit.py), fit_map's maps: a driven
 * hub's, each rib's fit in the hub's frame (fit_map; the shared coordinates as they are); a
 * free bus's (BusFit), the ribs' fits composed with the bus's correction S_bus = I + A B^T
 * over every coordinate (f->bus_rank rows: S = S_ribs S_bus, so S_bus applied first to the
 * physical velocity, last to the scheme's velocity and to the momentum; the Newton update
 * the ribs' then I + A_n B_n^T: the whole fit's); or (f->whole) one fit of the whole free system's modes, its rows u and phi over
 * every coordinate (the ribs', then the shared ones: N + ns).  vr: the ribs' blocks at
 * stride apart (n, or mb for the arrow's right-hand sides), vs: the shared coordinates. */
static void every_map(const Ctx3D *x, const double *in_t, const double *out, const double *sc,
                      const double *shrink, int r, int kind, double *vr, int stride,
                      double *vs) {
    const Base3D *B = x->base;
    int R = x->R, n = x->n, N = R * n;
    double *g = B->fitv, *acc = B->fita;
    for (int k = 0; k < R; k++) memcpy(g + k * n, vr + (size_t)k * stride, sizeof(double) * n);
    memcpy(g + N, vs, sizeof(double) * x->ns);
    modal_correction(in_t, out, sc, shrink, r, N + x->ns, kind, g, B->fitc, acc);
    for (int k = 0; k < R; k++)
        for (int a = 0; a < n; a++) vr[(size_t)k * stride + a] += acc[k * n + a];
    for (int i = 0; i < x->ns; i++) vs[i] += acc[N + i];
}

static void base_fit_map(const Ctx3D *x, const Fit3D *f, int kind, double *vr, int stride,
                         double *vs) {
    if (f->whole) {
        every_map(x, kind == TRANSPOSE ? f->phi_t : f->u_t, kind == TRANSPOSE ? f->u : f->phi,
                  f->sc, f->shrink, f->r, kind, vr, stride, vs);
        return;
    }
    if (kind == NEWTON) {
        fit_map(x, f, kind, vr, stride);
        if (f->newton_rank > 0)
            every_map(x, f->newton_bt, f->newton_a, NULL, NULL, f->newton_rank, kind, vr, stride,
                      vs);
        return;
    }
    int bus = f->bus_rank > 0;
    if (bus && kind == TO_PHYSICAL)
        every_map(x, f->bus_bt, f->bus_a, NULL, NULL, f->bus_rank, kind, vr, stride, vs);
    fit_map(x, f, kind, vr, stride);
    if (bus && kind == TO_SCHEME)
        every_map(x, f->bus_ct, f->bus_a, NULL, NULL, f->bus_rank, kind, vr, stride, vs);
    if (bus && kind == TRANSPOSE)
        every_map(x, f->bus_at, f->bus_b, NULL, NULL, f->bus_rank, kind, vr, stride, vs);
}

/* ------------------------------------------------------------------ the step */
/* step() for a moving base (integrator3d.MidpointUmbrella._step): the same modified Newton
 * and kept iteration matrix, the base's terms; then the free bus's linear momentum restored
 * (a uniform translation velocity), the projection (onto the drive's rates, its impulse's
 * work counted) and, without a drive, the energy scaling relative to the mass centre. */
static int base_step(Ctx3D *x, const double *stuck, int locked, double h, double force,
                     double tol, double phi_tol, int max_iter, const Fit3D *fit) {
    const Model3D *m = x->m;
    Base3D *B = x->base;
    int R = x->R, n = x->n, N = R * n, ns = x->ns, mb = x->mb, cs = x->cs;
    const double half_h2 = 0.5 * h * h;
    const int damped = m->damping_beta != 0.0;
    double *q = x->q, *q0 = x->q0, *v0 = x->v0, *p0 = x->p0;
    /* the scheme's velocity w0 (the mode fit; else v0) */
    const double *w0 = v0;
    if (fit) {
        memcpy(x->w0, v0, sizeof(double) * (N + ns));
        base_fit_map(x, fit, TO_SCHEME, x->w0, n, x->w0 + N);
        w0 = x->w0;
    }
    base_constraints(x, q0, stuck, locked, x->phi0);
    for (int i = 0; i < N + ns; i++) q[i] = q0[i] + h * w0[i];
    memcpy(x->lam, x->l0, sizeof(double) * (R * ROWS + cs));
    int lagged = kept_serves(x, stuck, locked, h);
    Fact *ff = lagged ? &x->slot[x->kept_slot] : NULL;
    Fact *fresh = &x->slot[x->kept ? 1 - x->kept_slot : 0];
    int factored = lagged, refactored = 0, it;
    x->pend_slot = -1;
    double last = INFINITY;
    for (it = 1; it <= max_iter; it++) {
        for (int i = 0; i < N + ns; i++) {
            x->dq[i] = q[i] - q0[i];
            x->qm[i] = q0[i] + 0.5 * x->dq[i];
            x->v1[i] = 2.0 * x->dq[i] / h - w0[i];
        }
        if (fit) base_fit_map(x, fit, TO_PHYSICAL, x->v1, n, x->v1 + N);
        base_mass_matrix(x, q);
        base_matvec(x, x->v1, x->p1);
        /* the scheme's momentum change S^T (M(q1) v1 - p0) (S^T M(q1) v1 - S^T p0: one map) */
        double *sp1 = x->sp1;
        for (int i = 0; i < N + ns; i++) sp1[i] = x->p1[i] - p0[i];
        if (fit) base_fit_map(x, fit, TRANSPOSE, sp1, n, sp1 + N);
        base_kinetic_gradient(x, x->qm, v0, x->v1, x->gt);
        /* Gonzalez over the whole dq, the correction along the ribs' and the sleeve's */
        base_matvec(x, v0, x->tmp);
        double delta = 0.0, dd = 0.0, gdq = 0.0, scale = 0.0;
        for (int i = 0; i < N + ns; i++) {
            delta += (x->tmp[i] - p0[i]) * x->v1[i];
            scale += 0.5 * (fabs(x->tmp[i] * x->v1[i]) + fabs(p0[i] * x->v1[i]))
                + fabs(x->gt[i] * x->dq[i]);
        }
        delta *= 0.5;
        for (int i = 0; i < N; i++) { dd += x->dq[i] * x->dq[i]; gdq += x->gt[i] * x->dq[i]; }
        for (int i = N; i < N + ns; i++) gdq += x->gt[i] * x->dq[i];
        dd += x->dq[N] * x->dq[N];
        /* (a spinning base: the bus's momentum in the scale; integrator3d.GONZALEZ_NOISE) */
        double corr = gonzalez_discrepancy(delta - gdq, scale);
        if (dd > 0.0 && corr != 0.0)
            for (int i = 0; i <= N; i++) x->gt[i] += corr / dd * x->dq[i];
        base_constraints(x, q, stuck, locked, x->phi);
        jacobian(x, x->qm, stuck, x->jm);
        if (damped) damping_forces(x, fit, h, x->damp);
        double cons_s[NB] = {0.0};
        cons_s[0] = locked ? x->lam[R * ROWS] : 0.0;
        if (B->prescribed)
            for (int j = 1; j < 7; j++) cons_s[j] = x->lam[R * ROWS + j];
        for (int r = 0; r < R; r++) {
            /* the joints' Gonzalez Jacobian G = J(q_m) + f dq^T (f: each row's correction),
             * in the residual as G^T lam = J^T lam + dq (f . lam) */
            const double *dq = x->dq + r * n, *J = x->jm + r * ROWS * n, *qm = x->qm + r * n;
            const double *lam = x->lam + r * ROWS;
            double ddr = 0.0, flam = 0.0, jl[n];
            for (int a = 0; a < n; a++) { ddr += dq[a] * dq[a]; jl[a] = 0.0; }
            for (int i = 0; i < ROWS; i++) {
                double lin = 0.0, size = 0.0;
                for (int a = 0; a < n; a++) {
                    lin += J[i * n + a] * dq[a];
                    size += fabs(J[i * n + a] * qm[a]);
                    jl[a] += J[i * n + a] * lam[i];
                }
                if (i == 7) { lin -= x->dq[N]; size += fabs(x->qm[N]); }
                double phi = x->phi[r * ROWS + i], phi0 = x->phi0[r * ROWS + i];
                size += fabs(phi) + fabs(phi0);
                if (ddr > 0.0) flam += gonzalez_discrepancy(phi - phi0 - lin, size) / ddr * lam[i];
            }
            friction(x, r, dq[m->i_a1], h, &x->fric[r], &x->fric[R + r]);
            if (m->nl_elements) nl_force(x, r, q0 + r * n, q + r * n, x->ycol);
            else rows_matvec(x, &x->krows, m->stiffness + (size_t)r * n * n, x->qm + r * n,
                             x->ycol);
            if (damped) damping_add(x, r, x->ycol);
            for (int a = 0; a < n; a++) {
                double applied = -x->ycol[a], cons = jl[a] + dq[a] * flam;
                if (a == m->i_a1) applied += x->fric[r];
                x->res[r * n + a] = sp1[r * n + a] - h * (x->gt[r * n + a] + applied + cons);
            }
            cons_s[0] -= lam[7];
        }
        for (int i = 0; i < ns; i++)
            x->res[N + i] = sp1[N + i]
                - h * (x->gt[N + i] + (i == 0 ? -force : 0.0) + cons_s[i]
                       - (damped ? x->damp[N + i] : 0.0));
        if (!factored) {
            iteration_blocks(x, q, stuck, h);
            if ((m->nl_elements ? nl_iteration_elastic(x) : iteration_elastic(x, h)) != OK
                || base_arrow_factor(x, fresh, x->gyro, x->jm, x->jr, stuck, locked, -1.0) != OK)
                return SINGULAR;
            ff = fresh;
            factored = refactored = 1;
            x->factorisations++;
        }
        for (int r = 0; r < R; r++) {
            for (int a = 0; a < n; a++) x->rr[r * mb + a] = -0.5 * h * x->res[r * n + a];
            for (int i = 0; i < ROWS; i++) x->rr[r * mb + n + i] = -x->phi[r * ROWS + i];
        }
        double rs[MAXS];
        for (int i = 0; i < ns; i++) rs[i] = -0.5 * h * x->res[N + i];
        for (int i = 0; i < cs; i++) rs[ns + i] = -x->phi[R * ROWS + i];
        if (!locked) rs[ns] = 0.0;
        base_arrow_solve(x, ff, x->rr, rs, -1.0, 0);
        if (fit) base_fit_map(x, fit, NEWTON, x->rr, mb, rs);
        int finite = 1;
        double norm = rib_update(x, q, mb, half_h2, &finite);
        for (int i = 0; i < ns; i++) {
            q[N + i] += rs[i];
            if (!isfinite(rs[i])) finite = 0;
            else if (i > 0 && fabs(rs[i]) > norm) norm = fabs(rs[i]);
        }
        for (int i = 0; i < cs; i++) x->lam[R * ROWS + i] += rs[ns + i] / half_h2;
        if (!finite) return NON_FINITE;
        double rate = it > 1 ? norm / last : 1.0;
        if (norm < tol || (rate < 0.5 && rate / (1.0 - rate) * norm < tol)) {
            base_constraints(x, q, stuck, locked, x->phi);
            if (max_abs(R * ROWS + cs, x->phi) < phi_tol) break;
        }
        if (it > 1 && rate > REFRESH_RATE) factored = 0;
        last = norm;
    }
    if (it > max_iter) return NO_CONVERGENCE;
    x->iterations = it;
    x->pend_slot = (int)(ff - x->slot);
    x->pend_uses = refactored ? 1 : ff->uses + 1;
    x->pend_h = h;
    /* velocities, works, the energy target */
    double *v = x->v;
    for (int i = 0; i < N + ns; i++) { x->dq[i] = q[i] - q0[i]; v[i] = 2.0 * x->dq[i] / h - w0[i]; }
    if (fit) base_fit_map(x, fit, TO_PHYSICAL, v, n, v + N);
    base_mass_matrix(x, q);
    double w_fric = friction_works(x, h);
    x->work_force = force * (q0[N] - q[N]);
    double w_drive = 0.0;
    if (B->prescribed)
        for (int j = 1; j < 7; j++) w_drive += x->lam[R * ROWS + j] * x->dq[N + j];
    double t0 = 0.0;
    for (int i = 0; i < N + ns; i++) t0 += v0[i] * p0[i];
    t0 *= 0.5;
    x->strain = strain_energy(x, q);
    x->work_damp = damped ? damping_work(x, fit, h) : 0.0;
    double t_target = t0 + strain_energy(x, q0) - x->strain + x->work_force + w_fric + w_drive
        - x->work_damp;
    double drift[NB] = {0.0};
    if (B->free_bus) {
        /* the bus position is cyclic: its momentum p_X is the step's start's */
        base_matvec(x, v, x->p);
        for (int i = 1; i < 4; i++) {
            drift[i] = p0[N + i] / m->total_mass;
            v[N + i] += (p0[N + i] - x->p[N + i]) / m->total_mass;
        }
    }
    if (B->prescribed) {
        double v_bus[6], mu[NB];
        memcpy(v_bus, v + N + 1, sizeof(v_bus));
        if (base_project(x, q, v, stuck, locked, B->drive_v, mu) != OK) return SINGULAR;
        for (int j = 0; j < 6; j++) w_drive -= 0.5 * mu[1 + j] * (v_bus[j] + v[N + 1 + j]);
        base_matvec(x, v, x->p);
    } else {
        if (base_project(x, q, v, stuck, locked, NULL, NULL) != OK) return SINGULAR;
        base_matvec(x, v, x->p);
        /* the scaling relative to the mass centre's velocity (König) */
        double t_drift = 0.0, t_after = 0.0;
        for (int i = 0; i < NB; i++) t_drift += drift[i] * drift[i];
        t_drift *= 0.5 * m->total_mass;
        for (int i = 0; i < N + ns; i++) t_after += v[i] * x->p[i];
        t_after = 0.5 * t_after - t_drift;
        double t_rel = t_target - t_drift;
        if (t_after > 0.0 && t_after / 1.01 <= t_rel && t_rel <= 1.01 * t_after) {
            double scale = sqrt(t_rel / t_after);
            for (int i = 0; i < N; i++) v[i] *= scale;
            for (int i = 0; i < ns; i++) v[N + i] = (v[N + i] - drift[i]) * scale + drift[i];
            base_matvec(x, v, x->p);
        }
    }
    B->work_drive = w_drive;
    return OK;
}

/* the state's p = M(q) v (load: a call without p) */
static void base_momenta(Ctx3D *x, const double *q, const double *v, double *p) {
    base_mass_matrix(x, q);
    base_matvec(x, v, p);
}

/* a row's base figures after the hub fixed's: the drive's work, and a free bus's linear and
 * angular momentum (inertial, about the origin) from the generalised momenta: P = p_X,
 * H = X x P + R B^-T p_theta (p_theta = B^T h, h the bus-frame angular momentum about the
 * bus origin: model3d.UmbrellaModel3D.momentum's sums) */
static double *base_row(const Ctx3D *x, const double *q, const double *p, double *o) {
    int N = x->R * x->n;
    *o++ = x->base ? x->base->work_drive : 0.0;
    if (!x->base || !x->base->free_bus) return o;
    BusFrame3 f;
    bus_frame(q + N + 4, &f);
    const double *P = p + N + 1, *pt = p + N + 4, *b = f.basis;
    /* B^T h = p_theta: h by Cramer's rule on the 3 x 3 B^T */
    double bt[9], det, h[3], xp[3], rh[3];
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) bt[3 * i + k] = b[3 * k + i];
    det = bt[0] * (bt[4] * bt[8] - bt[5] * bt[7]) - bt[1] * (bt[3] * bt[8] - bt[5] * bt[6])
        + bt[2] * (bt[3] * bt[7] - bt[4] * bt[6]);
    for (int c = 0; c < 3; c++) {
        double mcol[9];
        memcpy(mcol, bt, sizeof(mcol));
        for (int i = 0; i < 3; i++) mcol[3 * i + c] = pt[i];
        h[c] = (mcol[0] * (mcol[4] * mcol[8] - mcol[5] * mcol[7])
                - mcol[1] * (mcol[3] * mcol[8] - mcol[5] * mcol[6])
                + mcol[2] * (mcol[3] * mcol[7] - mcol[4] * mcol[6])) / det;
    }
    cross3(q + N + 1, P, xp);
    mv3(f.rot, h, rh);
    for (int i = 0; i < 3; i++) *o++ = P[i];
    for (int i = 0; i < 3; i++) *o++ = xp[i] + rh[i];
    return o;
}
