"""Benchmark of start-up (issue 12: ``bayesplate --help`` in under 0.3 s on 2 cores).

Times ``python -m bayesplate.cli --help`` and ``python -m bayesplate.cli <command> --help``
for every subcommand as whole processes (wall clock from start to exit), each ``--runs``
times after one warm-up, and the same commands in a checkout of a base commit (by default
9f5ebd1, before the package's exports became lazy), run in turn (now, base, now, base, ...)
so that a drift of the machine's speed hits both alike. The interpreter alone (``python -c
pass``) and ``import numpy`` are timed as yardsticks: no command can start faster than the
first, and the second is what importing any numerics costs at least.

Writes ``benchmark_startup.md`` to ``out_dir``. Run:
``python benchmarks/bench_startup.py [--runs 10] [--base-rev 9f5ebd1 | --base-dir DIR | --no-base]
[--out reports]``. Without ``--base-dir`` the base is checked out in a throwaway git worktree
(``git worktree add --detach``), removed afterwards.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import subprocess
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_startup.md"
ROOT = pathlib.Path(__file__).resolve().parents[1]
TARGET_S = 0.3
BASE_REV = "9f5ebd1"


def subcommands():
    """The subcommands of this tree's parser, in the order of ``bayesplate --help``."""
    sys.path.insert(0, str(ROOT))
    from bayesplate.cli import build_parser

    (sub,) = (a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices)


def _env(tree):
    """The environment with `tree` first on the path (None: no tree, the yardsticks)."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tree), env.get("PYTHONPATH")]))
    return env


def wall_time(argv, tree):
    """Seconds from start to exit of one run of `argv` with `tree` first on the path."""
    env = _env(tree)
    start = time.perf_counter()
    proc = subprocess.run(argv, env=env, cwd=tree or ROOT, capture_output=True)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{argv} in {tree} exited {proc.returncode}: {proc.stderr[-400:]!r}")
    return elapsed


def time_in_turn(argv, trees, runs):
    """``{tree: [seconds, ...]}``: one warm-up each, then `runs` rounds over `trees` in turn."""
    for tree in trees:
        wall_time(argv, tree)
    times = {tree: [] for tree in trees}
    for _ in range(runs):
        for tree in trees:
            times[tree].append(wall_time(argv, tree))
    return times


def run_benchmark(runs, base_dir=None):
    """Times of every help command (now and, with `base_dir`, base) and of the yardsticks."""
    python = sys.executable
    trees = [ROOT] + ([base_dir] if base_dir is not None else [])
    rows, load = [], [os.getloadavg()]
    for label, argv in (
        ("python -c pass", [python, "-c", "pass"]),
        ("python -c 'import numpy'", [python, "-c", "import numpy"]),
    ):
        rows.append({"command": label, "now": time_in_turn(argv, [None], runs)[None]})
    for args in [["--help"]] + [[c, "--help"] for c in subcommands()]:
        times = time_in_turn([python, "-m", "bayesplate.cli", *args], trees, runs)
        row = {"command": "bayesplate " + " ".join(args), "now": times[ROOT]}
        if base_dir is not None:
            row["base"] = times[base_dir]
        rows.append(row)
    load.append(os.getloadavg())
    return {"rows": rows, "load": load, "runs": runs}


def _span(values):
    return f"{min(values):.3f}-{max(values):.3f}"


def write_report(bench, info, out_dir, base_rev=None, date=None):
    """Write the Markdown report; returns its path."""
    date = date or _machine.utc_now()
    machine = ", ".join(f"{k} {v}" for k, v in info.items())
    (l1, l5, l15), (a1, _, _) = bench["load"]
    lines = [
        "# Start-up time of the command line",
        "",
        f"Made by `python benchmarks/bench_startup.py` on {date}.",
        "",
        f"Machine: {machine}.",
        f"Load average before: {l1:.2f} / {l5:.2f} / {l15:.2f} (1, 5, 15 min); after "
        f"(1 min): {a1:.2f}.",
        "",
        f"Wall time of the whole process, seconds: median of {bench['runs']} runs after one "
        "warm-up (min-max beside it), each command as `python -m bayesplate.cli ...`"
        + (f", here and at the base commit {base_rev} run in turn" if base_rev else "")
        + f". Target: every help under {TARGET_S} s.",
        "",
    ]
    with_base = any("base" in r for r in bench["rows"])
    head = "| command | median now | min-max now |"
    rule = "| --- | ---: | ---: |"
    if with_base:
        head += f" median at {base_rev} | min-max at {base_rev} | base / now |"
        rule += " ---: | ---: | ---: |"
    lines += [head + " under target |", rule + " :---: |"]
    for r in bench["rows"]:
        now = statistics.median(r["now"])
        cells = f"| `{r['command']}` | {now:.3f} | {_span(r['now'])} |"
        if with_base:
            if "base" in r:
                base = statistics.median(r["base"])
                cells += f" {base:.3f} | {_span(r['base'])} | {base / now:.1f} |"
            else:
                cells += " | | |"
        target = "yes" if now < TARGET_S else "no"
        lines.append(cells + (f" {target} |" if r["command"].startswith("bayesplate") else " |"))
    lines += [
        "",
        "What makes it short (held by `tests/test_startup.py`, not by a timed test): the "
        "package's public names are imported on first use (PEP 562), each subcommand builds "
        "its parser from the standard library and imports its machinery inside `run`, and "
        "the parser's choices are spelled in `bayesplate.cli.options`; `--help` loads no "
        "numpy, scipy, matplotlib, emcee or arviz, and no module of bayesplate outside "
        "`bayesplate.cli`. The first two rows are the floor: the interpreter alone, and the "
        "least that importing any numerics costs.",
        "",
    ]
    return _machine.write_report(out_dir, REPORT, lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10, help="counted runs per command (10)")
    _machine.add_base_arguments(parser, BASE_REV, ROOT / "reports")
    args = parser.parse_args(argv)
    info = _machine.machine()
    head = None
    if args.no_base:
        bench = run_benchmark(args.runs)
    else:
        with _machine.base_checkout(args.base_rev, args.base_dir, "bench-startup-") as base:
            head = _machine.commit(base)
            bench = run_benchmark(args.runs, base)
    base_rev = None if args.no_base else head
    path = write_report(bench, info, args.out, base_rev=base_rev)
    print(path.read_text())


if __name__ == "__main__":
    main()
