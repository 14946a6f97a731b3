"""Benchmark of ``sample --hierarchical`` (issue 42): ten plates, fast models and sampling.

The workload: ten synthetic single-layer plates of one material (the geometries of
``studies/population_coverage.py``: sizes and thicknesses varied), eight frequencies on a
``--mesh`` mesh (default 16 x 10) with 0.5 % noise, a fixed seed. Timed separately: every
plate's setup (pilot B, certified fast model, MAP, the Laplace of its likelihood) on the
batch engine's pool (:func:`bayesplate.cli.sample_plates.fit_plates`) with one worker and
with two, and the population's sampling (:func:`bayesplate.sampling.sample_population`,
the command line's defaults: 32 walkers, ESS 2000, R-hat 1.01). One run each, in this process.

Writes ``benchmark_hierarchical.md``. Run:
``python benchmarks/bench_hierarchical.py [--mesh 16 10] [--out reports]``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time
import warnings
from datetime import datetime, timezone

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_hierarchical.md"
ROOT = pathlib.Path(__file__).resolve().parents[1]
SEED = 20261128
TRUE_MU = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
TRUE_TAU = np.array([0.04, 0.05, 0.04, 0.03, 0.06, 0.06])


def cases(mesh):
    """The ten plates' cases (their constants drawn around TRUE_MU with TRUE_TAU)."""
    from studies import population_coverage as study

    rng = np.random.default_rng(SEED)
    out = []
    for p, geometry in enumerate(study.GEOMETRIES):
        c = np.exp(np.log(TRUE_MU) + TRUE_TAU * rng.standard_normal(6))
        case, _ = study.synthetic_plate(f"P{p + 1}", geometry, c, rng, mesh=mesh)
        out.append(case)
    return out


def run(mesh):
    from bayesplate.cli.sample_plates import fit_plates
    from bayesplate.sampling import sample_population

    warnings.simplefilter("ignore")
    plates = cases(mesh)
    bench = {"load": [os.getloadavg()]}
    for workers in (1, 2):
        started = time.perf_counter()
        fits = fit_plates(plates, np.random.default_rng(SEED), mesh, workers)
        bench[f"build_{workers}"] = time.perf_counter() - started
        bench["load"].append(os.getloadavg())
        print(f"build, {workers} worker(s): {bench[f'build_{workers}']:.1f} s", flush=True)
    p = fits[0].problem
    started = time.perf_counter()
    r = sample_population(fits, p.mu_b, p.V_b, rng=SEED, n_walkers=32, min_ess=2000.0)
    bench["sampling"] = time.perf_counter() - started
    bench["load"].append(os.getloadavg())
    bench["result"] = r
    print(f"sampling: {bench['sampling']:.1f} s, {r.message}", flush=True)
    return bench


def write_report(bench, info, mesh, out_dir):
    r = bench["result"]
    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    load = "; ".join(" ".join(f"{x:.2f}" for x in a) for a in bench["load"])
    lines = [
        "# Benchmark: `sample --hierarchical`, ten plates",
        "",
        f"{when}; code {_machine.commit(ROOT)}; {info['cpu']}, {info['nproc']} cores, "
        f"{info['memory']}, BLAS {info['blas']}; Python {info['python']}, numpy "
        f"{info['numpy']}, scipy {info['scipy']}, emcee {info['emcee']}.",
        f"Load average (1, 5, 15 min) at start and after each stage: {load} (a shared machine: "
        "the times are upper bounds of an idle one's).",
        "",
        f"Ten synthetic plates, {mesh[0]} x {mesh[1]} mesh, 8 frequencies, 0.5 % noise, each "
        "frequency labelled with its mode (as `studies/population_coverage.py` makes them, so "
        "each plate is paired by its labels, not by likelihood over assignments), seed "
        f"{SEED} (`python benchmarks/bench_hierarchical.py`). One run of each stage.",
        "",
        "| stage | wall time (s) |",
        "|---|---|",
        f"| fast models (pilot, build, MAP, Laplace), 1 worker | {bench['build_1']:.1f} |",
        f"| fast models on the batch pool, 2 workers | {bench['build_2']:.1f} |",
        f"| sampling the population ({r.n_walkers} walkers, {r.n_steps} steps) | "
        f"{bench['sampling']:.1f} |",
        "",
        f"Chain: {r.status}; {r.message}; {len(r.refined)} plates linearised again. "
        f"Outlier probabilities {', '.join(f'{x:.2f}' for x in r.outlier)}.",
    ]
    return _machine.write_report(out_dir, REPORT, lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", type=int, nargs=2, default=(16, 10))
    parser.add_argument("--out", default=str(ROOT / "reports"))
    args = parser.parse_args(argv)
    mesh = tuple(args.mesh)
    bench = run(mesh)
    print(write_report(bench, _machine.machine("emcee"), mesh, args.out))


if __name__ == "__main__":
    main()
