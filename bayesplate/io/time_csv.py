"""A tap recorded as a CSV time series, as a data acquisition system writes it.

One header line, then one row per sample. The columns are found by their names, without
options where that is unambiguous (case-insensitive; a unit in parentheses or brackets, or
after a last ``_``, is set apart: ``Time (s)``, ``time [ms]``, ``time_s``, ``Force (N)``):

- **time** (optional): ``time``, ``t``, ``times``, in s, ms or us (s when no unit is given);
  without it the sampling rate must be given (``rate_Hz``, ``--rate-Hz``);
- **force** (optional, an instrumented hammer): ``force``, ``hammer``, ``F``, ``impact``,
  ``excitation``, ... (:data:`FORCE_NAMES`);
- **response** (required): ``signal``, ``response``, ``acceleration``, ``accel``, ``acc``,
  ``a``, ``velocity``, ``mic``, ``microphone``, ... (:data:`RESPONSE_NAMES`).

A trailing channel number is allowed (``acc1``, ``Mic 2``). Columns of no role are ignored
(and named in a note). Two candidates for one role are refused unless ``force_column`` or
``response_column`` names the one to take. Cells are separated by commas; a header without
a comma but with ``;`` or tabs sets that separator instead. ``#`` starts a comment.

The times must be evenly spaced **at the precision they were written**: every time may be
off its exact value by half a unit of the last digit the column's writer kept, plus the
rounding of a float. That digit is the coarser, for each time, of the column's last decimal
place (the most decimals any time shows: ``%.9f`` writes 9) and the time's last significant
digit (the most significant digits any time shows: ``%.10g`` or the shortest ``repr``
write 10 or 17). A writer that drops trailing zeros writes ``0`` or ``0.5`` for times as
precise as the others, so the precision is the column's, not the cell's alone.
A column is refused when a time lies farther from the line
through the first and last times than those errors allow (the bound the exact times obey);
the rate is ``(n - 1) / (t_last - t_first)``, known to ``(e_first + e_last) / (n - 1)`` in
its step. Of the rates within that precision the one of fewest significant digits is taken
(48000, not 48000.000008: a DAQ's rate is a round number, and the taps of one test then
share it exactly). A ``rate_Hz`` given as well must lie within that precision.
"""

from __future__ import annotations

import csv
import re

import numpy as np

from .csv_table import csv_contents
from .errors import CaseError

__all__ = [
    "TIME_NAMES",
    "FORCE_NAMES",
    "RESPONSE_NAMES",
    "TIME_UNITS_S",
    "column_role",
    "sniff_header",
    "is_time_series_header",
    "read_time_csv",
]

TIME_NAMES = ("time", "t", "times")
"""Names of a time column (lower case, words separated by one space)."""

FORCE_NAMES = (
    "force",
    "f",
    "hammer",
    "hammer force",
    "force hammer",
    "impact",
    "impact force",
    "excitation",
    "load cell",
    "loadcell",
)
"""Names of a force column."""

RESPONSE_NAMES = (
    "signal",
    "response",
    "resp",
    "acceleration",
    "accel",
    "acc",
    "accelerometer",
    "a",
    "velocity",
    "vel",
    "displacement",
    "disp",
    "mic",
    "microphone",
    "sound",
    "sound pressure",
    "pressure",
    "audio",
    "vibration",
    "vibrometer",
    "ldv",
)
"""Names of a response column."""

TIME_UNITS_S = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "msec": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6}
"""Seconds per unit of a time column."""

_ROLES = {
    **{name: "time" for name in TIME_NAMES},
    **{name: "force" for name in FORCE_NAMES},
    **{name: "response" for name in RESPONSE_NAMES},
}
_BRACKETED = re.compile(r"(.*?)\s*[(\[]\s*([^()\[\]]*?)\s*[)\]]")
_DECIMAL = re.compile(r"[+-]?(?:([0-9]+)(?:\.([0-9]*))?|\.([0-9]+))(?:[eE]([+-]?[0-9]+))?")
_SEPARATORS = {",": "commas", ";": "semicolons", "\t": "tabs"}


