"""fast_model's settings as a FastModelOptions object and as keywords: the same model."""

import warnings

import numpy as np
import pytest

from bayesplate.io import bundled_case_path, load_case
from bayesplate.plate.model import PlateModel
from bayesplate.reduced import (
    FastModelOptions,
    ReducedModelWarning,
    fast_model,
    prior_stiffness,
    stiffness_box,
)

N_MODES = 14


@pytest.fixture(scope="module")
def plate1():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case, mesh=(8, 4))
    mean_b, _ = prior_stiffness(case.prior)
    return model, mean_b, stiffness_box(case.prior)


def test_options_object_and_keywords_give_the_same_model(plate1):
    model, mean_b, box = plate1
    settings = dict(n_snapshots=3, n_test=2, n_probe=2, max_rounds=2, safety=0.5)
    by_keywords = fast_model(model, mean_b, box, N_MODES, rng=4, **settings)
    options = FastModelOptions(**settings)
    by_object = fast_model(model, mean_b, box, N_MODES, options=options, rng=4)
    # a keyword over the object: the object's field replaced
    over = FastModelOptions(n_snapshots=3, n_test=5, n_probe=2, max_rounds=2, safety=0.5)
    by_both = fast_model(model, mean_b, box, N_MODES, options=over, rng=4, n_test=2)
    points = box.sample(4, np.random.default_rng(0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ReducedModelWarning)
        want = [by_keywords.eigenvalues(p) for p in points]
        for other in (by_object, by_both):
            np.testing.assert_array_equal(other.reduced.points, by_keywords.reduced.points)
            np.testing.assert_array_equal(other.certificate.points, by_keywords.certificate.points)
            assert other.reduced.size == by_keywords.reduced.size
            assert other.build_solves == by_keywords.build_solves
            got = [other.eigenvalues(p) for p in points]
            np.testing.assert_allclose(got, want, rtol=1e-9)


def test_options_of_takes_fields_by_name_and_refuses_others():
    base = FastModelOptions(n_snapshots=10)
    assert FastModelOptions.of() == FastModelOptions()
    assert FastModelOptions.of(base) is base
    assert FastModelOptions.of(base, n_test=4) == FastModelOptions(n_snapshots=10, n_test=4)
    with pytest.raises(TypeError, match="fast_model\\(\\) got unexpected keyword.*n_modes_x"):
        FastModelOptions.of(base, n_modes_x=3)
    with pytest.raises(TypeError, match="must be a FastModelOptions"):
        FastModelOptions.of({"n_test": 4})
    with pytest.raises(ValueError, match="max_rounds = 0"):
        FastModelOptions(max_rounds=0)
    assert base.build_settings() == {
        "n_snapshots": 10,
        "margin": 6,
        "rank_tol": 2e-3,
        "spacing": "log",
        "n_sigma": 3.0,
        "floor": 0.1,
    }
