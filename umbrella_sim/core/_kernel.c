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
 * Compiled stepping of the energy-consistent midpoint integrator (see integrators.py).
 *
 * The same arithmetic as MidpointDAE._step in numpy (the reference path the tests compare
 * against): discrete-gradient residual, Newton iterations on a once-factored iteration
 * matrix, velocity projection in the mass metric with the kinetic energy kept, and the
 * per-step outputs the node publishes (tip deflection, fibre stress peaks and where,
 * sleeve position and velocity, energies, work), and a Sample's figures of the state a call
 * reaches (sample_vector: reference stresses, sleeve reaction, residual, every fibre stress).
 * Plain C on double arrays, loaded with ctypes: no Python or numpy headers.
 *
 * Structure used so that the cost grows linearly with the mesh:
 *   - the constant matrices (elastic mass Mff, stiffness K, rotation-deformation coupling W)
 *     live only on the elastic coordinates, node by node, so they are banded (half
 *     bandwidth <= 5: an element couples two nodes) and are stored in band form;
 *   - M(q) and the iteration matrix are that band plus an "arrow": the rows and columns of
 *     the border coordinates (alpha1, R2x, R2y, alpha2) and of the multipliers.  Linear
 *     systems are solved by a band LU of the elastic block (its symmetric part is positive
 *     definite: M + h^2/4 K, plus a skew gyroscopic part, so no pivoting is needed) and a
 *     pivoted dense LU of the small Schur complement on the border;
 *   - M(q) is never formed: products M(q) v use the band and a few border vectors;
 *   - stage 2's mode fit (integrators.LockedModeFit: the phase_correction parameter) maps
 *     the scheme's velocity w to the physical v = S w, S = I + Phi diag(s - 1) U^T, a rank-r
 *     change (r modes: those with omega h <= 1.5) applied by modal sums, five r x n passes a
 *     Newton iteration (the Mff and W products of S w by the band, not by modal rows); its
 *     share of the tangent, left out of the constant iteration matrix, is put back into each Newton
 *     update mode by mode (mode_fit_update: LockedModeFit.newton_update).
 * The rigid-FE mode (every elastic coordinate constrained) goes through the same code with
 * a border as large as the mesh, so there it costs what a dense solve costs.
 *
 * A context (umbrella_new) holds the model and every work buffer, allocated once.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "_kernel.h"          /* the interface: structs, codes, fields, API */
#include "_kernel_elastic.h"   /* the nonlinear / damped elastic law (_kernel_nonlinear.c) */
#include "_kernel_dense.h"     /* the dense LU it shares with the 3D step (_kernel3d.c) */
#include "_kernel_crest.h"     /* a step's stress crest, the 3D figures' rule too */

#define JW 3   /* nonzeros of a joint/stop constraint row */

typedef struct {
    int ne, bw, nb;
    const double *C;          /* 4 x ne */
    int lo[4], hi[4];
    const int *cpos;          /* nc x JW elastic positions or -1 */
    const double *cval;       /* nc x JW */
} Arrow;

/* A constant elastic band F factored once (the elastic mass Mff, or Mff + h^2/4 K of the
 * step h), with F^-1 of every constant piece of the arrow's border columns, so that the
 * border solve Y = F^-1 B of a step is two band solves and sums instead of one band solve
 * per border column (arrow_border_from_solved). */
typedef struct {
    double h;              /* the step F is factored for; 0 for Mff, -1 not prepared */
    double *lu;            /* ne x (2 bw + 1) band LU of F */
    double *sb[2], *isb[2];  /* F^-1 of the link's sbar rows and their perpendiculars */
    double *ej, *es;       /* F^-1 e_p at the joint's and the sleeve's axial coordinate */
    int pj, ps;            /* their elastic positions */
} SolvedBand;

/* A factored arrow system with its own storage: the iteration matrix of the Newton steps
 * (two slots) and the mass matrix of the velocity projection each keep one, so that neither
 * the projection nor a step that is not kept overwrites the matrix a step carries over to
 * the next (Ctx: slot, it, it_kept, it_slot). */
typedef struct {
    Arrow a;
    const double *E;       /* the band LU of its elastic block */
    double *E_store;       /* storage for it when it is not constant (ne x (2 bw + 1));
                            * NULL for the projection's, whose E is the constant Emass */
    double *B, *C, *S;     /* Y = E^-1 B (ne x nbmax), 4 dense rows C, LU of the Schur complement */
    double *cval;          /* its constraint rows' values (a copy: jrow_val moves on) */
    int *piv, *cpos;
    /* the last step that used it: its end state (q, v), constraint count and length, and
     * how many steps it served whole since the step that factored it (the iteration slots
     * only) */
    double *q_end, *v_end, h;
    int nc, age;
} ArrowLU;

#define TRIG_CACHE 4

struct Ctx {
    const Model *m;
    int ne, nbmax, width;
    /* state-dependent pieces of M(q) */
    double *hq, *maf;      /* n */
    double maa[2], mra[2];
    double *mrf;           /* 2 x n_link */
    /* vectors */
    double *q1, *v1, *dq, *qm, *hm, *mffv, *wv0, *gt, *gy, *res, *kq, *mv, *wa, *wb, *vt, *rhs, *xa;
    /* band products (elastic entries of q-indexed vectors): of q0 and v0 at the start of a
     * step, of dq in each Newton iteration, of the converged q1; Mff, W, K are constant, so
     * a step needs one product of each per iteration (the rest by linearity) */
    double *mq0, *wq0, *kq0, *mv0, *mdq, *wdq, *kdq, *mq1, *wq1, *kq1;
    int q0_products;       /* mq0, wq0, kq0 hold the products of the q0 of the next step */
    double *phi0, *phi, *corr, *jrow_val, *jm_val;   /* constraint rows */
    int *jrow_idx, *jm_idx;
    double *E;             /* storage of the slots' bands and of Emass */
    double *Emass;         /* LU of the constant elastic mass band (projection) */
    ArrowLU slot[2], pm;   /* the iteration matrix's slots; the projection's mass matrix */
    ArrowLU *it;           /* the slot the step solves with */
    /* slot[it_slot] (if it_kept) as the last step left it, for the first Newton iteration of
     * a step that starts where that one ended, with the same constraint count and step
     * length (the nonlinear law, see step()); a step factors into the other slot */
    int it_kept, it_slot;
    /* what the last step hands on if it is taken (carry_commit): its slot (-1: nothing) and
     * that matrix's age after it */
    int carry_slot, carry_age;
    int *piv;              /* storage of it.piv, pm.piv */
    SolvedBand fmass, fiter;   /* Mff; Mff + h^2/4 K (or the damped linear law's band) */
    double *sv, *sdq;      /* work: a body-wise border column, F^-1 dq (ne each) */
    double cos2, sin2;     /* cos, sin of alpha2 of the last mass_data_from_products */
    double *solved_buf;    /* storage of fiter, fmass's solves, sv, sdq */
    double *q_s, *v_s, *p_s, *lam_s;  /* single-step results */
    ElasticLaw *law;       /* NULL: U = 1/2 q.K q, undamped; else U, C of the law */
    double dissipated;     /* damping dissipation of the last step (J) */
    /* stage 2's mode fit (integrators.LockedModeFit, the phase_correction parameter): the
     * step runs in w, v = S w = w + sum_i (s_i - 1) phi_i (u_i . w), with momentum
     * S^T M(q) S w; pc_r modes, rows u_i = M0 phi_i of pc_u and phi_i of pc_phi (pc_r x n),
     * scales s_i in pc_sc, the scheme's modal damping less the law's in pc_dc (NULL:
     * undamped), and each mode's Newton shrink d_i / (block_i + d_i) in pc_shrink (the
     * caller's arrays: LockedModeFit.newton_shrink);
     * pc_r = 0: none.  With the linear elastic law too (pc_acts). */
    int pc_r;
    const double *pc_u, *pc_phi, *pc_sc, *pc_dc, *pc_shrink;
    double *pc_s;          /* the modal sums (r <= n) */
    /* within a step: u_i . w0 and u_i . (q - q0) (kept up to date through the Newton
     * updates); w0 = S^-1 v0, S^T p0, Mff w0, W w0 */
    double *pc_eta_w0, *pc_eta_dq, *pc_w0, *pc_sp0, *pc_mw0, *pc_ww0;
    /* cos and sin of the last few angles (cos_sin): a Newton iteration needs alpha1 and
     * alpha2 of q1 and of the midpoint in several functions */
    double trig_a[TRIG_CACHE], trig_c[TRIG_CACHE], trig_s[TRIG_CACHE];
    int trig_n, trig_next;
    /* fibre stress (top of every stress point, then bottom) and its rate at the start of the
     * step advance() takes next (pk_sig, pk_rate) and at its end (pk_sig1, pk_rate1):
     * the step's peak is that of their cubic Hermite interpolant (output_row) */
    double *pk_sig, *pk_rate, *pk_sig1, *pk_rate1;
};

#define ENERGY_RESTORE_LIMIT 1.01   /* integrators.ENERGY_RESTORE_LIMIT */

/* Whether stage 2's mode fit acts on a step: it is set at the lock, and never with the
 * rigid-FE constraints or the nonlinear strain (engines' phase_correctable) */
static int pc_acts(const Ctx *x, int locked, int rigid) {
    return locked && !rigid && x->pc_r > 0 && !(x->law && x->law->d.nonlinear);
}

/* cos(a) and sin(a), bitwise, from the context's cache of the last TRIG_CACHE angles */
static inline void cos_sin(Ctx *x, double a, double *c, double *s) {
    for (int k = 0; k < x->trig_n; k++)
        if (memcmp(&x->trig_a[k], &a, sizeof a) == 0) {
            *c = x->trig_c[k];
            *s = x->trig_s[k];
            return;
        }
    int k = x->trig_next;
    x->trig_next = (k + 1) % TRIG_CACHE;
    if (x->trig_n < TRIG_CACHE) x->trig_n++;
    x->trig_a[k] = a;
    *c = x->trig_c[k] = cos(a);
    *s = x->trig_s[k] = sin(a);
}

static int nc_of(const Model *m, int locked, int rigid) {
    return 3 + (locked ? 1 : 0) + (rigid ? m->n_elastic : 0);
}

/* ------------------------------------------------------------------ band algebra */
/* y1 = band1 x, y2 = band2 x, y3 = band3 x in one pass (band3/y3 may be NULL, and then
 * band2/y2 too) at the elastic coordinates of q-indexed vectors; other entries of y untouched.
 * The elastic coordinates are two contiguous runs of q (leaf, link), not coupled by the band.
 * Rows away from a run's ends in full-width loops, unrolled for a constant bw (band_matvec3). */
static inline __attribute__((always_inline)) void band_matvec3_bw(
        const Model *m, const int bw, const double *band1, double *y1, const double *band2,
        double *y2, const double *band3, double *y3, const double *x) {
    int ne = m->n_elastic, nl = m->n_link, w = 2 * bw + 1;
    for (int seg = 0; seg < 2; seg++) {
        int p0 = seg == 0 ? 0 : ne - nl, np = seg == 0 ? ne - nl : nl;
        int off = seg == 0 ? 1 : m->s_link;
        const double *xs = x + off;
        for (int i = 0; i < np; i++) {
            size_t r = (size_t)(p0 + i) * w;
            double s1 = 0.0, s2 = 0.0, s3 = 0.0;
            if (i >= bw && i + bw < np) {
                const double *xi = xs + i - bw, *r1 = band1 + r;
                if (band3) {
                    const double *r2 = band2 + r, *r3 = band3 + r;
                    for (int k = 0; k < w; k++) {
                        s1 += r1[k] * xi[k];
                        s2 += r2[k] * xi[k];
                        s3 += r3[k] * xi[k];
                    }
                } else if (band2) {
                    const double *r2 = band2 + r;
                    for (int k = 0; k < w; k++) { s1 += r1[k] * xi[k]; s2 += r2[k] * xi[k]; }
                } else {
                    for (int k = 0; k < w; k++) s1 += r1[k] * xi[k];
                }
            } else {
                int lo = i - bw < 0 ? 0 : i - bw, hi = i + bw >= np ? np - 1 : i + bw;
                const double *r1 = band1 + r + bw - i;
                const double *r2 = band2 ? band2 + r + bw - i : NULL;
                const double *r3 = band3 ? band3 + r + bw - i : NULL;
                for (int j = lo; j <= hi; j++) {
                    s1 += r1[j] * xs[j];
                    if (r2) s2 += r2[j] * xs[j];
                    if (r3) s3 += r3[j] * xs[j];
                }
            }
            if (band3) y3[off + i] = s3;
            if (band2) y2[off + i] = s2;
            y1[off + i] = s1;
        }
    }
}

