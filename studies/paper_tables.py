"""The paper's results tables (3-14, 17, 20, 23) re-run with B, MVE and MVE-mod.

Writes to ``out_dir``:

- ``estimators_tables.md``: every run of Tables 3-14, 17, 20 and 23, ours beside the paper's
  (``bayesplate/data/paper/results.toml``), one row per run (two for MVE-mod: its stages),
  with iteration counts, forward solves, wall time and a verdict; every row outside the
  issue's tolerances carries an explanation.
- ``estimators_conventions.md``: which reading of the paper's conventions reproduces it
  (V_Y and V_b squared or not, diagonal or full V_b, MVE with fixed or updated V_b, the
  stopping rule on b or on the engineering constants, MVE-mod stage-2 deviations).
- ``estimators_timing.md``: wall time and forward solves of every run.
- ``estimators_fast.md``: every run again on the certified fast model (``forward="fast"``:
  iterations on the reduced-basis model, the answer checked by the full model), beside the
  full model's run: the largest relative difference of the constants, the iterations, and
  whether the row still reproduces the paper.

Run: ``python -m studies.paper_tables [--quick] [--out DIR]`` (quick: a subset, seconds).
"""

import argparse
import os
import pathlib
import sys
import time
from dataclasses import dataclass, replace

import numpy as np

from bayesplate.estimators import CONVENTIONS, DEFAULT_MAX_ITER, estimate
from bayesplate.io import atomic_write_text, bundled_case_path, load_case
from bayesplate.plate.model import PlateModel

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

TABLES = "estimators_tables.md"
CONVENTIONS_REPORT = "estimators_conventions.md"
TIMING = "estimators_timing.md"
FAST = "estimators_fast.md"
RESULTS = bundled_case_path("plate1").parents[1] / "paper" / "results.toml"
PAPER = tomllib.loads(RESULTS.read_text())
SI = np.array([1e9, 1e9, 1.0, 1e9, 1e9, 1e9])
NAMES = ("E1", "E2", "nu12", "G12", "G13", "G23")
FRACTION = {"1/2": 1 / 2, "1/3": 1 / 3, "1/6": 1 / 6, "1/10": 1 / 10}
DEVIATIONS = ("1/3", "1/6", "1/10")
STRONG, WEAK = [0, 1, 3], [2, 4, 5]  # E1, E2, G12 | nu12, G13, G23 (section 4.1)
TOL_STRONG, TOL_WEAK = 0.02, 0.10  # issue 3: 2 % and 10 % of the paper's value
TOL_TARGET = 0.005  # issue 3: Plate 1 MVE / MVE-mod reach the target within 0.5 %
CASE_OF = {
    "plate1": "plate1",
    "plate2": "plate2",
    "crossply": "crossply",
    "angleply": "angleply",
    "frederiksen": "frederiksen_t300",
}
TABLE_OF = {
    ("plate1", "test1"): ("3", "9"),
    ("plate1", "test2"): ("4", "10"),
    ("plate1", "test3"): ("5", "11"),
    ("plate2", "test1"): ("6", "12"),
    ("plate2", "test2"): ("7", "13"),
    ("plate2", "test3"): ("8", "14"),
}
# Why a row may differ from the paper. Text only: shown where a row is outside tolerance.
EXPLAIN = {
    ("12", "MVE-mod", "1/3", "stage 1"): (
        "The paper prints stage-1 G23 = 1.459 GPa, but its stage 2 starts from that estimate "
        "and ends at 4.159 GPa after 1 iteration (impossible with TOL = 1e-3 from 1.459), and "
        "Table 6's MVE row is 4.159: a misprint of 4.159. Every other constant agrees."
    ),
}


# ----------------------------------------------------------------------------- the runs


