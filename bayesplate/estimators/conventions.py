"""Choices the paper leaves open, named: :class:`Conventions` and the :data:`CONVENTIONS` sets.

Settled by reproducing Tables 3-23 (``studies/paper_tables.py``): ``CONVENTIONS["paper"]``.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..likelihood.posterior import OBSERVATION_CONVENTIONS, PRIOR_CONVENTIONS

__all__ = ["Conventions", "CONVENTIONS", "resolve_conventions"]


@dataclass(frozen=True)
class Conventions:
    """Choices the paper leaves open; see :mod:`bayesplate.likelihood.posterior`'s docstring.

    Parameters
    ----------
    observation : {"variance", "deviation"}
        ``V_Y = diag(d lambda^2)`` or ``diag(d lambda)`` as printed.
    prior : {"variance", "full", "deviation"}
        ``V_b = diag(dC^2)``, the full propagated covariance, or ``diag(dC)`` as printed.
    covariance : {"fixed", "updated"}
        MVE iterates with the initial ``V_b`` or with the updated ``V^{k+1}`` of section 2.2
        (which re-uses the same data at every iteration).
    stop_on : {"stiffness", "engineering"}
        The relative-change test of section 2.4 on ``b`` or on the engineering constants.
    stage2_base : {"initial", "estimate"}
        MVE-mod stage-2 deviations scale the initial values or the stage-1 estimate.
    """

    observation: str = "variance"
    prior: str = "variance"
    covariance: str = "fixed"
    stop_on: str = "stiffness"
    stage2_base: str = "initial"

    def __post_init__(self):
        for name, allowed in (
            ("observation", OBSERVATION_CONVENTIONS),
            ("prior", PRIOR_CONVENTIONS),
            ("covariance", ("updated", "fixed")),
            ("stop_on", ("stiffness", "engineering")),
            ("stage2_base", ("initial", "estimate")),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} = {getattr(self, name)!r}: must be one of {allowed}")


CONVENTIONS = {
    # reproduces Tables 3-23 (README.md, "Estimators"): the library and CLI default
    "paper": Conventions(),
    # the exact first-order image of the case file's independent engineering prior
    "full-prior": Conventions(prior="full"),
    # the formulas exactly as printed in section 3.6, with the MVE covariance update
    "printed": Conventions(observation="deviation", prior="deviation", covariance="updated"),
}


def resolve_conventions(convention):
    """The :class:`Conventions` of a name in :data:`CONVENTIONS`, or the object itself."""
    if isinstance(convention, Conventions):
        return convention
    if convention not in CONVENTIONS:
        raise ValueError(f"convention = {convention!r}: must be one of {tuple(CONVENTIONS)}")
    return CONVENTIONS[convention]