def column_role(name: str) -> tuple[str | None, str | None]:
    """The role of a header cell and its unit: ``("time", "ms")`` for ``time [ms]``.

    Parameters
    ----------
    name : str
        A header cell as written.

    Returns
    -------
    role : {"time", "force", "response"} or None
        None for a name of no role.
    unit : str or None
        The unit written with it, lower case; None without.
    """
    text = name.strip().strip("\"'").strip()
    unit = None
    bracketed = _BRACKETED.fullmatch(text)
    if bracketed:
        text, unit = bracketed.group(1), bracketed.group(2).lower()
    words = [word for word in re.split(r"[\s_\-.]+", text.lower()) if word]
    key = re.sub(r"\s*[0-9]+$", "", " ".join(words))  # acc1, Mic 2: a channel number
    if key in _ROLES:
        return _ROLES[key], unit
    if unit is None and len(words) > 1 and " ".join(words[:-1]) in _ROLES:  # time_s, force_N
        return _ROLES[" ".join(words[:-1])], words[-1]
    return None, unit


def _is_frequency_column(name: str) -> bool:
    text = name.strip().strip("\"'").lower()
    return text.startswith("freq") or bool(re.fullmatch(r"h.+_(re|im)", text))


def is_time_series_header(cells, named=()) -> bool:
    """Whether a CSV header is that of a time series rather than of FRFs or modes.

    True when no column is a frequency (``frequency_Hz``, ``Hk_re``) and one is a time or a
    response column, or is named in `named` (the ``--force-column``, ``--response-column``).
    """
    if not cells or any(_is_frequency_column(cell) for cell in cells):
        return False
    roles = {column_role(cell)[0] for cell in cells}
    return bool(roles & {"time", "response"}) or any(_find(cells, n) is not None for n in named)