@dataclass(frozen=True)
class Spec:
    """One run of one paper table."""

    table: str
    source: str  # key of results.toml: plate1, plate2, crossply, angleply, frederiksen
    test: str | None  # test1..test3 for Plates 1 and 2
    method: str
    d: str | None = None  # deviation fraction of the initial values (Plates 1, 2)
    d2: str | None = None  # MVE-mod stage 2

    @property
    def label(self):
        if self.d2:
            return f"{self.method} {self.d} -> {self.d2}"
        return f"{self.method} {self.d}" if self.d else self.method

    def paper(self):
        """The paper's row (list, "diverged", or {stage1, stage2}) for this run."""
        entry = PAPER[self.source] if self.test is None else PAPER[self.source][self.test]
        key = self.method.replace("-", "_")
        if self.method == "MVE-mod" and self.test is not None:
            return next(r for r in entry[key] if r["d1"] == self.d)
        return entry[key][self.d] if self.d else entry[key]


def paper_specs(quick=False):
    """Every run of Tables 3-14, 17, 20, 23 (a small subset when `quick`)."""
    if quick:
        return [
            Spec("3", "plate1", "test1", "B", "1/3"),
            Spec("4", "plate1", "test2", "B", "1/3"),
            Spec("4", "plate1", "test2", "MVE", "1/3"),
            Spec("11", "plate1", "test3", "MVE-mod", "1/6", "1/3"),
        ]
    specs = []
    for (source, test), (t_bm, t_mod) in TABLE_OF.items():
        specs += [Spec(t_bm, source, test, m, d) for m in ("B", "MVE") for d in DEVIATIONS]
        specs += [
            Spec(t_mod, source, test, "MVE-mod", r["d1"], r["d2"])
            for r in PAPER[source][test]["MVE_mod"]
        ]
    for table, source in (("17", "crossply"), ("20", "angleply")):
        specs += [Spec(table, source, None, m) for m in ("B", "MVE", "MVE-mod")]
    specs += [Spec("23", "frederiksen", None, m) for m in ("B", "MVE")]
    return specs


class _Models:
    """One case and one finite-element model per bundled case, built on first use."""

    def __init__(self):
        self._cache = {}

    def __call__(self, source):
        if source not in self._cache:
            case = load_case(bundled_case_path(CASE_OF[source]))
            self._cache[source] = (case, PlateModel.from_case(case))
        return self._cache[source]


def run_spec(spec, models, convention="paper", max_iter=DEFAULT_MAX_ITER, forward="full"):
    """Run one spec (on the full model unless `forward` says otherwise); its result."""
    case, model = models(spec.source)
    kwargs = {
        "model": model,
        "convention": convention,
        "max_iter": max_iter,
        "forward": forward,
        "pairing": "order",
    }  # the paper pairs by order (issue 16: not the default)
    if spec.d is not None:
        initial = np.array(PAPER[spec.source][spec.test]["initial"]) * SI
        kwargs.update(prior_mean=initial, prior_sd=FRACTION[spec.d] * initial)
    if spec.d2 is not None:
        kwargs["stage2_factor"] = FRACTION[spec.d2] / FRACTION[spec.d]
    return estimate(case, spec.method, **kwargs)


def fast_rows(specs, models, full_lines, log=print):
    """Every spec again on the fast model, beside its full-model lines.

    Returns a list of dicts: the spec's table and label (with the MVE-mod stage), the largest
    relative difference of the six constants between the two runs, both iteration counts,
    both statuses, whether each reproduces the paper, and the full-model check.
    """
    full = {(x.spec, x.stage): x for x in full_lines}
    rows = []
    for spec in specs:
        started = time.perf_counter()
        result = run_spec(spec, models, forward="fast")
        for line in lines_of(spec, result):
            line = judge(line)
            ref = full[(spec, line.stage)]
            diff = np.max(np.abs(line.ours.constants / ref.ours.constants - 1.0))
            rows.append(
                {
                    "table": spec.table,
                    "source": spec.source,
                    "test": spec.test or "",
                    "label": spec.label,
                    "stage": line.stage,
                    "diff": float(diff),
                    "iterations": (line.ours.iterations, ref.ours.iterations),
                    "status": (_stopped(result), _stopped(ref.run)),
                    "agrees": (line.agrees, ref.agrees),
                    "check": result.check,
                    "seconds": time.perf_counter() - started,
                }
            )
        log(
            f"  fast: Table {spec.table} {spec.source} {spec.test or ''} {spec.label}: "
            f"{rows[-1]['diff']:.1e}"
        )
    return rows


