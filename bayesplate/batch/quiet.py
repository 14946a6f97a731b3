"""The local workers' own Dask records, kept off the command line.

A task's failure comes back to the command as a failed row, and a worker that dies is
reported by its nanny, which runs in the command's process. What the worker processes log
themselves is their side of that and, when a run is stopped, the heartbeat that found the
scheduler gone (a traceback) and the tasks cancelled (warnings): lines that would follow
the command's one line. Registered only on a cluster the batch starts: the workers of a
scheduler given (``--scheduler``) are their owner's to configure.
"""

from __future__ import annotations

import logging

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["QuietWorker"]


class QuietWorker(WorkerPlugin):
    """Sets the worker process's ``distributed`` logger to CRITICAL."""

    def setup(self, worker):
        """Called by Dask in the worker process when the plugin is registered."""
        logging.getLogger("distributed").setLevel(logging.CRITICAL)
