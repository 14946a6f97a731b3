"""Model discrepancy: candidate physics the nominal model leaves out, and their diagnosis.

Every candidate implements the small interface of :class:`.physics.base.Physics`: its parameters
with units and priors, and how it changes the plate (a modified ``PlateModel``). A located
candidate (:mod:`.physics.point_mass`, :mod:`.physics.local_stiffness_loss`, :mod:`.physics.cutout`,
:mod:`.physics.point_support`) also implements the hooks
``location_map`` and ``scan``, which :func:`.diagnose.diagnose` calls on every candidate:
a new candidate, located or not, is one module.
"""

from .physics.base import Parameter, Physics
from .physics.cutout import Cutout
from .physics.elastic_foundation import ElasticFoundation
from .physics.local_stiffness_loss import LocalStiffnessLoss
from .physics.ply_misalignment import PlyMisalignment
from .physics.point_mass import PointMass
from .physics.point_support import PointSupport
from .physics.thickness_taper import ThicknessTaper

__all__ = [
    "CANDIDATES",
    "Cutout",
    "ElasticFoundation",
    "LocalStiffnessLoss",
    "Parameter",
    "Physics",
    "PlyMisalignment",
    "PointMass",
    "PointSupport",
    "ThicknessTaper",
    "candidates",
]


def candidates():
    """One instance of every candidate physics (the taper once per direction)."""
    return [
        PointMass(),
        ThicknessTaper("x"),
        ThicknessTaper("y"),
        PlyMisalignment(),
        ElasticFoundation(),
        LocalStiffnessLoss(),
        Cutout(),
        PointSupport(),
    ]


CANDIDATES = tuple(sorted({c.name for c in candidates()}))
