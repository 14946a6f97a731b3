"""Figures of diagnose: where a local change explains the misfit, residuals before and after."""

from __future__ import annotations

import numpy as np

from ._style import _MM, _axes

__all__ = ["diagnosis_figures", "location_map", "residual_comparison"]


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
    from ..discrepancy.base import mirror_positions

    d = diagnosis
    after = d.chosen.fit.residual_sigma if d.chosen is not None else None
    figs = {
        "residuals": residual_comparison(d.measured_Hz, d.nominal.residual_sigma, after,
                                         d.mode_kinds, title=f"verdict: {d.verdict}"),
    }  # fmt: skip
    for key, lm in d.maps.items():  # keyed by the located candidates' physics names
        title = key.replace("_", " ")
        best = lm.best()
        mirrors = [] if best is None else mirror_positions(model, *lm.points_mm[best])
        figs[f"map_{key}"] = location_map(lm, model, title=f"where: {title}", mirrors=mirrors)
    return figs
