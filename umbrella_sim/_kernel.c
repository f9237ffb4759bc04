/*
 * Compiled step of the energy-consistent midpoint integrator (see integrators.py).
 *
 * The same arithmetic as NewmarkDAE._step in numpy (the reference path the tests compare
 * against): discrete-gradient residual, Newton iterations on a once-factored iteration
 * matrix, velocity projection in the mass metric.  Plain C on double arrays, loaded with
 * ctypes: no Python or numpy headers.  Matrices are row-major.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    int n;                 /* coordinates */
    int n_link;            /* link elastic coordinates */
    int i_r2x, i_r2y, i_alpha2, s_link;
    int i_u_joint, i_u_sleeve;
    int n_elastic;
    double l1, l3, y_stop;
    double j0_leaf, j0_link, pbar0;
    const double *c_full, *g_full, *mff_full, *w_full;   /* n, n, n*n, n*n */
    const int *body;       /* n: -1 not elastic, 0 leaf, 1 link */
    const double *sbar, *isbar;                          /* 2 x n_link each */
    const double *mass_template, *stiffness;             /* n*n */
    const int *elastic_idx;                              /* n_elastic */
} Model;

enum { OK = 0, NO_CONVERGENCE = 1, NON_FINITE = 2, SINGULAR = 3, NOT_PD = 4, NO_MEMORY = 5 };

static void mass_matrix(const Model *m, const double *q, double *M) {
    int n = m->n, ia = m->i_alpha2, ix = m->i_r2x, iy = m->i_r2y, sk = m->s_link;
    memcpy(M, m->mass_template, sizeof(double) * n * n);
    double maa[2] = {m->j0_leaf, m->j0_link};
    for (int i = 0; i < n; i++) {
        int b = m->body[i];
        if (b < 0) continue;
        double h = m->c_full[i], af = m->g_full[i];
        for (int j = 0; j < n; j++) {
            h += m->mff_full[i * n + j] * q[j];
            af += q[j] * m->w_full[j * n + i];
        }
        maa[b] += (m->c_full[i] + h) * q[i];
        int a = b == 0 ? 0 : ia;
        M[a * n + i] = af;
        M[i * n + a] = af;
    }
    M[0] = maa[0];
    M[ia * n + ia] = maa[1];
    double c = cos(q[ia]), s = sin(q[ia]);
    double ub0 = m->pbar0, ub1 = 0.0;
    for (int k = 0; k < m->n_link; k++) {
        ub0 += m->sbar[k] * q[sk + k];
        ub1 += m->sbar[m->n_link + k] * q[sk + k];
    }
    M[ix * n + ia] = M[ia * n + ix] = -c * ub1 - s * ub0;
    M[iy * n + ia] = M[ia * n + iy] = -s * ub1 + c * ub0;
    for (int k = 0; k < m->n_link; k++) {
        double r0 = c * m->sbar[k] + s * m->isbar[k];
        double r1 = c * m->sbar[m->n_link + k] + s * m->isbar[m->n_link + k];
        M[ix * n + sk + k] = M[(sk + k) * n + ix] = r0;
        M[iy * n + sk + k] = M[(sk + k) * n + iy] = r1;
    }
}

static void matvec(int n, const double *A, const double *x, double *y) {
    for (int i = 0; i < n; i++) {
        double acc = 0.0;
        for (int j = 0; j < n; j++) acc += A[i * n + j] * x[j];
        y[i] = acc;
    }
}

