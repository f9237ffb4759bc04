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
 * Elastic law of the compiled step (see _kernel_elastic.h).
 *
 * The co-rotational beam (beam_strain.CorotationalStrainEnergy), element by element in its
 * body's frame on its coordinates x = (u_a, v_a, theta_a, u_b, v_b, theta_b):
 * z = (d_x, d_y, theta_a, theta_b) with the chord d = (l + u_b - u_a, v_b - v_a), and
 *   lambda = |d| / l, beta = atan2(d), tb_i = wrap(asin(theta_i) - beta),
 *   eps = lambda - 1 + (2 tb_a^2 - tb_a tb_b + 2 tb_b^2) / 30,   s = (eps, tb_a, tb_b),
 * U_e = 1/2 s.D s, D = diag(EA l, EI / l [[4, 2], [2, 4]]).  Over a step, the discrete
 * gradient L^T B~^T D (s0 + s1) / 2 with B~ (z1 - z0) = s1 - s0 (lambda by (d0 + d1) / ((|d0| +
 * |d1|) l), beta by Gonzalez's midpoint discrete gradient, asin(theta) by its secant, Q at the
 * mean angles), so that dq . G = U(q1) - U(q0) to round-off; s1 from s0 and the accurate angle
 * increments of the step (an iteration evaluates no angle itself); the Newton matrix
 * 1/2 L^T [J^T D J + sum_k (D s_mean)_k H_k] L at z_m = (z0 + z1) / 2 (J = ds/dz, H_k the Hessian
 * of s_k there, Q's pieces at s_mean); the damping C(q_m) = beta L^T J^T D J L at q_m with its
 * own strains; the fibre stress E (eps -/+ c kappa) at both ends of each element,
 * kappa = (-4 tb_a - 2 tb_b) / l and (2 tb_a + 4 tb_b) / l.  The same formulas as the numpy
 * reference.
 *
 * The linear strain (a damped flexible model): U = 1/2 q.K q, C = beta K, whose products the
 * caller's band products with ElasticData.k_band = K already hold.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "_kernel_elastic.h"

#define EDOF 6      /* coordinates of an element: u, v, theta of its two nodes */
#define CR_Z 4      /* its chord and nodal slopes z = (d_x, d_y, theta_a, theta_b) */
#define CR_STATE 10 /* z, its strains s = (eps, tb_a, tb_b), and the angle increments (beta,
                     * psi_a, psi_b) of the step to it (at a step's end) */
/* z index and sign of each coordinate: z = off + L x */
static const int Z_OF[EDOF] = {0, 1, 2, 0, 1, 3};
static const double Z_SIGN[EDOF] = {-1.0, -1.0, 1.0, 1.0, 1.0, 1.0};

ElasticLaw *elastic_new(const ElasticData *d) {
    ElasticLaw *law = calloc(1, sizeof(ElasticLaw));
    if (!law) return NULL;
    law->d = *d;
    int w = 2 * d->bw + 1, nc = d->ne + 4;
    size_t doubles = (size_t)d->ne * w + 6 * (size_t)d->n + 8 * (size_t)d->n_el + nc
                     + (size_t)(d->n + nc) + 2 * (size_t)d->n_el * CR_STATE;
    law->band = calloc(doubles, sizeof(double));
    if (!law->band) { free(law); return NULL; }
    double *p = law->band + (size_t)d->ne * w;
    law->qa = p; p += d->n;
    law->qb = p; p += d->n;
    law->q_base = p; p += d->n;
    law->energy_q = p; p += d->n;
    law->start_q = p; p += d->n;
    law->cur_q = p; p += d->n;
    law->el_stress = p; p += 4 * (size_t)d->n_el;
    law->el_stress_rate = p; p += 4 * (size_t)d->n_el;
    law->lam_base = p; p += nc;
    law->dx = p; p += d->n + nc;
    law->cr_start = p; p += (size_t)d->n_el * CR_STATE;
    law->cr_cur = p;
    law->band_h = -1.0;
    return law;
}

void elastic_free(ElasticLaw *law) {
    if (!law) return;
    free(law->band);
    free(law);
}

/* x . K x on the elastic coordinates (K = ElasticData.k_band) */
static double band_quadratic(const ElasticData *d, const double *x) {
    int ne = d->ne, bw = d->bw, w = 2 * bw + 1;
    double quad = 0.0;
    for (int p = 0; p < ne; p++) {
        int lo = p - bw < 0 ? 0 : p - bw, hi = p + bw >= ne ? ne - 1 : p + bw;
        const double *r = d->k_band + (size_t)p * w + bw - p;
        double s = 0.0;
        for (int j = lo; j <= hi; j++) s += r[j] * x[d->elastic_idx[j]];
        quad += x[d->elastic_idx[p]] * s;
    }
    return quad;
}

/* ------------------------------------------------------------------ co-rotational beam */
static const double CR_ARC = 1.0 / 30.0;

static double wrap_angle(double a) {   /* a in (-pi, pi] (beam_strain.wrap_angle) */
    const double pi = 3.141592653589793;
    return a - 2.0 * pi * floor((a + pi) / (2.0 * pi));
}

/* x: the element's coordinates of q (0 where the frame fixes one); z of x, offset by the
 * element's length (off = 1) or not (off = 0: the rate of z along a velocity) */
static void cr_chords(const ElasticData *d, int e, const double *q, int off, double *z) {
    const int *iq = d->el_q + (size_t)e * EDOF;
    double x[EDOF];
    for (int k = 0; k < EDOF; k++) x[k] = iq[k] >= 0 ? q[iq[k]] : 0.0;
    z[0] = (off ? d->el_length[e] : 0.0) + (x[3] - x[0]);
    z[1] = x[4] - x[1];
    z[2] = x[2];
    z[3] = x[5];
}

static void cr_strains_from(double lam, double ta, double tb, double *s) {
    s[0] = lam - 1.0 + (2.0 * ta * ta - ta * tb + 2.0 * tb * tb) * CR_ARC;
    s[1] = ta;
    s[2] = tb;
}

static void cr_strains(const ElasticData *d, int e, const double *z, double *s) {
    double beta = atan2(z[1], z[0]);
    cr_strains_from(hypot(z[0], z[1]) / d->el_length[e], wrap_angle(asin(z[2]) - beta),
                    wrap_angle(asin(z[3]) - beta), s);
}

/* z and s of element e at q into st (CR_STATE) */
static void cr_state(const ElasticData *d, int e, const double *q, double *st) {
    cr_chords(d, e, q, 1, st);
    cr_strains(d, e, st, st + CR_Z);
}

/* The principal angle from w0 to w1, atan2(w0 x w1, w0 . w1) (beam_strain.angle_increment):
 * for |tan| <= 1/16 (a step's increments) by the odd series of atan to t^15 (truncation
 * below 1e-20 relative), else by atan2 */
static double angle_increment(const double *w0, const double *w1) {
    double y = w0[0] * w1[1] - w0[1] * w1[0], x = w0[0] * w1[0] + w0[1] * w1[1];
    if (x > 0.0 && fabs(y) <= 0.0625 * x) {
        double r = y / x, u = r * r;
        return r * (1.0 - u * (1.0 / 3 - u * (1.0 / 5 - u * (1.0 / 7 - u * (1.0 / 9 - u * (1.0 / 11
                    - u * (1.0 / 13 - u * (1.0 / 15))))))));
    }
    return atan2(y, x);
}

/* asin(t1) - asin(t0) = asin(t1 sqrt(1 - t0^2) - t0 sqrt(1 - t1^2))
 * (beam_strain.section_angle_increment); a small argument by the series of asin to y^15 */
static double section_angle_increment(double t0, double t1) {
    double y = t1 * sqrt(1.0 - t0 * t0) - t0 * sqrt(1.0 - t1 * t1);
    if (fabs(y) <= 0.0625) {
        double u = y * y;
        return y * (1.0 + u * (1.0 / 6 + u * (3.0 / 40 + u * (5.0 / 112 + u * (35.0 / 1152
                    + u * (63.0 / 2816 + u * (231.0 / 13312 + u * (143.0 / 10240))))))));
    }
    return asin(y);
}

static void angle_gradient(const double *w, double *g) {
    double r2 = w[0] * w[0] + w[1] * w[1];
    g[0] = -w[1] / r2;
    g[1] = w[0] / r2;
}

/* [[2xy, y^2 - x^2], [y^2 - x^2, -2xy]] / |w|^4 */
static void angle_hessian(const double *w, double *h) {
    double x = w[0], y = w[1], r4 = (x * x + y * y) * (x * x + y * y), off = (y * y - x * x) / r4;
    h[0] = 2.0 * x * y / r4; h[1] = off; h[2] = off; h[3] = -2.0 * x * y / r4;
}

/* ds/dz (3 x 4, row-major) at z with the angles of s (Q's pieces) */
static void cr_jacobian(const ElasticData *d, int e, const double *z, const double *s, double *jac) {
    double gb[2];
    angle_gradient(z, gb);
    double ln = hypot(z[0], z[1]), le = d->el_length[e];
    double *ja = jac + CR_Z, *jb = jac + 2 * CR_Z;
    ja[0] = jb[0] = -gb[0];
    ja[1] = jb[1] = -gb[1];
    ja[2] = 1.0 / sqrt(1.0 - z[2] * z[2]); ja[3] = 0.0;
    jb[2] = 0.0; jb[3] = 1.0 / sqrt(1.0 - z[3] * z[3]);
    double qa = (4.0 * s[1] - s[2]) * CR_ARC, qb = (-s[1] + 4.0 * s[2]) * CR_ARC;
    jac[0] = z[0] / (ln * le) + qa * ja[0] + qb * jb[0];
    jac[1] = z[1] / (ln * le) + qa * ja[1] + qb * jb[1];
    jac[2] = qa * ja[2];
    jac[3] = qb * jb[3];
}

/* B~ in z (3 x 4) between the states st0, st1 (st1 with the step's angle increments) */
static void cr_discrete_jacobian(const ElasticData *d, int e, const double *st0, const double *st1,
                                 double *jac) {
    const double *inc = st1 + CR_Z + 3;
    double dw[2] = {st1[0] - st0[0], st1[1] - st0[1]};
    double wm[2] = {0.5 * (st0[0] + st1[0]), 0.5 * (st0[1] + st1[1])}, gb[2];
    angle_gradient(wm, gb);            /* Gonzalez in d: gb + (dbeta - gb.dw) dw / |dw|^2 */
    double dd = dw[0] * dw[0] + dw[1] * dw[1];
    double corr = dd > 0.0 ? (inc[0] - (gb[0] * dw[0] + gb[1] * dw[1])) / dd : 0.0;
    gb[0] += corr * dw[0];
    gb[1] += corr * dw[1];
    double *ja = jac + CR_Z, *jb = jac + 2 * CR_Z;
    ja[0] = jb[0] = -gb[0];
    ja[1] = jb[1] = -gb[1];
    double da = st1[2] - st0[2], db = st1[3] - st0[3];    /* asin(theta) by its secant */
    ja[2] = da != 0.0 ? inc[1] / da : 1.0 / sqrt(1.0 - st0[2] * st0[2]); ja[3] = 0.0;
    jb[2] = 0.0; jb[3] = db != 0.0 ? inc[2] / db : 1.0 / sqrt(1.0 - st0[3] * st0[3]);
    double l_sum = hypot(st0[0], st0[1]) + hypot(st1[0], st1[1]), le = d->el_length[e];
    const double *s0 = st0 + CR_Z, *s1 = st1 + CR_Z;
    double ma = 0.5 * (s0[1] + s1[1]), mb = 0.5 * (s0[2] + s1[2]);
    double qa = (4.0 * ma - mb) * CR_ARC, qb = (-ma + 4.0 * mb) * CR_ARC;
    jac[0] = (st0[0] + st1[0]) / (l_sum * le) + qa * ja[0] + qb * jb[0];
    jac[1] = (st0[1] + st1[1]) / (l_sum * le) + qa * ja[1] + qb * jb[1];
    jac[2] = qa * ja[2];
    jac[3] = qb * jb[3];
}

/* sigma = D s */
static void cr_resultants(const ElasticData *d, int e, const double *s, double *sigma) {
    double le = d->el_length[e], k4 = d->ei / le * 4.0, k2 = d->ei / le * 2.0;
    sigma[0] = d->ea * le * s[0];
    sigma[1] = k4 * s[1] + k2 * s[2];
    sigma[2] = k2 * s[1] + k4 * s[2];
}

/* y[q index] += scale L^T jac^T sigma on the element's coordinates */
static void cr_scatter_vector(const ElasticData *d, int e, const double *jac, const double *sigma,
                              double scale, double *y) {
    const int *iq = d->el_q + (size_t)e * EDOF;
    double r[CR_Z];
    for (int i = 0; i < CR_Z; i++)
        r[i] = jac[i] * sigma[0] + jac[CR_Z + i] * sigma[1] + jac[2 * CR_Z + i] * sigma[2];
    for (int k = 0; k < EDOF; k++)
        if (iq[k] >= 0) y[iq[k]] += scale * Z_SIGN[k] * r[Z_OF[k]];
}

/* m += J^T D J (4 x 4) */
static void cr_material(const ElasticData *d, int e, const double *jac, double *m) {
    double dj[3 * CR_Z];
    for (int i = 0; i < CR_Z; i++) {
        double col[3] = {jac[i], jac[CR_Z + i], jac[2 * CR_Z + i]}, sg[3];
        cr_resultants(d, e, col, sg);
        dj[i] = sg[0]; dj[CR_Z + i] = sg[1]; dj[2 * CR_Z + i] = sg[2];
    }
    for (int i = 0; i < CR_Z; i++)
        for (int j = 0; j < CR_Z; j++)
            m[i * CR_Z + j] += jac[i] * dj[j] + jac[CR_Z + i] * dj[CR_Z + j]
                               + jac[2 * CR_Z + i] * dj[2 * CR_Z + j];
}

/* m += sum_k sigma_k d^2 s_k / dz^2 at z, with jac = ds/dz there and Q's pieces of s */
static void cr_geometric(const ElasticData *d, int e, const double *z, const double *s,
                         const double *jac, const double *sigma, double *m) {
    double hb[4];
    angle_hessian(z, hb);
    double qa = (4.0 * s[1] - s[2]) * CR_ARC, qb = (-s[1] + 4.0 * s[2]) * CR_ARC;
    /* the weights of the Hessians of tb_a, tb_b in sum_k sigma_k H_k */
    double wa = sigma[1] + sigma[0] * qa, wb = sigma[2] + sigma[0] * qb;
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) m[i * CR_Z + j] -= (wa + wb) * hb[2 * i + j];
    double ta = z[2], tb = z[3];
    m[2 * CR_Z + 2] += wa * ta / pow(1.0 - ta * ta, 1.5);
    m[3 * CR_Z + 3] += wb * tb / pow(1.0 - tb * tb, 1.5);
    /* lambda = |d| / l: (I - n n^T) / (|d| l) */
    double ln = hypot(z[0], z[1]), le = d->el_length[e], n0 = z[0] / ln, n1 = z[1] / ln;
    double c = sigma[0] / (ln * le);
    m[0] += c * (1.0 - n0 * n0);
    m[1] -= c * n0 * n1;
    m[CR_Z] -= c * n0 * n1;
    m[CR_Z + 1] += c * (1.0 - n1 * n1);
    /* Q / 30: J_tb^T [[4, -1], [-1, 4]] J_tb / 30 */
    const double *ja = jac + CR_Z, *jb = jac + 2 * CR_Z;
    for (int i = 0; i < CR_Z; i++)
        for (int j = 0; j < CR_Z; j++)
            m[i * CR_Z + j] += sigma[0] * CR_ARC * (4.0 * ja[i] * ja[j] - ja[i] * jb[j]
                                                     - jb[i] * ja[j] + 4.0 * jb[i] * jb[j]);
}

