"""The hierarchical model by Laplace (issue 42): its Gaussian algebra, its plates, its chain."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayesplate import laminate
from bayesplate.sampling.hierarchical import PopulationDensity, log_jacobian
from bayesplate.sampling.population import (
    component_spreads,
    conditional,
    marginal_log_likelihood,
    mixture_log_likelihood,
)
from studies import many_plates, population_coverage


def _plate(rng, rank=6, scale=100.0, info=10.0):
    """A random plate precision of the given rank and an information vector."""
    A = rng.normal(size=(6, rank)) * np.sqrt(scale)
    return A @ A.T, rng.normal(size=6) * info


def _direct(log_mu, tau, H, h):
    """``N(H^-1 h; m, H^-1 + T)`` plus the constant relating it to ``int L N`` (full rank)."""
    zhat = np.linalg.solve(H, h)
    const = 0.5 * zhat @ H @ zhat - 0.5 * np.linalg.slogdet(H)[1] + 3 * np.log(2 * np.pi)
    cov = np.linalg.inv(H) + np.diag(tau**2)
    return multivariate_normal(log_mu, cov).logpdf(zhat) + const


def test_marginal_is_the_direct_gaussian_when_the_precision_is_full_rank(rng):
    for _ in range(5):
        H, h = _plate(rng)
        log_mu, tau = rng.normal(size=6), np.abs(rng.normal(size=6)) * 0.1
        # two routes to one number: differences of ~1e3-sized logs, round-off ~1e-12
        np.testing.assert_allclose(
            marginal_log_likelihood(log_mu, tau, H, h), _direct(log_mu, tau, H, h), atol=1e-8
        )


def test_marginal_is_the_monte_carlo_integral_when_the_precision_is_singular(rng):
    """Rank 3 (three constants unidentified): ``E_z[exp(q(z))]`` over ``z ~ N(m, T)``."""
    H, h = _plate(rng, rank=3, scale=1.0, info=1.0)  # weights of moderate spread
    log_mu = rng.normal(size=6) * 0.3
    tau = np.array([0.3, 0.2, 0.5, 0.4, 0.1, 0.6])
    z = log_mu + tau * rng.standard_normal((400_000, 6))
    q = -0.5 * np.einsum("ni,ij,nj->n", z, H, z) + z @ h
    top = q.max()
    mc = top + np.log(np.mean(np.exp(q - top)))
    w = np.exp(q - top)
    rel_se = np.std(w) / np.mean(w) / np.sqrt(len(w))  # the estimate's relative standard error
    exact = marginal_log_likelihood(log_mu, tau, H, h)
    assert rel_se < 0.01
    assert abs(exact - mc) < 4 * rel_se  # four standard errors of the Monte Carlo mean


def test_marginal_tends_to_the_plate_likelihood_as_the_spread_vanishes(rng):
    H, h = _plate(rng, rank=2)
    log_mu = rng.normal(size=6)
    q = -0.5 * log_mu @ H @ log_mu + h @ log_mu
    value = marginal_log_likelihood(log_mu, np.full(6, 1e-9), H, h)
    np.testing.assert_allclose(value, q, rtol=1e-9)


def test_conditional_is_the_gaussian_product(rng):
    H, h = _plate(rng)
    log_mu, tau = rng.normal(size=6), np.abs(rng.normal(size=6)) * 0.1 + 0.01
    mean, cov = conditional(log_mu, tau, H, h)
    Tinv = np.diag(tau**-2.0)
    ref_cov = np.linalg.inv(H + Tinv)  # the textbook product, fine at these spreads
    np.testing.assert_allclose(cov, ref_cov, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(mean, ref_cov @ (h + Tinv @ log_mu), rtol=1e-8)


def test_mixture_is_the_weighted_sum_of_its_components(rng):
    H, h = _plate(rng, rank=4)
    mu, tau = rng.normal(size=(3, 6)), np.abs(rng.normal(size=(3, 6))) * 0.05
    total, resp = mixture_log_likelihood(mu, tau, H[None], h[None], prior=0.05, scale=0.5)
    spreads = component_spreads(tau, 0.5)
    weights = np.array([0.95] + [0.05 / 7] * 7)
    for n in range(3):
        each = np.array([marginal_log_likelihood(mu[n], spreads[n, c], H, h) for c in range(8)])
        ref = np.log(np.sum(weights * np.exp(each - each.max()))) + each.max()
        np.testing.assert_allclose(total[n, 0], ref, rtol=1e-12)
        np.testing.assert_allclose(resp[n, 0].sum(), 1.0, rtol=1e-12)


def test_log_jacobian_is_that_of_the_stiffness_map(rng):
    for _ in range(5):
        e = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9]) * np.exp(0.2 * rng.normal(size=6))
        ref = np.linalg.slogdet(laminate.stiffness_jacobian(e))[1]
        np.testing.assert_allclose(log_jacobian(e), ref, rtol=1e-12)


def test_population_prior_is_the_case_prior_carried_to_log_mu():
    """``ln f(ln mu)`` = the Gaussian prior on b at b(mu) + ln|db/de| + sum ln mu (+ const)."""
    from bayesplate.likelihood.posterior import prior_in_stiffness

    mean = np.array([140e9, 9e9, 0.30, 3.5e9, 3.5e9, 2.5e9])
    mu_b, V_b = prior_in_stiffness(mean, mean * 0.2)
    d = PopulationDensity([], mu_b, V_b)
    values = []
    for s in (0.9, 1.0, 1.1):
        mu = mean * s
        b = laminate.stiffness_from_engineering(mu)
        ref = multivariate_normal(mu_b, V_b).logpdf(b)
        ref += np.linalg.slogdet(laminate.stiffness_jacobian(mu))[1] + np.log(mu).sum()
        theta = np.concatenate([np.log(mu), np.log(np.full(6, 0.1))])
        values.append(d.log_prior(theta)[0] - ref)
    np.testing.assert_allclose(values, values[0], atol=1e-9)  # equal up to one constant


@pytest.fixture(scope="module")
def study():
    return population_coverage


def test_linearised_likelihood_has_the_exact_gradient_at_its_point(study, rng):
    """``h - H z0`` is the gradient of ln L in ``z`` at ``z0`` (central differences)."""
    from bayesplate.likelihood.posterior import GaussianProblem
    from bayesplate.sampling.plate_laplace import linearise

    c = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    case, model = study.synthetic_plate("P", study.GEOMETRIES[0], c, rng)
    problem = GaussianProblem.from_case(case, model)
    z0 = np.log(c * 1.02)
    lap = linearise(problem, laminate.stiffness_from_engineering(np.exp(z0)))

    def loglik(z):
        return problem.log_likelihood(laminate.stiffness_from_engineering(np.exp(z)))

    step = 1e-5  # central differences: truncation ~step^2, round-off ~1e-16 lnL / step
    fd = [(loglik(z0 + step * e) - loglik(z0 - step * e)) / (2 * step) for e in np.eye(6)]
    np.testing.assert_allclose(lap.h - lap.H @ z0, fd, rtol=1e-4, atol=1e-3)
    # the same likelihood in y = (in-plane stiffness, shear compliance): the same gradient
    from bayesplate.sampling.plate_marginal import coordinates, coordinates_jacobian

    y0 = coordinates(np.exp(z0))
    J = coordinates_jacobian(np.exp(z0))
    np.testing.assert_allclose(J.T @ (lap.a - lap.A @ y0), fd, rtol=1e-4, atol=1e-3)


def _y_plate(study, rng):
    """A synthetic plate's likelihood in ``y`` (A, a) and that Gaussian as a function of ``z``."""
    from bayesplate.likelihood.posterior import GaussianProblem
    from bayesplate.sampling.plate_laplace import linearise
    from bayesplate.sampling.plate_marginal import coordinates

    c = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    case, model = study.synthetic_plate("P", study.GEOMETRIES[0], c, rng)
    problem = GaussianProblem.from_case(case, model)
    lap = linearise(problem, laminate.stiffness_from_engineering(c))

    def loglik(z):  # the Gaussian in y, through the exact map y(z)
        y = coordinates(np.exp(z))
        return np.sum(y * (lap.a - 0.5 * y @ lap.A.T), axis=-1)

    return np.log(c), lap, loglik


