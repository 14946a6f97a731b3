"""A modal test file, whatever its format: :func:`read_modal_data` dispatches on the suffix.

Measured modes come from a UFF dataset 55 file or a CSV table of frequencies; a tap test
(FRFs in UFF dataset 58 or a CSV table, an impulse recording in WAV or a CSV time series)
is recognised by its content and read as spectra by :func:`read_spectra`, whose modes are
extracted by :mod:`bayesplate.io.poles`.
"""

from __future__ import annotations

import os
import pathlib

from .errors import CaseError
from .modal_data import UFF_SUFFIXES, ModalData

__all__ = ["read_modal_data", "read_spectra", "is_tap_test"]

_TAP_SUFFIXES = (".wav",)


def read_modal_data(path) -> ModalData:
    """Read a UFF (``.uff``, ``.unv``, ``.uf``), CSV (``.csv``) or WAV file of a modal test.

    A file of modes (UFF dataset 55, a CSV of frequencies) is read as it is; a tap test
    (see :func:`is_tap_test`) is reduced to the modes whose poles are stable over the last
    model orders, with the defaults of :func:`bayesplate.io.poles.extract_poles`.

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
    if is_tap_test(path):
        from .poles import extract_poles, modal_data_from_poles

        spectra = read_spectra(path)
        return modal_data_from_poles(spectra, extract_poles(spectra).kept)
    if suffix == ".csv":
        from .csv_table import read_frequency_csv

        return read_frequency_csv(path)
    if suffix in UFF_SUFFIXES:
        from .uff import read_uff_modes  # pyuff is imported only for a UFF file

        return read_uff_modes(path)
    rule = f"unknown kind of file: expected {', '.join(UFF_SUFFIXES)} (UFF), .csv or .wav"
    raise CaseError("input", os.fspath(path), rule)


def is_tap_test(path) -> bool:
    """Whether `path` holds a tap test rather than modes.

    True for a ``.wav`` file, a CSV time series (a time or response column and no frequency:
    :func:`bayesplate.io.impulse.is_recording`) or a CSV with ``Hk_re`` columns (FRFs), and a
    UFF file with dataset 58 (FRFs) and no dataset 55 (modes). A file that cannot be read is
    not a tap test (its reader says why).
    """
    from .impulse import is_recording

    suffix = pathlib.Path(path).suffix.lower()
    if suffix in _TAP_SUFFIXES or is_recording(path):
        return True
    if suffix == ".csv":
        return any(n.startswith("H") and n.endswith("_re") for n in _csv_header(path))
    if suffix in UFF_SUFFIXES:
        try:
            import pyuff

            types = {int(t) for t in pyuff.UFF(os.fspath(path)).get_set_types()}
        except Exception:  # noqa: BLE001 - the modes reader reports the problem
            return False
        return 58 in types and 55 not in types
    return False


def _csv_header(path) -> list[str]:
    try:
        with open(path, encoding="utf-8-sig") as stream:
            for line in stream:
                content = line.split("#", 1)[0]
                if content.strip():
                    return [cell.strip() for cell in content.split(",")]
    except (OSError, UnicodeDecodeError):
        pass
    return []


def read_spectra(path, window: str = "auto"):
    """Read a tap test as spectra: FRFs (UFF dataset 58, CSV) or an impulse (WAV, CSV).

    Parameters
    ----------
    path : str or os.PathLike
    window : {"auto", "none", "exponential"}
        Window of an impulse recording (see :mod:`bayesplate.io.impulse`).

    Returns
    -------
    bayesplate.io.frf.FRFData

    Raises
    ------
    CaseError
        For another suffix, or anything the chosen reader refuses.
    """
    from .impulse import is_recording

    suffix = pathlib.Path(path).suffix.lower()
    if suffix in _TAP_SUFFIXES or is_recording(path):
        from .taps import read_impulse

        return read_impulse(path, window=window)
    if suffix == ".csv":
        from .frf import read_frf_csv

        return read_frf_csv(path)
    if suffix in UFF_SUFFIXES:
        from .frf import read_uff_frf

        return read_uff_frf(path)
    rule = f"unknown kind of tap test: expected {', '.join(UFF_SUFFIXES)} (UFF 58), .csv or .wav"
    raise CaseError("input", os.fspath(path), rule)
