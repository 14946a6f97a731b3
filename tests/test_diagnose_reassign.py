"""diagnose makes the assignment again at the fit its verdict rests on (discrepancy/reassign.py)."""

import numpy as np
import pytest

from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
from bayesplate.discrepancy import PointMass
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.discrepancy.search.reassign import assignment_log_prior, full_modes, pairing_of
from bayesplate.matching.assignment import P_SPURIOUS, P_UNOBSERVED, assign
from bayesplate.matching.pairing import Pairing
from bayesplate.quantities import eigenvalue_from_hz

MESH = (12, 6)
NOISE = 0.002


def test_the_assignment_terms_are_those_of_the_assignment_model():
    # assignment.py's log P(a) less its pairs' Gaussian densities (in Hz), plus the spurious
    # peaks' uniform density moved from Hz to eigenvalues: the terms written out by hand
    f = np.array([100.0, 210.0, 260.0, 400.0])
    s = 0.01 * f
    c = np.array([99.0, 150.0, 209.0, 330.0, 401.0, 500.0])
    a = assign(f, s, c)
    # modes 2 and 4 (150, 330 Hz) unseen, 260 Hz spurious; mode 5 (401 Hz) is paired but
    # above the band (the highest peak), where a mode is neither observed nor unobserved
    np.testing.assert_array_equal(a.modes, [0, 2, -1, 4])
    gauss = sum(
        -0.5 * ((f[i] - c[j]) ** 2 / s[i] ** 2 + np.log(2 * np.pi * s[i] ** 2))
        for i, j in enumerate(a.modes)
        if j >= 0
    )
    here = assignment_log_prior(a.modes, c, a.band_Hz, measured_Hz=f)
    spurious = np.log(P_SPURIOUS) - np.log(eigenvalue_from_hz(a.band_Hz))  # one, over [0, B]
    by_hand = (
        3 * np.log(1 - P_SPURIOUS)
        + spurious
        + 2 * np.log(1 - P_UNOBSERVED)
        + 2 * np.log(P_UNOBSERVED)
    )
    assert here == pytest.approx(by_hand, rel=1e-12)
    in_hz = np.log(a.band_Hz) - np.log(eigenvalue_from_hz(a.band_Hz))  # the one Hz term
    assert a.log_probability == pytest.approx(gauss + here - in_hz, rel=1e-12)


def test_full_modes_and_pairing_of_are_inverse():
    a = assign(
        np.array([100.0, 210.0, 400.0]),
        np.array([1.0, 2.1, 4.0]),
        np.array([99.0, 150.0, 209.0, 330.0, 401.0]),
    )
    p = pairing_of(a, "likelihood")
    np.testing.assert_array_equal(full_modes(p, 3), a.modes)
    assert p.assignment is a and p.how == "likelihood"


def _missing_mode_case():
    """Plate 1 recorded (0.2 % noise) with computed mode 3 not seen.

    Recorded on diagnose's own mesh: this is a test of the assignment, and a coarse mesh's
    own error (widened into the deviations) would blur it.
    """
    case = load_case(bundled_case_path("plate1"))
    off = np.array([1.05, 0.95, 1.05, 1.05, 0.95, 1.05])
    case = case.with_prior(
        case.reference * off, case.reference * np.array([0.15, 0.15, 0.2, 0.15, 0.3, 0.3])
    )
    fine = PlateModel.from_case(case, mesh=MESH)
    f = fine.solve(stiffness_from_engineering(case.reference), 11).frequency_Hz
    f = np.delete(f * (1 + NOISE * np.random.default_rng(3).standard_normal(f.size)), 2)
    return case.with_measured(frequency_Hz=f, sigma_Hz=NOISE * f)


def test_a_wrong_assignment_is_made_again_and_the_second_pass_kept():
    # the test missed mode 3; an assignment "by order" (marked as an assignment, as one
    # settled under a wrong model would be) shifts every pair above it. Made again at each
    # verdict's fit (at most three passes) it comes to skip mode 3; that pass is consistent
    # and explains all peaks far better, so it is kept
    case = _missing_mode_case()
    model = PlateModel.from_case(case, mesh=MESH)
    m = case.measured.size
    wrong = assign(
        case.measured.frequency_Hz, case.measured.sigma_Hz, case.measured.frequency_Hz
    )  # every peak on "its" mode, in order
    np.testing.assert_array_equal(wrong.modes, np.arange(m))
    said = []
    d = diagnose(
        case,
        model=model,
        rng=0,
        n_starts=2,
        physics=[PointMass()],
        pairing=Pairing(np.arange(m), how="likelihood", assignment=wrong),
        progress=said.append,
    )
    truth = np.array([0, 1, *range(3, m + 1)])  # peak 3 is computed mode 4, and so on
    np.testing.assert_array_equal(d.peak_modes, truth)
    assert d.verdict == "consistent"
    assert any("diagnosing again" in line for line in said)
    note = next(n for n in d.notes if n.startswith("assignment made again"))
    # the first pass's fit, pulled by the shifted pairs, moves peaks 4-9 first; a second
    # pass lets go of peak 3 too; every pass is scored and the best kept
    assert "pass 1 (unexplained)" in note and "pass 2 (" in note and "kept" in note


