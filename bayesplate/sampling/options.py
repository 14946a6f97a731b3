"""The sampler's settings in frozen objects: :class:`ChainOptions`, :class:`SetupOptions`.

:class:`ChainOptions` holds what the chain of :func:`~bayesplate.sampling.chain.sample_problem`
runs by: its walkers, its length, its stopping rule, its tuning, its moves, its progress bar and
the file keeping it. :class:`SetupOptions` holds what :func:`~bayesplate.sampling.setup.prepare`
builds the problem, the posterior box and the fast model from.
:func:`~bayesplate.sampling.pipeline.sample` takes one of each. Every entry point also takes each
field by name, as a keyword over the object (``sample(case, rng=1, min_ess=500)``): the
keywords it took before the objects existed, with the same defaults and the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..settings import with_overrides

__all__ = ["TUNE_ROUNDS", "TUNE_STEPS", "ChainOptions", "SetupOptions"]

#: Tuning of the Laplace proposal: rounds and steps per round (discarded afterwards).
TUNE_ROUNDS = 3
TUNE_STEPS = 30


@dataclass(frozen=True)
class ChainOptions:
    """How the chain runs: its size, its stopping rule, tuning, moves, progress and storage.

    The stopping rule (:class:`~bayesplate.sampling.stopping.StoppingRule`) is checked every
    `check_every` steps after tuning; the chain stops once all three of its conditions hold
    (`target_tau_factor`, `min_ess`, `max_rhat`), or at `max_steps`.

    Parameters
    ----------
    n_walkers : int
        emcee walkers (at least 12, twice the dimension).
    max_steps : int
        Cap on the chain's length, steps (resumed ones included); at least the tuning steps
        (``tune_rounds * tune_steps``) and one check (`check_every`).
    target_tau_factor : float
        Stop once the chain after tuning is longer than this many integrated autocorrelation
        times (of the slowest whitened coordinate)...
    min_ess : float
        ... and the smallest bulk effective sample size of the engineering constants after
        burn-in reaches this, draws...
    max_rhat : float
        ... and the largest R-hat (walkers as chains) is below this (dimensionless).
    check_every : int
        Steps between checks of the stopping rule.
    tune_rounds, tune_steps : int
        Tuning: rounds of `tune_steps` steps after each of which the
        :class:`~bayesplate.sampling.moves.LaplaceMove` proposes from the mean and covariance
        of the ensemble over the round's second half; then the proposal is frozen and the
        tuning steps discarded. Without a LaplaceMove among the moves there is no tuning.
    moves : list, optional
        emcee moves (or ``(move, weight)`` pairs); default
        :func:`~bayesplate.sampling.moves.default_moves` inside the fast model's box. The
        objects are used as they are: a LaplaceMove given here keeps its tuned proposal after
        the run.
    progress : bool
        A progress bar (tqdm) with the current ``tau`` and ESS.
    backend_path : str or path-like, optional
        HDF5 file (emcee ``HDFBackend`` layout) holding the chain, written whole at every
        check (:mod:`~bayesplate.sampling.storage`); if it holds a chain of the same problem,
        the run continues it from its last check (same coordinates, proposal and random
        state). None: the chain is kept in memory only.

    Raises
    ------
    ValueError
        Fewer than 12 walkers, or `max_steps` shorter than the tuning and one check.
    """

    n_walkers: int = 32
    max_steps: int = 5000
    target_tau_factor: float = 50.0
    min_ess: float = 2000.0
    max_rhat: float = 1.01
    check_every: int = 20
    tune_rounds: int = TUNE_ROUNDS
    tune_steps: int = TUNE_STEPS
    moves: list | None = None
    progress: bool = True
    backend_path: object = None

    def __post_init__(self):
        if self.n_walkers < 12:
            raise ValueError(
                f"n_walkers = {self.n_walkers}: need at least 12 (twice the dimension)"
            )
        least = self.tune_rounds * self.tune_steps + self.check_every
        if self.max_steps < least:
            raise ValueError(
                f"max_steps = {self.max_steps}: need at least {least} (the {self.tune_rounds} "
                f"x {self.tune_steps} tuning steps and one check of the stopping rule)"
            )

    @classmethod
    def of(cls, options=None, caller="sample_problem", **overrides):
        """`options` (default: the defaults) with `overrides`, each a field's name.

        Parameters
        ----------
        options : ChainOptions, optional
        caller : str
            Name of the function, for the messages.
        **overrides
            Fields by name, over `options`.

        Returns
        -------
        ChainOptions

        Raises
        ------
        TypeError
            An override that is no field of :class:`ChainOptions`.
        """
        return with_overrides(cls, options, caller, overrides)


@dataclass(frozen=True, eq=False)
class SetupOptions:
    """What the sampler's problem, posterior box and fast model are made from.

    The options of :func:`~bayesplate.sampling.setup.prepare`; the model itself, the seed and
    a setup prepared beforehand are arguments of their own.

    Parameters
    ----------
    forward : {"reduced", "full"}
        Sample with the certified fast model (falling back to the full one where it is not
        certified) or with the full model throughout.
    convention : str or bayesplate.estimators.Conventions
        Covariance conventions, as for :func:`bayesplate.estimators.estimate` (default
        ``"paper"``).
    prior_mean, prior_sd : array_like, shape (6,), optional
        Engineering prior (SI: Pa, and dimensionless for ``nu12``) replacing the case's.
    pairing : {"auto", "mac", "likelihood", "index", "order"} or Pairing
        As for :func:`bayesplate.estimators.estimate`
        (:func:`bayesplate.matching.pairing.pair_measured` at the prior mean; ``"likelihood"``: the
        assignment B settles on, on the working model, placing the box and the MAP; the chain
        re-makes it at every point unless the inputs are marginalised or an error scale is inferred
        (:func:`~bayesplate.sampling.assigned.reassignment`); any other pairing stays fixed,
        no modes computed beyond the paired ones. By order, the order is checked at the MAP
        and the setup made again by likelihood where the data refute it.
    box_sigma : float
        Half-width of the posterior box, in deviations of the pilot B estimate.
    box : bayesplate.reduced.Box, optional
        Explicit box for the fast model (stiffness coefficients, Pa; no pilot run).
    pilot_mesh : "auto", None or (nx, ny)
        Mesh of the pilot B run, elements: ``"auto"`` halves meshes above
        :data:`~bayesplate.sampling.setup.PILOT_MAX_ELEMENTS` elements (only when the model is
        the case's own); None runs it on the model.
    fast : bayesplate.reduced.CertifiedModel, optional
        A fast model already built (e.g. shared by several priors); no pilot, no build.
    fast_options : dict, optional
        Keywords of :func:`bayesplate.reduced.fast_model` (default
        :data:`~bayesplate.sampling.setup.FAST_DEFAULTS`).
    inputs : {"auto", "exact", "marginal"}
        The plate's measured inputs as exact numbers or with the case's deviations
        marginalised (:meth:`bayesplate.likelihood.posterior.GaussianProblem.from_case`);
        ``"auto"``: marginal when the case gives any ``plate.*_sd``. ``J_p`` is evaluated at the
        pilot (or settling) B estimate, else at the prior mean; with a fast model built here, its
        box is placed with the marginal problem's ``P`` there (one more full solve); then ``J_p``
        again at the marginal MAP, which is found again with it (:mod:`.setup`). A `fast`
        model or a `box` given is kept as it is: if it was placed for the exact posterior,
        walkers beyond it use the full model (counted in the result).

    Raises
    ------
    ValueError
        `forward` neither ``"reduced"`` nor ``"full"``.
    """

    forward: str = "reduced"
    convention: object = "paper"
    prior_mean: object = None
    prior_sd: object = None
    pairing: object = "auto"
    box_sigma: float = 6.0
    box: object = None
    pilot_mesh: object = "auto"
    fast: object = None
    fast_options: dict | None = None
    inputs: str = "auto"

    def __post_init__(self):
        if self.forward not in ("reduced", "full"):
            raise ValueError(f"forward = {self.forward!r}: must be 'reduced' or 'full'")

    @classmethod
    def of(cls, options=None, caller="prepare", **overrides):
        """`options` (default: the defaults) with `overrides`, each a field's name.

        Parameters
        ----------
        options : SetupOptions, optional
        caller : str
            Name of the function, for the messages.
        **overrides
            Fields by name, over `options`.

        Returns
        -------
        SetupOptions

        Raises
        ------
        TypeError
            An override that is no field of :class:`SetupOptions`.
        """
        return with_overrides(cls, options, caller, overrides)


#: The names of :class:`ChainOptions`' fields (:func:`~.pipeline.sample` parts its keywords).
CHAIN_FIELDS = frozenset(f.name for f in fields(ChainOptions))
