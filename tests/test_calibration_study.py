"""studies/calibration.py: the ideal test's power, the size search, the reading of the rows,
and a quick run of the study (issue 13)."""

import json
import logging

import numpy as np
import pytest
from scipy.stats import chi2

from studies import calibration as cal
from studies import calibration_sizes as cal_sizes
from studies import outside_effects as outside


def test_ideal_power_is_the_rejection_rate_of_simulated_recordings():
    """The noncentral chi-square against the test run on seeded noisy recordings."""
    rng = np.random.default_rng(7)
    f0 = np.linspace(100.0, 1400.0, 14)
    f_effect = f0 * (1 + 0.004 * np.sin(np.arange(14)))  # an effect of a few deviations
    lam = cal.noncentrality(f_effect, f0, noise=0.002)
    n = 20000
    z = rng.standard_normal((n, 14))
    stat = np.sum(((f_effect * (1 + 0.002 * z) - f0) / (0.002 * f0)) ** 2, axis=1)
    rate = np.mean(stat > chi2.ppf(0.99, 14))
    p = cal.ideal_power(lam, 14, alpha=0.01)
    assert 0.2 < p < 0.98  # a size where the comparison means something
    assert abs(rate - p) < 4 * np.sqrt(p * (1 - p) / n)


def test_no_effect_rejects_at_the_significance_level():
    assert cal.ideal_power(0.0, 14, alpha=0.01) == pytest.approx(0.01)
    assert cal.ideal_power(1e-12, 14, alpha=0.01) == pytest.approx(0.01, rel=1e-6)


@pytest.mark.parametrize("power", [0.5, 0.9, 0.99])
def test_the_noncentrality_found_gives_the_power_asked(power):
    lam = cal_sizes.noncentrality_for(power, 14)
    assert cal.ideal_power(lam, 14) == pytest.approx(power, abs=1e-9)


def test_size_for_inverts_a_power_law_exactly():
    """lambda = c s^2 is a straight line in log-log: the interpolation is exact on it."""
    grid = np.geomspace(0.01, 3.0, 8)
    lams = 40.0 * grid**2
    for target in (0.5, 7.0, 300.0):
        assert cal_sizes.size_for(grid, lams, target) == pytest.approx(np.sqrt(target / 40.0))
    assert cal_sizes.size_for(grid, lams, 1e6) is None  # beyond the largest admissible size
    assert cal_sizes.size_for(grid, lams, 1e-9) == grid[0]


def test_a_name_counts_when_explained_or_among_the_two_ambiguous_ones():
    row = {"effect": "cutout", "verdict": "explained", "chosen": "cutout", "rival": None}
    assert cal.named(row) and not cal.wrong_name(row)
    row = {**row, "chosen": "local_stiffness_loss"}
    assert not cal.named(row) and cal.wrong_name(row)
    row = {**row, "verdict": "ambiguous", "rival": "cutout"}
    assert cal.named(row) and not cal.wrong_name(row)
    # a third candidate that ties as well is named too
    third = {**row, "rival": "point_mass", "also": ["cutout"]}
    assert cal.named(third) and not cal.wrong_pair(third)
    assert cal.wrong_pair({**third, "also": []}) and not cal.named({**third, "also": []})
    for verdict in ("consistent", "unexplained"):
        row = {**row, "verdict": verdict, "chosen": None, "rival": None}
        assert not cal.named(row) and not cal.wrong_name(row)


def test_coverage_is_judged_at_the_mirror_image_nearest_the_truth():
    row = {
        "recovered": {"mass_g": [0.31, 0.02], "x_mm": [77.0, 2.0], "y_mm": [14.5, 1.0]},
        "truth": {"mass_g": 0.3, "x_mm": 23.0, "y_mm": 14.0},
        "images": [{"mass_g": 0.31, "x_mm": 23.1, "y_mm": 14.5}],
    }
    assert cal.covered(row) == {"mass_g": True, "x_mm": True, "y_mm": True}
    row["recovered"]["mass_g"] = [0.5, 0.02]  # 10 sd off, at every image
    row["images"][0]["mass_g"] = 0.5
    assert cal.covered(row)["mass_g"] is False
    assert cal.covered({**row, "recovered": None}) == {}


