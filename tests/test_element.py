"""The TSDT rectangle: interpolation, exactness of quadrature, zero-energy modes."""

import numpy as np
import pytest

from bayesplate import laminate
from bayesplate.fem.element import CORNERS, TSDTRectangle, gauss_rule
from bayesplate.fem.mesh import DOF_NAMES

DX, DY = 0.03, 0.02
E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])


def _nodal_values(func, grads):
    """Local unknown vector interpolating w = func and its derivatives at the corners."""
    q = np.zeros(32)
    for node, (sx, sy) in enumerate(CORNERS):
        x, y = sx * DX / 2, sy * DY / 2
        for name, g in grads.items():
            q[8 * node + DOF_NAMES.index(name)] = g(x, y)
        q[8 * node + DOF_NAMES.index("w")] = func(x, y)
    return q


def test_hermite_reproduces_bicubic_exactly(rng):
    c = rng.normal(size=(4, 4))

    def w(x, y, dx=0, dy=0):
        total = 0.0
        for i in range(4):
            for j in range(4):
                if i >= dx and j >= dy:
                    fx = np.prod(range(i - dx + 1, i + 1)) * x ** (i - dx)
                    fy = np.prod(range(j - dy + 1, j + 1)) * y ** (j - dy)
                    total = total + c[i, j] * fx * fy / (DX**i * DY**j)
        return total

    grads = {
        "w_x": lambda x, y: w(x, y, 1, 0),
        "w_y": lambda x, y: w(x, y, 0, 1),
        "w_xy": lambda x, y: w(x, y, 1, 1),
    }
    q = _nodal_values(w, grads)
    local = rng.uniform(-1, 1, size=(20, 2))
    x, y = local[:, 0] * DX / 2, local[:, 1] * DY / 2
    f = TSDTRectangle(DX, DY).fields(local)
    for key, (dx, dy) in {
        "w": (0, 0),
        "w_x": (1, 0),
        "w_y": (0, 1),
        "w_xx": (2, 0),
        "w_yy": (0, 2),
        "w_xy": (1, 1),
    }.items():
        expected = w(x, y, dx, dy)
        np.testing.assert_allclose(
            f[key] @ q, expected, rtol=1e-10, atol=1e-10 * np.abs(expected).max(), err_msg=key
        )


def test_bilinear_fields_reproduce_linear_functions(rng):
    a0, ax, ay = rng.normal(size=3)
    q = np.zeros(32)
    for node, (sx, sy) in enumerate(CORNERS):
        q[8 * node + DOF_NAMES.index("psi_y")] = a0 + ax * sx * DX / 2 + ay * sy * DY / 2
    local = rng.uniform(-1, 1, size=(10, 2))
    f = TSDTRectangle(DX, DY).fields(local)
    np.testing.assert_allclose(
        f["psi_y"] @ q, a0 + ax * local[:, 0] * DX / 2 + ay * local[:, 1] * DY / 2, rtol=1e-12
    )
    np.testing.assert_allclose(f["psi_y_x"] @ q, ax, rtol=1e-12)
    np.testing.assert_allclose(f["psi_y_y"] @ q, ay, rtol=1e-12)


def test_four_point_rule_is_exact():
    # the stiffness integrand is of degree <= 6 per direction: 4 and 6 points must agree
    C = laminate.constitutive_matrix(
        laminate.laminate_matrices(
            laminate.stiffness_from_engineering(E_REF), [0, 45, -45, 90], [1e-3] * 4
        )
    )
    K4 = TSDTRectangle(DX, DY, order=4).stiffness(C)
    K6 = TSDTRectangle(DX, DY, order=6).stiffness(C)
    np.testing.assert_allclose(K4, K6, rtol=0, atol=1e-10 * np.abs(K6).max())
    pts, wts = gauss_rule(4)
    assert pts.shape == (16, 2) and np.isclose(wts.sum(), 4.0)


@pytest.mark.parametrize("layup", [[0], [0, 90], [30, -45, 60]])
def test_element_has_exactly_six_zero_energy_modes(layup):
    # a thick, mildly orthotropic element keeps the spectrum of K well conditioned, so that the
    # gap between rigid-body (zero) and deforming modes is clear
    b = laminate.stiffness_from_engineering([3.0, 1.0, 0.3, 0.5, 0.4, 0.35])
    h = 0.3
    lam = laminate.laminate_matrices(b, layup, np.full(len(layup), h / len(layup)))
    el = TSDTRectangle(1.0, 1.5)
    K = el.stiffness(laminate.constitutive_matrix(lam))
    M = el.mass(
        laminate.inertia_matrix(laminate.inertias(1.0, [h / len(layup)] * len(layup)), lam.c)
    )
    np.testing.assert_allclose(K, K.T, atol=1e-12 * np.abs(K).max())
    np.testing.assert_allclose(M, M.T, atol=1e-12 * np.abs(M).max())
    assert np.linalg.eigvalsh(M).min() > 0
    ev = np.linalg.eigvalsh(K)
    zero = np.abs(ev) < 1e-10 * ev.max()
    assert zero.sum() == 6  # 3 translations, 3 rotations; no spurious zero-energy mode
    assert ev[~zero].min() > 1e-6 * ev.max()  # clear gap above them
    assert ev.min() > -1e-10 * ev.max()
