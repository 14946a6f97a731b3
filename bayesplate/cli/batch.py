"""``bayesplate batch``: the chosen steps on many case files, on a Dask cluster."""

from __future__ import annotations

import argparse

from .options import (
    FORWARD_CHOICES,
    METHOD_CHOICES,
    add_mesh_option,
    add_pairing_option,
    chain_steps,
    mesh_of,
    positive_int,
)

__all__ = ["register"]

#: :data:`bayesplate.batch.STEPS`, spelled here so that ``--help`` imports no numerics, and
#: ``population``: every case as one plate of a population (``sample --hierarchical``).
STEP_CHOICES = ("estimate", "sample", "diagnose", "population")


def steps_list(text):
    """``"estimate,diagnose"`` -> ``("estimate", "diagnose")`` (an argparse type)."""
    steps = tuple(s.strip() for s in text.split(",") if s.strip())
    bad = [s for s in steps if s not in STEP_CHOICES]
    if bad or not steps:
        raise argparse.ArgumentTypeError(
            f"{text!r}: a comma-separated list of {', '.join(STEP_CHOICES)}"
        )
    return tuple(dict.fromkeys(steps))


def run(args):
    """Run the batch; the exit status is 1 when any case failed (the others finished).

    The ``population`` step runs after the per-case steps, on all the cases at once.
    """
    per_case = tuple(s for s in args.steps if s != "population")
    status = run_cases(args, per_case) if per_case else 0
    if "population" in args.steps:
        status = max(status, run_population_step(args))
    return status


def run_population_step(args):
    """The cases as one population: ``OUT/population.json``, ``.nc`` and ``population.png``."""
    import pathlib

    from ..batch.run import find_cases
    from ..io import load_case
    from .sample_plates import run_population

    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cases = [load_case(path) for path in find_cases(args.cases)]
    population = argparse.Namespace(**vars(args))
    population.json = str(out / "population.json")
    population.out = str(out / "population.nc")
    population.output = str(out)
    population.full = args.forward == "full"
    population.inputs = None
    return run_population(population, cases)


def run_cases(args, steps):
    """The per-case steps on the Dask cluster; 1 when any case failed."""
    from ..batch import BatchOptions, run_batch

    options = BatchOptions(
        steps=steps,
        mesh=mesh_of(args),
        method=args.method,
        forward=args.forward,
        pairing=args.pairing,
        seed=args.seed,
        walkers=args.walkers,
        max_steps=args.max_steps,
        min_ess=args.min_ess,
    )
    result = run_batch(
        args.cases, args.out, options, scheduler=args.scheduler, workers=args.workers, progress=None
    )
    for case, step in result.failed:
        row = next(r for r in result.rows if (r["case"], r["step"]) == (case, step))
        print(f"failed: {case} {step}: {row['reason']}")
    print(
        f"{len(result.rows)} results ({len(result.computed)} computed, "
        f"{len(result.skipped)} already done, {len(result.failed)} failed): "
        f"{', '.join(str(p) for p in result.paths)}"
    )
    return 1 if result.failed else 0


def register(sub):
    """Add the ``batch`` subcommand."""
    p = sub.add_parser(
        "batch",
        help="run estimate, sample and/or diagnose on many case files (Dask)",
        description="Run the chosen steps on every case file of a folder or glob pattern, "
        "one task per case and step, on a Dask LocalCluster of single-threaded worker "
        "processes (default) or on a running Dask scheduler (--scheduler tcp://HOST:8786; "
        "its workers need bayesplate installed). Writes OUT/<case>/<step>.json (the "
        "single-case command's --json), OUT/summary.csv (summary.parquet with pyarrow) and "
        "OUT/summary.png. A re-run skips every step whose case file and options are "
        "unchanged; a failed case is recorded with its reason and the others go on (exit "
        "status 1 when any failed). The step population takes every case as one plate of a "
        "material (as sample --hierarchical): OUT/population.json, population.nc and "
        "population.png. Progress goes to standard error.",
    )
    p.add_argument(
        "cases",
        metavar="DIR_OR_GLOB",
        help="a folder of case files (*.toml), a glob pattern (quoted) or one file",
    )
    p.add_argument("-o", "--out", required=True, metavar="OUT", help="output folder")
    p.add_argument(
        "--steps",
        type=steps_list,
        default=("estimate",),
        help="comma-separated steps (default: estimate): " + ",".join(STEP_CHOICES),
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="address of a running Dask scheduler (default: a local cluster)",
    )
    p.add_argument(
        "--workers",
        type=positive_int,
        help="worker processes of the local cluster (default: the cores)",
    )
    p.add_argument(
        "--method",
        choices=METHOD_CHOICES,
        default="MVE",
        help="estimator of the estimate step (default MVE)",
    )
    p.add_argument(
        "--forward",
        choices=FORWARD_CHOICES,
        default="auto",
        help="model of the estimate step (as `bayesplate estimate --forward`)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of sample and diagnose (default 0)")
    p.add_argument("--walkers", type=positive_int, default=32, help="sample: walkers (32)")
    p.add_argument(
        "--max-steps", type=chain_steps, default=5000, help="sample: cap on steps (5000)"
    )
    p.add_argument(
        "--min-ess",
        type=float,
        default=2000.0,
        help="sample: effective samples per constant to reach (2000)",
    )
    add_pairing_option(p)
    add_mesh_option(p)
    p.set_defaults(func=run)
