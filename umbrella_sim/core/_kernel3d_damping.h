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

/* The beams' structural damping of the umbrella's 3D step (umbrella3d/damping3d.py: the planar
 * model's, C = beta K over every rib's elastic coordinates; the co-rotational ribs' C(q_m) =
 * beta B^T D B at the step's midpoint, _kernel3d_nonlinear.h's nl_damping_force and, in
 * iteration_blocks, nl_damping_block): the damping force -C dq / h in
 * the step's residual (step, base_step), h/2 C in its iteration matrix (stiffness_weight:
 * M + (h^2/4 + h beta/2) K), and the step's dissipation dq . C dq / h; with a damped mode fit
 * (Fit3D.damp), its share U diag(c_w - c) U^T dq / h (integrators.LockedModeFit.
 * damping_force), rib by rib (a free bus's: with its low-rank difference to the whole free
 * system's) or the whole free system's.  Included by _kernel3d.c after the
 * mode fit's maps. */

/* the weight of K in the iteration matrix's elastic blocks: h^2/4, + h beta / 2 damped */
static double stiffness_weight(const Model3D *m, double h) {
    return 0.25 * h * h + 0.5 * h * m->damping_beta;
}

/* y (len) += sum_j a_j (damp_j / h) (u_j . dq): the share of a fit's modes (rows u_j over
 * len coordinates, each mode's damping change damp_j; a = u) in the damping force, or of a
 * low-rank share A B^T dq / h (rows a_j, u = b_j, damp NULL: 1) */
static void modal_damping(const double *a, const double *u, const double *damp, int modes,
                          int len, const double *dq, double h, double *y) {
    for (int j = 0; j < modes; j++) {
        const double *uj = u + (size_t)j * len, *aj = a + (size_t)j * len;
        double d = 0.0;
        for (int i = 0; i < len; i++) d += uj[i] * dq[i];
        d *= (damp ? damp[j] : 1.0) / h;
        for (int i = 0; i < len; i++) y[i] += aj[i] * d;
    }
}

/* y (N + ns) = C dq / h + the fit's share, at the iterate's step x->dq */
static void damping_forces(Ctx3D *x, const Fit3D *fit, double h, double *y) {
    const Model3D *m = x->m;
    int R = x->R, n = x->n, N = R * n, L = N + x->ns;
    double c = m->damping_beta / h;
    for (int r = 0; r < R; r++) {
        double *yr = y + (size_t)r * n;
        if (m->nl_elements) {          /* the co-rotational ribs: C(q_m) (_kernel3d_nonlinear.h) */
            nl_damping_force(m, r, n, x->q0 + (size_t)r * n, x->dq + (size_t)r * n, c, yr);
            continue;
        }
        rows_matvec(x, &x->krows, m->stiffness + (size_t)r * n * n, x->dq + (size_t)r * n, yr);
        for (int a = 0; a < n; a++) yr[a] *= c;
    }
    for (int i = N; i < L; i++) y[i] = 0.0;
    if (!fit || !fit->damp) return;
    if (fit->whole) {                  /* the free system's modes: rows over every coordinate */
        modal_damping(fit->u, fit->u, fit->damp, fit->r, L, x->dq, h, y);
        return;
    }
    for (int r = 0; r < R; r++) {      /* each rib's modes */
        const double *u = fit->u + (size_t)r * fit->r * n;
        modal_damping(u, u, fit->damp + (size_t)r * fit->r, fit->r, n, x->dq + (size_t)r * n, h,
                      y + (size_t)r * n);
    }
    if (fit->damp_rank)                /* a free bus's: the whole fit's share less the ribs' */
        modal_damping(fit->damp_a, fit->damp_b, NULL, fit->damp_rank, L, x->dq, h, y);
}

/* y (rib r's n) += its damping force's negative (damping_forces' x->damp) */
static void damping_add(const Ctx3D *x, int r, double *y) {
    const double *d = x->damp + (size_t)r * x->n;
    for (int a = 0; a < x->n; a++) y[a] += d[a];
}

/* the step's dissipation dq . (C dq / h + the fit's share) >= 0 at the step taken (x->dq) */
static double damping_work(Ctx3D *x, const Fit3D *fit, double h) {
    int L = x->R * x->n + x->ns;
    damping_forces(x, fit, h, x->damp);
    double w = 0.0;
    for (int i = 0; i < L; i++) w += x->damp[i] * x->dq[i];
    return w;
}
