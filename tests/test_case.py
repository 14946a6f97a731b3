"""Tests of bayesplate.io's case files: reading, validating and converting case files."""

import copy
import math
import pickle

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayesplate.io import (
    Case,
    CaseError,
    Measurement,
    Plate,
    bundled_case_names,
    bundled_case_path,
    check_engineering_constants,
    engineering_from_si,
    engineering_to_si,
    load_case,
    parse_case,
)
from bayesplate.quantities import ENGINEERING_KEYS, ENGINEERING_NAMES

BUNDLED = ["angleply", "badiane_spruce_5R", "crossply", "frederiksen_t300", "plate1", "plate2"]
DELETE = object()


def valid_case() -> dict:
    """A small valid case mapping, as tomllib would return it, using every optional key."""
    return {
        "name": "test plate",
        "source": "made up",
        "plate": {
            "length_mm": 100,
            "width_mm": 50,
            "thickness_mm": 3.0,
            "density_kg_m3": 1500,
            "layup_deg": [0, 90, 0],
            "ply_thickness_mm": [1.0, 1.0, 1.0],
        },
        "measured": {
            "frequency_Hz": [100.0, 200.0, 200.0, 300.5],
            "sigma_Hz": [1.0, 2.0, 2.0, 3.0],
            "mode": [1, 2, 3, 5],
            "points_mm": [[0, 0], [100, 50], [25.5, 10]],
            "shapes": [[1, 0, 0.5], [0, 1, 0.5], [1, 1, 0], [-1, 0.2, 0.3]],
        },
        "prior": {
            "E1_GPa": {"mean": 144, "sd": 15},
            "E2_GPa": {"mean": 16.5, "sd": 3.5},
            "nu12": {"mean": 0.30, "sd": 0.05},
            "G12_GPa": {"mean": 6, "sd": 1.5},
            "G13_GPa": {"mean": 6, "sd": 1.5},
            "G23_GPa": {"mean": 4, "sd": 1.5},
        },
        "model": {"mesh": [10, 5]},
        "reference": {
            "E1_GPa": 113.0,
            "E2_GPa": 8.5,
            "nu12": 0.323,
            "G12_GPa": 4.45,
            "G13_GPa": 4.43,
            "G23_GPa": 2.97,
        },
    }


def corrupted(where: tuple, value) -> dict:
    """Return a valid case with the entry at key path `where` replaced (or deleted)."""
    data = valid_case()
    node = data
    for step in where[:-1]:
        node = node[step]
    if value is DELETE:
        del node[where[-1]]
    else:
        node[where[-1]] = value
    return data


def assert_one_line_error(err: CaseError, key: str) -> None:
    message = str(err)
    assert "\n" not in message
    assert key in message
    assert err.key == key


# ----------------------------------------------------------------------------- bundled cases


def test_bundled_case_names():
    assert bundled_case_names() == BUNDLED


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_cases_load(name):
    case = load_case(bundled_case_path(name))
    assert isinstance(case, Case)
    assert case.path == str(bundled_case_path(name))
    # the paper's cases and Frederiksen's plate have 14 frequencies, the spruce plate 10
    assert case.measured.frequency_Hz.shape == ((10,) if name == "badiane_spruce_5R" else (14,))
    # Every bundled case uses sigma_rel = 0.01.
    np.testing.assert_allclose(case.measured.sigma_Hz, 0.01 * case.measured.frequency_Hz)
    assert case.prior.mean.shape == case.prior.sd.shape == (6,)
    assert case.reference is not None and case.reference.shape == (6,)
    assert case.mesh is not None
    assert len(case.plate.ply_thickness) == len(case.plate.layup_deg)
    assert math.isclose(sum(case.plate.ply_thickness), case.plate.thickness, rel_tol=1e-12)


