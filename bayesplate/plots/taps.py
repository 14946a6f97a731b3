"""A tap test's measured FRF with the peaks used, the ones called spurious, and the model's modes.

What a modal analyst looks at first: the FRF magnitude over the band, each kept pole marked
by its role in the estimate (paired with a computed mode, or called spurious: a peak the
model does not explain), and the computed modes at the estimate, those no peak explains
(unobserved: a node at the tap or the sensor?) marked apart.
"""

from __future__ import annotations

import numpy as np

from ._style import _axes

__all__ = ["tap_frf"]

_ROLE_STYLE = {
    "paired": ("tab:green", "v", "peak paired with a computed mode"),
    "spurious": ("tab:red", "x", "peak called spurious (left out of the fit)"),
}


def tap_frf(frequency_Hz, frf, band_Hz, peaks_Hz, roles, computed_Hz, unobserved=(), ax=None):
    """The FRF magnitude with the peaks' roles and the computed modes.

    Parameters
    ----------
    frequency_Hz : numpy.ndarray, shape (n,)
        Frequency lines, Hz.
    frf : numpy.ndarray, shape (p, n)
        The FRFs (complex); their mean magnitude is drawn.
    band_Hz : tuple of float
        The band shown, Hz.
    peaks_Hz : array_like, shape (m,)
        The measured peaks (the case's frequencies), Hz.
    roles : sequence of str, length m
        ``"paired"`` or ``"spurious"`` for each peak.
    computed_Hz : array_like, shape (k,)
        Computed elastic frequencies at the estimate, Hz.
    unobserved : sequence of int
        0-based computed modes that no peak explains (drawn dashed red).
    ax : matplotlib.axes.Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _axes(ax, (9, 4.5))
    lower, upper = band_Hz
    inside = (frequency_Hz >= lower) & (frequency_Hz <= upper)
    magnitude = np.mean(np.abs(np.atleast_2d(frf)[:, inside]), axis=0)
    ax.semilogy(frequency_Hz[inside], magnitude, color="0.35", lw=0.8, label="measured |FRF|")
    top = magnitude.max() * 2.0
    for role, (color, marker, label) in _ROLE_STYLE.items():
        chosen = [f for f, r in zip(peaks_Hz, roles, strict=True) if r == role]
        if chosen:
            ax.plot(
                chosen, [top] * len(chosen), ls="", marker=marker, color=color, ms=8, label=label
            )
    unobserved = set(int(j) for j in unobserved)
    for j, f in enumerate(computed_Hz):
        if lower <= f <= upper:
            missed = j in unobserved
            ax.axvline(
                f,
                color="tab:red" if missed else "tab:blue",
                lw=0.8,
                ls="--" if missed else ":",
                alpha=0.8,
            )
    ax.plot([], [], color="tab:blue", ls=":", label="computed mode at the estimate")
    if unobserved:
        ax.plot([], [], color="tab:red", ls="--", label="computed mode no peak explains")
    ax.set_xlim(lower, upper)
    ax.set_ylim(magnitude.min() / 2.0, top * 3.0)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("mean |FRF| (units of the recording)")
    ax.set_title("measured FRF: peaks used, peaks called spurious, computed modes")
    ax.legend(loc="lower right", fontsize="small", framealpha=0.9)
    return fig
