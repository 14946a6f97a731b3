"""The one error of the edge: a case file, or a case built in code, breaks a rule.

Every problem with a case file, a plate sheet or an imported modal test raises
:class:`CaseError`, a one-line :class:`ValueError` naming the key, the value and the rule.
List items are named with 0-based indices: ``measured.frequency_Hz[3]`` is the fourth
frequency.
"""

from __future__ import annotations

import enum
import json
import numbers
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["CaseError"]

_SHOW_WIDTH = 60  # characters of a value quoted in an error message


class _Missing(enum.Enum):
    MISSING = "missing"


class CaseError(ValueError):
    """A case file, or a case built in code, breaks a rule of the case format.

    ``str(err)`` is a single line: ``[file: ]key = value: rule``, e.g.
    ``plate.thickness_mm = -3.0: must be a positive number``.

    Parameters
    ----------
    key : str or None
        Dotted key path of the offending entry (``measured.frequency_Hz[3]``); None for a
        problem with the file as a whole (unreadable, TOML syntax).
    value : object
        The offending value as given, or ``CaseError.MISSING`` when the key is absent.
    rule : str
        The rule that is broken, phrased as a requirement.
    path : str or os.PathLike, optional
        The case file, when there is one.

    Attributes
    ----------
    key, value, rule, path
        As given.
    """

    MISSING = _Missing.MISSING

    def __init__(self, key: str | None, value: Any = MISSING, rule: str = "", path=None):
        self.key = key
        self.value = value
        self.rule = rule
        self.path = None if path is None else os.fspath(path)
        super().__init__(self._message())

    def __reduce__(self):
        return (type(self), (self.key, self.value, self.rule, self.path))

    def with_path(self, path) -> CaseError:
        """Return the same error attributed to the case file `path`."""
        return type(self)(self.key, self.value, self.rule, path)

    def _message(self) -> str:
        head = "" if self.path is None else f"{self.path}: "
        if self.key is None:
            body = self.rule
        elif self.value is _Missing.MISSING:
            body = f"{self.key}: {self.rule}"
        else:
            body = f"{self.key} = {_show(self.value)}: {self.rule}"
        return " ".join((head + body).splitlines())


def _show(value: Any) -> str:
    """Render `value` briefly, in TOML spelling, on one line."""
    text = _render(value)
    return text if len(text) <= _SHOW_WIDTH else text[: _SHOW_WIDTH - 3] + "..."


def _render(value: Any) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_render(item) for item in value[:20]) + "]"
    if isinstance(value, Mapping):
        items = (f"{key} = {_render(item)}" for key, item in value.items())
        return "{ " + ", ".join(items) + " }"
    return repr(value)
