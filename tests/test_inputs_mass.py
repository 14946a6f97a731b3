"""Mass-derived density: the case keys mass_g and mass_sd_g, and the budget through rho = m/(abh).

The reference for the budget is independent of :func:`bayesplate.likelihood.inputs.input_sources`:
the full covariance of (h, rho, a, b) written out by hand from the same readings (first-order error
propagation of rho = m / (a b h)), put through the estimator's gain.
"""

import dataclasses
import math

import numpy as np
import pytest
from test_inputs import MESH, _case, _plate_table

from bayesplate import laminate
from bayesplate.estimators import estimate
from bayesplate.io import CaseError, Plate, parse_case
from bayesplate.likelihood.inputs import (
    describe_inputs,
    input_covariance,
    input_jacobian,
    input_sources,
)
from bayesplate.likelihood.posterior import GaussianProblem
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import hz_from_eigenvalue
from bayesplate.run.budget import estimate_budget

A_MM, B_MM, H_MM, M_G = 300.0, 200.0, 4.9, 128.1  # 435.7 kg/m^3


def _mass_table(**extra):
    table = _plate_table(**extra)
    del table["plate"]["density_kg_m3"]
    return table


def test_density_derived_from_the_mass():
    case = parse_case(_mass_table(mass_g=M_G, mass_sd_g=0.1, thickness_sd_mm=0.11))
    p = case.plate
    assert p.density == pytest.approx(M_G * 1e-3 / (A_MM * B_MM * H_MM * 1e-9), rel=1e-14)
    assert p.mass == pytest.approx(0.1281, rel=1e-15)
    assert p.mass_sd == pytest.approx(1e-4, rel=1e-15)
    assert describe_inputs(p) == "thickness 0.11 mm, mass 0.1 g"


def test_given_density_checked_against_the_mass():
    rho = M_G * 1e-3 / (A_MM * B_MM * H_MM * 1e-9)
    # within the stated sd: accepted, and the density is the mass's
    ok = parse_case(_plate_table(mass_g=M_G, density_kg_m3=rho + 4.0, density_sd_kg_m3=4.4))
    assert ok.plate.density == pytest.approx(rho, rel=1e-14)
    with pytest.raises(CaseError) as info:
        parse_case(
            _plate_table(mass_g=M_G, density_kg_m3=rho + 5.0, density_sd_kg_m3=4.4),
            path="plate.toml",
        )
    text = str(info.value)
    assert "\n" not in text and text.startswith("plate.toml: plate.density_kg_m3 = 440.7")
    assert "plate.mass_g" in text and "435.7" in text and "4.4" in text
    # no stated sd: the derived density's own (h 0.11 mm: 2.2 %), at least 0.1 %
    parse_case(_plate_table(mass_g=M_G, density_kg_m3=rho * 1.02, thickness_sd_mm=0.11))
    parse_case(_plate_table(mass_g=M_G, density_kg_m3=rho * 1.0009))
    with pytest.raises(CaseError, match="plate.mass_g / \\(a b h\\)"):
        parse_case(_plate_table(mass_g=M_G, density_kg_m3=rho * 1.002))


@pytest.mark.parametrize(
    ("table", "key"),
    [
        (_mass_table(mass_g=-1.0), "plate.mass_g"),
        (_mass_table(mass_g=math.nan), "plate.mass_g"),
        (_mass_table(mass_g=M_G, mass_sd_g=-0.1), "plate.mass_sd_g"),
        (_plate_table(mass_sd_g=0.1), "plate.mass_sd_g"),  # a mass sd without a mass
    ],
)
def test_bad_mass_refused_in_one_line(table, key):
    with pytest.raises(CaseError) as info:
        parse_case(table, path="plate.toml")
    assert info.value.key == key and "\n" not in str(info.value)


def test_neither_density_nor_mass_refused():
    with pytest.raises(CaseError) as info:
        parse_case(_mass_table())
    assert info.value.key == "plate.density_kg_m3" and "mass_g" in str(info.value)


def test_mass_sd_needs_a_mass_in_code():
    with pytest.raises(CaseError, match="plate.mass"):
        Plate(0.3, 0.2, 0.004, 2700.0, (0,), mass_sd=1e-4)


# ----------------------------------------------------------------------------- the budget

SD = {"thickness_sd": 0.08e-3, "length_sd": 0.8e-3, "width_sd": 0.5e-3}


