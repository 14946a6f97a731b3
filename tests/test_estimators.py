"""The paper's estimators B, MVE and MVE-mod against closed forms and the paper's tables."""

import copy
import json
import sys
from dataclasses import dataclass

import numpy as np
import pytest

from bayesplate import laminate
from bayesplate.cli import main as cli_main
from bayesplate.estimators import CONVENTIONS, b_step, estimate, mve_step, run
from bayesplate.estimators.iteration import DEFAULT_MAX_ITER
from bayesplate.io import bundled_case_path, load_case
from bayesplate.likelihood.posterior import GaussianProblem, prior_in_stiffness
from bayesplate.matching.pairing import Pairing
from bayesplate.plate.model import PlateModel

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

PAPER = tomllib.loads(
    (bundled_case_path("plate1").parents[1] / "paper" / "results.toml").read_text()
)
SI = np.array([1e9, 1e9, 1.0, 1e9, 1e9, 1e9])
FRACTION = {"1/2": 1 / 2, "1/3": 1 / 3, "1/6": 1 / 6, "1/10": 1 / 10}
TARGET1 = np.array(PAPER["plate1"]["target"]["constants"]) * SI
IN_PLANE = [0, 1, 3]  # E1, E2, G12: the constants the frequencies determine well (sec. 4.1)


@pytest.fixture(scope="module")
def plate1():
    case = load_case(bundled_case_path("plate1"))
    return case, PlateModel.from_case(case)


def _paper_run(plate1, test, method, d, **kwargs):
    case, model = plate1
    initial = np.array(PAPER["plate1"][test]["initial"]) * SI
    sd = FRACTION[d] * initial
    kwargs.setdefault("pairing", "order")  # the paper's pairing (issue 16: not the default)
    return estimate(case, method, model=model, prior_mean=initial, prior_sd=sd, **kwargs)


# ----------------------------------------------------------------------------- closed forms


def test_section_2_3_one_b_step_with_mu_at_the_iterate_is_one_mve_step(plate1):
    # Section 2.3 (matrix inversion lemma, eq. 13): eq. 9 with mu = b^k is eq. 12, and P^k
    # equals the updated covariance. Only rounding separates them: 1e-9 relative is far
    # above double-precision solves of 6x6 / 14x14 systems and far below any real difference.
    case, model = plate1
    problem = GaussianProblem.from_case(case, model)
    b = laminate.stiffness_from_engineering(np.array([180e9, 12e9, 0.2, 2e9, 2e9, 4e9]))
    p = problem.predict(b)
    b_B, P = b_step(b, b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)
    b_MVE, V_next = mve_step(b, p.g, p.S, problem.Y, problem.V_Y, problem.V_b)
    np.testing.assert_allclose(b_B, b_MVE, rtol=1e-9)
    np.testing.assert_allclose(P, V_next, rtol=1e-7, atol=1e-9 * np.max(np.abs(P)))
    assert np.max(np.abs(b_B - b) / b) > 0.01  # the step is not trivially zero


@dataclass
class _Linear:
    b: np.ndarray
    eigenvalues: np.ndarray
    sensitivities: np.ndarray
    vectors: np.ndarray


def _linear_problem(A, Y, V_Y, mu, V_b, S=None):
    """g(b) = A b, with sensitivities S (default the true A)."""
    S = A if S is None else S

    def forward(b, n_modes):
        return _Linear(b, A @ b, S, np.eye(len(A)))

    return GaussianProblem(Y, V_Y, mu, V_b, forward, Pairing(np.arange(len(A)), extra=0))


def _linear_case(rng, m=10):
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, V_b = prior_in_stiffness(e0, e0 / 6, "full")
    A = rng.uniform(0.2, 2.0, size=(m, 6)) * 1e7 / mu[None, :]
    b_true = mu * rng.uniform(0.85, 1.15, 6)
    V_Y = np.diag((0.01 * A @ b_true) ** 2)
    return A, b_true, V_Y, mu, V_b


