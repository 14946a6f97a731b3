"""The poles file a user edits, and the stabilisation chart, of a tap-test import.

The poles file is a CSV table, one candidate mode per row::

    # comments
    keep,frequency_Hz,damping,orders_stable,p_spurious,coherence,phase_deviation_deg,amplitude,spread_Hz
    1,611.2336,0.00701,58,0.031,0.998,2.1,1.3,0.0004
    0,1499.87,0.0432,6,,,,,

``keep`` is 1 (take the pole into the case) or 0 (leave it out); deleting a row leaves it
out too. ``frequency_Hz`` (undamped natural frequency, Hz) and ``damping`` (viscous
damping ratio) define the pole. ``p_spurious`` is the prior probability that the pole is no
mode of the plate (:mod:`bayesplate.matching.peak_prior`), which the assignment of peaks to modes
weighs: edit it to say what you know (empty: not assessed; a case then pairs by order).
``orders_stable``, ``coherence``, ``phase_deviation_deg``, ``amplitude`` and ``spread_Hz``
are the evidence it came from (:class:`~bayesplate.io.poles.Pole`), information only.
Frequencies are written with full precision so that a pole read back is the pole written.
"""

from __future__ import annotations

import os

import numpy as np

from .csv_rows import check_columns, check_width, read_csv_rows
from .errors import CaseError
from .export import atomic_write_text, save_figure
from .poles import Pole, PoleAnalysis

__all__ = ["write_poles", "read_poles", "write_chart", "stabilisation_chart"]

_COLUMNS = (
    "keep",
    "frequency_Hz",
    "damping",
    "orders_stable",
    "p_spurious",
    "coherence",
    "phase_deviation_deg",
    "amplitude",
    "spread_Hz",
)
_EVIDENCE = _COLUMNS[4:]
_KEEP = {"1": True, "0": False, "true": True, "false": False, "yes": True, "no": False}


def write_poles(path, analysis: PoleAnalysis, source: str = "") -> None:
    """Write the candidate poles of `analysis` as an editable CSV file (atomically).

    Parameters
    ----------
    path : str or os.PathLike
    analysis : PoleAnalysis
    source : str
        The test file, named in the comment header.
    """
    lower, upper = analysis.band_Hz
    lines = [
        f"# candidate poles of {source} (LSCF, sdypy-EMA), band {lower:g}-{upper:g} Hz, "
        f"model orders up to {int(analysis.orders[-1])}",
        "# keep: 1 = take the pole into the case, 0 = leave it out (or delete the row);",
        "# then: bayesplate import TEST --plate SHEET -o CASE --use-poles THIS_FILE",
        ",".join(_COLUMNS),
    ]
    for pole in analysis.candidates:
        evidence = ",".join(
            "" if np.isnan(v) else f"{v:.4g}" for v in (getattr(pole, name) for name in _EVIDENCE)
        )
        lines.append(
            f"{int(pole.keep)},{pole.frequency_Hz!r},{pole.damping!r},"
            f"{pole.orders_stable},{evidence}"
        )
    atomic_write_text(path, "\n".join(lines) + "\n")


def read_poles(path) -> tuple[Pole, ...]:
    """Read an (edited) poles file and return the poles marked ``keep``.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    tuple of Pole
        The kept poles, ascending in frequency.

    Raises
    ------
    CaseError
        Naming the file, the line and the column, for a malformed file, a value out of
        range, two kept poles at the same frequency or no kept pole at all.
    """
    path = os.fspath(path)
    try:
        return _read_poles(path)
    except CaseError as err:
        raise err.with_path(path) from None


def _read_poles(path: str) -> tuple[Pole, ...]:
    header_line, header, rows = read_csv_rows(path, min_rows=0)
    check_columns(header_line, header, _COLUMNS, _COLUMNS[:3])
    kept = []
    for number, cells in rows:
        check_width(number, cells, header)
        row = dict(zip(header, cells, strict=True))
        keep = _KEEP.get(row["keep"].lower())
        if keep is None:
            raise CaseError(f"line {number}, column keep", row["keep"], "must be 1 or 0")
        frequency = _number(row, "frequency_Hz", number)
        damping = _number(row, "damping", number)
        if not frequency > 0:
            raise CaseError(f"line {number}, column frequency_Hz", frequency, "must be positive")
        if not 0 <= damping < 1:
            raise CaseError(f"line {number}, column damping", damping, "must be >= 0 and < 1")
        if keep:
            evidence = {name: _optional(row, name, number) for name in _EVIDENCE}
            kept.append((number, Pole(frequency, damping, 0, True, **evidence)))
    if not kept:
        raise CaseError("keep", rule="no pole is kept: mark at least one row with keep = 1")
    kept.sort(key=lambda item: item[1].frequency_Hz)
    for (_, previous), (number, pole) in zip(kept, kept[1:], strict=False):
        if pole.frequency_Hz == previous.frequency_Hz:
            rule = "two kept poles have the same frequency"
            raise CaseError(f"line {number}, column frequency_Hz", pole.frequency_Hz, rule)
    return tuple(pole for _, pole in kept)


