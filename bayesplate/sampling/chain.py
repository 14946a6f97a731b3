"""The emcee run: walkers' start, tuning of the proposal, the run loop to the stopping rule.

:func:`sample_problem` samples ``ln f(b | Y)`` of a Gaussian problem in whitened log
coordinates (:class:`~bayesplate.sampling.density.WhitenedLogPosterior`) with the default
moves (:func:`~bayesplate.sampling.moves.default_moves`): the walkers start from ``N(0, I)``
(the Laplace approximation at the MAP) inside the fast model's box; :data:`TUNE_ROUNDS`
rounds of :data:`TUNE_STEPS` steps tune the independence proposal on the ensemble, then it is
frozen and those steps discarded; the chain runs ``check_every`` steps at a time until the
stopping rule (:mod:`bayesplate.sampling.stopping`) or ``max_steps``; an HDF backend
(:mod:`bayesplate.sampling.storage`) lets a later call continue it.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from dataclasses import dataclass, replace

import emcee
import numpy as np
from threadpoolctl import threadpool_limits

from .. import laminate
from .density import EigenvalueForward, WhitenedLogPosterior
from .moves import InBox, LaplaceMove, RitzScreen, ScreenedDEMove, default_moves, moves_and_weights
from .options import TUNE_ROUNDS, TUNE_STEPS, ChainOptions
from .result import build_result
from .seeding import generator, resolve_rng
from .stopping import StoppingRule, autocorr_time
from .storage import commit, open_backend, restore_tuning, store_tuning

__all__ = ["TUNE_ROUNDS", "TUNE_STEPS", "ChainOptions", "sample_problem"]

log = logging.getLogger(__name__)


def _initial_walkers(density, n_walkers, rng, box=None, tries=1000):
    """``z ~ N(0, I)`` (the B estimate with its covariance), redrawn until physical.

    Redrawn also until inside `box` when one is given; `rng` is a numpy Generator.
    Returns shape (n_walkers, 6).
    """
    z = rng.standard_normal((n_walkers, 6))
    for _ in range(tries):
        b = density.to_b(z)
        bad = ~laminate.is_physical(b)
        if box is not None:
            bad |= ~box.contains(b)
        if not np.any(bad):
            return z
        z[bad] = rng.standard_normal((int(np.sum(bad)), 6))
    raise RuntimeError("could not draw physical initial walkers around the B estimate")


def _progress_bar(progress, total, initial):
    """A tqdm bar, or None (no progress asked, or no tqdm)."""
    if not progress:
        return None
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover - tqdm comes with the test environment
        return None
    return tqdm(total=total, initial=initial, desc="sampling", unit="step", leave=False)


class _Interrupt:
    """Ctrl-C while sampling is taken at the end of the step under way, not inside emcee.

    emcee prints the traceback of any exception raised in the log-density (Ctrl-C
    included) before passing it on; within this block the first SIGINT only sets
    :attr:`asked`, and :func:`_advance` raises ``KeyboardInterrupt`` after the step. A
    second Ctrl-C interrupts at once. Outside the main thread nothing changes.
    """

    def __enter__(self):
        self.asked, self.saved = False, None
        if threading.current_thread() is threading.main_thread():
            self.saved = signal.signal(signal.SIGINT, self._ask)
        return self

    def _ask(self, signum, frame):
        if self.asked:
            raise KeyboardInterrupt
        self.asked = True

    def __exit__(self, *exc):
        if self.saved is not None:
            signal.signal(signal.SIGINT, self.saved)
        return False


def _advance(sampler, state, steps, interrupt):
    """``steps`` steps of the sampler; ``KeyboardInterrupt`` after a step if Ctrl-C came."""
    for _ in sampler.sample(state, iterations=steps, skip_initial_state_check=True):
        if interrupt is not None and interrupt.asked:
            raise KeyboardInterrupt
    return sampler.backend.get_last_sample()


def _run_chain(sampler, state, max_steps, check_every, stop, bar, n_tune, interrupt=None):
    """Advance ``check_every`` steps at a time until ``stop(sampler)`` or ``max_steps``.

    The chain is committed to its file after every block (:func:`.storage.commit`), so a
    resumed chain starts on a check and meets the rule on the same step as one never
    stopped; a resumed chain is checked before it runs (it may have met the rule already).
    """
    history = []
    converged = False
    if sampler.iteration > n_tune:
        tau = autocorr_time(sampler, n_tune)
        history.append([sampler.iteration, *tau])
        converged, _ = stop(sampler, tau)
    while not converged and sampler.iteration < max_steps:
        steps = min(check_every, max_steps - sampler.iteration)
        state = _advance(sampler, state, steps, interrupt)
        commit(sampler.backend)
        tau = autocorr_time(sampler, n_tune)
        history.append([sampler.iteration, *tau])
        converged, note = stop(sampler, tau)
        if bar is not None:
            bar.update(steps)
            bar.set_postfix_str(note, refresh=False)
    return state, np.array(history).reshape(-1, 1 + sampler.ndim), converged


def _tune(sampler, state, move, rounds, steps, max_steps, bar, interrupt=None):
    """Rounds of ``steps``; after each, ``move`` proposes from the ensemble's last half.

    Returns the state and the step at which the proposal was frozen (the burn-in).
    """
    for _ in range(rounds):
        steps = min(steps, max_steps - sampler.iteration)
        if steps < 4:
            break
        state = _advance(sampler, state, steps, interrupt)
        z = sampler.get_chain(discard=sampler.iteration - steps // 2).reshape(-1, sampler.ndim)
        move.set_proposal(z.mean(axis=0), np.cov(z, rowvar=False))
        if bar is not None:
            bar.update(steps)
            bar.set_postfix_str("tuning", refresh=False)
    return state, sampler.iteration


def _laplace_move(moves):
    """The first :class:`LaplaceMove` of a list of moves (the one tuned), or None."""
    found = [m for m in moves if isinstance(m, LaplaceMove)]
    return found[0] if found else None


def sample_problem(
    problem,
    center,
    covariance,
    *,
    rng=None,
    options=None,
    pool=None,
    forward=None,
    box=None,
    assigned=None,
    seed=None,
    **settings,
):
    """Sample ``ln f(b | Y)`` of a Gaussian problem with emcee, whitened around ``center``.

    The stages: the start (:func:`_start`: backend, moves, initial walkers or the resumed
    state), the tuning and the run to the stopping rule (:func:`_walk`), the result
    (:func:`_finish`).

    Parameters
    ----------
    problem : GaussianProblem
    center : array_like, shape (6,)
        Centre of the whitening and of the initial walkers (the MAP), Pa.
    covariance : array_like, shape (6, 6)
        Whitening and initial spread (``P`` of the B estimate), Pa^2.
    rng : int, numpy.random.Generator or None
        Seeds the initial walkers and emcee's random state (a ``RandomState`` seeded with
        an integer drawn from it): the same seed gives the same chain.
    options : ChainOptions, optional
        Size, stopping rule, tuning, moves, progress bar, file (default ``ChainOptions()``).
    pool : object with ``map``, optional
        E.g. a ``multiprocessing.Pool``; the log-density (problem and model) is pickled with
        every batch of proposals, which pays for slow models only.
    forward : callable, optional
        ``forward(b, n_modes)`` replacing the problem's (e.g. an eigenvalues-only path).
    box : Box, optional
        The fast model's box: initial walkers and the Laplace proposals (default moves)
        are drawn inside it, and DE proposals outside it are screened (when ``forward`` is
        an :class:`~bayesplate.sampling.density.EigenvalueForward` holding a reduced model).
    assigned : bayesplate.sampling.assigned.ReassignedLikelihood, optional
        The likelihood of all measured peaks with the assignment re-made at every point
        (pairing by likelihood); the result then carries what the chain did
        (``assignment``). None: the problem's fixed pairing.
    seed : int, numpy.random.Generator or None
        Deprecated name of ``rng`` (a DeprecationWarning; removed in the next release).
    **settings
        Any field of :class:`ChainOptions` by name (``n_walkers=16``, ``min_ess=500``, ...),
        over `options`.

    Returns
    -------
    SamplingResult
        Without ``estimate``, ``certificate`` and fast-model counts (see :func:`sample`).
    """
    options = ChainOptions.of(options, "sample_problem", **settings)
    entropy, rng = generator(resolve_rng(rng, seed, "sample_problem"))
    density = WhitenedLogPosterior(problem, center, covariance, forward, assigned)
    start = _start(density, options, rng, pool, forward, box)
    state, n_tune, history, converged = _walk(start, options)
    return _finish(start, options, entropy, n_tune, history, converged)


@dataclass(frozen=True, eq=False)
class _Start:
    """The chain before its first step: what :func:`_walk` runs and :func:`_finish` reads.

    ``state`` is the initial walkers' or the resumed chain's last; ``stored`` what the
    backend held (None: a new chain); ``moves`` and ``weights`` our own references to the
    moves (emcee keeps its copy private); ``laplace`` the one tuned, or None; ``started``,
    ``steps0`` and ``forward0`` the clock, the steps and the forward solves at the start.
    """

    density: WhitenedLogPosterior
    sampler: emcee.EnsembleSampler
    state: emcee.State
    stored: object
    moves: list
    weights: list
    laplace: LaplaceMove | None
    emcee_seed: int
    started: float
    steps0: int
    forward0: int


def _start(density, options, rng, pool, forward, box):
    """The sampler on its backend, the moves, and its state: new walkers or the chain resumed.

    The integer seeding emcee's random state is drawn from `rng` first, then the initial
    walkers (a resumed chain draws none and keeps its stored random state).
    """
    backend, stored = open_backend(options.backend_path, density, options.n_walkers)
    moves = options.moves
    if moves is None:
        moves = _default_moves(density, forward, box)
    move_objects, move_weights = moves_and_weights(moves)
    sampler = emcee.EnsembleSampler(
        options.n_walkers, 6, density, pool=pool, moves=moves, backend=backend
    )
    emcee_seed = int(rng.integers(2**32))
    if stored is not None:
        state = backend.get_last_sample()
        log.info("resuming %s at step %d", options.backend_path, backend.iteration)
    else:
        sampler.random_state = np.random.RandomState(emcee_seed).get_state()
        state = emcee.State(_initial_walkers(density, options.n_walkers, rng, box))
    return _Start(
        density=density,
        sampler=sampler,
        state=state,
        stored=stored,
        moves=move_objects,
        weights=move_weights,
        laplace=_laplace_move(move_objects),
        emcee_seed=emcee_seed,
        started=time.perf_counter(),
        steps0=sampler.iteration,
        forward0=density.n_forward,
    )


def _default_moves(density, forward, box):
    """:func:`default_moves` inside `box`, screened with the reduced model `forward` holds."""
    inside = None if box is None else InBox(density, box)
    reduced = forward.reduced if isinstance(forward, EigenvalueForward) else None
    screen = None if box is None or reduced is None else RitzScreen(density, reduced, box)
    return default_moves(inside, screen)


def _walk(start, options):
    """The tuning (or the resumed chain's, restored) and the run to the stopping rule.

    Returns the last state, the tuning steps (the burn-in), the history of ``tau`` and
    whether the rule was met. BLAS runs on one thread meanwhile: the reduced model solves
    small dense eigenproblems, which more threads only slow down (up to ten times on a busy
    machine, reports/benchmark_reduced.md).
    """
    sampler, laplace, state = start.sampler, start.laplace, start.state
    bar = _progress_bar(options.progress, options.max_steps, sampler.iteration)
    limits = threadpool_limits(limits=1, user_api="blas")
    try:
        with _Interrupt() as interrupt:
            n_tune = restore_tuning(start.stored, laplace)
            if n_tune is None:
                rounds = options.tune_rounds if laplace is not None else 0
                state, n_tune = _tune(
                    sampler,
                    state,
                    laplace,
                    rounds,
                    options.tune_steps,
                    options.max_steps,
                    bar,
                    interrupt,
                )
                store_tuning(sampler.backend, laplace, n_tune)
            stop = StoppingRule(
                start.density, n_tune, options.target_tau_factor, options.min_ess, options.max_rhat
            )
            state, history, converged = _run_chain(
                sampler, state, options.max_steps, options.check_every, stop, bar, n_tune, interrupt
            )
    finally:
        limits.restore_original_limits()
        if bar is not None:
            bar.close()
    return state, n_tune, history, converged


def _finish(start, options, entropy, n_tune, history, converged):
    """The :class:`SamplingResult`, its settings and its counts of evaluations and screens."""
    sampler, density, resumed = start.sampler, start.density, start.stored is not None
    wall = time.perf_counter() - start.started
    n_eval = options.n_walkers * (sampler.iteration - start.steps0 + (0 if resumed else 1))
    path = options.backend_path
    settings = {
        "seed_entropy": entropy,
        "emcee_seed": None if resumed else start.emcee_seed,
        "n_walkers": options.n_walkers,
        "max_steps": options.max_steps,
        "target_tau_factor": options.target_tau_factor,
        "min_ess": options.min_ess,
        "max_rhat": options.max_rhat,
        "check_every": options.check_every,
        "n_tune": n_tune,
        "moves": [type(m).__name__ for m in start.moves],
        "move_weights": list(map(float, start.weights)),
        "backend": None if path is None else str(path),
        "resumed": resumed,
        "center_b": density.center,
        "chol_b": density.chol,
    }
    result = build_result(
        sampler, density, history, converged, wall, n_eval, start.forward0, settings
    )
    screened = sum(m.n_screened for m in start.moves if isinstance(m, ScreenedDEMove))
    return replace(result, n_screened=screened, n_evaluations=n_eval - screened)
