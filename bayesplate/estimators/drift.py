"""An MVE run that drifts along directions the data barely determine: when to say so.

With fixed sensitivities the MVE step (Daghia et al. 2007, eq. 12) contracts the error along
each direction by ``1 / (1 + lambda)``, ``lambda`` the information the data carry there
relative to the step covariance's (:func:`slow_directions`). A run whose only moving
directions would need more iterations than remain, and are determined no better as it goes,
is stopped as ``"unidentified"`` with one line naming them (:func:`drift`), rather than left
to creep to the cap.
"""

from __future__ import annotations

import numpy as np

from ..quantities import STIFFNESS_NAMES

__all__ = ["DRIFT_WINDOW", "WEAK_INFORMATION", "drift", "slow_directions", "weakly_determined"]

#: Consecutive MVE iterations drifting along directions the data determine no better as it
#: goes (each predicted to need more iterations than remain) before the run stops as
#: "unidentified" (:func:`drift`).
DRIFT_WINDOW = 5
#: A direction along which the data carry less than this fraction of the step covariance's
#: information is weakly determined: an MVE run that moves without progress mostly along
#: such a direction is stopped as "unidentified" rather than "oscillating".
WEAK_INFORMATION = 1.0
#: Relative growth of the information along the slowest direction below which it counts as
#: the same (round-off: on a linear problem it varies by about 1e-12 from one iterate to the
#: next, and a strict comparison restarted the window at random).
_SAME = 1e-6
#: The engineering constant each stiffness coefficient mostly carries, for messages.
_CARRIES = ("E1", "E2", "nu12", "G12", "G23", "G13")


def slow_directions(b, S, V_Y, V, step, tol):
    """The MVE iteration linearised at `b`: how long each direction of `step` takes to settle.

    With fixed sensitivities the MVE step (eq. 12) maps the error ``x - x*`` (``x = b / |b|``)
    to ``(I + V F)^-1 (x - x*)``, ``F = S^T V_Y^-1 S`` the data's information: along the
    ``V``-scaled eigenvectors ``u_i`` of ``V F`` (eigenvalues ``lambda_i``, the information
    the data carry there relative to ``V``'s) the steps shrink by ``c_i = 1 / (1 + lambda_i)``
    per iteration. A step part ``p_i`` (largest relative entry) falls below `tol` after
    ``ln(p_i / tol) / -ln(c_i)`` more iterations.

    Parameters
    ----------
    b : numpy.ndarray, shape (6,)
        Iterate, Pa.
    S : numpy.ndarray, shape (m, 6)
        Sensitivities at `b`, rad^2/s^2 per Pa.
    V_Y : numpy.ndarray, shape (m, m)
        Observation covariance, (rad^2/s^2)^2.
    V : numpy.ndarray, shape (6, 6)
        Covariance of the next MVE step, Pa^2.
    step : numpy.ndarray, shape (6,)
        The last step relative to `b` (dimensionless).
    tol : float
        TOL of section 2.4.

    Returns
    -------
    n : numpy.ndarray, shape (6,)
        Predicted iterations until each direction's part of the step is below `tol` (0 for
        parts already below it; inf where ``lambda_i = 0``).
    c : numpy.ndarray, shape (6,)
        Contraction per iteration along each direction.
    parts : numpy.ndarray, shape (6, 6)
        Row ``i``: the step's part along direction ``i``, relative, per coefficient.
    """
    scale = np.abs(b)
    Sx, Vx = S * scale[None, :], V / np.outer(scale, scale)
    F = Sx.T @ np.linalg.solve(V_Y, Sx)
    L = np.linalg.cholesky(Vx)
    lam, Q = np.linalg.eigh(L.T @ F @ L)
    U = L @ Q
    parts = np.linalg.solve(U, step)[:, None] * U.T
    size = np.max(np.abs(parts), axis=1)
    c = 1.0 / (1.0 + np.maximum(lam, 0.0))
    with np.errstate(divide="ignore"):
        n = np.where(size > tol, np.log(size / tol) / -np.log(c), 0.0)
    return n, c, parts


