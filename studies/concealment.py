"""Concealed-effect study of `bayesplate diagnose` (issue 5).

Each candidate effect is concealed, one at a time and at two sizes, in recordings that the
fitting model did not make: the frequencies are computed with the effect on a mesh twice as
fine in each direction as diagnose's, and 0.2 % Gaussian noise is added to each. diagnose
then runs blind on the nominal case (geometry, prior, the recorded frequencies and their
0.2 % deviations). Controls carry no effect. The recordings are the plate's lowest modes,
every one of them, sorted: diagnose pairs them by order (named; by default it would first
settle the most probable assignment, issue 16).

The plate is the Frederiksen T300/epoxy plate (bundled case `frederiksen_t300`); the truth
is Frederiksen's own estimate of its constants. Run: `python -m studies.concealment`.
"""

from __future__ import annotations

import datetime
import json
import os
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
from bayesplate.batch import map_tasks
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.discrepancy.physics.combined import Pair
from bayesplate.io import atomic_write_text
from studies import recordings as rec
from studies._study_host import code_version, cpu
from studies.recordings import NOISE, recordings  # noqa: F401  (recordings: tests call it here)

SEED = 20261121
NAMES = ("E1", "E2", "nu12", "G12", "G13", "G23")


def scenarios(quick=False):
    """(label, physics, size label, theta) of every run; physics None for a control."""
    truth = load_case(bundled_case_path("frederiksen_t300")).reference
    b_true = stiffness_from_engineering(truth)  # where the pair checks its mirror images

    def at(name, label, size):  # the candidate at its place (recordings.EFFECTS), this size
        physics, theta = rec.effect(name, size)
        return (name, physics, label, theta)

    mass, mass_theta = rec.effect("point_mass", 1.0)
    ply, ply_theta = rec.effect("ply_misalignment", 3.0)
    runs = [
        ("control", None, "-", None),
        ("control", None, "-", None),
        at("point_mass", "0.3 g", 0.3),
        at("point_mass", "1.0 g", 1.0),
        at("thickness_taper", "e = 0.03", 0.03),
        at("thickness_taper", "e = 0.08", 0.08),
        at("ply_misalignment", "3 deg", 3.0),
        at("ply_misalignment", "8 deg", 8.0),
        at("elastic_foundation", "1.3e6 N/m^3", 1.3e6),
        at("elastic_foundation", "5e6 N/m^3", 5.0e6),
        at("local_stiffness_loss", "keeps 70 %", 0.3),  # the share of stiffness lost
        at("local_stiffness_loss", "keeps 40 %", 0.6),
        # added with the candidates of issue 13 (rows 12-14)
        at("cutout", "d = 10 mm", 10.0),
        at("point_support", "1e5 N/m", 1e5),
        (
            "point_mass+ply_misalignment",
            Pair(mass, ply, b_true),
            "1.0 g + 3 deg",
            mass_theta + ply_theta,
        ),
    ]
    return [runs[0], runs[3]] if quick else runs


def blind_recording(index, quick=False, mesh=None):
    """Scenario ``index``'s recordings as a case that does not know the effect.

    Made by :mod:`studies.recordings`, its noise from its own stream of ``SeedSequence(SEED)``
    (:func:`.recordings.stream`), so a recording does not depend on which other scenarios
    ran, in which order or in which process. ``mesh``: another working mesh than the case's
    (the recordings on one twice as fine each way).

    Returns
    -------
    blind : Case
        The nominal case with the noisy recorded frequencies (sorted), 0.2 % deviations.
    model : PlateModel
        The working mesh's plate.
    """
    _, physics, _, theta = scenarios(quick)[index]
    case = load_case(bundled_case_path("frederiksen_t300"))
    mesh = (12, 6) if quick else tuple(mesh or case.mesh)
    model, fine = rec.meshes(case, mesh)
    f = rec.recordings(case, fine, physics, theta, rec.stream(SEED, index))
    return rec.blind(case, f), model


