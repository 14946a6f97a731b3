"""Case files out: a plate sheet plus imported modal data, written as a validated case file.

:func:`case_from_modal_data` combines a :class:`~bayesplate.io.modal_data.ModalData` with a
*plate sheet* (a case file without measured frequencies: name, [plate], [prior], optional
[model], [reference] and [measured] sigma_rel) into the text of a complete case file,
validated by :func:`~bayesplate.io.case_file.parse_case` before anything is written;
:func:`write_case` writes it atomically. The bundled plate sheets are in
``bayesplate/data/plates``.

Every problem raises :class:`~bayesplate.io.errors.CaseError`, one line naming the plate
sheet or the imported file, the key, the value and the rule.
"""

from __future__ import annotations

import json
import numbers
import os
import pathlib
import sys
from collections.abc import Mapping

import numpy as np

from .case import Case
from .case_file import parse_case
from .errors import CaseError
from .export import atomic_write_text
from .modal_data import ModalData

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 only
    import tomli as tomllib

__all__ = [
    "DEFAULT_SIGMA_REL",
    "case_from_modal_data",
    "sheet_case",
    "write_case",
    "bundled_plate_names",
    "bundled_plate_path",
]

DEFAULT_SIGMA_REL = 0.01
"""Relative standard deviation of each frequency when neither the data nor the sheet say."""

_SHEET_MEASURED_KEYS = ("sigma_rel", "tap_point_mm", "sensor_point_mm")
_SET_UP_KEYS = _SHEET_MEASURED_KEYS[1:]  # where the test taps and listens: carried over
_WIDTH = 100  # characters per line of the written case file
_PACKED = 40  # list items up to this long (numbers, [x, y] points) share lines


def case_from_modal_data(plate, modal: ModalData, sigma_rel: float | None = None) -> str:
    """Text of a complete case file: a plate sheet plus imported frequencies and shapes.

    Parameters
    ----------
    plate : str, os.PathLike or mapping
        The plate sheet: a TOML file (or its parsed mapping) with the keys of a case file
        except the measured data: name, optional source, [plate], [prior], optional
        [model] and [reference], and optionally [measured] with only ``sigma_rel``.
    modal : ModalData
        The imported measurement.
    sigma_rel : float, optional
        Relative standard deviation of every frequency; default the sheet's
        ``measured.sigma_rel``, else :data:`DEFAULT_SIGMA_REL`. Not allowed when `modal`
        carries ``sigma_Hz`` (per-frequency values from the file take precedence over the
        sheet's default).

    Returns
    -------
    str
        The case file, already validated by :func:`~bayesplate.io.case_file.parse_case`.

    Raises
    ------
    CaseError
        Naming the plate sheet (for its keys) or the imported file (for ``measured.*``).
    """
    sheet_path = None if isinstance(plate, Mapping) else os.fspath(plate)
    sheet = dict(plate) if sheet_path is None else _read_sheet(sheet_path)
    try:
        default = _sheet_sigma_rel(sheet)
    except CaseError as err:
        raise _blame(err, sheet_path) from None
    if sigma_rel is not None:
        _check_sigma_rel(sigma_rel, "sigma_rel")
        if modal.sigma_Hz is not None:
            rule = "the imported file gives a sigma per frequency; do not give sigma_rel too"
            raise CaseError("sigma_rel", sigma_rel, rule)
    measured = _measured_table(modal, default if sigma_rel is None else sigma_rel)
    sheet_measured = sheet.get("measured", {})
    measured.update({key: sheet_measured[key] for key in _SET_UP_KEYS if key in sheet_measured})
    data = {**sheet, "measured": measured}
    source = sheet.get("source", "")
    if modal.source and isinstance(source, str):  # a non-string is refused by parse_case
        imported = f"measured data imported from {pathlib.Path(modal.source).name}"
        data["source"] = f"{source}; {imported}" if source.strip() else imported
    try:
        case = parse_case(data)
    except CaseError as err:
        imported = str(err.key).startswith("measured.") and err.key != "measured.sigma_rel"
        raise _blame(err, modal.source if imported else sheet_path) from None
    text = _case_text(data, modal, sheet_path)
    if parse_case(tomllib.loads(text)) != case:  # pragma: no cover - an emitter bug
        raise RuntimeError("the written case file does not read back as the same case")
    return text


