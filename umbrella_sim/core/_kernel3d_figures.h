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
 * Each committed grid step's stress figures, rib by rib, in the compiled advance's rows
 * (included by _kernel3d.c; umbrella3d/outputs3d.py Record3D._crests and _put_steps are the
 * numpy reference, which documents the rule): at every stress point of a rib (the leaf's,
 * then the link's) the four components (axial, bending in and out of the plane, torsion
 * shear: the recovery rows times the body's elastic coordinates, model3d.stress_blocks)
 * and the combined von Mises bound sqrt((|a| + |bz| + |by|)^2 + 3 tau^2), each with its
 * rate (the same rows times the elastic velocities); over the step the crest of the cubic
 * Hermite interpolant of the ends' values and rates times h (hermite_peak, _kernel.c's
 * arithmetic; points whose bound |ends| + 4/27 (|d0| + |d1|) cannot pass the row's largest
 * end value keep their ends' value: outputs.hermite_crests), or the end's own |value| for a
 * run's first step (Advance3DCall.crest_from_state 0: the step before was across the lock
 * or there was none); the largest over the rib's points of each of the five channels and
 * where (the first point holding it: body code 0 leaf / 1 link, x along it).  The figures
 * are the last 15 R doubles of a row: R x 5 largest values, then R x 5 x 2 places.  The
 * co-rotational ribs (model flexible-nonlinear, umbrella3d_set_corotational_stress) take
 * the same rule with their components from the elements' co-rotated strains at both ends
 * of every element (_kernel3d_nonlinear.h's nl_stress_components; numpy reference
 * corotational3d.RibCorotationalStrain.stress_blocks) in place of the recovery rows.
 */

#define FIG_CHANNELS 5         /* outputs3d.STRESS_NAMES */
#define FIG_HERMITE_RATE_BOUND (4.0 / 27.0)   /* outputs.HERMITE_RATE_BOUND */

struct Figures3D {
    int pl, pk, P;                     /* stress points of the leaf, the link, a rib's */
    double *rows[2];                   /* R x 4 pb x ne: each body's recovery rows */
    int *ptr[2], *col[2];              /* their nonzeros (any rib's), row by row */
    double *moduli;                    /* R x 3, the co-rotational ribs' (rows NULL): E, E c,
                                        * G c_t (nl_stress_components) */
    double *x;                         /* P: each point's x along its body */
    double *val[2], *rate[2];          /* R x 5 x P: a state's channels (two: a step's ends) */
    int cur;                           /* the buffer of the last committed state */
    int have;                          /* val[cur] holds the state the next step starts at */
};

static void figures_free(Figures3D *f) {
    if (!f) return;
    for (int j = 0; j < 2; j++) {
        free(f->rows[j]); free(f->val[j]); free(f->rate[j]); free(f->ptr[j]); free(f->col[j]);
    }
    free(f->x);
    free(f->moduli);
    free(f);
}

int umbrella3d_set_stress(Ctx3D *x, int leaf_points, int link_points, const double *leaf_rows,
                          const double *link_rows, const double *point_x) {
    figures_free(x->fig);
    x->fig = NULL;
    if (leaf_points <= 0 && link_points <= 0) return OK;
    Figures3D *f = calloc(1, sizeof(Figures3D));
    if (!f) return SINGULAR;
    int R = x->R, P = leaf_points + link_points;
    f->pl = leaf_points;
    f->pk = link_points;
    f->P = P;
    const double *src[2] = {leaf_rows, link_rows};
    int ok = 1;
    for (int j = 0; j < 2; j++) {
        size_t len = (size_t)R * 4 * (j ? link_points : leaf_points) * x->b[j].ne;
        f->rows[j] = malloc(sizeof(double) * (len ? len : 1));
        f->val[j] = calloc((size_t)R * FIG_CHANNELS * P, sizeof(double));
        f->rate[j] = calloc((size_t)R * FIG_CHANNELS * P, sizeof(double));
        ok = ok && f->rows[j] && f->val[j] && f->rate[j];
        if (f->rows[j] && len) memcpy(f->rows[j], src[j], sizeof(double) * len);
        /* the nonzeros of each row over the ribs (a recovery row reads its element's
         * coordinates of one kind: a few of the body's) */
        int nrow = 4 * (j ? link_points : leaf_points), ne = x->b[j].ne, nnz = 0;
        f->ptr[j] = malloc(sizeof(int) * (nrow + 1));
        f->col[j] = malloc(sizeof(int) * (nrow * ne + 1));
        ok = ok && f->ptr[j] && f->col[j];
        for (int i = 0; ok && i < nrow; i++) {
            f->ptr[j][i] = nnz;
            for (int e = 0; e < ne; e++) {
                int any = 0;
                for (int r = 0; r < R && !any; r++)
                    any = src[j][((size_t)r * nrow + i) * ne + e] != 0.0;
                if (any) f->col[j][nnz++] = e;
            }
        }
        if (ok) f->ptr[j][nrow] = nnz;
    }
    f->x = malloc(sizeof(double) * P);
    if (!ok || !f->x) { figures_free(f); return SINGULAR; }
    memcpy(f->x, point_x, sizeof(double) * P);
    x->fig = f;
    return OK;
}

