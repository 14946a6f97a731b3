"""Coverage of the 94 % intervals when the plate's thickness and density are off (issue 17).

Seeded synthetic plates: a single-ply orthotropic plate 300 x 200 x 4 mm (a/h = 75), density
1600 kg/m^3, true constants ``E_TRUE``, 10 frequencies with a declared 0.5 % deviation. The case
declares thickness sd 2 % and density sd 1 %. Each replicate draws

- the plate's true thickness and density from the declared deviations (normal, so the errors
  are inside the declared sd in the sense the case states it: 68 % within one sd);
- the prior mean from the prior (sd 25 % of each true constant), so that the truth is a draw
  from the prior and a Bayesian interval should cover it at its nominal rate in every constant,
  those the data barely inform (G13, G23) included;
- the frequencies from the model at the true geometry and density, with the declared noise.

It is then fitted with the nominal thickness and density (what the lab wrote down), twice:
``inputs="exact"`` (today's treatment) and ``inputs="marginal"`` (the deviations marginalised,
``V_Y + J_p Sigma_p J_p^T``). B's linearised interval is the estimate +- 1.881 sd (94 % of a
normal); a replicate covers a constant when the interval holds the true value. The share of
covering replicates has a binomial deviation ``sqrt(p (1 - p) / n)``; its 95 % band around
0.94 is printed with each row (Wilson interval of the observed share beside it).

The sampler (emcee on the certified fast model, :func:`bayesplate.sampling.sample`, 94 % HDI)
runs on the first replicates for as long as ``--sampler-minutes`` allows (both treatments per
replicate); the report says how many.

Writes ``input_coverage.md`` to ``out_dir``. Run:
``python studies/input_coverage.py [--quick] [--replicates N] [--sampler-minutes M] [--out DIR]``
(quick: 6 replicates, no sampler).
"""

# no `from __future__ import annotations`: loaded by tests with spec_from_file_location
import argparse
import dataclasses
import datetime
import logging
import os
import pathlib
import sys
import time
import warnings

import numpy as np

from bayesplate import laminate
from bayesplate.estimators import run as run_estimator
from bayesplate.io import Case, Measurement, Plate, Prior, atomic_write_text
from bayesplate.model import PlateModel
from bayesplate.posterior import GaussianProblem
from bayesplate.quantities import ENGINEERING_KEYS, hz_from_eigenvalue

_HERE = pathlib.Path(__file__).resolve().parent
if str(_HERE) not in sys.path:
    sys.path.insert(0, str(_HERE))
from _study_host import cpu  # noqa: E402  (this folder's helper, not a package)

REPORT = "input_coverage.md"
SEED = 20261125
E_TRUE = np.array([140e9, 10e9, 0.3, 5e9, 5e9, 3.5e9])  # E1, E2, nu12, G12, G13, G23 (SI)
LENGTH, WIDTH, THICKNESS, DENSITY = 0.3, 0.2, 0.004, 1600.0  # m, kg/m^3
SD_H_REL, SD_RHO_REL = 0.02, 0.01  # declared input deviations, relative
SIGMA_REL = 0.005  # declared (and drawn) frequency deviation, relative
PRIOR_REL = 0.25  # prior sd, relative to the true constants
N_FREQ = 10
MESH = (12, 8)
Z94 = 1.8807936081512509  # normal quantile of 0.97: a two-sided 94 % interval
NOMINAL = 0.94
TREATMENTS = ("marginal", "exact")


def nominal_case(frequency_Hz, prior_mean, input_sd=True, prior_sd=None):
    """The case the lab writes: nominal geometry and density, with their deviations or not.

    `prior_sd` (SI, shape (6,)) defaults to ``PRIOR_REL * E_TRUE``.
    """
    sd = {"thickness_sd": SD_H_REL * THICKNESS, "density_sd": SD_RHO_REL * DENSITY}
    plate = Plate(LENGTH, WIDTH, THICKNESS, DENSITY, (0,), **(sd if input_sd else {}))
    measured = Measurement(frequency_Hz, SIGMA_REL * np.asarray(frequency_Hz))
    prior = Prior(prior_mean, PRIOR_REL * E_TRUE if prior_sd is None else prior_sd)
    return Case("coverage plate", "studies/input_coverage.py", plate, measured, prior, MESH)


