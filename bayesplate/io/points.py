"""A points file: where each response point (or the tap) sits on the plate, in mm.

``point,x_mm,y_mm`` with one row per point (:func:`read_points`); read by the tap-test and
FRF readers to give their responses coordinates.
"""

from __future__ import annotations

import os

import numpy as np

from .csv_rows import check_columns, check_width, numeric_table, read_csv_rows
from .errors import CaseError

__all__ = ["read_points"]

_POINT_COLUMNS = ("point", "x_mm", "y_mm")


def read_points(path) -> tuple[tuple[str, ...], np.ndarray]:
    """Read a points file: CSV ``point,x_mm,y_mm``, one row per response point.

    ``point`` is a name (unique; for an FRF CSV it is the ``<point>`` of its ``H<point>_re``
    columns), ``x_mm, y_mm`` the point's coordinates in the plate frame, mm. ``#`` starts a
    comment.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    names : tuple of str, length p
    points_mm : numpy.ndarray, shape (p, 2)

    Raises
    ------
    CaseError
        Naming the file, line and column, for a missing or unknown column, a number that is
        not finite, or a name given twice.
    """
    path = os.fspath(path)
    try:
        header_line, header, rows = read_csv_rows(path, min_rows=1)
        check_columns(header_line, header, _POINT_COLUMNS, _POINT_COLUMNS)
        names = []
        for number, cells in rows:
            check_width(number, cells, header)
            name = cells[header.index("point")]
            if not name:
                raise CaseError(f"line {number}, column point", rule="must name the point")
            if name in names:
                raise CaseError(f"line {number}, column point", name, "point named twice")
            names.append(name)
        columns = [name for name in header if name != "point"]
        table = numeric_table(
            columns,
            [
                (n, [c for c, h in zip(cells, header, strict=True) if h != "point"])
                for n, cells in rows
            ],
        )
    except CaseError as err:
        raise err.with_path(path) from None
    return tuple(names), np.column_stack([table["x_mm"], table["y_mm"]])
