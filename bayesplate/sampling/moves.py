"""The sampler's emcee moves: a tuned independence proposal and screened differential evolution.

:class:`LaplaceMove` (an :class:`emcee.moves.MHMove` through its proposal function) draws
from a Gaussian or Student-t approximation truncated to the fast model's box
(:class:`InBox`); :class:`ScreenedDEMove` is emcee's :class:`~emcee.moves.DEMove` that
rejects, without evaluating them, proposals whose upper bound of the log-posterior
(:class:`RitzScreen`) proves them rejected. :func:`default_moves` mixes them;
:func:`moves_and_weights` reads a ``moves`` argument as emcee does.
"""

from __future__ import annotations

import emcee
import numpy as np

__all__ = [
    "InBox",
    "LaplaceMove",
    "RitzScreen",
    "ScreenedDEMove",
    "default_moves",
    "moves_and_weights",
]


class LaplaceMove(emcee.moves.MHMove):
    """Independence Metropolis-Hastings proposal from a Gaussian approximation.

    In whitened coordinates the proposal is ``z' = m + scale A t`` whatever the current
    ``z``, with ``t`` standard normal (``df=None``) or multivariate Student-t with ``df``
    degrees of freedom; ``m = 0``, ``A = I`` (the Laplace approximation the coordinates are
    whitened by) until :meth:`set_proposal` sets them, e.g. from the ensemble after a
    tuning run. The Hastings factor is ``ln q(z) - ln q(z')``. A ``scale`` above 1 and
    Student-t tails make the proposal wider than the approximation, so that posterior tails
    a little heavier than it are still reached.

    With ``inside``, the proposal is truncated to a region (the fast model's certified box):
    draws outside it are redrawn, so no proposal of this move needs the full model. The
    truncated density differs from the untruncated one by a constant inside, so the factor
    is unchanged there, and it is zero outside: from a walker outside the region (which
    only another move can take there) this move is never accepted. Each pair of points
    then still satisfies detailed balance, so the move leaves the posterior invariant; the
    other move (differential evolution) keeps the whole space reachable.

    Parameters
    ----------
    scale : float
        Proposal deviation in units of ``A``.
    inside : callable, optional
        ``inside(z) -> bool array`` for ``z`` of shape (n, 6).
    df : float, optional
        Degrees of freedom of Student-t proposals; None for Gaussian ones.
    max_redraws : int
        Redraws of proposals outside the region before giving up (then rejected).
    """

    def __init__(self, scale=1.1, inside=None, df=None, max_redraws=100):
        self.scale = float(scale)
        self.inside = inside
        self.df = None if df is None else float(df)
        self.max_redraws = int(max_redraws)
        self.mean = None
        self.chol = None
        super().__init__(self._proposal)

    def set_proposal(self, mean, covariance):
        """Centre ``m`` and covariance ``A A^T`` of the proposal (whitened coordinates)."""
        self.mean = np.array(mean, dtype=float)
        self.chol = np.linalg.cholesky(np.asarray(covariance, dtype=float))

    def _standardised(self, z):
        if self.mean is None:
            return z / self.scale
        return np.linalg.solve(self.chol, (z - self.mean).T).T / self.scale

    def _log_q(self, z):
        r2 = np.sum(self._standardised(z) ** 2, axis=1)
        if self.df is None:
            return -0.5 * r2
        return -0.5 * (self.df + z.shape[1]) * np.log1p(r2 / self.df)

    def _draw(self, n, d, random):
        t = random.randn(n, d)
        if self.df is not None:
            t *= np.sqrt(self.df / random.chisquare(self.df, size=(n, 1)))
        t *= self.scale
        return t if self.mean is None else self.mean + t @ self.chol.T

    def _proposal(self, z, random):
        new = self._draw(*z.shape, random)
        if self.inside is not None:
            for _ in range(self.max_redraws):
                out = ~self.inside(new)
                if not np.any(out):
                    break
                new[out] = self._draw(int(np.sum(out)), z.shape[1], random)
        factor = self._log_q(z) - self._log_q(new)
        if self.inside is not None:
            factor[~self.inside(z) | ~self.inside(new)] = -np.inf
        return new, factor


