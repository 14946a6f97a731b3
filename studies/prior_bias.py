"""How much the prior biases B: B, the sampled posterior, MVE and the target, side by side.

Plate 1, test 2 of the paper (initial values of ``bayesplate/data/paper/results.toml``
[plate1.test2], deviations d x initial value; Tables 4 and 10) and the Frederiksen plate
(deviations d x the case's prior mean), at d = 1/3, 1/6 and 1/10. For every run: the B
estimate (the MAP), the posterior mean and 94 % highest-density interval (emcee, the same
Gaussian problem), the MVE estimate and the target (Plate 1: the constants the frequencies
were computed from; Frederiksen: his own two-specimen estimate), and a corner plot of the
posterior with the B and MVE Gaussian ellipses and the target.

Writes ``prior_bias.md`` and ``prior_bias_{plate1,frederiksen}_d{3,6,10}.png`` to
``out_dir``. Run: ``python -m studies.prior_bias [--quick] [--out DIR]`` (quick: Plate 1 at
d = 1/3 only, shorter chains, seconds).
"""

import argparse
import pathlib
import sys
import time
from dataclasses import dataclass

import matplotlib
import numpy as np

from bayesplate.io import atomic_write_text, bundled_case_path, load_case
from bayesplate.likelihood.posterior import GaussianProblem
from bayesplate.matching.pairing import Pairing
from bayesplate.plate.model import PlateModel
from bayesplate.reduced import Box, fast_model
from bayesplate.sampling import posterior_box, prepare, sample
from bayesplate.sampling.setup import FAST_DEFAULTS, PILOT_TOL
from studies._study_host import utc_now

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

matplotlib.use("Agg")  # files only, never a window

REPORT = "prior_bias.md"
FIGURE = "prior_bias_{}_d{}.png"
SEED = 20070461
MIN_ESS = 2000.0
QUICK_MIN_ESS = 500.0
RESULTS = bundled_case_path("plate1").parents[1] / "paper" / "results.toml"
PAPER = tomllib.loads(RESULTS.read_text())
SI = np.array([1e9, 1e9, 1.0, 1e9, 1e9, 1e9])
NAMES = ("E1", "E2", "nu12", "G12", "G13", "G23")
UNITS = ("GPa", "GPa", "-", "GPa", "GPa", "GPa")
DEVIATIONS = {"1/3": 3, "1/6": 6, "1/10": 10}
PILOT_MESH = (25, 25)  # the Frederiksen pilots (its own mesh is 50 x 50)


@dataclass
class Run:
    """One prior: the estimates, the posterior and the paper's numbers."""

    plate: str
    d: str
    prior_mean: np.ndarray
    prior_sd: np.ndarray
    target: np.ndarray
    b: object  # EstimateResult (B at the MAP)
    mve: object  # EstimateResult
    posterior: object  # SamplingResult
    paper_b: object = None  # the paper's B row (case units) or None
    paper_mve: object = None


def _plate1_runs(deviations, min_ess):
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    initial = np.array(PAPER["plate1"]["test2"]["initial"], dtype=float) * SI
    target = np.array(PAPER["plate1"]["target"]["constants"], dtype=float) * SI
    runs = []
    for d in deviations:
        sd = initial / DEVIATIONS[d]
        setup = prepare(case, model=model, rng=SEED, prior_mean=initial, prior_sd=sd)
        runs.append(_run(case, "plate1", d, setup, initial, sd, target, min_ess))
        runs[-1].paper_b = PAPER["plate1"]["test2"]["B"][d]
        runs[-1].paper_mve = PAPER["plate1"]["test2"]["MVE"][d]
    return runs


def _shared_fast_model(case, model, priors):
    """One certified fast model over the union of the posterior boxes of several priors."""
    coarse = PlateModel.from_case(case, mesh=PILOT_MESH)
    pairing = Pairing.from_measurement(case.measured)
    boxes, centres = [], []
    from bayesplate.estimators import run

    for mean, sd in priors:
        problem = GaussianProblem.from_case(case, coarse, pairing, prior_mean=mean, prior_sd=sd)
        pilot = run(problem, "B", tol=PILOT_TOL)
        boxes.append(posterior_box(pilot, problem.mu_b, problem.V_b))
        centres.append(pilot.b)
    box = Box(np.min([b.lower for b in boxes], axis=0), np.max([b.upper for b in boxes], axis=0))
    return fast_model(
        model,
        np.mean(centres, axis=0),
        box,
        pairing.n_modes() - pairing.extra,
        rng=SEED,
        **FAST_DEFAULTS,
    )


