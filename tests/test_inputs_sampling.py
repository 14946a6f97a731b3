"""The sampler with uncertain inputs: a full eigenvalue covariance, and prepare's marginal problem.

Tiers: a linear forward model whose eigenvalue errors are correlated (``V_Y = D + J Sigma J^T``,
as with marginalised inputs), where the posterior is closed form; the pointwise terms against
Gaussian conditioning done by hand; the Ritz screen's bound against the misfit itself; Plate 1
with a 2 % thickness deviation: ``prepare`` adds ``J_p Sigma_p J_p^T`` and the box spans the
marginal posterior.
"""

import dataclasses

import numpy as np
import pytest

from bayesplate.io import bundled_case_path, load_case
from bayesplate.likelihood.inputs import input_covariance, input_jacobian
from bayesplate.likelihood.posterior import GaussianProblem, prior_in_stiffness
from bayesplate.matching.pairing import Pairing
from bayesplate.plate.model import PlateModel
from bayesplate.sampling import WhitenedLogPosterior, prepare, sample_problem
from bayesplate.sampling.moves import RitzScreen
from bayesplate.sampling.setup import resolve_inputs

SEED = 20070461
N_MC = 4.0  # Monte Carlo errors allowed: a 4-sigma band fails by chance ~6e-5 per check


class _Linear:
    def __init__(self, b, A):
        self.eigenvalues = A @ b
        self.sensitivities = A


def _correlated_problem(rng, m=10):
    """g(b) = A b with V_Y = 1 % data + a common 3 % scale error (rank one, like thickness)."""
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, V_b = prior_in_stiffness(e0, e0 / 6, "full")
    A = rng.uniform(0.2, 2.0, size=(m, 6)) * 1e7 / mu[None, :]
    b_true = mu * rng.uniform(0.9, 1.1, 6)
    g = A @ b_true
    V_Y = np.diag((0.01 * g) ** 2) + np.outer(0.03 * g, 0.03 * g)
    Y = g + np.linalg.cholesky(V_Y) @ rng.standard_normal(m)

    def forward(b, n_modes):
        return _Linear(b, A)

    problem = GaussianProblem(Y, V_Y, mu, V_b, forward, Pairing(np.arange(m), extra=0))
    W = np.linalg.inv(V_Y)
    P = np.linalg.inv(A.T @ W @ A + np.linalg.inv(V_b))
    mean = P @ (A.T @ W @ Y + np.linalg.solve(V_b, mu))
    return problem, mean, P


def test_sampler_with_correlated_errors_gives_the_closed_form_posterior(rng):
    from bayesplate.sampling.stopping import load_arviz

    problem, mean, P = _correlated_problem(rng)
    sd = np.sqrt(np.diag(P))
    result = sample_problem(
        problem, mean + 0.5 * sd, np.diag(2 * sd**2), rng=3, progress=False, min_ess=1500
    )
    assert result.converged
    az = load_arviz()
    draws = result.samples_b.reshape(-1, result.n_walkers, 6)
    ess = np.array([az.ess(draws[:, :, j].T) for j in range(6)])
    np.testing.assert_array_less(np.abs(result.mean_b - mean), N_MC * sd / np.sqrt(ess))
    var_s = np.diag(result.covariance_b)
    np.testing.assert_array_less(np.abs(var_s / sd**2 - 1), N_MC * np.sqrt(2 / ess))


def test_pointwise_terms_are_leave_one_out_conditionals(rng):
    # ln f(Y_i | Y_-i, b) by Gaussian conditioning on the covariance blocks, written out
    problem, mean, P = _correlated_problem(rng)
    density = WhitenedLogPosterior(problem, mean, P)
    z = np.full(6, 0.3)
    _, pointwise = density(z)
    r = problem.Y - problem.forward(density.to_b(z), 0).eigenvalues
    V = problem.V_Y
    for i in range(problem.m):
        rest = np.delete(np.arange(problem.m), i)
        w = np.linalg.solve(V[np.ix_(rest, rest)], V[rest, i])
        mean_i = w @ r[rest]
        var_i = V[i, i] - V[i, rest] @ w
        expected = -0.5 * ((r[i] - mean_i) ** 2 / var_i + np.log(2 * np.pi * var_i))
        assert pointwise[i] == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_ritz_screen_bound_below_the_misfit_with_correlated_errors(rng):
    # the screen's misfit bound never exceeds r^T V^-1 r for residuals r >= gap
    problem, mean, P = _correlated_problem(rng)
    screen = RitzScreen.__new__(RitzScreen)
    screen._diagonal = False
    W = np.linalg.inv(problem.V_Y)
    scale = np.sqrt(np.diag(problem.V_Y))
    for _ in range(200):
        gap = np.maximum(rng.normal(0, 2, problem.m), 0) * scale
        free = rng.normal(0, 3, problem.m) * scale  # unconstrained where gap is 0
        r = np.where(gap > 0, gap + rng.exponential(0.3, problem.m) * scale, free)
        assert screen._misfit(gap, problem.V_Y) <= r @ W @ r * (1 + 1e-12)


