"""studies/calibration.py: the ideal test's power, the size search, the reading of the rows,
and a quick run of the study (issue 13)."""

import numpy as np
import pytest
from scipy.stats import chi2

from tests._studies import load_study

cal = load_study("calibration", "calibration_study")


def test_ideal_power_is_the_rejection_rate_of_simulated_recordings():
    """The noncentral chi-square against the test run on seeded noisy recordings."""
    rng = np.random.default_rng(7)
    f0 = np.linspace(100.0, 1400.0, 14)
    f_effect = f0 * (1 + 0.004 * np.sin(np.arange(14)))  # an effect of a few deviations
    lam = cal.noncentrality(f_effect, f0, noise=0.002)
    n = 20000
    z = rng.standard_normal((n, 14))
    stat = np.sum(((f_effect * (1 + 0.002 * z) - f0) / (0.002 * f0)) ** 2, axis=1)
    rate = np.mean(stat > chi2.ppf(0.99, 14))
    p = cal.ideal_power(lam, 14, alpha=0.01)
    assert 0.2 < p < 0.98  # a size where the comparison means something
    assert abs(rate - p) < 4 * np.sqrt(p * (1 - p) / n)


def test_no_effect_rejects_at_the_significance_level():
    assert cal.ideal_power(0.0, 14, alpha=0.01) == pytest.approx(0.01)
    assert cal.ideal_power(1e-12, 14, alpha=0.01) == pytest.approx(0.01, rel=1e-6)


@pytest.mark.parametrize("power", [0.5, 0.9, 0.99])
def test_the_noncentrality_found_gives_the_power_asked(power):
    lam = cal.noncentrality_for(power, 14)
    assert cal.ideal_power(lam, 14) == pytest.approx(power, abs=1e-9)


def test_size_for_inverts_a_power_law_exactly():
    """lambda = c s^2 is a straight line in log-log: the interpolation is exact on it."""
    grid = np.geomspace(0.01, 3.0, 8)
    lams = 40.0 * grid**2
    for target in (0.5, 7.0, 300.0):
        assert cal.size_for(grid, lams, target) == pytest.approx(np.sqrt(target / 40.0))
    assert cal.size_for(grid, lams, 1e6) is None  # beyond the largest admissible size
    assert cal.size_for(grid, lams, 1e-9) == grid[0]


def test_a_name_counts_when_explained_or_among_the_two_ambiguous_ones():
    row = {"effect": "cutout", "verdict": "explained", "chosen": "cutout", "rival": None}
    assert cal.named(row) and not cal.wrong_name(row)
    row = {**row, "chosen": "local_stiffness_loss"}
    assert not cal.named(row) and cal.wrong_name(row)
    row = {**row, "verdict": "ambiguous", "rival": "cutout"}
    assert cal.named(row) and not cal.wrong_name(row)
    for verdict in ("consistent", "unexplained"):
        row = {**row, "verdict": verdict, "chosen": None, "rival": None}
        assert not cal.named(row) and not cal.wrong_name(row)


def test_coverage_is_judged_at_the_mirror_image_nearest_the_truth():
    row = {"recovered": {"mass_g": [0.31, 0.02], "x_mm": [77.0, 2.0], "y_mm": [14.5, 1.0]},
           "truth": {"mass_g": 0.3, "x_mm": 23.0, "y_mm": 14.0},
           "images": [{"mass_g": 0.31, "x_mm": 23.1, "y_mm": 14.5}]}  # fmt: skip
    assert cal.covered(row) == {"mass_g": True, "x_mm": True, "y_mm": True}
    row["recovered"]["mass_g"] = [0.5, 0.02]  # 10 sd off, at every image
    row["images"][0]["mass_g"] = 0.5
    assert cal.covered(row)["mass_g"] is False
    assert cal.covered({**row, "recovered": None}) == {}


@pytest.mark.slow  # the quick study: 5 diagnoses on 6 x 3 / 8 x 4 meshes, ~45 s on 2 cores
def test_quick_study_runs_and_clean_plates_are_consistent(tmp_path, monkeypatch):
    path = cal.main(tmp_path, quick=True, workers=1)
    text = path.read_text()
    stored = cal.load(tmp_path, True)
    clean = [r for r in stored["rows"].values() if r["kind"] == "clean"]
    assert len(clean) == 4 and all(r["verdict"] == "consistent" for r in clean)
    assert "false alarms: 0 of 4" in text
    (power,) = [r for r in stored["rows"].values() if r["kind"] == "power"]
    # the ideal test's statistic at the true constants, recomputed from its noncentrality's
    # definition: the point mass at the 0.9 size is several deviations away
    assert power["ideal_lambda"] == pytest.approx(cal.noncentrality_for(0.9, 14), rel=0.3)
    assert (tmp_path / "calibration-quick.png").exists()
    monkeypatch.setattr(cal, "run_task", None)  # everything must come from the cache now
    again = cal.main(tmp_path, quick=True, workers=1)
    assert again.read_text().split("\n", 3)[3] == text.split("\n", 3)[3]


def test_what_the_constants_can_mimic_leaves_no_noncentrality():
    """An effect that is a change of the constants (in the span of S) is absorbed entirely;
    one orthogonal to that span keeps all of its noncentrality."""
    rng = np.random.default_rng(3)
    S = rng.standard_normal((14, 6))
    sigma = rng.uniform(0.5, 2.0, 14)
    mimic = S @ rng.standard_normal(6)
    assert cal.fitted_noncentrality(mimic, S, sigma) == pytest.approx(0.0, abs=1e-18)
    A = S / sigma[:, None]
    q, _ = np.linalg.qr(A, mode="complete")
    r = q[:, 6:] @ rng.standard_normal(8)  # whitened, orthogonal to the span of A
    assert cal.fitted_noncentrality(r * sigma, S, sigma) == pytest.approx(np.sum(r**2))