@pytest.mark.slow  # the quick study: 5 diagnoses on 6 x 3 / 8 x 4 meshes, ~45 s on 2 cores
def test_quick_study_runs_and_clean_plates_are_consistent(tmp_path, monkeypatch):
    path = cal.main(tmp_path, quick=True, workers=1)
    text = path.read_text()
    stored = cal.load(tmp_path, True)
    clean = [r for r in stored["rows"].values() if r["kind"] == "clean"]
    assert len(clean) == 4 and all(r["verdict"] == "consistent" for r in clean)
    assert "false alarms: 0 of 4" in text
    (power,) = [r for r in stored["rows"].values() if r["kind"] == "power"]
    # the quick run's one power replicate is at the fitted test's 0.9 size: the constants
    # absorb part of the effect, so the ideal test (true constants) sees more than its own
    # 0.9 noncentrality there, and what the constants leave is the fitted test's 0.9 one
    assert power["size_label"] == "fitted 0.9" and power["code"]
    assert power["ideal_lambda"] > 0.8 * cal_sizes.noncentrality_for(0.9, 14)
    (left,) = [lam for lam in cal_sizes.absorbed(stored["sizes"], quick=True)["point_mass"][:1]]
    assert left == pytest.approx(cal_sizes.noncentrality_for(0.9, 14 - 6), rel=0.3)
    # its power with the noise drawn (not widened: the declared deviations) is the noncentral
    # chi-square's at that noncentrality (closed form), to the Monte Carlo's error
    (drawn,) = cal_sizes.absorbed(stored["sizes"], quick=True, power=True)["point_mass"][:1]
    assert drawn == pytest.approx(cal.ideal_power(left, 14 - 6), abs=0.004)
    widened = cal_sizes.absorbed(
        stored["sizes"], quick=True, widen=cal_sizes.widening(quick=True), power=True
    )["point_mass"][0]
    assert widened < drawn  # the widened test is the weaker
    assert (tmp_path / f"{cal.report_name(None, quick=True)}.png").exists()
    monkeypatch.setattr(cal, "run_task", None)  # everything must come from the cache now
    again = cal.main(tmp_path, quick=True, workers=1)
    assert again.read_text().split("\n", 3)[3] == text.split("\n", 3)[3]


def test_what_the_constants_can_mimic_leaves_no_noncentrality():
    """An effect that is a change of the constants (in the span of S) is absorbed entirely;
    one orthogonal to that span keeps all of its noncentrality."""
    rng = np.random.default_rng(3)
    S = rng.standard_normal((14, 6))
    sigma = rng.uniform(0.5, 2.0, 14)
    mimic = S @ rng.standard_normal(6)
    assert cal_sizes.fitted_noncentrality(mimic, S, sigma) == pytest.approx(0.0, abs=1e-18)
    A = S / sigma[:, None]
    q, _ = np.linalg.qr(A, mode="complete")
    r = q[:, 6:] @ rng.standard_normal(8)  # whitened, orthogonal to the span of A
    assert cal_sizes.fitted_noncentrality(r * sigma, S, sigma) == pytest.approx(np.sum(r**2))


def _noncentrality_for_power(power, dof, alpha=0.01):
    """An independent inversion of the noncentral chi-square's power (scipy's brentq)."""
    from scipy.optimize import brentq
    from scipy.stats import ncx2

    crit = chi2.ppf(1.0 - alpha, dof)
    return brentq(lambda lam: ncx2.sf(crit, dof, lam) - power, 1e-6, 1e4, xtol=1e-12)


def test_fitted_size_of_a_linear_effect_is_known_in_closed_form():
    """An effect ``s (S a + sigma u)``, ``u`` whitened and orthogonal to the span of ``S /
    sigma``: the constants absorb ``S a`` exactly and leave ``s^2 |u|^2``, so the fitted
    test (8 dof) rejects with 0.9 at ``s* = sqrt(lambda_90 / |u|^2)``; and a simulated
    least-squares fit of the constants to noisy recordings of it rejects at that rate."""
    rng = np.random.default_rng(11)
    m = 14
    S = rng.standard_normal((m, 6)) * rng.uniform(1.0, 5.0, 6)
    sigma = rng.uniform(0.5, 2.0, m)
    A = S / sigma[:, None]
    q, _ = np.linalg.qr(A, mode="complete")
    u = q[:, 6:] @ rng.standard_normal(m - 6)
    u *= 3.0 / np.linalg.norm(u)  # |u|^2 = 9 per unit size squared
    mimic = S @ rng.standard_normal(6) * 50.0  # large, and entirely absorbed
    grid = np.geomspace(0.1, 10.0, 9)
    deltas = [s * (mimic + sigma * u) for s in grid]
    found, lams = cal_sizes.fitted_size(grid, deltas, S, sigma, 0.9)
    assert lams == pytest.approx(9.0 * grid**2, rel=1e-9)
    lam90 = _noncentrality_for_power(0.9, m - 6)
    assert found == pytest.approx(np.sqrt(lam90 / 9.0), rel=1e-6)
    # Monte Carlo: recordings delta(s*) / sigma + N(0, 1), the constants fitted by least
    # squares, the residual's chi-square against chi2(8) at 1 %
    r = found * (mimic + sigma * u) / sigma
    z = r + rng.standard_normal((20000, m))
    coef, *_ = np.linalg.lstsq(A, z.T, rcond=None)
    stat = np.sum((z.T - A @ coef) ** 2, axis=0)
    rate = np.mean(stat > chi2.ppf(0.99, m - 6))
    assert abs(rate - 0.9) < 4 * np.sqrt(0.9 * 0.1 / 20000)


