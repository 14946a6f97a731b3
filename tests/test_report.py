"""`bayesplate report`: the newcomer's command, the report pipeline, its cache and atomic
writes; mode pairing by measured shapes (MAC) and its figure."""

import os
import pathlib
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest
from matplotlib.figure import Figure

from bayesplate.estimators import estimate
from bayesplate.io import Measurement, bundled_case_path, load_case
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.likelihood.posterior import GaussianProblem
from bayesplate.matching.pairing import (
    MAC_EXTRA_MODES,
    Pairing,
    UnpairedModeWarning,
    pair_measured,
)
from bayesplate.plate.model import PlateModel
from bayesplate.plots import mac_matrix_plot
from bayesplate.report import (
    ESTIMATORS,
    ReportOptions,
    StepCache,
    compute_report,
    make_report,
    write_report,
)

REPO = pathlib.Path(__file__).resolve().parents[1]
SECTIONS = (
    "## Case",
    "### Prior",
    "### Measured frequencies",
    "## Estimates",
    "### Per-mode residuals",
    "## Modes",
    "## Posterior",
    "## Model discrepancy",
)
PNG = b"\x89PNG\r\n\x1a\n"
# A PNG of a real figure (axes, labels, bars) is tens of kB at 120 dpi; an empty or broken
# one is a few kB.
MIN_PNG_BYTES = 10_000
FAST = ReportOptions(diagnose=False, sample=False)  # pairing, B, MVE, MVE-mod, modes


def _leftovers(folder):
    """Temporary files (dot-prefixed) left next to the outputs."""
    if not pathlib.Path(folder).exists():
        return []
    return [
        p.name for p in pathlib.Path(folder).iterdir() if p.name.startswith(".") and p.is_file()
    ]


# ----------------------------------------------------------------------------- (c) pairing


@pytest.fixture(scope="module")
def plate1():
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    b = stiffness_from_engineering(case.prior.mean)
    modal = model.solve(b, 20)
    x, y = np.meshgrid(np.linspace(0.01, 0.19, 7), np.linspace(0.01, 0.09, 5))
    points = np.column_stack([x.ravel(), y.ravel()])
    w = (model.interpolation(points) @ modal.vectors).T  # (modes, points)
    return case, model, b, modal, points, w


def _shaped_case(plate1, shapes_of, rng, noise=0.05, extra_rows=()):
    """Plate 1 measured with the shapes of computed modes `shapes_of` (sign flips, a random
    scale, `noise` x max|w| Gaussian noise) at ascending frequencies (those of the same
    modes, sorted), then `extra_rows` of given shapes at higher frequencies.

    Measured mode i has the shape of computed mode ``shapes_of[i]``: the expected pairing.
    """
    case, _, _, modal, points, w = plate1
    k = len(shapes_of)
    shapes = w[shapes_of] * rng.choice([-1.0, 1.0], (k, 1)) * rng.uniform(0.5, 3.0)
    shapes += noise * np.abs(shapes).max(axis=1, keepdims=True) * rng.standard_normal(shapes.shape)
    f = np.sort(modal.frequency_Hz[shapes_of])
    for row in extra_rows:
        shapes = np.vstack([shapes, row])
        f = np.append(f, f[-1] + 500.0)
    measured = Measurement(f, 0.01 * f, points=points, shapes=shapes)
    return case.with_measured(measured), np.asarray(shapes_of)


def test_mac_pairing_finds_permuted_modes(plate1, rng):
    case, model, b, *_ = plate1
    perm = [0, 1, 3, 2, 5, 4, 6, 8, 7]  # measured shapes of swapped close pairs
    shaped, expected = _shaped_case(plate1, perm, rng)
    pairing = pair_measured(shaped, model, b)
    assert pairing.how == "mac"
    np.testing.assert_array_equal(pairing.modes, expected)
    np.testing.assert_array_equal(pairing.kept(shaped.measured.size), np.arange(len(perm)))
    assert pairing.mac.shape == (len(perm), len(perm) + MAC_EXTRA_MODES)
    # 5 % noise on a 35-point grid: the paired MACs stay near 1 (they are ~0.99)
    assert np.all(pairing.mac[np.arange(len(perm)), pairing.modes] > 0.9)


