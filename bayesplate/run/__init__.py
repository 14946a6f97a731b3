"""One run layer: a case to its estimate or its posterior, for every entry point.

The command line (``bayesplate estimate``, ``bayesplate sample``), a batch's tasks and the
report's steps all run a case through these functions, so that the same options and seed give
the same numbers through all three (issue 38). An edge package: it computes and may build the
export's JSON documents, it writes nothing (the callers print, store and cache).

- :mod:`~bayesplate.run.options`: :class:`EstimateOptions`, :class:`SampleOptions` (frozen:
  what a run computes, the numbers' only inputs besides the case and the seed);
- :mod:`~bayesplate.run.seeds`: :func:`run_seeds`, the one rule from a seed to the streams
  of a run;
- :mod:`~bayesplate.run.estimate`: :func:`run_estimate` (estimate, variance budget, error
  scale, JSON document);
- :mod:`~bayesplate.run.budget`: what a run adds to an estimate, its variance budget
  (:func:`~bayesplate.run.budget.estimate_budget`) and its error scale
  (:func:`~bayesplate.run.budget.scale_estimate`);
- :mod:`~bayesplate.run.sample`: :func:`run_sample` (prepare, the chain, the error scale's
  draws, MVE beside B, JSON document).
"""

from __future__ import annotations

from .estimate import EstimateRun, run_estimate
from .options import EstimateOptions, SampleOptions
from .sample import SampleRun, run_sample
from .seeds import RunSeeds, run_seeds

__all__ = [
    "EstimateOptions",
    "EstimateRun",
    "RunSeeds",
    "SampleOptions",
    "SampleRun",
    "run_estimate",
    "run_sample",
    "run_seeds",
]
