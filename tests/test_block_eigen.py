"""Block shift-invert Lanczos against ARPACK and dense eigensolvers; the model's fast path.

References are other methods (ARPACK's implicitly restarted Lanczos, LAPACK's dense
``eigh``) or the definition (``a^T K_j a`` with the assembled ``K_j``), never this code's
own output.
"""

import logging

import numpy as np
import pytest
import scipy.linalg as sla

from bayesplate import bundled_case_path, laminate, load_case
from bayesplate.fem.eigen import lowest_modes
from bayesplate.fem.submatrix import SubPattern
from bayesplate.plate.model import PlateModel

E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
B_REF = laminate.stiffness_from_engineering(E_REF)
E_ISO = np.array([70e9, 70e9, 0.3, 70e9 / 2.6, 70e9 / 2.6, 70e9 / 2.6])
B_ISO = laminate.stiffness_from_engineering(E_ISO)


def _problem(model, b):
    """``K, M, shift, rigid basis, n_rigid`` on the free unknowns (the old extraction)."""
    free = model.free_dofs
    K = model.stiffness(b)[free][:, free]
    M = model.mass[free][:, free]
    rigid = None if model._rigid_basis is None else model._rigid_basis[free]
    return K, M, model.spectral_shift(b), rigid, 0 if rigid is None else 6


def _both(model, b, n_modes, **kw):
    K, M, shift, rigid, n_rigid = _problem(model, b)
    common = dict(n_rigid_max=n_rigid, ordering=model._ordering, rigid_basis=rigid, **kw)
    block = lowest_modes(K, M, n_modes, shift, method="block", **common)
    arpack = lowest_modes(K, M, n_modes, shift, method="arpack", **common)
    return block, arpack, M


def _assert_same_modes(block, arpack, M, rtol=1e-10):
    """Eigenvalues to ``rtol``; distinct modes by MAC, clusters by their spanned subspace.

    The vectors of the last cluster are not compared: it may go on past the modes computed.
    """
    np.testing.assert_allclose(block.eigenvalues, arpack.eigenvalues, rtol=rtol, atol=0)
    np.testing.assert_array_equal(len(block.rigid_eigenvalues), len(arpack.rigid_eigenvalues))
    lam = arpack.eigenvalues
    # clusters: eigenvalues within 1e-6 of each other (degenerate to discretisation symmetry)
    starts = np.flatnonzero(np.r_[True, np.diff(lam) > 1e-6 * lam[1:]])
    ends = np.r_[starts[1:], len(lam)]
    overlap = arpack.vectors.T @ (M @ block.vectors)  # both M-orthonormal
    for s, e in zip(starts, ends, strict=True):
        if e == len(lam):
            break  # the last cluster may go on past the modes computed: not comparable
        cosines = sla.svdvals(overlap[s:e, s:e])  # cosines of the principal angles
        if e - s == 1:
            assert cosines[0] ** 2 > 1 - 1e-8, (s, cosines)  # MAC, sign-free
        else:
            assert np.all(cosines**2 > 1 - 1e-8), (s, e, cosines)


@pytest.fixture(scope="module")
def frederiksen():
    case = load_case(bundled_case_path("frederiksen_t300"))
    model = PlateModel.from_case(case, mesh=(50, 50))
    return model, laminate.stiffness_from_engineering(case.reference)


def test_frederiksen_50x50_matches_arpack(frederiksen):
    model, b = frederiksen
    block, arpack, M = _both(model, b, 14)
    assert len(block.rigid_eigenvalues) == 6
    _assert_same_modes(block, arpack, M)


@pytest.mark.parametrize("split", [False, True])
def test_frederiksen_model_fast_path_matches_arpack_path(frederiksen, split):
    """model.solve: index maps, element sensitivities, and (split) in-plane / bending apart."""
    model, b = frederiksen
    model.split_decoupled = split
    try:
        fast = model.solve(b, 14)
    finally:
        model.split_decoupled = False
    old = model.solve(b, 14, method="arpack")
    assert model._decoupled(model._stiffness_data(b))  # single ply: the split applies
    assert fast.n_rigid == old.n_rigid == 6
    _assert_same_modes(fast, old, model.mass)
    scale = fast.eigenvalues[:, None] / b[None, :]
    np.testing.assert_allclose(fast.sensitivities / scale, old.sensitivities / scale, atol=1e-9)


