"""The value rules of the case format: each check returns the clean value or raises.

The same small checks serve both layers of validation: :mod:`bayesplate.io.case_file` applies
them to the file's own keys and values (millimetres, GPa), so a message quotes what the user
wrote, and the dataclasses of :mod:`bayesplate.io.case` apply them again in SI on
construction. Every failure is a :class:`~bayesplate.io.errors.CaseError` naming the key.
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Mapping

import numpy as np

from ..quantities import ENGINEERING_KEYS, ENGINEERING_NAMES, from_case_units, to_case_units
from .errors import CaseError

__all__ = [
    "MAX_MESH_ELEMENTS",
    "PLAUSIBLE_RANGES",
    "check_plausible",
    "check_engineering_plausible",
    "check_engineering_constants",
    "engineering_to_si",
    "engineering_from_si",
]

MAX_MESH_ELEMENTS = 400
"""Largest number of elements allowed along one side in ``model.mesh``."""

_PLY_SUM_RTOL = 1e-6  # relative tolerance on sum(ply thicknesses) == thickness

#: The one table of plausible ranges of a case's physical inputs, in case-file units:
#: quantity -> (lowest, highest, unit, SI per unit). Generous on purpose (balsa to tungsten,
#: micro-plates to metre panels, 0.1 Hz to 1 MHz): a value outside is a typo or a unit mix-up
#: (m for mm, Pa for GPa, kg/mm^3), never a plate. Moduli: 0.1 MPa (soft foams) to 2,000 GPa
#: (above diamond, 1,220 GPa); nu12: -1 to 5 (auxetic to steep angle-ply laminae; the
#: lamina's own bound nu12^2 < E1/E2 is checked besides); shapes: the largest amplitude of a
#: row, any scale that squares without overflow or underflow in the MAC.
PLAUSIBLE_RANGES: dict[str, tuple[float, float, str, float]] = {
    "length_mm": (0.01, 10_000.0, "mm", 1e-3),
    "width_mm": (0.01, 10_000.0, "mm", 1e-3),
    "thickness_mm": (1e-4, 1_000.0, "mm", 1e-3),
    "ply_thickness_mm": (1e-5, 1_000.0, "mm", 1e-3),
    "density_kg_m3": (10.0, 25_000.0, "kg/m^3", 1.0),
    "layup_deg": (-360.0, 360.0, "deg", 1.0),
    "frequency_Hz": (0.1, 1e6, "Hz", 1.0),
    "sigma_Hz": (1e-6, 1e5, "Hz", 1.0),
    "sigma_rel": (1e-6, 0.5, "(fraction of the frequency)", 1.0),
    "modulus_GPa": (1e-4, 2_000.0, "GPa", 1e9),
    "modulus_sd_GPa": (1e-7, 2_000.0, "GPa", 1e9),
    "nu12": (-1.0, 5.0, "", 1.0),
    "nu12_sd": (1e-6, 5.0, "", 1.0),
    "shape_amplitude": (1e-100, 1e100, "(largest of a row, any unit)", 1.0),
}


# ----------------------------------------------------------------------------- public checks


def check_engineering_constants(
    values, key_prefix: str = "prior", *, keys=ENGINEERING_NAMES, key_suffix: str = ""
) -> None:
    """Refuse engineering constants that no orthotropic lamina can have.

    E1, E2, G12, G13 and G23 must be positive and nu12 finite, and the in-plane compliance
    must be positive definite: 1 - nu12^2 E2/E1 > 0, i.e. nu12^2 < E1/E2. The checks do not
    depend on the unit of the moduli, so SI and case units (GPa) both work.

    Parameters
    ----------
    values : array_like, shape (6,)
        Constants in the order of :data:`ENGINEERING_NAMES`.
    key_prefix : str
        Start of the key named in an error, e.g. ``"prior"`` or ``"reference"``.
    keys : sequence of str, length 6
        Names of the six constants in errors; :data:`ENGINEERING_KEYS` for case-file units.
    key_suffix : str
        End of the key named in an error, e.g. ``".mean"``.

    Raises
    ------
    CaseError
        Naming the first offending constant, e.g.
        ``prior.nu12.mean = 3.0: nu12^2 must be < E1/E2 = 2 (positive-definite ...)``.
    """
    names = [_join(key_prefix, key) + key_suffix for key in keys]
    v = _array(values, key_prefix or "values", ndim=1, finite=False)
    _check_length(v, 6, key_prefix or "values", "value per engineering constant")
    for i, name in enumerate(names):
        if not math.isfinite(v[i]):
            raise CaseError(name, v[i], "must be a finite number")
        if i != 2 and not v[i] > 0:
            raise CaseError(name, v[i], "must be a positive number")
    ratio = v[0] / v[1]
    if not v[2] ** 2 < ratio:
        rule = f"nu12^2 must be < E1/E2 = {ratio:.4g} (positive-definite lamina stiffness)"
        raise CaseError(names[2], v[2], rule)


def engineering_to_si(values) -> np.ndarray:
    """Convert engineering constants from case units (GPa, nu12 as is) to SI (Pa).

    Parameters
    ----------
    values : array_like, shape (..., 6)
        Constants in the order of :data:`ENGINEERING_NAMES`, moduli in GPa.

    Returns
    -------
    numpy.ndarray, shape (..., 6)
        The same constants with moduli in Pa (a new array).
    """
    return from_case_units(_engineering_array(values))


def engineering_from_si(values_si) -> np.ndarray:
    """Convert engineering constants from SI (Pa, nu12 as is) to case units (GPa).

    Parameters
    ----------
    values_si : array_like, shape (..., 6)
        Constants in the order of :data:`ENGINEERING_NAMES`, moduli in Pa.

    Returns
    -------
    numpy.ndarray, shape (..., 6)
        The same constants with moduli in GPa (a new array).
    """
    return to_case_units(_engineering_array(values_si))


def _engineering_array(values) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.ndim == 0 or array.shape[-1] != 6:
        raise ValueError(
            f"expected shape (..., 6) in the order {', '.join(ENGINEERING_NAMES)}, "
            f"got shape {array.shape}"
        )
    return array


def _mesh(raw, key: str) -> tuple[int, int]:
    items = _list(raw, key, "two integers [nx, ny]")
    if len(items) != 2:
        raise CaseError(key, raw, "must be two integers [nx, ny]")
    nx, ny = (_integer(v, f"{key}[{i}]", 1, MAX_MESH_ELEMENTS) for i, v in enumerate(items))
    return nx, ny


def check_plausible(value, quantity: str, key: str, si: bool = False) -> None:
    """Refuse a value outside the plausible range of its quantity (:data:`PLAUSIBLE_RANGES`).

    Parameters
    ----------
    value : float or array_like
        The value (each entry of an array is checked), in the quantity's case-file unit, or
        in SI with `si`.
    quantity : str
        A key of :data:`PLAUSIBLE_RANGES`, e.g. ``"density_kg_m3"``.
    key : str
        Dotted key named in the error; array entries get ``[i]``.
    si : bool
        Whether `value` is in SI (converted to the case-file unit before the check).

    Raises
    ------
    CaseError
        E.g. ``plate.density_kg_m3 = 1e+30: outside the plausible range 10 to 25,000 kg/m^3``.
    """
    low, high, unit, per_unit = PLAUSIBLE_RANGES[quantity]
    values = np.atleast_1d(np.asarray(value, dtype=float)) / (per_unit if si else 1.0)
    for i, v in enumerate(values.ravel()):
        if not low <= v <= high:
            name = key if np.ndim(value) == 0 else f"{key}[{i}]"
            rule = f"outside the plausible range {_figure(low)} to {_figure(high)} {unit}"
            raise CaseError(name, float(v), rule.rstrip())


def check_engineering_plausible(
    mean, sd, key_prefix: str, si: bool = False, *, moduli: bool = True, nu12: bool = True
) -> None:
    """Refuse prior means (or reference values) and sds outside their plausible ranges.

    Parameters
    ----------
    mean : array_like, shape (6,)
        Constants in the order of :data:`ENGINEERING_NAMES` (GPa for the moduli, or Pa with
        `si`).
    sd : array_like, shape (6,) or None
        Their standard deviations, same units; None for reference values.
    key_prefix : str
        ``"prior"`` (keys ``prior.E1_GPa.mean``) or ``"reference"`` (``reference.E1_GPa``).
    si : bool
        Whether the values are in SI.
    moduli, nu12 : bool
        Check the moduli and every sd; check the mean (value) of nu12. A case file checks the
        moduli first (an absurd E2 is named, not the nu12 it makes impossible), then the
        lamina's rule nu12^2 < E1/E2 (:func:`check_engineering_constants`), then nu12.
    """
    for i, key in enumerate(ENGINEERING_KEYS):
        is_nu = key == "nu12"
        name = _join(key_prefix, key) + ("" if sd is None else ".mean")
        if nu12 if is_nu else moduli:
            check_plausible(mean[i], "nu12" if is_nu else "modulus_GPa", name, si)
        if sd is not None and moduli:
            quantity = "nu12_sd" if is_nu else "modulus_sd_GPa"
            check_plausible(sd[i], quantity, _join(key_prefix, key) + ".sd", si)


def _figure(x: float) -> str:
    """A range limit for people: ``25,000``, ``0.1``, ``1e-100``."""
    return f"{x:,.10g}" if 1e-4 <= abs(x) < 1e7 else f"{x:.10g}"


# ----------------------------------------------------------------------------- value rules


def _join(prefix: str, key) -> str:
    return f"{prefix}.{key}" if prefix else str(key)


def _table(raw, key: str, allowed, required=(), what: str = "a table") -> Mapping:
    """Check that `raw` is a mapping with only `allowed` keys and all `required` ones."""
    if not isinstance(raw, Mapping):
        raise CaseError(key or "case", raw, f"must be {what}")
    for name, value in raw.items():
        if name not in allowed:
            raise CaseError(_join(key, name), value, _unknown_key_rule(name, allowed))
    for name in required:
        if name not in raw:
            raise CaseError(_join(key, name), rule="required key is missing")
    return raw


def _unknown_key_rule(name, allowed) -> str:
    close = difflib.get_close_matches(str(name), allowed, n=1)
    hint = f" (did you mean {close[0]}?)" if close else ""
    return f"unknown key{hint}; allowed: {', '.join(allowed)}"


def _string(raw, key: str, nonempty: bool = False) -> str:
    if not isinstance(raw, str):
        raise CaseError(key, raw, "must be a string")
    if nonempty and not raw.strip():
        raise CaseError(key, raw, "must be a non-empty string")
    return raw


def _require_type(value, cls: type, key: str) -> None:
    if not isinstance(value, cls):
        raise CaseError(key, value, f"must be a {cls.__name__}")


def _is_number(raw) -> bool:
    return isinstance(raw, numbers.Real) and not isinstance(raw, (bool, np.bool_))


def _number(raw, key: str) -> float:
    """Return `raw` as a finite float; refuse bools, strings and anything else."""
    if not _is_number(raw):
        raise CaseError(key, raw, "must be a number")
    try:
        value = float(raw)
    except OverflowError:  # an integer beyond the float range
        value = math.inf
    if not math.isfinite(value):
        raise CaseError(key, raw, "must be a finite number")
    return value


def _positive(raw, key: str) -> float:
    value = _number(raw, key)
    if value <= 0:
        raise CaseError(key, raw, "must be a positive number")
    return value


def _integer(raw, key: str, low: int, high: int) -> int:
    if not isinstance(raw, numbers.Integral) or isinstance(raw, (bool, np.bool_)):
        raise CaseError(key, raw, "must be an integer")
    if not low <= raw <= high:
        raise CaseError(key, raw, f"must be an integer between {low} and {high}")
    return int(raw)


def _list(raw, key: str, what: str) -> list:
    if isinstance(raw, np.ndarray):
        raw = raw.tolist()
    if not isinstance(raw, (list, tuple)):
        raise CaseError(key, raw, f"must be a list of {what}")
    return list(raw)


def _numbers(raw, key: str) -> np.ndarray:
    items = _list(raw, key, "numbers")
    return np.array([_number(item, f"{key}[{i}]") for i, item in enumerate(items)], dtype=float)


def _integers(raw, key: str, low: int, high: int) -> np.ndarray:
    items = _list(raw, key, "integers")
    values = [_integer(item, f"{key}[{i}]", low, high) for i, item in enumerate(items)]
    return np.array(values, dtype=np.int64)


def _angles(raw, key: str) -> list[float]:
    angles = _numbers(raw, key)
    if angles.size == 0:
        raise CaseError(key, raw, "must list at least one ply angle")
    return angles.tolist()


def _ply_thicknesses(raw, n_plies: int, thickness: float, key: str) -> list[float]:
    """Check one positive thickness per ply summing to `thickness` (any one unit)."""
    items = _list(raw, key, "numbers")
    if len(items) != n_plies:
        rule = f"must have one entry per ply of layup_deg ({n_plies}), got {len(items)}"
        raise CaseError(key, raw, rule)
    values = [_positive(item, f"{key}[{i}]") for i, item in enumerate(items)]
    total = math.fsum(values)
    if not abs(total - thickness) <= _PLY_SUM_RTOL * thickness:
        rule = f"must sum to the plate thickness {thickness:.10g} within 1e-6 (sum {total:.10g})"
        raise CaseError(key, raw, rule)
    return values


def _array(raw, key: str, ndim: int, finite: bool = True) -> np.ndarray:
    """Return a read-only float copy of `raw` with `ndim` dimensions (and finite entries)."""
    try:
        array = np.array(raw, dtype=float)
    except (TypeError, ValueError):
        raise CaseError(key, raw, "must be an array of numbers") from None
    if array.ndim != ndim:
        raise CaseError(key, raw, f"must be a {ndim}-dimensional array")
    bad = np.argwhere(~np.isfinite(array))
    if finite and bad.size:
        index = "".join(f"[{i}]" for i in bad[0])
        raise CaseError(f"{key}{index}", array[tuple(bad[0])], "must be a finite number")
    array.setflags(write=False)
    return array


def _check_length(array: np.ndarray, size: int, key: str, what: str) -> None:
    if len(array) != size:
        raise CaseError(key, array, f"must have one {what} ({size}), got {len(array)}")


def _check_positive_each(array: np.ndarray, key: str) -> None:
    for i, value in enumerate(array):
        if not value > 0:
            raise CaseError(f"{key}[{i}]", value, "must be a positive number")


def _check_frequencies(frequency: np.ndarray, key: str) -> None:
    """Positive and ascending; equal neighbours are legal (repeated modes)."""
    if frequency.size == 0:
        raise CaseError(key, frequency, "must list at least one frequency")
    _check_positive_each(frequency, key)
    for i in range(1, frequency.size):
        if frequency[i] < frequency[i - 1]:
            rule = f"must be >= the previous frequency {frequency[i - 1]:g} (ascending order)"
            raise CaseError(f"{key}[{i}]", frequency[i], rule)


def _mode_array(raw, n_frequencies: int) -> np.ndarray:
    key = "measured.mode"
    mode = np.array(raw)
    if mode.ndim != 1 or not (mode.size == 0 or np.issubdtype(mode.dtype, np.integer)):
        raise CaseError(key, raw, "must be a list of integers")
    mode = mode.astype(np.int64)
    _check_length(mode, n_frequencies, key, "entry per frequency")
    first_seen: dict[int, int] = {}
    for i, value in enumerate(mode.tolist()):
        if value < 1:
            raise CaseError(f"{key}[{i}]", value, "must be an integer >= 1 (1 = lowest elastic)")
        if value in first_seen:
            rule = f"mode indices must be distinct (also at {key}[{first_seen[value]}])"
            raise CaseError(f"{key}[{i}]", value, rule)
        first_seen[value] = i
    mode.setflags(write=False)
    return mode
