"""``bayesplate estimate``: the paper's estimators B, MVE and MVE-mod on a case."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from .options import (
    CONVENTION_CHOICES,
    DEFAULT_MAX_ITER,
    FORWARD_CHOICES,
    METHOD_CHOICES,
    add_case_argument,
    add_json_option,
    add_mesh_option,
    add_pairing_option,
    mesh_of,
    positive_float,
    positive_int,
    resolve_case,
)

__all__ = ["register"]


def estimate_text(case, model, result):
    """Human-readable table of ``bayesplate estimate``."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    lines = [
        f"{case.name}",
        f"{result.method}, mesh {model.mesh.nx} x {model.mesh.ny}: {status_word(result)} "
        f"{result.iterations} iterations ({result.n_solves} forward solves, "
        f"{result.wall_time:.1f} s)",
        f"  {result.message}",
        *([f"  {result.fit}"] if result.fit is not None else []),
        *_check_lines(result),
        f"{'constant':>9} {'estimate':>10} {'sd':>9} {'initial':>9}",
    ]
    prior = result.stages[0] if result.stages else result
    initial = prior.settings.get("prior_mean", case.prior.mean)
    columns = (to_case_units(v) for v in (result.constants, result.sd, initial))
    for key, m, d, m0 in zip(ENGINEERING_KEYS, *columns, strict=True):
        lines.append(f"{key:>9} {m:#10.4g} {d:#9.3g} {m0:#9.4g}")
    head = ("mode", "measured_Hz", "computed_Hz", "diff_Hz", "diff_%")
    lines.append("{:>4} {:>12} {:>12} {:>9} {:>7}".format(*head))
    for i, (fm, fc) in enumerate(zip(result.measured_Hz, result.frequency_Hz, strict=True)):
        d = fc - fm
        lines.append(f"{result.modes[i]:>4} {fm:12.1f} {fc:12.1f} {d:9.1f} {100 * d / fm:7.2f}")
    return "\n".join(lines)


def status_word(result):
    """How the run ended, before "N iterations": never "converged" for a flagged answer."""
    if not result.converged:
        return "NOT converged after"
    if result.status == "converged":
        return "converged after"
    return f"{result.status} (the iteration stopped; see the warnings) after"


def print_warnings(result):
    """Each of the result's warnings as one line on standard error."""
    for text in result.warnings:
        print(f"bayesplate: warning: {text}", file=sys.stderr)


def scale_text(scale):
    """The inferred error scale at the estimate, and how the sd above include it."""
    return (
        f"{scale.summary}\n  s_hat {scale.s_hat:.3g} at the estimate (chi2 {scale.chi2:.3g} "
        f"with the declared deviations, {scale.n_effective:.1f} effective constants); the sd "
        f"above are linearised with it (Student-t, {scale.dof:.1f} degrees of freedom)"
    )


def budget_text(budget):
    """The variance budget table: each constant's sd from each source, and its share."""
    import numpy as np

    from ..quantities import ENGINEERING_KEYS, to_case_units

    keep = [i for i, row in enumerate(budget.variance) if np.any(row > 0)]
    sd = np.array([to_case_units(row) for row in budget.source_sd])
    total = to_case_units(budget.sd)
    lines = [
        f"variance budget ({budget.method}, linearised at the estimate): sd from each source "
        "(case units) and its share of the variance",
        f"{'constant':>9}" + "".join(f"{budget.sources[i]:>15}" for i in keep) + f"{'total':>10}",
    ]
    for j, key in enumerate(ENGINEERING_KEYS):
        cells = "".join(f"{sd[i, j]:#9.3g} ({100 * budget.share[i, j]:3.0f}%)" for i in keep)
        lines.append(f"{key:>9}{cells}{total[j]:#10.3g}")
    if budget.status == "approximate":
        lines.append(
            f"  frequencies + prior split with the full model's sensitivities at the "
            f"fast model's answer: they add up to its covariance within "
            f"{budget.closure:.1e}"
        )
    elif budget.status != "ok":
        lines.append(
            f"  budget status {budget.status}: the split of the estimator's own "
            f"covariance does not close (closure {budget.closure:.1e})"
        )
    return "\n".join(lines)


