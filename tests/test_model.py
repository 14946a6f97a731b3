"""Free-free plate model: rigid-body modes, matrix properties, invariance, sensitivities."""

import numpy as np
import pytest
import scipy.linalg as sla

from bayesplate import laminate
from bayesplate.plate.model import PlateModel

E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
B_REF = laminate.stiffness_from_engineering(E_REF)
LAYUP = [0, 45, -30]  # unsymmetric: in-plane / bending coupling present


def _model(mesh=(6, 4), a=0.1, b=0.06, layup=LAYUP, **kw):
    return PlateModel(a, b, 3e-3, 1537.0, layup, mesh=mesh, **kw)


def test_exactly_six_rigid_body_modes_dense():
    m = _model(mesh=(3, 2))
    K, M = m.stiffness(B_REF).toarray(), m.mass.toarray()
    ev = sla.eigh(K, M, eigvals_only=True)
    zero = np.abs(ev) < 1e-8 * ev[6]  # six zeros to rounding, far below the first elastic one
    assert zero.sum() == 6 and np.all(zero[:6])


def test_stiffness_symmetric_psd_and_mass_symmetric_pd():
    m = _model(mesh=(3, 2))
    K, M = m.stiffness(B_REF), m.mass
    assert abs(K - K.T).max() <= 1e-12 * abs(K).max()
    assert abs(M - M.T).max() <= 1e-12 * abs(M).max()
    assert np.linalg.eigvalsh(M.toarray()).min() > 0
    ev = sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)
    assert ev.min() > -1e-8 * ev[6]


def test_sparse_solver_detects_six_rigid_modes_and_normalises():
    m = _model()
    r = m.solve(B_REF, 10)
    assert r.n_rigid == 6
    assert np.all(r.eigenvalues > 0) and np.all(np.diff(r.eigenvalues) >= 0)
    G = r.vectors.T @ (m.mass @ r.vectors)
    np.testing.assert_allclose(G, np.eye(10), atol=1e-10)
    dense = sla.eigh(m.stiffness(B_REF).toarray(), m.mass.toarray(), eigvals_only=True)
    np.testing.assert_allclose(r.eigenvalues, dense[6:16], rtol=1e-9)


def test_simply_supported_plate_has_no_rigid_modes():
    r = _model(boundary="simply_supported", layup=[0, 90, 0]).solve(B_REF, 5)
    assert r.n_rigid == 0 and r.eigenvalues[0] > 0


def test_the_same_plate_on_another_mesh_keeps_its_boundary_and_element():
    plate = _model(boundary="simply_supported", layup=[0, 90, 0], mesh=(6, 4))
    other = plate.on_mesh((4, 2))
    built = _model(boundary="simply_supported", layup=[0, 90, 0], mesh=(4, 2))
    assert other.boundary == "simply_supported" and (other.mesh.nx, other.mesh.ny) == (4, 2)
    np.testing.assert_array_equal(
        other.solve(B_REF, 5).eigenvalues, built.solve(B_REF, 5).eigenvalues
    )


def test_rotating_the_plate_by_ninety_degrees_changes_nothing():
    # swap a and b and add 90 degrees to every ply: the same physical plate
    r1 = _model(mesh=(6, 4), a=0.1, b=0.06).solve(B_REF, 12)
    r2 = _model(mesh=(4, 6), a=0.06, b=0.1, layup=[t + 90 for t in LAYUP]).solve(B_REF, 12)
    np.testing.assert_allclose(r1.frequency_Hz, r2.frequency_Hz, rtol=1e-9)


def test_mirror_layup_gives_same_frequencies():
    # flipping the stack upside down (z -> -z) with the angles mirrored is the same plate seen
    # from below; for a free plate the spectrum is unchanged
    r1 = _model().solve(B_REF, 8)
    r2 = _model(layup=LAYUP[::-1]).solve(B_REF, 8)
    np.testing.assert_allclose(r1.frequency_Hz, r2.frequency_Hz, rtol=1e-9)


