"""A one-point tap test's tap and sensor points: a mode with a node there is expected missing."""

import re

import numpy as np
import pytest

from bayesplate.io import CaseError, bundled_case_path, load_case, parse_case
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.matching.pairing import pair_measured
from bayesplate.matching.peak_prior import P_NODE, assignment_priors
from bayesplate.plate.model import PlateModel

TAP_MM, SENSOR_MM = [0.0, 0.0], [200.0, 70.0]  # sensor near a nodal line of plate1's mode 3


def _plate1_toml(tmp_path, drop=None, points=True):
    text = bundled_case_path("plate1").read_text()
    case = load_case(bundled_case_path("plate1"))
    f = [v for i, v in enumerate(case.measured.frequency_Hz) if i != drop]
    listed = ", ".join(repr(float(v)) for v in f)
    text = re.sub(r"frequency_Hz = \[[^\]]*\]", f"frequency_Hz = [{listed}]", text)
    if points:
        text = text.replace(
            "[measured]\n", f"[measured]\ntap_point_mm = {TAP_MM}\nsensor_point_mm = {SENSOR_MM}\n"
        )
    path = tmp_path / "plate1_tapped.toml"
    path.write_text(text)
    return path


def test_the_points_are_read_in_metres_and_checked(tmp_path):
    case = load_case(_plate1_toml(tmp_path))
    np.testing.assert_allclose(case.measured.tap_points, [[0.0, 0.0], [0.2, 0.07]])
    data = {
        "name": "x",
        "plate": {
            "length_mm": 200,
            "width_mm": 100,
            "thickness_mm": 2,
            "density_kg_m3": 1500,
            "layup_deg": [0],
        },
        "measured": {"frequency_Hz": [100.0], "sigma_rel": 0.01, "tap_point_mm": [1, 1]},
        "prior": {
            k: {"mean": m, "sd": m / 5}
            for k, m in (
                ("E1_GPa", 100),
                ("E2_GPa", 7),
                ("nu12", 0.3),
                ("G12_GPa", 4),
                ("G13_GPa", 4),
                ("G23_GPa", 1),
            )
        },
    }
    with pytest.raises(CaseError, match="measured.sensor_point_mm.*required with"):
        parse_case(data)
    data["measured"]["sensor_point_mm"] = [250, 1]
    with pytest.raises(CaseError, match=r"sensor_point_mm\[0\].*must lie on the plate"):
        parse_case(data)


def test_a_mode_at_a_node_is_expected_unobserved():
    # p_u = P_NODE / (1 + (a / 0.1)^2) with a the amplitude over the median, floored at 0.01
    measured = load_case(bundled_case_path("plate1")).measured
    p_u, p_s = assignment_priors(measured, 3, amplitude=[0.0, 1.0, 3.0])
    np.testing.assert_allclose(p_u, [P_NODE, 0.01, 0.01])
    assert p_s == pytest.approx(0.05)  # no p_spurious: the flat prior


def test_the_mode_the_sensor_cannot_see_is_the_one_left_unobserved(tmp_path):
    # plate1 without its third frequency, tapped at a corner and heard at (200, 70) mm, near a
    # nodal line of mode 3: the assignment by likelihood, at the reference constants, calls
    # mode 3 (and only it) unobserved, and its prior there is far above the others'
    case = load_case(_plate1_toml(tmp_path, drop=2))
    model = PlateModel.from_case(case)
    b = stiffness_from_engineering(case.reference)
    pair = pair_measured(case, model, b, "likelihood")
    a = pair.assignment
    assert a.unobserved.tolist() == [2]
    assert a.modes.tolist() == [0, 1, *range(3, case.measured.size + 1)]
    assert a.p_unobserved[2] > 0.5 > 0.05 > np.max(np.delete(a.p_unobserved, 2)[:9])


def test_the_mode_shapes_figure_marks_the_tap_and_the_sensor(tmp_path):
    """Every panel carries both points at their millimetres, and the legend names them."""
    from bayesplate.plots import mode_shapes

    case = load_case(_plate1_toml(tmp_path))
    model = PlateModel.from_case(case, mesh=(8, 4))
    result = model.solve(stiffness_from_engineering(case.prior.mean), n_modes=4)
    marks = {"tap": case.measured.tap_points[0], "sensor": case.measured.tap_points[1]}
    fig = mode_shapes(model, result, n=4, points=(21, 11), marks=marks)
    panels = [ax for ax in fig.axes if ax.get_visible() and ax.get_title().startswith("mode")]
    assert len(panels) == 4
    for ax in panels:
        lines = {line.get_label(): np.column_stack(line.get_data()) for line in ax.get_lines()}
        np.testing.assert_allclose(lines["tap"], [TAP_MM])
        np.testing.assert_allclose(lines["sensor"], [SENSOR_MM])
    legend = panels[0].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == ["tap", "sensor"]
