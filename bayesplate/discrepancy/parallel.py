"""Independent fits on several cores, without copying the plate to every process.

The fits of diagnose (the nominal model's starts, the candidates) are independent and each
holds a plate model of tens of megabytes. Forked worker processes inherit it from the
parent instead of receiving a pickled copy; only the small task indices go out and the
results come back. Where ``fork`` is not available (Windows) or one worker is asked for,
the tasks run in this process, in order, with the same results.
"""

from __future__ import annotations

import multiprocessing
import signal

from threadpoolctl import threadpool_limits

__all__ = ["fork_map"]

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
    if n <= 1 or "fork" not in multiprocessing.get_all_start_methods() or _TASK is not None:
        # nested maps run serially; at one BLAS thread, as the workers: the results do not
        # depend on the number of workers, to the last bit
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
