"""Markdown building blocks of the report: a table, a number, a constant, an image.

Shared by :mod:`~bayesplate.report.markdown` and :mod:`~bayesplate.report.md_taps`.
"""

from __future__ import annotations

import numpy as np

from ..quantities import CASE_SCALE

__all__ = ["_table", "_num", "_constant", "_image", "_short"]


def _table(head, rows):
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return lines


def _num(value, fmt):
    return "n/a" if value is None or not np.isfinite(value) else format(value, fmt)


def _constant(values, i, sd=None):
    """Constant i in case units, ``"113.5 ± 2.6"``."""
    v = values[i] / CASE_SCALE[i]
    text = _num(v, "#.4g") if i != 2 else _num(v, ".3f")
    if sd is not None:
        s = sd[i] / CASE_SCALE[i]
        text += " ± " + (_num(s, "#.2g") if i != 2 else _num(s, ".3f"))
    return text


def _image(figures, name, caption):
    return [f"![{caption}]({figures[name]})", "", f"*{caption}*", ""] if name in figures else []


def _short(value):
    return f"{value:.4g}" if isinstance(value, float) else str(value)
