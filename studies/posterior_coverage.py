"""Calibrated posteriors: coverage of the 94 % intervals on seeded synthetic plates (issue 14).

The plate, its true constants ``E_TRUE``, the mesh, the 10 frequencies and their declared
0.5 % deviation are those of studies/input_coverage.py (its helpers are imported from there),
here with exact inputs: each replicate's frequencies are the fitting model's (the full model
on the 12 x 8 mesh, at the nominal thickness and density, the true constants) times
``1 + 0.005 N(0, 1)``, the noise as declared. Nothing but the noise and the prior separates the
data from the model, so a calibrated interval covers at its nominal rate.

Two designs of the prior (``--design``):

- ``drawn`` (the headline): the constants are fixed (``E_TRUE``), the prior mean is drawn
  around them from the prior (sd 25 % of each constant), ``m0 = E_TRUE + 0.25 E_TRUE z``.
  For a Gaussian prior this is the same joint law of (truth - prior mean, data) as the truth
  drawn from the prior, so a Bayesian 94 % interval covers in 94 % of replicates in
  expectation for every constant, those the data barely inform (G13, G23) included: the
  issue's target (90-97 %) is then a test of the sampler, not of the prior.
- ``fixed``: one weak prior for every replicate (mean off the truth by +-10 %, sd 50 %), the
  frequentist view of "a plate with known constants". The data-informed constants should
  still cover near 94 %; those the data barely inform keep the prior's width around a mean
  0.2 sd from the truth and over-cover (near 100 %): no target applies to them.

Per replicate, per constant: does the sampler's 94 % HDI (emcee on the certified fast model,
:func:`bayesplate.sampling.sample`, settings ``SAMPLER``) hold the true value; the same for
B's and MVE's linearised intervals (estimate +- 1.881 sd; B at TOL 1e-6, MVE at TOL 1e-6
and at the command line's 1e-3: at 1e-6 it mostly oscillates without meeting TOL). The
share of covering replicates is given with its Wilson 95 % interval and the 95 % band of a
binomial share at 0.94 for that number of replicates. A replicate whose method did not
converge is counted as failed and left out of that method's shares.

The replicates run as independent tasks on :func:`bayesplate.batch.map_tasks`; each row is
stored as it arrives in ``out_dir/.cache/posterior_coverage*.json`` (atomic writes), so an
interrupted run resumes. Replicate ``i`` of design ``d`` draws from its own
``SeedSequence(SEED, spawn_key=(d, i))``: a row does not depend on which others ran, where or
in which order.

Writes ``posterior_coverage.md`` and ``posterior_coverage.png`` to ``out_dir``. Run:
``python -m studies.posterior_coverage [--quick] [--replicates N] [--design drawn|fixed|both]
[--workers W] [--out DIR]`` (quick: 2 replicates of ``drawn`` in this process).
"""

import argparse
import datetime
import functools
import json
import logging
import os
import pathlib
import sys
import time
import traceback

import numpy as np

from bayesplate import laminate
from bayesplate.batch import map_tasks
from bayesplate.io import atomic_write_text
from bayesplate.likelihood.posterior import GaussianProblem
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import ENGINEERING_KEYS
from studies import input_coverage as ic

REPORT = "posterior_coverage.md"
FIGURE = "posterior_coverage.png"
SEED = 20261214
DESIGNS = ("drawn", "fixed")
METHODS = ("sampler", "B", "MVE", "MVE@1e-3")
#: TOL of each linearised estimator: B as studies/input_coverage.py; MVE at that TOL and at
#: the command line's default (1e-3), at which it stops where 1e-6 finds it oscillating
TOLS = {"B": 1e-6, "MVE": 1e-6, "MVE@1e-3": 1e-3}
LABELS = {
    "sampler+": "sampler, other-mode replicates left out",
    "MVE": "MVE (TOL 1e-6)",
    "MVE@1e-3": "MVE (TOL 1e-3)",
}
#: the sampler's settings: one replicate in about 6 s on one core (measured before choosing)
SAMPLER = {"n_walkers": 32, "min_ess": 600.0, "max_steps": 2000}
QUICK_SAMPLER = {"n_walkers": 32, "min_ess": 300.0, "max_steps": 2000}
FIXED_PRIOR_MEAN = ic.E_TRUE * np.array([1.1, 0.9, 1.1, 0.9, 1.1, 0.9])  # SI
FIXED_PRIOR_SD = 0.5 * ic.E_TRUE  # SI
TARGET = (0.90, 0.97)  # the band for the sampled intervals
MODE_MISS = 0.10  # relative distance of an interval's centre from the truth: another mode


