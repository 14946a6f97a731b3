"""``bayesplate import``: a case file from a modal test (UFF or CSV) and a plate sheet."""

from __future__ import annotations

import pathlib

from ..io import (
    CaseError,
    bundled_plate_names,
    bundled_plate_path,
    case_from_modal_data,
    read_modal_data,
    write_case,
)

__all__ = ["register"]


def run(args):
    """Read the test file, combine it with the plate sheet, write the case file."""
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


def register(sub):
    """Add the ``import`` subcommand."""
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
    p.set_defaults(func=run)
