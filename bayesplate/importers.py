"""Measured modal data in, case files out: the UFF and CSV importers and the case writer.

A modal test ends in one of two files:

- a Universal File (UFF, ``.uff``/``.unv``) as exported by modal software: dataset 55 (data
  at nodes) per mode with its frequency and its response at each node, dataset 15 or 2411
  (node coordinates) and optionally dataset 164 (units). Read with ``pyuff``.
- a plain CSV table of frequencies, one row per mode, written by hand or by a script.

:func:`read_uff_modes` and :func:`read_frequency_csv` return a :class:`ModalData`.
:func:`case_from_modal_data` combines it with a *plate sheet* (a case file without measured
frequencies: name, [plate], [prior], optional [model], [reference] and [measured] sigma_rel)
into the text of a complete case file, validated by :func:`bayesplate.case.parse_case`
before anything is written; :func:`write_case` writes it atomically.

Every problem raises :class:`~bayesplate.case.CaseError`, one line naming the file, the
dataset/record (UFF) or the line and column (CSV), the value and the rule.
"""

from __future__ import annotations

import csv
import difflib
import json
import logging
import math
import numbers
import os
import pathlib
import sys
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pyuff

from .case import CaseError, parse_case
from .io import atomic_write_text

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 only
    import tomli as tomllib

__all__ = [
    "DEFAULT_SIGMA_REL",
    "ModalData",
    "read_modal_data",
    "read_uff_modes",
    "read_frequency_csv",
    "case_from_modal_data",
    "write_case",
    "bundled_plate_names",
    "bundled_plate_path",
]

logger = logging.getLogger(__name__)

DEFAULT_SIGMA_REL = 0.01
"""Relative standard deviation of each frequency when neither the data nor the sheet say."""

_UFF_SUFFIXES = (".uff", ".unv", ".uf")
_CSV_COLUMNS = ("frequency_Hz", "sigma_Hz", "sigma_rel", "mode")
_SHEET_MEASURED_KEYS = ("sigma_rel",)
# A plate lies in a plane z = const of the test frame; nodes off that plane by more than this
# fraction of the in-plane extent mean another orientation (shapes would not be out-of-plane).
# 5 % leaves room for digitised geometry and nodes on either face of a thick plate.
_PLANE_TOLERANCE = 0.05
_COORDINATE_DIGITS = 12  # significant digits kept after unit conversion (drops 0.1 * 3 noise)
_WIDTH = 100  # characters per line of the written case file
_PACKED = 40  # list items up to this long (numbers, [x, y] points) share lines


# ----------------------------------------------------------------------------- the data


@dataclass(frozen=True, eq=False)
class ModalData:
    """Measured modes as imported, before they meet a plate sheet.

    Parameters
    ----------
    frequency_Hz : numpy.ndarray, shape (m,)
        Natural frequencies, Hz, ascending.
    points_mm : numpy.ndarray, shape (p, 2), optional
        (x, y) of the measured nodes in the plate frame, mm; None without coordinates.
    shapes : numpy.ndarray, shape (m, p), optional
        Real out-of-plane (z) amplitude of each mode at each point (arbitrary scale).
    damping : numpy.ndarray, shape (m,), optional
        Modal viscous damping ratios as given by the file (not used for fitting).
    sigma_Hz : numpy.ndarray, shape (m,), optional
        One standard deviation of each frequency, Hz, when the file gives it.
    mode : numpy.ndarray of int, shape (m,), optional
        1-based elastic-mode index of each frequency, when the file gives it.
    source : str
        The file the data came from.
    notes : tuple of str
        What the reader had to assume (e.g. the length unit); logged as warnings and written
        as comments into the case file.
    """

    frequency_Hz: np.ndarray
    points_mm: np.ndarray | None = None
    shapes: np.ndarray | None = None
    damping: np.ndarray | None = None
    sigma_Hz: np.ndarray | None = None
    mode: np.ndarray | None = None
    source: str = ""
    notes: tuple[str, ...] = ()

    @property
    def size(self) -> int:
        """Number of modes m."""
        return int(np.size(self.frequency_Hz))

    @property
    def n_points(self) -> int:
        """Number of measurement points p (0 without shapes)."""
        return 0 if self.points_mm is None else len(self.points_mm)


def read_modal_data(path) -> ModalData:
    """Read a UFF (``.uff``, ``.unv``, ``.uf``) or CSV (``.csv``) file of measured modes.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    ModalData

    Raises
    ------
    CaseError
        For another suffix, or anything the chosen reader refuses.
    """
    suffix = pathlib.Path(path).suffix.lower()
    if suffix == ".csv":
        return read_frequency_csv(path)
    if suffix in _UFF_SUFFIXES:
        return read_uff_modes(path)
    rule = f"unknown kind of file: expected {', '.join(_UFF_SUFFIXES)} (UFF) or .csv"
    raise CaseError("input", os.fspath(path), rule)


