"""Benchmark of `diagnose` over the concealment study's recordings (issue 12: fast everywhere).

Each recording of ``studies/concealment.py`` (its scenarios, recordings and seeds; the
Frederiksen plate, 14 frequencies, 50 x 50 mesh) is diagnosed in a fresh process, one at a
time: wall time, verdict and chosen candidate. With ``--base TREE`` the same recordings are
also diagnosed by the code of another checkout (``PYTHONPATH=TREE``; e.g. ``git worktree add
/tmp/diag-base 9f5ebd1``) for the ratio.

Writes ``benchmark_diagnose.md`` to ``out_dir``. Run:
``python benchmarks/bench_diagnose.py [--runs 0 3 ...] [--base TREE [--base-runs 0 3]]``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import statistics
import subprocess
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

ROOT = pathlib.Path(__file__).resolve().parents[1]
REPORT = "benchmark_diagnose.md"
TARGET_MEDIAN_S, TARGET_WORST_S = 30.0, 90.0


def one(index, quick=False):
    """Diagnose scenario ``index`` of the concealment study; a JSON line on stdout.

    ``quick``: on the concealment study's quick mesh (12 x 6; recordings on 24 x 12), a
    regression run of this script, not a measurement.
    """
    import numpy as np

    sys.path.insert(0, str(ROOT / "studies"))
    from concealment import NOISE, SEED, recordings, scenarios

    from bayesplate import PlateModel, bundled_case_path, load_case
    from bayesplate.discrepancy.diagnose import diagnose

    label, physics, size, theta = scenarios()[index]
    case = load_case(bundled_case_path("frederiksen_t300"))
    mesh = (12, 6) if quick else case.mesh
    model = PlateModel.from_case(case, mesh=mesh)
    fine = PlateModel.from_case(case, mesh=(2 * mesh[0], 2 * mesh[1]))
    rng = np.random.default_rng(np.random.SeedSequence(SEED).spawn(index + 1)[index])
    f = recordings(case, fine, physics, theta, rng)
    blind = case.with_measured(frequency_Hz=f, sigma_Hz=NOISE * f)
    load = os.getloadavg()[0]
    start = time.perf_counter()
    d = diagnose(blind, model=model, rng=SEED)
    seconds = time.perf_counter() - start
    chosen = None
    if d.chosen is not None:
        chosen = d.chosen.name + "".join(f" ({v})" for v in d.chosen.parameters.values()
                                         if isinstance(v, str))  # fmt: skip
    print(json.dumps({"index": index, "effect": label, "size": size, "seconds": seconds,
                      "verdict": d.verdict, "chosen": chosen, "p_value": d.p_value,
                      "load": [load, os.getloadavg()[0]]}))  # fmt: skip


def run(index, tree, quick=False):
    """Scenario ``index`` in a fresh process on the code of ``tree``; its result dict."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    command = [sys.executable, __file__, "--one", str(index), *(["--quick"] if quick else [])]
    out = subprocess.run(command, env=env, check=True, capture_output=True,
                         text=True).stdout  # fmt: skip
    return json.loads(out.strip().splitlines()[-1])


def write_report(rows, base_rows, info, out_dir, base_label):
    seconds = [r["seconds"] for r in rows]
    med, worst = statistics.median(seconds), max(seconds)
    lines = [
        f"Made by `python benchmarks/bench_diagnose.py` on {datetime.date.today().isoformat()}.",
        "",
        "# diagnose: time over the concealment study's recordings",
        "",
        f"Machine: {info['cpu']}, {info['nproc']} processors; {info['platform']}; Python "
        f"{info['python']}, numpy {info['numpy']}, scipy {info['scipy']}. One worker; each "
        "run in a fresh process; load = 1-minute load average before / after (the machine "
        "was shared).",
        "",
        f"Targets: median under {TARGET_MEDIAN_S:.0f} s, worst under {TARGET_WORST_S:.0f} s. "
        f"Here: median {med:.0f} s, worst {worst:.0f} s over {len(rows)} recordings.",
        "",
        "| # | effect | size | verdict | chosen | time (s) | load | before (s) | before: verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    base = {r["index"]: r for r in base_rows}
    for r in rows:
        b = base.get(r["index"])
        before = ("-", "-") if b is None else (
            f"{b['seconds']:.0f}", f"{b['verdict']} {b['chosen'] or ''}".strip())  # fmt: skip
        lines.append(
            f"| {r['index']} | {r['effect']} | {r['size']} | {r['verdict']} | "
            f"{r['chosen'] or '-'} | {r['seconds']:.0f} | {r['load'][0]:.1f} / "
            f"{r['load'][1]:.1f} | {before[0]} | {before[1]} |"
        )
    pairs = [(base[r["index"]]["seconds"], r["seconds"]) for r in rows if r["index"] in base]
    if pairs:
        ratios = [b / n for b, n in pairs]
        lines += ["", f"Before ({base_label}) / now, same recordings: "
                  + ", ".join(f"{x:.1f}x" for x in ratios)
                  + f" (median {statistics.median(ratios):.1f}x)."]  # fmt: skip
    path = pathlib.Path(out_dir) / REPORT
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def main(out_dir, runs, base=None, base_runs=(), quick=False):
    rows, base_rows = [], []
    for i in runs:
        rows.append(run(i, ROOT, quick))
        print(json.dumps(rows[-1]), flush=True)
        if base is not None and i in base_runs:
            base_rows.append(run(i, base))
            print("base", json.dumps(base_rows[-1]), flush=True)
        write_report(rows, base_rows, _machine.machine(), out_dir, str(base))
    return rows, base_rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--runs", type=int, nargs="*", default=list(range(12)))
    parser.add_argument("--base", help="another checkout to compare with")
    parser.add_argument("--base-runs", type=int, nargs="*", default=[0, 3])
    parser.add_argument("--out", default=ROOT / "reports")
    parser.add_argument("--quick", action="store_true", help="12 x 6 mesh: a regression run")
    args = parser.parse_args()
    if args.one is not None:
        one(args.one, args.quick)
    else:
        main(args.out, args.runs, args.base, args.base_runs, args.quick)