def _frederiksen_runs(deviations, min_ess):
    case = load_case(bundled_case_path("frederiksen_t300"))
    model = PlateModel.from_case(case)
    mean = np.asarray(case.prior.mean, dtype=float)
    priors = [(mean, mean / DEVIATIONS[d]) for d in deviations]
    fast = _shared_fast_model(case, model, priors)
    runs = []
    for d, (m, sd) in zip(deviations, priors, strict=True):
        setup = prepare(case, model=model, fast=fast, prior_mean=m, prior_sd=sd)
        runs.append(_run(case, "frederiksen", d, setup, m, sd, case.reference, min_ess))
    return runs, fast


def _run(case, plate, d, setup, mean, sd, target, min_ess):
    posterior = sample(case, rng=SEED, setup=setup, progress=False, min_ess=min_ess)
    mve = setup.run_estimator("MVE")
    return Run(plate, d, mean, sd, np.asarray(target, dtype=float), setup.estimate, mve, posterior)


def compute(quick=False):
    """Every run (quick: Plate 1 at d = 1/3 with shorter chains)."""
    started = time.perf_counter()
    min_ess = QUICK_MIN_ESS if quick else MIN_ESS
    runs = _plate1_runs(["1/3"] if quick else list(DEVIATIONS), min_ess)
    fast = None
    if not quick:
        more, fast = _frederiksen_runs(list(DEVIATIONS), min_ess)
        runs += more
    return {"runs": runs, "fast": fast, "seconds": time.perf_counter() - started, "quick": quick}


# ----------------------------------------------------------------------------- report


def _fmt(value, i):
    v = value / SI[i]
    return f"{v:.3f}" if i == 2 else f"{v:#.4g}"


def _rel(value, target, i):
    return f"{100 * (value - target[i]) / target[i]:+.1f}"


def _table(head, rows):
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    return lines + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def _run_lines(r):
    p = r.posterior
    rows = []
    for i, (n, u) in enumerate(zip(NAMES, UNITS, strict=True)):
        inside = p.hdi[0, i] <= r.target[i] <= p.hdi[1, i]
        paper = "" if not isinstance(r.paper_b, list) else f"{r.paper_b[i]:#.4g}"
        paper_mve = "" if not isinstance(r.paper_mve, list) else f"{r.paper_mve[i]:#.4g}"
        rows.append(
            [
                f"{n} ({u})",
                _fmt(r.prior_mean[i], i),
                _fmt(r.target[i], i),
                f"{_fmt(r.b.constants[i], i)} ({_rel(r.b.constants[i], r.target, i)} %)",
                f"{_fmt(p.mean[i], i)} ({_rel(p.mean[i], r.target, i)} %)",
                f"{_fmt(p.hdi[0, i], i)} to {_fmt(p.hdi[1, i], i)}" + ("" if inside else " **"),
                f"{_fmt(r.mve.constants[i], i)} ({_rel(r.mve.constants[i], r.target, i)} %)",
                paper,
                paper_mve,
            ]
        )
    head = [
        "constant",
        "initial",
        "target",
        "B (MAP)",
        "posterior mean",
        "94 % HDI",
        "MVE",
        "paper B",
        "paper MVE",
    ]
    if r.paper_b is None:
        head, rows = head[:-2], [row[:-2] for row in rows]
    title = "Plate 1, test 2" if r.plate == "plate1" else "Frederiksen plate"
    return [
        f"### {title}, d = {r.d}",
        "",
        f"Posterior: {p.n_walkers} walkers x {p.n_steps} steps ({p.n_burn} discarded), ESS >= "
        f"{p.ess_min:.0f}, R-hat <= {p.rhat_max:.3f}, {p.n_full} full solves while sampling; "
        f"{p.message}. B: {r.b.message}. MVE: {r.mve.message}.",
        "",
        *_table(head, rows),
        "",
        f"![corner plot]({FIGURE.format(r.plate, DEVIATIONS[r.d])})",
        "",
    ]


