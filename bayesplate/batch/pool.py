"""Independent tasks on Dask, results in order: the engine of the studies and the sampler's pool.

:func:`map_tasks` is ``[fn(item) for item in items]`` on a Dask cluster (the same local
cluster of single-threaded worker processes as ``bayesplate batch``, or the scheduler at an
address), with a progress line per finished task and an optional callback (a study stores
each row as it comes). One worker and no scheduler runs the tasks here, in order, without
Dask: a task's result must not depend on where it ran, so the two paths give the same list.

:class:`TaskPool` is the same engine behind a ``map`` method, for the sampler's ``pool``
argument (:func:`bayesplate.sampling.sample`): the edge opens it and passes it in, so the
numerics never import this package.
"""

from __future__ import annotations

from ..report.progress import _Progress
from .run import _client, _describe

__all__ = ["TaskPool", "map_tasks"]


def map_tasks(fn, items, *, workers=None, scheduler=None, progress=None, on_result=None):
    """``[fn(item) for item in items]`` on Dask workers; the results in the order of `items`.

    Parameters
    ----------
    fn : callable
        A picklable function of one item (a module-level function; the workers import its
        module, so it must be importable there or pickled by value).
    items : iterable
        Picklable task arguments, one per task.
    workers : int, optional
        Worker processes of the local cluster started here (one thread each); default the
        cores usable. ``1`` with no `scheduler` runs the tasks in this process, in order.
    scheduler : str or distributed.Client, optional
        The address of a running Dask scheduler (``tcp://host:8786``), or a client.
    progress : callable, optional
        ``progress(line)`` after each task; default lines on standard error; ``False`` for
        none.
    on_result : callable, optional
        ``on_result(index, result)`` as each task finishes (in finishing order).

    Returns
    -------
    list
        ``fn(item)`` for each item, in order. A task's exception is raised here.
    """
    items = list(items)
    say = _Progress(None if progress is None else (progress or (lambda line: None)))
    results = [None] * len(items)
    if not items:
        return results
    if scheduler is None and workers == 1:
        for i, item in enumerate(items):
            results[i] = fn(item)
            _done(i, results[i], len(items), i + 1, say, on_result)
        return results
    from distributed import as_completed

    with _client(scheduler, workers) as client:
        say(f"cluster: {_describe(client)}")
        futures = client.map(fn, items, pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        for count, future in enumerate(as_completed(futures), start=1):
            i = index[future.key]
            results[i] = future.result()
            _done(i, results[i], len(items), count, say, on_result)
    return results


def _done(i, result, n, count, say, on_result):
    if on_result is not None:
        on_result(i, result)
    say(f"{count}/{n} tasks done (task {i})")


class TaskPool:
    """A Dask cluster behind a ``map`` method (a context manager), e.g. the sampler's pool.

    Parameters
    ----------
    workers : int, optional
        Worker processes of the local cluster started on entering; default the cores usable.
    scheduler : str or distributed.Client, optional
        The address of a running Dask scheduler, or a client (then not closed on exit).

    Examples
    --------
    >>> with TaskPool(workers=2) as pool:  # doctest: +SKIP
    ...     result = sample(problem, rng=1, pool=pool)
    """

    def __init__(self, workers=None, scheduler=None):
        self._opened = _client(scheduler, workers)
        self.client = None
        self._shipped = None  # (function, its future on the workers)

    def __enter__(self):
        self.client = self._opened.__enter__()
        return self

    def __exit__(self, *exc):
        self.client, self._shipped = None, None
        return self._opened.__exit__(*exc)

    def map(self, fn, items):
        """``[fn(item) for item in items]`` on the cluster, in order.

        Parameters
        ----------
        fn : callable
            Picklable; shipped to the workers on its first call and kept there while the
            same object is passed again (emcee's log-density with its model, every step).
        items : iterable
            Task arguments (emcee: one walker position per task).

        Returns
        -------
        list
        """
        if self.client is None:
            raise RuntimeError("TaskPool.map outside its `with` block")
        items = list(items)
        if not items:
            return []
        # one task per worker (a round trip costs milliseconds; a walker's log-density
        # may cost less), the items split in contiguous chunks, the results joined in order
        n = max(1, min(len(items), len(self.client.scheduler_info().get("workers", {}))))
        bounds = [len(items) * k // n for k in range(n + 1)]
        chunks = [items[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        # the function (emcee's log-density, holding the plate model: megabytes with the
        # full model) is shipped to the workers once, and reused while it is the same object
        if self._shipped is None or self._shipped[0] is not fn:
            self._shipped = (fn, self.client.scatter(fn, broadcast=True, hash=False))
        fn_future = self._shipped[1]
        futures = self.client.map(_apply, [fn_future] * n, chunks, pure=False)
        return [r for chunk in self.client.gather(futures) for r in chunk]


def _apply(fn, chunk):
    return [fn(item) for item in chunk]
