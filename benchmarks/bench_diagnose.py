"""Benchmark of `diagnose` (issue 5: a 14-frequency case in under 5 minutes on 2 cores).

Two cases on the case's 50 x 50 mesh: the measured Frederiksen plate (`frederiksen_t300`,
nothing to find) and the same plate with a concealed 1 g point mass (recordings as in
studies/concealment.py: 100 x 100 mesh, 0.2 % noise), each with one and with two worker
processes. Wall time of every step comes from diagnose's progress messages.

Writes ``benchmark_diagnose.md`` to ``out_dir``. Run:
``python benchmarks/bench_diagnose.py [--quick] [--out DIR]`` (quick: 12 x 6 mesh).
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_diagnose.md"
NOISE = 0.002
SEED = 20261122
LIMIT_S = 300.0
CANDIDATES = ("point_mass", "thickness_taper", "ply_misalignment", "elastic_foundation",
              "local_stiffness_loss")  # fmt: skip


def cases(quick=False):
    """``{label: (case, mesh)}``: the measured plate and a concealed 1 g mass."""
    from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
    from bayesplate.discrepancy import PointMass

    case = load_case(bundled_case_path("frederiksen_t300"))
    mesh = (12, 6) if quick else case.mesh
    fine = PlateModel.from_case(case, mesh=(2 * mesh[0], 2 * mesh[1]))
    plate = PointMass().apply(fine, np.array([1.0, 23.0, 14.0]))
    f = plate.solve(stiffness_from_engineering(case.reference), 14).frequency_Hz
    f = np.sort(f * (1 + NOISE * np.random.default_rng(SEED).standard_normal(f.size)))
    concealed = case.with_measured(frequency_Hz=f, sigma_Hz=NOISE * f)
    return {"measured Frederiksen plate": (case, mesh), "concealed 1 g mass": (concealed, mesh)}


def time_diagnose(case, mesh, workers):
    """One timed diagnose: total wall and CPU seconds, the verdict, per-step wall times."""
    from bayesplate import PlateModel
    from bayesplate.discrepancy.diagnose import diagnose

    steps, last = [], [time.perf_counter()]

    def progress(message):
        now = time.perf_counter()
        name = message.split(":")[0]
        name = "mesh check" if name.startswith("mesh") else name
        if name in CANDIDATES:  # reported together once all of them are fitted
            name = "candidates"
        if steps and steps[-1][0] == name:
            steps[-1] = (name, steps[-1][1] + now - last[0])
        else:
            steps.append((name, now - last[0]))
        last[0] = now

    load = os.getloadavg()[0]
    wall, cpu = time.perf_counter(), _cpu_seconds()
    model = PlateModel.from_case(case, mesh=mesh)
    last[0] = time.perf_counter()
    d = diagnose(case, model=model, rng=0, workers=workers, progress=progress)
    return {
        "wall_s": time.perf_counter() - wall,
        "cpu_s": _cpu_seconds() - cpu,
        "verdict": d.verdict + (f" ({d.chosen.name})" if d.chosen else ""),
        "steps": steps,
        "load": (load, os.getloadavg()[0]),
    }


def _cpu_seconds():
    """CPU time of this process and its finished children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def write_report(rows, info, out_dir, quick=False):
    cmd = f"python benchmarks/bench_diagnose.py{' --quick' if quick else ''}"
    lines = [
        f"Made by `{cmd}` on {datetime.date.today().isoformat()}.",
        "",
        "# diagnose: time on a 14-frequency case",
        "",
        f"Machine: {info['cpu']}, {info['nproc']} processors; {info['platform']}; Python "
        f"{info['python']}, numpy {info['numpy']}, scipy {info['scipy']}. Target: under "
        f"{LIMIT_S / 60:.0f} min on 2 cores. CPU time includes the worker processes.",
        "",
        "| case | mesh | workers | verdict | wall (s) | CPU (s) | load before / after | "
        "within target |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['mesh'][0]} x {r['mesh'][1]} | {r['workers']} | "
            f"{r['verdict']} | {r['wall_s']:.0f} | {r['cpu_s']:.0f} | "
            f"{r['load'][0]:.2f} / {r['load'][1]:.2f} | "
            f"{'yes' if r['wall_s'] < LIMIT_S else 'NO'} |"
        )
    for case in dict.fromkeys(r["case"] for r in rows):
        one = [r for r in rows if r["case"] == case and r["workers"] == 1]
        two = [r for r in rows if r["case"] == case and r["workers"] == 2]
        if one and two:
            lines.append(f"\n{case}: two workers take {two[0]['wall_s'] / one[0]['wall_s']:.2f}"
                         " of one worker's wall time (same run, same machine).")  # fmt: skip
    lines += ["", "Wall time of each step (s), two workers:", ""]
    for r in rows:
        if r["workers"] == 2:
            steps = ", ".join(f"{name} {s:.0f}" for name, s in r["steps"])
            lines.append(f"- {r['case']}: {steps}")
    path = pathlib.Path(out_dir) / REPORT
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def main(out_dir, quick=False):
    rows = []
    for label, (case, mesh) in cases(quick).items():
        for workers in (1, 2):
            r = time_diagnose(case, mesh, workers)
            rows.append({"case": label, "mesh": mesh, "workers": workers, **r})
            print(f"{label}, {workers} worker(s): {r['wall_s']:.0f} s, {r['verdict']}",
                  flush=True)  # fmt: skip
    write_report(rows, _machine.machine(), out_dir, quick)
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="12 x 6 mesh")
    parser.add_argument("--out", default=pathlib.Path(__file__).parents[1] / "reports")
    args = parser.parse_args()
    main(args.out, quick=args.quick)
