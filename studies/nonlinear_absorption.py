"""How much of an effect the six constants absorb: the linearised figure against the exact fit.

The calibration study sizes its effects, and judges what any method that estimates the
constants can see, by the noncentrality the fitted nominal model leaves, linearised at the
true constants (:func:`calibration_sizes.fitted_noncentrality`: ``|| (I - A A^+) r ||^2``). A fit
is not linear: where an effect is large the constants may move far, and a constant the
frequencies hardly feel near its true value (a transverse shear modulus of a thin plate) can
take up more than its slope there says. This study fits the six constants to each effect's
exact eigenvalues (the recordings' mesh of the calibration study, no noise, the declared
0.2 % deviations):

- without a prior, from the true constants: ``min_b || (lambda_effect - lambda(b)) /
  sigma ||^2``, the exact counterpart of the linearised figure;
- with the case's prior (Gaussian on the engineering constants), as diagnose's nominal fit
  has it: its chi-square part and its prior part.

Each row is an effect at one of the calibration study's sizes (its size table, cached with
its rows of the same code version in ``reports/.cache/calibration/``, or computed anew).
The rows are kept in ``out_dir/.cache/nonlinear_absorption.json``, the report is
``out_dir/nonlinear_absorption.md``. Run: ``python -m studies.nonlinear_absorption
[--quick] [--workers 2] [--effect NAME] [--report-only]``; ``--quick`` uses the
calibration study's coarse meshes and the point mass alone (a regression run, not a
measurement).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import time
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares

from bayesplate.io import atomic_write_text
from bayesplate.laminate import (
    engineering_from_stiffness,
    stiffness_from_engineering,
    stiffness_jacobian,
)
from bayesplate.parallel import fork_map
from bayesplate.quantities import ENGINEERING_NAMES
from studies import calibration as cal  # its effects, sizes and meshes
from studies import calibration_sizes as cal_sizes  # its tests' noncentralities and power
from studies._study_host import code_version, cpu, utc_now

REPORT = "nonlinear_absorption.md"
LABELS = ("fitted 0.9", "3 x ideal 0.9")  # the calibration study's sizes compared here


class Exact(NamedTuple):
    """What :func:`exact_fit` found."""

    chi2: float  #: ``|| (lam_effect - lambda(b)) / sigma ||^2`` at the fit
    prior_term: float  #: the prior's ``|| (e(b) - mean) / sd ||^2`` there (0 without one)
    b: np.ndarray  #: the fitted stiffness coefficients, Pa, shape (6,)
    residual: np.ndarray  #: the whitened residuals there, shape (m,) or (m + 6,)
    jacobian: np.ndarray  #: their derivatives in the log-stiffness steps, shape (len, 6)


def exact_fit(plate, b_true, lam_effect, sigma, prior=None, start=None, max_nfev=None):
    """The six constants fitted to ``lam_effect`` (log-stiffness steps from ``b_true``).

    Parameters
    ----------
    plate : bayesplate.plate.model.PlateModel
        The model of the recordings (without the effect).
    b_true : numpy.ndarray, shape (6,)
        The true stiffness coefficients, Pa: the start.
    lam_effect : numpy.ndarray, shape (m,)
        The eigenvalues with the effect, sorted, (rad/s)^2.
    sigma : numpy.ndarray, shape (m,)
        Their deviations, (rad/s)^2.
    prior : (mean, sd), optional
        Gaussian prior on the engineering constants, SI units, shapes (6,).
    start : numpy.ndarray, shape (6,), optional
        The first step ``ln(b / b_true)`` (default zeros: the true constants).
    max_nfev : int, optional
        Evaluation cap of the local fit (default: scipy's).

    Returns
    -------
    Exact
        The chi-square, the prior's term, the fitted ``b``, and the whitened residuals (the
        ``m`` data rows, then the prior's six) with their Jacobian at the fit.
    """
    m = lam_effect.size
    solved = {}

    def solve(z):
        key = z.tobytes()
        if key not in solved:
            solved.clear()
            solved[key] = plate.solve(b_true * np.exp(z), m)
        return solved[key]

    def prior_part(z):
        if prior is None:
            return np.zeros(0)
        return (engineering_from_stiffness(b_true * np.exp(z)) - prior[0]) / prior[1]

    def residuals(z):
        return np.concatenate([(lam_effect - solve(z).eigenvalues) / sigma, prior_part(z)])

    def jacobian(z):
        b = b_true * np.exp(z)
        sens = solve(z).sensitivities * b[None, :]  # d lambda / d z
        if prior is None:
            return -sens / sigma[:, None]
        # d e / d z = (d b / d e)^-1 diag(b), the inverse of the laminate's own Jacobian
        de_dz = np.linalg.solve(stiffness_jacobian(engineering_from_stiffness(b)), np.diag(b))
        return np.vstack([-sens / sigma[:, None], de_dz / prior[1][:, None]])

    z0 = np.zeros(6) if start is None else np.asarray(start, dtype=float)
    out = least_squares(residuals, z0, jac=jacobian, xtol=1e-10, ftol=1e-12, max_nfev=max_nfev)
    r = out.fun
    return Exact(
        float(np.sum(r[:m] ** 2)), float(np.sum(r[m:] ** 2)), b_true * np.exp(out.x), r, out.jac
    )


def plate(quick=False):
    """The calibration study's power plate: ``(case, fine, b, nominal, working)``: its model
    on the recordings' mesh, the true stiffness coefficients ``b``, their solution there, and
    the plate's model on diagnose's working mesh (the calibration study's)."""
    case, working, fine = cal._models(cal.POWER_FAMILY, quick)
    b = stiffness_from_engineering(case.reference)
    return case, fine, b, fine.solve(b, case.measured.size), working


def _recorded(fitted, widening, dof):
    """:func:`calibration_sizes.recorded_noise_power` of an :class:`Exact` fit, seeded."""
    return cal_sizes.recorded_noise_power(
        fitted.residual, fitted.jacobian, widening, dof, np.random.default_rng(cal_sizes.DRAWS_SEED)
    )


def effective_dof(fitted, m):
    """``m - p_eff`` as diagnose counts them: ``p_eff`` the trace of the data rows' share of
    the fit's Gauss-Newton Hessian (:attr:`bayesplate.discrepancy.search.laplace.JointFit.
    effective_parameters`), from the Jacobian of :class:`Exact`."""
    J = fitted.jacobian
    data = J[:m].T @ J[:m]
    return float(m - np.trace(np.linalg.solve(J.T @ J, data)))


def row(task, plated, widening=None):
    """One effect at one size: the ideal, linearised and exact fitted noncentralities.

    ``plated``: :func:`plate`. ``widening``, shape (m,): diagnose's factors on the deviations
    (the calibration study's replicates of this size, median); the linearised and exact
    (with the prior) figures are then also computed at the widened deviations.
    """
    effect, label, size = task
    start = time.perf_counter()
    case, fine, b, nominal, working = plated
    m = case.measured.size
    sigma = 2.0 * cal.NOISE * nominal.eigenvalues  # d lambda = 2 lambda df / f
    make, theta, _, _ = cal.EFFECTS[effect]
    lam = np.sort(make().apply(fine, np.asarray(theta(size), dtype=float)).solve(b, m).eigenvalues)
    delta = lam - nominal.eigenvalues
    free = exact_fit(fine, b, lam, sigma)
    prior = (np.asarray(case.prior.mean, dtype=float), np.asarray(case.prior.sd, dtype=float))
    held = exact_fit(fine, b, lam, sigma, prior)
    truth = np.asarray(case.reference, dtype=float)
    widened = {}
    if widening is not None:
        wide = sigma * np.asarray(widening, dtype=float)
        fitted = exact_fit(fine, b, lam, wide, prior)
        power = _recorded(fitted, widening, m - cal.N_CONSTANTS)
        # diagnose's nominal problem without its noise: its working mesh fitted to the
        # recordings' eigenvalues, its deviations, its prior, its degrees of freedom
        seen = exact_fit(working, b, lam, wide, prior)
        dof = effective_dof(seen, m)
        seen_power = _recorded(seen, widening, dof)
        widened = {
            "widening": float(np.median(widening)),
            "widened_prior_term": fitted.prior_term,
            "widened_linearised": cal_sizes.fitted_noncentrality(
                delta, nominal.sensitivities, wide
            ),
            "widened_exact": fitted.chi2,
            "recorded_noise_power": power,
            "working_exact": seen.chi2,
            "working_dof": dof,
            "working_power": seen_power,
        }
    return {
        **widened,
        "effect": effect,
        "label": label,
        "size": float(size),
        "m": int(m),
        "ideal": float(np.sum((delta / sigma) ** 2)),
        "linearised": cal_sizes.fitted_noncentrality(delta, nominal.sensitivities, sigma),
        "exact": free.chi2,
        "exact_ratio": (engineering_from_stiffness(free.b) / truth).tolist(),
        "prior_chi2": held.chi2,
        "prior_term": held.prior_term,
        "prior_at_truth": float(np.sum(((truth - prior[0]) / prior[1]) ** 2)),
        "prior_ratio": (engineering_from_stiffness(held.b) / truth).tolist(),
        "seconds": time.perf_counter() - start,
    }


def tasks(size_table, quick=False, effects=None):
    """``(effect, size label, size)`` of every row, in the calibration study's order."""
    labels = [entry[0] for entry in cal.SIZES]
    return [
        (name, label, entry["sizes"][labels.index(label)])
        for name, entry in size_table.items()
        if effects is None or name in effects
        for label in LABELS
        if entry["sizes"][labels.index(label)] is not None
    ]


def calibration(out_dir, quick):
    """The calibration study's size table and counted rows: from its cache when it holds a
    size table (else the table anew and no rows)."""
    stored = cal.load(out_dir, quick)  # the rows of this code version
    if stored["sizes"] is not None:
        return stored["sizes"], list(stored["rows"].values())
    return cal.sizes(quick), []


def diagnosed(rows, effect, size):
    """What the calibration study's replicates of ``effect`` at ``size`` say: the median of
    diagnose's factors on the deviations (None without rows) and how many replicates its
    nominal test rejected at 1 %, of how many."""
    mine = [
        r for r in rows if r.get("effect") == effect and r.get("size") == size and "widening" in r
    ]
    if not mine:
        return None, 0, 0
    widening = np.median([r["widening"] for r in mine], axis=0)
    return widening, sum(r["p_value"] < cal.ALPHA for r in mine), len(mine)


def _changed(ratio):
    """The constants the fit moved by more than 5 %, as ``name x ratio``."""
    pairs = zip(ENGINEERING_NAMES, ratio, strict=True)
    moved = [f"{n} x{r:.2f}" for n, r in pairs if abs(r - 1.0) > 0.05]
    return ", ".join(moved) or "none by more than 5 %"


def _run_facts(workers, minutes):
    """When, where and by what code the rows were made (kept with them)."""
    return {
        "workers": workers,
        "minutes": minutes,
        "code": code_version(),
        "cpu": cpu(),
        "made": utc_now(),
        "load": list(os.getloadavg()),
    }


def _size_and_power(r, linearised, exact):
    """A row's candidate and size cells, and its fitted test's power at two noncentralities
    (``m - 6`` dof, 1 %), as table cells."""
    unit = cal.EFFECTS[r["effect"]][2]
    power = [cal.ideal_power(r[k], r["m"] - cal.N_CONSTANTS) for k in (linearised, exact)]
    return (
        f"{r['effect']} | {r['size']:.2g} {unit} ({r['label']})",
        f"{power[0]:.2f} / {power[1]:.2f}",
    )


def _working(r):
    """The working-mesh cell of a widened row (rows made before it was computed: -)."""
    if "working_exact" not in r:
        return "-"
    return f"{r['working_exact']:.1f}, {r['working_dof']:.1f}, {r['working_power']:.2f}"


def report(rows, quick, facts):
    """The report's Markdown; ``facts``: :func:`_run_facts` of the run that made ``rows``."""
    load = ", ".join(f"{x:.2f}" for x in facts["load"])
    lines = [
        "# How much of an effect the six constants absorb: linearised against exact",
        "",
        f"Made by `python -m studies.nonlinear_absorption{' --quick' if quick else ''}` on "
        f"{facts['made']}, on {facts['cpu']}, {facts['workers']} worker(s), code "
        f"{facts['code']}; {len(rows)} rows in {facts['minutes']:.1f} min of wall time; load "
        f"averages (1, 5, 15 min) when the rows were done: {load}.",
        "",
        "The calibration study's effects on its Frederiksen plate and recordings' mesh, no "
        "noise, deviations 0.2 % of each frequency (in eigenvalue: `2 x 0.002 lambda`), at its "
        "sizes where the linearised fitted test rejects with probability 0.9 and three times "
        "the ideal test's 0.9 size. `ideal`: the noncentrality at the true constants; "
        "`linearised`: what is left once the constants absorb what they can, linearised at the "
        "true constants (the calibration study's figure); `exact`: the same by a fit of the six "
        "constants to the effect's eigenvalues from the true ones (no prior); `with prior`: the "
        "chi-square and the prior's term of the fit with the case's prior, as diagnose's "
        "nominal fit has it (the prior's term at the true constants in brackets: the true "
        "constants are not the prior's mean). The moved constants are given as ratios to the "
        "true ones.",
        "",
        "`P(reject)`: the fitted test's power (chi-square, `m - 6` dof, 1 %) at the "
        "linearised and at the exact noncentrality.",
        "",
        "| candidate | size | ideal | linearised | exact | exact / linearised | P(reject): "
        "linearised / exact | constants moved (exact) | with prior: chi-square + prior | "
        "constants moved (with prior) |",
        "|---|---|---:|---:|---:|---:|---|---|---|---|",
    ]
    for r in rows:
        size, power = _size_and_power(r, "linearised", "exact")
        lines.append(
            f"| {size} | {r['ideal']:.1f} | {r['linearised']:.1f} | {r['exact']:.1f} | "
            f"{r['exact'] / r['linearised']:.2f} | {power} | {_changed(r['exact_ratio'])} | "
            f"{r['prior_chi2']:.1f} + {r['prior_term']:.1f} ({r['prior_at_truth']:.1f}) | "
            f"{_changed(r['prior_ratio'])} |"
        )
    lines.append("")
    wide = [r for r in rows if "widening" in r]
    if wide:
        lines += [
            "## At diagnose's deviations",
            "",
            "diagnose widens the deviations by its mesh's estimated error (the median factors "
            "of the calibration study's counted replicates at each size, per mode; their "
            "median over the modes in the table) and fits with the case's prior. The fitted "
            "test's noncentrality there, linearised and exact (with the prior: its chi-square "
            "part) and its power (`m - 6` dof, 1 %) read as if the noise were as wide as the "
            "widened deviations; then its power with the noise as recorded (sd 0.2 %, not "
            "widened: the statistic is a generalised chi-square, whose tail is drawn from "
            f"{cal_sizes.DRAWS:,} seeded noise vectors, "
            "`calibration_sizes.recorded_noise_power`); then "
            "diagnose's nominal problem without its noise: the plate's model on diagnose's "
            "working mesh (half as fine each way as the recordings') fitted exactly to the "
            "recordings' eigenvalues with the same deviations and prior, its chi-square, "
            "degrees of freedom as diagnose counts them (`m - p_eff`) and power with the noise as "
            "recorded; beside how often diagnose's own nominal test rejected the replicates "
            "(p < 0.01). Sizes whose replicates did not record diagnose's widening (made by "
            "older code) are left out.",
            "",
            "| candidate | size | widening | linearised | exact + prior | P(reject) read at "
            "widened noise: linearised / exact | P(reject), noise as recorded (exact) | "
            "working mesh: chi-square, dof, P(reject) | diagnose's nominal test rejected |",
            "|---|---|---:|---:|---|---|---:|---|---|",
        ]
        for r in wide:
            size, power = _size_and_power(r, "widened_linearised", "widened_exact")
            recorded = r.get("recorded_noise_power")
            lines.append(
                f"| {size} | {r['widening']:.2f} | {r['widened_linearised']:.1f} | "
                f"{r['widened_exact']:.1f} + {r['widened_prior_term']:.1f} | {power} | "
                f"{'-' if recorded is None else f'{recorded:.2f}'} | {_working(r)} | "
                f"{r['rejected']} of {r['replicates']} |"
            )
        lines.append("")
    return "\n".join(lines)


def main(out_dir="reports", quick=False, workers=1, effects=None, report_only=False):
    """Fit every row (or, ``report_only``, read them from the last run), write the report;
    return its path."""
    start = time.perf_counter()
    prefix = "quick_" if quick else ""
    cache = pathlib.Path(out_dir) / ".cache" / f"{prefix}nonlinear_absorption.json"
    if report_only:
        stored = json.loads(cache.read_text())
    else:
        table, replicates = calibration(out_dir, quick)
        todo = tasks(table, quick, effects)
        print(f"{len(todo)} rows", flush=True)
        seen = [diagnosed(replicates, t[0], t[2]) for t in todo]
        plated = plate(quick)  # once: the workers inherit it
        rows = fork_map(lambda j: row(todo[j], plated, seen[j][0]), range(len(todo)), workers)
        for r, (_, rejected, n) in zip(rows, seen, strict=True):
            r["rejected"], r["replicates"] = rejected, n
        stored = {"rows": rows, **_run_facts(workers, (time.perf_counter() - start) / 60)}
        cache.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(cache, json.dumps(stored))
    path = pathlib.Path(out_dir) / (prefix + REPORT)
    atomic_write_text(path, report(stored["rows"], quick, stored))
    print(path)
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", default="reports")
    parser.add_argument("--effect", action="append", choices=list(cal.EFFECTS), default=None)
    parser.add_argument("--report-only", action="store_true", help="the last run's rows")
    args = parser.parse_args()
    main(args.out, args.quick, args.workers, args.effect, args.report_only)
