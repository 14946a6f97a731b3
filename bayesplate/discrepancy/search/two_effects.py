"""Two effects at once: the pairs' stage of a pass (:mod:`.refit`).

It runs when the best single candidate's refit is rejected. The leading single candidates
are taken in turn, best first (at most :data:`LEADERS` of distinct names): each is paired
with every other candidate (:func:`..physics.combined.pairs_with`), leaving out the pairs
fitted already, and the pairs are ranked on the same evidence scale as the single ones
(:func:`.rank.rank`).
A pair is chosen when it gains more than the threshold over the best single candidate; the
turn ends there if its refit is not rejected. The next leader's turn is for a recording
whose two effects the best single candidate does not stand for: a 1 g mass with a 3 degree
misalignment on the Frederiksen plate (50 x 50) was best explained alone by a stiffness
loss (+565 nats, the mass second at +530); every pair with the stiffness loss was rejected.
"""

from __future__ import annotations

from ..physics.combined import pairs_with
from .rank import rank
from .verdict import refit_test

__all__ = ["LEADERS", "two_effects"]

#: Single candidates (distinct names, best first) whose pairs are fitted in turn.
LEADERS = 2


def _key(physics):
    """A pair's components, in either order (a taper's direction told apart)."""
    return frozenset(
        (c.name, tuple(sorted(c.settings().items()))) for c in (physics.first, physics.second)
    )


def two_effects(best, ranked, physics, fitting, threshold, alpha, m, leaders=None):
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

    Returns
    -------
    chosen : CandidateResult or None
        The best pair gaining ``threshold`` over ``best`` (None if none does).
    pairs : list of CandidateResult
        Every pair fitted, best first.
    """
    leaders = LEADERS if leaders is None else leaders
    names, fitted, done, chosen = [], [], set(), None
    for leader in [best, *ranked]:
        if len(names) == leaders or (chosen is not None and refit_test(chosen.fit, m)[1] >= alpha):
            break
        if leader.name in names:
            continue
        names.append(leader.name)
        if len(names) > 1:
            fitting.say(f"no pair with {names[0]} explains: {leader.name} paired as well")
        todo = [
            p
            for p in pairs_with(leader, physics, ranked, fitting.model, fitting.scans)
            if _key(p) not in done
        ]
        done |= {_key(p) for p in todo}
        fitted += rank(fitting=fitting, physics_list=todo)
        top = max(
            (c for c in fitted if c.fit.refined), default=None, key=lambda c: c.log_evidence_gain
        )
        if top is not None and top.log_evidence_gain > best.log_evidence_gain + threshold:
            chosen = top
    return chosen, sorted(fitted, key=lambda c: -c.log_evidence_gain)
