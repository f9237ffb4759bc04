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

/* LU with partial pivoting of the row-major N x N A in place (the diagonal keeps the
 * reciprocals of the pivots); OK, or SINGULAR. */
int lu_factor(int N, double *A, int *piv);
/* b = A^-1 b with lu_factor's A and piv. */
void lu_solve(int N, const double *A, const int *piv, double *b);

#endif
