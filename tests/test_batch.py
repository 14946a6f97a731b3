"""``bayesplate batch``: many cases on a Dask cluster, checked against the single-case commands.

The reference of every number in the summary is the single-case command run in this process
(``bayesplate estimate CASE --json``) with one BLAS thread: the batch must give the same
document, bit for bit, from its worker processes (one BLAS thread each). The 94 % intervals
are checked against ``scipy.stats.norm`` (an independent quantile).
"""

import csv
import json
import math
import shutil

import numpy as np
import pytest
from scipy.stats import norm
from threadpoolctl import threadpool_limits

from bayesplate.batch import BatchOptions, ResultStore, find_cases, run_batch, run_step, step_key
from bayesplate.cli import main
from bayesplate.cli.batch import steps_list
from bayesplate.io import CaseError, bundled_case_names, bundled_case_path, load_case
from bayesplate.quantities import ENGINEERING_KEYS

MESH = ["--mesh", "6", "6"]  # a quick mesh: every bundled case estimates in a few seconds
BROKEN = "broken"
# a case whose plate is impossible: the parser refuses it with a one-line reason
_BROKEN_TEXT = (
    bundled_case_path("plate1").read_text().replace("thickness_mm = ", "thickness_mm = -", 1)
)


def _rows(path):
    with open(path, newline="") as handle:
        return {(r["case"], r["step"]): r for r in csv.DictReader(handle)}


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory):
    """The bundled cases plus a broken one, estimated by ``bayesplate batch`` on 2 workers."""
    root = tmp_path_factory.mktemp("batch")
    cases = root / "cases"
    cases.mkdir()
    for name in bundled_case_names():
        shutil.copy(bundled_case_path(name), cases / f"{name}.toml")
    (cases / f"{BROKEN}.toml").write_text(_BROKEN_TEXT)
    out = root / "out"
    status = main(["batch", str(cases), "-o", str(out), "--workers", "2", *MESH])
    return cases, out, status


def test_a_broken_case_is_recorded_and_the_others_finish(batch_run):
    cases, out, status = batch_run
    assert status == 1  # a failed case: exit status 1, after the others finished
    rows = _rows(out / "summary.csv")
    assert set(rows) == {(p.stem, "estimate") for p in cases.glob("*.toml")}
    broken = rows[BROKEN, "estimate"]
    assert broken["status"] == "failed"
    # the reason is the one line load_case gives for the same file
    with pytest.raises(CaseError) as err:
        load_case(cases / f"{BROKEN}.toml")
    assert broken["reason"] == str(err.value)
    assert "\n" not in broken["reason"] and "plate.thickness_mm" in broken["reason"]
    assert not (out / BROKEN / "estimate.json").exists()
    assert all(r["status"] != "failed" for k, r in rows.items() if k[0] != BROKEN)
    assert (out / "summary.png").stat().st_size > 0


def test_the_summary_is_the_single_case_commands_output(batch_run, tmp_path, capsys):
    cases, out, _ = batch_run
    rows = _rows(out / "summary.csv")
    z94 = norm.ppf(0.97)  # central 94 % interval of a Gaussian: the sampler's HDI level
    for name in bundled_case_names():
        single = tmp_path / f"{name}.json"
        with threadpool_limits(limits=1):  # as on the batch's workers
            main(["estimate", str(cases / f"{name}.toml"), *MESH, "-q", "--json", str(single)])
        want = json.loads(single.read_text())
        got = json.loads((out / name / "estimate.json").read_text())
        want.pop("wall_time_s"), got.pop("wall_time_s")
        assert got == want, name  # the same document, bit for bit
        row = rows[name, "estimate"]
        # the estimate's status: "rejected" or "implausible" for a flagged answer
        assert row["status"] == want["status"] and row["status"] != "failed"
        assert row["reason"] == ("" if want["converged"] else want["message"])
        assert row["mesh"] == "6x6"
        for key in ENGINEERING_KEYS:
            mean, sd = want["constants"][key]["mean"], want["constants"][key]["sd"]
            assert float(row[key]) == mean and float(row[f"{key}_sd"]) == sd
            # the interval: mean -/+ z sd (to round-off of the product)
            assert math.isclose(float(row[f"{key}_lo94"]), mean - z94 * sd, rel_tol=1e-14)
            assert math.isclose(float(row[f"{key}_hi94"]), mean + z94 * sd, rel_tol=1e-14)
        # chi-square of the paired modes, from the case's sigma (all modes paired here)
        sigma = load_case(cases / f"{name}.toml").measured.sigma_Hz
        residual = np.asarray(want["residual_Hz"])
        assert len(residual) == len(sigma) == int(row["dof"])
        chi2 = float(np.sum((residual / sigma) ** 2))
        assert math.isclose(float(row["chi2"]), chi2, rel_tol=1e-12)
    capsys.readouterr()


