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
 * The umbrella's co-rotational ribs (model flexible-nonlinear) in the compiled step:
 * umbrella3d/corotational3d.py's RibCorotationalStrain (the numpy reference, which documents
 * the element) element by element, and the O'' hinge's turned rows.  Included by _kernel3d.c
 * after its context; its hooks there, each under Model3D.nl_elements (0: the linear beams,
 * whose arithmetic does not change): the joints' rows 3 and 4 (nl_hinge_rows), the step's
 * elastic force (nl_force, the discrete gradient for K q_m), its Newton block (nl_block for
 * h^2/4 K) and the elastic LU of the iteration matrix made at each factorisation
 * (nl_iteration_elastic), the strain energy (nl_energy), and the elastic LU's pattern
 * (Model3D.nl_pattern: the elements' full blocks); in _kernel3d_base.h's step (a moving
 * base) the elastic force and the elastic LU; in _kernel3d_figures.h the stress figures'
 * components (nl_stress_components, at the end); with damping_beta, the structural damping
 * of the co-rotated strain rates (nl_damping_force in _kernel3d_damping.h's damping_forces,
 * nl_damping_block in iteration_blocks: its own section below).
 *
 * An element's z = (d_x, d_y, d_z, theta_a, theta_b, w'_a, w'_b, phi_a, phi_b) from its 12
 * coordinates (u, v, theta, w, slope, twist of node a, then b: NL_B, NL_A below), its strains
 * s = (eps, tb_a, tb_b, c_a, c_b, tau), U_e = 1/2 s.D s.
 */
#define NL_PI 3.14159265358979323846
/* z_k = x[NL_B[k]] - x[NL_A[k]] (NL_A -1: none) (corotational3d._Z_ROWS) */
static const int NL_B[9] = {6, 7, 9, 2, 8, 4, 10, 5, 11};
static const int NL_A[9] = {0, 1, 3, -1, -1, -1, -1, -1, -1};

static int elastic_lu_of(const Body *b, const double *M0, const double *K, double c, int R,
                         int n, double *out, Rows *lo, Rows *up);

static double nl_wrap(double a) { return a - 2.0 * NL_PI * floor((a + NL_PI) / (2.0 * NL_PI)); }

/* z - (l_e, 0, ...) of the element e of a rib from its coordinates qr (of velocities vr:
 * dz/dt) */
static void nl_chord_part(const Model3D *m, int e, const double *qr, double *z) {
    const int *p = m->nl_places + e * 12;
    double xe[12];
    for (int i = 0; i < 12; i++) xe[i] = p[i] < m->n_rib ? qr[p[i]] : 0.0;
    for (int k = 0; k < 9; k++) z[k] = xe[NL_B[k]] - (NL_A[k] >= 0 ? xe[NL_A[k]] : 0.0);
}

/* the element e of rib r (coordinates qr): z, its length */
static double nl_z(const Model3D *m, int r, int e, const double *qr, double *z) {
    double le = m->nl_length[r * m->nl_elements + e];
    nl_chord_part(m, e, qr, z);
    z[0] += le;
    return le;
}

/* g = sin psi = theta / sqrt(1 - w'^2) of end k */
static double nl_sine(const double *z, int k) { return z[3 + k] / sqrt(1.0 - z[5 + k] * z[5 + k]); }

/* s from z and the local in-plane rotations tb (the element's angles) */
static void nl_strains_from(const double *z, double le, const double *tb, double *s) {
    double len = sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2]);
    double c0 = z[5] - z[2] / len, c1 = z[6] - z[2] / len;
    double qt = 2.0 * tb[0] * tb[0] - tb[0] * tb[1] + 2.0 * tb[1] * tb[1];
    double qc = 2.0 * c0 * c0 - c0 * c1 + 2.0 * c1 * c1;
    s[0] = len / le - 1.0 + (qt + qc) / 30.0;
    s[1] = tb[0]; s[2] = tb[1]; s[3] = c0; s[4] = c1;
    s[5] = z[8] - z[7];
}

