"""Many plates of one material: each plate's own estimate beside the shared one, per constant.

:func:`plates_figure` draws one panel per engineering constant and, in each, one row per
plate (its own single-plate estimate with its interval; flagged plates in red) and a last
row for the constants the plates share (the joint posterior's mean and 94 % HDI).
:func:`plate_rows` reads those rows from a :class:`bayesplate.sampling.JointResult`.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..quantities import CASE_SCALE
from ._style import CONSTANT_LABELS

__all__ = ["plate_rows", "plates_figure"]

#: The single-plate interval: B's linearised deviation times this (94 %, as the HDI).
Z94 = float(stats.norm.ppf(0.97))


def plate_rows(result):
    """Rows of :func:`plates_figure` from a joint result: each plate's B, the shared posterior.

    Parameters
    ----------
    result : bayesplate.sampling.JointResult

    Returns
    -------
    rows : list of tuple
        ``(name, mean, lower, upper, flagged)`` per plate: B on the plate's own fast model,
        +- ``Z94`` linearised deviations (94 %), SI, shapes (6,).
    shared : tuple
        ``(mean, lower, upper)`` of the joint posterior (mean and 94 % HDI), SI.
    """
    rows = []
    for est, check in zip(result.setup.singles, result.checks, strict=True):
        half = Z94 * est.sd
        rows.append(
            (check.name, est.constants, est.constants - half, est.constants + half, check.flagged)
        )
    s = result.sampling
    return rows, (s.mean, s.hdi[0], s.hdi[1])


def plates_figure(rows, shared, reference=None, title=None, fig=None):
    """One panel per constant: a row per plate beside the shared estimate.

    Parameters
    ----------
    rows : sequence of tuple
        ``(name, mean, lower, upper, flagged)`` per plate; arrays of shape (6,), SI.
    shared : tuple
        ``(mean, lower, upper)`` of the shared constants, shapes (6,), SI.
    reference : array_like, shape (6,), optional
        Known constants (SI), drawn as a dashed line.
    title : str, optional
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    n = len(rows)
    fig = fig or Figure(figsize=(11, 1.6 + 0.45 * (n + 1) * 2), layout="constrained")
    axes = fig.subplots(2, 3, sharey=True).ravel()
    y = np.arange(n + 1)[::-1]
    names = [r[0] for r in rows] + ["shared"]
    for j, ax in enumerate(axes):
        scale = 1.0 / CASE_SCALE[j]
        for k, (_, mean, lower, upper, flagged) in enumerate(rows):
            color = "C3" if flagged else "C0"
            ax.errorbar(
                mean[j] * scale,
                y[k],
                xerr=[[(mean[j] - lower[j]) * scale], [(upper[j] - mean[j]) * scale]],
                fmt="o",
                color=color,
                capsize=3,
            )
        m, lo, hi = (np.asarray(v)[j] * scale for v in shared)
        ax.errorbar(m, y[-1], xerr=[[m - lo], [hi - m]], fmt="s", color="k", capsize=3)
        ax.axvspan(lo, hi, color="0.85", zorder=0)
        if reference is not None:
            ax.axvline(np.asarray(reference)[j] * scale, color="0.3", ls="--", lw=1)
        ax.set_xlabel(CONSTANT_LABELS[j])
        ax.set_yticks(y, names)
        ax.set_ylim(-0.7, n + 0.7)
    if title:
        fig.suptitle(title)
    return fig