def test_frederiksen_values_in_si():
    case = load_case(bundled_case_path("frederiksen_t300"))
    plate = case.plate
    # mm -> m and GPa -> Pa are exact up to one rounding: rel_tol 1e-12.
    assert math.isclose(plate.length, 100.1e-3, rel_tol=1e-12)
    assert math.isclose(plate.width, 53.0e-3, rel_tol=1e-12)
    assert math.isclose(plate.thickness, 3.36e-3, rel_tol=1e-12)
    assert plate.density == 1537.0
    assert plate.layup_deg == (0.0,)
    assert plate.ply_thickness == (plate.thickness,)
    f = case.measured.frequency_Hz
    assert f[0] == 1121.4 and f[-1] == 14048.0
    np.testing.assert_allclose(case.measured.sigma_Hz, 0.01 * f, rtol=1e-15)
    assert case.measured.mode is None and case.measured.points is None
    np.testing.assert_allclose(case.prior.mean, [144e9, 16.5e9, 0.30, 6e9, 6e9, 4e9], rtol=1e-12)
    np.testing.assert_allclose(case.prior.sd, [15e9, 3.5e9, 0.05, 1.5e9, 1.5e9, 1.5e9], rtol=1e-12)
    np.testing.assert_allclose(
        case.reference, [113.0e9, 8.50e9, 0.323, 4.45e9, 4.43e9, 2.97e9], rtol=1e-12
    )
    assert case.mesh == (50, 50)
    assert case.name.startswith("T300/epoxy")
    assert "Frederiksen" in case.source


def test_laminate_cases_have_33_equal_plies():
    # the 33-ply readings reproduce Tables 16 and 19 (tests/test_paper_frequencies.py)
    for name in ("crossply", "angleply"):
        plate = load_case(bundled_case_path(name)).plate
        assert len(plate.layup_deg) == 33 and plate.layup_deg[16] == 0
        np.testing.assert_allclose(plate.ply_thickness, 3.3e-3 / 33, rtol=1e-12)


def test_bundled_case_path_unknown_lists_names():
    with pytest.raises(CaseError) as info:
        bundled_case_path("nope")
    message = str(info.value)
    assert "nope" in message and "\n" not in message
    for name in BUNDLED:
        assert name in message


# ----------------------------------------------------------------------------- valid input


def test_valid_case_parses_with_every_option():
    case = parse_case(valid_case())
    assert case.name == "test plate" and case.source == "made up" and case.path is None
    np.testing.assert_allclose(case.plate.ply_thickness, [1e-3] * 3, rtol=1e-12)
    np.testing.assert_array_equal(case.measured.mode, [1, 2, 3, 5])
    assert case.measured.mode.dtype == np.int64
    np.testing.assert_allclose(case.measured.points, [[0, 0], [0.1, 0.05], [0.0255, 0.01]])
    assert case.measured.shapes.shape == (4, 3)
    assert case.mesh == (10, 5)


def test_minimal_case_defaults():
    data = valid_case()
    for key in ("source", "model", "reference"):
        del data[key]
    for key in ("ply_thickness_mm",):
        del data["plate"][key]
    for key in ("mode", "points_mm", "shapes"):
        del data["measured"][key]
    case = parse_case(data)
    assert case.source == "" and case.mesh is None and case.reference is None
    assert case.measured.mode is None and case.measured.shapes is None
    np.testing.assert_allclose(case.plate.ply_thickness, [1e-3] * 3, rtol=1e-12)


def test_equal_frequencies_accepted():
    data = corrupted(("measured", "frequency_Hz"), [100.0, 100.0, 100.0, 100.0])
    case = parse_case(data)
    np.testing.assert_array_equal(case.measured.frequency_Hz, 100.0)


def test_sigma_rel_gives_proportional_sigma():
    data = valid_case()
    del data["measured"]["sigma_Hz"]
    data["measured"]["sigma_rel"] = 0.02
    case = parse_case(data)
    np.testing.assert_allclose(case.measured.sigma_Hz, 0.02 * case.measured.frequency_Hz)


def test_arrays_are_read_only():
    case = parse_case(valid_case())
    for array in (
        case.measured.frequency_Hz,
        case.measured.sigma_Hz,
        case.measured.mode,
        case.measured.points,
        case.measured.shapes,
        case.prior.mean,
        case.prior.sd,
        case.reference,
    ):
        with pytest.raises(ValueError):
            array[0] = 1


def test_case_equality_and_pickle():
    a, b = parse_case(valid_case()), parse_case(valid_case())
    assert a == b
    assert pickle.loads(pickle.dumps(a)) == a
    assert a != parse_case(corrupted(("name",), "other"))


