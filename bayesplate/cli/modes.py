"""``bayesplate modes``: computed natural frequencies beside the measured ones."""

from __future__ import annotations

from .options import (
    add_case_argument,
    add_json_option,
    add_mesh_option,
    mesh_of,
    positive_int,
    resolve_case,
)

__all__ = ["register"]


def _constants(case, which):
    """Engineering constants (SI) chosen by ``--constants``."""
    from ..io import CaseError

    if which == "prior":
        return case.prior.mean
    if case.reference is None:
        raise CaseError("reference", None, "--constants reference needs a [reference] table")
    return case.reference


def run(args):
    """Solve the plate at the chosen constants; print (or write) the frequencies."""
    from ..io import write_json
    from ..laminate import stiffness_from_engineering
    from ..plate.model import PlateModel

    case = resolve_case(args.case)
    e = _constants(case, args.constants)
    measured = case.measured.frequency_Hz
    count = args.count or len(measured)
    model = PlateModel.from_case(case, mesh=mesh_of(args))
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


def register(sub):
    """Add the ``modes`` subcommand."""
    p = sub.add_parser("modes", help="computed natural frequencies beside the measured ones")
    add_case_argument(p)
    p.add_argument(
        "--constants",
        choices=("prior", "reference"),
        default="prior",
        help="evaluate at the prior mean (default) or the [reference] constants",
    )
    p.add_argument(
        "--count", type=positive_int, help="number of elastic modes (default: as measured)"
    )
    add_mesh_option(p)
    add_json_option(p)
    p.set_defaults(func=run)
