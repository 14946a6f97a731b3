"""Measured frequencies from a CSV table: a header line, then one row per mode.

Every problem raises :class:`~bayesplate.io.errors.CaseError`, one line naming the file,
the line and the column, the value and the rule.
"""

from __future__ import annotations

import csv
import difflib
import math
import os

import numpy as np

from .errors import CaseError
from .modal_data import ModalData

__all__ = ["read_frequency_csv"]

_CSV_COLUMNS = ("frequency_Hz", "sigma_Hz", "sigma_rel", "mode")


def read_frequency_csv(path) -> ModalData:
    """Read measured frequencies from a comma-separated table with a header line.

    Columns: ``frequency_Hz`` (required, ascending, equal values allowed), optionally one of
    ``sigma_Hz`` (one standard deviation, Hz) or ``sigma_rel`` (the same as a fraction of the
    frequency), and ``mode`` (1-based elastic-mode index, distinct). ``#`` starts a comment;
    blank lines are skipped.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    ModalData
        Frequencies, ``sigma_Hz`` (``sigma_rel * frequency`` for a sigma_rel column) and
        ``mode`` when given; no shapes.

    Raises
    ------
    CaseError
        Naming the file, the line number and the column, e.g.
        ``test.csv: line 4, column frequency_Hz = "12,5": must be a number``.
    """
    path = os.fspath(path)
    try:
        return _read_csv(path)
    except CaseError as err:
        raise err.with_path(path) from None


def csv_lines(path: str) -> list[tuple[int, list[str]]]:
    """``(line number, cells)`` of every line of a CSV file that is not blank or a comment.

    ``#`` starts a comment; a byte-order mark is skipped. Cells are as the csv module splits
    them (not stripped). An unreadable or non-UTF-8 file raises a :class:`CaseError`.
    """
    lines = []
    for number, content in csv_contents(path):
        try:
            lines.append((number, next(csv.reader([content]))))
        except csv.Error as err:  # a field over the csv module's limit (128 kB)
            raise CaseError(f"line {number}", rule=f"not a CSV line ({err})") from None
    return lines


def csv_contents(path: str) -> list[tuple[int, str]]:
    """``(line number, text)`` of every line not blank or a comment, the comment cut off.

    ``#`` starts a comment; a byte-order mark is skipped. An unreadable or non-UTF-8 file
    raises a :class:`CaseError`.
    """
    try:
        with open(path, encoding="utf-8-sig", newline="") as stream:
            text = stream.read()
    except OSError as err:
        raise CaseError(None, rule=f"cannot read the file ({err.strerror or err})") from None
    except UnicodeDecodeError:
        raise CaseError(None, rule="not a UTF-8 text file") from None
    contents = []
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0]
        if content.strip():
            contents.append((number, content))
    return contents


def _read_csv(path: str) -> ModalData:
    lines = csv_lines(path)
    if not lines:
        rule = "required, but the file is empty: give a header line and one row per frequency"
        raise CaseError("column frequency_Hz", rule=rule)
    (header_line, header), rows = lines[0], lines[1:]
    columns = _csv_columns(header_line, header)
    if not rows:
        raise CaseError(f"line {header_line}", rule="no data rows after the header")
    table = {name: [] for name in columns}
    for number, cells in rows:
        if len(cells) != len(columns):
            rule = f"must have {len(columns)} comma-separated values ({', '.join(columns)})"
            raise CaseError(f"line {number}", ",".join(cells), rule)
        for name, cell in zip(columns, cells, strict=True):
            table[name].append(_csv_value(name, cell.strip(), f"line {number}, column {name}"))
    frequency = np.array(table["frequency_Hz"])
    _check_csv_order(frequency, [number for number, _ in rows])
    sigma = table.get("sigma_Hz")
    if "sigma_rel" in table:
        sigma = np.array(table["sigma_rel"]) * frequency
    mode = table.get("mode")
    if mode is not None:
        _check_csv_distinct(mode, [number for number, _ in rows])
    return ModalData(
        frequency,
        sigma_Hz=None if sigma is None else np.array(sigma),
        mode=None if mode is None else np.array(mode, dtype=np.int64),
        source=path,
    )


def _csv_columns(number: int, header: list[str]) -> list[str]:
    columns = [cell.strip() for cell in header]
    for name in columns:
        if name in _CSV_COLUMNS:
            continue
        separator = next((s for s in ";\t|" if s in name), None)
        if separator is not None:
            rule = f"columns must be separated by commas, not {separator!r}"
        else:
            close = difflib.get_close_matches(name, _CSV_COLUMNS, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            allowed = ", ".join(_CSV_COLUMNS)
            rule = f"unknown column{hint}; allowed: {allowed} (the first line is a header)"
        raise CaseError(f"line {number}, column {name}", name, rule)
    for i, name in enumerate(columns):
        if name in columns[:i]:
            raise CaseError(f"line {number}, column {name}", name, "column given twice")
    if "frequency_Hz" not in columns:
        rule = f"required column is missing from the header ({', '.join(columns)})"
        raise CaseError(f"line {number}, column frequency_Hz", rule=rule)
    if "sigma_Hz" in columns and "sigma_rel" in columns:
        rule = "give a sigma_Hz or a sigma_rel column, not both"
        raise CaseError(f"line {number}, column sigma_rel", rule=rule)
    return columns


def _csv_value(name: str, cell: str, key: str):
    if name == "mode":
        try:
            value = int(cell)
        except ValueError:
            raise CaseError(key, cell, "must be an integer (1 = lowest elastic mode)") from None
        if value < 1:
            raise CaseError(key, cell, "must be an integer >= 1 (1 = lowest elastic mode)")
        return value
    try:
        value = float(cell)
    except ValueError:
        raise CaseError(key, cell, "must be a number") from None
    if not math.isfinite(value):
        raise CaseError(key, cell, "must be a finite number")
    if name == "sigma_rel" and not 0 < value < 1:
        raise CaseError(key, cell, "must be > 0 and < 1")
    if not value > 0:
        raise CaseError(key, cell, "must be a positive number")
    return value


def _check_csv_order(frequency: np.ndarray, numbers_: list[int]) -> None:
    for i in range(1, frequency.size):
        if frequency[i] < frequency[i - 1]:
            rule = f"must be >= the previous frequency {frequency[i - 1]:g} (ascending order)"
            raise CaseError(f"line {numbers_[i]}, column frequency_Hz", frequency[i], rule)


def _check_csv_distinct(mode: list[int], numbers_: list[int]) -> None:
    seen: dict[int, int] = {}
    for value, number in zip(mode, numbers_, strict=True):
        if value in seen:
            rule = f"mode indices must be distinct (also on line {seen[value]})"
            raise CaseError(f"line {number}, column mode", value, rule)
        seen[value] = number
