"""Fuzzing case files: every key corrupted every way, each refused through `bayesplate`.

Two valid base cases (plate1 with every optional key, and frederiksen_t300 as bundled) are
corrupted at one place: a key missing, of the wrong type, NaN, infinite, negative, huge, tiny,
physically absurd (outside the plausible range), an empty array, unsorted or duplicated
frequencies, unknown keys and tables, a unit renamed in a key; or the file itself truncated,
not UTF-8, not TOML. Each must be refused by ``bayesplate modes`` or ``estimate`` in one line
naming the file and the key (see :func:`test_fuzz_cli.assert_refused_cleanly`).
"""

import datetime
import json
import math
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_fuzz_cli import assert_refused_cleanly, fuzz_settings

from bayesplate.io import CaseError, bundled_case_path, parse_case
from bayesplate.io.checks import PLAUSIBLE_RANGES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


# ----------------------------------------------------------------------------- TOML out


def _key(k):
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (datetime.date, datetime.datetime)):
        return v.isoformat()
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"


def dumps(case):
    """TOML text of a case mapping: scalars first, then one [table] per top-level mapping."""
    lines = [f"{_key(k)} = {_value(v)}" for k, v in case.items() if not isinstance(v, dict)]
    for name, table in case.items():
        if isinstance(table, dict):
            lines.append(f"[{_key(name)}]")
            lines += [f"{_key(k)} = {_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- base cases


def _rich_plate1():
    """plate1 with every optional key: ply thicknesses, sigma_Hz, mode, points, shapes and
    the error scale's prior."""
    case = tomllib.loads(bundled_case_path("plate1").read_text())
    plate, measured = case["plate"], case["measured"]
    plate["layup_deg"] = [0.0, 90.0, 0.0]
    h = plate["thickness_mm"]
    plate["ply_thickness_mm"] = [h / 4, h / 2, h - h / 4 - h / 2]
    f = measured.pop("frequency_Hz")[:5]
    measured.pop("sigma_rel")
    measured["frequency_Hz"] = f
    measured["sigma_Hz"] = [round(0.01 * x, 3) for x in f]
    measured["mode"] = [1, 2, 3, 5, 4]
    measured["points_mm"] = [
        [0.0, 0.0],
        [plate["length_mm"] / 2, plate["width_mm"] / 3],
        [plate["length_mm"], plate["width_mm"]],
    ]
    measured["shapes"] = [[1.0, -0.5, 0.25 * (i + 1)] for i in range(len(f))]
    measured["error_scale"] = {"median": 1.0, "upper95": 3.0}
    case["model"] = {"mesh": [8, 4]}
    return case


BASES = {
    "plate1-full": _rich_plate1(),
    "frederiksen": tomllib.loads(bundled_case_path("frederiksen_t300").read_text()),
}


def test_the_base_cases_are_valid():
    for case in BASES.values():
        parse_case(tomllib.loads(dumps(case)))


def _leaves(node, path=()):
    """Every (path, value) below `node`: tables, keys and list items (not the root)."""
    items = node.items() if isinstance(node, dict) else enumerate(node)
    for k, v in items:
        yield path + (k,), v
        if isinstance(v, (dict, list)):
            yield from _leaves(v, path + (k,))


def _get(case, path):
    for k in path:
        case = case[k]
    return case


def _copy(case):
    return json.loads(json.dumps(case))


def _named(path):
    """The dotted key an error names for `path`, without list indices (a prefix of it)."""
    keys = [k for k in path if isinstance(k, str)]
    return ".".join(keys)


def _is(path, *names):
    keys = [k for k in path if isinstance(k, str)]
    return bool(keys) and keys[-1] in names


OPTIONAL = {
    ("source",),
    ("model",),
    ("model", "mesh"),
    ("plate", "ply_thickness_mm"),
    ("measured", "mode"),
    ("measured", "error_scale"),
    ("reference",),
}
ANGLE_OR_SHAPE = ("layup_deg", "shapes")
MAY_BE_TINY = ("layup_deg", "shapes", "points_mm", "nu12")  # 1e-200 is a legal value there
INTEGERS = ("mode", "mesh")


def _numeric_leaves(case):
    return [p for p, v in _leaves(case) if isinstance(v, (int, float)) and not isinstance(v, bool)]


def _spoil(value, kind):
    """A replacement of `value` of the given kind, or None if the kind does not apply."""
    if kind == "nan":
        return math.nan
    if kind == "inf":
        return math.inf
    if kind == "-inf":
        return -math.inf
    if kind == "huge":
        return 10**15 if isinstance(value, int) else 1e200
    if kind == "tiny":
        return 1e-200
    if kind == "negative":
        return -abs(value) - 1.5
    raise AssertionError(kind)


@st.composite
def value_corruption(draw):
    """(base name, case, path, expected words): one numeric value spoilt."""
    base = draw(st.sampled_from(sorted(BASES)))
    case = _copy(BASES[base])
    kind = draw(st.sampled_from(["nan", "inf", "-inf", "huge", "tiny", "negative"]))
    paths = _numeric_leaves(case)
    if kind == "negative":
        paths = [p for p in paths if not _is(p, *ANGLE_OR_SHAPE)]
    if kind == "tiny":
        paths = [p for p in paths if not _is(p, *MAY_BE_TINY) and not _is(p, *INTEGERS)]
        paths = [p for p in paths if not (p[0] == "prior" and p[1] == "nu12" and p[2] == "mean")]
    if kind == "huge":  # an unchanged largest amplitude keeps a shapes row legal
        paths = [p for p in paths if not _is(p, "shapes")]
    path = draw(st.sampled_from(paths))
    parent = _get(case, path[:-1])
    parent[path[-1]] = _spoil(parent[path[-1]], kind)
    return base, case, path, [_named(path)]


WRONG_TYPES = ["abc", True, [1.0], {"a": 1}, ["x"], datetime.date(2026, 11, 25), ""]


@st.composite
def type_corruption(draw):
    """A key, table or list item of another type than the format says."""
    base = draw(st.sampled_from(sorted(BASES)))
    case = _copy(BASES[base])
    path, value = draw(st.sampled_from(list(_leaves(case))))
    if isinstance(value, str):
        options = [3, 1.5, True, ["a"], {"a": "b"}]
    elif isinstance(value, list):
        options = ["abc", 5, 2.5, True, {"a": [0]}]
    elif isinstance(value, dict):
        options = ["abc", 5, True, [1, 2]]
    else:
        options = [w for w in WRONG_TYPES if not (isinstance(value, float) and w == [1.0])]
        if _is(path, *INTEGERS):
            options.append(2.5)  # mode and mesh want whole numbers
    if path == ("source",):
        options = [o for o in options if not isinstance(o, str)]
    new = draw(st.sampled_from(options))
    _get(case, path[:-1])[path[-1]] = new
    return base, case, path, [_named(path) or "case"]


@st.composite
def structure_corruption(draw):
    """Missing keys, empty arrays and tables, unknown keys, unit spellings, bad frequencies."""
    base = draw(st.sampled_from(sorted(BASES)))
    case = _copy(BASES[base])
    kind = draw(
        st.sampled_from(
            ["missing", "empty", "unknown key", "unit", "unsorted", "duplicated", "absurd"]
        )
    )
    keyed = [p for p, _ in _leaves(case) if isinstance(p[-1], str)]
    if kind == "missing":
        path = draw(st.sampled_from([p for p in keyed if p not in OPTIONAL]))
        del _get(case, path[:-1])[path[-1]]
        expected = _named(path)
        if _is(path, "points_mm", "shapes"):  # the other of the pair is named
            expected = "measured."
        return base, case, path, [expected]
    if kind == "empty":
        lists = [p for p, v in _leaves(case) if isinstance(v, list)]
        tables = [p for p, v in _leaves(case) if isinstance(v, dict) and p != ("model",)]
        path = draw(st.sampled_from(lists + tables))
        _get(case, path[:-1])[path[-1]] = [] if path in lists else {}
        return base, case, path, [_named(path)]
    if kind == "unknown key":
        tables = [()] + [p for p, v in _leaves(case) if isinstance(v, dict)]
        where = draw(st.sampled_from(tables))
        name = draw(st.sampled_from(["x", "extra", "E1_gpa", "comment", "mesh_size", "Hz"]))
        value = draw(st.sampled_from([1, "a", {"table": 1}, [1, 2]]))
        _get(case, where)[name] = value
        return base, case, where + (name,), [_named(where + (name,))]
    if kind == "unit":
        spelled = [p for p in keyed if re.search(r"_(mm|Hz|GPa|kg_m3|deg)$", p[-1])]
        path = draw(st.sampled_from(spelled))
        stem, unit = re.match(r"(.*?)_(mm|Hz|GPa|kg_m3|deg)$", path[-1]).groups()
        other = draw(st.sampled_from(["m", "cm", "in", "kHz", "MPa", "Pa", "g_cm3", "rad", ""]))
        new = f"{stem}_{other}" if other else stem
        table = _get(case, path[:-1])
        table[new] = table.pop(path[-1])
        return base, case, path[:-1] + (new,), [_named(path[:-1] + (new,))]
    f = case["measured"]["frequency_Hz"]
    if kind == "unsorted":
        i = draw(st.integers(0, len(f) - 2))
        j = draw(st.integers(i + 1, len(f) - 1).filter(lambda j: f[j] != f[i]))
        f[i], f[j] = f[j], f[i]
        return base, case, ("measured", "frequency_Hz"), ["measured.frequency_Hz", "ascending"]
    if kind == "duplicated":
        if "mode" in case["measured"]:  # a mode index given twice
            mode = case["measured"]["mode"]
            i, j = draw(
                st.sampled_from(
                    [(i, j) for i in range(len(mode)) for j in range(len(mode)) if i != j]
                )
            )
            mode[j] = mode[i]
            return base, case, ("measured", "mode"), ["measured.mode", "distinct"]
        i = draw(st.integers(0, len(f) - 1))  # a frequency given twice, out of order
        f.append(f[i] if f[i] != f[-1] else f[0])
        return base, case, ("measured", "frequency_Hz"), ["measured.frequency_Hz", "ascending"]
    return absurd_value(draw, base, case)


#: quantity of the plausible-range table -> where it sits in a case; absurd values scale
#: whole lists (one spoilt frequency would break the order first).
PLACES = {
    "length_mm": [("plate", "length_mm")],
    "width_mm": [("plate", "width_mm")],
    "thickness_mm": [("plate", "thickness_mm")],
    "density_kg_m3": [("plate", "density_kg_m3")],
    "frequency_Hz": [("measured", "frequency_Hz")],
    "sigma_Hz": [("measured", "sigma_Hz")],
    "sigma_rel": [("measured", "sigma_rel")],
    "layup_deg": [("plate", "layup_deg")],
    "modulus_GPa": [
        (t, k, "mean")
        for t in ["prior"]
        for k in ("E1_GPa", "E2_GPa", "G12_GPa", "G13_GPa", "G23_GPa")
    ]
    + [("reference", k) for k in ("E1_GPa", "E2_GPa", "G12_GPa", "G13_GPa", "G23_GPa")],
    "modulus_sd_GPa": [
        ("prior", k, "sd") for k in ("E1_GPa", "E2_GPa", "G12_GPa", "G13_GPa", "G23_GPa")
    ],
    "nu12": [("prior", "nu12", "mean"), ("reference", "nu12")],
    "nu12_sd": [("prior", "nu12", "sd")],
    "shape_amplitude": [("measured", "shapes")],
}


def absurd_value(draw, base, case):
    """A value outside the plausible range of its quantity: a unit mix-up or a typo."""
    places = [(q, p) for q, ps in PLACES.items() for p in ps if _present(case, p)]
    quantity, path = draw(st.sampled_from(places))
    low, high, _, _ = PLAUSIBLE_RANGES[quantity]
    up = draw(st.booleans()) or quantity in ("nu12", "layup_deg") or low <= 0
    if quantity == "layup_deg":
        new = draw(st.sampled_from([361.0, -400.0, 1e4]))
    elif quantity == "nu12":
        new = draw(st.sampled_from([high * 1.01, 30.0, -1.5, -30.0]))
    else:
        factor = draw(st.sampled_from([1e3, 1e6, 1e9, 1e12]))
        new = high * factor if up else low / factor
    parent = _get(case, path[:-1])
    old = parent[path[-1]]
    if quantity == "shape_amplitude":
        parent[path[-1]] = [[new * x for x in row] for row in old]
    elif quantity == "layup_deg":
        parent[path[-1]] = [new] + old[1:]
    elif isinstance(old, list):  # scale the whole list, keeping its order and signs
        scale = max(old) if up else min(old)
        parent[path[-1]] = [new * x / scale for x in old]
    else:
        parent[path[-1]] = new
    if quantity == "nu12" and new > 0:  # the lamina's own rule nu12^2 < E1/E2 comes first
        return base, case, path, [_named(path)]
    return base, case, path, [_named(path), "plausible range"]


def _present(case, path):
    try:
        _get(case, path)
    except (KeyError, IndexError, TypeError):
        return False
    return True


def _run(ledger, corruption, command=None):
    base, case, path, expected = corruption
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp, "case.toml")
        file.write_text(dumps(case), encoding="utf-8")
        with pytest.raises(CaseError):  # the reader itself refuses it, not only the CLI
            parse_case(tomllib.loads(file.read_text(encoding="utf-8")))
        out = Path(tmp, "out.json")
        argv = [command or "modes", file, "--json", out]
        if command == "estimate":
            argv += ["--method", "B", "--max-iter", "1"]
        assert_refused_cleanly(ledger, argv, [file], [out], ["case.toml", *expected])


