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
from dataclasses import replace

import emcee
import numpy as np
from threadpoolctl import threadpool_limits

from .. import laminate
from .density import EigenvalueForward, WhitenedLogPosterior
from .moves import InBox, LaplaceMove, RitzScreen, ScreenedDEMove, default_moves, moves_and_weights
from .result import build_result
from .seeding import generator, resolve_rng
from .stopping import StoppingRule, autocorr_time
from .storage import commit, open_backend, restore_tuning, store_tuning

__all__ = ["TUNE_ROUNDS", "TUNE_STEPS", "sample_problem"]

log = logging.getLogger(__name__)

#: Tuning of the Laplace proposal: rounds and steps per round (discarded afterwards).
TUNE_ROUNDS = 3
TUNE_STEPS = 30


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
    n_walkers=32,
    max_steps=5000,
    target_tau_factor=50.0,
    min_ess=2000.0,
    max_rhat=1.01,
    check_every=20,
    tune_rounds=TUNE_ROUNDS,
    tune_steps=TUNE_STEPS,
    pool=None,
    backend_path=None,
    progress=True,
    moves=None,
    forward=None,
    box=None,
    seed=None,
    assigned=None,
):
    """Sample ``ln f(b | Y)`` of a Gaussian problem with emcee, whitened around ``center``.

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
    n_walkers : int
        Walkers (at least 12).
    max_steps : int
        Cap on the chain length (steps in the backend, resumed ones included).
    target_tau_factor : float
        Stop once the chain after tuning is longer than this many autocorrelation times...
    min_ess : float
        ... and the smallest bulk ESS of the constants after burn-in reaches this...
    max_rhat : float
        ... and the largest R-hat (walkers as chains) is below this.
    check_every : int
        Steps between checks of the stopping rule.
    tune_rounds, tune_steps : int
        Tuning: rounds of ``tune_steps`` steps after each of which the
        :class:`LaplaceMove` proposes from the mean and covariance of the ensemble over the
        round's second half; then the proposal is frozen and the tuning steps discarded.
        Without a :class:`LaplaceMove` among the moves there is no tuning.
    pool : object with ``map``, optional
        E.g. a ``multiprocessing.Pool``; the log-density (problem and model) is pickled
        with every batch of proposals, which pays for slow models only.
    backend_path : path, optional
        HDF5 file (emcee ``HDFBackend`` layout) holding the chain, written whole at every
        check (:mod:`.storage`); if it holds one of the same problem, the run continues it
        from its last check (same coordinates, proposal and random state).
    progress : bool
        Progress bar (tqdm) with the current ``tau`` and ESS.
    moves : list, optional
        emcee moves; default :func:`default_moves`.
    forward : callable, optional
        ``forward(b, n_modes)`` replacing the problem's (e.g. an eigenvalues-only path).
    box : Box, optional
        The fast model's box: initial walkers and the Laplace proposals (default moves)
        are drawn inside it, and DE proposals outside it are screened (when ``forward`` is
        an :class:`~bayesplate.sampling.density.EigenvalueForward` holding a reduced model).
    seed : int, numpy.random.Generator or None
        Deprecated name of ``rng`` (a DeprecationWarning; removed in the next release).
    assigned : bayesplate.sampling.assigned.ReassignedLikelihood, optional
        The likelihood of all measured peaks with the assignment re-made at every point
        (pairing by likelihood); the result then carries what the chain did
        (``assignment``). None: the problem's fixed pairing.

    Returns
    -------
    SamplingResult
        Without ``estimate``, ``certificate`` and fast-model counts (see :func:`sample`).
    """
    if n_walkers < 12:
        raise ValueError(f"n_walkers = {n_walkers}: need at least 12 (twice the dimension)")
    if max_steps < tune_rounds * tune_steps + check_every:
        raise ValueError(
            f"max_steps = {max_steps}: need at least {tune_rounds * tune_steps + check_every} "
            f"(the {tune_rounds} x {tune_steps} tuning steps and one check of the stopping rule)"
        )
    entropy, rng = generator(resolve_rng(rng, seed, "sample_problem"))
    density = WhitenedLogPosterior(problem, center, covariance, forward, assigned)
    backend, stored = open_backend(backend_path, density, n_walkers)
    if moves is None:
        inside = None if box is None else InBox(density, box)
        reduced = forward.reduced if isinstance(forward, EigenvalueForward) else None
        screen = None if box is None or reduced is None else RitzScreen(density, reduced, box)
        moves = default_moves(inside, screen)
    # our own references to the moves (emcee keeps its copy private); emcee gets ``moves``
    move_objects, move_weights = moves_and_weights(moves)
    laplace = _laplace_move(move_objects)
    sampler = emcee.EnsembleSampler(n_walkers, 6, density, pool=pool, moves=moves, backend=backend)
    emcee_seed = int(rng.integers(2**32))
    resumed = stored is not None
    if resumed:
        state = backend.get_last_sample()
        log.info("resuming %s at step %d", backend_path, backend.iteration)
    else:
        sampler.random_state = np.random.RandomState(emcee_seed).get_state()
        state = emcee.State(_initial_walkers(density, n_walkers, rng, box))
    started, steps0, forward0 = time.perf_counter(), sampler.iteration, density.n_forward
    bar = _progress_bar(progress, max_steps, sampler.iteration)
    # the reduced model solves small dense eigenproblems: BLAS threads only slow them down
    # (up to ten times on a busy machine, reports/benchmark_reduced.md)
    limits = threadpool_limits(limits=1, user_api="blas")
    try:
        with _Interrupt() as interrupt:
            n_tune = restore_tuning(stored, laplace)
            if n_tune is None:
                rounds = tune_rounds if laplace is not None else 0
                state, n_tune = _tune(
                    sampler, state, laplace, rounds, tune_steps, max_steps, bar, interrupt
                )
                store_tuning(backend, laplace, n_tune)
            stop = StoppingRule(density, n_tune, target_tau_factor, min_ess, max_rhat)
            state, history, converged = _run_chain(
                sampler, state, max_steps, check_every, stop, bar, n_tune, interrupt
            )
    finally:
        limits.restore_original_limits()
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - started
    n_eval = n_walkers * (sampler.iteration - steps0 + (0 if resumed else 1))
    settings = {
        "seed_entropy": entropy,
        "emcee_seed": None if resumed else emcee_seed,
        "n_walkers": n_walkers,
        "max_steps": max_steps,
        "target_tau_factor": target_tau_factor,
        "min_ess": min_ess,
        "max_rhat": max_rhat,
        "check_every": check_every,
        "n_tune": n_tune,
        "moves": [type(m).__name__ for m in move_objects],
        "move_weights": list(map(float, move_weights)),
        "backend": None if backend_path is None else str(backend_path),
        "resumed": resumed,
        "center_b": density.center,
        "chol_b": density.chol,
    }
    result = build_result(sampler, density, history, converged, wall, n_eval, forward0, settings)
    screened = sum(m.n_screened for m in move_objects if isinstance(m, ScreenedDEMove))
    return replace(result, n_screened=screened, n_evaluations=n_eval - screened)
