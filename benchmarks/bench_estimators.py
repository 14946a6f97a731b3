"""Benchmark of the estimators on the fast model against the full model (issue 12).

Issue 12's figure: MVE's 200 iterations on the spruce-size case (bundled
``badiane_spruce_5R``: 580 x 215 mm, 60 x 24 mesh, 12,200 unknowns, 10 frequencies; MVE
by order reaches its 200-iteration cap there) in under 3 s. Per case it times, in one
process and one run of this script:

- the full path (``forward="full"``: every iterate a finite-element solve), once per method
  (minutes);
- the fast model's build and certification (``case_fast_model``), once;
- the fast path on that model (``estimate_on_fast``: iterations on the reduced model, the
  trust-region checks off the box, the full model's check of the answer), ``--runs`` times
  each, median; each run starts from the built model (not from the one the last run
  enriched);

and writes the largest relative difference of the constants between the two paths.
How the costs grow with the number of frequencies is measured on the Frederiksen plate
with its first 6, 10 and 14 frequencies (``--scaling``).

Writes ``benchmark_estimators.md``. Run:
``python benchmarks/bench_estimators.py [--runs 3] [--cases badiane_spruce_5R frederiksen_t300]
[--scaling] [--out reports]``.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

from bayesplate.estimators import case_fast_model, estimate, estimate_on_fast  # noqa: E402
from bayesplate.io import atomic_write_text, bundled_case_path, load_case  # noqa: E402
from bayesplate.matching.pairing import pair_measured  # noqa: E402
from bayesplate.plate.model import PlateModel  # noqa: E402

REPORT = "benchmark_estimators.md"
METHODS = ("B", "MVE", "MVE-mod")
TARGET_S = 3.0  # MVE's 200 iterations on the spruce-size case


def _timed(fn, *args, **kwargs):
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


def measure_case(name, runs, n_measured=None):
    """Times and differences of every method on one case (its first `n_measured` peaks)."""
    case = load_case(bundled_case_path(name))
    if n_measured is not None:
        case = case.with_measured(case.measured.select(np.arange(n_measured)))
    model = PlateModel.from_case(case)
    pair = pair_measured(case, model, None, "order")
    fast, build = _timed(case_fast_model, case, model, pair.n_modes())
    rows = []
    for method in METHODS:
        full, t_full = _timed(estimate, case, method, model=model, forward="full")
        times, result = [], None
        for _ in range(runs):
            (result, _), t = _timed(estimate_on_fast, case, method, model, fast)
            times.append(t)
        diff = float(np.max(np.abs(result.constants / full.constants - 1.0)))
        rows.append(
            {
                "method": method,
                "iterations": (result.iterations, full.iterations),
                "status": (result.status, full.status),
                "full_s": t_full,
                "fast_s": statistics.median(times),
                "fast_all": times,
                "full_solves": full.n_solves,
                "check_solves": result.check.n_full_solves,
                "diff": diff,
                "check": result.check.max_rel_error,
            }
        )
        print(f"{name} {method}: full {t_full:.1f} s, fast {rows[-1]['fast_s']:.2f} s", flush=True)
    return {
        "case": name,
        "m": case.measured.size,
        "mesh": (model.mesh.nx, model.mesh.ny),
        "dofs": model.mesh.n_dofs,
        "build_s": build,
        "build_solves": fast.build_solves,
        "basis": fast.reduced.size,
        "rows": rows,
    }


def markdown(results, runs, load):
    info = _machine.machine()
    out = [
        f"Made by `python benchmarks/bench_estimators.py` on {_machine.utc_now()}.",
        "",
        "# The estimators on the certified fast model against the full model",
        "",
        f"Machine: {info['cpu']}, {info['nproc']} processors, {info['memory']}; "
        f"{info['platform']}; Python {info['python']}, numpy {info['numpy']}, "
        f"scipy {info['scipy']}. Load average before / after: {load[0]:.2f} / {load[1]:.2f}.",
        "",
        'Full: `estimate(..., forward="full")`, every iterate a finite-element solve, one '
        f"run. Fast: `estimate_on_fast` on a fast model built once, median of {runs} runs "
        "(iterations on the reduced model, trust-region checks off the prior's box, the full "
        "model's check of the answer: its full solves are in 'check solves'). The build is "
        "paid once per case and shared by the three methods (and, in `bayesplate report`, by "
        "the sampler). Difference: largest relative difference of a constant between the two "
        "answers (the stopping tolerance is 1e-3).",
        "",
        "| case | frequencies | mesh (unknowns) | build (s, full solves, basis) | method | "
        "iterations fast / full | full (s) | fast (s) | full / fast | check solves | "
        "difference | status fast / full |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        for row in r["rows"]:
            out.append(
                f"| {r['case']} | {r['m']} | {r['mesh'][0]} x {r['mesh'][1]} ({r['dofs']}) | "
                f"{r['build_s']:.1f}, {r['build_solves']}, {r['basis']} | {row['method']} | "
                f"{row['iterations'][0]} / {row['iterations'][1]} | {row['full_s']:.1f} | "
                f"{row['fast_s']:.2f} | {row['full_s'] / row['fast_s']:.0f} | "
                f"{row['check_solves']} | {row['diff']:.1e} | {row['status'][0]} / "
                f"{row['status'][1]} |"
            )
    spruce = [r for r in results if r["case"] == "badiane_spruce_5R"]
    if spruce:
        mve = next(row for row in spruce[0]["rows"] if row["method"] == "MVE")
        verdict = "met" if mve["fast_s"] < TARGET_S else "**missed**"
        out += [
            "",
            f"Target (issue 12): MVE's {mve['iterations'][1]} iterations on the spruce-size "
            f"case in under {TARGET_S:.0f} s: {mve['fast_s']:.2f} s on the fast model "
            f"({verdict}; {mve['full_s']:.0f} s on the full model, "
            f"{mve['full_s'] / mve['fast_s']:.0f} times as long), plus the build "
            f"({spruce[0]['build_s']:.1f} s, once per case).",
        ]
    return "\n".join(out) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--cases", nargs="+", default=["badiane_spruce_5R", "frederiksen_t300"])
    parser.add_argument(
        "--scaling",
        action="store_true",
        help="also the Frederiksen plate with its first 6 and 10 frequencies",
    )
    parser.add_argument("--out", default=pathlib.Path(__file__).resolve().parents[1] / "reports")
    args = parser.parse_args()
    load0 = os.getloadavg()[0]
    results = [measure_case(name, args.runs) for name in args.cases]
    if args.scaling:
        results += [measure_case("frederiksen_t300", args.runs, m) for m in (6, 10)]
    text = markdown(results, args.runs, (load0, os.getloadavg()[0]))
    atomic_write_text(pathlib.Path(args.out) / REPORT, text)
    print(text)


if __name__ == "__main__":
    main()
