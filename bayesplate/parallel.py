"""Independent work on several cores, without copying the plate to every process.

The fits of diagnose (the nominal model's starts, the candidates) and the full solves that
build a reduced model (its snapshots, its held-out points) are independent, and each holds
a plate model of tens of megabytes. Forked worker processes inherit it from the
parent instead of receiving a pickled copy; only the small task indices go out and the
results come back. Where ``fork`` is not available (Windows) or one worker is asked for,
the tasks run in this process, in order, with the same results.
"""

from __future__ import annotations

import multiprocessing
import os
import signal

from threadpoolctl import threadpool_limits

__all__ = ["Forked", "available_cores", "fork_map"]

_TASK = None  # (function, items) of the map in progress, inherited by forked workers


def _start_worker():
    """Set up a worker: Ctrl-C ignored, one BLAS thread.

    Workers leave Ctrl-C to the parent, which stops them (no traceback from each). Each uses
    one BLAS thread: the workers share the cores, more would oversubscribe them (two workers
    at two threads each were 0.57 x as fast as one process, ``reports/benchmark_pool.md``).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threadpool_limits(limits=1)


def _call(index):
    function, items = _TASK
    return function(items[index])


def available_cores():
    """Cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform
        return max(1, os.cpu_count() or 1)


def fork_map(function, items, workers=1):
    """``[function(item) for item in items]``, on up to ``workers`` forked processes.

    Parameters
    ----------
    function : callable
        Any callable (closures included): the workers inherit it by ``fork``.
    items : sequence
    workers : int

    Returns
    -------
    list
        In the order of ``items``. Results must be picklable.
    """
    global _TASK
    items = list(items)
    n = min(int(workers), len(items))
    serial = (n <= 1 or "fork" not in multiprocessing.get_all_start_methods()
              or _TASK is not None or multiprocessing.current_process().daemon)  # fmt: skip
    if serial:
        # nested maps run serially, as do maps inside a daemonic process (a Dask worker's
        # task: it may not have children); at one BLAS thread, as the workers: the results
        # do not depend on the number of workers, to the last bit
        with threadpool_limits(limits=1, user_api="blas"):
            return [function(item) for item in items]
    _TASK = (function, items)
    try:
        context = multiprocessing.get_context("fork")
        # a Pool, not a ProcessPoolExecutor: on Ctrl-C (or a failed task) leaving the block
        # terminates the workers at once, where the executor waits for their tasks
        with context.Pool(n, initializer=_start_worker) as pool:
            return pool.map(_call, range(len(items)), chunksize=1)
    finally:
        _TASK = None


def _run_and_send(function, send):
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops this process
    try:
        outcome = (True, function())
    except BaseException as err:  # noqa: BLE001 - every failure goes back to the parent
        outcome = (False, err)
    try:
        send.send(outcome)
    except Exception as err:  # noqa: BLE001 - an unpicklable result or exception
        send.send((False, RuntimeError(f"{type(err).__name__}: {err}")))
    finally:
        send.close()


class Forked:
    """``function()`` running in a forked process beside this one; :meth:`result` waits.

    The process inherits everything (the plate, a fast model) and sends back only the
    result, which must be picklable. It ignores Ctrl-C: the parent stops it (:meth:`stop`,
    or leaving a ``with`` block). It is daemonic, so maps inside it run serially
    (:func:`fork_map`). Where ``fork`` is not available, ``function`` runs in this process
    when the result is asked for.

    Parameters
    ----------
    function : callable
        Called with no arguments; closures are fine.
    """

    def __init__(self, function):
        self._function, self._process, self._receive = function, None, None
        if "fork" in multiprocessing.get_all_start_methods():
            context = multiprocessing.get_context("fork")
            self._receive, send = context.Pipe(duplex=False)
            self._process = context.Process(target=_run_and_send, args=(function, send),
                                            daemon=True)  # fmt: skip
            self._process.start()
            send.close()

    def result(self):
        """The function's return value; its exception is raised here."""
        if self._process is None:
            return self._function()
        try:
            ok, value = self._receive.recv()  # before join: a large result fills the pipe
        except EOFError:
            self._process.join()
            raise RuntimeError(f"the forked process ended without a result "
                               f"(exit code {self._process.exitcode})") from None  # fmt: skip
        finally:
            self._receive.close()
        self._process.join()
        if ok:
            return value
        raise value

    def stop(self):
        """End the process if it is still running."""
        if self._process is not None and self._process.is_alive():
            self._process.terminate()
            self._process.join()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
        return False
