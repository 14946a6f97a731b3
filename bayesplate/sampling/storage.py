"""Where a chain is kept: emcee's backend, with what resuming it needs in an HDF file.

A new HDF chain records the whitening (centre and Cholesky factor) and a fingerprint of the
problem (data, prior, pairing); after tuning, the frozen proposal and the step it was frozen
at. :func:`open_backend` resumes a chain of the same problem and refuses another's.
"""

from __future__ import annotations

import emcee
import numpy as np

__all__ = ["open_backend", "restore_tuning", "store_tuning"]

_ATTRS = ("bayesplate_center", "bayesplate_chol", "bayesplate_fingerprint")


def _fingerprint(problem):
    """Numbers identifying a problem: its data, prior and pairing."""
    parts = [problem.Y, np.diag(problem.V_Y), problem.mu_b, problem.V_b.ravel()]
    return np.concatenate([*parts, problem.pairing.modes.astype(float)])


def open_backend(path, density, n_walkers):
    """An emcee backend and, for an HDF file that holds a chain, its stored settings.

    A chain of the same problem is resumed (its whitening replaces ``density``'s);
    another problem's is refused.

    Parameters
    ----------
    path : path or None
        HDF5 file; None for a backend in memory.
    density : WhitenedLogPosterior
        The sampler's density (its problem identifies the chain).
    n_walkers : int

    Returns
    -------
    backend : emcee.backends.Backend
    stored : dict or None
        The ``bayesplate_*`` attributes of a chain to resume, None for a new chain.
    """
    if path is None:
        return emcee.backends.Backend(), None
    backend = emcee.backends.HDFBackend(str(path))
    fingerprint = _fingerprint(density.problem)
    if backend.initialized and backend.iteration > 0:
        with backend.open() as f:
            attrs = f[backend.name].attrs
            stored = {k: np.asarray(attrs[k]) for k in attrs if k.startswith("bayesplate_")}
        if not all(k in stored for k in _ATTRS):
            raise ValueError(f"{path}: an emcee chain not written by bayesplate")
        same = stored["bayesplate_fingerprint"].shape == fingerprint.shape and np.allclose(
            stored["bayesplate_fingerprint"], fingerprint, rtol=1e-12, atol=0
        )
        if not same or backend.shape != (n_walkers, 6):
            raise ValueError(
                f"{path} holds a chain of another problem or ensemble size "
                f"{backend.shape[0]} walkers; use another file to start afresh"
            )
        density.center = stored["bayesplate_center"]
        density.chol = stored["bayesplate_chol"]
        return backend, stored
    backend.reset(n_walkers, 6)
    _store(backend, center=density.center, chol=density.chol, fingerprint=fingerprint)
    return backend, None


def _store(backend, **values):
    """Write ``bayesplate_*`` attributes to an HDF backend (nothing for one in memory)."""
    if not isinstance(backend, emcee.backends.HDFBackend):
        return
    with backend.open("a") as f:
        for key, value in values.items():
            f[backend.name].attrs[f"bayesplate_{key}"] = value


def store_tuning(backend, move, n_tune):
    """Record the frozen proposal and the end of tuning, for a resumed run."""
    if move is None or move.mean is None:
        _store(backend, tuned_at=n_tune)
    else:
        _store(backend, tuned_at=n_tune, proposal_mean=move.mean, proposal_chol=move.chol)


def restore_tuning(stored, move):
    """The end of tuning of a resumed chain (its proposal set on ``move``), or None."""
    if stored is None or "bayesplate_tuned_at" not in stored:
        return None
    if move is not None and "bayesplate_proposal_mean" in stored:
        move.mean = stored["bayesplate_proposal_mean"]
        move.chol = stored["bayesplate_proposal_chol"]
    return int(stored["bayesplate_tuned_at"])