/* sigma = D s (D of rib r's element e: EA l, EI_z / l, EI_y / l, GJ / l) */
static void nl_stress(const Model3D *m, int r, int e, const double *s, double *sig) {
    const double *k = m->nl_stiffness + ((size_t)r * m->nl_elements + e) * 4;
    sig[0] = k[0] * s[0];
    sig[1] = k[1] * (4.0 * s[1] + 2.0 * s[2]); sig[2] = k[1] * (2.0 * s[1] + 4.0 * s[2]);
    sig[3] = k[2] * (4.0 * s[3] + 2.0 * s[4]); sig[4] = k[2] * (2.0 * s[3] + 4.0 * s[4]);
    sig[5] = k[3] * s[5];
}

/* the eps row's shallow-arch part: row 0 += dQ/dtb / 30 rows 1, 2 + dQ/dc / 30 rows 3, 4 */
static void nl_eps_row(double *J, const double *s) {
    double dt0 = (4.0 * s[1] - s[2]) / 30.0, dt1 = (-s[1] + 4.0 * s[2]) / 30.0;
    double dc0 = (4.0 * s[3] - s[4]) / 30.0, dc1 = (-s[3] + 4.0 * s[4]) / 30.0;
    for (int i = 0; i < 9; i++)
        J[i] += dt0 * J[9 + i] + dt1 * J[18 + i] + dc0 * J[27 + i] + dc1 * J[36 + i];
}

/* psi's derivatives at end k: d/dtheta, d/dw', and if second the second ones (tt, tw, ww) */
static void nl_section(const double *z, int k, double *d, int second) {
    double th = z[3 + k], w = z[5 + k];
    double s = 1.0 / sqrt(1.0 - w * w), g = th * s, pg = 1.0 / sqrt(1.0 - g * g);
    double gw = th * w * s * s * s;
    d[0] = pg * s; d[1] = pg * gw;
    if (!second) return;
    double pgg = g * pg * pg * pg;
    d[2] = pgg * s * s; d[3] = pgg * s * gw + pg * w * s * s * s;
    d[4] = pgg * gw * gw + pg * th * (s * s * s + 3.0 * w * w * s * s * s * s * s);
}

/* ds/dz (6 x 9) at z with strains s, and with H the second derivatives (6 x 9 x 9) */
static void nl_jacobian(const double *z, double le, const double *s, double *J, double *H) {
    double len = sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2]), l3 = len * len * len;
    double r2 = z[0] * z[0] + z[1] * z[1];
    double gb[2] = {-z[1] / r2, z[0] / r2};
    double gs[3] = {-z[2] * z[0] / l3, -z[2] * z[1] / l3, 1.0 / len - z[2] * z[2] / l3};
    double sec[2][5];
    for (int k = 0; k < 2; k++) nl_section(z, k, sec[k], H != NULL);
    memset(J, 0, sizeof(double) * 54);
    for (int k = 0; k < 2; k++) {
        double *t = J + 9 * (1 + k), *c = J + 9 * (3 + k);
        t[0] = -gb[0]; t[1] = -gb[1]; t[3 + k] = sec[k][0]; t[5 + k] = sec[k][1];
        c[0] = -gs[0]; c[1] = -gs[1]; c[2] = -gs[2]; c[5 + k] = 1.0;
    }
    J[45 + 7] = -1.0; J[45 + 8] = 1.0;
    for (int i = 0; i < 3; i++) J[i] = z[i] / (len * le);
    nl_eps_row(J, s);
    if (!H) return;
    memset(H, 0, sizeof(double) * 486);
    double x = z[0], y = z[1], r4 = r2 * r2;
    double hb[2][2] = {{2 * x * y / r4, (y * y - x * x) / r4}, {(y * y - x * x) / r4, -2 * x * y / r4}};
    double l5 = l3 * len * len, hs[3][3];
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            hs[a][b] = -((a == 2) * z[b] + (b == 2) * z[a] + (a == b) * z[2]) / l3
                + 3.0 * z[2] * z[a] * z[b] / l5;
    for (int k = 0; k < 2; k++) {
        double *t = H + 81 * (1 + k), *c = H + 81 * (3 + k);
        for (int a = 0; a < 2; a++)
            for (int b = 0; b < 2; b++) t[a * 9 + b] = -hb[a][b];
        t[(3 + k) * 9 + 3 + k] = sec[k][2];
        t[(3 + k) * 9 + 5 + k] = t[(5 + k) * 9 + 3 + k] = sec[k][3];
        t[(5 + k) * 9 + 5 + k] = sec[k][4];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) c[a * 9 + b] = -hs[a][b];
    }
    double dt0 = (4.0 * s[1] - s[2]) / 30.0, dt1 = (-s[1] + 4.0 * s[2]) / 30.0;
    double dc0 = (4.0 * s[3] - s[4]) / 30.0, dc1 = (-s[3] + 4.0 * s[4]) / 30.0;
    for (int i = 0; i < 9; i++)
        for (int j = 0; j < 9; j++) {
            const double *t0 = J + 9, *t1 = J + 18, *c0 = J + 27, *c1 = J + 36;
            double v = (4.0 * t0[i] * t0[j] - t0[i] * t1[j] - t1[i] * t0[j] + 4.0 * t1[i] * t1[j]
                        + 4.0 * c0[i] * c0[j] - c0[i] * c1[j] - c1[i] * c0[j]
                        + 4.0 * c1[i] * c1[j]) / 30.0;
            H[i * 9 + j] = v + dt0 * H[81 + i * 9 + j] + dt1 * H[162 + i * 9 + j]
                + dc0 * H[243 + i * 9 + j] + dc1 * H[324 + i * 9 + j];
        }
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++)
            H[a * 9 + b] += ((a == b) - z[a] * z[b] / (len * len)) / (len * le);
}

