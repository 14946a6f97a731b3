"""studies/outside_effects.py: its effects are what it says, its outcomes and its report."""

import numpy as np
import pytest

from bayesplate import PlateModel, bundled_case_path, load_case
from studies import outside_effects as study


@pytest.fixture(scope="module")
def plate():
    return PlateModel.from_case(load_case(bundled_case_path("frederiksen_t300")), mesh=(20, 20))


def _mass(model):
    """Translation mass of the plate: u^T M u for a unit transverse translation, kg."""
    u = np.zeros(model.mesh.n_dofs)
    u[model.mesh.dofs("w")] = 1.0
    return float(u @ (model.mass @ u))


@pytest.mark.parametrize(
    "label, area_mm2, share",
    [
        ("slot 15 x 2 mm", 30.0, -(1 - study.RESIDUAL)),
        ("doubler 15 x 12 mm", 180.0, 0.3),
        ("edge notch 6 x 4 mm", 24.0, -(1 - study.RESIDUAL)),
        ("round delamination 16 mm", np.pi * 64.0, 0.0),
    ],
)
def test_each_effect_changes_the_mass_as_its_region_says(plate, label, area_mm2, share):
    # the reference: the plate's mass times the region's share of its area (100.1 x 53 mm)
    physics, _ = study.EFFECTS[label]
    m0 = _mass(plate)
    expected = m0 * (1 + share * area_mm2 / (100.1 * 53.0))
    assert _mass(physics.apply(plate, [0.0])) == pytest.approx(expected, rel=1e-9)


def test_the_delamination_lowers_only_shear_carrying_modes_more(plate):
    physics, _ = study.EFFECTS["round delamination 16 mm"]
    from bayesplate import stiffness_from_engineering

    b = stiffness_from_engineering(load_case(bundled_case_path("frederiksen_t300")).reference)
    f0 = plate.solve(b, 10).frequency_Hz
    f = physics.apply(plate, [0.0]).solve(b, 10).frequency_Hz
    assert np.all(f <= f0 * (1 + 1e-12))  # a softer plate, the same mass
    assert np.max(1 - f / f0) > 5e-3


def test_outcomes():
    assert study.outcome("consistent", [], set(), control=True) == "consistent"
    assert study.outcome("explained", ["point_mass"], set(), control=True) == "wrong"
    assert study.outcome("unexplained", [], set()) == "right"
    assert study.outcome("explained", ["cutout"], {"cutout"}) == "right"
    assert study.outcome("ambiguous", ["cutout", "point_mass"], {"cutout"}) == "wrong"


def test_report_is_the_table_of_the_rows_given(tmp_path):
    rows = [
        {
            "effect": "slot 15 x 2 mm",
            "replicate": k,
            "verdict": verdict,
            "named": named,
            "outcome": study.outcome(verdict, named, {"cutout", "local_stiffness_loss"}),
            "p_value": 1e-5,
            "best": "cutout",
            "best_gain": 9.0,
            "unnamed_gain": 4.0,
            "seconds": 30.0 + k,
        }
        for k, (verdict, named) in enumerate(
            [("unexplained", []), ("explained", ["cutout"]), ("explained", ["point_mass"])]
        )
    ]
    text = study.write_report(tmp_path, rows, "abc1234").read_text()
    assert "| slot 15 x 2 mm | 3 | 0 | 1 | 1 | 1 | cutout, point_mass | 31 |" in text
    assert "Code: abc1234" in text