static void band_matvec3(const Model *m, const double *band1, double *y1, const double *band2,
                         double *y2, const double *band3, double *y3, const double *x) {
    if (m->bw == 5) band_matvec3_bw(m, 5, band1, y1, band2, y2, band3, y3, x);  /* N >= 2 */
    else band_matvec3_bw(m, m->bw, band1, y1, band2, y2, band3, y3, x);
}

static void band_matvec2(const Model *m, const double *band1, double *y1, const double *band2,
                         double *y2, const double *x) {
    band_matvec3(m, band1, y1, band2, y2, NULL, NULL, x);
}

static void band_matvec(const Model *m, const double *band, const double *x, double *y, int acc) {
    (void)acc;
    band_matvec2(m, band, y, NULL, NULL, x);
}

/* LU without pivoting of a band matrix (n x (2 bw + 1)) in place; the diagonal keeps the
 * reciprocals of the pivots (the solves multiply) */
static int band_factor(int n, int bw, double *A) {
    int w = 2 * bw + 1;
    for (int k = 0; k < n; k++) {
        double piv = A[(size_t)k * w + bw];
        if (!(fabs(piv) > 0.0) || !isfinite(piv)) return SINGULAR;
        double inv = 1.0 / piv;
        int hi = k + bw >= n ? n - 1 : k + bw;
        for (int i = k + 1; i <= hi; i++) {
            double *ri = A + (size_t)i * w;
            double f = ri[k - i + bw] * inv;
            ri[k - i + bw] = f;
            if (f == 0.0) continue;
            const double *rk = A + (size_t)k * w;
            for (int j = k + 1; j <= hi; j++) ri[j - i + bw] -= f * rk[j - k + bw];
        }
        A[(size_t)k * w + bw] = inv;
    }
    return OK;
}

/* x = A^-1 x with A = band_factor's LU; rows away from the ends in full-width loops, so
 * that with bw a constant (band_solve) the compiler unrolls them.  Each row sums the
 * farthest unknowns first: the one just computed enters last, so only one multiply-add
 * per row waits for it (a substitution is a chain of rows; its latency is the cost). */
static inline __attribute__((always_inline)) void band_solve_bw(int n, const int bw,
                                                                const double *A, double *x) {
    int w = 2 * bw + 1;
    for (int i = 0; i < n; i++) {
        const double *ri = A + (size_t)i * w;
        double s = x[i];
        if (i >= bw)
            for (int k = 0; k < bw; k++) s -= ri[k] * x[i - bw + k];
        else
            for (int j = 0; j < i; j++) s -= ri[j - i + bw] * x[j];
        x[i] = s;
    }
    for (int i = n - 1; i >= 0; i--) {
        const double *ri = A + (size_t)i * w;
        double s = x[i];
        if (i + bw < n)
            for (int k = bw; k >= 1; k--) s -= ri[bw + k] * x[i + k];
        else
            for (int j = n - 1; j > i; j--) s -= ri[j - i + bw] * x[j];
        x[i] = s * ri[bw];
    }
}

static void band_solve(int n, int bw, const double *A, double *x) {
    if (bw == 5) band_solve_bw(n, 5, A, x);        /* N >= 2 elements a segment */
    else if (bw == 4) band_solve_bw(n, 4, A, x);   /* N = 1 */
    else band_solve_bw(n, bw, A, x);
}

/* X = A^-1 X for nrhs right-hand sides stored row-major (n x nrhs) */
static void band_solve_multi(int n, int bw, const double *A, double *X, int nrhs) {
    int w = 2 * bw + 1;
    for (int i = 0; i < n; i++) {
        int lo = i - bw < 0 ? 0 : i - bw;
        const double *ri = A + (size_t)i * w;
        double *xi = X + (size_t)i * nrhs;
        for (int j = lo; j < i; j++) {
            double f = ri[j - i + bw];
            if (f == 0.0) continue;
            const double *xj = X + (size_t)j * nrhs;
            for (int c = 0; c < nrhs; c++) xi[c] -= f * xj[c];
        }
    }
    for (int i = n - 1; i >= 0; i--) {
        int hi = i + bw >= n ? n - 1 : i + bw;
        const double *ri = A + (size_t)i * w;
        double *xi = X + (size_t)i * nrhs;
        for (int j = i + 1; j <= hi; j++) {
            double f = ri[j - i + bw];
            if (f == 0.0) continue;
            const double *xj = X + (size_t)j * nrhs;
            for (int c = 0; c < nrhs; c++) xi[c] -= f * xj[c];
        }
        double inv = ri[bw];     /* band_factor keeps the reciprocal */
        for (int c = 0; c < nrhs; c++) xi[c] *= inv;
    }
}

/* Arrow system [[E, B], [C, D]]: E banded (ne x ne), border nb = 4 + nc.  B (ne x nb,
 * row-major); C = 4 dense rows (ne each, nonzero only on [lo[r], hi[r])) and nc sparse
 * rows (JW entries: elastic position or -1, value).  On entry S = D.  On exit E = LU(E)
 * (unless e_factored), B = Y = E^-1 B, S = LU(D - C Y). */

static int arrow_schur(const Arrow *a, const double *B, double *S, int *piv);

static int arrow_factor(const Arrow *a, double *E, int e_factored, double *B, double *S, int *piv) {
    if (!e_factored && band_factor(a->ne, a->bw, E) != OK) return SINGULAR;
    band_solve_multi(a->ne, a->bw, E, B, a->nb);
    return arrow_schur(a, B, S, piv);
}

/* S = LU(D - C Y), given Y = E^-1 B in B */
static int arrow_schur(const Arrow *a, const double *B, double *S, int *piv) {
    int ne = a->ne, nb = a->nb;
    for (int r = 0; r < 4; r++) {
        const double *cr = a->C + (size_t)r * ne;
        double *sr = S + r * nb;
        for (int p = a->lo[r]; p < a->hi[r]; p++) {
            double f = cr[p];
            const double *bp = B + (size_t)p * nb;
            for (int c = 0; c < nb; c++) sr[c] -= f * bp[c];
        }
    }
    for (int r = 0; r < nb - 4; r++) {
        double *sr = S + (4 + r) * nb;
        for (int k = 0; k < JW; k++) {
            int p = a->cpos[r * JW + k];
            if (p < 0) continue;
            double f = a->cval[r * JW + k];
            const double *bp = B + (size_t)p * nb;
            for (int c = 0; c < nb; c++) sr[c] -= f * bp[c];
        }
    }
    return lu_factor(nb, S, piv);
}

/* x = [x_e (ne), x_b (nb)]: rhs in, solution out; top_zero: x_e is zero on entry */
static void arrow_solve(const Arrow *a, const double *E, const double *Y, const double *S,
                        const int *piv, double *x, int top_zero) {
    int ne = a->ne, nb = a->nb;
    double *xe = x, *xb = x + ne;
    if (!top_zero) {
        band_solve(ne, a->bw, E, xe);
        for (int r = 0; r < 4; r++) {
            const double *cr = a->C + (size_t)r * ne;
            double s = 0.0;
            for (int p = a->lo[r]; p < a->hi[r]; p++) s += cr[p] * xe[p];
            xb[r] -= s;
        }
        for (int r = 0; r < nb - 4; r++)
            for (int k = 0; k < JW; k++) {
                int p = a->cpos[r * JW + k];
                if (p >= 0) xb[4 + r] -= a->cval[r * JW + k] * xe[p];
            }
    }
    lu_solve(nb, S, piv, xb);
    for (int p = 0; p < ne; p++) {
        const double *yp = Y + (size_t)p * nb;
        double s = 0.0;
        for (int c = 0; c < nb; c++) s += yp[c] * xb[c];
        xe[p] -= s;
    }
}

/* --------------------------------------------------------------------- mass matrix */
/* border coordinate c (0..3) as a q index */
static int border_q(const Model *m, int c) {
    return c == 0 ? 0 : c == 1 ? m->i_r2x : c == 2 ? m->i_r2y : m->i_alpha2;
}

/* the state-dependent entries of M(q) (model.mass_matrix), given hq = Mff q and maf = W q
 * at the elastic entries (mass_data computes them; the step has them from its products) */
static void mass_data_from_products(Ctx *x, const double *q) {
    const Model *m = x->m;
    int nl = m->n_link, ia = m->i_alpha2, sk = m->s_link;
    double *h = x->hq, *maf = x->maf;
    /* h = c + Mff q; m_af = g + q W = g - W q (W skew) */
    x->maa[0] = m->j0_leaf;
    x->maa[1] = m->j0_link;
    for (int p = 0; p < m->n_elastic; p++) {
        int i = m->elastic_idx[p];
        h[i] += m->c_full[i];
        maf[i] = m->g_full[i] - maf[i];
        x->maa[m->body[i]] += (m->c_full[i] + h[i]) * q[i];
    }
    double c, s;
    cos_sin(x, q[ia], &c, &s);
    x->cos2 = c;
    x->sin2 = s;
    double ub0 = m->pbar0, ub1 = 0.0;
    for (int k = 0; k < nl; k++) {
        ub0 += m->sbar[k] * q[sk + k];
        ub1 += m->sbar[nl + k] * q[sk + k];
    }
    x->mra[0] = -c * ub1 - s * ub0;
    x->mra[1] = -s * ub1 + c * ub0;
    for (int k = 0; k < nl; k++) {
        x->mrf[k] = c * m->sbar[k] + s * m->isbar[k];
        x->mrf[nl + k] = c * m->sbar[nl + k] + s * m->isbar[nl + k];
    }
}

static void mass_data(Ctx *x, const double *q) {
    band_matvec2(x->m, x->m->mff_band, x->hq, x->m->w_band, x->maf, q);
    mass_data_from_products(x, q);
}

/* y = M(q) v with the pieces of mass_data, given mffv = Mff v (elastic entries) */
static void mass_matvec_pre(const Ctx *x, const double *v, const double *mffv, double *y) {
    const Model *m = x->m;
    int n = m->n, nl = m->n_link, ia = m->i_alpha2, ix = m->i_r2x, iy = m->i_r2y, sk = m->s_link;
    for (int i = 0; i < n; i++) y[i] = m->body[i] >= 0 ? mffv[i] : 0.0;
    y[ix] = m->link_mass * v[ix];
    y[iy] = m->link_mass * v[iy];
    for (int p = 0; p < m->n_elastic; p++) {
        int i = m->elastic_idx[p], a = m->body[i] == 0 ? 0 : ia;
        y[a] += x->maf[i] * v[i];
        y[i] += x->maf[i] * v[a];
    }
    y[0] += x->maa[0] * v[0];
    y[ia] += x->maa[1] * v[ia];
    y[ix] += x->mra[0] * v[ia];
    y[iy] += x->mra[1] * v[ia];
    y[ia] += x->mra[0] * v[ix] + x->mra[1] * v[iy];
    for (int k = 0; k < nl; k++) {
        y[ix] += x->mrf[k] * v[sk + k];
        y[iy] += x->mrf[nl + k] * v[sk + k];
        y[sk + k] += x->mrf[k] * v[ix] + x->mrf[nl + k] * v[iy];
    }
}

static void mass_matvec(const Ctx *x, const double *v, double *y) {
    band_matvec(x->m, x->m->mff_band, v, x->mffv, 0);
    mass_matvec_pre(x, v, x->mffv, y);
}

/* the border block of M(q) (rows and columns alpha1, R2x, R2y, alpha2: model.mass_matrix)
 * into the first four rows and columns of S (row length nb) */
static void mass_border_block(const Ctx *x, double *S, int nb) {
    double lm = x->m->link_mass, r0 = x->mra[0], r1 = x->mra[1];
    const double block[16] = {x->maa[0], 0.0, 0.0, 0.0,
                              0.0, lm, 0.0, r0,
                              0.0, 0.0, lm, r1,
                              0.0, r0, r1, x->maa[1]};
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++) S[r * nb + c] = block[r * 4 + c];
}

/* M(q)[i, border 0..3] of an elastic q index i: its body angle's column, and for the link
 * the R2 columns, in one pass */
static inline void mass_border_row(const Ctx *x, int i, double mb[4]) {
    const Model *m = x->m;
    if (m->body[i] == 0) {
        mb[0] = x->maf[i];
        mb[1] = mb[2] = mb[3] = 0.0;
    } else {
        int k = i - m->s_link;
        mb[0] = 0.0;
        mb[1] = x->mrf[k];
        mb[2] = x->mrf[m->n_link + k];
        mb[3] = x->maf[i];
    }
}

/* d/dq [1/2 a^T M(q) b] (model.kinetic_bilinear_gradient), given h = c + Mff q,
 * wa = W a and wb = W b at the elastic coordinates */
