"""One material, many plates (issue 42): do the population's 94 % intervals cover the truth?

Each replicate draws a material and its plate-to-plate spread from the hierarchical model's
own priors (the mean constants ``mu`` from the cases' prior, Gaussian in the stiffness
coefficients and restricted to physical laminae; each spread ``tau_k`` half-normal with scale
0.1), then :data:`N_PLATES` single-layer plates of varied size and thickness
(:data:`GEOMETRIES`) with constants ``ln c_p ~ N(ln mu, diag tau^2)``; their first
:data:`MODES` frequencies on a 12 x 6 finite-element mesh, times ``1 + 0.005 N(0, 1)``,
declared ``sigma_rel = 0.005``, each frequency with its mode (as a test that identifies its
modes by their shapes gives them: noise may swap a close pair). Each plate is fitted alone
(B on the same mesh: the model is exact, so the study tests the statistics, not the
discretisation), its likelihood linearised
there (:func:`bayesplate.sampling.plate_laplace.linearise`), and the population sampled
(:func:`bayesplate.sampling.sample_population`). Drawing the truth from the prior makes the
check a calibration check: a 94 % interval must cover about 94 % of replicates for every
parameter, the weakly identified ones (whose posterior is close to the prior) included.

Writes ``reports/population_coverage.md``. ``python -m studies.population_coverage
[--quick] [--replicates N] [--plates P] [--workers W]`` (``--quick``: one replicate; the
full run: 100 on two worker processes). Each replicate's row is appended, as it ends, to
``.bayesplate-cache/population_coverage/<code version>-p<plates>.jsonl``: a stopped run
resumes where it stopped, and rows of other code are never mixed in. With ``--plates P``
other than 10 (larger populations), the report is ``reports/population_coverage_pP.md``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: The cases' prior (mean, sd; SI): wide, as ``studies/many_plates.py``.
PRIOR_MEAN = np.array([140e9, 9e9, 0.30, 3.5e9, 3.5e9, 2.5e9])
PRIOR_SD = np.array([30e9, 2e9, 0.08, 1e9, 1e9, 1e9])
#: (length, width, thickness) of the plates, m: sizes and thicknesses varied.
GEOMETRIES = (
    (0.200, 0.100, 0.0066),
    (0.250, 0.150, 0.0050),
    (0.180, 0.120, 0.0080),
    (0.220, 0.110, 0.0060),
    (0.240, 0.100, 0.0045),
    (0.190, 0.140, 0.0070),
    (0.260, 0.130, 0.0055),
    (0.210, 0.090, 0.0075),
    (0.230, 0.160, 0.0065),
    (0.170, 0.100, 0.0050),
)  # fmt: skip (a table: three plates a row)
N_PLATES, MODES, NOISE, MESH = 10, 8, 0.005, (12, 6)
REPLICATES, QUICK_REPLICATES, QUICK_PLATES = 100, 1, 10
#: The chains' stopping rule in the study (the issue's ESS >= 400 and R-hat < 1.01).
#: 24 walkers (twice the dimension): R-hat with walkers as chains needs each walker's chain
#: long against its autocorrelation time, so fewer walkers reach it in fewer evaluations.
CHAIN = {"min_ess": 400.0, "max_rhat": 1.01, "n_walkers": 24, "max_steps": 8000}


def synthetic_plate(name, geometry, constants, rng, *, mesh=MESH, modes=MODES, noise=NOISE):
    """A case and its model: a single-layer plate's first `modes` frequencies at `constants`.

    Parameters
    ----------
    name : str
    geometry : tuple of float
        Length, width, thickness, m.
    constants : numpy.ndarray, shape (6,)
        The plate's engineering constants, SI.
    rng : numpy.random.Generator
        The noise.

    Returns
    -------
    case : bayesplate.io.Case
    model : PlateModel
    """
    from dataclasses import replace

    from bayesplate import laminate
    from bayesplate.io.case import Case, Measurement, Plate, Prior
    from bayesplate.plate.model import PlateModel

    length, width, thickness = geometry
    dummy = Measurement(np.linspace(500, 5000, modes), np.full(modes, 5.0))
    case = Case(
        name=name,
        source="synthetic (studies/population_coverage.py)",
        plate=Plate(length, width, thickness, 1000.0, (0.0,)),
        measured=dummy,
        prior=Prior(PRIOR_MEAN, PRIOR_SD),
        mesh=tuple(mesh),
        reference=np.asarray(constants, dtype=float),
    )
    model = PlateModel.from_case(case, mesh=tuple(mesh))
    lam = model.eigenvalues(laminate.stiffness_from_engineering(constants), modes)
    f = np.sqrt(lam) / (2 * np.pi) * (1 + noise * rng.standard_normal(modes))
    order = np.argsort(f)  # each frequency keeps its mode: noise may swap a close pair
    measured = Measurement(f[order], noise * f[order], mode=order + 1)
    return replace(case, measured=measured), model


def quick_fit(case, model):
    """A plate's own mode on `model` (its case's prior) and its likelihood's Laplace there.

    The mode of the best of several starts (the prior mean and
    :func:`bayesplate.estimators.starts.start_points` around it, by log posterior): from the
    prior mean alone, about one plate in ten settled in a wrong basin (E1 22 % low, E2 23 %
    high, chi-square 13-22 on 8 frequencies) that no later step leaves.
    """
    from bayesplate import laminate
    from bayesplate.estimators.starts import start_points
    from bayesplate.likelihood.posterior import GaussianProblem
    from bayesplate.sampling.plate_laplace import PlateFit, linearise, plate_mode

    problem = GaussianProblem.from_case(case, model)
    starts = [None] + [laminate.stiffness_from_engineering(e) for e in start_points(PRIOR_MEAN)]
    best, best_value = None, -np.inf
    for start in starts:
        mode = plate_mode(problem, start)
        value = problem.log_likelihood(mode.b) + problem.log_prior(mode.b)
        if np.isfinite(value) and value > best_value:
            best, best_value = mode, value
    return PlateFit(case.name, linearise(problem, best.b), best, problem)


def draw_truth(rng, tau_scale=0.1):
    """A material's mean constants (the prior, physical) and spreads (half-normal), SI."""
    from bayesplate import laminate
    from bayesplate.likelihood.posterior import prior_in_stiffness

    mu_b, V_b = prior_in_stiffness(PRIOR_MEAN, PRIOR_SD)
    while True:
        b = rng.multivariate_normal(mu_b, V_b)
        if laminate.is_physical(b):
            return laminate.engineering_from_stiffness(b), np.abs(tau_scale * rng.normal(size=6))


