"""``bayesplate sample``: the posterior of the constants with emcee (checks B's covariance).

One case: its posterior, as always. Several cases: plates of one material, sampled jointly
(:func:`bayesplate.sampling.sample_plates`: the six constants shared, one prior, the first
case's); the material's constants, then one line per plate with its own fit and whether it
disagrees with the others (:mod:`bayesplate.sampling.plate_checks`). Cases that cannot be one
material's plates are refused in one line naming the file, key, value and rule (status 2).
"""

from __future__ import annotations

import logging
import pathlib

from .options import (
    add_json_option,
    add_mesh_option,
    add_pairing_option,
    chain_steps,
    mesh_of,
    positive_float,
    positive_int,
    resolve_case,
    seed_int,
    walker_count,
)

__all__ = ["register"]


def sample_text(case, result):
    """Human-readable table of ``bayesplate sample``."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    est = result.estimate
    lines = [
        f"{case.name}",
        f"emcee: {result.n_walkers} walkers x {result.n_steps} steps ({result.n_burn} burn-in), "
        f"acceptance {result.acceptance:.2f}, tau <= {max(result.tau):.1f} steps; "
        f"{result.message}",
        f"ESS >= {result.ess_min:.0f}, R-hat <= {result.rhat_max:.3f}; "
        f"{result.n_evaluations} evaluations, {result.n_full} full solves while sampling; "
        f"{result.timings.get('total', result.wall_time):.1f} s in all",
        f"fast model: {result.certificate or 'none (the full model)'}",
        _inputs_line(case, result.settings.get("inputs", "exact")),
        f"{'constant':>9} {'B (MAP)':>10} {'B sd':>9} {'post mean':>10} {'post sd':>9} "
        f"{'hdi 3%':>9} {'hdi 97%':>9} {'ESS':>6} {'R-hat':>6}",
    ]
    b_mean, b_sd = to_case_units(est.constants), to_case_units(est.sd)
    mean, sd, hdi = (to_case_units(v) for v in (result.mean, result.sd, result.hdi))
    for i, key in enumerate(ENGINEERING_KEYS):
        lines.append(
            f"{key:>9} {b_mean[i]:#10.4g} {b_sd[i]:#9.3g} "
            f"{mean[i]:#10.4g} {sd[i]:#9.3g} {hdi[0, i]:#9.4g} "
            f"{hdi[1, i]:#9.4g} {result.ess_bulk[i]:6.0f} {result.rhat[i]:6.3f}"
        )
    return "\n".join(lines + _input_rows(result) + _assignment_lines(result))


def _assignment_lines(result):
    """Pairing by likelihood: how the chain treated the assignment, one line.

    Then one line per peak whose assignment was not the same in all draws.
    """
    note = result.settings.get("assignment")
    if note is None:
        return []
    lines = [note]
    if result.assignment is not None:
        varying = result.assignment.lines()
        lines += varying or [
            f"every peak kept one assignment in all {result.assignment.n_draws} draws"
        ]
    return lines


def _input_rows(result):
    """The declared inputs' posterior beside their declared value and sd, and the certificate.

    None of it when the inputs were exact (or none was declared).
    """
    lines = []
    posterior = result.input_posterior
    if posterior is not None:
        lines.append(
            f"{'input':>13} {'declared':>10} {'decl. sd':>9} {'post mean':>10} "
            f"{'post sd':>9} {'hdi 3%':>9} {'hdi 97%':>9}  "
            f"({len(posterior.rows)} draws, one per kept draw)"
        )
        for key, row in posterior.table().items():
            lines.append(
                f"{key:>13} {row['declared']:#10.4g} {row['declared_sd']:#9.3g} "
                f"{row['mean']:#10.4g} {row['sd']:#9.3g} {row['hdi_3%']:#9.4g} "
                f"{row['hdi_97%']:#9.4g}"
            )
    certificate = result.input_certificate
    if certificate is not None:
        warning = "" if certificate.passed else "WARNING: "
        lines.append(f"{warning}{certificate}")
    return lines


def _inputs_line(case, inputs):
    """Which treatment of the plate's inputs the posterior used, with their deviations."""
    from ..likelihood.inputs import describe_inputs

    given = describe_inputs(case.plate)
    if inputs == "marginal":
        return f"inputs: marginal (linearised), sd {given}"
    if given != "none":
        return f"inputs: exact (the case's sd {given} left out)"
    return "inputs: exact (the case gives no sd)"


def run(args):
    """Sample the posterior; print the table, write JSON, netCDF and figures on request."""
    if len(args.case) > 1:
        from .sample_plates import run_plates

        return run_plates(args)
    if args.hierarchical:
        return _refuse("--hierarchical needs several case files (plates of one material)")
    args.case = args.case[0]
    args.plots = args.plots or args.output
    return _run_one(args)


def _refuse(rule):
    """One line on standard error, status 2."""
    import sys

    print(f"bayesplate sample: error: {rule}", file=sys.stderr)
    return 2


