"""The global fitted test (``studies/fitted_test.py``): its fit, and a regression run."""

import json

import numpy as np
import pytest

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
    row = ft.fitted_test(f, 0.002 * f, fine, b, prior, draws=1, rng=0)
    assert row["at_truth"] < 1e-12 and row["chi2"] < 1e-8
    np.testing.assert_allclose(row["ratios"][:4], 1.0, atol=1e-4)  # the well-felt ones
    assert row["dof"] == 8 and len(row["by_start"]) == 2 + len(ft.SHEAR_GRID) + 1
    assert row["kinds"][:3] == ["truth", "prior mean", "shear"] and row["kinds"][-1] == "draw"


def test_the_aimed_starts_scale_the_shear_coefficients_alone():
    b = np.arange(1.0, 7.0)
    prior = (b * 1.1, np.diag((0.1 * b) ** 2))
    points = ft.starts(b, prior, draws=2, rng=0)
    shear = [np.exp(z) for z, kind in points if kind == "shear"]
    assert len(shear) == 8 and {(round(x[4], 6), round(x[5], 6)) for x in shear} == set(
        ft.SHEAR_GRID
    )
    assert all(np.allclose(x[:4], 1.0) for x in shear)
    np.testing.assert_allclose(np.exp(points[1][0]), 1.1)  # the prior mean
    # the same seed, the same draws
    again = ft.starts(b, prior, draws=2, rng=0)
    assert all(np.array_equal(z, w) for (z, _), (w, _) in zip(points, again, strict=True))


def test_the_best_optimum_is_no_worse_than_the_start_at_the_truth_and_rows_resume(tmp_path):
    rows = ft.main("ply_misalignment", 0.64, [0], draws=0, out_dir=tmp_path, quick=True)
    row = rows[0]
    assert row["chi2"] == min(row["by_start"]) <= row["by_start"][0] <= row["at_truth"]
    text = (tmp_path / "fitted_test.md").read_text()
    assert "ply_misalignment at 0.64" in text and f"| 0 | {row['at_truth']:.1f} |" in text
    assert "Rejected by the fitted test: **" in text
    # a second run reads the cached row, it does not fit again
    cache = next((tmp_path / ".cache" / "fitted_test").glob("*.jsonl"))
    assert len(cache.read_text().splitlines()) == 1
    again = ft.main("ply_misalignment", 0.64, [0], draws=0, out_dir=tmp_path, quick=True)
    assert again == [json.loads(cache.read_text())]
    # the row names the code that computed it, and its size's heading says it
    assert row["code"] == cache.stem and f"computed by code {cache.stem})" in text


def test_diagnose_beside_the_test_sees_the_recordings_the_test_fitted():
    # replicate() hands its recordings to run_task; run_task on its own makes them again
    row = ft.replicate("ply_misalignment", 0.64, 0, 0, quick=True, diagnose=True)
    task = ("power", ft.FAMILY, "ply_misalignment", "fitted 0.9", 0.64, 0)
    alone = cal.run_task(task, quick=True)
    said = row["diagnose"]
    assert (said["verdict"], said["chosen"], said["p_value"]) == (
        alone["verdict"],
        alone["chosen"],
        alone["p_value"],
    )


def test_another_mesh_error_rule_diagnoses_alone_in_a_column_of_its_own(tmp_path):
    # the test's row first (diagnose under the default rule beside it), then the same
    # replicate under another rule alone: no fit of the test again, a column of its own
    other = "whole" if cal.DEFAULT_RULE == "corrected" else "corrected"
    ft.main("ply_misalignment", 0.64, [0], draws=0, out_dir=tmp_path, quick=True, diagnose=True)
    rows = ft.main("ply_misalignment", 0.64, [0], out_dir=tmp_path, quick=True, rule=other)
    task = ("power", ft.FAMILY, "ply_misalignment", "fitted 0.9", 0.64, 0)
    alone = cal.run_task(task, quick=True, options={"mesh_error_part": other})
    said = rows[0]["diagnose"]
    assert rows[0]["rule"] == other
    # the row was made in a forked worker at one BLAS thread: the same to round-off
    assert said["verdict"] == alone["verdict"]
    assert said["p_value"] == pytest.approx(alone["p_value"], rel=1e-9)
    cache = tmp_path / ".cache" / "fitted_test"
    assert [len(p.read_text().splitlines()) for p in sorted(cache.glob("*.jsonl"))] == [1, 1]
    text = (tmp_path / "fitted_test.md").read_text()
    assert f"diagnose, `{other}` rule |" in text
    assert f"named by diagnose under the `{other}` rule: **" in text
    # run again: read from the cache, not diagnosed again
    again = ft.main("ply_misalignment", 0.64, [0], out_dir=tmp_path, quick=True, rule=other)
    assert again == rows


def _said(verdict, chosen, rule, seconds, rival=None):
    """A diagnose verdict as a row holds it; *named* when it names the point mass."""
    named = chosen == "point_mass" or rival == "point_mass"
    return {
        "verdict": verdict,
        "chosen": chosen,
        "rival": rival,
        "also": [],
        "p_value": 0.01,
        "seconds": seconds,
        "named": named,
        "rule": rule,
    }


def test_the_power_table_counts_each_rule_and_the_reading_is_kept(tmp_path):
    # three replicates by hand: the test rejects two; under `whole` one named, one explained
    # by a delamination (a name without the truth), one consistent; under `corrected` alone
    ps = (0.001, 0.5, 0.002)
    whole = (
        _said("explained", "point_mass", "whole", 10.0),
        _said("explained", "delamination", "whole", 30.0),
        _said("consistent", None, "whole", 20.0),
    )
    rows = [
        {
            "effect": "point_mass",
            "size": 0.24,
            "draws": 4,
            "rep": k,
            "p": p,
            "at_truth": 100.0,
            "by_start": [50.0, 60.0],
            "chi2": 40.0,
            "best_kind": "shear",
            "ratios": [1.0] * 6,
            "seconds": 300.0,
            "code": "abc",
            "diagnose": d,
        }
        for k, (p, d) in enumerate(zip(ps, whole, strict=True))
    ]
    ruled = [
        {"effect": "point_mass", "size": 0.24, "rep": 1, "rule": "corrected", "code": "abc"}
        | {"diagnose": _said("ambiguous", "delamination", "corrected", 50.0, "point_mass")}
    ]
    path = ft.write_report(tmp_path, rows, "abc", ruled)
    text = path.read_text()
    assert "| point_mass | 0.24 g | 2 of 3 | 1 of 1 + 0 (50 s) | 1 of 3 + 1 (20 s) |\n" in text
    # a reading written below the tables is kept when they are written again, once
    reading = "\n## What it shows\n\n- read by hand\n"
    path.write_text(text + reading)
    ft.write_report(tmp_path, rows, "abc", ruled)
    again = path.read_text()
    assert again.count("## What it shows") == 1 and again.endswith(reading)
    # another name keeps its own report, and says how it was made
    other = ft.write_report(tmp_path, rows, "abc", ruled, name="fitted_test_other")
    assert other.name == "fitted_test_other.md" and path.read_text() == again
    assert "--diagnose --report fitted_test_other`" in other.read_text()
