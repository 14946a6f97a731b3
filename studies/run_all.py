"""Regenerate every study's report: ``python -m studies.run_all [--quick] [--out DIR]``.

Each study is a module of this folder with ``main(out_dir, quick=False)``. To add one, add
its module name to ``STUDIES``.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pathlib
import time

import matplotlib

matplotlib.use("Agg")  # files only, never a window

HERE = pathlib.Path(__file__).resolve().parent
REPORTS = HERE.parent / "reports"

STUDIES = [
    "forward_model",
    "sensitivity_figures",
    "paper_tables",
    "concealment",
    "diagnose_frederiksen",
    "prior_bias",
    "spruce_badiane",
    "spruce_input_budget",
    "input_coverage",
    "error_scale",
    "mesh_correction",
]


def load(name):
    """The study module ``studies.<name>``."""
    return importlib.import_module(f"studies.{name}")


def main(out_dir=REPORTS, quick=False, only=None):
    """Run every study (or those in ``only``) into ``out_dir``; return ``{name: seconds}``."""
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    seconds = {}
    for name in STUDIES:
        if only and name not in only:
            continue
        start = time.perf_counter()
        load(name).main(out_dir, quick=quick)
        seconds[name] = time.perf_counter() - start
        print(f"{name}: {seconds[name]:.1f} s", flush=True)
    return seconds


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="each study's quick mode")
    parser.add_argument("--out", default=REPORTS, help="output folder (default: reports/)")
    parser.add_argument("only", nargs="*", help=f"run only these of {', '.join(STUDIES)}")
    args = parser.parse_args()
    unknown = sorted(set(args.only) - set(STUDIES))
    if unknown:
        parser.error(f"unknown studies {', '.join(unknown)}; known: {', '.join(STUDIES)}")
    main(args.out, quick=args.quick, only=args.only)
