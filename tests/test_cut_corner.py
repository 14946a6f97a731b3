"""The cut corner, each against an independent reference.

References: point sampling of the triangle in every element; the area and mass of the
triangle; a plate cut along a whole edge against a narrower plate built directly (with the
cut on element edges, and its convergence off them); the plate's symmetries; Rayleigh's
first-order identity; the projected matrices of the modified plate.
"""

import numpy as np
import pytest

from bayesplate import laminate
from bayesplate.discrepancy.physics.cut_corner import (
    CORNERS,
    CutCorner,
    half_plane_area,
    triangle_fractions,
)
from bayesplate.discrepancy.physics.cutout import RESIDUAL
from bayesplate.discrepancy.physics.local_stiffness_loss import element_energies
from bayesplate.discrepancy.physics.reduced_model import candidate_pencil, project, ritz_basis
from bayesplate.plate.model import PlateModel

E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
B_REF = laminate.stiffness_from_engineering(E_REF)
A, B, H, RHO = 0.2, 0.1, 3.36e-3, 1537.0


def _model(layup=(0, 90, 0), mesh=(20, 10), a=A):
    return PlateModel(a, B, H, RHO, list(layup), mesh=mesh)


def _eigenvalues(model, n=8):
    return model.solve(B_REF, n).eigenvalues


# --- the triangle's area --------------------------------------------------------------


def test_half_plane_area_of_a_rectangle_against_its_pieces():
    # wholly inside, wholly outside, and a line through two opposite sides (a trapezoid)
    assert half_plane_area(0.0, 2.0, 0.0, 1.0, 1.0, 1.0, 10.0) == pytest.approx(2.0)
    assert half_plane_area(0.0, 2.0, 0.0, 1.0, 1.0, 1.0, -0.5) == 0.0
    # x + 4 y <= 3 over [0, 2] x [0, 1]: y <= (3 - x) / 4, from 3/4 to 1/4: area 1
    assert half_plane_area(0.0, 2.0, 0.0, 1.0, 1.0, 4.0, 3.0) == pytest.approx(1.0)


def _sampled_fractions(mesh, corner, leg_x, leg_y, k):
    """Each element's share of a k x k grid of its points inside the triangle."""
    u = (np.arange(k) + 0.5) / k
    sx = mesh.centroids[:, 0, None] + (u - 0.5) * mesh.dx  # (n_el, k)
    sy = mesh.centroids[:, 1, None] + (u - 0.5) * mesh.dy
    xp = mesh.a - sx if corner[0] == "a" else sx
    yp = mesh.b - sy if corner[1] == "b" else sy
    inside = xp[:, :, None] / leg_x + yp[:, None, :] / leg_y < 1.0
    return inside.mean(axis=(1, 2))


def test_fractions_add_up_to_the_triangle_and_agree_with_sampling(rng):
    mesh = _model(mesh=(10, 6)).mesh
    cell = mesh.dx * mesh.dy
    k = 200
    for corner in CORNERS:
        for _ in range(3):  # legs anywhere in the prior's range: [0, half the side]
            leg_x, leg_y = rng.uniform(0.002, A / 2), rng.uniform(0.002, B / 2)
            frac = triangle_fractions(mesh, corner, leg_x, leg_y)
            np.testing.assert_allclose(frac.sum(), leg_x * leg_y / 2 / cell, rtol=1e-12)
            assert frac.min() >= 0.0 and frac.max() <= 1.0
            # sampling: in an element the line crosses, at most ~2k of its k^2 points lie
            # in cells the line cuts, each off by at most one point: error below 2 / k
            sampled = _sampled_fractions(mesh, corner, leg_x, leg_y, k)
            np.testing.assert_allclose(frac, sampled, rtol=0, atol=2.0 / k)
    # legs that do not cut, and the spellings of the corners
    assert not triangle_fractions(mesh, "00", 0.0, 0.03).any()
    assert [CutCorner(c).corner for c in ("x0y0", "xay0", "x0yb", "xayb")] == list(CORNERS)
    with pytest.raises(ValueError):
        CutCorner("ba")


def test_zero_legs_are_the_nominal_plate():
    model = _model()
    for theta in ([0.0, 0.0], [0.0, 30.0], [40.0, 0.0]):
        cut = CutCorner("ab").apply(model, np.array(theta))
        np.testing.assert_array_equal(cut.stiffness_terms, model.stiffness_terms)
        np.testing.assert_array_equal(cut.mass_data, model.mass_data)


