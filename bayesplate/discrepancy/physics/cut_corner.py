"""A cut corner: the triangle cut off by a straight line across a corner of the plate."""

from __future__ import annotations

import numpy as np

from ...fem.mesh import DOF_NAMES, DOFS_PER_NODE
from .base import Parameter, Physics
from .cutout import RESIDUAL, material_removed
from .reduced_model import project
from .region_projection import RegionProjection

__all__ = ["CORNERS", "CutCorner", "half_plane_area", "triangle_fractions"]

#: The four corners: ``"00"`` is ``(0, 0)``, ``"a0"`` is ``(a, 0)``, ``"0b"`` is ``(0, b)``,
#: ``"ab"`` is ``(a, b)``.
CORNERS = ("00", "a0", "0b", "ab")


def half_plane_area(x0, x1, y0, y1, p, q, c):
    """Area of the rectangle ``[x0, x1] x [y0, y1]`` inside ``p x + q y <= c`` (p, q > 0).

    The region ``{x >= u, y >= v, p x + q y <= c}`` is the triangle of area
    ``max(c - p u - q v, 0)^2 / (2 p q)``; the rectangle is four such regions by
    inclusion-exclusion, ``+`` at ``(x0, y0)`` and ``(x1, y1)``, ``-`` at the other two.
    Exact, and continuously differentiable in the line (the squares of ramps).
    """

    def corner(x, y):
        return np.maximum(c - p * x - q * y, 0.0) ** 2

    return (corner(x0, y0) + corner(x1, y1) - corner(x0, y1) - corner(x1, y0)) / (2.0 * p * q)


def _corner_frame(mesh, corner):
    """Each element's ``[x0, x1], [y0, y1]`` measured from ``corner`` inward, m."""
    half = np.array([mesh.dx, mesh.dy]) / 2
    lo, hi = mesh.centroids - half, mesh.centroids + half
    x0, x1 = (mesh.a - hi[:, 0], mesh.a - lo[:, 0]) if corner[0] == "a" else (lo[:, 0], hi[:, 0])
    y0, y1 = (mesh.b - hi[:, 1], mesh.b - lo[:, 1]) if corner[1] == "b" else (lo[:, 1], hi[:, 1])
    return np.maximum(x0, 0.0), x1, np.maximum(y0, 0.0), y1


def triangle_fractions(mesh, corner, leg_x, leg_y):
    """Fraction of each element's area inside the triangle cut off at ``corner``, exact.

    The triangle is ``{x'/leg_x + y'/leg_y < 1}`` in the corner's own coordinates (``x'``,
    ``y'`` >= 0 measured from the corner along the edges): the half-plane
    ``x'/leg_x + y'/leg_y <= 1`` inside the plate (:func:`half_plane_area`). Legs longer
    than the sides cut the plate where the line crosses it.

    Parameters
    ----------
    mesh : RectangularMesh
    corner : {"00", "a0", "0b", "ab"}
    leg_x, leg_y : float
        Legs along x and y, m; either <= 0: no cut.

    Returns
    -------
    numpy.ndarray, shape (n_elements,)
        In [0, 1]; ``sum(frac) dx dy`` is ``leg_x leg_y / 2`` while the legs are within
        the sides.
    """
    if corner not in CORNERS:
        raise ValueError(f"corner = {corner!r}: must be one of {CORNERS}")
    if leg_x <= 0.0 or leg_y <= 0.0:
        return np.zeros(mesh.n_elements)
    x0, x1, y0, y1 = _corner_frame(mesh, corner)
    area = half_plane_area(x0, x1, y0, y1, 1.0 / leg_x, 1.0 / leg_y, 1.0)
    return np.clip(area / (mesh.dx * mesh.dy), 0.0, 1.0)


def _region(model, basis):
    """:class:`~.region_projection.RegionProjection` of the element stiffness terms and mass.

    With the unknowns ``w_x``, ``w_y``, ``w_xy`` times ``dx``, ``dy``, ``dx dy`` (lengths,
    as ``w``): ``V^T A V = (T^-1 V)^T (T A T) (T^-1 V)`` for any diagonal ``T``. Unscaled,
    the element matrices' eigenvalues span so many decades that those it drops as round-off
    (below ``FACTOR_TOL`` of the largest) are not: on the derivative unknowns, whose rows of
    the basis are of order ``1 / dx`` and ``1 / (dx dy)``, they made the sum over a cut
    corner's elements wrong by up to 3e-5 of it (12 x 6 mesh of 200 x 100 mm, legs 47 x 23
    mm), and a pencil off its finite-element plate at its own snapshot by 7e-6 in
    eigenvalue; scaled, by 3e-10 and round-off.
    """
    mesh = model.mesh
    t = np.ones(DOFS_PER_NODE)
    t[[DOF_NAMES.index(n) for n in ("w_x", "w_y", "w_xy")]] = [
        1.0 / mesh.dx,
        1.0 / mesh.dy,
        1.0 / (mesh.dx * mesh.dy),
    ]
    local = np.tile(t, 4)  # an element's 32 unknowns, node by node
    element = np.concatenate([model.element_stiffness_terms(), model.element_mass()[None]])
    scaled = np.asarray(basis) / np.resize(t, mesh.n_dofs)[:, None]
    return RegionProjection(model, scaled, element * local[:, None] * local[None, :])