@functools.lru_cache(maxsize=1)
def _model():
    """The fitting model (one per process)."""
    case = ic.nominal_case(np.ones(ic.N_FREQ), ic.E_TRUE, input_sd=False)
    return PlateModel.from_case(case, mesh=ic.MESH)


def draw(design, index):
    """Replicate `index` of `design`: (case as written, seed sequence of its chain)."""
    data, chain = np.random.SeedSequence(SEED, spawn_key=(DESIGNS.index(design), index)).spawn(2)
    prior = (
        {} if design == "drawn" else {"prior_mean": FIXED_PRIOR_MEAN, "prior_sd": FIXED_PRIOR_SD}
    )
    case, _, _ = ic.draw(np.random.default_rng(data), input_errors=False, **prior)
    return case, chain


def run_replicate(task, sampler=None):
    """One replicate's row (plain data): each method's 94 % interval (SI) or None, seconds.

    `task` is ``(design, index)`` or ``(design, index, methods)`` (default all of
    ``METHODS``); `sampler` the keywords of :func:`bayesplate.sampling.sample` (default
    ``SAMPLER``). An exception inside a method is recorded in the row (``errors``) and that
    method counted as failed.
    """
    design, index, methods = (*task, METHODS) if len(task) == 2 else task
    case, chain = draw(design, index)
    row = {"design": design, "index": index, "intervals": {}, "seconds": {}, "errors": {}}
    for method in methods:
        start = time.perf_counter()
        try:
            if method == "sampler":
                rng = np.random.default_rng(chain)
                interval = ic.fit_sampler(case, _model(), "exact", rng, **(sampler or SAMPLER))
            else:
                interval = ic.fit_b(case, _model(), "exact", method[:3], TOLS[method])
        except Exception:  # noqa: BLE001 - one replicate must not end a 200-replicate run
            interval = None
            row["errors"][method] = traceback.format_exc(limit=2).strip().splitlines()[-1]
        row["seconds"][method] = time.perf_counter() - start
        row["intervals"][method] = None if interval is None else np.asarray(interval).tolist()
    return row


def _cache_path(out_dir, quick):
    return pathlib.Path(out_dir) / ".cache" / f"posterior_coverage{'-quick' if quick else ''}.json"


def _settings(quick):
    return {
        "seed": SEED,
        "sampler": QUICK_SAMPLER if quick else SAMPLER,
        "fixed_prior_rel": [1.1, 0.9, 1.1, 0.9, 1.1, 0.9, 0.5],
    }


def load_rows(out_dir, quick):
    """The finished rows in the cache, ``{"design/index": row}`` (none if made otherwise)."""
    path = _cache_path(out_dir, quick)
    if not path.exists():
        return {}
    stored = json.loads(path.read_text())
    return stored["rows"] if stored.get("settings") == _settings(quick) else {}


def main(
    out_dir, quick=False, replicates=None, designs=("drawn",), workers=None, report_only=False
):
    """Run the replicates not yet in the cache, write the report and figure; return the path.

    With `report_only`, nothing runs: the report is written from the cached rows.
    """
    logging.getLogger("bayesplate").setLevel(logging.ERROR)
    n = replicates or (2 if quick else 200)
    workers = workers or (1 if quick else 2)
    rows = load_rows(out_dir, quick)
    # a replicate not run, or run before a method was added: only what is missing runs
    todo = [
        (
            d,
            i,
            tuple(
                m for m in METHODS if m not in rows.get(f"{d}/{i}", {"intervals": {}})["intervals"]
            ),
        )
        for d in designs
        for i in range(n)
    ]
    todo = [t for t in todo if t[2]]
    if report_only:
        todo = []
    print(f"{len(todo)} replicates to run or complete ({len(rows)} cached)", flush=True)
    start = time.perf_counter()

    def keep(position, row):  # each row stored as it comes: an interrupted run resumes
        key = f"{row['design']}/{row['index']}"
        if key in rows:  # methods added to a cached row
            for field in ("intervals", "seconds", "errors"):
                row[field] = {**rows[key][field], **row[field]}
        rows[key] = row
        stored = {"settings": _settings(quick), "rows": rows}
        atomic_write_text(_cache_path(out_dir, quick), json.dumps(stored))
        got = row["intervals"]
        hits = {m: "-" if v is None else int(ic.covers(v).sum()) for m, v in got.items()}
        print(
            f"{row['design']} {row['index']:3d}: covers (of 6) "
            + ", ".join(f"{m} {h}" for m, h in hits.items())
            + f" ({sum(row['seconds'].values()):.1f} s; {position + 1}/{len(todo)} done, "
            f"{time.perf_counter() - start:.0f} s)",
            flush=True,
        )

    _ship_by_value()
    task = functools.partial(run_replicate, sampler=QUICK_SAMPLER if quick else SAMPLER)
    map_tasks(task, todo, workers=workers, progress=False, on_result=keep)
    return write_report(out_dir, rows, n, quick, workers)


