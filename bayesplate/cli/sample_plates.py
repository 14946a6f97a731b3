"""``bayesplate sample A.toml B.toml ...``: plates of one material, their shared constants.

The joint posterior (:func:`bayesplate.sampling.sample_plates`), printed as the material's
constants and one line per plate (its own B estimate's fit and the leave-one-out check
against the others); ``--json FILE`` writes the same as JSON, ``-o DIR`` the figure (one
row per plate beside the shared estimate), ``--out FILE.nc`` the shared constants' ArviZ
data. ``--hierarchical`` adds the hierarchical posterior
(:func:`bayesplate.sampling.sample_hierarchical`: the material's mean, the spread ``tau``
per constant, each plate's constants) after the shared one. Cases that cannot be one
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
    "hierarchical_text",
    "hierarchical_to_dict",
    "joint_text",
    "joint_to_dict",
    "run_plates",
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
            raise CaseError("case", f"argument {k + 1}, the file of argument {seen[key] + 1}",
                            "each plate's case file may be given once", path=case.path)  # fmt: skip
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
        lines.append(f"{key:>9} {mean[i]:#10.4g} {sd[i]:#9.3g} {hdi[0, i]:#9.4g} "
                     f"{hdi[1, i]:#9.4g} {s.ess_bulk[i]:6.0f} {s.rhat[i]:6.3f}")  # fmt: skip
    lines.append("plates: chi2 at the joint mean (m modes); q, p: the others' prediction "
                 "(flagged below p = 0.01); own B estimate E1, E2, G12 (GPa)")  # fmt: skip
    for est, c in zip(result.setup.singles, result.checks, strict=True):
        own = to_case_units(est.constants)
        flag = "FLAGGED" if c.status == "flagged" else c.status
        lines.append(f"  {c.name}: chi2 {c.chi2_joint:.1f} ({c.m}), q {c.chi2_rest:.1f} "
                     f"p {c.p_rest:.2g} {flag}; own {own[0]:.4g}, {own[1]:.4g}, "
                     f"{own[3]:.4g}")  # fmt: skip
    return "\n".join(lines)


def joint_to_dict(result, cases):
    """The JSON document of a joint posterior (``bayesplate sample A B ... --json``)."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    s = result.sampling
    mean, sd, hdi = (to_case_units(v) for v in (s.mean, s.sd, s.hdi))
    constants = {
        key: {"mean": float(mean[i]), "sd": float(sd[i]), "hdi_3%": float(hdi[0, i]),
              "hdi_97%": float(hdi[1, i]), "ess_bulk": float(s.ess_bulk[i]),
              "r_hat": float(s.rhat[i])}
        for i, key in enumerate(ENGINEERING_KEYS)
    }  # fmt: skip
    plates = []
    for case, est, c in zip(cases, result.setup.singles, result.checks, strict=True):
        own, own_sd = to_case_units(est.constants), to_case_units(est.sd)
        plates.append({
            "name": c.name, "file": case.path, "m": c.m,
            "chi2_joint": c.chi2_joint, "p_joint": c.p_joint,
            "q_others": c.chi2_rest, "p_others": c.p_rest,
            "flagged": c.flagged, "status": c.status,
            "own_B": {k: {"value": float(own[i]), "sd": float(own_sd[i])}
                      for i, k in enumerate(ENGINEERING_KEYS)},
        })  # fmt: skip
    return {
        "status": result.status,
        "prior_from": cases[0].path or result.names[0],
        "constants": constants,
        "plates": plates,
        "flagged": [result.names[i] for i in result.flagged],
        "chain": {"n_walkers": s.n_walkers, "n_steps": s.n_steps, "n_burn": s.n_burn,
                  "converged": bool(s.converged), "message": s.message,
                  "n_full": s.n_full, "rebuilt": list(result.setup.rebuilt)},
        "timings": {k: float(v) for k, v in result.timings.items()},
    }  # fmt: skip


