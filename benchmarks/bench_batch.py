"""Benchmark of ``bayesplate batch`` (issue 15): cases per minute with 1 and 2 Dask workers.

The workload: every bundled case, ``--copies`` times (copies under other names, so each is a
case of its own), the ``estimate`` step on a ``--mesh`` mesh. Each round runs it on the
local cluster ``bayesplate batch`` starts (``bayesplate.batch.run._client``: single-threaded
worker processes), of 1 worker, then of 2, into a fresh output folder, so nothing is
reused. Timed: the cluster's start, the tasks (submission to the last result stored) and
the summary. Also measured for the scaling argument: the bytes each task ships and brings
back (pickled), the workers' peak memory, and what building the plate model costs beside a
step (it is built in each task).

Writes ``benchmark_batch.md``. Run: ``python benchmarks/bench_batch.py [--runs 2]
[--copies 2] [--mesh 10 10] [--out reports]``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import pickle
import shutil
import statistics
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_batch.md"
ROOT = pathlib.Path(__file__).resolve().parents[1]


def _cases(folder, copies):
    from bayesplate.io import bundled_case_names, bundled_case_path

    folder.mkdir(parents=True, exist_ok=True)
    for name in bundled_case_names():
        for i in range(copies):
            shutil.copy(bundled_case_path(name), folder / f"{name}_{i}.toml")
    return sorted(folder.glob("*.toml"))


def _peak_rss_MiB():
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux


def one_run(cases, n_workers, options):
    """Seconds of the cluster's start, the tasks and the summary; the workers' peak memory."""
    from bayesplate.batch import run_batch
    from bayesplate.batch.run import _client

    t0 = time.perf_counter()
    # the engine's own local cluster, as `bayesplate batch` starts it (its workers'
    # environment included)
    with (
        _client(None, n_workers) as client,
        tempfile.TemporaryDirectory(prefix="bench-batch-") as out,
    ):
        client.wait_for_workers(n_workers)
        t1 = time.perf_counter()
        lines = []
        result = run_batch(cases, out, options, scheduler=client, progress=lines.append)
        t2 = time.perf_counter()
        rss = client.run(_peak_rss_MiB)
        shipped = _shipped(cases, options, out)
    assert not result.failed, result.failed
    summary = _stamp(lines[-1]) - _stamp(lines[-2])  # last task line -> summary line
    tasks = sum(float(r["seconds"]) for r in result.rows)
    return {
        "start": t1 - t0,
        "batch": t2 - t1,
        "summary": summary,
        "task_seconds": tasks,
        "rss_MiB": max(rss.values()),
        "shipped": shipped,
        "workers_used": len({r["worker"] for r in result.rows}),
    }


def _stamp(line):
    """Seconds of a progress line ``[   12.5 s] ...``."""
    return float(line[1:].split("s]")[0])


def _shipped(cases, options, out):
    """Largest pickled task arguments and result, bytes."""
    args = max(
        len(pickle.dumps(("x", str(p), p.read_bytes(), "estimate", options.for_step("estimate"))))
        for p in cases
    )
    import json

    back = 0
    for p in cases:
        doc = json.loads((pathlib.Path(out) / p.stem / "estimate.json").read_text())
        rec = json.loads((pathlib.Path(out) / p.stem / "estimate.record.json").read_text())
        back = max(back, len(pickle.dumps({"row": rec["row"], "document": doc})))
    return {"args": args, "result": back}


def model_build(mesh):
    """Seconds to build each bundled case's plate model, on `mesh` and on its own mesh."""
    from bayesplate.io import bundled_case_names, bundled_case_path, load_case
    from bayesplate.plate.model import PlateModel

    out = {}
    for name in bundled_case_names():
        case = load_case(bundled_case_path(name))
        times = []
        for m in (mesh, None):
            t = time.perf_counter()
            model = PlateModel.from_case(case, mesh=m)
            times.append((time.perf_counter() - t, model.mesh.nx, model.mesh.ny))
        out[name] = times
    return out


def run_benchmark(runs, copies, mesh):
    from bayesplate.batch import BatchOptions

    options = BatchOptions(steps=("estimate",), mesh=tuple(mesh))
    with tempfile.TemporaryDirectory(prefix="bench-batch-cases-") as folder:
        cases = _cases(pathlib.Path(folder), copies)
        load = [os.getloadavg()]
        results = {1: [], 2: []}
        for i in range(runs):
            for n in (1, 2):
                results[n].append(one_run(cases, n, options))
                r = results[n][-1]
                print(
                    f"run {i + 1}, {n} worker(s): start {r['start']:.1f} s, "
                    f"tasks {r['batch']:.1f} s",
                    flush=True,
                )
        load.append(os.getloadavg())
    return {
        "results": results,
        "load": load,
        "n_cases": len(cases),
        "runs": runs,
        "copies": copies,
        "mesh": mesh,
        "build": model_build(tuple(mesh)),
    }


