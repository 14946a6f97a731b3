"""One material, many plates (issue 42): do the population's 94 % intervals cover the truth?

Each replicate draws a material and its plate-to-plate spread from the hierarchical model's
own priors (the mean constants ``mu`` from the cases' prior, Gaussian in the stiffness
coefficients and restricted to physical laminae; each spread ``tau_k`` half-normal with scale
0.1), then :data:`N_PLATES` single-layer plates of varied size and thickness
(:data:`GEOMETRIES`) with constants ``ln c_p ~ N(ln mu, diag tau^2)``; their first
:data:`MODES` frequencies on a 12 x 6 finite-element mesh, times ``1 + 0.005 N(0, 1)``,
declared ``sigma_rel = 0.005``. Each plate is fitted alone (B on the same mesh: the model is
exact, so the study tests the statistics, not the discretisation), its likelihood linearised
there (:func:`bayesplate.sampling.plate_laplace.linearise`), and the population sampled
(:func:`bayesplate.sampling.sample_population`). Drawing the truth from the prior makes the
check a calibration check: a 94 % interval must cover about 94 % of replicates for every
parameter, the weakly identified ones (whose posterior is close to the prior) included.

Writes ``reports/population_coverage.md``. ``python studies/population_coverage.py
[--quick]`` (``--quick``: one replicate; the full run: 100).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: The cases' prior (mean, sd; SI): wide, as ``studies/many_plates.py``.
PRIOR_MEAN = np.array([140e9, 9e9, 0.30, 3.5e9, 3.5e9, 2.5e9])
PRIOR_SD = np.array([30e9, 2e9, 0.08, 1e9, 1e9, 1e9])
#: (length, width, thickness) of the plates, m: sizes and thicknesses varied.
GEOMETRIES = (
    (0.200, 0.100, 0.0066), (0.250, 0.150, 0.0050), (0.180, 0.120, 0.0080),
    (0.220, 0.110, 0.0060), (0.240, 0.100, 0.0045), (0.190, 0.140, 0.0070),
    (0.260, 0.130, 0.0055), (0.210, 0.090, 0.0075), (0.230, 0.160, 0.0065),
    (0.170, 0.100, 0.0050),
)  # fmt: skip
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
    from bayesplate.model import PlateModel

    length, width, thickness = geometry
    dummy = Measurement(np.linspace(500, 5000, modes), np.full(modes, 5.0))
    case = Case(name=name, source="synthetic (studies/population_coverage.py)",
                plate=Plate(length, width, thickness, 1000.0, (0.0,)), measured=dummy,
                prior=Prior(PRIOR_MEAN, PRIOR_SD), mesh=tuple(mesh),
                reference=np.asarray(constants, dtype=float))  # fmt: skip
    model = PlateModel.from_case(case, mesh=tuple(mesh))
    lam = model.eigenvalues(laminate.stiffness_from_engineering(constants), modes)
    f = np.sort(np.sqrt(lam) / (2 * np.pi) * (1 + noise * rng.standard_normal(modes)))
    return replace(case, measured=Measurement(f, noise * f)), model


def quick_fit(case, model):
    """A plate's own mode on `model` (its case's prior) and its likelihood's Laplace there."""
    from bayesplate.posterior import GaussianProblem
    from bayesplate.sampling.plate_laplace import PlateFit, linearise, plate_mode

    problem = GaussianProblem.from_case(case, model)
    mode = plate_mode(problem)
    return PlateFit(case.name, linearise(problem, mode.b), mode, problem)


