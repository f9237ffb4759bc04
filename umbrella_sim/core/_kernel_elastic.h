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
 * Elastic law of the compiled step for the models that nonlinear.py builds: the von Karman
 * (element-mean membrane strain) or linear strain energy U(q), its average-vector-field (AVF)
 * discrete gradient and tangent, and the Kelvin-Voigt damping C(q) = beta B(q)^T D B(q).
 * Internal to the library (its interface with Python: _kernel.h).
 * Implemented in _kernel_nonlinear.c; _kernel.c calls it through the hooks of step() and
 * output_row() when a law is attached (umbrella_set_law), else it uses its constant K.
 * The arithmetic is that of nonlinear.StrainEnergy / ElasticMidpointDAE (the numpy reference
 * the tests compare against step by step).
 */
#ifndef UMBRELLA_KERNEL_ELASTIC_H
#define UMBRELLA_KERNEL_ELASTIC_H

#include "_kernel.h"

/* Newton contraction rate above which the iteration matrix is re-factored (nonlinear strain;
 * nonlinear.REFRESH_RATE) */
#define ELASTIC_REFRESH_RATE 0.1
/* a step's last iteration matrix goes on to the next step; one factored this many steps
 * ago or less serves that step whole, an older one only its first iteration
 * (nonlinear.CARRY_STEPS) */
#define ELASTIC_CARRY_STEPS 2

/* (ElasticData, the law's API functions: _kernel.h) */
struct ElasticLaw {
    ElasticData d;
    double *band;            /* ne x (2 bw + 1): the law's part of the iteration matrix */
    double *qa, *qb, *g;     /* n, n, n_el x 6: work */
    double *el_stress;       /* n_el: membrane stress of the last elastic_membrane_stress */
    double *el_stress_rate;  /* n_el: its rate, of the last elastic_membrane_stress_rate */
    double *q_base, *lam_base, *dx;   /* line search: n, ne + 4, n + ne + 4 */
    double last_dissipation; /* dq . C(q_m) dq / h of the last elastic_dissipation (J) */
    double band_h;           /* step of the band (the linear strain's band is constant) */
    double *energy_q, energy; /* the last elastic_energy: q (n) and U(q) */
    double *du_mean;         /* n_el x 6: sum_g w_g / l_e u'_g (d eps_e / dq of the linear strain) */
    double *g_mat;           /* n_el x 6 x 6: sum_g w_g / l_e v'_g v'_g^T (0: linear strain), so
                              * eps_e = du_mean . x + x . G x / 2 on the element's coordinates x */
    double *start_q;         /* n: the q0 of the start terms below */
    double *start_gx;        /* n_el x 6: G x0 at the start of the step (x0: q0's element coords) */
    double *start_eps;       /* n_el x 2: du_mean . x0, x0 . G x0 */
    int energy_valid, start_valid;
};

/* out[i] at the elastic q indices += the AVF gradient of U between q0 and q1 without its
 * bending part + C(q_m) (q1 - q0) / h.  The bending part Kb q_m is the caller's: out holds it
 * on entry (Kb is linear: the band products of the step), and kb_dq = Kb (q1 - q0). */
void elastic_force(ElasticLaw *law, const double *q0, const double *q1, double h,
                   const double *kb_dq, double *out);
/* law->band = h^2/2 d AVF / d q1 + h/2 C(q_m) */
void elastic_iteration_band(ElasticLaw *law, const double *q0, const double *q1, double h);
/* U(q); kbq = Kb q at the elastic q indices if the caller has it, else NULL */
double elastic_energy(ElasticLaw *law, const double *q, const double *kbq);
/* dq . C(q_m) dq / h, also kept in law->last_dissipation */
double elastic_dissipation(ElasticLaw *law, const double *q0, const double *q1, double h);
/* law->el_stress[e] = E (1/l_e) int v'^2/2 dx (0 with the linear strain) */
void elastic_membrane_stress(ElasticLaw *law, const double *q);
/* law->el_stress_rate[e] = E (1/l_e) int v' v'_t dx, the rate of that stress at (q, v) */
void elastic_membrane_stress_rate(ElasticLaw *law, const double *q, const double *v);

#endif