def test_stiffness_is_linear_in_coefficients(rng):
    m = _model(mesh=(2, 2))
    b1, b2 = B_REF * rng.uniform(0.8, 1.2, 6), B_REF * rng.uniform(0.8, 1.2, 6)
    lhs = m.stiffness(2.0 * b1 - b2).toarray()
    rhs = 2.0 * m.stiffness(b1).toarray() - m.stiffness(b2).toarray()
    # the K_j are independent of b: any linear combination is exact to rounding
    np.testing.assert_allclose(lhs, rhs, atol=1e-9 * np.abs(lhs).max())
    full = PlateModel(0.1, 0.06, 3e-3, 1537.0, LAYUP, mesh=(2, 2))
    C = laminate.constitutive_matrix(full.laminate(b1))
    direct = full.assembler.assemble(full.element.stiffness(C)).toarray()
    np.testing.assert_allclose(m.stiffness(b1).toarray(), direct, atol=1e-9 * np.abs(direct).max())


def _richardson(f, x, j, rel):
    """d f / d x_j by central differences at steps h and h/2, Richardson-extrapolated.

    Truncation is O(h^4) (~1e-12 at h = 1e-3 x); rounding of the eigenvalues (~1e-12
    relative after the Rayleigh-quotient refinement) divided by h stays below 1e-8.
    """

    def central(h):
        dx = np.zeros(6)
        dx[j] = h
        return (f(x + dx) - f(x - dx)) / (2 * h)

    h = rel * x[j]
    return (4 * central(h / 2) - central(h)) / 3


@pytest.mark.parametrize("layup", [[0], LAYUP])
def test_sensitivities_match_central_differences(layup):
    m = _model(layup=layup)
    n = 10
    r = m.solve(B_REF, n)
    assert np.min(np.diff(r.eigenvalues) / r.eigenvalues[1:]) > 1e-3  # distinct modes
    for j in range(6):
        fd = _richardson(lambda b: m.solve(b, n).eigenvalues, B_REF, j, 1e-3)
        # relative error under 1e-5 (the bound) on every derivative; derivatives that
        # are zero by symmetry are compared on the scale 1e-6 lambda / b_j
        scale = np.maximum(np.abs(fd), 1e-6 * r.eigenvalues / B_REF[j])
        assert np.max(np.abs(r.sensitivities[:, j] - fd) / scale) < 1e-5, f"b_{j}"


def test_engineering_sensitivities_chain_rule():
    m = _model(layup=[0])
    n = 8
    r = m.solve(B_REF, n)
    de_sens = r.engineering_sensitivities()
    for j in range(6):
        fd = _richardson(
            lambda e: m.solve(laminate.stiffness_from_engineering(e), n).eigenvalues, E_REF, j, 1e-3
        )
        scale = np.maximum(np.abs(fd), 1e-6 * r.eigenvalues / E_REF[j])
        assert np.max(np.abs(de_sens[:, j] - fd) / scale) < 1e-5, f"e_{j}"


def test_normalised_sensitivities_sum_to_one():
    # lambda is homogeneous of degree one in b (K linear, M fixed): sum_j s_ij = 1 (Euler)
    r = _model().solve(B_REF, 10)
    np.testing.assert_allclose(r.normalised_sensitivities().sum(axis=1), 1.0, rtol=1e-9)


def test_interpolation_reproduces_nodal_values():
    m = _model()
    r = m.solve(B_REF, 3)
    nodes = np.arange(0, m.mesh.n_nodes, 7)
    w = m.interpolation(m.mesh.nodes[nodes]) @ r.vectors
    np.testing.assert_allclose(w, r.vectors[m.mesh.dofs("w", nodes)], atol=1e-10 * np.abs(w).max())


def test_bad_boundary_is_refused():
    with pytest.raises(ValueError, match="boundary"):
        _model(boundary="clamped")


def test_same_inputs_give_the_same_numbers():
    # the Lanczos start vector is fixed: no hidden randomness in the forward model
    m = _model()
    a, b = m.solve(B_REF, 8), m.solve(B_REF, 8)
    assert np.array_equal(a.eigenvalues, b.eigenvalues)
    assert np.array_equal(a.sensitivities, b.sensitivities)


# ------------------------------------------------ the Rayleigh bound of the lowest eigenvalue
# Candidate priors (discrepancy/elastic_foundation.py, point_support.py) scale on it.


