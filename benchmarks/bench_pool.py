"""Benchmark of diagnose's fork pool (issue 15): does ``workers=2`` beat ``workers=1`` on one case?

diagnose runs its independent fits (the nominal model's starts, the candidates) through
:func:`bayesplate.parallel.fork_map`: forked processes that inherit the plate
model. The issue keeps that pool only if it is measured faster for one case. The workload:
``diagnose`` of the bundled case ``--case`` (default plate1) on a ``--mesh`` mesh (default
12 x 6), all candidates, a fixed seed; each run in a fresh Python process (nothing cached
between runs), ``workers=1`` and ``workers=2`` in turn, ``--runs`` rounds. Timed: the
``diagnose`` call only (the model is built before the clock starts). The two verdicts and
chosen physics are compared (the pool must not change the result).

Writes ``benchmark_pool.md`` (the raw timings to ``.cache/benchmark_pool.json``). Run:
``python benchmarks/bench_pool.py [--runs 3] [--case plate1] [--mesh 12 6] [--out reports]``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_pool.md"
ROOT = pathlib.Path(__file__).resolve().parents[1]
SEED = 20261125

# one timed diagnose in a fresh process; prints a JSON line
_CHILD = """
import json, sys, time
from bayesplate import PlateModel, bundled_case_path, load_case
from bayesplate.discrepancy.diagnose import diagnose
name, nx, ny, workers, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
case = load_case(bundled_case_path(name))
model = PlateModel.from_case(case, mesh=(nx, ny))
t = time.perf_counter()
d = diagnose(case, model=model, rng=seed, workers=workers)
seconds = time.perf_counter() - t
print(json.dumps({"seconds": seconds, "verdict": d.verdict,
                  "chosen": d.chosen.name if d.chosen else None,
                  "p_value": float(d.p_value),
                  "constants": [float(c) for c in d.nominal.constants]}))
"""  # noqa: E501


#: the arms: label -> (workers, BLAS threads of the parent process; None: the machine's default)
ARMS = {"1": (1, None), "1 (1 BLAS thread)": (1, "1"), "2": (2, None)}


def one_run(case, mesh, workers, blas_threads=None):
    """The child's JSON record: seconds of ``diagnose``, verdict, chosen physics."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    if blas_threads is not None:
        env.update({v: blas_threads for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")})
    args = [sys.executable, "-c", _CHILD, case, *map(str, mesh), str(workers), str(SEED)]
    out = subprocess.run(args, check=True, capture_output=True, text=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_benchmark(runs, case, mesh):
    load = [os.getloadavg()]
    results = {k: [] for k in ARMS}
    for i in range(runs):
        for n, (workers, threads) in ARMS.items():
            results[n].append(one_run(case, mesh, workers, threads))
            r = results[n][-1]
            r["load_after"] = os.getloadavg()[0]
            print(
                f"run {i + 1}, workers={n}: {r['seconds']:.1f} s, {r['verdict']} "
                f"{r['chosen']}, load {os.getloadavg()[0]:.2f}",
                flush=True,
            )
    load.append(os.getloadavg())
    return {"results": results, "load": load, "runs": runs, "case": case, "mesh": mesh}


def write_report(bench, info, out_dir):
    date = _machine.utc_now()
    machine = ", ".join(f"{k} {v}" for k, v in info.items())
    (l1, l5, l15), (a1, _, _) = bench["load"]
    mesh = "x".join(str(m) for m in bench["mesh"])
    res = bench["results"]
    med = {k: statistics.median(r["seconds"] for r in res[k]) for k in res}
    same = all(
        (r["verdict"], r["chosen"]) == (res["1"][0]["verdict"], res["1"][0]["chosen"])
        for k in res
        for r in res[k]
    )
    ratio = med["1"] / med["2"]
    paired = [a["seconds"] / b["seconds"] for a, b in zip(res["1"], res["2"], strict=True)]
    one_thread = med["1 (1 BLAS thread)"]
    lines = [
        "# diagnose's fork pool: two workers against one, for one case (issue 15)",
        "",
        f"Date: {date}. Machine: {machine}.",
        f"Load average before: {l1:.2f} / {l5:.2f} / {l15:.2f} (1 / 5 / 15 min); after: {a1:.2f}"
        " (the machine was shared with other work).",
        f"Command: `python benchmarks/bench_pool.py --runs {bench['runs']} --case "
        f"{bench['case']} --mesh {' '.join(map(str, bench['mesh']))}`.",
        "",
        f"Workload: `diagnose` of the bundled case `{bench['case']}` on a {mesh} mesh, all "
        f"candidates, seed {SEED}; each run in a fresh process, the model built before the "
        f"clock starts; `workers=1`, `workers=1` with one BLAS thread (OPENBLAS_NUM_THREADS=1) "
        f"and `workers=2` in turn, {bench['runs']} rounds. The pool's workers use one BLAS "
        "thread each (two workers with two threads each oversubscribed the two cores).",
        "",
        "| workers | median (s) | runs (s) | 1-min load after each run | verdict | chosen |",
        "|---:|---:|---|---|---|---|",
    ]
    for k in ARMS:
        runs = ", ".join(f"{r['seconds']:.1f}" for r in res[k])
        loads = ", ".join(f"{r.get('load_after', float('nan')):.1f}" for r in res[k])
        lines.append(
            f"| {k} | {med[k]:.1f} | {runs} | {loads} | {res[k][0]['verdict']} | "
            f"{res[k][0]['chosen']} |"
        )
    # a round's two runs ran minutes apart under a load that moved: the pool is judged by
    # the paired ratios of every round, not by the medians alone
    if min(paired) > 1.05:
        verdict = "the fork pool earns its place (faster in every round)"
    elif max(paired) < 0.95:
        verdict = "the fork pool does not earn its place (slower in every round)"
    else:
        verdict = (
            "inconclusive: the rounds disagree, the load moved more than the pool changes; "
            "measure again on a quiet machine"
        )
    lines += [
        "",
        f"`workers=2` against `workers=1`: {ratio:.2f} x as fast by the medians "
        f"({med['1']:.1f} s -> {med['2']:.1f} s); per round (same round, one after the other): "
        + ", ".join(f"{q:.2f}" for q in paired)
        + f" x. Verdict: {verdict}. The verdict and chosen physics of diagnose are "
        f"{'the same' if same else 'NOT the same'} in every run.",
        "",
        f"Against one process at one BLAS thread (the fair serial baseline on small dense "
        f"problems): {one_thread / med['2']:.2f} x as fast ({one_thread:.1f} s -> "
        f"{med['2']:.1f} s).",
    ]
    path = pathlib.Path(out_dir) / REPORT
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--case", default="plate1")
    parser.add_argument("--mesh", type=int, nargs=2, default=[12, 6])
    parser.add_argument("--out", default=str(ROOT / "reports"))
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="rewrite the report from OUT/.cache/benchmark_pool.json",
    )
    args = parser.parse_args(argv)
    raw = pathlib.Path(args.out) / ".cache" / "benchmark_pool.json"
    if args.report_only:
        bench = json.loads(raw.read_text())
    else:
        bench = run_benchmark(args.runs, args.case, args.mesh)
        raw.parent.mkdir(parents=True, exist_ok=True)
        raw.write_text(json.dumps(bench, indent=1))
    info = _machine.machine()
    print(write_report(bench, info, args.out))


if __name__ == "__main__":
    main()