/* Gonzalez's discrete gradient of f (dimension k): g + (df - g.dd) dd / |dd|^2 */
static void nl_gonzalez(int k, double *g, const double *dd, double df) {
    double d2 = 0.0, gd = 0.0;
    for (int i = 0; i < k; i++) { d2 += dd[i] * dd[i]; gd += g[i] * dd[i]; }
    if (d2 > 0.0)
        for (int i = 0; i < k; i++) g[i] += (df - gd) / d2 * dd[i];
}

/* ------------------------------------------------------------------ kept strains
 * An element's strains at a configuration and what a step from there reads of them: z, s
 * (beta = atan2(d_y, d_x), tb = wrap(asin(sin psi) - beta), nl_strains_from), sin psi at
 * both ends and its cosine, |d|.  Computed once a configuration and
 * kept for the two latest of each rib (a step's start and end: the Newton iterations'
 * forces and blocks, the strain energy at both ends, the stress figures and the next step
 * read them), the same arithmetic as computed where read. */
typedef struct {
    double z[9], s[6], g[2], cg[2], len, le;
} NlStart;

struct NlStarts {
    double *key;                       /* R x 2 x n: the configuration a slot holds */
    int *have;                         /* R x 2: the slot holds one */
    int *latest;                       /* R: the slot last filled or read */
    NlStart *el;                       /* R x 2 x nl_elements */
};

static void nl_starts_free(NlStarts *c) {
    if (!c) return;
    free(c->key); free(c->have); free(c->latest); free(c->el);
    free(c);
}

static NlStarts *nl_starts_new(const Ctx3D *x) {
    NlStarts *c = calloc(1, sizeof(NlStarts));
    if (!c) return NULL;
    int R = x->R, n = x->n, E = x->m->nl_elements;
    c->key = calloc((size_t)R * 2 * n, sizeof(double));
    c->have = calloc((size_t)R * 2, sizeof(int));
    c->latest = calloc((size_t)R, sizeof(int));
    c->el = calloc((size_t)R * 2 * E, sizeof(NlStart));
    if (!c->key || !c->have || !c->latest || !c->el) { nl_starts_free(c); return NULL; }
    return c;
}

/* the elements of rib r at its coordinates qr, kept or computed into the slot not read last */
static const NlStart *nl_starts(Ctx3D *x, int r, const double *qr) {
    const Model3D *m = x->m;
    NlStarts *c = x->nl;
    int n = x->n, E = m->nl_elements;
    for (int k = 0; k < 2; k++) {
        int slot = 2 * r + k;
        if (c->have[slot] && !memcmp(c->key + (size_t)slot * n, qr, sizeof(double) * n)) {
            c->latest[r] = k;
            return c->el + (size_t)slot * E;
        }
    }
    int k = 1 - c->latest[r], slot = 2 * r + k;
    NlStart *out = c->el + (size_t)slot * E;
    for (int e = 0; e < E; e++) {
        NlStart *st = out + e;
        double *z = st->z, tb[2];
        st->le = nl_z(m, r, e, qr, z);
        double beta = atan2(z[1], z[0]);
        for (int j = 0; j < 2; j++) {
            st->g[j] = nl_sine(z, j);
            tb[j] = nl_wrap(asin(st->g[j]) - beta);
            st->cg[j] = sqrt(1.0 - st->g[j] * st->g[j]);
        }
        nl_strains_from(z, st->le, tb, st->s);
        st->len = sqrt(z[0] * z[0] + z[1] * z[1] + z[2] * z[2]);
    }
    memcpy(c->key + (size_t)slot * n, qr, sizeof(double) * n);
    c->have[slot] = 1;
    c->latest[r] = k;
    return out;
}