def sniff_header(path) -> tuple[str, list[str]]:
    """The separator and the cells of a CSV file's header line; ``(",", [])`` if unreadable."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as stream:
            for line in stream:
                content = line.split("#", 1)[0].rstrip("\r\n")
                if content.strip():
                    separator = _separator(content)
                    return separator, [cell.strip() for cell in _split(content, separator)]
    except (OSError, UnicodeDecodeError, CaseError):
        pass
    return ",", []


def _separator(header: str) -> str:
    """Comma first; else ``;``, else a tab, if the header holds one; else a comma."""
    return next((s for s in _SEPARATORS if s in header), ",")


def _split(content: str, separator: str, number: int = 1) -> list[str]:
    try:
        return next(csv.reader([content], delimiter=separator))
    except csv.Error as err:  # a field over the csv module's limit (128 kB)
        raise CaseError(f"line {number}", rule=f"not a CSV line ({err})") from None


def _lines(path) -> tuple[str, list]:
    """The separator and ``(line number, cells)`` of every line that is not blank or a comment."""
    contents = csv_contents(path)
    separator = _separator(contents[0][1]) if contents else ","
    return separator, [(n, _split(content, separator, n)) for n, content in contents]


def read_time_csv(path, rate_Hz=None, force_column=None, response_column=None):
    """Read a CSV time series: its sampling rate, response and force, and what was assumed.

    Parameters
    ----------
    path : str
        The CSV file (see the module docstring).
    rate_Hz : float, optional
        Sampling rate, Hz: required without a time column; with one, it must agree.
    force_column, response_column : str, optional
        The header cell of the force or response column, when the names do not say it
        (matched as written, else case-insensitively).

    Returns
    -------
    rate_Hz : float
        Hz.
    signal : numpy.ndarray, shape (n,)
    force : numpy.ndarray, shape (n,) or None
    notes : tuple of str
        The columns taken and ignored, and where the rate came from.

    Raises
    ------
    CaseError
        Naming the line and column (or the option), the value and the rule; the caller
        adds the file.
    """
    from .csv_rows import read_csv_rows

    if rate_Hz is not None and not (np.isfinite(rate_Hz) and rate_Hz > 0):
        raise CaseError("--rate-Hz", rate_Hz, "must be a positive number (Hz)")
    separator, lines = _lines(path)
    header_line, header, rows = read_csv_rows(path, lines=lines)
    chosen, ignored = _choose(header_line, header, force_column, response_column)
    if "time" not in chosen and rate_Hz is None:
        rule = f"no time column ({', '.join(header)}): give the sampling rate with --rate-Hz"
        raise CaseError(f"line {header_line}", rule=rule)
    for number, cells in rows:
        if len(cells) != len(header):
            rule = f"must have {len(header)} values separated by {_SEPARATORS[separator]}"
            rule += f" ({', '.join(header)})"
            raise CaseError(f"line {number}", separator.join(cells), rule)
    columns = {role: _numbers(rows, header, j) for role, j in chosen.items()}
    taken = ", ".join(f'{role} "{header[j]}"' for role, j in chosen.items())
    notes = [f"columns read: {taken}" + (f"; ignored: {', '.join(ignored)}" if ignored else "")]
    if "time" in chosen:
        rate_Hz, note = _rate_from_times(header, chosen["time"], rows, columns["time"], rate_Hz)
        notes.append(note)
    else:
        notes.append(f"no time column: sampling rate {rate_Hz:.10g} Hz from --rate-Hz")
    return float(rate_Hz), columns["response"], columns.get("force"), tuple(notes)


def _find(header, name) -> int | None:
    """Index of the header cell `name`: as written, else the one equal ignoring case."""
    cells = [cell.strip() for cell in header]
    if name.strip() in cells:
        return cells.index(name.strip())
    folded = [j for j, cell in enumerate(cells) if cell.casefold() == name.strip().casefold()]
    return folded[0] if len(folded) == 1 else None


def _choose(header_line, header, force_column, response_column):
    """Column index of each role found (time, force, response) and the cells ignored."""
    where = f"line {header_line}"
    listing = f"the header has {', '.join(header)}"
    chosen = {}
    for option, role, name in (
        ("--force-column", "force", force_column),
        ("--response-column", "response", response_column),
    ):
        if name is not None:
            j = _find(header, name)
            if j is None:
                raise CaseError(option, name, f"is not a column of the file ({listing})")
            if j in chosen.values():
                raise CaseError(option, name, "is also the --force-column: name two columns")
            chosen[role] = j
    roles = {j: column_role(cell) for j, cell in enumerate(header) if j not in chosen.values()}
    for role, option in (
        ("time", None),
        ("force", "--force-column"),
        ("response", "--response-column"),
    ):
        found = [j for j, (r, _) in roles.items() if r == role]
        if role in chosen or not found:
            continue
        if len(found) > 1:
            listed = ", ".join(header[j] for j in found)
            what = f"name the one to take with {option}" if option else "keep one"
            rule = f"{len(found)} {role} columns ({listed}): which one? {what}"
            raise CaseError(where, rule=rule)
        chosen[role] = found[0]
    if "response" not in chosen:
        rule = (
            f"required column is missing from the header ({', '.join(header)}): name the "
            "response signal, acceleration, mic, ... or give --response-column"
        )
        raise CaseError(f"{where}, column signal", rule=rule)
    order = {role: chosen[role] for role in ("time", "force", "response") if role in chosen}
    ignored = [f'"{cell}"' for j, cell in enumerate(header) if j not in chosen.values()]
    return order, ignored


def _numbers(rows, header, j) -> np.ndarray:
    """Column `j` as finite floats; a bad cell raises a CaseError naming it."""
    values = np.empty(len(rows))
    for i, (number, cells) in enumerate(rows):
        try:
            values[i] = float(cells[j])
        except ValueError:
            rule = "must be a number" + (" (with a decimal point)" if "," in cells[j] else "")
            raise CaseError(f"line {number}, column {header[j]}", cells[j], rule) from None
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        number, cells = rows[bad[0]]
        raise CaseError(f"line {number}, column {header[j]}", cells[j], "must be a finite number")
    return values


def _half_units(rows, header, j) -> np.ndarray:
    """Half a unit of the last digit written in column `j`, at each time (module docstring)."""
    decimals, digits, leading = (np.empty(len(rows), dtype=int) for _ in range(3))
    for i, (number, cells) in enumerate(rows):
        match = _DECIMAL.fullmatch(cells[j])
        if match is None:
            rule = "must be a decimal number such as 0.000125 or 1.25e-4"
            raise CaseError(f"line {number}, column {header[j]}", cells[j], rule)
        whole, fraction = match.group(1) or "", match.group(2) or match.group(3) or ""
        written = match.group(4) or "0"  # the exponent; 0e99999 is a finite 0 too
        exponent = int(written) if len(written) < 6 else (-400 if written[0] == "-" else 400)
        mantissa = (whole + fraction).lstrip("0")  # its significant digits
        decimals[i] = len(fraction) - exponent
        digits[i] = len(mantissa)
        leading[i] = len(whole) - (len(whole + fraction) - len(mantissa)) - 1 + exponent
    last = np.maximum(-decimals.max(), np.where(digits > 0, leading - digits.max() + 1, -999))
    return 0.5 * 10.0 ** np.clip(last, -400, 300).astype(float)


def _rate_from_times(header, j, rows, times, rate_Hz):
    """The sampling rate (Hz) the time column gives, checked as the module says, and a note."""
    name = header[j]
    unit = column_role(name)[1]
    if unit is not None and unit not in TIME_UNITS_S:
        rule = f"unit of the time must be {', '.join(TIME_UNITS_S)}"
        raise CaseError(f"column {name}", unit, rule)
    scale = TIME_UNITS_S.get(unit, 1.0)
    t = times * scale
    error = _half_units(rows, header, j) * scale + 4 * np.finfo(float).eps * np.abs(t).max()
    step = np.diff(t)
    if not np.all(step > 0):
        i = int(np.argmax(~(step > 0))) + 1
        number, cells = rows[i]
        rule = f"times must be ascending and evenly spaced; the previous is {rows[i - 1][1][j]}"
        raise CaseError(f"line {number}, column {name}", cells[j], rule)
    n = t.size
    along = np.arange(n) / (n - 1)
    off = np.abs(t - (t[0] * (1 - along) + t[-1] * along))
    allowed = error + (1 - along) * error[0] + along * error[-1]
    if np.any(off > allowed):
        i = int(np.argmax(off > allowed))
        rule = (
            f"times must be evenly spaced: {off[i]:.3g} s off the line through the first "
            "and last times, more than their written decimals allow "
            f"({allowed[i]:.3g} s)"
        )
        raise CaseError(f"line {rows[i][0]}, column {name}", rows[i][1][j], rule)
    step = (t[-1] - t[0]) / (n - 1)
    tolerance = (error[0] + error[-1]) / (n - 1)
    low = 1.0 / (step + tolerance)
    high = 1.0 / (step - tolerance) if step > tolerance else np.inf
    if rate_Hz is None:
        rate_Hz = _shortest(1.0 / step, low, high)
        note = f'sampling rate {rate_Hz:.10g} Hz from the column "{name}" (the shortest '
        return rate_Hz, note + f"number from {low:.12g} to {high:.12g} Hz, its precision)"
    if not low <= rate_Hz <= high:
        rule = (
            f'disagrees with the time column "{name}" ({1 / step:.12g} Hz, between '
            f"{low:.12g} and {high:.12g} Hz at the precision it is written)"
        )
        raise CaseError("--rate-Hz", rate_Hz, rule)
    return rate_Hz, f'sampling rate {rate_Hz:.10g} Hz from --rate-Hz (agrees with "{name}")'


def _shortest(rate_Hz: float, low: float, high: float) -> float:
    """The number of fewest significant digits from `low` to `high` (a DAQ's rate is round)."""
    for digits in range(1, 18):
        rounded = float(f"{rate_Hz:.{digits}g}")
        if low <= rounded <= high:
            return rounded
    return rate_Hz
