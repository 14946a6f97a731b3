"""A pass of diagnose with one assignment of the peaks, and the passes with others.

A pass is the stages in order, each handing its frozen state on (:mod:`.state`):
the deviations, the nominal fit, the location, the ranking, the refit and the verdict. After
the first, the assignment is made again at the verdict's fit and, where it differs, the
passes go on with it (:func:`.reassign.made_again`).
"""

from __future__ import annotations

import copy

from .conclude import conclude
from .deviations import deviations
from .locate import locate
from .nominal_check import fit_nominal_stage, nominal_again
from .rank import rank
from .reassign import made_again
from .refit import refit

__all__ = ["diagnose_passes", "one_pass"]


def one_pass(run, pairing, rng):
    """Steps 1-5 with one assignment of the peaks to the computed modes: a Diagnosis."""
    data = deviations(run, pairing)
    nominal = fit_nominal_stage(run, data, rng)
    if run.options.mesh_error_part == "corrected":  # the error where the constants are
        data = deviations(run, pairing, at=nominal.check.fit.b)
        nominal = nominal_again(run, data, nominal)
    located = locate(run, data, nominal)
    ranked = rank(located.fitting, run.physics)
    searched = refit(run, data, nominal, located, ranked)
    return conclude(run, data, nominal, located, searched)


def diagnose_passes(run, pairing, rng, checked):
    """The first pass with `pairing`, then others where the verdict's fit assigns otherwise.

    Parameters
    ----------
    run : Run
    pairing : bayesplate.matching.pairing.Pairing
        The assignment settled at the start.
    rng : numpy.random.Generator
        A second pass starts from the same state as the first (whether or not the first
        came from the store, which leaves the state unused).
    checked : bool
        Whether the pairing is by order checked (the null: every peak a mode).

    Returns
    -------
    Diagnosis
    """
    again = copy.deepcopy(rng)
    first = one_pass(run, pairing, rng)
    by_likelihood = pairing.how == "likelihood" and pairing.assignment
    if not run.options.reassign or not (checked or by_likelihood):
        return first  # by order, index or shapes as asked: kept
    settled = (lambda: _settled_by_likelihood(run)) if checked else None
    return made_again(
        first,
        lambda p: one_pass(run, p, again),
        run.model,
        pairing,
        run.case.measured,
        run.prior,
        run.say,
        settled,
    )


def _settled_by_likelihood(run):
    """The assignment B settles on (``pairing="likelihood"``)."""
    from ...estimators import settle_pairing

    return settle_pairing(run.case, run.model, "likelihood", tol=1e-2)[0]