/* band += scale L^T m L on the element's elastic positions */
static void cr_scatter_band(const ElasticData *d, int e, const double *m, double scale, double *band) {
    int bw = d->bw, w = 2 * bw + 1;
    const int *pos = d->el_pos + (size_t)e * EDOF;
    for (int k = 0; k < EDOF; k++) {
        if (pos[k] < 0) continue;
        double *r = band + (size_t)pos[k] * w + bw - pos[k];
        const double *mk = m + Z_OF[k] * CR_Z;
        double sk = scale * Z_SIGN[k];
        for (int l = 0; l < EDOF; l++)
            if (pos[l] >= 0) r[pos[l]] += sk * Z_SIGN[l] * mk[Z_OF[l]];
    }
}

/* the start states (z0, s0) of every element at q0, kept while q0 stays */
static void cr_step_start(ElasticLaw *law, const double *q0) {
    const ElasticData *d = &law->d;
    if (law->start_valid && memcmp(q0, law->start_q, sizeof(double) * d->n) == 0) return;
    for (int e = 0; e < d->n_el; e++) {
        double *st = law->cr_start + (size_t)e * CR_STATE;
        cr_state(d, e, q0, st);
        for (int k = 2; k < CR_Z; k++)
            if (fabs(st[k]) > law->max_slope) law->max_slope = fabs(st[k]);
    }
    memcpy(law->start_q, q0, sizeof(double) * d->n);
    law->start_valid = 1;
    law->cur_valid = 0;     /* the current states are increments from the start */
}

