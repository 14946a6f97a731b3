"""Writing a report: its figures, then ``report.md``, each file whole or not at all.

:func:`make_report` is the whole pipeline of ``bayesplate report``: compute (reusing the
cache in ``out_dir/.cache``), draw, render and write.
"""

from __future__ import annotations

import pathlib

from ..io import atomic_write_text, save_figure
from .figures import report_figures
from .markdown import render_markdown
from .progress import _Progress
from .runner import compute_report

__all__ = ["make_report", "write_report"]


def write_report(data, out_dir, progress=None):
    """Draw the figures and write them and ``report.md`` into `out_dir`.

    Each figure is written whole (temporary name, then rename); ``report.md`` last.

    Returns
    -------
    pathlib.Path
        The ``report.md`` written.
    """
    out = pathlib.Path(out_dir)
    say = progress or (lambda line: None)
    figures = {}
    for name, fig in report_figures(data).items():
        save_figure(fig, out / f"{name}.png")
        figures[name] = f"{name}.png"
    say(f"{len(figures)} figures written")
    path = out / "report.md"
    text = render_markdown(data, figures)
    atomic_write_text(path, text)
    return path


def make_report(case_file, out_dir, options=None, progress=None, label=None):
    """Compute (reusing ``out_dir/.cache``) and write the report of one case file.

    Returns
    -------
    (pathlib.Path, ReportData)
        ``report.md`` and the data it shows.
    """
    say = _Progress(progress)
    data = compute_report(case_file, options, pathlib.Path(out_dir) / ".cache", say, label)
    path = write_report(data, out_dir, say)
    say(f"report written: {path}")
    return path, data
