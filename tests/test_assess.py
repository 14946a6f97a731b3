"""Every estimate states its fit and says when it should not be trusted (issue 37, items 3-4).

References: the chi-square is ``r^T V^-1 r`` formed here directly, the p-value
:func:`scipy.stats.chi2.sf`, the effective number of constants the trace formula with
explicit inverses; the synthetic cases are Plate 1's model at its reference constants.
"""

import dataclasses
import json
import re

import numpy as np
import pytest
from scipy import stats

from bayesplate.cli.main import main as cli_main
from bayesplate.estimators import STATUSES, assess, estimate, fit_statement
from bayesplate.estimators.assess import (
    effective_constants,
    effective_constants_from_covariance,
    plausibility_warnings,
)
from bayesplate.io import bundled_case_path, load_case
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import ENGINEERING_KEYS, hz_from_eigenvalue, to_case_units

MESH = (6, 3)  # coarse: each estimate well under a second
NOISE = 0.005  # relative noise of the synthetic frequencies, and their declared deviation
SHIFTED = 5  # 0-based peak shifted by 8 % in the rejected case


@pytest.fixture(scope="module")
def synthetic():
    """Plate 1's frequencies computed at its reference constants on the coarse mesh, 0.5 %
    noise, 0.5 % declared deviations, a prior 10 % off with deviations of 1/6."""
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case, mesh=MESH)
    truth = case.reference
    exact = hz_from_eigenvalue(model.solve(stiffness_from_engineering(truth), 14).eigenvalues)
    rng = np.random.default_rng(1)
    f = exact * (1 + NOISE * rng.standard_normal(exact.size))
    mean = truth * np.array([1.1, 0.9, 1.1, 1.1, 0.9, 1.1])
    case = case.with_measured(frequency_Hz=f, sigma_Hz=NOISE * f).with_prior(mean, mean / 6)
    return dataclasses.replace(case, path=None), model


def _b(case, model, **kwargs):
    return estimate(case, "B", model=model, pairing="order", forward="full", **kwargs)


# ----------------------------------------------------------------------------- the statement


def test_chi_square_p_value_and_effective_count_by_hand():
    rng = np.random.default_rng(3)
    m = 9
    f = np.sort(rng.uniform(100.0, 2000.0, m))
    sigma = 0.01 * f * rng.uniform(0.5, 2.0, m)
    fc = f * (1 + 0.01 * rng.standard_normal(m))
    S = rng.standard_normal((m, 6)) * 1e3
    V_Y = np.diag(rng.uniform(0.5, 2.0, m) * 1e6)
    V_b = np.diag(rng.uniform(0.5, 2.0, 6) * 1e-6)
    # p_eff = trace(S (S^T V_Y^-1 S + V_b^-1)^-1 S^T V_Y^-1), inverses explicit
    P = np.linalg.inv(S.T @ np.linalg.inv(V_Y) @ S + np.linalg.inv(V_b))
    p_eff = np.trace(S @ P @ S.T @ np.linalg.inv(V_Y))
    assert effective_constants(S, V_Y, V_b) == pytest.approx(p_eff, rel=1e-10)
    assert effective_constants_from_covariance(P, V_b) == pytest.approx(p_eff, rel=1e-8)
    assert 0 < p_eff < 6
    fit = fit_statement(f, fc, sigma, p_eff, peaks=np.arange(m) + 3)
    # r^T V^-1 r in eigenvalues, V = diag((8 pi^2 f sigma)^2)
    r = (2 * np.pi * fc) ** 2 - (2 * np.pi * f) ** 2
    V = np.diag((8 * np.pi**2 * f * sigma) ** 2)
    chi2 = r @ np.linalg.inv(V) @ r
    assert fit.chi2 == pytest.approx(chi2, rel=1e-12)
    assert fit.dof == pytest.approx(m - p_eff, rel=1e-12)
    assert fit.p_value == pytest.approx(stats.chi2.sf(chi2, m - p_eff), rel=1e-12)
    z = r / np.sqrt(np.diag(V))
    order = np.argsort(-np.abs(z))[:3]
    assert [w.peak for w in fit.worst_residuals] == (order + 3).tolist()
    assert [w.sd for w in fit.worst_residuals] == pytest.approx(z[order], rel=1e-12)
    assert fit.worst_residuals[0].computed_Hz == fc[order[0]]
    assert np.sum(fit.residual_sd**2) == pytest.approx(chi2, rel=1e-12)


def test_the_statuses_are_declared():
    assert {"converged", "rejected", "implausible"} <= set(STATUSES)


# ----------------------------------------------------------------------------- estimates


def test_a_sound_fit_is_converged(synthetic):
    case, model = synthetic
    r = _b(case, model)
    assert r.converged and r.status == "converged", r.warnings
    assert r.warnings == ()
    assert r.fit.p_value > 0.05 and r.fit.n_paired == 14
    assert 3 < r.fit.p_effective < 6 and r.fit.dof == pytest.approx(14 - r.fit.p_effective)
    # assessment is idempotent, and B's count is its P's
    again = assess(r, case)
    assert again.status == r.status and again.fit.chi2 == r.fit.chi2


def test_a_shifted_peak_is_rejected_and_points_to_diagnose(synthetic):
    case, model = synthetic
    f = case.measured.frequency_Hz.copy()
    f[SHIFTED] *= 1.08
    shifted = case.with_measured(frequency_Hz=f)
    r = _b(shifted, model)
    assert r.converged and r.status == "rejected"
    assert r.fit.p_value < 0.01 and r.fit.worst_residuals[0].peak == SHIFTED + 1
    (warning,) = [w for w in r.warnings if w.startswith("fit rejected")]
    assert "bayesplate diagnose" in warning and f"{r.fit.chi2:.3g}" in warning


