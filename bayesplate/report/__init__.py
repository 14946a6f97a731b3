"""A case -> a folder with a Markdown report and its figures (``bayesplate report``).

The report runs a fixed list of steps on one case file:

``pairing``
    The modes at the prior mean (``m + 6`` of them) and the measured-to-computed pairing
    (:func:`bayesplate.matching.pairing.pair_measured`: by shape when the case has shapes).
``B``, ``MVE``, ``MVE-mod``
    The paper's estimators (:func:`bayesplate.estimators.estimate`) with that pairing.
``modes``
    Modes, sensitivities and mode kinds at the B estimate (the posterior mode).
``sample``
    The posterior by MCMC (:func:`bayesplate.sampling.sample`), when the package has it.
``diagnose``
    Model discrepancy (:func:`bayesplate.discrepancy.diagnose.diagnose`).

Each step's result is plain data (numbers, strings, arrays), cached in ``DIR/.cache`` under
a key that hashes the case file's bytes, the step's name and options and the package
version; re-running reuses every result whose key matches (a changed case, mesh or option
redoes the steps it touches). Results are always used in their cached (serialised) form, so
a report from reused results is the same as one from fresh results.

Computation (:func:`compute_report`) is kept apart from drawing (:func:`report_figures`),
rendering (:func:`render_markdown`) and writing (:func:`write_report`). Every file is written
whole or not at all (a temporary name in the same folder, then a rename), and ``report.md``
is written last, after all its figures.

The modules, one idea each: :mod:`~bayesplate.report.options` (what is computed),
:mod:`~bayesplate.report.cache` (the step cache), :mod:`~bayesplate.report.progress`
(progress lines), :mod:`~bayesplate.report.data` (the plain data shown),
:mod:`~bayesplate.report.steps` (each step's computation), :mod:`~bayesplate.report.runner`
(the steps in order, through the cache), :mod:`~bayesplate.report.figures`,
:mod:`~bayesplate.report.markdown` and :mod:`~bayesplate.report.writer` (files on disk).
"""

from __future__ import annotations

from .cache import StepCache
from .data import ESTIMATORS, ReportData, sampling_available
from .figures import report_figures
from .markdown import render_markdown
from .options import ReportOptions
from .runner import compute_report
from .writer import make_report, write_report

__all__ = [
    "ESTIMATORS",
    "ReportData",
    "ReportOptions",
    "StepCache",
    "compute_report",
    "make_report",
    "render_markdown",
    "report_figures",
    "sampling_available",
    "write_report",
]