static void bilinear_gradient(Ctx *x, const double *q, const double *a, const double *b,
                              const double *h, const double *wa, const double *wb, double *out) {
    const Model *m = x->m;
    int n = m->n, ia = m->i_alpha2, ix = m->i_r2x, iy = m->i_r2y, sk = m->s_link, nl = m->n_link;
    memset(out, 0, sizeof(double) * n);
    for (int p = 0; p < m->n_elastic; p++) {
        int i = m->elastic_idx[p], ang = m->body[i] == 0 ? 0 : ia;
        double oa = a[ang], ob = b[ang];
        out[i] = oa * ob * h[i] + 0.5 * (oa * wb[i] + ob * wa[i]);
    }
    double c, s;
    cos_sin(x, q[ia], &c, &s);
    double ub0 = m->pbar0, ub1 = 0.0;
    for (int k = 0; k < nl; k++) {
        ub0 += m->sbar[k] * q[sk + k];
        ub1 += m->sbar[nl + k] * q[sk + k];
    }
    double aub0 = c * ub0 - s * ub1, aub1 = s * ub0 + c * ub1;
    double acc = -0.5 * ((a[ix] * aub0 + a[iy] * aub1) * b[ia] + (b[ix] * aub0 + b[iy] * aub1) * a[ia]);
    for (int k = 0; k < nl; k++) {
        double ais0 = c * m->isbar[k] - s * m->sbar[k];
        double ais1 = c * m->isbar[nl + k] - s * m->sbar[nl + k];
        double ar = a[ix] * ais0 + a[iy] * ais1, br = b[ix] * ais0 + b[iy] * ais1;
        acc += 0.5 * (ar * b[sk + k] + br * a[sk + k]);
        out[sk + k] += 0.5 * (b[ia] * ar + a[ia] * br);
    }
    out[ia] = acc;
}

/* ------------------------------------------------------------------- constraints */
static double sleeve_height(Ctx *x, const double *q) {
    const Model *m = x->m;
    double c, s;
    cos_sin(x, q[m->i_alpha2], &c, &s);
    return q[m->i_r2y] + (m->l3 + q[m->i_u_sleeve]) * s;
}

static void sleeve_gradient(Ctx *x, const double *q, double *g) {
    const Model *m = x->m;
    memset(g, 0, sizeof(double) * m->n);
    g[m->i_r2y] = 1.0;
    double c, s;
    cos_sin(x, q[m->i_alpha2], &c, &s);
    g[m->i_alpha2] = (m->l3 + q[m->i_u_sleeve]) * c;
    g[m->i_u_sleeve] = s;
}

static void constraints(Ctx *x, const double *q, int locked, int rigid, double *phi) {
    const Model *m = x->m;
    double a1 = q[0], a2 = q[m->i_alpha2];
    double r1 = m->l1 + q[m->i_u_joint], r3 = m->l3 + q[m->i_u_sleeve];
    double c1, s1, c2, s2;
    cos_sin(x, a1, &c1, &s1);
    cos_sin(x, a2, &c2, &s2);
    phi[0] = r1 * c1 - q[m->i_r2x];
    phi[1] = r1 * s1 - q[m->i_r2y];
    phi[2] = q[m->i_r2x] + r3 * c2;
    int row = 3;
    if (locked) phi[row++] = q[m->i_r2y] + r3 * s2 - m->y_stop;
    if (rigid)
        for (int k = 0; k < m->n_elastic; k++) phi[row++] = q[m->elastic_idx[k]];
}

/* sparse rows of J(q): JW (index, value) pairs per row; rigid rows have one entry */
static void jacobian(Ctx *x, const double *q, int locked, int rigid, int *idx, double *val) {
    const Model *m = x->m;
    double a1 = q[0], a2 = q[m->i_alpha2];
    double c1, s1, c2, s2;
    cos_sin(x, a1, &c1, &s1);
    cos_sin(x, a2, &c2, &s2);
    double r1 = m->l1 + q[m->i_u_joint], r3 = m->l3 + q[m->i_u_sleeve];
    int *I = idx; double *V = val;
    I[0] = 0; V[0] = -r1 * s1; I[1] = m->i_u_joint; V[1] = c1; I[2] = m->i_r2x; V[2] = -1.0;
    I[3] = 0; V[3] = r1 * c1; I[4] = m->i_u_joint; V[4] = s1; I[5] = m->i_r2y; V[5] = -1.0;
    I[6] = m->i_r2x; V[6] = 1.0; I[7] = m->i_alpha2; V[7] = -r3 * s2; I[8] = m->i_u_sleeve; V[8] = c2;
    int row = 3;
    if (locked) {
        I[9] = m->i_r2y; V[9] = 1.0; I[10] = m->i_alpha2; V[10] = r3 * c2; I[11] = m->i_u_sleeve; V[11] = s2;
        row = 4;
    }
    if (rigid)
        for (int k = 0; k < m->n_elastic; k++, row++) {
            I[row * JW] = m->elastic_idx[k]; V[row * JW] = 1.0;
            I[row * JW + 1] = I[row * JW + 2] = 0; V[row * JW + 1] = V[row * JW + 2] = 0.0;
        }
}

static double jrow_dot(const int *I, const double *V, int r, const double *x) {
    return V[r * JW] * x[I[r * JW]] + V[r * JW + 1] * x[I[r * JW + 1]] + V[r * JW + 2] * x[I[r * JW + 2]];
}

/* a . b in four partial sums (one chain of n dependent adds is the cost otherwise) */
static double dot(int n, const double *a, const double *b) {
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        s0 += a[i] * b[i];
        s1 += a[i + 1] * b[i + 1];
        s2 += a[i + 2] * b[i + 2];
        s3 += a[i + 3] * b[i + 3];
    }
    for (; i < n; i++) s0 += a[i] * b[i];
    return (s0 + s1) + (s2 + s3);
}

static void gonzalez(int n, double *grad, double delta_f, const double *dq, double dd) {
    if (dd == 0.0) return;
    double gd = dot(n, grad, dq);
    double f = (delta_f - gd) / dd;
    for (int i = 0; i < n; i++) grad[i] += f * dq[i];
}

/* ------------------------------------------------------------------ context */
void umbrella_free(Ctx *x) {
    if (!x) return;
    free(x->hq); free(x->piv); free(x->jrow_idx); free(x->E); free(x->solved_buf);
    free(x->pc_eta_w0);
    free(x);
}

static int solved_band_prepare(Ctx *x, SolvedBand *f, double h, const double *band,
                               double scale);

Ctx *umbrella_new(const Model *m) {
    Ctx *x = calloc(1, sizeof(Ctx));
    if (!x) return NULL;
    int n = m->n, ne = m->n_elastic, w = 2 * m->bw + 1;
    int ncmax = 4 + ne, nbmax = 4 + ncmax;
    x->m = m;
    x->carry_slot = -1;
    x->ne = ne;
    x->nbmax = nbmax;
    x->width = w;
    size_t nvec = 31;
    size_t doubles = (size_t)n * nvec + 2 * (size_t)m->n_link + 2 * (size_t)(n + ncmax)
                     + 6 * (size_t)ncmax * JW + 3 * (size_t)ncmax;
    x->hq = calloc(doubles, sizeof(double));
    x->piv = calloc(3 * (size_t)nbmax, sizeof(int));
    x->jrow_idx = calloc(5 * (size_t)ncmax * JW, sizeof(int));
    x->E = calloc((size_t)ne * w * 3 + 3 * ((size_t)nbmax * ne * 2 + (size_t)nbmax * nbmax
                                           + (size_t)ncmax * JW) + 4 * (size_t)n, sizeof(double));
    if (!x->hq || !x->piv || !x->jrow_idx || !x->E) { umbrella_free(x); return NULL; }
    double *d = x->hq;
    double **vecs[] = {&x->hq, &x->maf, &x->q1, &x->v1, &x->dq, &x->qm, &x->hm, &x->gt, &x->gy,
                       &x->res, &x->kq, &x->mv, &x->wa, &x->wb, &x->vt, &x->q_s, &x->v_s, &x->p_s,
                       &x->mffv, &x->wv0, &x->mq0, &x->wq0, &x->kq0, &x->mv0, &x->mdq, &x->wdq,
                       &x->kdq, &x->mq1, &x->wq1, &x->kq1, &x->pc_s};
    for (size_t k = 0; k < sizeof(vecs) / sizeof(vecs[0]); k++) { *vecs[k] = d; d += n; }
    x->mrf = d; d += 2 * m->n_link;
    x->rhs = d; d += n + ncmax;
    x->xa = d; d += n + ncmax;
    x->jrow_val = d; d += (size_t)ncmax * JW;
    x->jm_val = d; d += (size_t)ncmax * JW;
    x->phi0 = d; d += ncmax;
    x->phi = d; d += ncmax;
    x->corr = d; d += ncmax;
    x->lam_s = d; d += ncmax;
    x->jm_idx = x->jrow_idx + (size_t)ncmax * JW;
    x->Emass = x->E + (size_t)ne * w;
    d = x->Emass + (size_t)ne * w;
    x->slot[0].E_store = x->E;
    x->slot[1].E_store = d; d += (size_t)ne * w;
    for (int k = 0; k < 2; k++) {
        x->slot[k].q_end = d; d += n;
        x->slot[k].v_end = d; d += n;
    }
    ArrowLU *fs[3] = {&x->slot[0], &x->slot[1], &x->pm};
    for (int k = 0; k < 3; k++) {
        fs[k]->B = d; d += (size_t)nbmax * ne;
        fs[k]->C = d; d += (size_t)nbmax * ne;
        fs[k]->S = d; d += (size_t)nbmax * nbmax;
        fs[k]->cval = d; d += (size_t)ncmax * JW;
        fs[k]->piv = x->piv + (size_t)k * nbmax;
        fs[k]->cpos = x->jm_idx + (size_t)(1 + k) * ncmax * JW;
    }
    x->pm.E = x->Emass;
    x->it = &x->slot[0];
    /* the solved bands: fmass on Mff, fiter (Mff + h^2/4 K) prepared at the first step */
    int npts = m->n_stress_leaf + m->n_stress_link;
    x->solved_buf = calloc((size_t)ne * (w + 2 * 6 + 2) + 8 * (size_t)npts, sizeof(double));
    if (!x->solved_buf) { umbrella_free(x); return NULL; }
    d = x->solved_buf;
    x->fiter.lu = d; d += (size_t)ne * w;
    SolvedBand *fb[2] = {&x->fmass, &x->fiter};
    for (int b = 0; b < 2; b++) {
        double **cols[6] = {&fb[b]->sb[0], &fb[b]->sb[1], &fb[b]->isb[0], &fb[b]->isb[1],
                            &fb[b]->ej, &fb[b]->es};
        for (int c = 0; c < 6; c++) { *cols[c] = d; d += ne; }
    }
    x->sv = d; d += ne;
    x->sdq = d; d += ne;
    double **pk[4] = {&x->pk_sig, &x->pk_rate, &x->pk_sig1, &x->pk_rate1};
    for (int k = 0; k < 4; k++) { *pk[k] = d; d += 2 * (size_t)npts; }
    x->fiter.h = -1.0;
    x->fmass.lu = x->Emass;      /* the LU of Mff (projection) */
    if (solved_band_prepare(x, &x->fmass, 0.0, m->k_band, 0.0) != OK) { umbrella_free(x); return NULL; }
    return x;
}

/* ------------------------------------------------------------------ one step */
/* elastic position of a q index, or -1 */
static int epos(const Model *m, int i) {
    if (m->body[i] < 0) return -1;
    return i < m->s_link ? i - 1 : (m->n_elastic - m->n_link) + (i - m->s_link);
}

/* border slot (0..3) of a border q index */
static int bslot(const Model *m, int i) {
    return i == 0 ? 0 : i == m->i_r2x ? 1 : i == m->i_r2y ? 2 : 3;
}

/* f's arrow description for the current rows J(q) (jrow_*, copied) */
static void make_arrow(Ctx *x, ArrowLU *f, int nc) {
    const Model *m = x->m;
    int n1 = x->ne - m->n_link;
    Arrow a = {x->ne, m->bw, 4 + nc, f->C, {0, n1, n1, n1}, {n1, x->ne, x->ne, x->ne},
               f->cpos, f->cval};
    memcpy(f->cval, x->jrow_val, sizeof(double) * nc * JW);
    for (int k = 0; k < nc * JW; k++) f->cpos[k] = f->cval[k] != 0.0 ? epos(m, x->jrow_idx[k]) : -1;
    f->a = a;
}