/* s1 of a step from the kept start st to z1 (from s0 and the accurate increments) */
static void nl_step_strains(const NlStart *st, const double *z1, double *s1, double *dbeta,
                            double *dpsi) {
    const double *z0 = st->z;
    *dbeta = atan2(z0[0] * z1[1] - z0[1] * z1[0], z0[0] * z1[0] + z0[1] * z1[1]);
    double tb[2];
    for (int k = 0; k < 2; k++) {
        double g1 = nl_sine(z1, k);
        dpsi[k] = asin(g1 * st->cg[k] - st->g[k] * sqrt(1.0 - g1 * g1));
        tb[k] = st->s[1 + k] + dpsi[k] - *dbeta;
    }
    nl_strains_from(z1, st->le, tb, s1);
}

/* add T^T g (g: 9, d/dz) to an element's 12 coordinates' places in out (n: skipped) */
static void nl_scatter(const Model3D *m, int e, const double *g, double *out) {
    const int *p = m->nl_places + e * 12;
    double xe[12] = {0};
    for (int k = 0; k < 9; k++) {
        xe[NL_B[k]] += g[k];
        if (NL_A[k] >= 0) xe[NL_A[k]] -= g[k];
    }
    for (int i = 0; i < 12; i++) if (p[i] < m->n_rib) out[p[i]] += xe[i];
}

/* rib r's discrete gradient of U over the step q0 -> q1 into out (n): dq . G = dU */
static void nl_force(Ctx3D *x, int r, const double *q0, const double *q1, double *out) {
    const Model3D *m = x->m;
    memset(out, 0, sizeof(double) * x->n);
    const NlStart *start = nl_starts(x, r, q0);
    for (int e = 0; e < m->nl_elements; e++) {
        const NlStart *st = start + e;
        const double *z0 = st->z, *s0 = st->s;
        double z1[9], s1[6], dbeta, dpsi[2], B[54], sig[6], sm[6], g[9];
        double le = nl_z(m, r, e, q1, z1);
        nl_step_strains(st, z1, s1, &dbeta, dpsi);
        memset(B, 0, sizeof(B));
        double l0 = st->len;
        double l1 = sqrt(z1[0] * z1[0] + z1[1] * z1[1] + z1[2] * z1[2]);
        double dm[3], dd[3];
        for (int i = 0; i < 3; i++) { dm[i] = 0.5 * (z0[i] + z1[i]); dd[i] = z1[i] - z0[i]; }
        double r2 = dm[0] * dm[0] + dm[1] * dm[1];
        double gb[2] = {-dm[1] / r2, dm[0] / r2};
        nl_gonzalez(2, gb, dd, dbeta);
        double lm = sqrt(dm[0] * dm[0] + dm[1] * dm[1] + dm[2] * dm[2]), lm3 = lm * lm * lm;
        double gs[3] = {-dm[2] * dm[0] / lm3, -dm[2] * dm[1] / lm3, 1.0 / lm - dm[2] * dm[2] / lm3};
        nl_gonzalez(3, gs, dd, z1[2] / l1 - z0[2] / l0);
        double zm[9];
        for (int i = 0; i < 9; i++) zm[i] = 0.5 * (z0[i] + z1[i]);
        for (int k = 0; k < 2; k++) {
            double sec[5];
            nl_section(zm, k, sec, 0);
            double gp[2] = {sec[0], sec[1]}, dp[2] = {z1[3 + k] - z0[3 + k], z1[5 + k] - z0[5 + k]};
            nl_gonzalez(2, gp, dp, dpsi[k]);
            double *t = B + 9 * (1 + k), *c = B + 9 * (3 + k);
            t[0] = -gb[0]; t[1] = -gb[1]; t[3 + k] = gp[0]; t[5 + k] = gp[1];
            c[0] = -gs[0]; c[1] = -gs[1]; c[2] = -gs[2]; c[5 + k] = 1.0;
        }
        B[45 + 7] = -1.0; B[45 + 8] = 1.0;
        for (int i = 0; i < 3; i++) B[i] = (z0[i] + z1[i]) / ((l0 + l1) * le);
        for (int i = 0; i < 6; i++) sm[i] = 0.5 * (s0[i] + s1[i]);
        nl_eps_row(B, sm);
        nl_stress(m, r, e, sm, sig);
        for (int i = 0; i < 9; i++) {
            g[i] = 0.0;
            for (int k = 0; k < 6; k++) g[i] += B[k * 9 + i] * sig[k];
        }
        nl_scatter(m, e, g, out);
    }
}