def test_b_on_a_linear_problem_gives_the_exact_gaussian_posterior(rng):
    # For g(b) = A b the posterior is Gaussian with covariance P = (A^T V_Y^-1 A + V_b^-1)^-1
    # and mean P (A^T V_Y^-1 Y + V_b^-1 mu) (closed form). One step of eq. 9 lands on it;
    # 1e-8 relative allows for the inversions of matrices spanning ~1e20 in scale.
    A, b_true, V_Y, mu, V_b = _linear_case(rng)
    Y = A @ b_true + rng.normal(0, np.sqrt(np.diag(V_Y)))
    W = np.linalg.inv(V_Y)
    P = np.linalg.inv(A.T @ W @ A + np.linalg.inv(V_b))
    mean = P @ (A.T @ W @ Y + np.linalg.solve(V_b, mu))
    result = run(_linear_problem(A, Y, V_Y, mu, V_b), "B", tol=1e-10)
    assert result.converged and result.iterations <= 3
    np.testing.assert_allclose(result.b, mean, rtol=1e-8)
    np.testing.assert_allclose(result.covariance_b, P, rtol=1e-6, atol=1e-8 * np.max(P))


def test_mve_on_noise_free_linear_data_reaches_the_truth_and_b_is_biased(rng):
    # Section 4.3: MVE forgets the prior mean (its fixed point has S^T (S V S^T + V_Y)^-1
    # (Y - g) = 0, i.e. Y = A b for exact data), B keeps a bias towards it.
    A, b_true, V_Y, mu, V_b = _linear_case(rng)
    problem = _linear_problem(A, A @ b_true, V_Y, mu, V_b)
    mve = run(problem, "MVE", tol=1e-10, max_iter=2000)
    bayes = run(problem, "B", tol=1e-10)
    assert mve.converged
    # the stopping rule leaves an error of the order of the last step (1e-10) over the
    # contraction margin; 1e-6 is a generous bound
    np.testing.assert_allclose(mve.b, b_true, rtol=1e-6)
    assert np.max(np.abs(bayes.b - b_true) / b_true) > 1e-3


def test_oscillation_is_detected_and_reported(rng):
    # Sensitivities half the true ones make each (nearly undamped) MVE step twice too long:
    # b^{k+1} - b* = -(b^k - b*), an exact period-2 cycle.
    A, b_true, _, mu, V_b = _linear_case(rng, m=6)
    b_star = mu * 1.02
    V_Y = np.diag((1e-9 * A @ b_star) ** 2)
    problem = _linear_problem(A, A @ b_star, V_Y, mu, V_b, S=A / 2)
    result = run(problem, "MVE", max_iter=100)
    assert not result.converged
    assert "oscillating" in result.message and "period 2" in result.message
    assert result.iterations < 30


def test_iteration_cap_and_failed_solves_end_the_run_without_raising(plate1, rng):
    capped = _paper_run(plate1, "test1", "MVE", "1/6", max_iter=3)
    assert not capped.converged and capped.iterations == 3
    assert "iteration cap" in capped.message

    A, b_true, V_Y, mu, V_b = _linear_case(rng)
    calls = []

    def failing(b, n_modes):
        calls.append(1)
        if len(calls) > 1:
            raise RuntimeError("ARPACK did not converge")
        return _Linear(b, A @ b, A, np.eye(len(A)))

    problem = GaussianProblem(
        A @ b_true, V_Y, mu, V_b, failing, Pairing(np.arange(len(A)), extra=0)
    )
    result = run(problem, "MVE")
    assert not result.converged and "forward solve failed at iteration 1" in result.message

    def broken(b, n_modes):
        raise RuntimeError("no factorisation")

    problem = GaussianProblem(A @ b_true, V_Y, mu, V_b, broken, Pairing(np.arange(len(A)), extra=0))
    result = run(problem, "B")
    assert not result.converged and "forward solve failed" in result.message