def drift(problem, state, V, step, tol, k, max_iter):
    """A message if the MVE run drifts along directions the data barely determine, else "".

    A direction holds the run when its part of the last step exceeds `tol`; the run drifts
    when every direction holding it needs more iterations than remain under the cap to
    settle (by the linearised iteration, :func:`slow_directions`), its steps shrink (as the
    linearisation has them do: a growing step is a path still leaving a plateau) and the
    slowest one contracts no faster at each iterate than at the one before: the data
    determine it no better the further it goes, so the linearisation's count is not
    pessimistic (a direction that contracts faster as it goes is approaching a point the
    data determine better, and is left to converge: the paper's Plate 2 runs along nu12).
    The run stops after :data:`DRIFT_WINDOW` consecutive such iterations; the message names
    the coefficients that carry the slowest direction, and ``state.drifted`` keeps the
    numbers. Only with a fixed step covariance (the paper's convention): an updated ``V``
    shrinks at every iteration, re-using the data, and slows every direction by itself.
    """
    h = np.asarray(state.history[state.since :])
    sizes = np.max(np.abs(np.diff(h[-3:], axis=0)) / np.abs(h[-3:-1]), axis=1)
    try:
        n, c, parts = slow_directions(state.b, state.prediction.S, problem.V_Y, V, step, tol)
    except np.linalg.LinAlgError:
        state.drift = []
        return ""
    moving = np.flatnonzero(n > 0)
    if (
        len(sizes) < 2
        or sizes[-1] >= sizes[-2]
        or moving.size == 0
        or np.any(n[moving] <= max_iter - k)
    ):
        state.drift = []
        return ""
    i = moving[np.argmax(n[moving])]
    if state.drift and _information(c[i]) > _information(state.drift[-1]) * (1 + _SAME):
        state.drift = []  # determined better here: approaching a point the data fix
    state.drift.append(c[i])
    if len(state.drift) < DRIFT_WINDOW:
        return ""
    part = np.abs(parts[i])
    named = [j for j in np.argsort(-part) if part[j] >= 0.5 * part.max()]
    names = ", ".join(f"{STIFFNESS_NAMES[j]} ({_CARRIES[j]})" for j in named)
    more = f"~{n[i]:.0f}" if np.isfinite(n[i]) else "infinitely many"
    state.drifted = {
        "coefficients": [STIFFNESS_NAMES[j] for j in named],
        "constants": [_CARRIES[j] for j in named],
        "information": [1.0 / c_ - 1.0 for c_ in state.drift[-DRIFT_WINDOW:]],
        "contraction": float(c[i]),
        "relative_change": float(part.max()),
        "predicted_iterations": float(n[i]),
    }
    return (
        f"unidentified: the data barely determine {names}, and no better along the path: "
        f"they carry {1 / state.drift[-DRIFT_WINDOW] - 1:.2g} to {1 / c[i] - 1:.2g} of the "
        f"step covariance's information along it over the last {DRIFT_WINDOW} iterations "
        f"(the MVE iteration contracts by {c[i]:.4f} per iteration); its relative change "
        f"{part.max():.2g} per iteration would need {more} more iterations to fall below TOL "
        f"{tol:g} (cap {max_iter}); the other directions settled"
    )


def _information(c):
    """``lambda = 1 / c - 1``: the information along a direction contracting by ``c``."""
    return 1.0 / c - 1.0


def weakly_determined(problem, state, V, step, tol):
    """A message if an MVE run without progress moves mostly where the data barely see.

    Called where the run has stopped making progress (cycling or stalling, which the
    relative-change test sees first when a weakly determined coefficient wanders near zero):
    the last step's largest part lies along a direction of :func:`slow_directions` whose
    information, relative to the step covariance's, is below :data:`WEAK_INFORMATION`. The
    message names the coefficients that carry it; else "" (a true oscillation).
    """
    try:
        _, c, parts = slow_directions(state.b, state.prediction.S, problem.V_Y, V, step, tol)
    except np.linalg.LinAlgError:
        return ""
    size = np.max(np.abs(parts), axis=1)
    i = int(np.argmax(size))
    information = _information(c[i])
    if not information < WEAK_INFORMATION:
        return ""
    part = np.abs(parts[i])
    named = [j for j in np.argsort(-part) if part[j] >= 0.5 * part.max()]
    names = ", ".join(f"{STIFFNESS_NAMES[j]} ({_CARRIES[j]})" for j in named)
    state.drifted = {
        "coefficients": [STIFFNESS_NAMES[j] for j in named],
        "constants": [_CARRIES[j] for j in named],
        "information": [float(information)],
        "contraction": float(c[i]),
        "relative_change": float(part.max()),
        "predicted_iterations": float("inf"),
    }
    return (
        f"unidentified: no progress, the steps moving along {names}, where the data carry "
        f"{information:.2g} of the step covariance's information (below "
        f"{WEAK_INFORMATION:g}): the data do not determine it; the other directions settled"
    )
