"""The plate-test case file: read it, validate it, hold it in SI units.

A case file (TOML, see ``shared/spec/case-format.md``) describes one vibration test of one
plate: the plate, the measured natural frequencies, the prior on the six engineering
constants and, optionally, the mesh and published reference constants. This is the only
module of the package that reads TOML.

Validation happens in two layers that share the same small checks:

- :func:`parse_case` checks the file's own keys and values (millimetres, GPa), so a message
  quotes what the user wrote, e.g. ``plate.thickness_mm = -3.0: must be a positive number``.
- The dataclasses check their invariants again in SI on construction, so a case built or
  modified in code (:meth:`Case.with_prior`, :meth:`Case.with_measured`) is just as safe.

Every problem raises :class:`CaseError`, a one-line :class:`ValueError` naming the key, the
value and the rule. List items are named with 0-based indices: ``measured.frequency_Hz[3]``
is the fourth frequency.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import importlib.resources
import json
import math
import numbers
import os
import pathlib
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .quantities import CASE_SCALE, ENGINEERING_KEYS, ENGINEERING_NAMES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 only
    import tomli as tomllib

__all__ = [
    "ENGINEERING_NAMES",
    "ENGINEERING_KEYS",
    "MAX_MESH_ELEMENTS",
    "CaseError",
    "Plate",
    "Measurement",
    "Prior",
    "Case",
    "load_case",
    "parse_case",
    "bundled_case_path",
    "bundled_case_names",
    "check_engineering_constants",
    "engineering_to_si",
    "engineering_from_si",
]

"""Names of the six lamina constants, in the order used by every array of the package."""

"""The same six constants as spelled in a case file (moduli in GPa)."""

MAX_MESH_ELEMENTS = 400
"""Largest number of elements allowed along one side in ``model.mesh``."""

_MM = 1e-3  # m per mm
_PLY_SUM_RTOL = 1e-6  # relative tolerance on sum(ply thicknesses) == thickness
_MAX_MODE_INDEX = 1_000_000  # keeps mode indices far inside int64
_SHOW_WIDTH = 60  # characters of a value quoted in an error message

_TOP_KEYS = ("name", "source", "plate", "measured", "prior", "model", "reference")
_TOP_REQUIRED = ("name", "plate", "measured", "prior")
_PLATE_KEYS = (
    "length_mm",
    "width_mm",
    "thickness_mm",
    "density_kg_m3",
    "layup_deg",
    "ply_thickness_mm",
)
_MEASURED_KEYS = ("frequency_Hz", "sigma_rel", "sigma_Hz", "mode", "points_mm", "shapes")
_PRIOR_ENTRY_KEYS = ("mean", "sd")
_PRIOR_ENTRY = "a table { mean = ..., sd = ... }"
_MODEL_KEYS = ("mesh",)


class _Missing(enum.Enum):
    MISSING = "missing"


# ----------------------------------------------------------------------------- the error


class CaseError(ValueError):
    """A case file, or a case built in code, breaks a rule of the case format.

    ``str(err)`` is a single line: ``[file: ]key = value: rule``, e.g.
    ``plate.thickness_mm = -3.0: must be a positive number``.

    Parameters
    ----------
    key : str or None
        Dotted key path of the offending entry (``measured.frequency_Hz[3]``); None for a
        problem with the file as a whole (unreadable, TOML syntax).
    value : object
        The offending value as given, or ``CaseError.MISSING`` when the key is absent.
    rule : str
        The rule that is broken, phrased as a requirement.
    path : str or os.PathLike, optional
        The case file, when there is one.

    Attributes
    ----------
    key, value, rule, path
        As given.
    """

    MISSING = _Missing.MISSING

    def __init__(self, key: str | None, value: Any = MISSING, rule: str = "", path=None):
        self.key = key
        self.value = value
        self.rule = rule
        self.path = None if path is None else os.fspath(path)
        super().__init__(self._message())

    def __reduce__(self):
        return (type(self), (self.key, self.value, self.rule, self.path))

    def with_path(self, path) -> CaseError:
        """Return the same error attributed to the case file `path`."""
        return type(self)(self.key, self.value, self.rule, path)

    def _message(self) -> str:
        head = "" if self.path is None else f"{self.path}: "
        if self.key is None:
            body = self.rule
        elif self.value is _Missing.MISSING:
            body = f"{self.key}: {self.rule}"
        else:
            body = f"{self.key} = {_show(self.value)}: {self.rule}"
        return " ".join((head + body).splitlines())


def _show(value: Any) -> str:
    """Render `value` briefly, in TOML spelling, on one line."""
    text = _render(value)
    return text if len(text) <= _SHOW_WIDTH else text[: _SHOW_WIDTH - 3] + "..."


def _render(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_render(item) for item in value[:20]) + "]"
    if isinstance(value, Mapping):
        items = (f"{key} = {_render(item)}" for key, item in value.items())
        return "{ " + ", ".join(items) + " }"
    return repr(value)


# ----------------------------------------------------------------------------- dataclasses


class _EqualByValue:
    """Field-wise equality that compares array fields by value (dataclass eq cannot)."""

    __hash__ = None

    def __eq__(self, other):
        if type(self) is not type(other):
            return NotImplemented
        return all(
            _equal(getattr(self, f.name), getattr(other, f.name)) for f in dataclasses.fields(self)
        )


@dataclass(frozen=True, eq=False)
class Plate(_EqualByValue):
    """Geometry, density and stacking sequence of the plate, in SI units.

    Parameters
    ----------
    length : float
        a, along x (the 0 degree fibre direction), m.
    width : float
        b, along y, m.
    thickness : float
        h, total, m.
    density : float
        Mass density, kg/m^3.
    layup_deg : tuple of float
        Ply angles from the bottom face (z = -h/2) upward, degrees.
    ply_thickness : tuple of float, optional
        One thickness per ply, m, summing to `thickness`; default h / number of plies.
    """

    length: float
    width: float
    thickness: float
    density: float
    layup_deg: tuple[float, ...]
    ply_thickness: tuple[float, ...] | None = None

    def __post_init__(self):
        for name in ("length", "width", "thickness", "density"):
            _set(self, name, _positive(getattr(self, name), f"plate.{name}"))
        layup = _angles(self.layup_deg, "plate.layup_deg")
        _set(self, "layup_deg", tuple(layup))
        if self.ply_thickness is None:
            plies = [self.thickness / len(layup)] * len(layup)
        else:
            plies = _ply_thicknesses(
                self.ply_thickness, len(layup), self.thickness, "plate.ply_thickness"
            )
        _set(self, "ply_thickness", tuple(plies))


@dataclass(frozen=True, eq=False)
class Measurement(_EqualByValue):
    """Measured natural frequencies with their standard deviations and optional mode shapes.

    Arrays are stored as read-only copies.

    Parameters
    ----------
    frequency_Hz : array_like, shape (m,)
        Undamped natural frequencies of the free-free plate, Hz, ascending (ties allowed).
    sigma_Hz : array_like, shape (m,)
        One standard deviation of each frequency, Hz.
    mode : array_like of int, shape (m,), optional
        Distinct 1-based elastic-mode indices (1 = lowest non-rigid mode) of the frequencies;
        None means the first m modes in order.
    points : array_like, shape (p, 2), optional
        (x, y) of the measurement points on the mid-plane, m. Given with `shapes`.
    shapes : array_like, shape (m, p), optional
        Out-of-plane amplitude of each measured mode at each point (arbitrary scale).
    """

    frequency_Hz: np.ndarray
    sigma_Hz: np.ndarray
    mode: np.ndarray | None = None
    points: np.ndarray | None = None
    shapes: np.ndarray | None = None

    def __post_init__(self):
        frequency = _array(self.frequency_Hz, "measured.frequency_Hz", ndim=1)
        _check_frequencies(frequency, "measured.frequency_Hz")
        _set(self, "frequency_Hz", frequency)
        sigma = _array(self.sigma_Hz, "measured.sigma_Hz", ndim=1)
        _check_length(sigma, frequency.size, "measured.sigma_Hz", "entry per frequency")
        _check_positive_each(sigma, "measured.sigma_Hz")
        _set(self, "sigma_Hz", sigma)
        if self.mode is not None:
            _set(self, "mode", _mode_array(self.mode, frequency.size))
        _set_shapes(self, frequency.size)

    @property
    def size(self) -> int:
        """Number of measured frequencies m."""
        return int(self.frequency_Hz.size)

    def select(self, index) -> Measurement:
        """Return the measurement restricted to some frequencies.

        Parameters
        ----------
        index : slice or array_like of int or bool
            Which frequencies to keep (NumPy indexing along the frequency axis); the kept
            frequencies must still be ascending.

        Returns
        -------
        Measurement
            A new measurement with the selected rows of every per-frequency array.
        """
        rows = np.arange(self.size)[index]
        return dataclasses.replace(
            self,
            frequency_Hz=self.frequency_Hz[rows],
            sigma_Hz=self.sigma_Hz[rows],
            mode=None if self.mode is None else self.mode[rows],
            shapes=None if self.shapes is None else self.shapes[rows],
        )


@dataclass(frozen=True, eq=False)
class Prior(_EqualByValue):
    """Independent Gaussian prior on the six engineering constants, in SI units.

    Parameters
    ----------
    mean : array_like, shape (6,)
        Prior means in the order of :data:`ENGINEERING_NAMES`: Pa for the moduli,
        dimensionless for nu12. Must describe a physically possible lamina.
    sd : array_like, shape (6,)
        Prior standard deviations, same order and units, each positive.
    """

    mean: np.ndarray
    sd: np.ndarray

    def __post_init__(self):
        mean = _array(self.mean, "prior.mean", ndim=1, finite=False)
        sd = _array(self.sd, "prior.sd", ndim=1, finite=False)
        _check_length(mean, 6, "prior.mean", "value per engineering constant")
        _check_length(sd, 6, "prior.sd", "value per engineering constant")
        for name, value in zip(ENGINEERING_NAMES, sd, strict=True):
            _positive(value, f"prior.{name}.sd")
        check_engineering_constants(mean, "prior", key_suffix=".mean")
        _set(self, "mean", mean)
        _set(self, "sd", sd)


@dataclass(frozen=True, eq=False)
class Case(_EqualByValue):
    """One vibration test of one plate, validated and in SI units.

    Parameters
    ----------
    name : str
        Free-text name of the test, non-empty.
    source : str
        Where the data come from; "" when not given.
    plate : Plate
        What was built.
    measured : Measurement
        What was measured.
    prior : Prior
        What is believed beforehand.
    mesh : tuple of int, optional
        Elements along x and y, (nx, ny); None lets the model choose.
    reference : array_like, shape (6,), optional
        Known or published constants (SI, order of :data:`ENGINEERING_NAMES`), never used
        to fit.
    path : str, optional
        The case file this case was read from.
    """

    name: str
    source: str
    plate: Plate
    measured: Measurement
    prior: Prior
    mesh: tuple[int, int] | None = None
    reference: np.ndarray | None = None
    path: str | None = None

    def __post_init__(self):
        _string(self.name, "name", nonempty=True)
        _string(self.source, "source")
        _require_type(self.plate, Plate, "plate")
        _require_type(self.measured, Measurement, "measured")
        _require_type(self.prior, Prior, "prior")
        if self.mesh is not None:
            _set(self, "mesh", _mesh(self.mesh, "model.mesh"))
        if self.reference is not None:
            reference = _array(self.reference, "reference", ndim=1, finite=False)
            _check_length(reference, 6, "reference", "value per engineering constant")
            check_engineering_constants(reference, "reference")
            _set(self, "reference", reference)
        if self.path is not None:
            _set(self, "path", os.fspath(self.path))

    def with_prior(self, mean, sd) -> Case:
        """Return the same case with another prior.

        Parameters
        ----------
        mean, sd : array_like, shape (6,)
            Prior means and standard deviations in SI (Pa, dimensionless nu12).

        Returns
        -------
        Case
            A new, validated case.
        """
        return dataclasses.replace(self, prior=Prior(mean, sd))

    def with_measured(self, measured: Measurement | None = None, **changes) -> Case:
        """Return the same case with another or modified measurement.

        Parameters
        ----------
        measured : Measurement, optional
            The new measurement; default the current one.
        **changes
            Fields of :class:`Measurement` to replace, e.g. ``frequency_Hz=...,
            sigma_Hz=...``.

        Returns
        -------
        Case
            A new, validated case.
        """
        base = self.measured if measured is None else measured
        return dataclasses.replace(self, measured=dataclasses.replace(base, **changes))


def _set(obj, name: str, value) -> None:
    """Assign a field of a frozen dataclass during ``__post_init__``."""
    object.__setattr__(obj, name, value)


def _equal(x, y) -> bool:
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and np.array_equal(x, y)
    return bool(x == y)


# ----------------------------------------------------------------------------- public helpers


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
    return _engineering_array(values) * CASE_SCALE


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
    return _engineering_array(values_si) / CASE_SCALE


def _engineering_array(values) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.ndim == 0 or array.shape[-1] != 6:
        raise ValueError(
            f"expected shape (..., 6) in the order {', '.join(ENGINEERING_NAMES)}, "
            f"got shape {array.shape}"
        )
    return array


# ----------------------------------------------------------------------------- reading


def load_case(path) -> Case:
    """Read and validate a case file.

    Parameters
    ----------
    path : str or os.PathLike
        The TOML case file.

    Returns
    -------
    Case
        The validated case, in SI units, with ``case.path`` set.

    Raises
    ------
    CaseError
        If the file cannot be read, is not valid TOML (the message names the line) or breaks
        a rule of the case format; the message starts with the file name.
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as stream:
            data = tomllib.load(stream)
    except OSError as err:
        rule = f"cannot read the case file ({err.strerror or type(err).__name__})"
        raise CaseError(None, rule=rule, path=path) from err
    except UnicodeDecodeError as err:
        raise CaseError(None, rule="not a UTF-8 text file", path=path) from err
    except tomllib.TOMLDecodeError as err:
        raise CaseError(None, rule=f"TOML syntax error: {err}", path=path) from err
    return parse_case(data, path=path)