class CutCorner(Physics):
    """``K_j -> K_j - sum_e f_e K_j^e``, ``M -> M - sum_e f_e M^e``: a corner cut off.

    Material missing at a corner (cut off or chipped), which a :class:`~.cutout.Cutout`
    cannot model (its disc stays inside the plate). The missing part is the triangle with
    legs ``dx_mm`` along x and ``dy_mm`` along y from the corner; ``f_e`` is the share of
    element ``e``'s area inside it (:func:`triangle_fractions`, exact, so that the
    frequencies vary smoothly with the legs), times ``1 - RESIDUAL`` (the ersatz material of
    :mod:`.cutout`). The new edge is smeared over the elements it cuts.

    Which corner is a setting, not a parameter. The half-turn leaves every layup as it was
    and maps the corner ``(0, 0)`` to ``(a, b)`` (and ``(a, 0)`` to ``(0, b)``) with the same
    legs; the reflections, which hold for 0 and 90 degree plies only
    (:func:`~.base.reflection_symmetric`), map ``(0, 0)`` to the other two. So on a
    reflection-symmetric plate one instance (corner ``"00"``) stands for all four corners; on
    any other, two are needed: ``"00"`` (also ``"ab"``) and ``"a0"`` (also ``"0b"``). In both
    cases the plate turned by a symmetry is, for this instance, the same legs: every image in
    ``theta`` is ``theta`` itself (:meth:`image`), and there are no mirror images.

    Parameters
    ----------
    corner : {"00", "a0", "0b", "ab"}
        Also spelled with the axes' letters: ``"x0y0"``, ``"xay0"``, ``"x0yb"``, ``"xayb"``.
    """

    name = "cut_corner"
    description = "a corner cut off: the triangle with legs dx along x and dy along y"

    def __init__(self, corner="00"):
        spelled = str(corner).replace("x", "").replace("y", "")
        if spelled not in CORNERS:
            raise ValueError(f"corner = {corner!r}: must be one of {CORNERS} (or 'x0y0', ...)")
        self.corner = spelled

    def settings(self):
        """``{"corner": "00", "a0", "0b" or "ab"}``."""
        return {"corner": self.corner}

    def parameters(self, model, b):
        """``dx_mm``, ``dy_mm``: each side's tenth, +- a tenth, in [0, half the side].

        A chipped or cut corner is mostly small: the prior's mean is a tenth of the side
        (a cut of half a percent of the plate's area) with a deviation as large, so that
        chips of a few percent of a side and cuts of a third of it are both a deviation or
        two away. The legs stay within half the sides: a cut of at most an eighth of the
        plate, which never reaches the neighbouring corners (past that it is another plate,
        not a damaged one). The lower bound is 0 (no cut): the area ``dx dy / 2`` then loses
        its slope in the other leg, which :meth:`starting_points` keeps the fits away from.
        """
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        return (
            Parameter("dx_mm", a_mm / 10, a_mm / 10, 0.0, a_mm / 2),
            Parameter("dy_mm", b_mm / 10, b_mm / 10, 0.0, b_mm / 2),
        )

    def starting_points(self, model, b):
        """Legs of 5, 15 and 30 % of the sides, and two unequal pairs (30 and 10 %)."""
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        shares = [(0.05, 0.05), (0.15, 0.15), (0.3, 0.3), (0.3, 0.1), (0.1, 0.3)]
        return [np.array([sx * a_mm, sy * b_mm]) for sx, sy in shares]

    def _triangle(self, model, theta):
        """Each element's share of area inside the cut-off triangle."""
        dx_mm, dy_mm = theta
        return triangle_fractions(model.mesh, self.corner, 1e-3 * dx_mm, 1e-3 * dy_mm)

    def _fractions(self, model, theta):
        """Each element's share of stiffness and mass removed."""
        return (1.0 - RESIDUAL) * self._triangle(model, theta)

    def apply(self, model, theta):
        """The plate with the corner cut off; ``theta = (dx_mm, dy_mm)``."""
        return material_removed(model, self._fractions(model, theta))

    def ritz(self, model, b, basis, near=None):
        """``V^T K_j V - sum_e f_e V_e^T K_j^e V_e`` (and the same for M), cut elements only.

        As :meth:`.cutout.Cutout.ritz`: the elements wholly inside the triangle are summed
        once per set of them, a difference in a leg visits only those along the cut. The
        slopes and the twist are measured in lengths there (:func:`_region`).
        """
        terms, constant, mass = project(model, basis)
        region = _region(model, basis)

        def matrices(theta):
            removed = (1.0 - RESIDUAL) * region.inside(self._triangle(model, theta))
            return terms - removed[:6], constant, mass - removed[6]

        def difference(theta, i, h):
            up, down = np.array(theta, dtype=float), np.array(theta, dtype=float)
            up[i] += h
            down[i] -= h
            edge = (self._fractions(model, up) - self._fractions(model, down)) / (2 * h)
            removed = region(edge)
            return -removed[:6], np.zeros_like(constant), -removed[6]

        matrices.difference = difference
        return matrices

    def image(self, model, theta, symmetry):
        """``theta`` itself: a symmetry moves the cut to the corner this instance stands for.

        The half-turn maps this corner to the opposite one, a reflection (0/90 layups) to an
        adjacent one, the legs along the same axes: the turned plate has the frequencies of
        this plate at the same ``theta`` (see the class docstring).
        """
        return np.asarray(theta, dtype=float)
