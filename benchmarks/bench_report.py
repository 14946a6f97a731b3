"""Benchmark of the README's main job, ``bayesplate report frederiksen_t300`` (issue 12).

Issue 12's figure: under 45 s end to end on the 2-core machine. Times the whole command
(``python -m bayesplate.cli report frederiksen_t300 -o DIR``, a fresh output folder each run,
so nothing is reused from the cache) in this tree and, for the ratio, in a checkout of a
base commit (default 9f5ebd1, before issue 12), run in turn (now, base, now, base, ...) so
that a drift of the machine's speed hits both alike; and the wall time of every step as the
report's own progress lines give it.

Writes ``benchmark_report.md``. Run: ``python benchmarks/bench_report.py [--runs 2]
[--base-rev 9f5ebd1 | --base-dir DIR | --no-base] [--out reports]``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import re
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_report.md"
ROOT = pathlib.Path(__file__).resolve().parents[1]
TARGET_S = 45.0
BASE_REV = "9f5ebd1"
CASE = "frederiksen_t300"
STEP = re.compile(r"\] (.+?): done in ([0-9.]+) s")
# on two cores the sampler runs beside diagnose: its step line gives the wait after diagnose,
# this one its own time
BESIDE = re.compile(r"\] posterior sampling took ([0-9.]+) s beside diagnose")


def one_run(tree):
    """Wall seconds of one report in `tree` and ``{step: seconds}`` from its progress."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree), env.get("PYTHONPATH")]))
    with tempfile.TemporaryDirectory(prefix="bench-report-") as out:
        argv = [sys.executable, "-m", "bayesplate.cli", "report", CASE, "-o", out]
        start = time.perf_counter()
        proc = subprocess.run(argv, env=env, cwd=tree, capture_output=True, text=True)
        elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"report in {tree} exited {proc.returncode}: {proc.stderr[-600:]}")
    steps = {m.group(1): float(m.group(2)) for m in STEP.finditer(proc.stderr)}
    for m in BESIDE.finditer(proc.stderr):
        steps["posterior sampling, its own time beside diagnose"] = float(m.group(1))
    return elapsed, steps


def run_benchmark(runs, base_dir=None):
    """``{tree: [(seconds, steps), ...]}`` over `runs` rounds, the trees in turn."""
    trees = [ROOT] + ([base_dir] if base_dir is not None else [])
    times = {tree: [] for tree in trees}
    load = [os.getloadavg()]
    for i in range(runs):
        for tree in trees:
            times[tree].append(one_run(tree))
            print(f"run {i + 1} {tree}: {times[tree][-1][0]:.1f} s", flush=True)
    load.append(os.getloadavg())
    return {"times": times, "load": load, "runs": runs, "trees": trees}


def _steps_table(runs_of, label):
    """Median seconds of each step over the runs of one tree."""
    names = list(dict.fromkeys(k for _, steps in runs_of for k in steps))
    lines = [f"Steps ({label}), median seconds:", "", "| step | s |", "|---|---:|"]
    for name in names:
        values = [steps[name] for _, steps in runs_of if name in steps]
        lines.append(f"| {name} | {statistics.median(values):.1f} |")
    return lines + [""]


def write_report(bench, info, out_dir, base_rev=None):
    """Write the Markdown report; returns its path."""
    date = _machine.utc_now()
    machine = ", ".join(f"{k} {v}" for k, v in info.items())
    (l1, l5, l15), (a1, _, _) = bench["load"]
    now_runs = bench["times"][ROOT]
    now = statistics.median(t for t, _ in now_runs)
    lines = [
        "# `bayesplate report frederiksen_t300`, end to end",
        "",
        f"Made by `python benchmarks/bench_report.py` on {date}.",
        "",
        f"Machine: {machine}.",
        f"Load average before: {l1:.2f} / {l5:.2f} / {l15:.2f} (1, 5, 15 min); after "
        f"(1 min): {a1:.2f}.",
        "",
        f"Wall time of the whole command (a fresh output folder each run: no step reused), "
        f"median of {bench['runs']} runs"
        + (f", here and at {base_rev} in turn" if base_rev else "")
        + f". Target: under {TARGET_S:.0f} s.",
        "",
        "| tree | median (s) | runs (s) |",
        "|---|---:|---|",
        f"| this tree | {now:.1f} | {', '.join(f'{t:.1f}' for t, _ in now_runs)} |",
    ]
    base_runs = [runs for tree, runs in bench["times"].items() if tree != ROOT]
    if base_runs:
        base = statistics.median(t for t, _ in base_runs[0])
        lines.append(
            f"| {base_rev} | {base:.1f} | {', '.join(f'{t:.1f}' for t, _ in base_runs[0])} |"
        )
        lines += ["", f"Base / now: {base / now:.1f}."]
    verdict = "met" if now < TARGET_S else "**missed**"
    lines += ["", f"Target under {TARGET_S:.0f} s: {verdict}.", ""]
    lines += _steps_table(now_runs, "this tree")
    if base_runs:
        lines += _steps_table(base_runs[0], base_rev)
    return _machine.write_report(out_dir, REPORT, lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2, help="runs per tree (2)")
    _machine.add_base_arguments(parser, BASE_REV, ROOT / "reports")
    args = parser.parse_args(argv)
    info = _machine.machine()
    head = None
    if args.no_base:
        bench = run_benchmark(args.runs)
    else:
        with _machine.base_checkout(args.base_rev, args.base_dir, "bench-report-") as base:
            head = _machine.commit(base)  # the checkout's own commit (--base-dir: not --base-rev)
            bench = run_benchmark(args.runs, base)
    path = write_report(bench, info, args.out, base_rev=head)
    print(path.read_text())


if __name__ == "__main__":
    main()
