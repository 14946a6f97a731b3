"""The measured inputs in the posterior: one exact draw of them per kept draw of the constants.

The plate's inputs (thickness h, density rho or the weighed mass m, length a, width b) are
read with the case's deviations. Write the independent readings as ``q = q0 + D z`` with
``z ~ N(0, I)`` (``D = diag(sd)``) and their effect on ``p = (h, rho, a, b)`` as
``p - p0 = A z`` (:func:`bayesplate.likelihood.inputs.input_sources`: ``A = diag(sd)``, or with a
mass ``rho = m / (a b h)`` linearised). The linear input model is

    ``Y = lambda(b) + B z + e``,   ``B = J_p A``,   ``e ~ N(0, V_Y)``,   ``z ~ N(0, I)``,

with ``V_Y`` the declared eigenvalue covariance and ``J_p = d lambda / d p``
(:func:`bayesplate.likelihood.inputs.input_jacobian`, held fixed where the sampler's setup evaluated
it: the marginal MAP).

Collapsed (Rao-Blackwellised) sampling
    The joint posterior factorises, ``f(b, z | Y) = f(b | Y) f(z | b, Y)``. Under the linear
    model ``z`` integrates out in closed form, ``f(b | Y) = N(Y; lambda(b), V_Y + B B^T)
    f(b)``: exactly the marginal problem the sampler runs on (``inputs="marginal"``). And
    ``f(z | b, Y)`` is Gaussian (Gaussian prior, likelihood linear in ``z``)::

        C = (I + B^T V_Y^-1 B)^-1,   E[z | b, Y] = C B^T V_Y^-1 (Y - lambda(b)),   Cov = C.

    So a kept draw ``b_i`` of the chain (a draw of ``f(b | Y)``) followed by one
    ``z_i ~ N(E[z | b_i, Y], C)`` is a draw of the joint posterior ``f(b, z | Y)``: the
    pairs are exact joint samples, with the chain's autocorrelation and nothing more. This
    is the collapsed Gibbs idea (Liu 1994): sample the parameters with the nuisance
    integrated out, then the nuisance from its conditional; no Markov step is added. The
    one approximation is the linear input model itself (eigenvalues linear in the inputs,
    ``J_p`` constant over the posterior), which :func:`linear_input_certificate` checks
    against full finite-element solves at +- 2 sd of each reading.

    With an error scale (the case's ``measured.error_scale``) the sampled problem is
    ``Y ~ N(lambda(b), s^2 (V_Y + B B^T))``, i.e. ``e ~ N(0, s^2 V_Y)`` and
    ``z ~ N(0, s^2 I)``: one ``s`` per kept draw from ``s^2 | b, Y`` (inverse gamma with the
    marginal chi-square, :func:`bayesplate.likelihood.error_scale.draw_scale`), then ``z`` with the
    same mean and covariance ``s^2 C``.

Readings reported are those the case declares (a deviation above 0), in case units (mm, g,
kg/m^3; :mod:`bayesplate.likelihood.input_summary`); a reading with no deviation has ``B`` column 0
and stays at its value.

Certificate
    :func:`linear_input_certificate`: at the estimate ``b``, each declared reading moved by
    +- 2 of its deviations alone; the full model solved there (the true density
    ``rho0 (m / m0) (a0 b0 h0) / (a b h)`` with a mass) against ``lambda(b) + J_p A dz``;
    the error relative to the nominal eigenvalue and in units of that mode's declared
    deviation. It fails (status ``"nonlinear"``, a warning logged) above
    :data:`CERTIFICATE_FRACTION` of the deviation.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field

import numpy as np

from ..matching.pairing import track
from ..plate.model import DEFAULT_MESH, PlateModel
from .input_summary import summarise_inputs
from .inputs import input_sd, input_sources

__all__ = [
    "CERTIFICATE_FRACTION",
    "CERTIFICATE_SD",
    "InputCertificate",
    "InputConditional",
    "declared_readings",
    "draw_inputs",
    "input_conditional",
    "inputs_from_chain",
    "linear_input_certificate",
]

log = logging.getLogger(__name__)

#: The linear input model fails its certificate when an error at +- CERTIFICATE_SD deviations
#: of a reading exceeds this fraction of a mode's declared deviation: a quarter of the noise
#: is where a misfit starts to move a chi-square (by about 0.06 per mode) and a posterior.
CERTIFICATE_FRACTION = 0.25
#: How far each reading moves in the certificate: +- 2 deviations hold 95 % of its prior.
CERTIFICATE_SD = 2.0
_EXTRA_MODES = 4  # computed beyond the highest paired mode, so MAC can follow a crossing


def declared_readings(plate):
    """The four independent readings of a plate: names, values and deviations.

    Parameters
    ----------
    plate : bayesplate.io.Plate

    Returns
    -------
    names : tuple of str
        ``("thickness", "density", "length", "width")``, or with ``"mass"`` for the density
        when the plate was weighed (``plate.mass``).
    value, sd : numpy.ndarray, shape (4,)
        SI (m, kg/m^3 or kg).
    """
    names, _ = input_sources(plate)
    sd = input_sd(plate)
    weighed = plate.mass is not None
    if weighed:
        sd[1] = plate.mass_sd
    second = plate.mass if weighed else plate.density
    value = np.array([plate.thickness, second, plate.length, plate.width], dtype=float)
    return names, value, sd


@dataclass(frozen=True)
class InputConditional:
    """``f(z | b, Y)`` of the linear input model (module docstring).

    Attributes
    ----------
    names : tuple of str
        The four readings (:func:`declared_readings`).
    value, sd : numpy.ndarray, shape (4,)
        Their declared values and deviations, SI.
    B : numpy.ndarray, shape (m, 4)
        ``J_p A``: the paired eigenvalues' change per deviation of each reading, rad^2/s^2.
    gain : numpy.ndarray, shape (4, m)
        ``C B^T V_Y^-1``: ``E[z | b, Y] = gain (Y - lambda(b))``.
    covariance : numpy.ndarray, shape (4, 4)
        ``C = (I + B^T V_Y^-1 B)^-1`` (at ``s = 1``).
    at : numpy.ndarray, shape (6,), or None
        The stiffness coefficients where ``J_p`` was evaluated, Pa (when given).
    """

    names: tuple
    value: np.ndarray
    sd: np.ndarray
    B: np.ndarray = field(repr=False)
    gain: np.ndarray = field(repr=False)
    covariance: np.ndarray
    at: np.ndarray | None = None

    @property
    def declared(self):
        """Indices of the readings with a deviation above 0, shape (k,)."""
        return np.flatnonzero(self.sd > 0)


def input_conditional(J, A, V_Y, names, value, sd, at=None) -> InputConditional:
    """The conditional of the standardised readings ``z`` given ``b`` and the data.

    Parameters
    ----------
    J : array_like, shape (m, 4)
        ``d lambda / d (h, rho, a, b)``, rad^2/s^2 per SI unit.
    A : array_like, shape (4, 4)
        One deviation of each reading's effect on ``(h, rho, a, b)``
        (:func:`bayesplate.likelihood.inputs.input_sources`).
    V_Y : array_like, shape (m, m)
        The declared eigenvalue covariance (without the inputs), rad^4/s^4.
    names : tuple of str
    value, sd : array_like, shape (4,)
        The readings and their deviations, SI (:func:`declared_readings`).
    at : array_like, shape (6,), optional
        Where `J` was evaluated, Pa (kept in the result).

    Returns
    -------
    InputConditional
    """
    B = np.asarray(J, dtype=float) @ np.asarray(A, dtype=float)
    WB = np.linalg.solve(np.asarray(V_Y, dtype=float), B)  # V_Y^-1 B, (m, 4)
    C = np.linalg.inv(np.eye(B.shape[1]) + B.T @ WB)
    C = 0.5 * (C + C.T)  # symmetric to round-off, for the Cholesky factor
    at = None if at is None else np.asarray(at, dtype=float)
    return InputConditional(
        tuple(names),
        np.asarray(value, dtype=float),
        np.asarray(sd, dtype=float),
        B,
        C @ WB.T,
        C,
        at,
    )


def draw_inputs(conditional, residuals, rng, s=None):
    """One draw of the readings per residual vector ``Y - lambda(b_i)``.

    Parameters
    ----------
    conditional : InputConditional
    residuals : array_like, shape (n, m)
        ``Y - lambda(b_i)`` at kept draws ``b_i`` of ``f(b | Y)``, rad^2/s^2.
    rng : numpy.random.Generator
    s : array_like, shape (n,), optional
        The error scale drawn with each ``b_i`` (module docstring); default 1.

    Returns
    -------
    numpy.ndarray, shape (n, 4)
        The readings, SI: ``value + sd z_i`` with ``z_i ~ N(gain r_i, s_i^2 C)``.
    """
    r = np.atleast_2d(np.asarray(residuals, dtype=float))
    mean = r @ conditional.gain.T
    L = np.linalg.cholesky(conditional.covariance)
    xi = rng.standard_normal(mean.shape)
    spread = xi @ L.T
    if s is not None:
        spread = spread * np.asarray(s, dtype=float)[:, None]
    z = mean + spread
    return conditional.value[None, :] + conditional.sd[None, :] * z


def inputs_from_chain(problem, samples_b, forward, conditional, rng, max_draws=4000):
    """The readings' posterior from a chain of the marginal problem (module docstring).

    Parameters
    ----------
    problem : bayesplate.likelihood.posterior.GaussianProblem
        The sampled (marginal) problem: its ``Y``, pairing and error scale.
    samples_b : array_like, shape (n, 6)
        Kept draws of ``b``, Pa (``SamplingResult.samples_b``).
    forward : callable
        ``forward(b, n_modes)`` with ``eigenvalues``: the sampler's own model.
    conditional : InputConditional
    rng : numpy.random.Generator
    max_draws : int
        At most this many kept draws, a seeded subset without replacement when there are
        more (a forward evaluation each: about a millisecond on the fast model).

    Returns
    -------
    InputPosterior
    """
    samples_b = np.asarray(samples_b, dtype=float)
    n = len(samples_b)
    rows = np.sort(rng.choice(n, max_draws, replace=False)) if n > max_draws else np.arange(n)
    n_modes, modes = problem.pairing.n_modes(), problem.pairing.modes
    lam = np.array([np.asarray(forward(b, n_modes).eigenvalues)[modes] for b in samples_b[rows]])
    residuals = problem.Y[None, :] - lam
    s = None
    if problem.error_scale is not None:
        from .error_scale import draw_scale

        chi2 = np.array([problem.chi2(g) for g in lam])  # with the marginal V_Y
        s = draw_scale(chi2, problem.m, problem.error_scale, rng)
    draws = draw_inputs(conditional, residuals, rng, s)
    return summarise_inputs(conditional, draws, rows)


@dataclass(frozen=True)
class InputCertificate:
    """The linear input model against full solves at +- ``n_sd`` deviations of each reading.

    Attributes
    ----------
    names : tuple of str
        The declared readings checked.
    n_sd : float
    relative : numpy.ndarray, shape (k, 2, m)
        ``(lambda_full - lambda_linear) / lambda(b)`` per reading, sign (+, -) and mode.
    in_sd : numpy.ndarray, shape (k, 2, m)
        ``|lambda_full - lambda_linear|`` in units of each mode's declared eigenvalue sd.
    fraction : float
        The pass mark on ``in_sd``.
    n_solves : int
        Full finite-element solves spent.
    """

    names: tuple
    n_sd: float
    relative: np.ndarray = field(repr=False)
    in_sd: np.ndarray = field(repr=False)
    fraction: float
    n_solves: int

    @property
    def max_relative(self):
        """Largest ``|relative|``."""
        return float(np.max(np.abs(self.relative))) if self.relative.size else 0.0

    @property
    def max_in_sd(self):
        """Largest error in units of the mode's declared deviation."""
        return float(np.max(self.in_sd)) if self.in_sd.size else 0.0

    @property
    def worst(self):
        """``(reading, "+" or "-", 1-based paired position)`` of the largest ``in_sd``."""
        if not self.in_sd.size:
            return None
        k, sign, i = np.unravel_index(int(np.argmax(self.in_sd)), self.in_sd.shape)
        return self.names[k], "+-"[sign], int(i) + 1

    @property
    def passed(self):
        """Whether every error is within ``fraction`` of the mode's deviation."""
        return self.max_in_sd <= self.fraction

    @property
    def status(self):
        """``"ok"`` or ``"nonlinear"`` (the linear input model fails its certificate)."""
        return "ok" if self.passed else "nonlinear"

    def __str__(self):
        if not self.names:
            return "linear input model: no declared input"
        name, sign, i = self.worst
        verdict = (
            f"within {self.fraction:g} sd: ok"
            if self.passed
            else f"FAILS (over {self.fraction:g} sd): the posterior's inputs are "
            "approximate beyond the linear model"
        )
        return (
            f"linear input model at +-{self.n_sd:g} sd of each input: largest error "
            f"{100 * self.max_relative:.2g} % of an eigenvalue, {self.max_in_sd:.2g} of "
            f"its measurement sd ({name} {sign}{self.n_sd:g} sd, paired frequency {i}); "
            f"{verdict}"
        )


