"""The paper's estimators B, MVE and MVE-mod (Daghia et al. 2007, sections 2 and 5).

All three iterate on the stiffness coefficients ``b = (C11, C22, C12, C66, C44, C55)`` with
the Gaussian problem of :mod:`bayesplate.likelihood.posterior`:

- **B** (eq. 9), the Bayesian estimator: Gauss-Newton steps on ``S_B`` (eq. 5) with the prior
  mean ``mu`` fixed, ``b^{k+1} = mu + P^k S^T V_Y^-1 [Y - g^k - S (mu - b^k)]``,
  ``P^k = (S^T V_Y^-1 S + V_b^-1)^-1``. Converges to the posterior mode (MAP).
- **MVE** (eq. 12), the minimum variance estimator: ``b^{k+1} = b^k + V S^T (S V S^T +
  V_Y)^-1 (Y - g^k)``, reporting the updated covariance ``V^{k+1} = V - V S^T (S V S^T +
  V_Y)^-1 S V``. Section 2.3: one MVE step is one B step with ``mu = b^k``.
- **MVE-mod** (section 5): MVE with small deviations and TOL = 1e-2, then MVE again from the
  stage-1 estimate with larger deviations and the prescribed TOL.

Stopping rule (section 2.4): ``|b_i^{k+1} - b_i^k| / |b_i^k| <= TOL`` for all i. A run that
leaves the physical region, oscillates (cycles or stalls), fails in the forward solve or
reaches its iteration cap returns ``converged=False`` with a message saying which; it never
raises.

Conventions the paper leaves open are keywords (:class:`Conventions`). Settled by
reproducing Tables 3-23 (``studies/paper_tables.py``), ``CONVENTIONS["paper"]``, the
default: ``V_Y = diag(d lambda^2)``, ``V_b = diag(dC^2)``; MVE iterates with the *initial*
``V_b`` (the updated ``V^{k+1}`` is only reported: re-using it would count the same data
again at every iteration, and does not reproduce the paper); the stopping rule on ``b``;
MVE-mod stage-2 deviations ``d2`` times the *initial* values. ``"full-prior"`` keeps the
correlations of the propagated prior; ``"printed"`` is section 3.6 to the letter.


Modules: :mod:`~.conventions` (the open choices), :mod:`~.steps` (one B or MVE update),
:mod:`~.iteration` (:func:`run`: the iteration and its stopping rules), :mod:`~.estimate`
(:func:`estimate`: a case, MVE-mod's two stages), :mod:`~.assignment_rounds` (the rounds of
assignment and estimate that pair by likelihood), :mod:`~.fast` (the same on the certified
fast model, each answer confirmed by the full model), :mod:`~.result` (:class:`EstimateResult`),
:mod:`~.assess` (:func:`assess`: every estimate's fit statement and warnings; "converged" is
the status of a run that stopped with nothing flagged, ``converged`` only that it stopped).
"""

from .assess import FitStatement, WorstResidual, assess, fit_statement
from .conventions import CONVENTIONS, Conventions, resolve_conventions
from .estimate import OrderRefuted, estimate, estimate_on_fast, settle_pairing
from .fast import (
    FAST_MIN_DOFS,
    FORWARDS,
    FastModelWarning,
    case_fast_model,
    modes_to_certify,
    resolve_forward,
)
from .iteration import DEFAULT_MAX_ITER, TRACKING, run
from .options import EstimatorOptions
from .result import METHODS, STATUSES, EstimateResult, FullModelCheck
from .steps import b_step, mve_step

__all__ = [
    "METHODS",
    "STATUSES",
    "TRACKING",
    "DEFAULT_MAX_ITER",
    "Conventions",
    "CONVENTIONS",
    "resolve_conventions",
    "EstimatorOptions",
    "EstimateResult",
    "FullModelCheck",
    "FitStatement",
    "WorstResidual",
    "assess",
    "fit_statement",
    "FAST_MIN_DOFS",
    "FORWARDS",
    "FastModelWarning",
    "case_fast_model",
    "estimate",
    "estimate_on_fast",
    "resolve_forward",
    "modes_to_certify",
    "settle_pairing",
    "OrderRefuted",
    "run",
    "b_step",
    "mve_step",
]
