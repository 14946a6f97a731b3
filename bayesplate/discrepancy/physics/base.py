"""The one small interface every candidate physics implements.

A candidate is a family of modified plates indexed by a few parameters ``theta`` (in the
units their names spell). :meth:`Physics.apply` returns the modified
:class:`~bayesplate.plate.model.PlateModel`; its stiffness stays linear in the six lamina
coefficients, so the estimators, the posterior and the sampler work on it unchanged.

A *located* candidate (an effect at a place on the plate: a point mass, a damaged patch)
also implements the two optional hooks :meth:`Physics.location_map` (first order: where a
small effect would explain the residuals) and :meth:`Physics.scan` (exact in a Ritz basis:
where, and how large, over a grid the candidate declares). :func:`..diagnose.diagnose` calls
them on every candidate and keys what they return by :attr:`Physics.name`; a new located
candidate is one module.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Parameter",
    "Physics",
    "distinct_images",
    "mirror_position",
    "mirror_positions",
    "plate_symmetries",
    "reflection_symmetric",
]


@dataclass(frozen=True)
class Parameter:
    """One parameter of a candidate physics, with its Gaussian prior and hard bounds.

    Attributes
    ----------
    name : str
        Unit in the name (``mass_g``, ``x_mm``), as in the case files.
    mean, sd : float
        Gaussian prior, in the parameter's unit.
    lower, upper : float
        Bounds of the admissible region (the prior is truncated there).
    """

    name: str
    mean: float
    sd: float
    lower: float = -np.inf
    upper: float = np.inf


class Physics:
    """A candidate piece of physics the nominal model leaves out.

    Subclasses set :attr:`name` (one string per candidate: it keys the candidate's results,
    maps and scans) and :attr:`description` and implement :meth:`parameters` and
    :meth:`apply`. ``theta`` is always a 1-D array ordered as :meth:`parameters`. Located
    candidates also implement :meth:`location_map` and :meth:`scan`.
    """

    name = ""
    description = ""

    def parameters(self, model, b):
        """The parameters and their priors: tuple of :class:`Parameter`.

        Priors are scaled to the plate (``model``) and its nominal stiffness coefficients
        ``b`` (Pa), so that "small" and "large" mean the same on every plate.
        """
        raise NotImplementedError

    def apply(self, model, theta):
        """The plate with this physics at ``theta``: a modified ``PlateModel``."""
        raise NotImplementedError

    def starting_points(self, model, b):
        """Values of ``theta`` to start a fit from, besides the prior mean.

        Default: one prior deviation either side of the mean for a single parameter (effects
        of either sign, and parameters whose sign the data cannot tell); none otherwise.
        """
        params = self.parameters(model, b)
        if len(params) != 1:
            return []
        p = params[0]
        return [np.array([np.clip(p.mean + s * p.sd, p.lower, p.upper)]) for s in (-1.0, 1.0)]

    def image(self, model, theta, symmetry):
        """``theta``'s image under one of the plate's symmetries (:func:`plate_symmetries`).

        The plate turned by ``symmetry`` with the effect at ``theta`` is the plate with the
        effect at the image: the same frequencies. Default: None (the candidate does not
        say; it then has no mirror images). Candidates override this (see :mod:`.point_mass`).
        """
        return None

    def mirror_images(self, model, theta):
        """Parameter values that the plate's symmetry makes indistinguishable from ``theta``.

        The distinct images of :meth:`image` under the plate's symmetries, ``theta`` left
        out (an effect on a line of symmetry is its own image there).
        """
        images = [self.image(model, theta, s) for s in plate_symmetries(model)]
        return [] if any(t is None for t in images) else distinct_images(theta, images)

    def settings(self):
        """Fixed choices of this instance that are not fitted, ``{name: value}``.

        Reported before the fitted parameters (a taper's ``direction``). Default: none.
        """
        return {}

    def location_map(self, model, paired, b, residual_whitened, sigma_lambda, projector):
        """First-order map: how well a small effect at each place explains the residuals.

        Linearised at the nominal fit: the column of each place is the derivative of the
        paired eigenvalues with respect to the effect's size there, whitened, with what the
        constants absorb projected out (:func:`.location.effect_map` does that part).

        Parameters
        ----------
        model : PlateModel
            The nominal plate.
        paired : ModalResult
            Modes of the nominal fit paired with the measured ones (measured order):
            ``eigenvalues`` shape (m,) in rad^2/s^2, ``vectors`` shape (n_dofs, m).
        b : numpy.ndarray, shape (6,)
            Stiffness coefficients of the nominal fit, Pa.
        residual_whitened : numpy.ndarray, shape (m,)
            ``(Y - lambda) / sigma`` of the nominal fit (dimensionless).
        sigma_lambda : numpy.ndarray, shape (m,)
            Deviations of the measured eigenvalues, rad^2/s^2.
        projector : numpy.ndarray, shape (m, m)
            Onto what the constants cannot absorb (:func:`.location.absorbable_projector`).

        Returns
        -------
        LocationMap or None
            None (the default) when the candidate is not located.
        """
        return None

    def scan(self, model, basis, b, Y, sigma, modes, projector):
        """Ritz scan: the chi-square of the effect over a grid of places and sizes.

        Exact (not linearised) in the Ritz basis of the nominal modes, so that large effects
        that reorder modes are found too. The candidate declares its own grid of sizes; the
        best distinct places of the scan start its joint fit.

        Parameters
        ----------
        model : PlateModel
            The nominal plate.
        basis : RitzBasis
            Rigid-body motions and elastic modes at the nominal fit (:mod:`.ritz_scan`).
        b : numpy.ndarray, shape (6,)
            Stiffness coefficients of the nominal fit, Pa.
        Y, sigma : numpy.ndarray, shape (m,)
            Measured eigenvalues and their deviations, rad^2/s^2.
        modes : numpy.ndarray of int, shape (m,)
            0-based elastic modes paired with the measured ones.
        projector : numpy.ndarray, shape (m, m)
            Onto what the constants cannot absorb (:func:`.location.absorbable_projector`).

        Returns
        -------
        Scan or None
            ``theta`` ordered as :meth:`parameters`; None (the default) when the candidate
            is not located.
        """
        return None

    def ritz(self, model, b, basis, near=None):
        """The modified plate's matrices projected on a Ritz basis, as functions of ``theta``.

        Parameters
        ----------
        model : PlateModel
            The plate to modify (the mesh of ``basis``).
        b : numpy.ndarray, shape (6,)
            Nominal stiffness coefficients, Pa (for priors scaled to the plate).
        basis : numpy.ndarray, shape (n_dofs, r)
            From :func:`.reduced_model.ritz_basis`.
        near : numpy.ndarray, shape (k,), optional
            When given, the form need only be exact at ``near`` and accurate around it (the
            pencil of a round of :mod:`..search.settling`, exact at its snapshot): a candidate whose
            exact form over the whole range is costly may build a cheaper local one.

        Returns
        -------
        callable or None
            ``theta -> (terms (6, r, r), constant (r, r), mass (r, r))`` (see
            :class:`.reduced_model.CandidatePencil`); None (the default) when the candidate has no
            cheap reduced form and is fitted on the finite-element model.
        """
        return None

    def labelled(self, model, b, theta):
        """``{name: value}`` of a parameter vector, for reports and JSON."""
        names = [p.name for p in self.parameters(model, b)]
        return {n: float(v) for n, v in zip(names, theta, strict=True)}


def distinct_images(theta, images):
    """The ``images`` that differ from ``theta`` and from each other (relative 1e-9)."""
    theta = np.asarray(theta, dtype=float)
    distinct = []
    for t in images:
        t = np.asarray(t, dtype=float)
        if not any(np.allclose(t, q, rtol=1e-9, atol=1e-12) for q in [theta, *distinct]):
            distinct.append(t)
    return distinct


def plate_symmetries(model):
    """The symmetries of the plate that leave its layup as it was.

    ``"x"``: the reflection ``x -> a - x``; ``"y"``: ``y -> b - y``; ``"xy"``: both, the
    half-turn. The half-turn leaves every ply as it was (an angle plus 180 degrees is the
    same ply); a reflection turns a ply at ``theta`` into one at ``-theta`` and holds only
    for 0 and 90 degree plies (:func:`reflection_symmetric`).
    """
    return ("x", "y", "xy") if reflection_symmetric(model) else ("xy",)


def mirror_position(model, x_mm, y_mm, symmetry):
    """The image of a point under one of :func:`plate_symmetries`, mm."""
    a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
    return (a_mm - x_mm if "x" in symmetry else x_mm, b_mm - y_mm if "y" in symmetry else y_mm)


def mirror_positions(model, x_mm, y_mm):
    """The mirror images of a point under the symmetries of a rectangular plate (mm).

    A single-material plate whose layup is unchanged by the reflections (0 and 90 degree
    plies) has the same frequencies for a located effect at ``(x, y)``, ``(a - x, y)``,
    ``(x, b - y)`` and ``(a - x, b - y)``. Other layups are only symmetric under the
    half-turn ``(a - x, b - y)``.
    """
    images = [mirror_position(model, x_mm, y_mm, s) for s in plate_symmetries(model)]
    tol = 1e-6 * 1e3 * max(model.mesh.a, model.mesh.b)
    distinct = []
    for p in images:  # a point on a line of symmetry is its own mirror image
        if all(np.hypot(p[0] - q[0], p[1] - q[1]) > tol for q in [(x_mm, y_mm), *distinct]):
            distinct.append(p)
    return distinct


def reflection_symmetric(model):
    """Whether the layup is unchanged by the reflections ``x -> -x`` and ``y -> -y``.

    A reflection turns a ply at ``theta`` into one at ``-theta``: only 0 and 90 degree plies
    stay as they were.
    """
    angles = np.mod(model.layup_deg, 90.0)
    return bool(np.all(np.isclose(angles, 0.0) | np.isclose(angles, 90.0)))
