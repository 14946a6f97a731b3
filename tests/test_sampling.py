"""Posterior sampling: a known Gaussian, determinism, resumption, and the plates.

Tiers: a linear forward model with a closed-form Gaussian posterior (sampler correctness,
tolerances from the effective sample size); determinism and resumption on the same cheap
problem; the log-density against GaussianProblem.log_posterior on the full model; Plate 1
on its 8 x 4 mesh with the certified fast model (B is the MAP, the linearised covariance
against the sampled one); the Frederiksen plate on its 50 x 50 mesh in the slow tier.
"""

import json
import warnings

import numpy as np
import pytest
from scipy.optimize import minimize

from bayesplate.estimators import estimate
from bayesplate.io import bundled_case_path, load_case
from bayesplate.likelihood.posterior import GaussianProblem, prior_in_stiffness
from bayesplate.matching.pairing import Pairing
from bayesplate.plate.model import PlateModel
from bayesplate.reduced import Box
from bayesplate.sampling import (
    CASE_UNITS,
    ScreenedDEMove,
    WhitenedLogPosterior,
    covariance_agreement,
    curvature_covariance,
    linearisation_band,
    prepare,
    sample,
    sample_problem,
)

SEED = 20070461
N_MC = 4.0  # Monte Carlo errors allowed: a 4-sigma band fails by chance ~6e-5 per check
NAMES = ("E1", "E2", "nu12", "G12", "G13", "G23")


# ----------------------------------------------------------------------------- linear problem


class _Linear:
    """What a forward model returns, for g(b) = A b."""

    def __init__(self, b, A):
        self.eigenvalues = A @ b
        self.sensitivities = A


def _linear_problem(rng, m=10):
    """g(b) = A b with Plate 1-like b, a prior of 1/6 and 1 % data: closed-form posterior.

    Returns the problem and the exact posterior mean and covariance of b.
    """
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, V_b = prior_in_stiffness(e0, e0 / 6, "full")
    A = rng.uniform(0.2, 2.0, size=(m, 6)) * 1e7 / mu[None, :]
    b_true = mu * rng.uniform(0.9, 1.1, 6)
    V_Y = np.diag((0.01 * A @ b_true) ** 2)
    Y = A @ b_true + rng.normal(0, np.sqrt(np.diag(V_Y)))

    def forward(b, n_modes):
        return _Linear(b, A)

    problem = GaussianProblem(Y, V_Y, mu, V_b, forward, Pairing(np.arange(m), extra=0))
    W = np.linalg.inv(V_Y)
    P = np.linalg.inv(A.T @ W @ A + np.linalg.inv(V_b))
    mean = P @ (A.T @ W @ Y + np.linalg.solve(V_b, mu))
    # the posterior lies 15+ deviations inside the physical region: the truncation of the
    # prior at non-physical laminae is invisible (probability < 1e-40)
    assert np.all(np.sqrt(np.diag(P))[[0, 1, 3, 4, 5]] < mean[[0, 1, 3, 4, 5]] / 15)
    return problem, mean, P


def _ess_b(result):
    """Bulk ESS of each stiffness coefficient (walkers as chains)."""
    from bayesplate.sampling.stopping import load_arviz

    az = load_arviz()
    draws = result.samples_b.reshape(-1, result.n_walkers, 6)
    return np.array([az.ess(draws[:, :, j].T) for j in range(6)])


def _check_gaussian(result, mean, P):
    """Sampled mean, deviations and correlations against exact ones, within MC error."""
    ess = _ess_b(result)
    sd = np.sqrt(np.diag(P))
    # standard error of a mean: sd / sqrt(ESS)
    np.testing.assert_array_less(np.abs(result.mean_b - mean), N_MC * sd / np.sqrt(ess))
    # of a variance (Gaussian): var sqrt(2 / ESS); the bulk ESS stands for that of the
    # squares, which differ by a few % for an independence sampler
    var_s = np.diag(result.covariance_b)
    np.testing.assert_array_less(np.abs(var_s / sd**2 - 1), N_MC * np.sqrt(2 / ess))
    # of a correlation: (1 - rho^2) / sqrt(ESS), with the smaller ESS of the pair
    rho = P / np.outer(sd, sd)
    rho_s = result.covariance_b / np.outer(np.sqrt(var_s), np.sqrt(var_s))
    band = N_MC * (1 - rho**2) / np.sqrt(np.minimum.outer(ess, ess)) + 1e-12
    np.testing.assert_array_less(np.abs(rho_s - rho), band)
    return ess


