"""Tests of the importers in bayesplate.io and `bayesplate import`: test files -> case files."""

import math
import re
import string
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
import pyuff
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayesplate.cli import main
from bayesplate.io import (
    CaseError,
    ModalData,
    bundled_case_path,
    bundled_plate_names,
    bundled_plate_path,
    case_from_modal_data,
    load_case,
    read_frequency_csv,
    read_modal_data,
    write_case,
)
from bayesplate.io.uff import read_uff_modes
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.plate.model import PlateModel

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

try:  # the package's MAC once bayesplate.matching.pairing is committed
    from bayesplate.matching.pairing import mac_matrix
except ImportError:  # pragma: no cover

    def mac_matrix(A, B):
        """MAC between the columns of A (n, p) and B (n, q)."""
        return (A.T @ B) ** 2 / np.outer(np.sum(A * A, 0), np.sum(B * B, 0))


PROPERTY = settings(
    max_examples=50,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
FREDERIKSEN_HZ = [
    1121.4,
    2795.4,
    2971.5,
    3590.6,
    3633.1,
    5947.5,
    7655.1,
    7671.4,
    8073.0,
    8431.8,
    10212,
    10281,
    14007,
    14048,
]
PLATE_SHEET = bundled_plate_path("frederiksen_plate")


def run_import(capsys, test, plate, out, *extra):
    """`bayesplate import` through cli.main: (exit status, stdout, stderr)."""
    status = main(["import", str(test), "--plate", str(plate), "-o", str(out), *extra])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def assert_refused(status, err, out_path, *names):
    """Exit status 2, one error line naming every one of `names`, no output file."""
    assert status == 2
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("bayesplate: error:")]
    assert len(errors) == 1, err
    for name in names:
        assert name in errors[0], (name, errors[0])
    assert not Path(out_path).exists()
    assert not list(Path(out_path).parent.glob(f".{Path(out_path).name}.*"))  # no temp file


def plate_sheet_text(case_name):
    """A bundled case file without its measured frequencies: a plate sheet."""
    text = bundled_case_path(case_name).read_text()
    sheet = re.sub(r"frequency_Hz = \[[^\]]*\]\n", "", text)
    assert sheet != text
    return sheet


# ----------------------------------------------------------------------------- UFF writing


def write_uff(
    path,
    points_mm,
    shapes,
    frequency_Hz,
    *,
    nodes_dataset=15,
    metres=False,
    complex_modes=False,
    order=None,
    labels=None,
):
    """Write modes as modal software exports them: units, nodes, one dataset 55 per mode.

    `shapes` is (p, m); `order` the order in which modes are written; `labels` node labels.
    With `metres`, coordinates are in m and a dataset 164 says so (SI, length factor 1).
    With `complex_modes`, each mode is exported as a complex mode (analysis type 3) with
    2 % damping and an arbitrary phase.
    """
    points_mm = np.asarray(points_mm, dtype=float)
    p, m = np.shape(shapes)
    labels = np.arange(1, p + 1) if labels is None else np.asarray(labels)
    order = range(m) if order is None else order
    scale = 1e-3 if metres else 1.0
    sets = []
    if metres:
        units = dict(length=1.0, force=1.0, temp=1.0, temp_offset=273.15)  # SI: 1 unit = 1 m
        sets.append(pyuff.prepare_164(units_code=1, units_description="SI", temp_mode=1, **units))
    prepare = pyuff.prepare_15 if nodes_dataset == 15 else pyuff.prepare_2411
    sets.append(
        prepare(
            node_nums=[int(v) for v in labels],
            def_cs=[0] * p,
            disp_cs=[0] * p,
            color=[0] * p,
            x=[float(v) for v in points_mm[:, 0] * scale],
            y=[float(v) for v in points_mm[:, 1] * scale],
            z=[0.0] * p,
        )
    )
    for number, i in enumerate(order, start=1):
        common = dict(
            model_type=1,
            id1="NONE",
            id2="NONE",
            id3="NONE",
            id4="NONE",
            id5="NONE",
            data_ch=2,
            spec_data_type=8,
            n_data_per_node=3,
            node_nums=labels,
            load_case=1,
            mode_n=number,
        )
        zeros = np.zeros(p)
        if complex_modes:
            omega, zeta = 2 * np.pi * frequency_Hz[i], 0.02
            eig = complex(-zeta * omega, omega * np.sqrt(1 - zeta**2))
            phase = np.exp(1j * (0.3 + 0.7 * number))
            z = shapes[:, i] * phase
            sets.append(
                pyuff.prepare_55(
                    analysis_type=3,
                    data_type=5,
                    r1=zeros + 0j,
                    r2=zeros + 0j,
                    r3=z,
                    eig=eig,
                    modal_a=0j,
                    modal_b=0j,
                    **common,
                )
            )
        else:
            sets.append(
                pyuff.prepare_55(
                    analysis_type=2,
                    data_type=2,
                    r1=zeros,
                    r2=zeros,
                    r3=shapes[:, i],
                    freq=float(frequency_Hz[i]),
                    modal_m=1.0,
                    modal_damp_vis=0.01,
                    modal_damp_his=0.0,
                    **common,
                )
            )
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    return path


