"""``bayesplate estimate``: the paper's estimators B, MVE and MVE-mod on a case."""

from __future__ import annotations

import logging

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

    status = "converged" if result.converged else "NOT converged"
    lines = [
        f"{case.name}",
        f"{result.method}, mesh {model.mesh.nx} x {model.mesh.ny}: {status} after "
        f"{result.iterations} iterations ({result.n_solves} forward solves, "
        f"{result.wall_time:.1f} s)",
        f"  {result.message}",
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
    from ..estimators import estimate
    from ..io import estimate_to_dict, write_json
    from ..model import PlateModel

    case = resolve_case(args.case)
    model = PlateModel.from_case(case, mesh=mesh_of(args))
    if not args.quiet:
        logging.getLogger("bayesplate.estimators").setLevel(logging.INFO)  # progress
    result = estimate(
        case,
        args.method,
        model=model,
        tol=args.tol,
        max_iter=args.max_iter,
        convention=args.convention,
        pairing=args.pairing,
        forward=args.forward,
    )
    if args.json:
        write_json(estimate_to_dict(result, case, model), args.json)
    if args.json != "-":
        print(estimate_text(case, model, result))
    return 0 if result.converged else 1


def register(sub):
    """Add the ``estimate`` subcommand."""
    p = sub.add_parser(
        "estimate",
        help="estimate the elastic constants with the paper's B, MVE or MVE-mod",
        description="Iterate the Bayesian estimator B (eq. 9), the minimum variance "
        "estimator MVE (eq. 12) or the two-stage MVE-mod (section 5) of Daghia et al. "
        "(2007) from the case's prior to the measured frequencies. The exit status is 1 "
        "when the run does not converge. Progress goes to standard error.",
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
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)
