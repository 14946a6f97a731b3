"""The machine and the code a study ran on, for its report (a helper here, not a study)."""

import datetime
import json
import pathlib
import platform
import subprocess


def utc_now():
    """The time now, to the minute, as reports date a run: ``2026-11-28 03:20 UTC``."""
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def cpu():
    """The processor's model name (from /proc/cpuinfo), else the machine type."""
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine()


def code_version(root=None, paths=("bayesplate", "studies")):
    """The last commit that changed the package or the studies (``+modified`` when they differ
    from it): a commit of documents or reports alone leaves a study's cached rows current.
    ``root``: the repository (default this one); ``paths``: in it, the code that counts
    (default the package and the studies)."""
    root = pathlib.Path(__file__).resolve().parents[1] if root is None else root
    try:
        head = subprocess.run(
            ["git", "log", "-1", "--format=%h", "--", *paths],
            cwd=root,
            text=True,
            capture_output=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", *paths],
            cwd=root,
            text=True,
            capture_output=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+modified" if dirty else "")


def jsonl_rows(path):
    """The rows of a JSON-lines cache, in order; none when it does not exist.

    A line cut short (a run killed while writing it) is skipped: its replicate runs again.
    """
    rows = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return rows
