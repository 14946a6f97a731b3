"""A rectangular region that lost stiffness (impact damage, porosity, a dry patch): located."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics, mirror_position
from .location import effect_map
from .reduced_model import project
from .region_projection import RegionProjection
from .ritz_scan import Scan, misfit

__all__ = [
    "LocalStiffnessLoss",
    "area_fractions",
    "element_energies",
    "stiffness_loss_map",
    "stiffness_loss_scan",
]

#: Which of ``(C11, C22, C12, C66, C44, C55)`` a local stiffness loss keeps (1) rather than
#: multiplies by its factor (0): the factor takes the matrix-dominated C22, C12, C66, C44, C55.
_KEPT = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def area_fractions(mesh, centre, size):
    """Fraction of each element's area inside an axis-aligned rectangle.

    Parameters
    ----------
    mesh : RectangularMesh
    centre, size : array_like, shape (2,)
        Rectangle centre and sides in m.

    Returns
    -------
    numpy.ndarray, shape (n_elements,)
    """
    lo = np.asarray(centre) - np.asarray(size) / 2
    hi = np.asarray(centre) + np.asarray(size) / 2
    half = np.array([mesh.dx, mesh.dy]) / 2
    overlap = np.clip(
        np.minimum(mesh.centroids + half, hi) - np.maximum(mesh.centroids - half, lo), 0.0, None
    )
    return overlap[:, 0] * overlap[:, 1] / (mesh.dx * mesh.dy)


class LocalStiffnessLoss(Physics):
    """Inside a rectangle, ``C22, C12, C66, C44, C55`` are multiplied by ``factor``.

    That keeps ``factor`` of E2, G12, G13 and G23 with nu12 unchanged; E1 rises by less than
    ``nu12 nu21 (1 - factor)`` (a fraction of a percent for carbon/epoxy). Elements cut by
    the rectangle's edge take the factor in proportion to the area inside, so the
    frequencies vary smoothly with position and size. Kept linear in the lamina
    coefficients: ``K_j -> K_j + (d_j - 1) sum_e frac_e K_j^e``.

    A subclass changes which coefficients the factor multiplies through :attr:`kept` (and
    its priors and scan grid); everything else is shared (:mod:`.delamination`).

    Attributes
    ----------
    kept : numpy.ndarray, shape (6,)
        1 for the coefficients of ``(C11, C22, C12, C66, C44, C55)`` left as they are, 0 for
        those the factor multiplies (here all but C11).
    scan_sizes : tuple of (float, float)
        Patch sides the scan tries, as fractions of the plate's sides ``(a, b)``.
    scan_factors : tuple of float
        Fractions of the multiplied coefficients kept that the scan tries.
    scan_stride : int
        The scan tries every ``scan_stride``-th element centre each way.
    """

    name = "local_stiffness_loss"
    description = "a rectangular region keeping a fraction of E2, G12, G13, G23"
    kept = _KEPT
    scan_sizes = ((0.1, 0.1), (0.2, 0.2), (0.4, 0.4), (0.2, 0.4), (0.4, 0.2))
    scan_factors = (0.2, 0.4, 0.6, 0.8, 0.9)
    scan_stride = 2

    def parameters(self, model, b):
        """Centre ``x_mm``, ``y_mm``; sides ``dx_mm``, ``dy_mm``; ``factor`` kept in (0, 1]."""
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        return (
            Parameter("x_mm", a_mm / 2, a_mm / np.sqrt(12), 0.0, a_mm),
            Parameter("y_mm", b_mm / 2, b_mm / np.sqrt(12), 0.0, b_mm),
            Parameter("dx_mm", a_mm / 5, a_mm / 10, 1e3 * model.mesh.dx, a_mm),
            Parameter("dy_mm", b_mm / 5, b_mm / 10, 1e3 * model.mesh.dy, b_mm),
            Parameter("factor", 0.7, 0.3, 0.02, 1.0),
        )

    def apply(self, model, theta):
        """The damaged plate; ``theta = (x_mm, y_mm, dx_mm, dy_mm, factor)``."""
        x, y, dx, dy, factor = theta
        frac = area_fractions(model.mesh, 1e-3 * np.array([x, y]), 1e-3 * np.array([dx, dy]))
        inside = np.flatnonzero(frac > 0)
        if inside.size == 0:
            return model
        kept = np.asarray(self.kept, dtype=float)
        multiplier = kept + (1.0 - kept) * factor
        terms = model.element_stiffness_terms()
        region = [
            model.assembler.element_data(inside, frac[inside, None, None] * Ke[None])
            for Ke in terms
        ]
        new = model.stiffness_terms + (multiplier - 1.0)[:, None] * np.array(region)
        return model.modified(stiffness_terms=new)

    def ritz(self, model, b, basis, near=None):
        """``V^T K_j V + (d_j - 1) sum_e frac_e V_e^T K_j^e V_e`` over the cut elements.

        Every element of the plate has the same matrices ``K_j^e``; only the elements the
        rectangle touches are projected at each evaluation (the sum of those wholly inside
        kept while they stay the same: :meth:`~.region_projection.RegionProjection.inside`), and a
        difference in a place or a side only the elements along the edges that moved.
        """
        terms, constant, mass = project(model, basis)
        lost = np.flatnonzero(np.asarray(self.kept, dtype=float) == 0.0)
        region = RegionProjection(model, basis, model.element_stiffness_terms()[lost])
        zero = np.zeros_like(constant)

        def fractions(theta):
            x, y, dx, dy, _ = theta
            return area_fractions(
                model.mesh, 1e-3 * np.array([x, y]), 1e-3 * np.abs(np.array([dx, dy]))
            )

        def matrices(theta):
            out = terms.copy()
            out[lost] += (theta[4] - 1.0) * region.inside(fractions(theta))
            return out, constant, mass

        def difference(theta, i, h):
            out = np.zeros_like(terms)
            if i == 4:  # linear in the factor (the region's sum at theta kept by ``inside``)
                out[lost] = region.inside(fractions(theta))
            else:
                up, down = np.array(theta, dtype=float), np.array(theta, dtype=float)
                up[i] += h
                down[i] -= h
                edge = (fractions(up) - fractions(down)) / (2 * h)
                out[lost] = (theta[4] - 1.0) * region(edge)
            return out, zero, zero

        matrices.difference = difference
        return matrices

    def image(self, model, theta, symmetry):
        """The same patch about the mirror position of its centre."""
        return np.array([*mirror_position(model, theta[0], theta[1], symmetry), *theta[2:]])

    def location_map(self, model, paired, b, residual_whitened, sigma_lambda, projector):
        """A small loss at each element (:func:`stiffness_loss_map`)."""
        return stiffness_loss_map(
            model, paired, b, residual_whitened, sigma_lambda, projector, kept=self.kept
        )

    def scan(self, model, basis, b, Y, sigma, modes, projector):
        """Every ``scan_stride``-th element centre, ``scan_sizes`` and ``scan_factors``."""
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        sizes = [(a_mm * sx, b_mm * sy) for sx, sy in self.scan_sizes]
        return stiffness_loss_scan(
            model,
            basis,
            b,
            Y,
            sigma,
            modes,
            projector,
            sizes,
            self.scan_factors,
            self.scan_stride,
            kept=self.kept,
        )


def element_energies(model, paired, weights):
    """Strain energy of each paired mode in each element, for weighted coefficients.

    Parameters
    ----------
    model : PlateModel
    paired : ModalResult
        ``vectors`` shape (n_dofs, m).
    weights : array_like, shape (6,)
        Multiplies the element stiffness of each lamina coefficient (Pa).

    Returns
    -------
    numpy.ndarray, shape (m, n_elements)
        ``a_i^T K^e a_i`` (twice the strain energy), rad^2/s^2 for M-normalised modes.
    """
    Ke = np.einsum("j,jab->ab", weights, model.element_stiffness_terms())
    q = paired.vectors[model.mesh.element_dofs]  # (n_el, 32, m)
    return np.einsum("eai,ab,ebi->ie", q, Ke, q)


def stiffness_loss_map(model, result, b, residual_whitened, sigma_lambda, projector, kept=_KEPT):
    """Map of a local loss of stiffness at each element.

    Column ``e``: ``d lambda_i / d alpha_e = -a_i^T K_loss^e a_i`` for losing a fraction
    ``alpha`` of the coefficients ``kept`` does not keep (by default the matrix-dominated
    ``C22, C12, C66, C44, C55``) in element ``e``.

    Parameters
    ----------
    model : PlateModel
    result : ModalResult
        Paired modes (columns of ``result.vectors`` in measured order).
    b : array_like, shape (6,)
        Stiffness coefficients of the nominal fit, Pa.
    residual_whitened : numpy.ndarray, shape (m,)
    sigma_lambda : numpy.ndarray, shape (m,)
    projector : numpy.ndarray, shape (m, m)
    kept : array_like, shape (6,)
        1 for the coefficients the loss leaves, 0 for those it takes
        (:attr:`LocalStiffnessLoss.kept`).

    Returns
    -------
    LocationMap
        On the element centres, shape ``(ny, nx)``.
    """
    weights = np.asarray(b, dtype=float) * (1.0 - np.asarray(kept, dtype=float))
    energy = element_energies(model, result, weights)
    mesh = model.mesh
    return effect_map(
        -energy,
        sigma_lambda,
        residual_whitened,
        projector,
        1e3 * mesh.centroids,
        (mesh.ny, mesh.nx),
    )


def stiffness_loss_scan(
    model, basis, b, Y, sigma, modes, projector, sizes_mm, factors, stride=2, kept=_KEPT
):
    """Scan a patch that lost stiffness over centres, sizes and factors.

    In the Ritz basis: ``(Lambda - (1 - factor) Phi^T K_loss Phi) q = lambda q``. The patch
    is made of whole elements (those whose centre lies inside); centres are element centres
    (every ``stride``-th each way). A factor above 1 is a stiffer patch.

    Parameters
    ----------
    model : PlateModel
    basis : RitzBasis
    b : array_like, shape (6,)
        Nominal stiffness coefficients, Pa.
    Y, sigma : numpy.ndarray, shape (m,)
        Measured eigenvalues and their deviations (rad^2/s^2).
    modes : numpy.ndarray of int, shape (m,)
        0-based elastic modes paired with the measured ones.
    projector : numpy.ndarray, shape (m, m)
        Onto what the constants cannot absorb (:func:`.location.absorbable_projector`).
    sizes_mm : sequence of (dx_mm, dy_mm)
    factors : array_like
        Fractions of the coefficients ``kept`` does not keep (by default ``C22, C12, C66,
        C44, C55``) left inside.
    stride : int
    kept : array_like, shape (6,)
        1 for the coefficients the loss leaves, 0 for those it takes.

    Returns
    -------
    Scan
        ``theta = (x_mm, y_mm, dx_mm, dy_mm, factor)``.
    """
    mesh = model.mesh
    lost = np.asarray(b) * (1.0 - np.asarray(kept, dtype=float))
    Ke = np.einsum("j,jab->ab", lost, model.element_stiffness_terms())
    q = basis.vectors[mesh.element_dofs]  # (n_el, 32, n)
    reduced = q.transpose(0, 2, 1) @ (Ke @ q)
    ix = np.floor(mesh.centroids[:, 0] / mesh.dx).astype(int)
    iy = np.floor(mesh.centroids[:, 1] / mesh.dy).astype(int)
    n = basis.eigenvalues.size
    table = np.zeros((mesh.ny + 1, mesh.nx + 1, n, n))  # summed-area table of the elements
    table[iy + 1, ix + 1] = reduced
    table = table.cumsum(axis=0).cumsum(axis=1)
    cy, cx = np.meshgrid(
        np.arange(0, mesh.ny, stride), np.arange(0, mesh.nx, stride), indexing="ij"
    )
    cx, cy = cx.ravel(), cy.ravel()
    thetas, chi2 = [], []
    for dx_mm, dy_mm in sizes_mm:
        # elements either side of the centre one: the patch spans 2 h + 1 elements
        hx = max(int(np.floor((1e-3 * dx_mm / mesh.dx - 1) / 2 + 0.5)), 0)
        hy = max(int(np.floor((1e-3 * dy_mm / mesh.dy - 1) / 2 + 0.5)), 0)
        x0, x1 = np.clip(cx - hx, 0, mesh.nx), np.clip(cx + hx + 1, 0, mesh.nx)
        y0, y1 = np.clip(cy - hy, 0, mesh.ny), np.clip(cy + hy + 1, 0, mesh.ny)
        patch = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]
        size = 1e3 * np.column_stack([(x1 - x0) * mesh.dx, (y1 - y0) * mesh.dy])
        centre = 1e3 * np.column_stack([(x0 + x1) * mesh.dx, (y0 + y1) * mesh.dy]) / 2
        for factor in np.asarray(factors, dtype=float):
            A = np.diag(basis.eigenvalues) - (1.0 - factor) * patch
            chi2.append(misfit(np.linalg.eigvalsh(A), basis, Y, sigma, modes, projector))
            thetas.append(np.column_stack([centre, size, np.full(cx.size, factor)]))
    return Scan(np.vstack(thetas), np.concatenate(chi2), (0, 1))
