"""diagnose on a working mesh coarser than the calibration's: the mesh-error rules where the
correction is least sure.

The calibration study diagnoses on 60 x 30 (Frederiksen plate) and 48 x 24 (cross-ply), where
the corrected rule leaves its frequencies within what it adds to the deviations
(``reports/mesh_correction.md``). A case without a mesh of its own is diagnosed on the
package's default, 24 x 12, where the mesh's error is larger and the correction less sure.
This study diagnoses the calibration study's own recordings (their mesh, seeds and 0.2 %
noise: :func:`studies.calibration.recordings`) blind on the working meshes scaled by
``factor`` each way (0.4: 24 x 12 and 19 x 10), under a mesh-error rule:

- ``clean``: the clean replicates of both families (a verdict other than ``consistent`` is a
  false alarm);
- ``EFFECT:SIZE``: a candidate concealed in the Frederiksen plate (named right: explained
  with it, or ambiguous with it among those named; a wrong name: explained with another, or
  ambiguous among others only).

Rows are cached by code version in ``out_dir/.cache/coarse_mesh/<version>.jsonl`` (a run
resumes); the report ``coarse_mesh.md`` is the current version's rows alone. Run:
``python -m studies.coarse_mesh WHAT [--rule RULE] [--factor 0.4] [--replicates 10]
[--workers 2] [--out DIR]`` (WHAT: ``clean`` or ``EFFECT:SIZE``; about a minute a replicate
on one core).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics

from bayesplate.io import atomic_write_text
from bayesplate.parallel import fork_map
from studies import calibration as cal
from studies._study_host import code_version, cpu, jsonl_rows, utc_now

FACTOR = 0.4  # the working mesh's elements each way, relative to the calibration's


def tasks(what, replicates):
    """The calibration study's tasks that ``what`` names, ``replicates`` of each family."""
    if what == "clean":
        return [("clean", f, None, None, None, r) for f in cal.FAMILIES for r in range(replicates)]
    effect, size = what.split(":")
    if effect not in cal.EFFECTS:
        raise ValueError(f"effect = {effect!r}: must be one of {', '.join(cal.EFFECTS)}")
    family = cal.POWER_FAMILY
    return [("power", family, effect, "fitted 0.9", float(size), r) for r in range(replicates)]


def run(task, rule, factor, quick=False):
    """Diagnose one replicate's recordings on the scaled working mesh; its row (plain data).

    The calibration study's own diagnosis of the replicate (:func:`studies.calibration.
    run_task`), its working model replaced by the coarser one.
    """
    blind, model, *rest = cal.recordings(task, quick)
    nx, ny = model.mesh.nx, model.mesh.ny
    coarse = model.on_mesh((max(2, round(nx * factor)), max(1, round(ny * factor))))
    d = cal.run_task(task, quick, {"mesh_error_part": rule}, made=(blind, coarse, *rest))
    keep = ("key", "effect", "family", "rep", "verdict", "chosen", "rival", "also", "p_value")
    row = {k: d[k] for k in keep}
    row |= {"rule": rule, "factor": factor, "mesh": [coarse.mesh.nx, coarse.mesh.ny]}
    return row | {"seconds": d["seconds"], "named": cal.named(d)}


def main(what, rule=None, factor=FACTOR, replicates=10, out_dir="reports", workers=2, quick=False):
    """Run what the cache lacks; write the report; return the rows of ``what``."""
    rule = rule or cal.DEFAULT_RULE
    version = code_version() + ("-quick" if quick else "")
    cache = pathlib.Path(out_dir) / ".cache" / "coarse_mesh" / f"{version}.jsonl"
    cache.parent.mkdir(parents=True, exist_ok=True)
    done = {(r["key"], r["rule"], r["factor"]) for r in jsonl_rows(cache)}
    todo = [t for t in tasks(what, replicates) if (cal.task_key(t), rule, factor) not in done]

    def one(task):
        row = {**run(task, rule, factor, quick), "code": version}
        with cache.open("a") as out:  # one line a replicate: a stopped run keeps its rows
            out.write(json.dumps(row) + "\n")
        print(f"{row['key']} {rule} x{factor:g}: {row['verdict']} (p {row['p_value']:.2g})")
        return row

    fork_map(one, todo, workers)
    rows = jsonl_rows(cache)
    write_report(out_dir, rows, version)
    keys = {cal.task_key(t) for t in tasks(what, replicates)}
    return [r for r in rows if r["key"] in keys and (r["rule"], r["factor"]) == (rule, factor)]


def write_report(out_dir, rows, version):
    """``coarse_mesh.md``: one line a (what, family, mesh, rule), the version's rows alone."""
    lines = [
        "# diagnose on a working mesh coarser than the calibration's",
        "",
        f"Date: {utc_now()}. Machine: {cpu()}, 2 cores; load (1 min) {os.getloadavg()[0]:.1f}"
        f" when written. Code: {version}. Made by `python -m studies.coarse_mesh WHAT --rule "
        "RULE` (its docstring says how).",
        "",
        "The calibration study's recordings (a mesh twice as fine as its working mesh, 0.2 % "
        "noise, its seeds), diagnosed blind on a coarser working mesh under a mesh-error rule. "
        "`not consistent`: on a clean plate, false alarms; `named`: the concealed candidate "
        "explained, or ambiguous with it; `wrong`: a name without it.",
        "",
        "| what | family | working mesh | rule | replicates | not `consistent` | named | wrong "
        "| verdicts | nominal p: median (min) | s: median (max) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    groups = sorted({(r["effect"] or "", r["family"], tuple(r["mesh"]), r["rule"]) for r in rows})
    for effect, family, mesh, rule in groups:
        mine = [
            r
            for r in rows
            if ((r["effect"] or ""), r["family"], tuple(r["mesh"]), r["rule"])
            == (effect, family, mesh, rule)
        ]
        verdicts = sorted({r["verdict"] for r in mine})
        counts = ", ".join(f"{v} {sum(r['verdict'] == v for r in mine)}" for v in verdicts)
        p = [r["p_value"] for r in mine]
        s = [r["seconds"] for r in mine]
        what = effect or "clean"
        if effect:
            what += f" {mine[0]['key'].split('/')[3]}"
        lines.append(
            f"| {what} | {family} | {mesh[0]} x {mesh[1]} | `{rule}` | {len(mine)} | "
            f"{sum(r['verdict'] != 'consistent' for r in mine)} | "
            f"{sum(r['named'] for r in mine) if effect else '-'} | "
            f"{sum(cal.misnamed(r) for r in mine)} | {counts} | "
            f"{statistics.median(p):.2g} ({min(p):.2g}) | "
            f"{statistics.median(s):.0f} ({max(s):.0f}) |"
        )
    path = pathlib.Path(out_dir) / "coarse_mesh.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", help="clean, or EFFECT:SIZE (a candidate at a size)")
    parser.add_argument("--rule", choices=cal.RULES, default=cal.DEFAULT_RULE)
    parser.add_argument("--factor", type=float, default=FACTOR)
    parser.add_argument("--replicates", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default=os.environ.get("STUDY_OUT", "reports"))
    parser.add_argument("--quick", action="store_true")
    a = parser.parse_args()
    main(a.what, a.rule, a.factor, a.replicates, a.out, a.workers, a.quick)
