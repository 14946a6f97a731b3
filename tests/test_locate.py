"""Locating a misfit on the plate, on data made by a known effect."""

import numpy as np

from bayesplate import laminate
from bayesplate.discrepancy import LocalStiffnessLoss, PointMass
from bayesplate.discrepancy.physics.base import mirror_positions
from bayesplate.discrepancy.physics.local_stiffness_loss import stiffness_loss_map
from bayesplate.discrepancy.physics.location import absorbable_projector, explained_chi2
from bayesplate.discrepancy.physics.point_mass import point_mass_map
from bayesplate.discrepancy.search.locate import mode_kinds
from bayesplate.plate.model import PlateModel

E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
B_REF = laminate.stiffness_from_engineering(E_REF)
N = 14


def _setup(physics, theta):
    model = PlateModel(0.1001, 0.053, 3.36e-3, 1537.0, [0], mesh=(20, 10))
    nominal = model.solve(B_REF, N)
    data = physics.apply(model, np.asarray(theta)).solve(B_REF, N).eigenvalues
    sigma = 0.002 * 2 * nominal.eigenvalues  # 0.2 % on f is 0.4 % on lambda
    r = (data - nominal.eigenvalues) / sigma
    P = absorbable_projector(nominal.sensitivities * B_REF / sigma[:, None])
    return model, nominal, r, sigma, P


def _near_one_of(point, candidates, tol_mm):
    return min(np.hypot(*(np.asarray(point) - np.asarray(c))) for c in candidates) < tol_mm


def test_what_the_constants_absorb_explains_nothing(rng):
    S = rng.normal(size=(14, 6))
    P = absorbable_projector(S)
    drop, _ = explained_chi2(rng.normal(size=14), S @ rng.normal(size=(6, 3)), P)
    np.testing.assert_allclose(drop, 0.0, atol=1e-20)
    g = rng.normal(size=14)
    drop, amp = explained_chi2(3.0 * (P @ g), g[:, None], P)
    np.testing.assert_allclose(amp, 3.0)  # recovers the amplitude of a pure effect


def test_point_mass_is_located_at_its_place_or_a_mirror_image():
    theta = [1.0, 23.0, 14.0]  # 1 g at (23, 14) mm on a 27 g plate
    model, nominal, r, sigma, P = _setup(PointMass(), theta)
    m = point_mass_map(model, nominal, r, sigma, P)
    best = m.points_mm[m.best()]
    images = [theta[1:], *mirror_positions(model, *theta[1:])]
    assert _near_one_of(best, images, tol_mm=2 * 1e3 * model.mesh.dx), best
    assert m.chi2_drop[m.best()] > 0.5 * np.sum((P @ r) ** 2)  # explains most of it


def test_local_stiffness_loss_is_located():
    theta = [75.0, 40.0, 15.0, 10.0, 0.5]
    model, nominal, r, sigma, P = _setup(LocalStiffnessLoss(), theta)
    m = stiffness_loss_map(model, nominal, B_REF, r, sigma, P)
    best = m.points_mm[m.best()]
    images = [theta[:2], *mirror_positions(model, *theta[:2])]
    assert _near_one_of(best, images, tol_mm=15.0), best


def test_mode_kinds_of_the_frederiksen_plate():
    model = PlateModel(0.1001, 0.053, 3.36e-3, 1537.0, [0], mesh=(20, 10))
    r = model.solve(B_REF, 6)
    kinds = mode_kinds(model, r)
    # mode 1 of a free unidirectional plate is twisting, mode 2 bending across the fibres
    # (lowest bending stiffness E2), as Frederiksen (1997) identifies them
    assert kinds[0] == "torsion"
    assert kinds[1] == "bending along y"
    assert "bending along x" in kinds
