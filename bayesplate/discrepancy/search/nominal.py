"""Step 1 of diagnose: the nominal model's global fit, on a reduced model first.

Every start (the prior mean and random draws from the prior) is fitted on a reduced model
of the nominal plate (by default one built on the half mesh over the prior's 3-sigma box,
its eigenvalues corrected to the working mesh by their ratio at the prior mean; or the
reduced part of a shared :class:`~bayesplate.reduced.CertifiedModel`), where an evaluation
is a small dense eigenproblem. The best distinct optima are polished on a Ritz model of the
working mesh made of its modes at each optimum, and the best is evaluated on the working
mesh itself: the fit reported is the finite-element model's.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from ...reduced import ReducedModel
from ..physics.reduced_model import candidate_pencil
from .joint_fit import JointProblem, fit
from .local_fits import local_fits

__all__ = [
    "N_STARTS",
    "check_fast",
    "fit_nominal",
    "nominal_polisher",
    "nominal_reduced",
    "nominal_stage",
]

log = logging.getLogger(__name__)

#: Random starts of the global stage besides the prior mean.
N_STARTS = 32
#: Elastic modes of a polishing snapshot beyond the highest paired one.
POLISH_EXTRA_MODES = 4


def fit_nominal(problem, rough, rng, n_starts=N_STARTS, workers=1, keep=3):
    """Global fit of the nominal model.

    The prior mean and ``n_starts`` random draws from the prior, then ``n_starts`` unit
    hops (in prior deviations) around the best optimum found, are each fitted on
    ``rough`` (the same problem on a reduced model: each evaluation costs a small dense
    eigenproblem); the ``keep`` best distinct optima are refined on the working mesh, and
    the other optima reached there are kept as ``alternatives``.

    Not a guarantee, but many starts are cheap on the reduced model: on the measured
    Frederiksen plate at 0.2 % deviations they reach the better basin (objective 14.1, the
    one reached from Frederiksen's own constants; 4 starts on the half mesh stopped at
    18.4; see reports/diagnose_frederiksen.md).

    A single local fit from the prior mean, with modes paired by order, can stop in a false
    minimum where the model's mode order differs from the plate's (see tests/test_diagnose.py).

    Parameters
    ----------
    problem : JointProblem
        The nominal problem on the working mesh.
    rough : JointProblem or PlateModel
        The same problem on a cheaper model (:meth:`.joint_fit.JointProblem.on`); a plate model
        is taken as a coarse mesh without correction.
    rng : numpy.random.Generator
    n_starts, workers, keep : int
        Random starts; processes; optima refined on the working mesh.

    Returns
    -------
    JointFit
    """
    if not isinstance(rough, JointProblem):
        rough = problem.on(rough)
    first = first_round(rough, rng, n_starts, workers)
    # a second round hops around the best first-round optimum (basins the prior's draws
    # seldom reach: on the measured Frederiksen plate the best one is two deviations off)
    starts = [r.x for r in first] + [first[0].x + rng.standard_normal(6) for _ in range(n_starts)]
    return fit(
        problem,
        starts,
        rough=rough,
        keep=keep,
        workers=workers,
        distinct=True,
        polish=nominal_polisher(problem),
        rough_nfev=200,
        tol=1e-8,
    )


def first_round(rough, rng, n_starts, workers=1):
    """The global stage's first round: fits of the constants from the prior mean and draws.

    Parameters
    ----------
    rough : JointProblem
        A problem in the six whitened constants on a reduced model.
    rng : numpy.random.Generator
        Draws the ``n_starts`` starts (standard normal: the prior, whitened).
    n_starts, workers : int

    Returns
    -------
    list of scipy.optimize.OptimizeResult
        Lowest cost first (:func:`.local_fits.local_fits`, 200 evaluations each at most).
    """
    starts = [np.zeros(6)] + [rng.standard_normal(6) for _ in range(n_starts)]
    return local_fits(rough, starts, 200, workers)


def nominal_polisher(problem):
    """``polish(z, earlier=())``: the nominal plate's pencil on the working mesh, exact at z.

    Its basis holds the working mesh's modes at ``z`` (:data:`POLISH_EXTRA_MODES` beyond the
    highest paired one) and the ``earlier`` snapshots (at the points before: :mod:`.settling`).
    """
    n = int(problem.modes.max()) + 1 + POLISH_EXTRA_MODES

    def polish(z, earlier=()):
        b = problem.unpack(z)[0]
        return problem.on_pencil(candidate_pencil(problem.model, None, b, [], n, earlier=earlier))

    return polish


def nominal_reduced(coarse, mu_b, V_b, n_modes, rng, n_snapshots=8):
    """A reduced model of the nominal plate over the prior's 3-sigma box (uncertified).

    Snapshots at the prior mean and ``n_snapshots`` points of a Latin hypercube of the box
    (:meth:`bayesplate.reduced.ReducedModel.build`); used for the global stage only.

    Parameters
    ----------
    coarse : PlateModel
    mu_b : numpy.ndarray, shape (6,)
    V_b : numpy.ndarray, shape (6, 6)
        Prior of ``b``, Pa and Pa^2.
    n_modes : int
        Elastic modes to reproduce (two more are kept for crossings).
    rng : numpy.random.Generator
    n_snapshots : int

    Returns
    -------
    ReducedModel
    """
    seed = int(rng.integers(2**31))
    return ReducedModel.build(
        coarse, mu_b, V_b, n_modes + 2, n_snapshots=n_snapshots, margin=6, rng=seed
    )


def nominal_stage(
    problem, prior, coarse, correction, rng, n_starts, workers, fast=None, stages=None
):
    """Step 1 whole: the reduced model (unless `fast`) and :func:`fit_nominal`, or both stored.

    The stage's key (:mod:`.store`) adds the generator's state and ``n_starts`` to the
    context of `stages`; the stored value holds the generator's state after the stage, which
    a hit restores, so that `rng` ends in the same state either way.

    Parameters
    ----------
    problem : JointProblem
        The nominal problem on the working mesh.
    prior : tuple of numpy.ndarray
        ``(mu_b, V_b)``, shapes (6,) and (6, 6): the prior of ``b``, Pa and Pa^2.
    coarse : PlateModel
        The half mesh the default reduced model is built on.
    correction : numpy.ndarray, shape (m,)
        Working-mesh to coarse eigenvalues of the paired modes at the prior mean.
    rng : numpy.random.Generator
    n_starts, workers : int
    fast : bayesplate.reduced.CertifiedModel, optional
    stages : Stages, optional

    Returns
    -------
    rough : JointProblem
        The nominal problem on the reduced model of the global stage.
    nominal : JointFit
    """
    key = None if stages is None else stages.key("nominal", rng.bit_generator.state, n_starts)
    found, stored = (False, None) if stages is None else stages.get(key)
    if found:
        reduced, nominal, state = stored
        rng.bit_generator.state = state
        stages.say("nominal fit: taken from the store")
    else:
        reduced = None
        if fast is None:
            n_solve = int(problem.modes.max()) + 1
            reduced = nominal_reduced(coarse, *prior, n_solve, rng)
    rough = problem.on(fast.reduced) if fast is not None else None
    if reduced is not None:
        reduced = replace(reduced, full_model=coarse)  # (stored without it)
        rough = problem.on(reduced, correction)
    if not found:
        nominal = fit_nominal(problem, rough, rng, n_starts, workers)
        if stages is not None:
            plain = None if reduced is None else replace(reduced, full_model=None)
            stages.put(key, (plain, nominal, rng.bit_generator.state))
    return rough, nominal


def check_fast(fast, nominal, modes, notes):
    """Log and note a disagreement of a shared fast model with the full one at the optimum."""
    if not fast.box.contains(nominal.b):
        return
    lam = fast.reduced.solve(nominal.b, int(modes.max()) + 1).eigenvalues[modes]
    error = float(np.max(np.abs(np.sqrt(lam / nominal.eigenvalues) - 1.0)))
    tolerance = fast.certificate.tolerance
    if error > tolerance:
        log.error(
            "the fast model is off by %.2g at the nominal fit (certified %.2g)", error, tolerance
        )
        notes.append(
            f"the shared fast model is off by {error:.2g} in frequency at the nominal fit, "
            f"beyond its certificate ({tolerance:.2g}); the full model was used"
        )