def test_a_rerun_skips_what_is_done_and_redoes_a_changed_case(batch_run):
    from distributed import LocalCluster

    cases, out, _ = batch_run
    before = json.loads((out / "plate2" / "estimate.json").read_text())
    record = out / "plate1" / "estimate.record.json"
    stamp = record.stat().st_mtime_ns
    with open(cases / "plate2.toml", "a") as handle:
        handle.write("\n# a comment: new content, so a new key, the same numbers\n")
    lines = []
    # an existing scheduler (as --scheduler tcp://...), not a cluster of the batch's own
    with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as cluster:
        result = run_batch(
            cases,
            out,
            BatchOptions(mesh=(6, 6)),
            scheduler=cluster.scheduler_address,
            progress=lines.append,
        )
    skipped = {(n, "estimate") for n in bundled_case_names()} - {("plate2", "estimate")}
    assert set(result.skipped) == skipped
    assert result.computed == [("plate2", "estimate")]
    assert result.failed == [(BROKEN, "estimate")]  # a failure is tried again
    assert record.stat().st_mtime_ns == stamp  # a skipped result is not rewritten
    after = json.loads((out / "plate2" / "estimate.json").read_text())
    before.pop("wall_time_s"), after.pop("wall_time_s")
    assert after == before
    done = [line for line in lines if "/2 " in line]  # one line per finished task
    assert len(done) == 2 and all(line.startswith("[") and " s] " in line for line in done)


def test_options_of_other_steps_do_not_redo_a_step():
    content = bundled_case_path("plate1").read_bytes()
    a, b = BatchOptions(seed=0), BatchOptions(seed=1, walkers=8)
    assert step_key(content, "estimate", a.for_step("estimate")) == step_key(
        content, "estimate", b.for_step("estimate")
    )
    assert step_key(content, "sample", a.for_step("sample")) != step_key(
        content, "sample", b.for_step("sample")
    )
    assert step_key(content + b"\n", "estimate", a.for_step("estimate")) != step_key(
        content, "estimate", a.for_step("estimate")
    )


def test_a_task_never_raises():
    out = run_step("x", "x.toml", b"name = [", "estimate", BatchOptions().for_step("estimate"))
    assert out["document"] is None
    assert out["row"]["status"] == "failed"
    assert out["row"]["reason"].startswith("x.toml: TOML syntax error")


def test_a_store_without_its_document_is_not_done(tmp_path):
    store = ResultStore(tmp_path)
    result = {"row": {"case": "c", "step": "estimate", "status": "converged"}, "document": {}}
    store.save("c", "estimate", "k1", result)
    assert store.done("c", "estimate", "k1")["status"] == "converged"
    assert store.done("c", "estimate", "k2") is None  # another key
    (tmp_path / "c" / "estimate.json").unlink()
    assert store.done("c", "estimate", "k1") is None


