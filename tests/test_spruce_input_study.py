"""studies/spruce_input_budget.py: each drawn input's share of a constant's posterior variance."""

import types

import numpy as np
import pytest

from bayesplate.laminate import stiffness_from_engineering
from studies import spruce_input_budget as study


def test_input_shares_are_squared_correlations(rng):
    # E1 = e0 + c x + noise with x the drawn input: the share of E1's variance x explains is
    # c^2 var(x) / (c^2 var(x) + var(noise)) = 0.8 here; the sample estimate of a squared
    # correlation rho^2 has sd about 2 rho (1 - rho^2) / sqrt(n) = 0.0036 at n = 20000: 4 of it
    n = 20_000
    x = rng.standard_normal(n)
    e = np.tile([12e9, 1e9, 0.3, 0.9e9, 0.6e9, 0.03e9], (n, 1))
    e *= 1 + 0.01 * rng.standard_normal((n, 6))  # each constant its own spread...
    e[:, 0] = 12e9 + 1e8 * (2 * x + rng.standard_normal(n))  # ... E1: var 4 from x, 1 noise
    post = types.SimpleNamespace(names=("thickness",), draws=x[:, None], rows=np.arange(n))
    result = types.SimpleNamespace(input_posterior=post, samples_b=stiffness_from_engineering(e))
    shares = study.input_shares(result)
    assert shares.shape == (1, 6)
    assert shares[0, 0] == pytest.approx(0.8, abs=4 * 0.0036)
    # the others are independent of x: rho^2 is then about chi^2_1 / n (mean 5e-5)
    assert np.all(shares[0, 1:] < 1e-3)
