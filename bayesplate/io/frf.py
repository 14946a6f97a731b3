"""Measured frequency response functions (FRFs) of a tap test: UFF dataset 58 or a CSV table.

Both readers return an :class:`FRFData`, the spectra that :mod:`bayesplate.io.poles` turns
into measured modes. Every problem raises :class:`~bayesplate.io.errors.CaseError`, one line
naming the file, the dataset or line and column, and the rule.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from .csv_rows import check_columns, numeric_table, read_csv_rows
from .errors import CaseError
from .points import read_points

__all__ = ["FRFData", "read_uff_frf", "read_frf_csv"]

_FRF_FORMS = {8: "receptance", 11: "mobility", 12: "accelerance"}  # ordinate spec data type


@dataclass(frozen=True, eq=False)
class FRFData:
    """Spectra of one tap test: one FRF (or response spectrum) per response point.

    Parameters
    ----------
    frequency_Hz : numpy.ndarray, shape (n,)
        Equally spaced frequency lines, Hz, ascending, from 0 or above.
    frf : numpy.ndarray of complex, shape (p, n)
        FRF (or response spectrum) of each response point at each frequency line.
    points_mm : numpy.ndarray, shape (p, 2), optional
        (x, y) of the response points in the plate frame, mm; None without coordinates
        (then only frequencies are imported).
    form : str
        ``"receptance"``, ``"mobility"`` or ``"accelerance"``: what the FRF measures
        (used by the modal-constant fit, not by the poles).
    added_decay_per_s : float
        Decay rate ``1/tau`` (1/s) an exponential window added to every pole; the pole
        estimates are corrected by it. 0 without a window.
    source : str
        The file the spectra came from.
    notes : tuple of str
        What the reader had to assume or chose (window, units).
    coherence : numpy.ndarray, shape (p, n), optional
        Ordinary coherence of each FRF at each line (H1 over several taps with a force,
        :mod:`bayesplate.io.taps`), 0 to 1; None when not measured.
    """

    frequency_Hz: np.ndarray
    frf: np.ndarray
    points_mm: np.ndarray | None = None
    form: str = "receptance"
    added_decay_per_s: float = 0.0
    source: str = ""
    notes: tuple[str, ...] = ()
    coherence: np.ndarray | None = None

    @property
    def n_points(self) -> int:
        """Number of response points p."""
        return int(self.frf.shape[0])


def read_uff_frf(path) -> FRFData:
    """Read FRFs from a Universal File: one dataset 58 per response point.

    Supported: dataset 58 records of function type 4 (frequency response function) with
    complex ordinates, all on the same evenly spaced frequency axis (Hz), one per response
    node, out-of-plane response (direction +z or -z: a -z record is negated). The FRF form
    comes from the ordinate's specific data type (8 displacement: receptance, 11 velocity:
    mobility, 12 acceleration: accelerance; otherwise receptance). Node coordinates come
    from datasets 15 or 2411 in the units of dataset 164 (default mm), as for
    :func:`bayesplate.io.uff.read_uff_modes`; without them only frequencies are imported.

    Parameters
    ----------
    path : str or os.PathLike
        The UFF file (ASCII).

    Returns
    -------
    FRFData

    Raises
    ------
    CaseError
        Naming the file, the dataset (with its 1-based block number) and the rule.
    """
    path = os.fspath(path)
    try:
        return _read_uff_frf(path)
    except CaseError as err:
        raise err.with_path(path) from None


def _read_uff_frf(path: str) -> FRFData:
    from .uff import _check_plane, _uff_coordinates, _uff_mm_per_unit, _uff_sets

    sets = _uff_sets(path, wanted=(15, 58, 164, 2411))
    records = [(key, dset) for key, dset in sets if dset["type"] == 58]
    if not records:
        found = sorted({dset["type"] for _, dset in sets}) or "none"
        rule = f"the file holds no dataset 58 (FRFs); supported datasets found: {found}"
        raise CaseError("dataset 58", rule=rule)
    frequency = None
    rows, nodes, forms = [], [], set()
    for key, dset in records:
        if dset.get("func_type") != 4:
            rule = "must be 4 (frequency response function)"
            raise CaseError(f"{key} record 6 field 1 (function type)", dset.get("func_type"), rule)
        x = np.asarray(dset.get("x", []), dtype=float)
        data = np.asarray(dset.get("data", []))
        if not np.iscomplexobj(data):
            rule = "must be 5 or 6 (complex ordinates): an FRF has a phase"
            raise CaseError(
                f"{key} record 8 field 2 (ordinate type)", dset.get("ord_data_type"), rule
            )
        if x.ndim != 1 or x.shape != data.shape or x.size < 8:
            raise CaseError(f"{key} record 12", rule="malformed: fewer than 8 frequency lines")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(data))):
            raise CaseError(f"{key} record 12", rule="values must be finite")
        if frequency is None:
            frequency = x
            _check_axis(frequency, f"{key} record 12 (abscissa)")
        elif x.shape != frequency.shape or not np.allclose(x, frequency, rtol=1e-9, atol=0):
            rule = "every FRF must share the frequency axis of the first dataset 58"
            raise CaseError(f"{key} record 12 (abscissa)", rule=rule)
        direction = dset.get("rsp_dir")
        if direction not in (3, -3):
            rule = "must be +3 or -3 (z, out of the plate's plane)"
            raise CaseError(f"{key} record 6 field 7 (response direction)", direction, rule)
        node = int(dset.get("rsp_node", 0))
        if node in nodes:
            rule = "one FRF per response node: the node appears twice"
            raise CaseError(f"{key} record 6 field 6 (response node)", node, rule)
        nodes.append(node)
        rows.append(data if direction == 3 else -data)
        forms.add(_FRF_FORMS.get(dset.get("ordinate_spec_data_type"), "receptance"))
    if len(forms) > 1:
        raise CaseError("dataset 58 record 8 field 1 (ordinate)", sorted(forms), "must agree")
    frf = np.array(rows)
    coordinates = _uff_coordinates(sets)
    notes: tuple[str, ...] = ()
    points = None
    if coordinates and all(node in coordinates for node in nodes):
        mm_per_unit, notes = _uff_mm_per_unit(sets)
        xyz = np.array([coordinates[node] for node in nodes]) * mm_per_unit
        _check_plane(xyz)
        points = np.array([[float(f"{v:.12g}") for v in row] for row in xyz[:, :2]])
    else:
        notes = ("no coordinates for the response nodes (dataset 15 or 2411): frequencies only",)
    return FRFData(frequency, frf, points, forms.pop(), source=path, notes=notes)


def _check_axis(frequency: np.ndarray, key: str) -> None:
    step = np.diff(frequency)
    if frequency[0] < 0 or not np.all(step > 0) or np.ptp(step) > 1e-6 * step.mean():
        raise CaseError(key, rule="frequencies must be >= 0, ascending and evenly spaced (Hz)")


def read_frf_csv(path, points=None) -> FRFData:
    """Read FRFs from a CSV table: ``frequency_Hz, H1_re, H1_im[, H2_re, H2_im, ...]``.

    A header line, then one row per frequency line (Hz, evenly spaced, ascending); each
    response point ``<point>`` has two columns ``H<point>_re`` and ``H<point>_im`` (real and
    imaginary part, any consistent unit, receptance assumed), the points in the order of
    the header. ``#`` starts a comment; blank lines are skipped. Coordinates come from a
    points file (:func:`bayesplate.io.points.read_points`, ``point,x_mm,y_mm``), matched by
    name: its row ``point = 3`` gives the coordinates of ``H3_re, H3_im``; it must name
    exactly the table's points (any row order). Without it only frequencies are imported.

    Parameters
    ----------
    path : str or os.PathLike
    points : str or os.PathLike, optional
        The points file.

    Returns
    -------
    FRFData

    Raises
    ------
    CaseError
        Naming the file, the line and the column, e.g.
        ``frf.csv: line 1, column H1_im: required column is missing (...)``, or the points
        file and the point it lacks or has too many.
    """
    path = os.fspath(path)
    try:
        header_line, header, rows = read_csv_rows(path)
        check_columns(header_line, header, required=("frequency_Hz",))
        names = [name for name in header if name != "frequency_Hz"]
        for name in names:
            if not (name.startswith("H") and name.endswith(("_re", "_im")) and len(name) > 4):
                rule = "unknown column: expected frequency_Hz, then Hk_re and Hk_im per point"
                raise CaseError(f"line {header_line}, column {name}", name, rule)
        prefixes = list(dict.fromkeys(name.rsplit("_", 1)[0] for name in names))  # header order
        for point in prefixes:
            check_columns(header_line, header, required=(f"{point}_re", f"{point}_im"))
        if not prefixes:
            rule = "required: give Hk_re and Hk_im columns for at least one response point"
            raise CaseError(f"line {header_line}, column H1_re", rule=rule)
        table = numeric_table(header, rows)
        frequency = table["frequency_Hz"]
        _check_axis(frequency, "column frequency_Hz")
        frf = np.array([table[p + "_re"] + 1j * table[p + "_im"] for p in prefixes])
    except CaseError as err:
        raise err.with_path(path) from None
    points_mm = None if points is None else _coordinates(points, [p[1:] for p in prefixes], path)
    return FRFData(frequency, frf, points_mm, source=path)


def _coordinates(points_path, names: list[str], path: str) -> np.ndarray:
    """(x, y) in mm of the named FRF points, from the points file (matched by name)."""
    given, xy = read_points(points_path)
    points_path = os.fspath(points_path)
    for name in names:
        if name not in given:
            rule = f"no row for the point of columns H{name}_re, H{name}_im of {path}"
            raise CaseError("column point", name, rule, path=points_path)
    for name in given:
        if name not in names:
            rule = f"{path} has no columns H{name}_re, H{name}_im for this point"
            raise CaseError("column point", name, rule, path=points_path)
    return xy[[given.index(name) for name in names]]
