"""What diagnose's stage store saves when a killed run is run again (issue 14).

``bayesplate diagnose CASE --mesh NX NY --seed 1 --workers 2`` three ways, each in a fresh
folder: uninterrupted without a store (``--no-cache``); started with its store, interrupted
(SIGINT, as Ctrl-C: the worker pool is stopped and reaped, so its processor time is
counted) at ``--at`` (default 0.7) of the uninterrupted wall time; then run again on that
store to the end. Processor time is user + system of the command and its forked workers
(``RUSAGE_CHILDREN``). The saving is the uninterrupted run's processor time less the run
again's; the JSON documents of the uninterrupted run and of the run again are compared.

Writes ``benchmark_diagnose_resume.md``. Run: ``python benchmarks/bench_diagnose_resume.py
[--case frederiksen_t300] [--mesh 12 6] [--at 0.7] [--out reports]``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import resource
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_diagnose_resume.md"
ROOT = pathlib.Path(__file__).resolve().parents[1]
STORED = "taken from the store"


def _cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def one(argv, cwd, kill_after=None):
    """(exit status, wall s, processor s, stdout) of one command, interrupted on request."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cpu, start = _cpu(), time.perf_counter()
    proc = subprocess.Popen(
        argv,
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        preexec_fn=_default_sigint,
    )
    if kill_after is not None:
        try:
            proc.wait(timeout=kill_after)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate()
    return proc.returncode, time.perf_counter() - start, _cpu() - cpu, out


def main(case, mesh, at, out_dir):
    base = [
        sys.executable,
        "-m",
        "bayesplate.cli",
        "diagnose",
        case,
        "--mesh",
        *map(str, mesh),
        "--seed",
        "1",
        "--workers",
        "2",
        "--json",
        "out.json",
    ]
    load = [os.getloadavg()]
    with tempfile.TemporaryDirectory(prefix="bench-resume-") as tmp:
        tmp = pathlib.Path(tmp)
        (tmp / "full").mkdir()
        (tmp / "resumed").mkdir()
        status, wall, cpu_full, _ = one([*base, "--no-cache"], tmp / "full")
        assert status == 0, status
        load.append(os.getloadavg())
        killed, wall_k, cpu_killed, _ = one(base, tmp / "resumed", kill_after=at * wall)
        stored = len(list((tmp / "resumed" / ".bayesplate-cache" / "diagnose").glob("*.pkl")))
        status, wall_r, cpu_resumed, out = one(base, tmp / "resumed")
        assert status == 0, status
        load.append(os.getloadavg())
        same = (tmp / "full" / "out.json").read_text() == (tmp / "resumed" / "out.json").read_text()
        same_numbers = json.loads((tmp / "full" / "out.json").read_text()) == json.loads(
            (tmp / "resumed" / "out.json").read_text()
        )
    info = _machine.machine()
    saved = cpu_full - cpu_resumed
    lines = [
        "# diagnose: what the stage store saves after a kill",
        "",
        f"Measured {_machine.utc_now()} by `python benchmarks/"
        f"bench_diagnose_resume.py --case {case} --mesh {mesh[0]} {mesh[1]} --at {at}` "
        "(one run of each; see the script's docstring for what is timed).",
        "",
        f"Machine: {info['cpu']}, {info['nproc']} cores, {info['memory']}, BLAS {info['blas']}; "
        f"Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}. Load "
        "average (1, 5, 15 min) before, between and after: "
        + "; ".join(", ".join(f"{v:.2f}" for v in x) for x in load)
        + ".",
        "",
        "| run | exit | wall s | processor s |",
        "|---|---|---|---|",
        f"| uninterrupted, no store | 0 | {wall:.1f} | {cpu_full:.1f} |",
        f"| with its store, SIGINT at {at:.0%} of {wall:.1f} s | {killed} | {wall_k:.1f} | "
        f"{cpu_killed:.1f} |",
        f"| run again on that store ({stored} stages stored, {out.count(STORED)} taken) | 0 | "
        f"{wall_r:.1f} | {cpu_resumed:.1f} |",
        "",
        f"Processor time saved by the store: {saved:.1f} s of {cpu_full:.1f} s "
        f"({saved / cpu_full:.0%}); the run again's JSON document is "
        + (
            "identical to the uninterrupted one, byte for byte."
            if same
            else "the same in its numbers."
            if same_numbers
            else "DIFFERENT from the uninterrupted one."
        )
        + " Startup (imports, the case, the pairing, the mesh check, the maps and scans) is "
        "not stored and is paid again.",
    ]
    path = pathlib.Path(out_dir) / REPORT
    path.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="frederiksen_t300")
    parser.add_argument("--mesh", type=int, nargs=2, default=(12, 6))
    parser.add_argument("--at", type=float, default=0.7, help="fraction of the wall time")
    parser.add_argument("--out", default=str(ROOT / "reports"))
    args = parser.parse_args()
    main(args.case, tuple(args.mesh), args.at, args.out)
