"""Start-up: ``bayesplate --help`` loads no numerics, and the lazy exports still import.

The time itself is measured by ``benchmarks/bench_startup.py``; these tests hold what makes it
short: the parser is built from the standard library and :mod:`bayesplate.cli` alone.
"""

import argparse
import importlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Third-party packages that ``--help`` must not load (slow to import).
HEAVY = (
    "numpy",
    "scipy",
    "matplotlib",
    "emcee",
    "arviz",
    "xarray",
    "h5py",
    "netCDF4",
    "pyuff",
    "sdypy",
    "dask",
    "distributed",
)

#: Each package's ``__all__`` before the exports became lazy (commit 9f5ebd1): every name
#: must still import from where it did.
PUBLIC = {
    "bayesplate": [
        "Case",
        "CaseError",
        "ModalResult",
        "PlateModel",
        "EstimateResult",
        "bundled_case_path",
        "diagnose",
        "estimate",
        "engineering_from_stiffness",
        "load_case",
        "stiffness_from_engineering",
        "__version__",
        # subpackages the eager __init__ left as attributes of the package
        "assignment",
        "discrepancy",
        "estimators",
        "fem",
        "io",
        "laminate",
        "model",
        "pairing",
        "posterior",
        "quantities",
    ],
    "bayesplate.cli": ["main", "build_parser"],
    "bayesplate.discrepancy": [
        "CANDIDATES",
        "ElasticFoundation",
        "LocalStiffnessLoss",
        "Parameter",
        "Physics",
        "PlyMisalignment",
        "PointMass",
        "ThicknessTaper",
        "candidates",
    ],
    "bayesplate.estimators": [
        "METHODS",
        "STATUSES",
        "TRACKING",
        "DEFAULT_MAX_ITER",
        "Conventions",
        "CONVENTIONS",
        "resolve_conventions",
        "EstimateResult",
        "estimate",
        "settle_pairing",
        "run",
        "b_step",
        "mve_step",
    ],
    "bayesplate.io": [
        "FRFData",
        "PoleAnalysis",
        "extract_poles",
        "is_tap_test",
        "modal_data_from_poles",
        "read_poles",
        "read_spectra",
        "write_chart",
        "write_poles",
        "MAX_MESH_ELEMENTS",
        "DEFAULT_SIGMA_REL",
        "CaseError",
        "Plate",
        "Measurement",
        "Prior",
        "Case",
        "load_case",
        "parse_case",
        "bundled_case_path",
        "bundled_case_names",
        "check_engineering_constants",
        "engineering_to_si",
        "engineering_from_si",
        "ModalData",
        "read_modal_data",
        "read_frequency_csv",
        "case_from_modal_data",
        "write_case",
        "bundled_plate_names",
        "bundled_plate_path",
        "atomic_write",
        "atomic_write_text",
        "save_figure",
        "write_netcdf",
        "jsonable",
        "write_json",
        "constants_json",
        "estimate_to_dict",
        "sampling_to_dict",
        "diagnosis_to_dict",
    ],
    "bayesplate.plots": [
        "CONSTANT_LABELS",
        "autocorrelation_plot",
        "corner_estimates",
        "diagnosis_figures",
        "estimate_residuals",
        "frequency_comparison",
        "location_map",
        "mac_matrix_plot",
        "mode_shapes",
        "posterior_corner",
        "residual_comparison",
        "sampling_figures",
        "sensitivity_bars",
        "trace_plot",
    ],
    "bayesplate.reduced": [
        "DEFAULT_TOLERANCE",
        "Box",
        "Certificate",
        "CertifiedModel",
        "ReducedModalResult",
        "ReducedModel",
        "ReducedModelWarning",
        "certify",
        "fast_model",
        "prior_stiffness",
        "stiffness_box",
    ],
    "bayesplate.report": [
        "ESTIMATORS",
        "ReportData",
        "ReportOptions",
        "StepCache",
        "compute_report",
        "make_report",
        "render_markdown",
        "report_figures",
        "sampling_available",
        "write_report",
    ],
    "bayesplate.sampling": [
        "CASE_UNITS",
        "HDI_PROB",
        "EigenvalueForward",
        "LaplaceMove",
        "SamplingResult",
        "SamplingSetup",
        "ScreenedDEMove",
        "WhitenedLogPosterior",
        "covariance_agreement",
        "curvature_covariance",
        "default_moves",
        "linearisation_band",
        "posterior_box",
        "prepare",
        "sample",
        "sample_problem",
    ],
}

#: After ``bayesplate ... --help``, print the loaded modules as JSON (stdout is the help).
_PROBE = """
import json, runpy, sys
sys.argv = ["bayesplate", *{argv!r}]
try:
    runpy.run_module("bayesplate.cli", run_name="__main__", alter_sys=True)
except SystemExit as stop:
    code = stop.code
else:
    code = None
sys.stderr.write("\\nMODULES " + json.dumps({{"code": code, "modules": sorted(sys.modules)}}))
"""


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return env


def _run(code):
    """Run `code` in a fresh interpreter with this tree first on the path."""
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=_env(), cwd=ROOT
    )


def _loaded_after(argv):
    """(exit code, stdout, modules loaded) of ``bayesplate *argv`` in a fresh interpreter."""
    proc = _run(_PROBE.format(argv=list(argv)))
    head, sep, tail = proc.stderr.rpartition("\nMODULES ")
    assert sep, proc.stderr
    probe = json.loads(tail)
    return probe["code"], proc.stdout, set(probe["modules"])


def _subcommands():
    from bayesplate.cli import build_parser

    (sub,) = (a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices)


