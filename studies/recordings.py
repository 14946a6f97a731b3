"""Synthetic recordings with known effects, as the concealed-effect studies make them.

An effect (a :class:`bayesplate.discrepancy.Physics` at parameters ``theta``, or none) is
put in the plate on a mesh twice as fine each way as the one diagnose works on; its lowest
frequencies at the case's reference constants are recorded times ``1 + noise N(0, 1)`` and
sorted (a test lists what it measured in ascending order: noise can swap two close modes),
and declared with their relative deviation ``noise``. The recordings' mesh is not the
diagnosis's, so the diagnosis does not see its own model's numbers.

The effects and their places (:data:`EFFECTS`) are those of ``studies.concealment`` (two
sizes of each, each scenario's noise from its own child of one seed) and
``studies.calibration`` (sizes found from the power of the tests; the studies that diagnose
its replicates again use its recordings), and ``studies.behaviour_fingerprint`` diagnoses
some of the concealment study's.
"""

import numpy as np

from bayesplate import PlateModel, stiffness_from_engineering
from bayesplate.discrepancy import (
    CutCorner,
    Cutout,
    Delamination,
    ElasticFoundation,
    LocalStiffnessLoss,
    PlyMisalignment,
    PointMass,
    PointSupport,
    ThicknessTaper,
)

#: The recordings' relative deviation: each frequency times ``1 + NOISE N(0, 1)``.
NOISE = 0.002

#: The effects concealed, by candidate: (its physics, its parameters ``theta`` at a size, the
#: size's unit, a grid of sizes for the calibration's ideal test). Places on the Frederiksen
#: plate (100.1 x 53.0 mm), away from its lines of symmetry; the sizes: a point mass's grams,
#: a taper's thickness ratio, a misalignment's degrees, a foundation's modulus (N/m^3), the
#: stiffness a local loss takes (0 to 1), a hole's diameter (mm), a support's N/m, the
#: transverse shear stiffness (G13, G23) a delamination takes (0 to 1; a rectangle 24 x 14 mm
#: about (28, 18) mm), a cut corner's leg along x (mm; the leg along y 0.6 times it, at the
#: corner x = a, y = 0).
EFFECTS = {
    "point_mass": (PointMass, lambda s: [s, 23.0, 14.0], "g", np.geomspace(0.01, 3.0, 8)),
    "thickness_taper": (
        lambda: ThicknessTaper("x"),
        lambda s: [s],
        "",
        np.geomspace(0.002, 0.3, 8),
    ),
    "ply_misalignment": (PlyMisalignment, lambda s: [s], "deg", np.geomspace(0.02, 10.0, 8)),
    "elastic_foundation": (ElasticFoundation, lambda s: [s], "N/m^3", np.geomspace(1e4, 1e9, 11)),
    "local_stiffness_loss": (
        LocalStiffnessLoss,
        lambda s: [70.0, 35.0, 20.0, 15.0, 1.0 - s],
        "stiffness lost",
        np.geomspace(0.01, 0.95, 8),
    ),
    "cutout": (Cutout, lambda s: [70.0, 20.0, s], "mm", np.geomspace(0.5, 17.0, 8)),
    "point_support": (
        PointSupport,
        lambda s: [np.log10(s), 80.0, 40.0],
        "N/m",
        np.geomspace(1.0, 1e7, 15),
    ),
    "delamination": (
        Delamination,
        lambda s: [28.0, 18.0, 24.0, 14.0, 1.0 - s],
        "shear lost",
        np.r_[np.geomspace(0.01, 0.5, 6), 0.6, 0.7, 0.8, 0.9, 0.99],
    ),
    "cut_corner": (
        lambda: CutCorner("a0"),
        lambda s: [s, 0.6 * s],
        "mm",
        np.geomspace(0.5, 40.0, 8),
    ),
}


def effect(name, size):
    """Candidate ``name`` concealed at ``size`` (:data:`EFFECTS`): ``(physics, theta)``."""
    make, theta_of, _, _ = EFFECTS[name]
    return make(), theta_of(size)


def meshes(case, mesh):
    """The plate on the working ``mesh`` and on the recordings' mesh (twice as fine).

    Returns
    -------
    model, fine : PlateModel
    """
    nx, ny = mesh
    return (
        PlateModel.from_case(case, mesh=(nx, ny)),
        PlateModel.from_case(case, mesh=(2 * nx, 2 * ny)),
    )


def frequencies(case, plate):
    """``plate``'s lowest ``case.measured.size`` frequencies at the case's reference, Hz."""
    return plate.solve(stiffness_from_engineering(case.reference), case.measured.size).frequency_Hz


def concealed(fine, physics, theta):
    """``fine`` with the effect at ``theta`` in it (``fine`` itself when ``physics`` is None)."""
    return fine if physics is None else physics.apply(fine, np.asarray(theta, dtype=float))


def noisy(f, rng, noise=NOISE):
    """``f`` times ``1 + noise N(0, 1)`` (one draw of ``rng`` a frequency), sorted."""
    return np.sort(f * (1 + noise * rng.standard_normal(f.size)))


def recordings(case, fine, physics, theta, rng, noise=NOISE):
    """The recorded frequencies of the plate with the effect on the fine mesh, Hz (sorted)."""
    return noisy(frequencies(case, concealed(fine, physics, theta)), rng, noise)


def blind(case, f, noise=NOISE):
    """The nominal ``case`` with the recorded frequencies ``f`` and their deviations."""
    return case.with_measured(frequency_Hz=f, sigma_Hz=noise * f)


def stream(seed, index):
    """Recording ``index``'s generator: the ``index``-th child of ``SeedSequence(seed)``.

    A recording's noise then does not depend on which others were made, in which order or
    in which process.
    """
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(index + 1)[index])
