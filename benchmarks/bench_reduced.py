"""Build, certificate and speed of the certified reduced model on the Frederiksen plate.

One run, one process: build the reduced basis on the case's own 50 x 50 mesh over the
prior's 3-sigma box, certify it greedily (``bayesplate.reduced.fast_model``), then time

- one reduced evaluation with frequencies and sensitivities (``ReducedModel.solve``) and
  with eigenvalues only (``ReducedModel.eigenvalues``), best of several batches at points of
  the box;
- one full evaluation (``PlateModel.solve``, frequencies and sensitivities) at a few points
  of the box;

and check the certificate once more on independent points of the box. BLAS is limited to one
thread (as in the main table of ``benchmark_forward.md``): the small dense eigenproblems run
up to ten times slower with threads on a busy machine. The full solves run one after another
(threads do not help them: ARPACK and SuperLU hold the GIL).

Writes ``benchmark_reduced.md``. Run: ``python benchmarks/bench_reduced.py [--quick]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402 - BLAS threads are fixed before numpy loads
import pathlib  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_reduced.md"
CASE = "frederiksen_t300"
SEED = 20070461
N_MODES = 14  # the measured frequencies of the case
N_SNAPSHOTS = 16  # design points besides the prior mean (the default of fast_model)
QUICK_MESH = (24, 12)
TARGET_TOTAL_S = 120.0  # issue 4: build + certify + a full posterior in under 2 minutes
TARGET_EVAL_S = 1e-3  # "well under 1 ms" per reduced evaluation
N_FULL = 3  # full solves timed
N_VALIDATE = 10  # independent points for the second check
EVAL_BATCH = 200  # reduced evaluations per timed batch
EVAL_REPEATS = 5  # batches; the best is kept
N_EVAL_POINTS = 50
# a posterior of the size the sampler is expected to draw, for the projection only
WALKERS, STEPS = 32, 2000


def _timed(fn, *args, **kwargs):
    """``(fn(*args, **kwargs), wall seconds, CPU seconds of this process)``."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - wall, time.process_time() - cpu


def _per_call(fn, points):
    """Best-of-batches wall and CPU time of one call of ``fn`` cycling over ``points``, s."""
    fn(points[0])
    wall = cpu = np.inf
    for _ in range(EVAL_REPEATS):
        start, start_cpu = time.perf_counter(), time.process_time()
        for i in range(EVAL_BATCH):
            fn(points[i % len(points)])
        wall = min(wall, (time.perf_counter() - start) / EVAL_BATCH)
        cpu = min(cpu, (time.process_time() - start_cpu) / EVAL_BATCH)
    return wall, cpu


def measure(mesh=None):
    """Build, certify and time; a dict of numbers and objects for the report."""
    from bayesplate.io import bundled_case_path, load_case
    from bayesplate.plate.model import PlateModel
    from bayesplate.reduced import certify, fast_model, prior_stiffness, stiffness_box

    case = load_case(bundled_case_path(CASE))
    model = PlateModel.from_case(case, mesh=mesh)
    mean_b, _ = prior_stiffness(case.prior)
    box = stiffness_box(case.prior)
    rng = np.random.default_rng(SEED)
    load = [os.getloadavg()]
    fast, build_wall, build_cpu = _timed(
        fast_model, model, mean_b, box, N_MODES, n_snapshots=N_SNAPSHOTS, rng=rng
    )
    load.append(os.getloadavg())
    reduced = fast.reduced
    points = box.sample(N_EVAL_POINTS, rng)
    t_solve = _per_call(lambda b: reduced.solve(b), points)
    t_values = _per_call(lambda b: reduced.eigenvalues(b), points)
    full = [_timed(model.solve, b, N_MODES) for b in points[:N_FULL]]
    load.append(os.getloadavg())
    validation, *t_validate = _timed(certify, model, reduced, n_test=N_VALIDATE, rng=rng)
    load.append(os.getloadavg())
    rel = [
        np.abs(reduced.solve(r.b).sensitivities - r.sensitivities).max(axis=1)
        / np.abs(r.sensitivities).max(axis=1)
        for r, *_ in full
    ]
    return {
        "mesh": model.mesh,
        "n_dofs": model.mesh.n_dofs,
        "box": box,
        "fast": fast,
        "build_wall_s": build_wall,
        "build_cpu_s": build_cpu,
        # points added by enrichment reuse the solves of their certification round
        "n_full_solves": N_SNAPSHOTS + 1 + sum(c.n_test for c in fast.history),
        "reduced_solve_s": t_solve,
        "reduced_eigenvalues_s": t_values,
        "full_wall_s": [t for _, t, _ in full],
        "full_cpu_s": [c for _, _, c in full],
        "validation": validation,
        "validation_wall_s": t_validate[0],
        "sensitivity_rel_diff": float(np.max(rel)),
        "load": load,
    }