def _heavy(modules):
    """The loaded modules that ``--help`` should not need."""
    third_party = {m for m in modules if m.split(".")[0] in HEAVY}
    ours = {
        m for m in modules if m.startswith("bayesplate.") and not m.startswith("bayesplate.cli")
    }
    return sorted(third_party | ours)


def test_subcommands_are_the_known_ones():
    # a new subcommand is covered by the help test below through _subcommands()
    assert _subcommands() == [
        "cases",
        "modes",
        "import",
        "diagnose",
        "estimate",
        "report",
        "sample",
        "batch",
    ]


@pytest.mark.parametrize(
    "argv", [["--help"]] + [[c, "--help"] for c in _subcommands()], ids=lambda argv: " ".join(argv)
)
def test_help_loads_no_numerics(argv):
    code, out, modules = _loaded_after(argv)
    assert code == 0
    assert out.startswith("usage: bayesplate")
    assert "bayesplate.cli.main" in modules  # the probe did run the command line
    assert _heavy(modules) == []


def test_a_usage_error_loads_no_numerics_and_exits_2():
    code, _, modules = _loaded_after(["estimate", "--method", "X", "plate1"])
    assert code == 2
    assert _heavy(modules) == []


def test_a_case_error_is_still_one_line_and_exit_2(tmp_path):
    # CaseError is imported after parsing now: the error path must still catch it
    missing = tmp_path / "missing.toml"
    proc = subprocess.run(
        [sys.executable, "-m", "bayesplate.cli", "modes", str(missing)],
        capture_output=True,
        text=True,
        env=_env(),
        cwd=ROOT,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("bayesplate: error: ")
    assert str(missing) in lines[0]


def test_import_bayesplate_is_light_and_its_names_load_on_use():
    code = (
        "import sys, bayesplate\n"
        "light = 'numpy' not in sys.modules and 'bayesplate.io' not in sys.modules\n"
        "from bayesplate import estimate, load_case\n"
        "import bayesplate.estimators\n"
        "print(light, estimate is bayesplate.estimators.estimate,\n"
        "      load_case is bayesplate.io.load_case, 'scipy' in sys.modules)\n"
        "print(bayesplate.__file__)\n"
    )
    proc = _run(code)
    assert proc.returncode == 0, proc.stderr
    flags, where = proc.stdout.splitlines()
    assert flags.split() == ["True", "True", "True", "True"]
    assert Path(where) == ROOT / "bayesplate" / "__init__.py"  # this tree, not an installed one


def test_star_import_gives_every_public_name():
    proc = _run(
        "from bayesplate import *\nimport bayesplate\n"
        "print(all(n in globals() for n in bayesplate.__all__))"
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "True"


@pytest.mark.parametrize("package", sorted(PUBLIC))
def test_every_public_name_still_imports(package):
    module = importlib.import_module(package)
    missing = [name for name in PUBLIC[package] if not hasattr(module, name)]
    assert missing == []
    exported = set(getattr(module, "__all__", ()))
    assert exported >= set(PUBLIC[package]) - {"__version__"} - _submodule_names(package)


def _submodule_names(package):
    module = importlib.import_module(package)
    return (
        {n for n in PUBLIC[package] if (ROOT / package.replace(".", "/") / n).is_dir()}
        | {n for n in PUBLIC[package] if (ROOT / package.replace(".", "/") / f"{n}.py").is_file()}
        # a submodule that moved into a group (``bayesplate.pairing`` is matching.pairing)
        | {n for n in PUBLIC[package] if isinstance(getattr(module, n, None), type(module))}
    )


def test_an_unknown_name_is_an_attribute_error():
    import bayesplate

    with pytest.raises(AttributeError, match="no_such_name"):
        bayesplate.no_such_name  # noqa: B018
    assert not hasattr(bayesplate, "cli_not_a_module")
    assert {"estimate", "io", "PlateModel"} <= set(dir(bayesplate))


def test_the_parser_choices_match_the_estimators():
    from bayesplate.cli import options
    from bayesplate.estimators import CONVENTIONS, DEFAULT_MAX_ITER, FORWARDS, METHODS

    assert options.METHOD_CHOICES == METHODS
    assert options.CONVENTION_CHOICES == tuple(CONVENTIONS)
    assert options.FORWARD_CHOICES == FORWARDS
    assert options.DEFAULT_MAX_ITER == DEFAULT_MAX_ITER


def test_the_parser_band_defaults_match_the_import():
    from bayesplate.cli import options
    from bayesplate.io import band

    assert options.DEFAULT_BAND_MODES == band.DEFAULT_BAND_MODES
    assert options.BAND_LOW_FACTOR == band.BAND_LOW_FACTOR
    assert options.BAND_HIGH_FACTOR == band.BAND_HIGH_FACTOR


def test_a_closed_standard_output_ends_in_one_line_without_traceback():
    # `bayesplate cases | head -0`: the reader is gone before the first line is written
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "bayesplate.cli", "cases"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=60) == 1
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert err == "bayesplate cases: standard output closed; stopped\n"


def test_a_ctrl_c_after_the_work_is_done_keeps_the_commands_status():
    # a SIGINT that lands once the command's work is done (its files closed, the interpreter
    # shutting down) must not turn its status into a death by SIGINT (-2), as it did in CI
    # once: a test that killed `sample` at a random moment hit the moment after its work
    script = (
        "import os, signal, sys, time\n"
        "from bayesplate.cli.main import main\n"
        "sys.argv = ['bayesplate', 'cases']\n"
        "status = main()\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "time.sleep(0.2)\n"
        "sys.exit(status)\n"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run(
        [sys.executable, "-c", script],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