def _ship_by_value():
    """Let Dask workers run this study's functions without importing it (a worker on
    another machine need not have the studies)."""
    import cloudpickle

    for name in (__name__, ic.__name__):
        module = sys.modules.get(name)
        if name != "__main__" and module is not None:
            cloudpickle.register_pickle_by_value(module)


def other_mode(row, method="sampler"):
    """Whether the method's interval sits in another mode of the posterior than the truth's.

    E1, E2 and G12 are fixed by the frequencies to about 1 %: an interval whose centre is
    more than ``MODE_MISS`` (10 %, some ten deviations) from the truth in any of them lies
    around another mode (with the frequencies paired by order, a plate of other E1 and E2
    fits them too: a prior mean drawn ~3 sd off leads the search from it there).
    """
    interval = row["intervals"][method]
    if interval is None:
        return False
    centre = np.mean(interval, axis=0) / ic.E_TRUE - 1
    return bool(np.any(np.abs(centre[[0, 1, 3]]) > MODE_MISS))


def log_posterior_gap(row, method="sampler"):
    """Log posterior at the truth minus at the method's interval centre (nats).

    Positive: the truth's mode is the higher one, so the interval sits around a lesser,
    local mode that the search from the prior mean found first.
    """
    case, _ = draw(row["design"], row["index"])
    problem = GaussianProblem.from_case(case, _model(), inputs="exact")
    centre = np.mean(row["intervals"][method], axis=0)
    at = [
        problem.log_posterior(laminate.stiffness_from_engineering(e)) for e in (ic.E_TRUE, centre)
    ]
    return float(at[0] - at[1])


def coverage(rows, design, method, skip_other_mode=False):
    """``ic.summary`` of one design and method: (n used, n failed, share (6,), Wilson (2, 6)).

    With `skip_other_mode`, the replicates where :func:`other_mode` holds for the sampler are
    left out (neither used nor failed).
    """
    rows = [
        r
        for r in rows
        if r["design"] == design
        and method in r["intervals"]
        and not (skip_other_mode and other_mode(r))
    ]
    covering = [
        None if r["intervals"][method] is None else ic.covers(r["intervals"][method]) for r in rows
    ]
    return ic.summary(covering)


def write_report(out_dir, rows, n, quick, workers):
    """Write the Markdown report and the figure from the rows; return the report's path."""
    rows = sorted(rows.values(), key=lambda r: (DESIGNS.index(r["design"]), r["index"]))
    designs = [d for d in DESIGNS if any(r["design"] == d for r in rows)]
    command = "python -m studies.posterior_coverage" + (" --quick" if quick else "")
    if designs and designs != ["drawn"]:
        command += " --design " + ("both" if len(designs) == 2 else designs[0])
    out_dir = pathlib.Path(out_dir)
    text = report(rows, designs, n, command, workers)
    path = out_dir / REPORT
    atomic_write_text(path, text)
    if designs:
        plot(rows, designs, out_dir / FIGURE)
    return path


def _table(rows, design):
    head = ["method", "replicates (failed)", "band at 0.94", *ENGINEERING_KEYS]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for method in (*METHODS, "sampler+"):
        used, failed, p, wilson = coverage(rows, design, method.rstrip("+"), method[-1] == "+")
        label = LABELS.get(method, method)
        if used == 0:
            out.append(f"| {label} | 0 ({failed}) | - |" + " - |" * 6)
            continue
        lo, hi = ic.nominal_band(used)
        cells = [label, f"{used} ({failed})", f"{lo:.3f} to {hi:.3f}"]
        cells += [f"{p[j]:.3f} ({wilson[0, j]:.2f}-{wilson[1, j]:.2f})" for j in range(6)]
        out.append("| " + " | ".join(cells) + " |")
    return out