# ----------------------------------------------------------------------------- the report


def machine():
    """Processor, core count, memory and library versions (see ``_machine``)."""
    return _machine.machine()


def _table(headers, rows):
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _gpa(x):
    return f"{x / 1e9:.3g}"


def _verdict(t_solve, t_values):
    """Which evaluation paths are under the 1 ms target."""
    if t_solve < TARGET_EVAL_S:
        return "both are under the 1 ms target."
    if t_values < TARGET_EVAL_S:
        return (
            "the eigenvalues-only path (what a sampler without gradients needs) is under 1 ms, "
            "the path with sensitivities is not."
        )
    return "neither is under 1 ms."


def write_report(m, info, out_dir, quick=False, date=None):
    """Write the Markdown report; returns its path."""
    from bayesplate.quantities import STIFFNESS_NAMES

    fast, reduced = m["fast"], m["fast"].reduced
    cert, val = fast.certificate, m["validation"]
    flag = " --quick" if quick else ""
    date = date or _machine.utc_now()
    loads = np.array(m["load"])
    full = float(np.mean(m["full_wall_s"]))
    full_cpu = float(np.mean(m["full_cpu_s"]))
    (t_solve, c_solve), (t_values, c_values) = m["reduced_solve_s"], m["reduced_eigenvalues_s"]
    sampling = WALKERS * STEPS * t_values
    total = m["build_wall_s"] + sampling
    total_cpu = m["build_cpu_s"] + WALKERS * STEPS * c_values
    mesh = m["mesh"]
    rounds = _table(
        ["round", "basis size", "max rel. error", "passed"],
        [
            [k + 1, c.basis_size, f"{c.max_rel_error:.2e}", "yes" if c.passed else "no"]
            for k, c in enumerate(fast.history)
        ],
    )
    modes = _table(
        ["mode"] + [str(i + 1) for i in range(cert.n_modes)],
        [
            ["certificate"] + [f"{e:.1e}" for e in cert.per_mode_max],
            ["independent check"] + [f"{e:.1e}" for e in val.per_mode_max],
        ],
    )
    box = _table(
        ["", *STIFFNESS_NAMES],
        [
            ["lower (GPa)", *map(_gpa, m["box"].lower)],
            ["prior mean (GPa)", *map(_gpa, reduced.reference)],
            ["upper (GPa)", *map(_gpa, m["box"].upper)],
        ],
    )
    lines = [
        f"Made by `python benchmarks/bench_reduced.py{flag}` (seed {SEED}) on {date}; not "
        "part of `studies/run_all.py` (timings belong to a machine).",
        "",
        f"# Certified reduced model: Frederiksen plate, {mesh.nx}x{mesh.ny} mesh, {N_MODES} modes",
        "",
        f"Machine: {info['cpu']}, {info['nproc']} processors available; {info['platform']}; "
        f"Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}. BLAS limited "
        f"to one thread; full solves one after another. Load average (1 min) "
        f"{loads[0, 0]:.2f} before the run and {loads[1:, 0].min():.2f} to "
        f"{loads[1:, 0].max():.2f} during it, on {info['nproc']} processors: the machine is "
        "shared, so wall times are inflated by other work; CPU times are this process's.",
        "",
        "## Summary",
        "",
        _table(
            ["quantity", "value"],
            [
                ["unknowns of the full model", m["n_dofs"]],
                [
                    "build + certify (wall / CPU)",
                    f"{m['build_wall_s']:.1f} s / {m['build_cpu_s']:.1f} s",
                ],
                [
                    "full solves in it",
                    f"{m['n_full_solves']} ({N_SNAPSHOTS + 1} snapshot points, "
                    f"{sum(c.n_test for c in fast.history)} held-out, "
                    f"{len(reduced.points) - N_SNAPSHOTS - 1} of them added to the basis)",
                ],
                ["certification rounds", len(fast.history)],
                ["basis size", reduced.size],
                ["symmetry classes (basis vectors)", " + ".join(map(str, reduced.block_sizes))],
                [
                    "dense eigenproblems per evaluation",
                    " + ".join(map(str, reduced._blocks.bin_sizes)),
                ],
                [
                    "certificate (max rel. frequency error)",
                    f"{cert.max_rel_error:.2e} on {cert.n_test} held-out points "
                    f"({'passed' if cert.passed else 'FAILED'}, tolerance {cert.tolerance:.0e})",
                ],
                [
                    "independent check",
                    f"{val.max_rel_error:.2e} on {val.n_test} more points "
                    f"({m['validation_wall_s']:.1f} s, not part of the build)",
                ],
                [
                    "largest coupling between classes (rounding, dropped)",
                    f"{reduced.max_dropped_coupling:.1e}",
                ],
                [
                    "reduced evaluation, frequencies + sensitivities (wall / CPU)",
                    f"{1e3 * t_solve:.3f} ms / {1e3 * c_solve:.3f} ms",
                ],
                [
                    "reduced evaluation, eigenvalues only (wall / CPU)",
                    f"{1e3 * t_values:.3f} ms / {1e3 * c_values:.3f} ms",
                ],
                [
                    "full evaluation, frequencies + sensitivities (wall / CPU)",
                    f"{full:.2f} s / {full_cpu:.2f} s (mean of {len(m['full_wall_s'])})",
                ],
                ["ratio full / reduced (with sensitivities)", f"{full / t_solve:,.0f}"],
                ["ratio full / reduced (eigenvalues only)", f"{full / t_values:,.0f}"],
                [
                    "sensitivities, reduced vs full (max over modes of max abs diff / "
                    "largest entry of the mode)",
                    f"{m['sensitivity_rel_diff']:.1e}",
                ],
            ],
        ),
        "",
        "## Against the targets of issue 4",
        "",
        f"- Reduced evaluation with sensitivities {1e3 * t_solve:.3f} ms (CPU "
        f"{1e3 * c_solve:.3f} ms), eigenvalues only {1e3 * t_values:.3f} ms (CPU "
        f"{1e3 * c_values:.3f} ms). In CPU time, about what an idle machine would take, "
        + _verdict(c_solve, c_values)
        + " In wall time at this load, "
        + _verdict(t_solve, t_values)
        + " Almost all of it is LAPACK on the dense blocks (syevd with vectors, syev without).",
        f"- Build + certify {m['build_wall_s']:.1f} s; a posterior of {WALKERS} walkers x "
        f"{STEPS} steps = {WALKERS * STEPS:,} evaluations at {1e3 * t_values:.3f} ms is "
        f"{sampling:.0f} s of model time (projected, not sampled here), "
        f"{total:.0f} s in all against the {TARGET_TOTAL_S:.0f} s target "
        f"({'meets' if total < TARGET_TOTAL_S else 'misses'} it) at this load. In CPU time, "
        f"about what an idle machine would take: {m['build_cpu_s']:.0f} s + "
        f"{WALKERS * STEPS * c_values:.0f} s = {total_cpu:.0f} s "
        f"({'meets' if total_cpu < TARGET_TOTAL_S else 'misses'} it). The build is "
        f"{m['n_full_solves']} full solves; nothing else in it takes more than a few seconds.",
        "",
        "## Certification rounds",
        "",
        "Each round checks the basis on fresh Latin-hypercube points of the box against the "
        "full model; a failed round adds the modes at its worst points to the basis.",
        "",
        rounds,
        "",
        "## Largest relative frequency error by mode",
        "",
        modes,
        "",
        "## The box",
        "",
        "The prior on the engineering constants carried to `b` to first order, +-3 sd, with "
        "the positive coefficients kept above a tenth of their mean (G23 = 4 +- 4.5 GPa "
        "would reach zero):",
        "",
        box,
        "",
        "## Settings",
        "",
        f"`fast_model(model, mean_b, box, {N_MODES}, n_snapshots={N_SNAPSHOTS}, "
        f"rng=default_rng({SEED}))`, otherwise its defaults: "
        f"{len(reduced.points)} snapshot points in the final basis, {reduced.margin} extra "
        f"modes per snapshot, compression tolerance {reduced.rank_tol:g} in the energy norm, "
        f"{cert.n_test} held-out points per round. Reduced times are the best of "
        f"{EVAL_REPEATS} batches of {EVAL_BATCH} calls at {N_EVAL_POINTS} points of the box.",
        "",
    ]
    path = _machine.write_report(out_dir, REPORT, lines)
    return path


def main(out_dir="reports", quick=False):
    """Measure and write the report; returns its path."""
    m = measure(QUICK_MESH if quick else None)
    path = write_report(m, machine(), out_dir, quick=quick)
    print(path.read_text())
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_MESH} mesh, a smoke run")
    parser.add_argument("--out", default=str(pathlib.Path(__file__).parents[1] / "reports"))
    args = parser.parse_args()
    main(args.out, quick=args.quick)
