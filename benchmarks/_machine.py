"""The machine a benchmark ran on: processor, cores, memory, BLAS and library versions.

Shared by every script of this folder (each puts the folder on ``sys.path`` to import it).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import pathlib
import platform
import subprocess
import sys
import tempfile

import numpy as np

# the studies' helper dates their reports; the benchmarks date theirs by the same function.
# The repository's root is appended, not put first: a base checkout on PYTHONPATH keeps its
# own package, and the studies (a package there) are found after it
sys.path.append(str(pathlib.Path(__file__).resolve().parents[1]))
from studies._study_host import utc_now  # noqa: E402

__all__ = ["add_base_arguments", "base_checkout", "commit", "machine", "utc_now"]


def _proc_field(path, key):
    """The value of ``key`` in a ``/proc`` text file, or "unknown"."""
    try:
        for line in pathlib.Path(path).read_text().splitlines():
            if line.startswith(key):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def _blas():
    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
    except Exception:  # noqa: BLE001 - informative only
        return "unknown"


def machine(*libraries):
    """``{cpu, nproc, memory, blas, platform, python, numpy, scipy, <library>: version}``."""
    mem = _proc_field("/proc/meminfo", "MemTotal")
    if mem != "unknown":
        mem = f"{int(mem.split()[0]) / 1024**2:.1f} GiB"
    nproc = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    info = {
        "cpu": _proc_field("/proc/cpuinfo", "model name"),
        "nproc": nproc,
        "memory": mem,
        "blas": _blas(),
        "platform": platform.platform(),
        "python": platform.python_version(),
    }
    for name in ("numpy", "scipy", *libraries):
        info[name] = importlib.import_module(name).__version__
    return info


def commit(tree):
    """The commit a checkout is at, short (raises if git cannot read it)."""
    rev = ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"]
    return subprocess.run(rev, check=True, capture_output=True, text=True).stdout.strip()


@contextlib.contextmanager
def base_checkout(rev, base_dir=None, prefix="bench-base-"):
    """A checkout of commit `rev` for a benchmark's ratio, removed afterwards.

    Yields `base_dir` itself when given (an existing checkout, kept), else a throwaway
    ``git worktree add --detach`` of `rev` in a temporary folder of this repository.
    """
    if base_dir is not None:
        yield pathlib.Path(base_dir).resolve()
        return
    root = pathlib.Path(__file__).resolve().parents[1]
    made = pathlib.Path(tempfile.mkdtemp(prefix=prefix)) / "base"

    def git(*args):
        subprocess.run(["git", "-C", str(root), *args], check=True, capture_output=True)

    git("worktree", "add", "--detach", str(made), rev)
    try:
        yield made.resolve()
    finally:
        git("worktree", "remove", "--force", str(made))
        made.parent.rmdir()


def add_base_arguments(parser, base_rev, out):
    """``--base-rev``, ``--base-dir``, ``--no-base`` and ``--out`` of a benchmark with a base."""
    parser.add_argument("--base-rev", default=base_rev, help=f"base commit (default {base_rev})")
    parser.add_argument("--base-dir", type=pathlib.Path, help="an existing checkout of the base")
    parser.add_argument("--no-base", action="store_true", help="time this tree only")
    parser.add_argument("--out", default=str(out), help="report folder")


def write_report(out_dir, name, lines):
    """Write ``lines`` joined by newlines to ``out_dir/name``, whole (a temporary, renamed).

    Returns
    -------
    pathlib.Path
        The report written.
    """
    path = pathlib.Path(out_dir) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text("\n".join(lines))
    tmp.replace(path)
    return path
