"""Certified reduced-basis model: exactness at snapshots, Ritz bounds, certificate, fallback.

Two plates: Daghia's plate 1 on its own 8 x 4 mesh (tiny) and the Frederiksen T300 plate on
a 24 x 12 mesh instead of its 50 x 50 one (the quick tier); the 50 x 50 model is in one slow
test that also reports build and evaluation times.
"""

import logging
import time
import warnings

import numpy as np
import pytest

from bayesplate import laminate
from bayesplate.discrepancy.physics.elastic_foundation import ElasticFoundation
from bayesplate.io import bundled_case_path, load_case
from bayesplate.plate.forward import ForwardModel, Modes
from bayesplate.plate.model import ModalResult, PlateModel
from bayesplate.reduced import (
    DEFAULT_TOLERANCE,
    Box,
    CertifiedModel,
    ReducedModalResult,
    ReducedModel,
    ReducedModelWarning,
    certify,
    fast_model,
    prior_stiffness,
    stiffness_box,
)

N_MODES = 14  # the measured frequencies of both cases
SEED = 20070461
CASES = {"plate1": (8, 4), "frederiksen_t300": (24, 12)}
# The Ritz values are upper bounds in exact arithmetic. Rounding of the full solution
# (Rayleigh quotients, ~1e-14) and of the reduced matrices (~1e-12 of the smallest eigenvalue:
# the basis energies span four decades) allow a violation far below this.
UPPER_BOUND_SLACK = 1e-10


def _setup(name, mesh=None):
    case = load_case(bundled_case_path(name))
    model = PlateModel.from_case(case, mesh=mesh or CASES[name])
    mean_b, _ = prior_stiffness(case.prior)
    return model, mean_b, stiffness_box(case.prior)


@pytest.fixture(scope="module", params=sorted(CASES))
def certified(request):
    """A certified fast model of each case, built once (greedy rounds as needed)."""
    model, mean_b, box = _setup(request.param)
    fast = fast_model(model, mean_b, box, N_MODES, rng=SEED)
    return request.param, model, fast


# ----------------------------------------------------------------------------- the box


def test_prior_box_is_three_sigma_cut_to_physical_laminae():
    case = load_case(bundled_case_path("frederiksen_t300"))
    mean_b, cov_b = prior_stiffness(case.prior)
    box = stiffness_box(case.prior)
    sd = np.sqrt(np.diag(cov_b))
    np.testing.assert_allclose(box.upper, mean_b + 3 * sd)
    # G23 = 4 +- 4.5 GPa: the lower bound of C44 is cut at a tenth of the mean
    assert box.lower[4] == pytest.approx(0.1 * mean_b[4])
    corners = np.array(np.meshgrid(*zip(box.lower, box.upper, strict=True))).reshape(6, -1).T
    assert np.all(laminate.is_physical(corners))


def test_design_fills_the_box_and_is_seeded():
    box = Box([10.0, 10.0, 1.0, 1.0, 1.0, 1.0], [11.0, 11.0, 2.0, 2.0, 2.0, 2.0])
    points = box.sample(16, np.random.default_rng(1))
    assert points.shape == (16, 6) and np.all(box.contains(points))
    # Latin hypercube: one point in each of the 16 strata of every coordinate
    strata = np.floor((points - box.lower) / (box.upper - box.lower) * 16).astype(int)
    assert all(sorted(col) == list(range(16)) for col in strata.T)
    np.testing.assert_array_equal(points, box.sample(16, np.random.default_rng(1)))
    assert not box.contains(box.upper + 1.0)


def test_box_refuses_non_physical_laminae():
    with pytest.raises(ValueError, match="non-physical"):
        Box([1e9, 1e9, -5e9, 1e9, 1e9, 1e9], [2e9, 2e9, 5e9, 2e9, 2e9, 2e9])


# ----------------------------------------------------------------------------- exactness