def test_mac_pairing_tolerates_missing_modes(plate1, rng):
    # the test missed computed modes 3 and 7 (0-based 2 and 6): the measured ones pair with
    # the modes they are, not with the next in order
    case, model, b, *_ = plate1
    computed = [0, 1, 3, 4, 5, 7, 8, 9]
    shaped, expected = _shaped_case(plate1, computed, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnpairedModeWarning)
        pairing = pair_measured(shaped, model, b)
    np.testing.assert_array_equal(pairing.modes, expected)


def test_mac_pairing_drops_an_extra_mode_with_a_warning(plate1, rng):
    # a measured shape that is no plate mode (a random pattern): MAC < 0.5 against all
    case, model, b, *_ = plate1
    noise = rng.standard_normal(plate1[4].shape[0])
    shaped, expected = _shaped_case(plate1, [0, 1, 2, 3, 4, 5], rng, extra_rows=[noise])
    with pytest.warns(UnpairedModeWarning, match="measured mode 7"):
        pairing = pair_measured(shaped, model, b)
    np.testing.assert_array_equal(pairing.modes, expected)
    np.testing.assert_array_equal(pairing.unpaired(7), [6])
    assert "measured mode 7 unpaired" in pairing.describe(7)
    # the unpaired frequency is left out of the fit: Y has the six paired ones
    problem = GaussianProblem.from_case(shaped, model, pairing)
    assert problem.m == 6
    with pytest.warns(UnpairedModeWarning):
        result = estimate(shaped, "B", model=model)  # "auto": by shape, the same pairing
    assert result.converged
    np.testing.assert_allclose(result.measured_Hz, shaped.measured.frequency_Hz[:6], rtol=1e-12)
    np.testing.assert_array_equal(result.modes, expected + 1)


def test_without_shapes_pairing_is_by_order_and_says_so(plate1):
    case, model, b, *_ = plate1
    pairing = pair_measured(case, model, b)
    assert pairing.how == "order" and pairing.mac is None
    np.testing.assert_array_equal(pairing.modes, np.arange(case.measured.size))
    assert pairing.describe(case.measured.size).startswith("by order")
    indexed = case.with_measured(mode=np.arange(case.measured.size) + 1)
    assert pair_measured(indexed, model, b).how == "index"
    with pytest.raises(ValueError, match="points_mm and measured.shapes"):
        pair_measured(case, model, b, how="mac")


def test_pairing_select_keeps_the_paired_measurements(plate1):
    case = plate1[0]
    pairing = Pairing([0, 2], "mac", measured=[0, 3])
    kept = pairing.select(case.measured)
    np.testing.assert_array_equal(kept.frequency_Hz, case.measured.frequency_Hz[[0, 3]])
    with pytest.raises(ValueError, match="one entry per paired mode"):
        Pairing([0, 2], "mac", measured=[0])


def test_mac_matrix_figure(tmp_path, rng):
    mac = rng.uniform(0, 0.05, (5, 9))
    mac[np.arange(5), [0, 2, 1, 3, 5]] = [0.99, 0.97, 0.95, 0.9, 0.7]
    fig = mac_matrix_plot(mac, [0, 2, 1, 3, 5], measured_Hz=[100, 200, 210, 300, 420])
    ax = fig.axes[0]
    assert ax.get_xlabel() == "computed elastic mode" and ax.get_ylabel() == "measured mode"
    assert fig.axes[1].get_ylabel().startswith("MAC")  # the colour bar, 0..1
    assert fig.axes[1].get_ylim() == (0.0, 1.0)
    fig.savefig(tmp_path / "mac.png", dpi=120)
    assert (tmp_path / "mac.png").stat().st_size > MIN_PNG_BYTES


# ----------------------------------------------------------------------------- (b) pipeline


