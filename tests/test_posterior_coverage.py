"""The calibrated-posteriors study (studies/posterior_coverage.py) in quick mode, and its
coverage machinery on a problem whose coverage is known exactly."""

import json

import numpy as np
import pytest
from scipy import stats

from studies import posterior_coverage


@pytest.fixture(scope="module")
def study():
    return posterior_coverage


@pytest.mark.slow  # two sampler runs: ~20 s of CPU, 129 s measured at load 11 on 2 cores
def test_quick_report_and_resume(study, tmp_path):
    path = study.main(tmp_path, quick=True)
    text = path.read_text()
    assert "Made by `python -m studies.posterior_coverage --quick`" in text
    assert "| method | replicates (failed) | band at 0.94 | E1_GPa |" in text
    for label in ("sampler", "B", "MVE (TOL 1e-6)", "MVE (TOL 1e-3)"):
        assert f"\n| {label} | " in text
    assert (tmp_path / study.FIGURE).stat().st_size > 0
    cache = tmp_path / ".cache" / "posterior_coverage-quick.json"
    rows = json.loads(cache.read_text())["rows"]
    assert sorted(rows) == ["drawn/0", "drawn/1"]
    # a second run finds every row in the cache and runs nothing: the same report
    mtime = cache.stat().st_mtime_ns
    again = study.main(tmp_path, quick=True).read_text()
    assert again.split("\n\n")[2:] == text.split("\n\n")[2:]
    assert cache.stat().st_mtime_ns == mtime


def test_replicates_are_their_own_streams(study):
    # replicate i's data do not depend on how many replicates there are or which ran before
    a, _ = study.draw("drawn", 5)
    b, _ = study.draw("drawn", 5)
    c, _ = study.draw("fixed", 5)
    np.testing.assert_array_equal(a.measured.frequency_Hz, b.measured.frequency_Hz)
    assert not np.array_equal(a.measured.frequency_Hz, c.measured.frequency_Hz)
    np.testing.assert_array_equal(c.prior.mean, study.FIXED_PRIOR_MEAN)


def test_coverage_of_a_conjugate_normal_is_nominal(study):
    # The study's interval and coverage code on a problem whose posterior is exact: each
    # constant observed directly, y = e + N(0, s^2), under the drawn-prior design (prior mean
    # e + N(0, s0^2), sd s0). The conjugate posterior's mean +- 1.881 sd covers e with
    # probability 0.94 exactly, so the shares must fall in the binomial band of 0.94 (not a
    # band around the code's own output).
    rng = np.random.default_rng(20261214)
    truth, n = study.ic.E_TRUE, 1000
    s0, s = 0.25 * truth, np.array([0.01, 0.01, 0.3, 0.01, 0.5, 1.0]) * truth
    rows = []
    for i in range(n):
        m0 = truth + s0 * rng.standard_normal(6)
        y = truth + s * rng.standard_normal(6)
        sd = 1 / np.sqrt(1 / s0**2 + 1 / s**2)
        mean = sd**2 * (m0 / s0**2 + y / s**2)
        interval = [mean - study.ic.Z94 * sd, mean + study.ic.Z94 * sd]
        rows.append({"design": "drawn", "index": i, "intervals": {"B": interval}})
    used, failed, share, _ = study.coverage(rows, "drawn", "B")
    assert (used, failed) == (n, 0)
    # per constant: inside the 99.9 % binomial band (six constants: a false alarm < 0.6 %)
    half = stats.norm.ppf(0.9995) * np.sqrt(0.94 * 0.06 / n)
    assert np.all(np.abs(share - 0.94) < half), share
    # pooled over the six independent constants: inside the 95 % band of 6000 trials
    assert abs(share.mean() - 0.94) < 1.96 * np.sqrt(0.94 * 0.06 / (6 * n))


def test_hdi_at_94_percent_of_a_normal_is_its_central_interval():
    # The sampler's HDI is ArviZ's at HDI_PROB: for a normal it is the central interval,
    # scipy's norm.interval(0.94) = +-1.8808. 200 000 draws: the sample quantile's sd is
    # sqrt(0.03 * 0.97 / n) / pdf(1.88) = 0.006; tolerance 0.025 (4 sd)
    import arviz as az

    from bayesplate.sampling.result import HDI_PROB

    draws = np.random.default_rng(7).standard_normal(200_000)
    lo, hi = az.hdi(draws, hdi_prob=HDI_PROB)
    ref = stats.norm.interval(0.94)
    assert HDI_PROB == 0.94
    np.testing.assert_allclose([lo, hi], ref, atol=0.025)