@pytest.mark.parametrize("name", sorted(CASES))
def test_snapshot_points_are_reproduced_exactly_without_compression(name):
    # rank_tol = 1e-7 keeps every direction above 1e-14 of a snapshot's energy, so the
    # snapshot modes are in the span to ~1e-14 and their Ritz values equal the full ones.
    model, mean_b, box = _setup(name)
    reduced = ReducedModel.build(model, mean_b, box, N_MODES, n_snapshots=2, rank_tol=1e-7, rng=1)
    for b in reduced.points:
        full, red = model.solve(b, N_MODES), reduced.solve(b)
        np.testing.assert_allclose(red.eigenvalues, full.eigenvalues, rtol=1e-10)
        assert red.n_rigid == full.n_rigid == 6


def test_compressed_basis_is_close_at_snapshots(certified):
    # compression drops directions below rank_tol of a snapshot's energy norm: the
    # eigenvalues move by about rank_tol^2 at most (4e-6 at the default 2e-3)
    _, model, fast = certified
    reduced = fast.reduced
    b = reduced.points[0]
    rel = reduced.solve(b).eigenvalues / model.solve(b, N_MODES).eigenvalues - 1
    assert np.all(rel >= -UPPER_BOUND_SLACK) and rel.max() < reduced.rank_tol**2


