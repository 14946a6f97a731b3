"""A circular through-hole: mass and stiffness removed over a disc (a located candidate)."""

from __future__ import annotations

import numpy as np

from .base import Parameter, Physics, mirror_position
from .local_stiffness_loss import element_energies
from .location import effect_map
from .reduced_model import project
from .region_projection import RegionProjection
from .ritz_scan import Scan, misfit

__all__ = [
    "Cutout",
    "cutout_map",
    "cutout_scan",
    "disc_fractions",
    "discs_fractions",
    "material_removed",
]

#: Share of the material kept inside the hole (an "ersatz" material, as in topology
#: optimisation): a node whose every element lies in the hole keeps a regular, if light, row
#: in K and M. Mass and stiffness scale alike, so the ersatz material has no low modes of its
#: own (its modes are those of a patch the size of the hole, held by the plate around it).
RESIDUAL = 1e-4
#: Elements times centres of the discs of one call of :func:`discs_fractions` in the scan
#: (the size of the fractions it returns; what it computes is the windows' share of that).
_SCAN_CHUNK = 2**18


def _chord_integral(u, v, r):
    """``int_u^v sqrt(r^2 - x^2) dx`` with ``u, v`` clipped to ``[-r, r]``; 0 if ``v < u``."""

    def primitive(x):
        x = np.clip(x, -r, r)
        return 0.5 * (x * np.sqrt(np.maximum(r * r - x * x, 0.0)) + r * r * np.arcsin(x / r))

    return np.maximum(primitive(v) - primitive(np.maximum(u, -r)), 0.0) * (v > u)


def _quadrant_area(X, Y, r):
    """Area of the disc of radius ``r`` at the origin inside ``{x <= X, y <= Y}``.

    The vertical chord at ``x`` runs over ``[-s, s]``, ``s = sqrt(r^2 - x^2)``; its length
    below ``Y`` is ``2 s`` where ``s <= Y`` (only for ``Y >= 0``, at ``|x| >= x_c``,
    ``x_c = sqrt(r^2 - Y^2)``), ``Y + s`` for ``|x| < x_c``, and 0 elsewhere.
    """
    Xc = np.clip(X, -r, r)
    Yc = np.clip(Y, -r, r)
    xc = np.sqrt(np.maximum(r * r - Yc * Yc, 0.0))
    top = np.minimum(Xc, xc)
    inner = Yc * np.maximum(top + xc, 0.0) + _chord_integral(-xc, top, r)
    outer = 2.0 * (_chord_integral(-r, np.minimum(Xc, -xc), r) + _chord_integral(xc, Xc, r))
    return inner + np.where(Y >= 0.0, outer, 0.0)


def disc_fractions(mesh, centre, diameter):
    """Fraction of each element's area inside a disc, exact (closed form).

    Parameters
    ----------
    mesh : RectangularMesh
    centre : array_like, shape (2,)
        Disc centre, m.
    diameter : float
        m.

    Returns
    -------
    numpy.ndarray, shape (n_elements,)
        In [0, 1]; ``sum(frac) dx dy`` is the disc's area inside the plate.
    """
    return discs_fractions(mesh, np.asarray(centre, dtype=float)[None], diameter)[0]


def discs_fractions(mesh, centres, diameter):
    """:func:`disc_fractions` of discs of one diameter at several centres at once.

    Each disc is integrated over the window of elements around its bounding square only
    (elements beyond it get exactly 0 from the closed form too), with the same arithmetic
    element by element: the same numbers to the last bit, without a loop over the centres.

    Parameters
    ----------
    mesh : RectangularMesh
    centres : numpy.ndarray, shape (c, 2)
        Disc centres, m.
    diameter : float
        m.

    Returns
    -------
    numpy.ndarray, shape (c, n_elements)
    """
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    out = np.zeros((len(centres), mesh.n_elements))
    r = 0.5 * float(diameter)
    if r <= 0.0:
        return out
    # element (i, j) (column i, row j) is number j nx + i, its centre ((i + 1/2) dx, (j + 1/2) dy)
    nx, ny = mesh.nx, mesh.ny
    wx = min(nx, int(np.ceil(2.0 * r / mesh.dx)) + 2)
    wy = min(ny, int(np.ceil(2.0 * r / mesh.dy)) + 2)
    i0 = np.clip(np.floor((centres[:, 0] - r) / mesh.dx).astype(int), 0, nx - wx)
    j0 = np.clip(np.floor((centres[:, 1] - r) / mesh.dy).astype(int), 0, ny - wy)
    window = (
        (j0[:, None, None] + np.arange(wy)[:, None]) * nx + i0[:, None, None] + np.arange(wx)
    ).reshape(len(centres), -1)
    size = np.array([mesh.dx, mesh.dy])
    lo = (mesh.centroids - size / 2)[window] - centres[:, None]  # (c, wy wx, 2)
    hi = lo + size
    (x0, y0), (x1, y1) = np.moveaxis(lo, -1, 0), np.moveaxis(hi, -1, 0)
    # the four corners' quadrants in one call (a few dozen array operations, not four times)
    q = _quadrant_area(np.stack([x1, x0, x1, x0]), np.stack([y1, y1, y0, y0]), r)
    area = q[0] - q[1] - q[2] + q[3]
    np.put_along_axis(out, window, np.clip(area / (mesh.dx * mesh.dy), 0.0, 1.0), axis=1)
    return out


