"""Certification: the reduced model's relative frequency error at held-out points.

Held-out points of the box are solved with the full model, and the largest relative
frequency error over the first ``n_modes`` modes is the :class:`Certificate`. The error is
largest in small corners of the box, which a few random points miss: probe points
(:func:`_probe_points`) are chosen where the model changed most with its last batch of
snapshots.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .basis import _solve_many

__all__ = ["DEFAULT_TOLERANCE", "Certificate", "certify", "relative_errors"]

DEFAULT_TOLERANCE = 1e-4
"""Largest relative frequency error the certificate accepts (issue 4)."""


@dataclass(frozen=True, eq=False)
class Certificate:
    """Accuracy of a reduced model at held-out points, against the full model.

    Attributes
    ----------
    max_rel_error : float
        Largest ``|f_reduced / f_full - 1|`` over the points and the first ``n_modes`` modes.
    per_mode_max : numpy.ndarray, shape (n_modes,)
        The same, mode by mode.
    n_test : int
        Number of held-out points, probes included.
    tolerance : float
        The bound the error was checked against.
    passed : bool
        ``max_rel_error < tolerance``.
    errors : numpy.ndarray, shape (n_test, n_modes)
        Signed relative frequency errors ``f_reduced / f_full - 1`` (non-negative up to
        rounding: Ritz values are upper bounds).
    points : numpy.ndarray, shape (n_test, 6)
        The held-out points, Pa.
    basis_size : int
        Number of basis vectors of the certified model.
    n_probe : int
        How many of the points (the last ones) were not drawn at random but chosen where
        the model is likeliest to be wrong (see :func:`fast_model`); 0 for a plain draw.
    """

    max_rel_error: float
    per_mode_max: np.ndarray
    n_test: int
    tolerance: float
    passed: bool
    errors: np.ndarray = field(repr=False)
    points: np.ndarray = field(repr=False)
    basis_size: int
    n_probe: int = 0

    @property
    def n_modes(self):
        """Number of modes checked."""
        return self.errors.shape[1]

    def __str__(self):
        verdict = "passed" if self.passed else "FAILED"
        probes = f" ({self.n_probe} of them probes)" if self.n_probe else ""
        return (
            f"certificate {verdict}: max relative frequency error {self.max_rel_error:.2e} "
            f"(tolerance {self.tolerance:.0e}) over {self.n_modes} modes at {self.n_test} "
            f"held-out points{probes}, basis of {self.basis_size}"
        )


def relative_errors(reduced, results, n_modes):
    """``f_reduced / f_full - 1`` at the points of ``results``, shape (k, n_modes).

    Parameters
    ----------
    reduced : ReducedModel
    results : sequence of ModalResult
        Full-model solutions (at least ``n_modes`` modes each), at their own ``b``.
    n_modes : int
    """
    errors = []
    for r in results:
        ritz = reduced.solve(r.b, n_modes).eigenvalues
        errors.append(np.sqrt(ritz / r.eigenvalues[:n_modes]) - 1.0)
    return np.array(errors)


def _certify(model, reduced, points, tolerance, n_modes, n_solve, n_probe=0):
    """Certificate and the full solutions (with ``n_solve`` modes) at ``points``."""
    results = _solve_many(model, points, n_solve)
    errors = relative_errors(reduced, results, n_modes)
    per_mode = np.max(np.abs(errors), axis=0)
    worst = float(per_mode.max())
    certificate = Certificate(
        max_rel_error=worst,
        per_mode_max=per_mode,
        n_test=len(points),
        tolerance=float(tolerance),
        passed=bool(worst < tolerance),
        errors=errors,
        points=np.asarray(points, dtype=float),
        basis_size=reduced.size,
        n_probe=int(n_probe),
    )
    return certificate, results


def certify(
    model,
    reduced,
    points=None,
    *,
    n_test=10,
    rng=None,
    tolerance=DEFAULT_TOLERANCE,
    n_modes=None,
):
    """Largest relative frequency error of a reduced model at held-out points.

    Parameters
    ----------
    model : bayesplate.plate.model.PlateModel
        The full model the reduced one was built from.
    reduced : ReducedModel
    points : array_like, shape (k, 6), optional
        Held-out points, Pa; default ``n_test`` Latin-hypercube points of the box drawn from
        ``rng`` (a different design from the snapshots' if ``rng`` is not reused).
    n_test : int
    rng : numpy.random.Generator or int, optional
    tolerance : float
        Bound on ``max |f_reduced / f_full - 1|``.
    n_modes : int, optional
        Modes checked; default those the basis is built for.

    Returns
    -------
    Certificate
    """
    n = reduced.n_modes if n_modes is None else int(n_modes)
    if points is None:
        points = reduced.box.sample(n_test, np.random.default_rng(rng))
    points = np.atleast_2d(np.asarray(points, dtype=float))
    return _certify(model, reduced, points, tolerance, n, n)[0]


def _probe_points(reduced, n_probe, n_candidates, rng):
    """Points of the box where the model changed most with its last batch of snapshots.

    Where the last batch moved the eigenvalues most, the basis is still converging, and the
    current model is likeliest to be wrong there too (a hierarchical error indicator; on the
    Frederiksen plate its logarithm correlates with that of the true error at 0.65 to 0.8).

    Returns
    -------
    numpy.ndarray, shape (n_probe, 6), or (0, 6) if there is no earlier stage
    """
    if n_probe <= 0 or len(reduced.levels) < 2:
        return np.empty((0, 6))
    earlier = reduced.leading(reduced.levels[-2])
    candidates = reduced.box.sample(n_candidates, rng)
    change = np.empty(len(candidates))
    for i, b in enumerate(candidates):
        try:
            ratio = earlier.eigenvalues(b) / reduced.eigenvalues(b)
        except ValueError:  # the earlier stage does not hold n_modes modes
            return np.empty((0, 6))
        change[i] = np.max(np.abs(np.sqrt(ratio) - 1.0))
    return candidates[np.argsort(-change, kind="stable")[:n_probe]]