def test_unsymmetric_laminate_keeps_only_the_half_turn_symmetry():
    # [0/45/-30] couples bending and stretching and has no mirror symmetry; turning the plate
    # by 180 degrees about its normal maps every ply onto itself, so two classes remain
    b_ref = laminate.stiffness_from_engineering([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
    model = PlateModel(0.1, 0.06, 3e-3, 1537.0, [0, 45, -30], mesh=(6, 4))
    box = Box(0.8 * b_ref, 1.2 * b_ref)
    reduced = ReducedModel.build(model, b_ref, box, 10, n_snapshots=2, rank_tol=1e-7, rng=1)
    assert len(reduced.block_sizes) == 2
    assert reduced.max_dropped_coupling < 1e-8  # rounding between the classes
    full = model.solve(reduced.points[1], 10)
    red = reduced.solve(reduced.points[1])
    np.testing.assert_allclose(red.eigenvalues, full.eigenvalues, rtol=1e-10)


def test_simply_supported_plate_has_no_rigid_columns():
    b_ref = laminate.stiffness_from_engineering([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
    model = PlateModel(
        0.1, 0.06, 3e-3, 1537.0, [0, 90, 0], mesh=(6, 4), boundary="simply_supported"
    )
    reduced = ReducedModel.build(
        model, b_ref, Box(0.8 * b_ref, 1.2 * b_ref), 8, n_snapshots=1, rank_tol=1e-7, rng=1
    )
    assert reduced.n_rigid == 0
    red, full = reduced.solve(b_ref), model.solve(b_ref, 8)
    np.testing.assert_allclose(red.eigenvalues, full.eigenvalues, rtol=1e-10)
    assert red.n_rigid == full.n_rigid == 0


def test_constant_stiffness_and_bouncing_rigid_modes_follow_the_full_model():
    # a Winkler foundation adds K_0 independent of b and turns three rigid-body modes into
    # low bouncing modes, which both models must drop by their shape
    model, mean_b, box = _setup("plate1")
    physics = ElasticFoundation()
    (k,) = physics.parameters(model, mean_b)
    supported = physics.apply(model, (10 * k.sd,))
    reduced = ReducedModel.build(
        supported, mean_b, box, N_MODES, n_snapshots=2, rank_tol=1e-7, rng=1
    )
    assert reduced.constant is not None
    full, red = supported.solve(mean_b, N_MODES), reduced.solve(mean_b)
    np.testing.assert_allclose(red.eigenvalues, full.eigenvalues, rtol=1e-10)
    assert red.n_rigid == full.n_rigid


# ----------------------------------------------------------------------------- bounds, certificate


def test_ritz_values_are_upper_bounds_at_held_out_points(certified):
    _, _, fast = certified
    errors = fast.certificate.errors  # f_reduced / f_full - 1 at points never in the basis
    assert np.all(fast.box.contains(fast.certificate.points))
    assert errors.min() >= -UPPER_BOUND_SLACK


def test_certificate_meets_the_issue_bound(certified, record_property):
    name, _, fast = certified
    cert = fast.certificate
    record_property(f"{name}_certificate", str(cert))
    print(f"\n{name}: {cert}; blocks {fast.reduced.block_sizes}")
    assert cert.passed and cert.max_rel_error < DEFAULT_TOLERANCE == cert.tolerance
    assert cert.n_test == 6 + 4 and cert.n_probe == 4  # random points and probes
    assert cert.per_mode_max.shape == (N_MODES,)
    assert cert.basis_size == fast.reduced.size
    # one orthotropic ply: mirror symmetric about both mid-lines and the mid-plane, 2^3
    # classes that no matrix couples
    assert len(fast.reduced.block_sizes) == 8 and fast.reduced.max_dropped_coupling < 1e-12
    # the held-out points are not snapshot points
    assert not np.any(np.all(np.isclose(cert.points[:, None], fast.reduced.points[None]), -1))


def test_certify_on_given_points_agrees_with_a_direct_comparison(certified):
    _, model, fast = certified
    points = fast.reduced.box.sample(2, np.random.default_rng(7))
    cert = certify(model, fast.reduced, points)
    direct = [
        fast.reduced.solve(p).frequency_Hz / model.solve(p, N_MODES).frequency_Hz - 1
        for p in points
    ]
    # the full model repeats itself to ~1e-14 only (random Lanczos start)
    np.testing.assert_allclose(cert.errors, direct, rtol=1e-8, atol=1e-12)
    assert cert.n_test == 2


def test_earlier_stages_are_leading_columns_with_higher_ritz_values(certified):
    # Courant-Fischer: a smaller subspace never gives a lower Ritz value
    _, model, fast = certified
    reduced = fast.reduced
    assert list(reduced.levels) == sorted(reduced.levels) and reduced.levels[-1] == reduced.size
    b = fast.certificate.points[0]
    final = reduced.solve(b).eigenvalues
    for size in reduced.levels[1:-1]:
        earlier = reduced.leading(size).solve(b).eigenvalues
        assert np.all(earlier >= final * (1 - UPPER_BOUND_SLACK))


# ----------------------------------------------------------------------------- sensitivities


def test_sensitivities_match_finite_differences_and_the_full_model(certified):
    _, model, fast = certified
    reduced = fast.reduced
    b = fast.certificate.points[0]
    red = reduced.solve(b)
    fd = np.empty((N_MODES, 6))
    for j in range(6):
        h = 1e-4 * b[j]  # central differences: truncation ~h^2 ~ 1e-8, rounding ~1e-12
        up, down = b.copy(), b.copy()
        up[j] += h
        down[j] -= h
        fd[:, j] = (reduced.solve(up).eigenvalues - reduced.solve(down).eigenvalues) / (2 * h)
    scale = np.abs(red.sensitivities * b).max(axis=1)  # per mode, in eigenvalue units
    assert np.max(np.abs((red.sensitivities - fd) * b).max(axis=1) / scale) < 1e-6
    # against the full model: first order in the eigenvector error, ~1e-3 of each mode's
    # largest normalised sensitivity (the eigenvalues themselves agree to ~1e-5)
    full = model.solve(b, N_MODES)
    diff = np.abs((red.sensitivities - full.sensitivities) * b).max(axis=1)
    assert np.max(diff / scale) < 2e-3


def test_results_carry_the_full_model_fields(certified):
    _, model, fast = certified
    b = fast.certificate.points[1]
    red = fast.reduced.solve(b)
    assert isinstance(red, ReducedModalResult)
    assert red.coefficients.shape == (fast.reduced.size, N_MODES)
    assert red.frequency_Hz.shape == red.eigenvalues.shape == (N_MODES,)
    assert red.n_rigid == 6
    v = red.vectors  # computed on request only
    assert v.shape == (model.mesh.n_dofs, N_MODES)
    np.testing.assert_allclose(v.T @ (model.mass @ v), np.eye(N_MODES), atol=1e-10)
    np.testing.assert_allclose(red.to_modal_result().sensitivities, red.sensitivities)
    # the eigenvalues-only path (no eigenvectors) gives the same numbers
    np.testing.assert_allclose(fast.reduced.eigenvalues(b), red.eigenvalues, rtol=1e-10)
    np.testing.assert_allclose(fast.eigenvalues(b), red.eigenvalues, rtol=1e-10)
    np.testing.assert_allclose(
        red.normalised_sensitivities().sum(axis=1), 1.0, rtol=1e-10
    )  # Euler: lambda is homogeneous of degree one in b


def test_models_implement_the_forward_interface(certified):
    _, model, fast = certified
    reduced = fast.reduced
    for m in (model, reduced, fast):
        assert isinstance(m, ForwardModel)
    # the reduced and certified models' mesh and mass are the full model's
    assert reduced.mesh is model.mesh and fast.mesh is model.mesh
    for m in (reduced, fast):
        assert (m.mass != model.mass).nnz == 0
    b = fast.certificate.points[0]
    assert isinstance(reduced.solve(b), Modes) and isinstance(fast.solve(b), Modes)
    # the model of an earlier stage and an enriched one keep the full model
    assert reduced.leading(reduced.levels[-2]).full_model is model
    assert reduced.enrich(model, b[None]).full_model is model


# ----------------------------------------------------------------------------- determinism


def test_same_seed_same_basis_and_certificate():
    model, mean_b, box = _setup("frederiksen_t300")
    kw = dict(n_snapshots=3, n_test=3, max_rounds=1)
    a = fast_model(model, mean_b, box, N_MODES, rng=5, **kw)
    b = fast_model(model, mean_b, box, N_MODES, rng=5, **kw)
    np.testing.assert_array_equal(a.reduced.points, b.reduced.points)
    np.testing.assert_array_equal(a.certificate.points, b.certificate.points)
    assert a.reduced.size == b.reduced.size
    # the eigensolver starts from a random vector: modes agree to its tolerance, and the
    # basis, whose signs are fixed, to that over the compression tolerance
    np.testing.assert_allclose(
        a.reduced.basis, b.reduced.basis, atol=1e-6 * np.abs(a.reduced.basis).max()
    )
    np.testing.assert_allclose(a.certificate.errors, b.certificate.errors, rtol=1e-6, atol=1e-12)
    c = fast_model(model, mean_b, box, N_MODES, rng=6, **kw)
    assert not np.allclose(a.reduced.points[1:], c.reduced.points[1:])


# ----------------------------------------------------------------------------- fallback


def test_uncertified_model_warns_once_and_returns_full_numbers(caplog):
    model, mean_b, box = _setup("frederiksen_t300")
    # three snapshot points and no enrichment: far from the 1e-4 bound
    fast = fast_model(model, mean_b, box, N_MODES, n_snapshots=2, n_test=2, max_rounds=1, rng=3)
    assert isinstance(fast, CertifiedModel) and not fast.certified
    assert fast.certificate.max_rel_error > DEFAULT_TOLERANCE
    b = box.center
    with caplog.at_level(logging.WARNING, logger="bayesplate.reduced"):
        with pytest.warns(ReducedModelWarning, match="not certified"):
            first = fast.solve(b)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no second warning
            second = fast.solve(b)
    assert "not certified" in caplog.text
    assert isinstance(first, ModalResult)
    np.testing.assert_allclose(first.eigenvalues, model.solve(b, N_MODES).eigenvalues, rtol=1e-12)
    np.testing.assert_allclose(second.eigenvalues, first.eigenvalues, rtol=1e-12)
    assert fast.fallbacks["uncertified"] == 2 and fast.n_reduced == 0


def test_points_outside_the_box_fall_back_and_are_counted(certified):
    _, model, fast = certified
    counts = dict(fast.fallbacks)
    outside = 1.5 * fast.box.upper
    with pytest.warns(ReducedModelWarning, match="outside"):
        result = fast.solve(outside)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fast.solve(outside)
    assert isinstance(result, ModalResult)
    # the full model itself agrees with itself to rounding (random Lanczos start)
    np.testing.assert_allclose(
        result.eigenvalues, model.solve(outside, N_MODES).eigenvalues, rtol=1e-12
    )
    assert fast.fallbacks["outside_box"] == counts["outside_box"] + 2
    n = fast.n_reduced
    assert isinstance(fast.solve(fast.box.center), ReducedModalResult)
    assert fast.n_reduced == n + 1


def test_more_modes_than_certified_fall_back(certified):
    _, _, fast = certified
    with pytest.warns(ReducedModelWarning, match="more modes"):
        result = fast.solve(fast.box.center, N_MODES + 2)
    assert isinstance(result, ModalResult) and len(result.eigenvalues) == N_MODES + 2


# ----------------------------------------------------------------------------- full size


@pytest.mark.slow
def test_frederiksen_50x50_build_certify_and_speed(record_property):
    model, mean_b, box = _setup("frederiksen_t300", mesh=(50, 50))
    start = time.perf_counter()
    fast = fast_model(model, mean_b, box, N_MODES, rng=SEED)
    build = time.perf_counter() - start
    b = fast.certificate.points[0]
    start = time.perf_counter()
    model.solve(b, N_MODES)
    full = time.perf_counter() - start
    repeats = 200
    start = time.perf_counter()
    for _ in range(repeats):
        fast.reduced.solve(b)
    reduced = (time.perf_counter() - start) / repeats
    summary = (
        f"50x50: build + certify {build:.1f} s, {fast.certificate}; full solve {full:.2f} s, "
        f"reduced {1e3 * reduced:.3f} ms, ratio {full / reduced:.0f}"
    )
    record_property("frederiksen_50x50", summary)
    print("\n" + summary)
    assert fast.certified
    assert full / reduced > 100


def test_parts_set_aside_before_the_products_change_nothing(monkeypatch):
    # a snapshot's parts in the symmetry classes it does not belong to are rounding noise,
    # set aside by their energy before any product with M or K: the basis spans the same
    # space (same size, the same Ritz values to rounding) as when every part is carried
    # through the projection and dropped after it, with several times fewer columns carried
    from bayesplate.reduced import basis as growth

    model, mean_b, box = _setup("frederiksen_t300", mesh=(12, 6))
    carried = []
    inner = growth._new_directions

    def counted(model, K, V, S, rank_tol):
        carried[-1] += S.shape[1]
        return inner(model, K, V, S, rank_tol)

    monkeypatch.setattr(growth, "_new_directions", counted)
    built = []
    for factor in (growth._UNLIFTABLE, 0.0):  # the default, then every part carried
        monkeypatch.setattr(growth, "_UNLIFTABLE", factor)
        carried.append(0)
        built.append(ReducedModel.build(model, mean_b, box, 10, n_snapshots=4, rng=SEED))
    kept, every = built
    assert kept.size == every.size
    # every class but one of each mode carries noise only
    assert 0 < carried[0] and carried[0] * 3 < carried[1]
    for b in box.sample(5, np.random.default_rng(SEED)):
        np.testing.assert_allclose(kept.eigenvalues(b, 10), every.eigenvalues(b, 10), rtol=1e-9)