def material_removed(model, frac):
    """``model`` with each element's stiffness and mass less the share ``frac`` of it.

    ``K_j -> K_j - sum_e f_e K_j^e``, ``M -> M - sum_e f_e M^e`` over the elements with
    ``f_e > 0``; ``model`` itself when there are none.
    """
    inside = np.flatnonzero(frac > 0)
    if inside.size == 0:
        return model
    f = frac[inside, None, None]
    removed = [
        model.assembler.element_data(inside, f * Ke[None]) for Ke in model.element_stiffness_terms()
    ]
    mass = model.assembler.element_data(inside, f * model.element_mass()[None])
    return model.modified(
        stiffness_terms=model.stiffness_terms - np.array(removed),
        mass_data=model.mass_data - mass,
    )


def _largest_mm(model):
    """The largest admissible diameter: a third of the plate's shorter side, mm."""
    return 1e3 * min(model.mesh.a, model.mesh.b) / 3.0


class Cutout(Physics):
    """``K_j -> K_j - sum_e f_e K_j^e``, ``M -> M - sum_e f_e M^e``: a hole of diameter d.

    ``f_e`` is the share of element ``e``'s area inside the disc (:func:`disc_fractions`,
    exact), times ``1 - RESIDUAL``: every stiffness term and the inertia go in proportion,
    so the removed mass is ``rho h pi d^2 / 4`` and the frequencies vary smoothly with the
    hole's place and size. The hole is smeared over the elements it cuts: the stress
    concentration at its rim is not resolved (a hole much smaller than the wavelengths
    changes the frequencies mainly through the mass and stiffness it removes).

    The disc stays inside the plate: the diameter is at most a third of the shorter side
    and the centre at least half that from every edge.

    Attributes
    ----------
    scan_diameters : tuple of float
        Diameters the scan tries, as fractions of the largest admissible one.
    scan_stride : int
        The scan tries every ``scan_stride``-th element centre each way.
    """

    name = "cutout"
    description = "a circular through-hole of diameter d at (x, y)"
    scan_diameters = (0.25, 0.5, 0.75, 1.0)
    scan_stride = 2

    def parameters(self, model, b):
        """``x_mm``, ``y_mm``, ``diameter_mm``.

        Position with the mean and deviation of a uniform position over the plate, within
        half the largest diameter of the edges; diameter ``D/4 +- D/4`` in ``[0, D]``, with
        ``D`` a third of the shorter side.
        """
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        big = _largest_mm(model)
        return (
            Parameter("x_mm", a_mm / 2, a_mm / np.sqrt(12), big / 2, a_mm - big / 2),
            Parameter("y_mm", b_mm / 2, b_mm / np.sqrt(12), big / 2, b_mm - big / 2),
            Parameter("diameter_mm", big / 4, big / 4, 0.0, big),
        )

    def _disc(self, model, theta):
        """Each element's share of area inside the hole."""
        x_mm, y_mm, d_mm = theta
        return disc_fractions(model.mesh, 1e-3 * np.array([x_mm, y_mm]), 1e-3 * abs(d_mm))

    def _fractions(self, model, theta):
        """Each element's share of stiffness and mass removed."""
        return (1.0 - RESIDUAL) * self._disc(model, theta)

    def apply(self, model, theta):
        """The plate with the hole; ``theta = (x_mm, y_mm, diameter_mm)``."""
        return material_removed(model, self._fractions(model, theta))

    def ritz(self, model, b, basis, near=None):
        """``V^T K_j V - sum_e f_e V_e^T K_j^e V_e`` (and the same for M), cut elements only.

        A difference in the place or the diameter visits only the elements along the rim; the
        sum of those wholly inside is kept while they stay the same
        (:meth:`~.region_projection.RegionProjection.inside`).
        """
        terms, constant, mass = project(model, basis)
        element = np.concatenate([model.element_stiffness_terms(), model.element_mass()[None]])
        region = RegionProjection(model, basis, element)

        def matrices(theta):
            removed = (1.0 - RESIDUAL) * region.inside(self._disc(model, theta))
            return terms - removed[:6], constant, mass - removed[6]

        def difference(theta, i, h):
            up, down = np.array(theta, dtype=float), np.array(theta, dtype=float)
            up[i] += h
            down[i] -= h
            rim = (self._fractions(model, up) - self._fractions(model, down)) / (2 * h)
            removed = region(rim)
            return -removed[:6], np.zeros_like(constant), -removed[6]

        matrices.difference = difference
        return matrices

    def image(self, model, theta, symmetry):
        """The same hole about the mirror position of its centre."""
        return np.array([*mirror_position(model, theta[0], theta[1], symmetry), theta[2]])

    def location_map(self, model, paired, b, residual_whitened, sigma_lambda, projector):
        """A small hole in each element (:func:`cutout_map`)."""
        return cutout_map(model, paired, b, residual_whitened, sigma_lambda, projector)

    def scan(self, model, basis, b, Y, sigma, modes, projector):
        """Every ``scan_stride``-th element centre, diameters ``scan_diameters``."""
        diameters = _largest_mm(model) * np.asarray(self.scan_diameters)
        return cutout_scan(model, basis, b, Y, sigma, modes, projector, diameters, self.scan_stride)


