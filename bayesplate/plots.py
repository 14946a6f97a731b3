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

from .quantities import STIFFNESS_NAMES

__all__ = [
    "CONSTANT_LABELS",
    "autocorrelation_plot",
    "corner_estimates",
    "diagnosis_figures",
    "estimate_residuals",
    "frequency_comparison",
    "location_map",
    "mac_matrix_plot",
    "mode_shapes",
    "posterior_corner",
    "residual_comparison",
    "sampling_figures",
    "sensitivity_bars",
    "trace_plot",
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


def estimate_residuals(measured_Hz, sigma_Hz, computed, labels=None, ax=None, title=None):
    """Standardised residuals ``(measured - computed) / sigma`` per mode, one series each.

    The sign is that of :func:`residual_comparison` (diagnose): positive where the model is
    too soft.

    Parameters
    ----------
    measured_Hz, sigma_Hz : array_like, shape (m,)
        Measured frequencies and their deviations, Hz.
    computed : mapping of str to array_like, shape (m,)
        Computed frequencies (Hz) of each labelled estimate, paired with the measured ones.
    labels : sequence of str, optional
        Tick label of each mode (default 1..m).
    ax : matplotlib.axes.Axes, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    measured = np.asarray(measured_Hz, dtype=float)
    sigma = np.asarray(sigma_Hz, dtype=float)
    m = len(measured)
    fig, ax = _axes(ax, (max(6.0, 0.55 * m + 2.0), 4.0))
    x = np.arange(m)
    width = 0.8 / max(len(computed), 1)
    for k, (label, values) in enumerate(computed.items()):
        z = (measured - np.asarray(values, dtype=float)) / sigma
        offset = (k - (len(computed) - 1) / 2) * width
        ax.bar(x + offset, z, width, color=f"C{k}",
               label=f"{label}: chi-square {np.sum(z**2):.3g}")  # fmt: skip
    ax.axhline(0.0, color="black", linewidth=0.8)
    for level in (-2, -1, 1, 2):
        ax.axhline(level, color="0.5", linewidth=0.7, linestyle="--" if abs(level) == 2 else ":")
    ax.set_xticks(x, labels if labels is not None else [str(i + 1) for i in x])
    ax.set_xlim(-0.6, m - 0.4)
    ax.set_xlabel("measured mode")
    ax.set_ylabel(r"(measured $-$ computed) / $\sigma$ (-)")
    ax.yaxis.grid(False)
    ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.14), frameon=False,
              ncol=min(len(computed), 3))  # fmt: skip
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
            ax.text(j, i, f"{value:.2f}"[1:] if value < 1 else "1", ha="center", va="center",
                    fontsize=8, color="white" if value > 0.6 else "black")  # fmt: skip
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


def posterior_corner(samples, labels, truths=None, fig=None, title=None):
    """Corner plot of posterior samples (corner.py), with the 3 % and 97 % quantiles.

    Parameters
    ----------
    samples : array_like, shape (n, k)
        Draws, in the units of `labels`.
    labels : sequence of str, length k
        Axis labels with units, e.g. ``"E1 (GPa)"``.
    truths : array_like, shape (k,), optional
        Values marked across the panels (e.g. the B estimate).
    fig : matplotlib.figure.Figure, optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    import corner

    k = len(labels)
    fig = fig or Figure(figsize=(1.7 * k + 0.8, 1.7 * k + 0.8))
    corner.corner(np.asarray(samples, dtype=float), fig=fig, labels=list(labels),
                  quantiles=[0.03, 0.5, 0.97], show_titles=True, title_fmt=".3g",
                  title_kwargs={"fontsize": 9}, label_kwargs={"fontsize": 10}, truths=truths,
                  truth_color="tab:red", max_n_ticks=3)  # fmt: skip
    if title:
        fig.suptitle(title, y=1.02)
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


# ----------------------------------------------------------------------------- sampling

#: Axis labels of the engineering constants in case units.
CONSTANT_LABELS = (
    r"$E_1$ (GPa)",
    r"$E_2$ (GPa)",
    r"$\nu_{12}$ (-)",
    r"$G_{12}$ (GPa)",
    r"$G_{13}$ (GPa)",
    r"$G_{23}$ (GPa)",
)
_RADII = (1.0, 2.0)  # Gaussian ellipses at 1 and 2 "sigma" in 2-D: 39.3 % and 86.5 %
_ESTIMATE_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple")


def _corner_ranges(samples, estimates, reference, sd_span=2.3, pad=0.04):
    """Axis ranges holding the samples (0.2-99.8 %), the ellipses and the reference."""
    lo, hi = np.percentile(samples, [0.2, 99.8], axis=0)
    for mean, cov in estimates.values():
        sd = np.sqrt(np.diag(cov))
        lo = np.minimum(lo, np.asarray(mean) - sd_span * sd)
        hi = np.maximum(hi, np.asarray(mean) + sd_span * sd)
    if reference is not None:
        lo, hi = np.minimum(lo, reference), np.maximum(hi, reference)
    span = hi - lo
    return list(zip(lo - pad * span, hi + pad * span, strict=True))


def _gaussian_ellipse(ax, mean, cov, radius, color, linestyle):
    """The ``radius``-sigma ellipse of a 2-D Gaussian on ``ax``."""
    values, vectors = np.linalg.eigh(cov)
    t = np.linspace(0.0, 2 * np.pi, 181)
    circle = radius * np.vstack([np.cos(t), np.sin(t)])
    xy = vectors @ (np.sqrt(np.maximum(values, 0.0))[:, None] * circle)
    ax.plot(mean[0] + xy[0], mean[1] + xy[1], color=color, lw=1.2, ls=linestyle)


def corner_estimates(samples, labels=CONSTANT_LABELS, estimates=None, reference=None,
                     fig=None, title=None, reference_label="reference constants"):  # fmt: skip
    """Corner plot of posterior samples with Gaussian estimates and reference values.

    The sample contours and the ellipses enclose the same probabilities, 39.3 % and 86.5 %
    (1 and 2 sigma of a 2-D Gaussian), so a linearised covariance that holds draws its
    ellipses on the contours; the diagonal shows the sample histogram (density) and each
    estimate's Gaussian density.

    Parameters
    ----------
    samples : array_like, shape (n, k)
        Posterior draws, in the units of `labels`.
    labels : sequence of str, length k
        Axis labels with units (default the engineering constants in GPa).
    estimates : mapping of str to (mean, covariance), optional
        Gaussian approximations, e.g. ``{"B": (mean, cov), "MVE": (mean, cov)}``, shapes
        (k,) and (k, k), in the units of `labels`.
    reference : array_like, shape (k,), optional
        Reference values (e.g. the target constants), drawn as lines.
    fig : matplotlib.figure.Figure, optional
    title : str, optional
    reference_label : str
        Legend entry of the reference values.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import corner
    from matplotlib.lines import Line2D

    samples = np.asarray(samples, dtype=float)
    estimates = dict(estimates or {})
    k = samples.shape[1]
    reference = None if reference is None else np.asarray(reference, dtype=float)
    fig = fig or Figure(figsize=(1.75 * k + 0.9, 1.75 * k + 0.9))
    levels = tuple(1 - np.exp(-0.5 * np.square(_RADII)))
    corner.corner(samples, fig=fig, labels=list(labels), range=_corner_ranges(
        samples, estimates, reference), levels=levels, bins=30, smooth=1.0,
        plot_datapoints=False, plot_density=False, fill_contours=False, color="0.15",
        hist_kwargs={"density": True, "color": "0.35"}, truths=reference,
        truth_color="tab:red", max_n_ticks=3, label_kwargs={"fontsize": 11},
        labelpad=0.08)  # fmt: skip
    axes = np.array(fig.axes).reshape(k, k)
    handles = [Line2D([], [], color="0.15", label="posterior samples (emcee)")]
    for n, (name, (mean, cov)) in enumerate(estimates.items()):
        color = _ESTIMATE_COLORS[n % len(_ESTIMATE_COLORS)]
        mean, cov = np.asarray(mean, dtype=float), np.asarray(cov, dtype=float)
        for i in range(k):
            x = np.linspace(*axes[i, i].get_xlim(), 200)
            sd = np.sqrt(cov[i, i])
            pdf = np.exp(-0.5 * ((x - mean[i]) / sd) ** 2) / (sd * np.sqrt(2 * np.pi))
            axes[i, i].plot(x, pdf, color=color, lw=1.2)
            for j in range(i):
                sub = cov[np.ix_([j, i], [j, i])]
                for radius, ls in zip(_RADII, ("-", "--"), strict=True):
                    _gaussian_ellipse(axes[i, j], mean[[j, i]], sub, radius, color, ls)
        handles.append(Line2D([], [], color=color, label=f"{name} (Gaussian, 1 and 2 sigma)"))
    for i in range(k):  # the densities of the estimates may overshoot the histogram
        top = max(line.get_ydata().max() for line in axes[i, i].get_lines() if len(
            line.get_ydata()) > 2) if estimates else None  # fmt: skip
        if top is not None:
            axes[i, i].set_ylim(0, 1.08 * max(top, axes[i, i].get_ylim()[1] / 1.1))
    if reference is not None:
        handles.append(Line2D([], [], color="tab:red", label=reference_label))
    fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.98, 0.98),
               frameon=False, fontsize=11)  # fmt: skip
    if title:
        fig.suptitle(title, x=0.6, y=0.78, ha="left", fontsize=12)
    return fig


def trace_plot(chains, labels=CONSTANT_LABELS, burn=0, fig=None, max_walkers=32):
    """Traces of every walker, one panel per parameter, burn-in shaded.

    Parameters
    ----------
    chains : array_like, shape (walkers, steps, k)
        In the units of `labels`.
    labels : sequence of str, length k
    burn : int
        Steps discarded as burn-in (shaded).
    fig : matplotlib.figure.Figure, optional
    max_walkers : int
        Walkers drawn at most (the first ones).

    Returns
    -------
    matplotlib.figure.Figure
    """
    chains = np.asarray(chains, dtype=float)[:max_walkers]
    k = chains.shape[2]
    fig = fig or Figure(figsize=(9, 1.35 * k + 0.6), layout="constrained")
    axes = fig.subplots(k, 1, sharex=True)
    steps = np.arange(chains.shape[1])
    for j, ax in enumerate(np.atleast_1d(axes)):
        ax.plot(steps, chains[:, :, j].T, color="k", lw=0.4, alpha=0.25)
        if burn:
            ax.axvspan(0, burn, color="0.85", zorder=0)
        ax.set_ylabel(labels[j])
        ax.margins(x=0)
    axes[-1].set_xlabel("step" + (f" (tuning and burn-in: {burn} steps, shaded)" if burn else ""))
    return fig


def autocorrelation_plot(acf, tau_history=None, labels=CONSTANT_LABELS, factor=50.0,
                         tau=None, fig=None):  # fmt: skip
    """Autocorrelation functions and the autocorrelation time against chain length.

    Parameters
    ----------
    acf : array_like, shape (k, lags)
        Normalised autocorrelation of each parameter (lag 0 first).
    tau_history : array_like, shape (checks, 1 + d), optional
        Chain length and the ``d`` autocorrelation-time estimates at each check of the
        stopping rule; drawn against the line ``N / factor``.
    labels : sequence of str, length k
    factor : float
        The stopping rule ``N > factor tau``.
    tau : array_like, shape (k,), optional
        Integrated autocorrelation time of each parameter, marked on its curve.
    fig : matplotlib.figure.Figure, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    acf = np.asarray(acf, dtype=float)
    panels = 1 if tau_history is None else 2
    fig = fig or Figure(figsize=(5.2 * panels, 4.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, panels))
    ax = axes[0]
    for j, row in enumerate(acf):
        name = labels[j].split(" (")[0]
        text = name if tau is None else f"{name}: tau = {tau[j]:.1f}"
        ax.plot(np.arange(row.size), row, color=f"C{j}", lw=1.2, label=text)
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set(xlabel="lag (steps)", ylabel="autocorrelation (-)",
           title="after burn-in, averaged over walkers")  # fmt: skip
    ax.legend(frameon=False, fontsize=9)
    if tau_history is not None:
        h = np.asarray(tau_history, dtype=float)
        ax = axes[1]
        n = h[:, 0]
        ax.plot(n, h[:, 1:], color="0.6", lw=0.8)
        ax.plot(n, h[:, 1:].max(axis=1), "ko-", ms=3, lw=1.2, label=r"largest $\tau$")
        ax.plot(n, n / factor, "k--", lw=1, label=f"N / {factor:g}: stop once above the largest")
        ax.set(xlabel="chain length N (steps)", ylabel=r"estimated $\tau$ (steps)",
               title="stopping rule: the sampler's (whitened) coordinates")  # fmt: skip
        ax.legend(frameon=False, fontsize=9)
    return fig


def sampling_figures(result, estimates=None, reference=None, title=None,
                     reference_label="reference constants"):  # fmt: skip
    """The figures of a sampling run: ``{"corner", "trace", "autocorrelation": Figure}``.

    Parameters
    ----------
    result : bayesplate.sampling.SamplingResult
    estimates : mapping of str to EstimateResult, optional
        Drawn as Gaussian ellipses (``constants`` and first-order ``covariance``).
    reference : array_like, shape (6,), optional
        Reference constants, SI.
    title : str, optional
    reference_label : str
        Legend entry of the reference constants.
    """
    scale = np.array([1e-9, 1e-9, 1.0, 1e-9, 1e-9, 1e-9])
    gauss = {name: (r.constants * scale, r.covariance * np.outer(scale, scale))
             for name, r in (estimates or {}).items()}  # fmt: skip
    samples = result.chain[:, result.n_burn :].reshape(-1, 6)
    ref = None if reference is None else np.asarray(reference) * scale
    factor = result.settings.get("target_tau_factor", 50.0)
    acf = autocorrelation_plot(result.acf, result.tau_history, factor=factor,
                               tau=result.tau_constants)  # fmt: skip
    corner = corner_estimates(samples, estimates=gauss, reference=ref, title=title,
                              reference_label=reference_label)  # fmt: skip
    return {
        "corner": corner,
        "trace": trace_plot(result.chain, burn=result.n_burn),
        "autocorrelation": acf,
    }