def test_square_isotropic_plate_degenerate_pairs():
    """A square isotropic plate has pairs of equal eigenvalues (x <-> y symmetry)."""
    model = PlateModel(0.2, 0.2, 2e-3, 2700.0, [0], mesh=(12, 12))
    block, arpack, M = _both(model, B_ISO, 12)
    lam = arpack.eigenvalues
    assert np.sum(np.diff(lam) < 1e-8 * lam[1:]) >= 2  # the case has degenerate pairs
    _assert_same_modes(block, arpack, M)
    arpack = model.solve(B_ISO, 12, method="arpack")
    _assert_same_modes(model.solve(B_ISO, 12), arpack, model.mass)
    model.split_decoupled = True
    _assert_same_modes(model.solve(B_ISO, 12), arpack, model.mass)


def test_simply_supported_plate_has_no_rigid_modes():
    model = PlateModel(
        0.3, 0.2, 3e-3, 1537.0, [0, 45, -30], mesh=(10, 8), boundary="simply_supported"
    )
    block, arpack, M = _both(model, B_REF, 10)
    assert len(block.rigid_eigenvalues) == 0
    _assert_same_modes(block, arpack, M)


def test_small_plate_against_dense_eigh():
    model = PlateModel(0.1, 0.06, 3e-3, 1537.0, [0, 45, -30], mesh=(5, 3))
    K, M, shift, rigid, _ = _problem(model, B_REF)
    dense = sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)
    sol = lowest_modes(K, M, 10, shift, ordering=model._ordering, rigid_basis=rigid)
    np.testing.assert_allclose(sol.eigenvalues, dense[6:16], rtol=1e-9)
    np.testing.assert_allclose(sol.vectors.T @ (M @ sol.vectors), np.eye(10), atol=1e-12)


def test_fallback_to_arpack_when_the_block_method_hits_its_cap(caplog):
    model = PlateModel(0.1, 0.06, 3e-3, 1537.0, [0, 45, -30], mesh=(6, 4))
    K, M, shift, rigid, _ = _problem(model, B_REF)
    common = dict(ordering=model._ordering, rigid_basis=rigid)
    with caplog.at_level(logging.WARNING, logger="bayesplate.fem.eigen"):
        capped = lowest_modes(K, M, 8, shift, max_dim=12, **common)
    assert "did not converge" in caplog.text
    arpack = lowest_modes(K, M, 8, shift, method="arpack", **common)
    np.testing.assert_array_equal(capped.eigenvalues, arpack.eigenvalues)
    np.testing.assert_array_equal(capped.vectors, arpack.vectors)


def test_deterministic_bit_identical():
    model = PlateModel(0.1, 0.06, 3e-3, 1537.0, [0, 45, -30], mesh=(8, 6))
    a, b = model.solve(B_REF, 10), model.solve(B_REF, 10)
    c = PlateModel(0.1, 0.06, 3e-3, 1537.0, [0, 45, -30], mesh=(8, 6)).solve(B_REF, 10)
    for other in (b, c):
        np.testing.assert_array_equal(a.eigenvalues, other.eigenvalues)
        np.testing.assert_array_equal(a.vectors, other.vectors)
        np.testing.assert_array_equal(a.sensitivities, other.sensitivities)


@pytest.mark.parametrize("modified", [False, True])
def test_sensitivities_are_the_quadratic_forms_of_the_assembled_terms(modified):
    model = PlateModel(0.1, 0.06, 3e-3, 1537.0, [0, 45, -30], mesh=(6, 4))
    if modified:  # terms replaced: the stacked sparse product instead of the element sums
        model = model.modified(stiffness_terms=model.stiffness_terms * 1.01)
    r = model.solve(B_REF, 8)
    expected = np.column_stack(
        [np.einsum("di,di->i", r.vectors, model.stiffness_term(j) @ r.vectors) for j in range(6)]
    )
    scale = r.eigenvalues[:, None] / B_REF[None, :]
    np.testing.assert_allclose(r.sensitivities / scale, expected / scale, atol=1e-10)


def test_subpattern_equals_slicing():
    model = PlateModel(0.1, 0.06, 3e-3, 1537.0, [0], mesh=(4, 3), boundary="simply_supported")
    data = np.random.default_rng(1).standard_normal(model.assembler.nnz)
    full = model.assembler.matrix(data)
    dofs = model.free_dofs[model._ordering]
    for subset in (model.free_dofs, dofs, dofs[dofs % 8 >= 2], np.arange(8, 40)):
        pattern = SubPattern(model.assembler, subset)
        expected = full[subset][:, subset].toarray()
        for matrix in (pattern.csr(data), pattern.csc(data), pattern.blocked(data)):
            np.testing.assert_array_equal(matrix.toarray(), expected)
    assert SubPattern(model.assembler, np.arange(8, 40)).node_size == 8
