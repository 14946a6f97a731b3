"""The fitted test fitted globally: a test any method could run (issue 40, item 2).

The calibration study sets each candidate's power size where the *fitted* test rejects 9 of
10: the nominal model, its six constants fitted to the recordings, chi-square on ``m - 6``
degrees of freedom at 1 %. Its size comes from a linearised absorption (and
``nonlinear_absorption`` fits from the true constants only). This study fits the constants
to a replicate's own recordings from many starts, with no prior in the objective, on the
recordings' own mesh (no mesh error), and takes the best optimum found:

- the true constants and the prior mean;
- starts aimed along the constants the frequencies of a thin plate hardly fix, where deeper
  optima lie: the transverse shear coefficients C44 (G23) times 0.4, 1 or 2.5 and C55 (G13)
  times 0.3, 1 or 3.5 (the eight pairs besides 1, 1), the others true;
- ``draws`` draws from the prior.

Each local fit is :func:`studies.nonlinear_absorption.exact_fit` from its start (log-stiffness
steps), capped at ``MAX_NFEV`` evaluations. The best optimum found bounds the global
minimum from above, so the rejections counted are an upper bound too.

With ``--diagnose`` each replicate is also diagnosed blind with the package's defaults
(:func:`studies.calibration.run_task`), so the fitted test's rejections and diagnose's names
stand side by side at one size. Rows are cached by code version in
``out_dir/.cache/fitted_test/<version>.jsonl`` (a run resumes); the report
``fitted_test.md`` holds every size of the current version, led by the power table (each
size's rejections by the test and names by diagnose under each rule run) and followed by a
reading written by hand (``## What it shows``), which is kept when the tables are written
again; each row names the code that
computed it (``code``), also a row carried over from an earlier version whose computation
is the same. ``--mesh-error RULE`` (a rule other than diagnose's default) diagnoses the
same replicates under that mesh-error rule alone, without the test, into
``<version>.rules.jsonl``; the report shows its verdicts in a column of their own.
``--report NAME`` writes ``NAME.md`` instead: sizes measured on other recordings (another
mesh of them) kept apart from ``fitted_test.md``'s. Run:
``python -m studies.fitted_test EFFECT SIZE [--replicates 0 1 ...] [--draws N] [--diagnose]
[--mesh-error RULE] [--workers 2] [--out DIR] [--report NAME]`` (about 5-6 min a replicate
on one core on 80 x 40 recordings, 15-20 min on 120 x 60; diagnose alone 0.5-3 min).
"""

import argparse
import json
import os
import pathlib
import time

import numpy as np
from scipy.stats import chi2 as chi2_dist

from bayesplate import stiffness_from_engineering
from bayesplate.io import atomic_write_text
from bayesplate.likelihood.posterior import prior_in_stiffness
from bayesplate.parallel import fork_map
from studies import calibration as cal
from studies._study_host import code_version, cpu, jsonl_rows, utc_now
from studies.nonlinear_absorption import exact_fit

FAMILY = "frederiksen_t300"
ALPHA = 0.01
MAX_NFEV = 40  # evaluations of each local fit
#: Factors of (C44, C55) the aimed starts take, the other constants true.
SHEAR_GRID = tuple((a, b) for a in (0.4, 1.0, 2.5) for b in (0.3, 1.0, 3.5) if (a, b) != (1, 1))


def starts(b_true, prior, draws, rng):
    """Every start as a step ``ln(b / b_true)``, and its kind.

    Returns
    -------
    list of (numpy.ndarray of shape (6,), str)
        The truth, the prior mean, :data:`SHEAR_GRID`, then ``draws`` draws from the prior
        (clipped at a twentieth of the truth).
    """
    mu_b, V_b = prior
    out = [(np.zeros(6), "truth"), (np.log(mu_b / b_true), "prior mean")]
    for a, b in SHEAR_GRID:
        out.append((np.log([1, 1, 1, 1, a, b]), "shear"))
    L, rng = np.linalg.cholesky(V_b), np.random.default_rng(rng)
    for _ in range(draws):
        d = mu_b + L @ rng.standard_normal(6)
        out.append((np.log(np.maximum(d / b_true, 0.05)), "draw"))
    return out


