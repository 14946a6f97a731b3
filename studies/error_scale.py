"""Coverage of the 94 % intervals when the frequency noise is 3 times the declared (issue 17).

A lab that does not know its measurement error declares a deviation too small; the case's
``measured.error_scale`` (a prior on one common scale ``s`` of the deviations) lets the
intervals widen with the misfit. Two seeded experiments:

1. A linear-Gaussian model (m = 14 data, p = 6 constants, sensitivities N(0, 1), a weak
   prior sd 100): B's interval, estimate +- 1.881 sd, without and with the scale
   (:func:`bayesplate.likelihood.error_scale.linearised_scale`), over ``TOY_REPLICATES`` replicates,
   for true noise 3 and 1 times the declared, and for three priors on ``s``.
2. A synthetic plate (single orthotropic ply 300 x 200 x 4 mm, density 1600 kg/m^3, mesh
   12 x 8, 10 frequencies, declared deviation 0.5 %, drawn with 1.5 %; the prior mean drawn
   from the prior, sd 25 %, so the truth is a draw from the prior): B (TOL 1e-6) and its
   linearised interval without and with the scale (prior median 1, upper 95 % 5), and the
   scale's own interval. The frequencies are sorted as a lab would list them (the noise can
   swap close modes: the misfit then grows, and so does ``s``). As a control the same with
   noise as declared. The sampler (emcee, :func:`bayesplate.sampling.sample`, the scale
   integrated out, ``s`` drawn once per kept draw) runs on the first replicates for as long
   as ``--sampler-minutes`` allows.

A cell is the share of intervals holding the true value, with its Wilson 95 % interval; the
95 % band of a binomial share around 0.94 for that number of replicates is printed beside it.

Writes ``error_scale.md`` to ``out_dir``. Run:
``python -m studies.error_scale [--quick] [--replicates N] [--sampler-minutes M] [--out DIR]``
(quick: 8 plate replicates, 400 toy replicates, no sampler).
"""

import argparse
import datetime
import logging
import os
import pathlib
import time
import warnings

import numpy as np

from bayesplate import laminate
from bayesplate.batch import map_tasks
from bayesplate.estimators import run as run_estimator
from bayesplate.io import Case, Measurement, Plate, Prior, atomic_write_text
from bayesplate.likelihood.error_scale import ErrorScalePrior, linearised_at, linearised_scale
from bayesplate.likelihood.posterior import GaussianProblem
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import ENGINEERING_KEYS, engineering_covariance, hz_from_eigenvalue
from studies._study_host import cpu

REPORT = "error_scale.md"
SEED = 20261117
E_TRUE = np.array([140e9, 10e9, 0.3, 5e9, 5e9, 3.5e9])  # E1, E2, nu12, G12, G13, G23 (SI)
LENGTH, WIDTH, THICKNESS, DENSITY = 0.3, 0.2, 0.004, 1600.0  # m, kg/m^3
SIGMA_REL = 0.005  # declared frequency deviation, relative
TRUE_SCALE = 3.0  # the noise drawn is this many times the declared
PRIOR_REL = 0.25  # prior sd, relative to the true constants
SCALE_PRIOR = (1.0, 5.0)  # median and upper 95 % of s
TOY_PRIORS = ((1.0, 3.0), (1.0, 5.0), (1.0, 10.0))
TOY_REPLICATES = 4000
N_FREQ = 10
MESH = (12, 8)
Z94 = 1.8807936081512509  # normal quantile of 0.97: a two-sided 94 % interval
NOMINAL = 0.94


# ----------------------------------------------------------------------------- the toy