class ScreenedDEMove(emcee.moves.DEMove):
    """emcee's differential-evolution move that skips proposals it can prove rejected.

    Metropolis-Hastings accepts a proposal ``q`` of walker ``j`` when ``ln f(q) > t_j =
    ln f(x_j) + ln u_j - factor_j``. With ``screen(q)``, an upper bound of ``ln f(q)``,
    a proposal whose bound is below ``t_j`` is rejected without evaluating ``ln f``: the
    decision is the one the evaluation would give, so the chain is that of ``DEMove``
    (with the uniform draws taken before the evaluations). Used for proposals outside the
    fast model's box, which would otherwise each cost a full finite-element solve.

    Parameters
    ----------
    screen : callable, optional
        ``screen(q) -> numpy.ndarray, shape (n,)``: upper bounds of ``ln f`` at the
        proposals ``q`` (shape (n, 6)); ``+inf`` where none is known. None: plain DEMove.
    **kwargs
        Of :class:`emcee.moves.DEMove`.

    Attributes
    ----------
    n_screened : int
        Proposals rejected without evaluation.

    Notes
    -----
    The proposals come from :class:`~emcee.moves.DEMove`'s public hooks (``setup``,
    ``get_proposal``) and the update from :meth:`emcee.moves.Move.update`; the red-blue
    sweep itself (:meth:`emcee.moves.RedBlueMove.propose`) is written out here, because no
    hook of it runs between drawing the proposals and evaluating them: ``get_proposal``
    sees neither the walkers' log-densities nor the uniform draws (taken after the
    evaluation), and ``propose`` evaluates every proposal. The sweep follows emcee 3.1's
    order of random draws exactly (split shuffle, proposal, one uniform per walker of the
    split), so that without a screen the chain is ``DEMove``'s and seeded chains do not
    change; it does not check ``live_dangerously`` (the sampler asks for 12 walkers or
    more).
    """

    def __init__(self, screen=None, **kwargs):
        super().__init__(**kwargs)
        self.screen = screen
        self.n_screened = 0

    def propose(self, model, state):
        """One red-blue sweep; see :meth:`emcee.moves.RedBlueMove.propose`."""
        if self.screen is None:
            return super().propose(model, state)
        nwalkers = state.coords.shape[0]
        self.setup(state.coords)
        accepted = np.zeros(nwalkers, dtype=bool)
        all_inds = np.arange(nwalkers)
        inds = all_inds % self.nsplits
        if self.randomize_split:
            model.random.shuffle(inds)
        for split in range(self.nsplits):
            S1 = inds == split
            sets = [state.coords[inds == j] for j in range(self.nsplits)]
            q, factors = self.get_proposal(
                sets[split], sets[:split] + sets[split + 1 :], model.random
            )
            log_u = np.log(model.random.rand(len(q)))
            threshold = state.log_prob[S1] + log_u - factors
            need = ~(self.screen(q) < threshold)
            self.n_screened += int(np.sum(~need))
            log_prob = np.full(len(q), -np.inf)
            blobs = None
            if state.blobs is not None:
                blobs = np.full((len(q), *state.blobs.shape[1:]), np.nan)
            if np.any(need):
                lp, bl = model.compute_log_prob_fn(q[need])
                log_prob[need] = lp
                if blobs is not None:
                    blobs[need] = bl
            accepted[all_inds[S1]] = log_prob > threshold
            new_state = emcee.State(q, log_prob=log_prob, blobs=blobs)
            state = self.update(state, new_state, accepted, S1)
        return state, accepted