def _mass_energies(model, paired):
    """``a_i^T M^e a_i`` of each paired mode in each element, shape (m, n_elements)."""
    q = paired.vectors[model.mesh.element_dofs]  # (n_el, 32, m)
    return np.einsum("eai,ab,ebi->ie", q, model.element_mass(), q)


def cutout_map(model, result, b, residual_whitened, sigma_lambda, projector):
    """Map of removing a small share of the material of each element.

    Column ``e``: ``d lambda_i / d f_e = -(a_i^T K^e a_i - lambda_i a_i^T M^e a_i)``
    (Rayleigh quotient, mass-normalised modes) for removing a share ``f_e`` of element
    ``e``'s stiffness and mass.

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

    Returns
    -------
    LocationMap
        On the element centres, shape ``(ny, nx)``; the amplitude is the share removed.
    """
    stiffness = element_energies(model, result, np.asarray(b, dtype=float))
    kinetic = result.eigenvalues[:, None] * _mass_energies(model, result)
    mesh = model.mesh
    return effect_map(
        kinetic - stiffness,
        sigma_lambda,
        residual_whitened,
        projector,
        1e3 * mesh.centroids,
        (mesh.ny, mesh.nx),
    )


def cutout_scan(model, basis, b, Y, sigma, modes, projector, diameters_mm, stride=2):
    """Scan a hole over element centres (every ``stride``-th each way) and ``diameters_mm``.

    In the Ritz basis: ``(Lambda - Phi^T K_f Phi) q = lambda (I - Phi^T M_f Phi) q`` with
    ``K_f, M_f`` the removed share of each element's matrices (exact disc fractions).

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
    diameters_mm : array_like
    stride : int

    Returns
    -------
    Scan
        ``theta = (x_mm, y_mm, diameter_mm)``.
    """
    mesh = model.mesh
    Ke = np.einsum("j,jab->ab", np.asarray(b, dtype=float), model.element_stiffness_terms())
    q = basis.vectors[mesh.element_dofs]  # (n_el, 32, n)
    n = basis.eigenvalues.size
    red_k = (q.transpose(0, 2, 1) @ (Ke @ q)).reshape(mesh.n_elements, -1)
    red_m = (q.transpose(0, 2, 1) @ (model.element_mass() @ q)).reshape(mesh.n_elements, -1)
    grid = np.arange(mesh.n_elements).reshape(mesh.ny, mesh.nx)[::stride, ::stride].ravel()
    centres = mesh.centroids[grid]
    chunks = max(1, len(centres) * mesh.n_elements // _SCAN_CHUNK)
    thetas, chi2 = [], []
    for d_mm in np.asarray(diameters_mm, dtype=float):
        F = (1.0 - RESIDUAL) * np.vstack(
            [discs_fractions(mesh, chunk, 1e-3 * d_mm) for chunk in np.array_split(centres, chunks)]
        )
        A = np.diag(basis.eigenvalues) - (F @ red_k).reshape(-1, n, n)
        B = np.eye(n) - (F @ red_m).reshape(-1, n, n)
        Linv = np.linalg.inv(np.linalg.cholesky(0.5 * (B + B.transpose(0, 2, 1))))
        C = Linv @ A @ Linv.transpose(0, 2, 1)
        values = np.linalg.eigvalsh(0.5 * (C + C.transpose(0, 2, 1)))
        chi2.append(misfit(values, basis, Y, sigma, modes, projector))
        thetas.append(np.column_stack([1e3 * centres, np.full(len(grid), d_mm)]))
    return Scan(np.vstack(thetas), np.concatenate(chi2), (0, 1))
