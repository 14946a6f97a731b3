"""One phase of the ranking (:func:`.rank.rank`) over the candidates: in parallel, stored.

A phase computes each candidate's next fit from its earlier one, on forked workers
(:func:`bayesplate.parallel.fork_map`), looking each up in the stages' store first
(:mod:`.store`) and storing it as soon as it is fitted; a fit that meets a plate that
cannot be solved keeps the candidate's earlier result, marked ``failed``.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from ...parallel import fork_map
from .store import fit_digest

__all__ = ["run_phase"]

log = logging.getLogger(__name__)


def run_phase(stages, name, compute, items, results, hits, workers, say):
    """One phase of :func:`.rank.rank`: ``compute((physics, earlier fit))`` for each item, stored.

    ``items`` are ``(index, physics, earlier fit or None)``; each result goes to
    ``results[index]`` (its ``fit.physics`` the very object given); the phase's name is
    appended to ``hits[index]`` when it came from the store (each stage used is announced:
    a rerun after an interruption shows what it took). A candidate whose fit meets a plate
    that cannot be solved (a far reduced model's mass no longer positive definite, say)
    keeps its earlier phase's result, marked ``failed`` (None for the first phase: the
    candidate is left out), and the failure is said; nothing is stored for it.
    """
    if not items:
        return

    def key(physics, earlier):
        return stages.key(name, physics, *(() if earlier is None else (fit_digest(earlier),)))

    def task(item):
        """``(result, taken from the store, why it failed or "")``."""
        _, physics, earlier = item
        given = physics if earlier is None else (physics, earlier)
        try:
            if stages is None:
                return compute(given), False, ""
            found, value = stages.get(key(physics, earlier))
            if not found:
                value = compute(given)
                stages.put(key(physics, earlier), value)
        except np.linalg.LinAlgError as error:
            log.warning("%s: %s fit failed: %s", physics.name, name, error)
            return None, False, f"its {name} fit failed ({type(error).__name__}: {error})"
        return value, found, ""

    done = fork_map(task, items, workers)
    for (i, physics, earlier), (value, found, failed) in zip(items, done, strict=True):
        if failed:
            failed += "; left out" if results[i] is None else "; the phase before kept"
            variant = "".join(f" ({v})" for v in physics.settings().values())
            say(f"{physics.name}{variant}: {failed}")
            if results[i] is not None:
                results[i] = replace(results[i], failed=failed)
            continue
        results[i] = replace(value, fit=replace(value.fit, physics=physics))
        if found:
            hits[i].append(name)
        if stages is not None and workers > 1 and not found:  # a worker's put may not arrive
            stages.put(key(physics, earlier), value)
