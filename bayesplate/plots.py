"""Figures: sensitivities, frequency differences, mode shapes, and diagnosis maps.

The only module of the package that uses matplotlib. Every function draws on an ``ax`` (or
``fig``) it is given, or on a new :class:`matplotlib.figure.Figure` built without pyplot (no
global figure registry, no GUI backend needed), and returns the figure; saving it is the
caller's business.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from .laminate import STIFFNESS_NAMES

__all__ = [
    "diagnosis_figures",
    "frequency_comparison",
    "location_map",
    "mode_shapes",
    "residual_comparison",
    "sensitivity_bars",
]

_SENSITIVITY_LABEL = (
    r"normalised sensitivity $|\partial\lambda_i/\partial C_{jk}\cdot C_{jk}/\lambda_i|$ (-)"
)
_MM = 1e3  # mm per m


def _axes(ax, figsize):
    """``(fig, ax)``: the given axes and its figure, or a new constrained-layout figure."""
    if ax is not None:
        return ax.figure, ax
    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.add_subplot()


def _tex_name(name):
    """``"C11"`` -> ``"$C_{11}$"``."""
    return f"${name[0]}_{{{name[1:]}}}$"


def sensitivity_bars(normalised, ax=None, title=None, names=STIFFNESS_NAMES, notes=None):
    """Grouped bars of the normalised sensitivities of eq. 29 (the paper's Figs. 2-3).

    Parameters
    ----------
    normalised : array_like, shape (n_modes, 6)
        ``s_ij = (d lambda_i / d b_j) b_j / lambda_i`` (dimensionless), e.g.
        :meth:`bayesplate.model.ModalResult.normalised_sensitivities`; absolute values are
        drawn.
    ax : matplotlib.axes.Axes, optional
    title : str, optional
    names : sequence of str, length 6
        Coefficient names, ``("C11", "C22", "C12", "C66", "C44", "C55")`` by default.
    notes : sequence of str, optional
        A short note per mode written under its number (e.g. ``"in-plane"``); empty strings
        for none.

    Returns
    -------
    matplotlib.figure.Figure
    """
    s = np.abs(np.asarray(normalised, dtype=float))
    n_modes, n_par = s.shape
    fig, ax = _axes(ax, (10, 4.2))
    width = 0.84 / n_par
    mode = np.arange(1, n_modes + 1)
    for j, name in enumerate(names):
        offset = (j - (n_par - 1) / 2) * width
        ax.bar(mode + offset, s[:, j], width, label=_tex_name(name), color=f"C{j}")
    ax.set_xticks(mode)
    for k, note in zip(mode, notes if notes is not None else [""] * n_modes, strict=True):
        if note:  # under the mode number, smaller than it
            ax.annotate(
                note,
                xy=(k, 0.0),
                xycoords=("data", "axes fraction"),
                xytext=(0, -17),
                textcoords="offset points",
                ha="center",
                va="top",
                fontsize="x-small",
                color="0.3",
            )
    ax.set_xlim(0.5, n_modes + 0.5)
    ax.set_ylim(0, max(1.0, s.max() * 1.02))
    ax.set_xlabel("mode number", labelpad=10 if notes is not None and any(notes) else 4)
    ax.set_ylabel(_SENSITIVITY_LABEL)
    ax.yaxis.grid(True, linewidth=0.5, alpha=0.5)
    ax.set_axisbelow(True)
    # outside the axes, so that it never hides a bar
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), title="coefficient", frameon=False)
    if title:
        ax.set_title(title)
    return fig


def frequency_comparison(computed, measured, ax=None, title=None):
    """Bars of the percent difference ``(computed - measured) / measured`` per mode.

    Parameters
    ----------
    computed : array_like, shape (n_modes,), or mapping of str to such arrays
        Computed frequencies in Hz; a mapping draws one labelled series per entry, with its
        largest absolute difference in the legend (bars too small to see stay readable).
    measured : array_like, shape (n_modes,)
        Reference (measured or published) frequencies in Hz.
    ax : matplotlib.axes.Axes, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    series = dict(computed) if isinstance(computed, Mapping) else {None: computed}
    measured = np.asarray(measured, dtype=float)
    mode = np.arange(1, len(measured) + 1)
    fig, ax = _axes(ax, (8, 3.5))
    width = 0.8 / len(series)
    for k, (label, values) in enumerate(series.items()):
        diff = 100.0 * (np.asarray(values, dtype=float) - measured) / measured
        offset = (k - (len(series) - 1) / 2) * width
        if label is not None:  # bars too small to see still show in the legend
            label = f"{label}: max |diff| {np.max(np.abs(diff)):.2g} %"
        ax.bar(mode + offset, diff, width, label=label, color=f"C{k}")
    ax.axhline(0.0, color="black", linewidth=0.8)
    ax.set_xticks(mode)
    ax.set_xlim(0.5, len(measured) + 0.5)
    ax.set_xlabel("mode number")
    ax.set_ylabel("(computed - measured) / measured [%]")
    ax.yaxis.grid(True, linewidth=0.5, alpha=0.5)
    ax.set_axisbelow(True)
    if any(label is not None for label in series):
        # below the axes, so that it never hides a bar
        ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.16), frameon=False)
    if title:
        ax.set_title(title)
    return fig


