"""The Gaussian likelihood and prior: closed forms and independent references."""

from dataclasses import dataclass

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayesplate import laminate
from bayesplate.io import bundled_case_path, load_case
from bayesplate.likelihood.posterior import (
    GaussianProblem,
    observation_covariance,
    observed_eigenvalues,
    prior_in_stiffness,
)
from bayesplate.matching.pairing import Pairing

E_PLATE1 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])


@dataclass
class LinearModal:
    """What a forward model returns, for the linear model g(b) = A b."""

    b: np.ndarray
    eigenvalues: np.ndarray
    sensitivities: np.ndarray
    vectors: np.ndarray


def linear_forward(A):
    def forward(b, n_modes):
        return LinearModal(b, (A @ b)[:n_modes], A[:n_modes], np.eye(len(A))[:, :n_modes])

    return forward


def test_observed_eigenvalues_eq27():
    assert observed_eigenvalues([1.0])[0] == pytest.approx(4 * np.pi**2, rel=1e-15)


def test_observation_covariance_section_3_6():
    # d lambda = d(4 pi^2 f^2)/df df = 8 pi^2 f df, exactly.
    f, df = np.array([611.23, 2002.7]), np.array([6.1123, 20.027])
    dlam = 8 * np.pi**2 * f * df
    np.testing.assert_allclose(np.diag(observation_covariance(f, df, "variance")), dlam**2)
    np.testing.assert_allclose(np.diag(observation_covariance(f, df, "deviation")), dlam)
    with pytest.raises(ValueError, match="observation"):
        observation_covariance(f, df, "sd")


def test_prior_propagation_matches_finite_differences():
    # First-order propagation of one deviation at a time equals the change of b for a tiny
    # step (central difference, error O(h^2) ~ 1e-8 relative for h = 1e-4 of the value).
    sd = 1e-4 * E_PLATE1
    J = laminate.stiffness_jacobian(E_PLATE1)
    for j in range(6):
        step = np.zeros(6)
        step[j] = sd[j]
        db = (
            laminate.stiffness_from_engineering(E_PLATE1 + step)
            - laminate.stiffness_from_engineering(E_PLATE1 - step)
        ) / 2
        np.testing.assert_allclose(np.abs(J[:, j]) * sd[j], np.abs(db), rtol=1e-6, atol=1e-9)


def test_prior_conventions_are_consistent():
    sd = E_PLATE1 / 6
    mu, full = prior_in_stiffness(E_PLATE1, sd, "full")
    _, diag = prior_in_stiffness(E_PLATE1, sd, "variance")
    _, dev = prior_in_stiffness(E_PLATE1, sd, "deviation")
    np.testing.assert_allclose(mu, laminate.stiffness_from_engineering(E_PLATE1))
    np.testing.assert_allclose(np.diag(diag), np.diag(full))
    np.testing.assert_allclose(np.diag(dev) ** 2, np.diag(full))
    assert full[0, 1] != 0  # C11 and C22 share E1, E2 and nu12
    assert np.count_nonzero(diag - np.diag(np.diag(diag))) == 0


def _linear_problem(rng, m=8):
    b0 = laminate.stiffness_from_engineering(E_PLATE1)
    A = rng.uniform(0.5, 1.5, size=(m, 6)) * 1e7 / b0[None, :]
    Y = A @ (b0 * rng.uniform(0.9, 1.1, 6))
    V_Y = np.diag((0.02 * Y) ** 2)
    mu, V_b = prior_in_stiffness(E_PLATE1, E_PLATE1 / 6, "full")
    pairing = Pairing(np.arange(m), extra=0)
    return GaussianProblem(Y, V_Y, mu, V_b, linear_forward(A), pairing), A


def test_log_densities_match_scipy():
    # eqs. 3 and 4 are the multivariate normal densities; scipy is the independent reference.
    rng = np.random.default_rng(3)
    problem, A = _linear_problem(rng)
    b = problem.mu_b * 1.05
    ref_lik = multivariate_normal(A @ b, problem.V_Y).logpdf(problem.Y)
    ref_pri = multivariate_normal(problem.mu_b, problem.V_b).logpdf(b)
    assert problem.log_likelihood(b) == pytest.approx(ref_lik, rel=1e-10)
    assert problem.log_prior(b) == pytest.approx(ref_pri, rel=1e-10)
    assert problem.log_posterior(b) == pytest.approx(ref_lik + ref_pri, rel=1e-10)


def test_log_posterior_is_minus_infinity_outside_the_lamina():
    rng = np.random.default_rng(4)
    problem, _ = _linear_problem(rng)
    bad = problem.mu_b.copy()
    bad[4] = -1.0  # C44 < 0
    assert problem.log_prior(bad) == -np.inf
    assert problem.log_posterior(bad) == -np.inf
    assert problem.n_solves == 0  # no forward solve for an impossible lamina


def test_objective_is_eq5():
    rng = np.random.default_rng(5)
    problem, A = _linear_problem(rng)
    b = problem.mu_b * 0.97
    r, d = problem.Y - A @ b, b - problem.mu_b
    ref = r @ np.linalg.solve(problem.V_Y, r) + d @ np.linalg.solve(problem.V_b, d)
    assert problem.objective(b) == pytest.approx(ref, rel=1e-10)


def test_from_case_plate1_pairs_by_order_and_counts_solves():
    case = load_case(bundled_case_path("plate1"))
    problem = GaussianProblem.from_case(case, _Plate1Stub(case))
    assert problem.pairing.how == "order"
    np.testing.assert_array_equal(problem.pairing.modes, np.arange(14))
    prediction = problem.predict(problem.mu_b)
    assert prediction.g.shape == (14,) and prediction.S.shape == (14, 6)
    assert problem.n_solves == 1
    # sd of the eigenvalue is 2 sigma_rel lambda for df = sigma_rel f (section 3.6)
    np.testing.assert_allclose(np.sqrt(np.diag(problem.V_Y)), 0.02 * problem.Y)


class _Plate1Stub:
    """A stand-in forward model (no finite elements needed to check the wiring)."""

    def __init__(self, case):
        self.n = 0

    def solve(self, b, n_modes):
        self.n = n_modes
        lam = np.arange(1, n_modes + 1) * 1e7
        return LinearModal(b, lam, np.ones((n_modes, 6)), np.eye(20)[:, :n_modes])
