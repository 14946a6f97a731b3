"""One material, many plates: the joint posterior and which plate disagrees (issue 17).

References independent of the code under test: each plate's own single-plate problem (the
joint density is their sum plus one prior), the closed form of a linear-Gaussian problem
(the joint precision is the sum of the plates' data precisions plus the prior's), and the
true constants of synthetic plates computed on a finer mesh.
"""

from dataclasses import dataclass

import numpy as np
import pytest

from bayesplate import laminate
from bayesplate.likelihood.posterior import GaussianProblem, prior_in_stiffness
from bayesplate.sampling import (
    PlatesMismatch,
    WhitenedLogPosterior,
    check_plates,
    joint_problem,
    plate_checks,
    prepare_joint,
    sample_plates,
    sample_problem,
)
from bayesplate.sampling.plate_checks import predictive_check
from studies import many_plates as study

TRUE = study.TRUE
B_TRUE = laminate.stiffness_from_engineering(TRUE)


# ----------------------------------------------------------------- linear-Gaussian plates


@dataclass(frozen=True)
class _Modal:
    eigenvalues: np.ndarray
    sensitivities: np.ndarray


class _Linear:
    """``g(b) = g0 + A (b - b0)``: a linear forward model (the same shape as a plate's)."""

    def __init__(self, A, g0, b0):
        self.A, self.g0, self.b0 = A, g0, b0

    def __call__(self, b, n_modes=None):
        return _Modal(self.g0 + self.A @ (np.asarray(b) - self.b0), self.A.copy())


@dataclass
class _LinearSetup:
    """Duck-typed SamplingSetup of a linear plate (what the plate checks use)."""

    problem: GaussianProblem
    fast = None

    def forward_with_sensitivities(self):
        return self.problem.forward

    def problem_on_fast_model(self):
        return self.problem


def _prior():
    from bayesplate.io import bundled_case_path, load_case

    prior = load_case(bundled_case_path("plate1")).prior
    return prior_in_stiffness(prior.mean, prior.sd)


def linear_plates(rng, n=3, m=8, shift=None):
    """`n` linear plates of one material (data at ``B_TRUE``, 1 % noise); shift: last off."""
    from bayesplate.matching.pairing import Pairing

    mu_b, V_b = _prior()
    problems = []
    for p in range(n):
        g0 = np.sort(rng.uniform(1e7, 1e9, m))
        A = g0[:, None] / B_TRUE[None, :] * rng.uniform(0.0, 1.0, (m, 6))
        A[:, 2] *= 0.1  # C12 weakly identified, as in plates
        b_data = B_TRUE if shift is None or p < n - 1 else B_TRUE * shift
        sd = 0.01 * g0
        Y = g0 + A @ (b_data - B_TRUE) + sd * rng.standard_normal(m)
        fwd = _Linear(A, g0, B_TRUE)
        problems.append(GaussianProblem(Y, np.diag(sd**2), mu_b, V_b, fwd, Pairing(np.arange(m))))
    return problems


def _closed_form(problems):
    """Posterior mean and covariance of ``b`` (Pa) of linear plates sharing ``b``."""
    p0 = problems[0]
    prec = np.linalg.inv(p0.V_b)
    rhs = prec @ p0.mu_b
    for p in problems:
        A, g0, b0 = p.forward.A, p.forward.g0, p.forward.b0
        W = np.linalg.inv(p.V_Y)
        prec = prec + A.T @ W @ A
        rhs = rhs + A.T @ W @ (p.Y - g0 + A @ b0)
    cov = np.linalg.inv(prec)
    return cov @ rhs, cov


def test_joint_problem_is_the_stack_of_the_plates(rng):
    problems = linear_plates(rng)
    joint = joint_problem(problems)
    mean, cov = _closed_form(problems)
    assert joint.m == sum(p.m for p in problems)
    # ln f differences equal the closed-form Gaussian's (the normalisations are constants)
    points = rng.multivariate_normal(mean, cov, size=5)
    lp = np.array([joint.log_posterior(b) for b in points])
    prec = np.linalg.inv(cov)
    quad = np.array([-0.5 * (b - mean) @ prec @ (b - mean) for b in points])
    np.testing.assert_allclose(lp - lp[0], quad - quad[0], rtol=1e-6, atol=1e-6)