/* Factor F = Mff + scale * band (h^2/4 K, the damped linear law's band, or scale 0: the
 * mass) into f->lu and solve for its constant border pieces.  f->h = h on success. */
static int solved_band_prepare(Ctx *x, SolvedBand *f, double h, const double *band,
                               double scale) {
    const Model *m = x->m;
    int ne = x->ne, w = x->width, nl = m->n_link, n1 = ne - nl, bw = m->bw;
    for (size_t k = 0; k < (size_t)ne * w; k++) f->lu[k] = m->mff_band[k] + scale * band[k];
    f->h = -1.0;
    if (band_factor(ne, bw, f->lu) != OK) return SINGULAR;
    double *cols[6] = {f->sb[0], f->sb[1], f->isb[0], f->isb[1], f->ej, f->es};
    for (int c = 0; c < 6; c++) memset(cols[c], 0, sizeof(double) * ne);
    for (int k = 0; k < nl; k++) {
        f->sb[0][n1 + k] = m->sbar[k];
        f->sb[1][n1 + k] = m->sbar[nl + k];
        f->isb[0][n1 + k] = m->isbar[k];
        f->isb[1][n1 + k] = m->isbar[nl + k];
    }
    f->pj = epos(m, m->i_u_joint);
    f->ps = epos(m, m->i_u_sleeve);
    f->ej[f->pj] = 1.0;
    f->es[f->ps] = 1.0;
    for (int c = 0; c < 6; c++) band_solve(ne, bw, f->lu, cols[c]);
    f->h = h;
    return OK;
}

/* Y = F^-1 B of the arrow's border columns, into B (row-major, nb = 4 + nc), for the
 * flexible model (constraint rows touch the elastic coordinates only at the joint's and the
 * sleeve's axial coordinates), where
 *   columns alpha1 / alpha2: sv (elastic order; leaf entries are alpha1's, link alpha2's),
 *     solved here in place;
 *   columns R2x, R2y: M's link coupling cos(alpha2) sbar + sin(alpha2) isbar (cos2, sin2);
 *   constraint column r: dcoef[r] dq (dcoef may be NULL) + sign * the elastic entries of the
 *     sparse rows (idx, val): nc <= 4, the flexible model, whose rows (jacobian()) touch the
 *     elastic coordinates only at the joint's and the sleeve's axial coordinate. */
static void arrow_border_from_solved(Ctx *x, const SolvedBand *f, int nc, double *sv,
                                     const double *dcoef, const int *idx, const double *val,
                                     double sign, double *B) {
    const Model *m = x->m;
    int ne = x->ne, nb = 4 + nc, n1 = ne - m->n_link;
    band_solve(ne, m->bw, f->lu, sv);
    const double *sdq = NULL;
    if (dcoef) {
        const int *ei = m->elastic_idx;
        for (int p = 0; p < ne; p++) x->sdq[p] = x->dq[ei[p]];
        band_solve(ne, m->bw, f->lu, x->sdq);
        sdq = x->sdq;
    }
    double c = x->cos2, s = x->sin2;
    for (int p = 0; p < ne; p++) {
        double *Bp = B + (size_t)p * nb;
        Bp[0] = p < n1 ? sv[p] : 0.0;
        Bp[1] = c * f->sb[0][p] + s * f->isb[0][p];
        Bp[2] = c * f->sb[1][p] + s * f->isb[1][p];
        Bp[3] = p < n1 ? 0.0 : sv[p];
        for (int r = 0; r < nc; r++) Bp[4 + r] = sdq ? dcoef[r] * sdq[p] : 0.0;
    }
    for (int r = 0; r < nc; r++)
        for (int k = 0; k < JW; k++) {
            double v = val[r * JW + k];
            int p = v != 0.0 ? epos(m, idx[r * JW + k]) : -1;
            if (p < 0) continue;
            const double *col = p == f->pj ? f->ej : f->es;
            v *= sign;
            for (int q = 0; q < ne; q++) B[(size_t)q * nb + 4 + r] += v * col[q];
        }
}

/* Iteration matrix M(q) + h^2/4 K + h/2 G(qm, dq/h) with the constraint columns -Jm^T and
 * rows J(q), as an arrow system; the multipliers are scaled by h^2/2 (integrators.py). */
static int factor_iteration_matrix(Ctx *x, double h, int nc) {
    const Model *m = x->m;
    int ne = x->ne, w = x->width, nb = 4 + nc, nl = m->n_link;
    int ia = m->i_alpha2, sk = m->s_link;
    const int *ei = m->elastic_idx;
    double *vt = x->vt, *h_m = x->hm, *wed = x->wb;
    const double *qm = x->qm;
    double inv_h = 1.0 / h;
    for (int i = 0; i < m->n; i++) vt[i] = x->dq[i] * inv_h;
    /* h_m = c + Mff qm and W dq from this Newton iteration */
    for (int p = 0; p < ne; p++) wed[ei[p]] = x->wdq[ei[p]] * inv_h;
    double om[2] = {vt[0], vt[ia]};
    /* The iteration matrix of integrators.iteration_blocks: for the flexible model (nc <= 4)
     * the gyroscopic elastic block G_ee = -2 w W and the Gonzalez correction of the
     * constraint columns are left out, which only changes how Newton converges, not to what.
     * Then the elastic block E of the linear strain is constant: Mff + h^2/4 K, or with the
     * damped law (linear strain) Mff + its band (h^2/4 K + h/2 C), factored once per step
     * length with the solves of its constant border pieces (SolvedBand: "solved").
     * Otherwise E = Mff + (the nonlinear law's band, or h^2/4 K) (- h w_body W, rigid-FE),
     * here. */
    int exact = nc > 4, solved = !(x->law && x->law->d.nonlinear) && !exact;
    /* the grid step t1 - t0 varies in its last bits: the band of a step within 1e-9 of it
     * serves (the iteration matrix only steers Newton) */
    if (solved && !(fabs(x->fiter.h - h) <= 1e-9 * h)
        && solved_band_prepare(x, &x->fiter, h, x->law ? x->law->band : m->k_band,
                               x->law ? 1.0 : 0.25 * h * h) != OK)
        return SINGULAR;
    if (!solved) {
        double h2 = 0.25 * h * h;
        const double *k_band = m->k_band;   /* with a law: its h^2/2 dG_U/dq1 + h/2 C, scale 1 */
        if (x->law) { k_band = x->law->band; h2 = 1.0; }
        for (int p = 0; p < ne; p++) {
            double f = exact ? -h * om[m->body[ei[p]]] : 0.0;
            const double *mf = m->mff_band + (size_t)p * w, *kb = k_band + (size_t)p * w;
            const double *wb = m->w_band + (size_t)p * w;
            double *e = x->it->E_store + (size_t)p * w;
            for (int k = 0; k < w; k++) e[k] = mf[k] + h2 * kb[k] + f * wb[k];
        }
    }
    /* gyroscopic border terms (model.gyroscopic_matrix) */
    double g00 = 0.0, gaa = 0.0;
    for (int p = 0; p < ne; p++) {
        int i = ei[p];
        if (m->body[i] == 0) g00 += 2.0 * h_m[i] * vt[i]; else gaa += 2.0 * h_m[i] * vt[i];
    }
    double c, s, w2 = vt[ia];
    cos_sin(x, qm[ia], &c, &s);
    double ub0 = m->pbar0, ub1 = 0.0, sd0 = 0.0, sd1 = 0.0;
    for (int k = 0; k < nl; k++) {
        ub0 += m->sbar[k] * qm[sk + k];
        ub1 += m->sbar[nl + k] * qm[sk + k];
        sd0 += m->sbar[k] * vt[sk + k];
        sd1 += m->sbar[nl + k] * vt[sk + k];
    }
    double x0 = 2.0 * w2 * ub0 + 2.0 * sd1, x1 = 2.0 * w2 * ub1 - 2.0 * sd0;
    double g_xa = -(c * x0 - s * x1), g_ya = -(s * x0 + c * x1);
    double hh = 0.5 * h;
    ArrowLU *f = x->it;
    make_arrow(x, f, nc);
    /* B (row-major) and the four dense rows C */
    double *B = f->B, *C = f->C;
    for (int p = 0; p < ne; p++) {
        int i = ei[p], b = m->body[i];
        double *Bp = B + (size_t)p * nb, mbr[4];
        mass_border_row(x, i, mbr);
        for (int cb = 0; cb < 4; cb++) {
            double mb = mbr[cb];
            double gcol = 0.0, grow = 0.0;     /* G[i, c], G[c, i] */
            if ((cb == 0 && b == 0) || (cb == 3 && b == 1)) {
                double wb = om[b];
                gcol = -2.0 * wb * h_m[i] - 2.0 * wed[i];
                grow = 2.0 * wb * h_m[i];
            } else if (b == 1 && (cb == 1 || cb == 2)) {
                int k = i - sk;
                grow = cb == 1 ? 2.0 * w2 * (c * m->isbar[k] - s * m->sbar[k])
                               : 2.0 * w2 * (c * m->isbar[nl + k] - s * m->sbar[nl + k]);
            }
            if (solved) {
                if (cb == (b == 0 ? 0 : 3)) x->sv[p] = mb + hh * gcol;
            } else {
                Bp[cb] = mb + hh * gcol;
            }
            C[(size_t)cb * ne + p] = mb + hh * grow;
        }
        /* multiplier columns -Jc^T: Jc = J(qm) (+ corr dq, exact) */
        double dqi = exact ? x->dq[i] : 0.0;
        if (!solved)
            for (int r = 0; r < nc; r++) Bp[4 + r] = -x->corr[r] * dqi;
    }
    if (solved) {
        arrow_border_from_solved(x, &x->fiter, nc, x->sv, NULL, x->jm_idx, x->jm_val, -1.0, B);
    } else {
        for (int r = 0; r < nc; r++)
            for (int k = 0; k < JW; k++) {
                int p = epos(m, x->jm_idx[r * JW + k]);
                if (p >= 0) B[(size_t)p * nb + 4 + r] -= x->jm_val[r * JW + k];
            }
    }
    /* D */
    double *S = f->S;
    memset(S, 0, sizeof(double) * nb * nb);
    mass_border_block(x, S, nb);
    S[0] += hh * g00;
    S[3 * nb + 3] += hh * gaa;
    S[1 * nb + 3] += hh * g_xa;
    S[2 * nb + 3] += hh * g_ya;
    for (int r = 0; r < nc; r++) {
        for (int cb = 0; cb < 4; cb++)
            S[cb * nb + 4 + r] = exact ? -x->corr[r] * x->dq[border_q(m, cb)] : 0.0;
        for (int k = 0; k < JW; k++) {
            int i = x->jm_idx[r * JW + k];
            if (m->body[i] < 0) S[bslot(m, i) * nb + 4 + r] -= x->jm_val[r * JW + k];
            i = x->jrow_idx[r * JW + k];
            if (m->body[i] < 0) S[(4 + r) * nb + bslot(m, i)] += x->jrow_val[r * JW + k];
        }
    }
    if (solved) {
        f->E = x->fiter.lu;
        return arrow_schur(&f->a, B, S, f->piv);
    }
    f->E = f->E_store;
    return arrow_factor(&f->a, f->E_store, 0, B, S, f->piv);
}

/* solve the factored arrow system for a q-ordered rhs of length n + nc, in place */
static void arrow_solve_q(Ctx *x, const ArrowLU *f, int nc, double *r, int top_zero) {
    const Model *m = x->m;
    int ne = x->ne, n = m->n;
    double *a = x->xa;
    for (int p = 0; p < ne; p++) a[p] = r[m->elastic_idx[p]];
    for (int c = 0; c < 4; c++) a[ne + c] = r[border_q(m, c)];
    for (int k = 0; k < nc; k++) a[ne + 4 + k] = r[n + k];
    arrow_solve(&f->a, f->E, f->B, f->S, f->piv, a, top_zero);
    for (int p = 0; p < ne; p++) r[m->elastic_idx[p]] = a[p];
    for (int c = 0; c < 4; c++) r[border_q(m, c)] = a[ne + c];
    for (int k = 0; k < nc; k++) r[n + k] = a[ne + 4 + k];
}

static double max_abs(int n, const double *x) {
    double r = 0.0;
    for (int i = 0; i < n; i++) { double a = fabs(x[i]); if (!(a <= r)) r = a; }
    return r;
}

/* A state's constraint residual max(|Phi(q)|, |J v|), J's rows at q in (I, V); leaves Phi(q)
 * in x->phi */
static double state_residual(Ctx *x, const double *q, const double *v, int locked, int rigid,
                             int nc, const int *I, const double *V) {
    constraints(x, q, locked, rigid, x->phi);
    double r = max_abs(nc, x->phi);
    for (int c = 0; c < nc; c++) {
        double a = fabs(jrow_dot(I, V, c, v));
        if (!(a <= r)) r = a;
    }
    return r;
}

