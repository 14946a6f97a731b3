"""A modal test file, whatever its format: :func:`read_modal_data` dispatches on the suffix."""

from __future__ import annotations

import os
import pathlib

from .errors import CaseError
from .modal_data import UFF_SUFFIXES, ModalData

__all__ = ["read_modal_data"]


def read_modal_data(path) -> ModalData:
    """Read a UFF (``.uff``, ``.unv``, ``.uf``) or CSV (``.csv``) file of measured modes.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    ModalData

    Raises
    ------
    CaseError
        For another suffix, or anything the chosen reader refuses.
    """
    suffix = pathlib.Path(path).suffix.lower()
    if suffix == ".csv":
        from .csv_table import read_frequency_csv

        return read_frequency_csv(path)
    if suffix in UFF_SUFFIXES:
        from .uff import read_uff_modes  # pyuff is imported only for a UFF file

        return read_uff_modes(path)
    rule = f"unknown kind of file: expected {', '.join(UFF_SUFFIXES)} (UFF) or .csv"
    raise CaseError("input", os.fspath(path), rule)