/* the states of every element at q1 (z1, s1 from s0 and the angle increments, which they
 * keep), for the force and the iteration band of the same q1 (beam_strain.CorotationalStrainEnergy._step_strains) */
static void cr_step_current(ElasticLaw *law, const double *q1) {
    const ElasticData *d = &law->d;
    if (law->cur_valid && memcmp(q1, law->cur_q, sizeof(double) * d->n) == 0) return;
    for (int e = 0; e < d->n_el; e++) {
        const double *st0 = law->cr_start + (size_t)e * CR_STATE;
        double *st1 = law->cr_cur + (size_t)e * CR_STATE, *inc = st1 + CR_Z + 3;
        cr_chords(d, e, q1, 1, st1);
        inc[0] = angle_increment(st0, st1);
        inc[1] = section_angle_increment(st0[2], st1[2]);
        inc[2] = section_angle_increment(st0[3], st1[3]);
        cr_strains_from(hypot(st1[0], st1[1]) / d->el_length[e], st0[CR_Z + 1] + inc[1] - inc[0],
                        st0[CR_Z + 2] + inc[2] - inc[0], st1 + CR_Z);
    }
    memcpy(law->cur_q, q1, sizeof(double) * d->n);
    law->cur_valid = 1;
}

/* s' = J dz on the element (dz: z1 - z0, or the rate of z) */
static void cr_strain_change(const double *jac, const double *dz, double *ds) {
    for (int k = 0; k < 3; k++) {
        double r = 0.0;
        for (int i = 0; i < CR_Z; i++) r += jac[k * CR_Z + i] * dz[i];
        ds[k] = r;
    }
}