@fuzz_settings(200)
@given(corruption=value_corruption())
def test_a_spoilt_value_is_refused_naming_the_key(fuzz_ledger, corruption):
    _run(fuzz_ledger, corruption)


@fuzz_settings(150)
@given(corruption=type_corruption(), command=st.sampled_from(["modes", "estimate"]))
def test_a_value_of_the_wrong_type_is_refused_naming_the_key(fuzz_ledger, corruption, command):
    _run(fuzz_ledger, corruption, command)


@fuzz_settings(250)
@given(corruption=structure_corruption(), command=st.sampled_from(["modes", "estimate"]))
def test_a_broken_structure_is_refused_naming_the_key(fuzz_ledger, corruption, command):
    _run(fuzz_ledger, corruption, command)


@pytest.mark.parametrize(
    ("key", "value", "range_"),
    [
        ("density_kg_m3", "1e30", "10 to 25,000 kg/m^3"),
        ("length_mm", "1e9", "0.01 to 10,000 mm"),
        ("thickness_mm", "3.36e-9", "0.0001 to 1,000 mm"),
        ("density_kg_m3", "1.537", "10 to"),
    ],
)
def test_the_issue_s_absurd_density_is_refused_with_its_range(
    fuzz_ledger, tmp_path, key, value, range_
):
    text = bundled_case_path("frederiksen_t300").read_text()
    text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
    case = tmp_path / "case.toml"
    case.write_text(text)
    line = assert_refused_cleanly(
        fuzz_ledger,
        ["estimate", case, "--method", "B"],
        [case],
        [],
        [f"plate.{key} = ", "outside the plausible range " + range_],
    )
    assert str(case) in line