def _importance(log_mu, tau, lap, loglik, rng, n=200_000):
    """``ln int L N(z; m, tau^2) dz`` by importance sampling from a widened Gaussian."""
    from bayesplate.sampling.plate_marginal import conditional_y

    mean, cov = conditional_y(log_mu, tau, lap.A, lap.a)
    q = multivariate_normal(mean, 2.0 * cov)
    z = q.rvs(n, random_state=rng)
    prior = multivariate_normal(log_mu, np.diag(tau**2))
    w = loglik(z) + prior.logpdf(z) - q.logpdf(z)
    top = w.max()
    weights = np.exp(w - top)
    rel_se = np.std(weights) / np.mean(weights) / np.sqrt(n)
    return top + np.log(np.mean(weights)), rel_se, z, weights


# the Laplace's own error (the conditional is not Gaussian in z), measured on three plates:
# at most 0.008 nats at spread 0.02, 0.028 at 0.1 and 0.090 at 0.25 (it grows with the spread)
@pytest.mark.parametrize(("spread", "tol"), [(0.02, 0.02), (0.1, 0.05), (0.25, 0.15)])
def test_marginal_in_y_is_the_importance_sampled_integral(study, rng, spread, tol):
    """The Laplace at the conditional mode against an importance-sampled reference."""
    from bayesplate.sampling.plate_marginal import marginal_y

    z_true, lap, loglik = _y_plate(study, rng)
    log_mu = z_true + np.array([0.05, -0.03, -0.4, 0.02, 0.1, -0.2])  # nu12 far off
    tau = np.full(6, spread)
    reference, rel_se, _, _ = _importance(log_mu, tau, lap, loglik, rng)
    assert rel_se < 0.01
    assert abs(marginal_y(log_mu, tau, lap.A, lap.a) - reference) < tol


