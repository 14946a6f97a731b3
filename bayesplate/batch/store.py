"""Where a batch keeps its results: one folder per case, a record per step, the summary.

Layout of the output folder ``OUT``::

    OUT/<case>/<step>.json         the step's JSON document (the single-case command's)
    OUT/<case>/<step>.record.json  {"key": ..., "row": ...}: what made it, its summary row
    OUT/summary.csv                one row per case and step (summary.parquet with pyarrow)
    OUT/summary.png                the constants with their intervals, one row per case

The key is the report cache's (:meth:`bayesplate.report.StepCache.key`: SHA-256 of the case
file's content, the step, its options and the package version). A step is done when its
record has the key of this run and did not fail; its document is written before its record,
each whole or not at all, so a record always has its document.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import pathlib

from ..io import atomic_write, atomic_write_text, jsonable, write_json
from ..quantities import ENGINEERING_KEYS
from ..report.cache import StepCache
from .tasks import FAILED

__all__ = ["COLUMNS", "ResultStore", "step_key"]

log = logging.getLogger("bayesplate.batch")

#: The summary's columns, in order (a step leaves the ones it has no value for empty).
COLUMNS = (
    "case",
    "step",
    "status",
    "reason",
    "method",
    "mesh",
    *(f"{k}{s}" for k in ENGINEERING_KEYS for s in ("", "_sd", "_lo94", "_hi94")),
    "verdict",
    "physics",
    "chi2",
    "dof",
    "p_value",
    "error_scale",
    "error_scale_lo94",
    "error_scale_hi94",
    "seconds",
    "worker",
    "warnings",
    "key",
)


def step_key(case_bytes, step, options):
    """The key of one step's result: SHA-256 of case content, step, options and version."""
    return StepCache(None, case_bytes).key(step, options)


class ResultStore:
    """The output folder of a batch (see the module's docstring for its layout).

    Parameters
    ----------
    directory : path
        ``OUT``; created when needed.
    """

    def __init__(self, directory):
        self.directory = pathlib.Path(directory)

    def _paths(self, name, step):
        folder = self.directory / name
        return folder / f"{step}.json", folder / f"{step}.record.json"

    def done(self, name, step, key):
        """The stored row of a step done with this key, or None (to be computed)."""
        document, record = self._paths(name, step)
        try:
            stored = json.loads(record.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        row = stored.get("row") or {}
        if stored.get("key") != key or row.get("status") == FAILED or not document.exists():
            return None
        return row

    def save(self, name, step, key, result):
        """Store a task's result: its document (if any), then its record; returns the row."""
        document, record = self._paths(name, step)
        row = {**result["row"], "key": key}
        if result["document"] is not None:
            write_json(result["document"], document)
        write_json({"key": key, "row": row}, record)
        return row

    def write_summary(self, rows):
        """``summary.csv`` (and ``summary.parquet`` when pyarrow is installed); their paths."""
        self.directory.mkdir(parents=True, exist_ok=True)
        text = io.StringIO()
        writer = csv.DictWriter(
            text, fieldnames=COLUMNS, extrasaction="ignore", lineterminator="\n"
        )
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _cell(row.get(k)) for k in COLUMNS})
        paths = [self.directory / "summary.csv"]
        atomic_write_text(paths[0], text.getvalue())
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            return paths
        table = pa.Table.from_pylist([{k: row.get(k) for k in COLUMNS} for row in rows])
        paths.append(self.directory / "summary.parquet")
        atomic_write(paths[1], lambda handle: pq.write_table(table, handle), "wb")
        return paths


def _cell(value):
    """A CSV cell: floats in full (``repr``), None as empty, the rest as text."""
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return json.dumps(value, default=jsonable) if isinstance(value, list | dict) else value
