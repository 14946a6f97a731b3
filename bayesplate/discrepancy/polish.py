"""Rough optima polished on a reduced model of the working mesh, finished on the mesh itself.

Each rough optimum ``z`` (found on a cheap model) is polished on ``polish(z)``, a reduced
model of the working mesh made of its modes at ``z`` (exact there), then finished on the
working mesh by least squares and :func:`.finish.finish`, best polished first; the best
finished one is reported. A polished optimum whose objective (``chi2 + chi2_prior``)
exceeds the best finished one by more than :data:`FINISH_MARGIN` plus the largest polish
error seen so far (``|polished - finished|`` of those finished) cannot win and is not
finished: it is kept as an alternative at its polished objective.
"""

from __future__ import annotations

import logging

import numpy as np

from .finish import finish
from .local import local_fits, problem_name

__all__ = ["FINISH_MARGIN", "polish_and_finish"]

log = logging.getLogger("bayesplate.discrepancy.fit")  # the fits' records, as before

#: See the module's docstring. On the measured Frederiksen plate the nominal polish is
#: within 0.002 of the finished objective and the second basin 2.55 above the best; a
#: cutout's polish was off by up to 2.7 (plate 1), which the error term covers.
FINISH_MARGIN = 2.0


def polish_and_finish(problem, polish, starts, max_nfev, tol):
    """The rough optima ``starts`` polished and, where they can still win, finished.

    Parameters
    ----------
    problem : JointProblem
        On the working mesh.
    polish : callable
        ``polish(z) -> JointProblem``: a reduced model of ``problem`` accurate near ``z``.
    starts : sequence of numpy.ndarray, each shape (6 + k,)
        Rough optima (whitened unknowns).
    max_nfev : int
        Evaluation cap of each fit on ``problem``.
    tol : float
        ``ftol`` and ``xtol`` of the fits on ``problem``.

    Returns
    -------
    finished : list of scipy.optimize.OptimizeResult
        On ``problem``, lowest cost first (at least one).
    others : list of (numpy.ndarray, float)
        The constants ``b`` (Pa) and objective of every other optimum, finished or polished,
        lowest first.
    """
    polished = [_polished(problem, polish, z) for z in starts]
    if all(r is None for r in polished):  # no solvable plate: the best one's error
        _polished(problem, polish, starts[0], strict=True)
    polished = sorted((r for r in polished if r is not None), key=lambda r: r.cost)
    finished, far, error = [], [], 0.0
    for r in polished:
        if finished and 2.0 * (r.cost - finished[0].cost) > FINISH_MARGIN + error:
            far.append(r)
            continue
        done = _finished(problem, r, max_nfev, tol)
        if done is not None:
            error = max(error, 2.0 * abs(r.cost - done.cost))
            finished = sorted([*finished, done], key=lambda f: f.cost)
    if not finished:  # no polished optimum could be finished: the best one's error
        _finished(problem, polished[0], max_nfev, tol, strict=True)
    others = sorted(((problem.unpack(r.x)[0], 2.0 * r.cost) for r in finished[1:] + far),
                    key=lambda pair: pair[1])  # fmt: skip
    return finished, others


def _polished(problem, polish, z, strict=False):
    """The rough optimum ``z`` polished on ``polish(z)`` (its ``cost`` on that model).

    None (unless ``strict``) when the plate at ``z`` cannot be solved (a far rough optimum
    of an inaccurate reduced model: its modified plate is not positive definite).
    """
    try:
        return local_fits(polish(z), [z], 100)[0]
    except (ValueError, np.linalg.LinAlgError) as error:
        if strict:
            raise
        log.warning("%s: rough optimum %s not polished (%s)", problem_name(problem), np.round(z, 2),
                    error)  # fmt: skip
        return None


def _finished(problem, polished, max_nfev, tol, strict=False):
    """The polished optimum finished on ``problem`` (tightly, at its canonical image).

    None (unless ``strict``) when a plate on the way cannot be solved.
    """
    try:
        best = local_fits(problem, [polished.x], max_nfev, 1, tol)[0]
        best = finish(problem, best, max_nfev)  # tight, at its canonical image
    except (ValueError, np.linalg.LinAlgError) as error:
        if strict:
            raise
        log.warning("%s: polished optimum %s not finished (%s)", problem_name(problem),
                    np.round(polished.x, 2), error)  # fmt: skip
        return None
    log.info("%s: polished %.6g, finished %.6g", problem_name(problem), 2 * polished.cost,
             2 * best.cost)  # fmt: skip
    return best
