"""The case file: read a TOML case file, validate it, return a :class:`Case` in SI units.

A case file (TOML, see ``shared/spec/case-format.md``) describes one vibration test of one
plate. This is the only module of the package that reads case files (the plate sheets of
:mod:`bayesplate.io.case_writer` are read there).

:func:`parse_case` checks the file's own keys and values (millimetres, GPa), so a message
quotes what the user wrote, e.g. ``plate.thickness_mm = -3.0: must be a positive number``;
the :class:`Case` it builds checks its invariants again in SI. The ``[measured]`` table is
read by :mod:`.case_measured`.

Uncertain inputs (optional keys of ``[plate]``): ``thickness_sd_mm``, ``density_sd_kg_m3``,
``length_sd_mm`` and ``width_sd_mm`` give one standard deviation of the measured thickness,
density, length and width, in the units of the value they qualify; absent means 0 (taken as
exact). Each must be a finite number >= 0, e.g. ``plate.thickness_sd_mm = -0.1: must be a
number >= 0 (a standard deviation)``. They are not fitted: :mod:`bayesplate.likelihood.inputs`
carries them into each constant's variance (the estimate's variance budget) and, on request, into
the eigenvalue covariance of the Gaussian problem (``inputs="marginal"``). Example::

    [plate]
    thickness_mm = 4.89
    thickness_sd_mm = 0.11     # spread of ten readings
    density_kg_m3 = 435.7
    density_sd_kg_m3 = 4.4

Error scale (optional key ``error_scale`` of ``[measured]``): a lab unsure of its deviations
states a prior on one common scale ``s`` of them (the deviations are ``s`` times the declared
``sigma_rel`` or ``sigma_Hz``): ``error_scale = { median = 1.0, upper95 = 3.0 }``, the median of
``s`` and the value it stays below with 95 % probability (dimensionless, both > 0). They fix an
inverse-gamma prior on ``s^2`` (:class:`bayesplate.likelihood.error_scale.ErrorScalePrior`);
``upper95`` must lie between 1.005 and about 100 times ``median``, e.g.
``measured.error_scale.upper95 = 1.0: must be between 1.005 and 102 times the median (1); closer, s
is known (leave error_scale out)``. ``s`` is then inferred with the constants (integrated out of the
likelihood: a Student-t); absent, ``s = 1`` as before::

    [measured]
    frequency_Hz = [...]
    sigma_rel = 0.005
    error_scale = { median = 1.0, upper95 = 3.0 }

Mass-derived density (optional keys ``mass_g`` and ``mass_sd_g``): a lab that weighs the plate
computes rho = m / (a b h), so the density's error moves with the thickness's. With ``mass_g``
the density is derived from it and ``density_kg_m3`` may be left out; when it is given too, it
must agree with m / (a b h) within its stated sd (``density_sd_kg_m3``; without one, within the
derived density's own sd from those of m, a, b, h, and at least 0.1 % for a printed value's
rounding), else one line names both, e.g. ``plate.density_kg_m3 = 480: must agree with
plate.mass_g / (a b h) = 435.7 kg/m^3 within 4.4 kg/m^3``. The measured inputs are then
h, a, b and m, independent (``density_sd_kg_m3`` is only the check's tolerance)::

    [plate]
    thickness_mm = 4.89
    thickness_sd_mm = 0.11
    mass_g = 269.2
    mass_sd_g = 0.1            # the scale's resolution
"""

from __future__ import annotations

import importlib.resources
import os
import pathlib
import sys
from collections.abc import Mapping

import numpy as np

from ..quantities import ENGINEERING_KEYS
from .case import Case, Plate, Prior
from .case_measured import parse_measured
from .checks import (
    _angles,
    _mesh,
    _number,
    _ply_thicknesses,
    _positive,
    _string,
    _table,
    check_engineering_constants,
    check_engineering_plausible,
    check_plausible,
    engineering_to_si,
)
from .errors import CaseError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 only
    import tomli as tomllib

__all__ = ["load_case", "parse_case", "bundled_case_path", "bundled_case_names"]