def test_the_cut_removes_the_mass_of_the_triangle():
    model = _model()
    w = np.zeros(model.mesh.n_dofs)
    w[model.mesh.dofs("w")] = 1.0  # rigid translation along z
    for corner, theta in [("00", [37.0, 23.0]), ("a0", [100.0, 50.0]), ("ab", [3.0, 41.0])]:
        cut = CutCorner(corner).apply(model, np.array(theta))
        removed = w @ (model.mass @ w) - w @ (cut.mass @ w)
        dx, dy = 1e-3 * np.asarray(theta)
        # the triangle's mass rho h dx dy / 2, less the ersatz share RESIDUAL kept
        np.testing.assert_allclose(removed, (1 - RESIDUAL) * RHO * H * dx * dy / 2, rtol=1e-10)
        np.testing.assert_allclose(cut.solve(B_REF, 4).n_rigid, 6)


# --- a whole edge cut off: the narrower plate -----------------------------------------

# With dy = 1e6 mm the triangle is x < dx (1 - y / dy): a strip of width dx along x = 0,
# narrowing by dx b / dy = 2e-6 m over the plate's width (2e-4 of a 10 mm element).
FAR_MM = 1e6


def test_a_strip_on_element_edges_is_the_narrower_plate():
    # A 20 x 10 mesh on 200 mm with 20 mm (two elements) cut off, against an 18 x 10 mesh on
    # 180 mm built directly: the same elements. What differs: the strip's slope leaves
    # 2e-4 of the second column's elements at most (about 3e-5 in eigenvalue, measured by a
    # dy of 1e9 mm instead), and the strip keeps RESIDUAL = 1e-4 of its stiffness and mass,
    # an ersatz strip moving with the new edge (about 1e-4 in eigenvalue, the same order as
    # RESIDUAL: measured 1.3e-4 at most over 10 modes). Tolerance 1e-3: ten times that.
    for corner in ("00", "a0"):  # the strip along x = 0, then along x = a
        cut = CutCorner(corner).apply(_model(), np.array([20.0, FAR_MM]))
        narrow = _model(mesh=(18, 10), a=0.18)
        np.testing.assert_allclose(_eigenvalues(cut, 10), _eigenvalues(narrow, 10), rtol=1e-3)


def test_a_strip_off_element_edges_converges_to_the_narrower_plate():
    # 13 mm cut off: 1.3, 2.6 and 5.2 elements of 10, 5 and 2.5 mm; the narrower plate of
    # 187 mm on elements of (nearly) the same length (19, 37, 75 along x), so that the
    # discretisation errors cancel and what is left is the cut smeared over the elements
    # it crosses (measured 1.7e-2, 5.3e-3, 9.0e-4)
    errors = []
    for nx in (20, 40, 80):
        cut = CutCorner("00").apply(_model(mesh=(nx, 10)), np.array([13.0, FAR_MM]))
        narrow = _model(mesh=(round(0.935 * nx), 10), a=0.187)
        errors.append(np.abs(_eigenvalues(cut) / _eigenvalues(narrow) - 1.0).max())
    assert errors[0] > errors[1] > errors[2] and errors[2] < 2e-3, errors


# --- the plate's symmetries -----------------------------------------------------------


def test_every_corner_is_the_same_on_a_cross_ply_plate():
    model = _model(mesh=(12, 6))
    theta = np.array([60.0, 30.0])
    want = _eigenvalues(CutCorner("00").apply(model, theta))
    assert np.abs(want / _eigenvalues(model) - 1.0).max() > 1e-2  # a cut that shows
    for corner in CORNERS[1:]:
        got = _eigenvalues(CutCorner(corner).apply(model, theta))
        np.testing.assert_allclose(got, want, rtol=1e-8)
    assert CutCorner("00").mirror_images(model, theta) == []


def test_opposite_corners_are_the_same_on_an_angle_ply_plate_adjacent_ones_not():
    model = _model(layup=(45, -45, 45), mesh=(12, 6))  # D16, D26 != 0
    theta = np.array([60.0, 30.0])
    at_00 = _eigenvalues(CutCorner("00").apply(model, theta))
    np.testing.assert_allclose(_eigenvalues(CutCorner("ab").apply(model, theta)), at_00, rtol=1e-8)
    at_a0 = _eigenvalues(CutCorner("a0").apply(model, theta))
    np.testing.assert_allclose(_eigenvalues(CutCorner("0b").apply(model, theta)), at_a0, rtol=1e-8)
    assert np.abs(at_a0 / at_00 - 1.0).max() > 1e-3
    # the half-turn, the only symmetry of this layup, gives theta itself: no mirror images
    assert CutCorner("a0").mirror_images(model, theta) == []


# --- first order ----------------------------------------------------------------------


