"""Benchmark of the batch engine's workers with and without Dask's ``MALLOC_TRIM_THRESHOLD_``.

Dask starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (its
``distributed.nanny.pre-spawn-environ``). Setting it also fixes glibc's mmap threshold at its
128 KiB floor, so every larger array is mapped and unmapped each time; the batch engine
(:func:`bayesplate.batch.map_tasks`, ``bayesplate batch``, the studies) starts its workers
without it. The workload is a calibration study's clean replicate: the cross-ply plate of the
paper, 14 frequencies from a mesh twice as fine (96 x 48) with 0.2 % noise of the task's own
seed, ``diagnose`` blind on 48 x 24 (one worker inside the task), ``--tasks`` of them on two
workers. Each run is a fresh process; the two settings alternate, ``--runs`` rounds (the
second of a round first in every other round). Timed: the tasks, submission to last result;
each task's processor time split into user and system (``getrusage`` of its thread).

Writes ``benchmark_worker_malloc.md``. Run: ``python benchmarks/bench_worker_malloc.py
[--runs 3] [--tasks 4] [--out reports]``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_worker_malloc.md"
ROOT = pathlib.Path(__file__).resolve().parents[1]
SEED = 20261201
SETTINGS = {"Dask's default (65536)": "65536", "as the engine starts them (unset)": None}


def _task(index):
    """One clean replicate, diagnosed; its seconds (wall, user, system) and verdict."""
    import resource

    import numpy as np

    from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
    from bayesplate.discrepancy.diagnose import diagnose

    before = resource.getrusage(resource.RUSAGE_THREAD)
    t0 = time.perf_counter()
    case = load_case(bundled_case_path("crossply"))
    b, m = stiffness_from_engineering(case.reference), case.measured.size
    f = PlateModel.from_case(case, mesh=(96, 48)).solve(b, m).frequency_Hz
    rng = np.random.default_rng(np.random.SeedSequence(SEED, spawn_key=(index,)))
    f = np.sort(f * (1 + 0.002 * rng.standard_normal(m)))
    blind = case.with_measured(frequency_Hz=f, sigma_Hz=0.002 * f)
    model = PlateModel.from_case(case, mesh=(48, 24))
    verdict = diagnose(blind, model=model, rng=index, workers=1).verdict
    after = resource.getrusage(resource.RUSAGE_THREAD)
    return {
        "wall": time.perf_counter() - t0,
        "user": after.ru_utime - before.ru_utime,
        "system": after.ru_stime - before.ru_stime,
        "verdict": verdict,
    }


def child(n_tasks):
    """One run: the tasks on two workers; a JSON line."""
    import logging

    from bayesplate.batch import map_tasks

    logging.getLogger("bayesplate").setLevel(logging.ERROR)
    t0 = time.perf_counter()
    rows = map_tasks(_task, range(n_tasks), workers=2, progress=False)
    print(json.dumps({"seconds": time.perf_counter() - t0, "tasks": rows}))


def _run(value, n_tasks):
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
    env["PYTHONPATH"] = str(ROOT)  # this tree's package, here and on the workers
    if value is not None:
        env["MALLOC_TRIM_THRESHOLD_"] = value
    cmd = [sys.executable, __file__, "--child", "--tasks", str(n_tasks)]
    out = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(runs, n_tasks, out_dir):
    info = _machine.machine("dask", "distributed")
    load_before = os.getloadavg()
    names = list(SETTINGS)
    got = {name: [] for name in names}
    for r in range(runs):
        for name in names if r % 2 == 0 else names[::-1]:
            got[name].append(_run(SETTINGS[name], n_tasks))
            print(f"round {r + 1}: {name}: {got[name][-1]['seconds']:.1f} s", flush=True)
    load_after = os.getloadavg()
    lines = [
        "# The batch engine's workers and glibc's mmap threshold",
        "",
        f"Date: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. Machine: "
        + ", ".join(f"{k} {v}" for k, v in info.items())
        + f". Code: {_machine.commit(ROOT)}.",
        f"Load average before: {' / '.join(f'{x:.2f}' for x in load_before)} (1 / 5 / 15 min);"
        f" after: {load_after[0]:.2f}.",
        f"Command: `python benchmarks/bench_worker_malloc.py --runs {runs} --tasks {n_tasks}`.",
        "",
        f"Workload: {n_tasks} clean replicates of the cross-ply plate (recordings on 96 x 48, "
        "0.2 % noise), `diagnose` on 48 x 24, on two Dask workers; each run a fresh process, "
        f"the settings alternating, {runs} rounds. Times in seconds, medians over the runs; "
        "a task's user and system seconds are its thread's.",
        "",
        "| workers' `MALLOC_TRIM_THRESHOLD_` | run, median (s) | runs (s) | task user (s) | "
        "task system (s) | system share | verdicts |",
        "|---|---:|---|---:|---:|---:|---|",
    ]
    for name in names:
        runs_s = [g["seconds"] for g in got[name]]
        tasks = [t for g in got[name] for t in g["tasks"]]
        user = statistics.median(t["user"] for t in tasks)
        system = statistics.median(t["system"] for t in tasks)
        share = sum(t["system"] for t in tasks) / sum(t["user"] + t["system"] for t in tasks)
        verdicts = sorted({t["verdict"] for t in tasks})
        lines.append(
            f"| {name} | {statistics.median(runs_s):.1f} | "
            f"{', '.join(f'{s:.1f}' for s in runs_s)} | {user:.1f} | {system:.1f} | "
            f"{share:.0%} | {', '.join(verdicts)} |"
        )
    a, b = (got[name] for name in names)
    ratios = [x["seconds"] / y["seconds"] for x, y in zip(a, b, strict=True)]
    same = all(
        [t["verdict"] for t in x["tasks"]] == [t["verdict"] for t in y["tasks"]]
        for x, y in zip(a, b, strict=True)
    )
    lines += [
        "",
        f"Dask's default against the engine's: {statistics.median(ratios):.2f} x the time "
        f"(median of the rounds' ratios: {', '.join(f'{q:.2f}' for q in ratios)}). "
        f"Each task's verdict the same under both: {'yes' if same else 'NO'}.",
        "",
    ]
    path = _machine.write_report(out_dir, REPORT, lines)
    print(f"wrote {path}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--tasks", type=int, default=4)
    parser.add_argument("--out", default=str(ROOT / "reports"))
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = parser.parse_args()
    if a.child:
        child(a.tasks)
    else:
        main(a.runs, a.tasks, a.out)