def _optional(row: dict, name: str, number: int) -> float:
    """An evidence column's value: NaN where absent or empty; p_spurious in (0, 1)."""
    if not row.get(name, "").strip():
        return float("nan")
    value = _number(row, name, number)
    if name == "p_spurious" and not 0 < value < 1:
        rule = "must be a probability > 0 and < 1 (or empty)"
        raise CaseError(f"line {number}, column p_spurious", value, rule)
    return value


def _number(row: dict, name: str, number: int) -> float:
    try:
        value = float(row[name])
    except ValueError:
        raise CaseError(f"line {number}, column {name}", row[name], "must be a number") from None
    if not np.isfinite(value):
        raise CaseError(f"line {number}, column {name}", row[name], "must be a finite number")
    return value


def write_chart(path, analysis: PoleAnalysis, frequency_Hz, frf, kept=(), coherence=None) -> None:
    """Write the stabilisation chart (:func:`stabilisation_chart`) as a PNG."""
    save_figure(stabilisation_chart(analysis, frequency_Hz, frf, kept, coherence), path)


def stabilisation_chart(analysis: PoleAnalysis, frequency_Hz, frf, kept=(), coherence=None):
    """The stabilisation chart as a matplotlib Figure (matplotlib imported here).

    Poles of each model order at their frequency: stable in frequency and damping (green
    x), in frequency only (blue dot), unstable (grey dot); the kept poles are marked at the
    top (black triangles); behind, the mean FRF magnitude over the response points (log).

    Parameters
    ----------
    path : str or os.PathLike
    analysis : PoleAnalysis
    frequency_Hz : numpy.ndarray, shape (n,)
        Frequency lines of the FRFs, Hz.
    frf : numpy.ndarray, shape (p, n)
        The FRFs.
    kept : sequence of Pole
        The poles taken into the case.
    coherence : numpy.ndarray, shape (p, n), optional
        Coherence of each FRF (several taps with a force): drawn in a second panel below,
        with the kept poles and the warning level 0.9.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 5.5 if coherence is None else 7.5))
    if coherence is None:
        ax = fig.add_subplot()
    else:
        ax, low = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    lower, upper = analysis.band_Hz
    band = (frequency_Hz >= lower) & (frequency_Hz <= upper)
    magnitude = np.mean(np.abs(frf[:, band]), axis=0)
    back = ax.twinx()
    back.semilogy(frequency_Hz[band], magnitude, color="0.75", lw=0.8)
    back.set_ylabel("mean |FRF|")
    ax.set_zorder(back.get_zorder() + 1)
    ax.patch.set_visible(False)
    styles = (
        ("unstable", "o", "0.6", 2),
        ("stable frequency", "o", "tab:blue", 3),
        ("stable frequency and damping", "x", "tab:green", 5),
    )
    for label, marker, color, size in styles:
        xs, ys = [], []
        rows = (analysis.orders, analysis.frequency_Hz, analysis.stable_frequency, analysis.stable)
        for order, f, sf, s in zip(*rows, strict=True):
            pick = {"unstable": ~sf, "stable frequency": sf & ~s}.get(label, s)
            xs.extend(f[pick])
            ys.extend([order] * int(np.count_nonzero(pick)))
        ax.plot(xs, ys, ls="", marker=marker, color=color, ms=size, label=label)
    top = int(analysis.orders[-1]) + 2
    ax.plot([p.frequency_Hz for p in kept], [top] * len(kept), "kv", ms=8, label="kept")
    ax.set_xlim(lower, upper)
    if coherence is not None:
        _coherence_panel(low, frequency_Hz[band], np.asarray(coherence)[:, band], kept)
        low.set_xlabel("frequency (Hz)")
    else:
        ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order (pole pairs)")
    ax.set_title("Stabilisation chart (LSCF, sdypy-EMA)")
    ax.legend(loc="lower center", ncol=4, fontsize="small", framealpha=0.9)
    return fig


def _coherence_panel(ax, frequency_Hz, coherence, kept) -> None:
    """Coherence of each response point against frequency, the kept poles and 0.9."""
    for i, row in enumerate(coherence):
        ax.plot(frequency_Hz, row, lw=0.7, label=f"point {i}")
    if len(coherence) > 1:
        ax.legend(loc="lower left", ncol=len(coherence), fontsize="small", framealpha=0.9)
    for pole in kept:
        ax.axvline(pole.frequency_Hz, color="k", lw=0.5, ls=":")
    ax.axhline(0.9, color="tab:red", lw=0.8, ls="--")
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("coherence")