# ----------------------------------------------------------------------------- whole files


@fuzz_settings(120)
@given(data=st.data())
def test_a_damaged_file_is_refused_naming_the_file(fuzz_ledger, data):
    base = data.draw(st.sampled_from(sorted(BASES)))
    text = dumps(BASES[base]).encode()
    kind = data.draw(
        st.sampled_from(
            ["truncated", "not utf-8", "binary", "syntax", "empty", "bom", "bytes flipped"]
        )
    )
    if kind == "truncated":
        cut = data.draw(st.integers(0, len(text) - 1))
        text = text[:cut]
    elif kind == "not utf-8":
        at = data.draw(st.integers(0, len(text)))
        text = text[:at] + data.draw(st.sampled_from([b"\xff", b"\xc3(", b"\xe9t\xe9"])) + text[at:]
    elif kind == "binary":
        text = data.draw(st.binary(min_size=1, max_size=64))
    elif kind == "syntax":
        lines = text.split(b"\n")
        i = data.draw(st.integers(0, len(lines) - 2))
        lines[i] = lines[i] + data.draw(st.sampled_from([b" = 1", b" ]", b"[", b'"', b" x"]))
        text = b"\n".join(lines)
    elif kind == "empty":
        text = data.draw(st.sampled_from([b"", b"\n", b"   ", b"# only a comment\n"]))
    elif kind == "bom":
        text = b"\xef\xbb\xbf" + text
    else:
        i = data.draw(st.integers(0, len(text) - 1))
        text = text[:i] + bytes([text[i] ^ data.draw(st.integers(1, 255))]) + text[i + 1 :]
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp, "case.toml")
        file.write_bytes(text)
        try:  # a damage that leaves a valid case (a cut after the last key) is not one
            parse_case(tomllib.loads(text.decode("utf-8")))
        except (CaseError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            pass
        else:
            assert kind in ("truncated", "bytes flipped"), kind
            return
        out = Path(tmp, "out.json")
        assert_refused_cleanly(
            fuzz_ledger, ["modes", file, "--json", out], [file], [out], ["case.toml"]
        )


def test_a_numpy_free_check_of_the_writer():
    """The fuzzer's TOML writer round-trips what it writes (else corruptions are not real)."""
    for case in BASES.values():
        assert tomllib.loads(dumps(case)) == case
    odd = {"a": [math.inf, -math.inf], "b": {"c": 'q"\\\n\u03bd'}, "d": datetime.date(2026, 1, 2)}
    back = tomllib.loads(dumps(odd))
    assert back["a"] == [math.inf, -math.inf] and back["b"] == odd["b"] and back["d"] == odd["d"]
    assert np.isnan(tomllib.loads(dumps({"n": math.nan}))["n"])
