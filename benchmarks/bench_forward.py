"""Speed and memory of the forward model on the Frederiksen plate, mesh by mesh.

Every mesh runs in its own Python process, so that its peak resident memory (``ru_maxrss``)
is its own. Per mesh it times, separately:

- assembly: ``PlateModel(...)`` (element matrices, sparsity pattern, the six ``K_j`` and
  ``M``, the nested-dissection order);
- solve: ``model.solve(b, 20)``, which is ``K(b)``, the shift-invert factorisation, the
  Lanczos iterations and the sensitivities; the eigen solve is ``solve - sensitivities``;
- factorisation alone (``bayesplate.fem.eigen._shift_invert``) and sensitivities alone
  (``model.sensitivities``).

Writes ``benchmark_forward.md``. Run: ``python benchmarks/bench_forward.py [--quick]``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import resource
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_forward.md"
CASE = "frederiksen_t300"
N_MODES = 20
MESHES = [(8, 8), (16, 16), (24, 24), (32, 32), (50, 50), (70, 70), (100, 100)]
QUICK_MESHES = [(4, 4), (8, 8)]
TARGET_S = 1.0  # the target for one 50 x 50 forward solve (assembly + solve)
TARGET_MESH = (50, 50)
STOP_S = 60.0  # do not go to a larger mesh once assembly + solve takes longer than this
CHILD_TIMEOUT_S = 900
REPEAT_BELOW_DOFS = 30_000  # best of 3 below this many unknowns, a single run above
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


# ----------------------------------------------------------------------------- one mesh


def _timed(fn, *args, **kwargs):
    """``(fn(*args, **kwargs), wall seconds, CPU seconds of this process)``."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - wall, time.process_time() - cpu


def measure(nx, ny):
    """Time and memory of one mesh in this process; a dict of numbers.

    The whole forward run (assembly, solve, sensitivities) is repeated ``repeats`` times
    and the smallest time of each stage kept; the peak memory is read after the first run,
    before anything else is allocated, so it is that of one forward run.
    """
    from bayesplate.fem.eigen import _shift_invert
    from bayesplate.io import bundled_case_path, load_case
    from bayesplate.laminate import stiffness_from_engineering
    from bayesplate.model import PlateModel

    case = load_case(bundled_case_path(CASE))
    b = stiffness_from_engineering(case.reference)
    PlateModel.from_case(case, mesh=(2, 2)).solve(b, 4)  # warm up imports and caches
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    n_dofs = 8 * (nx + 1) * (ny + 1)
    repeats = 3 if n_dofs < REPEAT_BELOW_DOFS else 1

    best = {}
    for rep in range(repeats):
        model = result = None  # free the previous run before the next
        model, *t_asm = _timed(PlateModel.from_case, case, mesh=(nx, ny))
        result, *t_solve = _timed(model.solve, b, N_MODES)
        _, *t_sens = _timed(model.sensitivities, result.vectors)
        if rep == 0:
            rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        for key, t in (("assembly", t_asm), ("solve", t_solve), ("sensitivities", t_sens)):
            best[key] = min(best.get(key, (np.inf, np.inf)), tuple(t))
    free = model.free_dofs
    K = model.stiffness(b)[free][:, free]
    A = K - model.spectral_shift(b) * model.mass[free][:, free]
    t_fact = min(_timed(_shift_invert, A, model._ordering)[1] for _ in range(repeats))
    op = _shift_invert(A, model._ordering)
    x = np.random.default_rng(0).standard_normal(A.shape[0])
    t_apply = min(_timed(op.matvec, x)[1] for _ in range(5))
    n_apply = _count_applications(model, b)
    return {
        "mesh": [nx, ny],
        "n_dofs": model.mesh.n_dofs,
        "nnz": int(K.nnz),
        "repeats": repeats,
        "assembly_s": best["assembly"][0],
        "solve_s": best["solve"][0],
        "sensitivities_s": best["sensitivities"][0],
        "eigen_s": best["solve"][0] - best["sensitivities"][0],
        "factorisation_s": t_fact,
        "lu_apply_s": t_apply,
        "n_apply": n_apply,
        "total_s": best["assembly"][0] + best["solve"][0],
        "total_cpu_s": best["assembly"][1] + best["solve"][1],
        "peak_rss_MB": rss1 / 1024,  # ru_maxrss is in KiB on Linux
        "baseline_rss_MB": rss0 / 1024,
        "f1_Hz": float(result.frequency_Hz[0]),
        "n_rigid": result.n_rigid,
    }


