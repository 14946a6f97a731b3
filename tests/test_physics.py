"""Candidate physics of the discrepancy module, each against an independent fact."""

import numpy as np
import pytest

from bayesplate import laminate
from bayesplate.discrepancy import (
    Cutout,
    ElasticFoundation,
    LocalStiffnessLoss,
    PlyMisalignment,
    PointMass,
    PointSupport,
    ThicknessTaper,
    candidates,
)
from bayesplate.discrepancy.physics.base import plate_symmetries
from bayesplate.discrepancy.physics.combined import Pair
from bayesplate.discrepancy.physics.delamination import Delamination
from bayesplate.discrepancy.physics.local_stiffness_loss import area_fractions
from bayesplate.plate.model import PlateModel

E_REF = np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9])
B_REF = laminate.stiffness_from_engineering(E_REF)
A, B, H, RHO = 0.1, 0.053, 3.36e-3, 1537.0


def _model(layup=(0,), mesh=(10, 6), **kw):
    return PlateModel(A, B, H, RHO, list(layup), mesh=mesh, **kw)


def _f(model, n=8):
    return model.solve(B_REF, n).frequency_Hz


def _every_candidate():
    """``candidates()`` and those not registered there yet (each once)."""
    registered = candidates()
    names = {c.name for c in registered}
    return [*registered, *(c for c in [Delamination()] if c.name not in names)]


@pytest.mark.parametrize("physics", _every_candidate(), ids=lambda c: f"{c.name}")
def test_parameters_have_units_priors_and_bounds(physics):
    model = _model()
    params = physics.parameters(model, B_REF)
    assert params
    for p in params:
        assert p.sd > 0 and p.lower < p.upper and p.lower <= p.mean <= p.upper, p


@pytest.mark.parametrize(
    "physics, theta",
    [
        (PointMass(), [0.0, 30.0, 20.0]),
        (ThicknessTaper("x"), [0.0]),
        (ThicknessTaper("y"), [0.0]),
        (PlyMisalignment(), [0.0]),
        (ElasticFoundation(), [0.0]),
        (LocalStiffnessLoss(), [50.0, 26.5, 20.0, 10.0, 1.0]),
        (Delamination(), [50.0, 26.5, 20.0, 10.0, 1.0]),
        (Cutout(), [31.0, 17.0, 0.0]),
        (PointSupport(), [-np.inf, 30.0, 20.0]),
    ],
    ids=lambda x: getattr(x, "name", ""),
)
def test_zero_effect_is_the_nominal_plate(physics, theta):
    model = _model()
    np.testing.assert_allclose(_f(physics.apply(model, np.array(theta))), _f(model), rtol=1e-9)


def test_point_mass_adds_its_mass_to_the_rigid_translation():
    model = _model()
    heavier = PointMass().apply(model, np.array([7.0, 31.0, 17.0]))
    w = np.zeros(model.mesh.n_dofs)
    w[model.mesh.dofs("w")] = 1.0  # rigid translation along z
    added = w @ (heavier.mass @ w) - w @ (model.mass @ w)
    np.testing.assert_allclose(added, 7e-3, rtol=1e-12)


def test_point_mass_first_order_frequency_drop():
    # Rayleigh: d lambda_i = -lambda_i m w_i(x)^2 for mass-normalised modes, to first order;
    # the remainder is second order in m: halving m divides it by four
    model = _model()
    r = model.solve(B_REF, 6)
    w = (model.interpolation(np.array([[0.02, 0.01]])) @ r.vectors)[0]

    def remainder(m):
        lam = PointMass().apply(model, np.array([1e3 * m, 20.0, 10.0])).solve(B_REF, 6).eigenvalues
        return lam / r.eigenvalues - (1 - m * w**2)

    m = 2e-4  # 0.2 g on a 27 g plate
    assert np.max(m * w**2) > 1e-3  # the first-order term is visible
    big, small = remainder(m), remainder(m / 2)
    assert np.all(np.abs(big) < 0.2 * m * w**2)  # first order explains most of it (modes 4
    # and 5 are 1 % apart here, so their mutual second-order term is large)
    np.testing.assert_allclose(big / small, 4.0, rtol=0.1)  # the remainder is O(m^2)


def test_foundation_lifts_bending_eigenvalues_by_k_over_i0_and_drops_bouncing_modes():
    model = _model()
    r0 = model.solve(B_REF, 6)
    k = 0.02 * r0.eigenvalues[0] * RHO * H  # lifts lambda_1 by 2 %
    r1 = ElasticFoundation().apply(model, np.array([k])).solve(B_REF, 6)
    assert r1.n_rigid == 6  # the three bouncing modes are recognised by shape
    shift = (r1.eigenvalues - r0.eigenvalues) / (k / (RHO * H))
    # exact for pure bending; rotary inertia makes int rho h w^2 slightly below 1
    np.testing.assert_allclose(shift, 1.0, atol=2e-2)


def test_uniform_thickness_scale_equals_a_thicker_plate():
    model = _model(layup=(0, 90, 0))
    taper = ThicknessTaper("x")
    # a taper with ratio e on a one-element-wide mesh is a uniform plate of thickness h(1 + 0)
    one_column = _model(layup=(0, 90, 0), mesh=(1, 6))
    np.testing.assert_allclose(
        _f(taper.apply(one_column, np.array([0.2]))), _f(one_column), rtol=1e-9
    )
    # the element matrices at thickness scale s are those of a plate of thickness s h
    thick = PlateModel(A, B, 1.1 * H, RHO, [0, 90, 0], mesh=(10, 6))
    np.testing.assert_allclose(
        model.element_stiffness_terms(thickness_scale=1.1),
        thick.element_stiffness_terms(),
        rtol=1e-12,
        atol=1e-12 * np.abs(thick.element_stiffness_terms()).max(),
    )
    np.testing.assert_allclose(
        model.element_mass(1.1),
        thick.element_mass(),
        rtol=1e-12,
        atol=1e-12 * np.abs(thick.element_mass()).max(),
    )


