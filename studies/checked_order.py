"""diagnose with the default pairing (by order, checked) on the calibration study's recordings.

Issue 16: without shapes or mode numbers the default pairing is by order, checked at the
answer (:mod:`bayesplate.matching.checked_order`): diagnose's first pass pairs by order and the most
probable assignment is made again at its verdict's fit, a further pass made only where it
pairs a peak with another mode. This study asks two things of that default, on recordings
diagnose did not make (`studies.calibration`'s, made by :mod:`studies.recordings`: the finer
mesh, 0.2 % noise, its seeds):

- **Does it change what the order said on complete tests?** Clean replicates and power
  replicates at two sizes, diagnosed again with the default; their verdicts and names
  against the calibration's rows (by order, read from its cache), the passes each took and
  the time.
- **Does it see a mode the test missed or a peak that is no mode?** Clean replicates with
  the middle peak taken out, and with a peak put into the widest gap between two middle
  peaks (their geometric mean, many deviations from both): whether the check at the first
  pass's verdict fit set the order aside (diagnose then diagnoses again from the assignment
  B settles and keeps the pass that explains every peak best), the verdict kept, and
  whether every peak went to its right mode.

The report is ``reports/checked_order.md``; rows are kept in
``reports/.cache/checked_order.json`` as they come (a run again resumes). Run:
``python -m studies.checked_order [--workers 2]`` after the calibration study of the same
code version (its cache holds the sizes and the order's rows; without it, the sizes anew and
no rows of the order to compare).
"""

from __future__ import annotations

import argparse
import functools
import json
import logging
import os
import pathlib
import time
import traceback

import numpy as np

from bayesplate.batch import map_tasks
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.io import atomic_write_text
from studies import calibration as cal  # its recordings and seeds
from studies._study_host import code_version, cpu

#: Replicates per family (clean) and per candidate and size (power), and the sizes.
N_CLEAN, N_POWER, N_ALTERED = 10, 2, 1
SIZES = ("fitted 0.9", "3 x ideal 0.9")
VARIANTS = ("as recorded", "mode missed", "peak inserted")


def plan(sizes, quick=False):
    """Every row to run: ``(variant, calibration task)``, in running order."""
    every = [t for t in cal.tasks(sizes, quick) if t[0] == "clean" or t[3] in SIZES]
    clean = [t for t in every if t[0] == "clean"]
    rows = [("as recorded", t) for t in clean if t[5] < N_CLEAN]
    rows += [("as recorded", t) for t in every if t[0] == "power" and t[5] < N_POWER]
    for variant in VARIANTS[1:]:
        rows += [(variant, t) for t in clean if t[5] < N_ALTERED]
    return rows


def key(row_task):
    variant, task = row_task
    return f"{variant}/{cal.task_key(task)}"


