"""A glued sensor or lump: a point mass on the plate's mid-plane (a located candidate)."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics, mirror_position
from .location import effect_map
from .reduced_model import project
from .ritz_scan import Scan, misfit

__all__ = ["PointMass", "point_mass_map", "point_mass_scan"]


def _plate_mass_g(model):
    return 1e3 * model.density * model.thickness * model.mesh.a * model.mesh.b


class PointMass(Physics):
    """``M + m N_w(x, y)^T N_w(x, y)``: translational inertia of a mass ``m`` at ``(x, y)``.

    The mass moves with the mid-plane deflection ``w``; its rotary and in-plane inertia are
    neglected (a sensor much smaller than the wavelengths).

    Attributes
    ----------
    scan_mass_fractions : numpy.ndarray
        Masses the scan tries, as fractions of the plate's mass.
    scan_stride : int
        The scan tries every ``scan_stride``-th node each way.
    """

    name = "point_mass"
    description = "a point mass (glued sensor) at (x, y)"
    scan_mass_fractions = np.geomspace(0.003, 1.0, 18)
    scan_stride = 2

    def parameters(self, model, b):
        """``mass_g``, ``x_mm``, ``y_mm``.

        Mass prior 5 +- 10 % of the plate's mass (>= 0); position with the mean and
        deviation of a uniform position over the plate.
        """
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        plate_mass_g = _plate_mass_g(model)
        return (
            Parameter("mass_g", 0.05 * plate_mass_g, 0.1 * plate_mass_g, 0.0, plate_mass_g),
            Parameter("x_mm", a_mm / 2, a_mm / np.sqrt(12), 0.0, a_mm),
            Parameter("y_mm", b_mm / 2, b_mm / np.sqrt(12), 0.0, b_mm),
        )

    def apply(self, model, theta):
        """The plate with the mass added; ``theta = (mass_g, x_mm, y_mm)``."""
        mass_g, x_mm, y_mm = theta
        point = np.array([[1e-3 * x_mm, 1e-3 * y_mm]])
        element, local = model.mesh.locate(point)
        n_w = model.element.fields(local)["w"][0]
        added = model.assembler.element_data(element, 1e-3 * mass_g * np.outer(n_w, n_w)[None])
        return model.modified(mass_data=model.mass_data + added)

    def ritz(self, model, b, basis, near=None):
        """Rank one: ``V^T M V + m u u^T`` with ``u`` the basis' ``w`` at ``(x, y)``.

        Its differences are exact: ``u u^T`` in the mass, ``m (u' u^T + u u'^T)`` in a
        coordinate with ``u'`` the basis' slope of ``w`` there.
        """
        terms, constant, mass = project(model, basis)
        return _rank_one(model, basis, terms, constant, mass, "mass")

    def image(self, model, theta, symmetry):
        """The same mass at the mirror position of ``(x, y)``."""
        return np.array([theta[0], *mirror_position(model, theta[1], theta[2], symmetry)])

    def location_map(self, model, paired, b, residual_whitened, sigma_lambda, projector):
        """A small mass at each node (:func:`point_mass_map`)."""
        return point_mass_map(model, paired, residual_whitened, sigma_lambda, projector)

    def scan(self, model, basis, b, Y, sigma, modes, projector):
        """Every ``scan_stride``-th node, masses ``scan_mass_fractions`` of the plate's."""
        masses_g = self.scan_mass_fractions * _plate_mass_g(model)
        return point_mass_scan(model, basis, Y, sigma, modes, projector, masses_g, self.scan_stride)


def point_mass_map(model, result, residual_whitened, sigma_lambda, projector):
    """Map of a small point mass at each node: ``d lambda_i / d m = -lambda_i w_i(x)^2``.

    Parameters are those of :meth:`.base.Physics.location_map` (``result``: the paired
    modes). The amplitude is the mass, kg.

    Returns
    -------
    LocationMap
        On the nodes, shape ``(ny + 1, nx + 1)``.
    """
    w = result.vectors[model.mesh.dofs("w")]  # (n_nodes, m)
    derivatives = -(result.eigenvalues[:, None] * (w.T**2))
    mesh = model.mesh
    return effect_map(
        derivatives,
        sigma_lambda,
        residual_whitened,
        projector,
        1e3 * mesh.nodes,
        (mesh.ny + 1, mesh.nx + 1),
    )