def parse_case(data: Mapping, path=None) -> Case:
    """Validate an already-parsed case mapping and convert it to SI units.

    Parameters
    ----------
    data : mapping
        The case as read from TOML: tables are mappings, arrays are lists.
    path : str or os.PathLike, optional
        The file the mapping came from; stored in ``case.path`` and named in errors.

    Returns
    -------
    Case
        The validated case.

    Raises
    ------
    CaseError
        On the first broken rule found.
    """
    try:
        return _parse(data, path)
    except CaseError as err:
        if path is None or err.path is not None:
            raise
        raise err.with_path(path) from None


def bundled_case_names() -> list[str]:
    """Names of the case files shipped with the package, sorted.

    Returns
    -------
    list of str
        E.g. ``["angleply", "crossply", "frederiksen_t300", "plate1", "plate2"]``.
    """
    files = _bundled_cases_dir().iterdir()
    return sorted(f.name[: -len(".toml")] for f in files if f.name.endswith(".toml"))


def bundled_case_path(name: str) -> pathlib.Path:
    """Path of a case file shipped with the package.

    Parameters
    ----------
    name : str
        Case name without extension, e.g. ``"frederiksen_t300"``.

    Returns
    -------
    pathlib.Path
        ``bayesplate/data/cases/<name>.toml``.

    Raises
    ------
    CaseError
        If there is no such case; the message lists the available names.
    """
    names = bundled_case_names()
    if name not in names:
        rule = f"no such bundled case; available: {', '.join(names)}"
        raise CaseError("bundled case", name, rule)
    return pathlib.Path(str(_bundled_cases_dir().joinpath(f"{name}.toml")))