def test_linear_gaussian_joint_covariance_matches_the_closed_form(rng):
    problems = linear_plates(rng)
    joint = joint_problem(problems)
    mean, cov = _closed_form(problems)
    res = sample_problem(joint, mean, cov, rng=5, min_ess=1500.0, max_steps=4000, progress=False)
    assert res.converged
    sd = np.sqrt(np.diag(cov))
    ess = res.ess_bulk  # per engineering constant; b's are as well mixed (same coordinates)
    n_eff = float(np.min(ess))
    # Monte-Carlo errors: of a mean sd / sqrt(ESS), of an sd about sd / sqrt(2 ESS)
    np.testing.assert_array_less(np.abs(res.mean_b - mean), 5 * sd / np.sqrt(n_eff))
    sd_mc = np.sqrt(np.diag(res.covariance_b))
    np.testing.assert_array_less(np.abs(sd_mc / sd - 1), 5 / np.sqrt(2 * n_eff))
    # every plate alone is wider in every coefficient
    for p in problems:
        single = np.sqrt(np.diag(_closed_form([p])[1]))
        assert np.all(sd < single)


def test_linear_plate_checks_flag_the_unlike_plate_only(rng):
    problems = linear_plates(rng, n=4, shift=np.array([0.85, 1, 1, 1, 1, 1]))
    setups = [_LinearSetup(p) for p in problems]
    checks = plate_checks(setups, _closed_form(problems)[0], B_TRUE)
    assert [c.flagged for c in checks] == [False, False, False, True]
    assert checks[3].status == "flagged" and checks[3].p_rest < 1e-6


def test_linear_predictive_check_is_calibrated():
    """Plates that agree: the leave-one-out p-value below 1 % in about 1 % of replicates."""
    rng = np.random.default_rng(7)
    p_values = []
    for _ in range(300):
        setups = [_LinearSetup(p) for p in linear_plates(rng)]
        p_values.append(predictive_check(setups[0], setups[1:], B_TRUE)[1])
    p_values = np.array(p_values)
    # binomial(300, 0.01): 9 or more has probability 4e-3; the median of a uniform is 0.5
    assert np.sum(p_values < 0.01) <= 8
    assert 0.4 < np.median(p_values) < 0.6


# ----------------------------------------------------------------- case-level rules


def test_check_plates_refuses_mixed_priors_twice_given_and_one_case():
    a, b = study.plates()[:2]
    check_plates([a, b])
    with pytest.raises(PlatesMismatch, match=r"plate 2: case = the same as plate 1"):
        check_plates([a, a])
    other = b.with_prior(b.prior.mean * np.array([1.1, 1, 1, 1, 1, 1]), b.prior.sd)
    with pytest.raises(PlatesMismatch, match=r"plate 2: prior\.E1_GPa = .*one prior") as err:
        check_plates([a, other])
    assert err.value.index == 1 and err.value.key == "prior.E1_GPa"
    with pytest.raises(PlatesMismatch, match="two plates or more"):
        check_plates([a])


@pytest.fixture(scope="module")
def two_plates():
    cases = [
        study.synthetic_plate(n, a, b, h, TRUE, s, mesh=(10, 6), data_mesh=(10, 6))
        for n, a, b, h, s in study.PLATES[:2]
    ]
    return prepare_joint(cases, rng=3)


def test_joint_density_is_the_sum_of_the_plates_plus_one_prior(rng, two_plates):
    setup = two_plates
    est = setup.estimate
    density = WhitenedLogPosterior(setup.problem, est.b, est.covariance_b, setup.sampling_forward())
    singles = [s.problem.with_forward(s.sampling_forward()) for s in setup.setups]
    prior = setup.setups[0].problem
    for z in rng.standard_normal((5, 6)):
        lp, pointwise = density(z)
        b = density.to_b(z)
        reference = sum(p.log_likelihood(b) for p in singles) + prior.log_prior(b)
        np.testing.assert_allclose(lp, reference + density.log_jacobian(z), rtol=1e-12)
        own = [
            WhitenedLogPosterior(s.problem, est.b, est.covariance_b, s.sampling_forward())(z)[1]
            for s in setup.setups
        ]
        np.testing.assert_allclose(pointwise, np.concatenate(own), rtol=1e-12)


# ----------------------------------------------------------------- synthetic plates (slow)


