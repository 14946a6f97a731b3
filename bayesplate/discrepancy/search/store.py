"""Where diagnose keeps its finished stages, so that a run killed half-way can resume.

The store is an interface in the style of emcee's backends: :func:`..diagnose.diagnose`
takes any object with ``get(key)`` (the value stored under ``key``, or None) and
``put(key, value)`` (``value``: plain picklable data), and never touches a disk itself.
:class:`MemoryStore` is a dict; the on-disk one is the edge's
(:class:`bayesplate.io.stage_store.DirectoryStore`).

Each expensive, independent stage (the nominal fit, each candidate's joint fit, the nominal
refits from the candidates' constants, each pair of effects) is looked up under a key that
covers everything it depends on (:func:`digest`): the measured eigenvalues, their deviations
and the pairing, the plate and its mesh, the prior, the options, the random generator's
state, the package version, the candidate and its variant, and the stages it builds on (by
the digest of their results). A stage found is not computed; one computed is stored at
once. A stage that draws random numbers stores the generator's state after it, and a hit
restores it, so the stream after it is the same either way and a resumed run gives the
same numbers bit for bit.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import os
import pickle
import struct
import types

import numpy as np

from ... import __version__

__all__ = ["MemoryStore", "Stages", "digest", "fit_digest", "plate_digest"]


class MemoryStore:
    """A store in a dict (for tests and for several diagnoses in one process).

    Attributes
    ----------
    data : dict
        ``{key: value}``.
    hits, puts : int
        Values found and values stored. A forked worker's ``put`` (``workers > 1``) is
        not seen here; :func:`.rank.rank` puts its results again from the parent.
    """

    def __init__(self):
        self.data, self.hits, self.puts = {}, 0, 0

    def get(self, key):
        """The value stored under `key`, or None."""
        value = self.data.get(key)
        self.hits += value is not None
        return value

    def put(self, key, value):
        """Store `value` under `key`."""
        self.data[key] = value
        self.puts += 1


_TOKENS = itertools.count()


def _unique():
    """A token never given twice (not even after an object's id is reused): never a hit."""
    return f"{os.getpid()}:{next(_TOKENS)}:{os.urandom(8).hex()}"


def _feed(h, obj, depth=0):
    """Feed a canonical encoding of `obj` to the hash `h` (type-tagged, recursive)."""
    if depth > 20:  # (a cycle): a key never made again, so never a wrong hit
        h.update(f"deep:{_unique()};".encode())
        return
    if obj is None or isinstance(obj, (bool, str, bytes)):
        h.update(f"{type(obj).__name__}:{len(repr(obj))}:{obj!r};".encode())
    elif isinstance(obj, (int, np.integer)):
        h.update(f"int:{int(obj)};".encode())
    elif isinstance(obj, (float, np.floating)):
        h.update(b"float:" + struct.pack("<d", float(obj)))  # exact bits, not a rounding
    elif isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"array:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes() if a.dtype != object else repr(a.tolist()).encode())
    elif isinstance(obj, (list, tuple)):
        h.update(f"{type(obj).__name__}:{len(obj)}[".encode())
        for item in obj:
            _feed(h, item, depth + 1)
        h.update(b"]")
    elif isinstance(obj, dict):
        h.update(f"dict:{len(obj)}{{".encode())
        for key in sorted(obj, key=repr):
            _feed(h, key, depth + 1)
            _feed(h, obj[key], depth + 1)
        h.update(b"}")
    elif isinstance(obj, (types.FunctionType, types.MethodType, types.BuiltinFunctionType)):
        name = f"{getattr(obj, '__module__', '')}.{obj.__qualname__}"
        local = "<" in name or isinstance(obj, types.MethodType)  # a closure, a bound method
        h.update((f"call:{_unique()};" if local else f"call:{name};").encode())
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"{type(obj).__module__}.{type(obj).__qualname__}(".encode())
        _feed(h, {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}, depth + 1)
        h.update(b")")
    elif hasattr(obj, "__dict__") and not isinstance(obj, type):
        h.update(f"{type(obj).__module__}.{type(obj).__qualname__}(".encode())
        _feed(h, dict(vars(obj)), depth + 1)
        h.update(b")")
    else:  # by its pickle; unpicklable: a key never made again, so never a wrong hit
        try:
            h.update(f"{type(obj).__qualname__}:".encode() + pickle.dumps(obj, protocol=4))
        except Exception:  # noqa: BLE001 - any failure to pickle means the same here
            h.update(f"opaque:{_unique()};".encode())


