"""The ``bayesplate`` command.

Every subcommand takes a case file (see ``bayesplate cases`` for the bundled ones); output is
a human-readable table by default and JSON with ``--json FILE`` (``-`` for standard output).
Units: frequencies in Hz, moduli in GPa, lengths in mm.
"""

from __future__ import annotations

import argparse
import logging
import pathlib
import sys

from . import case as case_module
from .case import CaseError, load_case
from .io import save_figure, write_json
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
        "`bayesplate report frederiksen_t300 --quick` (everything about one case in a folder).",
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
    _add_mesh_option(p)
    _add_json_option(p)
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


def _cmd_diagnose(args):
    from .discrepancy.diagnose import diagnose, diagnosis_to_dict

    case = _resolve_case(args.case)
    mesh = tuple(args.mesh) if args.mesh else None
    model = PlateModel.from_case(case, mesh=mesh)
    quiet = args.json == "-"
    d = diagnose(
        case,
        model=model,
        rng=args.seed,
        workers=args.workers,
        progress=None if quiet else (lambda msg: print(f"  {msg}", flush=True)),
    )
    if args.plots:
        from .plots import diagnosis_figures

        for name, fig in diagnosis_figures(model, d).items():
            save_figure(fig, pathlib.Path(args.plots) / f"{name}.png")
    if args.json:
        write_json(diagnosis_to_dict(d), args.json)
    if not quiet:
        print(_diagnosis_text(d))
    return 0


def _diagnosis_text(d):
    """Human-readable summary of a diagnosis."""
    lines = [
        f"verdict: {d.verdict}" + (f" ({d.chosen.name})" if d.chosen else ""),
        f"nominal fit: chi2 = {d.nominal.chi2:.1f} on {d.dof:.1f} dof, p = {d.p_value:.3g}",
    ]
    if d.located_modes:
        kinds = ", ".join(f"{i} ({d.mode_kinds[i - 1]})" for i in d.located_modes)
        lines.append(f"misfit carried by modes {kinds}")
    if d.region_mm is not None:
        lines.append(f"located near x = {d.region_mm[0]:.0f} mm, y = {d.region_mm[1]:.0f} mm")
    lines.append("candidates (evidence gain over the nominal model, nats):")
    for c in d.candidates:
        params = ", ".join(
            f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
            for k, v in c.parameters.items()
        )
        lines.append(f"  {c.name:22s} {c.log_evidence_gain:+8.1f}   {params}")
    if d.chosen is not None:
        lines.append(
            f"refit: chi2 = {d.chosen.fit.chi2:.1f} on {d.refit_dof:.1f} dof, "
            f"p = {d.refit_p_value:.3g}"
        )
    if d.unidentified:
        lines.append("unidentified by the data (prior dominates): " + ", ".join(d.unidentified))
    lines += [f"note: {n}" for n in d.notes]
    return "\n".join(lines)


def _add_mesh_option(p):
    """``--mesh NX NY``, shared by every command that builds the plate model."""
    p.add_argument(
        "--mesh",
        type=int,
        nargs=2,
        metavar=("NX", "NY"),
        help="elements along x and y (default: the case's [model] mesh)",
    )


def _add_json_option(p):
    """``--json FILE``, shared by every command that writes results."""
    p.add_argument("--json", metavar="FILE", help="write results as JSON ('-' for stdout)")


