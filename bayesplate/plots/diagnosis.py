"""Figures of diagnose: where a local change explains the misfit, residuals before and after."""

from __future__ import annotations

import numpy as np

from ._style import _MM, _axes

__all__ = ["diagnosis_figures", "location_map", "residual_comparison"]

_BOX = {"boxstyle": "round", "facecolor": "white", "edgecolor": "0.6"}


def location_map(location, model, ax=None, title=None, mirrors=(), nothing_found_chi2=None):
    """How much of the misfit a local change at each place explains (diagnose, step 2).

    Parameters
    ----------
    location : bayesplate.discrepancy.physics.location.LocationMap
    model : PlateModel
        For the plate outline.
    mirrors : sequence of (x_mm, y_mm)
        Places that fit equally by symmetry, marked with open circles.
    nothing_found_chi2 : float, optional
        The nominal fit's chi-square when diagnose found nothing (verdict "consistent"):
        the map then marks no best place, and says in the figure how much of that
        chi-square the best place would explain (a map of noise, not of a defect).

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
    nothing = nothing_found_chi2 is not None
    # nothing found: the scale runs to the whole chi-square, so the map looks as faint as it is
    scale = (
        {"cmap": "Greys", "vmin": 0.0, "vmax": max(nothing_found_chi2, drop.max())}
        if nothing
        else {"cmap": "magma"}
    )
    mesh = ax.pcolormesh(x, y, drop, shading="nearest", **scale)
    fig.colorbar(mesh, ax=ax, label=r"$\chi^2$ explained (-)")
    best = location.best()
    if nothing:
        explained = 0.0 if best is None else float(drop.max())
        best, mirrors = None, ()
    if best is not None:
        ax.plot(*location.points_mm[best], "c*", ms=14, label="best place")
    for i, (px, py) in enumerate(mirrors):
        ax.plot(px, py, "co", mfc="none", ms=10, label="mirror images" if i == 0 else None)
    if best is not None:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)
    if nothing:
        title = f"{title}: nothing found" if title else "nothing found"
    ax.set(xlim=(0, a), ylim=(0, b), aspect="equal", xlabel="x (mm)", ylabel="y (mm)", title=title)
    if nothing:  # under the x label (where the legend goes otherwise): the map stays in view
        ax.annotate(
            _nothing_found(explained, nothing_found_chi2),
            (0.5, 0.0),
            xycoords=ax.xaxis.label,
            xytext=(0, -8),
            textcoords="offset points",
            ha="center",
            va="top",
            fontsize=9,
            bbox=_BOX,
        )
    return fig


def _nothing_found(explained, chi2):
    """The sentence a map of a consistent plate carries in place of a best place."""
    if explained <= 0:
        return "nothing found: no place explains any of the misfit"
    share = explained / chi2 if chi2 > 0 else 1.0
    only = " only" if share < 0.25 else ""
    return (
        f"nothing found: the best place explains{only} {explained:.2g} of the chi-square "
        f"{chi2:.2g} ({100 * share:.0f} %),\na chi-square the plate model already fits "
        "(verdict: consistent)"
    )


def residual_comparison(
    measured_Hz, before_sigma, after_sigma=None, kinds=None, ax=None, title=None
):
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
    ax.bar(
        modes - (width / 2 if after_sigma is not None else 0),
        before_sigma,
        width,
        color="tab:red",
        label="nominal fit",
    )
    if after_sigma is not None:
        ax.bar(modes + width / 2, after_sigma, width, color="tab:blue", label="refit")
    for level in (-2, 2):
        ax.axhline(level, color="0.5", lw=0.8, ls="--")
    labels = [
        f"{i}" if not kinds else f"{i}\n{k.replace('bending along ', 'bend ')}"
        for i, k in zip(modes, kinds or [""] * n, strict=True)
    ]
    ax.set_xticks(modes, labels, fontsize=7)
    ax.set(xlabel="measured mode", ylabel=r"(measured $-$ model) / $\sigma$ (-)", title=title)
    ax.legend(frameon=False)
    return fig


def diagnosis_figures(model, diagnosis):
    """The figures of a diagnosis: ``{name: Figure}`` (maps and residuals)."""
    from ..discrepancy.physics.base import mirror_positions

    d = diagnosis
    after = d.chosen.fit.residual_sigma if d.chosen is not None else None
    figs = {
        "residuals": residual_comparison(
            d.measured_Hz,
            d.nominal.residual_sigma,
            after,
            d.mode_kinds,
            title=f"verdict: {d.verdict}",
        ),
    }
    # nothing found: the maps say so instead of marking a best place as if it meant a defect
    chi2 = float(np.sum(np.square(d.nominal.residual_sigma)))
    nothing = chi2 if d.verdict == "consistent" else None
    for key, lm in d.maps.items():  # keyed by the located candidates' physics names
        title = key.replace("_", " ")
        best = lm.best()
        mirrors = [] if best is None else mirror_positions(model, *lm.points_mm[best])
        figs[f"map_{key}"] = location_map(
            lm, model, title=f"where: {title}", mirrors=mirrors, nothing_found_chi2=nothing
        )
    return figs
