"""The parameter box: where in ``b`` a reduced model is built, certified and used.

An axis-aligned box of lamina stiffness coefficients ``b = (C11, C22, C12, C66, C44, C55)``
(Pa) inside the physical region, by default the prior's 3-sigma box cut to physical laminae
(:func:`stiffness_box`), and its Latin-hypercube designs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import qmc

from .. import laminate
from ..quantities import stiffness_covariance

__all__ = ["Box", "prior_stiffness", "stiffness_box"]


@dataclass(frozen=True, eq=False)
class Box:
    """Axis-aligned box of lamina stiffness coefficients inside the physical region.

    Parameters
    ----------
    lower, upper : array_like, shape (6,)
        Bounds of ``(C11, C22, C12, C66, C44, C55)`` in Pa, ``lower < upper``. Every point
        of the box must be a positive-definite lamina, which is checked at the worst corner.
    """

    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self):
        lower = np.array(self.lower, dtype=float)
        upper = np.array(self.upper, dtype=float)
        if lower.shape != (6,) or upper.shape != (6,):
            raise ValueError(f"box bounds have shapes {lower.shape}, {upper.shape}: need (6,)")
        if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
            raise ValueError("box bounds must be finite")
        if not np.all(lower < upper):
            raise ValueError(f"box lower {lower} must be below upper {upper}")
        worst = lower.copy()
        worst[2] = max(abs(lower[2]), abs(upper[2]))
        if not laminate.is_physical(worst):
            raise ValueError(f"box [{lower}, {upper}] reaches non-physical laminae")
        lower.setflags(write=False)
        upper.setflags(write=False)
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)

    @classmethod
    def from_covariance(cls, mean, cov, n_sigma=3.0, floor=0.1):
        """The ``n_sigma`` box of a Gaussian in ``b``, cut to physical laminae.

        Parameters
        ----------
        mean : array_like, shape (6,)
            Pa.
        cov : array_like, shape (6, 6)
            Pa^2; only the diagonal is used.
        n_sigma : float
            Half-width of the box in standard deviations.
        floor : float
            The positive coefficients (all but C12) are kept above ``floor * mean``: the
            3-sigma box of a wide prior reaches zero stiffness (G23 = 4 +- 4.5 GPa in the
            Frederiksen case). C12 is kept within 0.99 of ``sqrt(C11 C22)`` at the lower
            corner, so that the whole box is positive definite.

        Returns
        -------
        Box
        """
        mean = np.asarray(mean, dtype=float)
        sd = np.sqrt(np.diag(np.asarray(cov, dtype=float)))
        lower, upper = mean - n_sigma * sd, mean + n_sigma * sd
        positive = np.array([0, 1, 3, 4, 5])
        lower[positive] = np.maximum(lower[positive], floor * mean[positive])
        cap = 0.99 * math.sqrt(lower[0] * lower[1])
        lower[2], upper[2] = max(lower[2], -cap), min(upper[2], cap)
        return cls(lower, upper)

    @property
    def center(self):
        """Centre of the box, shape (6,), Pa."""
        return 0.5 * (self.lower + self.upper)

    def contains(self, b):
        """Whether points lie in the box (bounds included).

        Parameters
        ----------
        b : array_like, shape (..., 6)
            Pa.

        Returns
        -------
        bool or numpy.ndarray of bool, shape (...)
        """
        b = np.asarray(b, dtype=float)
        return np.all((b >= self.lower) & (b <= self.upper), axis=-1)

    def sample(self, n, rng, spacing="linear"):
        """Latin-hypercube design of ``n`` points in the box.

        Parameters
        ----------
        n : int
        rng : numpy.random.Generator or int
            Source of the design; the same generator state gives the same points.
        spacing : {"linear", "log"}
            Uniform strata in ``b`` or, for the coefficients whose bounds are positive, in
            ``log b``.

        Returns
        -------
        numpy.ndarray, shape (n, 6)
            Pa.
        """
        unit = qmc.LatinHypercube(d=6, rng=np.random.default_rng(rng)).random(int(n))
        points = self.lower + unit * (self.upper - self.lower)
        if spacing == "log":
            pos = self.lower > 0
            lo, hi = np.log(self.lower[pos]), np.log(self.upper[pos])
            points[:, pos] = np.exp(lo + unit[:, pos] * (hi - lo))
        elif spacing != "linear":
            raise ValueError(f"spacing = {spacing!r}: must be 'linear' or 'log'")
        return points


def prior_stiffness(prior):
    """The prior on the engineering constants carried over to ``b`` to first order.

    Parameters
    ----------
    prior : bayesplate.io.Prior
        Independent Gaussian on ``(E1, E2, nu12, G12, G13, G23)`` (SI).

    Returns
    -------
    mean : numpy.ndarray, shape (6,)
        ``b`` at the prior mean, Pa.
    cov : numpy.ndarray, shape (6, 6)
        ``J diag(sd^2) J^T`` with ``J = d b / d e`` at the mean, Pa^2.
    """
    mean_e = np.asarray(prior.mean, dtype=float)
    cov = stiffness_covariance(mean_e, np.diag(np.asarray(prior.sd, dtype=float) ** 2))
    return laminate.stiffness_from_engineering(mean_e), cov


def stiffness_box(prior, n_sigma=3.0, floor=0.1):
    """The ``n_sigma`` box in ``b`` of a prior on the engineering constants.

    Parameters
    ----------
    prior : bayesplate.io.Prior
    n_sigma, floor : float
        See :meth:`Box.from_covariance`.

    Returns
    -------
    Box
    """
    mean, cov = prior_stiffness(prior)
    return Box.from_covariance(mean, cov, n_sigma, floor)


def _as_box(mean_b, box, n_sigma, floor):
    """A :class:`Box` from a box, an array of bounds (2, 6) or a covariance (6, 6)."""
    if isinstance(box, Box):
        return box
    box = np.asarray(box, dtype=float)
    if box.shape == (2, 6):
        return Box(box[0], box[1])
    if box.shape == (6, 6):
        return Box.from_covariance(mean_b, box, n_sigma, floor)
    raise ValueError(f"box has shape {box.shape}: give a Box, bounds (2, 6) or a covariance")