@pytest.fixture(scope="module")
def plate1_report(tmp_path_factory):
    """The report of Plate 1 without diagnose and sampling (the fast steps), and its lines."""
    out = tmp_path_factory.mktemp("plate1_report")
    lines = []
    path, data = make_report(bundled_case_path("plate1"), out, FAST, lines.append, "plate1")
    return out, path, data, lines


def test_report_pipeline_on_plate1(plate1_report):
    out, path, data, lines = plate1_report
    text = path.read_text(encoding="utf-8")
    for section in SECTIONS:
        assert section in text, section
    assert "Pairing: by order" in text  # Plate 1 has no measured shapes
    assert "Not sampled: not requested" in text and "Not run (--no-diagnose)" in text
    for method in ESTIMATORS:
        assert data.results[method]["converged"], data.results[method]["message"]
    # MVE on Plate 1 reaches the constants the frequencies came from (Table 3: 0.1 %)
    ref = data.case.reference
    np.testing.assert_allclose(
        data.results["MVE"]["constants"][[0, 1, 3]], ref[[0, 1, 3]], rtol=2e-3
    )
    for name in ("residuals", "sensitivities", "mode_shapes"):
        png = out / f"{name}.png"
        assert png.read_bytes()[:8] == PNG and png.stat().st_size > MIN_PNG_BYTES
        assert f"({name}.png)" in text
    assert not _leftovers(out)
    # one line per step at its start and end, each with the elapsed time
    assert sum("estimate MVE-mod" in line for line in lines) == 2
    assert all(line.startswith("[") and " s] " in line for line in lines)


def test_second_run_reuses_every_step(plate1_report):
    out, _, first, _ = plate1_report
    lines = []
    data = compute_report(bundled_case_path("plate1"), FAST, out / ".cache", lines.append)
    assert data.computed == []
    assert data.reused == ["pairing", *ESTIMATORS, "modes"]
    assert sum("reused (cached)" in line for line in lines) == 5
    for step in data.reused:  # the same numbers as the run that computed them
        for key, value in first.results[step].items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(data.results[step][key], value)


def test_changed_case_or_options_invalidate(tmp_path):
    case = bundled_case_path("plate1")
    cache = StepCache(tmp_path, case.read_bytes())
    cache.save("B", {"mesh": [8, 4]}, {"constants": np.arange(6.0), "message": "ok"})
    stored = cache.load("B", {"mesh": [8, 4]})
    np.testing.assert_array_equal(stored["constants"], np.arange(6.0))
    assert stored["message"] == "ok"
    assert cache.load("B", {"mesh": [16, 8]}) is None  # other options
    edited = case.read_bytes().replace(b"611.23", b"611.24")
    assert StepCache(tmp_path, edited).load("B", {"mesh": [8, 4]}) is None  # other case
    assert StepCache(tmp_path, case.read_bytes(), "9.9").load("B", {"mesh": [8, 4]}) is None
    (tmp_path / "B.npz").write_bytes(b"not a zip file")  # a damaged file is recomputed
    assert cache.load("B", {"mesh": [8, 4]}) is None


def test_changed_case_recomputes(plate1_report, tmp_path):
    out, *_ = plate1_report
    edited = tmp_path / "plate1.toml"
    text = bundled_case_path("plate1").read_text().replace("611.23", "611.3")
    edited.write_text(text)
    shutil.copytree(out / ".cache", tmp_path / ".cache")
    data = compute_report(
        edited, ReportOptions(diagnose=False, sample=False), tmp_path / ".cache", lambda line: None
    )
    assert data.reused == [] and data.computed[:2] == ["pairing", "B"]


def test_failure_mid_report_leaves_no_partial_file(plate1_report, tmp_path, monkeypatch):
    out, *_ = plate1_report
    data = compute_report(bundled_case_path("plate1"), FAST, out / ".cache", lambda line: None)
    import bayesplate.plots

    def broken(*args, **kwargs):
        raise RuntimeError("figure failed")

    monkeypatch.setattr(bayesplate.plots, "mode_shapes", broken)
    target = tmp_path / "report"
    with pytest.raises(RuntimeError, match="figure failed"):
        write_report(data, target)
    assert not (target / "report.md").exists()  # written last: not at all
    assert not (target / "mode_shapes.png").exists()
    assert not _leftovers(target)
    for png in target.glob("*.png"):  # figures written before the failure are whole
        assert png.read_bytes()[:8] == PNG


