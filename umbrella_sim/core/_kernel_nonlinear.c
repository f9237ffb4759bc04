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
 * Elastic law of the compiled step (see _kernel_elastic.h): the strain energy of
 * nonlinear.StrainEnergy and the damping of NonlinearUmbrellaModel.damping_matrix, element
 * by element on the elastic band of _kernel.c.
 *
 *   U = 1/2 q.Kb q + 1/2 sum_e EA l_e eps_e^2,   eps_e = sum_g (w_g / l_e)(u'_g + v'_g^2 / 2)
 *
 * (Kb: the bending stiffness; v'^2 dropped with the linear strain, then U = 1/2 q.K q).
 * Gradient Kb q + sum_g EA w_g eps_e (du_g + v'_g dv_g); tangent Kb + EA l_e g g^T
 * + sum_g EA w_g eps_e dv_g dv_g^T with g = d eps_e / dq; the material tangent (no
 * geometric part) times beta is the Kelvin-Voigt damping C(q).  AVF gradient over a step:
 * 2-point Gauss in s on [0, 1] (exact: the integrand is cubic in s).
 *
 * The element mean over the Gauss points does not depend on the state: elastic_new sums it
 * once into du_mean = sum_g (w_g / l_e) u'_g and G = sum_g (w_g / l_e) v'_g v'_g^T, so that
 * eps_e = du_mean . x + x . G x / 2, g = du_mean + G x, the geometric tangent EA l_e eps_e G
 * and the membrane stress E x . G x / 2 (x: the element's coordinates) cost one 6 x 6
 * product per element instead of a pass over the Gauss points.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "_kernel_elastic.h"

#define EDOF 6      /* coordinates of an element: two nodes x (u, v, theta) */

ElasticLaw *elastic_new(const ElasticData *d) {
    if (d->n_gauss < 1) return NULL;
    ElasticLaw *law = calloc(1, sizeof(ElasticLaw));
    if (!law) return NULL;
    law->d = *d;
    int w = 2 * d->bw + 1, nc = d->ne + 4;
    size_t doubles = (size_t)d->ne * w + 4 * (size_t)d->n + (size_t)d->n_el * EDOF + d->n_el
                     + nc + (size_t)(d->n + nc) + (size_t)d->n_el * (EDOF + EDOF * EDOF)
                     + d->n + (size_t)d->n_el * (EDOF + 2) + d->n_el;
    law->band = calloc(doubles, sizeof(double));
    if (!law->band) { free(law); return NULL; }
    double *p = law->band + (size_t)d->ne * w;
    law->qa = p; p += d->n;
    law->qb = p; p += d->n;
    law->q_base = p; p += d->n;
    law->energy_q = p; p += d->n;
    law->band_h = -1.0;
    law->g = p; p += (size_t)d->n_el * EDOF;
    law->el_stress = p; p += d->n_el;
    law->el_stress_rate = p; p += d->n_el;
    law->lam_base = p; p += nc;
    law->dx = p; p += d->n + nc;
    law->du_mean = p; p += (size_t)d->n_el * EDOF;
    law->g_mat = p; p += (size_t)d->n_el * EDOF * EDOF;
    law->start_q = p; p += d->n;
    law->start_gx = p; p += (size_t)d->n_el * EDOF;
    law->start_eps = p;
    for (int e = 0; e < d->n_el; e++)
        for (int gp = 0; gp < d->n_gauss; gp++) {
            size_t row = ((size_t)e * d->n_gauss + gp) * EDOF;
            double mw = d->mean_w[(size_t)e * d->n_gauss + gp];
            double *dm = law->du_mean + (size_t)e * EDOF, *gm = law->g_mat + (size_t)e * EDOF * EDOF;
            for (int k = 0; k < EDOF; k++) {
                dm[k] += mw * d->du[row + k];
                if (d->nonlinear)
                    for (int l = 0; l < EDOF; l++) gm[k * EDOF + l] += mw * d->dv[row + k] * d->dv[row + l];
            }
        }
    return law;
}

void elastic_free(ElasticLaw *law) {
    if (!law) return;
    free(law->band);
    free(law);
}

/* eps_e = a + xgx / 2 for the coordinates q, with a = du_mean . x and xgx = x . G x (0 for
 * the linear strain); x: the element's coordinates, gx = G x (0 for the linear strain) */
static double element_strain(const ElasticLaw *law, int e, const double *q, double *x, double *gx,
                             double *a_out, double *xgx_out) {
    const ElasticData *d = &law->d;
    const int *iq = d->el_q + (size_t)e * EDOF;
    const double *dm = law->du_mean + (size_t)e * EDOF, *gm = law->g_mat + (size_t)e * EDOF * EDOF;
    for (int k = 0; k < EDOF; k++) x[k] = iq[k] >= 0 ? q[iq[k]] : 0.0;
    double a = 0.0, xgx = 0.0;
    if (!d->nonlinear) {   /* G = 0 */
        for (int k = 0; k < EDOF; k++) { gx[k] = 0.0; a += dm[k] * x[k]; }
    } else {
        for (int k = 0; k < EDOF; k++) {
            double s = 0.0;
            for (int l = 0; l < EDOF; l++) s += gm[k * EDOF + l] * x[l];
            gx[k] = s;
            a += dm[k] * x[k];
            xgx += x[k] * s;
        }
    }
    if (a_out) { *a_out = a; *xgx_out = xgx; }
    return a + 0.5 * xgx;
}

/* The start terms G x0, du_mean . x0 and x0 . G x0 of every element at q0, kept while q0
 * stays the same: the Newton iterations of a step share them, and the end of a step computes
 * them at q1 for its energy and membrane stress, which the next step then starts from. */
static void step_start(ElasticLaw *law, const double *q0) {
    const ElasticData *d = &law->d;
    if (law->start_valid && memcmp(q0, law->start_q, sizeof(double) * d->n) == 0) return;
    double x[EDOF];
    for (int e = 0; e < d->n_el; e++) {
        double *ce = law->start_eps + 2 * (size_t)e;
        element_strain(law, e, q0, x, law->start_gx + (size_t)e * EDOF, &ce[0], &ce[1]);
    }
    memcpy(law->start_q, q0, sizeof(double) * d->n);
    law->start_valid = 1;
}

/* Strain of element e along the step q0 + s (q1 - q0) at the two AVF points s = AVF_S[j]:
 * eps[j] and g_j = d eps / dq there (g: 2 x 6), from the start terms and one G dx
 * (eps(s) = du.x0 + s du.dx + (x0.G x0 + 2 s dx.G x0 + s^2 dx.G dx) / 2, g(s) = du + G x0
 * + s G dx: the same polynomial the Gauss points evaluate, without a G product per point) */
static const double AVF_S[2] = {0.21132486540518713, 0.78867513459481287};  /* 1/2 -+ 1/(2 sqrt 3) */

static void element_step_strain(const ElasticLaw *law, int e, const double *q0, const double *q1,
                                double *eps, double *g) {
    const ElasticData *d = &law->d;
    const int *iq = d->el_q + (size_t)e * EDOF;
    const double *dm = law->du_mean + (size_t)e * EDOF, *gm = law->g_mat + (size_t)e * EDOF * EDOF;
    const double *gx0 = law->start_gx + (size_t)e * EDOF, *ce = law->start_eps + 2 * (size_t)e;
    double dx[EDOF], gdx[EDOF], lin1 = 0.0, c1 = 0.0, c2 = 0.0;
    for (int k = 0; k < EDOF; k++) dx[k] = iq[k] >= 0 ? q1[iq[k]] - q0[iq[k]] : 0.0;
    for (int k = 0; k < EDOF; k++) {
        double s = 0.0;
        for (int l = 0; l < EDOF; l++) s += gm[k * EDOF + l] * dx[l];
        gdx[k] = s;
        lin1 += dm[k] * dx[k];
        c1 += dx[k] * gx0[k];
        c2 += dx[k] * s;
    }
    for (int j = 0; j < 2; j++) {
        double t = AVF_S[j];
        eps[j] = ce[0] + t * lin1 + 0.5 * (ce[1] + t * (2.0 * c1 + t * c2));
        for (int k = 0; k < EDOF; k++) g[j * EDOF + k] = dm[k] + gx0[k] + t * gdx[k];
    }
}

/* g = d eps_e / dq = du_mean + G x on the element's coordinates */
static void element_strain_gradient(const ElasticLaw *law, int e, const double *gx, double *g) {
    const double *dm = law->du_mean + (size_t)e * EDOF;
    for (int k = 0; k < EDOF; k++) g[k] = dm[k] + gx[k];
}

/* x . Kb x */
static double bending_quadratic(const ElasticData *d, const double *x) {
    int ne = d->ne, bw = d->bw, w = 2 * bw + 1;
    double quad = 0.0;
    for (int p = 0; p < ne; p++) {
        int lo = p - bw < 0 ? 0 : p - bw, hi = p + bw >= ne ? ne - 1 : p + bw;
        const double *r = d->kb_band + (size_t)p * w + bw - p;
        double s = 0.0;
        for (int j = lo; j <= hi; j++) s += r[j] * x[d->elastic_idx[j]];
        quad += x[d->elastic_idx[p]] * s;
    }
    return quad;
}

/* y += scale * (grad U(q) - Kb q), the membrane part, at the elastic q indices */
static void membrane_gradient(const ElasticLaw *law, const double *q, double scale, double *y) {
    const ElasticData *d = &law->d;
    double x[EDOF], gx[EDOF], g[EDOF];
    for (int e = 0; e < d->n_el; e++) {
        double eps = element_strain(law, e, q, x, gx, NULL, NULL);
        element_strain_gradient(law, e, gx, g);
        const int *iq = d->el_q + (size_t)e * EDOF;
        double nw = scale * d->ea_l[e] * eps;
        for (int k = 0; k < EDOF; k++)
            if (iq[k] >= 0) y[iq[k]] += nw * g[k];
    }
}

/* band += scale * (tangent of U at q), or its material part (geometric = 0); without the
 * bending stiffness Kb, which the caller adds once */
static void tangent_band(const ElasticLaw *law, const double *q, double scale, int geometric,
                         double *band) {
    const ElasticData *d = &law->d;
    int bw = d->bw, w = 2 * bw + 1;
    double x[EDOF], gx[EDOF], g[EDOF];
    for (int e = 0; e < d->n_el; e++) {
        double eps = element_strain(law, e, q, x, gx, NULL, NULL);
        element_strain_gradient(law, e, gx, g);
        const int *pos = d->el_pos + (size_t)e * EDOF;
        const double *gm = law->g_mat + (size_t)e * EDOF * EDOF;
        double geo = geometric && d->nonlinear ? d->ea_l[e] * eps : 0.0;   /* times G */
        for (int k = 0; k < EDOF; k++) {
            if (pos[k] < 0) continue;
            double *r = band + (size_t)pos[k] * w + bw - pos[k];
            for (int l = 0; l < EDOF; l++)
                if (pos[l] >= 0) r[pos[l]] += scale * (d->ea_l[e] * g[k] * g[l] + geo * gm[k * EDOF + l]);
        }
    }
}

/* x . M x with M the material tangent at q (Kb + sum EA l_e g g^T); y (+)= scale M x.
 * kbx: Kb x at the elastic q indices (the step's band products), else NULL: x . Kb x is
 * computed here, and y must be NULL. */
static double material_apply(const ElasticLaw *law, const double *q, const double *x,
                             const double *kbx, double scale, double *y) {
    const ElasticData *d = &law->d;
    double xe[EDOF], gx[EDOF], g[EDOF], quad = 0.0;
    if (kbx) {
        for (int p = 0; p < d->ne; p++) {
            int i = d->elastic_idx[p];
            quad += x[i] * kbx[i];
            if (y) y[i] += scale * kbx[i];
        }
    } else {
        quad += bending_quadratic(d, x);
    }
    for (int e = 0; e < d->n_el; e++) {
        element_strain(law, e, q, xe, gx, NULL, NULL);
        element_strain_gradient(law, e, gx, g);
        const int *iq = d->el_q + (size_t)e * EDOF;
        double gx = 0.0;
        for (int k = 0; k < EDOF; k++) if (iq[k] >= 0) gx += g[k] * x[iq[k]];
        quad += d->ea_l[e] * gx * gx;
        if (y)
            for (int k = 0; k < EDOF; k++) if (iq[k] >= 0) y[iq[k]] += scale * d->ea_l[e] * gx * g[k];
    }
    return quad;
}

void elastic_force(ElasticLaw *law, const double *q0, const double *q1, double h,
                   const double *kb_dq, double *out) {
    const ElasticData *d = &law->d;
    int n = d->n;
    if (!d->nonlinear) {   /* U quadratic, C = beta K constant: K (q_m + beta dq / h) */
        double c = d->beta / h;
        for (int i = 0; i < n; i++) law->qa[i] = q0[i] + 0.5 * (q1[i] - q0[i]) + c * (q1[i] - q0[i]);
        if (c > 0.0)
            for (int p = 0; p < d->ne; p++) { int i = d->elastic_idx[p]; out[i] += c * kb_dq[i]; }
        membrane_gradient(law, law->qa, 1.0, out);
        return;
    }
    /* AVF: Kb q_m (on entry: Kb q is linear) + the mean of the membrane gradient at the
     * Gauss points */
    step_start(law, q0);
    for (int e = 0; e < d->n_el; e++) {
        double eps[2], g[2 * EDOF];
        element_step_strain(law, e, q0, q1, eps, g);
        const int *iq = d->el_q + (size_t)e * EDOF;
        double w0 = 0.5 * d->ea_l[e] * eps[0], w1 = 0.5 * d->ea_l[e] * eps[1];
        for (int k = 0; k < EDOF; k++)
            if (iq[k] >= 0) out[iq[k]] += w0 * g[k] + w1 * g[EDOF + k];
    }
    if (d->beta > 0.0) {
        for (int i = 0; i < n; i++) {
            law->qa[i] = q0[i] + 0.5 * (q1[i] - q0[i]);
            law->qb[i] = q1[i] - q0[i];
        }
        material_apply(law, law->qa, law->qb, kb_dq, d->beta / h, out);
    }
}

void elastic_iteration_band(ElasticLaw *law, const double *q0, const double *q1, double h) {
    const ElasticData *d = &law->d;
    int n = d->n;
    size_t nb = (size_t)d->ne * (2 * d->bw + 1);
    double kb_scale = 0.25 * h * h + 0.5 * h * d->beta;   /* sum of the scales below */
    if (!d->nonlinear && law->band_h == h) return;       /* constant for the linear strain */
    for (size_t k = 0; k < nb; k++) law->band[k] = kb_scale * d->kb_band[k];
    law->band_h = h;
    if (d->nonlinear) {   /* sum_j h^2/4 s_j (tangent at the AVF point j), one pass */
        int bw = d->bw, w = 2 * bw + 1;
        step_start(law, q0);
        for (int e = 0; e < d->n_el; e++) {
            double eps[2], g[2 * EDOF];
            element_step_strain(law, e, q0, q1, eps, g);
            const int *pos = d->el_pos + (size_t)e * EDOF;
            const double *gm = law->g_mat + (size_t)e * EDOF * EDOF;
            double c0 = 0.25 * h * h * AVF_S[0] * d->ea_l[e], c1 = 0.25 * h * h * AVF_S[1] * d->ea_l[e];
            double geo = c0 * eps[0] + c1 * eps[1];   /* times G */
            for (int k = 0; k < EDOF; k++) {
                if (pos[k] < 0) continue;
                double *r = law->band + (size_t)pos[k] * w + bw - pos[k];
                double a0 = c0 * g[k], a1 = c1 * g[EDOF + k];
                for (int l = 0; l < EDOF; l++)
                    if (pos[l] >= 0) r[pos[l]] += a0 * g[l] + a1 * g[EDOF + l] + geo * gm[k * EDOF + l];
            }
        }
    } else {
        for (int s = 0; s < 2; s++) {
            for (int i = 0; i < n; i++) law->qa[i] = q0[i] + AVF_S[s] * (q1[i] - q0[i]);
            tangent_band(law, law->qa, 0.25 * h * h * AVF_S[s], 1, law->band);
        }
    }
    if (d->beta > 0.0) {
        for (int i = 0; i < n; i++) law->qa[i] = q0[i] + 0.5 * (q1[i] - q0[i]);
        tangent_band(law, law->qa, 0.5 * h * d->beta, 0, law->band);
    }
}

double elastic_energy(ElasticLaw *law, const double *q, const double *kbq) {
    const ElasticData *d = &law->d;
    /* asked for the end of a step, then its output row, then the start of the next */
    if (law->energy_valid && memcmp(q, law->energy_q, sizeof(double) * d->n) == 0)
        return law->energy;
    double u = 0.0;
    if (kbq)
        for (int p = 0; p < d->ne; p++) { int i = d->elastic_idx[p]; u += q[i] * kbq[i]; }
    else
        u += bending_quadratic(d, q);
    step_start(law, q);   /* the element strains at q: the next step starts from them */
    for (int e = 0; e < d->n_el; e++) {
        const double *ce = law->start_eps + 2 * (size_t)e;
        double eps = ce[0] + 0.5 * ce[1];
        u += d->ea_l[e] * eps * eps;
    }
    memcpy(law->energy_q, q, sizeof(double) * d->n);
    law->energy = 0.5 * u;
    law->energy_valid = 1;
    return law->energy;
}

double elastic_dissipation(ElasticLaw *law, const double *q0, const double *q1, double h) {
    const ElasticData *d = &law->d;
    double diss = 0.0;
    if (d->beta > 0.0) {
        for (int i = 0; i < d->n; i++) {
            law->qa[i] = q0[i] + 0.5 * (q1[i] - q0[i]);
            law->qb[i] = q1[i] - q0[i];
        }
        diss = d->beta * material_apply(law, law->qa, law->qb, NULL, 0.0, NULL) / h;
    }
    law->last_dissipation = diss;
    return diss;
}

void elastic_membrane_stress(ElasticLaw *law, const double *q) {
    const ElasticData *d = &law->d;
    step_start(law, q);   /* usually kept from the energy of the step that ended at q */
    for (int e = 0; e < d->n_el; e++)
        law->el_stress[e] = d->youngs_modulus * 0.5 * law->start_eps[2 * (size_t)e + 1];
}

void elastic_membrane_stress_rate(ElasticLaw *law, const double *q, const double *v) {
    const ElasticData *d = &law->d;
    step_start(law, q);   /* G x of q's element coordinates x */
    for (int e = 0; e < d->n_el; e++) {
        const int *iq = d->el_q + (size_t)e * EDOF;
        const double *gx = law->start_gx + (size_t)e * EDOF;
        double r = 0.0;   /* d/dt (x . G x / 2) = (G x) . x_t */
        for (int k = 0; k < EDOF; k++) if (iq[k] >= 0) r += gx[k] * v[iq[k]];
        law->el_stress_rate[e] = d->youngs_modulus * r;
    }
}

double elastic_last_dissipation(const ElasticLaw *law) {
    return law->last_dissipation;
}