def test_ply_thickness_sum_within_tolerance_accepted():
    # 1e-7 relative is inside the 1e-6 tolerance of the format.
    data = corrupted(("plate", "ply_thickness_mm"), [1.0, 1.0, 1.0000003])
    parse_case(data)


def test_parse_case_does_not_modify_input():
    data = valid_case()
    before = copy.deepcopy(data)
    parse_case(data)
    assert data == before


# ----------------------------------------------------------------------------- corruptions

CORRUPTIONS = [
    # (id, key path in the mapping, new value or DELETE, key named in the error)
    ("missing name", ("name",), DELETE, "name"),
    ("name not str", ("name",), 3, "name"),
    ("empty name", ("name",), "  ", "name"),
    ("source not str", ("source",), ["x"], "source"),
    ("unknown top key", ("extra",), 1, "extra"),
    ("plate not table", ("plate",), [1, 2], "plate"),
    ("missing plate", ("plate",), DELETE, "plate"),
    ("missing length", ("plate", "length_mm"), DELETE, "plate.length_mm"),
    ("typo lenght_mm", ("plate", "lenght_mm"), 100, "plate.lenght_mm"),
    ("string for number", ("plate", "width_mm"), "50", "plate.width_mm"),
    ("bool for number", ("plate", "width_mm"), True, "plate.width_mm"),
    ("negative thickness", ("plate", "thickness_mm"), -3.0, "plate.thickness_mm"),
    ("zero length", ("plate", "length_mm"), 0, "plate.length_mm"),
    ("zero density", ("plate", "density_kg_m3"), 0.0, "plate.density_kg_m3"),
    ("nan width", ("plate", "width_mm"), math.nan, "plate.width_mm"),
    ("inf density", ("plate", "density_kg_m3"), math.inf, "plate.density_kg_m3"),
    ("huge int", ("plate", "length_mm"), 10**400, "plate.length_mm"),
    ("empty layup", ("plate", "layup_deg"), [], "plate.layup_deg"),
    ("layup not list", ("plate", "layup_deg"), 0, "plate.layup_deg"),
    ("nan ply angle", ("plate", "layup_deg"), [0, math.nan, 0], "plate.layup_deg[1]"),
    ("ply count", ("plate", "ply_thickness_mm"), [1.5, 1.5], "plate.ply_thickness_mm"),
    ("ply sum", ("plate", "ply_thickness_mm"), [1.0, 1.0, 1.1], "plate.ply_thickness_mm"),
    ("ply negative", ("plate", "ply_thickness_mm"), [2, -1, 2], "plate.ply_thickness_mm[1]"),
    ("missing measured", ("measured",), DELETE, "measured"),
    ("missing freq", ("measured", "frequency_Hz"), DELETE, "measured.frequency_Hz"),
    ("empty freq", ("measured", "frequency_Hz"), [], "measured.frequency_Hz"),
    (
        "descending freq",
        ("measured", "frequency_Hz"),
        [100.0, 200.0, 150.0, 300.0],
        "measured.frequency_Hz[2]",
    ),
    ("negative freq", ("measured", "frequency_Hz"), [-1, 2, 3, 4], "measured.frequency_Hz[0]"),
    ("zero freq", ("measured", "frequency_Hz"), [0, 2, 3, 4], "measured.frequency_Hz[0]"),
    ("freq string", ("measured", "frequency_Hz"), [1, "2", 3, 4], "measured.frequency_Hz[1]"),
    ("freq inf", ("measured", "frequency_Hz"), [1, 2, 3, math.inf], "measured.frequency_Hz[3]"),
    ("sigma_Hz length", ("measured", "sigma_Hz"), [1.0, 2.0, 3.0], "measured.sigma_Hz"),
    ("sigma_Hz zero", ("measured", "sigma_Hz"), [1.0, 0.0, 1.0, 1.0], "measured.sigma_Hz[1]"),
    ("both sigma keys", ("measured", "sigma_rel"), 0.01, "measured.sigma_rel"),
    ("no sigma key", ("measured", "sigma_Hz"), DELETE, "measured.sigma_rel"),
    ("unknown measured key", ("measured", "frequencies"), [1.0], "measured.frequencies"),
    ("mode length", ("measured", "mode"), [1, 2, 3], "measured.mode"),
    ("mode zero", ("measured", "mode"), [0, 1, 2, 3], "measured.mode[0]"),
    ("mode repeated", ("measured", "mode"), [1, 2, 2, 3], "measured.mode[2]"),
    ("mode float", ("measured", "mode"), [1, 2.0, 3, 4], "measured.mode[1]"),
    ("mode bool", ("measured", "mode"), [1, True, 3, 4], "measured.mode[1]"),
    ("point outside x", ("measured", "points_mm"), [[0, 0], [101, 0], [1, 1]], "points_mm[1][0]"),
    ("point outside y", ("measured", "points_mm"), [[0, 0], [1, 1], [1, -1]], "points_mm[2][1]"),
    ("point not pair", ("measured", "points_mm"), [[0, 0], [1, 1, 1], [1, 1]], "points_mm[1]"),
    ("shapes without points", ("measured", "points_mm"), DELETE, "measured.shapes"),
    ("points without shapes", ("measured", "shapes"), DELETE, "measured.points_mm"),
    (
        "shape row length",
        ("measured", "shapes"),
        [[1, 0, 0.5], [0, 1], [1, 1, 0], [1, 0, 0]],
        "measured.shapes[1]",
    ),
    ("shape rows", ("measured", "shapes"), [[1, 0, 0.5], [0, 1, 1]], "measured.shapes"),
    (
        "shape nan",
        ("measured", "shapes"),
        [[1, 0, 0.5], [0, 1, 1], [1, math.nan, 0], [1, 0, 0]],
        "measured.shapes[2][1]",
    ),
    ("missing prior entry", ("prior", "G23_GPa"), DELETE, "prior.G23_GPa"),
    ("prior entry number", ("prior", "E1_GPa"), 144, "prior.E1_GPa"),
    ("prior unknown key", ("prior", "E3_GPa"), {"mean": 1, "sd": 1}, "prior.E3_GPa"),
    ("prior entry typo", ("prior", "E1_GPa", "std"), 1.0, "prior.E1_GPa.std"),
    ("prior missing sd", ("prior", "E2_GPa", "sd"), DELETE, "prior.E2_GPa.sd"),
    ("prior sd zero", ("prior", "E2_GPa", "sd"), 0, "prior.E2_GPa.sd"),
    ("prior mean str", ("prior", "G12_GPa", "mean"), "6", "prior.G12_GPa.mean"),
    ("prior mean negative", ("prior", "G13_GPa", "mean"), -6, "prior.G13_GPa.mean"),
    ("prior mean nan", ("prior", "nu12", "mean"), math.nan, "prior.nu12.mean"),
    ("impossible nu12", ("prior", "nu12", "mean"), 3.0, "prior.nu12.mean"),
    ("model unknown key", ("model", "nodes"), [1, 2], "model.nodes"),
    ("mesh zero", ("model", "mesh"), [0, 5], "model.mesh[0]"),
    ("mesh too fine", ("model", "mesh"), [10, 401], "model.mesh[1]"),
    ("mesh float", ("model", "mesh"), [10.0, 5], "model.mesh[0]"),
    ("mesh length", ("model", "mesh"), [10], "model.mesh"),
    ("reference missing", ("reference", "G13_GPa"), DELETE, "reference.G13_GPa"),
    ("reference str", ("reference", "E1_GPa"), "113", "reference.E1_GPa"),
    ("reference impossible", ("reference", "nu12"), 4.0, "reference.nu12"),
    ("reference zero", ("reference", "E2_GPa"), 0.0, "reference.E2_GPa"),
]


