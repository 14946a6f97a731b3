import hashlib
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# the independent closed-form references live in tests/reference
sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture
def rng():
    """One seeded generator per test: the same seed gives the same numbers."""
    return np.random.default_rng(20070461)


@pytest.fixture
def sheet(tmp_path):
    """plate1 without its measured frequencies: a plate sheet (the tap-test imports')."""
    from bayesplate.io import bundled_case_path

    text = bundled_case_path("plate1").read_text()
    path = tmp_path / "plate1_sheet.toml"
    path.write_text(re.sub(r"frequency_Hz = \[[^\]]*\]\n", "", text))
    return path


# ----------------------------------------------------------------------------- fuzz counting


class FuzzLedger:
    """The corrupted inputs the fuzz tests (tests/test_fuzz_*.py) saw refused cleanly.

    An input is counted once: by the bytes of the files it consists of and the command line
    with file paths reduced to their names (a temporary folder does not make it new).
    """

    def __init__(self):
        self.seen = set()

    def count(self, argv, files=()):
        """Record one corrupted input: `argv` and the contents of `files` (paths)."""
        digest = hashlib.sha256()
        for arg in argv:
            digest.update(Path(str(arg)).name.encode("utf-8", "surrogateescape") + b"\0")
        for path in files:
            digest.update(b"\1" + (Path(path).read_bytes() if Path(path).exists() else b""))
        self.seen.add(digest.hexdigest())


_LEDGER = FuzzLedger()


@pytest.fixture(scope="session")
def fuzz_ledger():
    """The session's :class:`FuzzLedger` (session scope: usable under hypothesis)."""
    return _LEDGER


def pytest_terminal_summary(terminalreporter):
    """Print how many distinct corrupted inputs the fuzz tests saw refused cleanly."""
    if not _LEDGER.seen:
        return
    failed = [r for r in terminalreporter.stats.get("failed", []) if "test_fuzz_" in r.nodeid]
    verdict = "all refused cleanly" if not failed else f"{len(failed)} fuzz tests FAILED"
    line = f"fuzzing: {len(_LEDGER.seen)} distinct corrupted inputs, {verdict}"
    terminalreporter.write_line(line)


