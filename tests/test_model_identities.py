# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The FE matrices against their definitions, by independent quadrature and complex step."""
import numpy as np
import pytest

from umbrella_sim.core.beam import shape_functions
from umbrella_sim.core.model import UmbrellaModel
from umbrella_sim.core.params import UmbrellaParams

MESHES = [1, 2, 3, 5]


def random_state(model, rng, elastic=1e-3):
    q, qd = model.initial_state()
    q = q + rng.normal(size=model.n) * elastic
    qd = qd + rng.normal(size=model.n)
    return q, qd


def point_position(model, body, q, x):
    """Return r = R + A (p + N B e) (Eq. 3.17) of the point at abscissa x, from [N]."""
    leaf = body is model.leaf
    e = q[model.s_leaf] if leaf else q[model.s_link]
    alpha = q[0] if leaf else q[model.i_alpha2]
    origin = np.zeros(2) if leaf else q[[model.i_r2x, model.i_r2y]]
    j = min(np.searchsorted(body.node_x, x, side='right') - 1, len(body.element_length) - 1)
    le = body.element_length[j]
    n, _, _ = shape_functions(np.array([(x - body.node_x[j]) / le]), le)
    u = n[0] @ (body.element_dof_maps[j] @ e)
    c, s = np.cos(alpha), np.sin(alpha)
    local = np.array([x + u[0], u[1]])
    return origin + np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]])


def quadrature_kinetic_energy(model, q, qd, points=8):
    """1/2 int rho |r'|^2 dx, r' by complex step of r along qd, Gauss points per element."""
    eta, w = np.polynomial.legendre.leggauss(points)
    eta, w = 0.5 * (eta + 1), 0.5 * w
    rho_a = model.params.mass_per_length
    total = 0.0
    for body in (model.leaf, model.link):
        for j, le in enumerate(body.element_length):
            for et, wt in zip(eta, w):
                x = body.node_x[j] + et * le
                rdot = point_position(model, body, q + 1e-30j * qd, x).imag / 1e-30
                total += 0.5 * rho_a * le * wt * rdot @ rdot
    return total


@pytest.mark.parametrize('n_el', MESHES)
def test_kinetic_energy_matches_direct_quadrature(n_el):
    model = UmbrellaModel(UmbrellaParams(elements_per_segment=n_el))
    rng = np.random.default_rng(n_el)
    for _ in range(3):
        q, qd = random_state(model, rng)
        t_matrix = 0.5 * qd @ model.mass_matrix(q) @ qd
        assert t_matrix == pytest.approx(quadrature_kinetic_energy(model, q, qd), rel=1e-12)


@pytest.mark.parametrize('n_el', MESHES)
def test_mass_matrix_symmetric_positive_definite(n_el):
    model = UmbrellaModel(UmbrellaParams(elements_per_segment=n_el))
    q, _ = random_state(model, np.random.default_rng(0))
    m = model.mass_matrix(q)
    assert np.allclose(m, m.T, rtol=0, atol=1e-15)
    assert np.linalg.eigvalsh(m).min() > 0


@pytest.mark.parametrize('n_el', MESHES)
def test_mass_derivatives_match_complex_step(n_el):
    model = UmbrellaModel(UmbrellaParams(elements_per_segment=n_el))
    rng = np.random.default_rng(10 + n_el)
    q, qd = random_state(model, rng, elastic=1e-2)
    h = 1e-30
    # Mdot = dM/dq . qd
    mdot_cs = model.mass_matrix(q + 1j * h * qd).imag / h
    assert np.abs(model.mass_matrix_derivative(q, qd) - mdot_cs).max() < 1e-13
    # (dT/dq)^T (Eq. 4.86)
    dtdq_cs = np.array([0.5 * qd @ model.mass_matrix(q + 1j * h * e) @ qd
                        for e in np.eye(model.n)]).imag / h
    assert np.abs(model.kinetic_energy_gradient(q, qd) - dtdq_cs).max() < 1e-12
    # the closed-form quadratic velocity vector Qv = -Mdot qd + dT/dq used in the solver
    qv = model.quadratic_velocity_forces(q, qd)
    assert np.abs(qv - (-mdot_cs @ qd + dtdq_cs)).max() < 1e-12 * (1 + np.abs(qv).max())
    # the bilinear gradient used by the discrete-gradient integrator
    a, b = rng.normal(size=model.n), rng.normal(size=model.n)
    grad_cs = np.array([0.5 * a @ model.mass_matrix(q + 1j * h * e) @ b
                        for e in np.eye(model.n)]).imag / h
    assert np.abs(model.kinetic_bilinear_gradient(q, a, b) - grad_cs).max() < 1e-13