def fitted_test(recorded_Hz, sigma_Hz, model, b_true, prior, draws=4, rng=0):
    """The nominal model's six constants fitted to recorded frequencies from many starts.

    Parameters
    ----------
    recorded_Hz, sigma_Hz : numpy.ndarray, shape (m,)
        Sorted recorded frequencies and their deviations, Hz (paired by order).
    model : PlateModel
        The nominal plate on the mesh to fit on.
    b_true : numpy.ndarray, shape (6,)
        The true stiffness coefficients (Pa): a start, and the unit of the fitted ratios.
    prior : tuple of numpy.ndarray
        ``(mu_b, V_b)`` (Pa, Pa^2): its mean is a start and ``draws`` draws from it are more.
    draws : int
    rng : int or numpy.random.Generator

    Returns
    -------
    dict
        ``chi2`` (the best optimum's), ``dof`` (``m - 6``), ``p``, ``ratios`` (its constants
        over the true ones, shape (6,)), ``by_start`` (every start's optimum's chi-square, in
        the order of :func:`starts`), ``kinds`` (each start's kind), ``best_kind`` and
        ``at_truth`` (the chi-square at the true constants).
    """
    f, s = np.asarray(recorded_Hz, float), np.asarray(sigma_Hz, float)
    m, Y = f.size, (2 * np.pi * f) ** 2
    sigma = 2 * Y * s / f
    points = starts(b_true, prior, draws, rng)
    optima = [exact_fit(model, b_true, Y, sigma, start=z, max_nfev=MAX_NFEV) for z, _ in points]
    k = int(np.argmin([o.chi2 for o in optima]))
    r = (model.solve(b_true, m).eigenvalues - Y) / sigma
    dof = m - 6
    return {
        "chi2": optima[k].chi2,
        "dof": dof,
        "p": float(chi2_dist.sf(optima[k].chi2, dof)),
        "ratios": (optima[k].b / b_true).tolist(),
        "by_start": [o.chi2 for o in optima],
        "kinds": [kind for _, kind in points],
        "best_kind": points[k][1],
        "at_truth": float(r @ r),
    }


def _task(effect, size, rep):
    """The calibration study's power replicate at ``size`` (its fitted 0.9 label)."""
    return ("power", FAMILY, effect, "fitted 0.9", size, rep)


def replicate(effect, size, rep, draws=4, quick=False, diagnose=False):
    """The fitted test on one power replicate of the calibration study (and, asked, diagnose's
    verdict on it); its row."""
    task = _task(effect, size, rep)
    made = cal.recordings(task, quick)
    blind = made[0]
    case, _, fine = cal._models(FAMILY, quick)
    prior = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    b_true = stiffness_from_engineering(case.reference)
    m = blind.measured
    start = time.perf_counter()
    row = fitted_test(m.frequency_Hz, m.sigma_Hz, fine, b_true, prior, draws, rng=rep)
    row = {"effect": effect, "size": size, "rep": rep, "draws": draws, **row}
    row["seconds"] = time.perf_counter() - start
    row["diagnose"] = None
    if diagnose:  # the same recordings, not made again
        row["diagnose"] = {
            **_verdict(cal.run_task(task, quick, made=made)),
            "rule": cal.DEFAULT_RULE,
        }
    return row


def diagnosed(effect, size, rep, rule, quick=False):
    """Diagnose's verdict on one power replicate under mesh-error ``rule``; its row."""
    task = _task(effect, size, rep)
    d = cal.run_task(task, quick, options={"mesh_error_part": rule})
    return {"effect": effect, "size": size, "rep": rep, "rule": rule, "diagnose": _verdict(d)}


def _verdict(d):
    """What the report keeps of a calibration row: verdict, names, p-value, time, named."""
    out = {k: d[k] for k in ("verdict", "chosen", "rival", "also", "p_value", "seconds")}
    out["named"] = cal.named(d)
    return out


def _key(row):
    return (row["effect"], row["size"], row["rep"], row["draws"])


def _rule_key(row):
    return (row["effect"], row["size"], row["rep"], row["rule"])


def main(
    effect,
    size,
    replicates,
    draws=4,
    out_dir="reports",
    quick=False,
    workers=1,
    diagnose=False,
    rule=cal.DEFAULT_RULE,
    report="fitted_test",
):
    """Run what the cache lacks (``workers`` replicates at a time; ``diagnose``: diagnose each
    one too; ``rule`` other than the default: diagnose alone under it); write the report
    ``out_dir/<report>.md`` from the rows of this version; return this size's rows (the
    test's, or the rule's)."""
    version = code_version() + ("-quick" if quick else "")
    cache = pathlib.Path(out_dir) / ".cache" / "fitted_test" / f"{version}.jsonl"
    ruled = cache.with_suffix(".rules.jsonl")
    cache.parent.mkdir(parents=True, exist_ok=True)
    if rule == cal.DEFAULT_RULE:
        path, key, tag = cache, _key, draws
        work = lambda rep: replicate(effect, size, rep, draws, quick, diagnose)  # noqa: E731
    else:
        path, key, tag = ruled, _rule_key, rule
        work = lambda rep: diagnosed(effect, size, rep, rule, quick)  # noqa: E731
    done = {key(r) for r in jsonl_rows(path)}
    todo = [k for k in replicates if (effect, size, k, tag) not in done]

    def one(rep):
        row = {**work(rep), "code": version}
        with path.open("a") as out:  # one line a replicate: a stopped run keeps its rows
            out.write(json.dumps(row) + "\n")
        print(f"{effect} {size:g} #{rep}: {_said(row)}", flush=True)
        return row

    fork_map(one, todo, workers)
    write_report(out_dir, jsonl_rows(cache), version, jsonl_rows(ruled), report)
    mine = [r for r in jsonl_rows(path) if (r["effect"], r["size"]) == (effect, size)]
    return [r for r in mine if key(r)[3] == tag]  # of these draws (the test) or this rule


