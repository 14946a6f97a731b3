"""The 5R study of what an unmodelled effect would show (studies/spruce_what_shows.py)."""

import numpy as np
import pytest

from bayesplate import stiffness_from_engineering
from bayesplate.discrepancy import PointMass, ThicknessTaper
from bayesplate.quantities import CASE_SCALE
from studies import spruce_what_shows

MESH = (20, 8)


@pytest.fixture(scope="module")
def study():
    return spruce_what_shows


@pytest.fixture(scope="module")
def plate(study):
    from bayesplate.io import bundled_case_path, load_case
    from bayesplate.plate.model import PlateModel

    model = PlateModel.from_case(load_case(bundled_case_path(study.CASE)), mesh=MESH)
    return model, stiffness_from_engineering(np.array(study.CONSTANTS_GPA) * CASE_SCALE)


def test_a_small_mass_shifts_each_mode_as_first_order_perturbation_says(study, plate):
    """Rayleigh: d lambda / lambda = -m w(x)^2 for mass-normalised shapes (0.2 g, a corner)."""
    model, b = plate
    m_kg, corner = 0.2e-3, np.array([[0.0, 0.0]])
    base = model.solve(b, 6)
    w = (model.interpolation(corner, "w") @ base.vectors).ravel()
    changed = PointMass().apply(model, np.array([0.2, 0.0, 0.0])).solve(b, 6)
    shift = changed.eigenvalues / base.eigenvalues - 1
    np.testing.assert_allclose(shift, -m_kg * w**2, rtol=0.03, atol=1e-6)
    largest, _, _ = study.what_shows(model, b, PointMass(), (0.2, 0.0, 0.0), n=6)
    assert largest == pytest.approx(np.max(np.abs(0.5 * np.log1p(shift))) / study.SIGMA_REL)


def test_a_taper_moves_the_frequencies_at_second_order(study, plate):
    """A linear taper keeps the mean thickness and each mode's energy is symmetric about
    the centre, so the first-order shift vanishes: doubling the taper quadruples it."""
    model, b = plate
    one = study.what_shows(model, b, ThicknessTaper("y"), (0.02,), n=6)[0]
    two = study.what_shows(model, b, ThicknessTaper("y"), (0.04,), n=6)[0]
    assert two / one == pytest.approx(4.0, rel=0.05)


def test_a_shift_the_constants_explain_leaves_nothing(study, plate):
    """Stiffer by 3 % everywhere (b x 1.03) is a refit, not a misfit: nothing is left."""
    model, b = plate

    class Stiffer:
        def apply(self, model, theta):
            return _Scaled(model, theta[0])

    largest, left, moved = study.what_shows(model, b, Stiffer(), (1.03,), n=6)
    assert largest == pytest.approx(100 * 0.5 * np.log(1.03), rel=1e-6)
    assert left < 1e-8
    np.testing.assert_allclose(moved, 0.03, atol=1e-6)


class _Scaled:
    """The plate with every stiffness coefficient scaled: frequencies by sqrt(scale)."""

    def __init__(self, model, scale):
        self.model, self.scale = model, scale

    def solve(self, b, n):
        return self.model.solve(self.scale * np.asarray(b), n)


def test_the_study_runs_and_writes_its_table(study, tmp_path):
    rows = study.main(tmp_path, MESH)
    text = (tmp_path / study.REPORT).read_text()
    assert len(rows) == 8 and text.count("\n| ") == 1 + 8
    corner2, corner5 = rows[0], rows[3]
    assert corner5[1] > corner2[1] > 1.0  # a heavier mass at the same place moves more
