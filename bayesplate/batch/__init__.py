"""Many cases at once on Dask (``bayesplate batch``): one task per case and step.

An edge package like :mod:`bayesplate.report`: it reads case files and writes results. The
modules, one idea each: :mod:`~bayesplate.batch.options` (what every step computes),
:mod:`~bayesplate.batch.tasks` (one step on one case, run on a worker; plain data back),
:mod:`~bayesplate.batch.store` (the output folder: documents, records with their keys, the
summary), :mod:`~bayesplate.batch.run` (finding the cases, skipping what is done,
submitting the rest to a Dask cluster, progress) and :mod:`~bayesplate.batch.pool`
(the same engine for any independent tasks: :func:`map_tasks` for the studies, and
:class:`TaskPool`, a ``map`` for the sampler's ``pool``).

Importing this package does not import Dask; :func:`run_batch` and :func:`map_tasks` do, when
there is work for a cluster.
"""

from __future__ import annotations

from .options import STEPS, BatchOptions
from .pool import TaskPool, map_tasks
from .run import BatchResult, find_cases, run_batch
from .store import COLUMNS, ResultStore, step_key
from .tasks import run_step

__all__ = [
    "COLUMNS",
    "STEPS",
    "BatchOptions",
    "BatchResult",
    "ResultStore",
    "TaskPool",
    "find_cases",
    "map_tasks",
    "run_batch",
    "run_step",
    "step_key",
]
