"""``bayesplate diagnose``: locate a model-data mismatch, name the missing physics, refit.

Its finished stages are kept in a folder (``--cache``; :mod:`bayesplate.io.stage_store`) so
that a run killed half-way resumes where it stopped when run again.
"""

from __future__ import annotations

import pathlib

from .options import (
    MESH_ERROR_CHOICES,
    add_case_argument,
    add_json_option,
    add_mesh_option,
    add_pairing_option,
    mesh_of,
    positive_int,
    resolve_case,
    seed_int,
)

__all__ = ["register"]

#: The stages' folder by default: in the JSON output's folder, else in the working directory.
DEFAULT_CACHE = pathlib.Path(".bayesplate-cache") / "diagnose"


def cache_dir(args):
    """The folder of the stored stages (None: ``--no-cache``)."""
    if args.no_cache:
        return None
    if args.cache:
        folder = pathlib.Path(args.cache)
        if folder.exists() and not folder.is_dir():
            from ..io import CaseError

            raise CaseError("--cache", args.cache, "must be a folder (it is made when absent)")
        return folder
    if args.json and args.json != "-":
        return pathlib.Path(args.json).parent / DEFAULT_CACHE
    return DEFAULT_CACHE


def run(args):
    """Diagnose the case; print the summary, write JSON and figures on request."""
    from ..discrepancy.diagnose import diagnose
    from ..io import diagnosis_to_dict, save_figure, write_json
    from ..io.stage_store import DirectoryStore
    from ..plate.model import PlateModel

    folder = cache_dir(args)
    case = resolve_case(args.case)
    model = PlateModel.from_case(case, mesh=mesh_of(args))
    quiet = args.json == "-"
    store = None if folder is None else DirectoryStore(folder)
    d = diagnose(
        case,
        model=model,
        rng=args.seed,
        pairing=args.pairing,
        workers=args.workers,
        mesh_error_part=args.mesh_error,
        store=store,
        progress=None if quiet else (lambda msg: print(f"  {msg}", flush=True)),
    )
    if args.plots:
        from ..plots import diagnosis_figures

        for name, fig in diagnosis_figures(model, d).items():
            save_figure(fig, pathlib.Path(args.plots) / f"{name}.png")
    if args.json:
        write_json(diagnosis_to_dict(d), args.json)
    if not quiet:
        print(diagnosis_text(d))
    return 0


def diagnosis_text(d):
    """Human-readable summary of a diagnosis."""
    rival = getattr(d, "rival", None)
    others = "".join(f" or {c.name}" for c in [rival, *getattr(d, "also_tied", [])] if c)
    lines = [
        f"verdict: {d.verdict}" + (f" ({d.chosen.name}{others})" if d.chosen else ""),
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
    probabilities = getattr(d, "probabilities", {})
    if probabilities:
        lines.append(
            "posterior probabilities: "
            + ", ".join(f"{k} {v:.3g}" for k, v in probabilities.items() if v >= 1e-3)
        )
    if d.chosen is not None:
        lines.append(
            f"refit: chi2 = {d.chosen.fit.chi2:.1f} on {d.refit_dof:.1f} dof, "
            f"p = {d.refit_p_value:.3g}"
        )
    if d.unidentified:
        lines.append("unidentified by the data (prior dominates): " + ", ".join(d.unidentified))
    lines += [f"note: {n}" for n in d.notes]
    return "\n".join(lines)


def register(sub):
    """Add the ``diagnose`` subcommand."""
    p = sub.add_parser(
        "diagnose",
        help="locate a model-data mismatch, name the missing physics, refit",
        description="Fit the nominal model, test it (chi-square), locate the misfit, rank "
        "candidate physics (point_mass, thickness_taper, ply_misalignment, "
        "elastic_foundation, local_stiffness_loss, cutout, point_support) and, when the best "
        "single one is still rejected, pairs of them by Laplace evidence, refit, and give a "
        "verdict: consistent, explained, ambiguous (two or more candidates fit about equally: all "
        "named, with the measurement that would tell the first two apart) or unexplained.",
    )
    add_case_argument(p)
    add_mesh_option(p)
    p.add_argument("--seed", type=seed_int, default=0, help="seed of the random fit starts")
    p.add_argument(
        "--workers",
        type=positive_int,
        default=2,
        help="processes for the independent fits (default 2; the results do not depend on it)",
    )
    p.add_argument(
        "--mesh-error",
        choices=MESH_ERROR_CHOICES,
        default=MESH_ERROR_CHOICES[0],
        help="what of the working mesh's estimated error widens the deviations where it is "
        "not well under them: 'whole' (default) or 'unabsorbed', the part the six constants "
        "cannot absorb (measured in reports/mesh_error_rule.md); or 'corrected': each computed "
        "frequency corrected by its error (Richardson with the mesh twice as fine), the "
        "deviations widened only by what the correction leaves uncertain",
    )
    add_pairing_option(p)
    add_json_option(p)
    cache = p.add_mutually_exclusive_group()
    cache.add_argument(
        "--cache",
        metavar="DIR",
        help="keep each finished stage (nominal fit, candidate fits, refits, pairs) in DIR, so "
        "that a run killed half-way resumes there when run again with the same case and "
        "options; default: .bayesplate-cache/diagnose in the folder of the --json file, else "
        "in the working directory (delete it at will: it is recomputed)",
    )
    cache.add_argument("--no-cache", action="store_true", help="keep nothing: compute every stage")
    p.add_argument("--plots", metavar="DIR", help="write figures (PNG) into DIR")
    p.set_defaults(func=run)
