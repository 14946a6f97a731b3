"""Reduced candidate models (discrepancy.pencil) against the finite-element modified plate.

The reference is the full solve of ``physics.apply(model, theta)``: an independent path
(assembly and sparse eigen solver on every unknown) from the projected pencil.
"""

import numpy as np
import pytest

from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
from bayesplate.discrepancy import candidates
from bayesplate.discrepancy.physics.reduced_model import candidate_pencil

N_MODES = 14


@pytest.fixture(scope="module")
def plate():
    case = load_case(bundled_case_path("frederiksen_t300"))
    model = PlateModel.from_case(case, mesh=(16, 10))
    return model, stiffness_from_engineering(case.reference)


def _snapshots_and_probe(physics, model, b):
    """Snapshot parameters and a probe value that is not one of them."""
    params = physics.parameters(model, b)
    if physics.name == "point_mass":  # the scan's places, another mass at one of them
        return [np.array([1.0, 23.0, 14.0]), np.array([0.5, 70.0, 40.0])], np.array(
            [0.7, 23.0, 14.0]
        )
    if physics.name in ("local_stiffness_loss", "delamination"):  # scan's patches, a factor
        return [
            np.array([70.0, 35.0, 20.0, 15.0, 0.4]),
            np.array([30.0, 20.0, 20.0, 15.0, 0.6]),
        ], np.array([70.0, 35.0, 20.0, 15.0, 0.7])
    if physics.name == "cutout":  # the scan's holes, a diameter between two at one of them
        # (a new diameter cuts other elements by other shares: not in the span of one
        # snapshot, as a patch's factor is)
        return [
            np.array([70.0, 35.0, 12.0]),
            np.array([70.0, 35.0, 8.0]),
            np.array([30.0, 20.0, 8.0]),
        ], np.array([70.0, 35.0, 10.0])
    if physics.name == "point_support":  # springs lifting mode 1 by ~1-10 %, another at one
        return [np.array([4.0, 23.0, 14.0]), np.array([3.5, 70.0, 40.0])], np.array(
            [3.7, 23.0, 14.0]
        )
    if physics.name == "cut_corner":  # legs between two snapshots' (cutting other elements)
        a_mm, b_mm = 1e3 * model.mesh.a, 1e3 * model.mesh.b
        legs = [np.array([a_mm, b_mm]) * f for f in (0.10, 0.14, 0.18)]
        return legs, np.array([a_mm, b_mm]) * 0.15
    mean = np.array([p.mean for p in params])
    sd = np.array([p.sd for p in params])
    lo, hi = np.array([p.lower for p in params]), np.array([p.upper for p in params])
    snaps = [np.clip(mean + s * sd, lo, hi) for s in (-4.0, -1.0, 1.0, 4.0)]
    return snaps, np.clip(mean + 1.7 * sd, lo, hi)


@pytest.mark.parametrize(
    "physics", candidates(), ids=lambda p: p.name + "".join(p.settings().values())
)
def test_reduced_candidate_matches_full_solve(plate, physics):
    model, b = plate
    snapshots, probe = _snapshots_and_probe(physics, model, b)
    nominal = model.solve(b, N_MODES + 20).vectors
    pencil = candidate_pencil(model, physics, b, snapshots, N_MODES + 4, nominal_modes=nominal)
    full = physics.apply(model, probe).solve(b, N_MODES)
    modal, d_theta = pencil.solve(b, probe, N_MODES)
    assert np.max(np.abs(modal.eigenvalues / full.eigenvalues - 1.0)) < 1e-4
    # Rayleigh-Ritz: upper bounds of the finite-element eigenvalues
    assert np.all(modal.eigenvalues >= full.eigenvalues * (1 - 1e-9))
    # sensitivities in b: the full model's eq. 28 at the same point
    rel = np.abs(modal.sensitivities - full.sensitivities) / np.abs(full.sensitivities).max()
    assert rel.max() < 1e-3
    # the parameter derivative: central difference of full solves (of the size only for a
    # located effect: its basis resolves the place only near its snapshots), and of the
    # pencil's own eigenvalues (the Jacobian the fit uses is that of its model)
    h = 0.05 * np.array([p.sd for p in physics.parameters(model, b)])
    for i in range(probe.size):
        up, down = probe.copy(), probe.copy()
        up[i] += 1e-3 * h[i]
        down[i] -= 1e-3 * h[i]
        own = (pencil.eigenvalues(b, up, N_MODES) - pencil.eigenvalues(b, down, N_MODES)) / (
            2e-3 * h[i]
        )
        assert np.max(np.abs(d_theta[:, i] - own)) <= 1e-4 * np.abs(own).max() + 1e-9
        if (
            (i > 0 and physics.name in ("point_mass", "point_support"))
            or (i < 4 and physics.name in ("local_stiffness_loss", "delamination"))
            or (i < 2 and physics.name == "cutout")
        ):
            continue
        up, down = probe.copy(), probe.copy()
        up[i] += h[i]
        down[i] -= h[i]
        fd = (
            physics.apply(model, up).solve(b, N_MODES).eigenvalues
            - physics.apply(model, down).solve(b, N_MODES).eigenvalues
        ) / (2 * h[i])
        scale = np.abs(fd).max()
        if scale > 0:
            assert np.max(np.abs(d_theta[:, i] - fd)) < 1e-2 * scale


