"""The settings of :func:`~bayesplate.estimators.estimate.estimate` in one frozen object.

:class:`EstimatorOptions` (the estimator's settings; :class:`bayesplate.run.EstimateOptions`
is a whole run's: method, mesh, budget and these) holds what an estimate runs by: its
stopping rule and iteration cap, its conventions, its prior, MVE-mod's two stages, the
pairing, the tracking and the forward model.
:func:`~bayesplate.estimators.estimate.estimate` takes one as ``options``, and each field by
name as a keyword over it (``estimate(case, "MVE", tol=1e-4)``): the keywords it
took before the object existed, with the same defaults and the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..settings import with_overrides
from .iteration import DEFAULT_MAX_ITER

__all__ = ["EstimatorOptions"]


@dataclass(frozen=True, eq=False)
class EstimatorOptions:
    """How :func:`~bayesplate.estimators.estimate.estimate` runs: its settings.

    The case, the method, the model, a fast model and the seed are arguments of their own.

    The prior deviations of ``b`` follow from those of the engineering constants by
    first-order propagation through eqs. 20-21
    (:func:`bayesplate.likelihood.posterior.prior_in_stiffness`); ``V_Y`` from the frequency
    deviations, ``d lambda = 8 pi^2 f df`` (section 3.6).

    Parameters
    ----------
    tol : float
        TOL of section 2.4 (of stage 2 for MVE-mod): the largest relative change of a
        coefficient between iterates at which the iteration stops (dimensionless).
    max_iter : int
        Iteration cap (per stage).
    convention : str or Conventions
        ``"paper"`` (reproduces the paper, the default) or ``"consistent"``, or explicit
        :class:`~bayesplate.estimators.conventions.Conventions`.
    prior_mean, prior_sd : array_like, shape (6,), optional
        Initial values and deviations of ``(E1, E2, nu12, G12, G13, G23)`` in SI (Pa, and
        dimensionless for ``nu12``), replacing the case's prior (stage 1 of MVE-mod).
    stage1_tol : float
        MVE-mod stage-1 TOL (section 5: 1e-2; dimensionless).
    stage2_factor : float
        MVE-mod stage-2 deviations are this multiple of stage 1's (section 6: 2).
    stage2_sd : array_like, shape (6,), optional
        Explicit stage-2 deviations (SI, as `prior_sd`), overriding `stage2_factor`.
    pairing : {"auto", "mac", "likelihood", "index", "order"} or Pairing
        Measured-to-computed mode pairing (:func:`bayesplate.matching.pairing.pair_measured`, at the
        prior mean): "auto" pairs by shape and frequency ("mac") when the case has measured
        shapes, else by the case's mode indices if any, else by order (the paper's), the
        order checked at the estimate. "likelihood": the most probable assignment of
        frequencies (:mod:`bayesplate.matching.assignment`), made at the prior with the prior's
        spread and remade at each estimate with the estimate's, the estimator run again
        until the assignment stands (at most :data:`.assignment_rounds.MAX_ASSIGNMENTS`
        rounds); unobserved computed modes and spurious peaks are in ``settings`` and the
        message. Measured modes left unpaired are left out of the fit.
    tracking : {"auto", "report", "follow", "off"}
        MAC tracking of paired modes between iterates (see :func:`.iteration.run`); "auto"
        follows modes paired by shape and keeps order or index pairings as they are.
    forward : {"auto", "fast", "full"}
        Iterate on the certified fast model, the answer confirmed by the full one
        (:mod:`bayesplate.estimators.fast`; the result's ``check``), or on the full model
        throughout; ``"auto"``: fast on meshes of more than ``FAST_MIN_DOFS`` unknowns,
        except for B (a handful of solves, fewer than the fast model's build).
    """

    tol: float = 1e-3
    max_iter: int = DEFAULT_MAX_ITER
    convention: object = "paper"
    prior_mean: object = None
    prior_sd: object = None
    stage1_tol: float = 1e-2
    stage2_factor: float = 2.0
    stage2_sd: object = None
    pairing: object = "auto"
    tracking: str = "auto"
    forward: str = "auto"

    @classmethod
    def of(cls, options=None, caller="estimate", **overrides):
        """`options` (default: the defaults) with `overrides`, each a field's name.

        Parameters
        ----------
        options : EstimatorOptions, optional
        caller : str
            Name of the function, for the messages.
        **overrides
            Fields by name, over `options`.

        Returns
        -------
        EstimatorOptions

        Raises
        ------
        TypeError
            An override that is no field of :class:`EstimatorOptions`, or `options` of
            another type.
        """
        return with_overrides(cls, options, caller, overrides)