def _said(row):
    """One replicate's outcome in a line of progress."""
    if "chi2" in row:
        return f"chi2 {row['chi2']:.1f}, p {row['p']:.2g}"
    return f"{row['rule']}: {row['diagnose']['verdict']}, named {row['diagnose']['named']}"


def write_report(out_dir, rows, version, ruled=(), name="fitted_test"):
    """``<name>.md``: every size of the current version, one line a replicate; ``ruled``:
    diagnose's rows under other mesh-error rules, a column each."""
    fine = [2 * n for n in cal.FAMILIES[cal.POWER_FAMILY]]  # the recordings' mesh
    lines = [
        "# The fitted test fitted globally",
        "",
        f"Date: {utc_now()}. Machine: {cpu()}, 2 cores. Code: {version}. Made by "
        "`python -m studies.fitted_test EFFECT SIZE --diagnose"
        + ("" if name == "fitted_test" else f" --report {name}")
        + "` (its docstring says how).",
        "",
        "The calibration study's power replicates (Frederiksen plate, recordings on "
        f"{fine[0]} x {fine[1]}, "
        "14 frequencies, 0.2 % noise): the six constants fitted with no prior, on the "
        "recordings' own mesh, from the true constants, the prior mean, eight starts aimed "
        "along the transverse shear coefficients and draws from the prior. The statistic is "
        f"the best optimum's chi-square; rejected at {ALPHA:g}. `first two`: the best of the "
        "true constants and the prior mean alone; `found by`: the kind of start of the best. "
        "`ratios`: the best optimum's coefficients over the true ones (C11, C22, C12, C66, "
        "C44 = G23, C55 = G13). `diagnose, RULE rule`: its verdict on the same replicate with "
        "the package's defaults but its mesh-error rule (`--mesh-error`; the default is "
        f"`{cal.DEFAULT_RULE}`; rows made before the rule was kept: `whole`, the default "
        "then), its nominal p-value and time; *named* when it names the concealed candidate "
        "(explained, or ambiguous with it); *a name without the truth*: explained with another "
        "candidate, or ambiguous among others only.",
    ]
    groups = sorted({(r["effect"], r["size"], r["draws"]) for r in rows})
    tables, summary = [], []
    for effect, size, draws in groups:
        mine = sorted(
            (r for r in rows if (r["effect"], r["size"], r["draws"]) == (effect, size, draws)),
            key=lambda r: r["rep"],
        )
        theirs = [r for r in ruled if (r["effect"], r["size"]) == (effect, size)]
        by = _by_rule(mine, theirs)
        tables += _group(effect, size, draws, mine, theirs, by)
        summary.append((effect, size, mine, by))
    lines += _summary(summary) + tables
    path = pathlib.Path(out_dir) / f"{name}.md"
    atomic_write_text(path, "\n".join(lines) + "\n" + _kept_reading(path))
    return path


#: The heading of the report's reading of its numbers, written by hand and kept when the
#: tables are written again.
READING = "## What it shows"


def _kept_reading(path):
    """The hand-written :data:`READING` section of the report at ``path`` (empty if none)."""
    try:
        text = pathlib.Path(path).read_text()
    except FileNotFoundError:
        return ""
    at = text.find("\n" + READING + "\n")
    return "" if at < 0 else text[at:]


def _by_rule(rows, ruled):
    """``{(rule, rep): verdict}``: diagnose's verdicts on one size's replicates, every rule
    (``rows``: the test's, diagnosed beside it; ``ruled``: under other rules alone)."""
    by = {(_rule(r["diagnose"]), r["rep"]): r["diagnose"] for r in rows if r["diagnose"]}
    return by | {(r["rule"], r["rep"]): r["diagnose"] for r in ruled}


def _tally(effect, rows, by, rule):
    """One rule's verdicts on ``rows`` (those diagnosed), how many named the concealed
    ``effect`` and how many gave a name without it: ``(verdicts, named, wrong)``."""
    ds = [by[rule, r["rep"]] for r in rows if (rule, r["rep"]) in by]
    named = sum(d["named"] for d in ds)
    return ds, named, sum(cal.misnamed({**d, "effect": effect}) for d in ds)