/* Velocity projection onto J(q1) v = 0 in the mass metric, then scaled to the kinetic energy
 * t_target of the discrete energy balance (integrators.project_keeping_energy).  Needs
 * mass_data(q1) and the rows J(q1) in jrow_*.  Leaves the momentum M(q1) v in p. */
static int project_velocity(Ctx *x, int nc, double *v, double *p_out, double t_target) {
    const Model *m = x->m;
    int ne = x->ne, nb = 4 + nc, n = m->n;
    const int *ei = m->elastic_idx;
    double jv_max = 0.0;
    for (int r = 0; r < nc; r++) {
        double a = fabs(jrow_dot(x->jrow_idx, x->jrow_val, r, v));
        if (a > jv_max) jv_max = a;
    }
    if (!(jv_max > 0.0)) { mass_matvec(x, v, p_out); goto scale; }
    /* KKT [[M, J^T], [J, 0]] [dv; mu] = [0; -J v], arrow form with E = Mff (factored once,
     * with the solves of its constant border pieces: the flexible model) */
    ArrowLU *fm = &x->pm;
    make_arrow(x, fm, nc);
    double *B = fm->B, *C = fm->C;
    int solved = nc <= 4;
    for (int p = 0; p < ne; p++) {
        double *Bp = B + (size_t)p * nb, mbr[4];
        mass_border_row(x, ei[p], mbr);
        for (int cb = 0; cb < 4; cb++) {
            double mb = mbr[cb];
            C[(size_t)cb * ne + p] = mb;
            if (solved) {
                if (cb == (m->body[ei[p]] == 0 ? 0 : 3)) x->sv[p] = mb;
            } else {
                Bp[cb] = mb;
            }
        }
        if (!solved)
            for (int r = 0; r < nc; r++) Bp[4 + r] = 0.0;
    }
    double *S = fm->S;
    memset(S, 0, sizeof(double) * nb * nb);
    mass_border_block(x, S, nb);
    for (int r = 0; r < nc; r++)
        for (int k = 0; k < JW; k++) {
            int i = x->jrow_idx[r * JW + k];
            double val = x->jrow_val[r * JW + k];
            int p = epos(m, i);
            if (p >= 0) {
                if (!solved) B[(size_t)p * nb + 4 + r] += val;
            } else {
                S[bslot(m, i) * nb + 4 + r] += val;
                S[(4 + r) * nb + bslot(m, i)] += val;
            }
        }
    if (solved) {
        arrow_border_from_solved(x, &x->fmass, nc, x->sv, NULL, x->jrow_idx, x->jrow_val, 1.0, B);
        if (arrow_schur(&fm->a, B, S, fm->piv) != OK) return SINGULAR;
    } else if (arrow_factor(&fm->a, x->Emass, 1, B, S, fm->piv) != OK) return SINGULAR;
    double *r = x->rhs;
    memset(r, 0, sizeof(double) * n);
    for (int k = 0; k < nc; k++) r[n + k] = -jrow_dot(x->jrow_idx, x->jrow_val, k, v);
    /* the elastic rows of the rhs are zero (the border rows too, but they are not skipped) */
    arrow_solve_q(x, fm, nc, r, 1);
    for (int i = 0; i < n; i++) v[i] += r[i];
    mass_matvec(x, v, p_out);
scale:;
    double t_after = 0.0;
    for (int i = 0; i < n; i++) t_after += v[i] * p_out[i];
    t_after *= 0.5;
    if (t_after > 0.0 && t_target >= t_after / ENERGY_RESTORE_LIMIT
        && t_target <= ENERGY_RESTORE_LIMIT * t_after) {
        double f = sqrt(t_target / t_after);
        for (int i = 0; i < n; i++) { v[i] *= f; p_out[i] *= f; }
    }
    return OK;
}

/* eta_j = u_j . d (j < r; u_j the rows of u, r x n), each summed in i order as a plain loop
 * would, four modes at a time: independent sums instead of one latency-bound chain */
static void modal_dots(int r, int n, const double *u, const double *d, double *eta) {
    int j = 0;
    for (; j + 4 <= r; j += 4) {
        const double *u0 = u + (size_t)j * n, *u1 = u0 + n, *u2 = u1 + n, *u3 = u2 + n;
        double a0 = 0.0, a1 = 0.0, a2 = 0.0, a3 = 0.0;
        for (int i = 0; i < n; i++) {
            a0 += u0[i] * d[i];
            a1 += u1[i] * d[i];
            a2 += u2[i] * d[i];
            a3 += u3[i] * d[i];
        }
        eta[j] = a0;
        eta[j + 1] = a1;
        eta[j + 2] = a2;
        eta[j + 3] = a3;
    }
    for (; j < r; j++) {
        const double *uj = u + (size_t)j * n;
        double a = 0.0;
        for (int i = 0; i < n; i++) a += uj[i] * d[i];
        eta[j] = a;
    }
}

/* y[i] += sign s_j rows_j[i] for j = 0 .. r-1 in that order (rows: r x n), each y[i]
 * held in a register over the modes, four at a time (one pass over y instead of r) */
static void modal_combine(int r, int n, const double *rows, const double *s, double sign,
                          double *y) {
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        double a0 = y[i], a1 = y[i + 1], a2 = y[i + 2], a3 = y[i + 3];
        for (int j = 0; j < r; j++) {
            const double *rj = rows + (size_t)j * n + i;
            double sj = sign * s[j];
            a0 += sj * rj[0];
            a1 += sj * rj[1];
            a2 += sj * rj[2];
            a3 += sj * rj[3];
        }
        y[i] = a0;
        y[i + 1] = a1;
        y[i + 2] = a2;
        y[i + 3] = a3;
    }
    for (; i < n; i++) {
        double a = y[i];
        for (int j = 0; j < r; j++) a += sign * s[j] * rows[(size_t)j * n + i];
        y[i] = a;
    }
}

/* Stage 2's mode fit from now on (r = 0: none); the arrays stay the caller's (dc may be
 * NULL: undamped).  Returns 0, or SINGULAR if its buffers cannot be allocated. */
int umbrella_set_mode_fit(Ctx *x, int r, const double *u, const double *phi, const double *sc,
                          const double *shrink, const double *dc) {
    const Model *m = x->m;
    int n = m->n;
    free(x->pc_eta_w0);
    x->pc_eta_w0 = NULL;
    x->pc_r = 0;
    if (r > 0) {
        x->pc_eta_w0 = calloc(2 * (size_t)r + 4 * (size_t)n, sizeof(double));
        if (!x->pc_eta_w0) return SINGULAR;
        x->pc_eta_dq = x->pc_eta_w0 + r;
        x->pc_w0 = x->pc_eta_dq + r;
        x->pc_sp0 = x->pc_w0 + n;
        x->pc_mw0 = x->pc_sp0 + n;
        x->pc_ww0 = x->pc_mw0 + n;
    }
    x->pc_r = r;
    x->pc_u = u;
    x->pc_phi = phi;
    x->pc_sc = sc;
    x->pc_shrink = shrink;
    x->pc_dc = dc;
    return OK;
}

/* The Newton update x (n + nc, q-ordered then multipliers) with the fit's share of the
 * tangent put back mode by mode (LockedModeFit.newton_update): each modal component
 * g_j = u_j . x_q is shrunk by shrink_j = d_j / (block_j + d_j), d_j the fit's share of the
 * mode's tangent, block_j the iteration matrix's (1 + (omega_j h)^2 / 4 + h c_j / 2).  The
 * exact Woodbury correction on the factored matrix took 2.6 Newton iterations a stage-2 step
 * where this takes 2.06 (N = 1, 2, 4; 2.0 without the fit): the tangent S^T M(q) S is nearer
 * the modes' own blocks than the factored matrix plus U diag(d) U^T. */
static void mode_fit_update(Ctx *x, double *upd) {
    int n = x->m->n, r = x->pc_r;
    double *g = x->pc_s;
    modal_dots(r, n, x->pc_u, upd, g);
    for (int j = 0; j < r; j++) {
        double shrunk = x->pc_shrink[j] * g[j];
        x->pc_eta_dq[j] += g[j] - shrunk;          /* u_j . dq gains what is left of g_j */
        g[j] = shrunk;
    }
    modal_combine(r, n, x->pc_phi, g, -1.0, upd);
}

/* At the start of a step from (v0, p0 = M(q0) v0), after Mff v0 and W v0 (x->mv0, wv0):
 * w0 = S^-1 v0 (u_i . S^-1 v = u_i . v / s_i) with Mff w0 and W w0, S^T p0, and u_i . dq of
 * the predictor dq = h w0 */
static void mode_fit_start(Ctx *x, const double *v0, const double *p0, double h) {
    int n = x->m->n, r = x->pc_r;
    double *c = x->pc_s;
    modal_dots(r, n, x->pc_u, v0, x->pc_eta_w0);
    for (int j = 0; j < r; j++) {
        double eta_v = x->pc_eta_w0[j];
        c[j] = (1.0 / x->pc_sc[j] - 1.0) * eta_v;
        x->pc_eta_w0[j] = eta_v / x->pc_sc[j];
        x->pc_eta_dq[j] = h * x->pc_eta_w0[j];
    }
    memcpy(x->pc_w0, v0, sizeof(double) * n);
    modal_combine(r, n, x->pc_phi, c, 1.0, x->pc_w0);
    /* Mff w0 and W w0: band products (of the elastic entries), not r x n passes */
    band_matvec2(x->m, x->m->mff_band, x->pc_mw0, x->m->w_band, x->pc_ww0, x->pc_w0);
    modal_dots(r, n, x->pc_phi, p0, c);               /* S^T p0 = p0 + U diag(s-1) Phi^T p0 */
    for (int j = 0; j < r; j++) c[j] *= x->pc_sc[j] - 1.0;
    memcpy(x->pc_sp0, p0, sizeof(double) * n);
    modal_combine(r, n, x->pc_u, c, 1.0, x->pc_sp0);
}

/* The modal sums c_j = (s_j - 1) u_j . w1 of the iterate, w1 = 2 dq / h - w0 */
static void mode_fit_sums(Ctx *x, double two_h) {
    for (int j = 0; j < x->pc_r; j++)
        x->pc_s[j] = (x->pc_sc[j] - 1.0) * (two_h * x->pc_eta_dq[j] - x->pc_eta_w0[j]);
}

