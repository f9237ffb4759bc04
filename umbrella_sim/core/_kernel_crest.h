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
 * The crest of a fibre's stress over a step, one rule for the planar step (_kernel.c) and the
 * umbrella's stress figures (_kernel3d_figures.h): outputs.hermite_peak's arithmetic.
 */
#ifndef UMBRELLA_KERNEL_CREST_H
#define UMBRELLA_KERNEL_CREST_H

#include <math.h>

#define RESOLVED_CREST 1.0   /* outputs.RESOLVED_CREST */

/* The largest of best and |p| inside (0, 1), p the cubic with p(0) = s0, p(1) = s1,
 * p'(0) = d0, p'(1) = d1 (a fibre's stress over a step: values and rates times the step at
 * its ends), a crest inside counted where |p''| <= RESOLVED_CREST |p| */
static inline double hermite_crest(double s0, double d0, double s1, double d1, double best) {
    double a = 3.0 * (s1 - s0) - 2.0 * d0 - d1, b = 2.0 * (s0 - s1) + d0 + d1;
    /* p(t) = s0 + t (d0 + t (a + t b)); p'(t) = 3 b t^2 + 2 a t + d0 = 0 */
    double qa = 3.0 * b, qb = 2.0 * a, disc = qb * qb - 4.0 * qa * d0;
    if (!(disc >= 0.0)) return best;
    double r = -0.5 * (qb + copysign(sqrt(disc), qb)), roots[2];
    int nr = 0;
    if (r != 0.0) roots[nr++] = d0 / r;
    if (qa != 0.0) roots[nr++] = r / qa;
    for (int i = 0; i < nr; i++) {
        double t = roots[i];
        if (t > 0.0 && t < 1.0) {
            double val = fabs(s0 + t * (d0 + t * (a + t * b)));
            if (fabs(2.0 * a + 6.0 * b * t) <= RESOLVED_CREST * val && val > best) best = val;
        }
    }
    return best;
}

#endif
