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
 * The interface of the compiled step (libumbrella_kernel.so): every struct, status code,
 * list of output fields and function that crosses between the library and Python, declared
 * once.  _kernel.c and _kernel_nonlinear.c include it; kernel.py reads it (it is installed
 * with the package) to build its ctypes structures, function signatures and field names,
 * so nothing here is mirrored by hand.  kernel.py's parser reads a fixed subset of C and
 * refuses anything else: keep to the statement forms below (comments are free):
 *   - #define UMBRELLA_ABI_VERSION <integer>, #define UMBRELLA_API <attribute>;
 *   - X-macro lists, #define UMBRELLA_<LIST>(X) X(C name, Python name) ..., one entry a line;
 *   - enum entry macros, #define <NAME>(name, py) [PREFIX##]name, and the enums they make,
 *     enum { UMBRELLA_<LIST>(<NAME>) <COUNT> };
 *   - typedef struct { <members> } <Name>; with members of int, long, double, pointers to
 *     those (const or not) and pointers to this header's structs; typedef struct <Name>
 *     <Name>; for a type Python only holds a pointer to;
 *   - UMBRELLA_API <type> <function>(<parameters>); of the same types.
 * The library reports its ABI version, the size of each struct and the length of each list
 * (umbrella_abi); kernel.load_kernel refuses a library whose figures differ from the
 * header's, e.g. one left from an older build.
 */
#ifndef UMBRELLA_KERNEL_H
#define UMBRELLA_KERNEL_H

/* Raised when the meaning of the interface changes while its sizes stay (a field renamed or
 * reordered, a function's arguments changed). */
#define UMBRELLA_ABI_VERSION 10

/* The API functions: the library is compiled with -fvisibility=hidden, so these alone are
 * exported. */
#define UMBRELLA_API __attribute__((visibility("default")))

/* ------------------------------------------------------------------- status codes */
/* What the stepping functions return, 0, 1, ... in this order; CROSSING and DIVERGED stop
 * umbrella_advance_call without being failures. */
#define UMBRELLA_STATUS_CODES(X) \
    X(OK, ok) \
    X(NO_CONVERGENCE, no_convergence) \
    X(NON_FINITE, non_finite) \
    X(SINGULAR, singular) \
    X(NOT_PD, not_positive_definite) \
    X(NO_MEMORY, no_memory) \
    X(CROSSING, crossing) \
    X(DIVERGED, diverged) \
    X(AXLE, axle)
#define UMBRELLA_STATUS_ENTRY(name, py) name,
enum { UMBRELLA_STATUS_CODES(UMBRELLA_STATUS_ENTRY) N_STATUS };

/* ------------------------------------------------------------- per-step output row */
/* The fields of one step's output row, in this order (outputs.STEP_FIELDS; C: F_<name>);
 * an advance writes them field-major, out[field * cap + step].  The state's figures at the
 * step's end (stage: the int code of model.Stage), except the peak stresses and where they
 * are: the largest over the whole step (the cubic Hermite interpolant of the fibre stress).
 * Every figure a CSV row of the run needs: alpha1_accel = (v1 - v0) / h of the step; the
 * reference stresses as the Sample vector's; the sleeve reaction lam[2], and lam[3] once
 * locked, else 0; the end state's max(|Phi|, |J v|); the damping dissipation so far. */
#define UMBRELLA_STEP_FIELDS(X) \
    X(TIME, time) \
    X(STAGE, stage) \
    X(ALPHA1, alpha1) \
    X(ALPHA1_RATE, alpha1_rate) \
    X(SLEEVE_POS, sleeve_position) \
    X(SLEEVE_VEL, sleeve_velocity) \
    X(FORCE, sleeve_force) \
    X(TIP_AXIAL, tip_axial) \
    X(TIP_TRANSVERSE, tip_transverse) \
    X(PEAK_LEAF, peak_stress_leaf) \
    X(PEAK_LEAF_X, peak_stress_leaf_x) \
    X(PEAK_LINK, peak_stress_link) \
    X(PEAK_LINK_X, peak_stress_link_x) \
    X(KINETIC, kinetic_energy) \
    X(STRAIN, strain_energy) \
    X(WORK, work) \
    X(LOCK_LOSS, lock_energy_loss) \
    X(ALPHA2, alpha2) \
    X(ALPHA2_RATE, alpha2_rate) \
    X(ALPHA1_ACCEL, alpha1_accel) \
    X(STRESS_LEAF_JOINT, stress_leaf_joint) \
    X(STRESS_LINK_MID, stress_link_mid) \
    X(REACTION_X, sleeve_reaction_x) \
    X(REACTION_Y, sleeve_reaction_y) \
    X(RESIDUAL, constraint_residual) \
    X(DISSIPATION, damping_dissipation) \
    X(AXIAL_STRESS, axial_stress)