def _reading(rows, design):
    """One paragraph per design: where the target is met and where the intervals fall short."""
    out = []
    used, _, p, wilson = coverage(rows, design, "sampler")
    if used:
        inside = [
            k for k, x in zip(ENGINEERING_KEYS, p, strict=True) if TARGET[0] <= x <= TARGET[1]
        ]
        out.append(
            f"Sampler: {len(inside)} of 6 constants inside the target "
            f"{TARGET[0]:.2f}-{TARGET[1]:.2f}"
            + (
                ""
                if len(inside) == 6
                else " (outside: "
                + ", ".join(
                    f"{k} {x:.3f}"
                    for k, x in zip(ENGINEERING_KEYS, p, strict=True)
                    if k not in inside
                )
                + ")"
            )
            + "."
        )
    mine = [r for r in rows if r["design"] == design]
    missed = [r for r in mine if other_mode(r)]
    missed_b = sum(other_mode(r, "B") for r in mine)
    gaps = ", ".join(f"{r['index']} ({log_posterior_gap(r):+.1f})" for r in missed)
    out.append(
        f"The sampler sat in another mode (E1, E2 or G12 off the truth by more than "
        f"{100 * MODE_MISS:.0f} %) in {len(missed)} of {len(mine)} replicates"
        + (
            f": {gaps}, log posterior at the truth minus at the interval's centre, in nats"
            if missed
            else ""
        )
        + f"; B, started from the same prior mean, in {missed_b}."
    )
    for method in ("B", "MVE", "MVE@1e-3"):
        used, _, p, wilson = coverage(rows, design, method)
        if not used:
            continue
        lo, hi = ic.nominal_band(used)
        short = [
            f"{k} {x:.3f}"
            for k, x, w in zip(ENGINEERING_KEYS, p, wilson[1], strict=True)
            if w < 0.94
        ]
        over = [
            f"{k} {x:.3f}"
            for k, x, w in zip(ENGINEERING_KEYS, p, wilson[0], strict=True)
            if w > 0.94
        ]
        out.append(
            f"{method}: short of 94 % (Wilson interval below it): "
            f"{', '.join(short) or 'none'}; above it: {', '.join(over) or 'none'}."
        )
    return " ".join(out)


def report(rows, designs, n, command, workers):
    """The Markdown report."""
    seconds = {m: [r["seconds"][m] for r in rows if m in r["seconds"]] for m in METHODS}
    median = {m: float(np.median(s)) if s else float("nan") for m, s in seconds.items()}
    errors = [f"{r['design']}/{r['index']} {m}: {e}" for r in rows for m, e in r["errors"].items()]
    out = [
        "# Calibrated posteriors: coverage of the 94 % intervals (issue 14)",
        "",
        f"Made by `{command}` on {datetime.date.today()}, {ic.cpu()}, {os.cpu_count()} cores, "
        f"load {os.getloadavg()[0]:.1f} at writing, {workers} worker(s) of "
        "`bayesplate.batch.map_tasks`; seed "
        f"{SEED}. Median seconds per replicate: sampler {median['sampler']:.1f}, B "
        f"{median['B']:.2f}, MVE {median['MVE']:.2f} (TOL 1e-3: {median['MVE@1e-3']:.2f}) "
        "(one core each, shared with other work). Synthetic plate "
        f"{ic.LENGTH * 1e3:.0f} x {ic.WIDTH * 1e3:.0f} x {ic.THICKNESS * 1e3:.0f} mm, one "
        f"orthotropic ply, density {ic.DENSITY:.0f} kg/m^3, true constants E1 140, E2 10, "
        f"nu12 0.3, G12 5, G13 5, G23 3.5 GPa; {ic.N_FREQ} frequencies from the fitting "
        f"model (mesh {ic.MESH[0]} x {ic.MESH[1]}) with {100 * ic.SIGMA_REL:.1f} % Gaussian "
        "noise, as declared; thickness and density exact. Sampler: emcee on the certified "
        f"fast model, {SAMPLER['n_walkers']} walkers, min ESS {SAMPLER['min_ess']:g}, "
        f"at most {SAMPLER['max_steps']} steps (quick: min ESS {QUICK_SAMPLER['min_ess']:g}), "
        "94 % HDI. B (TOL 1e-6) and MVE (TOL 1e-6, and 1e-3, the command line's default): "
        "estimate +- 1.881 sd. A cell is the share of "
        "replicates whose interval holds the true constant, with its Wilson 95 % interval; "
        '"band at 0.94" is the 95 % band of a binomial share at 0.94 for that number of '
        "replicates (a share outside it is off nominal). Failed: the method did not converge "
        "(sampler: its stopping rule not met within the step cap), left out of its shares.",
        "",
        "Why the prior mean is drawn: the constants are fixed, but a prior centred on them "
        "would hand the weakly informed G13 and G23 their truth. Drawing the prior mean "
        "around the truth from the prior gives (truth - prior mean, data) the joint law of "
        "a truth drawn from the prior, for which a Bayesian 94 % interval covers 94 % of "
        "replicates in expectation in every constant: the target is then a check of the "
        "sampler. `--design fixed` runs one fixed weak prior instead (mean +-10 % off the "
        "truth, sd 50 %), the frequentist reading: there no target applies to the "
        "constants the data barely inform.",
    ]
    titles = {
        "drawn": "Prior mean drawn from the prior around the truth (sd 25 %)",
        "fixed": "One fixed weak prior (mean +-10 % off the truth, sd 50 %)",
    }
    for design in designs:
        got = sum(1 for r in rows if r["design"] == design)
        partial = "" if got >= n else f" (**partial: {got} of {n} replicates finished**)"
        out += [
            "",
            f"## {titles[design]}{partial}",
            "",
            *_table(rows, design),
            "",
            _reading(rows, design),
        ]
    if errors:
        out += ["", "Errors (counted as failed): " + "; ".join(errors)]
    out += [
        "",
        WHY,
        "",
        f"Figure: `{FIGURE}` (coverage per constant, Wilson 95 % intervals, "
        "the binomial band at 0.94 shaded, the target dotted).",
    ]
    return "\n".join(out) + "\n"