def test_marginal_in_y_is_the_likelihood_at_the_mean_as_the_spread_vanishes(study, rng):
    from bayesplate.sampling.plate_marginal import marginal_y

    z_true, lap, loglik = _y_plate(study, rng)
    log_mu = z_true + np.array([0.01, -0.02, 0.3, 0.0, 0.05, -0.1])
    value = marginal_y(log_mu, np.full(6, 1e-7), lap.A, lap.a)
    np.testing.assert_allclose(value, loglik(log_mu), rtol=0, atol=1e-6)


def test_conditional_in_y_has_the_importance_sampled_moments(study, rng):
    from bayesplate.sampling.plate_marginal import conditional_y

    z_true, lap, loglik = _y_plate(study, rng)
    log_mu, tau = z_true + np.array([0.05, -0.03, -0.4, 0.02, 0.1, -0.2]), np.full(6, 0.1)
    _, _, z, w = _importance(log_mu, tau, lap, loglik, rng)
    w = w / w.sum()
    mean_is = w @ z
    sd_is = np.sqrt(w @ (z - mean_is) ** 2)
    mean, cov = conditional_y(log_mu, tau, lap.A, lap.a)
    sd = np.sqrt(np.diag(cov))
    # measured on three plates at spread 0.1: at most 0.066 sd apart, sd within 1.4 %
    assert np.all(np.abs(mean - mean_is) < 0.1 * sd_is)
    np.testing.assert_allclose(sd, sd_is, rtol=0.05)


def test_plate_mode_is_b_where_b_converges(study, rng):
    from bayesplate.estimators import run
    from bayesplate.likelihood.posterior import GaussianProblem
    from bayesplate.sampling.plate_laplace import plate_mode

    c = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    case, model = study.synthetic_plate("P", study.GEOMETRIES[1], c, rng)
    problem = GaussianProblem.from_case(case, model)
    b = run(problem, "B", tol=1e-9)
    mode = plate_mode(problem)
    assert b.converged and mode.converged
    # both minimise S_B: equal to the iterations' tolerance (1e-9 relative change)
    np.testing.assert_allclose(mode.constants, b.constants, rtol=1e-5)
    np.testing.assert_allclose(mode.sd, b.sd, rtol=1e-3)  # Laplace in z vs in b, first order


