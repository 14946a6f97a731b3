"""ChainOptions and SetupOptions: the same numbers as the keywords they hold, and their checks."""

import dataclasses

import numpy as np
import pytest

from bayesplate.io import bundled_case_path, load_case
from bayesplate.likelihood.posterior import GaussianProblem, prior_in_stiffness
from bayesplate.matching.pairing import Pairing
from bayesplate.plate.model import PlateModel
from bayesplate.sampling import (
    ChainOptions,
    SetupOptions,
    prepare,
    sample,
    sample_problem,
)

SHORT = {"n_walkers": 16, "max_steps": 120, "min_ess": 10.0, "progress": False}


def _linear_problem():
    """g(b) = A b: a cheap problem with Plate 1-like coefficients; its posterior mean and P."""
    rng = np.random.default_rng(11)
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, V_b = prior_in_stiffness(e0, e0 / 6, "full")
    A = rng.uniform(0.2, 2.0, size=(8, 6)) * 1e7 / mu[None, :]
    Y = A @ (mu * rng.uniform(0.9, 1.1, 6))
    V_Y = np.diag((0.01 * Y) ** 2)

    class Linear:
        def __init__(self, b):
            self.eigenvalues, self.sensitivities = A @ b, A

    problem = GaussianProblem(
        Y, V_Y, mu, V_b, lambda b, n: Linear(b), Pairing(np.arange(8), extra=0)
    )
    P = np.linalg.inv(A.T @ np.linalg.solve(V_Y, A) + np.linalg.inv(V_b))
    return problem, mu, P


def test_sample_problem_with_options_is_the_keyword_chain():
    problem, mu, P = _linear_problem()
    keywords = sample_problem(problem, mu, P, rng=5, check_every=10, **SHORT)
    options = ChainOptions(check_every=10, **SHORT)
    given = sample_problem(problem, mu, P, rng=5, options=options)
    # a keyword over the options object wins, as a field of it would
    over = sample_problem(problem, mu, P, rng=5, options=ChainOptions(**SHORT), check_every=10)
    for other in (given, over):
        np.testing.assert_array_equal(keywords.chain, other.chain)
        np.testing.assert_array_equal(keywords.samples_b, other.samples_b)
        assert other.settings["check_every"] == 10


def test_sample_with_options_gives_the_keyword_numbers():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    keywords = sample(case, rng=3, model=model, pairing="order", box_sigma=5.0, **SHORT)
    given = sample(
        case,
        rng=3,
        model=model,
        options=ChainOptions(**SHORT),
        setup_options=SetupOptions(pairing="order", box_sigma=5.0),
    )
    np.testing.assert_array_equal(keywords.samples_b, given.samples_b)
    np.testing.assert_array_equal(keywords.estimate.b, given.estimate.b)
    np.testing.assert_array_equal(keywords.estimate.covariance_b, given.estimate.covariance_b)
    np.testing.assert_array_equal(keywords.settings["box_lower"], given.settings["box_lower"])
    assert keywords.n_full == given.n_full and keywords.settings["n_walkers"] == 16


def test_prepare_with_options_is_prepare_with_keywords():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    keywords = prepare(case, model=model, rng=2, forward="full", pairing="order")
    given = prepare(case, model=model, rng=2, options=SetupOptions(forward="full", pairing="order"))
    assert keywords.fast is None and given.fast is None
    np.testing.assert_array_equal(keywords.estimate.b, given.estimate.b)
    assert keywords.n_full_solves == given.n_full_solves


def test_the_options_objects_check_their_fields():
    with pytest.raises(ValueError, match="n_walkers = 8: need at least 12"):
        ChainOptions(n_walkers=8)
    with pytest.raises(ValueError, match="max_steps = 100: need at least 110"):
        ChainOptions(max_steps=100)
    assert ChainOptions(max_steps=40, tune_rounds=1, tune_steps=10).max_steps == 40
    with pytest.raises(ValueError, match="forward = 'fast'"):
        SetupOptions(forward="fast")
    with pytest.raises(dataclasses.FrozenInstanceError):
        ChainOptions().n_walkers = 64
    # today's keywords, checked the same way through the entry points
    problem, mu, P = _linear_problem()
    with pytest.raises(ValueError, match="n_walkers = 8"):
        sample_problem(problem, mu, P, n_walkers=8)
    with pytest.raises(TypeError, match=r"sample_problem\(\) got unexpected keyword.*n_walker"):
        sample_problem(problem, mu, P, n_walker=16)
    with pytest.raises(TypeError, match="options must be a ChainOptions"):
        sample_problem(problem, mu, P, options=SetupOptions())
    case = load_case(bundled_case_path("plate1"))
    with pytest.raises(TypeError, match=r"sample\(\) got unexpected keyword.*box_sd"):
        sample(case, box_sd=3.0)
    with pytest.raises(TypeError, match=r"prepare\(\) got unexpected keyword.*min_ess"):
        prepare(case, min_ess=100.0)


def test_the_defaults_are_the_keywords_of_before():
    assert ChainOptions() == ChainOptions.of()
    chain = dataclasses.asdict(ChainOptions())
    assert chain == {
        "n_walkers": 32,
        "max_steps": 5000,
        "target_tau_factor": 50.0,
        "min_ess": 2000.0,
        "max_rhat": 1.01,
        "check_every": 20,
        "tune_rounds": 3,
        "tune_steps": 30,
        "moves": None,
        "progress": True,
        "backend_path": None,
    }
    setup = dataclasses.asdict(SetupOptions())
    assert setup == {
        "forward": "reduced",
        "convention": "paper",
        "prior_mean": None,
        "prior_sd": None,
        "pairing": "auto",
        "box_sigma": 6.0,
        "box": None,
        "pilot_mesh": "auto",
        "fast": None,
        "fast_options": None,
        "inputs": "auto",
    }