def run_scenario(index, quick=False):
    """Diagnose scenario ``index`` blind (:func:`blind_recording`); its row (plain data)."""
    label, physics, size, theta = scenarios(quick)[index]
    blind, model = blind_recording(index, quick)
    start = time.perf_counter()
    d = diagnose(blind, model=model, rng=SEED, pairing="order")
    row = _row(label, physics, size, theta, d, blind, model, time.perf_counter() - start)
    row.update(
        code=code_version(),
        cpu=cpu(),
        load=os.getloadavg()[0],
        finished=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    )
    print(
        f"{label:22s} {size:12s} -> {d.verdict:12s} {row['chosen']} ({row['seconds']:.0f} s)",
        flush=True,
    )
    return row


def main(out_dir="reports", quick=False, workers=1, scheduler=None, first=()):
    """Run every scenario and write ``concealment.md``; returns the rows.

    The scenarios run as independent tasks (:func:`bayesplate.batch.map_tasks`): in this
    process with one worker, else on a local Dask cluster of `workers` processes or on the
    Dask scheduler at `scheduler`; each row is the same wherever it ran.

    Finished rows are kept in ``out_dir/.cache/concealment/<code version>[-quick].json``
    and reused when the study is run again by the same code; rows of other code are never
    read. ``first``: indices of scenarios to run before the others (the table keeps its
    order).
    """
    cache = cache_path(out_dir, quick)
    done = json.loads(cache.read_text()) if cache.exists() else {}
    todo = [i for i in range(len(scenarios(quick))) if str(i) not in done]
    todo = [i for i in first if i in todo] + [i for i in todo if i not in first]
    print(f"{len(todo)} scenarios to run ({len(done)} cached)", flush=True)

    def keep(position, row):  # each row stored as it comes: an interrupted run resumes
        done[str(todo[position])] = row
        atomic_write_text(cache, json.dumps(done, default=_plain))
        write_report(out_dir, quick)

    _ship_by_value()
    map_tasks(
        partial(run_scenario, quick=quick),
        todo,
        workers=workers,
        scheduler=scheduler,
        on_result=keep,
    )
    return write_report(out_dir, quick)


def _ship_by_value():
    """Let Dask workers run this study's functions without importing it (a worker on
    another machine need not have the studies)."""
    module = sys.modules.get(__name__)
    if __name__ != "__main__" and module is not None:
        import cloudpickle

        cloudpickle.register_pickle_by_value(module)


def cache_path(out_dir, quick=False, version=None):
    """The rows of the code ``version`` (default: this code's), keyed by scenario index."""
    name = f"{version or code_version()}{'-quick' if quick else ''}.json"
    return Path(out_dir) / ".cache" / "concealment" / name


def write_report(out_dir="reports", quick=False):
    """Write ``concealment.md`` from this code's finished rows; returns them."""
    cache = cache_path(out_dir, quick)
    done = json.loads(cache.read_text()) if cache.exists() else {}
    n = len(scenarios(quick))
    rows = [done[str(i)] for i in range(n) if str(i) in done]
    case = load_case(bundled_case_path("frederiksen_t300"))
    mesh = (12, 6) if quick else case.mesh
    _with_mirror_images(rows, scenarios(quick), PlateModel.from_case(case, mesh=mesh))
    text = _report(rows, mesh, quick)
    if len(rows) < n:
        text += (
            f"\n**Partial: {len(rows)} of {n} scenarios finished**; run the command again "
            "to finish the rest (finished rows are kept in reports/.cache/concealment/).\n"
        )
    atomic_write_text(Path(out_dir) / "concealment.md", text)
    return rows


def same(name, effect):
    """Whether a candidate's name is the effect's: a pair's two parts in either order."""
    if name is None:
        return False
    return sorted(name.split("+")) == sorted(effect.split("+"))