#define UMBRELLA_STEP_ENTRY(name, py) F_##name,
enum { UMBRELLA_STEP_FIELDS(UMBRELLA_STEP_ENTRY) N_FIELDS };

/* ------------------------------------------------------------------- Sample vector */
/* What a Sample holds of a state beyond q, q', q'' and the multipliers, in this order
 * (kernel.SAMPLE_VECTOR; C: S_<name>), then the fibre stress at every stress point: top of
 * every point, then bottom; leaf points first. */
#define UMBRELLA_SAMPLE_FIELDS(X) \
    X(ALPHA1, alpha1) \
    X(ALPHA2, alpha2) \
    X(ALPHA1_RATE, alpha1_rate) \
    X(ALPHA2_RATE, alpha2_rate) \
    X(SLEEVE_POS, sleeve_position) \
    X(SLEEVE_VEL, sleeve_velocity) \
    X(TIP_AXIAL, tip_axial) \
    X(TIP_TRANSVERSE, tip_transverse) \
    X(PEAK_LEAF, peak_stress_leaf) \
    X(PEAK_LEAF_X, peak_stress_leaf_x) \
    X(PEAK_LINK, peak_stress_link) \
    X(PEAK_LINK_X, peak_stress_link_x) \
    X(STRESS_LEAF_JOINT, stress_leaf_joint) \
    X(STRESS_LINK_MID, stress_link_mid) \
    X(REACTION_X, sleeve_reaction_x) \
    X(REACTION_Y, sleeve_reaction_y) \
    X(KINETIC, kinetic_energy) \
    X(STRAIN, strain_energy) \
    X(RESIDUAL, constraint_residual)
#define UMBRELLA_SAMPLE_ENTRY(name, py) S_##name,
enum { UMBRELLA_SAMPLE_FIELDS(UMBRELLA_SAMPLE_ENTRY) N_SAMPLE };

/* ---------------------------------------------------------------------- structs */
/* The model (kernel.CompiledKernel builds it): sizes, indices of q, constants, and the
 * constant arrays it points into (the caller keeps them alive). */
typedef struct {
    int n;                 /* coordinates */
    int n_link;            /* link elastic coordinates */
    int i_r2x, i_r2y, i_alpha2, s_link;
    int i_u_joint, i_u_sleeve, i_tip_u, i_tip_v;
    int n_elastic;         /* leaf + link elastic coordinates, in q order */
    int bw;                /* half bandwidth of the elastic block, elastic ordering */
    int n_stress_leaf, n_stress_link, stress_width;
    double l1, l3, y_stop;
    double j0_leaf, j0_link, pbar0, link_mass;
    const double *c_full, *g_full;                       /* n */
    const int *body;       /* n: -1 not elastic, 0 leaf, 1 link */
    const int *elastic_idx;                              /* n_elastic: q index of elastic p */
    const double *sbar, *isbar;                          /* 2 x n_link each */
    const double *mff_band, *k_band, *w_band;            /* n_elastic x (2 bw + 1) */
    const int *stress_idx;                               /* points x width: q indices */
    const double *stress_top, *stress_bottom;            /* points x width */
    const double *stress_x;                              /* points */
    /* the reference stresses (model.reference_stresses): the leaf's stress point at O'';
     * the link element holding l3/2 and where in it (0..1) */
    int ref_leaf_point, ref_link_element;
    double ref_link_frac;
} Model;

/* umbrella_advance_call's arguments, kept by the caller and updated in place (from Python,
 * converting 22 ctypes arguments cost as much as half a physics step, setting the few that
 * change costs a tenth of that).  Up to n_steps grid steps t_k -> t_{k+1} = (k + 1) h from
 * the state (q, v, lam, p = M v) at t_k0, updated in place after every committed step, with
 * one output row per step in out (N_FIELDS x cap, field-major) and accel = (v1 - v0) / h of
 * the last one.  acc = {work, lock loss, damping dissipation} in/out (J).
 * states: NULL, or the state rows of every step, field-major like out (row r of step k at
 * states[r * cap + k]), 2 n + 2 points rows: q (n), q' (n), then the fibre stress at every
 * stress point, top of every point, then bottom, leaf points first (Model.n_stress_leaf +
 * n_stress_link points). */