/* ds/dz at q_m = q0 + (q1 - q0) / 2 with its own strains (the damping's) */
static void cr_midpoint_jacobian(const ElasticLaw *law, int e, const double *qm, double *jac) {
    double st[CR_STATE];
    cr_state(&law->d, e, qm, st);
    cr_jacobian(&law->d, e, st, st + CR_Z, jac);
}

/* the element states of a step q0 -> q1, and its midpoint (for the damping term) */
static void cr_step_states(ElasticLaw *law, const double *q0, const double *q1) {
    const ElasticData *d = &law->d;
    cr_step_start(law, q0);
    cr_step_current(law, q1);
    if (d->beta > 0.0)
        for (int i = 0; i < d->n; i++) law->qa[i] = q0[i] + 0.5 * (q1[i] - q0[i]);
}

static void cr_force(ElasticLaw *law, const double *q0, const double *q1, double h, double *out) {
    const ElasticData *d = &law->d;
    cr_step_states(law, q0, q1);
    for (int e = 0; e < d->n_el; e++) {
        const double *st0 = law->cr_start + (size_t)e * CR_STATE, *st1 = law->cr_cur + (size_t)e * CR_STATE;
        double jac[3 * CR_Z], sm[3], sigma[3];
        cr_discrete_jacobian(d, e, st0, st1, jac);
        for (int k = 0; k < 3; k++) sm[k] = 0.5 * (st0[CR_Z + k] + st1[CR_Z + k]);
        cr_resultants(d, e, sm, sigma);
        cr_scatter_vector(d, e, jac, sigma, 1.0, out);
        if (d->beta > 0.0) {   /* + C(q_m) dq / h = beta / h L^T J^T D J dz */
            double jm[3 * CR_Z], dz[CR_Z], ds[3], sd[3];
            cr_midpoint_jacobian(law, e, law->qa, jm);
            for (int i = 0; i < CR_Z; i++) dz[i] = st1[i] - st0[i];
            cr_strain_change(jm, dz, ds);
            cr_resultants(d, e, ds, sd);
            cr_scatter_vector(d, e, jm, sd, d->beta / h, out);
        }
    }
}

