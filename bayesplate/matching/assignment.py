"""Which computed mode explains which measured peak: the most probable assignment.

Without measured shapes, a one-point test shows some of the plate's modes and not others (a
mode with a node at the point is missed) and may show peaks that are not bending modes of the
plate (in-plane or suspension modes, noise). Pairing by order then shifts every pair above
the first gap. Here each measured peak ``i`` (frequency ``f_i``, deviation ``s_i``) is either
one computed mode ``j`` (frequency ``c_j``, predictive deviation ``t_j`` from the constants'
current uncertainty) or spurious, each computed mode is seen at most once, and a computed
mode inside the measured band that no peak explains is unobserved. With prior probabilities
``p_u`` (a mode in the band is unobserved) and ``p_s`` (a peak is spurious), the log-probability
of an assignment ``a`` is

``log P(a) = sum_paired [log N(f_i; c_j, s_i^2 + t_j^2) + log(1 - p_s)]``
``          + sum_spurious [log p_s - log B] + sum_in_band [log(1 - p_u) or log p_u]``,

a spurious peak being uniform over ``[0, B]``, ``B`` the highest measured frequency plus
three deviations, and each computed mode up to the highest measured frequency (the band)
observed or not (computed modes above it were not looked for). Its maximum is a linear
assignment problem (Hungarian method, scipy's ``linear_sum_assignment``) on an
``m x (n + m)`` cost matrix: the ``n`` computed modes, and one "spurious" column per peak.

With measured shapes, :func:`assign_with_shapes` adds to each pair the log-density of its
modal assurance criterion ``MAC_ij`` under a stated model: a peak's shape against its own
mode has ``1 - MAC`` exponential with scale ``s_MAC`` (:data:`MAC_SCALE`), against any other
mode (and a spurious peak against every mode) ``MAC`` uniform on [0, 1]. The frequency
residual is then Student-t with :data:`SHAPE_DOF` degrees of freedom instead of Gaussian:
the predictive deviation ``t_j`` is first order at a prior that may itself be several
deviations off, and where the shapes speak, a far frequency should weaken a pair, not veto it.

``log P(a) = sum_paired [log T_nu(f_i - c_j; sqrt(s_i^2 + t_j^2)) - log s_MAC``
``          - (1 - MAC_ij) / s_MAC + log(1 - p_s)] + sum_spurious [log p_s - log B]``
``          + sum_in_band [log(1 - p_u) or log p_u]``,

pairs below a MAC threshold being excluded outright (the shape says it is not that mode).

Pure array computation. The estimators recompute the assignment where the constants move
(:func:`bayesplate.estimators.estimate`) and keep the pairing fixed within one run, so that
an iteration cannot cycle between pairings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import t as student_t

from ..quantities import eigenvalue_from_hz, eigenvalue_sd, hz_from_eigenvalue, predictive_sd_Hz

__all__ = [
    "P_UNOBSERVED",
    "P_SPURIOUS",
    "MAC_SCALE",
    "SHAPE_DOF",
    "Assignment",
    "assign",
    "assign_with_shapes",
    "assignment_terms",
    "best_assignment",
    "spurious_band_Hz",
    "most_probable",
    "predictive_sd_Hz",
]

#: Prior probability that a computed mode inside the measured band is not seen by the test
#: (a one-point FRF misses the modes with a node at the point: a few in ten).
P_UNOBSERVED = 0.1
#: Prior probability that a measured peak is not a bending mode of the plate.
P_SPURIOUS = 0.05
#: Scale ``s_MAC`` of ``1 - MAC`` between a measured shape and its own computed mode
#: (exponential): noisy shapes at a few tens of points reach MAC 0.9-0.99 against their
#: mode, so a mean shortfall of 0.05; a clean match then outweighs a frequency residual of
#: about five predictive deviations, a MAC difference of 0.01 only a tenth of one.
MAC_SCALE = 0.05
#: Degrees of freedom ``nu`` of the Student-t frequency residual when shapes are measured: a
#: residual of 8 deviations costs 6 nats (a Gaussian 32), 2 deviations 1.7 (Gaussian 2).
SHAPE_DOF = 3.0
_BAND_SIGMAS = 3.0  # the band ends this many deviations above the highest peak
_FORBIDDEN = 1e12  # cost of a peak's spurious column taken by another peak


@dataclass(frozen=True)
class Assignment:
    """The most probable assignment of measured peaks to computed modes.

    Attributes
    ----------
    modes : numpy.ndarray of int, shape (m,)
        0-based computed mode explaining each measured peak; -1 where the peak is spurious.
    unobserved : numpy.ndarray of int, shape (k,)
        0-based computed modes inside the band that no peak explains.
    log_probability : float
        ``log P(a)`` of the module docstring (up to the normalising sum over assignments).
    band_Hz : float
        Upper end of the range a spurious peak may lie in (the highest peak plus three
        deviations), Hz.
    p_unobserved : numpy.ndarray, shape (n,), optional
        The computed modes' prior of going unobserved that made it (:func:`most_probable`).
    """

    modes: np.ndarray
    unobserved: np.ndarray
    log_probability: float
    band_Hz: float
    p_unobserved: np.ndarray | None = None

    @property
    def paired(self):
        """0-based measured peaks that a computed mode explains, shape (m - spurious,)."""
        return np.flatnonzero(self.modes >= 0)

    @property
    def spurious(self):
        """0-based measured peaks left unexplained, shape (spurious,)."""
        return np.flatnonzero(self.modes < 0)

    @property
    def in_order(self):
        """Whether this is pairing by order: peak i with computed mode i, for all peaks."""
        return bool(np.array_equal(self.modes, np.arange(self.modes.size)))

    @property
    def keeps_order(self):
        """Whether every peak it pairs goes with its own computed mode (peak i with mode i).

        True for the order and for the order with some peaks called spurious in their own
        place (their own mode then unobserved): outliers of a fit, not a re-ordering. False
        where a peak goes with another mode: a mode missed or a peak inserted below it.
        """
        k = self.paired
        return bool(np.array_equal(self.modes[k], k))

    def describe(self):
        """One sentence on what went unobserved and unexplained (1-based numbers)."""
        parts = []
        if self.unobserved.size:
            which = ", ".join(str(j + 1) for j in self.unobserved)
            parts.append(
                f"computed mode{'s' if self.unobserved.size > 1 else ''} {which} unobserved"
            )
        if self.spurious.size:
            which = ", ".join(str(i + 1) for i in self.spurious)
            parts.append(
                f"measured peak{'s' if self.spurious.size > 1 else ''} {which} unexplained "
                "(spurious) and left out of the fit"
            )
        return "; ".join(parts) if parts else "every peak in order, none missed"


def assign(
    measured_Hz,
    sigma_Hz,
    computed_Hz,
    computed_sd_Hz=None,
    p_unobserved=P_UNOBSERVED,
    p_spurious=P_SPURIOUS,
):
    """The most probable assignment of measured peaks to computed modes.

    Parameters
    ----------
    measured_Hz, sigma_Hz : array_like, shape (m,)
        Measured frequencies and their deviations, Hz.
    computed_Hz : array_like, shape (n,)
        Computed elastic frequencies, ascending, Hz; ``n`` should exceed ``m`` by the number
        of modes that may have been missed.
    computed_sd_Hz : array_like, shape (n,), optional
        Predictive deviations of the computed frequencies (:func:`predictive_sd_Hz`); zero
        when None.
    p_unobserved, p_spurious : float or array_like
        Prior probabilities in (0, 1): of each computed mode (n,) going unobserved and of
        each peak (m,) being spurious, or one for all.
        Prior probabilities, in (0, 1).

    Returns
    -------
    Assignment
    """
    log_pair, in_band, band = _log_pair(
        measured_Hz, sigma_Hz, computed_Hz, computed_sd_Hz, p_unobserved, p_spurious
    )
    return _solve(log_pair, p_spurious, in_band, band, p_unobserved)


def assign_with_shapes(
    measured_Hz,
    sigma_Hz,
    computed_Hz,
    computed_sd_Hz,
    mac,
    threshold=0.0,
    mac_scale=MAC_SCALE,
    p_unobserved=P_UNOBSERVED,
    p_spurious=P_SPURIOUS,
    dof=SHAPE_DOF,
):
    """The most probable assignment by frequency and mode shape together.

    Maximises the module's combined ``log P(a)``: each pair scores its frequency residual
    (Student-t, `dof`) and ``-log s_MAC - (1 - MAC_ij) / s_MAC``, a spurious peak
    ``log p_s - log B`` (its shape, unrelated to every mode, has MAC density 1); pairs with
    ``MAC_ij < threshold`` are not allowed (the peak is then paired elsewhere or spurious).

    Parameters
    ----------
    measured_Hz, sigma_Hz : array_like, shape (m,)
        Measured frequencies and their deviations, Hz.
    computed_Hz, computed_sd_Hz : array_like, shape (n,)
        Computed elastic frequencies and their predictive deviations
        (:func:`predictive_sd_Hz`), Hz.
    mac : array_like, shape (m, n)
        MAC of each measured shape against each computed mode, in [0, 1].
    threshold : float
        Smallest MAC of an allowed pair.
    mac_scale : float
        ``s_MAC`` > 0.
    p_unobserved, p_spurious : float or array_like
        Prior probabilities in (0, 1): of each computed mode (n,) going unobserved and of
        each peak (m,) being spurious, or one for all.
        Prior probabilities, in (0, 1).
    dof : float
        Degrees of freedom of the frequency residual's Student-t, > 0.

    Returns
    -------
    Assignment
        ``modes[i] = -1`` where peak ``i`` is spurious (or matches no mode by shape).
    """
    if not (mac_scale > 0.0 and dof > 0.0):
        raise ValueError(f"mac_scale = {mac_scale}, dof = {dof}: must be positive")
    log_pair, in_band, band = _log_pair(
        measured_Hz, sigma_Hz, computed_Hz, computed_sd_Hz, p_unobserved, p_spurious, dof
    )
    mac = np.asarray(mac, dtype=float)
    if mac.shape != log_pair.shape:
        raise ValueError(f"mac has shape {mac.shape}: needs {log_pair.shape} (peaks, modes)")
    log_pair = log_pair - np.log(mac_scale) - (1.0 - mac) / mac_scale
    log_pair[mac < threshold] = -_FORBIDDEN
    return _solve(log_pair, p_spurious, in_band, band, p_unobserved)


def _log_pair(f, s, c, t, p_unobserved, p_spurious, dof=None):
    """Log-probability of each pair (peak, mode), shape (m, n); in-band modes; ``B``, Hz.

    The residual is Gaussian, or Student-t with `dof` degrees of freedom when given.
    """
    f = np.asarray(f, dtype=float)
    s = np.asarray(s, dtype=float)
    c = np.asarray(c, dtype=float)
    t = np.zeros_like(c) if t is None else np.asarray(t, dtype=float)
    p_unobserved, p_spurious = _priors(p_unobserved, p_spurious, f.size, c.size)
    band = spurious_band_Hz(f, s)
    in_band = c <= np.max(f)
    var = s[:, None] ** 2 + t[None, :] ** 2
    if dof is None:
        log_pair = -0.5 * ((f[:, None] - c[None, :]) ** 2 / var + np.log(2 * np.pi * var))
    else:
        log_pair = student_t.logpdf(f[:, None] - c[None, :], dof, scale=np.sqrt(var))
    log_pair += (
        np.log1p(-p_spurious)[:, None]
        + np.where(in_band, np.log1p(-p_unobserved) - np.log(p_unobserved), 0.0)[None, :]
    )
    return log_pair, in_band, band


def _priors(p_unobserved, p_spurious, m, n):
    """``p_u`` (n,) and ``p_s`` (m,) as arrays, each checked to lie in (0, 1)."""
    out = []
    for name, p, size in (("p_unobserved", p_unobserved, n), ("p_spurious", p_spurious, m)):
        array = np.broadcast_to(np.asarray(p, dtype=float), (size,))
        if not np.all((array > 0.0) & (array < 1.0)):
            raise ValueError(f"{name} = {p}: must lie strictly between 0 and 1")
        out.append(array)
    return out


def _solve(log_pair, p_spurious, in_band, band, p_unobserved):
    """The assignment maximising the summed pair and spurious scores (Hungarian)."""
    p_unobserved, p_spurious = _priors(p_unobserved, p_spurious, *log_pair.shape)
    modes, total = best_assignment(log_pair, np.log(p_spurious) - np.log(band))
    log_p = total + np.sum(np.log(p_unobserved[in_band]))
    unobserved = np.setdiff1d(np.flatnonzero(in_band), modes[modes >= 0])
    return Assignment(modes, unobserved, float(log_p), band)


def best_assignment(score, spurious):
    """One-to-one pairs and spurious peaks maximising the summed scores (Hungarian method).

    A linear assignment problem on an ``m x (n + m)`` cost matrix: the ``n`` computed modes,
    then one "spurious" column per peak, open to that peak alone.

    Parameters
    ----------
    score : numpy.ndarray, shape (m, n)
        Score of pairing peak ``i`` with computed mode ``j`` (log-probability, nats); scores
        below ``-1e12`` count as ``-1e12`` (a pair excluded outright).
    spurious : float or numpy.ndarray, shape (m,)
        Score of each peak left spurious.

    Returns
    -------
    modes : numpy.ndarray of int, shape (m,)
        0-based computed mode of each peak; -1 spurious.
    total : float
        The maximal summed score.
    """
    m, n = score.shape
    cost = np.full((m, n + m), _FORBIDDEN)
    cost[:, :n] = np.minimum(-score, _FORBIDDEN)
    cost[np.arange(m), n + np.arange(m)] = -np.asarray(spurious, dtype=float)
    rows, cols = linear_sum_assignment(cost)
    modes = np.full(m, -1)
    paired = cols < n
    modes[rows[paired]] = cols[paired]
    return modes, float(-cost[rows, cols].sum())


def spurious_band_Hz(frequency_Hz, sigma_Hz):
    """``B``: the upper end of the range a spurious peak may lie in, Hz.

    The highest of ``f_i + 3 s_i`` over the measured peaks (:data:`_BAND_SIGMAS`).
    """
    f = np.asarray(frequency_Hz, dtype=float)
    return float(np.max(f + _BAND_SIGMAS * np.asarray(sigma_Hz, dtype=float)))


def _log_evidence(modes, Y, V_Y, g, S, shift, V_b, in_band, p_unobserved, p_spurious, log_B):
    """``log P(a)`` with the constants integrated out (linearised), for paired `modes`."""
    paired = np.flatnonzero(modes >= 0)
    j = modes[paired]
    r = Y[paired] - g[j] - shift[j]
    C = S[j] @ V_b @ S[j].T + V_Y[np.ix_(paired, paired)]
    L = np.linalg.cholesky(C)
    z = np.linalg.solve(L, r)
    log_n = -0.5 * (z @ z) - np.sum(np.log(np.diag(L))) - 0.5 * paired.size * np.log(2 * np.pi)
    return float(log_n + assignment_terms(modes, in_band, log_B, p_unobserved, p_spurious))


def assignment_terms(modes, in_band, log_B, p_unobserved=P_UNOBSERVED, p_spurious=P_SPURIOUS):
    """The terms of ``log P(a)`` that are the assignment's own, the pairs' densities apart.

    ``n_paired log(1 - p_s) + n_spurious (log p_s - log B)`` and, over the computed modes in
    the band, ``log(1 - p_u)`` for each one observed and ``log p_u`` for each one not.

    Parameters
    ----------
    modes : numpy.ndarray of int, shape (m,)
        0-based computed mode of each peak; -1 spurious.
    in_band : numpy.ndarray of bool, shape (n,)
        Which computed modes lie in the band (up to the highest peak).
    log_B : float
        ``log`` of the range a spurious peak is uniform over, in the units of the pairs'
        densities (Hz, or rad^2/s^2 for densities in eigenvalues).
    p_unobserved, p_spurious : float or array_like
        Prior probabilities in (0, 1): of each computed mode (n,) going unobserved and of
        each peak (m,) being spurious, or one for all.

    Returns
    -------
    float
    """
    modes = np.asarray(modes)
    in_band = np.asarray(in_band, dtype=bool)
    p_unobserved, p_spurious = _priors(p_unobserved, p_spurious, modes.size, in_band.size)
    paired = modes >= 0
    seen = np.zeros(in_band.size, dtype=bool)
    seen[modes[paired]] = True
    return float(
        np.sum(np.log1p(-p_spurious[paired]))
        + np.sum(np.log(p_spurious[~paired]) - log_B)
        + np.sum(np.log1p(-p_unobserved[in_band & seen]))
        + np.sum(np.log(p_unobserved[in_band & ~seen]))
    )


def _neighbours(modes, n):
    """Order-preserving assignments one move away from `modes`.

    A gap opens or closes before a peak; a peak turns spurious (the ones above moving down
    a mode, or not) or back.
    """
    m = modes.size
    out = []
    for k in range(m):
        above = np.arange(k, m)
        for step in (1, -1):
            new = modes.copy()
            paired = above[new[above] >= 0]
            new[paired] += step
            out.append(new)
        new = modes.copy()
        if new[k] >= 0:
            new[k] = -1
            out.append(new.copy())
            rest = above[1:][new[above[1:]] >= 0]
            new[rest] -= 1
            out.append(new)
        else:
            below = modes[:k][modes[:k] >= 0]
            new[k] = below[-1] + 1 if below.size else 0
            out.append(new.copy())
            rest = above[1:][new[above[1:]] >= 0]
            new[rest] += 1
            out.append(new)
    return [a for a in out if _valid(a, n)]


def _valid(modes, n):
    paired = modes[modes >= 0]
    return paired.size > 0 and paired.max() < n and bool(np.all(np.diff(paired) > 0))


def most_probable(
    measured_Hz,
    sigma_Hz,
    eigenvalues,
    sensitivities,
    b,
    prior_mean_b,
    prior_covariance_b,
    p_unobserved=P_UNOBSERVED,
    p_spurious=P_SPURIOUS,
    start=None,
):
    """The assignment that best explains the peaks, the constants integrated out.

    The computed eigenvalues are linearised at `b`, ``lambda(b') = g + S (b' - b)``, and
    ``b'`` has the prior ``N(mu, V_b)``, so that the paired measured eigenvalues are jointly
    Gaussian, ``N(g + S (mu - b), S V_b S^T + V_Y)``: unlike :func:`assign`, the
    frequencies' errors are correlated (six constants move all of them together), which is
    what tells a shifted pairing from the right one when the prior is far off. The
    probability (the module's, with this marginal in place of the independent Gaussians,
    in eigenvalues) is maximised by local search over order-preserving assignments from
    pairing by order and from :func:`assign`'s answer.

    Parameters
    ----------
    measured_Hz, sigma_Hz : array_like, shape (m,)
        Hz.
    eigenvalues : array_like, shape (n,)
        Computed elastic eigenvalues at `b`, ascending, rad^2/s^2; ``n > m`` leaves room
        for missed modes.
    sensitivities : array_like, shape (n, 6)
        ``d lambda / d b`` at `b`.
    b, prior_mean_b : array_like, shape (6,)
        Linearisation point and prior mean of the stiffness coefficients, Pa.
    prior_covariance_b : array_like, shape (6, 6)
        Pa^2.
    p_unobserved, p_spurious : float or array_like
        Prior probabilities in (0, 1): of each computed mode (n,) going unobserved and of
        each peak (m,) being spurious, or one for all.
    start : array_like of int, shape (m,), optional
        An assignment to search from as well (e.g. the one in use).

    Returns
    -------
    Assignment
        ``log_probability`` is the marginal one.
    """
    f = np.asarray(measured_Hz, dtype=float)
    s = np.asarray(sigma_Hz, dtype=float)
    g = np.asarray(eigenvalues, dtype=float)
    S = np.asarray(sensitivities, dtype=float)
    V_b = np.asarray(prior_covariance_b, dtype=float)
    Y = eigenvalue_from_hz(f)
    V_Y = np.diag(eigenvalue_sd(f, s) ** 2)
    shift = S @ (np.asarray(prior_mean_b, dtype=float) - np.asarray(b, dtype=float))
    band = spurious_band_Hz(f, s)
    log_B = np.log(eigenvalue_from_hz(band))
    in_band = g <= eigenvalue_from_hz(np.max(f))
    m, n = f.size, g.size

    def score(modes):
        args = (Y, V_Y, g, S, shift, V_b, in_band, p_unobserved, p_spurious, log_B)
        return _log_evidence(modes, *args)

    computed_Hz = hz_from_eigenvalue(g)
    spread = predictive_sd_Hz(computed_Hz, S, V_b)
    starts = [np.arange(m), assign(f, s, computed_Hz, spread, p_unobserved, p_spurious).modes]
    if start is not None:
        starts.append(np.asarray(start, dtype=int))
    best, best_score = None, -np.inf
    for modes in starts:
        if not _valid(modes, n):
            continue
        current = score(modes)
        while True:
            moves = [(score(a), tuple(a)) for a in _neighbours(modes, n)]
            top, key = max(moves) if moves else (-np.inf, None)
            if top <= current + 1e-9:
                break
            modes, current = np.array(key), top
        if current > best_score:
            best, best_score = modes, current
    unobserved = np.setdiff1d(np.flatnonzero(in_band), best[best >= 0])
    p_u = np.broadcast_to(np.asarray(p_unobserved, dtype=float), (n,)).copy()
    return Assignment(best, unobserved, best_score, band, p_u)