/* add c T^T Z T (Z: 9 x 9 in the element e's z) into G (n x n, row-major) at its places */
static void nl_add_block(const Model3D *m, int e, const double *Z, double c, int n, double *G) {
    double A[144];
    memset(A, 0, sizeof(A));              /* T^T Z T: the element's 12 x 12 block */
    for (int a = 0; a < 9; a++)
        for (int b = 0; b < 9; b++) {
            double v = Z[a * 9 + b];
            if (v == 0.0) continue;
            int ia[2] = {NL_B[a], NL_A[a]}, ib[2] = {NL_B[b], NL_A[b]};
            for (int u = 0; u < 2; u++)
                for (int w = 0; w < 2; w++)
                    if (ia[u] >= 0 && ib[w] >= 0)
                        A[ia[u] * 12 + ib[w]] += (u ? -v : v) * (w ? -1.0 : 1.0);
        }
    const int *p = m->nl_places + e * 12;
    for (int i = 0; i < 12; i++) {
        if (p[i] >= n) continue;
        for (int j = 0; j < 12; j++)
            if (p[j] < n) G[p[i] * n + p[j]] += c * A[i * 12 + j];
    }
}

/* add c times the Newton matrix's dG/dq1 of rib r (1/2 [B^T D B + sum sigma_k H_k] at the
 * midpoint, sigma = D (s0 + s1) / 2) into G (n x n, row-major) */
static void nl_block(Ctx3D *x, int r, const double *q0, const double *q1, double c,
                     double *G) {
    const Model3D *m = x->m;
    int n = x->n;
    const NlStart *start = nl_starts(x, r, q0);
    for (int e = 0; e < m->nl_elements; e++) {
        const NlStart *st = start + e;
        const double *z0 = st->z, *s0 = st->s;
        double z1[9], zm[9], s1[6], sm[6], dbeta, dpsi[2], J[54], H[486];
        double sig[6], DJ[54], Z[81];
        double le = nl_z(m, r, e, q1, z1);
        nl_step_strains(st, z1, s1, &dbeta, dpsi);
        for (int i = 0; i < 9; i++) zm[i] = 0.5 * (z0[i] + z1[i]);
        for (int i = 0; i < 6; i++) sm[i] = 0.5 * (s0[i] + s1[i]);
        nl_jacobian(zm, le, sm, J, H);
        nl_stress(m, r, e, sm, sig);
        for (int i = 0; i < 9; i++) {       /* D J, column by column */
            double col[6], out[6];
            for (int k = 0; k < 6; k++) col[k] = J[k * 9 + i];
            nl_stress(m, r, e, col, out);
            for (int k = 0; k < 6; k++) DJ[k * 9 + i] = out[k];
        }
        for (int i = 0; i < 9; i++)
            for (int j = 0; j < 9; j++) {
                double v = 0.0;
                for (int k = 0; k < 6; k++) v += J[k * 9 + i] * DJ[k * 9 + j] + sig[k] * H[k * 81 + i * 9 + j];
                Z[i * 9 + j] = 0.5 * v;
            }
        nl_add_block(m, e, Z, c, n, G);
    }
}

/* ------------------------------------------------------------------ structural damping
 * The Kelvin-Voigt damping of the co-rotated strain rates (umbrella3d/damping3d.py;
 * corotational3d.RibCorotationalStrain.material_tangent, the numpy reference): C(q_m) =
 * beta B^T D B, B = ds/dq exact (nl_jacobian) at the step's midpoint q_m, its strains
 * computed there afresh (nl_starts' arithmetic; not kept: q_m is no step's end).  Hooks,
 * under nl_elements: _kernel3d_damping.h's damping_forces (the force C dq / h, and so the
 * step's dissipation) and iteration_blocks (h/2 C(q_m) at the iterate factored at). */