def test_lowest_eigenvalue_bound_is_navier_for_a_thin_simply_supported_cross_ply():
    # [0/90/0] has D16 = D26 = 0, so sin(pi x/a) sin(pi y/b) is its Kirchhoff mode and the
    # bound is exact there; at a/h = 200 the TSDT Navier solution (tests/reference, an
    # independent code) differs from Kirchhoff by shear deformation only, about 0.05 %.
    try:
        from reference import navier_tsdt as nt
    except ImportError:  # tests/ imported as a package
        from tests.reference import navier_tsdt as nt
    a, b, h, rho = 0.3, 0.2, 1.5e-3, 1537.0
    model = PlateModel(a, b, h, rho, [0, 90, 0], mesh=(4, 4), boundary="simply_supported")
    E1, E2, nu12, G12, G13, G23 = E_REF
    omega = nt.navier_frequencies(a, b, h, rho, (0, 90, 0), E1, E2, nu12, G12, G13, G23, m=1, n=1)
    ratio = model.lowest_eigenvalue_bound(B_REF) / omega[0] ** 2
    assert 1.0 <= ratio < 1.002


def test_lowest_eigenvalue_bound_of_a_free_square_isotropic_plate():
    # w = xy is the twist: 576 D66/(I0 a^4) = 576 (1 - nu)/2 D/(rho h a^4); Leissa (1969,
    # Vibration of Plates, table 4.75) gives the true lowest omega a^2 sqrt(rho h/D) = 13.468
    # for nu = 0.3, so the bound is (sqrt(201.6)/13.468)^2 = 1.111 times the true value.
    E, nu = 70e9, 0.3
    e = np.array([E, E, nu, E / (2 * (1 + nu)), E / (2 * (1 + nu)), E / (2 * (1 + nu))])
    model = PlateModel(0.2, 0.2, 1e-3, 2700.0, [0], mesh=(4, 4))
    D = E * 1e-3**3 / (12 * (1 - nu**2))
    bound = model.lowest_eigenvalue_bound(laminate.stiffness_from_engineering(e))
    leissa = (13.468 / 0.2**2) ** 2 * D / (2700.0 * 1e-3)
    assert bound / leissa == pytest.approx(576 * (1 - nu) / 2 / 13.468**2, rel=1e-3)


@pytest.mark.parametrize(
    ("a", "b", "layup", "mesh"),
    [
        (0.1, 0.06, LAYUP, (10, 6)),  # unsymmetric: D - B A^-1 B
        (0.3, 0.05, [0, 90, 90, 0], (24, 4)),  # a beam: the beam shape along x
        (0.2, 0.2, [45, -45, -45, 45], (12, 12)),  # D12 near D11: the saddle x^2 - y^2
    ],
)
def test_lowest_eigenvalue_bound_lies_just_above_the_computed_one(a, b, layup, mesh):
    # a Rayleigh quotient bounds the lowest eigenvalue from above; shear deformation and the
    # shapes' distance from the true mode keep it within about 30 % on plates of any aspect
    model = PlateModel(a, b, 2e-3, 1537.0, layup, mesh=mesh)
    computed = model.solve(B_REF, 1).eigenvalues[0]
    assert 1.0 < model.lowest_eigenvalue_bound(B_REF) / computed < 1.3


def test_assembled_matrices_leave_out_exact_zeros_and_multiply_bit_for_bit():
    """The model's ``K_j``, ``M`` and a foundation's ``K_0`` against the CSR on the whole
    shared pattern: fewer stored entries, none of them zero, the same products to the last
    bit; a modified copy gets its own matrices, and the original keeps its."""
    model = PlateModel(0.2, 0.1, 0.004, 1500.0, [0.0, 90.0, 90.0, 0.0], mesh=(6, 4))
    x = np.random.default_rng(5).standard_normal((model.mesh.n_dofs, 3))
    foundation = model.modified(extra_stiffness_data=0.5 * model.mass_data)
    pairs = [(model.stiffness_term(j), model.stiffness_terms[j]) for j in range(6)]
    pairs += [
        (model.mass, model.mass_data),
        (foundation.extra_stiffness, foundation.extra_stiffness_data),
    ]
    for A, data in pairs:
        full = model.assembler.matrix(data)
        assert A.nnz == np.count_nonzero(data) < full.nnz
        assert np.all(A.data != 0)
        assert np.array_equal(A @ x, full @ x)
        assert np.array_equal(A.toarray(), full.toarray())
    assert model.extra_stiffness is None
    heavier = model.modified(mass_data=2.0 * model.mass_data)
    assert np.array_equal(heavier.mass @ x, 2.0 * (model.mass @ x))
    assert model.mass is model.mass  # built once