def test_engineering_covariance_is_the_first_order_image(plate1):
    # cov_e = (de/db) cov_b (de/db)^T with de/db by central differences of eqs. 20-21
    # (independent of stiffness_jacobian); 1e-5 is the finite-difference error.
    result = _paper_run(plate1, "test2", "B", "1/3")
    b = result.b
    D = np.empty((6, 6))
    for j in range(6):
        h = np.zeros(6)
        h[j] = 1e-6 * b[j]
        D[:, j] = (
            laminate.engineering_from_stiffness(b + h) - laminate.engineering_from_stiffness(b - h)
        ) / (2 * h[j])
    np.testing.assert_allclose(
        result.covariance, D @ result.covariance_b @ D.T, rtol=1e-5, atol=1e-12
    )
    np.testing.assert_allclose(result.sd, np.sqrt(np.diag(result.covariance)))


# ----------------------------------------------------------------------------- the paper


@pytest.mark.parametrize("test", ["test2", "test3"])
def test_b_bias_grows_as_the_deviation_shrinks(plate1, test):
    # Section 4.3 on Tables 4 and 5: B's E1 lies between the initial value and the target
    # and moves towards the initial value as d shrinks.
    initial = PAPER["plate1"][test]["initial"][0] * 1e9
    runs = [_paper_run(plate1, test, "B", d) for d in ("1/3", "1/6", "1/10")]
    assert all(r.converged for r in runs)
    e1 = np.array([r.constants[0] for r in runs])
    low, high = sorted([initial, TARGET1[0]])
    assert np.all((e1 > low) & (e1 < high))
    distance = np.abs(e1 - initial)
    assert distance[0] > distance[1] > distance[2]
    # and the values themselves: the paper prints 4 figures (<= 0.04 %), our frequencies
    # differ from the paper's by <= 0.003 %, so 0.2 % on E1 bounds rounding plus model
    paper = [PAPER["plate1"][test]["B"][d][0] * 1e9 for d in ("1/3", "1/6", "1/10")]
    np.testing.assert_allclose(e1, paper, rtol=2e-3)
    assert [r.iterations for r in runs] == [
        PAPER["plate1"][test]["B"][d][6] for d in ("1/3", "1/6", "1/10")
    ]


_CONVERGED_MVE = [
    (test, d)
    for test in ("test1", "test2", "test3")
    for d in ("1/3", "1/6", "1/10")
    if not isinstance(PAPER["plate1"][test]["MVE"][d], str)
]


@pytest.mark.parametrize("test, d", _CONVERGED_MVE)
def test_mve_reaches_the_target_where_the_paper_does(plate1, test, d):
    # Issue 3: E1, E2, G12 within 0.5 % of the target (the paper's own rows are within
    # 0.2 %; TOL = 1e-3 on the step leaves errors of that order on slow directions).
    result = _paper_run(plate1, test, "MVE", d)
    assert result.converged, result.message
    np.testing.assert_allclose(result.constants[IN_PLANE], TARGET1[IN_PLANE], rtol=5e-3)


_MVE_MOD = [
    (test, row["d1"], row["d2"])
    for test in ("test1", "test2", "test3")
    for row in PAPER["plate1"][test]["MVE_mod"]
]


@pytest.mark.parametrize("test, d1, d2", _MVE_MOD)
def test_mve_mod_reaches_the_target_where_the_paper_does(plate1, test, d1, d2):
    # Tables 9-11: every MVE-mod run on Plate 1 reaches the target; same 0.5 % as above.
    factor = FRACTION[d2] / FRACTION[d1]
    result = _paper_run(plate1, test, "MVE-mod", d1, stage2_factor=factor)
    assert result.converged, result.message
    assert len(result.stages) == 2
    np.testing.assert_allclose(result.constants[IN_PLANE], TARGET1[IN_PLANE], rtol=5e-3)
    stage1, stage2 = result.stages
    assert stage1.settings["tol"] == 1e-2 and stage2.settings["tol"] == 1e-3
    np.testing.assert_allclose(stage2.settings["prior_mean"], stage1.constants)
    initial = np.array(PAPER["plate1"][test]["initial"]) * SI
    np.testing.assert_allclose(stage2.settings["prior_sd"], FRACTION[d2] * initial)


