"""Diagnose a mismatch between the model and the recordings: the steps, in order.

1. Fit the nominal model globally (many starts on a reduced model, the best refined on the
   working mesh: :mod:`.nominal`) and check it: chi-square of the
   standardised residuals against ``m - p_eff`` degrees of freedom (``p_eff``: parameters
   the data fix), and a predictive check per mode (:mod:`.verdict`).
2. Locate: which modes carry the misfit, what kind of modes they are, and where on the plate
   a local change would explain the residuals (after the constants took their share): the
   location map and the Ritz scan of every located candidate (its
   :meth:`~.base.Physics.location_map` and :meth:`~.base.Physics.scan`).
3. Name: fit every candidate physics (every variant: a taper along x and along y) jointly
   with the constants, on a reduced model of the modified plate (:mod:`.pencil`) refined on
   the working mesh, and rank the candidates by their Laplace evidence gain over the nominal
   model (what the constants cannot absorb; :mod:`.rank`).
4. Model: the chosen candidate's joint fit is the refit, with its Laplace posterior. When
   the best single candidate's refit is still rejected, two effects at once: the best one
   paired with every other candidate (:mod:`.pair`), ranked on the same evidence scale.
5. Verdict: ``consistent``, ``explained``, ``ambiguous`` (the refit is consistent but a
   different candidate's posterior odds are within ``ambiguity_margin``, or within
   ``prior_margin`` while it fits the recordings as well: all that tie are named, and the
   measurement that would tell the first two apart, :mod:`.separate`) or ``unexplained``
   (:mod:`.verdict`), with the posterior probability of every model
   (:mod:`.probabilities`).

Before any of it, the mesh's own error on every frequency is estimated by Richardson
extrapolation (the element converges as h^2) and reported beside the measurement deviation;
where it is not well under it, it is added to the deviation in quadrature and the report says
so, so that discretisation is never blamed on physics.

No candidate is named here: the candidates are :class:`~.base.Physics` objects, and what is
found about each (maps, scans, results) is keyed by its :attr:`~.base.Physics.name`.
"""

from __future__ import annotations

import copy
import logging
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..checked_order import checks_order
from ..model import PlateModel
from ..pairing import Pairing
from ..parallel import fork_map
from ..posterior import observed_eigenvalues, prior_in_stiffness
from ..quantities import hz_from_eigenvalue
from . import candidates as all_candidates
from .physics.location import absorbable_projector, best_region, mode_kinds
from .physics.ritz_scan import RitzBasis
from .search.joint_fit import JointFit, JointProblem
from .search.mesh_error import MESH_ERROR_PARTS, coarse_model, mesh_error, unabsorbed
from .search.nominal import N_STARTS, check_fast, fit_nominal, nominal_reduced, nominal_stage
from .search.probabilities import model_probabilities
from .search.rank import CandidateResult, improved_nominal, rank, searched_anew
from .search.reassign import made_again
from .search.separation import Separation, separate
from .search.store import Stages, digest, fit_digest, plate_digest
from .search.two_effects import two_effects
from .search.verdict import (
    basins_note,
    predictive_p_values,
    refit_test,
    tie_text,
    ties,
    unidentified,
    unsettled_notes,
    verdict,
)

__all__ = [
    "CandidateResult",
    "DEFAULTS",
    "Diagnosis",
    "coarse_model",
    "diagnose",
    "fit_nominal",
    "mesh_error",
    "nominal_reduced",
]

log = logging.getLogger(__name__)


DEFAULTS = {
    "alpha": 0.01,  # significance of the chi-square test
    "evidence_threshold": 3.0,  # nats (about 20:1): a candidate must gain this much
    "n_starts": N_STARTS,  # random starts of the nominal fit (reduced model), and the mean
    "unidentified_ratio": 0.7,  # posterior sd / prior sd above which a constant is unidentified
    "mesh_error_ratio": 0.3,  # mesh error / sigma above which sigma is inflated
    "mesh_error_part": "whole",  # of the mesh error added: all, or what the constants leave
    "refine_margin": 1.0,  # nats: candidates below this on the coarse mesh are not refined
    "basin_margin": 2.0,  # chi2 + chi2_prior: another nominal optimum this close fits as well
    "workers": 1,  # processes for independent fits (fork); the CLI uses 2
    "ambiguity_margin": 2.0,  # nats (odds about 7:1): a different candidate this close ties
    "prior_margin": 4.0,  # nats (odds about 55:1): one that fits as well this close ties too
    "pairs": True,  # fit two effects at once when the best single one is rejected
    "reassign": True,  # the assignment made again at the verdict's fit (not by order/index)
}
"""Default values of :func:`diagnose`'s keyword-only options (their single source)."""