def toy(n, rng, prior, true_s, m=14, p=6):
    """Linear-Gaussian replicates: (hits without, hits with: (n, p) bool; s covered: (n,))."""
    S = rng.standard_normal((m, p))
    W = np.eye(p) / 100.0**2
    theta = rng.standard_normal(p)
    P = np.linalg.inv(S.T @ S + W)
    without, with_, s_in = [], [], []
    for _ in range(n):
        Y = S @ theta + true_s * rng.standard_normal(m)
        est = P @ (S.T @ Y)
        without.append(np.abs(est - theta) <= Z94 * np.sqrt(np.diag(P)))
        lin = linearised_scale(S, Y - S @ est, np.eye(m), W, prior)
        with_.append(np.abs(est - theta) <= Z94 * np.sqrt(np.diag(lin.covariance_b)))
        s_in.append(lin.summary.interval[0] <= true_s <= lin.summary.interval[1])
    return np.array(without), np.array(with_), np.array(s_in)


# ----------------------------------------------------------------------------- the plate


def nominal_case(frequency_Hz, prior_mean, scale=SCALE_PRIOR):
    """The case the lab writes: declared 0.5 % deviations and a prior on their scale."""
    plate = Plate(LENGTH, WIDTH, THICKNESS, DENSITY, (0,))
    prior_s = None if scale is None else ErrorScalePrior(*scale)
    measured = Measurement(frequency_Hz, SIGMA_REL * np.asarray(frequency_Hz), error_scale=prior_s)
    prior = Prior(prior_mean, PRIOR_REL * E_TRUE)
    return Case("error-scale plate", "studies/error_scale.py", plate, measured, prior, MESH)


def draw(rng, true_s):
    """One replicate's case: frequencies at ``E_TRUE`` with ``true_s`` times the noise."""
    prior_mean = E_TRUE + PRIOR_REL * E_TRUE * rng.standard_normal(6)
    model = PlateModel.from_case(nominal_case(np.ones(N_FREQ), E_TRUE), mesh=MESH)
    lam = model.solve(laminate.stiffness_from_engineering(E_TRUE), N_FREQ).eigenvalues[:N_FREQ]
    f = hz_from_eigenvalue(lam) * (1 + true_s * SIGMA_REL * rng.standard_normal(N_FREQ))
    return nominal_case(np.sort(f), prior_mean)


def fit_b(task):
    """B and its intervals without and with the scale, for one replicate (a map task).

    Returns None when B did not converge, else ``(covers without (6,), covers with (6,),
    s interval (2,))``.
    """
    seed, true_s = task
    case = draw(np.random.default_rng(seed), true_s)
    model = PlateModel.from_case(case, mesh=MESH)
    problem = GaussianProblem.from_case(case, model)
    result = run_estimator(problem.with_error_scale(None), "B", tol=1e-6)
    if not result.converged or not np.all(np.isfinite(result.sd)):
        return None
    lin = linearised_at(problem, result.b)
    sd = np.sqrt(np.diag(engineering_covariance(result.constants, lin.covariance_b)))
    return (
        _covers(result.constants, result.sd),
        _covers(result.constants, sd),
        np.array(lin.summary.interval),
    )


def fit_sampler(seed, true_s, rng):
    """The sampler's 94 % HDI covers (6,) and the interval of s, or None (B, the MAP, or the
    chain did not converge)."""
    from bayesplate.likelihood.error_scale import scale_from_draws
    from bayesplate.sampling import prepare, sample

    case = draw(np.random.default_rng(seed), true_s)
    model = PlateModel.from_case(case, mesh=MESH)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # full-model fallbacks are counted in the result
        setup = prepare(case, model=model, rng=rng)
        if not setup.estimate.converged:  # as B's failures in fit_b: no walkers around it
            return None
        result = sample(case, rng=rng, setup=setup, progress=False, min_ess=400, max_steps=3000)
    if not result.converged:
        return None
    summary, _ = scale_from_draws(
        setup.problem, result.samples_b, setup.sampling_forward(), rng=rng
    )
    covers = (result.hdi[0] <= E_TRUE) & (E_TRUE <= result.hdi[1])
    return covers, np.array(summary.interval)


def _covers(estimate, sd):
    return np.abs(estimate - E_TRUE) <= Z94 * sd