@pytest.mark.parametrize("method", ["B", "MVE", "MVE-mod"])
def test_the_papers_diverging_run_ends_unconverged_with_a_message(plate1, method):
    # Table 3 (and 9): test 1 on Plate 1 with d = 1/3 does not converge.
    result = _paper_run(plate1, "test1", method, "1/3")
    assert not result.converged
    assert "physical region" in result.message


def test_mve_mod_on_a_case_file_doubles_the_deviations(plate1):
    # Section 6: stage-2 deviations are twice stage 1's (the case prior).
    case, model = plate1
    result = estimate(
        case.with_prior(case.prior.mean * 1.0, case.prior.sd),
        "MVE-mod",
        model=model,
        max_iter=3,
        pairing="order",
    )
    if result.stages[0].converged:  # pragma: no cover - three iterations cannot meet TOL
        pytest.fail("stage 1 should hit its cap")
    assert "stage 1 did not converge" in result.message
    case2 = case.with_prior(TARGET1 * 1.05, TARGET1 / 20)
    result = estimate(case2, "MVE-mod", model=model, pairing="order")
    assert result.converged
    np.testing.assert_allclose(result.stages[1].settings["prior_sd"], 2 * TARGET1 / 20)


def test_conventions_are_named_and_checked(plate1):
    assert set(CONVENTIONS) >= {"paper", "full-prior", "printed"}
    case, model = plate1
    with pytest.raises(ValueError, match="convention"):
        estimate(case, "MVE", model=model, convention="nope")
    with pytest.raises(ValueError, match="method"):
        estimate(case, "LS", model=model)


# ----------------------------------------------------------------------------- command line


def test_cli_estimate_json(capsys):
    # the paper's pairing by order (issue 16: the default pairs by likelihood)
    status = cli_main(
        ["estimate", "plate1", "--method", "B", "--pairing", "order", "--json", "-", "-q"]
    )
    out = json.loads(capsys.readouterr().out)
    assert status == 0
    for key in (
        "method",
        "converged",
        "iterations",
        "message",
        "n_solves",
        "constants",
        "frequency_Hz",
        "measured_Hz",
    ):
        assert key in out
    assert set(out["constants"]) == {"E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa"}
    assert set(out["constants"]["E1_GPa"]) == {"mean", "sd"}
    # plate1.toml carries test 1 at d = 1/6: Table 3 prints B = 145.0 GPa after 15 iterations
    assert out["constants"]["E1_GPa"]["mean"] == pytest.approx(145.0, rel=2e-3)
    assert out["iterations"] == 15 and out["converged"] is True


def test_cli_estimate_table_and_exit_status(capsys):
    status = cli_main(["estimate", "plate1", "--method", "MVE", "--max-iter", "2", "-q"])
    text = capsys.readouterr().out
    assert status == 1  # not converged
    assert "NOT converged" in text and "iteration cap" in text
    assert "E1_GPa" in text and "diff_%" in text


# ----------------------------------------------------------------------------- slow


@pytest.mark.slow
def test_frederiksen_mve_matches_the_paper():
    # Table 23 (50 x 50 mesh): issue 3 asks for 2 % on E1, E2, G12 and 10 % on the weakly
    # determined nu12, G13, G23.
    case = load_case(bundled_case_path("frederiksen_t300"))
    result = estimate(case, "MVE", pairing="order")
    assert result.converged, result.message
    paper = np.array(PAPER["frederiksen"]["MVE"]) * SI
    np.testing.assert_allclose(result.constants[IN_PLANE], paper[IN_PLANE], rtol=0.02)
    np.testing.assert_allclose(result.constants[[2, 4, 5]], paper[[2, 4, 5]], rtol=0.10)


