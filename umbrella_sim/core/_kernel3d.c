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
 * The compiled step of the whole umbrella in 3D, hub fixed: umbrella3d/integrator3d.py's
 * MidpointUmbrella step (the numpy reference, which documents the scheme) operation for
 * operation, rib by rib, and the simulator's grid loop around it (umbrella3d/simulator3d.py:
 * the stop's crossing ends a run of steps, the lock itself stays in Python; a stuck hinge's
 * release).
 *
 * Layout: every per-rib array is rib-major (rib r's block contiguous); a body (leaf, link)
 * of a rib has t translations (0, 3), its angle, its elastic coordinates, at an offset in
 * the rib's coordinates; its points' kinematics (umbrella3d/model3d.py _BodyStack.kin) are
 * rho = R(alpha) (x + S e) [+ R2], Jacobian [I3 | e_z x R y | R S].  M(q), M v, the
 * kinetic gradient and a fresh iteration matrix's gyroscopic term come from each body's
 * inertia invariants (Body.inv, summed over the points once at the context): rotation
 * combinations of constants, no point loop.  M v and K q
 * run over the rib's nonzeros (Rows: K and the elastic mass blocks are banded).  The linear
 * algebra is block-arrow (umbrella3d/arrow.py): each rib's (n + 9) block factored alone, the shared
 * unknowns (sleeve, stop multiplier) through their Schur complement: cost linear in the ribs.
 * A body's block (the projection's M, the iteration matrix M + h^2/4 K + h/2 G) is factored
 * elastic coordinates first from its elastic block's LU, which no motion changes (of M once,
 * of the iteration matrix once a step length), and solved over that LU's nonzeros (ef_solve);
 * the joint Jacobian's products run over its nonzeros (jrows).  Pivoting, summation order and
 * so round-off differ from the numpy reference's dense algebra; so does, with the hub fixed,
 * the mode fit's map of each iterate's velocity, from tracked modal coordinates (fit_start).
 * The iteration matrix is kept across steps (kept_serves: the numpy reference's rule).
 * Model flexible-nonlinear (the co-rotational ribs): _kernel3d_nonlinear.h, whose hooks
 * here act under Model3D.nl_elements only.
 */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "_kernel.h"
#include "_kernel_dense.h"
#include "_kernel_crest.h"    /* a step's stress crest (outputs.hermite_peak) */

#define ROWS 9         /* joint rows of a rib (model3d.N_RIB_ROWS) */
#define ROW_STICK 8    /* the stuck hinge's row */
#define MAXS 16        /* shared unknowns at most (coordinates + rows) */
/* the iteration matrix kept across steps (modified Newton; integrator3d.MidpointUmbrella):
 * it serves at most Model3D.carry_steps steps, and is factored anew at the iterate after an
 * iteration that contracted the update by less than REFRESH_RATE */
#define REFRESH_RATE 0.1
/* a kept projection's passes at most, and the correction of v (relative to its largest
 * component) that ends them (integrator3d.PROJECTION_PASSES, PROJECTION_TOLERANCE) */
#define PROJECTION_PASSES 4
#define PROJECTION_TOLERANCE 1e-12
/* the Newton tolerance from which stage 2 keeps its projection (PROJECTION_KEPT_FROM) */
#define PROJECTION_KEPT_FROM 1e-10
/* Gonzalez's discrepancies within this many ulps of their terms' scale are their round-off:
 * no correction (integrator3d.GONZALEZ_NOISE, gonzalez_discrepancy, says why) */
#define GONZALEZ_NOISE 32.0

/* Gonzalez's discrepancy, 0 where it is within GONZALEZ_NOISE ulps of scale (the sum of the
 * magnitudes of its terms) */
static double gonzalez_discrepancy(double discrepancy, double scale) {
    return fabs(discrepancy) > GONZALEZ_NOISE * DBL_EPSILON * scale ? discrepancy : 0.0;
}

/* the nonzeros of a matrix, row by row (columns ascending): rows_of, sparse_of */
typedef struct { int *ptr, *col; } Rows;

typedef struct {
    int t, nb, ne, np, off;            /* translations, coordinates, elastic, points, offset */
    const double *x, *w, *shape;       /* R x P x 3, R x P, R x P x 3 x ne */
    double *inv;                       /* R x INV_LEN(ne): the inertia invariants (invariants) */
    Rows c_rows, d_rows, d_cols;       /* the nonzeros of C, D, D^T (every rib's) */
    double *elu;                       /* R x ne x ne: the LU of M's elastic block (constant;
                                        * no pivoting: it is positive definite), elastic_lu */
    double *elu_it, elu_h;             /* the same of the iteration matrix's elastic block,
                                        * M + h^2/4 K (constant for a step length: elu_h) */
    Rows lpat[2], upat[2];             /* the nonzeros of elu's, elu_it's rows: L (columns
                                        * below the diagonal), U (above) (elastic_rows) */
    Rows lcol[2];                      /* lpat's by column: the rows below the diagonal */
} Body;

/* The inertia invariants of a body (the floating frame's: Shabana's S-bar, I-bar), per rib,
 * sums over its points p (weights w, y = x + S e, in-plane rows 0, 1): the mass m = sum w,
 * c = sum w x, Sb = sum w S (3 x ne), I0 = sum w (x0^2 + x1^2), g = sum w (x0 S0 + x1 S1),
 * h = sum w (x0 S1 - x1 S0), C = sum w (S0^T S0 + S1^T S1), D[c][a] = sum w (S0c S1a - S1c
 * S0a) (ne x ne).  With them M(q)'s frame rows are rotation combinations of constants:
 * M_uu = m I, M_ua = e_z x R (c + Sb e), M_ue = R Sb, M_aa = I0 + 2 g.e + e^T C e,
 * M_ae = h + D^T e, and so are their gradients (kinetic_gradient); the sums the quadrature
 * loops did, rearranged. */
#define INV_LEN(ne) (5 + 5 * (ne) + 2 * (ne) * (ne))
enum { INV_M = 0, INV_C = 1, INV_I0 = 4, INV_SB = 5 };
#define INV_G(ne) (5 + 3 * (ne))
#define INV_H(ne) (5 + 4 * (ne))
#define INV_CC(ne) (5 + 5 * (ne))
#define INV_D(ne) (5 + 5 * (ne) + (ne) * (ne))

/* A factored arrow matrix: a rib's block [[A, sign Jc^T], [Jr, Z]] factored through its
 * bodies: A is block diagonal (leaf, link), each LU'd; W = A^-1 sign Jc^T; T = Z - Jr W,
 * LU'd; Y = B^-1 C; S the LU of the shared unknowns' Schur complement. */
typedef struct {
    double *Af, *W, *T, *Jf, *Y;       /* R x (nb0^2 + nb1^2), R x n x 9, R x 81, R x 9 x n,
                                        * R x mb x s */
    double *Wt;                        /* W's ribs transposed (R x 9 x n: rib_solve's) */
    int *apiv, *tpiv;                  /* R x n, R x 9 */
    double S[MAXS * MAXS];
    int spiv[MAXS];
    int uses;                          /* steps it served (iteration slots) */
    int elastic_first;                 /* the bodies' blocks factored elastic coordinates
                                        * first, from Body.elu (1: the projection's M) or
                                        * Body.elu_it (2: the iteration matrix) */
} Fact;

/* a moving base's context (_kernel3d_base.h) */
typedef struct Base3D Base3D;
/* the steps' stress figures (_kernel3d_figures.h) */
typedef struct Figures3D Figures3D;
/* the co-rotational ribs' element strains of the latest configurations (_kernel3d_nonlinear.h) */
typedef struct NlStarts NlStarts;

struct Ctx3D {
    const Model3D *m;
    Rows mrows, krows;                 /* of M(q) (frame rows, columns: all) and K */
    Rows jrows;                        /* of a rib's joint Jacobian (ROWS x n; jacobian_rows) */
    Body b[2];
    int R, n, ns, cs, s, mb;
    double *mass;                      /* R x n x n: M(q1) */
    /* the iteration matrix's two slots (a step factors into the one not kept, so a step not
     * committed leaves the kept one intact), the projection factored at the end of the step
     * that factored each (kept_pm: the hub fixed; project), and a projection's scratch */
    Fact slot[2], kept_pm[2], pm;
    int kept_pm_ok[2];                 /* kept_pm[k] is of the step that factored slot k */
    double E[MAXS * MAXS];
    /* the kept iteration matrix: its slot, and the end of the committed step that used it
     * (q, v, length, lock, the stuck hinges); a step that starts there takes it */
    int kept, kept_slot, kept_locked, pend_slot, pend_uses;
    double kept_h, pend_h, *kept_q, *kept_v;
    unsigned char *kept_stuck;
    double *jm, *jr;                   /* R x 9 x n: J(q_m), J(q) */
    double *q0, *v0, *p0, *l0, *q, *v, *lam, *p, *dq, *qm, *v1, *p1, *gt, *res, *tmp;
    double *phi0, *phi, *rr, *x, *gyro, *ycol, *fric;
    double *v_in;                      /* the velocity a kept projection started from */
    double *mw0, *mdq;                 /* the hub fixed: the modal coordinates U^T w0, U^T dq
                                        * (R x n: a rib's r; fit_start, fit_newton) */
    double *w0, *sp1, *fitc;           /* the mode fit's: w0 = S^-1 v0, S^T (M(q1) v1 - p0);
                                        * modal sums, then a rib's (n + n: a rib has n
                                        * modes at most) */
    double work_force, *work_fric, strain;   /* the last step's works, V(q1) */
    double *damp, work_damp;           /* the beams' damping force C dq / h (N + ns) and the
                                        * last step's dissipation (_kernel3d_damping.h) */
    double strain0;                    /* V(q0) when strain0_ok: a run's step after the first
                                        * starts where the last one committed (V(q1)) */
    int strain0_ok;
    int iterations, factorisations;
    Base3D *base;                      /* a moving base's (n_shared 7), else NULL */
    Figures3D *fig;                    /* the rows' stress figures (umbrella3d_set_stress),
                                        * else NULL */
    NlStarts *nl;                      /* the co-rotational ribs' (nl_elements), else NULL */
};

static Base3D *base_new(Ctx3D *x);
static void base_free(Base3D *B);
static double stiffness_weight(const Model3D *m, double h);      /* _kernel3d_damping.h */
static void figures_free(Figures3D *f);

#include "_kernel3d_nonlinear.h"   /* the co-rotational ribs (hooks: nl_elements) */

/* ------------------------------------------------------------------ context */
static void body_of(Body *b, int t, int ne, int np, int off, const double *x, const double *w,
                    const double *shape) {
    b->t = t; b->ne = ne; b->nb = t + 1 + ne; b->np = np; b->off = off;
    b->x = x; b->w = w; b->shape = shape;
    b->inv = NULL;
}

/* the nonzeros of every rib's ne x ne matrix at A + r L (transposed: of A^T) */
static int sparse_of(int R, int ne, const double *A, int L, int transposed, Rows *p) {
    int k = 0;
    p->ptr = malloc(sizeof(int) * (ne + 1));
    p->col = malloc(sizeof(int) * (ne * ne > 0 ? ne * ne : 1));
    if (!p->ptr || !p->col) return 0;
    for (int a = 0; a < ne; a++) {
        p->ptr[a] = k;
        for (int c = 0; c < ne; c++) {
            int keep = 0;
            for (int r = 0; r < R && !keep; r++)
                keep = A[(size_t)r * L + (transposed ? c * ne + a : a * ne + c)] != 0.0;
            if (keep) p->col[k++] = c;
        }
    }
    p->ptr[ne] = k;
    return 1;
}

static void rows_free(Rows *p) { free(p->ptr); free(p->col); }

static int invariants(Body *b, int R) {
    int ne = b->ne, P = b->np, L = INV_LEN(ne);
    b->inv = calloc((size_t)R * L, sizeof(double));
    if (!b->inv) return 0;
    for (int r = 0; r < R; r++) {
        double *v = b->inv + (size_t)r * L;
        for (int pt = 0; pt < P; pt++) {
            int rp = r * P + pt;
            double w = b->w[rp];
            const double *xp = b->x + rp * 3, *S = b->shape + (size_t)rp * 3 * ne;
            const double *S0 = S, *S1 = S + ne;
            v[INV_M] += w;
            for (int i = 0; i < 3; i++) v[INV_C + i] += w * xp[i];
            v[INV_I0] += w * (xp[0] * xp[0] + xp[1] * xp[1]);
            for (int i = 0; i < 3 * ne; i++) v[INV_SB + i] += w * S[i];
            for (int a = 0; a < ne; a++) {
                v[INV_G(ne) + a] += w * (xp[0] * S0[a] + xp[1] * S1[a]);
                v[INV_H(ne) + a] += w * (xp[0] * S1[a] - xp[1] * S0[a]);
                for (int c = 0; c < ne; c++) {
                    v[INV_CC(ne) + a * ne + c] += w * (S0[a] * S0[c] + S1[a] * S1[c]);
                    v[INV_D(ne) + c * ne + a] += w * (S0[c] * S1[a] - S1[c] * S0[a]);
                }
            }
        }
    }
    return sparse_of(R, ne, b->inv + INV_CC(ne), L, 0, &b->c_rows)
        && sparse_of(R, ne, b->inv + INV_D(ne), L, 0, &b->d_rows)
        && sparse_of(R, ne, b->inv + INV_D(ne), L, 1, &b->d_cols);
}

static void fact_free(Fact *f) {
    free(f->Af); free(f->W); free(f->Wt); free(f->T); free(f->Jf); free(f->Y);
    free(f->apiv); free(f->tpiv);
}

static int fact_alloc(Fact *f, const Ctx3D *x) {
    int R = x->R, n = x->n, nb0 = x->b[0].nb, nb1 = x->b[1].nb;
    f->Af = calloc((size_t)R * (nb0 * nb0 + nb1 * nb1), sizeof(double));
    f->W = calloc((size_t)R * n * ROWS, sizeof(double));
    f->Wt = calloc((size_t)R * n * ROWS, sizeof(double));
    f->T = calloc((size_t)R * ROWS * ROWS, sizeof(double));
    f->Jf = calloc((size_t)R * ROWS * n, sizeof(double));
    f->Y = calloc((size_t)R * x->mb * x->s, sizeof(double));
    f->apiv = calloc((size_t)R * n, sizeof(int));
    f->tpiv = calloc((size_t)R * ROWS, sizeof(int));
    return f->Af && f->W && f->Wt && f->T && f->Jf && f->Y && f->apiv && f->tpiv;
}

void umbrella3d_free(Ctx3D *x) {
    if (!x) return;
    base_free(x->base);
    figures_free(x->fig);
    nl_starts_free(x->nl);
    for (int j = 0; j < 2; j++) {
        free(x->b[j].inv);
        free(x->b[j].elu); free(x->b[j].elu_it);
        for (int k = 0; k < 2; k++) {
            rows_free(&x->b[j].lpat[k]); rows_free(&x->b[j].upat[k]); rows_free(&x->b[j].lcol[k]);
        }
        rows_free(&x->b[j].c_rows); rows_free(&x->b[j].d_rows); rows_free(&x->b[j].d_cols);
    }
    fact_free(&x->slot[0]); fact_free(&x->slot[1]); fact_free(&x->pm);
    fact_free(&x->kept_pm[0]); fact_free(&x->kept_pm[1]);
    rows_free(&x->mrows); rows_free(&x->krows); rows_free(&x->jrows);
    free(x->kept_q); free(x->kept_v); free(x->kept_stuck);
    double *bufs[] = {x->mass, x->jm, x->jr,
                      x->q0, x->v0, x->p0, x->l0, x->q, x->v, x->lam, x->p, x->dq, x->qm,
                      x->v1, x->p1, x->gt, x->res, x->tmp, x->phi0, x->phi, x->rr, x->x,
                      x->gyro, x->ycol, x->fric, x->work_fric, x->w0, x->sp1, x->fitc, x->mw0,
                      x->mdq, x->damp, x->v_in};
    for (size_t k = 0; k < sizeof(bufs) / sizeof(bufs[0]); k++) free(bufs[k]);
    free(x);
}

static int rows_of(const Ctx3D *x, const double *A, int frame, Rows *p);
static int jacobian_rows(Ctx3D *x);

/* the nonzeros of the rows of every rib's elastic LU E (R x ne x ne), their union: lo the
 * columns left of the diagonal (L), up those right of it (U); the storage is the context's */
static void elastic_rows(const Body *b, const double *E, int R, Rows *lo, Rows *up) {
    int ne = b->ne, kl = 0, ku = 0;
    for (int a = 0; a < ne; a++) {
        lo->ptr[a] = kl;
        up->ptr[a] = ku;
        for (int c = 0; c < ne; c++) {
            int keep = 0;
            for (int r = 0; r < R && !keep; r++) keep = E[(size_t)r * ne * ne + a * ne + c] != 0.0;
            if (keep && c < a) lo->col[kl++] = c;
            if (keep && c > a) up->col[ku++] = c;
        }
    }
    lo->ptr[ne] = kl;
    up->ptr[ne] = ku;
}

static int rows_alloc(Rows *p, int ne) {
    p->ptr = malloc(sizeof(int) * (ne + 1));
    p->col = malloc(sizeof(int) * (ne * ne > 0 ? ne * ne : 1));
    return p->ptr && p->col;
}

/* lo's nonzeros column by column (rows ascending): cols */
static int columns_of(const Rows *lo, int ne, Rows *cols) {
    if (!rows_alloc(cols, ne)) return 0;
    int k = 0;
    for (int c = 0; c < ne; c++) {
        cols->ptr[c] = k;
        for (int a = c + 1; a < ne; a++)
            for (int i = lo->ptr[a]; i < lo->ptr[a + 1]; i++)
                if (lo->col[i] == c) cols->col[k++] = a;
    }
    cols->ptr[ne] = k;
    return 1;
}

/* the nonzeros an LU without pivoting of any M0 + c K can have (the elastic blocks' union
 * over the ribs, filled in by the elimination), as elastic_rows: Body.elu_it's, whatever the
 * step length it was made at (a kept iteration matrix may outlive a later length's LU) */
static int elastic_pattern(const Body *b, const double *M0, const double *K, int R, int n,
                           Rows *lo, Rows *up) {
    int ne = b->ne, o = b->off + b->t + 1;
    double *B = calloc((size_t)ne * ne > 0 ? (size_t)ne * ne : 1, sizeof(double));
    if (!B) return 0;
    for (int r = 0; r < R; r++)
        for (int a = 0; a < ne; a++)
            for (int c = 0; c < ne; c++) {
                size_t at = (size_t)r * n * n + (o + a) * n + o + c;
                if (M0[at] != 0.0 || K[at] != 0.0) B[a * ne + c] = 1.0;
            }
    for (int k = 0; k < ne; k++)
        for (int i = k + 1; i < ne; i++)
            if (B[i * ne + k] != 0.0)
                for (int j = k + 1; j < ne; j++)
                    if (B[k * ne + j] != 0.0) B[i * ne + j] = 1.0;
    elastic_rows(b, B, 1, lo, up);
    free(B);
    return 1;
}

/* each rib's LU (lu_factor's packing, no pivoting: positive definite) of the body's elastic
 * block of M0 + c K into E (R x ne x ne), and its nonzeros (elastic_rows; lo NULL: not) */
static int elastic_lu_of(const Body *b, const double *M0, const double *K, double c, int R,
                         int n, double *out, Rows *lo, Rows *up) {
    int ne = b->ne, o = b->off + b->t + 1;
    for (int r = 0; r < R; r++) {
        double *E = out + (size_t)r * ne * ne;
        for (int a = 0; a < ne; a++)
            for (int k = 0; k < ne; k++) {
                size_t at = (size_t)r * n * n + (o + a) * n + o + k;
                E[a * ne + k] = M0[at] + (K ? c * K[at] + 0.0 : 0.0);
            }
        for (int k = 0; k < ne; k++) {
            if (!(E[k * ne + k] > 0.0)) return 0;
            double inv = 1.0 / E[k * ne + k];
            lu_eliminate(ne, E, k, k + 1, inv);
            E[k * ne + k] = inv;
        }
    }
    if (lo) elastic_rows(b, out, R, lo, up);
    return 1;
}

/* Body.elu: of M's elastic block, which no motion changes (mass_matrix); the storage of
 * Body.elu_it, made at a step's length (iteration_elastic) */
static int elastic_lu(Body *b, const double *M0, const double *K, int R, int n) {
    size_t size = (size_t)R * b->ne * b->ne > 0 ? (size_t)R * b->ne * b->ne : 1;
    b->elu = calloc(size, sizeof(double));
    b->elu_it = calloc(size, sizeof(double));
    b->elu_h = NAN;
    if (!b->elu || !b->elu_it) return 0;
    for (int k = 0; k < 2; k++)
        if (!rows_alloc(&b->lpat[k], b->ne) || !rows_alloc(&b->upat[k], b->ne)) return 0;
    return elastic_lu_of(b, M0, NULL, 0.0, R, n, b->elu, &b->lpat[0], &b->upat[0])
        && elastic_pattern(b, M0, K, R, n, &b->lpat[1], &b->upat[1])
        && columns_of(&b->lpat[0], b->ne, &b->lcol[0])
        && columns_of(&b->lpat[1], b->ne, &b->lcol[1]);
}

/* Body.elu_it at the step length h: the elastic block of the iteration matrix M + h^2/4 K
 * (+ h/2 the gyroscopic term, which leaves that block alone: gyroscopic) */
static int iteration_elastic(Ctx3D *x, double h) {
    for (int j = 0; j < 2; j++) {
        Body *b = &x->b[j];
        if (b->elu_h == h) continue;
        b->elu_h = NAN;
        if (!elastic_lu_of(b, x->m->const_mass, x->m->stiffness, stiffness_weight(x->m, h),
                           x->R, x->n,
                           b->elu_it, NULL, NULL))
            return SINGULAR;
        b->elu_h = h;
    }
    return OK;
}

/* y = A^-1 y (nrhs right-hand sides, row-major nb x nrhs) of factor_elastic_first's A and
 * piv: lu_solve's substitutions over the nonzeros, the elastic rows' of E's LU (lo, up),
 * the frame rows and columns dense */
static void ef_solve(const Body *b, const Rows *lo, const Rows *up, const double *A,
                     const int *piv, double *y, int nrhs) {
    int nb = b->nb, ne = b->ne;
    for (int k = ne; k < nb; k++)
        if (piv[k] != k)
            for (int c = 0; c < nrhs; c++) {
                double t = y[k * nrhs + c];
                y[k * nrhs + c] = y[piv[k] * nrhs + c];
                y[piv[k] * nrhs + c] = t;
            }
    for (int i = 0; i < nb; i++) {
        double *yi = y + i * nrhs;
        const double *Ai = A + i * nb;
        if (i < ne) {
            for (int k = lo->ptr[i]; k < lo->ptr[i + 1]; k++) {
                int j = lo->col[k];
                double f = Ai[j];
                for (int c = 0; c < nrhs; c++) yi[c] -= f * y[j * nrhs + c];
            }
        } else {
            for (int j = 0; j < i; j++) {
                double f = Ai[j];
                if (f != 0.0)
                    for (int c = 0; c < nrhs; c++) yi[c] -= f * y[j * nrhs + c];
            }
        }
    }
    for (int i = nb - 1; i >= 0; i--) {
        double *yi = y + i * nrhs;
        const double *Ai = A + i * nb;
        for (int j = nb - 1; j > i && j >= ne; j--) {
            double f = Ai[j];
            if (f != 0.0)
                for (int c = 0; c < nrhs; c++) yi[c] -= f * y[j * nrhs + c];
        }
        if (i < ne)
            for (int k = up->ptr[i + 1] - 1; k >= up->ptr[i]; k--) {
                int j = up->col[k];
                double f = Ai[j];
                for (int c = 0; c < nrhs; c++) yi[c] -= f * y[j * nrhs + c];
            }
        for (int c = 0; c < nrhs; c++) yi[c] *= Ai[i];
    }
}

/* body j's coordinate at place i of the elastic-first order (elastic, then frame) */
static int elastic_first(const Body *b, int i) { return i < b->ne ? b->t + 1 + i : i - b->ne; }

/* lu_factor of body j's block A (nb x nb, elastic-first order) whose elastic rows and columns
 * are a constant elastic block, its LU E (b->elu's or b->elu_it's rib r, kind 0 or 1: copied,
 * not recomputed): the frame rows eliminated through E, then the frame block's Schur
 * complement with pivoting.  lu_eliminate's operations over E's nonzeros (lcol, upat: an
 * entry left out would lose f * 0) */
static int factor_elastic_first(const Body *b, const double *elu, int kind, int r, double *A,
                                int *piv) {
    int nb = b->nb, ne = b->ne;
    const double *E = elu + (size_t)r * ne * ne;
    const Rows *lc = &b->lcol[kind], *up = &b->upat[kind];
    for (int a = 0; a < ne; a++) memcpy(A + a * nb, E + a * ne, sizeof(double) * ne);
    for (int k = 0; k < ne; k++) {
        piv[k] = k;
        double inv = A[k * nb + k];
        const double *Ak = A + k * nb;
        for (int l = lc->ptr[k]; l < lc->ptr[k + 1]; l++) {   /* E's rows: its factors, */
            double *Ai = A + lc->col[l] * nb;                    /* the frame columns */
            double f = Ai[k];
            if (f != 0.0)
                for (int j = ne; j < nb; j++) Ai[j] -= f * Ak[j];
        }
        for (int i = ne; i < nb; i++) {         /* the frame rows (lu_eliminate's) */
            double *Ai = A + i * nb;
            double f = Ai[k] * inv;
            Ai[k] = f;
            if (f == 0.0) continue;
            for (int l = up->ptr[k]; l < up->ptr[k + 1]; l++) Ai[up->col[l]] -= f * Ak[up->col[l]];
            for (int j = ne; j < nb; j++) Ai[j] -= f * Ak[j];
        }
    }
    return lu_factor_from(nb, ne, A, piv);
}

Ctx3D *umbrella3d_new(const Model3D *m) {
    if (m->n_shared + m->n_shared_rows > MAXS) return NULL;
    Ctx3D *x = calloc(1, sizeof(Ctx3D));
    if (!x) return NULL;
    x->m = m;
    int R = m->n_ribs, n = m->n_rib;
    x->R = R; x->n = n; x->ns = m->n_shared; x->cs = m->n_shared_rows;
    x->s = x->ns + x->cs; x->mb = n + ROWS;
    body_of(&x->b[0], 0, m->leaf_elastic, m->leaf_points, 0, m->leaf_x, m->leaf_w,
            m->leaf_shape);
    body_of(&x->b[1], 3, m->link_elastic, m->link_points, m->link_offset, m->link_x,
            m->link_w, m->link_shape);
    int ok = 1;
    for (int j = 0; j < 2; j++)
        ok &= invariants(&x->b[j], R);
    int mb = x->mb, N = R * n;
#define ALLOC(f, k) (x->f = calloc((size_t)(k), sizeof(double))) != NULL
    ok = ok && fact_alloc(&x->slot[0], x) && fact_alloc(&x->slot[1], x) && fact_alloc(&x->pm, x)
        && fact_alloc(&x->kept_pm[0], x) && fact_alloc(&x->kept_pm[1], x);
    ok = ok && ALLOC(mass, R * n * n) && ALLOC(jm, R * ROWS * n)
        && ALLOC(kept_q, N + MAXS) && ALLOC(kept_v, N + MAXS)
        && ALLOC(jr, R * ROWS * n) && ALLOC(q0, N + MAXS) && ALLOC(v0, N + MAXS)
        && ALLOC(p0, N + MAXS) && ALLOC(l0, R * ROWS + MAXS) && ALLOC(q, N + MAXS)
        && ALLOC(v, N + MAXS) && ALLOC(lam, R * ROWS + MAXS) && ALLOC(p, N + MAXS)
        && ALLOC(dq, N + MAXS) && ALLOC(qm, N + MAXS) && ALLOC(v1, N + MAXS)
        && ALLOC(p1, N + MAXS) && ALLOC(gt, N + MAXS) && ALLOC(res, N + MAXS)
        && ALLOC(tmp, N + MAXS) && ALLOC(phi0, R * ROWS + MAXS) && ALLOC(phi, R * ROWS + MAXS)
        && ALLOC(rr, R * mb + MAXS) && ALLOC(x, R * mb + MAXS) && ALLOC(gyro, R * n * n)
        && ALLOC(ycol, mb) && ALLOC(fric, 2 * R) && ALLOC(work_fric, R)
        && ALLOC(w0, N + MAXS) && ALLOC(sp1, N + MAXS) && ALLOC(mw0, N) && ALLOC(mdq, N)
        && ALLOC(fitc, 2 * n) && ALLOC(damp, N + MAXS) && ALLOC(v_in, N + MAXS);
#undef ALLOC
    if (ok) memcpy(x->mass, m->const_mass, sizeof(double) * R * n * n);
    const double *pattern = m->nl_elements ? m->nl_pattern : m->stiffness;
    ok = ok && elastic_lu(&x->b[0], m->const_mass, pattern, R, n)
        && elastic_lu(&x->b[1], m->const_mass, pattern, R, n);
    ok = ok && rows_of(x, m->const_mass, 1, &x->mrows) && rows_of(x, m->stiffness, 0, &x->krows)
        && jacobian_rows(x);
    x->kept_stuck = ok ? calloc((size_t)R, 1) : NULL;
    if (ok && x->ns > 1) ok = (x->base = base_new(x)) != NULL;
    if (ok && m->nl_elements) ok = (x->nl = nl_starts_new(x)) != NULL;
    if (!ok || !x->kept_stuck) { umbrella3d_free(x); return NULL; }
    x->pend_slot = -1;
    x->pm.elastic_first = x->kept_pm[0].elastic_first = x->kept_pm[1].elastic_first = 1;
    x->slot[0].elastic_first = x->slot[1].elastic_first = 2;
    return x;
}

/* ------------------------------------------------------------------ kinematics */
/* R(angle) (c + Sb e), in plane (ry[0], ry[1]): the body's first moment, rotated */
static void first_moment(const double *inv, int ne, const double *e, double cs, double sn,
                         double *ry) {
    double y[2];
    for (int i = 0; i < 2; i++) {
        double acc = inv[INV_C + i];
        for (int a = 0; a < ne; a++) acc += inv[INV_SB + i * ne + a] * e[a];
        y[i] = acc;
    }
    ry[0] = cs * y[0] - sn * y[1];
    ry[1] = sn * y[0] + cs * y[1];
}

/* M(q) of every rib (R x n x n; its body blocks: the blocks between bodies stay 0): the
 * constant part (Model3D.const_mass: the twist's rotary inertia and each body's elastic
 * block sum_p w S^T S, which the rotation leaves alone: copied once, at the context), plus
 * sum_p w J^T J in the rows and columns of each body's frame coordinates, from the inertia
 * invariants (Body.inv). */
static void mass_matrix(Ctx3D *x, const double *q) {
    const Model3D *m = x->m;
    int R = x->R, n = x->n;
    for (int j = 0; j < 2; j++) {
        const Body *b = &x->b[j];
        int nb = b->nb, t = b->t, ne = b->ne, L = INV_LEN(ne);
        for (int r = 0; r < R; r++) {
            double *M = x->mass + (size_t)r * n * n + b->off * n + b->off;
            const double *M0 = m->const_mass + (size_t)r * n * n + b->off * n + b->off;
            const double *inv = b->inv + (size_t)r * L, *qb = q + r * n + b->off;
            const double *e = qb + t + 1, *Sb = inv + INV_SB, *g = inv + INV_G(ne);
            const double *h = inv + INV_H(ne), *C = inv + INV_CC(ne), *D = inv + INV_D(ne);
            /* the frame rows anew (the elastic block stays M0's from the context on) */
            for (int a = 0; a <= t; a++) memcpy(M + a * n, M0 + a * n, sizeof(double) * nb);
            double *Ma = M + t * n;                   /* the angle's row */
            double aa = inv[INV_I0];
            for (int a = 0; a < ne; a++) {
                double ce = 0.0, de = h[a];
                for (int k = b->c_rows.ptr[a]; k < b->c_rows.ptr[a + 1]; k++)
                    ce += C[a * ne + b->c_rows.col[k]] * e[b->c_rows.col[k]];
                for (int k = b->d_cols.ptr[a]; k < b->d_cols.ptr[a + 1]; k++)
                    de += D[b->d_cols.col[k] * ne + a] * e[b->d_cols.col[k]];
                aa += (2.0 * g[a] + ce) * e[a];
                Ma[t + 1 + a] += de;
            }
            Ma[t] += aa;
            if (t) {
                double cs = cos(qb[t]), sn = sin(qb[t]), ry[2];
                first_moment(inv, ne, e, cs, sn, ry);
                for (int i = 0; i < 3; i++) M[i * n + i] += inv[INV_M];
                M[t] += -ry[1];
                M[n + t] += ry[0];
                for (int a = 0; a < ne; a++) {
                    M[t + 1 + a] += cs * Sb[a] - sn * Sb[ne + a];
                    M[n + t + 1 + a] += sn * Sb[a] + cs * Sb[ne + a];
                    M[2 * n + t + 1 + a] += Sb[2 * ne + a];
                }
            }
            for (int a = 0; a <= t; a++)
                for (int c = a + 1; c < nb; c++) M[c * n + a] = M[a * n + c];
        }
    }
}

/* The nonzeros of a rib's n x n matrix, block diagonal in the bodies (M, K), every rib's
 * union, row by row (columns ascending); rows_of builds it at the context from the constant
 * matrices (R x n x n), the frame rows and columns of each body (frame: M(q)'s moving ones)
 * included.  K and M's elastic blocks are banded by the elements: 3-4 nonzeros a row. */

static int rows_of(const Ctx3D *x, const double *A, int frame, Rows *p) {
    int R = x->R, n = x->n, k = 0;
    p->ptr = malloc(sizeof(int) * (n + 1));
    p->col = malloc(sizeof(int) * (n * n > 0 ? n * n : 1));
    if (!p->ptr || !p->col) return 0;
    for (int j = 0; j < 2; j++) {
        const Body *b = &x->b[j];
        int nf = frame ? b->t + 1 : 0;
        for (int a = b->off; a < b->off + b->nb; a++) {
            p->ptr[a] = k;
            for (int c = b->off; c < b->off + b->nb; c++) {
                int keep = a - b->off < nf || c - b->off < nf;
                for (int r = 0; r < R && !keep; r++) keep = A[(size_t)r * n * n + a * n + c] != 0.0;
                if (keep) p->col[k++] = c;
            }
        }
    }
    p->ptr[n] = k;
    return 1;
}

/* y = A v of rib r's n x n matrix A over its nonzeros p (the dense sum's order) */
static void rows_matvec(const Ctx3D *x, const Rows *p, const double *A, const double *v,
                        double *y) {
    for (int a = 0; a < x->n; a++) {
        const double *Aa = A + a * x->n;
        double acc = 0.0;
        for (int k = p->ptr[a]; k < p->ptr[a + 1]; k++) acc += Aa[p->col[k]] * v[p->col[k]];
        y[a] = acc;
    }
}

/* (pr, ps) = M (vr, vs) (the hub fixed: no rib-shared block) */
static void matvec(const Ctx3D *x, const double *v, double *p) {
    int R = x->R, n = x->n;
    for (int r = 0; r < R; r++)
        rows_matvec(x, &x->mrows, x->mass + (size_t)r * n * n, v + r * n, p + r * n);
    p[R * n] = x->m->sleeve_mass * v[R * n];
}

/* matvec of two vectors at once (M's nonzeros read once): pa = M a, pb = M b */
static void matvec2(const Ctx3D *x, const double *a, double *pa, const double *b, double *pb) {
    int R = x->R, n = x->n;
    const Rows *p = &x->mrows;
    for (int r = 0; r < R; r++) {
        const double *M = x->mass + (size_t)r * n * n, *ar = a + r * n, *br = b + r * n;
        for (int i = 0; i < n; i++) {
            const double *Mi = M + i * n;
            double acc_a = 0.0, acc_b = 0.0;
            for (int k = p->ptr[i]; k < p->ptr[i + 1]; k++) {
                double mk = Mi[p->col[k]];
                acc_a += mk * ar[p->col[k]];
                acc_b += mk * br[p->col[k]];
            }
            pa[r * n + i] = acc_a;
            pb[r * n + i] = acc_b;
        }
    }
    pa[R * n] = x->m->sleeve_mass * a[R * n];
    pb[R * n] = x->m->sleeve_mass * b[R * n];
}

/* d/dq [1/2 a^T M(q) b] of the rib coordinates (the hub fixed: none of the shared ones),
 * from the inertia invariants: M's frame rows depend on the angle (through R) and the
 * elastic coordinates e (mass_matrix) */
static void kinetic_gradient(Ctx3D *x, const double *q, const double *a, const double *bv,
                             double *g) {
    int R = x->R, n = x->n;
    memset(g, 0, sizeof(double) * (R * n + x->ns));
    for (int j = 0; j < 2; j++) {
        const Body *b = &x->b[j];
        int t = b->t, ne = b->ne, L = INV_LEN(ne);
        for (int r = 0; r < R; r++) {
            const double *inv = b->inv + (size_t)r * L, *qb = q + r * n + b->off;
            const double *ab = a + r * n + b->off, *bb = bv + r * n + b->off;
            const double *e = qb + t + 1, *ae = ab + t + 1, *be = bb + t + 1;
            const double *gg = inv + INV_G(ne), *C = inv + INV_CC(ne), *D = inv + INV_D(ne);
            double *o = g + r * n + b->off, *oe = o + t + 1;
            double aw = ab[t], bw = bb[t];
            for (int c = 0; c < ne; c++) {           /* M_aa, M_ae */
                double ce = 0.0, da = 0.0, db = 0.0;
                for (int i = b->c_rows.ptr[c]; i < b->c_rows.ptr[c + 1]; i++)
                    ce += C[c * ne + b->c_rows.col[i]] * e[b->c_rows.col[i]];
                for (int i = b->d_rows.ptr[c]; i < b->d_rows.ptr[c + 1]; i++) {
                    int k = b->d_rows.col[i];
                    da += D[c * ne + k] * ae[k];
                    db += D[c * ne + k] * be[k];
                }
                oe[c] += aw * bw * (gg[c] + ce) + 0.5 * (aw * db + bw * da);
            }
            if (!t) continue;
            const double *Sb = inv + INV_SB;
            double cs = cos(qb[t]), sn = sin(qb[t]), ry[2];
            first_moment(inv, ne, e, cs, sn, ry);
            /* d/dangle: M_ua' = -(R y) in plane, M_ue' = e_z x R Sb */
            double ga = -(ab[0] * ry[0] + ab[1] * ry[1]) * bw
                - (bb[0] * ry[0] + bb[1] * ry[1]) * aw;
            for (int k = 0; k < ne; k++) {
                double rs0 = cs * Sb[k] - sn * Sb[ne + k], rs1 = sn * Sb[k] + cs * Sb[ne + k];
                /* column k of e_z x R Sb: (-rs1, rs0, 0) */
                double ka = -ab[0] * rs1 + ab[1] * rs0, kb = -bb[0] * rs1 + bb[1] * rs0;
                ga += ka * be[k] + kb * ae[k];
                oe[k] += 0.5 * (ka * bw + kb * aw);   /* d/de_k of M_ua */
            }
            o[t] += 0.5 * ga;
        }
    }
}

/* 2 sum w J^T d(J v)/dq of every rib (R x n x n) at q (the midpoint), without the
 * elastic-elastic block, from the inertia invariants (no point loop): with y = x + S e, omega = v's angle rate and e' its elastic rates, dv's column t is
 * e_z x (omega e_z x R y + R S e') = -omega (R y) + e_z x R S e' in plane, its elastic
 * columns omega e_z x R S; so the translation rows 2 (-omega R (c + Sb e) + e_z x R Sb e'),
 * 2 omega e_z x R Sb; the angle row 2 (g + C e) . e' (column t), 2 omega (g + C e) (elastic
 * columns); the elastic rows' column t 2 (-omega (g + C e) - D e') */
static void gyroscopic(Ctx3D *x, const double *q, const double *v) {
    int R = x->R, n = x->n;
    memset(x->gyro, 0, sizeof(double) * R * n * n);
    for (int j = 0; j < 2; j++) {
        const Body *b = &x->b[j];
        int t = b->t, ne = b->ne, L = INV_LEN(ne);
        for (int r = 0; r < R; r++) {
            const double *inv = b->inv + (size_t)r * L, *qb = q + r * n + b->off;
            const double *vb = v + r * n + b->off, *e = qb + t + 1, *ed = vb + t + 1;
            const double *g = inv + INV_G(ne), *C = inv + INV_CC(ne), *D = inv + INV_D(ne);
            double *G = x->gyro + (size_t)r * n * n + b->off * n + b->off, w = vb[t];
            double gtt = 0.0;
            for (int k = 0; k < ne; k++) {
                double ge = g[k], de = 0.0;
                for (int i = b->c_rows.ptr[k]; i < b->c_rows.ptr[k + 1]; i++)
                    ge += C[k * ne + b->c_rows.col[i]] * e[b->c_rows.col[i]];
                for (int i = b->d_rows.ptr[k]; i < b->d_rows.ptr[k + 1]; i++)
                    de += D[k * ne + b->d_rows.col[i]] * ed[b->d_rows.col[i]];
                G[(t + 1 + k) * n + t] = 2.0 * (-w * ge - de);
                G[t * n + t + 1 + k] = 2.0 * w * ge;
                gtt += ge * ed[k];
            }
            G[t * n + t] = 2.0 * gtt;
            if (!t) continue;
            const double *Sb = inv + INV_SB;
            double cs = cos(qb[t]), sn = sin(qb[t]), ry[2], s0 = 0.0, s1 = 0.0;
            first_moment(inv, ne, e, cs, sn, ry);
            for (int k = 0; k < ne; k++) {
                s0 += Sb[k] * ed[k];
                s1 += Sb[ne + k] * ed[k];
                double rs0 = cs * Sb[k] - sn * Sb[ne + k], rs1 = sn * Sb[k] + cs * Sb[ne + k];
                G[t + 1 + k] = -2.0 * w * rs1;
                G[n + t + 1 + k] = 2.0 * w * rs0;
            }
            double rs0 = cs * s0 - sn * s1, rs1 = sn * s0 + cs * s1;
            G[t] = 2.0 * (-w * ry[0] - rs1);
            G[n + t] = 2.0 * (-w * ry[1] + rs0);
        }
    }
}

/* ------------------------------------------------------------------ joints */
static double stuck_on(double s) { return isnan(s) ? 0.0 : 1.0; }

/* Phi (R x 9, then the shared rows) at (qr, qs) */
static void constraints(const Ctx3D *x, const double *q, const double *stuck, int locked,
                        double *phi) {
    const Model3D *m = x->m;
    int n = x->n;
    for (int r = 0; r < x->R; r++) {
        const double *qr = q + r * n;
        double a1 = qr[m->i_a1], a2 = qr[m->i_a2];
        double c1 = cos(a1), s1 = sin(a1), c2 = cos(a2), s2 = sin(a2);
        double r1 = m->l1[r] + qr[m->i_u1], r3 = m->l3[r] + qr[m->i_uh];
        double sl1 = qr[m->i_s1], tw1 = qr[m->i_p1], sl2 = qr[m->i_s2], tw2 = qr[m->i_p2];
        double *f = phi + r * ROWS;
        f[0] = r1 * c1 - qr[m->i_rx];
        f[1] = r1 * s1 - qr[m->i_ry];
        f[2] = qr[m->i_w1] - qr[m->i_rz];
        f[3] = c1 * sl1 - s1 * tw1 - c2 * sl2 + s2 * tw2;
        f[4] = s1 * sl1 + c1 * tw1 - s2 * sl2 - c2 * tw2;
        f[5] = qr[m->i_rx] + r3 * c2;
        f[6] = qr[m->i_rz] + qr[m->i_wh];
        f[7] = qr[m->i_ry] + r3 * s2 - q[x->R * n];
        f[8] = isnan(stuck[r]) ? 0.0 : a1 + qr[m->i_t0] - stuck[r];   /* the root's turn */
        if (m->nl_elements) nl_hinge_rows(m, qr, f, NULL, n);
    }
    phi[x->R * ROWS] = locked ? q[x->R * n] - m->y_stop : 0.0;
}

/* J_rr (R x 9 x n) at q (J_rs: -1 at row 7 of y_s; J_ss: the stop's 1 when locked) */
static void jacobian(const Ctx3D *x, const double *q, const double *stuck, double *J) {
    const Model3D *m = x->m;
    int n = x->n;
    memset(J, 0, sizeof(double) * x->R * ROWS * n);
    for (int r = 0; r < x->R; r++) {
        const double *qr = q + r * n;
        double *j = J + r * ROWS * n;
        double a1 = qr[m->i_a1], a2 = qr[m->i_a2];
        double c1 = cos(a1), s1 = sin(a1), c2 = cos(a2), s2 = sin(a2);
        double r1 = m->l1[r] + qr[m->i_u1], r3 = m->l3[r] + qr[m->i_uh];
        double sl1 = qr[m->i_s1], tw1 = qr[m->i_p1], sl2 = qr[m->i_s2], tw2 = qr[m->i_p2];
#define JS(row, col, val) j[(row) * n + (col)] = (val)
        JS(0, m->i_a1, -r1 * s1); JS(0, m->i_u1, c1); JS(0, m->i_rx, -1.0);
        JS(1, m->i_a1, r1 * c1); JS(1, m->i_u1, s1); JS(1, m->i_ry, -1.0);
        JS(2, m->i_w1, 1.0); JS(2, m->i_rz, -1.0);
        JS(3, m->i_a1, -s1 * sl1 - c1 * tw1);
        JS(4, m->i_a1, c1 * sl1 - s1 * tw1);
        JS(3, m->i_s1, c1); JS(4, m->i_s1, s1);
        JS(3, m->i_p1, -s1); JS(4, m->i_p1, c1);
        JS(3, m->i_a2, s2 * sl2 + c2 * tw2);
        JS(4, m->i_a2, -c2 * sl2 + s2 * tw2);
        JS(3, m->i_s2, -c2); JS(4, m->i_s2, -s2);
        JS(3, m->i_p2, s2); JS(4, m->i_p2, -c2);
        JS(5, m->i_rx, 1.0); JS(5, m->i_a2, -r3 * s2); JS(5, m->i_uh, c2);
        JS(6, m->i_rz, 1.0); JS(6, m->i_wh, 1.0);
        JS(7, m->i_ry, 1.0); JS(7, m->i_a2, r3 * c2); JS(7, m->i_uh, s2);
        JS(8, m->i_a1, stuck_on(stuck[r])); JS(8, m->i_t0, stuck_on(stuck[r]));
#undef JS
        if (m->nl_elements) nl_hinge_rows(m, qr, NULL, j, n);
    }
}

/* Ctx3D.jrows: the nonzeros of jacobian's rows, read off jacobian itself at a generic
 * configuration (every rib's coordinates distinct, non-zero; a hinge stuck) */
static int jacobian_rows(Ctx3D *x) {
    int R = x->R, n = x->n, N = R * n, k = 0;
    double *q = malloc(sizeof(double) * (N + MAXS)), *st = malloc(sizeof(double) * R);
    x->jrows.ptr = malloc(sizeof(int) * (ROWS + 1));
    x->jrows.col = malloc(sizeof(int) * ROWS * n);
    int ok = q && st && x->jrows.ptr && x->jrows.col;
    if (ok) {
        for (int i = 0; i < N + MAXS; i++) q[i] = 0.3 + 0.0137 * i;
        for (int r = 0; r < R; r++) st[r] = 0.1;
        jacobian(x, q, st, x->jr);
        for (int i = 0; i < ROWS; i++) {
            x->jrows.ptr[i] = k;
            for (int a = 0; a < n; a++) {
                int keep = 0;
                for (int r = 0; r < R && !keep; r++) keep = x->jr[(size_t)r * ROWS * n + i * n + a] != 0.0;
                if (keep) x->jrows.col[k++] = a;
            }
        }
        x->jrows.ptr[ROWS] = k;
    }
    free(q); free(st);
    return ok;
}

static double max_abs(int k, const double *a) {
    double best = 0.0;
    for (int i = 0; i < k; i++) if (fabs(a[i]) > best || isnan(a[i])) best = isnan(a[i]) ? NAN : fabs(a[i]);
    return best;
}

/* ------------------------------------------------------------------ row combinations */
/* out (len) = sum_i w[i] rows[i] (rows: count rows of len, contiguous), each sum in i's
 * order from 0.0: the mode fit's modal sums and expansions, a rib's W lambda.  Blocked: a
 * block of sums held in vector registers across the loop over the rows (GNU C's vector
 * extension, lanes of COMBINE_LANES doubles: plain multiplies and adds, lane by lane), the
 * rest one by one; the same figures as the plain loop to the last bit (which a compiler
 * without the extension takes), at a fraction of its loads and stores.  (4 lanes where
 * the build does not enable AVX go through memory: twice the plain loop's time.) */
#if defined(__GNUC__)
#define COMBINE_LANES 2
typedef double CombineVec __attribute__((vector_size(COMBINE_LANES * sizeof(double))));
static inline CombineVec combine_load(const double *p) {
    CombineVec v;
    memcpy(&v, p, sizeof v);
    return v;
}
static inline void combine_store(double *p, CombineVec v) { memcpy(p, &v, sizeof v); }
#else
#define COMBINE_LANES 0
#endif

static void combine_rows(const double *restrict rows, const double *restrict w, int count,
                         int len, double *restrict out) {
    int k = 0;
#if COMBINE_LANES
    const int L = COMBINE_LANES;
    for (; k + 4 * L <= len; k += 4 * L) {
        CombineVec s0 = {0.0}, s1 = {0.0}, s2 = {0.0}, s3 = {0.0};
        for (int i = 0; i < count; i++) {
            const double *row = rows + (size_t)i * len + k;
            double wi = w[i];
            s0 += combine_load(row) * wi;
            s1 += combine_load(row + L) * wi;
            s2 += combine_load(row + 2 * L) * wi;
            s3 += combine_load(row + 3 * L) * wi;
        }
        combine_store(out + k, s0);
        combine_store(out + k + L, s1);
        combine_store(out + k + 2 * L, s2);
        combine_store(out + k + 3 * L, s3);
    }
    if (k < len) {                     /* the rest's vectors and odd sum: one pass */
        int nv = (len - k) / L, odd = len - k - nv * L;
        CombineVec s0 = {0.0}, s1 = {0.0}, s2 = {0.0};
        double t = 0.0;
        for (int i = 0; i < count; i++) {
            const double *row = rows + (size_t)i * len + k;
            double wi = w[i];
            if (nv > 0) s0 += combine_load(row) * wi;
            if (nv > 1) s1 += combine_load(row + L) * wi;
            if (nv > 2) s2 += combine_load(row + 2 * L) * wi;
            if (odd) t += row[nv * L] * wi;
        }
        if (nv > 0) combine_store(out + k, s0);
        if (nv > 1) combine_store(out + k + L, s1);
        if (nv > 2) combine_store(out + k + 2 * L, s2);
        if (odd) out[k + nv * L] = t;
        k = len;
    }
#endif
    for (; k < len; k++) {
        double acc = 0.0;
        for (int i = 0; i < count; i++) acc += rows[(size_t)i * len + k] * w[i];
        out[k] = acc;
    }
}

/* ------------------------------------------------------------------ arrow algebra */
/* X = A^-1 X for the ROWS right-hand sides of X (N x ROWS, row-major), with lu_factor's A
 * and piv (lu_solve's substitutions, a row of X at a time) */
static void lu_solve_rows(int N, const double *A, const int *piv, double *X) {
    for (int k = 0; k < N; k++)
        if (piv[k] != k)
            for (int c = 0; c < ROWS; c++) {
                double t = X[k * ROWS + c];
                X[k * ROWS + c] = X[piv[k] * ROWS + c];
                X[piv[k] * ROWS + c] = t;
            }
    for (int i = 0; i < N; i++)
        for (int j = 0; j < i; j++) {
            double f = A[i * N + j];
            if (f != 0.0)
                for (int c = 0; c < ROWS; c++) X[i * ROWS + c] -= f * X[j * ROWS + c];
        }
    for (int i = N - 1; i >= 0; i--) {
        for (int j = N - 1; j > i; j--) {
            double f = A[i * N + j];
            if (f != 0.0)
                for (int c = 0; c < ROWS; c++) X[i * ROWS + c] -= f * X[j * ROWS + c];
        }
        for (int c = 0; c < ROWS; c++) X[i * ROWS + c] *= A[i * N + i];
    }
}

/* lu_solve's b = A^-1 b (a rib's ROWS x ROWS joint block T) by columns: each unknown, once
 * final, taken out of the rows after it (back substituting: before it), so each row's sum
 * takes lu_solve's terms in lu_solve's order (the same figures) while the rows' chains run
 * side by side, not one after another */
static inline void joint_solve(const double *A, const int *piv, double *b) {
    for (int k = 0; k < ROWS; k++)
        if (piv[k] != k) { double t = b[k]; b[k] = b[piv[k]]; b[piv[k]] = t; }
    double y[ROWS];                    /* (unrolled whole: y in registers) */
    memcpy(y, b, sizeof y);
#pragma GCC unroll 9
    for (int j = 0; j < ROWS; j++)
#pragma GCC unroll 9
        for (int i = j + 1; i < ROWS; i++) y[i] -= A[i * ROWS + j] * y[j];
#pragma GCC unroll 9
    for (int j = ROWS - 1; j >= 0; j--) {
        y[j] *= A[j * ROWS + j];
#pragma GCC unroll 9
        for (int i = 0; i < j; i++) y[i] -= A[i * ROWS + j] * y[j];
    }
    memcpy(b, y, sizeof y);
}

/* rib r's block, factored (arrow_factor), solved for v (mb) in place:
 * x = A^-1 v_top, lambda = T^-1 (v_bottom - Jr x), x -= W lambda (top_zero: v_top = 0, so
 * x = 0 and Jr x = 0: the bodies' solves left out) */
static void rib_solve(const Ctx3D *x, const Fact *f, int r, double *v, int top_zero) {
    int n = x->n;
    const double *A = f->Af + (size_t)r * (x->b[0].nb * x->b[0].nb + x->b[1].nb * x->b[1].nb);
    for (int j = 0; j < 2 && !top_zero; j++) {
        const Body *b = &x->b[j];
        const int *piv = f->apiv + r * n + b->off;
        if (f->elastic_first) {
            double y[b->nb];
            int kind = f->elastic_first - 1, map[b->nb];
            for (int i = 0; i < b->nb; i++) map[i] = b->off + elastic_first(b, i);
            for (int i = 0; i < b->nb; i++) y[i] = v[map[i]];
            ef_solve(b, &b->lpat[kind], &b->upat[kind], A, piv, y, 1);
            for (int i = 0; i < b->nb; i++) v[map[i]] = y[i];
        } else {
            lu_solve(b->nb, A, piv, v + b->off);
        }
        A += b->nb * b->nb;
    }
    const double *J = f->Jf + (size_t)r * ROWS * n, *Wt = f->Wt + (size_t)r * n * ROWS;
    const Rows *jp = &x->jrows;
    for (int i = 0; i < ROWS && !top_zero; i++) {
        double acc = 0.0;
        for (int k = jp->ptr[i]; k < jp->ptr[i + 1]; k++) acc += J[i * n + jp->col[k]] * v[jp->col[k]];
        v[n + i] -= acc;
    }
    joint_solve(f->T + r * ROWS * ROWS, f->tpiv + r * ROWS, v + n);
    double acc[n];                             /* W lambda: a row's sum, in i's order */
    combine_rows(Wt, v + n, ROWS, n, acc);
    for (int a = 0; a < n; a++) v[a] -= acc[a];
}

/* Factor rib r's block [[M + extra, sign Jc^T], [Jr, Z]] through its bodies (rib_solve):
 * each body's block LU'd, W = A^-1 sign Jc^T, T = Z - Jr W LU'd. */
static int rib_factor(Ctx3D *x, Fact *f, int r, const double *extra, const double *jc,
                      const double *jr, const double *stuck, double sign) {
    int n = x->n;
    {
        const double *M = x->mass + (size_t)r * n * n;
        const double *Ex = extra ? extra + (size_t)r * n * n : NULL;
        const double *Jc = jc + r * ROWS * n, *Jr = jr + r * ROWS * n;
        double *A = f->Af + (size_t)r * (x->b[0].nb * x->b[0].nb + x->b[1].nb * x->b[1].nb);
        double *W = f->W + (size_t)r * n * ROWS, *T = f->T + r * ROWS * ROWS;
        memset(W, 0, sizeof(double) * n * ROWS);      /* sign Jc^T, over Jc's nonzeros */
        for (int i = 0; i < ROWS; i++)
            for (int k = x->jrows.ptr[i]; k < x->jrows.ptr[i + 1]; k++)
                W[x->jrows.col[k] * ROWS + i] = sign * Jc[i * n + x->jrows.col[k]];
        for (int j = 0; j < 2; j++) {
            const Body *b = &x->b[j];
            int nb = b->nb, o = b->off;
            int *piv = f->apiv + r * n + o;
            if (f->elastic_first) {             /* (M + extra's elastic block: E's) */
                double Y[nb * ROWS];
                int kind = f->elastic_first - 1, map[nb];
                for (int a = 0; a < nb; a++) map[a] = o + elastic_first(b, a);
                for (int a = 0; a < nb; a++) {   /* (the elastic block: E's, below) */
                    const double *Ma = M + (size_t)map[a] * n;
                    double *Aa = A + a * nb;
                    int c0 = a < b->ne ? b->ne : 0;
                    if (Ex) {
                        const double *Ea = Ex + (size_t)map[a] * n;
                        for (int c = c0; c < nb; c++) Aa[c] = Ma[map[c]] + Ea[map[c]];
                    } else {
                        for (int c = c0; c < nb; c++) Aa[c] = Ma[map[c]] + 0.0;
                    }
                    memcpy(Y + a * ROWS, W + map[a] * ROWS, sizeof(double) * ROWS);
                }
                if (factor_elastic_first(b, kind ? b->elu_it : b->elu, kind, r, A, piv) != OK)
                    return SINGULAR;
                ef_solve(b, &b->lpat[kind], &b->upat[kind], A, piv, Y, ROWS);
                for (int a = 0; a < nb; a++)
                    memcpy(W + map[a] * ROWS, Y + a * ROWS, sizeof(double) * ROWS);
            } else {
                for (int a = 0; a < nb; a++)
                    for (int c = 0; c < nb; c++)
                        A[a * nb + c] = M[(o + a) * n + o + c]
                            + (Ex ? Ex[(o + a) * n + o + c] : 0.0);
                if (lu_factor(nb, A, piv) != OK) return SINGULAR;
                lu_solve_rows(nb, A, piv, W + o * ROWS);
            }
            A += nb * nb;
        }
        memset(T, 0, sizeof(double) * ROWS * ROWS);
        for (int i = 0; i < ROWS; i++)                 /* T = -Jr W over Jr's nonzeros */
            for (int k = x->jrows.ptr[i]; k < x->jrows.ptr[i + 1]; k++) {
                int a = x->jrows.col[k];
                double f = Jr[i * n + a];
                if (f == 0.0) continue;
                for (int k = 0; k < ROWS; k++) T[i * ROWS + k] -= f * W[a * ROWS + k];
            }
        T[ROW_STICK * ROWS + ROW_STICK] += 1.0 - stuck_on(stuck[r]);
        if (lu_factor(ROWS, T, f->tpiv + r * ROWS) != OK) return SINGULAR;
        double *Wt = f->Wt + (size_t)r * n * ROWS;
        for (int a = 0; a < n; a++)
            for (int i = 0; i < ROWS; i++) Wt[i * n + a] = W[a * ROWS + i];
        memcpy(f->Jf + (size_t)r * ROWS * n, Jr, sizeof(double) * ROWS * n);
    }
    return OK;
}

/* Factor [[M + extra, sign Jc^T], [Jr, Z]] (integrator3d._blocks) in arrow form: each rib's
 * block (rib_factor), B^-1 C, the Schur complement of the shared unknowns by LU. */
static int arrow_factor(Ctx3D *x, Fact *f, const double *extra, const double *jc,
                        const double *jr, const double *stuck, int locked, double sign) {
    int R = x->R, n = x->n, mb = x->mb, s = x->s, ns = x->ns;
    const double msl = x->m->sleeve_mass;
    double L = locked ? 1.0 : 0.0;
    /* the corner: [[m_ss, sign J_ss^T], [J_ss, 1 - active]] */
    x->E[0] = msl; x->E[1] = sign * L; x->E[s] = L; x->E[s + 1] = 1.0 - L;
    memcpy(f->S, x->E, sizeof(double) * s * s);
    for (int r = 0; r < R; r++) {
        if (rib_factor(x, f, r, extra, jc, jr, stuck, sign) != OK) return SINGULAR;
        /* C: row n + 7 of y_s is J_rs = -1; D: y_s's row at n + 7 is sign J_rs^T */
        double *Y = f->Y + (size_t)r * mb * s;
        for (int c = 0; c < s; c++) {
            memset(x->ycol, 0, sizeof(double) * mb);
            if (c < ns) {
                x->ycol[n + 7] = -1.0;
                rib_solve(x, f, r, x->ycol, 1);
            }
            for (int a = 0; a < mb; a++) Y[a * s + c] = x->ycol[a];
        }
        for (int c = 0; c < s; c++) f->S[c] -= sign * -1.0 * Y[(n + 7) * s + c];
    }
    return lu_factor(s, f->S, f->spiv) == OK ? OK : SINGULAR;
}

/* Solve the factored arrow system for (rr (R x mb), rs (s)), in place (top_zero: every rib's
 * first n right-hand sides are 0, rib_solve's) */
static void arrow_solve(Ctx3D *x, const Fact *f, double *rr, double *rs, double sign,
                        int top_zero) {
    int R = x->R, n = x->n, mb = x->mb, s = x->s, ns = x->ns;
    double z[MAXS];
    memcpy(z, rs, sizeof(double) * s);
    for (int r = 0; r < R; r++) {
        rib_solve(x, f, r, rr + r * mb, top_zero);
        z[0] -= sign * -1.0 * rr[r * mb + n + 7];
    }
    lu_solve(s, f->S, f->spiv, z);
    memcpy(rs, z, sizeof(double) * s);
    for (int r = 0; r < R; r++) {     /* (Y's columns of the shared rows: 0, arrow_factor) */
        const double *Y = f->Y + (size_t)r * mb * s;
        for (int a = 0; a < mb; a++) {
            double acc = 0.0;
            for (int c = 0; c < ns; c++) acc += Y[a * s + c] * z[c];
            rr[r * mb + a] -= acc;
        }
    }
}

/* ------------------------------------------------------------------ the step */
static double strain_energy(Ctx3D *x, const double *q) {
    if (x->m->nl_elements) return nl_energy(x, q);
    int n = x->n;
    double e = 0.0;
    for (int r = 0; r < x->R; r++) {
        rows_matvec(x, &x->krows, x->m->stiffness + (size_t)r * n * n, q + r * n, x->ycol);
        for (int a = 0; a < n; a++) e += q[r * n + a] * x->ycol[a];
    }
    return 0.5 * e;
}

/* below this |rate| / hinge_regularisation the Coulomb torque's secant is its tangent, 1 */
#define FRICTION_AT_REST 1e-6

static void friction(const Ctx3D *x, int r, double dq_a1, double h, double *torque,
                     double *slope) {
    const Model3D *m = x->m;
    double w = dq_a1 / h, eps = m->regularisation, th = tanh(w / eps);
    *torque = -(m->viscous[r] * w + m->coulomb[r] * th);
    /* the slope the iteration matrix takes: the Coulomb torque's secant from rest, tanh(s) / s
     * (its tangent at rest), not its tangent sech^2(s), which is 0 away from rest: a rate
     * crossing 0 then overshot the tanh's narrow ramp back and forth, and Newton never
     * converged (integrator3d.MidpointUmbrella.friction, the same rule) */
    double s = w / eps, secant = fabs(s) < FRICTION_AT_REST ? 1.0 : th / s;
    if (slope) *slope = -(m->viscous[r] + m->coulomb[r] * secant / eps) / h;
}

/* v's correction onto J v = 0 by the factored projection f ([[M, J^T], [J, 0]] of some
 * q): v += dv, M dv = -J^T mu, J (v + dv) = 0 with f's M and J, the residual J v of x->jr;
 * returns max |dv| */
static double projection_pass(Ctx3D *x, const Fact *f, double *v, int locked) {
    int R = x->R, n = x->n, mb = x->mb, ns = x->ns;
    for (int r = 0; r < R; r++) {
        double *rr = x->rr + r * mb;
        const double *J = x->jr + r * ROWS * n;
        memset(rr, 0, sizeof(double) * n);
        for (int i = 0; i < ROWS; i++) {
            double acc = 0.0;
            for (int k = x->jrows.ptr[i]; k < x->jrows.ptr[i + 1]; k++)
                acc += J[i * n + x->jrows.col[k]] * v[r * n + x->jrows.col[k]];
            rr[n + i] = -acc;
        }
        rr[n + 7] += v[R * n];           /* -J_rs v_s = y_s' */
    }
    double rs[MAXS] = {0.0};
    rs[ns] = locked ? -v[R * n] : 0.0;
    arrow_solve(x, f, x->rr, rs, 1.0, 1);     /* (M dv = -J^T mu: no top) */
    double largest = fabs(rs[0]);
    for (int r = 0; r < R; r++)
        for (int a = 0; a < n; a++) {
            double d = x->rr[r * mb + a];
            v[r * n + a] += d;
            if (fabs(d) > largest) largest = fabs(d);
        }
    v[R * n] += rs[0];
    return largest;
}

/* v projected onto J(q) v = 0 (M = x->mass at q): in the mass metric, one pass of the
 * projection factored at q; or, kept (the projection factored at the end of the step that
 * factored the iteration matrix kept: integrator3d.MidpointUmbrella.project_kept's rule),
 * passes of the kept factor until the correction is below PROJECTION_TOLERANCE of v (each
 * pass's residual J(q) v: the limit holds J(q) v = 0, its correction in the kept M's
 * metric), at most PROJECTION_PASSES, else v as it came projected by a pass of the
 * projection factored at q; store: the projection factored at q into it */
static int project(Ctx3D *x, const double *q, double *v, const double *stuck, int locked,
                   const Fact *kept, Fact *store) {
    int N = x->R * x->n + x->ns;
    jacobian(x, q, stuck, x->jr);
    if (kept) {
        double size = max_abs(N, v);
        memcpy(x->v_in, v, sizeof(double) * N);
        for (int pass = 0; pass < PROJECTION_PASSES; pass++) {
            if (!(projection_pass(x, kept, v, locked) > PROJECTION_TOLERANCE * size))
                return OK;
        }
        memcpy(v, x->v_in, sizeof(double) * N);
    }
    Fact *f = store ? store : &x->pm;
    if (arrow_factor(x, f, NULL, x->jr, x->jr, stuck, locked, 1.0) != OK) return SINGULAR;
    projection_pass(x, f, v, locked);
    return OK;
}

/* ------------------------------------------------------------------ the mode fit */
/* Stage 2's mode fit (integrators.LockedModeFit, rib by rib): S = I + Phi diag(s - 1) U^T */
typedef struct {
    int r; const double *u, *phi, *sc, *shrink; int whole;
    const double *damp;                /* each mode's damping change (NULL: undamped) */
    const double *u_t, *phi_t;         /* u and phi transposed (modal_correction's in_t) */
    /* a free bus's correction of the ribs' fit (Advance3DCall.bus_*: base_fit_map) */
    int bus_rank; const double *bus_a, *bus_b, *bus_c, *bus_at, *bus_bt, *bus_ct;
    int newton_rank; const double *newton_a, *newton_bt;
    int damp_rank; const double *damp_a, *damp_b;
} Fit3D;

enum { TO_SCHEME, TO_PHYSICAL, TRANSPOSE, NEWTON };

#include "_kernel3d_damping.h"

/* acc = out^T diag(factor) in^T v over L coordinates: the mode fit's correction of v for the
 * map `kind` (fit_map), the r modes' projection rows `in` given transposed (in_t: L rows of
 * r) and their shapes `out` (r rows of L), their scales sc and Newton shrinks shrink (sc
 * NULL: a low-rank map's, factor -1 to the scheme, else 1); c: r doubles of scratch.  Each
 * sum in order (c[j] over the coordinates, acc[a] over the modes): combine_rows. */
static void modal_correction(const double *restrict in_t, const double *restrict out,
                             const double *sc, const double *shrink, int r, int L, int kind,
                             const double *restrict v, double *restrict c,
                             double *restrict acc) {
    combine_rows(in_t, v, L, r, c);
    for (int j = 0; j < r; j++) {
        if (!sc) {
            if (kind == TO_SCHEME) c[j] = -c[j];
            continue;
        }
        double s = sc[j];
        c[j] *= kind == TO_SCHEME ? 1.0 / s - 1.0 : kind == NEWTON ? -shrink[j] : s - 1.0;
    }
    combine_rows(out, c, r, L, acc);
}

/* v (the rib coordinates, R x n) mapped in place, rib by rib, as LockedModeFit's maps:
 * to_scheme v + Phi diag(1/s - 1) U^T v, to_physical v + Phi diag(s - 1) U^T v, transpose
 * v + U diag(s - 1) Phi^T v, newton_update v - Phi diag(shrink) U^T v; a rib's block of v at
 * stride apart (n for R x n, mb for the arrow's right-hand sides) */
static void fit_map(const Ctx3D *x, const Fit3D *f, int kind, double *v, int stride) {
    int n = x->n, r = f->r;
    double *c = x->fitc, *acc = x->fitc + n;
    for (int k = 0; k < x->R; k++) {
        double *vk = v + (size_t)k * stride;
        size_t rib = (size_t)k * r;
        modal_correction((kind == TRANSPOSE ? f->phi_t : f->u_t) + rib * n,
                         (kind == TRANSPOSE ? f->u : f->phi) + rib * n, f->sc + rib,
                         f->shrink + rib, r, n, kind, vk, c, acc);
        for (int a = 0; a < n; a++) vk[a] += acc[a];
    }
}

/* The hub fixed's maps of the iterates' velocities at half a map each: the step tracks the
 * modal coordinates U^T dq of its dq (the predictor's h U^T w0, then each Newton update's
 * U^T N x = (1 - shrink) U^T x, U^T Phi = I: Phi mass-normalised), so S (2 dq / h - w0) =
 * (2 dq / h - w0) + Phi diag(s - 1) (2 U^T dq / h - U^T w0) takes no projection of its own
 * (fit_velocity); the same velocity as fit_map's TO_PHYSICAL to round-off (the tracked
 * coordinates leave out q's rounding, weighted by s - 1). */

/* w0 = S^-1 v0 (fit_map's TO_SCHEME), U^T w0 = U^T v0 / s into x->mw0 and the
 * predictor's U^T dq = h U^T w0 into x->mdq */
static void fit_start(Ctx3D *x, const Fit3D *f, const double *v0, double *w0, double h) {
    int n = x->n, r = f->r;
    double *c = x->fitc, *acc = x->fitc + n;
    for (int k = 0; k < x->R; k++) {
        size_t rib = (size_t)k * r;
        const double *sc = f->sc + rib;
        double *mw = x->mw0 + rib, *md = x->mdq + rib;
        combine_rows(f->u_t + rib * n, v0 + k * n, n, r, c);
        for (int j = 0; j < r; j++) {
            mw[j] = c[j] / sc[j];
            md[j] = h * mw[j];
            c[j] *= 1.0 / sc[j] - 1.0;
        }
        combine_rows(f->phi + rib * n, c, r, n, acc);
        for (int a = 0; a < n; a++) w0[k * n + a] = v0[k * n + a] + acc[a];
    }
}

/* v (R x n: 2 dq / h - w0) mapped to S v by the tracked modal coordinates (fit_start) */
static void fit_velocity(const Ctx3D *x, const Fit3D *f, double *v, double h) {
    int n = x->n, r = f->r;
    double *c = x->fitc, *acc = x->fitc + n;
    for (int k = 0; k < x->R; k++) {
        size_t rib = (size_t)k * r;
        const double *sc = f->sc + rib, *mw = x->mw0 + rib, *md = x->mdq + rib;
        for (int j = 0; j < r; j++) c[j] = (sc[j] - 1.0) * (2.0 * md[j] / h - mw[j]);
        combine_rows(f->phi + rib * n, c, r, n, acc);
        for (int a = 0; a < n; a++) v[k * n + a] += acc[a];
    }
}

/* fit_map's NEWTON of the update v (each rib's block at stride apart), its modal
 * coordinates (1 - shrink) U^T v added to x->mdq */
static void fit_newton(Ctx3D *x, const Fit3D *f, double *v, int stride) {
    int n = x->n, r = f->r;
    double *c = x->fitc, *acc = x->fitc + n;
    for (int k = 0; k < x->R; k++) {
        double *vk = v + (size_t)k * stride;
        size_t rib = (size_t)k * r;
        const double *shrink = f->shrink + rib;
        double *md = x->mdq + rib;
        combine_rows(f->u_t + rib * n, vk, n, r, c);
        for (int j = 0; j < r; j++) {
            md[j] += c[j] - shrink[j] * c[j];
            c[j] *= -shrink[j];
        }
        combine_rows(f->phi + rib * n, c, r, n, acc);
        for (int a = 0; a < n; a++) vk[a] += acc[a];
    }
}

/* Whether the kept iteration matrix serves a step of length h from (q0, v0): the step
 * starts where the committed step that used it ended, with the same length (to 1e-9), lock
 * and stuck hinges, and the matrix has served fewer than carry_steps steps.  A rule of the
 * trajectory alone (integrator3d.MidpointUmbrella._kept_factor is the same), so runs of
 * steps and single steps take the same iterates. */
static int kept_serves(const Ctx3D *x, const double *stuck, int locked, double h) {
    if (!x->kept || x->kept_locked != locked || fabs(x->kept_h - h) > 1e-9 * h
        || x->slot[x->kept_slot].uses >= x->m->carry_steps)
        return 0;
    for (int r = 0; r < x->R; r++)
        if (x->kept_stuck[r] != !isnan(stuck[r])) return 0;
    size_t bytes = sizeof(double) * (x->R * x->n + x->ns);
    return memcmp(x->q0, x->kept_q, bytes) == 0 && memcmp(x->v0, x->kept_v, bytes) == 0;
}

/* One step of length h from (q0, v0, l0, p0) into (q, v, lam, p); the works. */
/* The iteration matrix's body blocks at the iterate q (x->dq, x->qm its step): the joint
 * Jacobian into x->jr, and per rib h^2/4 K + h/2 G (G the gyroscopic tangent of the midpoint
 * velocity dq / h) less h^2/2 the hinge friction's slope, into x->gyro: what arrow_factor and
 * base_arrow_factor read */
static void iteration_blocks(Ctx3D *x, const double *q, const double *stuck, double h) {
    const Model3D *m = x->m;
    int R = m->n_ribs, n = m->n_rib, N = R * n;
    jacobian(x, q, stuck, x->jr);
    for (int i = 0; i < N; i++) x->tmp[i] = x->dq[i] / h;
    gyroscopic(x, x->qm, x->tmp);
    for (int r = 0; r < R; r++) {
        double *G = x->gyro + (size_t)r * n * n;
        const double *K = m->stiffness + (size_t)r * n * n;
        double ck = m->nl_elements ? 0.0 : stiffness_weight(m, h);
        for (int j = 0; j < 2; j++) {
            const Body *b = &x->b[j];
            for (int a = b->off; a < b->off + b->nb; a++)
                for (int c = b->off; c < b->off + b->nb; c++)
                    G[a * n + c] = ck * K[a * n + c] + 0.5 * h * G[a * n + c];
        }
        if (m->nl_elements) nl_block(x, r, x->q0 + r * n, q + r * n, 0.5 * h * h, G);
        if (m->nl_elements && m->damping_beta != 0.0)     /* h/2 C(q_m): the damped ribs' */
            nl_damping_block(m, r, n, x->qm + r * n, 0.5 * h * m->damping_beta, G);
        G[m->i_a1 * n + m->i_a1] -= 0.5 * h * h * x->fric[R + r];
    }
}

/* A Newton update of the ribs' coordinates and joint multipliers from x->rr (each rib's
 * block of mb: its n coordinates, then its ROWS multipliers times h^2 / 2); returns the
 * largest |coordinate update|, and clears *finite if one is not finite */
static double rib_update(Ctx3D *x, double *q, int mb, double half_h2, int *finite) {
    const Model3D *m = x->m;
    int R = m->n_ribs, n = m->n_rib;
    double norm = 0.0;
    for (int r = 0; r < R; r++) {
        for (int a = 0; a < n; a++) {
            double d = x->rr[r * mb + a];
            q[r * n + a] += d;
            if (!isfinite(d)) *finite = 0;
            else if (fabs(d) > norm) norm = fabs(d);
        }
        for (int i = 0; i < ROWS; i++) x->lam[r * ROWS + i] += x->rr[r * mb + n + i] / half_h2;
    }
    return norm;
}

/* The ribs' right-hand sides of a correction of the joints alone (after an iterate that
 * converged in q but not in the joints): the momentum rows 0, the joint rows -phi */
static void joint_correction_rhs(Ctx3D *x) {
    int n = x->n, mb = x->mb;
    for (int r = 0; r < x->R; r++) {
        memset(x->rr + r * mb, 0, sizeof(double) * n);
        for (int i = 0; i < ROWS; i++) x->rr[r * mb + n + i] = -x->phi[r * ROWS + i];
    }
}

/* Each hinge's friction work over the step taken (x->dq) into x->work_fric; their sum */
static double friction_works(Ctx3D *x, double h) {
    const Model3D *m = x->m;
    int n = m->n_rib;
    double w_fric = 0.0;
    for (int r = 0; r < m->n_ribs; r++) {
        double torque;
        friction(x, r, x->dq[r * n + m->i_a1], h, &torque, NULL);
        x->work_fric[r] = torque * x->dq[r * n + m->i_a1];
        w_fric += x->work_fric[r];
    }
    return w_fric;
}

static int step(Ctx3D *x, const double *stuck, int locked, double h, double force, double tol,
                double phi_tol, int max_iter, const Fit3D *fit) {
    const Model3D *m = x->m;
    int R = x->R, n = x->n, N = R * n, ns = x->ns, mb = x->mb, cs = x->cs;
    const double half_h2 = 0.5 * h * h;
    const int damped = m->damping_beta != 0.0;
    double *q = x->q, *q0 = x->q0, *v0 = x->v0, *p0 = x->p0;
    /* the scheme's velocity w0 (the mode fit; else v0) */
    const double *w0 = v0;
    if (fit) {
        memcpy(x->w0, v0, sizeof(double) * (N + ns));
        fit_start(x, fit, v0, x->w0, h);
        w0 = x->w0;
    }
    constraints(x, q0, stuck, locked, x->phi0);
    for (int i = 0; i < N + ns; i++) q[i] = q0[i] + h * w0[i];
    memcpy(x->lam, x->l0, sizeof(double) * (R * ROWS + cs));
    /* modified Newton: the kept matrix if it serves, else (and after a slow iteration) one
     * factored at the iterate into the slot not kept */
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
        if (fit) fit_velocity(x, fit, x->v1, h);
        mass_matrix(x, q);
        matvec2(x, x->v1, x->p1, v0, x->tmp);     /* (M(q1) v0: Gonzalez's, below) */
        /* the scheme's momentum change S^T (M(q1) v1 - p0) (S^T M(q1) v1 - S^T p0: one map) */
        double *sp1 = x->sp1;
        for (int i = 0; i < N + ns; i++) sp1[i] = x->p1[i] - p0[i];
        if (fit) fit_map(x, fit, TRANSPOSE, sp1, n);
        kinetic_gradient(x, x->qm, v0, x->v1, x->gt);
        /* Gonzalez along the rib coordinates: dq . G_T = f(q1) - f(q0) */
        double delta = 0.0, dd = 0.0, gdq = 0.0, scale = 0.0;
        for (int i = 0; i < N + ns; i++) {
            delta += (x->tmp[i] - p0[i]) * x->v1[i];
            scale += 0.5 * (fabs(x->tmp[i] * x->v1[i]) + fabs(p0[i] * x->v1[i]));
        }
        delta *= 0.5;
        for (int i = 0; i < N; i++) { dd += x->dq[i] * x->dq[i]; gdq += x->gt[i] * x->dq[i]; }
        gdq += x->gt[N] * x->dq[N];
        for (int i = 0; i <= N; i++) scale += fabs(x->gt[i] * x->dq[i]);
        double corr = gonzalez_discrepancy(delta - gdq, scale);
        if (dd > 0.0 && corr != 0.0)
            for (int i = 0; i < N; i++) x->gt[i] += corr / dd * x->dq[i];
        constraints(x, q, stuck, locked, x->phi);
        jacobian(x, x->qm, stuck, x->jm);
        if (damped) damping_forces(x, fit, h, x->damp);
        double cons_s = locked ? x->lam[R * ROWS] : 0.0;
        const Rows *jp = &x->jrows;
        for (int r = 0; r < R; r++) {
            /* the joints' Gonzalez Jacobian G = J(q_m) + f dq^T (f: each row's correction),
             * in the residual as G^T lam = J^T lam + dq (f . lam), J over its nonzeros */
            const double *dq = x->dq + r * n, *J = x->jm + r * ROWS * n, *qm = x->qm + r * n;
            const double *lam = x->lam + r * ROWS;
            double ddr = 0.0, flam = 0.0, jl[n];
            for (int a = 0; a < n; a++) { ddr += dq[a] * dq[a]; jl[a] = 0.0; }
            for (int i = 0; i < ROWS; i++) {
                double lin = 0.0, size = 0.0;
                for (int k = jp->ptr[i]; k < jp->ptr[i + 1]; k++) {
                    int a = jp->col[k];
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
            cons_s -= lam[7];
        }
        x->res[N] = sp1[N] - h * (x->gt[N] - force + cons_s);
        if (!factored) {
            iteration_blocks(x, q, stuck, h);
            if ((m->nl_elements ? nl_iteration_elastic(x) : iteration_elastic(x, h)) != OK
                || arrow_factor(x, fresh, x->gyro, x->jm, x->jr, stuck, locked, -1.0) != OK)
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
        rs[0] = -0.5 * h * x->res[N];
        rs[ns] = locked ? -x->phi[R * ROWS] : 0.0;
        arrow_solve(x, ff, x->rr, rs, -1.0, 0);
        if (fit) fit_newton(x, fit, x->rr, mb);
        int finite = 1;
        double norm = rib_update(x, q, mb, half_h2, &finite);
        q[N] += rs[0];
        x->lam[R * ROWS] += rs[ns] / half_h2;
        if (!finite) return NON_FINITE;
        double rate = it > 1 ? norm / last : 1.0;
        if (norm < tol || (rate < 0.5 && rate / (1.0 - rate) * norm < tol)) {
            constraints(x, q, stuck, locked, x->phi);
            if (max_abs(R * ROWS + cs, x->phi) < phi_tol) break;
            /* converged in q, not in the joints: one correction of the joints alone (the
             * momentum rows' right-hand side 0: integrators.newton_converged; the hub fixed
             * only, base_step takes whole iterations) */
            joint_correction_rhs(x);
            rs[0] = 0.0;
            rs[ns] = locked ? -x->phi[R * ROWS] : 0.0;
            arrow_solve(x, ff, x->rr, rs, -1.0, 1);
            if (fit) fit_newton(x, fit, x->rr, mb);
            rib_update(x, q, mb, half_h2, &finite);
            q[N] += rs[0];
            x->lam[R * ROWS] += rs[ns] / half_h2;
            if (!finite) return NON_FINITE;
            constraints(x, q, stuck, locked, x->phi);
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
    if (fit) fit_velocity(x, fit, v, h);
    mass_matrix(x, q);
    double w_fric = friction_works(x, h);
    x->work_force = force * (q0[N] - q[N]);
    double t0 = 0.0;
    for (int i = 0; i < N; i++) t0 += v0[i] * p0[i];
    t0 = 0.5 * (t0 + v0[N] * p0[N]);
    double strain0 = x->strain0_ok ? x->strain0 : strain_energy(x, q0);
    x->strain = strain_energy(x, q);
    x->work_damp = damped ? damping_work(x, fit, h) : 0.0;
    double t_target = t0 + strain0 - x->strain + x->work_force + w_fric - x->work_damp;
    /* (stage 2's projection kept with the iteration matrix: a step that factored it factors
     * the projection at its end, the steps it serves take that) */
    int keeps = locked && tol >= PROJECTION_KEPT_FROM, slot = x->pend_slot;
    if (refactored) x->kept_pm_ok[slot] = keeps;
    Fact *pk = keeps && x->kept_pm_ok[slot] ? &x->kept_pm[slot] : NULL;
    if (project(x, q, v, stuck, locked, refactored ? NULL : pk, refactored ? pk : NULL) != OK)
        return SINGULAR;
    matvec(x, v, x->p);
    double t_after = 0.0;
    for (int i = 0; i < N + ns; i++) t_after += v[i] * x->p[i];
    t_after *= 0.5;
    if (t_after > 0.0 && t_after / 1.01 <= t_target && t_target <= 1.01 * t_after) {
        double scale = sqrt(t_target / t_after);
        for (int i = 0; i < N + ns; i++) { v[i] *= scale; x->p[i] *= scale; }
    }
    return OK;
}

#include "_kernel3d_base.h"
#include "_kernel3d_figures.h"

/* ------------------------------------------------------------------ the grid loop */
static void load(Ctx3D *x, const Advance3DCall *a) {
    int R = x->R, n = x->n, N = R * n;
    memcpy(x->q0, a->qr, sizeof(double) * N);
    memcpy(x->q0 + N, a->qs, sizeof(double) * x->ns);
    memcpy(x->v0, a->vr, sizeof(double) * N);
    memcpy(x->v0 + N, a->vs, sizeof(double) * x->ns);
    memcpy(x->l0, a->lam_r, sizeof(double) * R * ROWS);
    memcpy(x->l0 + R * ROWS, a->lam_s, sizeof(double) * x->cs);
    if (a->have_p) {
        memcpy(x->p0, a->pr, sizeof(double) * N);
        memcpy(x->p0 + N, a->ps, sizeof(double) * x->ns);
    } else if (x->base) {
        base_momenta(x, x->q0, x->v0, x->p0);
    } else {
        mass_matrix(x, x->q0);
        matvec(x, x->v0, x->p0);
    }
}

static void put(double **o, const double *src, int k) { memcpy(*o, src, sizeof(double) * k); *o += k; }

/* commit the step into the call's state; its iteration matrix is kept (kept_serves) */
static void commit(Ctx3D *x, Advance3DCall *a) {
    int R = x->R, n = x->n, N = R * n, ns = x->ns, cs = x->cs;
    if (x->pend_slot >= 0) {
        x->kept = 1;
        x->kept_slot = x->pend_slot;
        x->slot[x->kept_slot].uses = x->pend_uses;
        x->kept_h = x->pend_h;
        x->kept_locked = a->locked;
        memcpy(x->kept_q, x->q, sizeof(double) * (N + ns));
        memcpy(x->kept_v, x->v, sizeof(double) * (N + ns));
        for (int r = 0; r < R; r++) x->kept_stuck[r] = !isnan(a->stuck[r]);
        x->pend_slot = -1;
    }
    memcpy(a->qr, x->q, sizeof(double) * N);
    memcpy(a->qs, x->q + N, sizeof(double) * ns);
    memcpy(a->vr, x->v, sizeof(double) * N);
    memcpy(a->vs, x->v + N, sizeof(double) * ns);
    memcpy(a->lam_r, x->lam, sizeof(double) * R * ROWS);
    memcpy(a->lam_s, x->lam + R * ROWS, sizeof(double) * cs);
    memcpy(a->pr, x->p, sizeof(double) * N);
    memcpy(a->ps, x->p + N, sizeof(double) * ns);
    a->have_p = 1;
}

/* the committed state's output row (Advance3DCall) */
static void write_row(Ctx3D *x, const Advance3DCall *a, double *o) {
    int R = x->R, N = R * x->n, ns = x->ns;
    *o++ = a->t;
    put(&o, a->qr, N); put(&o, a->qs, ns); put(&o, a->vr, N); put(&o, a->vs, ns);
    put(&o, a->lam_r, R * ROWS); put(&o, a->lam_s, x->cs); put(&o, a->stuck, R);
    double kin = 0.0;
    for (int i = 0; i < N + ns; i++) kin += x->v[i] * x->p[i];
    *o++ = 0.5 * kin;
    *o++ = x->strain;
    *o++ = x->work_force;
    put(&o, x->work_fric, R);
    *o++ = x->iterations;
    *o++ = x->factorisations;
    *o++ = x->work_damp;
    base_row(x, x->q, x->p, o);
}

/* the simulator's release (UmbrellaSimulator3D._release) after a committed step */
static void release(Ctx3D *x, Advance3DCall *a) {
    const Model3D *m = x->m;
    for (int r = 0; r < x->R; r++) {
        if (isnan(a->stuck[r])) continue;
        double torque = fabs(a->lam_r[r * ROWS + ROW_STICK]);
        if ((m->stick_until[r] > 0.0 && a->t >= m->stick_until[r] - 1e-12)
            || (m->stick_torque[r] > 0.0 && torque >= m->stick_torque[r])) {
            a->stuck[r] = NAN;
            a->lam_r[r * ROWS + ROW_STICK] = 0.0;
        }
    }
}

/* the offset in a row of the works and counts a folded row sums (kernel3d.row_layout:
 * work_force, work_friction (R), iterations, factorisations, work_damping, work_drive) */
static int summed_offset(const Ctx3D *x) {
    int R = x->R, N = R * x->n;
    return 1 + 2 * N + 2 * x->ns + R * ROWS + x->cs + R + 2;
}

/* merge a step's stress figures f into its run's folded ones o: each the first of the
 * largest, a NaN the largest (np.argmax's over the steps: outputs.first_largest_of_substeps) */
static void merge_figures(int R, const double *f, double *o) {
    const double *f_at = f + R * FIG_CHANNELS;
    double *o_at = o + R * FIG_CHANNELS;
    for (int i = 0; i < R * FIG_CHANNELS; i++)
        if (!isnan(o[i]) && (isnan(f[i]) || f[i] > o[i])) {
            o[i] = f[i];
            o_at[2 * i] = f_at[2 * i];
            o_at[2 * i + 1] = f_at[2 * i + 1];
        }
}

int umbrella3d_advance(Ctx3D *x, Advance3DCall *a) {
    a->n_done = 0;
    a->iterations = 0;
    int N = x->R * x->n;
    int steps = a->single ? 1 : a->n_steps;
    Fit3D fit = {a->fit_modes, a->fit_u, a->fit_phi, a->fit_scale, a->fit_shrink, a->fit_whole,
                 a->fit_damping, a->fit_ut, a->fit_phit, a->bus_rank, a->bus_a, a->bus_b,
                 a->bus_c, a->bus_at, a->bus_bt, a->bus_ct, a->bus_newton_rank,
                 a->bus_newton_a, a->bus_newton_bt, a->bus_damp_rank, a->bus_damp_a,
                 a->bus_damp_b};
    int bus_ranks = a->bus_rank || a->bus_newton_rank || a->bus_damp_rank;
    if (a->fit_modes > (a->fit_whole ? N + x->ns : x->n) || (a->fit_whole && !x->base)
        || (bus_ranks && (a->fit_whole || !x->base)) || a->bus_rank > N + x->ns
        || a->bus_newton_rank > N + x->ns || a->bus_damp_rank > N + x->ns)
        return SINGULAR;
    int figures = x->fig && !a->single && a->out;
    if (figures) figures_start(x, a);
    int fold = a->single || a->fold < 1 ? 1 : a->fold;
    int sum_at = summed_offset(x), n_sum = x->R + 5, n_fig = FIG_CHANNELS * 3 * x->R;
    double sums[x->R + 5], fig[FIG_CHANNELS * 3 * x->R];     /* (C99 arrays of the ribs) */
    for (int k = 0; k < steps; k++) {
        load(x, a);
        double t_next = a->single ? a->t + a->h : (double)(a->k0 + k + 1) * a->h;
        double t_before = a->t;
        x->factorisations = 0;
        x->strain0_ok = k > 0;         /* (the state loaded: the last step's committed one) */
        x->strain0 = x->strain;
        int status;
        if (x->base) {
            x->base->drive_q = a->drive_q ? a->drive_q + 6 * k : NULL;
            x->base->drive_v = a->drive_v ? a->drive_v + 6 * k : NULL;
            if (x->base->prescribed && !a->drive_q) return SINGULAR;
            status = base_step(x, a->stuck, a->locked, t_next - a->t, a->force, a->tol,
                               a->phi_tol, a->max_iter,
                               a->locked && a->fit_modes > 0 ? &fit : NULL);
        } else {
            status = step(x, a->stuck, a->locked, t_next - a->t, a->force, a->tol, a->phi_tol,
                          a->max_iter, a->locked && a->fit_modes > 0 ? &fit : NULL);
        }
        if (status != OK) return status;
        if (!a->single && !a->locked && x->q[N] - x->m->y_stop <= 0.0) return CROSSING;
        /* a leaf at the axle before the lock: the planar kernel's fault (ALPHA1_AXLE), any rib */
        if (!a->locked)
            for (int r = 0; r < x->R; r++)
                if (x->q[r * x->n + x->m->i_a1] >= 1.57079632679489661923) return AXLE;
        a->iterations += x->iterations;
        a->t = t_next;
        commit(x, a);
        if (!a->single) release(x, a);
        double *row = a->out ? a->out + (size_t)(k / fold) * a->row_len : NULL;
        int first = k % fold == 0;
        if (row) {
            write_row(x, a, row);
            if (fold > 1) {             /* the run's sums so far, into its row */
                for (int i = 0; i < n_sum; i++)
                    sums[i] = first ? row[sum_at + i] : sums[i] + row[sum_at + i];
                memcpy(row + sum_at, sums, sizeof(double) * n_sum);
            }
        }
        if (figures) {
            double *o = row + a->row_len - n_fig;
            figure_row(x, a, t_next - t_before, first ? o : fig);
            if (!first) merge_figures(x->R, fig, o);
        }
        if (a->tips && !a->single) {    /* every physics step's tips, which a fold drops */
            double *o = a->tips + (size_t)k * 2 * x->R;
            for (int r = 0; r < x->R; r++) {
                o[2 * r] = a->qr[r * x->n + x->m->i_tip_v];
                o[2 * r + 1] = a->qr[r * x->n + x->m->i_tip_w];
            }
        }
        a->n_done++;
    }
    return OK;
}