def test_known_gaussian_posterior_within_monte_carlo_error(rng):
    # The sampler starts from a wrong centre (+0.7 sd) and a wrong covariance (diagonal,
    # twice the variances): tuning and the Metropolis-Hastings rule must still give the
    # closed-form posterior.
    problem, mean, P = _linear_problem(rng)
    sd = np.sqrt(np.diag(P))
    result = sample_problem(
        problem, mean + 0.7 * sd, np.diag(2 * sd**2), rng=1, progress=False, min_ess=2000
    )
    assert result.converged and result.rhat_max < 1.01
    ess = _check_gaussian(result, mean, P)
    assert ess.min() > 1500  # the tolerances above are then below 10 % of a deviation


def test_truncated_proposals_leave_the_posterior_invariant(rng):
    # The Laplace proposals are truncated to a box cutting 2.2 deviations into the posterior
    # in C11 (1.4 % of its mass outside): only differential evolution goes beyond, and the
    # posterior must still be the whole Gaussian, its cut tail included.
    problem, mean, P = _linear_problem(rng)
    sd = np.sqrt(np.diag(P))
    lower, upper = mean - 10 * sd, mean + 10 * sd
    upper[0] = mean[0] + 2.2 * sd[0]
    box = Box(lower, upper)
    result = sample_problem(problem, mean, P, rng=2, progress=False, min_ess=2000, box=box)
    _check_gaussian(result, mean, P)
    outside = np.mean(result.samples_b[:, 0] > upper[0])
    assert 0.005 < outside < 0.03  # 1.4 % expected; zero would mean a truncated posterior


def test_same_rng_same_chain_and_a_generator_is_a_seed(rng):
    problem, mean, P = _linear_problem(rng)
    kwargs = {"progress": False, "max_steps": 150, "min_ess": np.inf}
    a = sample_problem(problem, mean, P, rng=7, **kwargs)
    b = sample_problem(problem, mean, P, rng=7, **kwargs)
    c = sample_problem(problem, mean, P, rng=np.random.default_rng(7), **kwargs)
    d = sample_problem(problem, mean, P, rng=8, **kwargs)
    np.testing.assert_array_equal(a.chain, b.chain)
    np.testing.assert_array_equal(a.chain, c.chain)
    assert not np.array_equal(a.chain, d.chain)
    assert a.settings["moves"] == ["LaplaceMove", "ScreenedDEMove"]
    assert a.settings["move_weights"] == [0.9, 0.1]


def test_seed_keyword_still_works_with_a_deprecation_warning(rng):
    # ``seed`` was the name of ``rng`` before: the same int, the same chain, for one release
    problem, mean, P = _linear_problem(rng)
    kwargs = {"progress": False, "max_steps": 150, "min_ess": np.inf}
    a = sample_problem(problem, mean, P, rng=7, **kwargs)
    with pytest.warns(DeprecationWarning, match="rng"):
        b = sample_problem(problem, mean, P, seed=7, **kwargs)
    np.testing.assert_array_equal(a.chain, b.chain)
    with pytest.raises(TypeError, match="not both"):
        sample_problem(problem, mean, P, rng=7, seed=7, **kwargs)


def test_case_units_multiply_as_before():
    # results are multiplied by CASE_UNITS: 1 / CASE_SCALE is the old literal to the last bit
    assert CASE_UNITS.tobytes() == np.array([1e-9, 1e-9, 1.0, 1e-9, 1e-9, 1e-9]).tobytes()


def test_resuming_a_backend_continues_the_same_chain(rng, tmp_path):
    # 90 tuning steps, then 40 + 40 in two runs against 80 in one: the same numbers.
    problem, mean, P = _linear_problem(rng)
    kwargs = {"progress": False, "min_ess": np.inf, "check_every": 20}
    whole = sample_problem(problem, mean, P, rng=3, max_steps=170, **kwargs)
    path = tmp_path / "chain.h5"
    first = sample_problem(problem, mean, P, rng=3, max_steps=130, backend_path=path, **kwargs)
    assert first.n_steps == 130 and not first.settings["resumed"]
    second = sample_problem(problem, mean, P, rng=99, max_steps=170, backend_path=path, **kwargs)
    assert second.settings["resumed"] and second.n_steps == 170
    np.testing.assert_array_equal(second.chain, whole.chain)
    other, _, _ = _linear_problem(np.random.default_rng(5))
    with pytest.raises(ValueError, match="another problem"):
        sample_problem(other, mean, P, rng=3, max_steps=200, backend_path=path, **kwargs)