def test_a_prior_far_from_the_plate_is_implausible_and_named(synthetic):
    case, model = synthetic
    truth = load_case(bundled_case_path("plate1")).reference
    mean, sd = truth.copy(), truth / 6
    sd[3] = 0.05 * truth[3]
    mean[3] = truth[3] + 5 * sd[3]  # G12's prior mean 5 tight deviations above the plate's
    r = _b(case.with_prior(mean, sd), model)
    assert r.converged and r.status == "implausible", r.warnings
    (warning,) = r.warnings
    assert warning.startswith("G12 is") and "prior sd below its prior mean" in warning
    n_sd = float(re.search(r"is ([\d.]+) prior sd", warning).group(1))
    assert n_sd == pytest.approx(abs(r.constants[3] - mean[3]) / sd[3], abs=0.05) and n_sd > 4


def test_a_run_that_did_not_stop_keeps_its_status(synthetic):
    case, model = synthetic
    r = _b(case, model, max_iter=1)
    assert not r.converged and r.status == "iteration_cap" and r.fit is not None


def test_a_rival_basin_is_implausible(synthetic):
    case, model = synthetic
    r = _b(case, model)
    far = r.constants + 4 * r.sd * np.array([0, 0, 0, 1, 0, 0])
    flagged = assess(r, case, rivals=[(far, 1.5)])
    assert flagged.status == "implausible" and "second basin" in flagged.warnings[-1]
    assert "G12" in flagged.warnings[-1]
    assert assess(r, case, rivals=[(far, 10.0)]).status == "converged"  # far less probable
    near = r.constants + 0.5 * r.sd
    assert assess(r, case, rivals=[(near, 0.1)]).status == "converged"  # the same basin


def test_low_modes_unobserved_and_a_spurious_fundamental_are_flagged():
    e = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    f = np.arange(1.0, 11.0) * 100
    base = {"constants": e, "prior_mean": e, "prior_sd": e / 6, "measured_Hz": f}
    none = plausibility_warnings(
        **base, settings={"unobserved_modes": [4], "spurious_peaks": []}, modes=np.arange(1, 11)
    )
    assert none == ()
    fundamental = plausibility_warnings(
        **base, settings={"unobserved_modes": [1], "spurious_peaks": []}, modes=np.arange(2, 12)
    )
    assert len(fundamental) == 1 and "fundamental" in fundamental[0]
    many = plausibility_warnings(
        **base,
        settings={"unobserved_modes": [2, 3, 5, 7], "spurious_peaks": []},
        modes=np.array([1, 4, 6, 8, 9, 10]),
    )
    assert len(many) == 1 and "4 of the 9 computed modes below" in many[0]
    spurious = plausibility_warnings(
        **base, settings={"unobserved_modes": [], "spurious_peaks": [1]}, modes=np.arange(1, 10)
    )
    assert len(spurious) == 1 and "lowest peak (peak 1, 100.0 Hz) is called spurious" in spurious[0]


# ----------------------------------------------------------------------------- output


def test_the_json_carries_the_numbers_of_the_text(synthetic, tmp_path, capsys):
    case, _ = synthetic
    f = case.measured.frequency_Hz.copy()
    f[SHIFTED] *= 1.08
    mean = to_case_units(case.prior.mean)
    prior = "\n".join(
        f"{key} = {{ mean = {m:.6g}, sd = {m / 6:.6g} }}"
        for key, m in zip(ENGINEERING_KEYS, mean, strict=True)
    )
    text = bundled_case_path("plate1").read_text(encoding="utf-8")
    text = text[: text.index("[measured]")] + (
        f"[measured]\nfrequency_Hz = {[round(float(x), 3) for x in f]}\n"
        f"sigma_rel = {NOISE}\n\n[prior]\n{prior}\n"
    )
    path = tmp_path / "shifted.toml"
    path.write_text(text, encoding="utf-8")
    out = tmp_path / "estimate.json"
    args = ["estimate", str(path), "--method", "B", "--pairing", "order", "-q"]
    status = cli_main([*args, "--mesh", *map(str, MESH), "--json", str(out)])
    captured = capsys.readouterr()
    assert status == 0  # an answer with a warning
    doc = json.loads(out.read_text())
    assert doc["status"] == "rejected" and doc["converged"] is True
    fit = doc["fit"]
    line = next(x for x in captured.out.splitlines() if x.strip().startswith("fit:"))
    assert f"chi-square {fit['chi2']:.3g} on {fit['dof']:.1f} dof, p {fit['p_value']:.2g}" in line
    worst = ", ".join(f"peak {w['peak']} {w['sd']:+.1f} sd" for w in fit["worst_residuals"])
    assert line.endswith(f"worst residuals: {worst}")
    assert fit["worst_residuals"][0]["peak"] == SHIFTED + 1
    assert ": rejected (the iteration stopped" in captured.out
    assert ": converged after" not in captured.out
    warned = [x for x in captured.err.splitlines() if x.startswith("bayesplate: warning: ")]
    assert warned == [f"bayesplate: warning: {w}" for w in doc["warnings"]]
    assert len(warned) == 1 and f"bayesplate diagnose {path}" in warned[0]