TRUE_MU = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])


def _population(study, seed, tau, offsets=None):
    from bayesplate.likelihood.posterior import prior_in_stiffness

    rng = np.random.default_rng(seed)
    fits, truths = study.population(rng, TRUE_MU, np.asarray(tau), offsets=offsets)
    return fits, truths, prior_in_stiffness(study.PRIOR_MEAN, study.PRIOR_SD)


@pytest.mark.slow
def test_synthetic_population_converges_and_covers_the_truth(study):
    from bayesplate.sampling import sample_population

    tau = np.array([0.04, 0.05, 0.04, 0.03, 0.06, 0.06])
    fits, _, (mu_b, V_b) = _population(study, 11, tau)
    r = sample_population(fits, mu_b, V_b, rng=5, min_ess=400)
    assert r.converged and r.rhat_max < 1.01 and r.ess_min >= 400, r.message
    assert np.all((r.hdi[0] <= TRUE_MU) & (TRUE_MU <= r.hdi[1]))
    assert np.all((r.tau_hdi[0] <= tau) & (tau <= r.tau_hdi[1]))
    assert not r.flagged


@pytest.mark.slow
def test_without_spread_the_population_mean_is_the_shared_answer(study):
    """Identical plates: the population's mean is the shared-constants B answer within its sd."""
    from bayesplate.estimators import run
    from bayesplate.sampling import sample_population
    from bayesplate.sampling.stacked import joint_problem

    fits, _, (mu_b, V_b) = _population(study, 12, np.zeros(6))
    shared = run(joint_problem([f.problem for f in fits]), "B", tol=1e-9, tracking="off")
    assert shared.converged, shared.message
    r = sample_population(fits, mu_b, V_b, rng=6, min_ess=400)
    assert r.converged
    assert np.all(np.abs(r.mean - shared.constants) < shared.sd), r.mean / shared.constants


@pytest.mark.slow
def test_a_plate_fifteen_percent_low_on_e1_is_flagged(study):
    from bayesplate.sampling import sample_population

    offsets = np.ones((10, 6))
    offsets[3, 0] = 0.85
    tau = np.full(6, 0.02)
    fits, _, (mu_b, V_b) = _population(study, 13, tau, offsets)
    r = sample_population(fits, mu_b, V_b, rng=7, min_ess=400)
    # flagged, alone, on E1. Its probability is 0.60, not near 1, and rightly: with ten plates
    # an E1 spread of about 5 % explains the plate within ~2 nats of the outlier's component
    # (whose prior weight is 0.05 / 7); the other nine plates stay at 0.014-0.033
    assert r.flagged == (3,), np.round(r.outlier, 3)
    assert r.outlier_constant[3] == 0  # E1
    assert np.max(np.delete(r.outlier, 3)) < 0.1
    # the outlier does not widen the material's E1 spread: its truth is still covered
    assert r.tau_hdi[0, 0] <= 0.02 <= r.tau_hdi[1, 0]


@pytest.mark.slow
def test_study_quick_tier(study):
    """One replicate of the quick tier (10 plates) converges and covers most parameters."""
    s = study.main(quick=True)
    assert s["n"] == 1 and s["rhat_max"] < 1.01 and s["ess_min"] >= 400
    assert s["all_mu"] >= 4 / 6 and s["all_tau"] >= 4 / 6  # one replicate: most covered


@pytest.fixture(scope="module")
def case_files(tmp_path_factory):
    """Four plates' case files (the fourth E1 15 % low), on a 12 x 6 mesh."""
    many = many_plates
    folder = tmp_path_factory.mktemp("plates")
    return many.write_cases(folder, odd=True, mesh=(12, 6), data_mesh=(24, 12))