def population(rng, mu, tau, n_plates=N_PLATES, offsets=None):
    """Fitted plates (PlateFit) of one population and their true constants (P, 6), SI.

    `offsets` (P, 6) multiply plates' constants (e.g. an outlier 15 % low on E1).
    """
    from bayesplate import laminate

    fits, truths = [], []
    for p in range(n_plates):
        while True:
            c = np.exp(np.log(mu) + tau * rng.standard_normal(6))
            c = c if offsets is None else c * offsets[p]
            if laminate.is_physical(laminate.stiffness_from_engineering(c)):
                break
        case, model = synthetic_plate(f"P{p + 1}", GEOMETRIES[p % len(GEOMETRIES)], c, rng)
        fits.append(quick_fit(case, model))
        truths.append(c)
    return fits, np.array(truths)


def replicate(seed, n_plates=N_PLATES, **options):
    """One replicate: whether each 94 % interval covers the truth, and the run's numbers."""
    from threadpoolctl import threadpool_limits

    from bayesplate.likelihood.posterior import prior_in_stiffness
    from bayesplate.sampling import sample_population

    rng = np.random.default_rng(seed)
    with threadpool_limits(1):  # one replicate a core: the workers share the machine
        mu, tau = draw_truth(rng)
        fits, _ = population(rng, mu, tau, n_plates)
        mu_b, V_b = prior_in_stiffness(PRIOR_MEAN, PRIOR_SD)
        r = sample_population(fits, mu_b, V_b, rng=rng, **options)
    return {
        "seed": seed,
        "mu": ((r.hdi[0] <= mu) & (mu <= r.hdi[1])).tolist(),
        "tau": ((r.tau_hdi[0] <= tau) & (tau <= r.tau_hdi[1])).tolist(),
        "rhat": r.rhat_max,
        "ess": r.ess_min,
        "converged": r.converged,
        "seconds": r.wall_time,
        "refined": len(r.refined),
    }


