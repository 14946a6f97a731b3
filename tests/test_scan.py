"""Ritz scans of located effects: exact in a complete basis, and they find large effects."""

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as sla

from bayesplate import laminate
from bayesplate.discrepancy import LocalStiffnessLoss, PointMass
from bayesplate.discrepancy.physics.base import mirror_positions
from bayesplate.discrepancy.physics.local_stiffness_loss import stiffness_loss_scan
from bayesplate.discrepancy.physics.location import absorbable_projector
from bayesplate.discrepancy.physics.point_mass import point_mass_scan
from bayesplate.discrepancy.physics.ritz_scan import RitzBasis, Scan
from bayesplate.plate.model import PlateModel

E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
B_REF = laminate.stiffness_from_engineering(E_REF)
N = 10


@pytest.fixture(scope="module")
def small():
    """A coarse plate and ALL its modes (dense): the Ritz basis is then complete."""
    model = PlateModel(0.1001, 0.053, 3.36e-3, 1537.0, [0, 90, 0], mesh=(6, 4))
    K, M = model.stiffness(B_REF).toarray(), model.mass.toarray()
    lam, vec = sla.eigh(K, M)
    modal = SimpleNamespace(eigenvalues=lam[6:], vectors=vec[:, 6:])  # rigid ones re-added
    return model, RitzBasis.from_modes(model, modal)


def _row(scan, theta):
    """Index of the scan's row at ``theta``."""
    (i,) = np.flatnonzero(np.all(np.isclose(scan.theta, theta), axis=1))
    return i


def _exact_misfit(data, basis):
    """Y = the effect's exact eigenvalues, unit deviations, nothing absorbed."""
    return data, np.ones(N), np.arange(N), np.eye(N)


def test_point_mass_scan_is_exact_in_a_complete_basis(small):
    model, basis = small
    node = 9  # an interior node of the 7 x 5 node grid
    x_mm, y_mm = 1e3 * model.mesh.nodes[node]
    data = PointMass().apply(model, [1.5, x_mm, y_mm]).solve(B_REF, N).eigenvalues
    scan = point_mass_scan(model, basis, *_exact_misfit(data, basis), [0.5, 1.5, 3.0], stride=1)
    i = _row(scan, [1.5, x_mm, y_mm])
    assert scan.chi2[i] < 1e-12 * np.sum(data**2)
    assert scan.chi2[i] == pytest.approx(scan.chi2.min(), abs=1e-12 * np.sum(data**2))


def test_stiffness_loss_scan_is_exact_in_a_complete_basis(small):
    model, basis = small
    dx, dy = 1e3 * model.mesh.dx, 1e3 * model.mesh.dy
    theta = [2.5 * dx, 1.5 * dy, 3 * dx, 3 * dy, 0.4]  # 3 x 3 elements around element (2, 1)
    data = LocalStiffnessLoss().apply(model, theta).solve(B_REF, N).eigenvalues
    scan = stiffness_loss_scan(
        model, basis, B_REF, *_exact_misfit(data, basis), [(3 * dx, 3 * dy)], [0.4, 0.7], stride=1
    )
    i = _row(scan, theta)
    assert scan.chi2[i] < 1e-10 * np.sum(data**2)
    assert scan.chi2[i] == pytest.approx(scan.chi2.min(), abs=1e-10 * np.sum(data**2))


def test_scan_finds_a_large_mass_that_the_linear_map_places_poorly():
    """1 g on a 27 g plate reorders modes; the scan's best places include the truth."""
    model = PlateModel(0.1001, 0.053, 3.36e-3, 1537.0, [0], mesh=(20, 10))
    truth = [1.0, 25.0, 15.9]  # at a node
    nominal = model.solve(B_REF, N + 20)
    data = PointMass().apply(model, truth).solve(B_REF, N).eigenvalues
    sigma = 0.004 * data
    P = absorbable_projector(nominal.sensitivities[:N] * B_REF / sigma[:, None])
    basis = RitzBasis.from_modes(model, nominal)
    scan = point_mass_scan(
        model, basis, data, sigma, np.arange(N), P, np.geomspace(0.1, 5.0, 12), stride=1
    )
    best = scan.best(model, 3)
    places = [truth[1:], *mirror_positions(model, *truth[1:])]
    x, y = best[0][1:]
    assert min(np.hypot(x - px, y - py) for px, py in places) < 1e3 * model.mesh.dx + 1e-9
    assert 0.5 < best[0][0] < 2.0  # the Ritz basis is stiffer: mass within a factor 2


def test_best_places_are_distinct_and_not_mirror_images():
    model = PlateModel(0.1, 0.05, 3e-3, 1500.0, [0], mesh=(10, 5))
    pts = np.array([[20.0, 10.0], [21.0, 10.0], [80.0, 10.0], [50.0, 25.0], [20.0, 40.0]])
    theta = np.column_stack([np.ones(5), pts])
    scan = Scan(theta, np.array([1.0, 2.0, 3.0, 4.0, 5.0]), (1, 2))
    best = scan.best(model, 3)
    # (21, 10) is next to the best, (80, 10) and (20, 40) are its mirror images
    np.testing.assert_allclose([t[1:] for t in best], [[20.0, 10.0], [50.0, 25.0]])