def test_a_map_like_pool_gives_the_same_chain(rng):
    class Serial:
        calls = 0

        def map(self, f, xs):
            Serial.calls += 1
            return list(map(f, xs))

    problem, mean, P = _linear_problem(rng)
    kwargs = {"progress": False, "max_steps": 160, "min_ess": np.inf, "rng": 4}
    plain = sample_problem(problem, mean, P, **kwargs)
    pooled = sample_problem(problem, mean, P, pool=Serial(), **kwargs)
    assert Serial.calls > 0
    np.testing.assert_array_equal(plain.chain, pooled.chain)


def test_screening_changes_no_decision(rng):
    # A screen returning the exact log-density (the tightest valid upper bound) rejects
    # without evaluating, and the chain is that of the same move evaluating everything.
    import emcee

    problem, mean, P = _linear_problem(rng)
    density = WhitenedLogPosterior(problem, mean, P)

    def exact(q):
        return np.array([density(z)[0] for z in q]) - 1e-9

    runs = []
    for screen in (exact, lambda q: np.full(len(q), np.inf)):
        move = ScreenedDEMove(screen)
        sampler = emcee.EnsembleSampler(16, 6, density, moves=[move])
        sampler.random_state = np.random.RandomState(5).get_state()
        start = np.random.default_rng(5).standard_normal((16, 6))
        sampler.run_mcmc(start, 60, progress=False)
        runs.append((sampler.get_chain(), move.n_screened))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert runs[0][1] > 0 and runs[1][1] == 0


# ----------------------------------------------------------------------------- Plate 1


@pytest.fixture(scope="module")
def plate1():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    setup = prepare(case, model=model, rng=SEED)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no full-model fallback while sampling
        result = sample(case, rng=SEED, setup=setup, progress=False, min_ess=2000)
    return case, model, setup, result


def test_log_density_is_the_problems_log_posterior(plate1):
    # On the full model the sampler's density is GaussianProblem.log_posterior itself, to
    # the last bit, plus its log-Jacobian; the pointwise terms sum to the log-likelihood.
    case, model, setup, _ = plate1
    problem = setup.problem
    est = setup.estimate
    density = WhitenedLogPosterior(problem, est.b, est.covariance_b)
    rng = np.random.default_rng(SEED)
    for z in rng.standard_normal((4, 6)):
        b = density.to_b(z)
        value, pointwise = density(z)
        assert density.problem.log_posterior(b) == problem.log_posterior(b)
        assert value == problem.log_posterior(b) + density.log_jacobian(z)
        assert np.sum(pointwise) == pytest.approx(problem.log_likelihood(b), rel=1e-12)
    z_bad = density.to_z(
        np.array([est.b[0], est.b[1], 1.01 * np.sqrt(est.b[0] * est.b[1]), *est.b[3:]])
    )
    value, pointwise = density(z_bad)
    assert value == -np.inf and np.all(np.isnan(pointwise))


def test_fast_model_density_within_its_certificate(plate1):
    # With the certified model plugged into the same problem the log-posterior moves by at
    # most sum_i (|r_i| d_i + d_i^2 / 2) / v_i, with d_i = 2 eps g_i the eigenvalue error
    # for a relative frequency error eps (the certificate; 2x for the square).
    case, model, setup, _ = plate1
    est = setup.estimate
    full = WhitenedLogPosterior(setup.problem, est.b, est.covariance_b)
    fast = WhitenedLogPosterior(setup.problem, est.b, est.covariance_b, setup.sampling_forward())
    eps = setup.certificate.max_rel_error
    v = np.diag(setup.problem.V_Y)
    rng = np.random.default_rng(1)
    for z in rng.standard_normal((4, 6)):
        if not setup.box.contains(full.to_b(z)):
            continue
        g = setup.problem.predict(full.to_b(z)).g
        d = 2 * eps * g
        bound = np.sum((np.abs(setup.problem.Y - g) * d + d**2 / 2) / v)
        assert abs(fast(z)[0] - full(z)[0]) <= bound