static void cr_iteration_band(ElasticLaw *law, const double *q0, const double *q1, double h) {
    const ElasticData *d = &law->d;
    size_t nb = (size_t)d->ne * (2 * d->bw + 1);
    memset(law->band, 0, sizeof(double) * nb);
    law->band_h = h;
    cr_step_states(law, q0, q1);
    for (int e = 0; e < d->n_el; e++) {
        const double *st0 = law->cr_start + (size_t)e * CR_STATE, *st1 = law->cr_cur + (size_t)e * CR_STATE;
        double zm[CR_Z], sm[3], sigma[3], jac[3 * CR_Z], m[CR_Z * CR_Z];
        for (int i = 0; i < CR_Z; i++) zm[i] = 0.5 * (st0[i] + st1[i]);
        for (int k = 0; k < 3; k++) sm[k] = 0.5 * (st0[CR_Z + k] + st1[CR_Z + k]);
        cr_jacobian(d, e, zm, sm, jac);
        cr_resultants(d, e, sm, sigma);
        memset(m, 0, sizeof m);
        cr_material(d, e, jac, m);
        cr_geometric(d, e, zm, sm, jac, sigma, m);
        cr_scatter_band(d, e, m, 0.25 * h * h, law->band);
        if (d->beta > 0.0) {
            double jm[3 * CR_Z];
            cr_midpoint_jacobian(law, e, law->qa, jm);
            memset(m, 0, sizeof m);
            cr_material(d, e, jm, m);
            cr_scatter_band(d, e, m, 0.5 * h * d->beta, law->band);
        }
    }
}

