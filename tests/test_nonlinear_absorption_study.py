"""studies/nonlinear_absorption.py: the exact fit of the constants, and a quick run."""

import json

import numpy as np
import pytest

from bayesplate.laminate import stiffness_from_engineering
from studies import nonlinear_absorption as na

cal, cal_sizes = na.cal, na.cal_sizes


@pytest.fixture(scope="module")
def plate():
    case, _, fine = cal._models(cal.POWER_FAMILY, quick=True)
    return case, fine, stiffness_from_engineering(case.reference)


def test_an_effect_that_is_a_change_of_the_constants_is_absorbed_whole(plate):
    # a plate whose shear modulus G12 is 8 % higher is no effect at all once the constants are
    # fitted: the exact fit leaves nothing and finds the 8 % (closed form: lambda(b) itself)
    case, fine, b = plate
    m = case.measured.size
    moved = b * np.array([1.0, 1.0, 1.0, 1.08, 1.0, 1.0])
    lam = fine.solve(moved, m).eigenvalues
    sigma = 2.0 * cal.NOISE * fine.solve(b, m).eigenvalues
    chi2, prior_term, fitted, *_ = na.exact_fit(fine, b, lam, sigma)
    assert chi2 < 1e-10 and prior_term == 0.0
    np.testing.assert_allclose(fitted, moved, rtol=1e-6)


def test_a_stiffer_plate_all_round_is_absorbed_and_the_prior_pulls_back(plate):
    # every eigenvalue is linear in a common factor of the stiffnesses: 5 % stiffer all round
    # is absorbed whole without a prior; the prior (its mean below the truth) holds the fit
    # back, leaving a chi-square, and its own term is the Gaussian's at the fitted constants
    case, fine, b = plate
    m = case.measured.size
    lam = 1.05 * fine.solve(b, m).eigenvalues
    sigma = 2.0 * cal.NOISE * lam
    chi2, _, fitted, *_ = na.exact_fit(fine, b, lam, sigma)
    assert chi2 < 1e-10
    np.testing.assert_allclose(fitted / b, 1.05, rtol=1e-6)
    prior = (np.asarray(case.prior.mean, float), np.asarray(case.prior.sd, float))
    chi2_p, term, fitted_p, *_ = na.exact_fit(fine, b, lam, sigma, prior)
    e = na.engineering_from_stiffness(fitted_p)
    assert chi2_p > 1e-6 and term == pytest.approx(np.sum(((e - prior[0]) / prior[1]) ** 2))


def _a_fit(m, chi2, seed):
    """A made-up exact fit without a prior: a Jacobian (m, 6) and a residual orthogonal to
    its columns with the given chi-square (what a fit leaves at its optimum)."""
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((m, 6))
    r = rng.standard_normal(m)
    r -= J @ np.linalg.lstsq(J, r, rcond=None)[0]
    r *= np.sqrt(chi2) / np.linalg.norm(r)
    return na.Exact(chi2, 0.0, np.ones(6), r, J)


@pytest.mark.parametrize("chi2", [0.0, 8.0, 25.0])
def test_recorded_noise_power_is_the_noncentral_chi_square_without_widening(chi2):
    # w = 1, no prior: the fitted test's chi-square is ncx2(m - 6, chi2) (closed form)
    m = 14
    fit = _a_fit(m, chi2, 1)
    got = cal_sizes.recorded_noise_power(
        fit.residual, fit.jacobian, np.ones(m), m - 6, np.random.default_rng(2)
    )
    want = cal.ideal_power(chi2, m - 6) if chi2 > 0 else cal.ALPHA
    assert got == pytest.approx(want, abs=0.004)  # 3.5 standard errors of 200 000 draws