def _check_lines(result):
    """The full model's check of a fast-model answer, if there is one."""
    check = result.check
    if check is None:
        return []
    return [
        f"  fast model: built in {check.build_seconds:.1f} s ({check.build_solves} full "
        f"solves); {check} ({check.n_full_solves} full solves besides the build)"
    ]


def run(args):
    """Estimate the constants; print the table, write JSON on request."""
    from ..io import save_figure, write_json
    from ..run import EstimateOptions, run_estimate

    case = resolve_case(args.case)
    if not args.quiet:
        logging.getLogger("bayesplate.estimators").setLevel(logging.INFO)  # progress
    options = EstimateOptions(
        method=args.method,
        mesh=mesh_of(args),
        tol=args.tol,
        max_iter=args.max_iter,
        convention=args.convention,
        pairing=args.pairing,
        forward=args.forward,
    )
    done = run_estimate(case, options)
    result, budget, scale = done.result, done.budget, done.scale
    if args.json:
        write_json(done.document, args.json)
    if args.json != "-":
        print(estimate_text(case, done.model, result))
        if scale is not None:
            print(scale_text(scale))
            if budget is not None:
                print(
                    "the variance budget below is at s = 1 (the declared deviations): the "
                    "error scale widens the frequencies' share"
                )
        if budget is not None:
            print(budget_text(budget))
        sys.stdout.flush()  # the warnings follow the table
    print_warnings(result)
    if args.plots and budget is not None:
        from ..plots import variance_budget_bars

        path = Path(args.plots) / "variance_budget.png"
        save_figure(variance_budget_bars(budget, title=case.name), path)
    return 0 if result.converged else 1


def register(sub):
    """Add the ``estimate`` subcommand."""
    p = sub.add_parser(
        "estimate",
        help="estimate the elastic constants with the paper's B, MVE or MVE-mod",
        description="Iterate the Bayesian estimator B (eq. 9), the minimum variance "
        "estimator MVE (eq. 12) or the two-stage MVE-mod (section 5) of Daghia et al. "
        "(2007) from the case's prior to the measured frequencies. Every estimate states its "
        "fit (chi-square of the paired peaks with the declared deviations, degrees of "
        "freedom, p-value, worst residuals); an answer that should not be trusted (fit "
        "rejected, a constant far from its prior, most low modes unobserved) is reported "
        "as 'rejected' or 'implausible', with a warning on standard error. The exit status "
        "is 1 when the run does not converge (0 for a flagged answer). Progress goes to "
        "standard error.",
    )
    add_case_argument(p)
    p.add_argument(
        "--method", choices=METHOD_CHOICES, default="MVE", help="estimator (default MVE)"
    )
    p.add_argument("--tol", type=positive_float, default=1e-3, help="TOL of section 2.4 (1e-3)")
    p.add_argument(
        "--max-iter", type=positive_int, default=DEFAULT_MAX_ITER, help="iteration cap per stage"
    )
    p.add_argument(
        "--convention",
        choices=CONVENTION_CHOICES,
        default="paper",
        help="covariance conventions: 'paper' (default, reproduces the paper's tables; "
        "V_Y = diag(dlambda^2), V_b = diag(dC^2), MVE with fixed V_b), 'full-prior' (the "
        "full propagated prior covariance), 'printed' (section 3.6 as printed)",
    )
    add_pairing_option(p)
    p.add_argument(
        "--forward",
        choices=FORWARD_CHOICES,
        default="auto",
        help="model iterated on: 'fast' (the certified reduced-basis model over the prior's "
        "box, each answer checked by the full model; exit status 1 if they disagree), "
        "'full' (the finite-element model throughout), 'auto' (default: fast above 5,000 "
        "unknowns)",
    )
    add_mesh_option(p)
    add_json_option(p)
    p.add_argument(
        "--plots",
        metavar="DIR",
        help="write the variance budget figure (variance_budget.png: each constant's "
        "variance split by source) to DIR",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)