def test_resolve_inputs_default_follows_the_case():
    case = load_case(bundled_case_path("plate1"))
    assert resolve_inputs(case) == "exact"
    plate = dataclasses.replace(case.plate, thickness_sd=1e-5)
    assert resolve_inputs(dataclasses.replace(case, plate=plate)) == "marginal"
    assert resolve_inputs(dataclasses.replace(case, plate=plate), "exact") == "exact"
    weighed = dataclasses.replace(case.plate, mass=0.1, mass_sd=1e-4)  # the mass's sd alone
    assert resolve_inputs(dataclasses.replace(case, plate=weighed)) == "marginal"
    with pytest.raises(ValueError, match="inputs"):
        resolve_inputs(case, "nominal")


@pytest.fixture(scope="module")
def plate1_thickness():
    case = load_case(bundled_case_path("plate1"))
    plate = dataclasses.replace(case.plate, thickness_sd=0.02 * case.plate.thickness)
    case = dataclasses.replace(case, plate=plate)
    model = PlateModel.from_case(case)
    exact = prepare(case, model=model, rng=SEED, inputs="exact")
    marginal = prepare(case, model=model, rng=SEED)
    return case, model, exact, marginal


def test_prepare_marginalises_the_inputs_the_case_gives(plate1_thickness):
    case, model, exact, marginal = plate1_thickness
    assert exact.inputs == "exact" and marginal.inputs == "marginal"
    # the same data, prior and pairing; V_Y gains J Sigma J^T, with J where the pilot was
    assert np.array_equal(marginal.problem.Y, exact.problem.Y)
    assert np.array_equal(marginal.problem.pairing.modes, exact.problem.pairing.modes)
    added = marginal.problem.V_Y - exact.problem.V_Y
    modes = exact.problem.pairing.modes
    at = marginal.input_model.at  # the first marginal MAP (J_p again there: setup docstring)
    assert np.linalg.norm(at - marginal.estimate.b) < 1e-3 * np.linalg.norm(at)
    expected = input_covariance(case, at, modes, mesh=(8, 4))
    # (the subtraction leaves round-off of the largest V_Y entry, ~1e-16 relative)
    np.testing.assert_allclose(
        added, expected, rtol=1e-12, atol=1e-14 * np.abs(marginal.problem.V_Y).max()
    )
    # rank one (thickness only): J_h J_h^T sd_h^2 with d ln lambda / d ln h about 2 in
    # bending (1.5-1.95 on this thick plate's modes)
    rel = input_jacobian(case, at, modes, mesh=(8, 4)).relative[:, 0]
    assert np.all(rel[:12] > 1.4) and np.all(rel[:12] < 2.0)
    assert np.linalg.matrix_rank(added, tol=1e-9 * np.abs(added).max()) == 1
    # the MAP's deviations widen (E1, E2, G12: the thickness-bound ones)
    sd_exact = np.sqrt(np.diag(exact.estimate.covariance))
    sd_marginal = np.sqrt(np.diag(marginal.estimate.covariance))
    assert np.all(sd_marginal[[0, 1, 3]] > 1.1 * sd_exact[[0, 1, 3]])


def test_marginal_box_spans_the_marginal_posterior(plate1_thickness):
    # the fast model's box is placed with the marginal P: the MAP +- 5 of its deviations
    # lies inside it in the well-identified coefficients (the exact pilot's P would give
    # ~6 exact deviations, i.e. ~4 marginal ones, in C11)
    _, _, exact, marginal = plate1_thickness
    est = marginal.estimate
    sd = np.sqrt(np.diag(est.covariance_b))
    box = marginal.box
    for j in (0, 1, 3):
        assert box.lower[j] <= est.b[j] - 5 * sd[j] and est.b[j] + 5 * sd[j] <= box.upper[j]
    assert marginal.certificate.passed
    width = (marginal.box.upper - marginal.box.lower) / (exact.box.upper - exact.box.lower)
    assert width[0] > 1.2


def test_cli_and_report_say_which_inputs_were_used():
    from bayesplate.cli.main import build_parser
    from bayesplate.cli.sample import _inputs_line
    from bayesplate.report.markdown import _inputs_lines

    case = load_case(bundled_case_path("plate1"))
    assert _inputs_line(case, "exact") == "inputs: exact (the case gives no sd)"
    plate = dataclasses.replace(case.plate, thickness_sd=0.11e-3, mass=0.1, mass_sd=1e-4)
    weighed = dataclasses.replace(case, plate=plate)
    assert _inputs_line(weighed, "marginal") == (
        "inputs: marginal (linearised), sd thickness 0.11 mm, mass 0.1 g"
    )
    assert "left out" in _inputs_line(weighed, "exact")
    args = build_parser().parse_args(["sample", "plate1", "--inputs", "exact"])
    assert args.inputs == "exact"
    assert build_parser().parse_args(["sample", "plate1"]).inputs is None  # auto
    assert _inputs_lines({"inputs": "exact"}) == []
    text = _inputs_lines({"inputs": "marginal", "inputs_given": "thickness 0.11 mm"})[0]
    assert "thickness 0.11 mm" in text and "V_Y + J Σ J^T" in text