/* ds/dz J (6 x 9) of rib r's element e at coordinates qr, and z, s there; returns l_e */
static double nl_damping_jacobian(const Model3D *m, int r, int e, const double *qr,
                                  double *z, double *s, double *J) {
    double le = nl_z(m, r, e, qr, z), tb[2];
    double beta = atan2(z[1], z[0]);
    for (int j = 0; j < 2; j++) tb[j] = nl_wrap(asin(nl_sine(z, j)) - beta);
    nl_strains_from(z, le, tb, s);
    nl_jacobian(z, le, s, J, NULL);
    return le;
}

/* y (n) = c B^T D B dq of rib r, B at its midpoint q0 + dq / 2 (c: beta / h) */
static void nl_damping_force(const Model3D *m, int r, int n, const double *q0,
                             const double *dq, double c, double *y) {
    double qm[n];
    for (int a = 0; a < n; a++) qm[a] = q0[a] + 0.5 * dq[a];
    memset(y, 0, sizeof(double) * n);
    for (int e = 0; e < m->nl_elements; e++) {
        double z[9], s[6], J[54], dz[9], ds[6], sig[6], g[9];
        nl_damping_jacobian(m, r, e, qm, z, s, J);
        nl_chord_part(m, e, dq, dz);
        for (int k = 0; k < 6; k++) {
            double d = 0.0;
            for (int i = 0; i < 9; i++) d += J[k * 9 + i] * dz[i];
            ds[k] = d;
        }
        nl_stress(m, r, e, ds, sig);
        for (int i = 0; i < 9; i++) {
            double d = 0.0;
            for (int k = 0; k < 6; k++) d += J[k * 9 + i] * sig[k];
            g[i] = d;
        }
        nl_scatter(m, e, g, y);
    }
    for (int a = 0; a < n; a++) y[a] *= c;
}

/* add c B^T D B of rib r at its midpoint qm into G (n x n; c: h beta / 2) */
static void nl_damping_block(const Model3D *m, int r, int n, const double *qm, double c,
                             double *G) {
    for (int e = 0; e < m->nl_elements; e++) {
        double z[9], s[6], J[54], DJ[54], Z[81];
        nl_damping_jacobian(m, r, e, qm, z, s, J);
        for (int i = 0; i < 9; i++) {       /* D J, column by column */
            double col[6], out[6];
            for (int k = 0; k < 6; k++) col[k] = J[k * 9 + i];
            nl_stress(m, r, e, col, out);
            for (int k = 0; k < 6; k++) DJ[k * 9 + i] = out[k];
        }
        for (int i = 0; i < 9; i++)
            for (int j = 0; j < 9; j++) {
                double v = 0.0;
                for (int k = 0; k < 6; k++) v += J[k * 9 + i] * DJ[k * 9 + j];
                Z[i * 9 + j] = v;
            }
        nl_add_block(m, e, Z, c, n, G);
    }
}

/* the strain energy of every rib at q */
static double nl_energy(Ctx3D *x, const double *q) {
    const Model3D *m = x->m;
    double u = 0.0;
    for (int r = 0; r < x->R; r++) {
        const NlStart *start = nl_starts(x, r, q + (size_t)r * x->n);
        for (int e = 0; e < m->nl_elements; e++) {
            const double *s = start[e].s;
            double sig[6];
            nl_stress(m, r, e, s, sig);
            for (int k = 0; k < 6; k++) u += 0.5 * s[k] * sig[k];
        }
    }
    return u;
}

/* Body.elu_it from the iteration matrix's elastic block M0 + x->gyro (which holds h^2/2 dG/dq1
 * there: nl_block; the gyroscopic term leaves that block alone), at every factorisation */
static int nl_iteration_elastic(Ctx3D *x) {
    for (int j = 0; j < 2; j++) {
        Body *b = &x->b[j];
        b->elu_h = NAN;
        if (!elastic_lu_of(b, x->m->const_mass, x->gyro, 1.0, x->R, x->n, b->elu_it, NULL, NULL))
            return SINGULAR;
    }
    return OK;
}

/* the O'' hinge's rows 3 and 4 of rib coordinates qr with each section turned by its angle
 * asin(theta) (CorotationalUmbrellaModel3D): into f (values) or j (Jacobian rows, n) */
