"""Running a batch on Dask: the cases found, the steps not yet done submitted, rows gathered.

:func:`run_batch` is the whole of ``bayesplate batch``: it finds the case files, skips every
step whose stored result has this run's key (:mod:`~bayesplate.batch.store`), submits one
task per remaining case and step (:func:`bayesplate.batch.tasks.run_step`) to a Dask cluster
(a :class:`distributed.LocalCluster` of single-threaded worker processes by default, or the
scheduler at an address), stores each result as it arrives with a progress line, and writes
the summary table and figure at the end.
"""

from __future__ import annotations

import glob
import logging
import os
import pathlib
import sys
from dataclasses import dataclass, field

from ..io import CaseError, save_figure
from ..report.progress import _Progress
from .options import BatchOptions
from .store import ResultStore, step_key
from .tasks import FAILED, run_step

__all__ = ["BatchResult", "find_cases", "run_batch"]


@dataclass(frozen=True)
class BatchResult:
    """What a batch did.

    Attributes
    ----------
    rows : list of dict
        One summary row per case and step (:data:`bayesplate.batch.store.COLUMNS`), sorted
        by case, then step.
    computed, skipped, failed : list of tuple
        ``(case, step)`` computed by this run, found done, and failed (this run).
    paths : list of pathlib.Path
        The summary files written (CSV, parquet when pyarrow is there, the figure).
    status : str
        ``"done"``, or ``"failed"`` when any step failed (the others finished).
    """

    rows: list
    computed: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    failed: list = field(default_factory=list)
    paths: list = field(default_factory=list)

    @property
    def status(self):
        """``"failed"`` when any step failed, else ``"done"``."""
        return FAILED if self.failed else "done"


def find_cases(pattern):
    """Case files of a folder (``*.toml``), a glob pattern or one file, sorted by path.

    Raises
    ------
    CaseError
        When nothing matches, or two files share a name (their output folders would).
    """
    where = pathlib.Path(pattern)
    if where.is_dir():
        paths = sorted(where.glob("*.toml"))
    elif where.is_file():
        paths = [where]
    else:
        paths = sorted(pathlib.Path(p) for p in glob.glob(str(pattern)) if os.path.isfile(p))
    if not paths:
        raise CaseError(None, rule="no case file (*.toml) found there", path=str(pattern))
    stems = [p.stem for p in paths]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        rule = f"several case files are named {twice[0]!r} (one output folder per name)"
        raise CaseError(None, rule=rule, path=str(pattern))
    return paths


def run_batch(cases, out, options=None, *, scheduler=None, workers=None, progress=None):
    """Run the steps of `options` on every case, on Dask; store and summarise the results.

    Parameters
    ----------
    cases : str, path or list of paths
        A folder, a glob pattern or a case file (:func:`find_cases`), or the case files.
    out : path
        The output folder (:class:`bayesplate.batch.store.ResultStore`).
    options : BatchOptions, optional
    scheduler : str or distributed.Client, optional
        The address of a running Dask scheduler (``tcp://host:8786``), or a client; default a
        :class:`distributed.LocalCluster` started (and stopped) here.
    workers : int, optional
        Worker processes of the local cluster (one thread each); default the cores usable.
    progress : callable, optional
        ``progress(line)``; default lines on standard error.

    Returns
    -------
    BatchResult
    """
    options = options or BatchOptions()
    paths = find_cases(cases) if isinstance(cases, str | os.PathLike) else list(cases)
    store = ResultStore(out)
    say = _Progress(progress)
    rows, todo, skipped, failed = {}, [], [], []
    for path in paths:
        content, reason = _read(path)
        for step in options.steps:
            opts = options.for_step(step)
            key = step_key(content or b"", step, opts)
            if content is None:  # recorded as failed here: no task to ship
                row = {"case": path.stem, "step": step, "status": FAILED, "reason": reason}
                rows[path.stem, step] = store.save(
                    path.stem, step, key, {"row": row, "document": None}
                )
                failed.append((path.stem, step))
            elif (row := store.done(path.stem, step, key)) is not None:
                rows[path.stem, step] = row
                skipped.append((path.stem, step))
            else:
                todo.append((path, content, step, opts, key))
    say(
        f"{len(paths)} cases x {len(options.steps)} steps: {len(skipped)} done before, "
        f"{len(todo)} to run, {len(failed)} unreadable"
    )
    computed = _compute(todo, store, rows, say, scheduler, workers, failed)
    ordered = [rows[p.stem, s] for p in paths for s in options.steps]
    written = store.write_summary(ordered)
    written.append(_figure(ordered, store.directory / "summary.png"))
    say(
        f"summary: {written[0]} ({len(computed)} computed, {len(skipped)} skipped, "
        f"{len(failed)} failed)"
    )
    return BatchResult(ordered, computed, skipped, failed, written)


def _read(path):
    """``(bytes, None)``, or ``(None, reason)`` when the file cannot be read."""
    try:
        return pathlib.Path(path).read_bytes(), None
    except OSError as err:
        rule = f"cannot read the case file ({err.strerror or type(err).__name__})"
        return None, str(CaseError(None, rule=rule, path=path))