static double cr_energy(ElasticLaw *law, const double *q) {
    const ElasticData *d = &law->d;
    cr_step_start(law, q);   /* the element states at q: the next step starts from them */
    double u = 0.0;
    for (int e = 0; e < d->n_el; e++) {
        const double *s = law->cr_start + (size_t)e * CR_STATE + CR_Z;
        double sigma[3];
        cr_resultants(d, e, s, sigma);
        u += s[0] * sigma[0] + s[1] * sigma[1] + s[2] * sigma[2];
    }
    return 0.5 * u;
}

static double cr_dissipation(ElasticLaw *law, const double *q0, const double *q1, double h) {
    const ElasticData *d = &law->d;
    double diss = 0.0;
    for (int i = 0; i < d->n; i++) law->qa[i] = q0[i] + 0.5 * (q1[i] - q0[i]);
    for (int e = 0; e < d->n_el; e++) {
        double jm[3 * CR_Z], z0[CR_Z], z1[CR_Z], dz[CR_Z], ds[3], sd[3];
        cr_midpoint_jacobian(law, e, law->qa, jm);
        cr_chords(d, e, q0, 1, z0);
        cr_chords(d, e, q1, 1, z1);
        for (int i = 0; i < CR_Z; i++) dz[i] = z1[i] - z0[i];
        cr_strain_change(jm, dz, ds);
        cr_resultants(d, e, ds, sd);
        diss += ds[0] * sd[0] + ds[1] * sd[1] + ds[2] * sd[2];
    }
    return d->beta * diss / h;
}

/* E (eps -/+ c kappa) at both ends of every element from s (or its rate: linear in s) */
static void cr_fibre(const ElasticData *d, int e, const double *s, double *out) {
    int npts = 2 * d->n_el;
    double le = d->el_length[e], ka = (-4.0 * s[1] - 2.0 * s[2]) / le, kb = (2.0 * s[1] + 4.0 * s[2]) / le;
    double em = d->youngs_modulus, c = d->fibre;
    out[2 * e] = em * (s[0] - c * ka);
    out[2 * e + 1] = em * (s[0] - c * kb);
    out[npts + 2 * e] = em * (s[0] + c * ka);
    out[npts + 2 * e + 1] = em * (s[0] + c * kb);
}