WHY = (
    "Where the intervals fall short, and why. (1) Another mode: with the frequencies paired "
    "by order, a plate of lower E1 and higher E2 (E1 about 0.37 and E2 about 2.7 of the "
    "truth) fits the ten frequencies nearly as well (replicate 0: chi-square 9.7 there, 7.0 "
    "at the truth). B, run from a prior mean a few deviations off, converges there; the "
    "sampler starts at B's MAP, inside a certified box of +-6 deviations around it, and "
    "never leaves. The log posterior is higher at the truth (the gaps above), so this is a "
    "mode the search missed, not a property of the posterior: a global start (several "
    "starting points, or the walkers spread over the prior) would be the remedy. It costs "
    "the sampler and B coverage in most constants of those replicates; the row without "
    "them shows the sampler's intervals where it sampled the right mode. (2) MVE has no "
    "prior: the frequencies alone barely fix nu12, G13 and G23. Its iteration wanders "
    "there (at TOL 1e-6 it mostly ends oscillating or at its iteration cap, counted as "
    "failed), and its estimate misses the truth by more than its linearised deviation "
    "says: its intervals are about as wide as B's in nu12 and G13 (narrower in G23) yet "
    "cover far less often. (3) B's linearised interval, on the same posterior as the "
    "sampler's, falls short of it in E1 and nu12 as well as where the posterior spans "
    "tens of percent (nu12, G23): the shortfall is the linearisation's; its cause in E1 "
    "(a MAP-centred interval, the paper's covariance convention) is not isolated here."
)


def plot(rows, designs, path):
    """Coverage per constant with Wilson intervals, one panel per design; written to `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(designs), figsize=(6.5 * len(designs), 4.2), squeeze=False)
    x = np.arange(6)
    for ax, design in zip(axes[0], designs, strict=True):
        for k, (method, marker) in enumerate(zip(METHODS, "osD^", strict=True)):
            used, _, p, wilson = coverage(rows, design, method)
            if used == 0:
                continue
            lo, hi = ic.nominal_band(used)
            if k == 0:
                ax.axhspan(lo, hi, color="0.88", label=f"binomial band at 0.94 (n = {used})")
            label = f"{LABELS.get(method, method)} ({used} replicates)"
            ax.errorbar(
                x + 0.16 * (k - 1.5),
                p,
                yerr=[p - wilson[0], wilson[1] - p],
                fmt=marker,
                capsize=3,
                label=label,
            )
        ax.axhline(ic.NOMINAL, color="k", lw=0.8, ls="--", label="nominal 0.94")
        for level in TARGET:
            ax.axhline(level, color="C3", lw=0.6, ls=":")
        ax.set_xticks(x, list(ENGINEERING_KEYS))
        ax.set_xlabel("constant")
        ax.set_ylabel("share of replicates covering the truth (-)")
        ax.set_title(f"{design} prior; target 0.90-0.97 dotted")
        ax.set_ylim(min(0.5, ax.get_ylim()[0]), 1.02)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    os.replace(tmp, path)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 replicates in this process")
    parser.add_argument("--replicates", type=int, default=None, help="default 200")
    parser.add_argument("--design", choices=("drawn", "fixed", "both"), default="drawn")
    parser.add_argument("--workers", type=int, default=None, help="default 2 (quick: 1)")
    parser.add_argument("--out", default=pathlib.Path(__file__).resolve().parents[1] / "reports")
    parser.add_argument("--report-only", action="store_true", help="from the cached rows")
    args = parser.parse_args()
    chosen = DESIGNS if args.design == "both" else (args.design,)
    print(main(args.out, args.quick, args.replicates, chosen, args.workers, args.report_only))
