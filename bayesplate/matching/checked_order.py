"""Pairing by order, checked at the answer: the default without shapes or mode numbers.

The paper pairs the i-th measured peak with the i-th computed mode. A one-point tap test can
miss a mode (a node at the point) or show a peak that is no bending mode, and the order then
shifts every pair above it. The most probable assignment of frequencies
(:mod:`bayesplate.matching.assignment`) sees that, but made before the fit it can also explain a
concealed defect away as missed modes and spurious peaks. So the answer (an estimate, the
sampler's MAP, diagnose's verdict fit) is made by order, and the most probable assignment is
made again at it:

- it pairs every peak it pairs with its own mode
  (:attr:`bayesplate.matching.assignment.Assignment.keeps_order`): the order stands, the answer as
  it is (a peak it calls spurious in its own place is an outlier of the fit, kept: diagnose is
  what weighs it);
- it pairs a peak with another mode: the order is set aside and the answer made by
  likelihood (:func:`refuted_order` says why).

Pure functions; one eigen solve per check.
"""

from __future__ import annotations

import numpy as np

from .pairing import pair_measured, resolve_pairing

__all__ = ["assignment_at", "checks_order", "refuted_order"]


def checks_order(measured, how):
    """Whether `how` asks for pairing by order checked by the most probable assignment.

    ``"auto"`` on a measurement with neither shapes nor mode numbers: the paper's pairing
    by order is used, and the assignment by likelihood made again at the answer (the
    estimate, the sampler's MAP, diagnose's verdict fit) decides whether it stands. Order
    alone cannot see a mode the test missed or a peak that is not a bending mode; the
    assignment alone, made before the fit, can explain a concealed defect away as missed
    modes and spurious peaks. Checked at the answer, a complete test keeps its order
    results to the bit.

    Parameters
    ----------
    measured : bayesplate.io.Measurement
    how : str or Pairing
        A pairing's name or a :class:`Pairing` (never checked: it is fixed).

    Returns
    -------
    bool
    """
    if not isinstance(how, str) or how != "auto":
        return False
    return resolve_pairing(measured, how) == "order"


def assignment_at(case, model, b, covariance_b, pairing):
    """The most probable assignment at `b`, over a fixed pairing's modes, searched from it.

    What checks a pairing by order at an answer (:func:`checks_order`): the assignment by
    likelihood (:func:`bayesplate.matching.assignment.most_probable`) over the ``pairing.n_modes()``
    lowest computed modes (all that a fast model made for that pairing holds), the constants
    integrated out over `covariance_b` centred at `b`.

    Parameters
    ----------
    case : bayesplate.io.Case
    model : ForwardModel
        Anything with ``solve(b, n_modes)`` (the full model or a fast one); one solve.
    b : array_like, shape (6,)
        The answer, Pa.
    covariance_b : array_like, shape (6, 6)
        The prior's covariance of ``b``, Pa^2.
    pairing : Pairing
        The pairing in use.

    Returns
    -------
    bayesplate.matching.assignment.Assignment
    """
    b = np.asarray(b, dtype=float)
    extra = pairing.n_modes() - case.measured.size
    again = pair_measured(
        case, model, b, "likelihood", extra_modes=extra, prior=(b, covariance_b), start=pairing
    )
    return again.assignment


def refuted_order(assignment):
    """One clause: why pairing by order was set aside (1-based numbers)."""
    return (
        f"pairing by order set aside: at its estimate the most probable assignment has "
        f"{assignment.describe()}; paired by likelihood instead"
    )