typedef struct {
    int locked, rigid;
    long k0;
    double h;
    int n_steps;
    double force, tol, phi_tol;
    int max_iter;
    double div_tol;
    double *q, *v, *lam, *p, *acc, *out;
    int cap;
    int n_done, iterations;   /* out: committed steps, Newton iterations */
    double residual;          /* out: the last checked state's max(|Phi|, |J v|) */
    double *accel;
    double *final;   /* NULL, or N_SAMPLE + 2 points: the Sample vector of the state reached */
    double *states;  /* NULL, or (2 n + 2 points) x cap: the state rows */
} AdvanceCall;

/* umbrella_sample_call's arguments: the Sample vector (N_SAMPLE, then the fibre stresses)
 * of the state (q, v, p = M(q) v, lam) into out. */
typedef struct {
    int locked, rigid;
    const double *q, *v, *p, *lam;
    double *out;
} SampleCall;

/* The elastic law of _kernel_nonlinear.c (nonlinear.CompiledElasticLaw builds it): the linear
 * strain with Kelvin-Voigt damping (nonlinear = 0: U = 1/2 q.K q, C = beta K), or the
 * co-rotational beam (nonlinear = 1: beam_strain.CorotationalStrainEnergy, element by element
 * on its 6 coordinates (u, v, theta of its two nodes): chord d = (l_e + u_b - u_a, v_b - v_a),
 * section angles asin(theta), D = diag(EA l_e, EI / l_e [[4, 2], [2, 4]]), fibre stress
 * E (eps -/+ c kappa)). */
typedef struct {
    int n;                   /* coordinates */
    int ne;                  /* elastic coordinates (Model.n_elastic) */
    int bw;                  /* half bandwidth of the elastic band (Model.bw) */
    int n_el;                /* elements, leaf then link */
    int nonlinear;           /* 0: the linear strain; 1: the co-rotational beam */
    double beta;             /* damping: C = beta B^T D B (s); 0: undamped */
    double youngs_modulus;   /* E (Pa), for the fibre stress */
    const int *elastic_idx;  /* ne: q index of elastic position p */
    const double *k_band;    /* ne x (2 bw + 1): K (nonlinear = 0), zero (nonlinear = 1: U is
                              * all the law's) */
    const int *el_q;         /* n_el x 6: q index of u_a, v_a, theta_a, u_b, v_b, theta_b, -1
                              * where the frame fixes one */
    const int *el_pos;       /* n_el x 6: their elastic positions, -1 if none */
    const double *el_length; /* n_el: l_e (m) */
    double ea, ei, fibre;    /* EA (N), EI (N m^2), fibre distance c (m) */
} ElasticData;

/* The whole umbrella in 3D (umbrella3d.kernel3d builds it from
 * umbrella3d.model3d.UmbrellaModel3D): N ribs of n_rib coordinates each around one sleeve
 * (hub fixed: n_shared = 1: y_s; n_shared_rows = 1: the stop; a moving base: below), the rib coordinates' indices, and per
 * body (leaf, link) of every rib its quadrature and attached points: rest positions x
 * (R x P x 3), weights w (R x P), shapes S (R x P x 3 x elastic).  Arrays rib-major; the
 * caller keeps them alive. */