def _table():
    """A size table as ``sizes`` makes it, for two effects and the current ``SIZES``."""
    n = len(cal.SIZES)
    return {
        "point_mass": {
            "grid": [0.01, 3.0],
            "lambda": [0.1, 1e4],
            "fitted_lambda": [0.05, 5e3],
            "sizes": [0.17, 0.42, 0.14, 0.11][:n],
        },
        "cutout": {
            "grid": [0.5, 17.0],
            "lambda": [1e-3, 1e4],
            "fitted_lambda": [1e-4, 3e3],
            "sizes": [6.2, 13.0, 4.3, 3.7][:n],
        },
    }


def _row(task, code, verdict="consistent"):
    kind, family, effect, label, size, rep = task
    return {
        "key": cal.task_key(task),
        "kind": kind,
        "family": family,
        "effect": effect,
        "size_label": label,
        "size": size,
        "rep": rep,
        "verdict": verdict,
        "chosen": None,
        "rival": None,
        "code": code,
        "seconds": 1.0,
    }


def test_a_run_reads_the_rows_of_its_own_code_version_alone(tmp_path):
    """Each code version's rows in their own file: another version's are never read, and a
    line cut short (a run killed while writing it) is skipped."""
    one, two = cal.tasks(_table(), quick=True)[:2]
    cal.save(tmp_path, True, {"version": "aaaaaaa", "sizes": _table(), "rows": {}})
    cal.save(tmp_path, True, {"version": "bbbbbbb", "sizes": None, "rows": {}})
    rows_a, head_a = cal.cache_paths(tmp_path, True, "aaaaaaa")
    suffix = cal._rule_suffix(None)  # diagnose's default rule
    assert rows_a.name == f"aaaaaaa{suffix}-quick.jsonl"
    assert head_a.name == f"aaaaaaa{suffix}-quick.json"
    assert rows_a.parent == tmp_path / ".cache" / "calibration"
    with rows_a.open("a") as out:
        out.write(json.dumps(_row(one, "aaaaaaa")) + "\n" + json.dumps(_row(two, "aaaaaaa"))[:40])
    stored = cal.load(tmp_path, True, "aaaaaaa")
    assert list(stored["rows"]) == [cal.task_key(one)] and stored["sizes"] == _table()
    assert cal.load(tmp_path, True, "bbbbbbb")["rows"] == {}
    assert cal.load(tmp_path, True, "ccccccc") == cal._empty(True, "ccccccc")
    assert cal.load(tmp_path, False, "aaaaaaa")["sizes"] is None  # the full run's own files


@pytest.fixture
def package_log_level():
    """The package's log level restored after the test (the study's main quiets it)."""
    logger = logging.getLogger("bayesplate")
    level = logger.level
    yield
    logger.setLevel(level)


def test_a_run_resumes_from_its_versions_rows_and_a_new_version_starts_afresh(
    tmp_path, monkeypatch, package_log_level
):
    table, ran = _table(), []

    def fake(task, quick=False, code=None, options=None):
        ran.append(cal.task_key(task))
        return _row(task, code)

    monkeypatch.setattr(cal, "sizes", lambda quick=False: table)
    monkeypatch.setattr(cal, "run_task_recorded", fake)
    monkeypatch.setattr(cal, "write_report", lambda out_dir, stored, quick, workers: stored)
    keys = [cal.task_key(t) for t in cal.tasks(table, quick=True)]
    monkeypatch.setattr(cal, "code_version", lambda: "abc1234")
    cal.save(tmp_path, True, {"version": "abc1234", "sizes": table, "rows": {}})
    rows_path, _ = cal.cache_paths(tmp_path, True, "abc1234")
    rows_path.write_text(json.dumps(_row(cal.tasks(table, quick=True)[0], "abc1234")) + "\n")
    stored = cal.main(tmp_path, quick=True, workers=1)
    assert ran == keys[1:]  # the cached row is not run again
    assert set(stored["rows"]) == set(keys) and stored["runs"][-1]["rows"] == len(keys) - 1
    assert len(rows_path.read_text().splitlines()) == len(keys)  # each row appended
    ran.clear()
    assert set(cal.main(tmp_path, quick=True, workers=1)["rows"]) == set(keys) and ran == []
    monkeypatch.setattr(cal, "code_version", lambda: "def5678")  # a commit since
    stored = cal.main(tmp_path, quick=True, workers=1)
    assert ran == keys and {r["code"] for r in stored["rows"].values()} == {"def5678"}
    assert len(rows_path.read_text().splitlines()) == len(keys)  # the older rows untouched