/* d/dq [1/2 a^T M(q) b] */
static void bilinear_gradient(const Model *m, const double *q, const double *a, const double *b,
                              double *out, double *tmp) {
    int n = m->n, ia = m->i_alpha2, ix = m->i_r2x, iy = m->i_r2y, sk = m->s_link, nl = m->n_link;
    double *wa = tmp, *wb = tmp + n;
    matvec(n, m->w_full, a, wa);
    matvec(n, m->w_full, b, wb);
    for (int i = 0; i < n; i++) {
        int bd = m->body[i];
        if (bd < 0) { out[i] = 0.0; continue; }
        double h = m->c_full[i];
        for (int j = 0; j < n; j++) h += m->mff_full[i * n + j] * q[j];
        int ang = bd == 0 ? 0 : ia;
        double oa = a[ang], ob = b[ang];
        out[i] = oa * ob * h + 0.5 * (oa * wb[i] + ob * wa[i]);
    }
    double c = cos(q[ia]), s = sin(q[ia]);
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

/* -dQv/dqdot */
static void gyroscopic_matrix(const Model *m, const double *q, const double *v, double *G) {
    int n = m->n, ia = m->i_alpha2, ix = m->i_r2x, iy = m->i_r2y, sk = m->s_link, nl = m->n_link;
    memset(G, 0, sizeof(double) * n * n);
    for (int i = 0; i < n; i++) {
        int bd = m->body[i];
        if (bd < 0) continue;
        int ang = bd == 0 ? 0 : ia;
        double w = v[ang], h = m->c_full[i], wed = 0.0;
        for (int j = 0; j < n; j++) {
            h += m->mff_full[i * n + j] * q[j];
            wed += m->w_full[i * n + j] * v[j];
            G[i * n + j] = -2.0 * w * m->w_full[i * n + j];
        }
        G[ang * n + ang] += 2.0 * h * v[i];
        G[ang * n + i] = 2.0 * w * h;
        G[i * n + ang] = -2.0 * w * h - 2.0 * wed;
    }
    double c = cos(q[ia]), s = sin(q[ia]), w2 = v[ia];
    double ub0 = m->pbar0, ub1 = 0.0, sd0 = 0.0, sd1 = 0.0;
    for (int k = 0; k < nl; k++) {
        ub0 += m->sbar[k] * q[sk + k];
        ub1 += m->sbar[nl + k] * q[sk + k];
        sd0 += m->sbar[k] * v[sk + k];
        sd1 += m->sbar[nl + k] * v[sk + k];
    }
    double x0 = 2.0 * w2 * ub0 + 2.0 * sd1, x1 = 2.0 * w2 * ub1 - 2.0 * sd0; /* 2w u - 2 I~ sd */
    G[ix * n + ia] = -(c * x0 - s * x1);
    G[iy * n + ia] = -(s * x0 + c * x1);
    for (int k = 0; k < nl; k++) {
        G[ix * n + sk + k] = 2.0 * w2 * (c * m->isbar[k] - s * m->sbar[k]);
        G[iy * n + sk + k] = 2.0 * w2 * (c * m->isbar[nl + k] - s * m->sbar[nl + k]);
    }
}

static double sleeve_height(const Model *m, const double *q) {
    return q[m->i_r2y] + (m->l3 + q[m->i_u_sleeve]) * sin(q[m->i_alpha2]);
}

static void sleeve_gradient(const Model *m, const double *q, double *g) {
    memset(g, 0, sizeof(double) * m->n);
    g[m->i_r2y] = 1.0;
    g[m->i_alpha2] = (m->l3 + q[m->i_u_sleeve]) * cos(q[m->i_alpha2]);
    g[m->i_u_sleeve] = sin(q[m->i_alpha2]);
}

static void constraints(const Model *m, const double *q, int locked, int rigid, double *phi) {
    double a1 = q[0], a2 = q[m->i_alpha2];
    double r1 = m->l1 + q[m->i_u_joint], r3 = m->l3 + q[m->i_u_sleeve];
    phi[0] = r1 * cos(a1) - q[m->i_r2x];
    phi[1] = r1 * sin(a1) - q[m->i_r2y];
    phi[2] = q[m->i_r2x] + r3 * cos(a2);
    int row = 3;
    if (locked) phi[row++] = q[m->i_r2y] + r3 * sin(a2) - m->y_stop;
    if (rigid)
        for (int k = 0; k < m->n_elastic; k++) phi[row++] = q[m->elastic_idx[k]];
}

static void jacobian(const Model *m, const double *q, int locked, int rigid, int nc, double *J) {
    int n = m->n;
    memset(J, 0, sizeof(double) * nc * n);
    double a1 = q[0], a2 = q[m->i_alpha2];
    double c1 = cos(a1), s1 = sin(a1), c2 = cos(a2), s2 = sin(a2);
    double r1 = m->l1 + q[m->i_u_joint], r3 = m->l3 + q[m->i_u_sleeve];
    J[0] = -r1 * s1; J[m->i_u_joint] = c1; J[m->i_r2x] = -1.0;
    J[n] = r1 * c1; J[n + m->i_u_joint] = s1; J[n + m->i_r2y] = -1.0;
    J[2 * n + m->i_r2x] = 1.0; J[2 * n + m->i_alpha2] = -r3 * s2; J[2 * n + m->i_u_sleeve] = c2;
    int row = 3;
    if (locked) {
        J[3 * n + m->i_r2y] = 1.0; J[3 * n + m->i_alpha2] = r3 * c2; J[3 * n + m->i_u_sleeve] = s2;
        row = 4;
    }
    if (rigid)
        for (int k = 0; k < m->n_elastic; k++) J[(row + k) * n + m->elastic_idx[k]] = 1.0;
}

static void gonzalez(int n, double *grad, double delta_f, const double *dq, double dd) {
    if (dd == 0.0) return;
    double gd = 0.0;
    for (int i = 0; i < n; i++) gd += grad[i] * dq[i];
    double f = (delta_f - gd) / dd;
    for (int i = 0; i < n; i++) grad[i] += f * dq[i];
}

/* LU with partial pivoting in place; returns 0 or SINGULAR */
static int lu_factor(int N, double *A, int *piv) {
    for (int k = 0; k < N; k++) {
        int p = k;
        double best = fabs(A[k * N + k]);
        for (int i = k + 1; i < N; i++)
            if (fabs(A[i * N + k]) > best) { best = fabs(A[i * N + k]); p = i; }
        if (best == 0.0 || !isfinite(best)) return SINGULAR;
        piv[k] = p;
        if (p != k)
            for (int j = 0; j < N; j++) { double t = A[k * N + j]; A[k * N + j] = A[p * N + j]; A[p * N + j] = t; }
        double inv = 1.0 / A[k * N + k];
        for (int i = k + 1; i < N; i++) {
            double f = A[i * N + k] * inv;
            A[i * N + k] = f;
            if (f != 0.0)
                for (int j = k + 1; j < N; j++) A[i * N + j] -= f * A[k * N + j];
        }
    }
    return OK;
}

static void lu_solve(int N, const double *A, const int *piv, double *b) {
    for (int k = 0; k < N; k++)
        if (piv[k] != k) { double t = b[k]; b[k] = b[piv[k]]; b[piv[k]] = t; }
    for (int i = 0; i < N; i++) {
        double acc = b[i];
        for (int j = 0; j < i; j++) acc -= A[i * N + j] * b[j];
        b[i] = acc;
    }
    for (int i = N - 1; i >= 0; i--) {
        double acc = b[i];
        for (int j = i + 1; j < N; j++) acc -= A[i * N + j] * b[j];
        b[i] = acc / A[i * N + i];
    }
}

static int cholesky(int n, double *A) {   /* lower factor in place */
    for (int j = 0; j < n; j++) {
        double d = A[j * n + j];
        for (int k = 0; k < j; k++) d -= A[j * n + k] * A[j * n + k];
        if (!(d > 0.0)) return NOT_PD;
        d = sqrt(d);
        A[j * n + j] = d;
        for (int i = j + 1; i < n; i++) {
            double acc = A[i * n + j];
            for (int k = 0; k < j; k++) acc -= A[i * n + k] * A[j * n + k];
            A[i * n + j] = acc / d;
        }
    }
    return OK;
}

static void cholesky_solve(int n, const double *L, double *b) {
    for (int i = 0; i < n; i++) {
        double acc = b[i];
        for (int k = 0; k < i; k++) acc -= L[i * n + k] * b[k];
        b[i] = acc / L[i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double acc = b[i];
        for (int k = i + 1; k < n; k++) acc -= L[k * n + i] * b[k];
        b[i] = acc / L[i * n + i];
    }
}

static double max_abs(int n, const double *x) {
    double r = 0.0;
    for (int i = 0; i < n; i++) { double a = fabs(x[i]); if (!(a <= r)) r = a; }
    return r;
}

int umbrella_step(const Model *m, int locked, int rigid,
                  const double *q0, const double *v0, const double *lam0, const double *p0_in,
                  double h, double force, double tol, double phi_tol, int max_iter,
                  double *q, double *v, double *lam, double *p1, int *iterations) {
    int n = m->n;
    int nc = 3 + (locked ? 1 : 0) + (rigid ? m->n_elastic : 0);
    int N = n + nc;
    size_t doubles = (size_t)n * n * 3 + (size_t)N * N + (size_t)nc * n * 3 + (size_t)n * 16
                     + (size_t)N * 2 + (size_t)nc * nc + (size_t)nc * 8;
    double *buf = malloc(sizeof(double) * doubles);
    int *piv = malloc(sizeof(int) * (N + nc));
    if (!buf || !piv) { free(buf); free(piv); return NO_MEMORY; }
    double *M1 = buf, *G = M1 + n * n, *Kqm_tmp = G + n * n;    /* Kqm_tmp: n*n scratch */
    double *A = Kqm_tmp + n * n, *Jm = A + N * N, *J1 = Jm + nc * n, *X = J1 + nc * n;
    double *p0 = X + nc * n, *dq = p0 + n, *qm = dq + n, *v1 = qm + n, *gt = v1 + n;
    double *gy = gt + n, *res = gy + n, *tmp = res + n, *kq = tmp + 2 * n, *mv = kq + n;
    double *rhs = mv + n, *phi0 = rhs + N, *phi = phi0 + nc, *corr = phi + nc, *S = corr + nc;
    double *mu = S + nc * nc;
    int status = OK, it = 0, factored = 0;
    double half_h2 = 0.5 * h * h;

    if (p0_in) memcpy(p0, p0_in, sizeof(double) * n);
    else { mass_matrix(m, q0, M1); matvec(n, M1, v0, p0); }
    constraints(m, q0, locked, rigid, phi0);
    double y0 = sleeve_height(m, q0);
    for (int i = 0; i < n; i++) q[i] = q0[i] + h * v0[i];
    memcpy(lam, lam0, sizeof(double) * nc);
    double last_norm = INFINITY;
    int converged = 0;
    for (it = 1; it <= max_iter; it++) {
        double dd = 0.0;
        for (int i = 0; i < n; i++) {
            dq[i] = q[i] - q0[i];
            dd += dq[i] * dq[i];
            qm[i] = q0[i] + 0.5 * dq[i];
            v1[i] = 2.0 * dq[i] / h - v0[i];
        }
        mass_matrix(m, q, M1);
        constraints(m, q, locked, rigid, phi);
        bilinear_gradient(m, qm, v0, v1, gt, tmp);
        matvec(n, M1, v1, mv);
        /* f = 1/2 v0^T M(q) v1: f(q1) - f(q0) = 1/2 (v0^T M1 v1 - p0 . v1), M symmetric */
        double df = 0.0;
        for (int i = 0; i < n; i++) df += 0.5 * (v0[i] * mv[i] - p0[i] * v1[i]);
        gonzalez(n, gt, df, dq, dd);
        sleeve_gradient(m, qm, gy);
        gonzalez(n, gy, sleeve_height(m, q) - y0, dq, dd);
        jacobian(m, qm, locked, rigid, nc, Jm);
        if (dd > 0.0) {
            for (int r = 0; r < nc; r++) {
                double jd = 0.0;
                for (int i = 0; i < n; i++) jd += Jm[r * n + i] * dq[i];
                corr[r] = (phi[r] - phi0[r] - jd) / dd;
            }
            for (int r = 0; r < nc; r++)
                for (int i = 0; i < n; i++) Jm[r * n + i] += corr[r] * dq[i];
        }
        matvec(n, m->stiffness, qm, kq);
        for (int i = 0; i < n; i++) {
            double jl = 0.0;
            for (int r = 0; r < nc; r++) jl += Jm[r * n + i] * lam[r];
            res[i] = mv[i] - p0[i] - h * (gt[i] - kq[i] - force * gy[i] + jl);
        }
        if (!factored) {
            jacobian(m, q, locked, rigid, nc, J1);
            for (int i = 0; i < n; i++) tmp[i] = dq[i] / h;
            gyroscopic_matrix(m, qm, tmp, G);
            for (int i = 0; i < n; i++) {
                for (int j = 0; j < n; j++)
                    A[i * N + j] = M1[i * n + j] + 0.25 * h * h * m->stiffness[i * n + j] + 0.5 * h * G[i * n + j];
                for (int r = 0; r < nc; r++) A[i * N + n + r] = -Jm[r * n + i];
            }
            for (int r = 0; r < nc; r++) {
                for (int j = 0; j < n; j++) A[(n + r) * N + j] = J1[r * n + j];
                for (int j = 0; j < nc; j++) A[(n + r) * N + n + j] = 0.0;
            }
            if (lu_factor(N, A, piv) != OK) { status = SINGULAR; goto done; }
            factored = 1;
        }
        for (int i = 0; i < n; i++) rhs[i] = -0.5 * h * res[i];
        for (int r = 0; r < nc; r++) rhs[n + r] = -phi[r];
        lu_solve(N, A, piv, rhs);
        double step_norm = 0.0;
        for (int i = 0; i < n; i++) {
            q[i] += rhs[i];
            double a = fabs(rhs[i]);
            if (!(a <= step_norm)) step_norm = a;
        }
        for (int r = 0; r < nc; r++) lam[r] += rhs[n + r] / half_h2;
        if (!isfinite(step_norm)) { status = NON_FINITE; goto done; }
        double rate = it > 1 ? step_norm / last_norm : 1.0;
        if (step_norm < tol || (rate < 0.5 && rate / (1.0 - rate) * step_norm < tol)) {
            constraints(m, q, locked, rigid, phi);
            if (max_abs(nc, phi) < phi_tol) { converged = 1; break; }
        }
        last_norm = step_norm;
    }
    if (!converged) { status = NO_CONVERGENCE; goto done; }
    /* velocity, then projection onto J(q1) v = 0 in the mass metric */
    for (int i = 0; i < n; i++) v[i] = 2.0 * (q[i] - q0[i]) / h - v0[i];
    jacobian(m, q, locked, rigid, nc, J1);
    mass_matrix(m, q, M1);
    double jv_max = 0.0;
    for (int r = 0; r < nc; r++) {
        double acc = 0.0;
        for (int i = 0; i < n; i++) acc += J1[r * n + i] * v[i];
        mu[r] = acc;
        if (fabs(acc) > jv_max) jv_max = fabs(acc);
    }
    if (jv_max > 0.0) {
        memcpy(Kqm_tmp, M1, sizeof(double) * n * n);
        if (cholesky(n, Kqm_tmp) != OK) { status = NOT_PD; goto done; }
        for (int r = 0; r < nc; r++) {          /* X[:, r] = M^-1 J^T[:, r], stored by rows */
            for (int i = 0; i < n; i++) X[r * n + i] = J1[r * n + i];
            cholesky_solve(n, Kqm_tmp, X + r * n);
        }
        for (int r = 0; r < nc; r++)
            for (int c2 = 0; c2 < nc; c2++) {
                double acc = 0.0;
                for (int i = 0; i < n; i++) acc += J1[r * n + i] * X[c2 * n + i];
                S[r * nc + c2] = acc;
            }
        if (lu_factor(nc, S, piv + N) != OK) { status = SINGULAR; goto done; }
        lu_solve(nc, S, piv + N, mu);
        for (int r = 0; r < nc; r++)
            for (int i = 0; i < n; i++) v[i] -= X[r * n + i] * mu[r];
    }
    matvec(n, M1, v, p1);
done:
    *iterations = it > max_iter ? max_iter : it;
    free(buf);
    free(piv);
    return status;
}