def sheet_case(plate) -> Case:
    """A plate sheet read as a case, for predictions before any test is read.

    Its plate, prior, model and reference as in the sheet; its measurement a placeholder
    (one frequency) that nothing should read.

    Parameters
    ----------
    plate : str, os.PathLike or mapping
        The plate sheet (see :func:`case_from_modal_data`).

    Returns
    -------
    Case

    Raises
    ------
    CaseError
        Naming the sheet and the key that breaks its rules.
    """
    sheet_path = None if isinstance(plate, Mapping) else os.fspath(plate)
    sheet = dict(plate) if sheet_path is None else _read_sheet(sheet_path)
    try:
        sigma_rel = _sheet_sigma_rel(sheet)
        set_up = {k: v for k, v in sheet.get("measured", {}).items() if k in _SET_UP_KEYS}
        measured = {"frequency_Hz": [100.0], "sigma_rel": sigma_rel, **set_up}
        return parse_case({**sheet, "measured": measured})
    except CaseError as err:
        raise _blame(err, sheet_path) from None


def write_case(path, text: str):
    """Validate a case file's text and write it atomically (whole or not at all).

    Parameters
    ----------
    path : str or os.PathLike
        The case file to write; its folder is created if needed.
    text : str
        TOML text, e.g. from :func:`case_from_modal_data`.

    Returns
    -------
    bayesplate.io.Case
        The case as written.

    Raises
    ------
    CaseError
        If `text` is not a valid case file (nothing is written then).
    OSError
        If the file cannot be written.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise CaseError(None, rule=f"TOML syntax error: {err}", path=path) from None
    case = parse_case(data, path=path)
    atomic_write_text(path, text)
    return case


def bundled_plate_names() -> list[str]:
    """Names of the plate sheets shipped with the package (``frederiksen_plate``), sorted."""
    return sorted(p.stem for p in _plates_dir().glob("*.toml"))


def bundled_plate_path(name: str) -> pathlib.Path:
    """Path of a bundled plate sheet, ``bayesplate/data/plates/<name>.toml``.

    Raises
    ------
    CaseError
        If there is no such sheet; the message lists the available names.
    """
    names = bundled_plate_names()
    if name not in names:
        raise CaseError("bundled plate sheet", name, f"no such sheet; available: {names}")
    return _plates_dir() / f"{name}.toml"


def _plates_dir() -> pathlib.Path:
    return pathlib.Path(__file__).resolve().parent.parent / "data" / "plates"


def _blame(err: CaseError, path) -> CaseError:
    """`err` attributed to the file `path` (unchanged without one)."""
    return err.with_path(path) if path else err


def _read_sheet(path: str) -> dict:
    try:
        with open(path, "rb") as stream:
            return tomllib.load(stream)
    except OSError as err:
        rule = f"cannot read the plate sheet ({err.strerror or type(err).__name__})"
        raise CaseError(None, rule=rule, path=path) from None
    except UnicodeDecodeError:
        raise CaseError(None, rule="not a UTF-8 text file", path=path) from None
    except tomllib.TOMLDecodeError as err:
        raise CaseError(None, rule=f"TOML syntax error: {err}", path=path) from None


def _sheet_sigma_rel(sheet: Mapping) -> float:
    """The sheet's [measured] sigma_rel, or :data:`DEFAULT_SIGMA_REL` (its keys checked)."""
    table = sheet.get("measured", {})
    if not isinstance(table, Mapping):
        raise CaseError("measured", table, "must be a table (with only sigma_rel)")
    for key, value in table.items():
        if key not in _SHEET_MEASURED_KEYS:
            rule = (
                "a plate sheet's [measured] holds only sigma_rel, tap_point_mm and "
                "sensor_point_mm; the data come from the test"
            )
            raise CaseError(f"measured.{key}", value, rule)
    return _check_sigma_rel(table.get("sigma_rel", DEFAULT_SIGMA_REL), "measured.sigma_rel")


def _check_sigma_rel(value, key: str) -> float:
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and 0 < value < 1
    if not ok:
        raise CaseError(key, value, "must be a number > 0 and < 1")
    return value


