"""Two effects at once: the pairs' stage of a pass (:mod:`.refit`).

It runs when the best single candidate's refit is rejected. The leading single candidates
are taken in turn, best first (at most :data:`LEADERS` of distinct names): each is paired
with every other candidate (:func:`..physics.combined.pairs_with`), leaving out the pairs
fitted already, and the pairs are ranked on the same evidence scale as the single ones
(:func:`.rank.rank`), by the same rules with the best single candidate in the nominal
model's place (:func:`pair_fitting`): a pair is refined on the working mesh when its rough
gain exceeds the best single one's by the refinement margin, and chosen when it gains more
than the threshold over it; the turn ends there if its refit is not rejected. The next
leader's turn is for a recording whose two effects the best single candidate does not
stand for: a 1 g mass with a 3 degree misalignment on the Frederiksen plate (50 x 50) was
best explained alone by a stiffness loss (+565 nats, the mass second at +530); every pair
with the stiffness loss was rejected.

A later leader's turn is skipped when ``enough`` says the fits so far are beaten already
(by the unnamed local change, :mod:`.unnamed`, by more than its margin: the verdict is
then ``unexplained`` unless a pair of that leader beat it too). On an edge notch outside
the candidates (``studies/outside_effects.py``) the second leader's nine pairs took 148 of
398 s and the best of them gained +9.0 nats against the unnamed change's +17.4.
"""

from __future__ import annotations

from dataclasses import replace

from ..physics.combined import pairs_with
from .rank import REACH_SHARE, rank
from .verdict import refit_test

__all__ = ["LEADERS", "pair_fitting", "two_effects"]

#: Single candidates (distinct names, best first) whose pairs are fitted in turn.
LEADERS = 2


def pair_fitting(fitting, best, threshold):
    """What the pairs' fits take: ``fitting`` with its bars raised to the best single gain.

    A single candidate is refined when its rough gain exceeds the nominal model's (0) by
    ``fitting.margin`` and may be named above ``threshold``; a pair, when it exceeds the best
    single candidate's gain ``g`` by as much, less :data:`.rank.REACH_SHARE` of ``g`` (a
    coarse model misjudges a large gain by a tenth and more), and may be chosen above
    ``g + threshold``. Below that it cannot be chosen, and a pair's refinement is the
    dearest of a diagnosis.

    Measured, each diagnosis alone on two workers: the calibration study's fifth edge notch
    (60 x 30; the stiffness loss +6.0 alone, its nine pairs' rough gains -1.9 to +5.3) took
    403 s with the pairs ranked against the nominal model (all nine refined, +5.9 at best)
    and 187 s so (none refined), ``unexplained`` both; the concealment study's mass with a
    misalignment (24 x 24; the best pair +242.4) refines the same 15 fits either way.

    Parameters
    ----------
    fitting : Fitting
    best : CandidateResult
        The best single candidate.
    threshold : float
        Evidence gain over ``best`` for a pair to be chosen, nats.

    Returns
    -------
    Fitting
    """
    g = best.log_evidence_gain
    margin = g + fitting.margin - REACH_SHARE * max(g, 0.0)
    return replace(fitting, margin=margin, threshold=g + threshold)


def _key(physics):
    """A pair's components, in either order (a taper's direction told apart)."""
    return frozenset(
        (c.name, tuple(sorted(c.settings().items()))) for c in (physics.first, physics.second)
    )


def two_effects(best, ranked, physics, fitting, threshold, alpha, m, leaders=None, enough=None):
    """The pairs of the leading single candidates, in turn, until one explains.

    Parameters
    ----------
    best : CandidateResult
        The best single candidate (its refit rejected).
    ranked : list of CandidateResult
        Every single candidate, best first.
    physics : list of Physics
        The single candidates.
    fitting : Fitting
        What :func:`.rank.rank` takes besides the candidates (:class:`.state.Fitting`).
    threshold : float
        Evidence gain over the best single candidate for a pair to be chosen, nats.
    alpha : float
        Level of the refit's chi-square test.
    m : int
        Paired frequencies.
    leaders : int, optional
        Default :data:`LEADERS`.
    enough : callable, optional
        ``enough(gain) -> str or None``: before a later leader's turn, with the largest
        evidence gain fitted so far (single or pair, nats); a reason (said, and returned as
        ``stopped``) ends the stage there.

    Returns
    -------
    chosen : CandidateResult or None
        The best pair gaining ``threshold`` over ``best`` (None if none does).
    pairs : list of CandidateResult
        Every pair fitted, best first.
    stopped : str or None
        Why a later leader's turn was skipped (``enough``'s reason).
    """
    leaders = LEADERS if leaders is None else leaders
    names, fitted, done, chosen, stopped = [], [], set(), None, None
    ranking = pair_fitting(fitting, best, threshold)
    for leader in [best, *ranked]:
        if len(names) == leaders or (chosen is not None and refit_test(chosen.fit, m)[1] >= alpha):
            break
        if leader.name in names:
            continue
        if names and enough is not None:
            top_gain = max(c.log_evidence_gain for c in [best, *fitted])
            stopped = enough(top_gain)
            if stopped:
                fitting.say(f"{leader.name} not paired: {stopped}")
                break
        names.append(leader.name)
        if len(names) > 1:
            fitting.say(f"no pair with {names[0]} explains: {leader.name} paired as well")
        todo = [
            p
            for p in pairs_with(leader, physics, ranked, fitting.model, fitting.scans)
            if _key(p) not in done
        ]
        done |= {_key(p) for p in todo}
        fitted += rank(fitting=ranking, physics_list=todo)
        top = max(
            (c for c in fitted if c.fit.refined), default=None, key=lambda c: c.log_evidence_gain
        )
        if top is not None and top.log_evidence_gain > ranking.threshold:  # g + threshold
            chosen = top
    return chosen, sorted(fitted, key=lambda c: -c.log_evidence_gain), stopped
