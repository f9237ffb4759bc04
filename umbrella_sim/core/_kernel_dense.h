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
 * The dense LU of _kernel.c, shared inside the library (hidden: not part of the API) with the
 * 3D step (_kernel3d.c).
 */
#ifndef UMBRELLA_KERNEL_DENSE_H
#define UMBRELLA_KERNEL_DENSE_H

/* one elimination step: rows i0.. of A lose column k by pivot row k (inv: 1 / its pivot),
 * their factors stored in column k */
static inline void lu_eliminate(int N, double *A, int k, int i0, double inv) {
    for (int i = i0; i < N; i++) {
        double f = A[i * N + k] * inv;
        A[i * N + k] = f;
        if (f != 0.0)
            for (int j = k + 1; j < N; j++) A[i * N + j] -= f * A[k * N + j];
    }
}

/* lu_factor's steps k0.. of A whose first k0 columns are already eliminated (piv[0..k0)
 * set by the caller) */
static inline int lu_factor_from(int N, int k0, double *A, int *piv) {
    for (int k = k0; k < N; k++) {
        int p = k;
        double best = fabs(A[k * N + k]);
        for (int i = k + 1; i < N; i++)
            if (fabs(A[i * N + k]) > best) { best = fabs(A[i * N + k]); p = i; }
        if (best == 0.0 || !isfinite(best)) return SINGULAR;
        piv[k] = p;
        if (p != k)
            for (int j = 0; j < N; j++) { double t = A[k * N + j]; A[k * N + j] = A[p * N + j]; A[p * N + j] = t; }
        double inv = 1.0 / A[k * N + k];
        lu_eliminate(N, A, k, k + 1, inv);
        A[k * N + k] = inv;
    }
    return OK;
}

/* LU with partial pivoting of the row-major N x N A in place (the diagonal keeps the
 * reciprocals of the pivots); OK, or SINGULAR.  These three inline too, so the 3D step's
 * ROWS x ROWS joint blocks are factored by code compiled for that size */
static inline int lu_factor(int N, double *A, int *piv) { return lu_factor_from(N, 0, A, piv); }

/* b = A^-1 b with lu_factor's A and piv (each row's latest unknown last, as band_solve);
 * inline, so a call with a constant N (the 3D step's ROWS x ROWS joint blocks) is compiled
 * for that size */
static inline void lu_solve(int N, const double *A, const int *piv, double *b) {
    for (int k = 0; k < N; k++)
        if (piv[k] != k) { double t = b[k]; b[k] = b[piv[k]]; b[piv[k]] = t; }
    for (int i = 0; i < N; i++) {
        double acc = b[i];
        for (int j = 0; j < i; j++) acc -= A[i * N + j] * b[j];
        b[i] = acc;
    }
    for (int i = N - 1; i >= 0; i--) {
        double acc = b[i];
        for (int j = N - 1; j > i; j--) acc -= A[i * N + j] * b[j];
        b[i] = acc * A[i * N + i];
    }
}

#endif
