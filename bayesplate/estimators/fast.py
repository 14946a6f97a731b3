"""The estimators on the certified fast model, each answer confirmed by the full model.

Every iteration of B, MVE and MVE-mod needs the paired eigenvalues ``g(b)`` and their
sensitivities ``S(b)``. On the fast path they come from the reduced-basis model of
:mod:`bayesplate.reduced` (a Rayleigh-Ritz solve of ``r`` unknowns, about a millisecond,
instead of the finite-element model's ``n``): the full model builds it over the prior's box
(:func:`case_fast_model`, certified on held-out points to a relative frequency error below
its tolerance) and then checks the answer ``b*`` of each run once:

    max_i |f_i,fast(b*) / f_i,full(b*) - 1| <= tolerance   (the certificate's).

Iterates inside the certified box use the reduced model. Off the box (a prior far from the
plate: the path leaves the prior's box before it comes back; MVE moving a weakly determined
constant far) the reduced model is a Ritz model of unknown error, and MVE's path through a
weakly determined direction is sensitive enough for such errors to change how many
iterations it takes, or whether it is seen to stall: there the full model checks the
reduced one in a trust region and enriches it where it misses (:class:`BoxedModel`). The
answer is then checked. When the check fails (a corner the held-out points missed), the
full solution at ``b*`` (the check's own solve) joins the basis and the run is repeated on
the enriched model, at most :data:`CONFIRM_ROUNDS` times; an answer still not confirmed
gets the status ``"unconfirmed"``, an error in the log and a :class:`FastModelWarning`.

``forward="auto"`` takes this path on meshes of more than :data:`FAST_MIN_DOFS` unknowns;
below that a full solve costs a few hundredths of a second and the build would cost more
than it saves.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import replace

import numpy as np

from ..likelihood.posterior import prior_in_stiffness
from ..matching.checked_order import checks_order
from ..matching.pairing import MAC_EXTRA_MODES, Pairing
from ..quantities import hz_from_eigenvalue
from ..reduced import Box, CertifiedModel, fast_model, relative_errors
from .result import FullModelCheck

__all__ = [
    "CONFIRM_ROUNDS",
    "FAST_DEFAULTS",
    "FAST_MIN_DOFS",
    "FORWARDS",
    "BoxedModel",
    "FastModelWarning",
    "case_fast_model",
    "confirmed_run",
    "modes_to_certify",
    "resolve_forward",
]

log = logging.getLogger(__package__)

#: Half-width of the fast model's box in prior deviations of ``b``.
BOX_SIGMA = 3.0
#: ``forward`` choices of the estimators.
FORWARDS = ("auto", "fast", "full")
#: ``forward="auto"`` uses the fast model above this many unknowns (a 25 x 25 mesh has 5,408).
FAST_MIN_DOFS = 5000
#: Runs on the fast model at most: the first, and one after each enrichment.
CONFIRM_ROUNDS = 3
#: Trust radius off the box (relative change of every coefficient) at the start, at least
#: and at most (see :class:`BoxedModel`).
RADIUS_START, RADIUS_MIN, RADIUS_MAX = 0.05, 0.01, 0.2
#: Settings of :func:`bayesplate.reduced.fast_model` for the prior's box: 12 design points
#: besides the prior mean, rounds of 4 random + 2 probe held-out points.
FAST_DEFAULTS = {"n_snapshots": 12, "n_test": 4, "n_probe": 2}


class FastModelWarning(UserWarning):
    """The full model disagrees with the fast model's answer beyond the certificate."""


def resolve_forward(forward, model, method=None):
    """``"fast"`` or ``"full"`` for a ``forward`` choice on `model` (see :data:`FORWARDS`).

    ``"auto"``: fast above :data:`FAST_MIN_DOFS` unknowns, except for ``method="B"``, whose
    few iterations (5-10 solves a start) cost less than the fast model's build (about 20).
    """
    if forward not in FORWARDS:
        raise ValueError(f"forward = {forward!r}: must be one of {FORWARDS}")
    if forward != "auto":
        return forward
    if method == "B":
        return "full"
    return "fast" if model.mesh.n_dofs > FAST_MIN_DOFS else "full"