def test_a_new_code_version_keeps_the_size_table_its_inputs_made(
    tmp_path, monkeypatch, package_log_level
):
    """The size table is computed again when the code it runs on changes, not when diagnose
    alone does: a new code version with the same inputs reads the kept table."""
    made = []

    def sizes(quick=False):
        made.append(quick)
        return _table()

    monkeypatch.setattr(cal, "sizes", sizes)
    monkeypatch.setattr(cal, "run_task_recorded", lambda task, *a, **k: _row(task, "x"))
    monkeypatch.setattr(cal, "write_report", lambda out_dir, stored, quick, workers: stored)
    monkeypatch.setattr(cal, "tasks", lambda table, quick=False, plan_=None: [])
    for code, inputs, runs in (("abc1234", "1111111", 1), ("def5678", "1111111", 1)):
        monkeypatch.setattr(cal, "code_version", lambda code=code: code)
        monkeypatch.setattr(cal_sizes, "inputs_version", lambda inputs=inputs: inputs)
        assert cal.main(tmp_path, quick=True, workers=1)["sizes"] == _table()
        assert len(made) == runs
    assert cal_sizes.table_path(tmp_path, True, version="1111111").exists()
    monkeypatch.setattr(cal_sizes, "inputs_version", lambda: "2222222")  # the elements changed
    monkeypatch.setattr(cal, "code_version", lambda: "0123abc")
    cal.main(tmp_path, quick=True, workers=1)
    assert len(made) == 2


def test_the_size_tables_inputs_hold_every_function_it_calls():
    """Every function of the package or the studies that the size table and its figures run
    (traced on the quick meshes) lies in one of ``INPUTS``, the paths whose version keys it."""
    import pathlib
    import sys

    root = pathlib.Path(cal_sizes.__file__).resolve().parents[1]
    called = set()

    def trace(frame, event, arg):
        if event == "call":
            called.add(frame.f_code.co_filename)

    sys.setprofile(trace)
    try:
        table = cal_sizes.sizes(quick=True)
        cal_sizes.figures(table, quick=True)
    finally:
        sys.setprofile(None)
    ours = set()
    for name in called:
        path = pathlib.Path(name).resolve()
        if path.is_relative_to(root) and path.parts[len(root.parts)] in ("bayesplate", "studies"):
            ours.add(path.relative_to(root).as_posix())
    assert "bayesplate/fem/eigen.py" in ours and "studies/recordings.py" in ours
    outside_inputs = sorted(
        p for p in ours if not any(p == i or p.startswith(i + "/") for i in cal_sizes.INPUTS)
    )
    assert outside_inputs == []