def _stopped(result):
    """How the iteration ended: "converged" when it stopped, whatever the fit's assessment
    (issue 37: ``status`` is "rejected" or "implausible" for a flagged answer)."""
    return "converged" if result.converged else result.status


def fast_markdown(rows, quick):
    """``estimators_fast.md``: the paper's runs on the fast model beside the full model."""
    both = [r for r in rows if r["agrees"][1]]
    kept = sum(r["agrees"][0] for r in both)
    converged = [r for r in rows if r["status"] == ("converged", "converged")]
    worst = max((r["diff"] for r in converged), default=float("nan"))
    same_it = sum(r["iterations"][0] == r["iterations"][1] for r in converged)
    out = [
        _header(quick, "The paper's runs on the certified fast model."),
        'Every run of the tables on the certified fast model (`forward="fast"`: B, MVE and '
        "MVE-mod iterate on the reduced-basis model over the prior's 3-sigma box, the full "
        "finite-element model checks each answer and enriches the basis where it disagrees), "
        "beside the same run on the full model.",
        "",
        f"- Rows that reproduce the paper on the full model: {len(both)}; on the fast model "
        f"too: {kept}.",
        f"- Runs that converge both ways: {len(converged)}; the largest relative difference "
        f"of a constant between the two answers: {worst:.1e} (the stopping tolerance TOL is "
        f"1e-3); the same iteration count in {same_it} of them.",
        f"- Status the same both ways in {sum(r['status'][0] == r['status'][1] for r in rows)}"
        f" of {len(rows)} rows.",
        "",
        "TOL bounds the last step, not the distance to the fixed point: where MVE contracts "
        "slowly, by a ratio q per iteration, a run stopped by TOL is about TOL q / (1 - q) "
        "from it, and two runs whose paths differ slightly stop at different places within "
        "that. Plate 2's test-2 MVE runs contract by q = 0.94 per iteration in nu12 (81 "
        "iterations; 1.6e-2 from the fixed point by that bound): their fast and full "
        "answers differ by up to 2.4e-3 in nu12 and by less than 1e-4 in E1, E2 and G12. "
        "Runs capped at 200 iterations are at no fixed point at all.",
        "",
        "| table | run | stage | max rel. diff | iterations fast / full | status fast / full "
        "| reproduces fast / full | full-model check |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        check = r["check"]
        text = "-" if check is None else (f"{check.max_rel_error:.0e}, {check.rounds} run(s)")
        agree = " / ".join("yes" if a else "**no**" for a in r["agrees"])
        out.append(
            f"| {r['table']} | {r['source']} {r['test']} {r['label']} | {r['stage'] or '-'} | "
            f"{r['diff']:.1e} | {r['iterations'][0]} / {r['iterations'][1]} | "
            f"{r['status'][0]} / {r['status'][1]} | {agree} | {text} |"
        )
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- comparison


@dataclass
class Line:
    """One printed row: our estimate (or one MVE-mod stage) beside the paper's."""

    spec: Spec
    stage: str  # "" or "stage 1" / "stage 2"
    ours: object  # EstimateResult of the run or of the stage
    paper: object  # list of 6 (+ iterations) or "diverged" or None
    agrees: bool = True
    target_ok: bool | None = None
    note: str = ""
    run: object = None  # the whole run's EstimateResult (both stages for MVE-mod)


def lines_of(spec, result):
    """The printed lines of one run: one, or one per MVE-mod stage."""
    paper = spec.paper()
    if spec.method != "MVE-mod":
        return [Line(spec, "", result, paper)]
    stages = list(result.stages) + [None] * (2 - len(result.stages))
    return [Line(spec, f"stage {i + 1}", s, paper[f"stage{i + 1}"]) for i, s in enumerate(stages)]


def judge(line):
    """Set ``agrees``, ``target_ok`` and ``note`` of a line from the numbers."""
    ours, paper = line.ours, line.paper
    if paper == "diverged":
        line.agrees = ours is not None and not ours.converged
        line.note = "paper: does not converge; ours: " + _short(ours)
        return line if line.agrees else _explain(line)
    if ours is None or not ours.converged:
        line.agrees = False
        line.note = "ours: " + _short(ours)
        return _explain(line)
    rel = np.abs(ours.constants / SI - paper[:6]) / np.abs(paper[:6])
    line.agrees = bool(np.all(rel[STRONG] <= TOL_STRONG) and np.all(rel[WEAK] <= TOL_WEAK))
    if _target_applies(line):
        target = np.array(PAPER["plate1"]["target"]["constants"]) * SI
        err = np.abs(ours.constants - target) / target
        line.target_ok = bool(np.all(err[STRONG] <= TOL_TARGET))
    if not line.agrees:
        worst = int(np.argmax(rel / np.where(np.isin(range(6), STRONG), TOL_STRONG, TOL_WEAK)))
        line.note = f"{NAMES[worst]} differs by {100 * rel[worst]:.1f} %"
        _explain(line)
    return line


def _target_applies(line):
    """Issue 3: Plate 1 MVE and MVE-mod (final stage) rows where the paper reaches target."""
    return (
        line.spec.source == "plate1"
        and line.stage in ("", "stage 2")
        and (line.spec.method in ("MVE", "MVE-mod"))
    )


def _explain(line):
    key = (line.spec.table, line.spec.method, line.spec.d, line.stage)
    text = EXPLAIN.get(key)
    line.note += f". {text}" if text else ". UNEXPLAINED"
    return line


def _short(result):
    if result is None:
        return "not run (stage 1 did not converge)"
    return result.message.split("; the paired")[0]


def beyond_cap(spec, models, max_iter=3 * DEFAULT_MAX_ITER):
    """What a run that hit the iteration cap does with a larger cap (evidence for a note)."""
    result = run_spec(spec, models, max_iter=max_iter)
    e = result.constants / SI
    return (
        f"with a cap of {max_iter}: {_short(result)} after {result.iterations} iterations at "
        f"E1 = {e[0]:.4g} GPa, nu12 = {e[2]:.3g}, G23 = {e[5]:.4g} GPa, largest frequency "
        f"residual {np.max(np.abs(result.residual_percent)):.1f} % (sigma = 1 %)"
    )


# ----------------------------------------------------------------------------- conventions


def variants():
    """Readings of the paper's conventions, each against the runs it affects."""
    paper = CONVENTIONS["paper"]
    bm, mve, mod = ("B", "MVE"), ("MVE",), ("MVE-mod",)
    return [
        ("paper (the default)", paper, bm + mod),
        ("V_Y = diag(d lambda), as printed", replace(paper, observation="deviation"), bm),
        ("V_b = diag(dC), as printed", replace(paper, prior="deviation"), bm),
        ("section 3.6 as printed, MVE with updated V ('printed')", CONVENTIONS["printed"], bm),
        ("V_b = J diag(sd_e^2) J^T, full ('full-prior')", CONVENTIONS["full-prior"], bm),
        ("MVE iterates with the updated V^{k+1}", replace(paper, covariance="updated"), mve),
        ("stopping rule on the engineering constants", replace(paper, stop_on="engineering"), bm),
        (
            "MVE-mod stage 2: sd = d2 x stage-1 estimate",
            replace(paper, stage2_base="estimate"),
            mod,
        ),
    ]


def convention_rows(specs, models, log=print):
    """For each reading: agreement with the paper over the Plate 1 and 2 runs it affects."""
    rows = []
    plates = [s for s in specs if s.source in ("plate1", "plate2")]
    for name, conventions, methods in variants():
        lines = []
        for spec in (s for s in plates if s.method in methods):
            lines += [judge(x) for x in lines_of(spec, run_spec(spec, models, conventions))]
        rows.append((name, conventions, methods, _summary(lines)))
        log(f"  conventions: {name}: {rows[-1][3]['agree']}/{rows[-1][3]['n']}")
    return rows


def _summary(lines):
    iters = [
        (x.ours.iterations, x.paper[6])
        for x in lines
        if x.ours is not None
        and x.ours.converged
        and isinstance(x.paper, list)
        and len(x.paper) > 6
    ]
    diff = np.array([abs(a - b) for a, b in iters]) if iters else np.array([np.nan])
    de1 = [
        abs(x.ours.constants[0] / 1e9 / x.paper[0] - 1)
        for x in lines
        if x.ours is not None and isinstance(x.paper, list)
    ]
    return {
        "n": len(lines),
        "agree": sum(x.agrees for x in lines),
        "explained": sum(not x.agrees and "UNEXPLAINED" not in x.note for x in lines),
        "iter_exact": int(np.sum(diff == 0)),
        "iter_pm1": int(np.sum(diff <= 1)),
        "n_iter": len(iters),
        "median_dE1": 100 * float(np.median(de1)) if de1 else float("nan"),
    }


# ----------------------------------------------------------------------------- Markdown


def _header(quick, what):
    command = "python -m studies.paper_tables" + (" --quick" if quick else "")
    return (
        f"Made by `{command}` (no randomness). {what}\n\n"
        'Conventions (`convention="paper"`, the library default, settled by the comparison '
        f"in `{CONVENTIONS_REPORT}`): V_Y = diag(d lambda^2) with d lambda = 8 pi^2 f df and "
        "df = 0.01 f; V_b = diag(dC^2) propagated to first order from sd = d x initial value "
        "(eqs. 20-21); MVE iterates eq. 12 with the initial V_b; stop when |b_i^{k+1} - "
        "b_i^k| / |b_i^k| <= TOL for all i (TOL = 1e-3; MVE-mod stage 1: 1e-2); MVE-mod "
        "stage-2 sd = d2 x initial value; pairing by order; iteration cap "
        f"{DEFAULT_MAX_ITER}.\n"
    )


def _fmt(values):
    return [f"{v:#.4g}" for v in values]


def _row(line):
    spec, ours, paper = line.spec, line.ours, line.paper
    head = f"| {spec.label} | {line.stage or '-'} "
    if ours is None:
        cells = ["-"] * 6 + ["-", "not run", "-", "-"]
    else:
        e = _fmt(ours.constants / SI)
        if not ours.converged:  # the last physical iterate, not an estimate
            e = [f"({v})" for v in e]
        status = "converged" if ours.converged else "**not converged**"
        cells = e + [str(ours.iterations), status, str(ours.n_solves), f"{ours.wall_time:.1f}"]
    if paper == "diverged":
        pcells = ["diverged"] + [""] * 5 + ["-"]
    elif paper is None:
        pcells = ["-"] * 7
    else:
        pcells = _fmt(paper[:6]) + [str(paper[6]) if len(paper) > 6 else "-"]
    both = [f"{a} / {b}" if b else a for a, b in zip(cells[:7], pcells, strict=True)]
    verdict = "yes" if line.agrees else "**no**"
    if line.target_ok is not None:
        verdict += ", target " + ("yes" if line.target_ok else "**no**")
    return head + "| " + " | ".join(both + cells[7:] + [verdict, line.note]) + " |"


def tables_markdown(lines, quick):
    """The tables report: one section per paper table."""
    cols = (
        "run",
        "stage",
        "E1 GPa",
        "E2 GPa",
        "nu12",
        "G12 GPa",
        "G13 GPa",
        "G23 GPa",
        "iter",
        "status",
        "solves",
        "time s",
        "within tol",
        "note",
    )
    out = [_header(quick, "Ours / the paper's in each cell."), _tolerance_text(), ""]
    out += _summary_table(lines)
    for table in sorted(dict.fromkeys(x.spec.table for x in lines), key=int):
        mine = [x for x in lines if x.spec.table == table]
        out += [
            f"\n## Table {table}: {_title(mine[0].spec)}\n",
            "| " + " | ".join(cols) + " |",
            "|" + "---|" * len(cols),
        ]
        out += [_row(x) for x in mine]
    return "\n".join(out) + "\n"


def _tolerance_text():
    return (
        "\nWithin tolerance (issue 3): E1, E2, G12 within 2 % and nu12, G13, G23 within 10 % "
        "of the paper's value, or both runs not converging where the paper prints '-'. "
        "'target' (Plate 1 MVE and MVE-mod): E1, E2, G12 within 0.5 % of the target "
        "constants. Iteration counts are compared in the summary, not judged. Values in "
        "parentheses are the last iterate of a run that did not converge, not an estimate."
    )


def _summary_table(lines):
    out = [
        "\n| tables | rows | within tol | outside, explained | iterations equal | within +-1 "
        "| target reached |",
        "|---|---|---|---|---|---|---|",
    ]
    groups = {
        "3-8 (B, MVE)": [str(t) for t in range(3, 9)],
        "9-14 (MVE-mod)": [str(t) for t in range(9, 15)],
        "17, 20 (laminates)": ["17", "20"],
        "23 (Frederiksen)": ["23"],
    }
    for name, tables in groups.items():
        mine = [x for x in lines if x.spec.table in tables]
        if not mine:
            continue
        s = _summary(mine)
        targets = [x.target_ok for x in mine if x.target_ok is not None]
        target = f"{sum(targets)}/{len(targets)}" if targets else "-"
        out.append(
            f"| {name} | {s['n']} | {s['agree']} | {s['explained']} | "
            f"{s['iter_exact']}/{s['n_iter']} | "
            f"{s['iter_pm1']}/{s['n_iter']} | {target} |"
        )
    return out


def _title(spec):
    if spec.test:
        return f"{spec.source.replace('plate', 'Plate ')}, {spec.test.replace('test', 'test ')}"
    return {
        "crossply": "cross-ply laminate (case prior; MVE-mod stage 2 = 2 x stage 1)",
        "angleply": "angle-ply laminate (case prior; MVE-mod stage 2 = 2 x stage 1)",
        "frederiksen": "Frederiksen T300/epoxy plate, measured (50 x 50 mesh; the paper "
        "prints no iteration counts)",
    }[spec.source]


def conventions_markdown(rows, quick):
    out = [
        _header(quick, "Which reading of the paper's conventions reproduces it."),
        "",
        "Each reading is run on the Plate 1 and Plate 2 rows of the methods it changes "
        "(Tables 3-8 for B and MVE, 9-14 for MVE-mod) and compared with the paper as in "
        f"`{TABLES}`.",
        "",
        "| reading | methods | rows | within tol | iterations equal | within +-1 | "
        "median abs(dE1) % |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, _, methods, s in rows:
        out.append(
            f"| {name} | {', '.join(methods)} | {s['n']} | {s['agree']} | "
            f"{s['iter_exact']}/{s['n_iter']} | {s['iter_pm1']}/{s['n_iter']} | "
            f"{s['median_dE1']:.2f} |"
        )
    out += ["", "Verdicts, from the numbers above:", ""]
    out += [f"- {name}: {_verdict(s)}" for name, _, _, s in rows]
    out += ["", _WHY]
    return "\n".join(out) + "\n"


def _verdict(s):
    """One sentence on a reading, from its summary numbers."""
    unexplained = s["n"] - s["agree"] - s["explained"]
    estimates = (
        f"{s['agree']} of {s['n']} rows within tolerance"
        + (f" ({s['explained']} more explained)" if s["explained"] else "")
        + (f", {unexplained} not" if unexplained else "")
    )
    counts = (
        f"iteration counts equal in {s['iter_exact']} and within one in {s['iter_pm1']} "
        f"of {s['n_iter']} converged rows"
    )
    if unexplained:
        head = "does not reproduce"
    elif s["iter_pm1"] == s["n_iter"]:
        head = "**reproduces** estimates and iteration counts"
    else:
        head = "reproduces the estimates, not all iteration counts"
    return f"{head}: {estimates}; {counts}"


_WHY = """\
Why (mechanisms, not numbers): section 3.6 prints V_Y = diag(d lambda) and V_b = diag(dC_ij).
Taken literally (a deviation where a variance belongs) the balance of prior and data depends on
the units: in SI, V_b = diag(dC) makes the prior outweigh the data by orders of magnitude (B
barely leaves its initial values) and V_Y = diag(d lambda) makes the data outweigh the prior (B
loses the bias of Tables 4-5, lands on the target or overshoots out of the physical region in
one undamped step). With squared deviations on the diagonal both are ordinary variances. The full
propagated V_b correlates C11, C22 and C12 through E1, E2 and nu12 and moves the weakly
determined nu12 and G13 of B. Iterating MVE with the updated V^{k+1} re-uses the same data at
every iteration, so the covariance and the steps shrink and the run stops early; with the
initial V_b, eq. 12 is a damped Gauss-Newton step whose fixed point fits the data whatever the
initial values (section 4.3), and V^{k+1} is only the reported covariance."""


def timing_markdown(lines, quick):
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    out = [
        _header(quick, "Wall time and forward solves per run."),
        "",
        f"Machine: {os.cpu_count()} CPUs shared with other jobs (load average {load:.1f} "
        "at the end of the run), so times are indicative; the solve counts are exact.",
        "",
    ]
    out += _timing_summary(lines)
    out += [
        "",
        "Per run (MVE-mod: both stages):",
        "",
        "| table | run | case mesh | iterations | forward solves | wall s | in solves s "
        "| s per solve |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r, x in {id(x.run): (x.run, x) for x in lines}.values():
        solve_s = r.settings.get("solve_seconds", float("nan"))
        out.append(
            f"| {x.spec.table} | {x.spec.label} | {r.settings['mesh']} | {r.iterations} | "
            f"{r.n_solves} | {r.wall_time:.2f} | {solve_s:.2f} | "
            f"{r.wall_time / max(r.n_solves, 1):.3f} |"
        )
    return "\n".join(out) + "\n"


def _timing_summary(lines):
    """Per mesh: runs, solves, total and per-solve wall time, share spent in solves."""
    runs = {id(x.run): x.run for x in lines}.values()
    out = [
        "| mesh | runs | forward solves | wall s | median s per solve | share in solves |",
        "|---|---|---|---|---|---|",
    ]
    for mesh in dict.fromkeys(r.settings["mesh"] for r in runs):
        mine = [r for r in runs if r.settings["mesh"] == mesh]
        solves = sum(r.n_solves for r in mine)
        wall = sum(r.wall_time for r in mine)
        in_solves = sum(r.settings.get("solve_seconds", 0.0) for r in mine)
        per = np.median([r.wall_time / max(r.n_solves, 1) for r in mine])
        out.append(
            f"| {mesh} | {len(mine)} | {solves} | {wall:.1f} | {per:.3f} | "
            f"{100 * in_solves / wall:.0f} % |"
        )
    return out


# ----------------------------------------------------------------------------- main


def compute(quick=False, log=print):
    """Run every spec with the paper's conventions and every reading of the conventions."""
    models = _Models()
    lines = []
    for spec in paper_specs(quick):
        start = time.perf_counter()
        result = run_spec(spec, models)
        mesh = models(spec.source)[1].mesh
        result.settings["mesh"] = f"{mesh.nx}x{mesh.ny}"
        for line in lines_of(spec, result):
            line.run = result
            lines.append(judge(line))
        log(
            f"Table {spec.table} {spec.source} {spec.test or ''} {spec.label}: "
            f"{result.iterations} it, {time.perf_counter() - start:.1f} s"
        )
        if not quick and spec.paper() == "diverged" and result.status == "iteration_cap":
            lines[-1].note += f"; {beyond_cap(spec, models)}"
    conventions = convention_rows(paper_specs(quick), models, log)
    fast = fast_rows(paper_specs(quick), models, lines, log)
    return {"lines": lines, "conventions": conventions, "fast": fast}


def main(out_dir, quick=False):
    """Compute and write the three reports; return the results dict."""
    out_dir = pathlib.Path(out_dir)
    results = compute(quick=quick)
    atomic_write_text(out_dir / TABLES, tables_markdown(results["lines"], quick))
    atomic_write_text(
        out_dir / CONVENTIONS_REPORT, conventions_markdown(results["conventions"], quick)
    )
    atomic_write_text(out_dir / TIMING, timing_markdown(results["lines"], quick))
    atomic_write_text(out_dir / FAST, fast_markdown(results["fast"], quick))
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a subset of the runs")
    parser.add_argument("--out", default=pathlib.Path(__file__).parents[1] / "reports")
    args = parser.parse_args()
    main(args.out, quick=args.quick)
