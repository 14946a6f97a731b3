"""``bayesplate sample A.toml B.toml ...``: plates of one material, their shared constants.

The joint posterior (:func:`bayesplate.sampling.sample_plates`), printed as the material's
constants and one line per plate (its own B estimate's fit and the leave-one-out check
against the others); ``--json FILE`` writes the same as JSON, ``-o DIR`` the figure (one
row per plate beside the shared estimate), ``--out FILE.nc`` the shared constants' ArviZ
data. ``--hierarchical`` samples the population instead
(:func:`bayesplate.sampling.sample_population`: each plate's fast model built on the batch
engine's pool, :func:`bayesplate.batch.map_tasks`, ``--workers`` of them; the material's mean
and spread per constant, every plate's constants shrunk towards them beside its own answer,
each plate's outlier probability; ``--out`` the population's ArviZ data, ``-o DIR``
``population.png``). Cases that cannot be one
material's plates (another prior, a file given twice, an error scale) are refused in one
line naming the file, key, value and rule (status 2).
"""

from __future__ import annotations

import logging
import os
import pathlib
import sys

from .options import mesh_of, resolve_case

__all__ = [
    "fit_plates",
    "hierarchical_text",
    "joint_text",
    "joint_to_dict",
    "run_plates",
    "run_population",
]

#: Options of ``sample`` that one case takes and several do not (yet).
_ONE_CASE_ONLY = (("workers", "--workers"), ("scheduler", "--scheduler"), ("plots", "--plots"))


def _refuse(rule):
    print(f"bayesplate sample: error: {rule}", file=sys.stderr)
    return 2


def _load(names):
    """The cases, in order; a file given twice is refused (CaseError naming it)."""
    from ..io import CaseError

    seen = {}
    cases = []
    for k, name in enumerate(names):
        case = resolve_case(name)
        key = os.path.realpath(case.path) if case.path else name
        if key in seen:
            raise CaseError(
                "case",
                f"argument {k + 1}, the file of argument {seen[key] + 1}",
                "each plate's case file may be given once",
                path=case.path,
            )
        seen[key] = k
        cases.append(case)
    return cases


def joint_text(result):
    """Human-readable table of a joint posterior: constants, then one line per plate."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    s = result.sampling
    lines = [
        f"{len(result.names)} plates of one material (prior: {result.names[0]}'s), the six "
        "constants shared",
        f"emcee: {s.n_walkers} walkers x {s.n_steps} steps ({s.n_burn} burn-in), acceptance "
        f"{s.acceptance:.2f}, tau <= {max(s.tau):.1f} steps; {s.message}",
        f"ESS >= {s.ess_min:.0f}, R-hat <= {s.rhat_max:.3f}; {s.n_evaluations} evaluations, "
        f"{s.n_full} full solves while sampling; {result.timings['total']:.1f} s in all",
        f"{'constant':>9} {'post mean':>10} {'post sd':>9} {'hdi 3%':>9} {'hdi 97%':>9} "
        f"{'ESS':>6} {'R-hat':>6}",
    ]
    mean, sd, hdi = (to_case_units(v) for v in (s.mean, s.sd, s.hdi))
    for i, key in enumerate(ENGINEERING_KEYS):
        lines.append(
            f"{key:>9} {mean[i]:#10.4g} {sd[i]:#9.3g} {hdi[0, i]:#9.4g} "
            f"{hdi[1, i]:#9.4g} {s.ess_bulk[i]:6.0f} {s.rhat[i]:6.3f}"
        )
    lines.append(
        "plates: chi2 at the joint mean (m modes); q, p: the others' prediction "
        "(flagged below p = 0.01); own B estimate E1, E2, G12 (GPa)"
    )
    for est, c in zip(result.setup.singles, result.checks, strict=True):
        own = to_case_units(est.constants)
        flag = "FLAGGED" if c.status == "flagged" else c.status
        lines.append(
            f"  {c.name}: chi2 {c.chi2_joint:.1f} ({c.m}), q {c.chi2_rest:.1f} "
            f"p {c.p_rest:.2g} {flag}; own {own[0]:.4g}, {own[1]:.4g}, "
            f"{own[3]:.4g}"
        )
    return "\n".join(lines)


def joint_to_dict(result, cases):
    """The JSON document of a joint posterior (``bayesplate sample A B ... --json``)."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    s = result.sampling
    mean, sd, hdi = (to_case_units(v) for v in (s.mean, s.sd, s.hdi))
    constants = {
        key: {
            "mean": float(mean[i]),
            "sd": float(sd[i]),
            "hdi_3%": float(hdi[0, i]),
            "hdi_97%": float(hdi[1, i]),
            "ess_bulk": float(s.ess_bulk[i]),
            "r_hat": float(s.rhat[i]),
        }
        for i, key in enumerate(ENGINEERING_KEYS)
    }
    plates = []
    for case, est, c in zip(cases, result.setup.singles, result.checks, strict=True):
        own, own_sd = to_case_units(est.constants), to_case_units(est.sd)
        plates.append(
            {
                "name": c.name,
                "file": case.path,
                "m": c.m,
                "chi2_joint": c.chi2_joint,
                "p_joint": c.p_joint,
                "q_others": c.chi2_rest,
                "p_others": c.p_rest,
                "flagged": c.flagged,
                "status": c.status,
                "own_B": {
                    k: {"value": float(own[i]), "sd": float(own_sd[i])}
                    for i, k in enumerate(ENGINEERING_KEYS)
                },
            }
        )
    return {
        "status": result.status,
        "prior_from": cases[0].path or result.names[0],
        "constants": constants,
        "plates": plates,
        "flagged": [result.names[i] for i in result.flagged],
        "chain": {
            "n_walkers": s.n_walkers,
            "n_steps": s.n_steps,
            "n_burn": s.n_burn,
            "converged": bool(s.converged),
            "message": s.message,
            "n_full": s.n_full,
            "rebuilt": list(result.setup.rebuilt),
        },
        "timings": {k: float(v) for k, v in result.timings.items()},
    }


