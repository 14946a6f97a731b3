"""The certified model: reduced where certified, the full model elsewhere; and its builder.

:func:`fast_model` builds a reduced model, certifies it and enriches it greedily at the worst
held-out points until the certificate passes; :class:`CertifiedModel` evaluates with the
reduced model where the certificate holds and falls back to the full model, with a
:class:`ReducedModelWarning`, elsewhere.
"""

from __future__ import annotations

import logging
import math
import time
import warnings

import numpy as np

from .certify import _certify, _probe_points
from .model import ReducedModel
from .options import FastModelOptions

__all__ = ["CertifiedModel", "ReducedModelWarning", "fast_model"]

# the package's logger (the name the report and the tests listen to)
log = logging.getLogger(__package__)


class ReducedModelWarning(UserWarning):
    """The reduced model is not used for an evaluation; the full model is used instead."""


def fast_model(model, mean_b, box, n_modes, *, options=None, rng=None, **settings):
    """Build, certify and greedily enrich a reduced model; wrap it with a full-model fallback.

    Each round certifies the current basis against the full model on ``n_test`` fresh
    Latin-hypercube points of the box and ``n_probe`` probe points; if the error is above
    ``safety * tolerance``, the modes at the (up to ``n_add``) worst of them, already
    computed, join the basis and the next round certifies again on fresh points
    (:class:`~bayesplate.reduced.options.FastModelOptions`).

    Parameters
    ----------
    model : bayesplate.plate.model.PlateModel
    mean_b : array_like, shape (6,)
        Prior mean of ``(C11, C22, C12, C66, C44, C55)``, Pa; always a snapshot point.
    box : Box or array_like
        As for :meth:`ReducedModel.build` (bounds in Pa, or a covariance in Pa^2).
    n_modes : int
        Elastic modes to be reproduced and certified.
    options : FastModelOptions, optional
        The build's, certificate's and enrichment's settings (default: the defaults).
    rng : numpy.random.Generator or int, optional
        Seed of every design; the same seed gives the same basis and certificate.
    **settings
        Fields of :class:`~bayesplate.reduced.options.FastModelOptions` by name, over
        `options` (``tolerance``, ``safety``, ``n_snapshots``, ``n_test``, ``n_probe``,
        ``n_candidates``, ``n_add``, ``max_rounds``, ``max_basis``, ``margin``,
        ``rank_tol``, ``spacing``, ``n_sigma``, ``floor``).

    Returns
    -------
    CertifiedModel

    Raises
    ------
    TypeError
        A keyword that is no field of :class:`~bayesplate.reduced.options.FastModelOptions`.
    """
    options = FastModelOptions.of(options, "fast_model", **settings)
    started = time.perf_counter()
    rng = np.random.default_rng(rng)
    reduced = ReducedModel.build(model, mean_b, box, n_modes, rng=rng, **options.build_settings())
    reduced, history = _enriched(model, reduced, n_modes, options, rng)
    solves = 1 + options.n_snapshots + sum(c.n_test for c in history)
    return CertifiedModel(
        model, reduced, history[-1], history, time.perf_counter() - started, solves
    )


def _enriched(model, reduced, n_modes, options, rng):
    """The rounds of :func:`fast_model`: the last basis, and every round's certificate.

    Each round certifies on fresh points (:func:`_certified_round`); the rounds stop once
    the error is under ``safety * tolerance``, after ``max_rounds``, or where the enriched
    basis would pass ``max_basis`` (the basis certified last is kept).
    """
    target = options.safety * options.tolerance
    history = []
    for round_ in range(1, options.max_rounds + 1):
        certificate, points, results = _certified_round(model, reduced, n_modes, options, rng)
        history.append(certificate)
        log.info("round %d: %s", round_, certificate)
        if certificate.max_rel_error < target or round_ == options.max_rounds:
            break
        worst = _worst(certificate, options.n_add, target)
        enriched = reduced.enrich(model, points[worst], [results[i] for i in worst])
        if options.max_basis is not None and enriched.size > options.max_basis:
            log.info("basis cap %d reached (%d needed)", options.max_basis, enriched.size)
            break
        reduced = enriched
    return reduced, history


def _certified_round(model, reduced, n_modes, options, rng):
    """One round's certificate, its held-out points and the full solutions there.

    The points: ``n_test`` drawn from the box and ``n_probe`` probes (drawn first).
    """
    probes = _probe_points(reduced, options.n_probe, options.n_candidates, rng)
    points = np.vstack([reduced.box.sample(options.n_test, rng), probes])
    n_solve = n_modes + options.margin
    certificate, results = _certify(
        model, reduced, points, options.tolerance, n_modes, n_solve, n_probe=len(probes)
    )
    return certificate, points, results


