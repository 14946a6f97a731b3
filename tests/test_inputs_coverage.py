"""The coverage study of uncertain inputs (studies/input_coverage.py) in quick mode."""

import numpy as np
import pytest
from scipy import stats

from studies import input_coverage


@pytest.fixture(scope="module")
def study():
    return input_coverage


def test_quick_report(study, tmp_path):
    path = study.main(tmp_path, quick=True)
    text = path.read_text()
    made = text.split("\n\n")[1]
    assert made.startswith("Made by `python -m studies.input_coverage --quick`")
    assert "| marginal | 6 (0) |" in text and "| exact | 6 (0) |" in text


def test_marginal_intervals_hold_the_input_errors(study):
    # the same replicate fitted both ways: the marginal interval of a bending modulus is
    # wider by about sqrt(1 + (2 sd_h/h)^2 / s^2 + ...) with s the frequency-only deviation
    # (~1 %): at least twice as wide; nu12 barely moves (a ratio of moduli)
    rng = np.random.default_rng(3)
    model = None
    for stream in rng.spawn(2):
        case, h, rho = study.draw(stream)
        model = model or study.PlateModel.from_case(case, mesh=study.MESH)
        lo_m, hi_m = study.fit_b(case, model, "marginal")
        lo_e, hi_e = study.fit_b(case, model, "exact")
        ratio = (hi_m - lo_m) / (hi_e - lo_e)
        assert np.all(ratio[[0, 1, 3]] > 2.0)
        assert ratio[2] < 1.3


def test_binomial_bands_against_scipy(study):
    covering = [np.arange(6) < k for k in range(6)] * 30 + [None, None]  # 180 used, 2 failed
    n, failed, p, wilson = study.summary(covering)
    assert (n, failed) == (180, 2)
    for j in range(6):
        k = int(round(p[j] * n))
        ci = stats.binomtest(k, n).proportion_ci(0.95, method="wilson")
        np.testing.assert_allclose(wilson[:, j], [ci.low, ci.high], rtol=1e-12, atol=1e-15)
    lo, hi = study.nominal_band(200)
    assert lo == pytest.approx(0.94 - 1.96 * np.sqrt(0.94 * 0.06 / 200), abs=1e-4)
    assert hi == pytest.approx(0.94 + 1.96 * np.sqrt(0.94 * 0.06 / 200), abs=1e-4)
