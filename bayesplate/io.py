"""Files at the edge of the package: every output is written whole or not at all."""

from __future__ import annotations

import json
import os
import pathlib
import sys
import tempfile

import numpy as np

__all__ = [
    "atomic_write",
    "atomic_write_text",
    "constants_json",
    "jsonable",
    "save_figure",
    "write_json",
]


def atomic_write(path, write, mode="w"):
    """Call ``write(handle)`` on a temporary file next to ``path``, then rename it to ``path``.

    A reader never sees a partial file, and an error leaves any previous file untouched.
    ``mode`` is ``"w"`` (text, UTF-8) or ``"wb"``.
    """
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode, encoding=None if "b" in mode else "utf-8") as handle:
            write(handle)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        pathlib.Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path, text):
    """Write ``text`` to ``path`` whole or not at all (see :func:`atomic_write`)."""
    atomic_write(path, lambda handle: handle.write(text))


def save_figure(fig, path, dpi=120):
    """Write a matplotlib figure as PNG whole or not at all."""
    atomic_write(path, lambda h: fig.savefig(h, format="png", dpi=dpi, bbox_inches="tight"), "wb")


_CONSTANT_KEYS = ("E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa")
_TO_CASE_UNITS = np.array([1e-9, 1e-9, 1.0, 1e-9, 1e-9, 1e-9])


def constants_json(mean, sd=None, **extra):
    """Engineering constants in case-file units: ``{"E1_GPa": {"mean", "sd", ...}, ...}``.

    Parameters
    ----------
    mean, sd : array_like, shape (6,)
        SI values (Pa, dimensionless nu12); ``sd`` may be None.
    **extra : array_like, shape (6,)
        Further SI fields per constant (e.g. ``hdi_3%``).
    """
    fields = {"mean": mean, "sd": sd, **extra}
    scaled = {k: None if v is None else np.asarray(v, dtype=float) * _TO_CASE_UNITS
              for k, v in fields.items()}  # fmt: skip
    return {
        key: {k: None if v is None else float(v[i]) for k, v in scaled.items()}
        for i, key in enumerate(_CONSTANT_KEYS)
    }


def _umask():
    """The process's file-creation mask (read by setting and restoring it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def jsonable(value):
    """``json.dumps(default=...)``: numpy arrays and scalars, tuples and sets as lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple | set):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def write_json(obj, target):
    """Write ``obj`` as JSON to the file ``target``, or to standard output for ``"-"``."""
    text = json.dumps(obj, indent=2, default=jsonable) + "\n"
    if str(target) == "-":
        sys.stdout.write(text)
    else:
        atomic_write_text(target, text)