/* ------------------------------------------------------------------ co-rotational ribs
 * The figures of the co-rotational ribs (model flexible-nonlinear): the same channels,
 * crests and places, the components from each element's co-rotated strains
 * (nl_stress_components) at both ends of every element; moduli (R x 3: E, E c, G c_t) and
 * each point's x copied. */
int umbrella3d_set_corotational_stress(Ctx3D *x, int leaf_points, int link_points,
                                       const double *moduli, const double *point_x) {
    figures_free(x->fig);
    x->fig = NULL;
    int R = x->R, P = leaf_points + link_points;
    if (leaf_points < 0 || link_points < 0 || P != 2 * x->m->nl_elements || P == 0)
        return SINGULAR;
    Figures3D *f = calloc(1, sizeof(Figures3D));
    if (!f) return SINGULAR;
    f->pl = leaf_points;
    f->pk = link_points;
    f->P = P;
    int ok = 1;
    for (int j = 0; j < 2; j++) {
        f->val[j] = calloc((size_t)R * FIG_CHANNELS * P, sizeof(double));
        f->rate[j] = calloc((size_t)R * FIG_CHANNELS * P, sizeof(double));
        ok = ok && f->val[j] && f->rate[j];
    }
    f->moduli = malloc(sizeof(double) * 3 * R);
    f->x = malloc(sizeof(double) * P);
    if (!ok || !f->moduli || !f->x) { figures_free(f); return SINGULAR; }
    memcpy(f->moduli, moduli, sizeof(double) * 3 * R);
    memcpy(f->x, point_x, sizeof(double) * P);
    x->fig = f;
    return OK;
}

static double fig_sign(double s) { return s > 0.0 ? 1.0 : s < 0.0 ? -1.0 : s; }

/* the five channels of the state (q, v) at every point of every rib into val, rate
 * (R x 5 x P: channel-major per rib): the four components, then von Mises (Record3D's
 * combined) */
static void figure_channels(Ctx3D *x, const Figures3D *f, const double *q,
                            const double *v, double *val, double *rate) {
    int R = x->R, n = x->n, P = f->P;
    for (int r = 0; r < R; r++) {
        double *sv = val + (size_t)r * FIG_CHANNELS * P, *sr = rate + (size_t)r * FIG_CHANNELS * P;
        if (f->moduli)         /* the co-rotational ribs' (_kernel3d_nonlinear.h) */
            nl_stress_components(x, r, q + (size_t)r * n, v + (size_t)r * n,
                                 f->moduli + 3 * r, P, sv, sr);
        for (int j = 0; !f->moduli && j < 2; j++) {
            const Body *b = &x->b[j];
            int pb = j ? f->pk : f->pl, first = j ? f->pl : 0, ne = b->ne;
            const double *qe = q + (size_t)r * n + b->off + b->t + 1;
            const double *ve = v + (size_t)r * n + b->off + b->t + 1;
            const double *A = f->rows[j] + (size_t)r * 4 * pb * ne;
            const int *ptr = f->ptr[j], *col = f->col[j];
            for (int c = 0; c < 4; c++)
                for (int p = 0; p < pb; p++) {
                    int i = c * pb + p;
                    const double *row = A + (size_t)i * ne;
                    double s = 0.0, d = 0.0;
                    for (int k = ptr[i]; k < ptr[i + 1]; k++) {  /* (ascending, as dense) */
                        int e = col[k];
                        s += row[e] * qe[e];
                        d += row[e] * ve[e];
                    }
                    sv[c * P + first + p] = s;
                    sr[c * P + first + p] = d;
                }
        }
        for (int p = 0; p < P; p++) {
            double s0 = sv[p], s1 = sv[P + p], s2 = sv[2 * P + p], s3 = sv[3 * P + p];
            double total = fabs(s0) + fabs(s1) + fabs(s2);
            double vm = sqrt(total * total + 3.0 * s3 * s3);
            double growth = fig_sign(s0) * sr[p] + fig_sign(s1) * sr[P + p]
                + fig_sign(s2) * sr[2 * P + p];
            sv[4 * P + p] = vm;
            sr[4 * P + p] = vm > 0.0 ? (total * growth + 3.0 * s3 * sr[3 * P + p]) / vm : 0.0;
        }
    }
}