def test_cli_hierarchical_refuses_other_priors_in_one_line(case_files, tmp_path, capsys):
    from bayesplate.cli.main import main

    other = tmp_path / "other.toml"
    other.write_text(
        case_files[1].read_text().replace("E1_GPa = { mean = 140", "E1_GPa = { mean = 99")
    )
    assert main(["sample", str(case_files[0]), str(other), "--hierarchical"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "prior.E1_GPa" in err and str(other) in err
    assert main(["sample", str(case_files[0]), "--hierarchical"]) == 2
    assert "several case files" in capsys.readouterr().err


#: the sampler's options of the pool's runs (the hierarchical command and the batch's step)
_POOL = ["--seed", "1", "--workers", "2", "--walkers", "24", "--min-ess", "400"]
_POOL += ["--max-steps", "20000"]


@pytest.fixture(scope="module")
def pool_run(case_files, tmp_path_factory):
    """``sample --hierarchical`` on the pool: (output folder, standard output, JSON)."""
    import contextlib
    import io
    import json

    from bayesplate.cli.main import main

    folder = tmp_path_factory.mktemp("pool")
    argv = ["sample", *map(str, case_files), "--hierarchical", *_POOL, "-o", str(folder)]
    argv += ["--out", str(folder / "pop.nc"), "--json", str(folder / "pop.json")]
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        status = main(argv)
    assert status == 0
    return folder, stdout.getvalue(), json.loads((folder / "pop.json").read_text())


@pytest.mark.slow
def test_cli_hierarchical_on_the_pool_writes_table_json_netcdf_figure(pool_run):
    from bayesplate.sampling.stopping import load_arviz

    folder, text, doc = pool_run
    assert "4 plates of one material" in text and "P(outlier)" in text and "E1_GPa" in text
    assert doc["status"] == "converged" and len(doc["plates"]) == 4
    assert doc["chain"]["rhat_max"] < 1.01
    idata = load_arviz().from_netcdf(str(folder / "pop.nc"))
    assert idata.posterior["plate"].shape[-2:] == (4, 6)
    assert (folder / "population.png").stat().st_size > 0


def test_mixture_in_y_puts_both_forms_on_one_level(study, rng):
    """The population's component is ``marginal_y``; the wide ones, in ``z``, meet it at ``z0``."""
    from bayesplate.sampling.plate_marginal import Plates, marginal_y, mixture_y
    from bayesplate.sampling.population import component_log_weights

    z_true, lap, loglik = _y_plate(study, rng)
    plates = Plates.of([lap, lap])
    log_mu = (z_true + np.array([0.02, 0.01, -0.1, 0.0, 0.05, -0.05]))[None]
    tau = np.full((1, 6), 0.08)
    total, resp = mixture_y(log_mu, tau, plates, 0.05, 0.5)
    own = marginal_y(log_mu, tau, lap.A, lap.a) + component_log_weights(0.05)[0]
    np.testing.assert_allclose(np.log(resp[0, :, 0]) + total[0], own[0], atol=1e-9)
    np.testing.assert_allclose(resp.sum(axis=-1), 1.0, atol=1e-12)
    # at the plate's own point and no spread, the z form is the b form's likelihood there
    q = lap.z0 @ (lap.h - 0.5 * lap.H @ lap.z0)
    np.testing.assert_allclose(q + plates.offset[0], loglik(lap.z0), rtol=1e-12)


@pytest.mark.slow
def test_batch_population_step_is_the_hierarchical_command(case_files, pool_run, tmp_path, capsys):
    """``batch --steps population``: the folder's cases as one population, with the numbers
    of ``sample --hierarchical`` on the same files and options."""
    import json
    from pathlib import Path

    from test_interrupt import _same_numbers

    from bayesplate.cli.main import main

    out = tmp_path / "out"
    argv = ["batch", str(case_files[0].parent), "-o", str(out), "--steps", "population", *_POOL]
    assert main(argv) == 0
    assert "4 plates of one material" in capsys.readouterr().out
    doc = json.loads((out / "population.json").read_text())
    assert doc["status"] == "converged" and len(doc["plates"]) == 4
    names = sorted(Path(p["file"]).name for p in doc["plates"])
    assert names == sorted(f.name for f in case_files)
    _same_numbers(doc, pool_run[2])
    assert (out / "population.nc").stat().st_size > 0
    assert (out / "population.png").stat().st_size > 0