def _bundled_cases_dir():
    try:
        package = importlib.resources.files("bayesplate")
    except (NotADirectoryError, TypeError):
        # bayesplate as a namespace package (no __init__.py) on a path with non-directory
        # entries, e.g. an editable-install hook: the package is next to this module.
        package = pathlib.Path(__file__).resolve().parent
    return package.joinpath("data").joinpath("cases")


# ----------------------------------------------------------------------------- parsing


def _parse(data: Mapping, path) -> Case:
    top = _table(data, "", _TOP_KEYS, _TOP_REQUIRED)
    name = _string(top["name"], "name", nonempty=True)
    source = _string(top.get("source", ""), "source")
    plate, extent_mm = _parse_plate(top["plate"])
    measured = _parse_measured(top["measured"], extent_mm)
    prior = _parse_prior(top["prior"])
    mesh = _parse_model(top["model"]) if "model" in top else None
    reference = _parse_reference(top["reference"]) if "reference" in top else None
    return Case(name, source, plate, measured, prior, mesh, reference, path)


def _parse_plate(raw) -> tuple[Plate, tuple[float, float]]:
    """Return the plate and its (length, width) in mm, for checking points."""
    table = _table(raw, "plate", _PLATE_KEYS, _PLATE_KEYS[:5])
    length, width, thickness, density = (
        _positive(table[key], f"plate.{key}") for key in _PLATE_KEYS[:4]
    )
    layup = _angles(table["layup_deg"], "plate.layup_deg")
    plies = None
    if "ply_thickness_mm" in table:
        plies_mm = _ply_thicknesses(
            table["ply_thickness_mm"], len(layup), thickness, "plate.ply_thickness_mm"
        )
        plies = tuple(t * _MM for t in plies_mm)
    plate = Plate(length * _MM, width * _MM, thickness * _MM, density, tuple(layup), plies)
    return plate, (length, width)


