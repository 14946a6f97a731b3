"""Diagnose a mismatch between the model and the recordings: the steps, in order.

1. Fit the nominal model globally (many starts on a reduced model, the best refined on the
   working mesh: :mod:`.search.nominal`) and check it: chi-square of the
   standardised residuals against ``m - p_eff`` degrees of freedom (``p_eff``: parameters
   the data fix), and a predictive check per mode (:mod:`.search.nominal_check`).
2. Locate: which modes carry the misfit, what kind of modes they are, and where on the plate
   a local change would explain the residuals (after the constants took their share): the
   location map and the Ritz scan of every located candidate (its
   :meth:`~.physics.base.Physics.location_map` and :meth:`~.physics.base.Physics.scan`;
   :mod:`.search.locate`).
3. Name: fit every candidate physics (every variant: a taper along x and along y) jointly
   with the constants, on a reduced model of the modified plate
   (:mod:`.physics.reduced_model`) refined on the working mesh, and rank the candidates by
   their Laplace evidence gain over the nominal model (what the constants cannot absorb;
   :mod:`.search.rank`).
4. Model: the chosen candidate's joint fit is the refit, with its Laplace posterior. When
   the best single candidate's refit is still rejected, two effects at once: the best one
   paired with every other candidate (:mod:`.physics.combined`, :mod:`.search.two_effects`),
   ranked on the same evidence scale (:mod:`.search.refit`).
5. Verdict: ``consistent``, ``explained``, ``ambiguous`` (the refit is consistent but a
   different candidate's posterior odds are within ``ambiguity_margin``, or within
   ``prior_margin`` while it fits the recordings as well: all that tie are named, and the
   measurement that would tell the first two apart, :mod:`.search.separation`) or
   ``unexplained`` (:mod:`.search.verdict`, :mod:`.search.conclude`), with the posterior
   probability of every model (:mod:`.search.probabilities`).

Before any of it, the mesh's own error on every frequency is estimated by Richardson
extrapolation (the element converges as h^2) and reported beside the measurement deviation;
where it is not well under it, it is added to the deviation in quadrature and the report says
so, so that discretisation is never blamed on physics (:mod:`.search.deviations`).

Each step is a module-level function of :mod:`.search` that hands a small frozen state on
(:mod:`.search.state`); :func:`.search.passes.one_pass` chains them. No candidate is named
here: the candidates are :class:`~.physics.base.Physics` objects, and what is found about
each (maps, scans, results) is keyed by its :attr:`~.physics.base.Physics.name`.
"""

from __future__ import annotations

import logging

import numpy as np

from ..likelihood.posterior import prior_in_stiffness
from ..matching.checked_order import checks_order
from ..matching.pairing import Pairing
from ..plate.model import PlateModel
from . import candidates as all_candidates
from .search.locate import RITZ_EXTRA_MODES
from .search.mesh_error import coarse_model, mesh_error
from .search.nominal import fit_nominal, nominal_reduced
from .search.options import DEFAULTS, DiagnoseOptions
from .search.passes import diagnose_passes
from .search.rank import CandidateResult
from .search.result import Diagnosis
from .search.state import Run

__all__ = [
    "CandidateResult",
    "DEFAULTS",
    "DiagnoseOptions",
    "Diagnosis",
    "RITZ_EXTRA_MODES",
    "coarse_model",
    "diagnose",
    "fit_nominal",
    "mesh_error",
    "nominal_reduced",
]

log = logging.getLogger(__name__)


def diagnose(
    case,
    model=None,
    physics=None,
    rng=None,
    progress=None,
    pairing="auto",
    *,
    options=None,
    fast=None,
    store=None,
    **settings,
):
    """Diagnose a case: nominal fit, location, candidate ranking, refit, verdict.

    Parameters
    ----------
    case : bayesplate.io.Case
        Duck-typed: its ``.plate``, ``.measured`` and ``.prior``.
    model : PlateModel, optional
        Default: the case's mesh.
    physics : list of Physics, optional
        Candidates to rank (default: all of :func:`bayesplate.discrepancy.candidates`); the
        located ones among them are also mapped and scanned.
    rng : numpy.random.Generator or int, optional
        Seeds the random starts of the nominal fit.
    progress : callable, optional
        ``progress(message)`` after each step.
    pairing : {"auto", "mac", "likelihood", "index", "order"} or Pairing
        Measured-to-computed modes (:func:`bayesplate.matching.pairing.pair_measured` at the prior
        mean, as :func:`bayesplate.estimators.estimate` takes it): "auto" pairs by shape
        and frequency when the case has shapes, else by mode numbers if any, else by order
        checked (the assignment made again at the verdict's fit: ``reassign``);
        "likelihood" takes the assignment B settles on (on `model`). Unpaired measured modes
        (spurious peaks) are left out.
    options : DiagnoseOptions, optional
        Every setting (default: :data:`DEFAULTS`).
    fast : bayesplate.reduced.CertifiedModel, optional
        A reduced model of ``model`` for the nominal fit's global stage (its reduced part is
        used uncertified, also outside its box); default: one built on the half mesh over
        the prior's 3-sigma box (:func:`nominal_reduced`). The best optima are refined on
        ``model`` either way.
    store : object with ``get(key)`` and ``put(key, value)``, optional
        Where the expensive stages (the nominal fit, each candidate's fit, the nominal refits
        from their constants, each pair) are looked up and stored as soon as each is done,
        so that a run again after an interruption resumes (:mod:`.search.store`; on disk:
        :class:`bayesplate.io.stage_store.DirectoryStore`). The results are the same bit for
        bit with or without it, with any worker count. None: nothing is kept.
    **settings
        Any field of :class:`DiagnoseOptions` by name (``alpha=0.05``, ``workers=2``, ...),
        over ``options``.

    Returns
    -------
    Diagnosis
    """
    options = DiagnoseOptions.of(options, **settings)
    rng = np.random.default_rng(rng)
    model = model or PlateModel.from_case(case)
    mu_b, V_b = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    checked = checks_order(case.measured, pairing)  # by order, the null: every peak a mode
    if not isinstance(pairing, Pairing):
        from ..estimators import settle_pairing

        pairing, _ = settle_pairing(case, model, pairing, tol=1e-2)
    say = progress or (lambda message: log.info(message))
    run = Run(
        case=case,
        model=model,
        coarse=coarse_model(model),  # the same in every pass
        physics=physics or all_candidates(model),
        prior=(mu_b, V_b),
        options=options,
        say=say,
        store=store,
        fast=fast,
    )
    return diagnose_passes(run, pairing, rng, checked)