def draw_truth(rng, tau_scale=0.1):
    """A material's mean constants (the prior, physical) and spreads (half-normal), SI."""
    from bayesplate import laminate
    from bayesplate.posterior import prior_in_stiffness

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
    from bayesplate.posterior import prior_in_stiffness
    from bayesplate.sampling import sample_population

    rng = np.random.default_rng(seed)
    mu, tau = draw_truth(rng)
    fits, _ = population(rng, mu, tau, n_plates)
    mu_b, V_b = prior_in_stiffness(PRIOR_MEAN, PRIOR_SD)
    r = sample_population(fits, mu_b, V_b, rng=rng, **options)
    covers_mu = (r.hdi[0] <= mu) & (mu <= r.hdi[1])
    covers_tau = (r.tau_hdi[0] <= tau) & (tau <= r.tau_hdi[1])
    return {"seed": seed, "mu": covers_mu, "tau": covers_tau, "rhat": r.rhat_max,
            "ess": r.ess_min, "converged": r.converged, "seconds": r.wall_time,
            "refined": len(r.refined)}  # fmt: skip


def main(out_dir=None, quick=False, replicates=None, seed0=4200):
    """Run the replicates; write the report (full run only); return the summary."""
    from bayesplate.quantities import ENGINEERING_NAMES

    n = replicates or (QUICK_REPLICATES if quick else REPLICATES)
    load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    version = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                             capture_output=True, text=True).stdout.strip()  # fmt: skip
    started = time.perf_counter()
    rows = []
    for k in range(n):  # the report is rewritten after each replicate (the run so far)
        rows.append(replicate(seed0 + k, QUICK_PLATES if quick else N_PLATES, **CHAIN))
        summary = _summary(rows, time.perf_counter() - started)
        if not quick and out_dir is not None:
            _write(Path(out_dir), summary, ENGINEERING_NAMES, (load, version), n)
    return summary


def _summary(rows, elapsed):
    mu = np.array([r["mu"] for r in rows])
    tau = np.array([r["tau"] for r in rows])
    summary = {"mu": mu.mean(axis=0), "tau": tau.mean(axis=0),
               "all_mu": float(mu.mean()), "all_tau": float(tau.mean()),
               "rhat_max": max(r["rhat"] for r in rows), "ess_min": min(r["ess"] for r in rows),
               "converged": sum(r["converged"] for r in rows), "seconds": elapsed,
               "refined": sum(r["refined"] for r in rows)}  # fmt: skip
    return {"n": len(rows), **summary}


def _write(out, s, names, started, planned):
    """The report of the replicates so far; `started` is the (load, code version) at start."""
    from _study_host import cpu

    load, version = started
    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        "# Population coverage: 94 % intervals of the means and the spreads",
        "",
        f"{when}, {cpu()}, load average at start {load}, code {version}; {s['n']} of "
        f"{planned} seeded replicates done (seeds 4200-{4199 + s['n']}), {s['seconds']:.0f} s "
        "in all (`python studies/population_coverage.py`; chains: "
        f"min_ess {CHAIN['min_ess']:g}, R-hat < {CHAIN['max_rhat']:g}, {CHAIN['n_walkers']} "
        f"walkers, at most {CHAIN['max_steps']} steps).",
        "",
        f"Each replicate: a material drawn from the prior, {N_PLATES} plates of varied size "
        f"and thickness, {MODES} frequencies on a {MESH[0]} x {MESH[1]} mesh with "
        f"{NOISE * 100:g} % noise; the plates fitted alone, their likelihoods' Laplace in "
        "ln c, the population (ln mu, ln tau) sampled with emcee (module docstring).",
        "",
        "| constant | mean mu covered | spread tau covered |",
        "|---|---|---|",
    ]
    for k, name in enumerate(names):
        lines.append(f"| {name} | {s['mu'][k] * 100:.0f} % | {s['tau'][k] * 100:.0f} % |")
    lines += [
        f"| all | {s['all_mu'] * 100:.1f} % | {s['all_tau'] * 100:.1f} % |",
        "",
        f"Target 94 %, accepted 90-97 % (pooled over constants). Chains: {s['converged']} of "
        f"{s['n']} met the stopping rule; largest R-hat {s['rhat_max']:.4f}, smallest bulk "
        f"ESS {s['ess_min']:.0f}; {s['refined']} plate fits linearised again.",
    ]
    out.mkdir(parents=True, exist_ok=True)
    (out / "population_coverage.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    print(main(ROOT / "reports", quick="--quick" in sys.argv[1:]))