# ------------------------------------------------------------------------------- test tiers
# Every test is in one of three tiers:
#   quick  the README's command, `python -m pytest -m "not slow and not ci" -q`: the analytic
#          references, the input checks, the layer rules, the fast tiers of the studies and a
#          quick run of every command; under 5 minutes on two cores (reports/test_tiers.md);
#   ci     fast tests left out of the quick run because they cost more than they add to it:
#          many diagnoses, Dask clusters, commands run as subprocesses; `.ci/run` runs them;
#   slow   long runs, marked `@pytest.mark.slow` test by test; `.ci/run` runs them.
# The ci tier is chosen here, from measured durations (reports/test_tiers.md): one list to
# read instead of markers spread over the modules, and a new test is in the quick run until
# its time says otherwise (as a test is fast until marked slow). Whole modules where they
# can be; a test by name where the rest of its module is cheap or holds the quick run of a
# command. A test goes here when it takes more than about 10 s at load ~10 (a few seconds on
# a quiet machine) and a cheaper test checks its subject in the quick run.
_CI_TIER = {
    # module, or module::test (all its parameters): what it costs at load ~10 (2026-11-28;
    # about a quarter of that on a quiet machine); what checks its subject in the quick run
    "test_assignment.py": "diagnoses and samplers on every bundled case (150 s in CI); "
    "test_sampling_assignment, test_pairing",
    "test_batch.py::test_a_broken_case_is_recorded_and_the_others_finish": "these three share "
    "a Dask cluster (60 s); the batch's task in test_batch's other tests and test_run_layer",
    "test_batch.py::test_the_summary_is_the_single_case_commands_output": "(the cluster above)",
    "test_batch.py::test_a_rerun_skips_what_is_done_and_redoes_a_changed_case": "(as above)",
    "test_batch_map.py": "a Dask cluster per test (30 s in CI); test_parallel",
    "test_block_eigen.py::test_frederiksen_model_fast_path_matches_arpack_path": "the full "
    "Frederiksen mesh twice (25 s); the module's small plates",
    "test_block_eigen.py::test_frederiksen_50x50_matches_arpack": "the 50 x 50 mesh (13 s)",
    "test_checked_order_study.py": "the study's quick rows are diagnoses (60 s in CI)",
    "test_diagnose.py::test_workers_do_not_change_the_diagnosis": "two diagnoses (16 s in CI); "
    "test_diagnose's control diagnosis stays in the quick run",
    "test_diagnose.py::test_concealed_point_mass_is_named_and_recovered": "130 s in CI",
    "test_diagnose.py::test_a_located_candidate_defined_outside_the_package_is_mapped_scanned_"
    "and_fitted": "81 s in CI",
    "test_diagnose.py::test_control_without_effect_is_consistent": "a diagnosis (84 s); the "
    "diagnose command in test_mesh_error, its stages in test_scan, test_verdict, test_two_effects",
    "test_run_layer.py::test_the_posterior_is_the_same_through_the_three": "three samplers "
    "(105 s); the estimate through the three stays in the quick run",
    "test_verdict.py::test_a_constructed_tie_is_ambiguous_and_names_all": "a diagnosis (82 s); "
    "the module's closed forms",
    "test_batch.py::test_a_case_with_an_error_scale_gets_it_in_the_summary": "two estimates "
    "(25 s); the batch's task in test_run_layer",
    "test_inputs_posterior.py::test_cli_sample_shows_the_inputs": "a sampler (17 s); the sample "
    "command in test_run_layer",
    "test_diagnose_reassign.py": "seven diagnoses (190 s in CI); test_sampling_assignment",
    "test_diagnose_store.py": "diagnoses stopped and resumed (157 s)",
    "test_error_scale.py::test_the_study_quick": "the study (41 s)",
    "test_error_scale.py::test_the_reports_posterior_gives_the_scale_from_its_draws": "a report "
    "with the sampler (30 s); the report without it stays in the quick run",
    "test_error_scale.py::test_the_sampler_with_a_setup_prepared_from_its_stream_gives_the_"
    "same_chain": "a second chain of one already checked (11 s)",
    "test_estimators.py::test_estimates_do_not_depend_on_round_off": "every estimator twice (25 s)",
    "test_fast_candidates.py": "every candidate solved in full beside its reduced model (49 s); "
    "test_physics",
    "test_fast_estimators.py": "every estimator on both models (72 s); test_reduced",
    "test_inputs_posterior.py::test_no_input_sd_gives_todays_chain_and_no_rows": "a chain "
    "against the code before (38 s); the module's closed forms",
    "test_interrupt.py": "commands killed and run again as subprocesses",
    "test_report.py": "report pipelines; test_error_scale's report stays in the quick run",
    "test_report_html.py": "report pipelines and a headless Chromium",
    "test_report_pdf.py": "a headless Chromium",
    "test_same_seed.py": "every command twice as subprocesses; test_run_layer",
    "test_signals.py": "commands stopped as subprocesses",
    "test_taps_end_to_end.py": "hammer taps to constants (10 s a test); test_synthetic_taps",
}


def pytest_configure(config):
    missing = {name.split("::")[0] for name in _CI_TIER} - {
        p.name for p in Path(__file__).parent.glob("test_*.py")
    }
    if missing:  # a renamed module would silently join the quick run
        raise pytest.UsageError(f"tests/conftest.py _CI_TIER names no module: {sorted(missing)}")


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects by marker
def pytest_collection_modifyitems(items):
    """Mark the tests of the ci tier (`_CI_TIER`) with `ci`."""
    named = {key for key in _CI_TIER if "::" in key}
    for item in items:
        name = item.path.name
        test = f"{name}::{getattr(item, 'originalname', item.name)}"
        if name in _CI_TIER or test in _CI_TIER:
            item.add_marker(pytest.mark.ci)
            named.discard(test)
    collected = {item.path.name for item in items}
    stale = sorted(key for key in named if key.split("::")[0] in collected)
    if stale:  # a renamed test would silently join the quick run
        raise pytest.UsageError(f"tests/conftest.py _CI_TIER names no test: {stale}")
