"""Figures of the posterior: corner plots (with Gaussian estimates), traces, autocorrelation."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ..quantities import CASE_SCALE
from ._style import CONSTANT_LABELS

__all__ = [
    "autocorrelation_plot",
    "corner_estimates",
    "posterior_corner",
    "sampling_figures",
    "trace_plot",
]

_RADII = (1.0, 2.0)  # Gaussian ellipses at 1 and 2 "sigma" in 2-D: 39.3 % and 86.5 %
_ESTIMATE_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple")


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
    corner.corner(
        np.asarray(samples, dtype=float),
        fig=fig,
        labels=list(labels),
        quantiles=[0.03, 0.5, 0.97],
        show_titles=True,
        title_fmt=".3g",
        title_kwargs={"fontsize": 9},
        label_kwargs={"fontsize": 10},
        truths=truths,
        truth_color="tab:red",
        max_n_ticks=3,
    )
    if title:
        fig.suptitle(title, y=1.02)
    return fig


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


def corner_estimates(
    samples,
    labels=CONSTANT_LABELS,
    estimates=None,
    reference=None,
    fig=None,
    title=None,
    reference_label="reference constants",
):
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
    corner.corner(
        samples,
        fig=fig,
        labels=list(labels),
        range=_corner_ranges(samples, estimates, reference),
        levels=levels,
        bins=30,
        smooth=1.0,
        plot_datapoints=False,
        plot_density=False,
        fill_contours=False,
        color="0.15",
        hist_kwargs={"density": True, "color": "0.35"},
        truths=reference,
        truth_color="tab:red",
        max_n_ticks=3,
        label_kwargs={"fontsize": 11},
        labelpad=0.08,
    )
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
        top = (
            max(
                line.get_ydata().max()
                for line in axes[i, i].get_lines()
                if len(line.get_ydata()) > 2
            )
            if estimates
            else None
        )
        if top is not None:
            axes[i, i].set_ylim(0, 1.08 * max(top, axes[i, i].get_ylim()[1] / 1.1))
    if reference is not None:
        handles.append(Line2D([], [], color="tab:red", label=reference_label))
    fig.legend(
        handles=handles, loc="upper right", bbox_to_anchor=(0.98, 0.98), frameon=False, fontsize=11
    )
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


def autocorrelation_plot(
    acf, tau_history=None, labels=CONSTANT_LABELS, factor=50.0, tau=None, fig=None
):
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
    ax.set(
        xlabel="lag (steps)",
        ylabel="autocorrelation (-)",
        title="after burn-in, averaged over walkers",
    )
    ax.legend(frameon=False, fontsize=9)
    if tau_history is not None:
        h = np.asarray(tau_history, dtype=float)
        ax = axes[1]
        n = h[:, 0]
        ax.plot(n, h[:, 1:], color="0.6", lw=0.8)
        ax.plot(n, h[:, 1:].max(axis=1), "ko-", ms=3, lw=1.2, label=r"largest $\tau$")
        ax.plot(n, n / factor, "k--", lw=1, label=f"N / {factor:g}: stop once above the largest")
        ax.set(
            xlabel="chain length N (steps)",
            ylabel=r"estimated $\tau$ (steps)",
            title="stopping rule: the sampler's (whitened) coordinates",
        )
        ax.legend(frameon=False, fontsize=9)
    return fig


def sampling_figures(
    result, estimates=None, reference=None, title=None, reference_label="reference constants"
):
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
    scale = 1.0 / CASE_SCALE  # [1e-9, 1e-9, 1, 1e-9, ...]: the same doubles as those literals
    gauss = {
        name: (r.constants * scale, r.covariance * np.outer(scale, scale))
        for name, r in (estimates or {}).items()
    }
    samples = result.chain[:, result.n_burn :].reshape(-1, 6)
    ref = None if reference is None else np.asarray(reference) * scale
    factor = result.settings.get("target_tau_factor", 50.0)
    acf = autocorrelation_plot(
        result.acf, result.tau_history, factor=factor, tau=result.tau_constants
    )
    corner = corner_estimates(
        samples, estimates=gauss, reference=ref, title=title, reference_label=reference_label
    )
    return {
        "corner": corner,
        "trace": trace_plot(result.chain, burn=result.n_burn),
        "autocorrelation": acf,
    }