def test_a_run_without_progress_is_called_oscillating():
    # Quasi-periodic iterates (steps of constant size, no short cycle): the stall rule fires
    # once 2 x 40 iterations show no decrease of the largest relative change.
    from bayesplate.estimators.iteration import _oscillation

    b0 = laminate.stiffness_from_engineering(np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9]))
    history = [b0 * (1 + 0.05 * np.sin(k * 2.399963)) for k in range(81)]
    assert "no progress" in _oscillation(history, 1e-3)
    assert _oscillation(history[:60], 1e-3) == ""
    converging = [b0 * (1 + 0.5**k) for k in range(81)]
    assert _oscillation(converging, 1e-3) == ""


def _crossing_problem():
    """Seven linear modes, sorted by frequency (pairing by order); six peaks, mode 5 unseen.

    Mode 6's sensitivities are mode 5's reversed, scaled to cross it 1 % from the truth:
    by order the fifth and sixth peaks go with whichever of the two is lower at the iterate.
    """
    rng = np.random.default_rng(3)
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, V_b = prior_in_stiffness(e0, e0 / 6, "full")
    A = rng.uniform(0.2, 2.0, size=(7, 6)) * 1e7 / mu[None, :]
    b_true = mu * rng.uniform(0.9, 1.1, 6)
    A = A[np.argsort(A @ b_true)]
    A[6] = A[5][::-1] * (A[5] @ b_true) / (A[5][::-1] @ b_true) * 0.99
    Y = np.delete(A @ b_true, 5)

    def forward(b, n_modes):
        g = A @ b
        order = np.argsort(g)
        return _Linear(b, g[order], A[order], np.eye(7)[:, order])

    V_Y = np.diag((1e-3 * Y) ** 2)
    pairing = Pairing(np.arange(6), how="order", extra=1)
    return GaussianProblem(Y, V_Y, mu, V_b, forward, pairing), A, Y


def test_a_pairing_by_order_that_flips_between_crossing_modes_is_frozen(monkeypatch):
    # Re-paired by order at every iterate, the peaks flip between the two crossing modes and
    # MVE cycles; frozen, the paired modes are followed and the run is linear with exact
    # data: it must land on the solution of the frozen pairing's 6 x 6 system (closed form).
    from bayesplate.estimators import iteration

    problem, A, Y = _crossing_problem()
    frozen = run(problem, "MVE", tol=1e-9)
    assert frozen.status == "converged", frozen.message
    assert frozen.settings["frozen_pairing"]["iteration"] == iteration.PAIRING_CYCLE
    assert "\n" not in frozen.message and "frozen at iteration" in frozen.message
    rows = np.argsort(A @ frozen.b)[frozen.modes - 1]  # the physical modes paired at the end
    np.testing.assert_allclose(frozen.b, np.linalg.solve(A[rows], Y), rtol=1e-6)
    assert frozen.iterations < 20

    monkeypatch.setattr(iteration, "PAIRING_CYCLE", 10**6)  # the paper's re-pairing only
    flipping = run(problem.with_prior(problem.mu_b, problem.V_b), "MVE", tol=1e-9)
    assert flipping.status == "oscillating"
    assert {s[0] for s in flipping.mode_swaps} == set(range(1, flipping.iterations + 1))