def _count_applications(model, b):
    """Number of shift-invert operator applications (LU solves) ARPACK makes in one solve."""
    from bayesplate.fem import eigen

    original, count = eigen._shift_invert, [0]

    def counting(A, ordering):
        op = original(A, ordering)

        def matvec(x):
            count[0] += 1
            return op.matvec(x)

        return eigen.spla.LinearOperator(op.shape, matvec=matvec, dtype=op.dtype)

    eigen._shift_invert = counting
    try:
        model.solve(b, N_MODES)
    finally:
        eigen._shift_invert = original
    return count[0]


def run_child(nx, ny, blas_threads=None):
    """:func:`measure` in a fresh interpreter, for an honest peak memory.

    ``blas_threads`` limits OpenBLAS/OpenMP threads in the child (None: the library default).
    """
    env = dict(os.environ)
    if blas_threads is not None:
        for var in BLAS_THREAD_VARS:
            env[var] = str(blas_threads)
    out = subprocess.run(
        [sys.executable, __file__, "--child", str(nx), str(ny)],
        capture_output=True,
        text=True,
        timeout=CHILD_TIMEOUT_S,
        check=True,
        env=env,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- the machine


def machine():
    """Processor, core count, memory and library versions (see ``_machine``)."""
    return _machine.machine()


# ----------------------------------------------------------------------------- the run


def run(meshes, blas_threads=None):
    """Run the meshes in order, stopping after one whose total exceeds :data:`STOP_S`."""
    rows, stopped = [], None
    load = [os.getloadavg()]
    for k, (nx, ny) in enumerate(meshes):
        row = run_child(nx, ny, blas_threads)
        rows.append(row)
        threads = "default" if blas_threads is None else blas_threads
        print(
            f"{nx}x{ny} (BLAS threads {threads}): {row['total_s']:.2f} s, "
            f"{row['peak_rss_MB']:.0f} MB",
            flush=True,
        )
        load.append(os.getloadavg())
        if row["total_s"] > STOP_S and k + 1 < len(meshes):
            stopped = (nx, ny)
            break
    return {"rows": rows, "stopped_after": stopped, "load": load}


def _ratio_range(single, default):
    """``"0.9 to 3.1 x"``: range of default-thread over one-thread totals."""
    by_mesh = {tuple(r["mesh"]): r["total_s"] for r in single}
    ratios = [r["total_s"] / by_mesh[tuple(r["mesh"])] for r in default]
    if not ratios:
        return "not measured against"
    return f"{min(ratios):.1f} to {max(ratios):.1f} x"


def _default_table(single, default):
    """Totals with default BLAS threads beside those with one thread."""
    by_mesh = {tuple(r["mesh"]): r for r in single}
    rows = []
    for r in default:
        one = by_mesh[tuple(r["mesh"])]
        rows.append(
            [
                f"{r['mesh'][0]}x{r['mesh'][1]}",
                f"{r['eigen_s']:.3f}",
                f"{r['total_s']:.3f}",
                f"{r['total_cpu_s']:.3f}",
                f"{r['total_s'] / one['total_s']:.2f}",
            ]
        )
    headers = [
        "mesh",
        "eigen solve (s)",
        "total (s)",
        "total CPU (s)",
        "total / one-thread total",
    ]
    return _table(headers, rows)


def _fit_exponent(rows, key, min_dofs=10_000):
    """Slope of log(time) against log(unknowns) over the meshes with >= ``min_dofs``."""
    pts = [(r["n_dofs"], r[key]) for r in rows if r["n_dofs"] >= min_dofs and r[key] > 0]
    if len(pts) < 2:
        return None
    x, y = np.log(np.array(pts)).T
    return float(np.polyfit(x, y, 1)[0])


def _table(headers, rows):
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def write_report(bench, info, out_dir, quick=False, date=None):
    """Write the Markdown report."""
    rows = bench["rows"]
    flag = " --quick" if quick else ""
    date = date or datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    default = bench.get("default_threads", {"rows": [], "load": []})
    loads = np.array(bench["load"] + default["load"])
    table = _table(
        [
            "mesh",
            "unknowns",
            "nnz(K)",
            "runs",
            "assembly (s)",
            "eigen solve, 20 modes (s)",
            "of which factorisation (s)",
            "LU solves x one solve",
            "sensitivities (s)",
            "total (s)",
            "total CPU (s)",
            "peak RSS (MB)",
            "f1 (Hz)",
        ],
        [
            [
                f"{r['mesh'][0]}x{r['mesh'][1]}",
                r["n_dofs"],
                r["nnz"],
                f"best of {r['repeats']}" if r["repeats"] > 1 else "1",
                f"{r['assembly_s']:.3f}",
                f"{r['eigen_s']:.3f}",
                f"{r['factorisation_s']:.3f}",
                f"{r['n_apply']} x {r['lu_apply_s'] * 1e3:.2f} ms",
                f"{r['sensitivities_s']:.3f}",
                f"{r['total_s']:.3f}",
                f"{r['total_cpu_s']:.3f}",
                f"{r['peak_rss_MB']:.0f}",
                f"{r['f1_Hz']:.2f}",
            ]
            for r in rows
        ],
    )
    lines = [
        f"Made by `python benchmarks/bench_forward.py{flag}` on {date}; not part of "
        "`studies/run_all.py` (timings belong to a machine).",
        "",
        "# Forward-model benchmark (Frederiksen plate, free-free, 20 elastic modes)",
        "",
        f"Machine: {info['cpu']}, {info['nproc']} processors available, {info['memory']} "
        f"memory; {info['platform']}; Python {info['python']}, numpy {info['numpy']}, scipy "
        f"{info['scipy']} (BLAS: {info['blas']}). Load average (1 min) before the run "
        f"{loads[0][0]:.2f}, during it {loads[1:, 0].min():.2f} to {loads[1:, 0].max():.2f} "
        f"on {info['nproc']} processors: the machine is shared with other work, so wall times "
        "are inflated by it; `total CPU` is the CPU time of the benchmark process.",
        "",
        "The main table runs with BLAS limited to one thread (`OPENBLAS_NUM_THREADS=1`, "
        "likewise OMP and MKL): the sparse LU (SuperLU) is single-threaded anyway. The second "
        "table runs the same meshes with the default BLAS threads, which ARPACK's dense "
        f"vector operations go through: {_ratio_range(rows, default['rows'])} the one-thread "
        "total on this machine at this load.",
        "",
        "Each mesh runs in a fresh process (peak RSS is `ru_maxrss` of that process, including "
        f"about {rows[0]['baseline_rss_MB']:.0f} MB of interpreter and libraries). `assembly` "
        "is `PlateModel(...)`; `eigen solve` is `model.solve(b, 20)` minus its sensitivities "
        "(K(b), the shift-invert LU with nested-dissection order, ARPACK Lanczos, Ritz "
        "vectors); `factorisation` is the LU alone, timed separately; `LU solves` is how "
        "many times ARPACK applied the shift-invert operator in one solve, times one "
        "application (forward and back substitution), timed separately; `sensitivities` is "
        "`model.sensitivities` (six sparse products); `total` = assembly + `model.solve` "
        "(sensitivities included).",
        "",
        "## BLAS limited to one thread",
        "",
        table,
        "",
        "## Default BLAS threads",
        "",
        _default_table(rows, default["rows"]),
        "",
        "## Against the target",
        "",
    ]
    target = next((r for r in rows if tuple(r["mesh"]) == TARGET_MESH), None)
    if target is not None:
        verdict = "meets" if target["total_s"] <= TARGET_S else "misses"
        lines += [
            f"- 50x50 ({target['n_dofs']} unknowns): total {target['total_s']:.2f} s = "
            f"{target['total_s'] / TARGET_S:.2f} x the {TARGET_S:g} s target ({verdict} it); "
            f"assembly {target['assembly_s']:.2f} s, eigen solve {target['eigen_s']:.2f} s "
            f"(factorisation {target['factorisation_s']:.2f} s = "
            f"{target['factorisation_s'] / target['eigen_s']:.0%} of it; {target['n_apply']} LU "
            f"solves = {target['n_apply'] * target['lu_apply_s']:.2f} s = "
            f"{target['n_apply'] * target['lu_apply_s'] / target['eigen_s']:.0%}; the rest is "
            "ARPACK's own work, K(b) and the Ritz vectors), sensitivities "
            f"{target['sensitivities_s']:.3f} s. Its CPU time, {target['total_cpu_s']:.2f} s "
            f"= {target['total_cpu_s'] / TARGET_S:.2f} x the target, is close to what it would "
            "take on an idle machine (wall / CPU = "
            f"{target['total_s'] / target['total_cpu_s']:.2f}: the rest is waiting for the "
            "processor). A "
            "solve at new constants on an existing model (what an estimator repeats) is "
            f"{target['solve_s']:.2f} s = {target['solve_s'] / TARGET_S:.2f} x the target.",
        ]
        other = next((r for r in default["rows"] if tuple(r["mesh"]) == TARGET_MESH), None)
        if other is not None:
            lines.append(
                f"- With the default BLAS threads the same 50x50 total is {other['total_s']:.2f} s"
                f" = {other['total_s'] / target['total_s']:.2f} x the one-thread total "
                f"(CPU {other['total_cpu_s']:.2f} s against {target['total_cpu_s']:.2f} s)."
            )
    else:
        lines.append("- The 50x50 mesh was not run (quick mode).")
    for key, label in (
        ("assembly_s", "assembly"),
        ("eigen_s", "eigen solve"),
        ("factorisation_s", "factorisation"),
        ("total_s", "total"),
        ("peak_rss_MB", "peak RSS"),
    ):
        slope = _fit_exponent(rows, key)
        if slope is not None:
            lines.append(
                f"- {label} grows as (unknowns)^{slope:.2f} (least-squares slope over the "
                "meshes with at least 10 000 unknowns)."
            )
    last = rows[-1]
    if bench["stopped_after"] is not None:
        lines.append(
            f"- Stopped after {last['mesh'][0]}x{last['mesh'][1]}: its total "
            f"{last['total_s']:.1f} s exceeds {STOP_S:g} s."
        )
    else:
        lines.append(
            f"- Largest mesh run: {last['mesh'][0]}x{last['mesh'][1]}, total "
            f"{last['total_s']:.1f} s (under the {STOP_S:g} s stop), peak RSS "
            f"{last['peak_rss_MB']:.0f} MB."
        )
    path = pathlib.Path(out_dir) / REPORT
    path.write_text("\n".join(lines) + "\n")
    return path


def main(out_dir, quick=False):
    """Benchmark every mesh and write the report; return the measurements."""
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    info = machine()
    meshes = QUICK_MESHES if quick else MESHES
    bench = run(meshes, blas_threads=1)
    bench["default_threads"] = run(meshes[: len(bench["rows"])], blas_threads=None)
    write_report(bench, info, out_dir, quick=quick)
    return bench


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two tiny meshes only")
    parser.add_argument("--out", default=pathlib.Path(__file__).resolve().parents[1] / "reports")
    parser.add_argument("--child", nargs=2, type=int, metavar=("NX", "NY"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(*args.child)))
    else:
        main(args.out, quick=args.quick)