@pytest.mark.parametrize(
    ("where", "value", "key"),
    [case[1:] for case in CORRUPTIONS],
    ids=[case[0] for case in CORRUPTIONS],
)
def test_corruption_is_refused(where, value, key):
    with pytest.raises(CaseError) as info:
        parse_case(corrupted(where, value))
    message = str(info.value)
    assert "\n" not in message
    assert key in message
    assert info.value.key.endswith(key)


@pytest.mark.parametrize("sigma_rel", [0, -0.01, 1.0, 1.5, "1%", True, math.nan])
def test_sigma_rel_out_of_range(sigma_rel):
    data = valid_case()
    del data["measured"]["sigma_Hz"]
    data["measured"]["sigma_rel"] = sigma_rel
    with pytest.raises(CaseError) as info:
        parse_case(data)
    assert info.value.key == "measured.sigma_rel"


def test_all_zero_shape_row_refused():
    data = corrupted(("measured", "shapes"), [[1, 0, 0.5], [0, 0, 0], [1, 1, 0], [1, 0, 0]])
    with pytest.raises(CaseError) as info:
        parse_case(data)
    assert info.value.key == "measured.shapes[1]"


def test_error_message_format():
    with pytest.raises(CaseError) as info:
        parse_case(corrupted(("plate", "thickness_mm"), -3.0))
    err = info.value
    assert str(err) == "plate.thickness_mm = -3.0: must be a positive number"
    assert (err.key, err.value, err.rule) == (
        "plate.thickness_mm",
        -3.0,
        "must be a positive number",
    )
    assert isinstance(err, ValueError)


