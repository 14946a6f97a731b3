"""The measured inputs in the posterior: collapsed draws and the linear input model's certificate.

Tiers: a problem linear in the constants and the inputs, where the joint posterior of (b, z)
is Gaussian in closed form: exact draws of the marginal ``f(b | Y)`` followed by
:func:`inputs_from_chain` must be draws of it (mean and covariance within Monte Carlo error),
and the conditional's gain form against Gaussian conditioning written out; the certificate
against the density's closed form (``lambda ~ 1 / rho`` exactly); Plate 1 with no input
deviation gives today's chain bit for bit and no input rows; ``bayesplate sample`` on Plate 1
(8 x 4 mesh) with a thickness and a density deviation prints and writes the input rows.
"""

import dataclasses
import json
import logging
import types

import numpy as np
import pytest

from bayesplate.io import bundled_case_path, load_case
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.likelihood.input_summary import highest_density_interval
from bayesplate.likelihood.inputs import input_jacobian, input_sources
from bayesplate.likelihood.inputs_posterior import (
    declared_readings,
    draw_inputs,
    input_conditional,
    inputs_from_chain,
    linear_input_certificate,
)
from bayesplate.likelihood.posterior import GaussianProblem, prior_in_stiffness
from bayesplate.matching.pairing import Pairing

SEED = 20070461
N_MC = 4.0  # Monte Carlo errors allowed: a 4-sigma band fails by chance ~6e-5 per check


class _Linear:
    def __init__(self, b, A):
        self.eigenvalues = A @ b
        self.sensitivities = A


def _linear_inputs_problem(rng, m=8):
    """lambda(b) = G b, inputs moving the eigenvalues by B z (B = J_p diag(sd)), 1 % data.

    Readings: thickness, density, length with deviations, width exact (its column of B is 0).
    Returns the marginal problem, the conditional, the exact joint posterior of (b, z) (mean,
    covariance) and the draws of b from the exact marginal.
    """
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, V_b = prior_in_stiffness(e0, e0 / 6, "full")
    G = rng.uniform(0.2, 2.0, size=(m, 6)) * 1e7 / mu[None, :]
    g = G @ (mu * rng.uniform(0.9, 1.1, 6))
    names, value = ("thickness", "density", "length", "width"), np.array([4e-3, 1600, 0.3, 0.2])
    sd = np.array([0.02, 0.01, 0.003, 0.0]) * value
    J = np.column_stack([2 * g / value[0], -g / value[1], -1.5 * g / value[2], -0.5 * g / value[3]])
    J *= rng.uniform(0.7, 1.3, size=J.shape)  # not a common scaling: each mode its own
    V = np.diag((0.01 * g) ** 2)
    B = J * sd[None, :]
    Y = g + B @ rng.standard_normal(4) + np.sqrt(np.diag(V)) * rng.standard_normal(m)
    V_marg = V + B @ B.T

    def forward(b, n_modes):
        return _Linear(b, G)

    problem = GaussianProblem(Y, V_marg, mu, V_b, forward, Pairing(np.arange(m), extra=0))
    conditional = input_conditional(J, np.diag(sd), V, names, value, sd)
    # the joint posterior of theta = (b, z): prior N((mu, 0), diag(V_b, I)), Y = [G B] theta + e
    H = np.hstack([G, B])
    prior_inv = np.zeros((10, 10))
    prior_inv[:6, :6] = np.linalg.inv(V_b)
    prior_inv[6:, 6:] = np.eye(4)
    cov = np.linalg.inv(H.T @ np.linalg.solve(V, H) + prior_inv)
    mean = cov @ (H.T @ np.linalg.solve(V, Y) + prior_inv[:, :6] @ mu)
    # exact draws of the marginal f(b | Y) (z integrated out: V + B B^T)
    W = np.linalg.inv(V_marg)
    P = np.linalg.inv(G.T @ W @ G + np.linalg.inv(V_b))
    m_b = P @ (G.T @ W @ Y + np.linalg.solve(V_b, mu))
    return problem, conditional, mean, cov, (m_b, P)