def test_plate1_sampler_converges_without_full_solves(plate1):
    _, _, setup, result = plate1
    assert setup.certificate.passed and setup.certificate.max_rel_error < 1e-4
    assert result.converged and result.ess_min >= 2000 and result.rhat_max < 1.01
    assert result.n_full == 0
    # the InferenceData: posterior in case units, pointwise log-likelihood per mode
    idata = result.idata
    assert set(idata.posterior.data_vars) == {
        "E1_GPa",
        "E2_GPa",
        "nu12",
        "G12_GPa",
        "G13_GPa",
        "G23_GPa",
    }
    ll = idata.log_likelihood["Y"]
    assert ll.shape[-1] == 14 and np.all(np.isfinite(ll))
    total = ll.sum("mode") + 0.0
    prior = np.array([setup.problem.log_prior(b) for b in result.samples_b[:50]])
    lp = idata.sample_stats["lp"].values.T.reshape(-1)[:50]  # draws-major like samples_b
    np.testing.assert_allclose(lp, prior + total.values.T.reshape(-1)[:50], rtol=1e-10)
    assert float(idata.posterior["E1_GPa"].mean()) == pytest.approx(result.mean[0] / 1e9)


def test_b_estimate_is_the_posterior_mode(plate1):
    # B (eq. 9) run to TOL 1e-8 on the full model; Nelder-Mead on the full model's
    # log_posterior from there, in coordinates scaled by P (steps of 0.2 deviations), may
    # not move it: the optimiser stops at xatol 1e-3 deviations and B's stopping rule leaves
    # ~1e-7 relative; 0.01 deviations is ten times the optimiser's resolution. The gain in
    # ln f must be below 5e-5 (a quadratic moved by 0.01 deviations gains 5e-5).
    case, model, setup, _ = plate1
    b_est = estimate(case, "B", model=model, tol=1e-8)
    assert b_est.converged
    problem = GaussianProblem.from_case(case, model, setup.problem.pairing)
    L = np.linalg.cholesky(b_est.covariance_b)

    def f(y):
        return -problem.log_posterior(b_est.b + L @ y)

    simplex = np.vstack([np.zeros(6), 0.2 * np.eye(6)])
    opt = minimize(
        f,
        np.zeros(6),
        method="Nelder-Mead",
        options={"initial_simplex": simplex, "xatol": 1e-3, "fatol": 1e-9, "maxfev": 3000},
    )
    assert np.max(np.abs(opt.x)) < 0.01
    assert f(np.zeros(6)) - opt.fun < 5e-5
    # the sampler's MAP (B on the fast model) is the same point within 0.01 deviations
    sd = np.sqrt(np.diag(b_est.covariance_b))
    np.testing.assert_array_less(np.abs(setup.estimate.b - b_est.b) / sd, 0.01)


def test_plate1_covariance_linearised_against_sampled(plate1):
    # Two Gaussian approximations at the MAP against the sampled posterior (b):
    # - the full-Hessian Laplace covariance (finite differences of log_posterior): the
    #   posterior is Gaussian to Monte Carlo precision, so deviations and correlations agree
    #   within 4 Monte Carlo errors plus the O(step^2) = 0.3 % of the differences;
    # - B's P (Gauss-Newton: no residual curvature) then agrees within the Monte Carlo error
    #   plus its own linearisation error, the measured gap between P and the full-Hessian
    #   covariance. Where that gap exceeds the Monte Carlo error (E2 and G23 on Plate 1, a
    #   prior that pulls the fit 10 % away from the data) B's deviations are off by it;
    #   reports/benchmark_sampling.md shows the table.
    _, _, setup, result = plate1
    est = setup.estimate
    H = curvature_covariance(setup.problem_on_fast_model(), est.b, est.covariance_b)
    ess = _ess_b(result)
    mc = N_MC / np.sqrt(2 * ess)
    sd_s = np.sqrt(np.diag(result.covariance_b))
    sd_h = np.sqrt(np.diag(H))
    sd_p = np.sqrt(np.diag(est.covariance_b))
    np.testing.assert_array_less(np.abs(sd_s / sd_h - 1), mc + 3e-3)
    rho = lambda C: C / np.outer(np.sqrt(np.diag(C)), np.sqrt(np.diag(C)))  # noqa: E731
    rho_h = rho(H)
    corr_band = N_MC * (1 - rho_h**2) / np.sqrt(np.minimum.outer(ess, ess)) + 3e-3
    np.testing.assert_array_less(np.abs(rho(result.covariance_b) - rho_h), corr_band + 1e-12)
    linearisation = np.abs(sd_h / sd_p - 1)
    np.testing.assert_array_less(np.abs(sd_s / sd_p - 1), mc + linearisation + 3e-3)
    # ... and the disagreement is there, not hidden: C22 (E2) and C44 (G23) are off by
    # more than the Monte Carlo error alone
    off = np.abs(sd_s / sd_p - 1) > mc
    assert off[1] and off[4]
    # the same comparison in engineering constants (what the report prints)
    agreement = covariance_agreement(result, est.covariance)
    assert agreement["sd_agrees"][[0, 2, 3]].all()


