"""Many plates of one material, each a little different: the plates against the population.

:func:`population_figure` draws one panel per engineering constant: per plate its own
single-plate answer (grey, +- 94 % linearised) and its constants shrunk towards the
population (94 % interval; outliers in red), over the material's mean (its 94 % interval,
dark band) and the plates' predicted scatter ``mu exp(+- 1.88 tau)`` (light band).
"""

from __future__ import annotations

import numpy as np

from ..quantities import CASE_SCALE
from ._style import CONSTANT_LABELS
from .plates import Z94

__all__ = ["population_figure"]


def population_figure(result, reference=None, title=None, fig=None):
    """One panel per constant: each plate, own and shrunk, over the population.

    Parameters
    ----------
    result : bayesplate.sampling.HierarchicalResult
    reference : array_like, shape (6,), optional
        Known mean constants (SI), drawn as a dashed line.
    title : str, optional
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    n = len(result.names)
    fig = fig or Figure(figsize=(11, 2.0 + 0.5 * n * 2), layout="constrained")
    axes = fig.subplots(2, 3, sharey=True).ravel()
    y = np.arange(n)[::-1].astype(float)
    for j, ax in enumerate(axes):
        s = 1.0 / CASE_SCALE[j]
        spread = np.exp(Z94 * result.tau_mean[j])
        ax.axvspan(result.mean[j] / spread * s, result.mean[j] * spread * s, color="0.93", zorder=0)
        ax.axvspan(result.hdi[0, j] * s, result.hdi[1, j] * s, color="0.75", zorder=0)
        own, half = result.own[:, j] * s, Z94 * result.own_sd[:, j] * s
        ax.errorbar(own, y + 0.18, xerr=half, fmt="o", color="0.55", capsize=2, ms=4)
        lo, hi = result.plate_hdi[0, :, j] * s, result.plate_hdi[1, :, j] * s
        mean = result.plate_mean[:, j] * s
        out = np.isin(np.arange(len(result.names)), result.flagged)
        for mask, color in ((~out, "C0"), (out, "C3")):
            ax.errorbar(
                mean[mask],
                y[mask] - 0.18,
                xerr=[mean[mask] - lo[mask], hi[mask] - mean[mask]],
                fmt="s",
                color=color,
                capsize=2,
                ms=4,
            )
        if reference is not None:
            ax.axvline(np.asarray(reference)[j] * s, color="0.3", ls="--", lw=1)
        ax.set_xlabel(CONSTANT_LABELS[j])
        ax.set_yticks(
            y, [f"{name} ({p:.0%})" for name, p in zip(result.names, result.outlier, strict=True)]
        )
        ax.set_ylim(-0.7, n - 0.3)
    fig.supylabel("plate (outlier probability); grey: own answer, blue: shrunk")
    if title:
        fig.suptitle(title)
    return fig