def test_region_projection_is_the_projected_assembled_region(plate):
    """``RegionProjection`` (element by element, summed over runs of element numbers) against
    the assembled matrix of the same weighted elements projected on the same basis; weights
    on runs split across rows, a single element, none, and a run long enough for its own
    matrix-vector product beside short ones (``RUN_MIN``)."""
    from bayesplate.discrepancy.physics.region_projection import RUN_MIN, RegionProjection

    model, b = plate
    V = np.random.default_rng(3).standard_normal((model.mesh.n_dofs, 9))
    element = np.concatenate([model.element_stiffness_terms()[:2], model.element_mass()[None]])
    region = RegionProjection(model, V, element)
    nx = model.mesh.nx
    assert 10 >= RUN_MIN
    for inside in (
        [3, 4, 5, nx + 3, nx + 4, 2 * nx + 7],
        [11],
        [],
        [*range(nx + 2, nx + 12), 3 * nx + 1, 3 * nx + 2],
    ):
        inside = np.array(inside, dtype=int)
        weights = np.zeros(model.mesh.n_elements)
        weights[inside] = np.linspace(0.3, 1.0, len(inside))
        got = region(weights)
        assert got.shape == (3, 9, 9)
        for t, E in enumerate(element):
            data = model.assembler.element_data(inside, weights[inside, None, None] * E[None])
            want = V.T @ (model.assembler.matrix(data) @ V)
            assert np.allclose(got[t], want, rtol=1e-12, atol=1e-12 * np.abs(want).max(initial=1))


def test_region_sum_by_whole_elements_kept_is_the_weighted_sum(plate):
    """``RegionProjection.inside`` (whole elements' sums kept by their set, the last result
    kept) against ``__call__`` (every element weighted): patches moved so that the set of
    whole elements stays and changes, one repeated, a result changed by its caller, and more
    sets than are kept."""
    from bayesplate.discrepancy.physics import region_projection as pencil
    from bayesplate.discrepancy.physics.local_stiffness_loss import area_fractions

    model, b = plate
    mesh = model.mesh
    V = np.random.default_rng(5).standard_normal((mesh.n_dofs, 7))
    region = pencil.RegionProjection(model, V, model.element_stiffness_terms()[:2])
    size = np.array([0.45 * mesh.a, 0.5 * mesh.b])
    centres = [
        (0.5 + s) * np.array([mesh.a, mesh.b])
        for s in (
            0.0,
            1e-4,
            0.01,
            0.01,
            0.07,
            -0.03,
            0.11,
            0.15,
            -0.1,
            0.19,
            -0.07,
            -0.15,
            0.23,
            0.0,
            1e-4,
        )
    ]
    sets = set()
    for centre in centres:
        fractions = area_fractions(mesh, centre, size)
        whole = np.flatnonzero(np.abs(fractions - 1.0) <= pencil.WHOLE_TOL)
        assert whole.size >= pencil.WHOLE_MIN
        sets.add(whole.tobytes())
        got, want = region.inside(fractions), region(fractions)
        assert np.allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
        got[:] = 0.0  # the caller's copy: the kept result is not changed
        assert np.allclose(
            region.inside(fractions), want, rtol=1e-13, atol=1e-13 * np.abs(want).max()
        )
    assert len(sets) > pencil.WHOLE_KEPT  # the first set was let go, and is summed again
    assert len(region._whole) == pencil.WHOLE_KEPT