# ----------------------------------------------------------------------------- UFF


def read_uff_modes(path) -> ModalData:
    """Read measured modes from a Universal File.

    Supported: dataset 55 (data at nodes) with analysis type 2 (normal modes: frequency in
    Hz and viscous damping ratio from record 8) or 3 and 7 (complex modes: eigenvalue
    ``lambda`` in rad/s, undamped natural frequency ``|lambda| / 2 pi``, damping ratio
    ``-Re(lambda) / |lambda|``), with 3 or 6 values per node (data characteristic 2 or 3,
    global translation); only the z (out-of-plane) component is kept. A complex shape is
    turned into a real one by the rotation ``exp(-i theta)`` that makes it as real as
    possible (``2 theta = arg(sum phi_k^2)``), then its real part: exact for a real mode
    multiplied by any complex factor, and the least-squares real fit otherwise. Nodes that a
    mode's dataset omits are zero there (UFF rule: all-zero records may be left out).

    Node coordinates come from datasets 15 and 2411 and are converted to mm with the length
    factor of dataset 164; without dataset 164 they are taken to be mm already, and without
    any node dataset only the frequencies are imported (both are logged as warnings). The
    coordinates must be in the plate frame (origin at a corner of the mid-plane, x along the
    length, z normal to the plate): local coordinate systems (datasets 18/2420, the
    coordinate-system fields of the node records) are not applied.

    Parameters
    ----------
    path : str or os.PathLike
        The UFF file (ASCII).

    Returns
    -------
    ModalData
        Modes sorted by ascending frequency (stable for equal frequencies).

    Raises
    ------
    CaseError
        Naming the file, the dataset (with its 1-based block number in the file), the record
        or node and the rule, for anything unreadable or unsupported.
    """
    path = os.fspath(path)
    try:
        modal = _read_uff(path)
    except CaseError as err:
        raise err.with_path(path) from None
    for note in modal.notes:
        logger.warning("%s: %s", path, note)
    return modal


def _read_uff(path: str) -> ModalData:
    sets = _uff_sets(path, wanted=(15, 55, 164, 2411))
    modes = [_uff_mode(key, dset) for key, dset in sets if dset["type"] == 55]
    if not modes:
        found = sorted({dset["type"] for _, dset in sets}) or "none"
        rule = f"the file holds no dataset 55 (modes at nodes); supported datasets found: {found}"
        raise CaseError("dataset 55", rule=rule)
    load_cases = sorted({mode["load_case"] for mode in modes})
    if len(load_cases) > 1:
        rule = "all modes must come from one load case (analysis run)"
        raise CaseError("dataset 55 record 7 field 3 (load case)", load_cases, rule)
    order = np.argsort([mode["frequency"] for mode in modes], kind="stable")
    modes = [modes[i] for i in order]
    frequency = np.array([mode["frequency"] for mode in modes])
    damping = np.array([mode["damping"] for mode in modes])
    coordinates = _uff_coordinates(sets)
    if not coordinates:
        note = "no node coordinates (dataset 15 or 2411): frequencies only, no shapes"
        return ModalData(frequency, damping=damping, source=path, notes=(note,))
    nodes = list(dict.fromkeys(node for mode in modes for node in mode["values"]))
    shapes = np.array([[mode["values"].get(node, 0.0) for node in nodes] for mode in modes])
    for mode in modes:
        for node in mode["values"]:
            if node not in coordinates:
                rule = "the node has no coordinates in any dataset 15 or 2411 of the file"
                raise CaseError(f"{mode['key']} record 9 (node {node})", rule=rule)
    mm_per_unit, notes = _uff_mm_per_unit(sets)
    xyz = np.array([coordinates[node] for node in nodes]) * mm_per_unit
    _check_plane(xyz)
    points = np.array([[float(f"{v:.{_COORDINATE_DIGITS}g}") for v in row] for row in xyz[:, :2]])
    return ModalData(frequency, points, shapes, damping, source=path, notes=notes)