def draw(rng, input_errors=True, prior_mean=None, prior_sd=None):
    """One replicate's truth and data: (case as written, true thickness, true density).

    With ``input_errors=False`` the plate is the nominal one and the case declares no input
    deviation (studies/posterior_coverage.py); a given `prior_mean` (SI, shape (6,)) is used
    as is instead of a draw from the prior around ``E_TRUE``.
    """
    h, rho = THICKNESS, DENSITY
    if input_errors:
        h = THICKNESS * (1 + SD_H_REL * rng.standard_normal())
        rho = DENSITY * (1 + SD_RHO_REL * rng.standard_normal())
    if prior_mean is None:
        prior_mean = E_TRUE + PRIOR_REL * E_TRUE * rng.standard_normal(6)
    true_plate = Plate(LENGTH, WIDTH, h, rho, (0,))
    written = nominal_case(np.ones(N_FREQ), prior_mean, input_errors, prior_sd)
    true_case = dataclasses.replace(written, plate=true_plate)
    lam = (
        PlateModel.from_case(true_case, mesh=MESH)
        .solve(laminate.stiffness_from_engineering(E_TRUE), N_FREQ)
        .eigenvalues[:N_FREQ]
    )
    f = hz_from_eigenvalue(lam) * (1 + SIGMA_REL * rng.standard_normal(N_FREQ))
    return nominal_case(np.sort(f), prior_mean, input_errors, prior_sd), h, rho


def fit_b(case, model, inputs, method="B", tol=1e-6):
    """B or MVE (TOL `tol`); (lower, upper) of the 94 % linearised interval, or None."""
    problem = GaussianProblem.from_case(case, model, inputs=inputs)
    result = run_estimator(problem, method, tol=tol)
    if not result.converged or not np.all(np.isfinite(result.sd)):
        return None
    return result.constants - Z94 * result.sd, result.constants + Z94 * result.sd


def fit_sampler(case, model, inputs, rng, **settings):
    """The sampler's 94 % HDI (shape (2, 6)), or None when its stopping rule was not met.

    `settings`: keywords of :func:`bayesplate.sampling.sample` (default ``min_ess=400,
    max_steps=3000``).
    """
    from bayesplate.sampling import sample

    settings = {"min_ess": 400, "max_steps": 3000, **settings}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # full-model fallbacks are counted in the result
        # the replicates are every low mode, sorted: pairing by order (named, issue 16)
        result = sample(case, rng=rng, model=model, inputs=inputs, progress=False,
                        **{"pairing": "order", **settings})  # fmt: skip
    return (result.hdi[0], result.hdi[1]) if result.converged else None


def run(n_replicates=200, sampler_minutes=10.0, seed=SEED):
    """Coverage records: ``{(method, treatment): list of (6,) bool or None}``."""
    rng = np.random.default_rng(seed)
    streams = rng.spawn(n_replicates)
    model = PlateModel.from_case(nominal_case(np.ones(N_FREQ), E_TRUE), mesh=MESH)
    records = {(m, t): [] for m in ("B", "sampler") for t in TREATMENTS}
    draws, cases = [], []
    for stream in streams:
        case, h, rho = draw(stream)
        draws.append((h / THICKNESS - 1, rho / DENSITY - 1))
        cases.append(case)
        for t in TREATMENTS:
            interval = fit_b(case, model, t)
            records[("B", t)].append(None if interval is None else covers(interval))
    started = time.perf_counter()
    for i, case in enumerate(cases):
        if time.perf_counter() - started >= 60 * sampler_minutes:
            break
        for t in TREATMENTS:
            interval = fit_sampler(case, model, t, 1000 + i)
            records[("sampler", t)].append(None if interval is None else covers(interval))
    return records, np.array(draws), time.perf_counter() - started


def covers(interval):
    """(6,) bool: whether the interval ``(lower, upper)`` (SI) holds ``E_TRUE``."""
    lower, upper = interval
    return (lower <= E_TRUE) & (E_TRUE <= upper)


def summary(covering):
    """(n used, n failed, share per constant (6,), Wilson 95 % interval (2, 6))."""
    used = [c for c in covering if c is not None]
    n = len(used)
    if n == 0:
        return 0, len(covering), np.full(6, np.nan), np.full((2, 6), np.nan)
    p = np.mean(used, axis=0)
    z = 1.959963984540054
    centre = (p + z**2 / (2 * n)) / (1 + z**2 / n)
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / (1 + z**2 / n)
    return n, len(covering) - n, p, np.array([centre - half, centre + half])


def nominal_band(n):
    """95 % band of the observed share when the true coverage is 94 % (normal approx.)."""
    half = 1.959963984540054 * np.sqrt(NOMINAL * (1 - NOMINAL) / n)
    return NOMINAL - half, NOMINAL + half


