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

from .certify import DEFAULT_TOLERANCE, _certify, _probe_points
from .model import ReducedModel

__all__ = ["CertifiedModel", "ReducedModelWarning", "fast_model"]

# the package's logger (the name the report and the tests listen to)
log = logging.getLogger(__package__)


class ReducedModelWarning(UserWarning):
    """The reduced model is not used for an evaluation; the full model is used instead."""


def fast_model(
    model,
    mean_b,
    box,
    n_modes,
    *,
    tolerance=DEFAULT_TOLERANCE,
    safety=1.0,
    n_snapshots=16,
    n_test=6,
    n_probe=4,
    n_candidates=256,
    n_add=3,
    max_rounds=4,
    max_basis=None,
    margin=6,
    rank_tol=2e-3,
    spacing="log",
    rng=None,
    n_sigma=3.0,
    floor=0.1,
):
    """Build, certify and greedily enrich a reduced model; wrap it with a full-model fallback.

    Each round certifies the current basis against the full model on ``n_test`` fresh
    Latin-hypercube points of the box and ``n_probe`` probe points; if the error is above
    ``safety * tolerance``, the modes at the (up to ``n_add``) worst of them, already
    computed, join the basis and the next round certifies again on fresh points.

    Parameters
    ----------
    model : bayesplate.model.PlateModel
    mean_b, box, n_modes, n_snapshots, margin, rank_tol, spacing, n_sigma, floor
        As for :meth:`ReducedModel.build`.
    tolerance : float
        Bound on the relative frequency error over the first ``n_modes`` modes.
    safety : float
        Enrichment goes on until the held-out error is below ``safety * tolerance`` (1:
        until the certificate passes; less for a margin). The certificate passes below
        ``tolerance``.
    n_test : int
        Held-out points per round drawn at random (Latin hypercube) from the box.
    n_probe : int
        Held-out points per round chosen among ``n_candidates`` random ones where the model
        changed most with its last batch of snapshots (its error is likeliest to be large
        there); they join the certificate, which a random draw alone makes optimistic (the
        error is largest in small corners of the box).
    n_candidates : int
        Candidates for the probes, evaluated with the reduced model only.
    n_add : int
        Points added per failed round.
    max_rounds : int
        Certification rounds at most.
    max_basis : int, optional
        Stop enriching once the basis would grow beyond this size.
    rng : numpy.random.Generator or int, optional
        Seed of every design; the same seed gives the same basis and certificate.

    Returns
    -------
    CertifiedModel
    """
    started = time.perf_counter()
    rng = np.random.default_rng(rng)
    reduced = ReducedModel.build(
        model,
        mean_b,
        box,
        n_modes,
        n_snapshots=n_snapshots,
        margin=margin,
        rng=rng,
        rank_tol=rank_tol,
        spacing=spacing,
        n_sigma=n_sigma,
        floor=floor,
    )
    n_solve = n_modes + margin
    history = []
    for round_ in range(1, max_rounds + 1):
        probes = _probe_points(reduced, n_probe, n_candidates, rng)
        points = np.vstack([reduced.box.sample(n_test, rng), probes])
        certificate, results = _certify(
            model, reduced, points, tolerance, n_modes, n_solve, n_probe=len(probes)
        )
        history.append(certificate)
        log.info("round %d: %s", round_, certificate)
        if certificate.max_rel_error < safety * tolerance or round_ == max_rounds:
            break
        worst = np.argsort(-np.max(np.abs(certificate.errors), axis=1), kind="stable")
        target = safety * tolerance
        worst = [i for i in worst[:n_add] if np.abs(certificate.errors[i]).max() >= target]
        enriched = reduced.enrich(model, points[worst], [results[i] for i in worst])
        if max_basis is not None and enriched.size > max_basis:
            log.info("basis cap %d reached (%d needed)", max_basis, enriched.size)
            break
        reduced = enriched
    solves = 1 + n_snapshots + sum(c.n_test for c in history)
    return CertifiedModel(
        model, reduced, certificate, history, time.perf_counter() - started, solves
    )


class CertifiedModel:
    """Reduced model where it is certified, the full model elsewhere.

    ``solve`` uses the reduced model when its certificate passed, the point lies in the
    certified box and no more modes are asked than were certified; otherwise it uses the full
    model and counts the fallback. The first fallback of each kind is reported by
    ``logging`` and by one :class:`ReducedModelWarning`; repeats are only counted (and logged
    again at 10, 100, 1000, ... occurrences).

    A :class:`bayesplate.forward.ForwardModel`: :attr:`mesh` and :attr:`mass` are the full
    model's, which both paths' mode shapes live on.

    Parameters
    ----------
    model : bayesplate.model.PlateModel
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