def _positive_int(text):
    """An integer of at least 1 (an argparse type)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a whole number of at least 1")
    return value


def _register_diagnose(sub):
    p = sub.add_parser(
        "diagnose",
        help="locate a model-data mismatch, name the missing physics, refit",
        description="Fit the nominal model, test it (chi-square), locate the misfit, rank "
        "candidate physics (point_mass, thickness_taper, ply_misalignment, "
        "elastic_foundation, local_stiffness_loss) by Laplace evidence, refit, and give a "
        "verdict: consistent, explained or unexplained.",
    )
    p.add_argument("case", help="case file (TOML) or the name of a bundled case")
    _add_mesh_option(p)
    p.add_argument("--seed", type=int, default=0, help="seed of the random fit starts")
    p.add_argument(
        "--workers",
        type=_positive_int,
        default=2,
        help="processes for the independent fits (default 2; the results do not depend on it)",
    )
    _add_json_option(p)
    p.add_argument("--plots", metavar="DIR", help="write figures (PNG) into DIR")
    p.set_defaults(func=_cmd_diagnose)


_EXTRA_COMMANDS.append(_register_diagnose)


_GPA_SCALE = (1e9, 1e9, 1.0, 1e9, 1e9, 1e9)  # SI -> case units (GPa, -)


def _estimate_dict(case, model, result):
    """The JSON document of ``bayesplate estimate``."""
    from .case import ENGINEERING_KEYS
    from .quantities import STIFFNESS_NAMES

    def constants(r):
        return {
            key: {"mean": float(m / s), "sd": float(d / s)}
            for key, m, d, s in zip(ENGINEERING_KEYS, r.constants, r.sd, _GPA_SCALE, strict=True)
        }

    conventions = result.settings.get("conventions")
    out = {
        "case": case.name,
        "method": result.method,
        "convention": None if conventions is None else vars(conventions),
        "mesh": [model.mesh.nx, model.mesh.ny],
        "converged": bool(result.converged),
        "iterations": int(result.iterations),
        "message": result.message,
        "n_solves": int(result.n_solves),
        "wall_time_s": float(result.wall_time),
        "constants": constants(result),
        "stiffness_GPa": dict(zip(STIFFNESS_NAMES, (result.b / 1e9).tolist(), strict=True)),
        "frequency_Hz": result.frequency_Hz,
        "measured_Hz": result.measured_Hz,
        "residual_Hz": result.residual,
        "modes": result.modes,
        "mode_swaps": [list(s) for s in result.mode_swaps],
    }
    if result.stages:
        out["stages"] = [
            {
                "converged": bool(s.converged),
                "iterations": int(s.iterations),
                "message": s.message,
                "constants": constants(s),
            }
            for s in result.stages
        ]
    return out


def _estimate_text(case, model, result):
    """Human-readable table of ``bayesplate estimate``."""
    from .case import ENGINEERING_KEYS

    status = "converged" if result.converged else "NOT converged"
    lines = [
        f"{case.name}",
        f"{result.method}, mesh {model.mesh.nx} x {model.mesh.ny}: {status} after "
        f"{result.iterations} iterations ({result.n_solves} forward solves, "
        f"{result.wall_time:.1f} s)",
        f"  {result.message}",
        f"{'constant':>9} {'estimate':>10} {'sd':>9} {'initial':>9}",
    ]
    prior = result.stages[0] if result.stages else result
    initial = prior.settings.get("prior_mean", case.prior.mean)
    for key, m, d, m0, s in zip(
        ENGINEERING_KEYS, result.constants, result.sd, initial, _GPA_SCALE, strict=True
    ):
        lines.append(f"{key:>9} {m / s:#10.4g} {d / s:#9.3g} {m0 / s:#9.4g}")
    head = ("mode", "measured_Hz", "computed_Hz", "diff_Hz", "diff_%")
    lines.append("{:>4} {:>12} {:>12} {:>9} {:>7}".format(*head))
    for i, (fm, fc) in enumerate(zip(result.measured_Hz, result.frequency_Hz, strict=True)):
        d = fc - fm
        lines.append(f"{result.modes[i]:>4} {fm:12.1f} {fc:12.1f} {d:9.1f} {100 * d / fm:7.2f}")
    return "\n".join(lines)


def _cmd_estimate(args):
    from .estimators import estimate

    case = _resolve_case(args.case)
    mesh = tuple(args.mesh) if args.mesh else None
    model = PlateModel.from_case(case, mesh=mesh)
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
    )
    if args.json:
        write_json(_estimate_dict(case, model, result), args.json)
    if args.json != "-":
        print(_estimate_text(case, model, result))
    return 0 if result.converged else 1


def _register_estimate(sub):
    from .estimators import CONVENTIONS, DEFAULT_MAX_ITER, METHODS

    p = sub.add_parser(
        "estimate",
        help="estimate the elastic constants with the paper's B, MVE or MVE-mod",
        description="Iterate the Bayesian estimator B (eq. 9), the minimum variance "
        "estimator MVE (eq. 12) or the two-stage MVE-mod (section 5) of Daghia et al. "
        "(2007) from the case's prior to the measured frequencies. The exit status is 1 "
        "when the run does not converge. Progress goes to standard error.",
    )
    p.add_argument("case", help="case file (TOML) or the name of a bundled case")
    p.add_argument("--method", choices=METHODS, default="MVE", help="estimator (default MVE)")
    p.add_argument("--tol", type=float, default=1e-3, help="TOL of section 2.4 (1e-3)")
    p.add_argument("--max-iter", type=int, default=DEFAULT_MAX_ITER, help="iteration cap per stage")
    p.add_argument(
        "--convention",
        choices=tuple(CONVENTIONS),
        default="paper",
        help="covariance conventions: 'paper' (default, reproduces the paper's tables; "
        "V_Y = diag(dlambda^2), V_b = diag(dC^2), MVE with fixed V_b), 'full-prior' (the "
        "full propagated prior covariance), 'printed' (section 3.6 as printed)",
    )
    p.add_argument(
        "--pairing",
        choices=("auto", "mac", "order", "index"),
        default="auto",
        help="measured-to-computed modes: by shape (MAC) when the case has measured shapes, "
        "else by the case's mode indices if any, else by order",
    )
    _add_mesh_option(p)
    _add_json_option(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=_cmd_estimate)


_EXTRA_COMMANDS.append(_register_estimate)


def _cmd_report(args):
    from .report import ReportOptions, make_report

    case = _resolve_case(args.case)
    options = ReportOptions(
        quick=args.quick,
        mesh=tuple(args.mesh) if args.mesh else None,
        seed=args.seed,
        diagnose=not args.no_diagnose,
        sample=not args.no_sample,
    )
    path, data = make_report(case.path, args.output, options, label=args.case)
    print(f"{path}: {len(data.computed)} steps computed, {len(data.reused)} reused from the cache")
    return 0


def _register_report(sub):
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
    p.add_argument("case", help="case file (TOML) or the name of a bundled case")
    p.add_argument("-o", "--output", default="report", metavar="DIR",
                   help="folder of the report (default: ./report)")  # fmt: skip
    p.add_argument(
        "--quick",
        action="store_true",
        help="a first look: half the mesh each way, one random start in diagnose, shorter "
        "posterior chains (nothing skipped)",
    )
    _add_mesh_option(p)
    p.add_argument("--seed", type=int, default=0, help="seed of diagnose and the sampler")
    p.add_argument("--no-diagnose", action="store_true", help="leave out the diagnosis")
    p.add_argument("--no-sample", action="store_true", help="leave out posterior sampling")
    p.set_defaults(func=_cmd_report)


_EXTRA_COMMANDS.append(_register_report)


def _sample_dict(case, result, mve):
    """The JSON document of ``bayesplate sample``."""
    from .io import constants_json

    est = result.estimate
    cert = result.certificate
    certificate = None
    if cert is not None:
        certificate = {
            "max_rel_error": cert.max_rel_error,
            "tolerance": cert.tolerance,
            "passed": bool(cert.passed),
            "n_test": cert.n_test,
            "basis_size": cert.basis_size,
        }
    return {
        "case": case.name,
        "constants": result.constants_table(),
        "ess_min": result.ess_min,
        "rhat_max": result.rhat_max,
        "ess_bulk": dict(zip(_CONSTANT_KEYS, result.ess_bulk.tolist(), strict=True)),
        "rhat": dict(zip(_CONSTANT_KEYS, result.rhat.tolist(), strict=True)),
        "converged": bool(result.converged),
        "message": result.message,
        "n_walkers": result.n_walkers,
        "n_steps": result.n_steps,
        "n_burn": result.n_burn,
        "tau_steps": result.tau,
        "acceptance": result.acceptance,
        "n_evaluations": result.n_evaluations,
        "n_full_solves_sampling": result.n_full,
        "n_full_solves_setup": result.settings.get("full_solves_setup"),
        "certificate": certificate,
        "timings_s": result.timings,
        "seed_entropy": result.settings.get("seed_entropy"),
        "estimates": {
            name: constants_json(r.constants, r.sd)
            for name, r in (("B", est), ("MVE", mve))
            if r is not None
        },
    }


_CONSTANT_KEYS = ("E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa")


def _sample_text(case, result):
    """Human-readable table of ``bayesplate sample``."""
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
        f"{'constant':>9} {'B (MAP)':>10} {'B sd':>9} {'post mean':>10} {'post sd':>9} "
        f"{'hdi 3%':>9} {'hdi 97%':>9} {'ESS':>6} {'R-hat':>6}",
    ]
    for i, key in enumerate(_CONSTANT_KEYS):
        s = _GPA_SCALE[i]
        lines.append(
            f"{key:>9} {est.constants[i] / s:#10.4g} {est.sd[i] / s:#9.3g} "
            f"{result.mean[i] / s:#10.4g} {result.sd[i] / s:#9.3g} {result.hdi[0, i] / s:#9.4g} "
            f"{result.hdi[1, i] / s:#9.4g} {result.ess_bulk[i]:6.0f} {result.rhat[i]:6.3f}"
        )
    return "\n".join(lines)


def _write_netcdf(idata, path):
    """Write ArviZ data whole or not at all (temporary file, then rename)."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        idata.to_netcdf(str(tmp))
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _cmd_sample(args):
    from .sampling import prepare, sample

    case = _resolve_case(args.case)
    mesh = tuple(args.mesh) if args.mesh else None
    model = PlateModel.from_case(case, mesh=mesh)
    quiet = args.json == "-"
    if not quiet:
        logging.getLogger("bayesplate.sampling").setLevel(logging.INFO)  # progress
    setup = prepare(case, model=model, forward="full" if args.full else "reduced", seed=args.seed,
                    pairing=args.pairing)  # fmt: skip
    result = sample(
        case,
        seed=args.seed,
        n_walkers=args.walkers,
        max_steps=args.max_steps,
        min_ess=args.min_ess,
        backend_path=args.backend,
        progress=not quiet,
        setup=setup,
    )
    mve = None
    if args.plots or args.json:
        mve = setup.run_estimator("MVE")
    if args.out:
        _write_netcdf(result.idata, args.out)
    if args.plots:
        from .plots import sampling_figures

        estimates = {"B": result.estimate, "MVE": mve}
        figs = sampling_figures(result, estimates, case.reference, title=case.name)
        for name, fig in figs.items():
            save_figure(fig, pathlib.Path(args.plots) / f"{name}.png")
    if args.json:
        write_json(_sample_dict(case, result, mve), args.json)
    if not quiet:
        print(_sample_text(case, result))
    return 0 if result.converged else 1