def _measured_table(modal: ModalData, sigma_rel: float) -> dict:
    """The [measured] table: the data of `modal`, and `sigma_rel` unless it has sigma_Hz."""
    frequency = np.asarray(modal.frequency_Hz, dtype=float)
    sigma = modal.sigma_Hz
    if sigma is None and modal.spread_Hz is not None:
        spread = np.asarray(modal.spread_Hz, dtype=float)
        sigma = (
            None
            if np.all(spread <= sigma_rel * frequency)
            else np.maximum(spread, sigma_rel * frequency)
        )
    if modal.spread_Hz is not None:  # the digits the data support
        sd = sigma_rel * frequency if sigma is None else np.asarray(sigma, dtype=float)
        frequency = np.array([_to_digits(f, s) for f, s in zip(frequency, sd, strict=True)])
    table = {"frequency_Hz": _floats(frequency)}
    if sigma is not None:
        table["sigma_Hz"] = [float(f"{s:.2g}") for s in np.asarray(sigma, dtype=float)]
    else:
        table["sigma_rel"] = sigma_rel
    if modal.mode is not None:
        table["mode"] = [int(v) for v in np.asarray(modal.mode).ravel()]
    if modal.p_spurious is not None:
        table["p_spurious"] = [float(f"{v:.2g}") for v in np.asarray(modal.p_spurious).ravel()]
    if modal.points_mm is not None:
        table["points_mm"] = [_floats(row) for row in np.asarray(modal.points_mm)]
        table["shapes"] = [_floats(row) for row in np.asarray(modal.shapes)]
    return table


def _to_digits(value: float, sd: float) -> float:
    """`value` rounded to a hundredth of its deviation's leading digit."""
    return round(value, max(0, 2 - int(np.floor(np.log10(sd))))) if sd > 0 else value


def _floats(values) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=float).ravel()]


# ----------------------------------------------------------------------------- TOML out

_TABLES = ("plate", "measured", "prior", "model", "reference")


def _case_text(data: Mapping, modal: ModalData, sheet_path: str | None) -> str:
    """A validated case mapping as TOML (the fixed schema of a case file only)."""
    sheet = "a plate sheet" if sheet_path is None else pathlib.Path(sheet_path).name
    source = pathlib.Path(modal.source).name if modal.source else "measured data"
    lines = [f"# Written by `bayesplate import` from {source} and {sheet}."]
    if modal.shapes is not None:
        lines.append("# shapes: out-of-plane (z) amplitude, one row per frequency.")
    lines += [f"# note: {note}." for note in modal.notes]
    lines += [_assignment(key, data[key]) for key in ("name", "source") if key in data]
    for table in _TABLES:
        if table in data:
            lines += ["", f"[{table}]"]
            lines += [_assignment(key, value) for key, value in data[table].items()]
    return "\n".join(lines) + "\n"


def _assignment(key: str, value) -> str:
    head = f"{key} = "
    return head + _toml(value, len(head))


def _toml(value, column: int) -> str:
    """TOML for `value` starting at `column`; lists wrap at :data:`_WIDTH` characters."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))  # shortest round-trip digits; nan and inf are TOML too
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{k} = {_toml(v, 0)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return _toml_list(list(value), column)
    raise TypeError(f"cannot write {type(value).__name__} to a case file")


def _toml_list(items: list, column: int) -> str:
    parts = [_toml(item, column + 1) for item in items]
    flat = "[" + ", ".join(parts) + "]"
    if "\n" not in flat and column + len(flat) <= _WIDTH:
        return flat
    pad = " " * (column + 1)
    if any("\n" in part or len(part) > _PACKED for part in parts):
        return "[" + f",\n{pad}".join(parts) + "]"  # e.g. shapes: one row per line
    lines, line = [], ""
    for part in parts:
        if line and column + 1 + len(line) + len(part) + 3 > _WIDTH:
            lines.append(line + ",")
            line = ""
        line = f"{line}, {part}" if line else part
    lines.append(line)
    return "[" + f"\n{pad}".join(lines) + "]"


def _toml_string(text: str) -> str:
    """A TOML basic string: JSON escapes, plus DEL, which JSON leaves as it is."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")
