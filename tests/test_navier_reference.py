"""Check the independent TSDT Navier reference against published values.

Sources: tests/data/plate-benchmarks.md (Reddy 1984 TSDT tables; Srinivas et al. 1970 3D).
"""

import numpy as np
import pytest

try:
    from reference import navier_tsdt as nt
except ImportError:  # tests/ imported as a package
    from tests.reference import navier_tsdt as nt

# Reddy's material: E1/E2 = r, G12 = G13 = 0.6 E2, G23 = 0.5 E2, nu12 = 0.25 (E2 = rho = 1).
RATIOS = (3, 10, 20, 30, 40)
REDDY_AH5 = {
    (0, 90): (6.2169, 6.9887, 7.8210, 8.5050, 9.0871),
    (0, 90, 0, 90): (6.5008, 8.1954, 9.6265, 10.5348, 11.1716),
}
REDDY_0990 = {2: 5.5065, 4: 9.3235, 10: 15.1073, 20: 17.6466, 50: 18.6718, 100: 18.8356}

# The tables print 4 decimals, so exact agreement means |difference| <= 0.5e-4
# (relative <= 9.1e-6 over these values). Observed with all inertia terms: max |diff|
# 4.8e-5, max relative 7.0e-6, i.e. every printed digit is reproduced.
HALF_LAST_DIGIT = 0.5e-4 + 1e-9


def reddy_wbar(layup, a_over_h, r, drop_inertia=()):
    mat = dict(E1=r, E2=1.0, nu12=0.25, G12=0.6, G13=0.6, G23=0.5)
    w = nt.navier_frequencies(
        a_over_h, a_over_h, 1.0, 1.0, layup, **mat, m=1, n=1, drop_inertia=drop_inertia
    )
    return nt.nondimensional(w[0], a_over_h, 1.0, 1.0, 1.0)


def reddy_table():
    rows = [
        (lay, 5, r, v) for lay, vals in REDDY_AH5.items() for r, v in zip(RATIOS, vals, strict=True)
    ]
    return rows + [((0, 90, 90, 0), ah, 40, v) for ah, v in REDDY_0990.items()]


@pytest.mark.parametrize(("layup", "a_over_h", "r", "published"), reddy_table())
def test_reddy_1984_tsdt_all_inertia_terms(layup, a_over_h, r, published):
    assert abs(reddy_wbar(layup, a_over_h, r) - published) <= HALF_LAST_DIGIT


@pytest.mark.parametrize(
    ("drop", "min_rel"),
    [
        ((4, 6), 5e-3),  # higher-order inertia I4, I6 dropped: up to 0.57 % off
        ((2, 4, 6), 2e-2),
    ],  # only translatory inertia I0 (I1 = I3 = 0 anyway): up to 2.2 % off
)
def test_reddy_tables_need_full_inertia(drop, min_rel):
    # Convention check: truncated kinetic energies do not reproduce Reddy's numbers.
    rel = [abs(reddy_wbar(lay, ah, r, drop) / v - 1) for lay, ah, r, v in reddy_table()]
    assert max(rel) > min_rel


def isotropic(a, b, h, m, n, E=1.0, nu=0.3, rho=1.0):
    G = E / (2 * (1 + nu))
    return nt.navier_frequencies(a, b, h, rho, (0,), E, E, nu, G, G, G, m, n)


@pytest.mark.parametrize(
    ("m", "n", "w3d"), [(1, 1, 0.0932), (1, 2, 0.2226), (2, 2, 0.3421), (1, 3, 0.4171)]
)
def test_isotropic_thick_plate_vs_3d(m, n, w3d):
    # w_bar = omega h sqrt(rho/G), h/a = 0.1. This compares two theories, not two codes:
    # TSDT is below 3D elasticity by 0.18, 0.29, 0.43, 0.49 % for these modes (the gap
    # grows with h / wavelength), and the 3D values carry up to 0.05 % rounding.
    # Tolerance 1 %: a bound on the model error of a 2D theory at this thickness.
    G = 1.0 / 2.6
    w = isotropic(1.0, 1.0, 0.1, m, n)[0] * 0.1 / np.sqrt(G)
    assert w == pytest.approx(w3d, rel=1e-2)
    assert w < w3d


def test_isotropic_in_plane_roots_are_exact():
    # Symmetric laminate: U, V decouple and give the exact plane-stress wave frequencies.
    k = np.pi * np.hypot(1.0, 2.0 / 1.5)
    w = isotropic(1.0, 1.5, 0.1, 1, 2)
    shear, longitudinal = k * np.sqrt(1 / 2.6), k * np.sqrt(1 / 0.91)
    assert np.min(abs(w - shear)) <= 1e-12 * shear
    assert np.min(abs(w - longitudinal)) <= 1e-12 * longitudinal


@pytest.mark.parametrize("b", [1.0, 1.5])
def test_thin_limit_is_kirchhoff(b):
    # Shear and rotary-inertia corrections are O((h/a)^2): at a/h = 1000 the TSDT
    # fundamental is 3.6e-6 (square) / 2.6e-6 (b = 1.5 a) below Kirchhoff; tolerance 1e-5
    # (about (pi h / a)^2). The O((h/a)^2) rate itself is checked via a/h = 100.
    E, nu, rho, a = 1.0, 0.3, 1.0, 1.0

    def rel_gap(h):
        D = E * h**3 / (12 * (1 - nu**2))
        kirchhoff = np.pi**2 * (1 / a**2 + 1 / b**2) * np.sqrt(D / (rho * h))
        return isotropic(a, b, h, 1, 1)[0] / kirchhoff - 1

    gap_thin, gap_thick = rel_gap(1e-3), rel_gap(1e-2)
    assert -1e-5 < gap_thin < 0
    assert gap_thick / gap_thin == pytest.approx(100, rel=1e-2)


def test_frequencies_sorted_and_mode_numbers_checked():
    w = nt.navier_frequencies(1.0, 2.0, 0.1, 1.0, (0, 90, 0), 25, 1, 0.25, 0.5, 0.5, 0.2, 2, 1)
    assert w.shape == (5,) and np.all(np.diff(w) > 0)
    with pytest.raises(ValueError, match="m and n"):
        nt.navier_frequencies(1.0, 1.0, 0.1, 1.0, (0,), 25, 1, 0.25, 0.5, 0.5, 0.2, 0, 1)
    with pytest.raises(ValueError, match="0/90"):
        nt.laminate_abdefh((45,), 0.1, 25, 1, 0.25, 0.5, 0.5, 0.2)


def test_laminate_integrals_symmetric_crossply():
    lam = nt.laminate_abdefh((0, 90, 90, 0), 0.25, 25, 1, 0.25, 0.5, 0.5, 0.2)
    assert lam["h"] == 1.0 and lam["c"] == pytest.approx(-4 / 3)
    np.testing.assert_allclose(lam["B"], 0, atol=1e-15)
    np.testing.assert_allclose(lam["E"], 0, atol=1e-15)
    # A is the thickness average of 0 and 90 plies; D weights the outer 0 plies 7/8.
    q11, q22 = 25 / (1 - 0.25**2 / 25), 1 / (1 - 0.25**2 / 25)
    assert lam["A"][0, 0] == pytest.approx((q11 + q22) / 2)
    assert lam["D"][0, 0] == pytest.approx((7 * q11 + q22) / 96)