def test_mass_derivative_matches_finite_difference():
    model = UmbrellaModel(UmbrellaParams(elements_per_segment=2))
    q, qd = random_state(model, np.random.default_rng(5), elastic=1e-2)
    eps = 1e-6
    fd = (model.mass_matrix(q + eps * qd) - model.mass_matrix(q - eps * qd)) / (2 * eps)
    assert np.abs(model.mass_matrix_derivative(q, qd) - fd).max() < 1e-8


def test_gyroscopic_matrix_is_velocity_jacobian_of_qv():
    model = UmbrellaModel(UmbrellaParams(elements_per_segment=2))
    q, qd = random_state(model, np.random.default_rng(6), elastic=1e-2)
    h = 1e-30
    jac = np.column_stack([model.quadratic_velocity_forces(q, qd + 1j * h * e).imag / h
                           for e in np.eye(model.n)])
    assert np.abs(model.gyroscopic_matrix(q, qd) + jac).max() < 1e-12


@pytest.mark.parametrize('n_el', [1, 2, 4])
def test_strain_energy_matches_quadrature_of_curvature_and_strain(n_el):
    """1/2 e^T K e = 1/2 int (EI v''^2 + EA u'^2) dx with v'' and u' by finite differences."""
    p = UmbrellaParams(elements_per_segment=n_el)
    model = UmbrellaModel(p)
    q, _ = random_state(model, np.random.default_rng(20 + n_el))
    ei = p.youngs_modulus * p.cross_section_inertia
    ea = p.youngs_modulus * p.cross_section_area
    eta, w = np.polynomial.legendre.leggauss(6)
    eta, w = 0.5 * (eta + 1), 0.5 * w
    total = 0.0
    for body, e in ((model.leaf, q[model.s_leaf]), (model.link, q[model.s_link])):
        for j, le in enumerate(body.element_length):
            d = 1e-4 * le
            for et, wt in zip(eta, w):
                x = body.node_x[j] + et * le
                x = min(max(x, body.node_x[j] + d), body.node_x[j + 1] - d)
                (um, vm), (u0, v0), (up, vp) = body.displacement(e, [x - d, x, x + d])
                curvature = (vp - 2 * v0 + vm) / d**2
                strain = (up - um) / (2 * d)
                total += 0.5 * le * wt * (ei * curvature**2 + ea * strain**2)
    assert model.strain_energy(q) == pytest.approx(total, rel=1e-6)


def test_element_stiffness_has_corrected_sign():
    """Erratum 1: the (2,5) entry of Eq. 4.43 is -12 EI / l^3 (printed +12/l^2)."""
    p = UmbrellaParams(elements_per_segment=1)
    model = UmbrellaModel(p)
    k = model.leaf.stiffness
    ei = p.youngs_modulus * p.cross_section_inertia
    le = p.l2
    iv = model.leaf.elastic_index(2, 'v')       # v of G; v of O'' is removed by the frame
    # G's transverse stiffness of a clamped-guided element: 12 EI / l^3
    assert k[iv, iv] == pytest.approx(12 * ei / le**3, rel=1e-12)
    # full element: the v_i-v_j coupling is negative
    from umbrella_sim.core.beam import GAUSS_POINTS, GAUSS_WEIGHTS
    _, _, d2n = shape_functions(GAUSS_POINTS, le)
    ke = ei * np.einsum('q,qi,qj->ij', le * GAUSS_WEIGHTS, d2n[:, 1], d2n[:, 1])
    assert ke[1, 4] == pytest.approx(-12 * ei / le**3, rel=1e-12)


