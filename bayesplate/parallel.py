"""Independent work on several cores, without copying the plate to every process.

The fits of diagnose (the nominal model's starts, the candidates) and the full solves that
build a reduced model (its snapshots, its held-out points) are independent, and each holds
a plate model of tens of megabytes. Forked worker processes inherit it from the
parent instead of receiving a pickled copy; only the small task indices go out and the
results come back. Where ``fork`` is not available (Windows) or one worker is asked for,
the tasks run in this process, in order, with the same results.

No process outlives the command that started it (issue 39). A forked process leaves Ctrl-C,
SIGHUP and SIGTERM's handling to its parent (it ignores the first two and dies of the
third, as :func:`fork_map` and :meth:`Forked.stop` send it to end it), closes the pipe
ends it does not use (the parent's ends of other children's pipes: otherwise a child
writing a large result into a pipe it holds open itself blocks for good), and ends
when its parent ends, also when the parent is killed with SIGKILL (:func:`die_with_parent`:
the parent-death signal on Linux, a thread watching the parent elsewhere). The parent ends
its children on every way out: the ``finally`` of :func:`fork_map`, the ``with`` block of
:class:`Forked`, and :func:`end_children` for the command line's last word. Only the
parent's main thread reads the children's pipes, so ending them at any moment leaves no
reader waiting on half a result.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import time

from threadpoolctl import threadpool_limits

__all__ = ["Forked", "available_cores", "die_with_parent", "end_children", "fork_map"]

_TASK = None  # (function, items) of the map in progress, inherited by forked workers
#: The parent's read ends of the running :class:`Forked` calls: every forked child closes
#: them (a child holding a read end open keeps a writer blocked after the parent is gone).
_PARENT_ENDS = set()
#: How often a child without the parent-death signal looks whether its parent is gone (s).
WATCH_INTERVAL = 0.25
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def die_with_parent(parent=None, *, watch=False):
    """End this process as soon as its parent process ends, however the parent ends.

    On Linux the kernel sends SIGKILL when the parent dies (``prctl(PR_SET_PDEATHSIG)``),
    strictly when the parent's thread that forked this process ends: call it in a child
    forked by a thread that lives as long as the parent needs the child (the main thread,
    a pool's). Elsewhere, or with `watch` (a child started by a thread of unknown life),
    a daemon thread looks every
    :data:`WATCH_INTERVAL` s whether the parent is still the one it was and ends the
    process (``os._exit(1)``) once it is not.

    Parameters
    ----------
    parent : int, optional
        The parent's process id as the parent knew it before forking (default: the
        parent now). A parent that already ended before this call ends the process here.
    watch : bool
        Watch with a thread even where the parent-death signal is available.
    """
    parent = os.getppid() if parent is None else int(parent)
    if not watch and sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
        except (OSError, AttributeError):  # no libc prctl (another C library)
            armed = False
        if armed:
            if os.getppid() != parent:  # the parent ended between the fork and the prctl
                os._exit(1)
            return
    if os.getppid() != parent:
        os._exit(1)
    threading.Thread(
        target=_watch_parent, args=(parent,), name="bayesplate-parent-watch", daemon=True
    ).start()


def _watch_parent(parent):
    while os.getppid() == parent:
        time.sleep(WATCH_INTERVAL)
    os._exit(1)


#: Signals held (blocked) from before a fork until the child has set its own handling.
_HELD = frozenset(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


class _signals_held:
    """A block in which :data:`_HELD` signals wait (blocked); a fork inherits the block.

    A child forked in the block starts with the signals blocked and unblocks them in
    :func:`_child_setup`, once it has its own handling: a SIGTERM that ends it while it is
    still in Python's fork hooks would otherwise run the handler inherited from the parent
    (the command line's: a ``KeyboardInterrupt`` and a traceback in the child). Signals to
    this process wait until the block ends, then act (a ``KeyboardInterrupt`` raised on
    leaving it).
    """

    def __enter__(self):
        self.saved = None
        if hasattr(signal, "pthread_sigmask"):
            self.saved = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
        return self

    def __exit__(self, *exc):
        if self.saved is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, self.saved)
        return False


def _child_setup(parent):
    """In a forked child, first: the signals left to the parent, its pipe ends closed.

    SIGINT (Ctrl-C reaches the whole foreground process group) and SIGHUP are ignored: the
    parent stops the child. SIGTERM kills it (the default; a handler inherited from the
    command line would turn it into a KeyboardInterrupt and a traceback here): it is what
    the parent sends to end it, and what a batch system sends to every process of a job.
    Held since before the fork (:class:`_signals_held`), the signals act from here on.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD)
    die_with_parent(parent)
    for end in list(_PARENT_ENDS):
        end.close()
    _PARENT_ENDS.clear()