def test_tasks_run_the_fitted_size_first_with_clean_replicates_between_its_rounds():
    tasks = cal.tasks(_table())
    labels = [t[3] for t in tasks if t[0] == "power"]
    n_first = 2 * cal.N_POWER  # two effects
    assert labels[:n_first] == ["fitted 0.9"] * n_first
    assert "fitted 0.9" not in labels[n_first:]
    first_round = tasks[: 2 + 2 * cal.N_CLEAN // cal.N_POWER]
    assert [t[0] for t in first_round] == ["power"] * 2 + ["clean"] * (
        2 * cal.N_CLEAN // cal.N_POWER
    )
    assert {t[5] for t in first_round if t[0] == "power"} == {0}
    assert {t[5] for t in first_round if t[0] == "clean"} == {0, 1}
    # afterwards the other sizes, replicate by replicate, in the order of SIZES
    rest = [t for t in tasks if t[0] == "power" and t[3] != "fitted 0.9"]
    assert [t[5] for t in rest] == sorted(t[5] for t in rest)
    assert [t[3] for t in rest[:6]] == ["3 x ideal 0.9"] * 2 + ["ideal 0.9"] * 2 + ["ideal 0.5"] * 2
    keys = [cal.task_key(t) for t in tasks]
    n_outside = len(cal.outside_tasks())
    assert (
        len(keys)
        == len(set(keys))
        == (2 * cal.N_CLEAN + 2 * cal.N_POWER * len(cal.SIZES) + n_outside)
    )


def test_the_target_plan_runs_the_clean_replicates_and_the_fitted_size_alone():
    """40 clean replicates, each candidate at its fitted 0.9 size (130 for the nine
    candidates) and the four effects outside the candidates five times; they are the first
    tasks of the plan with every size, in the same order."""
    table = {
        name: {**_table()["point_mass"], "sizes": [0.1 * (k + 1), 1.0, 2.0, 3.0]}
        for k, name in enumerate(cal.EFFECTS)
    }
    target, every = cal.tasks(table, plan="target"), cal.tasks(table, plan="all")
    assert len(target) == 2 * cal.N_CLEAN + len(cal.EFFECTS) * cal.N_POWER + 20 == 150
    # the outside effects two a round, after the round's clean replicates
    assert [t for t in target if t[0] == "outside"] == cal.outside_tasks()
    first_round = target[: len(cal.EFFECTS) + 4 + 2]
    assert [t[0] for t in first_round[-6:]] == ["clean"] * 4 + ["outside"] * 2
    assert every[: len(target)] == target
    assert {t[3] for t in target if t[0] == "power"} == {"fitted 0.9"}
    assert sum(t[0] == "clean" for t in target) == 2 * cal.N_CLEAN
    assert len(every) == 2 * cal.N_CLEAN + len(cal.EFFECTS) * cal.N_POWER * len(cal.SIZES) + 20
    # quick mode runs the fitted size alone under either plan, as before
    assert cal.tasks(_table(), True, "target") == cal.tasks(_table(), True, "all")
    assert len(cal.tasks(_table(), True, "target")) == 2 * 2 + 2
    with pytest.raises(ValueError, match="plan"):
        cal.tasks(_table(), plan="some")


def test_the_rule_names_the_cache_and_the_report_unless_it_is_the_plain_one(tmp_path):
    rows, head = cal.cache_paths(tmp_path, True, "abc1234", "unabsorbed")
    assert (
        rows.name == "abc1234-unabsorbed-quick.jsonl"
        and head.name == "abc1234-unabsorbed-quick.json"
    )
    assert cal.cache_paths(tmp_path, False, "abc1234", "unabsorbed")[0].name == (
        "abc1234-unabsorbed.jsonl"
    )
    # the whole rule's files keep the plain names they had when it was the default
    assert cal.cache_paths(tmp_path, True, "abc1234", "whole")[0].name == "abc1234-quick.jsonl"
    assert cal.report_name("whole") == "calibration"
    assert cal.report_name("whole", quick=True) == "calibration-quick"
    # no rule is diagnose's default, named
    assert cal.report_name(None) == cal.report_name(cal.DEFAULT_RULE)
    assert cal.report_name("corrected") == "calibration_corrected"
    assert cal.report_name("unabsorbed") == "calibration_unabsorbed"
    assert cal.report_name("unabsorbed", quick=True) == "calibration_unabsorbed-quick"
    # each rule reads its own rows alone
    (task,) = cal.tasks(_table(), quick=True)[:1]
    cal.save(tmp_path, True, {"version": "abc1234", "rule": "unabsorbed", "rows": {}})
    with rows.open("a") as out:
        out.write(json.dumps(_row(task, "abc1234")) + "\n")
    assert list(cal.load(tmp_path, True, "abc1234", "unabsorbed")["rows"]) == [cal.task_key(task)]
    assert cal.load(tmp_path, True, "abc1234", "unabsorbed")["rule"] == "unabsorbed"
    assert cal.load(tmp_path, True, "abc1234")["rows"] == {}


def test_main_passes_the_rule_to_diagnose_and_runs_the_plan(
    tmp_path, monkeypatch, package_log_level
):
    table, ran = _table(), []

    def fake(task, quick=False, code=None, options=None):
        ran.append((cal.task_key(task), options))
        return _row(task, code)

    monkeypatch.setattr(cal, "sizes", lambda quick=False: table)
    monkeypatch.setattr(cal, "run_task_recorded", fake)
    monkeypatch.setattr(cal, "write_report", lambda out_dir, stored, quick, workers: stored)
    monkeypatch.setattr(cal, "code_version", lambda: "abc1234")
    stored = cal.main(tmp_path, quick=True, workers=1, rule="unabsorbed")
    assert {str(o) for _, o in ran} == {str({"mesh_error_part": "unabsorbed"})}
    assert stored["rule"] == "unabsorbed" and stored["plan"] == "target"
    rows_path, _ = cal.cache_paths(tmp_path, True, "abc1234", "unabsorbed")
    assert len(rows_path.read_text().splitlines()) == len(ran)
    assert not cal.cache_paths(tmp_path, True, "abc1234")[0].exists()
    with pytest.raises(ValueError, match="rule"):
        cal.main(tmp_path, quick=True, workers=1, rule="none such")


def _full_row(task, code, verdict="consistent"):
    """A row as ``run_task`` makes it, enough for :func:`report`."""
    row = _row(task, code, verdict)
    row.update(
        p_value=0.5,
        refit_p=0.5,
        gains={"point_mass": -1.0},
        ideal_chi2=10.0,
        m=14,
        truth=None,
        recovered=None,
        images=[],
        also=[],
    )
    return row


def _stored(rows, plan="target", rule=None, version="abc1234"):
    """A run's head with its figures already computed (none: the report skips them)."""
    figures = {key: {} for key in cal.FIGURES}
    figures["widening"] = []
    return {
        **cal._empty(True, version, rule),
        "sizes": _table(),
        "plan": plan,
        "rows": {r["key"]: r for r in rows},
        **figures,
    }


def test_the_report_is_the_current_table_alone_and_names_plan_band_and_rule(tmp_path):
    tasks = cal.tasks(_table(), quick=False, plan="all")
    clean = [t for t in tasks if t[0] == "clean"][:4]
    power = [t for t in tasks if t[0] == "power" and t[5] == 0][:2]  # the fitted 0.9 size
    rows = [_full_row(t, "abc1234") for t in clean]
    rows += [_full_row(t, "abc1234", "explained") | {"chosen": t[2]} for t in power]
    text = cal.report(rows, _stored(rows), quick=False, workers=2)
    assert "Which code made the rows" not in text and "Code `abc1234`." in text
    assert "made before the cache" not in text
    head = text.split("## False alarms")[0]
    lo, hi = cal.wilson(8, 10)
    _, top = cal.wilson(0, 40)
    assert f"{lo:.2f}-{hi:.2f}" == "0.49-0.94"  # the band the docstring quotes
    assert (
        "Plan `target`" in head and "named 8 of 10 has a Wilson 95 % interval of 0.49-0.94" in head
    )
    assert f"upper bound of {top:.2f}" in head and "upper bound of 0.09" in head
    n_outside = len(cal.outside_tasks())
    assert f"{len(rows)} of {2 * cal.N_CLEAN + 2 * cal.N_POWER + n_outside} replicates" in head
    assert f"mesh-error rule `{cal.DEFAULT_RULE}`" in head and "--mesh-error" in head
    assert "(ideal 0.5)" not in text and "(3 x ideal 0.9)" not in text  # sizes not run
    assert "(fitted 0.9)" in text and "at the ideal 0.9 size" not in text
    # every size under the plan `all`, and the rule named on the command line
    text = cal.report(rows, _stored(rows, "all", "unabsorbed"), quick=False, workers=2)
    assert "(ideal 0.5)" in text and "--sizes all --mesh-error unabsorbed" in text
    assert "mesh-error rule `unabsorbed`" in text
    # rows of other code (not cached by version) are listed by their code
    older = [{**rows[0], "code": "0123456"}, *rows[1:]]
    text = cal.report(older, _stored(older), quick=False, workers=2)
    assert "Which code made the rows" in text and "`0123456`" in text


def test_the_report_of_another_rule_goes_to_its_own_file(tmp_path):
    rows = [_full_row(t, "abc1234") for t in cal.tasks(_table(), quick=True) if t[0] == "clean"]
    path = cal.write_report(tmp_path, _stored(rows, rule="unabsorbed"), True, 1)
    assert path == tmp_path / "calibration_unabsorbed-quick.md"
    assert "mesh-error rule `unabsorbed`" in path.read_text()
    path = cal.write_report(tmp_path, _stored(rows), True, 1)
    assert path == tmp_path / f"{cal.report_name(None, quick=True)}.md"


def test_a_replicate_that_raises_is_recorded(monkeypatch):
    def boom(task, quick=False, options=None):
        raise RuntimeError("no convergence")

    monkeypatch.setattr(cal, "run_task", boom)
    task = ("power", "frederiksen_t300", "cutout", "fitted 0.9", 6.2, 4)
    row = cal.run_task_recorded(task, code="abc1234")
    assert row["verdict"] == "error" and "no convergence" in row["error"]
    assert row["key"] == cal.task_key(task) and row["code"] == "abc1234"
    assert not cal.named(row) and not cal.wrong_name(row)


@pytest.mark.slow  # one diagnosis on the quick 6 x 3 mesh per rule, a few seconds each
@pytest.mark.parametrize("rule", cal.RULES)
def test_the_widening_is_the_one_diagnose_applies(rule):
    """The deviations diagnose reports it tested against, over the recordings' own."""
    case, model, fine = cal._models("frederiksen_t300", True)
    f = np.sort(cal_sizes._frequencies(case, fine))
    blind = case.with_measured(frequency_Hz=f, sigma_Hz=cal.NOISE * f)
    d = cal.diagnose(blind, model=model, rng=1, pairing="order", mesh_error_part=rule)
    if rule == "corrected":  # estimated at the first nominal fit; d.nominal is the second
        widen, rel = cal_sizes.widening(quick=True, rule=rule, b=d.nominal.b), 0.1
    else:
        widen, rel = cal_sizes.widening(quick=True, frequency_Hz=f, rule=rule), 0.02
    assert widen.max() > 1.0  # the coarse quick mesh's error is widened in
    assert d.sigma_Hz / (cal.NOISE * f) == pytest.approx(widen, rel=rel)


def test_the_aimed_test_of_the_fitted_model_rejects_at_the_bound():
    """Knowing the effect's direction, the statistic is the residual's component along what
    the constants leave of it: simulated with fitted constants, it rejects (1 dof, 1 %) at
    ``bound_power`` of the fitted noncentrality, more often than the 8-dof test."""
    rng = np.random.default_rng(5)
    m = 14
    S = rng.standard_normal((m, 6))
    sigma = rng.uniform(0.5, 2.0, m)
    A = S / sigma[:, None]
    effect = rng.standard_normal(m) * sigma * 1.3  # some of it in the span of S
    lam = cal_sizes.fitted_noncentrality(effect, S, sigma)
    r = effect / sigma
    coef, *_ = np.linalg.lstsq(A, r, rcond=None)
    left = r - A @ coef
    direction = left / np.linalg.norm(left)
    z = r + rng.standard_normal((20000, m))
    coef, *_ = np.linalg.lstsq(A, z.T, rcond=None)
    residual = z.T - A @ coef
    rate = np.mean((direction @ residual) ** 2 > chi2.ppf(0.99, 1))
    p = cal.bound_power(lam)
    assert 0.2 < p < 0.98
    assert abs(rate - p) < 4 * np.sqrt(p * (1 - p) / 20000)
    assert p > cal.ideal_power(lam, m - 6)


def test_most_of_the_mesh_error_is_what_the_constants_absorb():
    # a mesh too stiff is much like a plate a little stiffer: projected off the whitened
    # sensitivities, the difference of the quick study's mesh to its recordings' mesh keeps a
    # small part of its size (the widening counts the rest twice); a projection never
    # lengthens a vector. (Diagnose's Richardson estimate is far off on a mesh this coarse:
    # 103 deviations RMS against the actual 56, 44 % of it left; on the study's 40 x 20 mesh
    # 1.27 against 1.00, 3 % left: reports/calibration.md.)
    left = cal_sizes.mesh_error_left(quick=True)
    for label in ("estimated", "actual"):
        assert 0.0 <= left[f"{label}_left"] <= left[label] <= left[f"{label}_max"]
    assert left["actual_left"] < 0.25 * left["actual"]


def test_the_outside_effects_have_their_own_keys_and_seeds():
    """Each effect outside the candidates (all but the control), N_OUTSIDE times; no key or
    seed shared with a candidate's replicate or another outside one."""
    out = cal.outside_tasks()
    labels = {t[2] for t in out}
    assert labels == {k for k, (physics, _) in outside.EFFECTS.items() if physics is not None}
    assert len(out) == len(labels) * cal.N_OUTSIDE
    power = [
        ("power", cal.POWER_FAMILY, e, "fitted 0.9", 1.0, r) for e in cal.EFFECTS for r in (0, 1)
    ]
    keys = [cal.task_key(t) for t in out + power]
    seeds = [tuple(cal._seed(t).spawn_key) for t in out + power]
    assert len(set(keys)) == len(keys) and len(set(seeds)) == len(seeds)


def test_the_report_counts_the_outside_effects_by_outcome():
    """The outside rows are tabled apart (right, wrong, unexplained) and never counted as
    power or false alarms."""
    label = "edge notch 6 x 4 mm"
    base = {"kind": "outside", "family": cal.POWER_FAMILY, "effect": label, "seconds": 60.0}
    rows = [
        {**base, "verdict": "unexplained", "named": [], "outcome": "right"},
        {**base, "verdict": "explained", "named": ["cut_corner"], "outcome": "right"},
        {**base, "verdict": "explained", "named": ["point_mass"], "outcome": "wrong"},
    ]
    text = "\n".join(cal._outside(rows))
    line = next(x for x in text.splitlines() if x.startswith(f"| {label} "))
    assert line.split(" | ")[1:6] == ["3", "0", "1", "1", "1"]
    assert cal.false_alarms(rows) == (0, 0) and cal.power_cells(rows) == {}
    assert "None run yet." in cal._outside([])


def test_the_fitted_size_is_the_measured_one_where_there_is_one():
    """The fitted 0.9 size is the fitted test's measured one (reports/fitted_test.md) where
    measured, and the quick mode keeps the linearised one."""
    assert cal_sizes.FITTED_MEASURED["point_mass"] == 0.24  # 10 of 10 rejected there
    assert "thickness_taper" not in cal_sizes.FITTED_MEASURED
    quick = cal.sizes(quick=True)["point_mass"]
    assert quick["measured"] is False
    for name, size in cal_sizes.FITTED_MEASURED.items():  # each inside its candidate's grid
        grid = cal.EFFECTS[name][3]
        assert grid[0] < size < grid[-1]


def _power_rows(named_flags, effect="cutout", size=7.5):
    rows = []
    for rep, hit in enumerate(named_flags):
        task = ("power", cal.POWER_FAMILY, effect, "fitted 0.9", size, rep)
        rows.append(
            {**_row(task, "abc1234", "explained" if hit else "consistent"), "chosen": effect}
        )
    return rows


def test_a_target_is_decided_by_eight_named_or_three_missed():
    """Met once 8 of 10 are named (the two left cannot unmeet it), missed once 3 are not
    (the rest cannot reach 8), open otherwise; a replicate that raised is not named."""
    assert cal.decided(_power_rows([True] * 7), "cutout", 7.5) is None
    assert cal.decided(_power_rows([True] * 8), "cutout", 7.5) == "met"
    assert cal.decided(_power_rows([True, False, False, True, True]), "cutout", 7.5) is None
    assert cal.decided(_power_rows([False, True, False, False]), "cutout", 7.5) == "missed"
    errors = _power_rows([True, True])
    errors += [{**r, "verdict": "error"} for r in _power_rows([True] * 3)[:3]]
    errors[2:] = [{**r, "key": f"x{i}"} for i, r in enumerate(errors[2:])]
    assert cal.decided(errors, "cutout", 7.5) == "missed"
    # another size or candidate is not counted
    assert cal.decided(_power_rows([False] * 3, size=6.2), "cutout", 7.5) is None
    assert cal.decided(_power_rows([False] * 3, effect="point_mass"), "cutout", 7.5) is None
    task = ("power", cal.POWER_FAMILY, "cutout", "fitted 0.9", 7.5, 9)
    decided_rows = _power_rows([True] * 8)
    assert cal.curtailed(task, decided_rows)
    assert not cal.curtailed(("power", *task[1:3], "ideal 0.9", *task[4:]), decided_rows)
    assert not cal.curtailed(("clean", cal.POWER_FAMILY, None, None, None, 9), decided_rows)


def test_rounds_begin_where_a_power_replicate_of_another_number_does():
    tasks = cal.tasks(_table())
    chunks = cal.rounds(tasks)
    assert [t for c in chunks for t in c] == tasks
    firsts = [next(t[5] for t in c if t[0] == "power") for c in chunks]
    assert firsts[: cal.N_POWER] == list(range(cal.N_POWER))
    assert all(len({t[5] for t in c if t[0] == "power"}) == 1 for c in chunks)


def test_a_rounds_longest_kinds_of_task_go_to_the_workers_first():
    tasks = cal.tasks(_table())
    (first, *_) = cal.rounds(tasks)
    assert {t[0] for t in first} == {"outside", "power", "clean"}
    ordered = cal.longest_first(first)
    kinds = [t[0] for t in ordered]
    assert kinds == sorted(kinds, key=cal.KIND_ORDER.index)
    assert sorted(ordered) == sorted(first)  # the same tasks, each once
    power = [t for t in ordered if t[0] == "power"]
    assert power == [t for t in first if t[0] == "power"]  # stable within a kind
    chunks = cal.running_order(tasks)
    assert chunks[0] == ordered and len(chunks) == len(cal.rounds(tasks))
    (whole,) = cal.running_order(tasks, curtail=False)  # one submission, round by round
    assert whole == [t for c in chunks for t in c]


def test_a_curtailed_run_leaves_out_a_decided_candidates_replicates(
    tmp_path, monkeypatch, package_log_level
):
    """Ten replicates of a candidate named every time: the first eight run, the last two are
    left out, and the report counts 8 of 8 as the target met; with curtail=False all ten."""
    plan = [("power", cal.POWER_FAMILY, "cutout", "fitted 0.9", 7.5, rep) for rep in range(10)]
    ran = []

    def fake(task, quick=False, code=None, options=None):
        ran.append(task[5])
        return {**_row(task, code, "explained"), "chosen": "cutout"}

    monkeypatch.setattr(cal, "sizes", lambda quick=False: _table())
    monkeypatch.setattr(cal, "tasks", lambda table, quick=False, plan_=None: plan)
    monkeypatch.setattr(cal, "run_task_recorded", fake)
    monkeypatch.setattr(cal, "write_report", lambda out_dir, stored, quick, workers: stored)
    monkeypatch.setattr(cal, "code_version", lambda: "abc1234")
    stored = cal.main(tmp_path, quick=True, workers=1)
    assert ran == list(range(8)) and len(stored["rows"]) == 8
    assert cal._planned(_table(), True, "target", list(stored["rows"].values()), True) == {
        cal.task_key(t) for t in plan[:8]
    }
    assert "(the other 2 left out: decided): met" in cal._judge({"named": 8, "n": 8})
    ran.clear()
    monkeypatch.setattr(cal, "code_version", lambda: "def5678")
    cal.main(tmp_path, quick=True, workers=1, curtail=False)
    assert ran == list(range(10))
