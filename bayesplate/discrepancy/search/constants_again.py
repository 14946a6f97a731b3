"""A rejected refit searched again: the candidate's constants, globally, at its own effect.

A strong effect drags the nominal fit's constants far from where they are (a ply
misalignment of 8 degrees on the Frederiksen plate: nu12 2.8 prior deviations low), and a
candidate's fit, started there, settles in a basin the drag made: objective 52.7 with the
misalignment found (chi-square rejected), against 16.7 at the true constants. Neither a
reduced model built at the nominal fit nor a local fit from the prior mean reaches the
better basin reliably (a bounded trust-region fit from the prior mean stopped at 699).

With the physics parameters held at the candidate's answer ``theta``, the problem in the
constants alone is the nominal problem of the plate *with* the effect, and the nominal fit's
global stage applies to it unchanged: a reduced model over the prior's box
(:func:`.nominal.nominal_reduced`) and its first round (:func:`.nominal.first_round`: the
prior mean and random draws as starts). Its best distinct optima, joined
to ``theta``, start the candidate's joint fit again (:func:`.joint_fit.settle`). Used by
:func:`..diagnose.diagnose` only when the best candidate's refit is rejected, before pairs
of effects are tried.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from .joint_fit import JointProblem, settle
from .local_fits import distinct
from .nominal import first_round, nominal_reduced

__all__ = ["ANEW_SEED", "ANEW_STARTS", "constants_anew"]

log = logging.getLogger(__name__)

#: Random starts (draws from the prior of the constants) besides the prior mean.
ANEW_STARTS = 24
#: Seed of the reduced model's snapshots and of the starts: the search is the same on
#: every run (it does not draw from diagnose's generator, whose state the store restores).
ANEW_SEED = 20261126
#: Distinct optima of the global stage that start the joint fit again.
ANEW_KEEP = 2


def constants_anew(problem, fitted, coarse, polish, workers=1):
    """The candidate's joint fit again, from its constants searched globally at ``theta``.

    Parameters
    ----------
    problem : JointProblem
        The candidate's joint problem on the working mesh.
    fitted : JointFit
        Its refined fit (``fitted.theta`` is held for the global stage).
    coarse : PlateModel
        The half mesh of the plate (the global stage's reduced model is built on it).
    polish : callable
        ``polish(z, earlier=())`` of the candidate (:func:`.joint_fit.settle`).
    workers : int

    Returns
    -------
    JointFit or None
        The settled fit when its evidence beats ``fitted``'s; None otherwise.
    """
    physics, theta = problem.physics, np.asarray(fitted.theta, dtype=float)
    plate, coarse_plate = physics.apply(problem.model, theta), physics.apply(coarse, theta)
    n = int(problem.modes.max()) + 1
    correction = (
        plate.solve(problem.mu_b, n).eigenvalues[problem.modes]
        / coarse_plate.solve(problem.mu_b, n).eigenvalues[problem.modes]
    )
    V_b = problem.L @ problem.L.T
    rng = np.random.default_rng(ANEW_SEED)
    reduced = nominal_reduced(coarse_plate, problem.mu_b, V_b, n, rng)
    reduced = replace(reduced, full_model=coarse_plate)
    constants = JointProblem(plate, problem.Y, problem.sigma, problem.mu_b, V_b, problem.modes)
    rough = constants.on(reduced, correction)
    found = distinct(first_round(rough, rng, ANEW_STARTS, workers))[:ANEW_KEEP]
    z_theta = problem.pack(problem.mu_b, theta)[6:]
    log.info(
        "%s: constants searched again at theta %s: %s",
        physics.name,
        np.round(theta, 4),
        ", ".join(f"{2 * r.cost:.4g}" for r in found),
    )
    again = settle(problem, polish, [np.concatenate([r.x, z_theta]) for r in found])
    if again.log_evidence <= fitted.log_evidence:
        return None
    earlier = (fitted.b, fitted.chi2 + fitted.chi2_prior)  # stays known, as another basin
    return replace(again, alternatives=(*again.alternatives, earlier))