def modes_to_certify(case, pairing):
    """Elastic modes a fast model must hold for `pairing` (a Pairing, or a pairing's name).

    A :class:`~bayesplate.matching.pairing.Pairing` needs its own ``n_modes()``, and so does pairing
    by order checked (``"auto"`` without shapes or mode numbers: the check looks at the
    order's modes only, and a run whose order is set aside is redone on a fast model of its
    own); an assignment by likelihood, still to be made, may reach any of the
    ``m + MAC_EXTRA_MODES`` modes it is offered.
    """
    if isinstance(pairing, Pairing):
        return pairing.n_modes()
    if checks_order(case.measured, pairing):
        return Pairing.from_measurement(case.measured, "order").n_modes()
    return case.measured.size + MAC_EXTRA_MODES


def case_fast_model(case, model, n_modes, *, prior_mean=None, prior_sd=None, rng=None, **options):
    """The certified fast model of a case over its prior's 3-sigma box in ``b``.

    Parameters
    ----------
    case : bayesplate.io.Case
        Duck-typed: its ``.prior`` (engineering mean and deviations, SI).
    model : bayesplate.plate.model.PlateModel
        The full model, which builds and certifies the fast one.
    n_modes : int
        Elastic modes to certify (the estimators' pairing needs ``pairing.n_modes()``).
    prior_mean, prior_sd : array_like, shape (6,), optional
        A prior replacing the case's (SI).
    rng : numpy.random.Generator or int, optional
        Seed of the design and of the held-out points (default 0: the same model every
        time).
    **options
        Keywords of :func:`bayesplate.reduced.fast_model` over :data:`FAST_DEFAULTS`.

    Returns
    -------
    CertifiedModel
    """
    mean = case.prior.mean if prior_mean is None else prior_mean
    sd = case.prior.sd if prior_sd is None else prior_sd
    mean_b, cov_b = prior_in_stiffness(mean, sd, "full")
    box = Box.from_covariance(mean_b, cov_b, BOX_SIGMA)
    settings = {**FAST_DEFAULTS, **options}
    rng = 0 if rng is None else rng
    fast = fast_model(model, mean_b, box, int(n_modes), rng=rng, **settings)
    log.info("fast model (%d modes) in %.1f s: %s", n_modes, fast.build_seconds, fast.certificate)
    return fast


def confirmed_run(run, model, fast):
    """A run on the fast model, its answer checked by the full model, repeated until it holds.

    Parameters
    ----------
    run : callable
        ``run(forward_model) -> EstimateResult``; called with the reduced model (a
        :class:`bayesplate.plate.forward.ForwardModel`).
    model : bayesplate.plate.model.PlateModel
        The full model.
    fast : CertifiedModel

    Returns
    -------
    result : EstimateResult
        The last run's, with its :class:`FullModelCheck` (status ``"unconfirmed"`` when it
        does not hold).
    fast : CertifiedModel
        `fast`, its basis enriched with the full solutions at answers it got wrong (share it
        with the next run).
    """
    tolerance = fast.certificate.tolerance
    reduced, n_full = fast.reduced, 0
    for rounds in range(1, CONFIRM_ROUNDS + 1):
        forward = BoxedModel(model, reduced, tolerance)
        result = run(forward)
        reduced = forward.reduced  # enriched along the path
        full, fast_Hz, full_Hz = _full_at(model, result)
        n_full += (full is not None) + forward.n_full
        check = FullModelCheck(
            np.array(result.b),
            fast_Hz,
            full_Hz,
            tolerance,
            rounds,
            n_full,
            fast.build_solves,
            fast.build_seconds,
        )
        if check.confirmed or full is None or rounds == CONFIRM_ROUNDS:
            break
        log.info("%s: %s; the basis takes the full modes there", result.method, check)
        reduced = reduced.enrich(model, result.b[None, :], [full])
    fast = _with_reduced(fast, reduced)
    return _checked(result, check), fast


