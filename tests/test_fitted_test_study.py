"""The global fitted test (``studies/fitted_test.py``): its fit, and a regression run."""

import numpy as np

from bayesplate import stiffness_from_engineering
from bayesplate.likelihood.posterior import prior_in_stiffness
from studies import calibration as cal
from studies import fitted_test as ft


def test_recordings_of_the_model_itself_are_fitted_exactly():
    # noise-free frequencies of the nominal model at the true constants: chi-square 0
    case, _, fine = cal._models(ft.FAMILY, True)
    b = stiffness_from_engineering(case.reference)
    prior = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    f = fine.solve(b, 14).frequency_Hz
    row = ft.fitted_test(f, 0.002 * f, fine, b, prior, starts=1, rng=0)
    assert row["at_truth"] < 1e-12 and row["chi2"] < 1e-8
    np.testing.assert_allclose(row["ratios"][:4], 1.0, atol=1e-4)  # the well-felt ones
    assert row["dof"] == 8 and len(row["by_start"]) == 3


def test_the_best_optimum_is_no_worse_than_the_start_at_the_truth_and_is_reported(tmp_path):
    rows = ft.main("ply_misalignment", 0.64, [0], starts=2, out_dir=tmp_path, quick=True)
    row = rows[0]
    assert row["chi2"] == min(row["by_start"]) <= row["by_start"][0] <= row["at_truth"]
    text = (tmp_path / "fitted_test.md").read_text()
    assert "ply_misalignment at 0.64" in text and f"| 0 | {row['at_truth']:.1f} |" in text