def _flat_problem():
    """Ten linear frequencies that barely see C44 (its column 1 % of the others), C44 far off.

    MVE's steps along C44 shrink by 1 / (1 + lambda) per iteration, lambda the small
    generalised eigenvalue of (F, V_x^-1): far more iterations than the cap allows.
    """
    rng = np.random.default_rng(7)
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, _ = prior_in_stiffness(e0, e0 / 6, "full")
    V_b = np.diag((0.2 * mu) ** 2)
    A = rng.uniform(0.2, 2.0, size=(10, 6)) * 1e7 / mu[None, :]
    A[:, 4] *= 1e-2
    b_true = mu * np.array([1.05, 0.95, 1.1, 1.02, 6.0, 0.97])
    Y = A @ b_true
    V_Y = np.diag((0.01 * Y) ** 2)
    return _linear_problem(A, Y, V_Y, mu, V_b), A


def test_mve_drifting_where_the_data_barely_see_stops_unidentified(monkeypatch):
    import scipy.linalg

    from bayesplate.estimators import drift as drift_rule

    problem, A = _flat_problem()
    result = run(problem, "MVE")
    assert result.status == "unidentified" and not result.converged
    assert result.iterations < 60 and "\n" not in result.message
    drift = result.settings["unidentified"]
    assert drift["coefficients"] == ["C44"] and drift["constants"] == ["G23"]
    # the information the data carry along the drift, by a generalised eigenproblem
    x = np.abs(result.b)
    Sx, Vx = A * x[None, :], problem.V_b / np.outer(x, x)
    F = Sx.T @ np.linalg.solve(problem.V_Y, Sx)
    lam = scipy.linalg.eigh(F, np.linalg.inv(Vx), eigvals_only=True)[0]
    assert drift["information"][-1] == pytest.approx(lam, rel=1e-6)
    assert drift["predicted_iterations"] > DEFAULT_MAX_ITER - result.iterations
    # and the prediction holds: without the rule the run meets the cap, still moving
    monkeypatch.setattr(drift_rule, "DRIFT_WINDOW", 10**6)
    capped = run(problem, "MVE")
    assert capped.status == "iteration_cap"
    # B on the same data converges: its prior holds the direction the data do not
    assert run(problem, "B").converged


@pytest.mark.filterwarnings("ignore::bayesplate.matching.pairing.UnpairedModeWarning")
def test_shape_pairing_recovers_a_test_that_missed_a_mode(plate1):
    # Plate 1's frequencies without mode 5, with shapes (w at 28 points) computed at the
    # target: by order every mode above the gap goes with the wrong computed mode and MVE
    # does not converge; paired by shape (MAC) and followed between iterates it reaches the
    # target within the same 0.5 % as the complete data. Modes 13 and 14 are in-plane (w is
    # round-off): they match nothing and are left out, on every CPU.
    case, model = plate1
    missing = _missed_mode_case(plate1)
    initial = np.array(PAPER["plate1"]["test2"]["initial"]) * SI
    options = {"model": model, "prior_mean": initial, "prior_sd": initial / 6}
    by_order = estimate(missing, "MVE", pairing="order", **options)
    by_shape = estimate(missing, "MVE", **options)
    assert not by_order.converged
    assert by_shape.converged, by_shape.message
    assert by_shape.settings["tracking"] == "follow"
    np.testing.assert_allclose(by_shape.constants[IN_PLANE], TARGET1[IN_PLANE], rtol=5e-3)
    assert 5 not in by_shape.modes  # the missed mode stays unpaired at the estimate


def _missed_mode_case(plate1, nudge=None):
    """Plate 1 without mode 5, with w at 28 points computed at the target (`nudge`d).

    The shapes come from a solve that does not split in-plane from bending unknowns: the two
    in-plane modes' w is round-off there, as a transverse sensor records noise for them (a
    row of exact zeros is not a measured shape, and the case reader refuses it).
    """
    case, model = plate1
    target = case.reference if nudge is None else nudge(case.reference)
    coupled = copy.copy(model)
    coupled.split_decoupled = False
    modal = coupled.solve(laminate.stiffness_from_engineering(target), 14)
    x, y = np.meshgrid(np.linspace(0.01, 0.19, 7), np.linspace(0.01, 0.09, 4))
    points = np.column_stack([x.ravel(), y.ravel()])
    shapes = (model.interpolation(points) @ modal.vectors).T
    keep = np.delete(np.arange(14), 4)
    return case.with_measured(
        frequency_Hz=case.measured.frequency_Hz[keep],
        sigma_Hz=case.measured.sigma_Hz[keep],
        points=points,
        shapes=shapes[keep],
    )


