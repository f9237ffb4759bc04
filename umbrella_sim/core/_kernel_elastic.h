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
 * Elastic law of the compiled step for the models that nonlinear.py builds: the co-rotational
 * (geometrically exact) beam of flexible-nonlinear, its energy-consistent discrete gradient,
 * Newton matrix and fibre stress, or the linear strain U = 1/2 q.K q of a damped flexible
 * model; and the Kelvin-Voigt damping C(q) = beta B(q)^T D B(q) of either.
 * Internal to the library (its interface with Python: _kernel.h).
 * Implemented in _kernel_nonlinear.c; _kernel.c calls it through the hooks of step() and
 * output_row() when a law is attached (umbrella_set_law), else it uses its constant K.
 * The arithmetic is that of beam_strain.CorotationalStrainEnergy / LinearStrainEnergy and
 * ElasticMidpointDAE (the numpy reference the tests compare against step by step).
 */
#ifndef UMBRELLA_KERNEL_ELASTIC_H
#define UMBRELLA_KERNEL_ELASTIC_H

#include "_kernel.h"

/* Newton contraction rate above which the iteration matrix is re-factored (nonlinear law;
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
    double *qa, *qb;         /* n, n: work */
    double *el_stress;       /* the fibre stress of the last elastic_fibre_stress: top of
                              * every stress point (two an element, leaf then link), then
                              * bottom (4 n_el; the co-rotational beam) */
    double *el_stress_rate;  /* its rate, of the last elastic_fibre_stress_rate (the same
                              * layout) */
    double *q_base, *lam_base, *dx;   /* line search: n, ne + 4, n + ne + 4 */
    double last_dissipation; /* dq . C(q_m) dq / h of the last elastic_dissipation (J) */
    double max_slope;        /* the largest |theta| of the states cr_step_start has seen */
    double band_h;           /* step of the band (the linear strain's band is constant) */
    double *energy_q, energy; /* the last elastic_energy: q (n) and U(q) */
    /* the co-rotational beam: per element z = (d, t_a, t_b) and s = (eps, tb_a, tb_b),
     * 9 doubles, at start_q (the q0 of a step, or the q of the last energy or stress) and at
     * cur_q (the q1 of the last elastic_force) */
    double *start_q, *cr_start, *cur_q, *cr_cur;
    int energy_valid, start_valid, cur_valid;
};

/* out[i] at the elastic q indices += the discrete gradient G_U of U between q0 and q1 less
 * what the caller holds of it + C(q_m) (q1 - q0) / h.  out holds K q_m on entry (the band
 * products of the step with ElasticData.k_band: all of G_U for the linear strain, zero for
 * the co-rotational beam), and k_dq = K (q1 - q0). */
void elastic_force(ElasticLaw *law, const double *q0, const double *q1, double h,
                   const double *k_dq, double *out);
/* 1 if q is inside the law's coordinates (the co-rotational beam: every slope |theta| < 1,
 * a section turned less than 90 deg from its body frame), else 0 */
int elastic_admissible(const ElasticLaw *law, const double *q);
/* law->band = h^2/2 (the Newton matrix's d G_U / d q1) + h/2 C(q_m) */
void elastic_iteration_band(ElasticLaw *law, const double *q0, const double *q1, double h);
/* U(q); kq = K q at the elastic q indices if the caller has it, else NULL */
double elastic_energy(ElasticLaw *law, const double *q, const double *kq);
/* dq . C(q_m) dq / h, also kept in law->last_dissipation */
double elastic_dissipation(ElasticLaw *law, const double *q0, const double *q1, double h);
/* law->el_stress: the co-rotational beam's fibre stress at q (nothing for the linear strain,
 * whose stress is the Model's linear rows) */
void elastic_fibre_stress(ElasticLaw *law, const double *q);
/* law->el_stress_rate: its rate at (q, v) */
void elastic_fibre_stress_rate(ElasticLaw *law, const double *q, const double *v);

#endif