/* One step from (q0, v0, lam0, p0) of length h; results in x->q_s, v_s, lam_s, p_s. */
static int step(Ctx *x, int locked, int rigid, const double *q0, const double *v0,
                const double *lam0, const double *p0, double h, double force, double tol,
                double phi_tol, int max_iter, int carry, int *iterations) {
    const Model *m = x->m;
    int n = m->n, nc = nc_of(m, locked, rigid);
    double *q = x->q_s, *v = x->v_s, *lam = x->lam_s, *dq = x->dq, *qm = x->qm, *v1 = x->v1;
    double *phi0 = x->phi0, *phi = x->phi, *rhs = x->rhs;
    int status = OK, it = 0, factored = 0, refactored = 0;
    /* nonlinear law: backtracking line search, the matrix re-factored after a slow
     * iteration (ElasticMidpointDAE._step_numpy) */
    ElasticLaw *law = x->law;
    int nonlinear_law = law && law->d.nonlinear, have_base = 0, refresh = 0;
    /* The nonlinear law's tangent turns with the slopes: taken at the predictor q0 + h v0
     * (~1e-3 off in stage 2 at V0 = -0.2) it gives Newton a linear rate of ~1e-2, and a step
     * 3 to 4 iterations.  So a step that starts where the last step ended (and carry: not a
     * trial step of the lock's root find) begins with that step's last matrix.  If that
     * matrix was factored ELASTIC_CARRY_STEPS steps ago or less it serves this step whole
     * (re-factored only after a slow iteration); an older one serves the first iteration,
     * and the matrix is factored anew at the first iterate, which is close.  A factorisation
     * costs about a Newton iteration: this takes 0.4 iterations more a step than factoring
     * every step, and 12 % less time (N = 2 and 4, V0 = -0.2 and -1).  A rule of the
     * trajectory alone, so umbrella_step and umbrella_advance_call give the same bits (a step is
     * handed on only once taken: carry_commit). */
    ArrowLU *kept = x->it_kept ? &x->slot[x->it_slot] : NULL;
    int lagged = carry && nonlinear_law && kept && kept->nc == nc
                 && fabs(kept->h - h) <= 1e-9 * h
                 && memcmp(q0, kept->q_end, sizeof(double) * n) == 0
                 && memcmp(v0, kept->v_end, sizeof(double) * n) == 0;
    int lag_whole = lagged && kept->age < ELASTIC_CARRY_STEPS;
    x->carry_slot = -1;
    /* this step's factorisations go to the other slot: the kept one stays intact if the
     * step is not taken (advance() restores it_kept, it_slot) */
    ArrowLU *fresh = kept ? &x->slot[1 - x->it_slot] : &x->slot[0];
    x->it = lagged ? kept : fresh;
    x->it_kept = 0;
    factored = lagged;
    int pc = pc_acts(x, locked, rigid);    /* stage 2's mode fit */
    double alpha = 1.0, f_base = INFINITY;
    double half_h2 = 0.5 * h * h, two_h = 2.0 / h;   /* v1 = 2 dq / h - v0 */
    constraints(x, q0, locked, rigid, phi0);
    double y0 = sleeve_height(x, q0);
    memcpy(lam, lam0, sizeof(double) * nc);
    double last_norm = INFINITY, step_norm = 0.0;
    int converged = 0;
    /* K, or with a law its k_band (K for the linear strain, zero for the co-rotational beam,
     * whose G_U the law adds) */
    const double *k_band = law ? law->d.k_band : m->k_band;
    const int *ei = m->elastic_idx;
    int ne = m->n_elastic;
    if (!x->q0_products) {
        band_matvec3(m, m->mff_band, x->mq0, m->w_band, x->wq0, k_band, x->kq0, q0);
        x->q0_products = 1;
    }
    band_matvec2(m, m->mff_band, x->mv0, m->w_band, x->wv0, v0);
    /* the iterate's velocity v1 = 2 dq / h - w0 (w0 = v0 without the fit), with its Mff and W
     * products; with the fit then v1 = S w1, p0s = S^T p0 */
    const double *w0 = v0, *mw0 = x->mv0, *ww0 = x->wv0, *p0s = p0;
    if (pc) {
        mode_fit_start(x, v0, p0, h);
        w0 = x->pc_w0;
        mw0 = x->pc_mw0;
        ww0 = x->pc_ww0;
        p0s = x->pc_sp0;
    }
    for (int i = 0; i < n; i++) q[i] = q0[i] + h * w0[i];   /* predictor: w0 held */
    /* a predictor outside the law's coordinates (a slope |theta| >= 1) starts from q0 */
    if (nonlinear_law && !elastic_admissible(law, q)) memcpy(q, q0, sizeof(double) * n);
    for (it = 1; it <= max_iter; it++) {
        for (int i = 0; i < n; i++) {
            dq[i] = q[i] - q0[i];
            qm[i] = q0[i] + 0.5 * dq[i];
            v1[i] = dq[i] * two_h - w0[i];
        }
        double dd = dot(n, dq, dq);
        /* Mff, W, K of q = q0 + dq, qm = q0 + dq / 2 and v1 = 2 dq / h - v0 */
        band_matvec3(m, m->mff_band, x->mdq, m->w_band, x->wdq, k_band, x->kdq, dq);
        for (int p = 0; p < ne; p++) {
            int i = ei[p];
            double md = x->mdq[i], wd = x->wdq[i];
            x->hq[i] = x->mq0[i] + md;
            x->maf[i] = x->wq0[i] + wd;
            x->hm[i] = m->c_full[i] + (x->mq0[i] + 0.5 * md);
            x->kq[i] = x->kq0[i] + 0.5 * x->kdq[i];
            x->mffv[i] = md * two_h - mw0[i];
            x->wb[i] = wd * two_h - ww0[i];
        }
        if (pc) {                  /* v1 = S w1: the physical velocity, and its products */
            mode_fit_sums(x, two_h);
            modal_combine(x->pc_r, n, x->pc_phi, x->pc_s, 1.0, v1);
            band_matvec2(m, m->mff_band, x->mffv, m->w_band, x->wb, v1);
        }
        mass_data_from_products(x, q);
        constraints(x, q, locked, rigid, phi);
        if (law) elastic_force(law, q0, q, h, x->kdq, x->kq);   /* + the rest of G_U, C dq / h */
        bilinear_gradient(x, qm, v0, v1, x->hm, x->wv0, x->wb, x->gt);
        mass_matvec_pre(x, v1, x->mffv, x->mv);
        /* f = 1/2 v0^T M(q) v1 (physical velocities): f(q1) - f(q0) = 1/2 (v0^T M1 v1 - p0 . v1),
         * M symmetric */
        double df = 0.5 * (dot(n, v0, x->mv) - dot(n, p0, v1));
        if (pc) {                  /* the scheme's momentum S^T M(q1) v1 */
            modal_dots(x->pc_r, n, x->pc_phi, x->mv, x->pc_s);
            for (int j = 0; j < x->pc_r; j++) x->pc_s[j] *= x->pc_sc[j] - 1.0;
            if (x->pc_dc)          /* + h times the fit's damping change U diag(c_w - c) U^T dq / h */
                for (int j = 0; j < x->pc_r; j++) x->pc_s[j] += x->pc_dc[j] * x->pc_eta_dq[j];
            modal_combine(x->pc_r, n, x->pc_u, x->pc_s, 1.0, x->mv);
        }
        gonzalez(n, x->gt, df, dq, dd);
        sleeve_gradient(x, qm, x->gy);
        gonzalez(n, x->gy, sleeve_height(x, q) - y0, dq, dd);
        jacobian(x, qm, locked, rigid, x->jm_idx, x->jm_val);
        double cl = 0.0;   /* corr . lam */
        for (int r = 0; r < nc; r++) {
            x->corr[r] = dd > 0.0 ? (phi[r] - phi0[r] - jrow_dot(x->jm_idx, x->jm_val, r, dq)) / dd : 0.0;
            cl += x->corr[r] * lam[r];
        }
        /* res = M1 v1 - p0 - h (gt - K qm - F gy + Jm^T lam) */
        double *res = x->res;
        for (int i = 0; i < n; i++) res[i] = dq[i] * cl;
        for (int r = 0; r < nc; r++)
            for (int k = 0; k < JW; k++) res[x->jm_idx[r * JW + k]] += x->jm_val[r * JW + k] * lam[r];
        for (int i = 0; i < n; i++)
            res[i] = x->mv[i] - p0s[i] - h * (x->gt[i] - x->kq[i] - force * x->gy[i] + res[i]);
        if (nonlinear_law) {
            double fn = 0.25 * h * h * dot(n, res, res);
            for (int r = 0; r < nc; r++) fn += phi[r] * phi[r];
            fn = sqrt(fn);
            if (have_base && !(fn < f_base) && alpha >= 0.05) {   /* backtrack */
                alpha *= 0.5;
                for (int i = 0; i < n; i++) q[i] = law->q_base[i] + alpha * law->dx[i];
                for (int r = 0; r < nc; r++) lam[r] = law->lam_base[r] + alpha * law->dx[n + r] / half_h2;
                it--;
                continue;
            }
            f_base = fn;
        }
        if (!factored || refresh) {
            jacobian(x, q, locked, rigid, x->jrow_idx, x->jrow_val);
            if (law) elastic_iteration_band(law, q0, q, h);
            x->it = fresh;
            if (factor_iteration_matrix(x, h, nc) != OK) { status = SINGULAR; goto done; }
            factored = refactored = 1;
        }
        for (int i = 0; i < n; i++) rhs[i] = -0.5 * h * res[i];
        for (int r = 0; r < nc; r++) rhs[n + r] = -phi[r];
        arrow_solve_q(x, x->it, nc, rhs, 0);
        if (pc) mode_fit_update(x, rhs);
        if (nonlinear_law) {
            memcpy(law->q_base, q, sizeof(double) * n);
            memcpy(law->lam_base, lam, sizeof(double) * nc);
            memcpy(law->dx, rhs, sizeof(double) * (n + nc));
            have_base = 1;
            alpha = 1.0;
        }
        step_norm = 0.0;
        for (int i = 0; i < n; i++) {
            q[i] += rhs[i];
            double a = fabs(rhs[i]);
            if (!(a <= step_norm)) step_norm = a;
        }
        for (int r = 0; r < nc; r++) lam[r] += rhs[n + r] / half_h2;
        if (!isfinite(step_norm)) { status = NON_FINITE; goto done; }
        double rate = it > 1 ? step_norm / last_norm : 1.0;
        refresh = nonlinear_law && ((it == 1 && lagged && !lag_whole)
                                    || (it > 1 && rate > ELASTIC_REFRESH_RATE));
        if (step_norm < tol || (rate < 0.5 && rate / (1.0 - rate) * step_norm < tol)) {
            constraints(x, q, locked, rigid, phi);
            if (max_abs(nc, phi) < phi_tol) { converged = 1; break; }
            /* converged in q, not in the joints: one correction of the joints alone, the
             * momentum rows' right-hand side 0 (integrators.newton_converged) */
            for (int i = 0; i < n; i++) rhs[i] = 0.0;
            for (int r = 0; r < nc; r++) rhs[n + r] = -phi[r];
            arrow_solve_q(x, x->it, nc, rhs, 0);
            if (pc) mode_fit_update(x, rhs);
            for (int i = 0; i < n; i++) q[i] += rhs[i];
            for (int r = 0; r < nc; r++) lam[r] += rhs[n + r] / half_h2;
            constraints(x, q, locked, rigid, phi);
            if (max_abs(nc, phi) < phi_tol) { converged = 1; break; }
        }
        last_norm = step_norm;
    }
    if (!converged) { status = NO_CONVERGENCE; goto done; }
    for (int i = 0; i < n; i++) {
        dq[i] = q[i] - q0[i];
        v[i] = dq[i] * two_h - w0[i];
    }
    if (pc) {                      /* v = S w1, from u . dq of the step taken */
        modal_dots(x->pc_r, n, x->pc_u, dq, x->pc_eta_dq);
        mode_fit_sums(x, two_h);
        modal_combine(x->pc_r, n, x->pc_phi, x->pc_s, 1.0, v);
    }
    jacobian(x, q, locked, rigid, x->jrow_idx, x->jrow_val);
    /* the products of q1, direct: the next step's q0 products (bitwise what it would compute) */
    band_matvec3(m, m->mff_band, x->mq1, m->w_band, x->wq1, k_band, x->kq1, q);
    for (int p = 0; p < ne; p++) { int i = ei[p]; x->hq[i] = x->mq1[i]; x->maf[i] = x->wq1[i]; }
    mass_data_from_products(x, q);
    /* kinetic energy of the discrete balance: T0 + V(q0) - V(q1) + F (y0 - y1) (- damping) */
    double t_target = force * (y0 - sleeve_height(x, q));
    x->dissipated = 0.0;
    if (law) {
        x->dissipated = elastic_dissipation(law, q0, q, h);
        /* U(q0) first: kept from the step before; U(q1) then keeps q1's strains */
        double u0 = elastic_energy(law, q0, x->kq0);
        if (pc && x->pc_dc)        /* the fit's damping change: dq.U diag(c_w - c) U^T dq / h */
            for (int j = 0; j < x->pc_r; j++)
                x->dissipated += x->pc_dc[j] * x->pc_eta_dq[j] * x->pc_eta_dq[j] / h;
        t_target += u0 - elastic_energy(law, q, x->kq1) - x->dissipated;
    } else {
        for (int p = 0; p < ne; p++) { int i = ei[p]; t_target += 0.5 * q0[i] * x->kq0[i]; }
        for (int p = 0; p < ne; p++) { int i = ei[p]; t_target -= 0.5 * q[i] * x->kq1[i]; }
    }
    for (int i = 0; i < n; i++) t_target += 0.5 * v0[i] * p0[i];
    if (project_velocity(x, nc, v, x->p_s, t_target) != OK) { status = SINGULAR; goto done; }
    if (carry && nonlinear_law) {
        x->carry_slot = (int)(x->it - x->slot);
        x->carry_age = refactored ? 0 : x->it->age + 1;
    }
done:
    *iterations = it > max_iter ? max_iter : it;
    return status;
}

/* Hand the matrix of the step just taken (q_s, v_s: its end; nc constraints, length h) on
 * to the next step (step(): the nonlinear law) */
static void carry_commit(Ctx *x, int nc, double h) {
    if (x->carry_slot < 0) return;
    ArrowLU *f = &x->slot[x->carry_slot];
    int n = x->m->n;
    memcpy(f->q_end, x->q_s, sizeof(double) * n);
    memcpy(f->v_end, x->v_s, sizeof(double) * n);
    f->nc = nc;
    f->h = h;
    f->age = x->carry_age;
    x->it_kept = 1;
    x->it_slot = x->carry_slot;
    x->carry_slot = -1;
}

