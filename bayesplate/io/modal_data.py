"""Measured modes as imported from a modal test file, before they meet a plate sheet.

A modal test ends in one of two files, read by :func:`bayesplate.io.modal_file.read_modal_data`:

- a Universal File (UFF, ``.uff``/``.unv``/``.uf``) as exported by modal software:
  :func:`bayesplate.io.uff.read_uff_modes`;
- a plain CSV table of frequencies, one row per mode:
  :func:`bayesplate.io.csv_table.read_frequency_csv`.

Both return a :class:`ModalData`; :func:`bayesplate.io.case_writer.case_from_modal_data`
turns it into a case file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ModalData"]

UFF_SUFFIXES = (".uff", ".unv", ".uf")
"""File name suffixes read as Universal Files."""


@dataclass(frozen=True, eq=False)
class ModalData:
    """Measured modes as imported, before they meet a plate sheet.

    Parameters
    ----------
    frequency_Hz : numpy.ndarray, shape (m,)
        Natural frequencies, Hz, ascending.
    points_mm : numpy.ndarray, shape (p, 2), optional
        (x, y) of the measured nodes in the plate frame, mm; None without coordinates.
    shapes : numpy.ndarray, shape (m, p), optional
        Real out-of-plane (z) amplitude of each mode at each point (arbitrary scale).
    damping : numpy.ndarray, shape (m,), optional
        Modal viscous damping ratios as given by the file (not used for fitting).
    sigma_Hz : numpy.ndarray, shape (m,), optional
        One standard deviation of each frequency, Hz, when the file gives it.
    mode : numpy.ndarray of int, shape (m,), optional
        1-based elastic-mode index of each frequency, when the file gives it.
    p_spurious : numpy.ndarray, shape (m,), optional
        Prior probability that each mode is spurious, from a tap test's pole evidence.
    spread_Hz : numpy.ndarray, shape (m,), optional
        Spread of each frequency over the fit's model orders, Hz: a frequency is written
        with a deviation at least this large (and to the digits it supports).
    source : str
        The file the data came from.
    notes : tuple of str
        What the reader had to assume (e.g. the length unit); logged as warnings and written
        as comments into the case file.
    """

    frequency_Hz: np.ndarray
    points_mm: np.ndarray | None = None
    shapes: np.ndarray | None = None
    damping: np.ndarray | None = None
    sigma_Hz: np.ndarray | None = None
    mode: np.ndarray | None = None
    p_spurious: np.ndarray | None = None
    spread_Hz: np.ndarray | None = None
    source: str = ""
    notes: tuple[str, ...] = ()

    @property
    def size(self) -> int:
        """Number of modes m."""
        return int(np.size(self.frequency_Hz))

    @property
    def n_points(self) -> int:
        """Number of measurement points p (0 without shapes)."""
        return 0 if self.points_mm is None else len(self.points_mm)