typedef struct {
    int n_ribs, n_rib, n_shared, n_shared_rows;
    int i_a1, i_rx, i_ry, i_rz, i_a2, i_u1, i_w1, i_s1, i_p1, i_s2, i_p2, i_uh, i_wh;
    int i_t0;                                        /* the leaf root's slope (a stuck
                                                      * hinge holds alpha1 + it) */
    int i_tip_v, i_tip_w;                            /* the leaf tip's in-plane and
                                                      * out-of-plane deflection
                                                      * (Advance3DCall.tips) */
    int leaf_points, leaf_elastic, link_points, link_elastic, link_offset;
    double sleeve_mass, y_stop, regularisation;
    int carry_steps;                                 /* steps an iteration matrix serves at
                                                      * most (1: factored every step) */
    const double *l1, *l3, *coulomb, *viscous;       /* n_ribs */
    const double *stick_until, *stick_torque;        /* n_ribs (0: not that release) */
    const double *stiffness, *const_mass;            /* n_ribs x n_rib x n_rib: K, and the
                                                      * part of M that does not move */
    const double *leaf_x, *leaf_w, *leaf_shape;
    const double *link_x, *link_w, *link_shape;
    /* a moving base (n_shared = 7: y_s, the bus's X (3) and angles psi, beta, gamma;
     * n_shared_rows 7: a prescribed drive's rows, 1: a free bus): _kernel3d_base.h */
    double hub_radius, total_mass;                   /* m; kg: ribs, sleeve and bus */
    const double *bus_inertia;                       /* 3 x 3 (kg m^2, bus frame) */
    const double *rib_frames;                        /* n_ribs x 3 x 3: psi (rib -> bus) */
    /* model flexible-nonlinear (umbrella3d/corotational3d.py; _kernel3d_nonlinear.h): the
     * elements a rib (0: the linear beams), each's 12 coordinates' places in the rib's
     * (n_rib: a fixed one), and per rib and element its length and D (EA l_e, EI_z / l_e,
     * EI_y / l_e, GJ / l_e); the leaf's and the link's slope at O''; the elastic LU's
     * pattern (1 where an element block can reach) */
    int nl_elements, nl_i_t1, nl_i_t2;
    const int *nl_places;                            /* nl_elements x 12 */
    const double *nl_length, *nl_stiffness;          /* n_ribs x nl_elements (x 4) */
    const double *nl_pattern;                        /* n_ribs x n_rib x n_rib */
    /* the beams' structural damping C = beta K (s; 0: none; the linear beams only:
     * umbrella3d/damping3d.py, _kernel3d_damping.h) */
    double damping_beta;
} Model3D;

/* umbrella3d_advance's arguments (kept by the caller, updated in place): the state (t, q, v,
 * multipliers, p = M v, stuck: the angle a stuck hinge holds, NaN where free), advanced in
 * place.  single: one step of length h, no event (the lock's root find takes these);
 * else up to n_steps grid steps t_k -> (k + 1) h from k0, stopping before a step in which
 * the sleeve reaches the stop unlocked (CROSSING, that step not committed), a stuck hinge
 * released after the step that frees it (its time, or its multiplier's torque).  have_p:
 * p holds M(q) v (else it is computed).  Each committed step writes a row into out (row_len
 * doubles, step-major): t, qr, qs, vr, vs, lam_r, lam_s, stuck, kinetic and strain energy,
 * the sleeve force's work, each hinge's friction work, Newton iterations, factorisations,
 * the beams' damping's dissipation (0 undamped), the drive's work (0 without a drive) and, with a free bus, its linear and angular
 * momentum (3 + 3, inertial). */
