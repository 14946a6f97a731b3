"""The cases of a batch compared: each constant with its 94 % interval, one row per case."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure

from ..quantities import ENGINEERING_KEYS
from ._style import CONSTANT_LABELS

__all__ = ["batch_comparison"]

_MARKERS = {"estimate": "o", "sample": "s", "diagnose": "D"}
#: Row statuses drawn filled; any other (not converged, stopped) is drawn hollow.
_SUCCESS = ("converged", "done")


def batch_comparison(rows, title=None):
    """One panel per constant; in each, one row per case and a bar per step.

    Parameters
    ----------
    rows : sequence of dict
        Summary rows of :func:`bayesplate.batch.run_batch`: ``case``, ``step``, ``status``
        and, per constant key ``K`` of :data:`bayesplate.quantities.ENGINEERING_KEYS`,
        ``K`` (the value, GPa or -) with ``K_lo94`` and ``K_hi94`` (its interval); failed
        rows are left out, rows not ``converged`` (or ``done``) drawn hollow.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    cases = list(dict.fromkeys(r["case"] for r in rows))
    steps = [s for s in _MARKERS if any(r["step"] == s for r in rows)]
    fig = Figure(figsize=(14, 1.6 + 0.35 * max(len(cases), 1)), layout="constrained")
    axes = fig.subplots(1, len(ENGINEERING_KEYS), sharey=True)
    offsets = np.linspace(-0.2, 0.2, len(steps)) if len(steps) > 1 else [0.0]
    for ax, key, label in zip(axes, ENGINEERING_KEYS, CONSTANT_LABELS, strict=True):
        for step, dy in zip(steps, offsets, strict=True):
            y, x, lo, hi, ok = _points(rows, cases, step, key)
            bars = ax.errorbar(x, y + dy, xerr=[x - lo, hi - x], fmt="none", capsize=2, label=None)
            colour = bars.lines[2][0].get_color()
            ax.plot(
                x[ok],
                y[ok] + dy,
                _MARKERS[step],
                ms=4,
                color=colour,
                label=step if key == ENGINEERING_KEYS[0] else None,
            )
            ax.plot(x[~ok], y[~ok] + dy, _MARKERS[step], ms=4, color=colour, mfc="white")
        ax.set_xlabel(label)
        ax.grid(True, axis="x", alpha=0.3)
    axes[0].set_yticks(range(len(cases)), cases)
    axes[0].set_ylim(len(cases) - 0.5, -0.5)
    if steps:
        fig.legend(loc="outside upper right", ncols=len(steps), title="94 % interval")
    default = f"{len(cases)} cases (hollow: the step did not converge)"
    fig.suptitle(title or default, x=0.02, ha="left")
    return fig


def _points(rows, cases, step, key):
    """Row index, value, interval and success of `key` in the rows of `step` with a value."""
    out = []
    for r in rows:
        value = r.get(key)
        if r["step"] != step or r.get("status") == "failed" or not _finite(value):
            continue
        lo, hi = r.get(f"{key}_lo94"), r.get(f"{key}_hi94")
        lo, hi = (value, value) if not (_finite(lo) and _finite(hi)) else (lo, hi)
        ok = r.get("status") in _SUCCESS
        out.append((cases.index(r["case"]), value, lo, hi, ok))
    if not out:
        return (*(np.empty(0),) * 4, np.empty(0, dtype=bool))
    *columns, ok = zip(*out, strict=True)
    return (*(np.asarray(c, dtype=float) for c in columns), np.asarray(ok, dtype=bool))


def _finite(value):
    return isinstance(value, int | float) and math.isfinite(value)