def _parse_measured(raw, extent_mm: tuple[float, float]) -> Measurement:
    table = _table(raw, "measured", _MEASURED_KEYS, ("frequency_Hz",))
    frequency = _numbers(table["frequency_Hz"], "measured.frequency_Hz")
    _check_frequencies(frequency, "measured.frequency_Hz")
    sigma = _parse_sigma(table, frequency)
    mode = None
    if "mode" in table:
        mode = _integers(table["mode"], "measured.mode", 1, _MAX_MODE_INDEX)
    points, shapes = _parse_shapes(table, extent_mm)
    return Measurement(frequency, sigma, mode, points, shapes)


def _parse_sigma(table: Mapping, frequency: np.ndarray) -> np.ndarray:
    if "sigma_rel" in table and "sigma_Hz" in table:
        rule = "give sigma_rel or sigma_Hz, not both"
        raise CaseError("measured.sigma_rel", table["sigma_rel"], rule)
    if "sigma_Hz" in table:
        return _numbers(table["sigma_Hz"], "measured.sigma_Hz")
    if "sigma_rel" not in table:
        rule = "required: give sigma_rel (fraction of each frequency) or sigma_Hz (list)"
        raise CaseError("measured.sigma_rel", rule=rule)
    sigma_rel = _number(table["sigma_rel"], "measured.sigma_rel")
    if not 0 < sigma_rel < 1:
        raise CaseError("measured.sigma_rel", table["sigma_rel"], "must be > 0 and < 1")
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
    return out