class RitzScreen:
    """Upper bounds of ``ln f(b | Y)`` off the fast model's box, from Ritz values.

    The reduced eigenvalues are upper bounds of the finite-element ones anywhere
    (Courant-Fischer; the rigid-body motions are in the basis): with ``g_i <= R_i``, the
    misfit of a measured ``Y_i > R_i`` is at least ``Y_i - R_i``, so ``ln f <= ln prior -
    sum_{Y_i > R_i} (Y_i - R_i)^2 / (2 v_i) - sum ln(2 pi v_i) / 2``, plus the sampler's
    log-Jacobian. ``R`` is inflated by ``1e-8`` relative for rounding. Inside the box (no
    full solve needed) the bound is ``+inf``: evaluate. With a full ``V_Y`` (the inputs
    marginalised) the misfit ``r^T V_Y^-1 r`` is at least that of the eigenvalues ``I`` with
    ``Y_i > R_i`` alone, ``r_I^T (V_Y)_II^-1 r_I >= |gap_I|^2 / lambda_max((V_Y)_II)``, and
    the normalising term is ``-(ln det V_Y + m ln 2 pi) / 2``. With an error scale the bound
    is the Student-t marginal at that misfit (it decreases with the misfit too). With the
    assignment re-made at every point (``density.assigned``), the bound is
    :meth:`~bayesplate.sampling.assigned.ReassignedLikelihood.upper_bound` at the Ritz values.

    Parameters
    ----------
    density : WhitenedLogPosterior
        The sampler's density (its problem, whitening and log-Jacobian).
    reduced : bayesplate.reduced.ReducedModel
        The reduced model whose eigenvalues bound the full model's from above.
    box : bayesplate.reduced.Box
        The certified box (inside it: no bound).
    """

    def __init__(self, density, reduced, box):
        self.density, self.reduced, self.box = density, reduced, box
        p = density.problem
        var = np.diag(p.V_Y)
        self._diagonal = np.array_equal(p.V_Y, np.diag(var))
        if self._diagonal:
            self._norm = -0.5 * np.sum(np.log(2 * np.pi * var))
        else:
            self._norm = -0.5 * (np.linalg.slogdet(p.V_Y)[1] + var.size * np.log(2 * np.pi))

    def __call__(self, z):
        """Upper bounds of the sampler's log-density at whitened `z` (n, 6), shape (n,)."""
        p = self.density.problem
        b = self.density.to_b(z)
        bounds = np.full(len(b), np.inf)
        for k in np.flatnonzero(~self.box.contains(b)):
            prior = p.log_prior(b[k])
            if not np.isfinite(prior):
                bounds[k] = -np.inf
                continue
            assigned = self.density.assigned
            try:
                if assigned is not None:  # the best assignment of the bounds bounds the best
                    R = self.reduced.eigenvalues(b[k], assigned.n) * (1 + 1e-8)
                    bounds[k] = prior + assigned.upper_bound(R)
                    continue
                R = self.reduced.eigenvalues(b[k], p.pairing.n_modes())[p.pairing.modes]
            except ValueError:  # the basis holds too few modes there: no bound
                continue
            gap = np.maximum(p.Y - R * (1 + 1e-8), 0.0)
            bounds[k] = prior + self._likelihood_bound(self._misfit(gap, p.V_Y))
        return bounds + self.density.log_jacobian(z)

    def _likelihood_bound(self, misfit):
        """``ln f(Y | b)`` at a lower bound of ``chi2``: it decreases with ``chi2``.

        With an error scale, the Student-t marginal
        (:func:`bayesplate.likelihood.error_scale.log_marginal`).
        """
        p = self.density.problem
        if p.error_scale is None:
            return self._norm - 0.5 * misfit
        from ..likelihood.error_scale import log_marginal

        return float(log_marginal(misfit, p.m, np.linalg.slogdet(p.V_Y)[1], p.error_scale))

    def _misfit(self, gap, V_Y):
        """A lower bound of ``r^T V_Y^-1 r`` over residuals with ``r_i >= gap_i`` (gap >= 0)."""
        if self._diagonal:
            return np.sum(gap**2 / np.diag(V_Y))
        on = gap > 0
        if not np.any(on):
            return 0.0
        return np.sum(gap[on] ** 2) / np.linalg.eigvalsh(V_Y[np.ix_(on, on)])[-1]


def default_moves(inside=None, screen=None):
    """The moves of :func:`sample`: 90 % :class:`LaplaceMove` (Student-t, scale 1.1), 10 % DE.

    Tuning runs (seeds 1 and 2) in whitened ``b`` on Plate 1 (case prior), effective
    samples per 1000 evaluations: Gaussian independence proposal, scale 1.1, 80/20 with DE,
    320-390; scale 1.2, 70/30, 250-280; scale 1.0, 170-270; emcee's stretch move 8-9; DE
    with snooker moves 35-42. On the Frederiksen plate in log coordinates with tuning:
    Student-t (10) at 90/10 65-106, at 80/20 65-92.

    Parameters
    ----------
    inside : callable, optional
        Region the Laplace proposals are truncated to (see :class:`LaplaceMove`).
    screen : callable, optional
        Upper bounds of the log-posterior for the DE move (see :class:`ScreenedDEMove`).

    Returns
    -------
    list of (emcee.moves.Move, float)
        The moves and their weights, as :class:`emcee.EnsembleSampler` takes them.
    """
    return [(LaplaceMove(1.1, inside, df=10), 0.9), (ScreenedDEMove(screen), 0.1)]


class InBox:
    """``inside(z)``: whether whitened points map into a box of ``b``.

    Parameters
    ----------
    density : WhitenedLogPosterior
        Its :meth:`~WhitenedLogPosterior.to_b` maps ``z`` to ``b``.
    box : bayesplate.reduced.Box
    """

    def __init__(self, density, box):
        self.density, self.box = density, box

    def __call__(self, z):
        """Whether each row of `z` (shape (n, 6)) maps into the box, bool (n,)."""
        return np.asarray(self.box.contains(self.density.to_b(z)))


def moves_and_weights(moves):
    """The move objects and their normalised weights, read as :class:`emcee.EnsembleSampler`.

    Parameters
    ----------
    moves : emcee.moves.Move, list of Move or list of (Move, float)

    Returns
    -------
    list of emcee.moves.Move
    numpy.ndarray, shape (n,)
        Weights summing to one (the same arithmetic as emcee's).
    """
    if isinstance(moves, emcee.moves.Move):
        objects, weights = [moves], [1.0]
    elif all(isinstance(m, tuple) for m in moves):
        objects = [m for m, _ in moves]
        weights = [w for _, w in moves]
    else:
        objects, weights = list(moves), np.ones(len(moves))
    weights = np.atleast_1d(weights).astype(float)
    weights /= np.sum(weights)
    return objects, weights