@pytest.fixture(scope="module")
def plate1_modes():
    """Ten computed modes of plate1 and w at a 9 x 5 grid of points (mm), shape (45, 10)."""
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    result = model.solve(stiffness_from_engineering(case.reference), 10)
    x, y = np.meshgrid(np.linspace(0, 200, 9), np.linspace(0, 100, 5))
    points_mm = np.column_stack([x.ravel(), y.ravel()])
    w = model.interpolation(points_mm * 1e-3, "w") @ result.vectors
    return result.frequency_Hz, points_mm, np.asarray(w)


# ----------------------------------------------------------------------------- UFF round trip


@pytest.mark.parametrize(
    "variant",
    [
        dict(nodes_dataset=15, metres=False, complex_modes=False),
        dict(nodes_dataset=2411, metres=True, complex_modes=True),
    ],
    ids=["ds15-mm-normal-modes", "ds2411-SI-complex-modes"],
)
def test_uff_round_trip(tmp_path, capsys, plate1_modes, variant, rng):
    frequency, points_mm, w = plate1_modes
    order = rng.permutation(len(frequency))  # modal software need not sort its modes
    labels = 1000 + 7 * rng.permutation(len(points_mm))  # node labels are labels, not indices
    uff = write_uff(
        tmp_path / "test.uff", points_mm, w, frequency, order=order, labels=labels, **variant
    )
    sheet = tmp_path / "plate1_sheet.toml"
    sheet.write_text(plate_sheet_text("plate1"))
    out = tmp_path / "case.toml"

    status, stdout, _ = run_import(capsys, uff, sheet, out)

    assert status == 0
    assert stdout.splitlines() == [f"10 modes, 45 points from {uff} -> {out}"]
    case = load_case(out)
    # dataset 55 record 8 is written as %13.5e: 6 significant digits, so each frequency
    # (or each part of a complex eigenvalue, hence |lambda|) is within half a unit in the
    # 6th digit, 5e-6 relative
    np.testing.assert_allclose(case.measured.frequency_Hz, frequency, rtol=5e-6, atol=0)
    # grid coordinates (multiples of 25 mm) are exact in both 13.5E (ds 15) and 25.16e
    # (ds 2411, m), and the conversion to mm is rounded to 12 digits: the file has them exactly
    written = tomllib.loads(out.read_text())["measured"]["points_mm"]
    np.testing.assert_array_equal(written, points_mm)
    np.testing.assert_allclose(case.measured.points, points_mm * 1e-3, rtol=1e-15)
    mac = mac_matrix(case.measured.shapes.T, w)
    assert np.all(np.diag(mac) > 0.99), np.diag(mac)
    np.testing.assert_array_equal(mac.argmax(axis=1), np.arange(len(frequency)))
    plate1 = load_case(bundled_case_path("plate1"))
    assert case.plate == plate1.plate and case.prior == plate1.prior
    assert case.mesh == plate1.mesh
    np.testing.assert_array_equal(case.reference, plate1.reference)
    np.testing.assert_allclose(case.measured.sigma_Hz, 0.01 * case.measured.frequency_Hz)