def run_plates(args):
    """Several cases: the joint posterior, its table, JSON, netCDF and figure on request."""
    from ..io import CaseError, save_figure, write_json, write_netcdf
    from ..plate.model import PlateModel
    from ..sampling import PlatesMismatch, sample_plates

    for attr, option in _ONE_CASE_ONLY:
        if getattr(args, attr, None) and not (args.hierarchical and attr == "workers"):
            return _refuse(f"{option} is for one case file (several plates: not yet)")
    cases = _load(args.case)
    if args.hierarchical:
        return run_population(args, cases)
    quiet = args.json == "-"
    if not quiet:
        logging.getLogger("bayesplate.sampling").setLevel(logging.INFO)
    models = [PlateModel.from_case(c, mesh=mesh_of(args)) for c in cases]
    try:
        result = sample_plates(
            cases,
            rng=args.seed,
            n_walkers=args.walkers,
            max_steps=args.max_steps,
            min_ess=args.min_ess,
            backend_path=args.backend,
            progress=not quiet,
            models=models,
            forward="full" if args.full else "reduced",
            pairing=args.pairing,
            inputs=args.inputs or "auto",
        )
    except PlatesMismatch as err:
        raise CaseError(err.key, err.value, err.rule, path=cases[err.index].path) from None
    if args.out:
        write_netcdf(result.sampling.idata, args.out)
    if args.output:
        from ..plots.plates import plate_rows, plates_figure

        rows, shared = plate_rows(result)
        fig = plates_figure(rows, shared, title=f"{len(cases)} plates of one material")
        save_figure(fig, pathlib.Path(args.output) / "plates.png")
    if args.json:
        write_json(joint_to_dict(result, cases), args.json)
    if not quiet:
        print(joint_text(result))
    return 0 if result.sampling.converged else 1


def _fit_task(item):
    """One plate's fit for the pool: its model, setup and Laplace (a PlateFit)."""
    import warnings

    from ..plate.model import PlateModel
    from ..sampling import fit_plate

    case, mesh, rng, prior, options = item
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the workers' warnings are the setup's log lines
        model = PlateModel.from_case(case, mesh=mesh)
        return fit_plate(
            case, model=model, rng=rng, prior_mean=prior.mean, prior_sd=prior.sd, **options
        )


def fit_plates(cases, rng, mesh=None, workers=1, progress=False, **options):
    """Every plate's PlateFit, built on the batch engine's pool (``workers`` processes).

    Parameters
    ----------
    cases : sequence of bayesplate.io.Case
    rng : numpy.random.Generator
        Spawned into one stream per plate (the same numbers with one worker or several).
    mesh : (int, int), optional
    workers : int
        Dask worker processes (:func:`bayesplate.batch.map_tasks`); 1: in this process.
    progress : bool
    **options
        Of :func:`~bayesplate.sampling.setup.prepare`.

    Returns
    -------
    list of PlateFit
    """
    from ..batch.pool import map_tasks

    prior = cases[0].prior
    items = [
        (c, mesh, r, prior, options) for c, r in zip(cases, rng.spawn(len(cases)), strict=True)
    ]
    return map_tasks(_fit_task, items, workers=workers, progress=None if progress else False)