def _uff_sets(path: str, wanted) -> list[tuple[str, dict]]:
    """Read the datasets of types `wanted` as ``(key, dset)``; key names type and block."""
    try:
        with open(path, "rb") as stream:
            stream.read(1)
    except OSError as err:
        raise CaseError(None, rule=f"cannot read the file ({err.strerror or err})") from None
    try:  # pyuff raises bare Exception for every problem; its text is not helpful
        uff = pyuff.UFF(path)
        types = [int(t) for t in uff.get_set_types()]
    except Exception:  # noqa: BLE001
        raise CaseError(None, rule="not a readable universal file") from None
    if not types:
        rule = "no UFF datasets found (blocks between '    -1' lines): not a universal file"
        raise CaseError(None, rule=rule)
    sets = []
    for block, set_type in enumerate(types, start=1):
        if set_type not in wanted:
            continue
        key = f"dataset {set_type} (block {block})"
        try:
            dset = uff.read_sets(block - 1)
        except Exception:  # noqa: BLE001
            raise CaseError(key, rule="malformed: its records cannot be parsed") from None
        sets.append((key, dset))
    return sets


def _uff_mode(key: str, dset: dict) -> dict:
    """Frequency, damping, load case and ``{node: real z value}`` of one dataset 55."""
    analysis = dset.get("analysis_type")
    if analysis == 2:
        frequency = _uff_number(dset, "freq", f"{key} record 8 field 1 (frequency)")
        damping = _uff_number(dset, "modal_damp_vis", f"{key} record 8 field 3 (damping)")
    elif analysis in (3, 7):
        eig = complex(dset.get("eig", math.nan))
        if not (math.isfinite(eig.real) and math.isfinite(eig.imag) and eig != 0):
            rule = "must be a finite, non-zero complex number (rad/s)"
            raise CaseError(f"{key} record 8 fields 1-2 (eigenvalue)", str(eig), rule)
        frequency = abs(eig) / (2 * math.pi)  # undamped natural frequency
        damping = -eig.real / abs(eig)
    else:
        rule = "must be 2 (normal mode) or 3, 7 (complex eigenvalue): other analyses are not modes"
        raise CaseError(f"{key} record 6 field 2 (analysis type)", analysis, rule)
    if not frequency > 0:
        raise CaseError(f"{key} record 8 field 1 (frequency)", frequency, "must be positive")
    if dset.get("data_ch") not in (2, 3):
        rule = "must be 2 or 3 (3 or 6 DOF global translation): the z component is needed"
        raise CaseError(f"{key} record 6 field 3 (data characteristic)", dset.get("data_ch"), rule)
    if dset.get("n_data_per_node") not in (3, 6):
        rule = "must be 3 or 6 (x, y, z translations first)"
        key6 = f"{key} record 6 field 6 (values per node)"
        raise CaseError(key6, dset.get("n_data_per_node"), rule)
    nodes = np.asarray(dset.get("node_nums", []))
    z = np.asarray(dset.get("r3", []))
    if nodes.shape != z.shape or nodes.ndim != 1:
        rule = "malformed: the node records (9) and value records (10) do not pair up"
        raise CaseError(f"{key} records 9-10", rule=rule)
    for node, value in zip(nodes.tolist(), z.tolist(), strict=True):
        if not np.isfinite(value):
            raise CaseError(f"{key} record 10 (node {node})", str(value), "must be finite")
    values = {}
    for node, value in zip(nodes.tolist(), _realised(z).tolist(), strict=True):
        if node in values:
            raise CaseError(f"{key} record 9 (node {node})", node, "appears twice in the dataset")
        values[node] = value
    load_case = dset.get("load_case", 0)
    return {"key": key, "frequency": frequency, "damping": damping, "load_case": load_case,
            "values": values}  # fmt: skip


def _uff_number(dset: dict, name: str, key: str) -> float:
    value = dset.get(name)
    if not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise CaseError(key, value, "must be a finite number")
    return float(value)


def _realised(values: np.ndarray) -> np.ndarray:
    """Real shape closest to a complex one: rotate by ``exp(-i theta)``, take the real part.

    ``theta`` maximises ``|Re(exp(-i theta) phi)|^2 = (|phi|^2 + Re(exp(-2 i theta) S)) / 2``
    with ``S = sum phi_k^2``, so ``2 theta = arg(S)``. A real shape is returned as it is.
    """
    if not np.iscomplexobj(values):
        return values.astype(float)
    theta = 0.5 * np.angle(np.sum(values**2))
    return np.real(values * np.exp(-1j * theta))


