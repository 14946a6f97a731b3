"""Local fits from many starts (:func:`bayesplate.discrepancy.search.local_fits.local_fits`)."""

import logging

import numpy as np

from bayesplate.discrepancy.search.local_fits import local_fits


class _TwoRoots:
    """``r(z) = z^2 - 4`` (optima at -2 and 2); the plate cannot be solved where z > 0.

    Stands for a reduced model far from where it was built: its mass matrix no longer
    positive definite, the eigensolver raises (as scipy's ``eigh`` does).
    """

    physics = None
    n_solves = 0

    def bounds(self):
        return np.array([-10.0]), np.array([10.0])

    def residuals(self, z):
        if z[0] > 0:
            raise np.linalg.LinAlgError("leading minor of order 3 of B not positive definite")
        self.n_solves += 1
        return np.array([z[0] ** 2 - 4.0])

    def jacobian(self, z):
        return np.array([[2.0 * z[0]]])


def test_a_start_that_meets_an_unsolvable_plate_is_dropped_with_a_warning(caplog):
    with caplog.at_level(logging.WARNING, logger="bayesplate"):
        results = local_fits(_TwoRoots(), [np.array([-1.0]), np.array([1.0])], 50)
    assert len(results) == 1
    np.testing.assert_allclose(results[0].x, [-2.0], atol=1e-6)
    assert "fit failed (LinAlgError" in caplog.text


def test_when_every_start_fails_they_come_back_at_their_starts_with_infinite_cost():
    results = local_fits(_TwoRoots(), [np.array([1.0]), np.array([3.0])], 50)
    assert [float(r.x[0]) for r in results] == [1.0, 3.0]
    assert all(r.cost == np.inf and not r.success for r in results)
