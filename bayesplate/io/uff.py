"""Measured modes from a Universal File (UFF), as exported by modal software.

Dataset 55 (data at nodes) per mode with its frequency and its response at each node,
dataset 15 or 2411 (node coordinates) and optionally dataset 164 (units). Read with
``pyuff``. Every problem raises :class:`~bayesplate.io.errors.CaseError`, one line naming
the file, the dataset and record, the value and the rule.
"""

from __future__ import annotations

import logging
import math
import numbers
import os

import numpy as np
import pyuff

from .errors import CaseError
from .modal_data import ModalData

__all__ = ["read_uff_modes"]

logger = logging.getLogger(__name__)

# A plate lies in a plane z = const of the test frame; nodes off that plane by more than this
# fraction of the in-plane extent mean another orientation (shapes would not be out-of-plane).
# 5 % leaves room for digitised geometry and nodes on either face of a thick plate.
_PLANE_TOLERANCE = 0.05
_COORDINATE_DIGITS = 12  # significant digits kept after unit conversion (drops 0.1 * 3 noise)


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
    return {
        "key": key,
        "frequency": frequency,
        "damping": damping,
        "load_case": load_case,
        "values": values,
    }


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