def _worst(certificate, n_add, target):
    """Indices of the (up to ``n_add``) worst held-out points whose error reaches ``target``."""
    worst = np.argsort(-np.max(np.abs(certificate.errors), axis=1), kind="stable")
    return [i for i in worst[:n_add] if np.abs(certificate.errors[i]).max() >= target]


class CertifiedModel:
    """Reduced model where it is certified, the full model elsewhere.

    ``solve`` uses the reduced model when its certificate passed, the point lies in the
    certified box and no more modes are asked than were certified; otherwise it uses the full
    model and counts the fallback. The first fallback of each kind is reported by
    ``logging`` and by one :class:`ReducedModelWarning`; repeats are only counted (and logged
    again at 10, 100, 1000, ... occurrences).

    A :class:`bayesplate.plate.forward.ForwardModel`: :attr:`mesh` and :attr:`mass` are the full
    model's, which both paths' mode shapes live on.

    Parameters
    ----------
    model : bayesplate.plate.model.PlateModel
        The full model.
    reduced : ReducedModel
    certificate : Certificate
    history : sequence of Certificate, optional
        The certificates of every round of :func:`fast_model`, the last one included.
    build_seconds : float
        Seconds :func:`fast_model` spent building and certifying it.
    build_solves : int
        Full solves it spent (design, held-out points).

    Attributes
    ----------
    fallbacks : dict of str to int
        Full-model evaluations by reason: ``"uncertified"``, ``"outside_box"``,
        ``"n_modes"``.
    n_reduced : int
        Reduced-model evaluations.
    """

    def __init__(self, model, reduced, certificate, history=(), build_seconds=0.0, build_solves=0):
        self.model = model
        self.build_seconds = float(build_seconds)
        self.build_solves = int(build_solves)
        self.reduced = reduced
        self.certificate = certificate
        self.history = tuple(history) or (certificate,)
        self.fallbacks = {"uncertified": 0, "outside_box": 0, "n_modes": 0}
        self.n_reduced = 0

    @property
    def mesh(self):
        """The full model's mesh, on whose unknowns the mode shapes live."""
        return self.model.mesh

    @property
    def mass(self):
        """The full model's mass matrix (CSR, all unknowns), shape (n_dofs, n_dofs)."""
        return self.model.mass

    @property
    def certified(self):
        """Whether the certificate passed."""
        return bool(self.certificate.passed)

    @property
    def box(self):
        """The certified box."""
        return self.reduced.box

    @property
    def n_modes(self):
        """Number of certified modes."""
        return self.certificate.n_modes

    def solve(self, b, n_modes=None):
        """Lowest elastic modes and sensitivities, reduced if certified there.

        Parameters
        ----------
        b : array_like, shape (6,)
            ``(C11, C22, C12, C66, C44, C55)`` in Pa.
        n_modes : int, optional
            Default: the certified number.

        Returns
        -------
        ReducedModalResult or ModalResult
        """
        return self._dispatch(b, n_modes, self.reduced.solve, lambda full: full)

    def eigenvalues(self, b, n_modes=None):
        """Lowest elastic eigenvalues, reduced if certified there (fastest path).

        Parameters
        ----------
        b : array_like, shape (6,)
            ``(C11, C22, C12, C66, C44, C55)`` in Pa.
        n_modes : int, optional
            Default: the certified number.

        Returns
        -------
        numpy.ndarray, shape (n_modes,)
            rad^2/s^2.
        """
        return self._dispatch(b, n_modes, self.reduced.eigenvalues, lambda full: full.eigenvalues)

    def _dispatch(self, b, n_modes, reduced, from_full):
        """``reduced(b, n)`` where certified, else ``from_full`` of the full model's solve."""
        n = self.n_modes if n_modes is None else int(n_modes)
        reason = self._fallback_reason(b, n)
        if reason is None:
            self.n_reduced += 1
            return reduced(b, n)
        self._report(reason)
        return from_full(self.model.solve(np.asarray(b, dtype=float), n))

    def _fallback_reason(self, b, n):
        if not self.certified:
            return "uncertified"
        if n > self.n_modes:
            return "n_modes"
        if not self.box.contains(b):
            return "outside_box"
        return None

    def _report(self, reason):
        count = self.fallbacks[reason] = self.fallbacks[reason] + 1
        if count == 1:
            message = {
                "uncertified": f"reduced model not certified ({self.certificate}); "
                "evaluating with the full model",
                "outside_box": "point outside the certified box; evaluating with the full model",
                "n_modes": f"more modes asked than the {self.n_modes} certified; evaluating "
                "with the full model",
            }[reason]
            log.warning(message)
            warnings.warn(message, ReducedModelWarning, stacklevel=3)
        elif math.log10(count).is_integer():
            log.warning("%d full-model evaluations so far: %s", count, reason)
