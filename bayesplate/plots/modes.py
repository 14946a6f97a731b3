"""Figures of the modes: mode shapes and the MAC of measured shapes against computed modes."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ._style import _MM, _axes

__all__ = ["mac_matrix_plot", "mode_shapes"]


def mode_shapes(model, result, n=6, fig=None, points=(121, 61), marks=None):
    """Filled contours of the transverse displacement ``w`` of the first ``n`` modes.

    Each shape is scaled to ``max |w| = 1`` with its largest deflection positive; the nodal
    lines (``w = 0``) are drawn in black.

    Parameters
    ----------
    model : bayesplate.plate.model.PlateModel
    result : bayesplate.plate.model.ModalResult
        Modes of ``model``.
    n : int
        Number of modes drawn (at most the number in ``result``).
    fig : matplotlib.figure.Figure, optional
    points : tuple of int
        Evaluation grid along the longer and the shorter side.
    marks : dict, optional
        Label -> point ``(x, y)`` in m (for example ``{"tap": ..., "sensor": ...}``), marked
        on every panel, so that a mode with a node at the tap or the sensor is seen to be one.

    Returns
    -------
    matplotlib.figure.Figure
    """
    n = min(n, result.vectors.shape[1])
    a, b = model.mesh.a, model.mesh.b
    n_long, n_short = points
    nx, ny = (n_long, n_short) if a >= b else (n_short, n_long)
    x, y = np.linspace(0.0, a, nx), np.linspace(0.0, b, ny)
    X, Y = np.meshgrid(x, y)
    w = model.interpolation(np.column_stack([X.ravel(), Y.ravel()]), "w") @ result.vectors[:, :n]
    # max |w| = 1 and positive; among equal maxima (symmetric modes) the first grid point
    # decides, so that the sign does not depend on rounding in the eigen solver
    big = np.abs(w) >= (1 - 1e-6) * np.abs(w).max(axis=0)
    w = w / w[np.argmax(big, axis=0), np.arange(n)]

    ncols = min(3, n)
    nrows = -(-n // ncols)
    if fig is None:
        panel = 3.6 * b / a if a >= b else 3.6
        fig = Figure(figsize=(3.9 * ncols + 0.8, (panel + 0.7) * nrows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, sharey=True, squeeze=False))
    levels = np.linspace(-1.0, 1.0, 21)
    for k, ax in enumerate(axes.ravel()):
        if k >= n:
            ax.set_visible(False)
            continue
        W = w[:, k].reshape(X.shape)
        filled = ax.contourf(X * _MM, Y * _MM, W, levels=levels, cmap="RdBu_r")
        ax.contour(X * _MM, Y * _MM, W, levels=[0.0], colors="black", linewidths=1.2)
        _mark_points(ax, marks)
        ax.set_aspect("equal")
        ax.set_title(f"mode {k + 1}: {result.frequency_Hz[k]:.1f} Hz")
        if k % ncols == 0:
            ax.set_ylabel("y [mm]")
        if k // ncols == nrows - 1 or k + ncols >= n:
            ax.set_xlabel("x [mm]")
    bar = fig.colorbar(filled, ax=axes.ravel().tolist(), shrink=0.9, ticks=levels[::5])
    bar.set_label("w / max|w| (-); nodal lines in black")
    if marks:
        axes.ravel()[0].legend(loc="upper right", fontsize=7, framealpha=0.8)
    return fig


_MARK_STYLES = ({"marker": "x", "color": "black"}, {"marker": "o", "color": "gold"})


def _mark_points(ax, marks):
    """Each point of ``marks`` (label -> (x, y) in m) as a marker with its label."""
    for (label, (x, y)), style in zip((marks or {}).items(), _MARK_STYLES * 4, strict=False):
        ax.plot(
            x * _MM,
            y * _MM,
            linestyle="none",
            markersize=7,
            markeredgecolor="black",
            label=label,
            **style,
        )


def mac_matrix_plot(mac, pairs=None, ax=None, title=None, measured_Hz=None):
    """The modal assurance criterion of measured shapes against computed modes.

    Parameters
    ----------
    mac : array_like, shape (m, q)
        Rows measured modes, columns computed elastic modes, entries in [0, 1].
    pairs : array_like of int, shape (m,), optional
        0-based computed mode paired with each measured one, -1 for none; the pairs are
        outlined.
    ax : matplotlib.axes.Axes, optional
    title : str, optional
    measured_Hz : array_like, shape (m,), optional
        Measured frequencies, written beside the row numbers.

    Returns
    -------
    matplotlib.figure.Figure
    """
    mac = np.asarray(mac, dtype=float)
    m, q = mac.shape
    fig, ax = _axes(ax, (1.6 + 0.42 * q, 1.2 + 0.36 * m))
    image = ax.imshow(mac, vmin=0.0, vmax=1.0, cmap="Blues", aspect="auto")
    fig.colorbar(image, ax=ax, label="MAC (-); blank cells < 0.01", shrink=0.9)
    for (i, j), value in np.ndenumerate(mac):
        if value >= 0.01:
            ax.text(
                j,
                i,
                f"{value:.2f}"[1:] if value < 1 else "1",
                ha="center",
                va="center",
                fontsize=8,
                color="white" if value > 0.6 else "black",
            )
    for i, j in enumerate(np.asarray(pairs if pairs is not None else [], dtype=int)):
        if j >= 0:
            ax.add_patch(_cell_outline(i, j))
    rows = [str(i + 1) for i in range(m)]
    if measured_Hz is not None:
        rows = [f"{r} ({f:.0f} Hz)" for r, f in zip(rows, measured_Hz, strict=True)]
    ax.set_yticks(np.arange(m), rows, fontsize=8)
    ax.set_xticks(np.arange(q), [str(j + 1) for j in range(q)], fontsize=8)
    ax.set(xlabel="computed elastic mode", ylabel="measured mode", title=title)
    return fig


def _cell_outline(i, j):
    """A red square around cell (row i, column j) of an image."""
    from matplotlib.patches import Rectangle

    return Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor="tab:red", linewidth=1.6)
