"""A stopped command leaves nothing behind (issue 39): SIGTERM as Ctrl-C, no orphaned process.

SIGTERM (and SIGHUP) is what Slurm, systemd, Docker and CI runners send to stop a job; SIGKILL
is what follows when a job does not stop in time. Each command that starts processes runs
as a subprocess (``report`` with the sampler forked beside diagnose, ``diagnose`` on two
forked workers, ``sample --workers 2`` and ``batch`` on a Dask local cluster), is stopped with
SIGTERM or SIGKILL at a seeded moment after its child processes are up, and then:

- no process of the run is left a few seconds later: every process whose environment
  carries the run's own token (read from ``/proc``; a child keeps it when re-parented to
  init, a Dask worker inherits it through ``spawn``);
- SIGTERM ends the command as Ctrl-C does: one line on standard error, no traceback, exit
  status 143, no temporary file left; SIGKILL ends it with -9;
- the run again resumes to the numbers of an uninterrupted run, bit for bit, compared as
  ``tests/test_interrupt.py`` compares them (its helpers and settings).

Fast tests check the pieces: the exit statuses and the one line of SIGTERM and SIGHUP, and
forked children (:class:`bayesplate.parallel.Forked`, :func:`bayesplate.parallel.fork_map`'s
workers, a child watching its parent) that end when their parent is killed with SIGKILL.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from test_interrupt import (
    _DIAGNOSE,
    _NOMINAL,
    _SAMPLE,
    _SAMPLE_DONE,
    _cache_numbers,
    _chain_readable,
    _command,
    _default_sigint,
    _reference,
    _report_text,
    _run,
    _same_numbers,
    _whole_json,
)

from bayesplate.parallel import fork_map

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(
    not Path("/proc/self/environ").exists(), reason="reads the processes from /proc (Linux)"
)
_RNG = np.random.default_rng(20261139)  # the moments of the stops
_TOKEN = "BAYESPLATE_SIGNAL_TEST"  # in the environment of every process of a run
#: Seconds a stopped run's processes get to end (the issue: "after a few seconds").
GRACE = 5.0
#: What the stopped runs measured, printed at the end of the module.
MEASURED = []


def _env(token):
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    env.pop("PYTHONWARNINGS", None)
    env[_TOKEN] = token
    return env


def _processes(token):
    """{pid: (parent pid, state, command line)} of every process carrying `token`."""
    mark = f"{_TOKEN}={token}".encode()
    found = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as handle:
                if mark not in handle.read().split(b"\0"):
                    continue
            with open(f"/proc/{entry}/stat") as handle:
                fields = handle.read().rpartition(")")[2].split()
            with open(f"/proc/{entry}/cmdline", "rb") as handle:
                cmdline = handle.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:  # ended meanwhile, or not ours to read
            continue
        if fields[0] != "Z":  # a zombie has ended; its parent reaps it
            found[int(entry)] = (int(fields[1]), fields[0], cmdline[:100])
    return found


def _left_after(token, grace=GRACE):
    """The processes of the run still there after up to `grace` s; (them, seconds waited)."""
    started = time.monotonic()
    while True:
        left = _processes(token)
        waited = time.monotonic() - started
        if not left or waited > grace:
            return left, waited
        time.sleep(0.05)


def _stop(args, cwd, sig, children, delay, after=None, timeout=600):
    """Start the command, wait for `children` processes of it, `delay` s more, send `sig`.

    With `after`, the children are counted once that text is on standard error. Returns a
    dict: status (None when the command ended before the signal), stderr, the processes
    of the run at the signal, those left after :data:`GRACE` s and the seconds until none
    was left.
    """
    token = uuid.uuid4().hex
    with tempfile.TemporaryFile("w+b") as err:
        proc = subprocess.Popen(
            _command(args),
            cwd=cwd,
            env=_env(token),
            stdout=subprocess.DEVNULL,
            stderr=err,
            preexec_fn=_default_sigint,
        )
        deadline = time.monotonic() + timeout
        while proc.poll() is None and time.monotonic() < deadline:
            said = after is None or after.encode() in os.pread(err.fileno(), 1 << 24, 0)
            if said and len(_processes(token)) > children:  # the command and its children
                break
            time.sleep(0.02)
        try:
            proc.wait(timeout=delay)
        except subprocess.TimeoutExpired:
            at_signal = _processes(token)
            proc.send_signal(sig)
            try:
                status = proc.wait(timeout=120)
            except subprocess.TimeoutExpired:  # stuck: said by _check_stopped, with stderr
                proc.kill()
                proc.wait()
                status = f"still running 120 s after {signal.Signals(sig).name}"
        else:
            at_signal, status = {}, None
        left, waited = _left_after(token)
        for pid in left:  # not to disturb the other tests; the assertion says it
            os.kill(pid, signal.SIGKILL)
        text = os.pread(err.fileno(), 1 << 24, 0).decode(errors="replace")
    got = {"status": status, "stderr": text, "at_signal": at_signal, "left": left, "waited": waited}
    MEASURED.append(
        (args[0], signal.Signals(sig).name, len(at_signal), len(left), round(waited, 2), status)
    )
    return got


def _check_stopped(sig, got, folder):
    """No process left; SIGTERM: one line, 143, no temporary file; SIGKILL: -9."""
    assert not got["left"], f"left after {GRACE} s: {got['left']}"
    err = got["stderr"]
    if sig == signal.SIGKILL:
        assert got["status"] == -signal.SIGKILL, (got["status"], err)
        return
    assert got["status"] == 143, (got["status"], err)
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if "interrupted" in line]
    assert len(lines) == 1 and err.rstrip().endswith(lines[0]), err
    assert lines[0].endswith("interrupted (SIGTERM); run it again to resume"), err
    assert not [p for p in folder.rglob("*.tmp")], list(folder.rglob("*.tmp"))


def _stopped(prepare, args, sig, children, delays, folder, after=None):
    """Stop a run in a fresh folder until the signal lands with a child of it running.

    The moment is a seeded delay after the run's children are up (and after the line
    `after` on standard error); on a loaded machine the children can be gone by then (a
    pool's work done), or the command done: then again in a new folder, sooner. Every stop
    is checked (:func:`_check_stopped`). Returns (the folder of the stop that landed, what
    it measured).
    """
    for attempt, delay in enumerate(delays):
        cwd = folder / f"try{attempt}"
        cwd.mkdir()
        prepare(cwd)
        got = _stop(args, cwd, sig, children, delay, after)
        if got["status"] is None:  # finished first: nothing stopped
            assert not got["left"], got["left"]
            continue
        _check_stopped(sig, got, cwd)
        if len(got["at_signal"]) > 1:  # the command and at least one child
            return cwd, got
    pytest.fail(f"no child running at the signal in {len(delays)} tries: {MEASURED[-3:]}")


def _delays(low, high, n=3):
    """A seeded moment, then sooner ones for the tries again."""
    first = _RNG.uniform(low, high)
    return [first, *(first * 0.3**k for k in range(1, n))]


# ------------------------------------------------------------------------- fast: the pieces

_PATCHED = """
import os, signal, sys, time
import bayesplate.cli.cases as cases
from bayesplate.parallel import Forked

def run(args):
    if {ignore_sigint}:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a background job of a script
    child = Forked(lambda: time.sleep(60))  # left running: the command line ends it
    print(child._process.pid, flush=True)
    os.kill(os.getpid(), signal.{sig})
    time.sleep(30)
    return 0

cases.run = run
from bayesplate.cli.main import main
sys.argv = ["bayesplate", "cases"]
sys.exit(main())
"""


@pytest.mark.parametrize(
    "sig, status, ignore_sigint",
    [
        ("SIGTERM", 143, False),
        ("SIGHUP", 129, False),
        ("SIGINT", 130, False),
        ("SIGTERM", 143, True),
    ],
    ids=["SIGTERM", "SIGHUP", "SIGINT", "SIGTERM-with-SIGINT-ignored"],
)
def test_a_stop_signal_is_one_line_its_status_and_no_child_left(sig, status, ignore_sigint):
    # SIGINT and SIGHUP as a terminal gives them (this process may run under nohup)
    token = uuid.uuid4().hex
    done = subprocess.run(
        [sys.executable, "-c", _PATCHED.format(sig=sig, ignore_sigint=ignore_sigint)],
        env=_env(token),
        capture_output=True,
        text=True,
        timeout=60,
        preexec_fn=lambda: (_default_sigint(), signal.signal(signal.SIGHUP, signal.SIG_DFL)),
    )
    child = int(done.stdout.split()[0])
    assert done.returncode == status, done.stderr
    by = "" if sig == "SIGINT" else f" ({sig})"
    assert done.stderr == f"bayesplate cases: interrupted{by}; run it again to resume\n"
    left, _ = _left_after(token, grace=1.0)
    assert child not in left and not left, left


_FORKED = """
import os, sys, time
from bayesplate.parallel import Forked, fork_map
if sys.argv[1] == "forked":
    beside = Forked(lambda: (time.sleep(1), b"x" * 10_000_000)[1])  # more than a pipe holds
    print(beside._process.pid, beside._receive.fileno(), flush=True)
    time.sleep(60)
else:
    print("map", flush=True)
    fork_map(lambda seconds: time.sleep(seconds), [60, 60], workers=2)
"""


def _pipe_ends(pid, inode):
    """The descriptors of process `pid` on the pipe `inode`: {fd: 'r' or 'w'}."""
    ends = {}
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}") != inode:
                continue
            with open(f"/proc/{pid}/fdinfo/{fd}") as handle:
                flags = next(int(line.split()[1], 8) for line in handle if line.startswith("flags"))
        except OSError:
            continue
        ends[int(fd)] = "w" if flags & os.O_WRONLY else "r"
    return ends


@pytest.mark.parametrize("what", ["forked", "map"])
def test_forked_children_end_when_their_parent_is_killed(what):
    # the orphan: the sampler forked beside diagnose, re-parented to init after the
    # parent's death, blocked for good writing its result into a pipe it held open itself
    token = uuid.uuid4().hex
    proc = subprocess.Popen(
        [sys.executable, "-c", _FORKED, what], env=_env(token), stdout=subprocess.PIPE, text=True
    )
    line = proc.stdout.readline().split()
    deadline = time.monotonic() + 30
    while len(_processes(token)) < (2 if what == "forked" else 3):
        assert time.monotonic() < deadline, _processes(token)
        time.sleep(0.02)
    if what == "forked":
        child, fd = int(line[0]), int(line[1])
        inode = os.readlink(f"/proc/{proc.pid}/fd/{fd}")
        # the child closes the read end first thing; then it holds only its write end
        while set(_pipe_ends(child, inode).values()) != {"w"}:
            assert time.monotonic() < deadline, _pipe_ends(child, inode)
            time.sleep(0.02)
    children = set(_processes(token)) - {proc.pid}
    proc.kill()
    assert proc.wait(timeout=30) == -signal.SIGKILL
    left, waited = _left_after(token, grace=2.0)
    assert not left, left
    MEASURED.append((f"parallel {what}", "SIGKILL", len(children) + 1, 0, round(waited, 2), -9))


_WATCHED = """
import os, sys, time
from bayesplate.parallel import die_with_parent
parent = os.getpid()
child = os.fork()
if child == 0:
    die_with_parent(parent, watch=True)  # the portable way: a thread watching the parent
    time.sleep(60)
    os._exit(0)
print(child, flush=True)
time.sleep(60)
"""


def test_a_child_watching_its_parent_ends_with_it():
    token = uuid.uuid4().hex
    proc = subprocess.Popen(
        [sys.executable, "-c", _WATCHED], env=_env(token), stdout=subprocess.PIPE, text=True
    )
    child = int(proc.stdout.readline())
    assert child in _processes(token)
    proc.kill()
    proc.wait(timeout=30)
    left, waited = _left_after(token, grace=2.0)
    assert not left, left
    assert waited < 1.5  # a look every WATCH_INTERVAL (0.25 s)


_MID_RESULT = """
import sys, time
import bayesplate.cli.cases as cases
from bayesplate.parallel import fork_map

def task(i):
    if i == 0:
        print("sending", flush=True)
        return b"x" * 150_000_000  # many times what a pipe holds: the send takes a while
    time.sleep(60)

def run(args):
    fork_map(task, [0, 1], workers=2)
    time.sleep(60)
    return 0

cases.run = run
from bayesplate.cli.main import main
sys.argv = ["bayesplate", "cases"]
sys.exit(main())
"""


def test_a_map_reads_its_workers_in_its_own_thread_only():
    # multiprocessing.Pool's result thread, reading a result whose sender terminate() had
    # killed half-way, waited for the rest for good, and terminate() waited for that thread:
    # the command never ended (CI, diagnose stopped by SIGTERM; 4 of 150 stops of a
    # map of short tasks). fork_map starts no thread: nothing reads on once it is left
    seen = []
    mapping = threading.Event()

    def count():
        while not mapping.is_set():
            time.sleep(0.001)
        while mapping.is_set():
            seen.append(threading.active_count())
            time.sleep(0.005)

    counter = threading.Thread(target=count)
    counter.start()
    before = threading.active_count()
    mapping.set()
    try:
        assert fork_map(lambda i: (time.sleep(0.3), i)[1], range(4), workers=2) == [0, 1, 2, 3]
    finally:
        mapping.clear()
        counter.join()
    assert seen and max(seen) == before, (before, max(seen))


@pytest.mark.parametrize("delay", [0.0, 0.05, 0.2])
def test_a_map_stopped_while_a_result_is_on_its_way_ends(delay):
    # SIGTERM while the parent reads a result larger than a pipe holds, or just before
    token = uuid.uuid4().hex
    proc = subprocess.Popen(
        [sys.executable, "-c", _MID_RESULT],
        env=_env(token),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_sigint,
    )
    assert proc.stdout.readline() == "sending\n"
    time.sleep(delay)
    proc.send_signal(signal.SIGTERM)
    try:
        status = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        status = "still running 30 s after SIGTERM"
    err = proc.stderr.read()
    left, waited = _left_after(token, grace=GRACE)
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert status == 143, (status, err)
    assert err.endswith("interrupted (SIGTERM); run it again to resume\n"), err
    assert not left, left
    MEASURED.append(("parallel map mid-result", "SIGTERM", 3, 0, round(waited, 2), status))


# ----------------------------------------------------------------- slow: the commands stopped

_SIGNALS = pytest.mark.parametrize(
    "sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"]
)


def _nothing(cwd):
    pass


# report: the sampler forked beside diagnose (the case), diagnose's forked workers
_REPORT_FULL = ["report", "plate1", "--quick", "--seed", 5, "-o", "rep"]


@pytest.fixture(scope="module")
def full_report_reference(tmp_path_factory):
    cwd = tmp_path_factory.mktemp("report_full_ref")
    status, err, _ = _run(_REPORT_FULL, cwd)
    assert status == 0, err
    return _cache_numbers(cwd / "rep"), (cwd / "rep" / "report.md").read_text()


@pytest.mark.slow
@_SIGNALS
def test_report_stopped_leaves_no_process_and_resumes(tmp_path, full_report_reference, sig):
    numbers, text = full_report_reference
    # while the sampler runs beside diagnose: after its line, a seeded moment
    cwd, got = _stopped(
        _nothing,
        _REPORT_FULL,
        sig,
        1,
        _delays(0.5, 4.0),
        tmp_path,
        after="posterior sampling: started beside diagnose",
    )
    status, err, _ = _run(_REPORT_FULL, cwd)
    assert status == 0, err
    _same_numbers(_cache_numbers(cwd / "rep"), numbers)
    assert _report_text((cwd / "rep" / "report.md").read_text()) == _report_text(text)


# diagnose on two forked workers (test_interrupt's settings)
@pytest.fixture(scope="module")
def diagnose_reference(tmp_path_factory):
    # test_interrupt's (one run in a process that runs both modules)
    folder = tmp_path_factory.mktemp("diagnose")
    return _reference([*_DIAGNOSE, "--cache", "ref-cache"], folder, _NOMINAL)[0]


@pytest.mark.slow
@_SIGNALS
def test_diagnose_stopped_leaves_no_process_and_resumes(tmp_path, diagnose_reference, sig):
    # while both workers are up (the starts' and the candidates' fits)
    cwd, got = _stopped(_nothing, _DIAGNOSE, sig, 2, _delays(0.0, 1.0), tmp_path)
    _whole_json(cwd / "out.json", diagnose_reference)
    status, err, _ = _run(_DIAGNOSE, cwd)
    assert status == 0, err
    _same_numbers(json.loads((cwd / "out.json").read_text()), diagnose_reference)


# sample on a Dask local cluster of two workers: the numbers of test_interrupt's serial run
_SAMPLE_POOL = [*_SAMPLE, "--workers", 2, "--backend", "chain.h5", "--json", "out.json"]


@pytest.fixture(scope="module")
def serial_sample_reference(tmp_path_factory):
    args = [*_SAMPLE, "--backend", "chain.h5", "--json", "out.json"]
    return _reference(args, tmp_path_factory.mktemp("sample"), done=_SAMPLE_DONE)[0]


@pytest.mark.slow
@_SIGNALS
def test_sample_on_workers_stopped_leaves_no_process_and_resumes(
    tmp_path, serial_sample_reference, sig
):
    # the command, multiprocessing's resource tracker and two Dask workers up
    cwd, got = _stopped(_nothing, _SAMPLE_POOL, sig, 3, _delays(0.5, 6.0), tmp_path)
    _whole_json(cwd / "out.json", serial_sample_reference)
    _chain_readable(cwd / "chain.h5")
    status, err, _ = _run(_SAMPLE_POOL, cwd)
    assert status in _SAMPLE_DONE, err
    _same_numbers(json.loads((cwd / "out.json").read_text()), serial_sample_reference)


# batch on a Dask local cluster of two workers
_BATCH = [
    "batch",
    "cases",
    "-o",
    "out",
    "--workers",
    2,
    "--steps",
    "estimate,diagnose",
    "--mesh",
    4,
    2,
    "--seed",
    1,
]
_BATCH_CASES = ("plate1", "frederiksen_t300")


def _batch_cases(cwd):
    from bayesplate.io import bundled_case_path

    (cwd / "cases").mkdir()
    for name in _BATCH_CASES:
        shutil.copy(bundled_case_path(name), cwd / "cases" / f"{name}.toml")


def _without_clocks(document):
    """A step's document without its wall times (the ones test_interrupt does not drop)."""
    if isinstance(document, dict):
        return {k: _without_clocks(v) for k, v in document.items() if k != "wall_time_s"}
    if isinstance(document, list):
        return [_without_clocks(v) for v in document]
    return document


def _batch_numbers(out):
    """The documents of every case and step, and the summary without clocks and workers."""
    import csv

    docs = {
        f"{case}/{step}": _without_clocks(json.loads((out / case / f"{step}.json").read_text()))
        for case in _BATCH_CASES
        for step in ("estimate", "diagnose")
    }
    with open(out / "summary.csv", newline="") as handle:
        rows = [
            {k: v for k, v in row.items() if k not in ("seconds", "worker")}
            for row in csv.DictReader(handle)
        ]
    return docs, rows


@pytest.fixture(scope="module")
def batch_reference(tmp_path_factory):
    cwd = tmp_path_factory.mktemp("batch_ref")
    _batch_cases(cwd)
    status, err, _ = _run(_BATCH, cwd)
    assert status == 0, err
    return _batch_numbers(cwd / "out")


@pytest.mark.slow
@_SIGNALS
def test_batch_stopped_leaves_no_process_and_resumes(tmp_path, batch_reference, sig):
    docs, rows = batch_reference
    # the command, the resource tracker and two workers up, the cluster started
    cwd, got = _stopped(_batch_cases, _BATCH, sig, 3, _delays(1.0, 8.0), tmp_path)
    out = cwd / "out"
    records = sorted(out.glob("*/*.record.json")) if out.exists() else []
    for path in out.glob("*/*.json") if out.exists() else []:
        if not path.name.endswith(".record.json"):  # stored: whole, the reference's
            stored = _without_clocks(json.loads(path.read_text()))
            _same_numbers(stored, docs[f"{path.parent.name}/{path.stem}"])
    status, err, _ = _run(_BATCH, cwd)
    assert status == 0, err
    assert f"{len(records)} done before" in err, err  # the steps stored are not run again
    got_docs, got_rows = _batch_numbers(out)
    _same_numbers(got_docs, docs)
    assert got_rows == rows


def test_zz_what_the_stops_measured():
    """Prints (command, signal, processes at the signal, left, seconds until none, status)."""
    print("\nstops:", *MEASURED, sep="\n  ")