def _safe_replicate(seed, n_plates):
    """:func:`replicate`, or the failure as a row (counted as covering nothing)."""
    try:
        return replicate(seed, n_plates, **CHAIN)
    except Exception as exc:  # noqa: BLE001 (a failed replicate is a result, not a crash)
        return {"seed": seed, "error": f"{type(exc).__name__}: {exc}"}


def cache_path(n_plates, version=None):
    """The replicates' rows of one code version and population size (JSON lines)."""
    from studies._study_host import code_version

    version = version or code_version()
    return ROOT / ".bayesplate-cache" / "population_coverage" / f"{version}-p{n_plates}.jsonl"


def cached_rows(path):
    """Rows of `path` by seed (a line cut short by a kill is skipped)."""
    from studies._study_host import jsonl_rows

    return {row["seed"]: row for row in jsonl_rows(path)}


def run(seeds, n_plates, workers, path):
    """Run the seeds not yet in `path` on `workers` processes, appending each row as it ends."""
    import json
    from concurrent.futures import ProcessPoolExecutor, as_completed

    done = cached_rows(path)
    todo = [s for s in seeds if s not in done]
    path.parent.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max_workers=workers) as pool, path.open("a") as out:
        futures = [pool.submit(_safe_replicate, s, n_plates) for s in todo]
        for k, future in enumerate(as_completed(futures), 1):
            row = future.result()
            out.write(json.dumps(row) + "\n")
            out.flush()
            done[row["seed"]] = row
            print(f"replicate {k}/{len(todo)} (seed {row['seed']}) done", file=sys.stderr)
    return [done[s] for s in seeds]


def main(out_dir=None, quick=False, replicates=None, seed0=4200, workers=2, n_plates=None):
    """Run the replicates (resuming a run of the same code); write the report; return it.

    ``quick``: one replicate in this process, nothing cached or written.
    """
    from studies._study_host import code_version, utc_now

    n_plates = n_plates or (QUICK_PLATES if quick else N_PLATES)
    n = replicates or (QUICK_REPLICATES if quick else REPLICATES)
    seeds = list(range(seed0, seed0 + n))
    if quick:
        return _summary([_safe_replicate(s, n_plates) for s in seeds])
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    version = code_version()  # the rows' code: commits made while it runs do not count
    started = time.perf_counter()
    rows = run(seeds, n_plates, workers, cache_path(n_plates, version))
    summary = _summary(rows)
    if out_dir is not None:
        run_info = {
            "when": utc_now(),
            "load": load,
            "version": version,
            "wall": time.perf_counter() - started,
            "workers": workers,
        }
        _write(Path(out_dir), summary, n_plates, run_info)
    return summary


def _summary(rows):
    ok = [r for r in rows if "error" not in r]
    mu = np.array([r["mu"] for r in ok] + [[False] * 6] * (len(rows) - len(ok)))
    tau = np.array([r["tau"] for r in ok] + [[False] * 6] * (len(rows) - len(ok)))
    return {
        "n": len(rows),
        "failed": [(r["seed"], r["error"]) for r in rows if "error" in r],
        "mu": mu.mean(axis=0),
        "tau": tau.mean(axis=0),
        "all_mu": float(mu.mean()),
        "all_tau": float(tau.mean()),
        "rhat_max": max((r["rhat"] for r in ok), default=np.nan),
        "ess_min": min((r["ess"] for r in ok), default=np.nan),
        "converged": sum(r["converged"] for r in ok),
        "seconds": [r["seconds"] for r in ok],
        "refined": sum(r["refined"] for r in ok),
        "seeds": (rows[0]["seed"], rows[-1]["seed"]) if rows else (0, -1),
    }