def _uff_coordinates(sets) -> dict[int, tuple[float, float, float]]:
    """``{node: (x, y, z)}`` in file units from every dataset 15 and 2411."""
    coordinates: dict[int, tuple[float, float, float]] = {}
    for key, dset in sets:
        if dset["type"] not in (15, 2411):
            continue
        columns = [np.asarray(dset.get(name, []), dtype=float) for name in ("x", "y", "z")]
        labels = np.asarray(dset.get("node_nums", []), dtype=float)
        if any(column.shape != labels.shape for column in columns) or labels.ndim != 1:
            raise CaseError(f"{key} record 1", rule="malformed: incomplete node records")
        for label, *xyz in zip(labels, *columns, strict=True):
            node = f"{key} record 1 (node {label:g})"
            if not (math.isfinite(label) and label == int(label)):
                raise CaseError(node, label, "the node label must be an integer")
            if not all(math.isfinite(v) for v in xyz):
                raise CaseError(node, xyz, "coordinates must be finite numbers")
            previous = coordinates.setdefault(int(label), tuple(xyz))
            if previous != tuple(xyz):
                raise CaseError(node, xyz, f"node defined twice, also at {list(previous)}")
    return coordinates


def _uff_mm_per_unit(sets) -> tuple[float, tuple[str, ...]]:
    """Millimetres per length unit of the file, from dataset 164 (default: mm), and notes."""
    factors = {}
    for key, dset in sets:
        if dset["type"] == 164:
            # record 2 field 1: file units / SI, i.e. file length units per metre
            factors[key] = _uff_number(dset, "length", f"{key} record 2 field 1 (length)")
    if not factors:
        return 1.0, ("no units dataset 164: node coordinates taken as mm",)
    (key, factor), *others = factors.items()
    if not factor > 0:
        raise CaseError(f"{key} record 2 field 1 (length)", factor, "must be positive")
    for other, value in others:
        if value != factor:
            rule = f"conflicts with the length factor {factor:g} of {key}"
            raise CaseError(f"{other} record 2 field 1 (length)", value, rule)
    return 1000.0 / factor, ()


def _check_plane(xyz_mm: np.ndarray) -> None:
    extent = float(np.ptp(xyz_mm[:, :2], axis=0).max())
    spread = float(np.ptp(xyz_mm[:, 2]))
    if spread > _PLANE_TOLERANCE * extent:
        rule = (
            f"the nodes must lie in a plane z = const (the plate frame): z varies by "
            f"{spread:.4g} mm over an in-plane extent of {extent:.4g} mm"
        )
        raise CaseError("node coordinates z (datasets 15/2411)", rule=rule)


# ----------------------------------------------------------------------------- CSV


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


def _read_csv(path: str) -> ModalData:
    try:
        with open(path, encoding="utf-8-sig", newline="") as stream:
            text = stream.read()
    except OSError as err:
        raise CaseError(None, rule=f"cannot read the file ({err.strerror or err})") from None
    except UnicodeDecodeError:
        raise CaseError(None, rule="not a UTF-8 text file") from None
    lines = []
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0]
        if content.strip():
            lines.append((number, next(csv.reader([content]))))
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


# ----------------------------------------------------------------------------- case files


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
        The case file, already validated by :func:`bayesplate.case.parse_case`.

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
    bayesplate.case.Case
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
    return pathlib.Path(__file__).resolve().parent / "data" / "plates"


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
    """The sheet's [measured] sigma_rel (its only key), or :data:`DEFAULT_SIGMA_REL`."""
    table = sheet.get("measured", {})
    if not isinstance(table, Mapping):
        raise CaseError("measured", table, "must be a table (with only sigma_rel)")
    for key, value in table.items():
        if key not in _SHEET_MEASURED_KEYS:
            rule = "a plate sheet's [measured] holds only sigma_rel; the data come from the test"
            raise CaseError(f"measured.{key}", value, rule)
    return _check_sigma_rel(table.get("sigma_rel", DEFAULT_SIGMA_REL), "measured.sigma_rel")


def _check_sigma_rel(value, key: str) -> float:
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and 0 < value < 1
    if not ok:
        raise CaseError(key, value, "must be a number > 0 and < 1")
    return value


def _measured_table(modal: ModalData, sigma_rel: float) -> dict:
    """The [measured] table: the data of `modal`, and `sigma_rel` unless it has sigma_Hz."""
    table = {"frequency_Hz": _floats(modal.frequency_Hz)}
    if modal.sigma_Hz is not None:
        table["sigma_Hz"] = _floats(modal.sigma_Hz)
    else:
        table["sigma_rel"] = sigma_rel
    if modal.mode is not None:
        table["mode"] = [int(v) for v in np.asarray(modal.mode).ravel()]
    if modal.points_mm is not None:
        table["points_mm"] = [_floats(row) for row in np.asarray(modal.points_mm)]
        table["shapes"] = [_floats(row) for row in np.asarray(modal.shapes)]
    return table


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