def run(
    n_replicates=200, toy_replicates=TOY_REPLICATES, sampler_minutes=10.0, seed=SEED, workers=1
):
    """All records (see :func:`report`)."""
    rng = np.random.default_rng(seed)
    toy_rng, plate_rng = rng.spawn(2)
    toys = {}
    for prior in TOY_PRIORS:
        toys[(prior, TRUE_SCALE)] = toy(
            toy_replicates, toy_rng, ErrorScalePrior(*prior), TRUE_SCALE
        )
    toys[(TOY_PRIORS[0], 1.0)] = toy(toy_replicates, toy_rng, ErrorScalePrior(*TOY_PRIORS[0]), 1.0)
    seeds = plate_rng.integers(2**63, size=n_replicates)
    started = time.perf_counter()
    plates = {
        s: map_tasks(fit_b, [(int(k), s) for k in seeds], workers=workers, progress=False)
        for s in (TRUE_SCALE, 1.0)
    }
    b_seconds = time.perf_counter() - started
    started = time.perf_counter()
    sampled = []
    for i, k in enumerate(seeds):
        if time.perf_counter() - started >= 60 * sampler_minutes:
            break
        sampled.append(fit_sampler(int(k), TRUE_SCALE, 1000 + i))
    return toys, plates, sampled, b_seconds, time.perf_counter() - started


# ----------------------------------------------------------------------------- report


def wilson(hits):
    """(share, low, high) of bool hits: Wilson 95 % interval."""
    hits = np.asarray(hits, dtype=float).ravel()
    n, p, z = hits.size, hits.mean(), 1.959963984540054
    centre = (p + z**2 / (2 * n)) / (1 + z**2 / n)
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / (1 + z**2 / n)
    return p, centre - half, centre + half


def _cell(hits):
    p, lo, hi = wilson(hits)
    return f"{p:.3f} ({lo:.2f}-{hi:.2f})"


def _band(n):
    half = 1.959963984540054 * np.sqrt(NOMINAL * (1 - NOMINAL) / n)
    return f"{NOMINAL - half:.3f} to {NOMINAL + half:.3f}"