def _band(n, p=0.94, z=2.0):
    """The coverage a calibrated 94 % interval gives over `n` replicates, +- `z` sd."""
    half = z * np.sqrt(p * (1 - p) / n)
    return 100 * (p - half), 100 * (p + half)


def _write(out, s, n_plates, info):
    """The report: the current table alone, with its code version, date, machine and load."""
    from bayesplate.quantities import ENGINEERING_NAMES
    from studies._study_host import cpu

    lo, hi = _band(6 * s["n"])
    secs = np.array(s["seconds"])
    lines = [
        f"# Population coverage ({n_plates} plates): 94 % intervals of the means and spreads",
        "",
        f"{info['when']}, {cpu()}, code {info['version']}, load average at start "
        f"{info['load']}; {s['n']} seeded replicates (seeds {s['seeds'][0]}-{s['seeds'][1]}) of "
        f"{n_plates} plates, {info['workers']} worker processes (`python -m "
        "studies.population_coverage`; rows cached by code version, so a stopped run "
        "resumes). Chains: "
        f"min_ess {CHAIN['min_ess']:g}, R-hat < {CHAIN['max_rhat']:g}, {CHAIN['n_walkers']} "
        f"walkers, at most {CHAIN['max_steps']} steps. One replicate: median "
        f"{np.median(secs):.0f} s ({secs.min():.0f}-{secs.max():.0f} s) of sampling.",
        "",
        f"Each replicate: a material drawn from the prior, {n_plates} plates of varied size "
        f"and thickness, {MODES} frequencies on a {MESH[0]} x {MESH[1]} mesh with "
        f"{NOISE * 100:g} % noise, each with its mode; the plates fitted alone, their "
        "likelihoods Gaussian in the in-plane stiffness and shear compliance, the population "
        "(ln mu, ln tau) sampled with emcee (module docstring).",
        "",
        "| constant | mean mu covered | spread tau covered |",
        "|---|---|---|",
    ]
    for k, name in enumerate(ENGINEERING_NAMES):
        lines.append(f"| {name} | {s['mu'][k] * 100:.0f} % | {s['tau'][k] * 100:.0f} % |")
    lines += [
        f"| all | {s['all_mu'] * 100:.1f} % | {s['all_tau'] * 100:.1f} % |",
        "",
        f"Target 94 %, accepted 90-97 % (pooled over constants). A calibrated interval would "
        f"give {lo:.1f}-{hi:.1f} % pooled over {6 * s['n']} intervals (two binomial sd; the "
        "six constants of a replicate are not independent, so the band is a little wider). "
        f"Chains: {s['converged']} of {s['n'] - len(s['failed'])} met the stopping rule within "
        f"{CHAIN['max_steps']} steps (the others' intervals are counted as they are); "
        f"largest R-hat {s['rhat_max']:.4f}, smallest bulk ESS {s['ess_min']:.0f}; "
        f"{s['refined']} plate fits linearised again.",
    ]
    if s["failed"]:
        lines += ["", "Failed replicates (counted as covering nothing):", ""]
        lines += [f"- seed {seed}: {error}" for seed, error in s["failed"]]
    out.mkdir(parents=True, exist_ok=True)
    name = "population_coverage" + ("" if n_plates == N_PLATES else f"_p{n_plates}")
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="one replicate, nothing written")
    parser.add_argument("--replicates", type=int, default=None)
    parser.add_argument("--plates", type=int, default=None, help=f"default {N_PLATES}")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    summary = main(
        ROOT / "reports", args.quick, args.replicates, workers=args.workers, n_plates=args.plates
    )
    print({k: v for k, v in summary.items() if k != "seconds"})