def _register_sample(sub):
    p = sub.add_parser(
        "sample",
        help="sample the posterior of the constants with emcee (checks B's covariance)",
        description="Sample the posterior of the estimators' Gaussian problem (same V_Y, "
        "prior and pairing as `bayesplate estimate`, paper conventions) with emcee, on a "
        "certified reduced-basis model around the B estimate (full-model fallback). Stops "
        "when the chain is longer than 50 autocorrelation times and every constant has "
        "--min-ess effective samples, or at --max-steps. The exit status is 1 when the "
        "stopping rule was not met. Progress goes to standard error.",
    )
    p.add_argument("case", help="case file (TOML) or the name of a bundled case")
    p.add_argument("--seed", type=int, default=None, help="seed (default: fresh entropy)")
    p.add_argument("--walkers", type=int, default=32, help="emcee walkers (default 32)")
    p.add_argument("--max-steps", type=int, default=5000, help="cap on steps (default 5000)")
    p.add_argument("--min-ess", type=float, default=2000.0,
                   help="effective samples per constant to reach (default 2000)")  # fmt: skip
    p.add_argument("--out", metavar="FILE.nc", help="write the ArviZ data (netCDF)")
    p.add_argument("--backend", metavar="FILE.h5",
                   help="keep the chain in this HDF5 file; re-running continues it")  # fmt: skip
    p.add_argument("--full", action="store_true", help="sample the full model (slow)")
    p.add_argument(
        "--pairing",
        choices=("auto", "mac", "index", "order"),
        default="auto",
        help="measured-to-computed modes (default: by shape, else mode numbers, else order)",
    )
    _add_mesh_option(p)
    _add_json_option(p)
    p.add_argument("--plots", metavar="DIR",
                   help="write corner.png (with B and MVE ellipses), trace.png, "
                   "autocorrelation.png into DIR")  # fmt: skip
    p.set_defaults(func=_cmd_sample)


_EXTRA_COMMANDS.append(_register_sample)


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