class BoxedModel:
    """The reduced model where it is known to be right; the full model checks it elsewhere.

    Inside the certified box the reduced model answers. Outside it, an iterate farther than
    :attr:`radius` (relative, in every coefficient) from every point already checked is
    solved by the full model too: if the reduced model missed it by more than the tolerance,
    the full modes there join the basis (so that the path goes on in a model that is right
    where it goes); the point is then trusted, and so are the iterates near it. The radius
    doubles after a check the reduced model passed and halves after one it failed (between
    :data:`RADIUS_MIN` and :data:`RADIUS_MAX`), as a trust region does. Iterates off the box
    are expected on a path from a far prior or along a weakly determined constant, so they
    are counted (:attr:`n_full`), not warned of.

    A :class:`bayesplate.plate.forward.ForwardModel`.

    Parameters
    ----------
    model : bayesplate.plate.model.PlateModel
    reduced : bayesplate.reduced.ReducedModel
    tolerance : float
        Largest relative frequency error accepted (the certificate's).
    """

    def __init__(self, model, reduced, tolerance):
        self.model, self.reduced, self.tolerance = model, reduced, float(tolerance)
        self.n_full = 0
        self.radius = RADIUS_START
        self._trusted = np.empty((0, 6))
        self._most = reduced.n_modes + reduced.margin

    @property
    def mesh(self):
        """The full model's mesh."""
        return self.model.mesh

    @property
    def mass(self):
        """The full model's mass matrix, shape (n_dofs, n_dofs)."""
        return self.model.mass

    def solve(self, b, n_modes):
        """Modes and sensitivities at `b` (Pa), `n_modes` of them, from a model right there."""
        b = np.asarray(b, dtype=float)
        if n_modes > self._most:
            self.n_full += 1
            return self.model.solve(b, n_modes)
        if not (self.reduced.box.contains(b) or self._near_trusted(b)):
            self._check(b)
        return self.reduced.solve(b, n_modes)

    def eigenvalues(self, b, n_modes):
        """Eigenvalues at `b`, shape (n_modes,) (see :meth:`solve`)."""
        return self.solve(b, n_modes).eigenvalues

    def _near_trusted(self, b):
        if not len(self._trusted):
            return False
        gap = np.abs(b - self._trusted) / np.abs(self._trusted)
        return bool(np.any(np.max(gap, axis=1) <= self.radius))

    def _check(self, b):
        """Solve the full model at `b`; enrich the basis if the reduced one misses it."""
        full = self.model.solve(b, self._most)
        self.n_full += 1
        error = np.max(np.abs(relative_errors(self.reduced, [full], self.reduced.n_modes)))
        if error > self.tolerance:
            self.reduced = self.reduced.enrich(self.model, b[None, :], [full])
            self.radius = max(self.radius / 2.0, RADIUS_MIN)
        else:
            self.radius = min(self.radius * 2.0, RADIUS_MAX)
        log.debug("off the box: reduced error %.1e, radius now %.3g", error, self.radius)
        self._trusted = np.vstack([self._trusted, b])


def _full_at(model, result):
    """The full solution at the answer and the paired frequencies of both models."""
    modes = np.asarray(result.modes, dtype=int) - 1  # 1-based in the result
    fast_Hz = np.asarray(result.frequency_Hz, dtype=float)
    try:
        full = model.solve(np.asarray(result.b, dtype=float), result.pairing.n_modes(modes))
    except Exception as err:  # noqa: BLE001 - reported in the check, never raised
        log.error("full-model check failed at the %s answer: %s", result.method, err)
        return None, fast_Hz, np.full_like(fast_Hz, np.nan)
    return full, fast_Hz, hz_from_eigenvalue(full.eigenvalues[modes])


def _with_reduced(fast, reduced):
    """The certified model on an enriched reduced model, with the same certificate.

    A larger basis only lowers the Ritz values towards the full ones.
    """
    if reduced is fast.reduced:
        return fast
    return CertifiedModel(
        fast.model, reduced, fast.certificate, fast.history, fast.build_seconds, fast.build_solves
    )


def _checked(result, check):
    """The result with its check; status ``"unconfirmed"`` and a loud warning if it fails."""
    message = f"{result.message}; {check}"
    if check.confirmed:
        return replace(result, check=check, message=message)
    text = (
        f"{result.method}: the full model disagrees with the fast model's answer: {check} "
        "(the answer is not trustworthy; run with forward='full')"
    )
    log.error(text)
    warnings.warn(text, FastModelWarning, stacklevel=3)
    return replace(result, check=check, message=message, status="unconfirmed", converged=False)