def _start_worker(parent):
    """Set up a worker: signals left to the parent, ended with it; one BLAS thread.

    Workers leave Ctrl-C to the parent, which stops them (no traceback from each). Each uses
    one BLAS thread: the workers share the cores, more would oversubscribe them (two workers
    at two threads each were 0.57 x as fast as one process, ``reports/benchmark_pool.md``).
    """
    _child_setup(parent)
    threadpool_limits(limits=1)


def end_children(keep=(), timeout=5.0):
    """Terminate and reap this process's children (:mod:`multiprocessing`'s) but `keep`.

    SIGTERM first; SIGKILL for any still alive after `timeout` s. The command line's last
    step on every way out: the ``with`` blocks end their own children, this ends any a
    block left (an interruption while a pool was starting, say).

    Parameters
    ----------
    keep : collection of multiprocessing.Process
        Children to leave alone (those that were there before, for a caller in-process).
    timeout : float

    Returns
    -------
    int
        How many children were still running and were ended.
    """
    children = [p for p in multiprocessing.active_children() if p not in keep]
    _end(children, timeout)
    return len(children)


def _end(processes, timeout=5.0):
    """Terminate started `processes` still running; SIGKILL any alive after `timeout` s; reap."""
    started = [p for p in processes if p.pid is not None]
    for process in started:
        if process.exitcode is None:
            process.terminate()
    deadline = time.monotonic() + timeout
    for process in started:
        process.join(max(0.0, deadline - time.monotonic()))
        if process.exitcode is None:
            process.kill()
            process.join()


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
    serial = (
        n <= 1
        or "fork" not in multiprocessing.get_all_start_methods()
        or _TASK is not None
        or multiprocessing.current_process().daemon
    )
    if serial:
        # nested maps run serially, as do maps inside a daemonic process (a Dask worker's
        # task: it may not have children); at one BLAS thread, as the workers: the results
        # do not depend on the number of workers, to the last bit
        with threadpool_limits(limits=1, user_api="blas"):
            return [function(item) for item in items]
    _TASK = (function, items)
    try:
        return _map_on_workers(n, len(items))
    finally:
        _TASK = None


def _serve(conn, parent):
    """A worker: compute the items whose indices come through `conn`, send each result back.

    It ends when the parent's end is closed, or by SIGTERM (the parent's way to stop it).
    """
    _start_worker(parent)
    while True:
        try:
            index = conn.recv()
        except EOFError:
            return
        try:
            ok, value = True, _call(index)
        except Exception as err:  # noqa: BLE001 - every failure goes back to the parent
            ok, value = False, err
        _send(conn, (index,), ok, value)


def _send(conn, head, ok, value):
    """Send ``(*head, ok, value)``; a value that cannot be pickled goes as an error."""
    try:
        conn.send((*head, ok, value))
    except Exception as err:  # noqa: BLE001 - an unpicklable result or exception
        conn.send((*head, False, RuntimeError(f"{type(err).__name__}: {err}")))