@pytest.mark.slow
def test_three_plates_tighter_than_each_and_cover_the_truth():
    from bayesplate.sampling import sample

    cases = study.plates()
    opts = {"min_ess": 800.0, "max_steps": 3000, "progress": False}
    joint = sample_plates(cases, rng=21, **opts)
    assert joint.sampling.converged and joint.status == "consistent"
    s = joint.sampling
    # the truth within 3 posterior deviations in every constant (the fits' 16 x 10 mesh is
    # stiffer than the data's 32 x 20 by up to 0.5 %: a bias well inside that)
    np.testing.assert_array_less(np.abs(s.mean - TRUE), 3 * s.sd)
    for i, case in enumerate(cases):
        single = sample(case, rng=11 + i, **opts)
        identified = single.sd / case.prior.sd < 0.5  # the data, not the prior, set them
        assert np.all(s.sd[identified] < single.sd[identified]), case.name


@pytest.mark.slow
def test_the_plate_of_another_material_is_flagged():
    cases = study.plates(odd=True)
    setup = prepare_joint(cases, rng=31)
    checks = plate_checks(setup.setups, setup.estimate.b, setup.estimate.b)
    assert [c.flagged for c in checks] == [False, False, False, True]
    assert checks[3].p_rest < 1e-6


# ----------------------------------------------------------------- command line


@pytest.fixture(scope="module")
def case_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plates")
    return study.write_cases(folder, odd=True, mesh=(10, 6), data_mesh=(10, 6))


def test_cli_refuses_a_file_twice_and_another_prior_in_one_line(case_files, capsys):
    from bayesplate.cli.main import main

    a = case_files[0]
    assert main(["sample", str(a), str(a)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(a) in err and "given once" in err
    other = a.with_name("A2.toml")
    other.write_text(a.read_text().replace("E1_GPa = { mean = 140", "E1_GPa = { mean = 141"))
    assert main(["sample", str(a), str(other)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(other) in err and "prior.E1_GPa" in err and "one prior" in err
    assert main(["sample", str(a), str(case_files[1]), "--workers", "2"]) == 2
    assert "--workers" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_several_plates_flags_the_fourth(case_files, tmp_path, capsys):
    import json

    from bayesplate.cli.main import main

    out = tmp_path / "j.json"
    argv = [
        "sample",
        *map(str, case_files),
        "--seed",
        "1",
        "--min-ess",
        "300",
        "-o",
        str(tmp_path),
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "4 plates of one material" in text and text.count("FLAGGED") == 1
    doc = json.loads(out.read_text())
    assert [p["flagged"] for p in doc["plates"]] == [False, False, False, True]
    assert (tmp_path / "plates.png").stat().st_size > 0


def test_hierarchical_density_without_spread_has_the_shared_forms_gradient(two_plates):
    """tau -> 0, no outliers: the population density in ln mu is the shared form's there.

    Each plate's likelihood linearised at the joint MAP z* (its Gauss-Newton gradient is the
    exact one at z*), the population's ln f(ln mu) and the shared form's ln f(b(mu)) plus the
    Jacobian of b -> ln e have the same gradient at ln mu = z*.
    """
    from bayesplate.sampling.hierarchical import PopulationDensity
    from bayesplate.sampling.plate_laplace import linearise

    setup = two_plates
    b_star = setup.estimate.b
    problems = [s.problem.with_forward(s.forward_with_sensitivities()) for s in setup.setups]
    p = setup.setups[0].problem
    density = PopulationDensity(
        [linearise(q, b_star) for q in problems], p.mu_b, p.V_b, outlier_prior=0.0
    )
    shared = joint_problem(problems)
    z_star = np.log(laminate.engineering_from_stiffness(b_star))

    def hier(z):
        return density.log_density_theta(np.concatenate([z, np.full(6, np.log(1e-9))]))[0]

    def joint(z):
        e = np.exp(z)
        jac = np.linalg.slogdet(laminate.stiffness_jacobian(e))[1] + np.sum(z)
        return shared.log_posterior(laminate.stiffness_from_engineering(e)) + jac

    step = 1e-6  # central differences in ln c: truncation ~1e-12, round-off ~1e-16 / 1e-6
    g_h = [(hier(z_star + step * e) - hier(z_star - step * e)) / (2 * step) for e in np.eye(6)]
    g_j = [(joint(z_star + step * e) - joint(z_star - step * e)) / (2 * step) for e in np.eye(6)]
    # the gradients are ~1e1-1e4 (the MAP: the likelihood's and the prior's balance); the
    # fast model's sensitivities are its own eigenvalues' exact derivatives
    np.testing.assert_allclose(g_h, g_j, rtol=1e-4, atol=1e-2)