def _parse_prior(raw) -> Prior:
    table = _table(raw, "prior", ENGINEERING_KEYS, ENGINEERING_KEYS)
    mean, sd = np.empty(6), np.empty(6)
    for i, key in enumerate(ENGINEERING_KEYS):
        entry = _table(
            table[key], f"prior.{key}", _PRIOR_ENTRY_KEYS, _PRIOR_ENTRY_KEYS, _PRIOR_ENTRY
        )
        mean[i] = _number(entry["mean"], f"prior.{key}.mean")
        sd[i] = _positive(entry["sd"], f"prior.{key}.sd")
    check_engineering_constants(mean, "prior", keys=ENGINEERING_KEYS, key_suffix=".mean")
    return Prior(engineering_to_si(mean), engineering_to_si(sd))


def _parse_model(raw) -> tuple[int, int] | None:
    table = _table(raw, "model", _MODEL_KEYS)
    return _mesh(table["mesh"], "model.mesh") if "mesh" in table else None


def _parse_reference(raw) -> np.ndarray:
    table = _table(raw, "reference", ENGINEERING_KEYS, ENGINEERING_KEYS)
    values = np.array([_number(table[key], f"reference.{key}") for key in ENGINEERING_KEYS])
    check_engineering_constants(values, "reference", keys=ENGINEERING_KEYS)
    return engineering_to_si(values)


def _mesh(raw, key: str) -> tuple[int, int]:
    items = _list(raw, key, "two integers [nx, ny]")
    if len(items) != 2:
        raise CaseError(key, raw, "must be two integers [nx, ny]")
    nx, ny = (_integer(v, f"{key}[{i}]", 1, MAX_MESH_ELEMENTS) for i, v in enumerate(items))
    return nx, ny


# ----------------------------------------------------------------------------- checks


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


def _set_shapes(measurement: Measurement, n_frequencies: int) -> None:
    points, shapes = measurement.points, measurement.shapes
    if (points is None) != (shapes is None):
        raise CaseError("measured.points", points, "points and shapes go together")
    if points is None:
        return
    points = _array(points, "measured.points", ndim=2)
    if points.shape[1] != 2 or len(points) == 0:
        raise CaseError("measured.points", points, "must have shape (p, 2) with p >= 1")
    shapes = _array(shapes, "measured.shapes", ndim=2)
    _check_length(shapes, n_frequencies, "measured.shapes", "row per frequency")
    if shapes.shape[1] != len(points):
        rule = f"must have one column per point ({len(points)}), got {shapes.shape[1]}"
        raise CaseError("measured.shapes", shapes, rule)
    for i, row in enumerate(shapes):
        if not np.any(row):
            raise CaseError(f"measured.shapes[{i}]", row, "must not be all zero")
    _set(measurement, "points", points)
    _set(measurement, "shapes", shapes)