def _summary(groups):
    """The power table: each size's rejections by the test and names by diagnose, per rule.

    ``groups``: ``(effect, size, rows, by_rule)`` a size, as :func:`write_report` gathers them.
    """
    rules = sorted({rule for *_, by in groups for rule, _ in by})
    out = [
        "",
        "## The power table",
        "",
        "Each size run: how often the fitted test rejects (at 0.01), and diagnose names the "
        "concealed candidate (named / diagnosed; after the + the names without the truth; "
        "the median seconds a diagnosis) under each mesh-error rule run.",
        "",
        "| candidate | size | fitted test rejects |"
        + "".join(f" named, `{rule}` rule |" for rule in rules),
        "|---|---|---|" + "---|" * len(rules),
    ]
    for effect, size, rows, by in groups:
        cells = []
        for rule in rules:
            ds, named, wrong = _tally(effect, rows, by, rule)
            seconds = np.median([d["seconds"] for d in ds]) if ds else None
            cells.append(f"{named} of {len(ds)} + {wrong} ({seconds:.0f} s)" if ds else "-")
        unit = cal.EFFECTS[effect][2] if effect in cal.EFFECTS else ""
        out.append(
            f"| {effect} | {size:g} {unit} | {sum(r['p'] < ALPHA for r in rows)} of "
            f"{len(rows)} |" + "".join(f" {c} |" for c in cells)
        )
    return out


def _group(effect, size, draws, rows, ruled, by):
    """One size's table and its counts; ``ruled``: diagnose's rows under other rules at this
    size, ``by``: every verdict (:func:`_by_rule`)."""
    rules = sorted({rule for rule, _ in by})
    codes = ", ".join(sorted({r.get("code", "-") for r in [*rows, *ruled]}))
    out = [
        "",
        f"## {effect} at {size:g} ({draws} draws; computed by code {codes})",
        "",
        "| replicate | chi2 at the truth | first two | best of all | found by | p | rejected "
        "| ratios | " + "".join(f"diagnose, `{rule}` rule | " for rule in rules) + "s (test) |",
        "|---|---|---|---|---|---|---|---|---|" + "---|" * len(rules),
    ]
    for r in rows:
        out.append(
            f"| {r['rep']} | {r['at_truth']:.1f} | {min(r['by_start'][:2]):.1f} | "
            f"{r['chi2']:.1f} | {r['best_kind']} | {r['p']:.2g} | "
            f"{'yes' if r['p'] < ALPHA else 'no'} | "
            f"{', '.join(f'{v:.2f}' for v in r['ratios'])} | "
            + "".join(f"{_verdict_text(by.get((rule, r['rep'])))} | " for rule in rules)
            + f"{r['seconds']:.0f} |"
        )
    tallies = [(rule, *_tally(effect, rows, by, rule)) for rule in rules]
    out += [
        "",
        f"Rejected by the fitted test: **{sum(r['p'] < ALPHA for r in rows)} of {len(rows)}**"
        + "".join(
            f"; named by diagnose under the `{rule}` rule: **{named} of {len(ds)}** (a name "
            f"without the truth: {wrong})"
            for rule, ds, named, wrong in tallies
            if ds
        )
        + ".",
    ]
    return out


def _rule(d):
    """The mesh-error rule a verdict was made under (rows before it was kept: ``whole``, the
    default then)."""
    return d.get("rule", "whole")


def _verdict_text(d):
    """A verdict, the names it gives, its nominal p-value and whether it named the truth."""
    if not d:
        return "-"
    names = [n for n in (d["chosen"], d["rival"], *d["also"]) if n]
    said = " ".join([d["verdict"], *([", ".join(names)] if names else [])])
    said += f" (p {d['p_value']:.2g}, {d['seconds']:.0f} s)"
    return said + (", named" if d["named"] else "")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("effect")
    parser.add_argument("size", type=float)
    parser.add_argument("--replicates", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--draws", type=int, default=4)
    parser.add_argument("--diagnose", action="store_true")
    parser.add_argument("--mesh-error", choices=cal.RULES, default=cal.DEFAULT_RULE)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", default=os.environ.get("STUDY_OUT", "reports"))
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--report", default="fitted_test", help="the report's name (no .md)")
    a = parser.parse_args()
    main(
        a.effect,
        a.size,
        a.replicates,
        a.draws,
        a.out,
        a.quick,
        workers=a.workers,
        diagnose=a.diagnose,
        rule=a.mesh_error,
        report=a.report,
    )