def test_plate1_summary_and_json_table(plate1):
    _, _, _, result = plate1
    table = result.constants_table()
    assert set(table) == {"E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa"}
    for i, entry in enumerate(table.values()):
        assert entry["hdi_3%"] < entry["mean"] < entry["hdi_97%"]
        assert entry["sd"] == pytest.approx(result.sd[i] * (1 if i == 2 else 1e-9))


def test_cli_sample_writes_json_netcdf_and_figures(tmp_path):
    from bayesplate.cli import main
    from bayesplate.sampling.stopping import load_arviz

    out = tmp_path / "posterior.nc"
    js = tmp_path / "posterior.json"
    status = main(
        [
            "sample",
            "plate1",
            "--seed",
            "3",
            "--min-ess",
            "800",
            "--out",
            str(out),
            "--json",
            str(js),
            "--plots",
            str(tmp_path / "figs"),
        ]
    )
    assert status == 0
    doc = json.loads(js.read_text())
    assert doc["ess_min"] >= 800 and doc["rhat_max"] < 1.01
    assert set(doc["constants"]["E1_GPa"]) >= {"mean", "sd", "hdi_3%", "hdi_97%"}
    idata = load_arviz().from_netcdf(out)
    assert "log_likelihood" in idata.groups()
    for name in ("corner", "trace", "autocorrelation"):
        assert (tmp_path / "figs" / f"{name}.png").stat().st_size > 10_000


# ----------------------------------------------------------------------------- Frederiksen


@pytest.mark.slow
def test_frederiksen_covariance_linearised_against_sampled():
    # The 50 x 50 model. The posterior is not Gaussian: G13 has a steep likelihood below
    # and the prior's tail above (draws 9 deviations of P above the MAP). Tolerance: 4
    # Monte Carlo errors plus the linearisation error, measured without sampling as the
    # largest change of B's deviations over MAP +- one column of chol(P)
    # (linearisation_band). It holds for nu12 and G12; it fails for G13 (and E1, E2,
    # correlated with it), shown in reports/benchmark_sampling.md and pinned here so that
    # it stays shown.
    case = load_case(bundled_case_path("frederiksen_t300"))
    setup = prepare(case, rng=SEED)
    result = sample(case, rng=SEED, setup=setup, progress=False, min_ess=2000)
    est = setup.estimate
    assert setup.certificate.passed
    assert result.converged and result.ess_min >= 2000 and result.rhat_max < 1.01
    agreement = covariance_agreement(result, est.covariance)
    band = linearisation_band(setup.problem_on_fast_model(), est.b, est.covariance_b)
    within = np.abs(agreement["ratio"] - 1) <= agreement["band"] + band
    assert within[2] and within[3]  # nu12, G12
    assert agreement["ratio"][4] > 1.3  # G13: the sampled deviation is far above P's
    # the sampler's MAP is the full model's B estimate within 0.05 deviations (the
    # certificate's 1e-4 in frequency is 1 % of the measurement deviation)
    full = estimate(case, "B", tol=1e-6)
    sd = np.sqrt(np.diag(full.covariance_b))
    np.testing.assert_array_less(np.abs(est.b - full.b) / sd, 0.05)


def test_prepare_assigns_a_test_that_missed_a_mode():
    # Issue 16: plate 1 without mode 5 and no shapes. By likelihood the sampler's problem
    # pairs the peaks above the gap with the modes above it (not by order), and its MAP is
    # the complete test's within the complete test's posterior deviations (both carry B's
    # bias from the case's prior, the paper's test 1: E1 about 145 GPa for 150).
    case = load_case(bundled_case_path("plate1"))
    keep = np.delete(np.arange(14), 4)
    missing = case.with_measured(
        frequency_Hz=case.measured.frequency_Hz[keep], sigma_Hz=case.measured.sigma_Hz[keep]
    )
    complete = prepare(case, rng=SEED, pairing="likelihood")
    assert complete.problem.pairing.assignment.in_order
    setup = prepare(missing, rng=SEED, pairing="likelihood")
    pairing = setup.problem.pairing
    assert pairing.how == "likelihood"
    np.testing.assert_array_equal(pairing.modes, keep)
    np.testing.assert_array_equal(pairing.assignment.unobserved, [4])
    assert setup.estimate.converged, setup.estimate.message
    difference = setup.estimate.constants - complete.estimate.constants
    assert np.all(np.abs(difference) < complete.estimate.sd)