def test_uff_reader_details(tmp_path, plate1_modes):
    frequency, points_mm, w = plate1_modes
    uff = write_uff(tmp_path / "t.unv", points_mm, w[:, :3], frequency[:3], complex_modes=True)
    modal = read_modal_data(uff)
    assert isinstance(modal, ModalData) and modal.size == 3 and modal.n_points == 45
    # damping ratio -Re(lambda)/|lambda| of the 2 % written, to the 6 digits of the file
    np.testing.assert_allclose(modal.damping, 0.02, rtol=1e-4)
    # a complex mode is realised by a rotation: the real computed shape up to scale
    for i in range(3):
        ratio = modal.shapes[i] / w[:, i]
        big = np.abs(w[:, i]) > 1e-3 * np.abs(w[:, i]).max()
        np.testing.assert_allclose(ratio[big], ratio[big][0], rtol=1e-4)
    assert modal.notes == ("no units dataset 164: node coordinates taken as mm",)


def test_uff_nodes_left_out_of_a_mode_are_zero(tmp_path):
    points = [[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]]
    uff = write_uff(tmp_path / "t.uff", points, np.array([[1.0], [2.0], [3.0]]), [50.0])
    sets = pyuff.UFF(str(uff)).read_sets()
    mode = sets[1]
    for key in ("node_nums", "r1", "r2", "r3"):
        mode[key] = np.asarray(mode[key])[:2]  # node 3 left out (all-zero record)
    second = dict(
        sets[1],
        mode_n=2,
        freq=60.0,
        node_nums=np.array([3]),
        r1=np.zeros(1),
        r2=np.zeros(1),
        r3=np.array([4.0]),
    )
    pyuff.UFF(str(tmp_path / "u.uff")).write_sets([sets[0], mode, second], mode="overwrite")
    modal = read_uff_modes(tmp_path / "u.uff")
    np.testing.assert_array_equal(modal.shapes, [[1.0, 2.0, 0.0], [0.0, 0.0, 4.0]])
    np.testing.assert_array_equal(modal.points_mm, [[0, 0], [10, 0], [10, 5]])


def test_uff_without_nodes_imports_frequencies(tmp_path, capsys, caplog):
    uff = write_uff(tmp_path / "t.uff", [[0.0, 0.0]], np.array([[1.0, 1.0]]), [200.0, 100.0])
    text = uff.read_text()
    start = text.index("    15\n") - 7
    end = text.index("    -1\n", start + 7) + 7
    uff.write_text(text[:start] + text[end:])  # drop dataset 15
    modal = read_uff_modes(uff)
    np.testing.assert_array_equal(modal.frequency_Hz, [100.0, 200.0])
    assert modal.shapes is None and modal.points_mm is None
    assert "no node coordinates" in caplog.text
    status, stdout, _ = run_import(capsys, uff, PLATE_SHEET, tmp_path / "c.toml")
    assert status == 0 and stdout.startswith("2 modes, 0 points")
    assert "no node coordinates" in (tmp_path / "c.toml").read_text()


def malformed_uff(tmp_path, kind):
    points = [[0.0, 0.0], [50.0, 0.0], [50.0, 25.0]]
    shapes = np.array([[1.0, -1.0], [0.5, 2.0], [-1.0, 1.0]])
    path = tmp_path / "bad.uff"
    if kind == "missing file":
        return path
    write_uff(path, points, shapes, [300.0, 500.0])
    text = path.read_text()
    if kind == "empty":
        text = ""
    elif kind == "not a universal file":
        text = "frequency_Hz\n300\n"
    elif kind == "frequency response":
        text = text.replace("         1         2         2", "         1         5         2")
    elif kind == "scalar data":
        text = text.replace("         1         2         2", "         1         2         1")
    elif kind == "nan frequency":
        text = text.replace("  3.00000e+02", "          nan")
    elif kind == "node without coordinates":
        text = re.sub(r"^         3$", "         9", text, flags=re.M)
    elif kind == "nan shape value":
        text = text.replace("  5.00000e-01", "          nan")
    elif kind == "no modes":
        text = text[: text.index("    55")]
    elif kind == "garbled record":
        text = text.replace("  3.00000e+02", "  3.0000xe+02")
    elif kind == "outside the plate":
        text = text.replace("  5.00000E+01  2.50000E+01", "  5.00000E+03  2.50000E+01")
    elif kind == "not planar":
        text = text.replace(
            "  5.00000E+01  2.50000E+01  0.00000E+00", "  5.00000E+01  2.50000E+01  2.00000E+01"
        )
    assert kind in ("empty", "valid") or text != path.read_text(), kind
    path.write_text(text)
    return path


