"""Writing a report: its figures, ``report.json``, ``report.html``, then ``report.md``.

Each file whole or not at all. ``report.html`` is the Markdown as one self-contained page
(the figures embedded, :mod:`~bayesplate.report.html`), ``report.json`` the numbers of its
summary. :func:`make_report` is the whole pipeline of ``bayesplate report``: compute
(reusing the cache in ``out_dir/.cache``), draw, render and write.
"""

from __future__ import annotations

import pathlib

from ..io import atomic_write_text, figure_png, write_json, write_png
from ..parallel import available_cores, fork_map
from .figures import figure_groups
from .html import render_html, report_summary
from .markdown import render_markdown
from .progress import _Progress
from .runner import compute_report

__all__ = ["make_report", "write_report"]


def write_report(data, out_dir, progress=None):
    """Draw the figures and write them, ``report.json``, ``report.html`` and ``report.md``.

    Each file is written whole (temporary name, then rename); ``report.md`` last. The
    figures are drawn and rendered in groups on forked workers (the same bytes as in turn);
    ``report.html`` embeds the same PNG bytes.

    Returns
    -------
    pathlib.Path
        The ``report.md`` written.
    """
    out = pathlib.Path(out_dir)
    say = progress or (lambda line: None)
    groups = figure_groups(data)
    # drawn and rendered on every core (forked workers, each a group); written here, in
    # order, each whole: a failure anywhere writes no figure and no report.md
    rendered = fork_map(_rendered, groups, available_cores())
    figures, images = {}, {}
    for group in rendered:
        for name, png in group.items():
            write_png(out / f"{name}.png", png)
            figures[name] = f"{name}.png"
            images[figures[name]] = png
    say(f"{len(figures)} figures written")
    path = out / "report.md"
    text = render_markdown(data, figures)
    write_json(report_summary(data), out / "report.json")
    atomic_write_text(out / "report.html", render_html(text, images, f"{data.case.name}: report"))
    atomic_write_text(path, text)
    return path


def _rendered(group):
    """``{name: PNG bytes}`` of one group of figures, each closed once rendered."""
    import matplotlib.pyplot as plt

    out = {}
    for name, fig in group().items():
        out[name] = figure_png(fig)
        plt.close(fig)
    return out


def make_report(case_file, out_dir, options=None, progress=None, label=None, taps=None):
    """Compute (reusing ``out_dir/.cache``) and write the report of one case file.

    `taps` (a :class:`~bayesplate.report.data.TapTest`): the tap test the case came from.

    Returns
    -------
    (pathlib.Path, ReportData)
        ``report.md`` and the data it shows.
    """
    say = _Progress(progress)
    cache = pathlib.Path(out_dir) / ".cache"
    data = compute_report(case_file, options, cache, say, label, taps)
    path = write_report(data, out_dir, say)
    say(f"report written: {path}")
    return path, data
