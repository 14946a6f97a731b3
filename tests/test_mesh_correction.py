"""diagnose's corrected mesh-error rule: the working mesh's error taken out of the model.

References: a frequency sequence with an exact ``h^2`` error (closed form), and a converged
reference from two much finer meshes (Richardson between 4x and 8x the working mesh), which
the rule never solves.
"""

import numpy as np
import pytest

from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.discrepancy.search.mesh_error import (
    GCI_SAFETY,
    corrected_error,
    finer_model,
    richardson,
)


def test_richardson_recovers_an_exact_h2_error():
    # f(h) = f0 + C h^2: the working mesh (h) and the one twice as fine (h / 2)
    f0, C, h = np.array([100.0, 250.0, 400.0]), np.array([3.0, -1.0, 8.0]), 0.1
    working, finer = f0 + C * h**2, f0 + C * (h / 2) ** 2
    error, uncertainty = richardson(working, finer)
    np.testing.assert_allclose(error, C * h**2, rtol=1e-12)  # f_mesh - f_converged
    np.testing.assert_allclose(working - error, f0, rtol=1e-12)
    # the grid convergence index of the finer mesh: 1.25 times its own error, C h^2 / 4
    np.testing.assert_allclose(uncertainty, GCI_SAFETY * np.abs(C) * h**2 / 4, rtol=1e-12)


def test_the_finer_mesh_has_twice_the_elements_each_way():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case, mesh=(6, 3))
    finer = finer_model(model)
    assert (finer.mesh.nx, finer.mesh.ny) == (12, 6)
    assert (finer.mesh.a, finer.mesh.b) == (model.mesh.a, model.mesh.b)


@pytest.mark.slow  # four meshes up to 8x the working one (~1 min each plate)
@pytest.mark.parametrize("name, mesh", [("crossply", (32, 16)), ("frederiksen_t300", (40, 20))])
def test_the_corrected_frequencies_are_within_their_uncertainty_of_a_converged_reference(
    name, mesh
):
    """The calibration study's meshes at the true constants: the corrected error is at most
    the uncertainty ``u`` on every mode, and a tenth of the uncorrected one (RMS)."""
    case = load_case(bundled_case_path(name))
    b, m = stiffness_from_engineering(case.reference), case.measured.size
    model = PlateModel.from_case(case, mesh=mesh)
    error, u = corrected_error(model, b, m)
    f4, f8 = (
        PlateModel.from_case(case, mesh=(k * mesh[0], k * mesh[1])).solve(b, m).frequency_Hz
        for k in (4, 8)
    )
    reference = f8 - (f4 - f8) / 3.0
    working = model.solve(b, m).frequency_Hz
    left = working - error - reference
    assert np.all(np.abs(left) <= u)  # measured: at most 0.32 u (cross-ply), 0.60 u (Frederiksen)
    rms = np.sqrt(np.mean(left**2)) / np.sqrt(np.mean((working - reference) ** 2))
    assert rms < 0.1  # measured: 0.064 and 0.096


@pytest.mark.slow  # two diagnoses of the cross-ply plate on 32 x 16 (~2 min)
def test_the_corrected_rule_widens_less_and_says_so_on_a_clean_plate():
    """Recordings at a converged reference with 0.2 % noise: both rules find nothing; the
    corrected one widens the deviations less and its note says the frequencies were
    corrected."""
    case = load_case(bundled_case_path("crossply"))
    b, m = stiffness_from_engineering(case.reference), case.measured.size
    f2, f4 = (
        PlateModel.from_case(case, mesh=(k * 32, k * 16)).solve(b, m).frequency_Hz for k in (2, 4)
    )
    f = np.sort((f4 - (f2 - f4) / 3.0) * (1 + 0.002 * np.random.default_rng(3).standard_normal(m)))
    blind = case.with_measured(frequency_Hz=f, sigma_Hz=0.002 * f)
    model = PlateModel.from_case(case, mesh=(32, 16))
    run = {
        rule: diagnose(blind, model=model, rng=0, pairing="order", mesh_error_part=rule)
        for rule in ("whole", "corrected")
    }
    assert [d.verdict for d in run.values()] == ["consistent", "consistent"]
    sigma = blind.measured.sigma_Hz
    widening = {rule: np.sum((d.sigma_Hz / sigma) ** 2) for rule, d in run.items()}
    assert widening["corrected"] < widening["whole"]
    assert any("corrected by its mesh's estimated error" in n for n in run["corrected"].notes)
    assert run["corrected"].p_value > 0.01


