"""The fitted test fitted globally: a test any method could run (issue 40, item 2).

The calibration study sets each candidate's power size where the *fitted* test rejects 9 of
10: the nominal model, its six constants fitted to the recordings, chi-square on ``m - 6``
degrees of freedom at 1 %. Its size comes from a linearised absorption (and
``nonlinear_absorption`` fits from the true constants only). This study fits the constants
to a replicate's own recordings from many starts (the true constants, the prior mean and
draws from the prior; no prior in the objective), on the recordings' own mesh (no mesh
error), and reports the best optimum found, beside what diagnose said on the same replicate
(from the calibration's cache, when it holds that replicate).

A local fit from the true constants can stop in one optimum while another, far along the
constants the frequencies hardly fix (G13, G23 of a thin plate), absorbs more of the effect:
the best of all the starts is the test's statistic.

Writes ``fitted_test.md`` to ``out_dir``. Run:
``python -m studies.fitted_test EFFECT SIZE [--replicates 0 1 ...] [--starts N] [--out DIR]``
(about 4-5 min a replicate on one core on the Frederiksen plate's 80 x 40 mesh).
"""

import argparse
import json
import os
import pathlib
import time

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2 as chi2_dist

from bayesplate import stiffness_from_engineering
from bayesplate.io import atomic_write_text
from bayesplate.likelihood.posterior import prior_in_stiffness
from studies import calibration as cal
from studies._study_host import code_version, utc_now

FAMILY = "frederiksen_t300"
ALPHA = 0.01


def fitted_test(recorded_Hz, sigma_Hz, model, b_true, prior, starts=8, rng=0, max_nfev=40):
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
        ``(mu_b, V_b)`` (Pa, Pa^2): its mean is a start and ``starts`` draws from it are more.
    starts : int
    rng : int or numpy.random.Generator
    max_nfev : int
        Evaluation cap of each local fit.

    Returns
    -------
    dict
        ``chi2`` (the best optimum's), ``dof`` (``m - 6``), ``p``, ``ratios`` (its constants
        over the true ones, shape (6,)), ``by_start`` (every start's optimum's chi-square, in
        the order above: the true constants, the prior mean, the draws) and ``at_truth`` (the
        chi-square at the true constants).
    """
    f, s = np.asarray(recorded_Hz, float), np.asarray(sigma_Hz, float)
    m, Y = f.size, (2 * np.pi * f) ** 2
    sigma = 2 * Y * s / f
    cache = {}

    def solved(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = model.solve(x * b_true, m)
        return cache[key]

    def residuals(x):
        return (solved(x).eigenvalues - Y) / sigma

    def jacobian(x):
        return solved(x).sensitivities * b_true[None, :] / sigma[:, None]

    mu_b, V_b = prior
    L, rng = np.linalg.cholesky(V_b), np.random.default_rng(rng)
    draws = [mu_b + L @ rng.standard_normal(6) for _ in range(starts)]
    x0s = [np.ones(6), mu_b / b_true] + [np.maximum(d / b_true, 0.05) for d in draws]
    optima = []
    for x0 in x0s:
        fit = least_squares(
            residuals, x0, jac=jacobian, x_scale="jac", bounds=(1e-3, np.inf), max_nfev=max_nfev
        )
        optima.append((float(fit.fun @ fit.fun), fit.x))
    best, x = min(optima, key=lambda pair: pair[0])
    dof = m - 6
    at_truth = residuals(np.ones(6))
    return {
        "chi2": best,
        "dof": dof,
        "p": float(chi2_dist.sf(best, dof)),
        "ratios": x.tolist(),
        "by_start": [c for c, _ in optima],
        "at_truth": float(at_truth @ at_truth),
    }


def replicate(effect, size, rep, starts=8, quick=False):
    """The fitted test on one power replicate of the calibration study; its row."""
    task = ("power", FAMILY, effect, "fitted 0.9", size, rep)
    blind, _, _, _, _, _, _ = cal.recordings(task, quick)
    case, _, fine = cal._models(FAMILY, quick)
    prior = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    b_true = stiffness_from_engineering(case.reference)
    m = blind.measured
    row = fitted_test(m.frequency_Hz, m.sigma_Hz, fine, b_true, prior, starts, rng=rep)
    return {"effect": effect, "size": size, "rep": rep, "key": cal.task_key(task), **row}


def diagnosed(out_dir, key):
    """What the calibration's caches say of replicate ``key``: ``{rule: row}``."""
    found = {}
    for path in sorted((pathlib.Path(out_dir) / ".cache" / "calibration").glob("*.jsonl")):
        rule = "corrected" if "-corrected" in path.name else "whole"
        for line in path.read_text().splitlines():
            row = json.loads(line)
            if row.get("key") == key and "-quick" not in path.name:
                found[f"{rule} ({row.get('code')})"] = row
    return found


