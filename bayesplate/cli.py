"""The ``bayesplate`` command.

Every subcommand takes a case file (see ``bayesplate cases`` for the bundled ones); output is
a human-readable table by default and JSON with ``--json FILE`` (``-`` for standard output).
Units: frequencies in Hz, moduli in GPa, lengths in mm.
"""

from __future__ import annotations

import argparse
import logging
import sys

from . import case as case_module
from .case import CaseError, load_case
from .io import write_json
from .laminate import stiffness_from_engineering
from .model import PlateModel

__all__ = ["main", "build_parser"]


def _resolve_case(name_or_path):
    """Load a case from a path, or from the bundled cases by name (``plate1``)."""
    import pathlib

    if not pathlib.Path(name_or_path).exists() and name_or_path in case_module.bundled_case_names():
        name_or_path = case_module.bundled_case_path(name_or_path)
    return load_case(name_or_path)


def _constants(case, which):
    """Engineering constants (SI) chosen by ``--constants``."""
    if which == "prior":
        return case.prior.mean
    if case.reference is None:
        raise CaseError("reference", None, "--constants reference needs a [reference] table")
    return case.reference


def _cmd_modes(args):
    case = _resolve_case(args.case)
    e = _constants(case, args.constants)
    measured = case.measured.frequency_Hz
    count = args.count or len(measured)
    mesh = tuple(args.mesh) if args.mesh else None
    model = PlateModel.from_case(case, mesh=mesh)
    result = model.solve(stiffness_from_engineering(e), count)
    f = result.frequency_Hz
    if args.json:
        write_json(
            {
                "case": case.name,
                "constants": args.constants,
                "mesh": [model.mesh.nx, model.mesh.ny],
                "frequency_Hz": f,
                "measured_Hz": measured,
                "rigid_body_modes": result.n_rigid,
            },
            args.json,
        )
        if args.json == "-":
            return 0
    print(
        f"{case.name}\nmesh {model.mesh.nx} x {model.mesh.ny}, constants: {args.constants}, "
        f"{result.n_rigid} rigid-body modes dropped"
    )
    print(f"{'mode':>4} {'computed_Hz':>12} {'measured_Hz':>12} {'diff_Hz':>9} {'diff_%':>7}")
    for i, fi in enumerate(f):
        if i < len(measured):
            d = fi - measured[i]
            pct = 100 * d / measured[i]
            print(f"{i + 1:>4} {fi:12.1f} {measured[i]:12.1f} {d:9.1f} {pct:7.2f}")
        else:
            print(f"{i + 1:>4} {fi:12.1f}")
    return 0


def _cmd_cases(args):
    for name in case_module.bundled_case_names():
        print(f"{name:20s} {case_module.bundled_case_path(name)}")
    return 0


def build_parser():
    """The argument parser of the ``bayesplate`` command."""
    parser = argparse.ArgumentParser(
        prog="bayesplate",
        description="Elastic constants of laminated plates from natural frequencies. "
        "Start with `bayesplate cases` (bundled test cases), then "
        "`bayesplate modes frederiksen_t300`.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("cases", help="list the bundled case files")
    p.set_defaults(func=_cmd_cases)
    p = sub.add_parser("modes", help="computed natural frequencies beside the measured ones")
    p.add_argument("case", help="case file (TOML) or the name of a bundled case")
    p.add_argument(
        "--constants",
        choices=("prior", "reference"),
        default="prior",
        help="evaluate at the prior mean (default) or the [reference] constants",
    )
    p.add_argument("--count", type=int, help="number of elastic modes (default: as measured)")
    p.add_argument(
        "--mesh",
        type=int,
        nargs=2,
        metavar=("NX", "NY"),
        help="elements along x and y (default: the case's [model] mesh)",
    )
    p.add_argument("--json", metavar="FILE", help="write results as JSON ('-' for stdout)")
    p.set_defaults(func=_cmd_modes)
    for register in _EXTRA_COMMANDS:
        register(sub)
    return parser


#: Functions ``register(subparsers)`` adding further subcommands (estimate, sample, ...).
_EXTRA_COMMANDS = []


def _cmd_import(args):
    import pathlib

    from .importers import (
        bundled_plate_names,
        bundled_plate_path,
        case_from_modal_data,
        read_modal_data,
        write_case,
    )

    if args.sigma_rel is not None and not 0 < args.sigma_rel < 1:
        raise CaseError("--sigma-rel", args.sigma_rel, "must be > 0 and < 1")
    plate = args.plate
    if not pathlib.Path(plate).exists() and plate in bundled_plate_names():
        plate = bundled_plate_path(plate)
    modal = read_modal_data(args.test)
    text = case_from_modal_data(plate, modal, sigma_rel=args.sigma_rel)
    try:
        write_case(args.output, text)
    except OSError as err:
        raise CaseError("-o", args.output, f"cannot write ({err.strerror or err})") from None
    print(f"{modal.size} modes, {modal.n_points} points from {args.test} -> {args.output}")
    return 0


def _register_import(sub):
    p = sub.add_parser(
        "import",
        help="make a case file from a modal test (UFF or CSV) and a plate sheet",
        description="Combine measured modes with a plate sheet (a case file without "
        "[measured] frequencies) into a case file. UFF: dataset 55 per mode, node "
        "coordinates from dataset 15 or 2411, units from dataset 164 (default mm); the z "
        "component of each shape is kept. CSV: a header with frequency_Hz and optionally "
        "sigma_Hz or sigma_rel, and mode.",
    )
    p.add_argument("test", metavar="TEST", help="measured modes: .uff/.unv/.uf or .csv")
    p.add_argument(
        "--plate",
        required=True,
        help="plate sheet (TOML) or the name of a bundled one (frederiksen_plate)",
    )
    p.add_argument("-o", "--output", required=True, metavar="CASE", help="case file to write")
    p.add_argument(
        "--sigma-rel",
        type=float,
        help="relative standard deviation of each frequency (default: the sheet's, else 0.01)",
    )
    p.set_defaults(func=_cmd_import)


_EXTRA_COMMANDS.append(_register_import)


def main(argv=None):
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s"
    )
    if getattr(args, "count", None) is not None and args.count < 1:
        parser.error(f"--count {args.count}: must be a positive integer")
    try:
        return args.func(args)
    except CaseError as err:
        print(f"bayesplate: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