def test_unknown_key_suggests_and_lists_allowed():
    with pytest.raises(CaseError) as info:
        parse_case(corrupted(("plate", "lenght_mm"), 100))
    message = str(info.value)
    assert "did you mean length_mm" in message
    assert "width_mm" in message and "ply_thickness_mm" in message


def test_missing_key_message():
    with pytest.raises(CaseError) as info:
        parse_case(corrupted(("plate", "length_mm"), DELETE))
    assert str(info.value) == "plate.length_mm: required key is missing"
    assert info.value.value is CaseError.MISSING


def test_impossible_nu12_rule():
    with pytest.raises(CaseError) as info:
        parse_case(corrupted(("prior", "nu12", "mean"), 3.0))
    assert "nu12^2 must be < E1/E2" in str(info.value)


def test_parse_case_names_the_path():
    with pytest.raises(CaseError) as info:
        parse_case(corrupted(("plate", "width_mm"), -1), path="my.toml")
    assert str(info.value).startswith("my.toml: plate.width_mm = -1:")
    assert info.value.path == "my.toml"


def test_case_error_pickles():
    err = CaseError("a.b[1]", 2.5, "must be smaller", "x.toml")
    again = pickle.loads(pickle.dumps(err))
    assert str(again) == str(err) == "x.toml: a.b[1] = 2.5: must be smaller"
    assert again.value == 2.5


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    where=st.sampled_from([case[1] for case in CORRUPTIONS]),
    junk=st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
        lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=3), inner),
        max_leaves=8,
    ),
)
def test_any_junk_gives_case_or_case_error(where, junk):
    """Whatever a leaf is replaced with, the result is a Case or a one-line CaseError."""
    try:
        parse_case(corrupted(where, junk))
    except CaseError as err:
        assert "\n" not in str(err)
        assert err.key is not None


# ----------------------------------------------------------------------------- files


def write(tmp_path, text: str):
    path = tmp_path / "case.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_load_case_from_file(tmp_path):
    source = bundled_case_path("plate1").read_text(encoding="utf-8")
    path = write(tmp_path, source)
    case = load_case(path)
    assert case.path == str(path)
    assert case == load_case(str(path))  # str and Path give the same case


def test_toml_syntax_error_names_file_and_line(tmp_path):
    path = write(tmp_path, 'name = "x"\n[plate]\nlength_mm = = 3\n')
    with pytest.raises(CaseError) as info:
        load_case(path)
    message = str(info.value)
    assert str(path) in message and "line 3" in message and "\n" not in message
    assert info.value.key is None and info.value.path == str(path)


def test_missing_file(tmp_path):
    path = tmp_path / "absent.toml"
    with pytest.raises(CaseError) as info:
        load_case(path)
    assert str(path) in str(info.value)


def test_binary_file(tmp_path):
    path = tmp_path / "case.toml"
    path.write_bytes(b"\xff\xfe\x00name")
    with pytest.raises(CaseError) as info:
        load_case(path)
    assert str(path) in str(info.value)


def test_file_validation_error_names_file(tmp_path):
    source = bundled_case_path("plate1").read_text(encoding="utf-8")
    path = write(tmp_path, source.replace("length_mm = 200", "lenght_mm = 200"))
    with pytest.raises(CaseError) as info:
        load_case(path)
    assert str(info.value).startswith(f"{path}: plate.lenght_mm = 200: unknown key")