/* single step (root finding of the lock, tests): p0 = M(q0) v0 may be NULL */
int umbrella_step(Ctx *x, int locked, int rigid,
                  const double *q0, const double *v0, const double *lam0, const double *p0_in,
                  double h, double force, double tol, double phi_tol, int max_iter,
                  double *q, double *v, double *lam, double *p1, int *iterations) {
    const Model *m = x->m;
    int n = m->n, nc = nc_of(m, locked, rigid);
    double *p0 = x->q1;         /* step() does not use q1 */
    x->q0_products = 0;
    if (p0_in) memcpy(p0, p0_in, sizeof(double) * n);
    else {
        mass_data(x, q0);
        mass_matvec(x, v0, p0);
    }
    int status = step(x, locked, rigid, q0, v0, lam0, p0, h, force, tol, phi_tol,
                      max_iter, 1, iterations);
    if (status == OK) {
        carry_commit(x, nc, h);
        memcpy(q, x->q_s, sizeof(double) * n);
        memcpy(v, x->v_s, sizeof(double) * n);
        memcpy(lam, x->lam_s, sizeof(double) * nc);
        memcpy(p1, x->p_s, sizeof(double) * n);
    }
    return status;
}

/* attach the elastic law of _kernel_nonlinear.c (NULL: the constant K, undamped) */
void umbrella_set_law(Ctx *x, ElasticLaw *law) {
    x->law = law;
    x->q0_products = 0;   /* kq0: K q0, or Kb q0 with a law */
    x->fiter.h = -1.0;    /* its band is the law's from now on */
}

double umbrella_dissipated(const Ctx *x) {
    return x->dissipated;
}

/* the momentum of a state: M(q) v */
void umbrella_momentum(Ctx *x, const double *q, const double *v, double *p) {
    mass_data(x, q);
    mass_matvec(x, v, p);
}

/* ------------------------------------------------------------------- outputs */
/* The fibre stress of the nonlinear law at q, top of every stress point then bottom (the
 * co-rotational beam's E (eps -/+ c kappa) in each element's rotated frame), or NULL for the
 * linear strain, whose fibre stress is the Model's linear rows. */
static const double *membrane_stress(const Ctx *x, const double *q) {
    if (!(x->law && x->law->d.nonlinear)) return NULL;
    elastic_fibre_stress(x->law, q);
    return x->law->el_stress;
}

/* Top and bottom fibre stress at stress point k: the law's (law_sig, membrane_stress), or the
 * section's linear rows. */
static void fibre_stress(const Model *m, const double *q, const double *law_sig, int k,
                         double *top, double *bot) {
    if (law_sig) {
        *top = law_sig[k];
        *bot = law_sig[m->n_stress_leaf + m->n_stress_link + k];
        return;
    }
    int W = m->stress_width;
    double t = 0.0, b = 0.0;
    for (int j = 0; j < W; j++) {
        double qj = q[m->stress_idx[k * W + j]];
        t += m->stress_top[k * W + j] * qj;
        b += m->stress_bottom[k * W + j] * qj;
    }
    *top = t;
    *bot = b;
}

/* Fibre stress at every stress point of (q, v) (top of each point, then bottom: sig[k],
 * sig[npts + k]) and its rate (rate, same order): the nonlinear law's, or the linear rows of
 * q and of v */
static void fibre_stress_and_rate(Ctx *x, const double *q, const double *v, double *sig,
                                  double *rate) {
    const Model *m = x->m;
    int npts = m->n_stress_leaf + m->n_stress_link;
    const double *law_sig = membrane_stress(x, q);
    if (law_sig) {
        elastic_fibre_stress_rate(x->law, q, v);
        memcpy(sig, law_sig, sizeof(double) * 2 * npts);
        memcpy(rate, x->law->el_stress_rate, sizeof(double) * 2 * npts);
        return;
    }
    int W = m->stress_width;
    for (int k = 0; k < npts; k++) {   /* the linear rows of q and of v in one pass */
        const int *idx = m->stress_idx + (size_t)k * W;
        const double *st = m->stress_top + (size_t)k * W, *sb = m->stress_bottom + (size_t)k * W;
        double t = 0.0, b = 0.0, rt = 0.0, rb = 0.0;
        for (int j = 0; j < W; j++) {
            double qj = q[idx[j]], vj = v[idx[j]];
            t += st[j] * qj;
            b += sb[j] * qj;
            rt += st[j] * vj;
            rb += sb[j] * vj;
        }
        sig[k] = t; sig[npts + k] = b;
        rate[k] = rt; rate[npts + k] = rb;
    }
}

/* The largest |p| on [0, 1] of a fibre's stress cubic over a step (hermite_crest from the
 * larger |end value|: outputs.hermite_peak, the same arithmetic) */
static double hermite_peak(double s0, double d0, double s1, double d1) {
    return hermite_crest(s0, d0, s1, d1, fabs(s0) > fabs(s1) ? fabs(s0) : fabs(s1));
}

/* A state's own peak stress of each body (leaf, its x, link, its x into peaks): the largest
 * max(|top|, |bottom|) over its stress points, the first point holding it (np.argmax);
 * sig: the fibre stresses, top of every point then bottom */
static void state_peaks(const Model *m, const double *sig, double *peaks) {
    int first = 0, npts = m->n_stress_leaf + m->n_stress_link;
    for (int body = 0; body < 2; body++) {
        int np = body == 0 ? m->n_stress_leaf : m->n_stress_link, at = first;
        double best = -1.0;
        for (int k = first; k < first + np; k++) {
            double top = fabs(sig[k]), bot = fabs(sig[npts + k]), a = top > bot ? top : bot;
            if (a > best) { best = a; at = k; }
        }
        peaks[2 * body] = best;
        peaks[2 * body + 1] = m->stress_x[at];
        first += np;
    }
}

/* The output row of the state (q, v, p = M v, lam) into column k of out; kq_known: K q at q
 * (Kb q with a law) if the caller has it, else NULL; acc = {work, lock loss, damping
 * dissipation}; accel: alpha1'' = (v1 - v0) / h of the step that ended here (0 for a state
 * alone); residual: the state's max(|Phi|, |J v|).  The peak stress: with h_step > 0, the
 * largest over the step of length h_step that ended at this state, whose start left its fibre
 * stress and rate in pk_sig, pk_rate (this state's then replace them); with h_step = 0, the
 * state's own, its fibre stresses left in pk_sig1 (top of every point, then bottom).  The
 * reference stresses (model.reference_stresses): the leaf's top fibre at O'', the link's
 * interpolated at l3/2; the sleeve's reaction (solver's sleeve_reaction): axle lam[2], stop
 * lam[3] once locked. */
static void output_row(Ctx *x, const double *q, const double *v, const double *p,
                       const double *lam, const double *kq_known, double t, int stage,
                       double force, const double *acc, double accel, double residual,
                       double h_step, double *out, int cap, int k) {
    const Model *m = x->m;
    int n = m->n, ia = m->i_alpha2;
    double *o = out + k, c2, s2;
    cos_sin(x, q[ia], &c2, &s2);
#define SET(f, val) o[(size_t)(f) * cap] = (val)
    SET(F_TIME, t);
    SET(F_STAGE, (double)stage);
    SET(F_ALPHA1, q[0]);
    SET(F_ALPHA1_RATE, v[0]);
    SET(F_SLEEVE_POS, sleeve_height(x, q));
    SET(F_SLEEVE_VEL, v[m->i_r2y] + (m->l3 + q[m->i_u_sleeve]) * c2 * v[ia]
                      + s2 * v[m->i_u_sleeve]);
    SET(F_FORCE, force);
    SET(F_TIP_AXIAL, q[m->i_tip_u]);
    SET(F_TIP_TRANSVERSE, q[m->i_tip_v]);
    SET(F_ALPHA2, q[ia]);
    SET(F_ALPHA2_RATE, v[ia]);
    SET(F_ALPHA1_ACCEL, accel);
    SET(F_REACTION_X, lam[2]);
    SET(F_REACTION_Y, stage == 1 ? lam[3] : 0.0);
    SET(F_RESIDUAL, residual);
    SET(F_DISSIPATION, acc[2]);
    int first = 0, npts = m->n_stress_leaf + m->n_stress_link;
    double *sig = x->pk_sig1, *rate = x->pk_rate1;
    const double *sig0 = x->pk_sig, *rate0 = x->pk_rate;
    if (h_step > 0.0) fibre_stress_and_rate(x, q, v, sig, rate);
    else {
        const double *membrane = membrane_stress(x, q);
        for (int k2 = 0; k2 < npts; k2++) fibre_stress(m, q, membrane, k2, &sig[k2], &sig[npts + k2]);
        double peaks[4];
        state_peaks(m, sig, peaks);
        SET(F_PEAK_LEAF, peaks[0]);
        SET(F_PEAK_LEAF_X, peaks[1]);
        SET(F_PEAK_LINK, peaks[2]);
        SET(F_PEAK_LINK_X, peaks[3]);
    }
    {   /* the largest axial stress |top + bottom| / 2 of the state (outputs.axial_stress_of) */
        double axial = 0.0;
        for (int k2 = 0; k2 < npts; k2++) {
            double a = fabs(0.5 * (sig[k2] + sig[npts + k2]));
            if (a > axial) axial = a;
        }
        SET(F_AXIAL_STRESS, axial);
    }
    const double *link_top = sig + m->n_stress_leaf;    /* (this state's fibre stresses) */
    int j = m->ref_link_element;
    SET(F_STRESS_LEAF_JOINT, sig[m->ref_leaf_point]);
    SET(F_STRESS_LINK_MID, (1.0 - m->ref_link_frac) * link_top[2 * j]
                           + m->ref_link_frac * link_top[2 * j + 1]);
    for (int body = 0; h_step > 0.0 && body < 2; body++) {   /* the step's peak */
        int np = body == 0 ? m->n_stress_leaf : m->n_stress_link;
        double best = -1.0, floor = -1.0;
        int at = first;
        /* The largest |sigma| at the step's ends, floor, is at most the peak; a point whose
         * cubics stay below it cannot hold the peak, and the Hermite bound
         * |p| <= max(|s0|, |s1|) + 4/27 (|d0| + |d1|) (p's basis: h00 + h01 = 1, both >= 0,
         * |h10|, |h11| <= 4/27) leaves most points out before their root solves: the same
         * result as taking every point (the margin covers the round-off of the bound) */
        for (int k2 = first; k2 < first + np; k2++) {
            int kb = npts + k2;
            double e[4] = {fabs(sig0[k2]), fabs(sig[k2]), fabs(sig0[kb]), fabs(sig[kb])};
            for (int j = 0; j < 4; j++) if (e[j] > floor) floor = e[j];
        }
        for (int k2 = first; k2 < first + np; k2++) {
            int kb = npts + k2;
            double top = sig[k2], bot = sig[kb];
            double d0t = h_step * rate0[k2], d1t = h_step * rate[k2];
            double d0b = h_step * rate0[kb], d1b = h_step * rate[kb];
            double et = fabs(sig0[k2]) > fabs(top) ? fabs(sig0[k2]) : fabs(top);
            double eb = fabs(sig0[kb]) > fabs(bot) ? fabs(sig0[kb]) : fabs(bot);
            double ut = et + (4.0 / 27.0) * (fabs(d0t) + fabs(d1t));
            double ub = eb + (4.0 / 27.0) * (fabs(d0b) + fabs(d1b));
            if ((ut > ub ? ut : ub) * (1.0 + 1e-12) < floor) continue;
            double pt = ut * (1.0 + 1e-12) < floor ? et : hermite_peak(sig0[k2], d0t, top, d1t);
            double pb = ub * (1.0 + 1e-12) < floor ? eb : hermite_peak(sig0[kb], d0b, bot, d1b);
            double a = pt > pb ? pt : pb;
            if (a > best) { best = a; at = k2; }
        }
        SET(body == 0 ? F_PEAK_LEAF : F_PEAK_LINK, best);
        SET(body == 0 ? F_PEAK_LEAF_X : F_PEAK_LINK_X, m->stress_x[at]);
        first += np;
    }
    if (h_step > 0.0) {   /* this state starts the next step */
        x->pk_sig1 = x->pk_sig; x->pk_sig = sig;
        x->pk_rate1 = x->pk_rate; x->pk_rate = rate;
    }
    double ke = 0.0;
    for (int i = 0; i < n; i++) ke += v[i] * p[i];
    SET(F_KINETIC, 0.5 * ke);
    double se = 0.0;
    if (x->law) se = elastic_energy(x->law, q, kq_known);
    else {
        const double *kq = kq_known;       /* K q, or computed here */
        if (!kq) {
            band_matvec(m, m->k_band, q, x->kq, 0);
            kq = x->kq;
        }
        for (int p2 = 0; p2 < m->n_elastic; p2++) {
            int i = m->elastic_idx[p2];
            se += q[i] * kq[i];
        }
        se *= 0.5;
    }
    SET(F_STRAIN, se);
    SET(F_WORK, acc[0]);
    SET(F_LOCK_LOSS, acc[1]);
#undef SET
}