def test_finding_cases(tmp_path):
    with pytest.raises(CaseError, match="no case file"):
        find_cases(tmp_path / "*.toml")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for sub in ("a", "b"):
        shutil.copy(bundled_case_path("plate1"), tmp_path / sub / "p.toml")
    with pytest.raises(CaseError, match="several case files are named 'p'"):
        find_cases(str(tmp_path / "*" / "p.toml"))
    assert find_cases(tmp_path / "a") == [tmp_path / "a" / "p.toml"]


def test_steps_option():
    from bayesplate.batch import STEPS
    from bayesplate.cli.batch import STEP_CHOICES

    # spelled twice so that --help imports no numerics; population runs on all cases at once
    assert STEP_CHOICES == (*STEPS, "population")
    assert steps_list("diagnose,estimate,diagnose") == ("diagnose", "estimate")
    with pytest.raises(Exception, match="comma-separated"):
        steps_list("estimate,report")


def test_a_bad_steps_option_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["batch", "x", "-o", "y", "--steps", "fit"])
    assert stop.value.code == 2
    assert "comma-separated" in capsys.readouterr().err


@pytest.mark.slow
def test_sample_and_diagnose_in_a_batch_are_the_commands(tmp_path, capsys):
    path = tmp_path / "cases" / "plate1.toml"
    path.parent.mkdir()
    shutil.copy(bundled_case_path("plate1"), path)
    chain = ["--walkers", "16", "--max-steps", "200", "--min-ess", "100"]
    status = main(
        [
            "batch",
            str(path.parent),
            "-o",
            str(tmp_path / "out"),
            "--workers",
            "2",
            "--steps",
            "sample,diagnose",
            *chain,
        ]
    )
    assert status == 0
    for step, argv in (("sample", chain), ("diagnose", ["--workers", "1"])):
        single = tmp_path / f"{step}.json"
        # one BLAS thread, as on the batch's workers: diagnose's unidentified candidates
        # (parameters ~1e-8 from zero, no evidence gain) move at round-off with the thread
        # count, their sign included
        with threadpool_limits(limits=1):
            main([step, str(path), "--seed", "0", *argv, "--json", str(single)])
        want = json.loads(single.read_text())
        got = json.loads((tmp_path / "out" / "plate1" / f"{step}.json").read_text())
        for doc in (want, got):
            doc.pop("timings_s", None)
        assert got == want, step
    rows = _rows(tmp_path / "out" / "summary.csv")
    diagnosis = json.loads((tmp_path / "out" / "plate1" / "diagnose.json").read_text())
    assert rows["plate1", "diagnose"]["verdict"] == diagnosis["verdict"]
    hdi = json.loads((tmp_path / "out" / "plate1" / "sample.json").read_text())["constants"]
    assert float(rows["plate1", "sample"]["E1_GPa_lo94"]) == hdi["E1_GPa"]["hdi_3%"]
    capsys.readouterr()


def test_a_case_with_an_error_scale_gets_it_in_the_summary():
    """The estimate step widens its sd as `bayesplate estimate` does and reports s."""
    text = bundled_case_path("plate1").read_text()
    scaled = text.replace(
        "sigma_rel = 0.01\n", "sigma_rel = 0.01\nerror_scale = { median = 1.0, upper95 = 3.0 }\n"
    )
    assert scaled != text
    options = BatchOptions().for_step("estimate")
    plain = run_step("p", "p.toml", text.encode(), "estimate", options)["row"]
    out = run_step("s", "s.toml", scaled.encode(), "estimate", options)
    row = out["row"]
    assert "error_scale" not in plain
    lo, hi = row["error_scale_lo94"], row["error_scale_hi94"]
    assert 0 < lo < row["error_scale"] < hi
    assert out["document"]["error_scale"]["median"] == pytest.approx(row["error_scale"])
    # the same estimate, its sd widened or narrowed by the scale (here s < 1 or > 1)
    assert row["E1_GPa"] == plain["E1_GPa"] and row["E1_GPa_sd"] != plain["E1_GPa_sd"]
