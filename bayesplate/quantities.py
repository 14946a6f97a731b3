"""The project's vocabulary: the constants' names, case-file keys, units and conversions.

Every other module takes these from here; nothing else spells them out.

- The engineering constants ``e = (E1, E2, nu12, G12, G13, G23)``: SI inside (Pa, -), case
  files and output in GPa (:data:`ENGINEERING_KEYS`, :func:`to_case_units`).
- The lamina stiffness coefficients ``b = (C11, C22, C12, C66, C44, C55)`` (Pa), the
  parameters the estimators iterate on; ``b(e)`` and its Jacobian ``J = d b / d e`` are the
  mechanics of :mod:`bayesplate.laminate`; here are the covariance transforms
  ``cov_b = J cov_e J^T`` and ``cov_e = J^-1 cov_b J^-T`` (first order).
- Frequencies and eigenvalues: ``lambda = (2 pi f)^2`` (rad^2/s^2), and a frequency deviation
  ``df`` as an eigenvalue deviation ``d lambda = 8 pi^2 f df`` (first order); a relative
  frequency deviation ``r`` is ``d lambda = 2 r lambda``.

Pure array computation; numpy only.
"""

from __future__ import annotations

import numpy as np

from . import laminate

__all__ = [
    "predictive_sd_Hz",
    "ENGINEERING_NAMES",
    "ENGINEERING_UNITS",
    "ENGINEERING_KEYS",
    "STIFFNESS_NAMES",
    "CASE_SCALE",
    "LOG_STIFFNESS",
    "to_case_units",
    "from_case_units",
    "stiffness_covariance",
    "engineering_covariance",
    "eigenvalue_from_hz",
    "hz_from_eigenvalue",
    "eigenvalue_sd",
    "hz_sd",
    "eigenvalue_sd_from_relative",
]

#: The engineering constants, in the order every array of them uses.
ENGINEERING_NAMES = ("E1", "E2", "nu12", "G12", "G13", "G23")
#: Their units in case files, tables and output.
ENGINEERING_UNITS = ("GPa", "GPa", "-", "GPa", "GPa", "GPa")
#: Their keys in case files and JSON output (name and unit).
ENGINEERING_KEYS = ("E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa")
#: The lamina stiffness coefficients (eqs. 20-21), Pa.
STIFFNESS_NAMES = ("C11", "C22", "C12", "C66", "C44", "C55")
#: Case units (GPa, -) to SI (Pa, -), per constant: ``e_SI = e_case * CASE_SCALE``.
CASE_SCALE = np.array([1e9, 1e9, 1.0, 1e9, 1e9, 1e9])
#: Stiffness coefficients that are positive scales, taken in log coordinates where a
#: parameterisation needs it (C12 may be of either sign).
LOG_STIFFNESS = np.array([True, True, False, True, True, True])


def to_case_units(e_si):
    """Engineering constants (or their deviations) from SI to case units (GPa, -).

    Parameters
    ----------
    e_si : array_like, shape (..., 6)

    Returns
    -------
    numpy.ndarray, shape (..., 6)
    """
    return np.asarray(e_si, dtype=float) / CASE_SCALE


def from_case_units(e_case):
    """Engineering constants (or their deviations) from case units (GPa, -) to SI.

    Parameters
    ----------
    e_case : array_like, shape (..., 6)

    Returns
    -------
    numpy.ndarray, shape (..., 6)
    """
    return np.asarray(e_case, dtype=float) * CASE_SCALE


def stiffness_covariance(e, cov_e):
    """``cov_b = J cov_e J^T`` with ``J = d b / d e`` at `e` (first order).

    Parameters
    ----------
    e : array_like, shape (6,)
        Engineering constants, SI.
    cov_e : array_like, shape (6, 6)
        Their covariance, SI.

    Returns
    -------
    numpy.ndarray, shape (6, 6)
        Pa^2.
    """
    J = laminate.stiffness_jacobian(e)
    return J @ np.asarray(cov_e, dtype=float) @ J.T


def engineering_covariance(e, cov_b):
    """``cov_e = J^-1 cov_b J^-T`` with ``J = d b / d e`` at `e` (first order).

    Parameters
    ----------
    e : array_like, shape (6,)
        Engineering constants at which to linearise, SI (the estimate's).
    cov_b : array_like, shape (6, 6)
        Their covariance, Pa^2.

    Returns
    -------
    numpy.ndarray, shape (6, 6)
        Covariance of ``(E1, E2, nu12, G12, G13, G23)``, SI.
    """
    J_inv = np.linalg.inv(laminate.stiffness_jacobian(e))
    return J_inv @ np.asarray(cov_b, dtype=float) @ J_inv.T


def eigenvalue_from_hz(frequency_Hz):
    """``lambda = (2 pi f)^2``, rad^2/s^2, same shape as `frequency_Hz`."""
    return (2.0 * np.pi * np.asarray(frequency_Hz, dtype=float)) ** 2


def hz_from_eigenvalue(eigenvalue):
    """``f = sqrt(lambda) / (2 pi)``, Hz; negative round-off eigenvalues give 0."""
    return np.sqrt(np.maximum(np.asarray(eigenvalue, dtype=float), 0.0)) / (2 * np.pi)


def eigenvalue_sd(frequency_Hz, sd_Hz):
    """Eigenvalue deviation of a frequency deviation, ``d lambda = 8 pi^2 f df`` (first order)."""
    f = np.asarray(frequency_Hz, dtype=float)
    return 8.0 * np.pi**2 * f * np.asarray(sd_Hz, dtype=float)


def hz_sd(frequency_Hz, eigenvalue_sd):
    """Frequency deviation of an eigenvalue deviation, ``df = d lambda / (8 pi^2 f)``."""
    f = np.asarray(frequency_Hz, dtype=float)
    return np.asarray(eigenvalue_sd, dtype=float) / (8 * np.pi**2 * f)


def eigenvalue_sd_from_relative(eigenvalue, relative):
    """Eigenvalue deviation of a relative frequency deviation ``r``: ``2 r lambda``."""
    return 2.0 * np.asarray(relative, dtype=float) * np.asarray(eigenvalue, dtype=float)


def predictive_sd_Hz(frequency_Hz, sensitivities, covariance_b):
    """Deviation of computed frequencies from the constants' uncertainty (first order).

    ``var(lambda_j) = S_j P S_j^T``, and ``d f = d lambda / (8 pi^2 f)``.

    Parameters
    ----------
    frequency_Hz : array_like, shape (n,)
    sensitivities : array_like, shape (n, 6)
        ``d lambda / d b``, rad^2/s^2/Pa.
    covariance_b : array_like, shape (6, 6)
        Covariance of ``b``, Pa^2.

    Returns
    -------
    numpy.ndarray, shape (n,)
        Hz.
    """
    S = np.asarray(sensitivities, dtype=float)
    var = np.einsum("ij,jk,ik->i", S, np.asarray(covariance_b, dtype=float), S)
    f = np.asarray(frequency_Hz, dtype=float)
    return hz_sd(f, np.sqrt(np.maximum(var, 0.0)))