def report(toys, plates, sampled, b_seconds, sampler_seconds, command):
    """The Markdown report."""
    n_toy = len(next(iter(toys.values()))[2])
    out = [
        "# Error scale: coverage when the frequency noise is 3 times the declared",
        "",
        f"Made by `{command}` on {datetime.date.today()}, {cpu()}, {os.cpu_count()} cores, "
        f"load {os.getloadavg()[0]:.1f}; {b_seconds:.0f} s of B fits, {sampler_seconds:.0f} s "
        f"of sampling; seed {SEED}. A cell is the share of 94 % intervals holding the truth "
        "(Wilson 95 % interval in brackets); beside it, the 95 % band of a binomial share "
        "around 0.94 for that many intervals (intervals of one replicate are correlated, so "
        "the band is a guide, not a test).",
        "",
        f"## 1. Linear-Gaussian toy (m = 14, p = 6, {n_toy} replicates each)",
        "",
        "B's interval, estimate +- 1.881 sd, pooled over the 6 constants; the scale's "
        "interval is its 94 % interval at the estimate (linearised).",
        "",
        "| true noise / declared | prior of s (median, upper 95 %) | without the scale | "
        "with the scale | s inside its interval | band at 0.94 |",
        "|---|---|---|---|---|---|",
    ]
    for (prior, true_s), (without, with_, s_in) in toys.items():
        out.append(
            f"| {true_s:g} | {prior[0]:g}, {prior[1]:g} | {_cell(without)} | "
            f"{_cell(with_)} | {_cell(s_in)} | {_band(without.size)} |"
        )
    out += [
        "",
        f"## 2. Synthetic plate (B, linearised; prior of s: median {SCALE_PRIOR[0]:g}, upper "
        f"95 % {SCALE_PRIOR[1]:g})",
        "",
        f"Single ply {LENGTH * 1e3:.0f} x {WIDTH * 1e3:.0f} x {THICKNESS * 1e3:.0f} mm, "
        f"mesh {MESH[0]} x {MESH[1]}, {N_FREQ} frequencies, declared deviation "
        f"{100 * SIGMA_REL:.1f} %, prior sd {100 * PRIOR_REL:.0f} % (its mean drawn from it).",
        "",
        "| true noise / declared | replicates (B failed) | scale | band at 0.94 | "
        + " | ".join(ENGINEERING_KEYS)
        + " | all | s inside its interval |",
        "|---|---|---|---|" + "---|" * 6 + "---|---|",
    ]
    for true_s, records in plates.items():
        used = [r for r in records if r is not None]
        if not used:
            continue
        failed = len(records) - len(used)
        s_iv = np.array([r[2] for r in used])
        s_in = (s_iv[:, 0] <= true_s) & (true_s <= s_iv[:, 1])
        for k, name in ((0, "without"), (1, "with")):
            hits = np.array([r[k] for r in used])
            cells = [_cell(hits[:, j]) for j in range(6)]
            out.append(
                f"| {true_s:g} | {len(used)} ({failed}) | {name} | {_band(len(used))} | "
                + " | ".join(cells)
                + f" | {_cell(hits)} | "
                + (_cell(s_in) if k else "-")
                + " |"
            )
        med = np.median(np.sqrt(s_iv.prod(axis=1)))
        out.append(
            f"|  |  | (median over replicates of the geometric centre of s's interval: "
            f"{med:.2f}) |  |" + "  |" * 8
        )
    done = [r for r in sampled if r is not None]
    out += [
        "",
        f"## 3. Sampler (emcee, the scale integrated out; true noise {TRUE_SCALE:g} "
        "times the declared)",
        "",
    ]
    if not sampled:
        out.append("Not run (quick mode or no time given).")
    else:
        hits = np.array([r[0] for r in done]) if done else np.zeros((0, 6), bool)
        s_iv = np.array([r[1] for r in done]) if done else np.zeros((0, 2))
        s_in = (s_iv[:, 0] <= TRUE_SCALE) & (TRUE_SCALE <= s_iv[:, 1])
        failed = len(sampled) - len(done)
        out.append(
            f"{len(sampled)} replicates sampled ({failed} had no converged MAP or "
            f"chain); 94 % HDI coverage pooled over the constants "
            f"{_cell(hits) if done else '-'}; s inside its 94 % interval (one draw per "
            f"kept draw) {_cell(s_in) if done else '-'}; intervals of s: "
            + ", ".join(f"[{a:.2f}, {b:.2f}]" for a, b in s_iv[:6])
            + "."
        )
    out += [
        "",
        "Regenerate: `python -m studies.error_scale` (the numbers above come from the "
        "command at the top).",
    ]
    return "\n".join(out) + "\n"


def main(out_dir, quick=False, replicates=None, sampler_minutes=None, workers=1):
    """Run the study and write ``error_scale.md`` into `out_dir`; return its path."""
    n = replicates or (8 if quick else 200)
    minutes = 0.0 if quick else (10.0 if sampler_minutes is None else sampler_minutes)
    n_toy = 400 if quick else TOY_REPLICATES
    toys, plates, sampled, b_s, s_s = run(n, n_toy, minutes, workers=workers)
    command = "python -m studies.error_scale" + (" --quick" if quick else "")
    if replicates:
        command += f" --replicates {replicates}"
    if sampler_minutes is not None:
        command += f" --sampler-minutes {sampler_minutes:g}"
    path = pathlib.Path(out_dir) / REPORT
    atomic_write_text(path, report(toys, plates, sampled, b_s, s_s, command))
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--replicates", type=int, default=None)
    parser.add_argument("--sampler-minutes", type=float, default=None)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", default=str(pathlib.Path(__file__).parents[1] / "reports"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    print(main(args.out, args.quick, args.replicates, args.sampler_minutes, args.workers))
