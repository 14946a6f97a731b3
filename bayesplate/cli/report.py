"""``bayesplate report``: everything about a case in one folder, report.md and its figures."""

from __future__ import annotations

from .options import (
    add_case_argument,
    add_mesh_option,
    add_pairing_option,
    mesh_of,
    resolve_case,
    seed_int,
)

__all__ = ["register"]


def run(args):
    """Make (or update) the report folder of a case."""
    from ..report import ReportOptions, make_report

    case = resolve_case(args.case)
    options = ReportOptions(
        quick=args.quick,
        mesh=mesh_of(args),
        seed=args.seed,
        diagnose=not args.no_diagnose,
        sample=not args.no_sample,
        pairing=args.pairing,
    )
    path, data = make_report(case.path, args.output, options, label=args.case)
    print(f"{path}: {len(data.computed)} steps computed, {len(data.reused)} reused from the cache")
    return 0


def register(sub):
    """Add the ``report`` subcommand."""
    p = sub.add_parser(
        "report",
        help="everything about a case in one folder: report.md and its figures",
        description="Run the whole analysis of a case and write DIR/report.md with its "
        "figures: the case and prior, mode pairing (by shape when the case has measured "
        "shapes), the B, MVE and MVE-mod estimates side by side, per-mode residuals, "
        "sensitivities, mode shapes, the sampled posterior (when bayesplate.sampling is "
        "installed) and the model-discrepancy diagnosis. Every step's result is cached in "
        "DIR/.cache: a re-run reuses what still matches the case file and options. Progress "
        "goes to standard error.",
    )
    add_case_argument(p)
    p.add_argument("-o", "--output", default="report", metavar="DIR",
                   help="folder of the report (default: ./report)")  # fmt: skip
    p.add_argument(
        "--quick",
        action="store_true",
        help="a first look: half the mesh each way, one random start in diagnose, shorter "
        "posterior chains (nothing skipped)",
    )
    add_mesh_option(p)
    add_pairing_option(p)
    p.add_argument("--seed", type=seed_int, default=0, help="seed of diagnose and the sampler")
    p.add_argument("--no-diagnose", action="store_true", help="leave out the diagnosis")
    p.add_argument("--no-sample", action="store_true", help="leave out posterior sampling")
    p.set_defaults(func=run)