MALFORMED_UFF = {
    "missing file": "cannot read",
    "empty": "no UFF datasets",
    "not a universal file": "no UFF datasets",
    "frequency response": "record 6 field 2 (analysis type)",
    "scalar data": "record 6 field 3 (data characteristic)",
    "nan frequency": "record 8 field 1 (frequency)",
    "node without coordinates": "node 9",
    "nan shape value": "record 10 (node 2)",
    "no modes": "dataset 55",
    "garbled record": "dataset 55 (block 2)",
    "outside the plate": "measured.points_mm[2][0]",
    "not planar": "node coordinates z",
}


@pytest.mark.parametrize("kind", MALFORMED_UFF)
def test_malformed_uff_is_refused_in_one_line(tmp_path, capsys, kind):
    uff = malformed_uff(tmp_path, kind)
    out = tmp_path / "out" / "case.toml"
    status, _, err = run_import(capsys, uff, PLATE_SHEET, out)
    assert_refused(status, err, out, MALFORMED_UFF[kind], "bad.uff")


@PROPERTY
@given(data=st.data())
def test_any_corrupted_uff_gives_modes_or_a_case_error(tmp_path, data):
    path = malformed_uff(tmp_path, "valid")
    lines = path.read_text().splitlines(keepends=True)
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(lines) - 1))
        action = data.draw(st.sampled_from(["delete", "duplicate", "replace", "truncate"]))
        if action == "delete":
            del lines[i]
        elif action == "duplicate":
            lines.insert(i, lines[i])
        elif action == "replace":
            lines[i] = data.draw(st.text(string.printable, max_size=40)) + "\n"
        else:
            lines = lines[:i]
        if not lines:
            break
    path.write_text("".join(lines))
    try:
        modal = read_uff_modes(path)
    except CaseError as err:
        assert "\n" not in str(err) and str(err).startswith(str(path))
    else:
        assert isinstance(modal, ModalData) and modal.size >= 1


# ----------------------------------------------------------------------------- CSV


def test_csv_and_bundled_sheet_rebuild_the_bundled_case(tmp_path, capsys):
    csv_path = tmp_path / "frederiksen.csv"
    csv_path.write_text("# Frederiksen 1997\nfrequency_Hz\n" + "\n".join(map(str, FREDERIKSEN_HZ)))
    out = tmp_path / "case.toml"
    status, stdout, err = run_import(capsys, csv_path, "frederiksen_plate", out)
    assert status == 0, err
    assert stdout == f"14 modes, 0 points from {csv_path} -> {out}\n"
    case, bundled = load_case(out), load_case(bundled_case_path("frederiksen_t300"))
    for field in ("name", "plate", "measured", "prior", "mesh"):
        assert getattr(case, field) == getattr(bundled, field), field
    np.testing.assert_array_equal(case.reference, bundled.reference)
    assert case.source.endswith("; measured data imported from frederiksen.csv")
    long_lines = [line for line in out.read_text().splitlines() if len(line) > 100]
    assert all(line.startswith(("source =", "#")) for line in long_lines)


def test_csv_sigma_and_mode_columns(tmp_path, capsys):
    csv_path = tmp_path / "t.csv"
    csv_path.write_text(
        "mode, frequency_Hz ,sigma_Hz\n1,100,2.5  # comment\n\n3,100,1\n2,250.5,3\n"
    )
    modal = read_frequency_csv(csv_path)
    np.testing.assert_array_equal(modal.frequency_Hz, [100, 100, 250.5])  # ties are legal
    np.testing.assert_array_equal(modal.sigma_Hz, [2.5, 1, 3])
    np.testing.assert_array_equal(modal.mode, [1, 3, 2])
    out = tmp_path / "c.toml"
    assert run_import(capsys, csv_path, PLATE_SHEET, out)[0] == 0
    case = load_case(out)
    np.testing.assert_array_equal(case.measured.sigma_Hz, [2.5, 1, 3])
    np.testing.assert_array_equal(case.measured.mode, [1, 3, 2])
    # a per-frequency sigma and --sigma-rel contradict each other
    status, _, err = run_import(
        capsys, csv_path, PLATE_SHEET, tmp_path / "d.toml", "--sigma-rel", "0.02"
    )
    assert_refused(status, err, tmp_path / "d.toml", "sigma_rel")