static void cr_fibre_stress(ElasticLaw *law, const double *q) {
    const ElasticData *d = &law->d;
    cr_step_start(law, q);   /* usually kept from the energy of the step that ended at q */
    for (int e = 0; e < d->n_el; e++) cr_fibre(d, e, law->cr_start + (size_t)e * CR_STATE + CR_Z, law->el_stress);
}

static void cr_fibre_stress_rate(ElasticLaw *law, const double *q, const double *v) {
    const ElasticData *d = &law->d;
    cr_step_start(law, q);
    for (int e = 0; e < d->n_el; e++) {
        const double *st = law->cr_start + (size_t)e * CR_STATE;
        double jac[3 * CR_Z], zd[CR_Z], rate[3];
        cr_jacobian(d, e, st, st + CR_Z, jac);
        cr_chords(d, e, v, 0, zd);        /* dz/dt = L v */
        cr_strain_change(jac, zd, rate);
        cr_fibre(d, e, rate, law->el_stress_rate);
    }
}

/* ------------------------------------------------------------------------------- API */
void elastic_force(ElasticLaw *law, const double *q0, const double *q1, double h,
                   const double *k_dq, double *out) {
    const ElasticData *d = &law->d;
    if (d->nonlinear) { cr_force(law, q0, q1, h, out); return; }
    if (d->beta > 0.0) {   /* K q_m (on entry) + beta K dq / h */
        double c = d->beta / h;
        for (int p = 0; p < d->ne; p++) { int i = d->elastic_idx[p]; out[i] += c * k_dq[i]; }
    }
}

void elastic_iteration_band(ElasticLaw *law, const double *q0, const double *q1, double h) {
    const ElasticData *d = &law->d;
    if (d->nonlinear) { cr_iteration_band(law, q0, q1, h); return; }
    if (law->band_h == h) return;                 /* constant for the linear strain */
    size_t nb = (size_t)d->ne * (2 * d->bw + 1);
    double scale = 0.25 * h * h + 0.5 * h * d->beta;
    for (size_t k = 0; k < nb; k++) law->band[k] = scale * d->k_band[k];
    law->band_h = h;
}

double elastic_energy(ElasticLaw *law, const double *q, const double *kq) {
    const ElasticData *d = &law->d;
    /* asked for the end of a step, then its output row, then the start of the next */
    if (law->energy_valid && memcmp(q, law->energy_q, sizeof(double) * d->n) == 0)
        return law->energy;
    double u;
    if (d->nonlinear) u = cr_energy(law, q);
    else if (kq) {
        u = 0.0;
        for (int p = 0; p < d->ne; p++) { int i = d->elastic_idx[p]; u += q[i] * kq[i]; }
        u *= 0.5;
    } else u = 0.5 * band_quadratic(d, q);
    memcpy(law->energy_q, q, sizeof(double) * d->n);
    law->energy = u;
    law->energy_valid = 1;
    return u;
}

double elastic_dissipation(ElasticLaw *law, const double *q0, const double *q1, double h) {
    const ElasticData *d = &law->d;
    double diss = 0.0;
    if (d->beta > 0.0) {
        if (d->nonlinear) diss = cr_dissipation(law, q0, q1, h);
        else {
            for (int i = 0; i < d->n; i++) law->qb[i] = q1[i] - q0[i];
            diss = d->beta * band_quadratic(d, law->qb) / h;
        }
    }
    law->last_dissipation = diss;
    return diss;
}

void elastic_fibre_stress(ElasticLaw *law, const double *q) {
    if (law->d.nonlinear) cr_fibre_stress(law, q);
}

void elastic_fibre_stress_rate(ElasticLaw *law, const double *q, const double *v) {
    if (law->d.nonlinear) cr_fibre_stress_rate(law, q, v);
}

int elastic_admissible(const ElasticLaw *law, const double *q) {
    const ElasticData *d = &law->d;
    if (!d->nonlinear) return 1;
    for (int e = 0; e < d->n_el; e++)
        for (int k = 2; k < EDOF; k += 3) {          /* theta_a, theta_b */
            int i = d->el_q[(size_t)e * EDOF + k];
            if (i >= 0 && !(fabs(q[i]) < 1.0)) return 0;
        }
    return 1;
}

double elastic_last_dissipation(const ElasticLaw *law) {
    return law->last_dissipation;
}

double elastic_max_slope(const ElasticLaw *law) {
    return law->max_slope;
}
