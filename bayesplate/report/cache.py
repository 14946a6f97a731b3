"""The report's step cache: results stored as ``.npz`` under a key of case, step and options.

A step's result is a dict of arrays and JSON-able values; it is stored as the arrays of an
``.npz`` file plus one JSON string, and always handed back in that (deserialised) form, so
that a report from reused results is the same as one from fresh results.
"""

from __future__ import annotations

import hashlib
import json
import logging
import pathlib

import numpy as np

from .. import __version__
from ..io import atomic_write, jsonable

__all__ = ["StepCache"]

log = logging.getLogger("bayesplate.report")


def _serialise(data):
    """Split a step result into its arrays (npz) and the rest (a JSON string)."""
    arrays = {k: v for k, v in data.items() if isinstance(v, np.ndarray)}
    rest = {k: v for k, v in data.items() if k not in arrays}
    return arrays, json.dumps(rest, default=jsonable, sort_keys=True)


def _deserialise(arrays, text):
    return {**json.loads(text), **{k: np.asarray(v) for k, v in arrays.items()}}


class StepCache:
    """Results of report steps in a folder, keyed by case, step, options and version.

    Parameters
    ----------
    directory : path or None
        Where the ``.npz`` files live (created when needed); None keeps nothing (every
        step is computed).
    case_bytes : bytes
        The case file's content.
    version : str
        The package version (a new version invalidates every result).

    Attributes
    ----------
    reused, computed : list of str
        Steps taken from the cache and steps computed, in order.
    """

    def __init__(self, directory, case_bytes, version=__version__):
        self.directory = None if directory is None else pathlib.Path(directory)
        self.case_digest = hashlib.sha256(case_bytes).hexdigest()
        self.version = version
        self.reused = []
        self.computed = []

    def key(self, step, options):
        """SHA-256 of (case content, step name, step options, package version)."""
        blob = json.dumps(
            {"case": self.case_digest, "step": step, "options": options, "version": self.version},
            sort_keys=True,
            default=jsonable,
        )
        return hashlib.sha256(blob.encode()).hexdigest()

    def _path(self, step):
        return self.directory / f"{step}.npz"

    def load(self, step, options):
        """The cached result of `step` with these options, or None."""
        if self.directory is None or not self._path(step).exists():
            return None
        try:
            with np.load(self._path(step), allow_pickle=False) as stored:
                if str(stored["__key__"]) != self.key(step, options):
                    return None
                arrays = {k: stored[k] for k in stored.files if not k.startswith("__")}
                return _deserialise(arrays, str(stored["__json__"]))
        except (OSError, KeyError, ValueError) as err:  # unreadable: compute afresh
            log.warning("cache file %s unreadable (%s): recomputing", self._path(step), err)
            return None

    def save(self, step, options, data):
        """Store `data` (a dict of arrays and JSON-able values); returns its stored form."""
        arrays, text = _serialise(data)
        if self.directory is not None:
            self.directory.mkdir(parents=True, exist_ok=True)
            stored = {
                **arrays,
                "__json__": np.array(text),
                "__key__": np.array(self.key(step, options)),
            }
            atomic_write(self._path(step), lambda handle: np.savez(handle, **stored), "wb")
        return _deserialise(arrays, text)

    def get(self, step, options, compute):
        """The cached result of `step`, or ``compute()`` stored; ``(data, reused)``."""
        data = self.load(step, options)
        if data is not None:
            self.reused.append(step)
            return data, True
        data = self.save(step, options, compute())
        self.computed.append(step)
        return data, False