def _map_on_workers(n, count):
    """Items ``0 .. count - 1`` of :data:`_TASK` on `n` forked workers; results in order.

    Each worker has its own pipe, and only this thread reads them: nothing reads on after
    the map is left, so stopping the workers at any moment (Ctrl-C, SIGTERM, a failed task)
    cannot leave a reader blocked on a result cut in two. :class:`multiprocessing.Pool`
    does leave one (its result thread, joined by ``terminate``), once in a few dozen stops.
    """
    context = multiprocessing.get_context("fork")
    workers = {}  # the parent's end of each worker's pipe: its process
    try:
        for _ in range(n):
            mine, theirs = context.Pipe()
            _PARENT_ENDS.add(mine)  # closed in every worker forked after it
            process = context.Process(target=_serve, args=(theirs, os.getpid()), daemon=True)
            workers[mine] = process
            try:
                with _signals_held():  # the worker starts with them held
                    process.start()
            finally:
                theirs.close()
        return _dispatch(workers, count)
    finally:
        _stop_workers(workers)


def _dispatch(workers, count):
    """Send each free worker the next index until every result is back; the results."""
    results = [None] * count
    pending = iter(range(count))
    busy = set()
    for mine in workers:
        index = next(pending, None)
        if index is None:
            break
        mine.send(index)
        busy.add(mine)
    while busy:
        for mine in multiprocessing.connection.wait(list(busy)):
            try:
                index, ok, value = mine.recv()
            except EOFError:
                process = workers[mine]
                process.join(1.0)  # a stop signal to this process too acts here first
                raise RuntimeError(
                    f"a forked worker ended without a result (exit code {process.exitcode})"
                ) from None
            if not ok:
                raise value
            results[index] = value
            following = next(pending, None)
            if following is None:
                busy.discard(mine)
            else:
                mine.send(following)
    return results


def _stop_workers(workers, timeout=5.0):
    """End the workers (SIGTERM; SIGKILL after `timeout` s), reap them, close the pipes."""
    _end(workers.values(), timeout)
    for mine in workers:
        _PARENT_ENDS.discard(mine)
        mine.close()


def _run_and_send(function, send, parent):
    _child_setup(parent)  # the parent stops this process; its read end closed here
    try:
        ok, value = True, function()
    except BaseException as err:  # noqa: BLE001 - every failure goes back to the parent
        ok, value = False, err
    try:
        _send(send, (), ok, value)
    finally:
        send.close()


class Forked:
    """``function()`` running in a forked process beside this one; :meth:`result` waits.

    The process inherits everything (the plate, a fast model) and sends back only the
    result, which must be picklable. It ignores Ctrl-C: the parent stops it (:meth:`stop`,
    or leaving a ``with`` block), and it ends when the parent ends (:func:`die_with_parent`).
    It is daemonic, so maps inside it run serially
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
            _PARENT_ENDS.add(self._receive)  # closed in the child, as in any child forked later
            try:
                self._process = context.Process(
                    target=_run_and_send, args=(function, send, os.getpid()), daemon=True
                )
                with _signals_held():
                    self._process.start()
            except BaseException:  # a signal held during the start acts on leaving the block
                self.stop()
                raise
            finally:
                send.close()

    def result(self):
        """The function's return value; its exception is raised here."""
        if self._process is None:
            return self._function()
        try:
            ok, value = self._receive.recv()  # before join: a large result fills the pipe
        except EOFError:
            self._process.join()
            raise RuntimeError(
                f"the forked process ended without a result (exit code {self._process.exitcode})"
            ) from None
        finally:
            self._close()
        self._process.join()
        if ok:
            return value
        raise value

    def _close(self):
        _PARENT_ENDS.discard(self._receive)
        self._receive.close()

    def stop(self, timeout=5.0):
        """End the process if it is still running (SIGTERM; SIGKILL after `timeout` s)."""
        if self._receive is None:  # no fork here
            return
        if self._process is None or self._process.pid is None:  # not started
            self._close()
            return
        _end([self._process], timeout)
        self._close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
        return False
