"""The report's progress lines: elapsed time, a heartbeat, and the library's log records.

One line per event, with the seconds since the report started; a "still running" line when
a long step says nothing for a while; and, while the steps run, the INFO records of the
long computations (estimators, sampling, reduced model) passed on as progress lines.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time

_HEARTBEAT = 30.0  # seconds without a progress line before a "still running" one
_LOGGERS = ("bayesplate.estimators", "bayesplate.sampling", "bayesplate.reduced")


class _Progress:
    """One line per event, with the seconds since the report started."""

    def __init__(self, say=None):
        self.say = say or (lambda line: print(line, file=sys.stderr, flush=True))
        self.started = self.last = time.perf_counter()
        self.lock = threading.Lock()

    def elapsed(self):
        return time.perf_counter() - self.started

    def __call__(self, message):
        with self.lock:
            self.last = time.perf_counter()
            self.say(f"[{self.elapsed():7.1f} s] {message}")

    @contextlib.contextmanager
    def heartbeat(self, title, every=_HEARTBEAT):
        """A "still running" line whenever `every` seconds pass without one."""
        done = threading.Event()

        def beat():
            while not done.wait(min(every, 5.0)):
                if time.perf_counter() - self.last >= every:
                    self(f"    {title}: still running")

        thread = threading.Thread(target=beat, daemon=True)
        thread.start()
        try:
            yield
        finally:
            done.set()
            thread.join()


class _Forward(logging.Handler):
    """Passes the library's log records on as progress lines.

    Estimator iterations (many, fast) are thinned to one line per `every` seconds.
    """

    def __init__(self, progress, every=10.0):
        super().__init__(logging.INFO)
        self.progress, self.every = progress, every
        self.last = time.perf_counter()

    def emit(self, record):
        if record.name.endswith("estimators") and time.perf_counter() - self.last < self.every:
            return
        self.last = time.perf_counter()
        self.progress(f"    {record.getMessage()}")


@contextlib.contextmanager
def _logs_shown(progress):
    """Within the block, INFO records of the long steps become progress lines (only)."""
    handler = _Forward(progress)
    saved = []
    for name in _LOGGERS:
        target = logging.getLogger(name)
        saved.append((target, target.level, target.propagate))
        target.addHandler(handler)
        target.setLevel(logging.INFO)
        target.propagate = False
    try:
        yield
    finally:
        for target, level, propagate in saved:
            target.removeHandler(handler)
            target.setLevel(level)
            target.propagate = propagate