def write_report(bench, info, out_dir):
    date = _machine.utc_now()
    machine = ", ".join(f"{k} {v}" for k, v in info.items())
    (l1, l5, l15), (a1, _, _) = bench["load"]
    n = bench["n_cases"]
    mesh = "x".join(str(m) for m in bench["mesh"])

    def med(k, key):
        return statistics.median(r[key] for r in bench["results"][k])

    lines = [
        "# `bayesplate batch`: throughput on this machine (issue 15)",
        "",
        f"Date: {date}. Machine: {machine}.",
        f"Load average before: {l1:.2f} / {l5:.2f} / {l15:.2f} (1 / 5 / 15 min); after: {a1:.2f}.",
        f"Command: `python benchmarks/bench_batch.py --runs {bench['runs']} --copies "
        f"{bench['copies']} --mesh {' '.join(map(str, bench['mesh']))}`.",
        "",
        f"Workload: the {n // bench['copies']} bundled cases x {bench['copies']} copies = {n} "
        f"cases, step `estimate` (MVE) on a {mesh} mesh, a fresh output folder each run "
        f"(nothing reused). Medians over {bench['runs']} runs, 1 and 2 workers in turn.",
        "",
        "| workers | cluster start (s) | tasks to last result (s) | summary + figure (s) | "
        "cases / min (tasks) | cases / min (with start) | sum of task seconds | "
        "workers used | peak RSS per worker (MiB) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for k in (1, 2):
        start, batch, summary = med(k, "start"), med(k, "batch"), med(k, "summary")
        lines.append(
            f"| {k} | {start:.1f} | {batch:.1f} | {summary:.1f} | {60 * n / batch:.1f} | "
            f"{60 * n / (start + batch):.1f} | {med(k, 'task_seconds'):.1f} | "
            f"{bench['results'][k][-1]['workers_used']} | {med(k, 'rss_MiB'):.0f} |"
        )
    speedup = med(1, "batch") / med(2, "batch")
    slowdown = med(2, "task_seconds") / med(1, "task_seconds")
    shipped = bench["results"][2][-1]["shipped"]
    lines += [
        "",
        f"Two workers against one: {speedup:.2f} x the throughput (tasks to last result). "
        f"Each task took {slowdown:.2f} x longer with two workers (sum of task seconds), at a "
        f"load of {l1:.1f} to {a1:.1f} on {info['nproc']} cores: "
        + (
            "the two workers shared what CPU one had alone, so the throughput could not grow "
            "here; it doubles only where two cores are free."
            if speedup < 1.2
            else "the second worker found a core mostly free; what is lost to 2x is the "
            "tasks' slowdown on shared cores (memory bandwidth, the client and scheduler "
            "processes on the same two cores) and the cases of unequal length at the end."
        ),
        "",
        "## The scaling argument for a cluster",
        "",
        f"- What a task ships: the case file's bytes, its name and path and the step's options "
        f"(at most {shipped['args']} bytes pickled here); it brings back plain data, the step's "
        f"JSON document and its summary row (at most {shipped['result']} bytes pickled for "
        f"`estimate`; `diagnose` adds its candidates, `sample` its posterior summary, not the "
        f"chain). No model, matrix or chain crosses the network, and the workers need no "
        f"shared file system: the client writes every file.",
        "- Memory: a task holds one plate model (sparse K and M, the eigen solver's "
        "factorisation) and, on meshes above 5,000 unknowns, the fast model; the peak RSS per "
        "worker above includes the Python process with numpy, scipy and Dask loaded. Each "
        "worker runs one task at a time (one thread, BLAS limited to one thread), so a "
        "node's memory is its workers times one task's.",
        "- The model is built inside each task, not once per worker: tasks of one case may "
        "land on any worker, and a result must not depend on where it ran. Building it costs "
        "little beside a step (below, seconds of `PlateModel.from_case`); the fast model, "
        "when the estimator uses one, is built per task too (its cost is in the step).",
        "- Independent tasks, one result each: throughput grows with workers until the "
        "scheduler's per-task overhead (milliseconds) matters, far below tasks of seconds "
        "to minutes. Two workers on this 2-core machine that others share cannot show "
        "more than the cores free at the time; on a cluster, workers scale the tasks run "
        "at once, and the longest single task bounds the wall time.",
        "",
        "| case | build on the benchmark mesh (s) | build on its own mesh (s) |",
        "|---|---:|---:|",
    ]
    for name, ((t1, *m1), (t2, *m2)) in bench["build"].items():
        lines.append(f"| {name} | {t1:.3f} ({m1[0]}x{m1[1]}) | {t2:.3f} ({m2[0]}x{m2[1]}) |")
    path = pathlib.Path(out_dir) / REPORT
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--copies", type=int, default=2)
    parser.add_argument("--mesh", type=int, nargs=2, default=[10, 10])
    parser.add_argument("--out", default=str(ROOT / "reports"))
    args = parser.parse_args(argv)
    bench = run_benchmark(args.runs, args.copies, args.mesh)
    info = _machine.machine("dask", "distributed")
    print(write_report(bench, info, args.out))


if __name__ == "__main__":
    main()