def _worst(values, target):
    """The largest relative distance from the target and its constant."""
    rel = np.abs(values - target) / np.abs(target)
    i = int(np.argmax(rel))
    return f"{100 * rel[i]:.1f} % ({NAMES[i]})"


def _summary_rows(runs):
    rows = []
    for r in runs:
        p = r.posterior

        def worst(values, target=r.target):
            return _worst(values, target)

        inside = np.sum((p.hdi[0] <= r.target) & (r.target <= p.hdi[1]))
        title = "Plate 1 test 2" if r.plate == "plate1" else "Frederiksen"
        rows.append(
            [
                f"{title}, d = {r.d}",
                worst(r.b.constants),
                worst(p.mean),
                f"{inside} of 6",
                worst(r.mve.constants),
            ]
        )
    return rows


def write_report(results, out_dir):
    """``prior_bias.md``."""
    runs = results["runs"]
    command = "python -m studies.prior_bias" + (" --quick" if results["quick"] else "")
    date = utc_now()
    fast = results["fast"]
    lines = [
        f"Made by `{command}` (seed {SEED}) on {date}, {results['seconds']:.0f} s.",
        "",
        "# Prior bias of B: the sampled posterior beside B, MVE and the target",
        "",
        "Same Gaussian problem for every column (the paper's conventions: V_Y = diag(dlambda^2), "
        "V_b = diag(dC^2)); B is its MAP, the posterior is sampled with emcee on a certified "
        "reduced model (bayesplate.sampling), MVE iterates eq. 12 to TOL 1e-3. Relative "
        "differences from the target in brackets; ** marks a target outside the 94 % "
        "highest-density interval.",
        "",
        "## Summary: largest relative distance from the target",
        "",
        *_table(
            ["run", "B (MAP)", "posterior mean", "target inside the 94 % HDI", "MVE"],
            _summary_rows(runs),
        ),
        "",
        *_reading(runs),
        "",
    ]
    if fast is not None:
        lines += [
            f"Frederiksen runs share one fast model over the union of their posterior "
            f"boxes: {fast.certificate}.",
            "",
        ]
    lines += ["## Runs", ""]
    for r in runs:
        lines += _run_lines(r)
    atomic_write_text(pathlib.Path(out_dir) / REPORT, "\n".join(lines))


def _reading(runs):
    """Sentences computed from the numbers."""
    lines = []
    for r in runs:
        p = r.posterior
        outside = [NAMES[i] for i in range(6) if not p.hdi[0, i] <= r.target[i] <= p.hdi[1, i]]
        closer = np.abs(p.mean - r.target) < np.abs(r.b.constants - r.target)
        title = "Plate 1 test 2" if r.plate == "plate1" else "Frederiksen"
        lines.append(
            f"- {title}, d = {r.d}: the target lies outside the 94 % HDI for "
            f"{', '.join(outside) or 'none'}; the posterior mean is closer to the target "
            f"than B for {', '.join(n for n, c in zip(NAMES, closer, strict=True) if c) or 'none'}."
        )
    return lines


def plot(results):
    """``{file name: Figure}``: a corner plot per run."""
    from bayesplate.plots import sampling_figures

    figs = {}
    for r in results["runs"]:
        base = "initial values" if r.plate == "plate1" else "case's prior mean"
        title = ("Plate 1, test 2" if r.plate == "plate1" else "Frederiksen plate") + (
            f"\nprior deviations d = {r.d} of the {base}"
        )
        label = "target" if r.plate == "plate1" else "target (Frederiksen's constants)"
        f = sampling_figures(
            r.posterior, {"B": r.b, "MVE": r.mve}, r.target, title=title, reference_label=label
        )
        figs[FIGURE.format(r.plate, DEVIATIONS[r.d])] = f["corner"]
    return figs


def main(out_dir, quick=False):
    """Compute, write the report and the figures; return the results dict."""
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = compute(quick=quick)
    write_report(results, out_dir)
    for name, fig in plot(results).items():
        tmp = out_dir / f".{name}.tmp.png"
        fig.savefig(tmp, dpi=100, bbox_inches="tight")
        tmp.replace(out_dir / name)
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="Plate 1 at d = 1/3 only")
    parser.add_argument("--out", default=pathlib.Path(__file__).parents[1] / "reports")
    args = parser.parse_args()
    main(args.out, quick=args.quick)