# ----------------------------------------------------------------------------- conversions


def test_engineering_units_round_trip():
    values = np.array([[144, 16.5, 0.3, 6, 6, 4], [1, 2, 0.1, 3, 4, 5]], dtype=float)
    si = engineering_to_si(values)
    np.testing.assert_allclose(si[0], [144e9, 16.5e9, 0.3, 6e9, 6e9, 4e9], rtol=1e-15)
    np.testing.assert_allclose(engineering_from_si(si), values, rtol=1e-15)
    with pytest.raises(ValueError):
        engineering_to_si([1.0, 2.0, 3.0])


def test_names_and_keys_agree():
    assert len(ENGINEERING_NAMES) == len(ENGINEERING_KEYS) == 6
    for name, key in zip(ENGINEERING_NAMES, ENGINEERING_KEYS, strict=True):
        assert key.split("_")[0] == name


@pytest.mark.parametrize(
    ("values", "key"),
    [
        ([0, 1e10, 0.3, 5e9, 5e9, 3e9], "prior.E1"),
        ([1e11, 1e10, 0.3, 5e9, -5e9, 3e9], "prior.G13"),
        ([1e11, 1e10, math.inf, 5e9, 5e9, 3e9], "prior.nu12"),
        # E1/E2 = 2, so |nu12| must stay below sqrt(2).
        ([2e10, 1e10, -1.5, 5e9, 5e9, 3e9], "prior.nu12"),
    ],
)
def test_check_engineering_constants_refuses(values, key):
    with pytest.raises(CaseError) as info:
        check_engineering_constants(values)
    assert info.value.key == key


def test_check_engineering_constants_accepts_and_names_prefix():
    check_engineering_constants([2e10, 1e10, -1.4, 5e9, 5e9, 3e9])  # auxetic but possible
    with pytest.raises(CaseError) as info:
        check_engineering_constants([1, 1, 2, 1, 1, 1], key_prefix="estimate")
    assert info.value.key == "estimate.nu12"


# ----------------------------------------------------------------------------- built in code


def test_with_prior_validates():
    case = load_case(bundled_case_path("plate1"))
    mean = case.prior.mean * 1.1
    new = case.with_prior(mean, case.prior.sd)
    np.testing.assert_allclose(new.prior.mean, mean)
    assert new.measured is case.measured
    with pytest.raises(CaseError) as info:
        case.with_prior(mean, np.zeros(6))
    assert info.value.key == "prior.E1.sd"
    with pytest.raises(CaseError):
        case.with_prior(mean[:5], case.prior.sd[:5])


def test_with_measured_and_select():
    case = parse_case(valid_case())
    first = case.with_measured(case.measured.select(slice(0, 2)))
    assert first.measured.size == 2
    np.testing.assert_array_equal(first.measured.mode, [1, 2])
    assert first.measured.shapes.shape == (2, 3)
    with pytest.raises(CaseError) as info:
        case.with_measured(frequency_Hz=case.measured.frequency_Hz[::-1])
    assert info.value.key.startswith("measured.frequency_Hz[")


def test_plate_defaults_and_checks():
    plate = Plate(0.2, 0.1, 4e-3, 1500, [0, 90, 90, 0])
    assert plate.layup_deg == (0.0, 90.0, 90.0, 0.0)
    assert plate.ply_thickness == (1e-3,) * 4
    with pytest.raises(CaseError):
        Plate(0.2, 0.1, 4e-3, 1500, [0, 90], ply_thickness=(1e-3, 2e-3))
    with pytest.raises(CaseError):
        Plate(-0.2, 0.1, 4e-3, 1500, [0])


def test_measurement_checks_in_code():
    Measurement([1.0, 2.0], [0.1, 0.1])
    with pytest.raises(CaseError):
        Measurement([1.0, 2.0], [0.1])
    with pytest.raises(CaseError):
        Measurement([1.0, 2.0], [0.1, 0.1], points=[[0, 0]])
    with pytest.raises(CaseError):
        Measurement([1.0, 2.0], [0.1, 0.1], points=[[0, 0]], shapes=[[1.0], [0.0]])