def _run_one(args):
    """One case: the posterior of its constants (the command's behaviour before issue 17)."""
    from ..io import save_figure, write_json, write_netcdf
    from ..run import SampleOptions, run_sample

    case = resolve_case(args.case)
    quiet = args.json == "-"
    if not quiet:
        logging.getLogger("bayesplate.sampling").setLevel(logging.INFO)  # progress
    options = SampleOptions(
        mesh=mesh_of(args),
        walkers=args.walkers,
        max_steps=args.max_steps,
        min_ess=args.min_ess,
        forward="full" if args.full else "reduced",
        pairing=args.pairing,
        inputs=args.inputs or "auto",
        backend=args.backend,
        mve=bool(args.plots or args.json),
    )
    with _walker_pool(args) as pool:
        done = run_sample(case, options, args.seed, pool=pool, progress=not quiet)
    result, scale = done.result, done.scale
    if args.out:
        write_netcdf(result.idata, args.out)
    if args.plots:
        from ..plots import sampling_figures

        estimates = {"B": result.estimate, "MVE": done.mve}
        figs = sampling_figures(result, estimates, case.reference, title=case.name)
        for name, fig in figs.items():
            save_figure(fig, pathlib.Path(args.plots) / f"{name}.png")
    if args.json:
        write_json(done.document, args.json)
    if not quiet:
        print(sample_text(case, result))
        if scale is not None:
            print(f"{scale} (one draw of s per kept draw of the constants)")
    certified = result.input_certificate is None or result.input_certificate.passed
    return 0 if result.converged and certified else 1


def _walker_pool(args):
    """The walkers' pool: none (this process) unless ``--workers`` > 1 or ``--scheduler``.

    The pool is the batch engine's :class:`~bayesplate.batch.TaskPool` (Dask): each step's
    walkers are split in one chunk per worker. It pays where a log-density is a full solve
    (``--full``: seconds each); on the certified fast model (a fraction of a millisecond) the
    round trips cost more than they save.
    """
    import contextlib

    if args.scheduler is None and (args.workers or 1) == 1:
        return contextlib.nullcontext(None)
    from ..batch import TaskPool

    return TaskPool(workers=args.workers, scheduler=args.scheduler)


def register(sub):
    """Add the ``sample`` subcommand."""
    p = sub.add_parser(
        "sample",
        help="sample the posterior of the constants with emcee (checks B's covariance)",
        description="Sample the posterior of the estimators' Gaussian problem (same V_Y, "
        "prior and pairing as `bayesplate estimate`, paper conventions) with emcee, on a "
        "certified reduced-basis model around the B estimate (full-model fallback). Stops "
        "when the chain is longer than 50 autocorrelation times and every constant has "
        "--min-ess effective samples, or at --max-steps. The exit status is 1 when the "
        "stopping rule was not met, or when the linear input model (with input deviations "
        "in the case) fails its certificate. Progress goes to standard error. Several case "
        "files: plates of one material (one prior, the first case's, stated by every case), "
        "the six constants shared; each plate is checked against the others (flagged at 1 %%).",
    )
    p.add_argument(
        "case",
        nargs="+",
        help="case file (TOML) or the name of a bundled case; several: plates of "
        "one material, sampled jointly",
    )
    p.add_argument(
        "--hierarchical",
        action="store_true",
        help="several plates: the population instead of shared constants: the "
        "material's mean and plate-to-plate spread per constant, each plate "
        "shrunk towards it, each plate's outlier probability (--workers builds "
        "the plates' fast models in parallel; -o DIR: population.png)",
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="DIR",
        help="write the figures into DIR (several plates: plates.png, one row per "
        "plate beside the shared estimate; one case: as --plots)",
    )
    p.add_argument("--seed", type=seed_int, default=None, help="seed (default: fresh entropy)")
    p.add_argument("--walkers", type=walker_count, default=32, help="emcee walkers (default 32)")
    p.add_argument(
        "--max-steps", type=chain_steps, default=5000, help="cap on steps (default 5000)"
    )
    p.add_argument(
        "--min-ess",
        type=positive_float,
        default=2000.0,
        help="effective samples per constant to reach (default 2000)",
    )
    p.add_argument("--out", metavar="FILE.nc", help="write the ArviZ data (netCDF)")
    p.add_argument(
        "--backend",
        metavar="FILE.h5",
        help="keep the chain in this HDF5 file; re-running continues it",
    )
    p.add_argument("--full", action="store_true", help="sample the full model (slow)")
    p.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help="evaluate the walkers on this many Dask worker processes (a local "
        "cluster; worth it with --full; default: this process)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="evaluate the walkers on a running Dask scheduler (tcp://HOST:8786) instead",
    )
    p.add_argument(
        "--inputs",
        choices=("exact", "marginal"),
        default=None,
        help="the plate's thickness, density, length and width as exact numbers, "
        "or their case deviations (plate.*_sd) marginalised to first order "
        "(default: marginal when the case gives any deviation)",
    )
    add_pairing_option(p)
    add_mesh_option(p)
    add_json_option(p)
    p.add_argument(
        "--plots",
        metavar="DIR",
        help="write corner.png (with B and MVE ellipses), trace.png, autocorrelation.png into DIR",
    )
    p.set_defaults(func=run)