def test_csv_sigma_rel_column_and_option(tmp_path, capsys):
    csv_path = tmp_path / "t.csv"
    csv_path.write_text("frequency_Hz,sigma_rel\n100,0.02\n200,0.05\n")
    np.testing.assert_allclose(read_frequency_csv(csv_path).sigma_Hz, [2.0, 10.0])
    plain = tmp_path / "p.csv"
    plain.write_text("frequency_Hz\n100\n200\n")
    out = tmp_path / "c.toml"
    assert run_import(capsys, plain, PLATE_SHEET, out, "--sigma-rel", "0.03")[0] == 0
    np.testing.assert_allclose(load_case(out).measured.sigma_Hz, [3.0, 6.0])
    status, _, err = run_import(
        capsys, plain, PLATE_SHEET, tmp_path / "d.toml", "--sigma-rel", "1.5"
    )
    assert_refused(status, err, tmp_path / "d.toml", "--sigma-rel")


def test_unknown_suffix_and_bundled_sheets(tmp_path):
    with pytest.raises(CaseError, match=r"input = .*: unknown kind of file"):
        read_modal_data(tmp_path / "test.xlsx")
    assert "frederiksen_plate" in bundled_plate_names()
    with pytest.raises(CaseError, match="no such sheet"):
        bundled_plate_path("nope")


def test_write_case_refuses_invalid_text(tmp_path):
    out = tmp_path / "c.toml"
    with pytest.raises(CaseError, match="measured: required key is missing"):
        write_case(out, 'name = "x"\n[plate]\n')
    with pytest.raises(CaseError, match="TOML syntax error"):
        write_case(out, "name = \n")
    assert not out.exists()


def test_written_text_round_trips_awkward_values():
    sheet = tomllib.loads(plate_sheet_text("plate2"))
    sheet["name"] = 'quote " backslash \\ tab \t newline \n del \x7f unicode \u03bd'
    # awkward to print, yet plausible (0.1 Hz to 1 MHz): 0.1 and 1/3 have no short binary form
    modal = ModalData(np.array([0.1, 1 / 3, 123456.789]), source="t.csv")
    text = case_from_modal_data(sheet, modal)
    assert tomllib.loads(text)["name"] == sheet["name"]
    assert tomllib.loads(text)["measured"]["frequency_Hz"] == [0.1, 1 / 3, 123456.789]


# ----------------------------------------------------------------------------- properties

frequencies = st.lists(
    st.floats(0.5, 1e5, allow_nan=False).map(lambda f: float(f"{f:.6g}")), min_size=1, max_size=12
).map(sorted)


@st.composite
def valid_csv(draw):
    """(text, frequencies, column names, rows) of a valid CSV table."""
    f = draw(frequencies)
    columns = ["frequency_Hz"]
    sigma = draw(st.sampled_from([None, "sigma_Hz", "sigma_rel"]))
    if sigma:
        columns.append(sigma)
    if draw(st.booleans()):
        columns.append("mode")
    columns = draw(st.permutations(columns))
    modes = draw(st.permutations(range(1, len(f) + 1)))
    rows = []
    for i, value in enumerate(f):
        cells = {"frequency_Hz": repr(value), "mode": str(modes[i])}
        cells["sigma_Hz"] = repr(draw(st.floats(0.01, 100)))
        cells["sigma_rel"] = repr(draw(st.floats(0.001, 0.5)))
        rows.append([cells[c] for c in columns])
    lines = [",".join(columns)] + [",".join(r) for r in rows]
    if draw(st.booleans()):
        lines.insert(0, "# measured on 2026-11-21")
    return "\n".join(lines) + "\n", f, list(columns), rows


@PROPERTY
@given(table=valid_csv())
def test_valid_csv_imports_exactly(capsys, table):
    text, f, _, _ = table
    with tempfile.TemporaryDirectory() as tmp:
        csv_path, out = Path(tmp, "t.csv"), Path(tmp, "c.toml")
        csv_path.write_text(text)
        status, _, err = run_import(capsys, csv_path, PLATE_SHEET, out)
        assert status == 0, err
        np.testing.assert_array_equal(load_case(out).measured.frequency_Hz, f)


CSV_CORRUPTIONS = [
    "missing column",
    "non-numeric",
    "nan",
    "negative",
    "descending",
    "empty",
    "delimiter",
    "cell count",
]