def test_recorded_noise_power_under_a_uniform_widening_is_the_scaled_noncentral_tail():
    # w_i = w: the statistic is ncx2(m - 6, w^2 chi2) / w^2 (closed form), less powerful
    # than the noncentral chi-square at the widened noncentrality the naive reading takes
    from scipy.stats import chi2 as chi2_dist
    from scipy.stats import ncx2

    m, w, chi2 = 14, 1.33, 12.0
    fit = _a_fit(m, chi2, 3)
    got = cal_sizes.recorded_noise_power(
        fit.residual, fit.jacobian, np.full(m, w), m - 6, np.random.default_rng(4)
    )
    crit = chi2_dist.ppf(1 - cal.ALPHA, m - 6)
    want = ncx2.sf(w**2 * crit, m - 6, w**2 * chi2)
    assert got == pytest.approx(want, abs=0.004)
    assert want < cal.ideal_power(chi2, m - 6) - 0.1


def test_effective_dof_is_m_minus_6_without_a_prior_and_more_with_one():
    # without a prior every constant is the data's (p_eff = 6); a prior row on each takes
    # a share, and a prior far tighter than the data takes nearly all of it (p_eff -> 0)
    m = 14
    fitted = _a_fit(m, 5.0, 5)
    assert na.effective_dof(fitted, m) == pytest.approx(m - 6, abs=1e-12)
    for scale, low, high in ((1.0, m - 6, m), (1e4, m - 1e-3, m)):
        J = np.vstack([fitted.jacobian, scale * np.eye(6)])
        held = fitted._replace(jacobian=J, residual=np.r_[fitted.residual, np.zeros(6)])
        assert low < na.effective_dof(held, m) < high


def test_diagnoses_read_per_size_median_widening_and_nominal_rejections():
    rows = [
        {"effect": "cutout", "size": 6.2, "widening": [1.0, 2.0], "p_value": 0.001},
        {"effect": "cutout", "size": 6.2, "widening": [1.2, 3.0], "p_value": 0.2},
        {"effect": "cutout", "size": 6.2, "widening": [1.4, 1.0], "p_value": 0.005},
        {"effect": "cutout", "size": 13.0, "widening": [9.0, 9.0], "p_value": 0.0},
        {"effect": "cutout", "size": 6.2, "p_value": 0.0},  # no widening kept: not read
    ]
    widening, rejected, n = na.diagnosed(rows, "cutout", 6.2)
    np.testing.assert_allclose(widening, [1.2, 2.0])
    assert (rejected, n) == (2, 3)
    assert na.diagnosed(rows, "point_mass", 0.17) == (None, 0, 0)


def test_quick_run_writes_its_report(tmp_path):
    # a calibration cache whose replicates were not widened: the figures at diagnose's
    # deviations are then those at the declared ones
    table = cal.sizes(quick=True)
    m = cal_sizes._case(cal.POWER_FAMILY).measured.size
    rows = {
        f"r{j}": {"effect": "point_mass", "size": size, "widening": [1.0] * m, "p_value": 0.5}
        for j, size in enumerate(table["point_mass"]["sizes"])
    }
    cal.save(tmp_path, True, {"sizes": table, "rows": rows})  # this code version's rows
    path = na.main(out_dir=tmp_path, quick=True)
    stored = json.loads((tmp_path / ".cache" / "quick_nonlinear_absorption.json").read_text())
    for r in stored["rows"]:
        assert r["widened_linearised"] == pytest.approx(r["linearised"], rel=1e-12)
        assert r["widened_exact"] == pytest.approx(r["prior_chi2"], rel=1e-6)
        assert (r["rejected"], r["replicates"]) == (0, 1)
        # the working mesh (half as fine) is diagnose's: its own dof, a power in [0, 1]
        assert m - 6 < r["working_dof"] < m and 0.0 <= r["working_power"] <= 1.0
        assert 0.0 <= r["recorded_noise_power"] <= 1.0
    text = path.read_text()
    assert "| point_mass | " in text and "(fitted 0.9)" in text and "(3 x ideal 0.9)" in text
    row = next(line for line in text.splitlines() if "(3 x ideal 0.9)" in line)
    ideal, linearised, exact = (float(row.split("|")[k]) for k in (3, 4, 5))
    # the constants absorb much of a point mass and no more than all of it
    assert 0.0 < exact < ideal and 0.0 < linearised < ideal
