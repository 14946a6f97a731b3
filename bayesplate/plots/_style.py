"""Shared drawing helpers of the figures: new figures without pyplot, labels, units.

Every figure function draws on an ``ax`` (or ``fig``) it is given, or on a new
:class:`matplotlib.figure.Figure` built without pyplot (no global figure registry, no GUI
backend needed).
"""

from __future__ import annotations

import re

from matplotlib.figure import Figure

from ..quantities import ENGINEERING_NAMES, ENGINEERING_UNITS

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


def _constant_label(name, unit):
    r"""``("E1", "GPa")`` -> ``"$E_1$ (GPa)"``, ``("nu12", "-")`` -> ``"$\nu_{12}$ (-)"``."""
    symbol, index = re.fullmatch(r"([A-Za-z]+?)(\d+)", name).groups()
    symbol = "\\" + symbol if len(symbol) > 1 else symbol  # a Greek letter
    index = index if len(index) == 1 else f"{{{index}}}"
    return f"${symbol}_{index}$ ({unit})"


#: Axis labels of the engineering constants in case units, e.g. ``"$E_1$ (GPa)"``.
CONSTANT_LABELS = tuple(
    _constant_label(n, u) for n, u in zip(ENGINEERING_NAMES, ENGINEERING_UNITS, strict=True)
)