typedef struct {
    int locked, single, have_p, n_steps, max_iter, row_len;
    long k0;
    double h, force, tol, phi_tol, t;
    double *qr, *qs, *vr, *vs, *lam_r, *lam_s, *pr, *ps, *stuck;
    double *out;
    int n_done, iterations;   /* out: committed steps, Newton iterations */
    /* stage 2's mode fit of the locked steps (integrator3d.MidpointUmbrella.fit_stage2_modes:
     * each rib's LockedModeFit), fit_modes a rib (0: none; padded with s = 1, shrink 0):
     * u = (M0 phi)^T and phi^T rows (R x fit_modes x n_rib), s and the Newton shrink
     * (R x fit_modes) */
    int fit_modes;
    const double *fit_u, *fit_phi, *fit_scale, *fit_shrink;
    /* the same u and phi rows transposed (a rib's n_rib x fit_modes; the whole fit's
     * coordinates x fit_modes): the modal sums' projections column by column */
    const double *fit_ut, *fit_phit;
    /* fit_whole 1: one fit of the whole system's modes (a free bus: stage2fit.WholeFit),
     * fit_modes rows over every coordinate (ribs', then the shared: fit_modes x (n_ribs
     * n_rib + n_shared) each), s and shrink (fit_modes) */
    int fit_whole;
    /* a prescribed base: the bus's coordinates and rates the drive gives at each step's end
     * (n_steps x 6 each; single: 1 x 6) */
    const double *drive_q, *drive_v;
    /* the stress figures (umbrella3d_set_stress), not single: 1 if the run's first step
     * takes its crests from the state it starts at (the steps' record continues in the same
     * stage), 0 if that state's own values stand (a record's first, or across the lock) */
    int crest_from_state;
    /* a damped fit (Model3D.damping_beta): each fitted mode's damping change c_w - c
     * (fit_scale's layout); NULL: undamped */
    const double *fit_damping;
    /* a free bus's fit at a rib's cost (fit_whole 0: stage2fit.BusFit): the ribs' fits
     * composed with the bus's correction S_bus = I + A B^T, S = S_ribs S_bus, S_bus^-1 =
     * I - A C^T, S_bus^T = I + B A^T; bus_rank rows a, b, c over every coordinate (bus_rank
     * x (n_ribs n_rib + n_shared) each) and the same transposed (coordinates x bus_rank);
     * 0: none */
    int bus_rank;
    const double *bus_a, *bus_b, *bus_c, *bus_at, *bus_bt, *bus_ct;
    /* its Newton update's: the ribs' composed with I + A_n B_n^T (the whole fit's),
     * bus_newton_rank rows of A_n (over every coordinate) and B_n transposed (coordinates x
     * bus_newton_rank) */
    int bus_newton_rank;
    const double *bus_newton_a, *bus_newton_bt;
    /* its damped fit's share less the ribs': A B^T dq / h, bus_damp_rank rows of each over
     * every coordinate (0: none) */
    int bus_damp_rank;
    const double *bus_damp_a, *bus_damp_b;
    /* not single: the rows of each run of fold steps (a grid step's stage-2 substeps) as one
     * row, substeps3d.fold_substeps3d's: the last step's figures, the works and counts summed
     * over the run, each stress figure the first of the largest (a NaN the largest); a last
     * shorter run (the steps before a failure) its own row.  0 or 1: a row a step */
    int fold;
    /* not single: NULL, or each committed physics step's tip deflections (n_steps x n_ribs
     * x 2, step-major: each rib's q[i_tip_v], q[i_tip_w]), which a folded row does not keep:
     * the summary's stage-2 figures are those of every physics step (summary.Stage2Series) */
    double *tips;
} Advance3DCall;

/* Held by Python only as pointers: the stepping contexts (every work buffer, allocated
 * once; planar and 3D) and an elastic law. */
typedef struct Ctx Ctx;
typedef struct Ctx3D Ctx3D;
typedef struct ElasticLaw ElasticLaw;

/* What umbrella_abi reports after the version, in this order: the size of each of these
 * structs, then each of these counts. */
#define UMBRELLA_ABI_STRUCTS(X) \
    X(Model, model) \
    X(AdvanceCall, advance_call) \
    X(SampleCall, sample_call) \
    X(ElasticData, elastic_data) \
    X(Model3D, model3d) \
    X(Advance3DCall, advance3d_call)
#define UMBRELLA_ABI_COUNTS(X) \
    X(N_STATUS, status_codes) \
    X(N_FIELDS, step_fields) \
    X(N_SAMPLE, sample_fields)

/* -------------------------------------------------------------------- functions */
/* UMBRELLA_ABI_VERSION; the first n of the figures UMBRELLA_ABI_STRUCTS and
 * UMBRELLA_ABI_COUNTS list, into figures. */
UMBRELLA_API int umbrella_abi(int *figures, int n);

/* A context for the model (which must outlive it), or NULL: out of memory, or a singular
 * elastic mass matrix. */
UMBRELLA_API Ctx *umbrella_new(const Model *m);
UMBRELLA_API void umbrella_free(Ctx *x);

/* Stage 2's mode fit (integrators.LockedModeFit) from now on: r modes, rows u = M0 phi and
 * phi (r x n), velocity scales s, each mode's Newton shrink, the modal damping change dc
 * (NULL: undamped); the arrays stay the caller's; r = 0: none.  OK, or SINGULAR if its
 * buffers cannot be allocated. */
UMBRELLA_API int umbrella_set_mode_fit(Ctx *x, int r, const double *u, const double *phi,
                                       const double *s, const double *shrink, const double *dc);

/* Step with this elastic law (NULL: the constant K, undamped). */
UMBRELLA_API void umbrella_set_law(Ctx *x, ElasticLaw *law);

/* The damping dissipation of the last step taken (J): the elastic law's, and stage 2's mode
 * fit's share. */