def point_mass_scan(model, basis, Y, sigma, modes, projector, masses_g, stride=2):
    """Scan a point mass over the nodes (every ``stride``-th each way) and ``masses_g``.

    In the Ritz basis: ``Lambda q = lambda (I + m w_p w_p^T) q`` with ``w_p`` the basis'
    ``w`` at node ``p``.

    Parameters
    ----------
    model : PlateModel
    basis : RitzBasis
    Y, sigma : numpy.ndarray, shape (m,)
        Measured eigenvalues and their deviations (rad^2/s^2).
    modes : numpy.ndarray of int, shape (m,)
        0-based elastic modes paired with the measured ones.
    projector : numpy.ndarray, shape (m, m)
        Onto what the constants cannot absorb (:func:`.location.absorbable_projector`).
    masses_g : array_like
        Masses to try, g.
    stride : int

    Returns
    -------
    Scan
        ``theta = (mass_g, x_mm, y_mm)``.
    """
    mesh = model.mesh
    grid = np.arange(mesh.n_nodes).reshape(mesh.ny + 1, mesh.nx + 1)[::stride, ::stride]
    nodes = grid.ravel()
    w = basis.vectors[mesh.dofs("w", nodes)]  # (p, n)
    s = np.einsum("pn,pn->p", w, w)
    lam = basis.eigenvalues
    xy = 1e3 * mesh.nodes[nodes]
    thetas, chi2 = [], []
    for mass_g in np.asarray(masses_g, dtype=float):
        m = 1e-3 * mass_g
        # (I + m w w^T)^(-1/2) = I - c w w^T: the symmetric form of the pencil
        c = (1.0 - 1.0 / np.sqrt(1.0 + m * s)) / np.where(s > 0, s, 1.0)
        S = np.eye(lam.size) - c[:, None, None] * w[:, :, None] * w[:, None, :]
        A = (S * lam) @ S
        chi2.append(misfit(np.linalg.eigvalsh(A), basis, Y, sigma, modes, projector))
        thetas.append(np.column_stack([np.full(nodes.size, mass_g), xy]))
    return Scan(np.vstack(thetas), np.concatenate(chi2), (1, 2))


def _rank_one(model, basis, terms, constant, mass, where):
    """The Ritz form of ``c u u^T`` added at ``(x, y)`` to the mass or to the stiffness.

    ``theta = (size, x_mm, y_mm)``; ``c`` is ``1e-3 size`` (a mass in g) for ``where =
    "mass"`` and ``10**size`` (a spring's log10 k in N/m) for ``"stiffness"``. The
    position is held on the plate. The matrices' differences are the exact derivatives
    (``u`` and its slopes from the element's Hermite functions), so a difference costs one
    evaluation of ``w`` and its slopes at the point.
    """
    a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
    zero_terms, zero = np.zeros_like(terms), np.zeros_like(mass)

    def point(theta):
        return 1e-3 * np.array([[np.clip(theta[1], 0.0, a_mm), np.clip(theta[2], 0.0, b_mm)]])

    def scale(size):
        return 1e-3 * size if where == "mass" else 10.0**size

    def added(rank_one):
        if where == "mass":
            return terms, constant, mass + rank_one
        return terms, constant + rank_one, mass

    last = {}

    def values(theta):  # w and its slopes (per mm) at the point, each (1, r); the last kept
        p = point(theta)
        if last.get("point") is None or not np.array_equal(last["point"], p):
            w, wx, wy = model.point_values(p, basis, ("w", "w_x", "w_y"))
            last.update(point=p, values=(w, 1e-3 * wx, 1e-3 * wy))
        return last["values"]

    def matrices(theta):
        u = values(theta)[0]
        return added(scale(theta[0]) * (u.T @ u))

    def difference(theta, i, h):
        u = values(theta)[0]
        if i == 0:
            slope = 1e-3 if where == "mass" else np.log(10.0) * scale(theta[0])
            d = slope * (u.T @ u)
        else:
            du = values(theta)[i]
            d = scale(theta[0]) * (du.T @ u + u.T @ du)
        return (zero_terms, zero, d) if where == "mass" else (zero_terms, d, zero)

    matrices.difference = difference
    return matrices