def test_failure_while_saving_a_figure_leaves_nothing(plate1_report, tmp_path, monkeypatch):
    out, *_ = plate1_report
    data = compute_report(bundled_case_path("plate1"), FAST, out / ".cache", lambda line: None)
    (tmp_path / "report.md").write_text("the previous report\n")

    def half_then_fail(self, handle, **kwargs):
        handle.write(PNG + b"\0" * 100)
        raise OSError("disk full")

    monkeypatch.setattr(Figure, "savefig", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        write_report(data, tmp_path)
    assert not list(tmp_path.glob("*.png"))
    assert (tmp_path / "report.md").read_text() == "the previous report\n"  # untouched
    assert not _leftovers(tmp_path)


def test_failure_in_a_step_writes_no_cache_entry(tmp_path, monkeypatch):
    import bayesplate.report

    def broken(*args, **kwargs):
        raise RuntimeError("solver failed")

    monkeypatch.setattr(bayesplate.report.steps, "estimate_step", broken)
    with pytest.raises(RuntimeError, match="solver failed"):
        make_report(bundled_case_path("plate1"), tmp_path, FAST, lambda line: None)
    assert sorted(p.name for p in (tmp_path / ".cache").iterdir()) == ["pairing.npz"]
    assert not (tmp_path / "report.md").exists()


def test_report_with_measured_shapes_shows_the_mac(plate1, rng, tmp_path):
    perm = [0, 1, 3, 2, 4, 5, 6, 7, 8, 9, 10, 11]
    shaped, _ = _shaped_case(plate1, perm, rng)
    toml = tmp_path / "shaped.toml"
    toml.write_text(_case_toml(shaped))
    path, data = make_report(toml, tmp_path / "out", FAST, lambda line: None)
    text = path.read_text(encoding="utf-8")
    assert "Pairing: by mode shape" in text and "| MAC |" in text
    assert (tmp_path / "out" / "mac.png").stat().st_size > MIN_PNG_BYTES
    np.testing.assert_array_equal(data.pairing().modes[:4], [0, 1, 3, 2])


def _case_toml(case):
    """A case file of Plate 1 with the given measurement (shapes included)."""
    m = case.measured
    head = bundled_case_path("plate1").read_text().split("[measured]")[0]
    tail = "[prior]" + bundled_case_path("plate1").read_text().split("[prior]")[1]
    rows = ",\n  ".join("[" + ", ".join(f"{v:.9g}" for v in row) + "]" for row in m.shapes)
    points = ", ".join(f"[{1e3 * x:.6g}, {1e3 * y:.6g}]" for x, y in m.points)
    return (
        f"{head}[measured]\nfrequency_Hz = [{', '.join(f'{f:.9g}' for f in m.frequency_Hz)}]\n"
        f"sigma_rel = 0.01\npoints_mm = [{points}]\nshapes = [\n  {rows}\n]\n\n{tail}"
    )


@pytest.mark.slow
def test_full_report_on_plate1(tmp_path):
    # every step, diagnose and (when the package has it) the posterior, on the 8 x 4 mesh
    path, data = make_report(
        bundled_case_path("plate1"), tmp_path, ReportOptions(), lambda line: None
    )
    text = path.read_text(encoding="utf-8")
    assert "**Verdict:" in text
    for name in (
        "diagnose_residuals",
        "diagnose_map_local_stiffness_loss",
        "diagnose_map_point_mass",
    ):
        assert (tmp_path / f"{name}.png").stat().st_size > MIN_PNG_BYTES
    if "sample" in data.results:
        assert (tmp_path / "posterior_corner.png").stat().st_size > MIN_PNG_BYTES
        assert "94 % HDI" in text


# ----------------------------------------------------------------------------- (a) newcomer


@pytest.mark.slow
def test_readme_first_command_in_a_fresh_environment(tmp_path):
    """The README's first command as a newcomer runs it, in a new virtual environment.

    A wheel of this checkout, installed (not editable) in a new environment: every module
    and bundled case file must come with the package, and the command must run from any
    folder; then `bayesplate report frederiksen_t300` with ``--quick`` (the full report takes
    about a minute and a half on a quiet 2-core machine, several on a loaded one; --quick runs
    every step on a coarser mesh). The dependencies are this environment's, seen from the
    new one and checked against the wheel's requirements by ``pip check``: `.ci/run` has
    just installed them from PyPI in a fresh environment of its own, as the README's command
    does, so installing them a second time here would test nothing more.
    """
    import sysconfig
    import zipfile

    readme = (REPO / "README.md").read_text()
    assert "bayesplate report frederiksen_t300 -o report" in readme
    pip = [sys.executable, "-m", "pip"]
    wheels = tmp_path / "wheels"
    subprocess.run([*pip, "wheel", "--quiet", "--no-deps", "-w", wheels, REPO], check=True)
    (wheel,) = wheels.glob("bayesplate-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        packed = set(archive.namelist())
    tree = {
        p.relative_to(REPO).as_posix()
        for p in (REPO / "bayesplate").rglob("*")
        if p.suffix in (".py", ".toml") and "__pycache__" not in p.parts
    }
    assert tree <= packed, sorted(tree - packed)  # modules and case files in the wheel
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", venv], check=True)
    bin_dir = venv / ("Scripts" if os.name == "nt" else "bin")
    python = bin_dir / "python"
    purelib = subprocess.run(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    here = sysconfig.get_paths()
    dependencies = dict.fromkeys((here["purelib"], here["platlib"]))  # after the new one's
    pathlib.Path(purelib, "dependencies.pth").write_text("\n".join(dependencies) + "\n")
    subprocess.run([*pip, "--python", python, "install", "--quiet", "--no-deps", wheel], check=True)
    checked = subprocess.run([*pip, "--python", python, "check"], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout + checked.stderr  # what is missing, named
    out = tmp_path / "report"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    where = subprocess.run(
        [python, "-c", "import bayesplate; print(bayesplate.__file__)"],
        cwd=tmp_path,
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    assert pathlib.Path(where.strip()).is_relative_to(venv), where  # the wheel's, not REPO's
    run = subprocess.run(
        ["bayesplate", "report", "frederiksen_t300", "-o", str(out), "--quick"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert "s] " in run.stderr  # progress lines with the elapsed time
    text = (out / "report.md").read_text(encoding="utf-8")
    for section in SECTIONS:
        assert section in text, section
    assert "**Verdict:" in text
    figures = list(out.glob("*.png"))
    assert {p.stem for p in figures} >= {
        "residuals",
        "sensitivities",
        "mode_shapes",
        "diagnose_residuals",
    }
    for png in figures:
        assert png.stat().st_size > MIN_PNG_BYTES, png.name
        assert f"({png.name})" in text


def test_report_names_a_missed_mode_by_likelihood(tmp_path):
    # Issue 16: plate 1 without its 5th frequency, `--pairing likelihood`: the report's
    # pairing line names computed mode 5 unobserved, and every estimator fits the 13 peaks
    # with the modes above the gap (not by order).
    text = bundled_case_path("plate1").read_text()
    old = "frequency_Hz = [611.23, 2002.7, 2171.2, 2338.5, 2478.2, 3810.3, 5165.3,"
    assert old in text
    case_file = tmp_path / "plate1_missed.toml"
    case_file.write_text(
        text.replace(old, "frequency_Hz = [611.23, 2002.7, 2171.2, 2338.5, 3810.3, 5165.3,")
    )
    options = ReportOptions(diagnose=False, sample=False, pairing="likelihood")
    path, data = make_report(case_file, tmp_path / "out", options, lambda line: None, "missed")
    report = path.read_text()
    assert "computed mode 5 unobserved" in report
    assert list(data.results["pairing"]["unobserved"]) == [4]
    np.testing.assert_array_equal(data.pairing().modes, np.delete(np.arange(14), 4))
    for method in ("B", "MVE", "MVE-mod"):  # each step settled the same assignment
        np.testing.assert_array_equal(
            data.results[method]["modes"], np.delete(np.arange(14), 4) + 1
        )


def test_the_estimate_steps_share_one_fast_model_checked_by_the_full_one(tmp_path, monkeypatch):
    # above FAST_MIN_DOFS unknowns the report builds one fast model and the three estimators
    # iterate on it; plate 1's 8 x 4 mesh is made to count as large
    from bayesplate.estimators import fast as fast_module

    monkeypatch.setattr(fast_module, "FAST_MIN_DOFS", 0)
    built = []
    original = fast_module.fast_model

    def counting(*args, **kwargs):
        built.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(fast_module, "fast_model", counting)
    path, data = make_report(bundled_case_path("plate1"), tmp_path, FAST, None, "plate1")
    assert len(built) == 1 and data.fast is not None
    full = estimate(data.case, "B", model=data.plate_model(), forward="full")
    for method in ("B", "MVE", "MVE-mod"):
        check = data.results[method]["check"]
        assert check["confirmed"] and check["max_rel_error"] <= check["tolerance"]
        # stopped and confirmed (MVE's answers are flagged implausible: the case's prior is 6
        # sd from the plate's G23)
        assert data.results[method]["converged"]
        assert data.results[method]["status"] in ("converged", "implausible")
    np.testing.assert_allclose(data.results["B"]["b"], full.b, rtol=1e-3)
    assert "| full-model check | confirmed" in path.read_text(encoding="utf-8")


def test_a_report_resumed_on_the_fast_model_gives_the_same_numbers(tmp_path, monkeypatch):
    # above FAST_MIN_DOFS unknowns the estimate steps iterate on a fast model; a step lost
    # to a kill and run again must see the same fast model as in the unbroken run (it used to
    # see one enriched by the steps before it only when they ran in the same process)
    from bayesplate.estimators import fast as fast_module

    monkeypatch.setattr(fast_module, "FAST_MIN_DOFS", 0)
    _, whole = make_report(bundled_case_path("plate1"), tmp_path / "whole", FAST, None, "p")
    out = tmp_path / "resumed"
    make_report(bundled_case_path("plate1"), out, FAST, None, "p")
    lost = [out / ".cache" / f"{step}.npz" for step in ("MVE", "MVE-mod")]
    assert all(path.exists() for path in lost)
    for path in lost:  # killed after B: MVE and MVE-mod not stored
        path.unlink()
    _, resumed = make_report(bundled_case_path("plate1"), out, FAST, None, "p")
    for method in ESTIMATORS:
        a, b = whole.results[method], resumed.results[method]
        np.testing.assert_array_equal(a["b"], b["b"])
        np.testing.assert_array_equal(a["sd"], b["sd"])
        assert a["iterations"] == b["iterations"]


def test_the_sampler_beside_diagnose_gives_the_numbers_of_the_two_in_turn(monkeypatch):
    # on two cores the report samples in a forked process while diagnose runs: the
    # posterior and the diagnosis are those of the steps run one after the other
    from bayesplate.report import runner

    options = ReportOptions(quick=True)
    side = compute_report(bundled_case_path("plate1"), options, progress=lambda line: None)
    assert runner.available_cores() < 2 or "sample" in side.computed
    monkeypatch.setattr(runner, "available_cores", lambda: 1)
    turn = compute_report(bundled_case_path("plate1"), options, progress=lambda line: None)
    for key in ("mean", "sd", "hdi", "ess_bulk"):
        np.testing.assert_array_equal(side.results["sample"][key], turn.results["sample"][key])
    assert side.results["diagnose"]["diagnosis"] == turn.results["diagnose"]["diagnosis"]
    assert side.seconds["sample"] > 0  # the sampler's own time, measured in its process