def write_report(out_dir, rows, starts, seconds):
    """``fitted_test.md``: one line a replicate, with diagnose's verdicts beside."""
    effect, size = rows[0]["effect"], rows[0]["size"]
    rejected = sum(r["p"] < ALPHA for r in rows)
    lines = [
        f"# The fitted test fitted globally: {effect} at {size:g}",
        "",
        f"Made by `python -m studies.fitted_test {effect} {size:g} --starts {starts}` on "
        f"{utc_now()}, on the 2-core development machine (AMD EPYC), code {code_version()}; "
        f"{len(rows)} replicates in {seconds / 60:.0f} min on one process.",
        "",
        "The calibration study's power replicates of this size (Frederiksen plate, recordings on "
        "80 x 40, 14 frequencies, 0.2 % noise): the six constants fitted with no prior, on the "
        f"recordings' own mesh, from the true constants, the prior mean and {starts} draws from "
        f"the prior. The statistic is the best optimum's chi-square on {rows[0]['dof']} dof; "
        f"rejected at {ALPHA:g}. `first two starts`: the best of the true constants and the "
        "prior mean alone. `ratios`: the best optimum's coefficients over the true ones (C11, "
        "C22, C12, C66, C44 = G23, C55 = G13). `diagnose`: its verdict "
        "and nominal p on the same replicate, from the calibration's cache.",
        "",
        "| replicate | chi2 at the truth | first two starts | best of all | p | rejected | ratios "
        "| diagnose |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        first_two = min(r["by_start"][:2])
        said = "; ".join(
            f"{rule}: {d['verdict']}{' ' + d['chosen'] if d.get('chosen') else ''} "
            f"(p {d['p_value']:.2g})"
            for rule, d in r["diagnose"].items()
        )
        lines.append(
            f"| {r['rep']} | {r['at_truth']:.1f} | {first_two:.1f} | {r['chi2']:.1f} | "
            f"{r['p']:.2g} | {'yes' if r['p'] < ALPHA else 'no'} | "
            f"{', '.join(f'{v:.2f}' for v in r['ratios'])} | {said or '-'} |"
        )
    lines += [
        "",
        f"Rejected: {rejected} of {len(rows)} (the linearised fitted test promised 0.9 at this "
        "size).",
        "",
    ]
    path = pathlib.Path(out_dir) / "fitted_test.md"
    atomic_write_text(path, "\n".join(lines))
    return path


def main(effect, size, replicates, starts=8, out_dir="reports", quick=False):
    """Run the replicates, write the report; return the rows."""
    start, rows = time.perf_counter(), []
    for rep in replicates:
        row = replicate(effect, size, rep, starts, quick)
        row["diagnose"] = {} if quick else diagnosed(out_dir, row["key"])
        print(f"{effect} {size:g} #{rep}: chi2 {row['chi2']:.1f}, p {row['p']:.2g}", flush=True)
        rows.append(row)
    write_report(out_dir, rows, starts, time.perf_counter() - start)
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("effect")
    parser.add_argument("size", type=float)
    parser.add_argument("--replicates", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--starts", type=int, default=8)
    parser.add_argument("--out", default=os.environ.get("STUDY_OUT", "reports"))
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    main(args.effect, args.size, args.replicates, args.starts, args.out, args.quick)