def test_constraint_jacobian_and_bias_match_complex_step():
    from umbrella_sim.core.model import ConstraintSet
    model = UmbrellaModel(UmbrellaParams(elements_per_segment=2))
    q, qd = random_state(model, np.random.default_rng(7), elastic=1e-2)
    h = 1e-30
    for cs in (ConstraintSet(False, False), ConstraintSet(True, False), ConstraintSet(True, True)):
        jac = model.constraint_jacobian(q, cs)
        jac_cs = np.column_stack([model.constraint_residual(q + 1j * h * e, cs).imag / h
                                  for e in np.eye(model.n)])
        assert np.abs(jac - jac_cs).max() < 1e-13
        # -Jdot qd = -d/dt (J qd) along qd
        jdot_qd = ((model.constraint_jacobian(q + 1e-6 * qd, cs)
                    - model.constraint_jacobian(q - 1e-6 * qd, cs)) / 2e-6) @ qd
        assert np.abs(model.constraint_bias(q, qd, cs) + jdot_qd).max() < 1e-6
    g = model.sleeve_height_gradient(q)
    g_cs = np.array([model.sleeve_height(q + 1j * h * e).imag / h for e in np.eye(model.n)])
    assert np.abs(g - g_cs).max() < 1e-14


@pytest.mark.parametrize('model_name', ['flexible', 'flexible-nonlinear'])
def test_stress_rates_are_the_time_derivative_of_the_stresses(model_name):
    """d/dt of the fibre stresses along q + t qd, by complex step (membrane: quadratic in q)."""
    from umbrella_sim.core.solver import UmbrellaSimulator
    model = UmbrellaSimulator(UmbrellaParams(elements_per_segment=3, model=model_name)).model
    q, qd = random_state(model, np.random.default_rng(4), elastic=1e-2)
    rates = model.stress_rates(q, qd)
    stepped = model.stresses(q + 1e-30j * qd)
    for body in (0, 1):
        for fibre in (0, 1):
            expected = np.imag(stepped[body][fibre]) / 1e-30
            assert np.allclose(rates[body][fibre], expected, rtol=1e-12,
                               atol=1e-12 * np.abs(expected).max())
    if model_name == 'flexible-nonlinear':      # the membrane part is there and moves
        linear = UmbrellaModel.stress_rates(model, q, qd)
        assert np.abs(rates[0][0] - linear[0][0]).max() > 1e-3 * np.abs(rates[0][0]).max()


@pytest.mark.slow
def test_hermite_peak_finds_resolved_crests_between_the_ends():
    """
    A fibre stress A cos(w t + phi) over a step of w h <= 0.8: its crest within 0.2 %.

    Also exact on a parabola and a straight line; a crest the step does not resolve
    (w h = 2.5 to 3, the crest mid-step) is not counted: the larger end stands.
    """
    from umbrella_sim.core.outputs import hermite_peak
    rng = np.random.default_rng(7)
    tau = np.linspace(0.0, 1.0, 20001)[:, None]

    def sinusoid(theta, phi):
        s = lambda t: np.cos(theta * t + phi)                       # noqa: E731
        d = lambda t: -theta * np.sin(theta * t + phi)              # noqa: E731
        return s(0.0), d(0.0), s(1.0), d(1.0), np.abs(s(tau)).max(axis=0)

    theta, phi = rng.uniform(0.05, 0.8, 3000), rng.uniform(0.0, 2 * np.pi, 3000)
    s0, d0, s1, d1, true = sinusoid(theta, phi)
    peak = hermite_peak(s0, d0, s1, d1)
    ends = np.maximum(np.abs(s0), np.abs(s1))
    assert np.all(peak >= ends)
    assert np.allclose(peak, true, rtol=2e-3)
    assert np.sum(peak > ends * (1 + 1e-3)) > 100        # crests inside the step, exercised
    # a parabola and a straight line: the exact maximum
    s0, s1, d0 = rng.normal(size=(3, 2000))
    d1 = 2.0 * (s1 - s0) - d0
    a = s1 - s0 - d0
    dense = np.abs(s0 + tau * (d0 + tau * a)).max(axis=0)
    curvature_ok = np.abs(2.0 * a) <= np.abs(s0 + tau * (d0 + tau * a)).max(axis=0)
    exact = hermite_peak(s0, d0, s1, d1)
    assert np.allclose(exact[curvature_ok], dense[curvature_ok], rtol=1e-6)
    line = hermite_peak(s0, s1 - s0, s1, s1 - s0)
    assert np.array_equal(line, np.maximum(np.abs(s0), np.abs(s1)))
    # unresolved: w h = 2.5 to 3 with the crest mid-step
    theta = rng.uniform(2.5, 3.0, 500)
    s0, d0, s1, d1, true = sinusoid(theta, -theta / 2)
    assert np.array_equal(hermite_peak(s0, d0, s1, d1), np.maximum(np.abs(s0), np.abs(s1)))
    assert np.all(true > 3 * np.maximum(np.abs(s0), np.abs(s1)))


