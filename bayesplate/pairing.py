"""Which computed mode goes with which measured one.

The paper pairs the i-th measured frequency with the i-th computed elastic mode (by order).
A case file may instead name the 1-based elastic mode of each measured frequency
(``measured.mode``). While an estimator iterates, the computed modes can change order
(two close frequencies cross); :func:`track` follows them from one iterate to the next by the
modal assurance criterion (MAC) of successive eigenvectors.

All functions are pure; :class:`Pairing` is a small immutable record. Mode numbers are
0-based computed elastic modes throughout the code (1-based only in case files and output).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = [
    "DEFAULT_EXTRA_MODES",
    "Pairing",
    "mac_matrix",
    "pair_by_order",
    "pair_by_index",
    "assign_by_mac",
    "track",
]

#: Computed modes beyond the highest paired one, so that a tracked mode can move up.
DEFAULT_EXTRA_MODES = 2


def mac_matrix(A, B, weight=None):
    """Modal assurance criterion between two sets of vectors.

    ``MAC_ij = (a_i^T W b_j)^2 / ((a_i^T W a_i) (b_j^T W b_j))``.

    Parameters
    ----------
    A : array_like, shape (n, p)
        One vector per column.
    B : array_like, shape (n, q)
    weight : array_like or sparse matrix, shape (n, n), optional
        ``W``, e.g. the mass matrix; identity when None.

    Returns
    -------
    numpy.ndarray, shape (p, q)
        Entries in [0, 1].
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    WB = B if weight is None else weight @ B
    WA = A if weight is None else weight @ A
    cross = A.T @ WB
    na = np.einsum("ij,ij->j", A, WA)
    nb = np.einsum("ij,ij->j", B, WB)
    return cross**2 / np.outer(na, nb)


def pair_by_order(m):
    """Measured frequency i goes with computed elastic mode i: ``arange(m)``."""
    return np.arange(int(m))


def pair_by_index(mode):
    """0-based computed modes from the case file's 1-based ``measured.mode`` indices."""
    mode = np.asarray(mode, dtype=int)
    if mode.ndim != 1 or np.any(mode < 1):
        raise ValueError(f"mode = {mode}: must be 1-based elastic mode numbers")
    return mode - 1


def assign_by_mac(mac, threshold=0.0):
    """One-to-one assignment of rows to columns maximising the total MAC (Hungarian).

    Parameters
    ----------
    mac : array_like, shape (p, q)
        E.g. measured shapes (rows) against computed modes (columns).
    threshold : float
        Pairs with a MAC below this are left unassigned.

    Returns
    -------
    numpy.ndarray of int, shape (p,)
        Column assigned to each row, -1 where none reaches `threshold` (or p > q).
    """
    mac = np.asarray(mac, dtype=float)
    rows, cols = linear_sum_assignment(mac, maximize=True)
    out = np.full(mac.shape[0], -1)
    keep = mac[rows, cols] >= threshold
    out[rows[keep]] = cols[keep]
    return out


def track(prev_vectors, vectors, modes, weight=None):
    """Follow paired modes from one iterate to the next by MAC.

    Parameters
    ----------
    prev_vectors : array_like, shape (n, q0)
        Eigenvectors at the previous iterate (all computed modes).
    vectors : array_like, shape (n, q)
        Eigenvectors at the current iterate.
    modes : array_like of int, shape (m,)
        0-based previous mode of each measured frequency.
    weight : array_like or sparse matrix, shape (n, n), optional
        MAC weight (the mass matrix); plain MAC when None.

    Returns
    -------
    new_modes : numpy.ndarray of int, shape (m,)
        Current mode most like each previously paired one (one-to-one).
    mac : numpy.ndarray, shape (m,)
        The MAC of each match.
    """
    modes = np.asarray(modes, dtype=int)
    mac = mac_matrix(np.asarray(prev_vectors)[:, modes], vectors, weight)
    new = assign_by_mac(mac)
    return new, mac[np.arange(len(modes)), new]


@dataclass(frozen=True)
class Pairing:
    """The computed mode of each measured frequency.

    Parameters
    ----------
    modes : array_like of int, shape (m,)
        0-based computed elastic mode of each measured frequency.
    how : str
        ``"order"`` or ``"index"``, for messages.
    extra : int
        Modes computed beyond the highest paired one (room for tracking).
    """

    modes: np.ndarray
    how: str = "order"
    extra: int = DEFAULT_EXTRA_MODES

    def __post_init__(self):
        modes = np.array(self.modes, dtype=int)
        modes.setflags(write=False)
        object.__setattr__(self, "modes", modes)

    @classmethod
    def from_measurement(cls, measured, how="auto", extra=DEFAULT_EXTRA_MODES):
        """Pairing of a :class:`bayesplate.case.Measurement`.

        Parameters
        ----------
        measured : Measurement
        how : {"auto", "order", "index"}
            ``"auto"`` uses the case's mode indices when it has them, else the order.
        extra : int

        Returns
        -------
        Pairing
        """
        if how not in ("auto", "order", "index"):
            raise ValueError(f"pairing = {how!r}: must be 'auto', 'order' or 'index'")
        if how == "auto":
            how = "order" if measured.mode is None else "index"
        if how == "index":
            if measured.mode is None:
                raise ValueError("pairing = 'index' needs measured.mode in the case file")
            return cls(pair_by_index(measured.mode), "index", extra)
        return cls(pair_by_order(measured.size), "order", extra)

    def n_modes(self, modes=None):
        """Computed modes needed for `modes` (default the pairing's own), with the extra."""
        modes = self.modes if modes is None else np.asarray(modes)
        return int(np.max(modes)) + 1 + self.extra