def _compute(todo, store, rows, say, scheduler, workers, failed):
    """Submit the tasks, store each result as it comes (failures into `failed`); computed."""
    computed = []
    if not todo:
        return computed
    from distributed import as_completed

    with _client(scheduler, workers) as client:
        say(f"cluster: {_describe(client)}")
        futures = {}
        for path, content, step, opts, key in todo:
            name = path.stem
            future = client.submit(
                run_step,
                name,
                str(path),
                content,
                step,
                opts,
                pure=False,
                key=f"{step}-{name}-{key[:12]}",
            )
            futures[future] = (name, step, key)
        for i, future in enumerate(as_completed(futures), start=1):
            name, step, key = futures[future]
            result = _result_of(future, name, step)
            row = rows[name, step] = store.save(name, step, key, result)
            (failed if row["status"] == FAILED else computed).append((name, step))
            what = row["status"] + (f": {row['reason']}" if row["status"] == FAILED else "")
            say(
                f"{i}/{len(todo)} {name} {step}: {what} ({row.get('seconds', 0.0):.1f} s); "
                f"{len(failed)} failed"
            )
    return computed


def _result_of(future, name, step):
    """The task's result, or a failed one when the task itself was lost (a worker died)."""
    try:
        return future.result()
    except Exception as err:  # noqa: BLE001 - a lost task is a failed case, not a stop
        reason = f"{type(err).__name__}: {' '.join(str(err).split())}"
        return {
            "row": {"case": name, "step": step, "status": FAILED, "reason": reason},
            "document": None,
        }


class _client:
    """A ``distributed.Client``: on `scheduler`, or on a LocalCluster started here.

    A cluster started here is closed on every way out (the block's end, an error, Ctrl-C or
    SIGTERM: :mod:`bayesplate.cli.main` makes them one), also when starting it is what was
    interrupted. If this process is killed (SIGKILL), its workers end at once by
    themselves: each holds a pipe from this process open and exits when it closes
    (``distributed.process``; the processes this one forks die with it, so that none keeps
    the pipe open, :func:`bayesplate.parallel.die_with_parent`).
    """

    def __init__(self, scheduler, workers):
        self.scheduler, self.workers = scheduler, workers
        self.owned = []
        self.logger = logging.getLogger("distributed")
        self.level = self.logger.level

    def __enter__(self):
        # Dask's INFO records (workers starting, connections) would reach the command
        # line's root handler: only its warnings are progress worth showing.
        self.logger.setLevel(max(self.level, logging.WARNING))
        try:
            return self._open()
        except BaseException:
            self.__exit__(*sys.exc_info())  # a cluster half started is closed too
            # interrupted inside LocalCluster(): its start goes on in Dask's thread until
            # this process ends (its workers are ended by the command line), and its INFO
            # records would follow the command's last line: Dask's logger stays quiet
            self.logger.setLevel(max(self.level, logging.ERROR))
            raise

    def _open(self):
        import dask
        from distributed import Client, LocalCluster

        from .quiet import QuietWorker

        if self.scheduler is not None and not isinstance(self.scheduler, str):
            return self.scheduler  # a client given by the caller: theirs to close
        if self.scheduler is not None:
            try:
                client = Client(self.scheduler)
            except (OSError, ValueError) as err:  # bad input: one line, not a traceback
                rule = f"no Dask scheduler answers there ({type(err).__name__}: {err})"
                raise CaseError(
                    "--scheduler", self.scheduler, rule=" ".join(rule.split())
                ) from None
            self.owned.insert(0, client)
            return client
        n = self.workers or _cores()
        with dask.config.set(_KEEP_MALLOC):  # read as each worker's nanny starts
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                env=_ONE_THREAD,
            )
        self.owned.append(cluster)
        client = Client(cluster)
        self.owned.insert(0, client)
        client.register_plugin(QuietWorker(), name="bayesplate-quiet-worker")
        return client

    def __exit__(self, kind, *exc):
        owned, self.owned = self.owned, []
        if kind is not None:
            # stopped (an error, Ctrl-C, SIGTERM): the tasks under way are dropped, and
            # Dask's warnings that it had to kill their workers would follow the command's
            # own one line
            self.logger.setLevel(max(self.level, logging.ERROR))
        try:
            _close_all(owned)
        finally:
            self.logger.setLevel(self.level)


def _close_all(things):
    """Close each in turn (the client, then its cluster), the rest even if one fails."""
    if things:
        try:
            things[0].close()
        finally:
            _close_all(things[1:])


#: BLAS and OpenMP threads of each local worker (a task also limits them by threadpoolctl).
_ONE_THREAD = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
#: Dask gives its workers ``MALLOC_TRIM_THRESHOLD_=65536`` to hand freed memory back to the
#: system; setting it also fixes glibc's mmap threshold at 128 KiB, so every larger array a
#: diagnosis makes and frees is mapped and unmapped again: a third of a calibration worker's
#: processor time went to the kernel (reports/benchmark_worker_malloc.md). The workers keep glibc's
#: default; a value set in this process's environment still reaches them.
_KEEP_MALLOC = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def _cores():
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _describe(client):
    info = client.scheduler_info()
    workers = info.get("workers", {})
    threads = sum(w.get("nthreads", 0) for w in workers.values())
    return f"{info.get('address', '?')}, {len(workers)} workers, {threads} threads"


def _figure(rows, path):
    """The cases compared (constants with intervals), written to `path`."""
    from ..plots.batch import batch_comparison

    save_figure(batch_comparison(rows), path)
    return path