def test_the_conditional_is_gaussian_conditioning(rng):
    # gain form C B^T V^-1 and (I + B^T V^-1 B)^-1 against conditioning z on r = B z + e
    # written with the joint covariance: E = B^T (B B^T + V)^-1 r, Cov = I - B^T (...)^-1 B
    problem, conditional, _, _, _ = _linear_inputs_problem(rng)
    B = conditional.B
    V = problem.V_Y - B @ B.T
    S = B @ B.T + V
    r = rng.standard_normal(problem.m) * np.sqrt(np.diag(V))
    expected_mean = B.T @ np.linalg.solve(S, r)
    expected_cov = np.eye(4) - B.T @ np.linalg.solve(S, B)
    # two algebraically equal forms, each in a few solves: round-off of a few 1e-16 times the
    # condition numbers (~1e3)
    np.testing.assert_allclose(conditional.gain @ r, expected_mean, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(conditional.covariance, expected_cov, rtol=1e-10, atol=1e-12)
    assert conditional.covariance[3, 3] == pytest.approx(1.0, abs=1e-14)  # width: no data
    assert list(conditional.declared) == [0, 1, 2]


def test_collapsed_draws_are_draws_of_the_joint_posterior(rng):
    # b from the exact marginal, then one z per b from f(z | b, Y): (b, z) must be N(mean,
    # cov) of the joint posterior. Whitened by that posterior, u = L^-1 (theta - mean) must be
    # N(0, I): with N independent draws each mean has sd 1/sqrt(N), each variance sqrt(2/N)
    # and each covariance 1/sqrt(N); N_MC of them allowed.
    problem, conditional, mean, cov, (m_b, P) = _linear_inputs_problem(rng)
    n = 20_000
    samples_b = rng.multivariate_normal(m_b, P, size=n)
    post = inputs_from_chain(
        problem, samples_b, problem.forward, conditional, np.random.default_rng(SEED), max_draws=n
    )
    assert post.names == ("thickness", "density", "length")
    assert post.keys == ("thickness_mm", "density_kg_m3", "length_mm")
    assert np.array_equal(post.rows, np.arange(n))
    z = (post.draws - conditional.value[:3]) / conditional.sd[:3]
    keep = np.r_[0:9]  # b and the three declared readings (width's z is not drawn)
    theta = np.hstack([samples_b, z])
    L = np.linalg.cholesky(cov[np.ix_(keep, keep)])
    u = np.linalg.solve(L, (theta - mean[keep]).T).T
    np.testing.assert_array_less(np.abs(u.mean(axis=0)), N_MC / np.sqrt(n))
    S = np.cov(u, rowvar=False)
    np.testing.assert_array_less(np.abs(np.diag(S) - 1), N_MC * np.sqrt(2 / n))
    off = S[~np.eye(9, dtype=bool)]
    np.testing.assert_array_less(np.abs(off), N_MC / np.sqrt(n))
    # the summary: sd and HDI of the readings from those draws
    assert post.sd[0] == pytest.approx(np.std(post.draws[:, 0], ddof=1), rel=1e-12)
    lo, hi = highest_density_interval(post.draws[:, 1])
    assert (post.hdi[0, 1], post.hdi[1, 1]) == (lo, hi)
    inside = np.mean((post.draws[:, 1] >= lo) & (post.draws[:, 1] <= hi))
    assert inside == pytest.approx(0.94, abs=2 / n)  # floor(0.94 n) gaps: both ends counted


def test_same_seed_same_draws(rng):
    problem, conditional, _, _, (m_b, P) = _linear_inputs_problem(rng)
    samples_b = rng.multivariate_normal(m_b, P, size=500)
    runs = [
        inputs_from_chain(
            problem,
            samples_b,
            problem.forward,
            conditional,
            np.random.default_rng(seed),
            max_draws=200,
        )
        for seed in (5, 5, 6)
    ]
    assert np.array_equal(runs[0].draws, runs[1].draws)
    assert np.array_equal(runs[0].rows, runs[1].rows) and len(runs[0].rows) == 200
    assert not np.array_equal(runs[0].draws, runs[2].draws)
    # the draws are value + sd z, z ~ N(gain r, C): with one residual, their mean is the gain's
    r = np.zeros((40_000, problem.m))
    d = draw_inputs(conditional, r, np.random.default_rng(1))
    # mean 0 within N_MC sd / sqrt(N); width (sd 0) stays at its value exactly
    z = (d[:, :3] - conditional.value[:3]) / conditional.sd[:3]
    np.testing.assert_array_less(np.abs(z.mean(axis=0)), N_MC / np.sqrt(len(r)))
    assert np.all(d[:, 3] == conditional.value[3])


# ----------------------------------------------------------------------------- certificate


def _plate1(**sd):
    case = load_case(bundled_case_path("plate1"))
    return dataclasses.replace(case, plate=dataclasses.replace(case.plate, **sd))


def test_certificate_gives_the_density_closed_form():
    # lambda ~ 1 / rho exactly (M proportional to rho, K independent of it): at rho (1 + d)
    # the linear model lambda (1 - d) misses by lambda (1 / (1 + d) - 1 + d), d = +-2 sd / rho
    case = _plate1(density_sd=30.0)  # 3 %: d = +-0.06
    b = stiffness_from_engineering(case.reference)
    modes = np.arange(14)
    _, A = input_sources(case.plate)
    B = input_jacobian(case, b, modes).J @ A
    lam = -B[:, 1] * case.plate.density / case.plate.density_sd
    sd_lambda = 0.02 * lam
    cert = linear_input_certificate(case, b, B, modes, sd_lambda)
    assert cert.names == ("density",) and cert.n_solves == 3
    for col, d in enumerate((0.06, -0.06)):
        # the eigen solver's round-off (~1e-14 relative) is all that may differ
        np.testing.assert_allclose(cert.relative[0, col], 1 / (1 + d) - 1 + d, rtol=0, atol=1e-9)
    worst = max(0.06**2 / 1.06, 0.06**2 / 0.94)
    assert cert.max_relative == pytest.approx(worst, abs=1e-9)
    assert cert.max_in_sd == pytest.approx(worst / 0.02, abs=1e-7)
    assert cert.passed and cert.status == "ok" and cert.worst[:2] == ("density", "-")


def test_certificate_fails_loudly_beyond_its_mark(caplog):
    # weighed plate: rho = m / (a b h), so bending eigenvalues go about as h^3 at fixed mass;
    # 3 % in h at +-2 sd is about 3 (0.06)^2 = 1 % of an eigenvalue off the line, about 0.5 of
    # Plate 1's 2 % deviation (0.23 at a 2 % thickness deviation: it passes)
    from bayesplate.cli.sample import _input_rows
    from bayesplate.report.markdown import _input_rows as report_rows

    plate = load_case(bundled_case_path("plate1")).plate
    mass = plate.density * plate.length * plate.width * plate.thickness
    case = _plate1(thickness_sd=0.03 * plate.thickness, mass=mass, mass_sd=1e-4)
    assert declared_readings(case.plate)[0][1] == "mass"
    b = stiffness_from_engineering(case.reference)
    modes = np.arange(14)
    names, A = input_sources(case.plate)
    B = input_jacobian(case, b, modes).J @ A
    lam = -B[:, 1] * mass / 1e-4  # B[:, 1] = d lambda / d m sd_m = -lambda sd_m / m
    with caplog.at_level(logging.WARNING, logger="bayesplate.likelihood.inputs_posterior"):
        cert = linear_input_certificate(case, b, B, modes, 0.02 * lam)
    assert cert.names == ("thickness", "mass")
    assert not cert.passed and cert.status == "nonlinear" and cert.worst[0] == "thickness"
    assert 0.25 < cert.max_in_sd < 0.8
    assert any("FAILS" in r.getMessage() for r in caplog.records)
    fake = types.SimpleNamespace(input_posterior=None, input_certificate=cert)
    assert _input_rows(fake)[-1].startswith("WARNING: linear input model")
    text = {"text": str(cert), "passed": False}
    assert report_rows({"input_certificate": text})[0].startswith("**Warning:** linear input")


# ----------------------------------------------------------------------------- the sampler


def test_no_input_sd_gives_todays_chain_and_no_rows():
    from bayesplate.cli.sample import sample_text
    from bayesplate.io import sampling_to_dict
    from bayesplate.sampling import prepare, sample, sample_problem
    from bayesplate.sampling.seeding import streams

    case = load_case(bundled_case_path("plate1"))
    zero = _plate1(thickness_sd=0.0, density_sd=0.0, length_sd=0.0, width_sd=0.0)
    settings = {"progress": False, "min_ess": 300, "max_steps": 400}
    a = sample(case, rng=SEED, **settings)
    b = sample(zero, rng=SEED, **settings)
    assert np.array_equal(a.samples_b, b.samples_b) and np.array_equal(a.mean, b.mean)
    assert a.input_posterior is None and a.input_certificate is None
    # today's path: prepare on the first stream, the chain on the second, nothing else
    _, build, walk = streams(SEED)
    setup = prepare(case, rng=build)
    est = setup.estimate
    chain = sample_problem(
        setup.problem,
        est.b,
        est.covariance_b,
        rng=walk,
        progress=False,
        forward=setup.sampling_forward(),
        box=setup.box,
        min_ess=300,
        max_steps=400,
    )
    assert np.array_equal(a.samples_b, chain.samples_b)
    assert "input" not in sample_text(case, a).splitlines()[-1]
    doc = sampling_to_dict(a, case)
    assert "inputs_posterior" not in doc and "input_certificate" not in doc


def test_cli_sample_shows_the_inputs(tmp_path, capsys):
    from bayesplate.cli import main

    text = bundled_case_path("plate1").read_text()
    text = text.replace(
        "density_kg_m3 = 1000\n",
        "density_kg_m3 = 1000\nthickness_sd_mm = 0.132\ndensity_sd_kg_m3 = 10\n",
    )
    assert "thickness_sd_mm" in text
    path = tmp_path / "plate1_inputs.toml"
    path.write_text(text)
    js = tmp_path / "posterior.json"
    status = main(
        [
            "sample",
            str(path),
            "--seed",
            "3",
            "--min-ess",
            "400",
            "--max-steps",
            "2000",
            "--json",
            str(js),
        ]
    )
    assert status == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split() for line in out.splitlines() if line.strip()}
    assert rows["thickness_mm"][1:3] == ["6.600", "0.132"]  # declared value and sd
    assert rows["density_kg_m3"][1:3] == ["1000.", "10.0"]
    assert "linear input model" in out and "within 0.25 sd: ok" in out
    doc = json.loads(js.read_text())
    inputs = doc["inputs_posterior"]
    assert set(inputs) == {"thickness_mm", "density_kg_m3", "n_draws"}
    h = inputs["thickness_mm"]
    assert h["declared"] == pytest.approx(6.6) and h["declared_sd"] == pytest.approx(0.132)
    assert h["hdi_3%"] < h["mean"] < h["hdi_97%"] and 0 < h["sd"]
    assert doc["input_certificate"]["passed"] and doc["input_certificate"]["status"] == "ok"
    assert set(doc["input_certificate"]["relative"]) == {"thickness", "density"}