def _inputs_at(plate, names, readings):
    """``(h, rho, a, b)`` SI of a plate whose readings are `readings` (4,), SI."""
    h, second, a, b = readings
    if names[1] != "mass":
        return np.array([h, second, a, b])
    # rho = m / (a b h), taken relative to the case's density (which may round m / (a b h))
    rho = (
        plate.density
        * (second / plate.mass)
        * (plate.thickness * plate.length * plate.width)
        / (h * a * b)
    )
    return np.array([h, rho, a, b])


def _case_with(case, p):
    """The case on a plate with inputs ``p = (h, rho, a, b)`` SI (plies keep their fractions)."""
    plate = case.plate
    ratio = p[0] / plate.thickness
    changed = dataclasses.replace(
        plate,
        thickness=p[0],
        density=p[1],
        length=p[2],
        width=p[3],
        ply_thickness=tuple(t * ratio for t in plate.ply_thickness),
    )
    return dataclasses.replace(case, plate=changed)


def linear_input_certificate(
    case, b, B, modes, sd_lambda, mesh=None, n_sd=CERTIFICATE_SD, fraction=CERTIFICATE_FRACTION
) -> InputCertificate:
    """Check the linear input model against full solves (module docstring).

    Parameters
    ----------
    case : bayesplate.io.Case
        Its plate's declared readings are moved, one at a time.
    b : array_like, shape (6,)
        Stiffness coefficients (the estimate), Pa.
    B : array_like, shape (m, 4)
        ``J_p A``: the eigenvalues' change per deviation of each reading that the model uses
        (:attr:`InputConditional.B`, ``J_p`` wherever it was evaluated).
    modes : array_like of int, shape (m,)
        0-based computed modes paired with the measured ones.
    sd_lambda : array_like, shape (m,)
        Declared eigenvalue deviations, rad^2/s^2.
    mesh : tuple of int, optional
        Default the case's.
    n_sd, fraction : float

    Returns
    -------
    InputCertificate
        A warning is logged when it fails.
    """
    modes = np.asarray(modes, dtype=int)
    mesh = tuple(mesh or case.mesh or DEFAULT_MESH)
    n_modes = int(modes.max()) + 1 + _EXTRA_MODES
    b = np.asarray(b, dtype=float)
    B = np.asarray(B, dtype=float)
    sd_lambda = np.asarray(sd_lambda, dtype=float)
    names, value, sd = declared_readings(case.plate)
    base = PlateModel.from_case(case, mesh=mesh).solve(b, n_modes)
    lam = base.eigenvalues[modes]
    declared = np.flatnonzero(sd > 0)
    relative = np.zeros((declared.size, 2, modes.size))
    for row, k in enumerate(declared):
        for col, sign in enumerate((1.0, -1.0)):
            readings = value.copy()
            readings[k] += sign * n_sd * sd[k]
            p = _inputs_at(case.plate, names, readings)
            modal = PlateModel.from_case(_case_with(case, p), mesh=mesh).solve(b, n_modes)
            moved, _ = track(base.vectors, modal.vectors, modes)
            linear = lam + B[:, k] * sign * n_sd
            relative[row, col] = (modal.eigenvalues[moved] - linear) / lam
    in_sd = np.abs(relative) * lam[None, None, :] / sd_lambda[None, None, :]
    cert = InputCertificate(
        tuple(names[k] for k in declared),
        float(n_sd),
        relative,
        in_sd,
        float(fraction),
        1 + 2 * declared.size,
    )
    if not cert.passed:
        log.warning("%s", cert)
    return cert