def test_the_study_quick_run_corrects_most_of_the_error(tmp_path):
    """The study's regression run (plate 1 on 6 x 3, references from 24 x 12 and 48 x 24)."""
    from studies import mesh_correction

    r = mesh_correction.measure("plate1", (6, 3))
    rms = {k: np.sqrt(np.mean(r[k] ** 2)) for k in ("uncorrected", "corrected")}
    assert rms["corrected"] < 0.2 * rms["uncorrected"]  # measured: 7.7 against 59.5
    text = mesh_correction.write_report(tmp_path, [(("plate1", (6, 3)), r)], True).read_text()
    assert "| plate1 | 6 x 3 |" in text and "of the error (RMS)" in text


def _corrected_run(mesh=(6, 3), seed=5):
    """plate 1 recorded on a mesh 4x as fine (0.2 % noise): a Run and a pairing by order."""
    from bayesplate.discrepancy.diagnose import DiagnoseOptions
    from bayesplate.discrepancy.search.mesh_error import coarse_model
    from bayesplate.discrepancy.search.state import Run
    from bayesplate.likelihood.posterior import prior_in_stiffness
    from bayesplate.matching.pairing import pair_measured

    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case, mesh=mesh)
    b = stiffness_from_engineering(case.reference)
    f = PlateModel.from_case(case, mesh=(4 * mesh[0], 4 * mesh[1])).solve(b, 10).frequency_Hz
    f = f * (1 + 0.002 * np.random.default_rng(seed).standard_normal(f.size))
    blind = case.with_measured(frequency_Hz=f, sigma_Hz=0.002 * f)
    prior = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    options = DiagnoseOptions.of(None, mesh_error_part="corrected", n_starts=8)
    run = Run(blind, model, coarse_model(model), [], prior, options, lambda m: None)
    return run, pair_measured(blind, model, prior[0], "order")


def test_the_second_nominal_fit_settled_from_the_first_is_as_good_as_a_global_one():
    """Under the corrected rule the nominal fit is made again with the mesh's error
    estimated at the first fit, settled from the first fit's optima. Reference: a whole
    global fit (reduced model, random starts) of the same deviations."""
    from bayesplate.discrepancy.search.deviations import deviations
    from bayesplate.discrepancy.search.nominal_check import fit_nominal_stage, nominal_again

    run, pairing = _corrected_run()
    data = deviations(run, pairing)
    first = fit_nominal_stage(run, data, np.random.default_rng(0))
    data2 = deviations(run, pairing, at=first.check.fit.b)
    assert not np.array_equal(data2.Y, data.Y)  # the correction moved with the constants
    again = nominal_again(run, data2, first).check.fit
    whole = fit_nominal_stage(run, data2, np.random.default_rng(1)).check.fit

    def objective(fit_):
        return fit_.chi2 + fit_.chi2_prior

    assert objective(again) <= objective(whole) + 1e-3  # measured: 23.1987 against 23.1999
    sd = np.sqrt(np.diag(whole.covariance)[:6])
    # the same optimum: measured at most 0.024 posterior sd apart
    assert np.all(np.abs(again.b - whole.b) <= 0.05 * sd)


def test_a_corrected_diagnosis_resumes_from_the_store_bit_for_bit():
    """A second run with the same store takes the second nominal fit from it."""
    import json

    from bayesplate.discrepancy import PointMass
    from bayesplate.discrepancy.search.store import MemoryStore
    from bayesplate.io import diagnosis_to_dict, jsonable

    run, _ = _corrected_run()
    said, again, store = [], [], MemoryStore()

    def diagnosed(say):
        d = diagnose(
            run.case,
            model=run.model,
            physics=[PointMass()],
            rng=0,
            n_starts=4,
            pairing="order",
            mesh_error_part="corrected",
            store=store,
            progress=say,
        )
        return json.dumps(diagnosis_to_dict(d), default=jsonable, sort_keys=True)

    text = diagnosed(said.append)
    assert diagnosed(again.append) == text
    assert "nominal fit again: taken from the store" in again
    assert "nominal fit again: taken from the store" not in said