#: Elastic modes of the Ritz basis of the scans beyond the highest paired one.
RITZ_EXTRA_MODES = 20


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`diagnose` found; see the module docstring for the steps.

    Attributes
    ----------
    verdict : {"consistent", "explained", "ambiguous", "unexplained"}
    nominal : JointFit
    dof : float
        Degrees of freedom of the nominal chi-square.
    p_value : float
    mode_p_values : numpy.ndarray, shape (m,)
        Predictive two-sided p-value of each measured frequency under the nominal fit.
    located_modes : list of int
        1-based measured modes whose standardised residual exceeds 2.
    mode_kinds : list of str
    maps : dict of LocationMap
        One per located candidate among ``physics``, keyed by its
        :attr:`~.base.Physics.name`, in the order of ``physics``.
    region_mm : tuple or None
        Best location of a local change, mm; ``region_mirrors_mm`` fit equally.
    candidates : list of CandidateResult
        Best first; every variant of a candidate is one (a taper along x and one along y,
        told apart by ``parameters["direction"]``), and so is every pair of effects fitted
        (named ``first+second``, :mod:`.pair`).
    chosen : CandidateResult or None
        The best candidate when ``explained`` or ``ambiguous``.
    refit_dof, refit_p_value : float
    unidentified : list of str
        Constants the data do not inform (nominal fit, and refit when there is one).
    sigma_Hz, mesh_error_Hz : numpy.ndarray, shape (m,)
    notes : list of str
    scans : dict of Scan
        The Ritz scan of each located candidate, keyed as ``maps``.
    probabilities : dict
        Posterior probability of ``"nominal"`` (nothing left out) and of each candidate by
        name, variants summed (:func:`.probabilities.model_probabilities`).
    rival : CandidateResult or None
        When ``ambiguous``: the runner-up, a different candidate.
    separation : Separation or None
        When ``ambiguous``: the measurement that would tell ``chosen`` from ``rival``.
    also_tied : list of CandidateResult
        When ``ambiguous``: the further candidates that tie with ``chosen`` as well.
    peak_modes : numpy.ndarray of int, shape (m_all,), or None
        The computed mode (0-based) of every measured peak in the pass kept, -1 where it was
        left out as spurious; set when the assignment was made again at the verdict's fit
        (:mod:`.reassign`).
    passes : int
        Passes diagnose ran, each with another assignment of the peaks (:mod:`.reassign`).
    """

    verdict: str
    nominal: JointFit = field(repr=False)
    dof: float
    p_value: float
    mode_p_values: np.ndarray
    located_modes: list
    mode_kinds: list
    maps: dict = field(repr=False)
    region_mm: tuple | None
    region_mirrors_mm: list
    candidates: list = field(repr=False)
    chosen: CandidateResult | None
    refit_dof: float
    refit_p_value: float
    unidentified: list
    sigma_Hz: np.ndarray
    mesh_error_Hz: np.ndarray
    measured_Hz: np.ndarray
    notes: list
    scans: dict = field(default_factory=dict, repr=False)
    probabilities: dict = field(default_factory=dict)
    rival: CandidateResult | None = None
    separation: Separation | None = None
    peak_modes: np.ndarray | None = None
    also_tied: list = field(default_factory=list, repr=False)
    passes: int = 1


def diagnose(
    case,
    model=None,
    physics=None,
    rng=None,
    progress=None,
    pairing="auto",
    *,
    alpha=DEFAULTS["alpha"],
    evidence_threshold=DEFAULTS["evidence_threshold"],
    n_starts=DEFAULTS["n_starts"],
    unidentified_ratio=DEFAULTS["unidentified_ratio"],
    mesh_error_ratio=DEFAULTS["mesh_error_ratio"],
    mesh_error_part=DEFAULTS["mesh_error_part"],
    refine_margin=DEFAULTS["refine_margin"],
    basin_margin=DEFAULTS["basin_margin"],
    workers=DEFAULTS["workers"],
    ambiguity_margin=DEFAULTS["ambiguity_margin"],
    prior_margin=DEFAULTS["prior_margin"],
    pairs=DEFAULTS["pairs"],
    reassign=DEFAULTS["reassign"],
    prior_odds=None,
    fast=None,
    store=None,
):
    """Diagnose a case: nominal fit, location, candidate ranking, refit, verdict.

    The defaults are those of :data:`DEFAULTS`.

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
        Measured-to-computed modes (:func:`bayesplate.pairing.pair_measured` at the prior
        mean, as :func:`bayesplate.estimators.estimate` takes it): "auto" pairs by shape
        and frequency when the case has shapes, else by mode numbers if any, else by order
        checked (the assignment made again at the verdict's fit: `reassign`);
        "likelihood" takes the assignment B settles on (on `model`). Unpaired measured modes
        (spurious peaks) are left out.
    alpha : float
        Significance of the chi-square tests (nominal fit and refit).
    evidence_threshold : float
        Laplace evidence gain a candidate needs to be chosen, nats (3: about 20 to 1).
    n_starts : int
        Random starts of the nominal fit (on the reduced model), besides the prior mean.
    unidentified_ratio : float
        Posterior sd / prior sd above which a constant is reported as unidentified.
    mesh_error_ratio : float
        Mesh error / measurement deviation above which the deviation is inflated.
    mesh_error_part : {"whole", "unabsorbed"}
        What of the mesh's estimated error inflates the deviations: all of it, or the part
        the six constants cannot absorb (:mod:`.mesh_error`; measured by
        ``studies/mesh_error_rule.py``).
    refine_margin : float
        Candidates gaining less than this on their reduced coarse model are not refined on
        the working mesh, nats.
    basin_margin : float
        Another nominal optimum whose ``chi2 + chi2_prior`` is this close fits as well.
    workers : int
        Processes for the independent fits (fork); the results do not depend on it.
    ambiguity_margin : float
        Posterior log-odds of the best candidate against a different one under which the
        verdict is ``ambiguous``, nats (2: about 7 to 1); also the log-likelihood margin of
        a rival that fits as well.
    prior_margin : float
        Log-odds under which a different candidate that fits the recordings as well makes
        the verdict ``ambiguous``: the odds are then its prior volume's alone, nats (4:
        about 55 to 1; :func:`.verdict.ties`).
    pairs : bool
        Fit two effects at once when the best single candidate's refit is rejected.
    reassign : bool
        Make the assignment again at the fit the verdict rests on and, where it differs (by
        order checked: where it pairs a peak with another mode), diagnose again (:mod:`.reassign`).
        Order or index asked by name, and pairing by shapes, are kept as they are.
    prior_odds : dict, optional
        ``{candidate name: prior odds against the nominal model}`` (default 1 for every
        candidate; a case-file key for them is not defined yet).
    fast : bayesplate.reduced.CertifiedModel, optional
        A reduced model of ``model`` for the nominal fit's global stage (its reduced part is
        used uncertified, also outside its box); default: one built on the half mesh over
        the prior's 3-sigma box (:func:`nominal_reduced`). The best optima are refined on
        ``model`` either way.
    store : object with ``get(key)`` and ``put(key, value)``, optional
        Where the expensive stages (the nominal fit, each candidate's fit, the nominal refits
        from their constants, each pair) are looked up and stored as soon as each is done,
        so that a run again after an interruption resumes (:mod:`.store`; on disk:
        :class:`bayesplate.io.stage_store.DirectoryStore`). The results are the same bit for
        bit with or without it, with any worker count. None: nothing is kept.

    Returns
    -------
    Diagnosis
    """
    if mesh_error_part not in MESH_ERROR_PARTS:
        raise ValueError(f"mesh_error_part = {mesh_error_part!r}: must be one of "
                         f"{', '.join(MESH_ERROR_PARTS)}")  # fmt: skip
    rng = np.random.default_rng(rng)
    say = progress or (lambda message: log.info(message))
    model = model or PlateModel.from_case(case)
    physics = physics or all_candidates()
    mu_b, V_b = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    checked = checks_order(case.measured, pairing)  # by order, the null: every peak a mode
    if not isinstance(pairing, Pairing):
        from ..estimators import settle_pairing

        pairing, _ = settle_pairing(case, model, pairing, tol=1e-2)
    coarse = coarse_model(model)  # the same in every pass
    at_mean = {}  # n -> both meshes' lowest n eigenvalues at the prior mean (the mesh error)

    def one_pass(pairing, rng):
        """Steps 1-5 with one assignment of the peaks to the computed modes."""
        measured, modes = pairing.select(case.measured), pairing.modes
        m = measured.size
        notes = []
        if getattr(case.measured, "error_scale", None) is not None:
            notes.append("the case gives an error scale for its deviations; diagnose tests against "
                         "the declared deviations (s = 1), so a misfit the scale would absorb "
                         "shows here as a mismatch")  # fmt: skip

        n_solve = int(modes.max()) + 1
        if n_solve not in at_mean:  # a second pass (another assignment) solves nothing again
            at_mean[n_solve] = (model.solve(mu_b, n_solve),
                                coarse.solve(mu_b, n_solve).eigenvalues)  # fmt: skip
        at_fine, coarse_at_mean = at_mean[n_solve]
        fine_lam = at_fine.eigenvalues
        err = ((hz_from_eigenvalue(coarse_at_mean) - hz_from_eigenvalue(fine_lam)) / 3.0)[modes]
        sigma_Hz = np.asarray(measured.sigma_Hz, dtype=float)
        ratio = np.abs(err) / sigma_Hz
        say(f"mesh {model.mesh.nx} x {model.mesh.ny}: error up to {ratio.max():.2f} sigma")
        added, left, what = err, ratio.max(), "it was"
        if mesh_error_part == "unabsorbed":  # what the six constants cannot take themselves
            added = unabsorbed(err, sigma_Hz, fine_lam[modes], at_fine.sensitivities[modes])
            left = np.abs(added / sigma_Hz).max()
            what = f"the part of it the constants cannot absorb (up to {left:.2f} sigma) was"
        if left > mesh_error_ratio:
            sigma_Hz = np.hypot(sigma_Hz, added)
            notes.append(
                f"the mesh's own error reaches {ratio.max():.2f} sigma (mode "
                f"{int(np.argmax(ratio)) + 1}); {what} added to the deviations in quadrature: "
                "use a finer [model] mesh"
            )
        Y = observed_eigenvalues(measured.frequency_Hz)
        sigma = 2.0 * Y * sigma_Hz / measured.frequency_Hz  # d lambda = 2 lambda df / f

        nominal_problem = JointProblem(model, Y, sigma, mu_b, V_b, modes)
        options = (alpha, evidence_threshold, n_starts, unidentified_ratio, mesh_error_ratio,
                   refine_margin, basin_margin, ambiguity_margin, prior_margin, pairs,
                   prior_odds)  # fmt: skip
        if mesh_error_part != "whole":  # (the default keeps the stores' keys of before)
            options += (mesh_error_part,)
        stages = Stages(store, digest(Y, sigma, measured.frequency_Hz, modes, mu_b, V_b, options,
                                      plate_digest(model), physics, fast), say)  # fmt: skip
        rough, nominal = nominal_stage(nominal_problem, (mu_b, V_b), coarse,
                                       (fine_lam / coarse_at_mean)[modes], rng, n_starts, workers,
                                       fast, stages)  # fmt: skip
        stages = stages.then("nominal", fit_digest(nominal))
        if fast is not None:
            check_fast(fast, nominal, modes, notes)
        dof = max(m - nominal.effective_parameters, 1.0)
        p_value = float(chi2_dist.sf(nominal.chi2, dof))
        say(f"nominal fit: chi2 = {nominal.chi2:.1f} on {dof:.1f} dof, p = {p_value:.3g}")
        mode_p = predictive_p_values(nominal, nominal_problem)
        loose = unidentified(nominal, V_b, unidentified_ratio, basin_margin)

        kinds = mode_kinds(model, _paired(nominal, modes))
        # what the constants can absorb, whitened: projected out of the maps and of the scans
        P = absorbable_projector(_paired(nominal, modes).sensitivities * nominal.b / sigma[:, None])
        maps = _maps(physics, model, nominal, modes, sigma, P)
        region, mirrors = best_region(model, maps)
        located = [int(i) + 1 for i in np.flatnonzero(np.abs(nominal.residual_sigma) > 2.0)]

        coarse_nominal = coarse.solve(nominal.b, int(modes.max()) + 1 + RITZ_EXTRA_MODES)
        level = {"coarse": coarse, "scale": nominal.eigenvalues / coarse_nominal.eigenvalues[modes],
                 "margin": refine_margin, "workers": workers, "threshold": evidence_threshold,
                 "coarse_modes": coarse_nominal.vectors, "rough": rough}  # fmt: skip
        ritz = model.solve(nominal.b, int(modes.max()) + 1 + RITZ_EXTRA_MODES)
        level["modes"] = ritz.vectors
        scans = _scans(physics, model, nominal, modes, Y, sigma, P, ritz, workers)
        ranked = rank(
            model, level, Y, sigma, mu_b, V_b, modes, nominal, scans, physics, say, stages
        )
        better = stages.run(
            "nominal refit from the candidates' constants",
            stages.key("improved", [fit_digest(c.fit) for c in ranked]),
            lambda: improved_nominal(nominal_problem, nominal, ranked, level),
        )
        if better is not None:
            stages = stages.then("improved", fit_digest(better))
            say(f"nominal fit improved from a candidate's constants: chi2 = {better.chi2:.1f}")
            shift = better.log_evidence - nominal.log_evidence
            ranked = [replace(c, log_evidence_gain=c.log_evidence_gain - shift) for c in ranked]
            earlier = ((nominal.b, nominal.chi2 + nominal.chi2_prior), *nominal.alternatives)
            nominal = replace(better, alternatives=earlier)  # the other basins stay known
            dof = max(m - nominal.effective_parameters, 1.0)
            p_value = float(chi2_dist.sf(nominal.chi2, dof))
            mode_p = predictive_p_values(nominal, nominal_problem)
            loose = unidentified(nominal, V_b, unidentified_ratio, basin_margin)
        best = next((c for c in ranked if c.fit.refined), None)
        warranted = best is not None and best.log_evidence_gain > evidence_threshold
        refit_dof, refit_p = np.nan, np.nan
        if warranted:
            refit_dof, refit_p = refit_test(best.fit, m)
        if warranted and refit_p < alpha:  # rejected: its constants searched again, globally
            anew = stages.run(
                f"{best.name}: constants searched again",
                stages.key("anew", fit_digest(best.fit)),
                lambda: searched_anew(model, level, Y, sigma, mu_b, V_b, modes, nominal, best),
            )
            if anew is not None:
                anew = replace(anew, fit=replace(anew.fit, physics=best.fit.physics))
                stages = stages.then("anew", fit_digest(anew.fit))
                say(
                    f"{best.name}: refit rejected (p = {refit_p:.2g}); from its constants "
                    f"searched again: chi2 = {anew.fit.chi2:.1f}, evidence gain "
                    f"{anew.log_evidence_gain:+.1f}"
                )
                ranked = sorted([anew if c is best else c for c in ranked],
                                key=lambda r: -r.log_evidence_gain)  # fmt: skip
                best = anew
                refit_dof, refit_p = refit_test(best.fit, m)
        if warranted and refit_p < alpha and pairs:  # two effects at once
            fitting = dict(model=model, level=level, Y=Y, sigma=sigma, mu_b=mu_b, V_b=V_b,
                           modes=modes, nominal=nominal, scans=scans, say=say, stages=stages)
            top, two = two_effects(best, ranked, physics, fitting, evidence_threshold, alpha, m)
            if top is not None:
                best = top
                refit_dof, refit_p = refit_test(best.fit, m)
            ranked = sorted(ranked + two, key=lambda r: -r.log_evidence_gain)
        if warranted:
            loose = unidentified(best.fit, V_b, unidentified_ratio)
        probabilities = model_probabilities([(c.name, c.log_evidence_gain) for c in ranked],
                                            prior_odds)  # fmt: skip
        tied = (ties(best, ranked, probabilities, ambiguity_margin, prior_margin)
                if warranted else [])  # fmt: skip
        outcome, chosen = verdict(p_value, warranted, refit_p, alpha, best, tied=bool(tied))
        rival, separation = (tied[0][0] if outcome == "ambiguous" else None), None
        if outcome == "ambiguous":
            separation = separate(
                model, best, rival, modes, float(np.median(sigma_Hz / measured.frequency_Hz))
            )
            notes.append(tie_text(best, tied, probabilities) + separation.text())
        if outcome == "consistent":
            region, mirrors = None, []
        if outcome == "unexplained":
            notes.append(
                "the recordings disagree with the model beyond their deviations and no candidate "
                "physics explains the mismatch"
            )
        basins = basins_note(nominal, basin_margin)
        if basins is not None and chosen is None:
            notes.append(basins)
        if outcome != "consistent" and region is not None and mirrors:
            notes.append("the plate's symmetry makes the mirror images of the located region fit "
                         "equally well from frequencies alone")  # fmt: skip
        notes += unsettled_notes(nominal, chosen, tied if rival else [], ranked)
        say(f"verdict: {outcome}" + (f" ({chosen.name})" if chosen else "")
            + "".join(f" or {c.name}" for c, _ in (tied if rival else [])))  # fmt: skip
        return Diagnosis(
            outcome, nominal, dof, p_value, mode_p, located, kinds, maps, region, mirrors, ranked,
            chosen, refit_dof, refit_p, loose, sigma_Hz, err, measured.frequency_Hz, notes, scans,
            probabilities, rival, separation, also_tied=[c for c, _ in tied[1:]] if rival else [],
        )  # fmt: skip

    # a second pass starts from the same random state (whether or not the first came from
    # the store, which leaves the state unused)
    again = copy.deepcopy(rng)
    first = one_pass(pairing, rng)
    if not reassign or not (checked or pairing.how == "likelihood" and pairing.assignment):
        return first  # by order, index or shapes as asked: kept
    settled = (lambda: settle_pairing(case, model, "likelihood", tol=1e-2)[0]) if checked else None
    return made_again(first, lambda p: one_pass(p, again), model, pairing, case.measured,
                      (mu_b, V_b), say, settled)  # fmt: skip


def _paired(fit_, modes):
    """The fit's modal result restricted to the paired modes (measured order)."""
    modal = fit_.modal
    return type(modal)(modal.b, modal.eigenvalues[modes], modal.vectors[:, modes],
                       modal.sensitivities[modes], modal.rigid_eigenvalues)  # fmt: skip


def _maps(physics_list, model, nominal, modes, sigma, P):
    """Location maps of the located candidates at the nominal fit, keyed by name."""
    paired = _paired(nominal, modes)
    r = nominal.residual_sigma
    maps = {}
    for physics in physics_list:
        location = physics.location_map(model, paired, nominal.b, r, sigma, P)
        if location is not None:
            maps[physics.name] = location
    return maps


def _scans(physics_list, model, nominal, modes, Y, sigma, P, ritz, workers=1):
    """Ritz scans of the located candidates at the nominal fit, keyed by name.

    The Ritz basis (:mod:`.scan`) holds the nominal modes up to ``RITZ_EXTRA_MODES`` beyond
    the highest paired one (``ritz``: the nominal fit's modes). The candidates' scans are
    independent: on ``workers`` processes (:func:`bayesplate.parallel.fork_map`).
    """
    basis = RitzBasis.from_modes(model, ritz)
    found = fork_map(lambda physics: physics.scan(model, basis, nominal.b, Y, sigma, modes, P),
                     physics_list, workers)  # fmt: skip
    return {physics.name: result for physics, result in zip(physics_list, found, strict=True)
            if result is not None}  # fmt: skip