def test_by_default_a_missed_mode_sets_the_order_aside_and_is_found_by_likelihood():
    # the default pairing (by order, checked): a first pass by order; the assignment made
    # again at its verdict's fit pairs peaks with other modes (mode 3 was missed), so the
    # next pass takes the assignment B settles (mode 3 unobserved), which scores higher on
    # every peak's evidence and is kept: the verdict and peaks of --pairing likelihood
    case = _missing_mode_case()
    model = PlateModel.from_case(case, mesh=MESH)
    said = []
    d = diagnose(case, model=model, rng=0, n_starts=1, physics=[PointMass()], progress=said.append)
    np.testing.assert_array_equal(d.peak_modes, [0, 1, *range(3, case.measured.size + 1)])
    assert d.verdict == "consistent"
    note = next(n for n in d.notes if n.startswith("pairing by order set aside"))
    assert "peak 4: mode 4 -> mode 5" in note and "2 passes in all" in note and d.passes == 2
    assert "pass 1 (unexplained)" in note and "pass 2 kept" in note
    assert any(line.endswith("diagnosing again by likelihood") for line in said)
    by_likelihood = diagnose(
        case, model=model, rng=0, n_starts=1, physics=[PointMass()], pairing="likelihood"
    )
    assert d.nominal.chi2 == by_likelihood.nominal.chi2


def test_by_default_a_complete_test_on_a_coarse_mesh_keeps_its_order_in_one_pass():
    # a complete test on the 12 x 6 mesh, whose error in the upper modes is several of the
    # 0.2 % deviations: assigned with the raw deviations the upper peaks would look spurious;
    # with the deviations the pass fitted (widened by the mesh's error) the order stands
    truth = load_case(bundled_case_path("plate1"))
    case = truth.with_prior(
        truth.reference * np.array([1.1, 0.9, 1.1, 1.1, 0.9, 1.1]),
        truth.reference * np.array([0.15, 0.15, 0.2, 0.15, 0.3, 0.3]),
    )
    fine = PlateModel.from_case(case, mesh=(2 * MESH[0], 2 * MESH[1]))
    f = fine.solve(stiffness_from_engineering(case.reference), 14).frequency_Hz
    f = f * (1 + NOISE * np.random.default_rng(1).standard_normal(f.size))
    case = case.with_measured(frequency_Hz=f, sigma_Hz=NOISE * f)
    model = PlateModel.from_case(case, mesh=MESH)
    d = diagnose(case, model=model, rng=0, n_starts=1, physics=[PointMass()])
    assert any("mesh" in n for n in d.notes)  # the deviations were widened
    np.testing.assert_array_equal(d.peak_modes, np.arange(14))
    assert any(n.endswith("the most probable one is the one used") for n in d.notes)
    assert d.verdict == "consistent"


def test_an_assignment_by_order_is_kept_as_asked():
    case = _missing_mode_case()
    model = PlateModel.from_case(case, mesh=MESH)
    d = diagnose(case, model=model, rng=0, n_starts=1, physics=[PointMass()], pairing="order")
    assert d.peak_modes is None and not any("assignment made again" in n for n in d.notes)


def test_a_missed_mode_settled_by_likelihood_is_checked_and_kept():
    # the usual path: B settles the assignment (mode 3 unobserved); made again at the
    # verdict's fit it is the same, so one pass, and the note says it was checked
    case = _missing_mode_case()
    model = PlateModel.from_case(case, mesh=MESH)
    d = diagnose(case, model=model, rng=0, n_starts=1, physics=[PointMass()], pairing="likelihood")
    np.testing.assert_array_equal(d.peak_modes, [0, 1, *range(3, case.measured.size + 1)])
    assert d.verdict == "consistent"
    assert any(n.endswith("the most probable one is the one used") for n in d.notes)