def test_report_posterior_section_shows_the_inputs():
    from bayesplate.report.markdown import _sample_lines

    result = {
        "hdi": np.ones((2, 6)) * 1e9,
        "mean": np.ones(6) * 1e9,
        "sd": np.ones(6) * 1e8,
        "ess_bulk": np.ones(6) * 500,
        "rhat": np.ones(6),
        "timings": {"total": 1.0},
        "n_walkers": 32,
        "n_steps": 400,
        "n_burn": 100,
        "acceptance": 0.5,
        "message": "converged",
        "certificate": None,
        "n_full": 0,
        "inputs": "marginal",
        "inputs_given": "thickness 0.132 mm",
    }
    row = {
        "declared": 6.6,
        "declared_sd": 0.132,
        "mean": 6.65,
        "sd": 0.065,
        "hdi_3%": 6.53,
        "hdi_97%": 6.77,
    }
    result["inputs_posterior"] = {"thickness_mm": row}
    result["input_certificate"] = {"text": "linear input model ... ok", "passed": True}
    lines = _sample_lines(result)
    assert "| thickness_mm | 6.600 ± 0.13 | 6.650 ± 0.065 | 6.530 to 6.770 |" in lines
    assert "linear input model ... ok." in lines
    result["inputs_posterior"], result["input_certificate"] = None, None
    assert not any("thickness_mm" in line for line in _sample_lines(result))
