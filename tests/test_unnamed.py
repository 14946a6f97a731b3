"""The unnamed local change, the rival every named candidate must beat (search/unnamed.py)."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
from bayesplate.discrepancy.search.unnamed import (
    GROUPS,
    SCALES,
    field_columns,
    field_gain,
    regions,
    window_gains,
    windows,
)

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


@pytest.fixture(scope="module")
def plate():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case, mesh=(12, 6))
    b = stiffness_from_engineering(case.reference)
    return model, b, model.solve(b, 10)


def test_field_gain_is_the_ratio_of_the_two_gaussian_marginals(rng):
    # the reference: both marginal densities of r0 evaluated directly, with and without the
    # field, as scipy's multivariate normal (no Woodbury, no Cholesky of ours)
    m, n = 9, 14
    J, G = rng.standard_normal((m, 6)), rng.standard_normal((m, n))
    r0 = J @ rng.standard_normal(6) + G @ (0.2 * rng.standard_normal(n)) + rng.standard_normal(m)
    gains, means = field_gain(r0, J, G, scales=(0.05, 0.2, 1.0))
    base = np.eye(m) + J @ J.T
    for tau, gain, w in zip((0.05, 0.2, 1.0), gains, means, strict=True):
        with_field = base + tau**2 * G @ G.T
        expected = multivariate_normal(np.zeros(m), with_field).logpdf(r0) - multivariate_normal(
            np.zeros(m), base
        ).logpdf(r0)
        assert gain == pytest.approx(expected, abs=1e-9)
        # the posterior mean of the field, E[w | r0] = tau^2 G^T (base + tau^2 G G^T)^-1 r0
        assert np.allclose(w, tau**2 * G.T @ np.linalg.solve(with_field, r0), atol=1e-10)


def test_a_field_the_data_cannot_see_gains_nothing(rng):
    m = 8
    J = rng.standard_normal((m, 6))
    gains, _ = field_gain(rng.standard_normal(m), J, np.zeros((m, 5)))
    assert np.allclose(gains, 0.0)


def test_regions_tile_the_plate(plate):
    model, _, _ = plate
    label, (edges_x, edges_y) = regions(model.mesh)
    # plate 1 is 200 x 100 mm: four regions along y, eight along x, each element in one
    assert edges_x.size == 9 and edges_y.size == 5
    assert edges_x[-1] == pytest.approx(200.0) and edges_y[-1] == pytest.approx(100.0)
    x, y = 1e3 * model.mesh.centroids.T
    ix, iy = label % 8, label // 8
    assert np.all((edges_x[ix] < x) & (x < edges_x[ix + 1]))
    assert np.all((edges_y[iy] < y) & (y < edges_y[iy + 1]))


def test_windows_are_every_rectangle_of_up_to_three_regions():
    members, corners = windows(8, 4)
    # (8 + 7 + 6) places along x times (4 + 3 + 2) along y
    assert len(members) == 21 * 9
    sizes = (corners[:, 1] - corners[:, 0]) * (corners[:, 3] - corners[:, 2])
    assert np.array_equal(members.sum(axis=1), sizes)
    assert len({tuple(m) for m in members}) == len(members)


def test_a_windows_gain_is_the_gain_of_its_summed_columns(rng):
    m, n_regions = 10, 6
    J = rng.standard_normal((m, 6))
    columns = rng.standard_normal((m, n_regions, 3))
    r0 = rng.standard_normal(m) + columns[:, 2] @ np.array([0.3, -0.2, 0.5])
    members, _ = windows(3, 2)
    gains, means = window_gains(r0, J, columns, members, scales=(0.1, 1.0))
    for k in (0, 4, len(members) - 1):
        G = columns[:, members[k] > 0].sum(axis=1)
        expected, expected_mean = field_gain(r0, J, G, scales=(0.1, 1.0))
        assert np.allclose(gains[:, k], expected, atol=1e-10)
        assert np.allclose(means[:, k], expected_mean, atol=1e-10)


@pytest.mark.parametrize("group", range(3))
def test_field_columns_are_the_derivatives_of_the_eigenvalues(plate, group):
    # the reference: the eigenvalues of the plate re-solved with one region's stiffness group
    # (or mass) scaled by 1 +- h, central differences
    model, b, modal = plate
    label, (edges_x, edges_y) = regions(model.mesh)
    columns = field_columns(model, modal, b, label, (edges_x.size - 1) * (edges_y.size - 1))
    region = 9
    inside = np.flatnonzero(label == region)
    weights = {0: [1, 1, 1, 1, 0, 0], 1: [0, 0, 0, 0, 1, 1], 2: [0] * 6}[group]

    def eigenvalues(h):
        terms = model.element_stiffness_terms()
        extra = [
            model.assembler.element_data(inside, np.repeat(Ke[None], inside.size, 0))
            for Ke in terms
        ]
        stiffness = model.stiffness_terms + h * np.array(weights)[:, None] * np.array(extra)
        mass = model.mass_data
        if group == 2:
            element = np.repeat(model.element_mass()[None], inside.size, 0)
            mass = mass + h * model.assembler.element_data(inside, element)
        return model.modified(stiffness_terms=stiffness, mass_data=mass).solve(b, 10).eigenvalues

    h = 1e-5
    fd = (eigenvalues(h) - eigenvalues(-h)) / (2 * h)
    got = columns[:, region, group]
    assert GROUPS[group] in ("stiffness", "shear stiffness", "mass")
    assert np.allclose(got, fd, rtol=1e-5, atol=1e-7 * np.abs(modal.eigenvalues).max())


def test_the_scales_span_small_to_whole_changes():
    assert SCALES[0] <= 0.05 and SCALES[-1] >= 0.5
