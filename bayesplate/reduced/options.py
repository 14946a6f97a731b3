"""The settings of :func:`~bayesplate.reduced.certified.fast_model` in one frozen object.

:class:`FastModelOptions` holds how the reduced model is built (its snapshots, their extra
modes, the compression), how it is certified (the tolerance, the held-out points, the
probes) and how it is enriched (points added per round, rounds, a cap on the basis).
:func:`~bayesplate.reduced.certified.fast_model` takes one as ``options``, and each field by
name as a keyword over it (``fast_model(model, mean_b, box, 14, n_snapshots=10)``, and the
``fast_options`` dicts of the sampler and the estimators): the keywords it took before the
object existed, with the same defaults and the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..settings import with_overrides
from .certify import DEFAULT_TOLERANCE

__all__ = ["FastModelOptions"]


@dataclass(frozen=True)
class FastModelOptions:
    """How :func:`~bayesplate.reduced.certified.fast_model` builds, certifies and enriches.

    Each round certifies the current basis against the full model on `n_test` fresh
    Latin-hypercube points of the box and `n_probe` probe points; if the error is above
    ``safety * tolerance``, the modes at the (up to `n_add`) worst of them, already
    computed, join the basis and the next round certifies again on fresh points.

    Parameters
    ----------
    tolerance : float
        Bound on the relative frequency error over the first ``n_modes`` modes
        (dimensionless).
    safety : float
        Enrichment goes on until the held-out error is below ``safety * tolerance`` (1:
        until the certificate passes; less for a margin). The certificate passes below
        `tolerance`.
    n_snapshots : int
        Design points besides the mean (Latin hypercube over the box), as for
        :meth:`~bayesplate.reduced.model.ReducedModel.build`.
    n_test : int
        Held-out points per round drawn at random (Latin hypercube) from the box.
    n_probe : int
        Held-out points per round chosen among `n_candidates` random ones where the model
        changed most with its last batch of snapshots (its error is likeliest to be large
        there); they join the certificate, which a random draw alone makes optimistic (the
        error is largest in small corners of the box).
    n_candidates : int
        Candidates for the probes, evaluated with the reduced model only.
    n_add : int
        Points added per failed round.
    max_rounds : int
        Certification rounds at most (at least one).
    max_basis : int, optional
        Stop enriching once the basis would grow beyond this many vectors.
    margin : int
        Extra modes computed at each snapshot and held-out point.
    rank_tol : float
        Compression tolerance in the energy norm (dimensionless; the eigenvalues lose about
        ``rank_tol**2`` relative accuracy).
    spacing : {"log", "linear"}
        Strata of the design (:meth:`~bayesplate.reduced.box.Box.sample`).
    n_sigma : float
        Half-width of the box, in deviations, when it is given as a covariance (Pa^2).
    floor : float
        As for :meth:`~bayesplate.reduced.box.Box.from_covariance` (a covariance box only).

    Raises
    ------
    ValueError
        `max_rounds` under one.
    """

    tolerance: float = DEFAULT_TOLERANCE
    safety: float = 1.0
    n_snapshots: int = 16
    n_test: int = 6
    n_probe: int = 4
    n_candidates: int = 256
    n_add: int = 3
    max_rounds: int = 4
    max_basis: int | None = None
    margin: int = 6
    rank_tol: float = 2e-3
    spacing: str = "log"
    n_sigma: float = 3.0
    floor: float = 0.1

    def __post_init__(self):
        if self.max_rounds < 1:
            raise ValueError(f"max_rounds = {self.max_rounds}: need at least one round")

    @classmethod
    def of(cls, options=None, caller="fast_model", **overrides):
        """`options` (default: the defaults) with `overrides`, each a field's name.

        Parameters
        ----------
        options : FastModelOptions, optional
        caller : str
            Name of the function, for the messages.
        **overrides
            Fields by name, over `options`.

        Returns
        -------
        FastModelOptions

        Raises
        ------
        TypeError
            An override that is no field of :class:`FastModelOptions`, or `options` of
            another type.
        """
        return with_overrides(cls, options, caller, overrides)

    def build_settings(self):
        """The keywords of :meth:`~bayesplate.reduced.model.ReducedModel.build` among these."""
        keys = ("n_snapshots", "margin", "rank_tol", "spacing", "n_sigma", "floor")
        return {key: getattr(self, key) for key in keys}