_MM = 1e-3  # m per mm

_TOP_KEYS = ("name", "source", "plate", "measured", "prior", "model", "reference")
_TOP_REQUIRED = ("name", "plate", "measured", "prior")
_PLATE_KEYS = (
    "length_mm",
    "width_mm",
    "thickness_mm",
    "density_kg_m3",
    "layup_deg",
    "ply_thickness_mm",
    "length_sd_mm",
    "width_sd_mm",
    "thickness_sd_mm",
    "density_sd_kg_m3",
    "mass_g",
    "mass_sd_g",
)
#: Relative agreement always allowed between a given and a mass-derived density (rounding).
_DENSITY_ROUNDING = 1e-3
#: Optional standard deviations of the measured plate inputs: (key, Plate field, to SI).
_PLATE_SD_KEYS = (
    ("length_sd_mm", "length_sd", 1e-3),
    ("width_sd_mm", "width_sd", 1e-3),
    ("thickness_sd_mm", "thickness_sd", 1e-3),
    ("density_sd_kg_m3", "density_sd", 1.0),
)
_PRIOR_ENTRY_KEYS = ("mean", "sd")
_PRIOR_ENTRY = "a table { mean = ..., sd = ... }"
_MODEL_KEYS = ("mesh",)


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
        # entries, e.g. an editable-install hook: the package is the parent of this one.
        package = pathlib.Path(__file__).resolve().parent.parent
    return package.joinpath("data").joinpath("cases")


# ----------------------------------------------------------------------------- parsing


def _parse(data: Mapping, path) -> Case:
    top = _table(data, "", _TOP_KEYS, _TOP_REQUIRED)
    name = _string(top["name"], "name", nonempty=True)
    source = _string(top.get("source", ""), "source")
    plate, extent_mm = _parse_plate(top["plate"])
    measured = parse_measured(top["measured"], extent_mm)
    prior = _parse_prior(top["prior"])
    mesh = _parse_model(top["model"]) if "model" in top else None
    reference = _parse_reference(top["reference"]) if "reference" in top else None
    return Case(name, source, plate, measured, prior, mesh, reference, path)


def _parse_plate(raw) -> tuple[Plate, tuple[float, float]]:
    """Return the plate and its (length, width) in mm, for checking points."""
    required = _PLATE_KEYS[:3] + _PLATE_KEYS[4:5]  # density: or the mass
    table = _table(raw, "plate", _PLATE_KEYS, required)
    if "density_kg_m3" not in table and "mass_g" not in table:
        raise CaseError("plate.density_kg_m3", rule="required key is missing (or give mass_g)")
    length, width, thickness = (
        _plausible(_positive(table[key], f"plate.{key}"), key, f"plate.{key}")
        for key in required[:3]
    )
    _check_proportions(length, width, thickness)
    if "density_kg_m3" in table:
        _plausible(
            _positive(table["density_kg_m3"], "plate.density_kg_m3"),
            "density_kg_m3",
            "plate.density_kg_m3",
        )
    layup = _angles(table["layup_deg"], "plate.layup_deg")
    check_plausible(layup, "layup_deg", "plate.layup_deg")
    plies = None
    if "ply_thickness_mm" in table:
        plies_mm = _ply_thicknesses(
            table["ply_thickness_mm"], len(layup), thickness, "plate.ply_thickness_mm"
        )
        check_plausible(plies_mm, "ply_thickness_mm", "plate.ply_thickness_mm")
        plies = tuple(t * _MM for t in plies_mm)
    sds = {
        field: _sd(table[key], f"plate.{key}") * to_si
        for key, field, to_si in _PLATE_SD_KEYS
        if key in table
    }
    density, mass = _density(table, length, width, thickness, sds)
    plate = Plate(
        length * _MM, width * _MM, thickness * _MM, density, tuple(layup), plies, **sds, **mass
    )
    return plate, (length, width)