def test_taper_keeps_mass_and_its_sign_mirrors_the_plate():
    model = _model()
    taper = ThicknessTaper("x")
    w = np.zeros(model.mesh.n_dofs)
    w[model.mesh.dofs("w")] = 1.0
    tapered = taper.apply(model, np.array([0.1]))
    np.testing.assert_allclose(w @ (tapered.mass @ w), w @ (model.mass @ w), rtol=1e-12)
    # thick end at x = a or at x = 0: the same plate turned round
    (image,) = taper.mirror_images(model, np.array([0.1]))  # which diagnose reports as such
    np.testing.assert_allclose(_f(tapered), _f(taper.apply(model, image)), rtol=1e-9)
    np.testing.assert_allclose(image, [-0.1])
    assert not np.allclose(_f(tapered), _f(model), rtol=1e-4)


def test_misalignment_equals_turned_layup_and_is_mirror_symmetric():
    model = _model()
    turned = PlyMisalignment().apply(model, np.array([7.0]))
    np.testing.assert_allclose(_f(turned), _f(_model(layup=(7,))), rtol=1e-9)
    np.testing.assert_allclose(
        _f(turned), _f(PlyMisalignment().apply(model, np.array([-7.0]))), rtol=1e-9
    )


def test_local_loss_over_the_whole_plate_scales_the_coefficients():
    model = _model()
    f = 0.6
    damaged = LocalStiffnessLoss().apply(model, np.array([50.0, 26.5, 200.0, 200.0, f]))
    scaled_b = B_REF * np.array([1, f, f, f, f, f])
    np.testing.assert_allclose(
        damaged.solve(B_REF, 8).frequency_Hz, model.solve(scaled_b, 8).frequency_Hz, rtol=1e-9
    )


def test_area_fractions():
    mesh = _model(mesh=(10, 5)).mesh  # 10 mm x 10.6 mm elements
    frac = area_fractions(mesh, centre=[0.05, 0.0265], size=[0.02, 0.0106])
    np.testing.assert_allclose(frac.sum() * mesh.dx * mesh.dy, 0.02 * 0.0106, rtol=1e-12)
    assert frac.max() <= 1.0


def test_located_effects_have_mirror_images_with_equal_frequencies():
    model = _model()
    pm = PointMass()
    theta = np.array([5.0, 23.0, 14.0])
    f0 = _f(pm.apply(model, theta))
    images = pm.mirror_images(model, theta)
    assert len(images) == 3
    for image in images:
        np.testing.assert_allclose(_f(pm.apply(model, image)), f0, rtol=1e-8)


def _generic_theta(physics, model):
    """Parameters off every line of symmetry: places at 23 % and 31 % of the sides."""
    theta = []
    for p in physics.parameters(model, B_REF):
        value = np.clip(p.mean + 0.6 * p.sd, p.lower, p.upper)
        if p.name.endswith("x_mm"):
            value = 0.23e3 * A
        elif p.name.endswith("y_mm"):
            value = 0.31e3 * B
        theta.append(value)
    return np.array(theta)


@pytest.mark.parametrize(
    "layup, n_symmetries",
    [((0, 90, 90, 0), 3), ((30, -30, -30, 30), 1)],
    ids=["cross-ply", "angle-ply"],
)
# a point support first: its prior's scale needs a physical plate (a pair once split its
# parameters at an unphysical b and raised deep inside numpy)
@pytest.mark.parametrize(
    "physics",
    [
        *_every_candidate(),
        Pair(PointMass(), ThicknessTaper("x"), B_REF),
        Pair(PlyMisalignment(), Cutout(), B_REF),
        Pair(PointSupport(), PointMass(), B_REF),
    ],
    ids=lambda c: c.name + "".join(f"-{v}" for v in c.settings().values()),
)
@pytest.mark.filterwarnings("error")  # numpy's warnings on a singular or absurd plate too
def test_every_candidates_mirror_images_have_its_frequencies(physics, layup, n_symmetries):
    # an image under each of the plate's symmetries: the half-turn always (every ply is
    # its own turned by 180 degrees), the two reflections on a cross-ply only
    model = _model(layup=layup)
    theta = _generic_theta(physics, model)
    assert len(plate_symmetries(model)) == n_symmetries
    images = physics.mirror_images(model, theta)
    f0 = _f(physics.apply(model, theta))
    for image in images:
        assert not np.allclose(image, theta)
        np.testing.assert_allclose(_f(physics.apply(model, image)), f0, rtol=1e-8)
    # distinct images: a located effect (alone or in a pair) one per symmetry; a taper
    # reversed by two of them, the same one; a misalignment its own under the half-turn,
    # reversed by either reflection; a foundation is its own image; a cut corner's images
    # are the other corners, which its setting names, not its legs (its own instance for
    # the corners a symmetry does not reach: CutCorner's docstring)
    fewer = {
        "elastic_foundation": 0,
        "thickness_taper": 1,
        "ply_misalignment": n_symmetries // 3,
        "cut_corner": 0,
    }
    assert len(images) == fewer.get(physics.name, n_symmetries), images
