"""Mode pairing and MAC tracking."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bayesplate.io import bundled_case_path, load_case
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.matching.pairing import (
    Pairing,
    assign_by_mac,
    mac_matrix,
    pair_by_index,
    pair_by_order,
    track,
)
from bayesplate.plate.model import PlateModel


@pytest.fixture(scope="module")
def plate1():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    return model, model.solve(stiffness_from_engineering(case.reference), 14)


def test_mac_of_identical_mode_sets_is_identity(plate1):
    # Mass-normalised modes are M-orthonormal: the mass-weighted MAC is exactly I (to the
    # eigen-solver's orthogonality, ~1e-12).
    model, modal = plate1
    mac = mac_matrix(modal.vectors, modal.vectors, model.mass)
    np.testing.assert_allclose(mac, np.eye(14), atol=1e-10)


def test_plain_mac_of_orthonormal_columns_is_identity():
    q, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(30, 5)))
    np.testing.assert_allclose(mac_matrix(q, q), np.eye(5), atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.floats(-1e6, 1e6).filter(lambda s: abs(s) > 1e-6))
def test_mac_ignores_scale_and_sign(scale):
    v = np.random.default_rng(1).normal(size=(10, 3))
    np.testing.assert_allclose(mac_matrix(v, scale * v), mac_matrix(v, v), rtol=1e-9)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(1e-16, 1e-7))
def test_mac_against_round_off_is_zero_whatever_its_direction(seed, level):
    # w of an in-plane mode is zero in exact arithmetic and ~1e-11 of a bending mode's in a
    # solver's output: its direction is round-off, so its MAC must not depend on it (a
    # different BLAS kernel gives another direction; issue: the shape-pairing test flipped
    # between CPUs). Exactly 0, for any direction, below the negligible level.
    rng = np.random.default_rng(seed)
    good = rng.normal(size=(28, 4))
    noise = level * rng.normal(size=(28, 2))
    mac = mac_matrix(good, np.hstack([good, noise]))
    np.testing.assert_array_equal(mac[:, 4:], 0.0)
    np.testing.assert_allclose(np.diag(mac[:, :4]), 1.0, rtol=1e-12)
    # and on the other side: a measured shape that is only round-off matches nothing
    np.testing.assert_array_equal(mac_matrix(np.hstack([good, noise]), good)[4:], 0.0)


def test_mac_keeps_a_small_but_real_shape():
    # Scale is irrelevant to the MAC: a real shape 1e-5 the size of the others is kept.
    v = np.random.default_rng(3).normal(size=(20, 3))
    v[:, 2] *= 1e-5
    np.testing.assert_allclose(np.diag(mac_matrix(v, v)), 1.0, rtol=1e-12)


def test_track_detects_a_swapped_pair(plate1):
    model, modal = plate1
    swapped = modal.vectors.copy()
    swapped[:, [3, 4]] = swapped[:, [4, 3]]
    new, mac = track(modal.vectors, swapped, np.arange(14), model.mass)
    expected = np.arange(14)
    expected[[3, 4]] = [4, 3]
    np.testing.assert_array_equal(new, expected)
    np.testing.assert_allclose(mac, 1.0, atol=1e-10)


def test_track_follows_modes_between_nearby_iterates(plate1):
    # A 1 % change of the constants moves the shapes little: every mode keeps its place.
    model, modal = plate1
    near = model.solve(modal.b * 1.01, 14)
    new, mac = track(modal.vectors, near.vectors, np.arange(14), model.mass)
    np.testing.assert_array_equal(new, np.arange(14))
    assert np.all(mac > 0.99)


def test_assign_by_mac_threshold_and_one_to_one():
    mac = np.array([[0.9, 0.8, 0.0], [0.95, 0.1, 0.0], [0.1, 0.2, 0.3]])
    # Hungarian: row 1 takes column 0 (0.95), row 0 column 1 (0.8): total 1.75 > 0.9 + 0.1
    np.testing.assert_array_equal(assign_by_mac(mac), [1, 0, 2])
    np.testing.assert_array_equal(assign_by_mac(mac, threshold=0.5), [1, 0, -1])


def test_pair_by_order_and_index():
    np.testing.assert_array_equal(pair_by_order(3), [0, 1, 2])
    np.testing.assert_array_equal(pair_by_index([1, 3, 4]), [0, 2, 3])
    with pytest.raises(ValueError):
        pair_by_index([0, 1])


def test_pairing_from_measurement_uses_mode_indices():
    case = load_case(bundled_case_path("plate1"))
    measured = case.with_measured(mode=np.arange(14) + 2).measured
    pairing = Pairing.from_measurement(measured)
    assert pairing.how == "index"
    np.testing.assert_array_equal(pairing.modes, np.arange(1, 15))
    assert pairing.n_modes() == 15 + pairing.extra
    assert Pairing.from_measurement(measured, "order").how == "order"
    with pytest.raises(ValueError, match="needs measured.mode"):
        Pairing.from_measurement(case.measured, "index")