def run_population(args, cases):
    """``--hierarchical``: the population of the plates, its table, JSON, netCDF and figure."""
    import time

    from ..io import CaseError, save_figure, write_json, write_netcdf
    from ..io.export_population import hierarchical_to_dict
    from ..parallel import available_cores
    from ..sampling import PlatesMismatch, check_plates, sample_population
    from ..sampling.seeding import resolve_rng, streams

    quiet = args.json == "-"
    try:
        check_plates(cases)
    except PlatesMismatch as err:
        raise CaseError(err.key, err.value, err.rule, path=cases[err.index].path) from None
    _, build, walk = streams(resolve_rng(args.seed, None, "sample"))
    workers = args.workers or min(len(cases), available_cores())
    started = time.perf_counter()
    fits = fit_plates(
        cases,
        build,
        mesh_of(args),
        workers,
        not quiet,
        forward="full" if args.full else "reduced",
        pairing=args.pairing,
        inputs=args.inputs or "auto",
    )
    t_build = time.perf_counter() - started
    p = fits[0].problem
    hier = sample_population(
        fits,
        p.mu_b,
        p.V_b,
        rng=walk,
        n_walkers=args.walkers,
        max_steps=args.max_steps,
        min_ess=args.min_ess,
    )
    timings = {"build": t_build, "sampling": hier.wall_time, "workers": workers}
    if args.out:
        write_netcdf(hier.idata, args.out)
    if args.output:
        from ..plots.population import population_figure

        fig = population_figure(hier, title=f"{len(cases)} plates of one material")
        save_figure(fig, pathlib.Path(args.output) / "population.png")
    if args.json:
        write_json(hierarchical_to_dict(hier, cases, timings), args.json)
    if not quiet:
        print(hierarchical_text(hier, timings))
    return 0 if hier.converged else 1


def hierarchical_text(hier, timings=None):
    """The population (mean, spread, 94 % intervals), each plate shrunk beside its own answer."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    timing = (
        ""
        if timings is None
        else (
            f"; fast models {timings['build']:.1f} s "
            f"({timings['workers']} workers), sampling "
            f"{timings['sampling']:.1f} s"
        )
    )
    lines = [
        f"{len(hier.names)} plates of one material, each its own constants around the "
        "material's mean (ln c_p ~ N(ln mu, tau^2); each plate's likelihood by Laplace)",
        f"emcee on (ln mu, ln tau): {hier.n_walkers} walkers x {hier.n_steps} steps "
        f"({hier.n_burn} burn-in), ESS >= {hier.ess_min:.0f}, R-hat <= {hier.rhat_max:.3f}: "
        f"{hier.status}{timing}"
        + ("" if hier.converged else " (NOT converged: raise --max-steps)"),
        f"{'constant':>9} {'mean':>9} {'94 % interval':>21} {'spread':>7} "
        f"{'94 % interval':>15} {'ESS':>6} {'R-hat':>6}",
    ]
    mean, lo, hi = (to_case_units(v) for v in (hier.mean, hier.hdi[0], hier.hdi[1]))
    for i, key in enumerate(ENGINEERING_KEYS):
        t_lo, t_hi = 100 * hier.tau_hdi[:, i]
        lines.append(
            f"{key:>9} {mean[i]:#9.4g} [{lo[i]:#9.4g}, {hi[i]:#9.4g}] "
            f"{100 * hier.tau_mean[i]:6.1f}% [{t_lo:5.1f}, {t_hi:5.1f}]% "
            f"{min(hier.ess[i], hier.ess[6 + i]):6.0f} {max(hier.rhat[i], hier.rhat[6 + i]):6.3f}"
        )
    lines.append("plates: shrunk (own answer) per constant; P(outlier)")
    lines.append(f"{'plate':>12} " + " ".join(f"{k:>19}" for k in ENGINEERING_KEYS) + " P(outlier)")
    shrunk, own = to_case_units(hier.plate_mean), to_case_units(hier.own)
    for p, name in enumerate(hier.names):
        cells = " ".join(f"{shrunk[p, i]:#8.4g} ({own[p, i]:#8.4g})" for i in range(6))
        flag = " OUTLIER" if p in hier.flagged else ""
        which = ENGINEERING_KEYS[c] if (c := hier.outlier_constant[p]) < 6 else "all"
        note = f" ({which})" if flag else ""
        lines.append(f"{name[:12]:>12} {cells} {hier.outlier[p]:10.3f}{flag}{note}")
    return "\n".join(lines)