#: The layout of what the stages store; a change of it (a field added to a fit) is a change
#: of every key, so that stages stored by older code are never taken.
FORMAT = 2


def digest(*parts):
    """SHA-256 (hex) of the content of `parts`, with the package version and :data:`FORMAT`.

    Numbers enter by their exact bits (a float differing in the last bit is another key);
    arrays by dtype, shape and bytes; containers in order (dicts by sorted key); other
    objects by their class and attributes (a candidate physics and its variant), or their
    pickle. What has no stable content (a closure, an unpicklable object) makes a key that
    is never made again: such a stage is computed every time, never wrongly found.
    """
    h = hashlib.sha256(f"bayesplate {__version__} stages {FORMAT};".encode())
    _feed(h, parts)
    return h.hexdigest()


def fit_digest(fit):
    """The part of a :class:`.laplace.JointFit` later stages build on (its optimum and value)."""
    return digest(
        fit.b,
        fit.theta,
        fit.chi2,
        fit.chi2_prior,
        fit.log_evidence,
        fit.refined,
        [(b, v) for b, v in fit.alternatives],
    )


def plate_digest(model):
    """The plate a :class:`~bayesplate.plate.model.PlateModel` stands for: geometry, layup, mesh."""
    mesh = model.mesh
    return digest(
        type(model).__qualname__,
        mesh.a,
        mesh.b,
        mesh.nx,
        mesh.ny,
        model.thickness,
        model.density,
        model.layup_deg,
        model.ply_thickness,
        getattr(model, "boundary", None),
        getattr(getattr(model, "element", None), "shear_order", None),
    )


class Stages:
    """Diagnose's view of a store: keys chained from one context, hits announced.

    Parameters
    ----------
    store : object with get and put, or None
        None computes every stage (nothing is kept).
    context : str
        Digest of what every stage depends on (:func:`digest`).
    say : callable
        ``say(message)``: a stage taken from the store is announced.
    """

    def __init__(self, store, context, say):
        self.store, self.context, self.say = store, context, say
        self._hits = [0]  # shared with the stages made by :meth:`then`

    @property
    def hits(self):
        """Stages taken from the store in this process (a forked worker's are not seen)."""
        return self._hits[0]

    def key(self, stage, *parts):
        """The key of `stage` with its own `parts` in this context."""
        return digest(self.context, stage, *parts)

    def then(self, *parts):
        """The same store in a context that also covers `parts` (an earlier stage's result)."""
        other = Stages(self.store, digest(self.context, *parts), self.say)
        other._hits = self._hits
        return other

    def get(self, key):
        """``(True, value)`` when `key` is stored, else ``(False, None)``."""
        if self.store is None:
            return False, None
        stored = self.store.get(key)
        if not isinstance(stored, tuple) or len(stored) != 2 or stored[0] != "stage":
            return False, None  # absent, or not something this module stored
        self._hits[0] += 1
        return True, stored[1]

    def put(self, key, value):
        """Store `value` (None included) under `key`."""
        if self.store is not None:
            self.store.put(key, ("stage", value))

    def run(self, label, key, compute):
        """The value stored under `key`, or ``compute()`` stored at once."""
        found, value = self.get(key)
        if found:
            self.say(f"{label}: taken from the store")
            return value
        value = compute()
        self.put(key, value)
        return value
