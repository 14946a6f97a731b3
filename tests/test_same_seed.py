"""Same seed, same numbers: every command run twice gives bit-identical results.

Each command runs twice with the same options and seed (as subprocesses: separate
interpreters, nothing shared but the files) and the JSON documents' numbers are compared
exactly; diagnose also with one worker process against two. Left out of the comparison:
wall times and timings (clocks, not results).

One stated tolerance: diagnose with 1 and 2 workers. Its fits run in forked workers or in
this process; the arithmetic is the same, but a parameter the data leave unidentified sits at
a flat optimum (values ~1e-8 of a taper ratio or a misalignment, where the chi-square does not
change within round-off), and where it stops depends on the last bits of the BLAS reductions,
which may be threaded differently in a worker. Such values (|x| < 1e-6 in both runs) are
compared to an absolute 1e-6, orders of magnitude below anything the diagnosis reports as
found; every other number is compared exactly. (On the 2-core machine the tests were written
on, 1 and 2 workers agree to the last bit, flat parameters included.)
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CASE = "frederiksen_t300"
_CLOCKS = {"timings_s", "timings", "wall_time", "wall_time_s", "build_seconds", "seconds"}
_FLAT_ATOL = 1e-6  # see the module docstring: unidentified parameters at a flat optimum


def _run(args, cwd, out="out.json"):
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    command = [sys.executable, "-m", "bayesplate.cli", *map(str, args), "--json", out]
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True)
    assert done.returncode in (0, 1), done.stderr  # 1: not converged (short runs on purpose)
    return json.loads((Path(cwd) / out).read_text())


def _numbers(value, path=""):
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if key not in _CLOCKS:
                out.update(_numbers(item, f"{path}/{key}"))
        return out
    if isinstance(value, list):
        out = {}
        for i, item in enumerate(value):
            out.update(_numbers(item, f"{path}/{i}"))
        return out
    return {path: value}


def _differences(a, b, flat_atol=0.0):
    a, b = _numbers(a), _numbers(b)
    assert a.keys() == b.keys()
    out = []
    for key in a:
        x, y = a[key], b[key]
        if x == y or (x != x and y != y):  # equal, or both NaN
            continue
        flat = isinstance(x, float) and isinstance(y, float) and max(abs(x), abs(y)) < 1e-6
        if flat and abs(x - y) <= flat_atol:
            continue
        out.append((key, x, y))
    return out


def _twice(args, tmp_path):
    return _run(args, tmp_path, "a.json"), _run(args, tmp_path, "b.json")


@pytest.mark.parametrize("forward", ["full", "fast"])
def test_estimate_twice_gives_the_same_numbers(tmp_path, forward):
    # "fast": the certified reduced model, built from seeded random designs
    args = ["estimate", CASE, "--mesh", 8, 6, "--method", "MVE", "--forward", forward, "-q"]
    a, b = _twice(args, tmp_path)
    assert _differences(a, b) == []


def test_sample_twice_gives_the_same_numbers(tmp_path):
    args = ["sample", CASE, "--mesh", 6, 4, "--seed", 11, "--walkers", 12, "--max-steps", 150]
    a, b = _twice(args, tmp_path)
    assert _differences(a, b) == []
    c = _run([*args[:6], 12, *args[7:]], tmp_path, "c.json")  # another seed: another chain
    assert _differences(a, c) != []


def test_report_twice_gives_the_same_numbers(tmp_path):
    from test_interrupt import _cache_numbers, _report_text

    args = ["report", CASE, "--quick", "--mesh", 6, 4, "--seed", 2, "--no-diagnose", "--no-sample"]
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    folders = []
    for name in ("a", "b"):
        command = [sys.executable, "-m", "bayesplate.cli", *map(str, args), "-o", name]
        done = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        folders.append(tmp_path / name)
    assert _differences(*map(_cache_numbers, folders)) == []
    texts = [_report_text((f / "report.md").read_text()) for f in folders]
    assert texts[0] == texts[1]


def _small_diagnosis(workers):
    """diagnose on a 4 x 2 mesh with two candidates and one random start (in this process)."""
    from bayesplate.cli.options import resolve_case
    from bayesplate.discrepancy import PointMass, ThicknessTaper
    from bayesplate.discrepancy.diagnose import diagnose
    from bayesplate.io import diagnosis_to_dict
    from bayesplate.plate.model import PlateModel

    case = resolve_case(CASE)
    model = PlateModel.from_case(case, mesh=(4, 2))
    physics = [PointMass(), ThicknessTaper("x")]
    d = diagnose(case, model=model, physics=physics, rng=7, n_starts=1, workers=workers)
    return json.loads(json.dumps(diagnosis_to_dict(d), default=_plain))


def _plain(value):
    import numpy as np

    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return list(value)


def test_diagnose_same_seed_same_numbers_with_one_and_two_workers():
    one, again, two = _small_diagnosis(1), _small_diagnosis(1), _small_diagnosis(2)
    assert _differences(one, again) == []
    # identical to the last bit on the 2-core test machine; the tolerance is for machines
    # where this process runs more BLAS threads than a forked worker (module docstring)
    assert _differences(one, two, flat_atol=_FLAT_ATOL) == []


@pytest.mark.slow
def test_diagnose_command_same_numbers_with_one_and_two_workers(tmp_path):
    # --no-cache: each run computes every stage (a shared store would hand the first run's on)
    args = ["diagnose", CASE, "--mesh", 4, 2, "--seed", 1, "--no-cache"]
    one = _run([*args, "--workers", 1], tmp_path, "one.json")
    two = _run([*args, "--workers", 2], tmp_path, "two.json")
    again = _run([*args, "--workers", 2], tmp_path, "again.json")
    assert _differences(two, again) == []
    assert _differences(one, two, flat_atol=_FLAT_ATOL) == []
