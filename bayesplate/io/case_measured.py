"""The ``[measured]`` table of a case file, read and checked (see :mod:`.case_file`).

The measured frequencies and their deviations (``sigma_rel`` or ``sigma_Hz``), mode numbers,
mode shapes at points on the plate, the tap and sensor points, the error scale's prior and
the probabilities of spurious peaks, as a :class:`Measurement` in SI units; a message quotes
what the user wrote, e.g. ``measured.sigma_rel = 2: must be > 0 and < 1``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .case import Measurement
from .checks import (
    _check_frequencies,
    _integers,
    _list,
    _number,
    _numbers,
    _positive,
    _table,
    check_plausible,
)
from .errors import CaseError

__all__ = ["parse_measured"]

_MM = 1e-3  # m per mm
_MAX_MODE_INDEX = 1_000_000  # keeps mode indices far inside int64

_MEASURED_KEYS = (
    "frequency_Hz",
    "sigma_rel",
    "sigma_Hz",
    "mode",
    "points_mm",
    "shapes",
    "error_scale",
    "p_spurious",
    "tap_point_mm",
    "sensor_point_mm",
)
_ERROR_SCALE_KEYS = ("median", "upper95")
_ERROR_SCALE_ENTRY = "a table { median = ..., upper95 = ... } (quantiles of the scale s)"


def parse_measured(raw, extent_mm: tuple[float, float]) -> Measurement:
    """The ``[measured]`` table as a :class:`Measurement`.

    Points are checked against ``extent_mm``, the plate's (length, width) in mm.
    """
    table = _table(raw, "measured", _MEASURED_KEYS, ("frequency_Hz",))
    frequency = _numbers(table["frequency_Hz"], "measured.frequency_Hz")
    _check_frequencies(frequency, "measured.frequency_Hz")
    check_plausible(frequency, "frequency_Hz", "measured.frequency_Hz")
    sigma = _parse_sigma(table, frequency)
    mode = None
    if "mode" in table:
        mode = _integers(table["mode"], "measured.mode", 1, _MAX_MODE_INDEX)
    points, shapes = _parse_shapes(table, extent_mm)
    scale = _parse_error_scale(table["error_scale"]) if "error_scale" in table else None
    p_spurious = None
    if "p_spurious" in table:
        p_spurious = _numbers(table["p_spurious"], "measured.p_spurious")
    tap = _tap_points(table, extent_mm)
    return Measurement(frequency, sigma, mode, points, shapes, scale, p_spurious, tap)


def _tap_points(table, extent_mm):
    """``tap_point_mm`` and ``sensor_point_mm`` (both or neither) as an array (2, 2), m."""
    keys = ("tap_point_mm", "sensor_point_mm")
    given = [key for key in keys if key in table]
    if not given:
        return None
    if len(given) == 1:
        missing = next(key for key in keys if key not in table)
        raise CaseError(f"measured.{missing}", rule=f"required with measured.{given[0]}")
    return np.array([_point(table[key], f"measured.{key}", extent_mm) for key in keys]) * _MM


def _parse_error_scale(raw):
    """``measured.error_scale = { median, upper95 }``: the prior of ``s`` (:mod:`.case_file`)."""
    key = "measured.error_scale"
    entry = _table(raw, key, _ERROR_SCALE_KEYS, _ERROR_SCALE_KEYS, _ERROR_SCALE_ENTRY)
    median = _positive(entry["median"], f"{key}.median")
    upper = _positive(entry["upper95"], f"{key}.upper95")
    from ..likelihood.error_scale import ErrorScalePrior

    try:
        return ErrorScalePrior(median, upper)
    except ValueError as err:
        field, rule = str(err).split(": ", 1)
        raise CaseError(f"{key}.{field}", entry[field], rule) from None


def _parse_sigma(table: Mapping, frequency: np.ndarray) -> np.ndarray:
    if "sigma_rel" in table and "sigma_Hz" in table:
        rule = "give sigma_rel or sigma_Hz, not both"
        raise CaseError("measured.sigma_rel", table["sigma_rel"], rule)
    if "sigma_Hz" in table:
        sigma = _numbers(table["sigma_Hz"], "measured.sigma_Hz")
        if sigma.size == frequency.size:  # else Measurement names the length rule
            _check_sigma_hz(sigma)
        return sigma
    if "sigma_rel" not in table:
        rule = "required: give sigma_rel (fraction of each frequency) or sigma_Hz (list)"
        raise CaseError("measured.sigma_rel", rule=rule)
    sigma_rel = _number(table["sigma_rel"], "measured.sigma_rel")
    if not 0 < sigma_rel < 1:
        raise CaseError("measured.sigma_rel", table["sigma_rel"], "must be > 0 and < 1")
    check_plausible(sigma_rel, "sigma_rel", "measured.sigma_rel")
    return sigma_rel * frequency


def _parse_shapes(table: Mapping, extent_mm) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Return measurement points (p, 2) in m and shapes (m, p), or (None, None)."""
    if ("points_mm" in table) != ("shapes" in table):
        given, other = ("points_mm", "shapes") if "points_mm" in table else ("shapes", "points_mm")
        rule = f"needs measured.{other} too (mode shapes are amplitudes at points)"
        raise CaseError(f"measured.{given}", table[given], rule)
    if "points_mm" not in table:
        return None, None
    points_mm = _points(table["points_mm"], "measured.points_mm", extent_mm)
    shapes = _matrix(table["shapes"], "measured.shapes", len(points_mm))
    return points_mm * _MM, shapes


def _points(raw, key: str, extent_mm) -> np.ndarray:
    items = _list(raw, key, "[x, y] pairs")
    if not items:
        raise CaseError(key, raw, "must list at least one [x, y] point")
    return np.array([_point(item, f"{key}[{i}]", extent_mm) for i, item in enumerate(items)])


def _point(raw, key: str, extent_mm) -> list[float]:
    pair = _list(raw, key, "two numbers [x, y]")
    if len(pair) != 2:
        raise CaseError(key, raw, "must be a pair [x, y] of numbers")
    xy = []
    for j, (value, axis, size, size_key) in enumerate(
        zip(pair, "xy", extent_mm, ("length_mm", "width_mm"), strict=True)
    ):
        coordinate = _number(value, f"{key}[{j}]")
        if not 0 <= coordinate <= size:
            rule = f"{axis} must lie on the plate: 0 <= {axis} <= plate.{size_key} = {size:g}"
            raise CaseError(f"{key}[{j}]", value, rule)
        xy.append(coordinate)
    return xy


def _matrix(raw, key: str, ncols: int) -> np.ndarray:
    rows = _list(raw, key, "rows (lists of numbers)")
    out = np.empty((len(rows), ncols))
    for i, row in enumerate(rows):
        values = _numbers(row, f"{key}[{i}]")
        if values.size != ncols:
            rule = f"must have one value per point of points_mm ({ncols}), got {values.size}"
            raise CaseError(f"{key}[{i}]", row, rule)
        out[i] = values
        check_plausible(np.max(np.abs(values), initial=0.0), "shape_amplitude", f"{key}[{i}]")
    return out


def _check_sigma_hz(sigma: np.ndarray) -> None:
    """Each sd positive and plausible (the positivity rule first, as Measurement has it)."""
    for i, s in enumerate(sigma):
        key = f"measured.sigma_Hz[{i}]"
        if not s > 0:
            raise CaseError(key, s, "must be a positive number")
        check_plausible(s, "sigma_Hz", key)