/* The Sample vector (S_*, then the fibre stresses) of a state from its output row
 * (row[f * stride], an output_row of the state) and its fibre stresses sig (pk_sig1's
 * layout): the row's figures, but the state's own peaks (state_peaks) */
static void sample_vector(const Model *m, const double *row, size_t stride, const double *sig,
                          double *out) {
    int npts = m->n_stress_leaf + m->n_stress_link;
#define ROW(f) row[(size_t)(f) * stride]
    out[S_ALPHA1] = ROW(F_ALPHA1);
    out[S_ALPHA2] = ROW(F_ALPHA2);
    out[S_ALPHA1_RATE] = ROW(F_ALPHA1_RATE);
    out[S_ALPHA2_RATE] = ROW(F_ALPHA2_RATE);
    out[S_SLEEVE_POS] = ROW(F_SLEEVE_POS);
    out[S_SLEEVE_VEL] = ROW(F_SLEEVE_VEL);
    out[S_TIP_AXIAL] = ROW(F_TIP_AXIAL);
    out[S_TIP_TRANSVERSE] = ROW(F_TIP_TRANSVERSE);
    state_peaks(m, sig, out + S_PEAK_LEAF);    /* leaf, its x, link, its x */
    out[S_STRESS_LEAF_JOINT] = ROW(F_STRESS_LEAF_JOINT);
    out[S_STRESS_LINK_MID] = ROW(F_STRESS_LINK_MID);
    out[S_REACTION_X] = ROW(F_REACTION_X);
    out[S_REACTION_Y] = ROW(F_REACTION_Y);
    out[S_KINETIC] = ROW(F_KINETIC);
    out[S_STRAIN] = ROW(F_STRAIN);
    out[S_RESIDUAL] = ROW(F_RESIDUAL);
#undef ROW
    memcpy(out + N_SAMPLE, sig, sizeof(double) * 2 * npts);
}

/* Whether advance() takes the step just made (x->q_s, v_s): OK, or why not (the
 * state became non-finite, the constraint residual diverged, the sleeve reached the stop:
 * CROSSING, the caller's lock step).  *residual: the new state's constraint residual. */
static int step_taken(Ctx *x, int locked, int rigid, int nc, double div_tol,
                      double *residual) {
    const Model *m = x->m;
    const double *q1 = x->q_s, *v1 = x->v_s;
    /* (the jacobian rows of q1 are in jrow_*) */
    double r = *residual = state_residual(x, q1, v1, locked, rigid, nc, x->jrow_idx,
                                          x->jrow_val);
    for (int i = 0; i < m->n; i++) if (!isfinite(q1[i]) || !isfinite(v1[i])) return NON_FINITE;
    if (!(r <= div_tol)) return DIVERGED;
    /* the leaf at the axle, folding back past its start (integrators.ALPHA1_AXLE) */
    if (!locked && q1[0] >= 1.57079632679489661923) return AXLE;
    if (!locked && sleeve_height(x, q1) - m->y_stop <= 0.0) return CROSSING;
    return OK;
}

/* The state's row of AdvanceCall.states (column k, field-major): q, v, then its fibre
 * stresses (top of every stress point, then bottom; leaf points first) */
static void state_row(const Ctx *x, const double *q, const double *v, double *states, int cap,
                      int k) {
    const Model *m = x->m;
    int n = m->n, nsig = 2 * (m->n_stress_leaf + m->n_stress_link);
    double *col = states + k;
    for (int i = 0; i < n; i++) col[(size_t)i * cap] = q[i];
    col += (size_t)n * cap;
    for (int i = 0; i < n; i++) col[(size_t)i * cap] = v[i];
    col += (size_t)n * cap;
    for (int i = 0; i < nsig; i++) col[(size_t)i * cap] = x->pk_sig[i];
}

/* Up to n_steps grid steps t_k -> t_{k+1} = (k + 1) h from the state (q, v, lam, p) at t_k0
 * (AdvanceCall, _kernel.h), updated in place after every committed step, with one output row
 * per step (out: N_FIELDS x cap, field-major), its state row if states, and accel =
 * (v1 - v0) / h of the last one.  Stops early:
 *   CROSSING  in stage 1 the sleeve reached the stop during the next step (not committed:
 *             the caller finds the crossing time and applies the lock);
 *   DIVERGED  max(|Phi|, |J v|) above div_tol after a step (not committed, residual: its
 *             value; otherwise that of the last state checked);
 *   others    the step failed (not committed).
 * n_done = committed steps; final: the Sample vector of the state reached, from its last
 * step's row and fibre stresses (left in pk_sig). */
int umbrella_advance_call(Ctx *x, AdvanceCall *a) {
    const Model *m = x->m;
    int locked = a->locked, rigid = a->rigid, cap = a->cap;
    int n = m->n, nc = nc_of(m, locked, rigid);
    int status = OK, its_total = 0;
    double *q = a->q, *v = a->v, *lam = a->lam, *p = a->p, *acc = a->acc, *accel = a->accel;
    double h = a->h, force = a->force;
    long k0 = a->k0;
    a->n_done = 0;
    x->q0_products = 0;
    fibre_stress_and_rate(x, q, v, x->pk_sig, x->pk_rate);   /* the first step's start */
    for (int k = 0; k < a->n_steps && k < cap; k++) {
        double t0 = (double)(k0 + k) * h, t1 = (double)(k0 + k + 1) * h;
        int its = 0, kept = x->it_kept, kept_slot = x->it_slot;
        status = step(x, locked, rigid, q, v, lam, p, t1 - t0, force, a->tol, a->phi_tol,
                      a->max_iter, 1, &its);
        its_total += its;
        if (status == OK) status = step_taken(x, locked, rigid, nc, a->div_tol, &a->residual);
        if (status != OK) {   /* not taken: the caller retakes it (umbrella_step) as it was */
            x->it_kept = kept;
            x->it_slot = kept_slot;
            break;
        }
        carry_commit(x, nc, t1 - t0);
        const double *q1 = x->q_s, *v1 = x->v_s;
        acc[0] += force * (sleeve_height(x, q) - sleeve_height(x, q1));
        if (x->law) acc[2] += x->dissipated;
        double inv_dt = 1.0 / (t1 - t0);
        for (int i = 0; i < n; i++) accel[i] = (v1[i] - v[i]) * inv_dt;
        memcpy(q, q1, sizeof(double) * n);
        memcpy(v, v1, sizeof(double) * n);
        memcpy(lam, x->lam_s, sizeof(double) * nc);
        memcpy(p, x->p_s, sizeof(double) * n);
        /* q1's products are the next step's q0 products */
        memcpy(x->mq0, x->mq1, sizeof(double) * n);
        memcpy(x->wq0, x->wq1, sizeof(double) * n);
        memcpy(x->kq0, x->kq1, sizeof(double) * n);
        output_row(x, q, v, p, lam, x->kq0, t1, locked ? 1 : 0, force, acc, accel[0],
                   a->residual, t1 - t0, a->out, cap, k);   /* (step_taken's residual) */
        if (a->states) state_row(x, q, v, a->states, cap, k);
        a->n_done = k + 1;
    }
    a->iterations = its_total;
    if (a->final && a->n_done > 0)
        sample_vector(m, a->out + a->n_done - 1, (size_t)cap, x->pk_sig, a->final);
    return status;
}

/* Lock instant inside a step (solver.UmbrellaSimulator._find_lock, the same Illinois
 * iteration): y_H(t0 + dt) = y_stop on the integrator's own trajectory, stage deploying, from
 * (q0, v0, lam0, p0) with the step length dt in (0, h], until the bracket is below event_tol
 * or y_H hits the stop exactly.  Every trial step is checked like a committed one (finite,
 * max(|Phi|, |J v|) <= div_tol).  On OK: the best trial (least |y_H - y_stop|) in q, v, lam,
 * p (nc rows of lam) and its step length in *dt_out.  On DIVERGED or a step failure: *dt_out
 * is the failing trial's step length and *residual its residual (DIVERGED).  The caller
 * knows that a step of length h crosses (advance() returned CROSSING). */
int umbrella_find_crossing(Ctx *x, int rigid, const double *q0, const double *v0,
                           const double *lam0, const double *p0, double h, double force,
                           double tol, double phi_tol, int max_iter, double div_tol,
                           double event_tol, double *q, double *v, double *lam, double *p,
                           double *dt_out, double *residual, int *iterations) {
    const Model *m = x->m;
    int n = m->n, nc = nc_of(m, 0, rigid), its_total = 0;
    double a = 0.0, fa = sleeve_height(x, q0) - m->y_stop, b = h, fb = 0.0;
    double best_dt = h, f_best = INFINITY;
    int have_best = 0, side = 0;
    x->q0_products = 0;        /* then every trial step starts from these q0 products */
    *residual = 0.0;
    for (int trial = 0; trial < 201; trial++) {
        double dt;
        if (trial == 0) dt = b;
        else {
            if (b - a < event_tol || f_best == 0.0) break;
            dt = b - fb * (b - a) / (fb - fa);
            if (!(a < dt && dt < b)) dt = 0.5 * (a + b);
        }
        int its = 0;
        int status = step(x, 0, rigid, q0, v0, lam0, p0, dt, force, tol, phi_tol, max_iter, 0,
                          &its);
        its_total += its;
        *dt_out = dt;
        if (status != OK) { *iterations = its_total; return status; }
        const double *q1 = x->q_s, *v1 = x->v_s;
        for (int i = 0; i < n; i++)
            if (!isfinite(q1[i]) || !isfinite(v1[i])) { *iterations = its_total; return NON_FINITE; }
        double r = state_residual(x, q1, v1, 0, rigid, nc, x->jrow_idx, x->jrow_val);
        if (!(r <= div_tol)) { *residual = r; *iterations = its_total; return DIVERGED; }
        double f = sleeve_height(x, q1) - m->y_stop;
        if (!have_best || fabs(f) < fabs(f_best)) {
            have_best = 1;
            f_best = f;
            best_dt = dt;
            memcpy(q, q1, sizeof(double) * n);
            memcpy(v, v1, sizeof(double) * n);
            memcpy(lam, x->lam_s, sizeof(double) * nc);
            memcpy(p, x->p_s, sizeof(double) * n);
        }
        if (trial == 0) { fb = f; continue; }
        if (f > 0.0) {
            a = dt; fa = f;
            if (side == -1) fb *= 0.5;
            side = -1;
        } else {
            b = dt; fb = f;
            if (side == 1) fa *= 0.5;
            side = 1;
        }
    }
    *dt_out = best_dt;
    *iterations = its_total;
    return OK;
}

/* The Sample vector (sample_vector: S_* then the fibre stresses) of an arbitrary state
 * (q, v, p = M(q) v, lam) into out[N_SAMPLE + 2 points] */
static void sample(Ctx *x, int locked, int rigid, const double *q, const double *v,
                   const double *p, const double *lam, double *out) {
    const Model *m = x->m;
    int nc = nc_of(m, locked, rigid);
    double row[N_FIELDS], acc[3] = {0.0, 0.0, 0.0};
    jacobian(x, q, locked, rigid, x->jm_idx, x->jm_val);
    double r = state_residual(x, q, v, locked, rigid, nc, x->jm_idx, x->jm_val);
    output_row(x, q, v, p, lam, NULL, 0.0, locked ? 1 : 0, 0.0, acc, 0.0, r, 0.0, row, 1, 0);
    sample_vector(m, row, 1, x->pk_sig1, out);   /* output_row's fibre stresses */
}

/* (SampleCall, _kernel.h) */
void umbrella_sample_call(Ctx *x, SampleCall *a) {
    sample(x, a->locked, a->rigid, a->q, a->v, a->p, a->lam, a->out);
}

/* ------------------------------------------------------------------ interface */
#define UMBRELLA_SIZEOF(name, py) (int)sizeof(name),
#define UMBRELLA_COUNT(name, py) name,

int umbrella_abi(int *figures, int n) {
    const int all[] = {UMBRELLA_ABI_STRUCTS(UMBRELLA_SIZEOF) UMBRELLA_ABI_COUNTS(UMBRELLA_COUNT)};
    for (int k = 0; k < n && k < (int)(sizeof(all) / sizeof(all[0])); k++) figures[k] = all[k];
    return UMBRELLA_ABI_VERSION;
}