def test_a_small_cut_is_rayleighs_first_order_change():
    # A chip of legs 2 x 1 mm in the corner element (10 x 10 mm): share f = 0.01 of it gone,
    # d lambda_i = -(1 - RESIDUAL) f (a_i^T K^e a_i - lambda_i a_i^T M^e a_i) to first order
    # (mass-normalised modes of the nominal plate; the element energies, not the continuum
    # densities at the corner point: the mesh's own first order)
    model = _model(mesh=(20, 10))
    r = model.solve(B_REF, 8)
    f = 0.002 * 0.001 / 2 / (model.mesh.dx * model.mesh.dy)
    q = r.vectors[model.mesh.element_dofs[0]]  # the element at (0, 0)
    kinetic = r.eigenvalues * np.einsum("ai,ab,bi->i", q, model.element_mass(), q)
    strain = element_energies(model, r, B_REF)[:, 0]
    want = -(1 - RESIDUAL) * f * (strain - kinetic)
    got = _eigenvalues(CutCorner("00").apply(model, np.array([2.0, 1.0]))) - r.eigenvalues
    np.testing.assert_allclose(got, want, rtol=0.02, atol=1e-3 * np.abs(want).max())


# --- the reduced form -----------------------------------------------------------------


def test_ritz_form_is_the_projected_cut_plate():
    model = _model(mesh=(12, 6))
    cut = CutCorner("a0")
    theta = np.array([47.0, 23.0])
    V = ritz_basis(model, [model.solve(B_REF, 10).vectors])
    matrices = cut.ritz(model, B_REF, V)
    # to round-off of the largest entry (measured 8e-12; 5e-7 before the ritz form scaled
    # the derivative unknowns: cut_corner._region)
    for t in (theta, np.array([13.0, 41.0]), np.array([0.0, 10.0])):
        want = project(cut.apply(model, t), V)
        for got, w in zip(matrices(t), want, strict=True):
            np.testing.assert_allclose(got, w, rtol=0, atol=1e-10 * max(np.abs(w).max(), 1e-300))
    # each leg's difference: the central difference of the matrices
    for i in range(2):
        h = 1e-3
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        fd = [(x - y) / (2 * h) for x, y in zip(matrices(up), matrices(down), strict=True)]
        for got, w in zip(matrices.difference(theta, i, h), fd, strict=True):
            np.testing.assert_allclose(got, w, rtol=0, atol=1e-8 * max(np.abs(w).max(), 1e-300))


def test_ritz_pencil_reproduces_the_cut_plate():
    model = _model(mesh=(12, 6))
    cut = CutCorner("00")
    snapshots = [np.array([20.0, 10.0]), np.array([60.0, 30.0])]
    pencil = candidate_pencil(model, cut, B_REF, snapshots, 12)
    # at a snapshot, its exact modes are in the basis: the finite-element eigenvalues
    np.testing.assert_allclose(
        pencil.eigenvalues(B_REF, snapshots[-1], 8),
        _eigenvalues(cut.apply(model, snapshots[-1])),
        rtol=1e-8,
    )
    # between them, an upper bound close to them
    probe = np.array([40.0, 20.0])
    full = _eigenvalues(cut.apply(model, probe))
    reduced = pencil.eigenvalues(B_REF, probe, 8)
    assert np.all(reduced >= full * (1 - 1e-9)) and np.max(reduced / full - 1) < 1e-3


# --- end to end -----------------------------------------------------------------------


@pytest.mark.slow
def test_concealed_cut_corner_is_named():
    from test_diagnose import MESH, _plate1_case, _recordings

    from bayesplate.discrepancy import Cutout, LocalStiffnessLoss, PointMass, ThicknessTaper
    from bayesplate.discrepancy.diagnose import diagnose

    case = _plate1_case()  # one 0 degree ply: one instance stands for every corner
    model = PlateModel.from_case(case, mesh=MESH)
    truth = np.array([60.0, 30.0])  # 30 % of each side at (a, b): 4.5 % of the plate
    physics = [
        CutCorner("x0y0"),
        Cutout(),
        LocalStiffnessLoss(),
        PointMass(),
        ThicknessTaper("x"),
        ThicknessTaper("y"),
    ]
    d = diagnose(
        _recordings(case, CutCorner("ab"), truth, seed=2), model=model, rng=0, physics=physics
    )
    assert d.verdict in ("explained", "ambiguous")
    named = [d.chosen, d.rival, *d.also_tied]
    corner = next(c for c in named if c is not None and c.name == "cut_corner")
    got, sd = corner.fit.theta, corner.fit.theta_sd
    # legs, mm (the recordings' finer mesh puts the truth a little off this mesh's)
    np.testing.assert_array_less(np.abs(got - truth), 3 * sd + 2.0)
