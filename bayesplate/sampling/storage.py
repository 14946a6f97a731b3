"""Where a chain is kept: emcee's HDF layout, written whole at every check, and resumed.

The chain runs in memory (an emcee ``Backend``); at the end of tuning and after every block
of steps between two checks of the stopping rule, :func:`commit` writes it to the HDF file
whole or not at all (a temporary file, then a rename), in emcee's ``HDFBackend`` layout
(readable by ``emcee.backends.HDFBackend(path, read_only=True)``). A run killed at any moment
(Ctrl-C or SIGKILL) leaves the last committed chain intact; run again with the same seed, it
continues from that check with the stored random state and ends with the same numbers as a
run never interrupted (the checks fall on the same steps). Writing in place, step by step,
as ``HDFBackend`` does, leaves a file torn between two steps when the process is killed.

Besides emcee's datasets, the file records the whitening (centre and Cholesky factor), a
fingerprint of the problem (data, prior, pairing) and, after tuning, the frozen proposal and
the step it was frozen at. :func:`open_backend` resumes a chain of the same problem and
refuses another's; a file from before the end of tuning is started afresh.
"""

from __future__ import annotations

import os
import pathlib
import tempfile

import emcee
import numpy as np

__all__ = ["commit", "open_backend", "restore_tuning", "store_tuning"]

_ATTRS = ("bayesplate_center", "bayesplate_chol", "bayesplate_fingerprint")
_GROUP = "mcmc"  # emcee's HDFBackend default name


class _Stored(emcee.backends.Backend):
    """emcee's in-memory backend that :func:`commit` writes to ``path`` whole."""

    def __init__(self, path):
        super().__init__()
        self.path = pathlib.Path(path)
        self.attrs = {}  # the bayesplate_* attributes


def _fingerprint(problem):
    """Numbers identifying a problem: its data, prior and pairing."""
    parts = [problem.Y, np.diag(problem.V_Y), problem.mu_b, problem.V_b.ravel()]
    scale = getattr(problem, "error_scale", None)
    if scale is not None:  # another target: a chain kept without it does not continue
        parts.append(np.array([scale.shape, scale.scale]))
    return np.concatenate([*parts, problem.pairing.modes.astype(float)])


def _read(path, backend):
    """Fill ``backend`` from an HDF chain file; its ``bayesplate_*`` attributes, or None.

    None when the file holds no steps; an unreadable file raises ``ValueError``.
    """
    import h5py  # as emcee's HDFBackend: needed only for a chain kept in a file

    try:
        with h5py.File(path, "r") as f:
            if _GROUP not in f or int(f[_GROUP].attrs.get("iteration", 0)) == 0:
                return None
            g = f[_GROUP]
            n = int(g.attrs["iteration"])
            backend.reset(int(g.attrs["nwalkers"]), int(g.attrs["ndim"]))
            backend.chain = np.asarray(g["chain"][:n])
            backend.log_prob = np.asarray(g["log_prob"][:n])
            backend.accepted = np.asarray(g["accepted"][...])
            if bool(g.attrs.get("has_blobs", False)):
                blobs = np.asarray(g["blobs"][:n])
                dt = np.dtype((blobs.dtype.base, blobs.shape[2:]))
                backend.blobs = np.empty(blobs.shape[:2], dtype=dt)
                backend.blobs[...] = blobs
            keys = sorted(k for k in g.attrs if k.startswith("random_state_"))
            backend.random_state = tuple(g.attrs[k] for k in keys) or None
            backend.iteration = n
            return {k: np.asarray(g.attrs[k]) for k in g.attrs if k.startswith("bayesplate_")}
    except (OSError, KeyError) as err:
        raise ValueError(f"{path}: not a readable chain file ({err})") from err