def mode_shapes(model, result, n=6, fig=None, points=(121, 61)):
    """Filled contours of the transverse displacement ``w`` of the first ``n`` modes.

    Each shape is scaled to ``max |w| = 1`` with its largest deflection positive; the nodal
    lines (``w = 0``) are drawn in black.

    Parameters
    ----------
    model : bayesplate.model.PlateModel
    result : bayesplate.model.ModalResult
        Modes of ``model``.
    n : int
        Number of modes drawn (at most the number in ``result``).
    fig : matplotlib.figure.Figure, optional
    points : tuple of int
        Evaluation grid along the longer and the shorter side.

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
        ax.set_aspect("equal")
        ax.set_title(f"mode {k + 1}: {result.frequency_Hz[k]:.1f} Hz")
        if k % ncols == 0:
            ax.set_ylabel("y [mm]")
        if k // ncols == nrows - 1 or k + ncols >= n:
            ax.set_xlabel("x [mm]")
    bar = fig.colorbar(filled, ax=axes.ravel().tolist(), shrink=0.9, ticks=levels[::5])
    bar.set_label("w / max|w| (-); nodal lines in black")
    return fig


def location_map(location, model, ax=None, title=None, mirrors=()):
    """How much of the misfit a local change at each place explains (diagnose, step 2).

    Parameters
    ----------
    location : bayesplate.discrepancy.locate.LocationMap
    model : PlateModel
        For the plate outline.
    mirrors : sequence of (x_mm, y_mm)
        Places that fit equally by symmetry, marked with open circles.

    Returns
    -------
    matplotlib.figure.Figure
    """
    a, b = _MM * model.mesh.a, _MM * model.mesh.b
    fig, ax = _axes(ax, (6.4, 0.6 + 5.2 * b / a))
    ny, nx = location.shape
    drop = np.where(location.physical, location.chi2_drop, 0.0).reshape(ny, nx)
    x = location.points_mm[:, 0].reshape(ny, nx)
    y = location.points_mm[:, 1].reshape(ny, nx)
    mesh = ax.pcolormesh(x, y, drop, shading="nearest", cmap="magma")
    fig.colorbar(mesh, ax=ax, label=r"$\chi^2$ explained (-)")
    best = location.best()
    if best is not None:
        ax.plot(*location.points_mm[best], "c*", ms=14, label="best place")
    for i, (px, py) in enumerate(mirrors):
        ax.plot(px, py, "co", mfc="none", ms=10, label="mirror images" if i == 0 else None)
    if best is not None:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)
    ax.set(xlim=(0, a), ylim=(0, b), aspect="equal", xlabel="x (mm)", ylabel="y (mm)",
           title=title)  # fmt: skip
    return fig


def residual_comparison(measured_Hz, before_sigma, after_sigma=None, kinds=None, ax=None,
                        title=None):  # fmt: skip
    """Standardised residuals per mode before and after a refit (diagnose, step 4).

    Parameters
    ----------
    measured_Hz : array_like, shape (m,)
    before_sigma, after_sigma : array_like, shape (m,)
        (measured - model) / sigma of the nominal fit and of the refit (optional).
    kinds : sequence of str, optional
        Kind of each mode, written under its number.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _axes(ax, (8.0, 4.2))
    n = len(measured_Hz)
    modes = np.arange(1, n + 1)
    width = 0.4 if after_sigma is not None else 0.7
    ax.bar(modes - (width / 2 if after_sigma is not None else 0), before_sigma, width,
           color="tab:red", label="nominal fit")  # fmt: skip
    if after_sigma is not None:
        ax.bar(modes + width / 2, after_sigma, width, color="tab:blue", label="refit")
    for level in (-2, 2):
        ax.axhline(level, color="0.5", lw=0.8, ls="--")
    labels = [f"{i}" if not kinds else f"{i}\n{k.replace('bending along ', 'bend ')}"
              for i, k in zip(modes, kinds or [""] * n, strict=True)]  # fmt: skip
    ax.set_xticks(modes, labels, fontsize=7)
    ax.set(xlabel="measured mode", ylabel=r"(measured $-$ model) / $\sigma$ (-)", title=title)
    ax.legend(frameon=False)
    return fig


def diagnosis_figures(model, diagnosis):
    """The figures of a diagnosis: ``{name: Figure}`` (maps and residuals)."""
    from .discrepancy.base import mirror_positions

    d = diagnosis
    after = d.chosen.fit.residual_sigma if d.chosen is not None else None
    figs = {
        "residuals": residual_comparison(d.measured_Hz, d.nominal.residual_sigma, after,
                                         d.mode_kinds, title=f"verdict: {d.verdict}"),
    }  # fmt: skip
    for key, title in (("stiffness_loss", "local stiffness loss"), ("point_mass", "point mass")):
        lm = d.maps[key]
        best = lm.best()
        mirrors = [] if best is None else mirror_positions(model, *lm.points_mm[best])
        figs[f"map_{key}"] = location_map(lm, model, title=f"where: {title}", mirrors=mirrors)
    return figs