@PROPERTY
@given(table=valid_csv(), kind=st.sampled_from(CSV_CORRUPTIONS), data=st.data())
def test_corrupted_csv_is_refused_naming_line_and_column(capsys, table, kind, data):
    text, f, columns, rows = table
    first = 2 if text.startswith("#") else 1  # line number of the header
    i = data.draw(st.integers(0, len(rows) - 1))
    column = data.draw(st.sampled_from(columns))
    j = columns.index(column)
    k = columns.index("frequency_Hz")
    sep = ","
    expected = [f"line {first + 1 + i}, column {column}"]
    if kind == "missing column":
        keep = [n for n, c in enumerate(columns) if c != "frequency_Hz"]
        rows = [[r[n] for n in keep] for r in rows]
        columns = [columns[n] for n in keep]
        expected = [f"line {first}, column frequency_Hz", "required column"]
        if not columns:
            expected = ["column frequency_Hz", "empty"]
    elif kind == "non-numeric":
        bad = ["abc", "0x10", "--1", "1e", "1,5"] + ([""] if len(columns) > 1 else [])
        rows[i][j] = data.draw(st.sampled_from(bad))
        if rows[i][j] == "1,5":
            expected = [f"line {first + 1 + i}", "comma-separated values"]
    elif kind == "nan":
        rows[i][j] = data.draw(st.sampled_from(["nan", "NaN", "inf", "-inf"]))
    elif kind == "negative":
        rows[i][j] = data.draw(st.sampled_from(["-1", "0", "-0.0", "-1e3"]))
    elif kind == "descending":
        if len(set(f)) == 1:  # append a lower frequency
            rows.append(list(rows[-1]))
            rows[-1][k] = repr(f[0] / 2)
            if "mode" in columns:
                rows[-1][columns.index("mode")] = str(len(f) + 1)
        else:  # swap the lowest and the highest
            rows[0][k], rows[-1][k] = rows[-1][k], rows[0][k]
        i = next(n for n in range(1, len(rows)) if float(rows[n][k]) < float(rows[n - 1][k]))
        expected = [f"line {first + 1 + i}, column frequency_Hz", "ascending"]
    elif kind == "empty":
        columns, rows = [], []
        expected = ["column frequency_Hz", "empty"]
    elif kind == "delimiter":
        if len(columns) == 1:
            columns, rows = columns + ["sigma_Hz"], [r + ["1.5"] for r in rows]
        sep = data.draw(st.sampled_from([";", "\t", "|"]))
        expected = [f"line {first}", "separated by commas"]
    elif kind == "cell count":
        rows[i].append("1")
        expected = [f"line {first + 1 + i}", "comma-separated values"]
    lines = [sep.join(columns)] + [sep.join(r) for r in rows] if columns else []
    text = ("# measured on 2026-11-21\n" if first == 2 else "") + "\n".join(lines)
    with tempfile.TemporaryDirectory() as tmp:
        csv_path, out = Path(tmp, "t.csv"), Path(tmp, "c.toml")
        csv_path.write_text(text)
        with pytest.raises(CaseError) as info:
            read_frequency_csv(csv_path)
        assert "\n" not in str(info.value)
        status, _, err = run_import(capsys, csv_path, PLATE_SHEET, out)
        assert_refused(status, err, out, "t.csv", *expected)


SHEET_LINES = PLATE_SHEET.read_text().splitlines()
TABLE_OF_LINE = {}
_table = ""
for _n, _line in enumerate(SHEET_LINES):
    if _line.startswith("["):
        _table = _line[1 : _line.index("]")]
    elif re.match(r"\w+\s*=", _line):
        TABLE_OF_LINE[_n] = _table
ASSIGNMENTS = sorted(TABLE_OF_LINE)
OPTIONAL = {"source", "measured.sigma_rel", "model.mesh"}
SIZES = ["plate.length_mm", "plate.width_mm", "plate.thickness_mm", "plate.density_kg_m3"]
WRONG = {  # a value of another type than the key takes
    int: ['"abc"', "true", "[1, 2]", "{ a = 1 }"],
    float: ['"abc"', "false", "[1.0]", "{ mean = 1 }"],
    str: ["3", "true", '["a"]', "1979-05-27"],
    list: ['"abc"', "true", "5", "{ a = [0] }"],
    dict: ['"abc"', "true", "5", "[1, 2]"],
}


