"""A support or suspension that is too stiff: a transverse spring at a point (located)."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics, mirror_position
from .location import effect_map
from .point_mass import _rank_one
from .reduced_model import RIGID_SHARE, project
from .ritz_scan import Scan

__all__ = ["PointSupport", "point_support_map", "point_support_scan", "reference_stiffness"]


def reference_stiffness(model, b):
    """The spring that lifts a mode by about its own eigenvalue: ``lambda_1 m_plate``, N/m.

    ``lambda_1`` is the Rayleigh bound of the lowest eigenvalue
    (:meth:`~bayesplate.plate.model.PlateModel.lowest_eigenvalue_bound`), ``m_plate`` the
    plate's mass.
    A spring ``k`` at ``(x, y)`` lifts mode ``i`` by ``k w_i(x, y)^2`` to first order, and
    ``w_i^2`` of a mass-normalised mode is of order ``1 / m_plate``.
    """
    lowest = model.lowest_eigenvalue_bound(b)
    return lowest * model.density * model.thickness * model.mesh.a * model.mesh.b


def _spring(model, k, x_mm, y_mm):
    """CSR data of ``k N_w^T N_w`` at ``(x, y)``, shape (nnz,)."""
    element, local = model.mesh.locate(np.array([[1e-3 * x_mm, 1e-3 * y_mm]]))
    n_w = model.element.fields(local)["w"][0]
    return model.assembler.element_data(element, k * np.outer(n_w, n_w)[None])


class PointSupport(Physics):
    """``K + k N_w(x, y)^T N_w(x, y)``: a transverse spring of stiffness ``k`` at ``(x, y)``.

    The spring holds the mid-plane deflection ``w`` only (no rotation, no in-plane
    motion), independent of the elastic constants (a ``K_0`` like the foundation's). It
    lifts the bouncing rigid-body motion off zero; the eigen solver still recognises it by
    its shape while it stays mostly rigid, and drops it like the free plate's. A spring
    stiff enough to lift it among the lowest elastic modes mixes it with them (an avoided
    crossing); a mode more than half rigid-body motion is then dropped, the package's one
    rule (the full solve, the Ritz pencil and the scan apply it alike).

    The stiffness is fitted as ``log10_k_N_m`` (the issue's ``k_N_m``, on a log scale):
    the frequencies change with ``k`` over many decades (from no effect, through
    ``Delta lambda_i = k w_i^2``, to a plate pinned at the point, where they saturate),
    so a Gaussian prior over decades is the honest ignorance, a fit is well posed at
    either end (the likelihood goes flat and the prior holds the parameter), and ``k``
    stays positive without a bound at the edge of the prior. ``k = 0`` (the nominal plate)
    is ``log10_k_N_m = -inf``, outside the bounds but accepted by :meth:`apply`.

    Attributes
    ----------
    scan_stiffness : numpy.ndarray
        Springs the scan tries, as multiples of :func:`reference_stiffness`.
    scan_stride : int
        The scan tries every ``scan_stride``-th node each way.
    """

    name = "point_support"
    description = "a transverse spring (a support too stiff) at (x, y)"
    scan_stiffness = np.geomspace(1e-4, 10.0, 11)
    scan_stride = 2

    def parameters(self, model, b):
        """``log10_k_N_m``, ``x_mm``, ``y_mm``.

        ``log10 k``: ``log10(k_ref) - 2 +- 1.5`` within ``log10(k_ref) + [-6, 2]``, with
        ``k_ref`` from :func:`reference_stiffness` (about 1 % of the lowest eigenvalue at the
        prior mean; from no visible effect to a pinned point within the bounds). Position
        with the mean and deviation of a uniform position over the plate.
        """
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        ref = np.log10(reference_stiffness(model, b))
        return (
            Parameter("log10_k_N_m", ref - 2.0, 1.5, ref - 6.0, ref + 2.0),
            Parameter("x_mm", a_mm / 2, a_mm / np.sqrt(12), 0.0, a_mm),
            Parameter("y_mm", b_mm / 2, b_mm / np.sqrt(12), 0.0, b_mm),
        )

    def apply(self, model, theta):
        """The plate on the spring; ``theta = (log10_k_N_m, x_mm, y_mm)``."""
        log_k, x_mm, y_mm = theta
        extra = _spring(model, 10.0**log_k, x_mm, y_mm)
        if model.extra_stiffness_data is not None:
            extra = extra + model.extra_stiffness_data
        return model.modified(extra_stiffness_data=extra)

    def ritz(self, model, b, basis, near=None):
        """Rank one: ``V^T K_0 V + k u u^T`` with ``u`` the basis' ``w`` at ``(x, y)``.

        With exact differences (:func:`.point_mass._rank_one`).
        """
        terms, constant, mass = project(model, basis)
        return _rank_one(model, basis, terms, constant, mass, "stiffness")

    def image(self, model, theta, symmetry):
        """The same support at the mirror position of ``(x, y)``."""
        return np.array([theta[0], *mirror_position(model, theta[1], theta[2], symmetry)])

    def location_map(self, model, paired, b, residual_whitened, sigma_lambda, projector):
        """A weak spring at each node (:func:`point_support_map`)."""
        return point_support_map(model, paired, residual_whitened, sigma_lambda, projector)

    def scan(self, model, basis, b, Y, sigma, modes, projector):
        """Every ``scan_stride``-th node, springs ``scan_stiffness`` times ``k_ref``."""
        springs = self.scan_stiffness * reference_stiffness(model, b)
        return point_support_scan(
            model, basis, Y, sigma, modes, projector, springs, self.scan_stride
        )


def point_support_map(model, result, residual_whitened, sigma_lambda, projector):
    """Map of a weak spring at each node: ``d lambda_i / d k = w_i(x)^2`` (Rayleigh).

    Parameters are those of :meth:`.base.Physics.location_map` (``result``: the paired
    modes). The amplitude is the spring, N/m.

    Returns
    -------
    LocationMap
        On the nodes, shape ``(ny + 1, nx + 1)``.
    """
    w = result.vectors[model.mesh.dofs("w")]  # (n_nodes, m)
    mesh = model.mesh
    return effect_map(
        w.T**2,
        sigma_lambda,
        residual_whitened,
        projector,
        1e3 * mesh.nodes,
        (mesh.ny + 1, mesh.nx + 1),
    )


def point_support_scan(model, basis, Y, sigma, modes, projector, springs_N_m, stride=2):
    """Scan a spring over the nodes (every ``stride``-th each way) and ``springs_N_m``.

    In the Ritz basis: ``(Lambda + k w_p w_p^T) q = lambda q`` with ``w_p`` the basis' ``w``
    at node ``p``. The bouncing motion the spring lifts is told from the elastic modes by
    its share on the rigid-body motions (as :mod:`.reduced_model` does), so a stiff spring whose
    bouncing mode rises among the elastic ones is scanned right.

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
    springs_N_m : array_like
        Springs to try, N/m.
    stride : int

    Returns
    -------
    Scan
        ``theta = (log10_k_N_m, x_mm, y_mm)``.
    """
    mesh = model.mesh
    grid = np.arange(mesh.n_nodes).reshape(mesh.ny + 1, mesh.nx + 1)[::stride, ::stride]
    nodes = grid.ravel()
    w = basis.vectors[mesh.dofs("w", nodes)]  # (p, n)
    xy = 1e3 * mesh.nodes[nodes]
    thetas, chi2 = [], []
    for k in np.asarray(springs_N_m, dtype=float):
        A = np.diag(basis.eigenvalues) + k * w[:, :, None] * w[:, None, :]
        values, vectors = np.linalg.eigh(A)
        rigid = np.sum(vectors[:, : basis.n_rigid] ** 2, axis=1) > RIGID_SHARE
        chi2.append(_elastic_misfit(values, rigid, Y, sigma, modes, projector))
        thetas.append(np.column_stack([np.full(nodes.size, np.log10(k)), xy]))
    return Scan(np.vstack(thetas), np.concatenate(chi2), (1, 2))


def _elastic_misfit(values, rigid, Y, sigma, modes, projector):
    """Projected chi-square of the elastic eigenvalues (ascending ``values``, ``rigid`` out).

    Inf where fewer elastic modes than the highest paired one remain.
    """
    elastic = np.where(rigid, np.inf, values)
    elastic = np.sort(elastic, axis=-1)
    n_elastic = np.sum(~rigid, axis=-1)
    picked = elastic[:, modes]
    with np.errstate(invalid="ignore"):
        r = ((Y - picked) / sigma) @ projector.T
        out = np.einsum("pi,pi->p", r, r)
    return np.where(n_elastic > modes.max(), out, np.inf)
