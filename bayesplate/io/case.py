"""The plate-test case: plate, measurement and prior, validated and held in SI units.

A case describes one vibration test of one plate: the plate, the measured natural
frequencies, the prior on the six engineering constants and, optionally, the mesh and
published reference constants. Read one from a case file with
:func:`bayesplate.io.load_case`.

The dataclasses check their invariants in SI on construction (with the rules of
:mod:`bayesplate.io.checks`), so a case built or modified in code (:meth:`Case.with_prior`,
:meth:`Case.with_measured`) is as safe as one read from a file; every problem raises
:class:`~bayesplate.io.errors.CaseError`.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import numpy as np

from ..quantities import ENGINEERING_NAMES
from .checks import (
    _angles,
    _array,
    _check_frequencies,
    _check_length,
    _check_positive_each,
    _mesh,
    _mode_array,
    _number,
    _ply_thicknesses,
    _positive,
    _require_type,
    _string,
    check_engineering_constants,
    check_engineering_plausible,
    check_plausible,
)
from .errors import CaseError

__all__ = ["Plate", "Measurement", "Prior", "Case"]


class _EqualByValue:
    """Field-wise equality that compares array fields by value (dataclass eq cannot)."""

    __hash__ = None

    def __eq__(self, other):
        if type(self) is not type(other):
            return NotImplemented
        return all(
            _equal(getattr(self, f.name), getattr(other, f.name)) for f in dataclasses.fields(self)
        )


@dataclass(frozen=True, eq=False)
class Plate(_EqualByValue):
    """Geometry, density and stacking sequence of the plate, in SI units.

    Parameters
    ----------
    length : float
        a, along x (the 0 degree fibre direction), m.
    width : float
        b, along y, m.
    thickness : float
        h, total, m.
    density : float
        Mass density, kg/m^3.
    layup_deg : tuple of float
        Ply angles from the bottom face (z = -h/2) upward, degrees.
    ply_thickness : tuple of float, optional
        One thickness per ply, m, summing to `thickness`; default h / number of plies.
    length_sd, width_sd, thickness_sd : float, optional
        One standard deviation of the measured length, width and thickness, m; default 0
        (taken as exact). Plies keep their fractions of the thickness when it varies.
    density_sd : float, optional
        One standard deviation of the density, kg/m^3; default 0. Not used when `mass` is
        given (the density's error then follows from the mass's and the geometry's).
    mass : float, optional
        The weighed mass, kg, when the density was derived from it, ``rho = m / (a b h)``:
        the measured inputs are then (h, a, b, m), independent, and the density's error
        is correlated with the thickness's (:func:`bayesplate.likelihood.inputs.input_sources`).
        Default None (the density measured on its own). Not checked against the density
        here: the input Jacobian perturbs one input at a time.
    mass_sd : float, optional
        One standard deviation of the mass, kg; default 0.
    """

    length: float
    width: float
    thickness: float
    density: float
    layup_deg: tuple[float, ...]
    ply_thickness: tuple[float, ...] | None = None
    length_sd: float = 0.0
    width_sd: float = 0.0
    thickness_sd: float = 0.0
    density_sd: float = 0.0
    mass: float | None = None
    mass_sd: float = 0.0

    def __post_init__(self):
        for name in ("length", "width", "thickness", "density"):
            _set(self, name, _positive(getattr(self, name), f"plate.{name}"))
            sd = f"{name}_sd"
            _set(self, sd, _nonnegative(getattr(self, sd), f"plate.{sd}"))
            if getattr(self, sd) >= 0.5 * getattr(self, name):  # the input is not known at all
                raise CaseError(
                    f"plate.{sd}",
                    getattr(self, sd),
                    f"must be below half of plate.{name} (a standard deviation)",
                )
        for name, unit in (
            ("length", "_mm"),
            ("width", "_mm"),
            ("thickness", "_mm"),
            ("density", "_kg_m3"),
        ):
            check_plausible(getattr(self, name), name + unit, f"plate.{name}{unit}", si=True)
        if self.mass is not None:
            _set(self, "mass", _positive(self.mass, "plate.mass"))
        _set(self, "mass_sd", _nonnegative(self.mass_sd, "plate.mass_sd"))
        if self.mass is None and self.mass_sd:
            raise CaseError("plate.mass_sd", self.mass_sd, "needs plate.mass")
        if self.mass is not None and self.mass_sd >= 0.5 * self.mass:
            raise CaseError(
                "plate.mass_sd",
                self.mass_sd,
                "must be below half of plate.mass (a standard deviation)",
            )
        layup = _angles(self.layup_deg, "plate.layup_deg")
        _set(self, "layup_deg", tuple(layup))
        if self.ply_thickness is None:
            plies = [self.thickness / len(layup)] * len(layup)
        else:
            plies = _ply_thicknesses(
                self.ply_thickness, len(layup), self.thickness, "plate.ply_thickness"
            )
        check_plausible(plies, "ply_thickness_mm", "plate.ply_thickness_mm", si=True)
        check_plausible(layup, "layup_deg", "plate.layup_deg")
        _set(self, "ply_thickness", tuple(plies))


@dataclass(frozen=True, eq=False)
class Measurement(_EqualByValue):
    """Measured natural frequencies with their standard deviations and optional mode shapes.

    Arrays are stored as read-only copies.

    Parameters
    ----------
    frequency_Hz : array_like, shape (m,)
        Undamped natural frequencies of the free-free plate, Hz, ascending (ties allowed).
    sigma_Hz : array_like, shape (m,)
        One standard deviation of each frequency, Hz.
    mode : array_like of int, shape (m,), optional
        Distinct 1-based elastic-mode indices (1 = lowest non-rigid mode) of the frequencies;
        None means the first m modes in order.
    points : array_like, shape (p, 2), optional
        (x, y) of the measurement points on the mid-plane, m. Given with `shapes`.
    shapes : array_like, shape (m, p), optional
        Out-of-plane amplitude of each measured mode at each point (arbitrary scale).
    error_scale : bayesplate.likelihood.error_scale.ErrorScalePrior, optional
        Prior of a common, unknown scale ``s`` of the deviations (`sigma_Hz` times ``s``),
        inferred with the constants; None: ``s = 1`` (the deviations as declared).
    p_spurious : array_like, shape (m,), optional
        Prior probability that each frequency is no mode of the plate, in (0, 1), from the
        test's own evidence (a tap-test import: :mod:`bayesplate.matching.peak_prior`). Given, the
        frequencies are paired with modes by the most probable assignment by default.
    tap_points : array_like, shape (2, 2), optional
        (x, y) of the tap and of the sensor of a one-point tap test, m: a computed mode weak
        at either is more likely unobserved
        (:func:`bayesplate.matching.peak_prior.unobserved_from_amplitude`).
    """

    frequency_Hz: np.ndarray
    sigma_Hz: np.ndarray
    mode: np.ndarray | None = None
    points: np.ndarray | None = None
    shapes: np.ndarray | None = None
    error_scale: object = None
    p_spurious: np.ndarray | None = None
    tap_points: np.ndarray | None = None

    def __post_init__(self):
        frequency = _array(self.frequency_Hz, "measured.frequency_Hz", ndim=1)
        _check_frequencies(frequency, "measured.frequency_Hz")
        _set(self, "frequency_Hz", frequency)
        sigma = _array(self.sigma_Hz, "measured.sigma_Hz", ndim=1)
        _check_length(sigma, frequency.size, "measured.sigma_Hz", "entry per frequency")
        _check_positive_each(sigma, "measured.sigma_Hz")
        check_plausible(frequency, "frequency_Hz", "measured.frequency_Hz")
        check_plausible(sigma, "sigma_Hz", "measured.sigma_Hz")
        _set(self, "sigma_Hz", sigma)
        if self.mode is not None:
            _set(self, "mode", _mode_array(self.mode, frequency.size))
        _set_shapes(self, frequency.size)
        if self.error_scale is not None:
            from ..likelihood.error_scale import ErrorScalePrior

            _require_type(self.error_scale, ErrorScalePrior, "measured.error_scale")
        if self.p_spurious is not None:
            p = _array(self.p_spurious, "measured.p_spurious", ndim=1)
            _check_length(p, frequency.size, "measured.p_spurious", "entry per frequency")
            bad = np.flatnonzero(~((p > 0) & (p < 1)))
            if bad.size:
                key = f"measured.p_spurious[{bad[0]}]"
                raise CaseError(key, float(p[bad[0]]), "must be a probability > 0 and < 1")
            _set(self, "p_spurious", p)
        if self.tap_points is not None:
            _set(self, "tap_points", _array(self.tap_points, "measured.tap_point_mm", ndim=2))

    @property
    def size(self) -> int:
        """Number of measured frequencies m."""
        return int(self.frequency_Hz.size)

    def select(self, index) -> Measurement:
        """Return the measurement restricted to some frequencies.

        Parameters
        ----------
        index : slice or array_like of int or bool
            Which frequencies to keep (NumPy indexing along the frequency axis); the kept
            frequencies must still be ascending.

        Returns
        -------
        Measurement
            A new measurement with the selected rows of every per-frequency array.
        """
        rows = np.arange(self.size)[index]
        return dataclasses.replace(
            self,
            frequency_Hz=self.frequency_Hz[rows],
            sigma_Hz=self.sigma_Hz[rows],
            mode=None if self.mode is None else self.mode[rows],
            shapes=None if self.shapes is None else self.shapes[rows],
            p_spurious=None if self.p_spurious is None else self.p_spurious[rows],
        )


@dataclass(frozen=True, eq=False)
class Prior(_EqualByValue):
    """Independent Gaussian prior on the six engineering constants, in SI units.

    Parameters
    ----------
    mean : array_like, shape (6,)
        Prior means in the order of :data:`ENGINEERING_NAMES`: Pa for the moduli,
        dimensionless for nu12. Must describe a physically possible lamina.
    sd : array_like, shape (6,)
        Prior standard deviations, same order and units, each positive.
    """

    mean: np.ndarray
    sd: np.ndarray

    def __post_init__(self):
        mean = _array(self.mean, "prior.mean", ndim=1, finite=False)
        sd = _array(self.sd, "prior.sd", ndim=1, finite=False)
        _check_length(mean, 6, "prior.mean", "value per engineering constant")
        _check_length(sd, 6, "prior.sd", "value per engineering constant")
        for name, value in zip(ENGINEERING_NAMES, sd, strict=True):
            _positive(value, f"prior.{name}.sd")
        check_engineering_constants(mean, "prior", key_suffix=".mean")
        check_engineering_plausible(mean, sd, "prior", si=True)
        _set(self, "mean", mean)
        _set(self, "sd", sd)


@dataclass(frozen=True, eq=False)
class Case(_EqualByValue):
    """One vibration test of one plate, validated and in SI units.

    Parameters
    ----------
    name : str
        Free-text name of the test, non-empty.
    source : str
        Where the data come from; "" when not given.
    plate : Plate
        What was built.
    measured : Measurement
        What was measured.
    prior : Prior
        What is believed beforehand.
    mesh : tuple of int, optional
        Elements along x and y, (nx, ny); None lets the model choose.
    reference : array_like, shape (6,), optional
        Known or published constants (SI, order of :data:`ENGINEERING_NAMES`), never used
        to fit.
    path : str, optional
        The case file this case was read from.
    """

    name: str
    source: str
    plate: Plate
    measured: Measurement
    prior: Prior
    mesh: tuple[int, int] | None = None
    reference: np.ndarray | None = None
    path: str | None = None

    def __post_init__(self):
        _string(self.name, "name", nonempty=True)
        _string(self.source, "source")
        _require_type(self.plate, Plate, "plate")
        _require_type(self.measured, Measurement, "measured")
        _require_type(self.prior, Prior, "prior")
        if self.mesh is not None:
            _set(self, "mesh", _mesh(self.mesh, "model.mesh"))
        if self.reference is not None:
            reference = _array(self.reference, "reference", ndim=1, finite=False)
            _check_length(reference, 6, "reference", "value per engineering constant")
            check_engineering_constants(reference, "reference")
            check_engineering_plausible(reference, None, "reference", si=True)
            _set(self, "reference", reference)
        if self.path is not None:
            _set(self, "path", os.fspath(self.path))

    def with_prior(self, mean, sd) -> Case:
        """Return the same case with another prior.

        Parameters
        ----------
        mean, sd : array_like, shape (6,)
            Prior means and standard deviations in SI (Pa, dimensionless nu12).

        Returns
        -------
        Case
            A new, validated case.
        """
        return dataclasses.replace(self, prior=Prior(mean, sd))

    def with_measured(self, measured: Measurement | None = None, **changes) -> Case:
        """Return the same case with another or modified measurement.

        Parameters
        ----------
        measured : Measurement, optional
            The new measurement; default the current one.
        **changes
            Fields of :class:`Measurement` to replace, e.g. ``frequency_Hz=...,
            sigma_Hz=...``.

        Returns
        -------
        Case
            A new, validated case.
        """
        base = self.measured if measured is None else measured
        return dataclasses.replace(self, measured=dataclasses.replace(base, **changes))


def _nonnegative(raw, key: str) -> float:
    """Return `raw` as a finite float >= 0 (a standard deviation; 0 means exact)."""
    value = _number(raw, key)
    if value < 0:
        raise CaseError(key, raw, "must be a number >= 0 (a standard deviation)")
    return value


def _set(obj, name: str, value) -> None:
    """Assign a field of a frozen dataclass during ``__post_init__``."""
    object.__setattr__(obj, name, value)


def _equal(x, y) -> bool:
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and np.array_equal(x, y)
    return bool(x == y)


def _set_shapes(measurement: Measurement, n_frequencies: int) -> None:
    points, shapes = measurement.points, measurement.shapes
    if (points is None) != (shapes is None):
        raise CaseError("measured.points", points, "points and shapes go together")
    if points is None:
        return
    points = _array(points, "measured.points", ndim=2)
    if points.shape[1] != 2 or len(points) == 0:
        raise CaseError("measured.points", points, "must have shape (p, 2) with p >= 1")
    shapes = _array(shapes, "measured.shapes", ndim=2)
    _check_length(shapes, n_frequencies, "measured.shapes", "row per frequency")
    if shapes.shape[1] != len(points):
        rule = f"must have one column per point ({len(points)}), got {shapes.shape[1]}"
        raise CaseError("measured.shapes", shapes, rule)
    for i, row in enumerate(shapes):
        if not np.any(row):
            raise CaseError(f"measured.shapes[{i}]", row, "must not be all zero")
    _set(measurement, "points", points)
    _set(measurement, "shapes", shapes)
