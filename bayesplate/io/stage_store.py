"""Diagnose's stages on disk: one file per key, written whole or not at all.

:class:`DirectoryStore` is the on-disk form of the store :func:`bayesplate.discrepancy.
diagnose.diagnose` takes (``get(key)`` / ``put(key, value)``, :mod:`bayesplate.discrepancy.
store`). Each value is a pickle in ``DIR/<key>.pkl`` together with its key, written to a
temporary file and renamed (:func:`.export.atomic_write`), so a run killed while writing
leaves the previous state. A file that cannot be read, or that holds another key or
something this module did not write, is ignored (and recomputed and overwritten by the run).

Pickles run code when loaded: keep the folder as private as the case files it came from
(the command line's default is a hidden folder of the user's own working directory).
"""

from __future__ import annotations

import logging
import pathlib
import pickle

from .export import atomic_write

__all__ = ["DirectoryStore"]

log = logging.getLogger(__name__)

_FORMAT = "bayesplate diagnose stage 1"


class DirectoryStore:
    """Stored values in a folder, one ``<key>.pkl`` file each.

    Parameters
    ----------
    directory : path
        Created on the first ``put``.

    Attributes
    ----------
    hits, misses, ignored, puts : int
        Values found, keys not found, unreadable or foreign files passed over, values
        written (in this process: a forked worker counts its own).
    """

    def __init__(self, directory):
        self.directory = pathlib.Path(directory)
        self.hits = self.misses = self.ignored = self.puts = 0

    def path(self, key):
        """The file of `key` (a hexadecimal digest)."""
        key = str(key)
        if not key or not key.isalnum():
            raise ValueError(f"store key {key!r}: must be letters and digits (a digest)")
        return self.directory / f"{key}.pkl"

    def get(self, key):
        """The value stored under `key`, or None (absent, unreadable or foreign)."""
        path = self.path(key)
        try:
            blob = path.read_bytes()
        except FileNotFoundError:
            self.misses += 1
            return None
        except OSError as err:
            return self._ignore(path, err)
        try:
            stored = pickle.loads(blob)
        except Exception as err:  # truncated, corrupt, or from an incompatible version
            return self._ignore(path, err)
        if not (
            isinstance(stored, dict)
            and stored.get("format") == _FORMAT
            and stored.get("key") == key
        ):
            return self._ignore(path, "not a stage of this key")
        self.hits += 1
        return stored["value"]

    def put(self, key, value):
        """Write `value` under `key` (atomically; it replaces any file of that key).

        A folder that cannot be written is logged and passed over: the diagnosis goes on.
        """
        blob = pickle.dumps(
            {"format": _FORMAT, "key": str(key), "value": value}, protocol=pickle.HIGHEST_PROTOCOL
        )
        try:
            atomic_write(self.path(key), lambda handle: handle.write(blob), "wb")
        except OSError as err:  # a full disk or a read-only folder costs the resume only
            log.warning("stage not stored in %s (%s): a run again computes it", self.directory, err)
            return
        self.puts += 1

    def _ignore(self, path, why):
        log.warning("stored stage %s ignored (%s): computing it again", path.name, why)
        self.ignored += 1
        return None
