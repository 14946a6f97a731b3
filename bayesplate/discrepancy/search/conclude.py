"""Step 5 of a pass, the verdict: what the evidence says, its ties and notes, the Diagnosis.

``consistent``, ``explained``, ``ambiguous`` (the refit is consistent but a different
candidate fits the recordings as well, within ``ambiguity_margin`` of log-likelihood, and
its posterior odds are within ``prior_margin``: all that tie are named, with the
measurement that would tell the first two apart, :mod:`.separation`) or ``unexplained``
(:mod:`.verdict`), with the posterior probability of every model (:mod:`.probabilities`).
"""

from __future__ import annotations

import numpy as np

from .probabilities import model_probabilities
from .result import Diagnosis
from .separation import separate
from .unnamed import beaten, unnamed
from .verdict import basins_note, tie_text, ties, unsettled_notes, verdict

__all__ = ["conclude"]

_UNEXPLAINED = (
    "the recordings disagree with the model beyond their deviations and no "
    "candidate physics explains the mismatch"
)
_MIRRORS = (
    "the plate's symmetry makes the mirror images of the located region fit equally "
    "well from frequencies alone"
)


def conclude(run, data, nominal_stage, located, searched):
    """The verdict of a pass and its :class:`~.result.Diagnosis` (every stage's result)."""
    o, s, check = run.options, searched, searched.check
    probabilities = model_probabilities(
        [(c.name, c.log_evidence_gain) for c in s.ranked], o.prior_odds
    )
    tied = (
        ties(s.best, s.ranked, probabilities, o.ambiguity_margin, o.prior_margin)
        if s.warranted
        else []
    )
    outcome, chosen = verdict(
        check.p_value, s.warranted, s.refit_p_value, o.alpha, s.best, tied=bool(tied)
    )
    change = None
    if outcome != "consistent" and o.unnamed_margin is not None:
        change = s.unnamed or unnamed(run.model, check.fit, data.problem, data.modes)
        if chosen is not None and beaten(chosen.log_evidence_gain, change, o.unnamed_margin):
            run.say(
                f"an unnamed local change gains {change.log_evidence_gain:+.1f} nats, "
                f"{chosen.name} {chosen.log_evidence_gain:+.1f}"
            )
            outcome, chosen, tied = "unexplained", None, []
    rival = tied[0][0] if outcome == "ambiguous" else None
    separation, notes = None, [*data.notes, *nominal_stage.notes, *s.notes]
    if outcome == "ambiguous":
        relative_sd = float(np.median(data.sigma_Hz / data.measured.frequency_Hz))
        separation = separate(run.model, s.best, rival, data.modes, relative_sd)
        notes.append(tie_text(s.best, tied, probabilities) + separation.text())
    region, mirrors = located.region, located.mirrors
    if outcome == "consistent":
        region, mirrors = None, []
    notes += _notes(outcome, chosen, check.fit, o.basin_margin, region is not None and mirrors)
    notes += _unnamed_notes(outcome, s.best if s.warranted else None, change, o.unnamed_margin)
    notes += unsettled_notes(check.fit, chosen, tied if rival else [], s.ranked)
    run.say(
        f"verdict: {outcome}"
        + (f" ({chosen.name})" if chosen else "")
        + "".join(f" or {c.name}" for c, _ in (tied if rival else []))
    )
    return Diagnosis(
        verdict=outcome,
        nominal=check.fit,
        dof=check.dof,
        p_value=check.p_value,
        mode_p_values=check.mode_p_values,
        located_modes=located.located_modes,
        mode_kinds=located.kinds,
        maps=located.maps,
        region_mm=region,
        region_mirrors_mm=mirrors,
        candidates=s.ranked,
        chosen=chosen,
        refit_dof=s.refit_dof,
        refit_p_value=s.refit_p_value,
        unidentified=s.unidentified,
        sigma_Hz=data.sigma_Hz,
        mesh_error_Hz=data.mesh_error_Hz,
        measured_Hz=data.measured.frequency_Hz,
        notes=notes,
        scans=located.fitting.scans,
        probabilities=probabilities,
        rival=rival,
        separation=separation,
        also_tied=[c for c, _ in tied[1:]] if rival else [],
        unnamed=change,
    )


def _unnamed_notes(outcome, best, change, margin):
    """What the unnamed local change says: where the mismatch sits, and against what."""
    if change is None or outcome == "consistent":
        return []
    gain = change.log_evidence_gain
    if outcome == "unexplained" and best is not None and gain > best.log_evidence_gain:
        return [
            f"an unnamed local change fits better than every named candidate (evidence gain "
            f"{gain:.1f} nats against {best.log_evidence_gain:.1f} of {best.name}): the plate "
            f"differs from the model in a way none of the candidates describes; {change.text()}"
        ]
    if outcome == "unexplained":
        return [change.text()[0].upper() + change.text()[1:]]
    if gain > best.log_evidence_gain - margin:
        return [
            f"an unnamed local change fits about as well as {best.name} (evidence gain "
            f"{gain:.1f} nats against {best.log_evidence_gain:.1f}): the name is the nearest "
            f"of the candidates, not a certainty; {change.text()}"
        ]
    return []


def _notes(outcome, chosen, nominal, basin_margin, mirrored):
    """The verdict's notes on no explanation, other nominal basins and mirror images."""
    notes = []
    if outcome == "unexplained":
        notes.append(_UNEXPLAINED)
    basins = basins_note(nominal, basin_margin)
    if basins is not None and chosen is None:
        notes.append(basins)
    if outcome != "consistent" and mirrored:
        notes.append(_MIRRORS)
    return notes
