"""What diagnose's stages hand on: the run's context and each stage's result, all frozen.

A pass of :func:`..diagnose.diagnose` reads as

``deviations(run, pairing) -> Deviations`` (:mod:`.deviations`),
``fit_nominal_stage(run, data, rng) -> NominalStage`` (:mod:`.nominal_check`),
``locate(run, data, nominal) -> Located`` (:mod:`.locate`),
``rank(located.fitting, run.physics)`` (:mod:`.rank`),
``refit(run, data, nominal, located, ranked) -> Searched`` (:mod:`.refit`),
``conclude(run, data, nominal, located, searched) -> Diagnosis`` (:mod:`.conclude`),

and :mod:`.passes` runs a pass per assignment of the peaks. The states are frozen: a
stage makes a new one (:func:`dataclasses.replace`) rather than changing the one it got.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Deviations", "Fitting", "Located", "NominalCheck", "NominalStage", "Run", "Searched"]


@dataclass(frozen=True)
class Run:
    """The context of one call of diagnose, the same in every pass.

    Attributes
    ----------
    case : bayesplate.io.Case
    model, coarse : PlateModel
        The working mesh and the half mesh (:func:`.mesh_error.coarse_model`).
    physics : list of Physics
        The candidates.
    prior : tuple of numpy.ndarray
        ``(mu_b, V_b)``: the prior of the stiffness coefficients, Pa and Pa^2.
    options : DiagnoseOptions
    say : callable
        ``say(message)`` after each step.
    store : object with ``get`` and ``put``, or None
    fast : bayesplate.reduced.CertifiedModel or None
    at_mean : dict
        ``n -> (the working mesh's modal result, the coarse mesh's eigenvalues)`` at the
        prior mean, and ``("finer", n) ->`` the mesh twice as fine's frequencies there (Hz;
        the corrected rule, its model under ``"finer"``), filled by the first pass that
        needs them (a cache: a second pass solves nothing again).
    """

    case: object
    model: object
    coarse: object
    physics: list
    prior: tuple
    options: object
    say: object
    store: object = None
    fast: object = None
    at_mean: dict = field(default_factory=dict, repr=False)


@dataclass(frozen=True)
class Deviations:
    """One pass's data: the paired peaks and their deviations, the mesh's error folded in.

    Attributes
    ----------
    measured : Measurement
        The paired peaks (``pairing.select``).
    modes : numpy.ndarray of int, shape (m,)
    sigma_Hz, mesh_error_Hz : numpy.ndarray, shape (m,)
        The deviations the fits use (widened by the mesh's error where it is not well under
        them) and the mesh's estimated error.
    Y, sigma : numpy.ndarray, shape (m,)
        Measured eigenvalues and their deviations, rad^2/s^2.
    correction : numpy.ndarray, shape (m,)
        Working-mesh to coarse eigenvalues of the paired modes at the prior mean.
    problem : JointProblem
        The nominal problem on the working mesh.
    notes : tuple of str
    """

    measured: object
    modes: np.ndarray
    sigma_Hz: np.ndarray
    mesh_error_Hz: np.ndarray
    Y: np.ndarray
    sigma: np.ndarray
    correction: np.ndarray
    problem: object
    notes: tuple = ()

    @property
    def m(self):
        """Paired peaks."""
        return self.measured.size


@dataclass(frozen=True)
class NominalCheck:
    """A nominal fit and its checks: chi-square test, predictive p-values, loose constants."""

    fit: object
    dof: float
    p_value: float
    mode_p_values: np.ndarray
    unidentified: list


@dataclass(frozen=True)
class NominalStage:
    """Step 1's result: the checked nominal fit, its reduced problem, the stages after it."""

    check: NominalCheck
    rough: object
    stages: object
    notes: tuple = ()


@dataclass(frozen=True)
class Fitting:
    """What every candidate's joint fit takes (:func:`.rank.rank`), the same for each.

    Attributes
    ----------
    model, coarse : PlateModel
    Y, sigma : numpy.ndarray, shape (m,)
    mu_b, V_b : numpy.ndarray
    modes : numpy.ndarray of int, shape (m,)
    nominal : JointFit
    scans : dict of Scan
        The located candidates' scans, keyed by name.
    say : callable
    stages : Stages or None
    scale : numpy.ndarray, shape (m,)
        Working-mesh to coarse eigenvalues at the nominal fit.
    coarse_modes : numpy.ndarray, shape (n_dofs, n), or None
        The coarse nominal modes at the nominal fit (the Ritz bases of the coarse fits).
    ritz_modes : numpy.ndarray, shape (n_dofs, n)
        The nominal modes at the nominal fit on the working mesh (for the refinement).
    rough : JointProblem or None
        The nominal problem on its reduced model.
    margin : float
        A candidate gaining less than this on its reduced coarse model is not refined, nats.
    workers : int
    threshold : float
        The evidence gain over which a candidate may be named, nats.
    """

    model: object
    coarse: object
    Y: np.ndarray
    sigma: np.ndarray
    mu_b: np.ndarray
    V_b: np.ndarray
    modes: np.ndarray
    nominal: object
    scans: dict
    say: object
    stages: object
    scale: np.ndarray
    coarse_modes: np.ndarray | None
    ritz_modes: np.ndarray
    rough: object = None
    margin: float = 1.0
    workers: int = 1
    threshold: float = 3.0


@dataclass(frozen=True)
class Located:
    """Step 2's result: where the misfit sits, and what the candidates' fits take."""

    kinds: list
    maps: dict
    region: tuple | None
    mirrors: list
    located_modes: list
    fitting: Fitting


@dataclass(frozen=True)
class Searched:
    """Steps 3-4's result: the candidates ranked, the best one, its refit test.

    ``check`` is the nominal fit the verdict weighs (improved from a candidate's constants
    when that beat it); ``unidentified`` the constants the verdict's fit leaves loose;
    ``unnamed`` the unnamed local change at ``check``'s fit when the pairs' stage weighed
    it (else None: the verdict computes it); ``notes`` what the stage left out and why.
    """

    check: NominalCheck
    ranked: list
    best: object
    warranted: bool
    refit_dof: float
    refit_p_value: float
    unidentified: list
    unnamed: object = None
    notes: tuple = ()