def _by_hand(plate, sd_m):
    """Covariance of (h, rho, a, b) from independent h, a, b, m: rho = m / (a b h)."""
    h, a, b, rho = plate.thickness, plate.length, plate.width, plate.density
    m = rho * a * b * h
    sd_h, sd_a, sd_b = SD["thickness_sd"], SD["length_sd"], SD["width_sd"]
    C = np.diag([sd_h**2, 0.0, sd_a**2, sd_b**2])
    C[1, 1] = rho**2 * ((sd_m / m) ** 2 + (sd_h / h) ** 2 + (sd_a / a) ** 2 + (sd_b / b) ** 2)
    C[0, 1] = C[1, 0] = -rho / h * sd_h**2
    C[2, 1] = C[1, 2] = -rho / a * sd_a**2
    C[3, 1] = C[1, 3] = -rho / b * sd_b**2
    return C


def _synthetic_mass(rng, thickness=0.004, sigma_rel=1e-3, prior_rel=0.25, mesh=MESH, n=10):
    e = np.array([140e9, 10e9, 0.3, 5e9, 5e9, 3.5e9])
    case = _case(thickness=thickness, constants=e, prior_rel=prior_rel, **SD)
    mass = case.plate.density * 0.3 * 0.2 * thickness
    plate = dataclasses.replace(case.plate, mass=mass, mass_sd=2e-4 * mass)
    case = dataclasses.replace(case, plate=plate, mesh=mesh)
    model = PlateModel.from_case(case, mesh=mesh)
    lam = model.solve(laminate.stiffness_from_engineering(e), n).eigenvalues[:n]
    f = np.sort(hz_from_eigenvalue(lam) * (1 + sigma_rel * rng.standard_normal(n)))
    prior_mean = e * (1 + 0.1 * np.array([1, -1, 1, -1, 1, -1]))
    case = case.with_measured(frequency_Hz=f, sigma_Hz=sigma_rel * f)
    return case.with_prior(prior_mean, prior_rel * prior_mean), model


def test_input_sources_covariance_is_the_hand_built_one():
    case, _ = _synthetic_mass(np.random.default_rng(1))
    names, A = input_sources(case.plate)
    assert names == ("thickness", "mass", "length", "width")
    C = _by_hand(case.plate, case.plate.mass_sd)
    np.testing.assert_allclose(A @ A.T, C, rtol=1e-12, atol=1e-12 * np.abs(C).max())


def test_mass_budget_equals_the_full_covariance_of_h_and_rho(rng):
    case, model = _synthetic_mass(rng)
    result = estimate(case, "B", model=model, forward="full")
    assert result.converged
    budget = estimate_budget(case, result, model)
    assert budget.sources == ("frequencies", "thickness", "mass", "length", "width", "prior")
    assert budget.status == "ok"
    # by hand: the estimate's gain G = P S^T V_Y^-1 applied to J C J^T, C of (h, rho, a, b)
    conv = result.settings["conventions"]
    problem = GaussianProblem.from_case(case, model, result.pairing, conv.observation, conv.prior)
    modes = np.asarray(result.modes) - 1
    S = problem.predict(result.b, modes).S
    G = result.covariance_b @ S.T @ np.linalg.inv(problem.V_Y)
    J = input_jacobian(case, result.b, modes, mesh=MESH).J
    C = _by_hand(case.plate, case.plate.mass_sd)
    inputs_b = G @ J @ C @ J.T @ G.T
    T = np.linalg.inv(laminate.stiffness_jacobian(result.constants))
    expected = result.covariance + T @ inputs_b @ T.T
    scale = np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    assert np.max(np.abs(budget.covariance - expected) / scale) < 1e-9
    # the inputs matter here (not a vacuous equality): E1's variance grows by > 50 %
    assert budget.covariance[0, 0] > 1.5 * result.covariance[0, 0]
    # and the marginal problem's added covariance is J C J^T
    np.testing.assert_allclose(
        input_covariance(case, result.b, modes, mesh=MESH), J @ C @ J.T, rtol=1e-9
    )


def test_thickness_weighs_three_times_with_the_mass():
    # thin plate (a/h = 300), precise data, weak prior: the estimate absorbs a common scaling
    # of the eigenvalues; lambda ~ E h^2 / rho = E h^3 a b / m, so a thickness error moves the
    # bending moduli by 3 sd_h / h (2 with an independent density). The band: TSDT at a/h =
    # 300 on the 36 x 24 mesh departs from h^2 by 4.2e-3 in d ln lambda / d ln h
    # (tests/test_inputs.py THIN_MESH), and the prior's pull (~1e-3).
    case, model = _synthetic_mass(
        np.random.default_rng(2), thickness=0.001, sigma_rel=1e-4, prior_rel=1.0, mesh=(36, 24), n=8
    )
    result = estimate(case, "B", model=model, forward="full")
    assert result.converged
    budget = estimate_budget(case, result, model)
    rel = budget.source_sd[1] / np.abs(result.constants)
    sd_h = SD["thickness_sd"] / case.plate.thickness
    np.testing.assert_allclose(rel[[0, 1, 3]], 3 * sd_h, rtol=1e-2)