UMBRELLA_API double umbrella_dissipated(const Ctx *x);

/* p = M(q) v. */
UMBRELLA_API void umbrella_momentum(Ctx *x, const double *q, const double *v, double *p);

/* One step of length h from (q0, v0, lam0, p0 = M(q0) v0 or NULL) into (q, v, lam, p1). */
UMBRELLA_API int umbrella_step(Ctx *x, int locked, int rigid, const double *q0,
                               const double *v0, const double *lam0, const double *p0_in,
                               double h, double force, double tol, double phi_tol,
                               int max_iter, double *q, double *v, double *lam, double *p1,
                               int *iterations);

/* Up to a->n_steps grid steps (AdvanceCall).  Stops early: CROSSING, in stage 1 the sleeve
 * reached the stop during the next step; DIVERGED, max(|Phi|, |J v|) above div_tol after a
 * step; any other status, the step failed.  The step that stopped it is not committed. */
UMBRELLA_API int umbrella_advance_call(Ctx *x, AdvanceCall *a);

/* The Sample vector of a state (SampleCall). */
UMBRELLA_API void umbrella_sample_call(Ctx *x, SampleCall *a);

/* The lock instant inside a step of length h from (q0, v0, lam0, p0), stage deploying: the
 * Illinois root find of y_H = y_stop over the step length (solver's _find_lock). */
UMBRELLA_API int umbrella_find_crossing(Ctx *x, int rigid, const double *q0, const double *v0,
                                        const double *lam0, const double *p0, double h,
                                        double force, double tol, double phi_tol,
                                        int max_iter, double div_tol, double event_tol,
                                        double *q, double *v, double *lam, double *p,
                                        double *dt_out, double *residual, int *iterations);

/* The elastic law of d (which must outlive it), or NULL (out of memory); its free; the
 * damping dissipation dq . C(q_m) dq / h of its last step (J); the co-rotational beam's
 * largest |theta| = |sin psi| (a section's turn from its body frame) over the states it
 * has stepped from or ended at (0 for the linear strain). */
UMBRELLA_API ElasticLaw *elastic_new(const ElasticData *d);
UMBRELLA_API void elastic_free(ElasticLaw *law);
UMBRELLA_API double elastic_last_dissipation(const ElasticLaw *law);
UMBRELLA_API double elastic_max_slope(const ElasticLaw *law);

/* The 3D umbrella's context for the model (which must outlive it), or NULL (out of memory);
 * its free; its steps (Advance3DCall): OK, CROSSING, or the failure (NO_CONVERGENCE,
 * NON_FINITE, SINGULAR) of the step that stopped it, not committed. */
UMBRELLA_API Ctx3D *umbrella3d_new(const Model3D *m);
UMBRELLA_API void umbrella3d_free(Ctx3D *x);
UMBRELLA_API int umbrella3d_advance(Ctx3D *x, Advance3DCall *a);

/* Each committed step of an advance (not single) ends its row with every rib's stress
 * figures (_kernel3d_figures.h; row_len counts them): the largest over its points of the
 * four components and von Mises, the Hermite crest over the step (ribs x 5), and where
 * (ribs x 5 x 2: body code 0 leaf / 1 link, x).  The recovery rows of each body, every
 * rib's (ribs x 4 x points x elastic: model3d.stress_blocks' axial, bending z, bending y,
 * shear), and each point's x (leaf points, then link points) are copied.  No points: no
 * figures.  OK, or SINGULAR (out of memory: no figures). */
UMBRELLA_API int umbrella3d_set_stress(Ctx3D *x, int leaf_points, int link_points,
                                       const double *leaf_rows, const double *link_rows,
                                       const double *point_x);

/* The same figures of the co-rotational ribs (Model3D.nl_elements: model flexible-nonlinear,
 * _kernel3d_nonlinear.h's nl_stress_components): their points both ends of every element
 * (leaf_points + link_points = 2 nl_elements: the leaf's, then the link's), the components
 * from the elements' co-rotated strains with each rib's moduli (ribs x 3: E, E c, G c_t:
 * axial, bending and torsion shear), each point's x; moduli and x are copied.  OK, or
 * SINGULAR (points not those, or out of memory: no figures). */
UMBRELLA_API int umbrella3d_set_corotational_stress(Ctx3D *x, int leaf_points,
                                                    int link_points, const double *moduli,
                                                    const double *point_x);

#endif
