"""The rows of a CSV file with a header line, and its columns as numbers.

The shared bottom of the CSV readers (FRF tables, time series, points and pole files): every
problem raises :class:`~bayesplate.io.errors.CaseError`, one line naming the file, the line,
the column, the value and the rule.
"""

from __future__ import annotations

import math

import numpy as np

from .csv_table import csv_lines
from .errors import CaseError

__all__ = ["check_columns", "check_width", "numeric_table", "read_csv_rows"]


def read_csv_rows(path: str, min_rows: int = 8, lines=None) -> tuple[int, list[str], list]:
    """Header line number, header cells and ``(line number, cells)`` rows of a CSV file.

    The lines of :func:`bayesplate.io.csv_table.csv_lines`, or `lines` (``(line number,
    cells)`` already split, e.g. at another separator), cells stripped.
    """
    lines = csv_lines(path) if lines is None else lines
    lines = [(number, [cell.strip() for cell in cells]) for number, cells in lines]
    if not lines:
        raise CaseError(None, rule="the file is empty: give a header line and data rows")
    (header_line, header), rows = lines[0], lines[1:]
    for i, name in enumerate(header):
        if name in header[:i]:
            raise CaseError(f"line {header_line}, column {name}", name, "column given twice")
    if len(rows) < min_rows:
        rule = f"at least {min_rows} data rows must follow the header"
        raise CaseError(f"line {header_line}", rule=rule)
    return header_line, header, rows


def check_columns(header_line: int, header: list[str], allowed=None, required=()) -> None:
    """Refuse a header with a column not in `allowed` (None: any) or without one of `required`."""
    for name in header if allowed is not None else ():
        if name not in allowed:
            rule = f"unknown column; allowed: {', '.join(allowed)}"
            raise CaseError(f"line {header_line}, column {name}", name, rule)
    for name in required:
        if name not in header:
            rule = f"required column is missing from the header ({', '.join(header)})"
            raise CaseError(f"line {header_line}, column {name}", rule=rule)


def check_width(number: int, cells: list[str], header: list[str]) -> None:
    """Refuse a row (at line `number`) that has not one value per column of `header`."""
    if len(cells) != len(header):
        rule = f"must have {len(header)} comma-separated values ({', '.join(header)})"
        raise CaseError(f"line {number}", ",".join(cells), rule)


def numeric_table(header: list[str], rows) -> dict[str, np.ndarray]:
    """Columns of finite numbers by name; a bad row or cell raises a CaseError naming it."""
    values = np.empty((len(rows), len(header)))
    for i, (number, cells) in enumerate(rows):
        check_width(number, cells, header)
        for j, (name, cell) in enumerate(zip(header, cells, strict=True)):
            try:
                value = float(cell)
            except ValueError:
                raise CaseError(f"line {number}, column {name}", cell, "must be a number") from None
            if not math.isfinite(value):
                raise CaseError(f"line {number}, column {name}", cell, "must be a finite number")
            values[i, j] = value
    return {name: values[:, j] for j, name in enumerate(header)}
