"""Figures of the estimates: sensitivities, frequency differences and residuals per mode."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..quantities import STIFFNESS_NAMES
from ._style import _axes, _tex_name

__all__ = ["estimate_residuals", "frequency_comparison", "sensitivity_bars"]

_SENSITIVITY_LABEL = (
    r"normalised sensitivity $|\partial\lambda_i/\partial C_{jk}\cdot C_{jk}/\lambda_i|$ (-)"
)


def sensitivity_bars(normalised, ax=None, title=None, names=STIFFNESS_NAMES, notes=None):
    """Grouped bars of the normalised sensitivities of eq. 29 (the paper's Figs. 2-3).

    Parameters
    ----------
    normalised : array_like, shape (n_modes, 6)
        ``s_ij = (d lambda_i / d b_j) b_j / lambda_i`` (dimensionless), e.g.
        :meth:`bayesplate.plate.model.ModalResult.normalised_sensitivities`; absolute values are
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
        ax.bar(x + offset, z, width, color=f"C{k}", label=f"{label}: chi-square {np.sum(z**2):.3g}")
    ax.axhline(0.0, color="black", linewidth=0.8)
    for level in (-2, -1, 1, 2):
        ax.axhline(level, color="0.5", linewidth=0.7, linestyle="--" if abs(level) == 2 else ":")
    ax.set_xticks(x, labels if labels is not None else [str(i + 1) for i in x])
    ax.set_xlim(-0.6, m - 0.4)
    ax.set_xlabel("measured mode")
    ax.set_ylabel(r"(measured $-$ computed) / $\sigma$ (-)")
    ax.yaxis.grid(False)
    ax.legend(
        fontsize="small",
        loc="upper center",
        bbox_to_anchor=(0.5, -0.14),
        frameon=False,
        ncol=min(len(computed), 3),
    )
    if title:
        ax.set_title(title)
    return fig