def key_of(n):
    """Dotted key of the assignment on line n of the sheet, and its value as TOML."""
    name, value = (part.strip() for part in SHEET_LINES[n].split("#")[0].split("=", 1))
    table = TABLE_OF_LINE[n]
    return (f"{table}.{name}" if table else name), value


@st.composite
def corrupted_sheet(draw):
    """(sheet text, words the error must contain)."""
    lines = list(SHEET_LINES)
    kind = draw(
        st.sampled_from(["missing", "wrong type", "negative", "nan", "material", "unknown key"])
    )
    if kind == "missing":
        n = draw(st.sampled_from([n for n in ASSIGNMENTS if key_of(n)[0] not in OPTIONAL]))
        del lines[n]
        return lines, [key_of(n)[0], "required key is missing"]
    if kind == "wrong type":
        n = draw(st.sampled_from(ASSIGNMENTS))
        key, value = key_of(n)
        parsed = tomllib.loads(f"v = {value}")["v"]
        new = draw(st.sampled_from(WRONG[type(parsed)]))
        lines[n] = f"{key.split('.')[-1]} = {new}"
        return lines, [key]
    if kind == "negative":
        key = draw(st.sampled_from(SIZES))
        n = next(n for n in ASSIGNMENTS if key_of(n)[0] == key)
        lines[n] = f"{key.split('.')[-1]} = -{key_of(n)[1]}"
        return lines, [key, "positive"]
    if kind == "nan":
        numeric = [
            n
            for n in ASSIGNMENTS
            if key_of(n)[0] not in ("name", "source", "model.mesh", "plate.layup_deg")
        ]
        n = draw(st.sampled_from(numeric))
        key, value = key_of(n)
        nan = draw(st.sampled_from(["nan", "-nan", "inf", "-inf"]))
        if value.startswith("{"):
            entry = draw(st.sampled_from(["mean", "sd"]))
            lines[n] = re.sub(rf"{entry} = [^,}}]+", f"{entry} = {nan}", SHEET_LINES[n])
            return lines, [f"{key}.{entry}"]
        lines[n] = f"{key.split('.')[-1]} = {nan}"
        return lines, [key]
    if kind == "material":  # nu12^2 >= E1/E2: no positive-definite lamina
        table = draw(st.sampled_from(["prior", "reference"]))
        values = tomllib.loads(PLATE_SHEET.read_text())[table]
        e1, e2 = (
            values[k]["mean"] if table == "prior" else values[k] for k in ("E1_GPa", "E2_GPa")
        )
        nu = math.sqrt(e1 / e2) * (1 + draw(st.floats(1e-6, 3)))
        n = next(n for n in ASSIGNMENTS if key_of(n)[0] == f"{table}.nu12")
        lines[n] = (
            f"nu12 = {{ mean = {nu!r}, sd = 0.05 }}" if table == "prior" else f"nu12 = {nu!r}"
        )
        return lines, [f"{table}.nu12", "nu12^2 must be < E1/E2"]
    name = "x_" + draw(st.text(string.ascii_lowercase + "_", min_size=1, max_size=8))
    tables = sorted(set(TABLE_OF_LINE.values()))
    table = draw(st.sampled_from(tables))
    n = min(n for n in ASSIGNMENTS if TABLE_OF_LINE[n] == table)
    lines.insert(n, f"{name} = 1")
    expected = "unknown key" if table != "measured" else "holds only sigma_rel"
    return lines, [f"{table}.{name}" if table else name, expected]


@PROPERTY
@given(sheet=corrupted_sheet())
def test_corrupted_plate_sheet_is_refused_naming_the_key(capsys, sheet):
    lines, expected = sheet
    with tempfile.TemporaryDirectory() as tmp:
        csv_path, sheet_path, out = Path(tmp, "t.csv"), Path(tmp, "sheet.toml"), Path(tmp, "c.toml")
        csv_path.write_text("frequency_Hz\n100\n200\n")
        sheet_path.write_text("\n".join(lines) + "\n")
        with pytest.raises(CaseError) as info:
            case_from_modal_data(sheet_path, read_frequency_csv(csv_path))
        assert "\n" not in str(info.value)
        status, _, err = run_import(capsys, csv_path, sheet_path, out)
        assert_refused(status, err, out, "sheet.toml", *expected)