def run_plates(args):
    """Several cases: the joint posterior, its table, JSON, netCDF and figure on request."""
    from ..io import CaseError, save_figure, write_json, write_netcdf
    from ..model import PlateModel
    from ..sampling import PlatesMismatch, sample_plates

    for attr, option in _ONE_CASE_ONLY:
        if getattr(args, attr, None):
            return _refuse(f"{option} is for one case file (several plates: not yet)")
    cases = _load(args.case)
    quiet = args.json == "-"
    if not quiet:
        logging.getLogger("bayesplate.sampling").setLevel(logging.INFO)
    models = [PlateModel.from_case(c, mesh=mesh_of(args)) for c in cases]
    try:
        result = sample_plates(
            cases, rng=args.seed, n_walkers=args.walkers, max_steps=args.max_steps,
            min_ess=args.min_ess, backend_path=args.backend, progress=not quiet,
            models=models, forward="full" if args.full else "reduced",
            pairing=args.pairing, inputs=args.inputs or "auto",
        )  # fmt: skip
    except PlatesMismatch as err:
        raise CaseError(err.key, err.value, err.rule, path=cases[err.index].path) from None
    if args.out:
        write_netcdf(result.sampling.idata, args.out)
    if args.output:
        from ..plots.plates import plate_rows, plates_figure

        rows, shared = plate_rows(result)
        fig = plates_figure(rows, shared, title=f"{len(cases)} plates of one material")
        save_figure(fig, pathlib.Path(args.output) / "plates.png")
    hier = None
    if args.hierarchical:
        from ..sampling import sample_hierarchical

        hier = sample_hierarchical(result.setup.setups, result.setup.singles, rng=args.seed,
                                   max_steps=args.max_steps, min_ess=args.min_ess,
                                   progress=not quiet)  # fmt: skip
    if args.json:
        doc = joint_to_dict(result, cases)
        if hier is not None:
            doc["hierarchical"] = hierarchical_to_dict(hier, result.names)
        write_json(doc, args.json)
    if not quiet:
        print(joint_text(result))
        if hier is not None:
            print(hierarchical_text(hier, result.names))
    converged = result.sampling.converged and (hier is None or hier.converged)
    return 0 if converged else 1


def hierarchical_text(hier, names):
    """The hierarchical posterior: the material's mean, the spread, each plate's constants."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    lines = [
        f"hierarchical (ln c_p = ln mu + tau eta_p): {hier.n_walkers} walkers x "
        f"{hier.n_steps} steps ({hier.n_burn} burn-in), tau <= {hier.tau_max:.0f} steps, "
        f"ESS >= {hier.ess_min:.0f}, R-hat <= {hier.rhat_max:.3f}: {hier.status}"
        + ("" if hier.converged else " (NOT converged: use the shared constants above)"),
        f"{'constant':>9} {'mean mu':>10} {'sd':>9} {'tau':>7} {'tau 97%':>8} "
        + " ".join(f"{n[:10]:>10}" for n in names),
    ]
    mean, sd = to_case_units(hier.mean), to_case_units(hier.sd)
    plates = to_case_units(hier.plate_mean)
    for i, key in enumerate(ENGINEERING_KEYS):
        lines.append(f"{key:>9} {mean[i]:#10.4g} {sd[i]:#9.3g} {hier.tau_mean[i]:7.3f} "
                     f"{hier.tau_hdi[1, i]:8.3f} "
                     + " ".join(f"{plates[p, i]:#10.4g}" for p in range(len(names))))  # fmt: skip
    return "\n".join(lines)


def hierarchical_to_dict(hier, names):
    """The hierarchical posterior as JSON (case units; ``tau`` of ``ln c``, dimensionless)."""
    from ..quantities import ENGINEERING_KEYS, to_case_units

    mean, sd = to_case_units(hier.mean), to_case_units(hier.sd)
    plates = to_case_units(hier.plate_mean)
    return {
        "status": hier.status,
        "mean": {k: {"mean": float(mean[i]), "sd": float(sd[i])}
                 for i, k in enumerate(ENGINEERING_KEYS)},
        "tau": {k: {"mean": float(hier.tau_mean[i]), "hdi_3%": float(hier.tau_hdi[0, i]),
                    "hdi_97%": float(hier.tau_hdi[1, i])} for i, k in enumerate(ENGINEERING_KEYS)},
        "plates": {n: {k: float(plates[p, i]) for i, k in enumerate(ENGINEERING_KEYS)}
                   for p, n in enumerate(names)},
        "chain": {"n_walkers": hier.n_walkers, "n_steps": hier.n_steps, "n_burn": hier.n_burn,
                  "tau_max": hier.tau_max, "ess_min": hier.ess_min, "rhat_max": hier.rhat_max},
    }  # fmt: skip