def commit(backend):
    """Write an in-memory chain to its HDF file whole (nothing for a chain kept nowhere)."""
    if not isinstance(backend, _Stored) or not backend.initialized:
        return
    import h5py

    path, n = backend.path, backend.iteration
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            g = f.create_group(_GROUP)
            g.attrs["version"] = emcee.__version__
            g.attrs["nwalkers"], g.attrs["ndim"] = backend.shape
            g.attrs["has_blobs"] = backend.blobs is not None
            g.attrs["iteration"] = n
            g.create_dataset("accepted", data=backend.accepted)
            nw, nd = backend.shape
            g.create_dataset("chain", data=backend.chain[:n], maxshape=(None, nw, nd))
            g.create_dataset("log_prob", data=backend.log_prob[:n], maxshape=(None, nw))
            if backend.blobs is not None:
                blobs = backend.blobs[:n]
                g.create_dataset("blobs", data=blobs, maxshape=(None, nw, *blobs.shape[2:]))
            for i, value in enumerate(backend.random_state or ()):
                g.attrs[f"random_state_{i}"] = value
            for key, value in backend.attrs.items():
                g.attrs[key] = value
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        pathlib.Path(tmp).unlink(missing_ok=True)
        raise


def _remove_stale(path):
    """Remove what a killed :func:`commit` left: ``.NAME.*.tmp`` beside the chain file."""
    for stale in path.parent.glob(f".{path.name}.*.tmp"):
        stale.unlink(missing_ok=True)


def open_backend(path, density, n_walkers):
    """An emcee backend and, for an HDF file that holds a chain, its stored settings.

    A chain of the same problem is resumed (its whitening replaces ``density``'s);
    another problem's is refused; one stored before the end of tuning is started afresh.

    Parameters
    ----------
    path : path or None
        HDF5 file; None for a backend in memory only.
    density : WhitenedLogPosterior
        The sampler's density (its problem identifies the chain).
    n_walkers : int

    Returns
    -------
    backend : emcee.backends.Backend
        In memory; :func:`commit` writes it to ``path``.
    stored : dict or None
        The ``bayesplate_*`` attributes of a chain to resume, None for a new chain.
    """
    if path is None:
        return emcee.backends.Backend(), None
    backend = _Stored(path)
    _remove_stale(backend.path)
    fingerprint = _fingerprint(density.problem)
    assigned = density.assigned
    if assigned is not None:  # another target: all the peaks, the assignment re-made
        fingerprint = np.concatenate([fingerprint, assigned.Y, [assigned.n]])
    stored = _read(path, backend) if pathlib.Path(path).exists() else None
    if stored is not None:
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
    if stored is not None and "bayesplate_tuned_at" in stored:
        density.center = stored["bayesplate_center"]
        density.chol = stored["bayesplate_chol"]
        backend.attrs = dict(stored)
        return backend, stored
    # a new chain, or one stopped during tuning (whose proposal was not kept): afresh
    backend.reset(n_walkers, 6)
    _store(backend, center=density.center, chol=density.chol, fingerprint=fingerprint)
    return backend, None


def _store(backend, **values):
    """Set ``bayesplate_*`` attributes of a stored chain (nothing for one kept nowhere)."""
    if isinstance(backend, _Stored):
        backend.attrs.update({f"bayesplate_{key}": value for key, value in values.items()})


def store_tuning(backend, move, n_tune):
    """Record the frozen proposal and the end of tuning, and commit the chain."""
    if move is None or move.mean is None:
        _store(backend, tuned_at=n_tune)
    else:
        _store(backend, tuned_at=n_tune, proposal_mean=move.mean, proposal_chol=move.chol)
    commit(backend)


def restore_tuning(stored, move):
    """The end of tuning of a resumed chain (its proposal set on ``move``), or None."""
    if stored is None or "bayesplate_tuned_at" not in stored:
        return None
    if move is not None and "bayesplate_proposal_mean" in stored:
        move.mean = stored["bayesplate_proposal_mean"]
        move.chol = stored["bayesplate_proposal_chol"]
    return int(stored["bayesplate_tuned_at"])
