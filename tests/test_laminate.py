import numpy as np
import pytest

from bayesplate import laminate

# T300/epoxy (Frederiksen) in Pa
E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])


def test_engineering_round_trip():
    b = laminate.stiffness_from_engineering(E_REF)
    np.testing.assert_allclose(laminate.engineering_from_stiffness(b), E_REF, rtol=1e-14)


def test_reduced_stiffness_closed_form():
    # eqs. 20-21 written out by hand for E1 = 150, E2 = 10 GPa, nu12 = 0.25
    b = laminate.stiffness_from_engineering([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    denom = 1 - 0.25 * 0.25 * 10 / 150
    np.testing.assert_allclose(
        b, [150e9 / denom, 10e9 / denom, 2.5e9 / denom, 3e9, 2e9, 3e9], rtol=1e-15
    )


def test_stiffness_jacobian_against_central_differences():
    J = laminate.stiffness_jacobian(E_REF)
    step = 1e-6 * np.abs(E_REF)
    for j in range(6):
        de = np.zeros(6)
        de[j] = step[j]
        fd = (
            laminate.stiffness_from_engineering(E_REF + de)
            - laminate.stiffness_from_engineering(E_REF - de)
        ) / (2 * step[j])
        # central differences are O(step^2) ~ 1e-12 relative; 1e-8 leaves room for rounding
        np.testing.assert_allclose(J[:, j], fd, rtol=1e-8, atol=1e-8 * np.abs(J).max())


def test_is_physical():
    b = laminate.stiffness_from_engineering(E_REF)
    assert laminate.is_physical(b)
    bad = b.copy()
    bad[2] = 1.01 * np.sqrt(b[0] * b[1])  # C12^2 > C11 C22
    assert not laminate.is_physical(bad)
    assert not laminate.is_physical(-b)
    assert list(laminate.is_physical(np.array([b, bad]))) == [True, False]


def test_rotation_by_zero_and_ninety_degrees():
    Q, Qs = laminate.lamina_matrices(laminate.stiffness_from_engineering(E_REF))
    Q0, Qs0 = laminate.rotate_lamina(Q, Qs, 0.0)
    np.testing.assert_allclose(Q0, Q, atol=1e-6)
    np.testing.assert_allclose(Qs0, Qs, atol=1e-6)
    Q90, Qs90 = laminate.rotate_lamina(Q, Qs, 90.0)
    np.testing.assert_allclose(Q90[0, 0], Q[1, 1], rtol=1e-12)
    np.testing.assert_allclose(Q90[1, 1], Q[0, 0], rtol=1e-12)
    # gamma_yz of a 90-degree ply is the 1-3 shear of the material: Qs_bar[0, 0] = C55 = G13
    np.testing.assert_allclose(Qs90[0, 0], E_REF[4], rtol=1e-12)


def test_rotation_closed_form_at_45_degrees():
    # Reddy, Mechanics of laminated composite plates, eq. 2.3.17 at theta = 45 deg
    b = laminate.stiffness_from_engineering(E_REF)
    Q, Qs = laminate.lamina_matrices(b)
    Qb, Qsb = laminate.rotate_lamina(Q, Qs, 45.0)
    Q11, Q22, Q12, Q66 = b[0], b[1], b[2], b[3]
    np.testing.assert_allclose(Qb[0, 0], (Q11 + 2 * (Q12 + 2 * Q66) + Q22) / 4, rtol=1e-12)
    np.testing.assert_allclose(Qb[0, 1], (Q11 + Q22 - 4 * Q66) / 4 + Q12 / 2, rtol=1e-12)
    np.testing.assert_allclose(Qb[0, 2], (Q11 - Q22) / 4, rtol=1e-12)
    np.testing.assert_allclose(Qb[2, 2], (Q11 + Q22 - 2 * Q12) / 4, rtol=1e-12)
    np.testing.assert_allclose(Qsb[0, 1], (b[5] - b[4]) / 2, rtol=1e-12)


@pytest.mark.parametrize("layup", [[0], [0, 90, 90, 0], [30, -30, -30, 30]])
def test_symmetric_laminates_have_no_coupling(layup):
    b = laminate.stiffness_from_engineering(E_REF)
    lam = laminate.laminate_matrices(b, layup, np.full(len(layup), 3.36e-3 / len(layup)))
    scale = np.abs(lam.Cf[0]).max() * 3.36e-3
    for q in (1, 3, 5):  # odd moments vanish for symmetric stacks
        assert np.abs(lam.Cf[q]).max() < 1e-12 * scale * 3.36e-3 ** (q - 1)


def test_unsymmetric_laminate_couples_membrane_and_bending():
    b = laminate.stiffness_from_engineering(E_REF)
    lam = laminate.laminate_matrices(b, [0, 90], [1e-3, 1e-3])
    # B11 = (Q11 - Q22) (z^2 evaluated) for a [0/90] pair of 1 mm plies: (Q22 - Q11) * 1e-6 / 2
    np.testing.assert_allclose(lam.Cf[1][0, 0], (b[1] - b[0]) * 1e-6 / 2, rtol=1e-12)


def test_single_layer_moments_and_inertias():
    b = laminate.stiffness_from_engineering(E_REF)
    h, rho = 3.36e-3, 1537.0
    lam = laminate.laminate_matrices(b, [0], [h])
    np.testing.assert_allclose(lam.Cf[0][0, 0], b[0] * h, rtol=1e-14)
    np.testing.assert_allclose(lam.Cf[2][0, 0], b[0] * h**3 / 12, rtol=1e-14)
    np.testing.assert_allclose(lam.Cf[6][0, 0], b[0] * h**7 / 448, rtol=1e-14)
    np.testing.assert_allclose(lam.c, -4 / (3 * h * h))
    moments = laminate.inertias(rho, [h])
    np.testing.assert_allclose(
        moments[[0, 2, 4, 6]], rho * np.array([h, h**3 / 12, h**5 / 80, h**7 / 448]), rtol=1e-14
    )
    assert np.all(np.abs(moments[[1, 3, 5]]) < 1e-20)


def test_shear_stiffness_of_reddy_theory():
    # sum over plies of int Qs (1 + 3 c z^2)^2 dz = 8 h / 15 Qs for one layer (parabolic shear)
    b = laminate.stiffness_from_engineering(E_REF)
    h = 3.36e-3
    C = laminate.constitutive_matrix(laminate.laminate_matrices(b, [0], [h]))
    np.testing.assert_allclose(np.diag(C[9:, 9:]), 8 * h / 15 * np.array([b[4], b[5]]), rtol=1e-12)
    np.testing.assert_allclose(C, C.T, rtol=0, atol=1e-12 * np.abs(C).max())
