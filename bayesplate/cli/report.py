"""``bayesplate report``: everything about a case in one folder, report.md and its figures."""

from __future__ import annotations

from .options import (
    add_mesh_option,
    add_pairing_option,
    mesh_of,
    positive_int,
    resolve_case,
    seed_int,
)

__all__ = ["register"]


def run(args):
    """Make (or update) the report folder of a case."""
    from ..io import CaseError
    from ..report import ReportOptions, make_report

    case_file, taps = args.case, None
    if args.taps:
        case_file, taps = _from_taps(args)
    elif args.case is None:
        raise CaseError("CASE", rule="give a case file, or --taps with --plate")
    case = resolve_case(case_file)
    options = ReportOptions(
        quick=args.quick,
        mesh=mesh_of(args),
        seed=args.seed,
        diagnose=not args.no_diagnose,
        sample=not args.no_sample,
        pairing=args.pairing,
    )
    path, data = make_report(case.path, args.output, options, label=str(case_file), taps=taps)
    print(f"{path}: {len(data.computed)} steps computed, {len(data.reused)} reused from the cache")
    return _print_pdf(path) if args.pdf else 0


def _print_pdf(report_md):
    """``--pdf``: report.html printed beside it; exit status 2, the report kept, on failure."""
    import sys

    from ..report.pdf import PdfError, print_pdf

    try:
        pdf = print_pdf(report_md.with_name("report.html"))
    except PdfError as err:
        print(f"bayesplate report: error: --pdf: {err}", file=sys.stderr)
        return 2
    print(f"{pdf}: the report page printed")
    return 0


def _from_taps(args):
    """``--taps``: the case written into the report's folder by ``import``; the tap test."""
    import pathlib

    from ..io import CaseError
    from .import_case import import_taps

    if args.plate is None:
        raise CaseError("--plate", rule="required with --taps: the plate sheet (TOML)")
    if args.case is not None:
        raise CaseError("CASE", args.case, "give a case file or --taps, not both")
    out = pathlib.Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    case_file = out / "case.toml"
    return case_file, import_taps(args.taps, args.plate, case_file, args.modes)


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
    p.add_argument("case", nargs="?", help="case file (TOML) or the name of a bundled case")
    taps = p.add_argument_group("from a tap test (instead of CASE)")
    taps.add_argument(
        "--taps",
        nargs="+",
        metavar="TAP",
        help="the recordings (WAV or CSV time series), imported as "
        "`bayesplate import` does with no options into DIR/case.toml",
    )
    taps.add_argument("--plate", metavar="SHEET", help="the plate sheet (TOML), with --taps")
    taps.add_argument(
        "--modes",
        type=positive_int,
        metavar="N",
        help="modes wanted from the taps (`bayesplate import --modes`)",
    )
    p.add_argument(
        "-o",
        "--output",
        default="report",
        metavar="DIR",
        help="folder of the report (default: ./report)",
    )
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
    p.add_argument(
        "--pdf",
        action="store_true",
        help="also DIR/report.pdf: report.html printed by a headless Chromium (apt-get "
        "install chromium, or name one in BAYESPLATE_CHROMIUM)",
    )
    p.set_defaults(func=run)