def _density(table, length, width, thickness, sds):
    """The density (kg/m^3) and the Plate's mass fields: from ``mass_g`` when it is given."""
    if "mass_g" not in table:
        if "mass_sd_g" in table:
            raise CaseError("plate.mass_sd_g", table["mass_sd_g"], "needs plate.mass_g")
        return _positive(table["density_kg_m3"], "plate.density_kg_m3"), {}
    mass_g = _positive(table["mass_g"], "plate.mass_g")
    mass_sd_g = _sd(table["mass_sd_g"], "plate.mass_sd_g") if "mass_sd_g" in table else 0.0
    derived = mass_g * 1e-3 / (length * width * thickness * _MM**3)
    if "density_kg_m3" in table:
        given = _positive(table["density_kg_m3"], "plate.density_kg_m3")
        stated = sds.get("density_sd", 0.0)
        if stated > 0:
            tol, why = stated, "its stated sd"
        else:  # the derived density's own sd (first order), or the rounding of a printed one
            rel = np.hypot.reduce(
                [
                    mass_sd_g / mass_g,
                    sds.get("thickness_sd", 0.0) / (thickness * _MM),
                    sds.get("length_sd", 0.0) / (length * _MM),
                    sds.get("width_sd", 0.0) / (width * _MM),
                ]
            )
            tol, why = max(rel, _DENSITY_ROUNDING) * derived, "the derived density's sd"
        if abs(given - derived) > tol:
            raise CaseError(
                "plate.density_kg_m3",
                table["density_kg_m3"],
                f"must agree with plate.mass_g / (a b h) = {derived:.5g} kg/m^3 "
                f"within {tol:.3g} kg/m^3 ({why})",
            )
    return derived, {"mass": mass_g * 1e-3, "mass_sd": mass_sd_g * 1e-3}


def _sd(raw, key: str) -> float:
    """A standard deviation as written: a finite number >= 0."""
    value = _number(raw, key)
    if value < 0:
        raise CaseError(key, raw, "must be a number >= 0 (a standard deviation)")
    return value


def _parse_prior(raw) -> Prior:
    table = _table(raw, "prior", ENGINEERING_KEYS, ENGINEERING_KEYS)
    mean, sd = np.empty(6), np.empty(6)
    for i, key in enumerate(ENGINEERING_KEYS):
        entry = _table(
            table[key], f"prior.{key}", _PRIOR_ENTRY_KEYS, _PRIOR_ENTRY_KEYS, _PRIOR_ENTRY
        )
        mean[i] = _number(entry["mean"], f"prior.{key}.mean")
        sd[i] = _positive(entry["sd"], f"prior.{key}.sd")
    check_engineering_plausible(mean, sd, "prior", nu12=False)  # name an absurd E2 itself
    check_engineering_constants(mean, "prior", keys=ENGINEERING_KEYS, key_suffix=".mean")
    check_engineering_plausible(mean, sd, "prior", moduli=False)
    return Prior(engineering_to_si(mean), engineering_to_si(sd))


def _parse_model(raw) -> tuple[int, int] | None:
    table = _table(raw, "model", _MODEL_KEYS)
    return _mesh(table["mesh"], "model.mesh") if "mesh" in table else None


def _parse_reference(raw) -> np.ndarray:
    table = _table(raw, "reference", ENGINEERING_KEYS, ENGINEERING_KEYS)
    values = np.array([_number(table[key], f"reference.{key}") for key in ENGINEERING_KEYS])
    check_engineering_plausible(values, None, "reference", nu12=False)
    check_engineering_constants(values, "reference", keys=ENGINEERING_KEYS)
    check_engineering_plausible(values, None, "reference", moduli=False)
    return engineering_to_si(values)


def _plausible(value: float, quantity: str, key: str) -> float:
    check_plausible(value, quantity, key)
    return value


def _check_proportions(length: float, width: float, thickness: float) -> None:
    """A plate is thin: its thickness may not exceed its length or its width (all mm)."""
    side = min(length, width)
    if thickness > side:
        rule = f"must not exceed the plate's length and width (smaller: {side:g} mm)"
        raise CaseError("plate.thickness_mm", thickness, rule)