static void nl_hinge_rows(const Model3D *m, const double *qr, double *f, double *j, int n) {
    double t1 = qr[m->nl_i_t1], t2 = qr[m->nl_i_t2];
    double a1 = qr[m->i_a1] + asin(t1), a2 = qr[m->i_a2] + asin(t2);
    double g1 = 1.0 / sqrt(1.0 - t1 * t1), g2 = 1.0 / sqrt(1.0 - t2 * t2);
    double c1 = cos(a1), s1 = sin(a1), c2 = cos(a2), s2 = sin(a2);
    double sl1 = qr[m->i_s1], tw1 = qr[m->i_p1], sl2 = qr[m->i_s2], tw2 = qr[m->i_p2];
    if (f) {
        f[3] = c1 * sl1 - s1 * tw1 - c2 * sl2 + s2 * tw2;
        f[4] = s1 * sl1 + c1 * tw1 - s2 * sl2 - c2 * tw2;
    }
    if (j) {
        double d31 = -s1 * sl1 - c1 * tw1, d41 = c1 * sl1 - s1 * tw1;
        double d32 = s2 * sl2 + c2 * tw2, d42 = -c2 * sl2 + s2 * tw2;
        double *j3 = j + 3 * n, *j4 = j + 4 * n;
        j3[m->i_a1] = d31; j4[m->i_a1] = d41;
        j3[m->nl_i_t1] = d31 * g1; j4[m->nl_i_t1] = d41 * g1;
        j3[m->i_s1] = c1; j4[m->i_s1] = s1;
        j3[m->i_p1] = -s1; j4[m->i_p1] = c1;
        j3[m->i_a2] = d32; j4[m->i_a2] = d42;
        j3[m->nl_i_t2] = d32 * g2; j4[m->nl_i_t2] = d42 * g2;
        j3[m->i_s2] = -c2; j4[m->i_s2] = -s2;
        j3[m->i_p2] = s2; j4[m->i_p2] = -c2;
    }
}

/* ------------------------------------------------------------------ the stress figures
 * Rib r's four stress components at both ends of every element (points 2e, 2e + 1: the
 * leaf's elements, then the link's) and their rates, for _kernel3d_figures.h's channels
 * (figure_channels: von Mises, crests and the largest are its rule, the linear beams'):
 * corotational3d.RibCorotationalStrain.stress_blocks, the numpy reference, in the
 * element's co-rotated frame from its strains s (nl_starts) and their rates ds/dz dz/dt:
 * axial E eps, bending E c kappa of tb and of c (kappa = (-4 t_a - 2 t_b) / l_e at end a,
 * (2 t_a + 4 t_b) / l_e at end b), torsion shear G c_t tau / l_e.  moduli: rib r's E, E c,
 * G c_t; sv, sr: component k of point p at k P + p. */
static void nl_components(const double *moduli, double le, const double *s, double *out,
                          int P) {
    double axial = moduli[0] * s[0], shear = moduli[2] * s[5] / le;
    out[0] = out[1] = axial;
    out[P] = moduli[1] * ((-4.0 * s[1] - 2.0 * s[2]) / le);
    out[P + 1] = moduli[1] * ((2.0 * s[1] + 4.0 * s[2]) / le);
    out[2 * P] = moduli[1] * ((-4.0 * s[3] - 2.0 * s[4]) / le);
    out[2 * P + 1] = moduli[1] * ((2.0 * s[3] + 4.0 * s[4]) / le);
    out[3 * P] = out[3 * P + 1] = shear;
}

static void nl_stress_components(Ctx3D *x, int r, const double *qr, const double *vr,
                                 const double *moduli, int P, double *sv, double *sr) {
    const Model3D *m = x->m;
    const NlStart *start = nl_starts(x, r, qr);
    for (int e = 0; e < m->nl_elements; e++) {
        const double *z = start[e].z, *s = start[e].s;
        double le = start[e].le, dz[9], ds[6], J[54];
        nl_jacobian(z, le, s, J, NULL);
        nl_chord_part(m, e, vr, dz);
        for (int k = 0; k < 6; k++) {
            double d = 0.0;
            for (int i = 0; i < 9; i++) d += J[k * 9 + i] * dz[i];
            ds[k] = d;
        }
        nl_components(moduli, le, s, sv + 2 * e, P);
        nl_components(moduli, le, ds, sr + 2 * e, P);
    }
}