/* max(|s0|, |s1|), NaN if either is (np.maximum) */
static double fig_ends(double s0, double s1) {
    double e0 = fabs(s0), e1 = fabs(s1);
    return isnan(e0) || isnan(e1) ? NAN : (e0 > e1 ? e0 : e1);
}

/* the committed state's figures (a->qr, a->vr: the step of length h from the state before,
 * whose channels val[cur] hold if have) into o (the row's last 15 R doubles) */
static void figure_row(Ctx3D *x, const Advance3DCall *a, double h, double *o) {
    Figures3D *f = x->fig;
    int R = x->R, P = f->P, nxt = 1 - f->cur, crest = f->have;
    double *v1 = f->val[nxt], *r1 = f->rate[nxt], *v0 = f->val[f->cur], *r0 = f->rate[f->cur];
    figure_channels(x, f, a->qr, a->vr, v1, r1);
    double *top = o, *at = o + R * FIG_CHANNELS;
    for (int r = 0; r < R; r++)
        for (int c = 0; c < FIG_CHANNELS; c++) {
            size_t k0 = ((size_t)r * FIG_CHANNELS + c) * P;
            /* the row's largest end value (NaN if one is: numpy's max) */
            double row_end = -INFINITY;
            int nan_row = 0;
            for (int p = 0; crest && p < P; p++) {
                double e = fig_ends(v0[k0 + p], v1[k0 + p]);
                if (isnan(e)) nan_row = 1;
                else if (e > row_end) row_end = e;
            }
            double best = 0.0;
            int at_p = 0, found = 0;
            for (int p = 0; p < P; p++) {
                double s1 = v1[k0 + p], e1 = fabs(s1), value;
                if (!crest) {
                    value = e1;
                } else {
                    double s0 = v0[k0 + p], e = fig_ends(s0, s1);
                    double d0 = h * r0[k0 + p], d1 = h * r1[k0 + p];
                    double reach = e + FIG_HERMITE_RATE_BOUND * (fabs(d0) + fabs(d1));
                    value = !nan_row && reach > row_end ? hermite_crest(s0, d0, s1, d1, e) : e;
                }
                /* the first of the largest; a NaN the largest (np.argmax) */
                if (!found || isnan(value) || value > best) {
                    if (found && isnan(best)) continue;
                    best = value;
                    at_p = p;
                    found = 1;
                }
            }
            top[r * FIG_CHANNELS + c] = best;
            at[(r * FIG_CHANNELS + c) * 2] = at_p >= f->pl ? 1.0 : 0.0;
            at[(r * FIG_CHANNELS + c) * 2 + 1] = f->x[at_p];
        }
    f->cur = nxt;
    f->have = 1;
}

/* the run's first state (the loaded one), the start of its first step's crests if
 * crest_from_state, else none */
static void figures_start(Ctx3D *x, const Advance3DCall *a) {
    Figures3D *f = x->fig;
    f->have = a->crest_from_state;
    if (f->have)
        figure_channels(x, f, a->qr, a->vr, f->val[f->cur], f->rate[f->cur]);
}