def altered(blind, variant):
    """The recordings with the middle peak out or a peak put in; the right assignment.

    Returns
    -------
    case : Case
    truth : numpy.ndarray of int, shape (m',)
        0-based computed mode of every peak, -1 for the inserted one.
    """
    f, s = blind.measured.frequency_Hz, blind.measured.sigma_Hz
    m = f.size
    if variant == "as recorded":
        return blind, np.arange(m)
    if variant == "mode missed":
        keep = np.delete(np.arange(m), m // 2)
        return blind.with_measured(frequency_Hz=f[keep], sigma_Hz=s[keep]), keep
    k = 1 + int(np.argmax(f[2 : m - 1] / f[1 : m - 2]))  # the widest gap between middle peaks
    added = np.insert(f, k + 1, np.sqrt(f[k] * f[k + 1]))
    truth = np.insert(np.arange(m), k + 1, -1)
    return blind.with_measured(frequency_Hz=added, sigma_Hz=np.insert(s, k + 1, s[k])), truth


def run_row(row_task, quick=False):
    """Diagnose one replicate's (altered) recordings with the default pairing: the row.

    A replicate that raises is a row too (verdict ``error``): recorded, not lost.
    """
    variant, task = row_task
    logging.getLogger("bayesplate").setLevel(logging.ERROR)
    blind, model, _, _, _, _, seed = cal.recordings(task, quick)
    case, truth = altered(blind, variant)
    start = time.perf_counter()
    try:
        d = diagnose(case, model=model, rng=seed)  # the default pairing
    except Exception as exc:  # noqa: BLE001 - every failure is a result of the study
        where = "; ".join(
            f"{pathlib.Path(f.filename).name}:{f.lineno}"
            for f in traceback.extract_tb(exc.__traceback__)[-4:]
        )
        return {
            "key": key(row_task),
            "variant": variant,
            "kind": task[0],
            "verdict": "error",
            "error": f"{type(exc).__name__}: {exc} (at {where})",
            "named": [],
            "peaks_right": False,
            "passes": 0,
            "outliers_kept": False,
            "chosen": None,
            "seconds": time.perf_counter() - start,
        }
    seconds = time.perf_counter() - start
    note = next(
        (
            n
            for n in d.notes
            if n.startswith(("assignment made again", "pairing by order set aside"))
        ),
        "",
    )
    passes = d.passes
    peaks = None if d.peak_modes is None else [int(j) for j in d.peak_modes]
    return {
        "key": key(row_task),
        "variant": variant,
        "kind": task[0],
        "family": task[1],
        "effect": task[2],
        "size_label": task[3],
        "rep": task[5],
        "verdict": d.verdict,
        "chosen": d.chosen.name if d.chosen else None,
        "named": [
            c
            for c in (
                d.chosen.name if d.chosen else None,
                d.rival.name if d.rival is not None else None,
                *[c.name for c in d.also_tied],
            )
            if c
        ],
        "peaks_right": peaks == truth.tolist(),
        "peak_modes": peaks,
        "passes": passes,
        "outliers_kept": "outliers of this fit, kept" in note,
        "seconds": seconds,
        "set_aside": any(n.startswith("pairing by order set aside") for n in d.notes),
    }


def _cache(out_dir, quick=False):
    return pathlib.Path(out_dir) / ".cache" / f"checked_order{'-quick' if quick else ''}.json"


def main(out_dir="reports", workers=2, quick=False, order_dir=None):
    """Run the rows not in the cache, write the report; return its path.

    ``order_dir``: where the calibration's cache is (default `out_dir`).
    """
    import cloudpickle

    cloudpickle.register_pickle_by_value(cal)  # Dask workers need not import the study
    stored_order = cal.load(order_dir or out_dir, quick)  # the calibration's rows of this code
    sizes = stored_order["sizes"] or cal.sizes(quick)
    path = _cache(out_dir, quick)
    done = json.loads(path.read_text()) if path.exists() else {"rows": {}, "runs": []}
    todo = [r for r in plan(sizes, quick) if key(r) not in done["rows"]]
    print(f"{len(todo)} rows to run ({len(done['rows'])} cached)", flush=True)
    if todo:
        done["runs"].append(
            {
                "start": cal._now(),
                "code": code_version(),
                "workers": workers,
                "load": list(os.getloadavg()),
            }
        )

    def keep(position, row):
        done["rows"][row["key"]] = row
        done["runs"][-1]["end"] = cal._now()
        atomic_write_text(path, json.dumps(done))
        print(
            f"{cal._now()} {row['key']:56s} {row['verdict']:12s} passes {row['passes']} "
            f"{row['seconds']:5.0f} s ({position + 1}/{len(todo)})",
            flush=True,
        )

    if todo:
        map_tasks(
            functools.partial(run_row, quick=quick),
            todo,
            workers=workers,
            progress=False,
            on_result=keep,
        )
    text = report(list(done["rows"].values()), stored_order["rows"], done["runs"])
    out = pathlib.Path(out_dir) / f"checked_order{'-quick' if quick else ''}.md"
    atomic_write_text(out, text)
    return out


def _said(row):
    return f"{row['verdict']} ({', '.join(row['named'])})" if row.get("named") else row["verdict"]


def report(rows, order_rows, runs):
    """The report's markdown from the rows and the calibration's rows by order."""
    recorded = [r for r in rows if r["variant"] == "as recorded"]
    same = [
        r
        for r in recorded
        if r["verdict"] == order_rows[r["key"].split("/", 1)[1]]["verdict"]
        and r["chosen"] == order_rows[r["key"].split("/", 1)[1]]["chosen"]
    ]
    one = sum(r["passes"] == 1 for r in recorded)
    t_new = np.median([r["seconds"] for r in recorded]) if recorded else float("nan")
    t_old = (
        np.median([order_rows[r["key"].split("/", 1)[1]]["seconds"] for r in recorded])
        if recorded
        else float("nan")
    )
    lines = [
        "# diagnose with the default pairing (by order, checked)",
        "",
        f"Made by `python -m studies.checked_order` on {_machine()}; runs: "
        + "; ".join(
            f"{r['start']} to {r.get('end', '?')} (code {r['code']}, {r['workers']} "
            f"workers, load at start {r['load'][0]:.1f})"
            for r in runs
        )
        + ".",
        "The recordings are the calibration study's (`reports/calibration.md`: recordings' "
        "mesh twice as fine, 0.2 % noise, its seeds); diagnose runs blind with its default "
        "pairing, against the calibration's rows made by order.",
        "",
        "## Complete tests: what the order said, kept?",
        "",
        f"- {len(recorded)} replicates ({sum(r['kind'] == 'clean' for r in recorded)} clean, "
        f"{sum(r['kind'] == 'power' for r in recorded)} with an effect at the sizes "
        f"{' and '.join(SIZES)}): the same verdict and name as by order in {len(same)}; one "
        f"pass (the order stood at the verdict's fit) in {one}; outliers named and kept in "
        f"{sum(r['outliers_kept'] for r in recorded)}. A row of one pass is, fit for fit, "
        "diagnose by order with this code (the first pass is the order's; the check only "
        "adds a note), so where its verdict differs from the calibration's row, that row "
        "was made by older code (its version in the table).",
        f"- diagnose's median time {t_new:.0f} s against {t_old:.0f} s by order (the "
        "calibration's rows, made under its own load: a rough comparison).",
        "",
        "| replicate | by order (calibration row, its code) | default | passes | s |",
        "|---|---|---|---|---|",
    ]
    for r in sorted(recorded, key=lambda r: r["key"]):
        o = order_rows[r["key"].split("/", 1)[1]]
        if r["kind"] == "clean" and r["verdict"] == o["verdict"] and r["passes"] == 1:
            continue  # the clean ones that agree are counted above, not listed
        said_o = o["verdict"] + (f" ({o['chosen']})" if o["chosen"] else "")
        said_o += f", {o['code']}" if o.get("code") else ""
        lines.append(
            f"| {r['key'].split('/', 1)[1]} | {said_o} | {_said(r)} | {r['passes']} "
            f"| {r['seconds']:.0f} |"
        )
    for variant, what in (
        ("mode missed", "the middle peak taken out (its mode missed)"),
        ("peak inserted", "a peak put into the widest middle gap"),
    ):
        got = [r for r in rows if r["variant"] == variant]
        lines += ["", f"## Clean recordings with {what}", ""]
        if not got:
            lines.append("Not run yet.")
            continue
        flagged = sum(bool(r.get("set_aside")) for r in got)
        lines += [
            f"- {len(got)} replicates: the order set aside at the first pass's verdict "
            f"fit (diagnosed again from the assignment B settles) in {flagged}; every "
            f"peak on its right mode in the pass kept in "
            f"{sum(bool(r.get('peaks_right')) for r in got)}; median "
            f"{np.median([r['seconds'] for r in got]):.0f} s.",
            "",
            "| replicate | verdict kept | order set aside | passes | peaks right | s |",
            "|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {r['key'].split('/', 1)[1]} | {_said(r)} | {bool(r.get('set_aside'))} "
            f"| {r['passes']} | {bool(r.get('peaks_right'))} | {r['seconds']:.0f} |"
            + (f" {r['error']}" if r.get("error") else "")
            for r in sorted(got, key=lambda r: r["key"])
        ]
    return "\n".join(lines) + "\n"


def _machine():
    return f"the {os.cpu_count()}-core development machine ({cpu()})"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="reports")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    print(main(args.out, args.workers, args.quick))