def _plain(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(type(value).__name__)


def _row(label, physics, size, theta, d, case, model, seconds):
    """One line of the table, as plain data."""
    truth = case.reference
    before = d.nominal.constants / truth - 1
    after = d.chosen.fit.constants / truth - 1 if d.chosen else None
    recovered = None
    if d.chosen is not None and physics is not None and same(d.chosen.name, physics.name):
        recovered = {k: (v, d.chosen.parameters_sd.get(k)) for k, v in d.chosen.parameters.items()}
    b_true = stiffness_from_engineering(truth)
    truth_params = None if physics is None else physics.labelled(model, b_true, theta)
    return {
        "effect": label,
        "size": size,
        "p_value": d.p_value,
        "verdict": d.verdict,
        "chosen": d.chosen.name if d.chosen else None,
        "recovered": recovered,
        "rival": d.rival.name if getattr(d, "rival", None) is not None else None,
        "also": [c.name for c in getattr(d, "also_tied", [])],
        "truth": truth_params,
        "before": before,
        "after": after,
        "seconds": seconds,
        "mirrors": d.chosen.mirror_images if d.chosen else [],
        "gains": {c.name: c.log_evidence_gain for c in d.candidates},
        "unidentified": d.unidentified,
    }


def _with_mirror_images(rows, runs, model):
    """Put the mirror images of each recovered parameter set in its row (``"mirrors"``).

    Computed here, from the physics, rather than kept from the run: rows made before a
    physics learnt its mirror images (the taper's ``-e``) are then judged the same way.
    """
    physics_of = {(label, size): physics for label, physics, size, _ in runs}
    for row in rows:
        physics = physics_of.get((row["effect"], row["size"]))
        if row["recovered"] is None or physics is None:
            continue
        names = [p.name for p in physics.parameters(model, np.zeros(6))]
        theta = np.array([row["recovered"][n][0] for n in names])
        row["mirrors"] = [
            dict(zip(names, map(float, t), strict=True))
            for t in physics.mirror_images(model, theta)
        ]


def recovery_z(row):
    """Largest |recovered - truth| / sd over the parameters, at the best mirror image.

    None when the effect was not named. A located effect may be recovered at a mirror image
    of its true place (the frequencies cannot tell them apart); the image nearest the truth
    is compared.
    """
    if row["recovered"] is None or row["truth"] is None:
        return None
    sd = {k: v[1] for k, v in row["recovered"].items() if not isinstance(v[0], str)}
    images = [{k: v[0] for k, v in row["recovered"].items()}, *row["mirrors"]]
    return min(
        max(abs(image[k] - row["truth"][k]) / sd[k] for k in sd if k in row["truth"])
        for image in images
    )


def _fmt_params(recovered, truth):
    if recovered is None:
        return "-"
    parts = []
    for k, (v, sd) in recovered.items():
        if isinstance(v, str):
            parts.append(f"{k} {v}")
            continue
        t = "" if truth is None or k not in truth else f" (truth {truth[k]:.4g})"
        parts.append(f"{k} {v:.4g} +- {sd:.2g}{t}")
    return "; ".join(parts)


def _fmt_errors(errors):
    if errors is None:
        return "-"
    return " ".join(f"{n} {100 * e:+.1f}" for n, e in zip(NAMES, errors, strict=True))


def _report(rows, mesh, quick):
    head = [
        "# Concealed effects: does `diagnose` find what it was not told?",
        "",
        f"Made by `python -m studies.concealment{' --quick' if quick else ''}` (seed {SEED}).",
        f"Plate: Frederiksen T300/epoxy, 100.1 x 53.0 x 3.36 mm, truth = Frederiksen's "
        f"constants. diagnose mesh {mesh[0]} x {mesh[1]}; recordings on "
        f"{2 * mesh[0]} x {2 * mesh[1]} with {100 * NOISE:.1f} % Gaussian noise on each of "
        "14 frequencies. Constants errors are (estimate / truth - 1) in %.",
        "",
        *_provenance(rows),
        "",
        "| effect | size | nominal p | verdict | chosen | recovered parameters | constants "
        "before (%) | constants after (%) | time (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    lines = [
        f"| {r['effect']} | {r['size']} | {r['p_value']:.2g} | {r['verdict']} | "
        f"{r['chosen'] or '-'} | {_fmt_params(r['recovered'], r['truth'])} | "
        f"{_fmt_errors(r['before'])} | {_fmt_errors(r['after'])} | {r['seconds']:.0f} |"
        for r in rows
    ]
    gains = ["", "Evidence gains (nats) of every candidate, per run:", ""]
    gains += [
        f"- {r['effect']} {r['size']}: "
        + ", ".join(f"{k} {v:+.1f}" for k, v in sorted(r["gains"].items(), key=lambda kv: -kv[1]))
        for r in rows
    ]
    return "\n".join(head + lines + gains + _findings(rows)) + "\n"


def _provenance(rows):
    """Which code made the rows, when, on which machine and at which load."""
    by_code = {}
    for r in rows:
        by_code.setdefault((r.get("code"), r.get("cpu")), []).append(r)
    out = []
    for (code, machine), mine in by_code.items():
        days = sorted({r["finished"][:10] for r in mine if r.get("finished")})
        loads = [r["load"] for r in mine if r.get("load") is not None]
        out.append(
            f"Rows made by the code of `{code}` on {', '.join(days) or '?'}, "
            f"{machine or 'an unrecorded machine'} (2 cores), "
            f"load average {min(loads):.1f}-{max(loads):.1f} (other work beside): "
            f"{len(mine)} row{'s' * (len(mine) != 1)}, "
            f"{sum(r['seconds'] for r in mine) / 60:.0f} min of "
            "diagnose."
            if loads
            else f"Rows made by `{code}`: {len(mine)}."
        )
    return out


def _findings(rows):
    """Checks of the issue's targets, computed from the rows."""
    controls = [r for r in rows if r["effect"] == "control"]
    rejected = [r for r in rows if r["effect"] != "control" and r["p_value"] < 0.01]
    named = [r for r in rejected if same(r["chosen"], r["effect"])]
    # `ambiguous` names two or more: right when the truth is one of them
    among = [
        r
        for r in rejected
        if r["verdict"] == "ambiguous"
        and any(
            same(name, r["effect"]) for name in (r["chosen"], r.get("rival"), *r.get("also", []))
        )
    ]
    better = [
        r
        for r in named
        if r["after"] is not None and np.abs(r["after"]).max() < np.abs(r["before"]).max()
    ]
    within = [r for r in named if recovery_z(r) is not None and recovery_z(r) <= 2.0]
    missed = [r for r in rejected if r not in named and r not in among]
    return [
        "",
        "## Targets",
        "",
        f"- controls saying `consistent`: {sum(r['verdict'] == 'consistent' for r in controls)}"
        f" of {len(controls)}",
        f"- effects rejected by the nominal fit (p < 0.01): {len(rejected)}; named correctly: "
        f"{len(named)}; refit consistent: {sum(r['verdict'] == 'explained' for r in named)}; "
        f"declared `ambiguous` with the truth among the two named: {len(among)}; neither: "
        f"{len(missed)}"
        + "".join(
            f" ({r['effect']} {r['size']}: {r['verdict']}"
            + (f", {r['chosen']} named" if r["chosen"] else "")
            + ")"
            for r in missed
        ),
        f"- of those named, parameters within 2 reported sd of the truth (or of a mirror "
        f"image of it): {len(within)} of {len(named)} (largest |error| / sd per row: "
        + ", ".join(f"{r['effect']} {r['size']} {recovery_z(r):.1f}" for r in named)
        + ")",
        f"- of those named, constants closer to the truth after the refit (largest error): "
        f"{len(better)} of {len(named)}",
    ]


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two scenarios on a 12 x 6 mesh")
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument("--first", default="", help="scenario indices to run first: 12,13,14")
    args = parser.parse_args()
    first = tuple(int(i) for i in args.first.split(",") if i.strip())
    main(quick=args.quick, workers=args.workers, first=first)
