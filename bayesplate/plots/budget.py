"""The variance budget figure: one stacked bar per constant, split by source."""

from __future__ import annotations

import numpy as np

from ..quantities import ENGINEERING_NAMES
from ._style import _axes, _constant_label

__all__ = ["variance_budget_bars"]

_SOURCE_COLORS = {
    "frequencies": "C0",
    "thickness": "C3",
    "density": "C1",
    "length": "C2",
    "width": "C8",
    "prior": "0.6",
}


def variance_budget_bars(budget, ax=None, title=None):
    """Stacked bars of each constant's variance share by source (frequencies, inputs, prior).

    Parameters
    ----------
    budget : bayesplate.likelihood.inputs.VarianceBudget
        Its ``share`` (n_sources, 6), the fraction of each constant's total variance from
        each source, stacks to 100 % per constant.
    ax : matplotlib.axes.Axes, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    share = 100.0 * np.asarray(budget.share, dtype=float)
    fig, ax = _axes(ax, (8, 4.2))
    x = np.arange(share.shape[1])
    bottom = np.zeros(share.shape[1])
    for source, row in zip(budget.sources, share, strict=True):
        if not np.any(row > 0):
            continue  # a source with no share (an input taken as exact) gets no legend entry
        color = _SOURCE_COLORS.get(source)
        ax.bar(x, row, 0.7, bottom=bottom, label=source, color=color)
        bottom += row
    ax.set_xticks(x, [_constant_label(n, "-").split(" ")[0] for n in ENGINEERING_NAMES])
    ax.set_ylim(0, 100)
    ax.set_ylabel("share of the variance (%)")
    ax.set_xlabel(f"constant ({budget.method}, linearised at the estimate)")
    ax.yaxis.grid(True, linewidth=0.5, alpha=0.5)
    ax.set_axisbelow(True)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), title="source", frameon=False)
    if title:
        ax.set_title(title)
    return fig
