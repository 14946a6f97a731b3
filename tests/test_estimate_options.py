"""estimate's settings as an EstimatorOptions object and as keywords: the same numbers."""

import numpy as np
import pytest

from bayesplate.estimators import EstimatorOptions, estimate
from bayesplate.io import bundled_case_path, load_case
from bayesplate.plate.model import PlateModel


@pytest.fixture(scope="module")
def plate1():
    case = load_case(bundled_case_path("plate1"))
    return case, PlateModel.from_case(case, mesh=(8, 4))


@pytest.mark.parametrize(
    "method, pairing", [("B", "likelihood"), ("MVE", "order"), ("MVE-mod", "auto")]
)
def test_options_object_and_keywords_give_the_same_estimate(plate1, method, pairing):
    case, model = plate1
    mean = case.reference * np.array([1.1, 0.9, 1.1, 1.1, 0.9, 1.1])
    settings = dict(tol=1e-4, prior_mean=mean, prior_sd=0.2 * mean, pairing=pairing, forward="full")
    by_keywords = estimate(case, method, model=model, **settings)
    by_object = estimate(case, method, model=model, options=EstimatorOptions(**settings))
    over = EstimatorOptions(**{**settings, "tol": 1e-2, "pairing": "index"})
    by_both = estimate(case, method, model=model, options=over, tol=1e-4, pairing=pairing)
    for other in (by_object, by_both):
        np.testing.assert_array_equal(other.b, by_keywords.b)
        np.testing.assert_array_equal(other.covariance_b, by_keywords.covariance_b)
        np.testing.assert_array_equal(other.pairing.modes, by_keywords.pairing.modes)
        assert other.iterations == by_keywords.iterations
        assert other.message == by_keywords.message


def test_options_of_takes_fields_by_name_and_refuses_others():
    base = EstimatorOptions(tol=1e-4)
    assert EstimatorOptions.of(base) is base
    assert EstimatorOptions.of(base, pairing="order").pairing == "order"
    assert EstimatorOptions.of(base, pairing="order").tol == 1e-4
    with pytest.raises(TypeError, match=r"estimate\(\) got unexpected keyword.*tolerance"):
        estimate(None, "B", tolerance=1e-3)
    with pytest.raises(TypeError, match="options must be a"):
        EstimatorOptions.of({"tol": 1e-3})
