"""Files written whole or not at all: through a temporary file and a rename.

A reader (or a re-run after a kill) never sees a partial file: text, figures, PNG bytes,
JSON and netCDF all go through :func:`atomic_write`.
"""

from __future__ import annotations

import io
import json
import os
import pathlib
import sys
import tempfile

import numpy as np

__all__ = [
    "atomic_write",
    "atomic_write_text",
    "figure_png",
    "jsonable",
    "save_figure",
    "write_json",
    "write_netcdf",
    "write_png",
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
    write_png(path, figure_png(fig, dpi))


def figure_png(fig, dpi=120):
    """A matplotlib figure rendered as PNG bytes (the settings of every figure written)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    return buffer.getvalue()


def write_png(path, png):
    """Write PNG bytes (:func:`figure_png`) whole or not at all."""
    atomic_write(path, lambda handle: handle.write(png), "wb")


def write_netcdf(idata, path):
    """Write ArviZ data (netCDF) whole or not at all (temporary file, then rename)."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        idata.to_netcdf(str(tmp))
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


# SI -> case units as a factor: 1 / 1e9 is exactly the double 1e-9, so this is the array
# [1e-9, 1e-9, 1, 1e-9, 1e-9, 1e-9] that the JSON documents have always been scaled by
# (multiplying by 1e-9 and dividing by 1e9 can differ in the last bit).
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
