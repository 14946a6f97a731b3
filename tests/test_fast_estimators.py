"""The estimators on the certified fast model: the full model's answers, to the tolerance.

The reference of every test is the same estimator run on the full finite-element model
(``forward="full"``), an independent computation of the same fixed point.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from bayesplate.estimators import (
    FAST_MIN_DOFS,
    FastModelWarning,
    case_fast_model,
    estimate,
    estimate_on_fast,
    resolve_forward,
)
from bayesplate.estimators import fast as fast_module
from bayesplate.io import bundled_case_path, load_case
from bayesplate.plate.model import PlateModel

TOL = 1e-3  # the estimators' stopping tolerance on b (section 2.4)


@pytest.fixture(scope="module")
def plate1():
    case = load_case(bundled_case_path("plate1"))
    return case, PlateModel.from_case(case)


# the paper's runs that converge in tens of iterations (Tables 4 and 11); on the case's own
# prior MVE creeps along the weakly determined nu12 for 86 iterations with its relative
# change near TOL, and whether it is called converged or stalled there turns on the 4e-6
# difference of the two models (see reports/estimators_fast.md)
RUNS = {
    "B": {"prior_mean": [120e9, 8e9, 0.25, 3.6e9, 3.6e9, 2.4e9], "d": 1 / 3},
    "MVE": {"prior_mean": [120e9, 8e9, 0.25, 3.6e9, 3.6e9, 2.4e9], "d": 1 / 3},
    "MVE-mod": {
        "prior_mean": [180e9, 12e9, 0.3, 2.4e9, 2.4e9, 1.6e9],
        "d": 1 / 6,
        "stage2_factor": 2.0,
    },
}


def _run(case, model, method, **kwargs):
    # pairing by order: these are the paper's runs, and the subject is the fast model's path
    spec = dict(RUNS[method], pairing="order")
    mean = np.array(spec.pop("prior_mean"))
    sd = spec.pop("d") * mean
    return estimate(case, method, model=model, prior_mean=mean, prior_sd=sd, **spec, **kwargs)


@pytest.mark.parametrize("method", ["B", "MVE", "MVE-mod"])
def test_fast_answers_are_the_full_models_to_the_stopping_tolerance(plate1, method):
    case, model = plate1
    full = _run(case, model, method, forward="full")
    fast = _run(case, model, method, forward="fast")
    assert full.check is None and fast.check is not None
    assert fast.status == full.status == "converged"
    assert fast.check.confirmed and fast.check.max_rel_error <= fast.check.tolerance
    np.testing.assert_allclose(fast.b, full.b, rtol=TOL)
    # the fixed points agree far better than TOL: the fast model's error is ~1e-6 here
    np.testing.assert_allclose(fast.constants, full.constants, rtol=1e-4)
    assert abs(fast.iterations - full.iterations) <= 1
    # the check compares the answer's paired frequencies with the full model's there
    np.testing.assert_allclose(fast.check.fast_Hz, fast.frequency_Hz)
    again = model.solve(fast.b, int(fast.modes.max())).frequency_Hz[fast.modes - 1]
    np.testing.assert_allclose(fast.check.full_Hz, again, rtol=1e-12)


def test_the_same_seed_gives_the_same_numbers_and_a_shared_model_is_reused(plate1):
    case, model = plate1
    first, shared = estimate_on_fast(case, "B", model, rng=3, pairing="order")
    again, _ = estimate_on_fast(case, "B", model, rng=3, pairing="order")
    np.testing.assert_array_equal(first.b, again.b)
    np.testing.assert_array_equal(first.check.full_Hz, again.check.full_Hz)
    reused, grown = estimate_on_fast(case, "MVE", model, shared, pairing="order")
    assert reused.check.build_solves == shared.build_solves  # no second build
    assert grown.reduced.size >= shared.reduced.size  # enriched, never shrunk


def _poor_fast_model(case, model):
    """A fast model of two snapshots (the prior mean and one more) over the prior box."""
    mean = np.array(RUNS["B"]["prior_mean"])
    return case_fast_model(
        case,
        model,
        case.measured.size + 2,
        prior_mean=mean,
        prior_sd=RUNS["B"]["d"] * mean,
        n_snapshots=1,
        n_test=2,
        n_probe=0,
        max_rounds=1,
    )


def _run_on(case, model, fast, method="B"):
    mean = np.array(RUNS[method]["prior_mean"])
    return estimate_on_fast(
        case,
        method,
        model,
        fast,
        prior_mean=mean,
        prior_sd=RUNS[method]["d"] * mean,
        pairing="order",
    )


def test_an_answer_the_full_model_corrects_is_enriched_and_confirmed(plate1):
    # a poor fast model: its answer is off, the full model's modes there join the basis,
    # and the run on the enriched model is confirmed and is the full model's answer
    case, model = plate1
    poor = _poor_fast_model(case, model)
    full = _run(case, model, "B", forward="full")
    result, enriched = _run_on(case, model, poor)
    assert result.check.rounds >= 2 and result.check.confirmed
    assert enriched.reduced.size > poor.reduced.size
    np.testing.assert_allclose(result.b, full.b, rtol=TOL)


def test_an_answer_the_full_model_contradicts_is_unconfirmed_and_loud(plate1, monkeypatch):
    case, model = plate1
    poor = _poor_fast_model(case, model)
    monkeypatch.setattr(fast_module, "CONFIRM_ROUNDS", 1)
    with pytest.warns(FastModelWarning, match="disagrees"):
        result, _ = _run_on(case, model, poor)
    assert result.status == "unconfirmed" and not result.converged
    assert not result.check.confirmed
    assert result.check.max_rel_error > result.check.tolerance


def test_iterates_off_the_box_are_checked_and_the_path_is_the_full_one(plate1):
    # the case's own prior is 3 to 6 deviations from the plate: MVE's path leaves the
    # prior's box at once and creeps along nu12 for 86 iterations with its relative change
    # near TOL; the reduced model, checked by the full one in a trust region off the box and
    # enriched where it missed, keeps the full path's iteration count and fixed point
    case, model = plate1
    full = estimate(case, "MVE", model=model, forward="full", pairing="order")
    fast = estimate(case, "MVE", model=model, forward="fast", pairing="order")
    # both stopped; the answer is flagged alike (G23 six prior sd from this prior's mean)
    assert fast.converged and full.converged and fast.status == full.status
    assert fast.iterations == full.iterations
    assert 0 < fast.check.n_full_solves < full.n_solves / 4
    np.testing.assert_allclose(fast.b, full.b, rtol=TOL)


def test_off_the_box_the_reduced_model_is_enriched_where_it_misses(plate1):
    case, model = plate1
    fast = case_fast_model(case, model, case.measured.size + 2)
    boxed = fast_module.BoxedModel(model, fast.reduced, fast.certificate.tolerance)
    far = fast.reduced.box.upper * 1.8  # well off the box
    got = boxed.solve(far, case.measured.size)
    want = model.solve(far, case.measured.size)
    assert boxed.n_full == 1
    np.testing.assert_allclose(got.eigenvalues, want.eigenvalues, rtol=2e-4)
    boxed.solve(far * 1.001, case.measured.size)  # near a checked point: trusted
    assert boxed.n_full == 1


def test_auto_takes_the_fast_path_on_large_meshes_only():
    small = SimpleNamespace(mesh=SimpleNamespace(n_dofs=FAST_MIN_DOFS))
    large = SimpleNamespace(mesh=SimpleNamespace(n_dofs=FAST_MIN_DOFS + 1))
    assert resolve_forward("auto", small) == "full"
    assert resolve_forward("auto", large) == "fast"
    assert resolve_forward("full", large) == "full"
    with pytest.raises(ValueError, match="forward = 'reduced'"):
        resolve_forward("reduced", large)


def test_by_likelihood_the_fast_path_settles_the_same_assignment(plate1):
    case, model = plate1
    dropped = case.with_measured(case.measured.select(np.r_[0:3, 4 : case.measured.size]))
    full = estimate(dropped, "B", model=model, pairing="likelihood", forward="full")
    fast = estimate(dropped, "B", model=model, pairing="likelihood", forward="fast")
    np.testing.assert_array_equal(fast.pairing.modes, full.pairing.modes)
    np.testing.assert_array_equal(fast.pairing.assignment.unobserved, [3])
    assert fast.check.confirmed
    np.testing.assert_allclose(fast.b, full.b, rtol=TOL)