@pytest.mark.filterwarnings("ignore::bayesplate.matching.pairing.UnpairedModeWarning")
@pytest.mark.parametrize(("method", "pairing"), [("B", "order"), ("MVE", "order"), ("MVE", "auto")])
def test_estimates_do_not_depend_on_round_off(plate1, method, pairing):
    # Issue 16: a result that flips with the CPU's round-off is a defect of the method.
    # Inputs perturbed at 1e-12 relative (frequencies, deviations, initial values, and the
    # constants the measured shapes are computed from, so that the solver's round-off in them
    # changes as between BLAS kernels) must give the same pairing,
    # the same outcome and constants equal within the estimator's own TOL (1e-3), in every
    # direction tried. The shapes include plate 1's two in-plane modes, whose w is round-off:
    # it was their MAC that flipped the shape pairing on AMD (OpenBLAS Zen kernels).
    case, model = plate1
    base = _missed_mode_case(plate1) if pairing == "auto" else case
    initial = np.array(PAPER["plate1"]["test2"]["initial"]) * SI
    options = {"model": model, "pairing": pairing, "tol": 1e-3}
    reference = estimate(base, method, prior_mean=initial, prior_sd=initial / 6, **options)
    rng = np.random.default_rng(16)

    def nudge(a):
        return np.asarray(a) * (1 + 1e-12 * rng.standard_normal(np.shape(a)))

    for _ in range(4):
        # the shapes made anew by the solver from nudged constants: its own round-off
        data = _missed_mode_case(plate1, nudge) if pairing == "auto" else case
        perturbed = data.with_measured(
            frequency_Hz=nudge(data.measured.frequency_Hz), sigma_Hz=nudge(data.measured.sigma_Hz)
        )
        start = nudge(initial)
        again = estimate(perturbed, method, prior_mean=start, prior_sd=start / 6, **options)
        assert again.converged == reference.converged, again.message
        np.testing.assert_array_equal(again.modes, reference.modes)
        np.testing.assert_allclose(again.constants, reference.constants, rtol=1e-3)


def test_no_progress_along_a_barely_seen_coefficient_is_unidentified():
    # The flat problem sees C44 through a column 1 % of the others': the data carry far less
    # information along it than the step covariance (a generalised eigenvalue well below 1,
    # computed independently here). A run that stalls with its step along C44 is named
    # unidentified there; one whose step lies along a well-seen coefficient (C11) is not.
    from types import SimpleNamespace

    import scipy.linalg

    from bayesplate.estimators.drift import WEAK_INFORMATION, weakly_determined

    problem, A = _flat_problem()
    b = problem.mu_b.copy()
    state = SimpleNamespace(b=b, prediction=problem.predict(b), drifted={})
    x = np.abs(b)
    F = (A * x).T @ np.linalg.solve(problem.V_Y, A * x)
    lam = scipy.linalg.eigh(F, np.linalg.inv(problem.V_b / np.outer(x, x)), eigvals_only=True)
    assert lam[0] < WEAK_INFORMATION < lam[1]  # one weak direction, the others well seen
    along = np.zeros(6)
    along[4] = 0.3
    message = weakly_determined(problem, state, problem.V_b, along, 1e-3)
    assert message.startswith("unidentified:") and "C44 (G23)" in message
    assert state.drifted["information"][0] == pytest.approx(lam[0], rel=1e-6)
    across = np.zeros(6)
    across[0] = 0.3
    assert weakly_determined(problem, state, problem.V_b, across, 1e-3) == ""