def report(records, draws, seconds, sampler_seconds, command):
    """The Markdown report."""
    load = os.getloadavg()[0]
    out = [
        "# Coverage of the 94 % intervals with uncertain thickness and density",
        "",
        f"Made by `{command}` on {datetime.date.today()}, {cpu()}, {os.cpu_count()} cores, "
        f"load {load:.1f}, {seconds:.0f} s in all ({sampler_seconds:.0f} s of sampling). "
        f"Synthetic plate {LENGTH * 1e3:.0f} x {WIDTH * 1e3:.0f} x {THICKNESS * 1e3:.0f} mm, "
        f"one orthotropic ply, density {DENSITY:.0f} kg/m^3, mesh {MESH[0]} x {MESH[1]}, "
        f"{N_FREQ} frequencies with {100 * SIGMA_REL:.1f} % noise (as declared). Declared "
        f"input deviations: thickness {100 * SD_H_REL:.0f} %, density {100 * SD_RHO_REL:.0f} %;"
        f" each replicate's true thickness and density drawn from them (drawn: thickness "
        f"sd {100 * draws[:, 0].std():.2f} %, max |error| {100 * np.abs(draws[:, 0]).max():.1f} "
        f"%; density sd {100 * draws[:, 1].std():.2f} %), the prior mean drawn from the prior "
        f"(sd {100 * PRIOR_REL:.0f} %), seed {SEED}. Fitted with the nominal thickness and "
        "density. A cell is the share of replicates whose 94 % interval holds the true "
        "constant, with its Wilson 95 % interval; a share outside the band printed for its "
        "number of replicates (95 % band around 0.94 of a binomial share) is off nominal.",
    ]
    for method in ("B", "sampler"):
        title = ("B, linearised interval (estimate +- 1.881 sd)" if method == "B" else
                 "Sampler (emcee on the certified fast model), 94 % HDI")  # fmt: skip
        out += ["", f"## {title}", ""]
        head = ["inputs", "replicates (failed)", "band at 0.94", *ENGINEERING_KEYS]
        out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for t in TREATMENTS:
            n, failed, p, wilson = summary(records[(method, t)])
            if n == 0:
                out.append(f"| {t} | 0 ({failed}) | - |" + " - |" * 6)
                continue
            lo, hi = nominal_band(n)
            cells = [t, f"{n} ({failed})", f"{lo:.3f} to {hi:.3f}"]
            cells += [f"{p[j]:.3f} ({wilson[0, j]:.2f}-{wilson[1, j]:.2f})" for j in range(6)]
            out.append("| " + " | ".join(cells) + " |")
    out += [
        "",
        'Reading: with `inputs="exact"` the intervals of the bending-determined moduli (E1, '
        "E2, G12) leave out the thickness and density errors (which move them by about "
        f"{200 * SD_H_REL:.0f} % and {100 * SD_RHO_REL:.0f} %, against a frequency-only "
        'deviation of about 1 %) and fall short; with `inputs="marginal"` they include '
        "them. nu12, G13 and G23 are little affected by a common scaling of the eigenvalues. "
        '"Failed": B did not converge (it left the physical region from a prior mean drawn '
        "far from the truth, e.g. E2 at 0.37 of its true value, 2.5 prior deviations), "
        "counted out of the shares. B's linearised interval carries its own shortfall when "
        "priors are drawn this far (nu12, which the inputs barely touch, shows it in both "
        "treatments); the marginal moduli sit at that level.",
    ]
    return "\n".join(out) + "\n"


def main(out_dir, quick=False, replicates=None, sampler_minutes=None):
    """Run and write the report; return its path."""
    logging.getLogger("bayesplate").setLevel(logging.ERROR)
    n = replicates or (6 if quick else 200)
    minutes = sampler_minutes if sampler_minutes is not None else (0.0 if quick else 10.0)
    start = time.perf_counter()
    records, draws, sampler_seconds = run(n, minutes)
    command = "python studies/input_coverage.py" + (" --quick" if quick else "")
    text = report(records, draws, time.perf_counter() - start, sampler_seconds, command)
    path = pathlib.Path(out_dir) / REPORT
    atomic_write_text(path, text)
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="6 replicates, no sampler")
    parser.add_argument("--replicates", type=int, default=None, help="default 200")
    parser.add_argument("--sampler-minutes", type=float, default=None, help="default 10")
    parser.add_argument("--out", default=pathlib.Path(__file__).resolve().parents[1] / "reports")
    args = parser.parse_args()
    print(main(args.out, args.quick, args.replicates, args.sampler_minutes))