@pytest.mark.parametrize('n_el', [1, 2, 16])
def test_drawn_shape_is_each_elements_cubic(n_el):
    """
    The drawn shape (markers, plots) is r = R + A (p + N B e) at its points, not chords.

    Every drawn point is Eq. 3.17 at its abscissa; the ends of each element's pieces are
    its nodes; a cubic transverse field (zero at the leaf's supports) with a linear axial
    one is drawn exactly, which the straight lines between the nodes are not at N = 1.
    """
    from umbrella_sim.core.beam import shape_abscissae, shape_pieces_per_element
    model = UmbrellaModel(UmbrellaParams(elements_per_segment=n_el))
    rng = np.random.default_rng(n_el)
    q, _ = random_state(model, rng)
    for body, drawn in zip((model.leaf, model.link), model.deformed_shape(q)):
        per = shape_pieces_per_element(len(body.element_length))
        x = shape_abscissae(body.node_x, per)
        assert len(drawn) == len(x) >= 17
        exact = np.array([point_position(model, body, q, xi) for xi in x])
        assert np.abs(drawn - exact).max() < 1e-12
        assert np.array_equal(drawn[::per], model.node_positions(q)[body is model.link])
    # a cubic field on the leaf: v = c x (x - l1) (x - d), u = k x; alpha1 = 0.3
    p = model.params
    c, d, k = 1e-2, 0.3, 1e-3
    v = lambda x: c * x * (x - p.l1) * (x - d)                        # noqa: E731
    dv = lambda x: c * (3 * x**2 - 2 * (p.l1 + d) * x + p.l1 * d)    # noqa: E731
    q = np.zeros(model.n)
    q[0] = 0.3
    for node, x in enumerate(model.leaf.node_x):
        for dof, value in (('u', k * x), ('v', v(x)), ('theta', dv(x))):
            try:
                q[model.s_leaf.start + model.leaf.elastic_index(node, dof)] = value
            except KeyError:                  # held by the frame (zero in this field)
                assert abs(value) < 1e-15
    leaf, _ = model.deformed_shape(q, magnification=7.0)
    x = shape_abscissae(model.leaf.node_x, shape_pieces_per_element(2 * n_el))
    local = np.column_stack([x + 7.0 * k * x, 7.0 * v(x)])
    exact = local @ np.array([[np.cos(0.3), np.sin(0.3)], [-np.sin(0.3), np.cos(0.3)]])
    assert np.abs(leaf - exact).max() < 1e-13
    if n_el == 1:                  # the chords between the 3 nodes miss the field by ~mm
        nodes = model.node_positions(q, 7.0)[0]
        chord = np.column_stack([np.interp(x, model.leaf.node_x, nodes[:, i]) for i in (0, 1)])
        assert np.abs(chord - exact).max() > 1e-3


def test_hermite_crests_give_each_rows_largest_crest_and_where():
    """
    hermite_crests skips the points whose bound cannot pass their row's largest end value.

    Rows of 12 stress points (sinusoids of w h up to 1.2, and some slow), against hermite_peak
    on every point: the same largest value of each row and the same point holding it; where
    a point is skipped, its ends' value stands, at most its crest.
    """
    from umbrella_sim.core.outputs import hermite_crests, hermite_peak
    rng = np.random.default_rng(11)
    theta = rng.uniform(0.0, 1.2, (4000, 12)) * rng.choice([1.0, 0.05], (4000, 1))
    phi = rng.uniform(0.0, 2 * np.pi, (4000, 12))
    amp = rng.uniform(0.1, 1.0, (4000, 12))
    s0, s1 = amp * np.cos(phi), amp * np.cos(theta + phi)
    d0, d1 = -amp * theta * np.sin(phi), -amp * theta * np.sin(theta + phi)
    every = hermite_peak(s0, d0, s1, d1)
    crests = hermite_crests(s0, d0, s1, d1)
    assert np.array_equal(crests.max(-1), every.max(-1))
    assert np.array_equal(crests.argmax(-1), every.argmax(-1))
    ends = np.maximum(np.abs(s0), np.abs(s1))
    assert np.all((crests == every) | (crests == ends))
    assert np.sum(crests != every) > 1000          # points skipped, exercised
    assert np.sum(every.max(-1) > ends.max(-1)) > 100     # crests inside the step, exercised
