import hashlib
import os
import re
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


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
    "test_fitted_test_study.py::test_diagnose_beside_the_test_sees_the_recordings_the_test_"
    "fitted": "two diagnoses and a fit (30 s); the module's other tests",
    "test_fitted_test_study.py::test_another_mesh_error_rule_diagnoses_alone_in_a_column_of_"
    "its_own": "three diagnoses (32 s); the module's other tests",
    "test_coarse_mesh_study.py::test_the_quick_run_diagnoses_on_the_coarser_mesh_and_"
    "resumes": "two diagnoses (40-100 s); the module's other tests",
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
    # the rest of the quick run measured at load ~7 (2026-11-28 16:00, reports/test_tiers.md):
    # every test of 5 s or more there, but for the analytic and paper references, the
    # input fuzzing and one run of the estimate and sample commands, which stay quick
    "test_spruce_estimators.py::test_by_likelihood_mve_and_mve_mod_converge_or_say_why_ear"
    "ly": "60 s",
    "test_studies.py::test_prior_bias_quick": "42 s",
    "test_studies.py::test_paper_tables_quick": "42 s",
    "test_inputs_mass.py::test_thickness_weighs_three_times_with_the_mass": "27 s",
    "test_spruce_estimators.py::test_by_order_mve_and_mve_mod_converge_or_say_why_early": "25 s",
    "test_error_scale.py::test_the_report_widens_the_estimates_with_the_scale": "20 s",
    "test_synthetic_taps.py::test_report_from_taps_shows_the_tap_test": "20 s",
    "test_estimators.py::test_cli_estimate_table_and_exit_status": "19 s",
    "test_scan.py::test_point_mass_scan_is_exact_in_a_complete_basis": "19 s",
    "test_inputs_coverage.py::test_quick_report": "18 s",
    "test_scan.py::test_stiffness_loss_scan_is_exact_in_a_complete_basis": "16 s",
    "test_reduced.py::test_compressed_basis_is_close_at_snapshots": "16 s",
    "test_inputs_sampling.py::test_prepare_marginalises_the_inputs_the_case_gives": "16 s",
    "test_sampling_assignment.py::test_sampler_reassigns_a_test_that_missed_a_mode": "15 s",
    "test_tap_csv.py::test_a_daq_csv_imports_as_its_wav": "14 s",
    "test_new_candidates.py::test_stiff_spring_tends_to_the_plate_pinned_at_the_point": "13 s",
    "test_inputs.py::test_density_derivative_is_exact": "13 s",
    "test_tap_average.py::test_eight_noisy_taps_with_a_force_average_to_the_model": "12 s",
    "test_physics.py::test_every_candidates_mirror_images_have_its_frequencies": "11 s",
    "test_joint_plates.py::test_joint_density_is_the_sum_of_the_plates_plus_one_prior": "11 s",
    "test_error_scale.py::test_the_sampler_gives_the_student_t_posterior_of_a_linear_model": "10 s",
    "test_tap_import.py::test_synthetic_tap_gives_the_model_frequencies": "10 s",
    "test_sampling.py::test_truncated_proposals_leave_the_posterior_invariant": "10 s",
    "test_reduced.py::test_same_seed_same_basis_and_certificate": "10 s",
    "test_run_layer.py::test_the_estimate_is_the_same_through_the_three": "10 s",
    "test_sampling.py::test_prepare_assigns_a_test_that_missed_a_mode": "9 s",
    "test_sampling.py::test_b_estimate_is_the_posterior_mode": "9 s",
    "test_sampling.py::test_log_density_is_the_problems_log_posterior": "9 s",
    "test_sampling_assignment.py::test_by_default_the_order_is_checked_at_the_map": "9 s",
    "test_sampling_assignment.py::test_sampler_calls_a_peak_between_two_modes_spurious": "9 s",
    "test_nonlinear_absorption_study.py::test_quick_run_writes_its_report": "8 s",
    "test_sampling_assignment.py::test_reassigned_likelihood_is_continuous_and_the_best_of"
    "_all_assignments": "8 s",
    "test_tap_csv.py::test_a_time_column_written_to_9_decimals_at_48kHz_is_accepted": "7 s",
    "test_studies.py::test_benchmark_quick": "7 s",
    "test_inputs_coverage.py::test_marginal_intervals_hold_the_input_errors": "7 s",
    "test_error_scale.py::test_the_pointwise_terms_are_leave_one_out_densities": "7 s",
    "test_synthetic_taps.py::test_several_sensors_give_the_model_shapes": "6 s",
    "test_inputs.py::test_budget_sums_to_the_total": "6 s",
    "test_inputs_mass.py::test_mass_budget_equals_the_full_covariance_of_h_and_rho": "6 s",
    "test_reduced.py::test_snapshot_points_are_reproduced_exactly_without_compression": "5 s",
    "test_estimators.py::test_shape_pairing_recovers_a_test_that_missed_a_mode": "5 s",
    "test_inputs.py::test_step_is_in_the_plateau": "5 s",
}


def pytest_configure(config):
    here = Path(__file__).parent
    missing = {name.split("::")[0] for name in _CI_TIER} - {p.name for p in here.glob("test_*.py")}
    if missing:  # a renamed module would silently join the quick run
        raise pytest.UsageError(f"tests/conftest.py _CI_TIER names no module: {sorted(missing)}")
    # a renamed test would silently join the quick run: each named test is defined in its
    # module (read from the source, so that running a few tests by name checks it too)
    named = [key.split("::") for key in _CI_TIER if "::" in key]
    sources = {module: (here / module).read_text() for module, _ in named}  # each read once
    stale = [f"{module}::{test}" for module, test in named if f"def {test}(" not in sources[module]]
    if stale:
        raise pytest.UsageError(f"tests/conftest.py _CI_TIER names no test: {stale}")


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects by marker
def pytest_collection_modifyitems(items):
    """Mark the tests of the ci tier (`_CI_TIER`) with `ci`."""
    for item in items:
        name = item.path.name
        test = f"{name}::{getattr(item, 'originalname', item.name)}"
        if name in _CI_TIER or test in _CI_TIER:
            item.add_marker(pytest.mark.ci)
