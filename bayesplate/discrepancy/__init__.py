"""Model discrepancy: candidate physics the nominal model leaves out, and their diagnosis.

Every candidate implements the small interface of :class:`.physics.base.Physics`: its parameters
with units and priors, and how it changes the plate (a modified ``PlateModel``). A located
candidate (:mod:`.physics.point_mass`, :mod:`.physics.local_stiffness_loss`, :mod:`.physics.cutout`,
:mod:`.physics.point_support`, :mod:`.physics.delamination`) also implements the hooks
``location_map`` and ``scan``, which :func:`.diagnose.diagnose` calls on every candidate:
a new candidate, located or not, is one module. Where no candidate beats an unnamed
local change (:mod:`.search.unnamed`), the verdict names none.
"""

from .physics.base import Parameter, Physics, reflection_symmetric
from .physics.cut_corner import CutCorner
from .physics.cutout import Cutout
from .physics.delamination import Delamination
from .physics.elastic_foundation import ElasticFoundation
from .physics.local_stiffness_loss import LocalStiffnessLoss
from .physics.ply_misalignment import PlyMisalignment
from .physics.point_mass import PointMass
from .physics.point_support import PointSupport
from .physics.thickness_taper import ThicknessTaper

__all__ = [
    "CANDIDATES",
    "CutCorner",
    "Cutout",
    "Delamination",
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


def candidates(model=None):
    """One instance of every candidate physics (the taper once per direction).

    A cut corner is one candidate at corner ``(0, 0)`` where the plate's symmetries make
    every corner alike (0 and 90 degree plies); given a ``model`` whose layup has only the
    half-turn, a second instance stands for the corners ``(a, 0)`` and ``(0, b)``.
    """
    corners = [CutCorner("00")]
    if model is not None and not reflection_symmetric(model):
        corners.append(CutCorner("a0"))
    return [
        PointMass(),
        ThicknessTaper("x"),
        ThicknessTaper("y"),
        PlyMisalignment(),
        ElasticFoundation(),
        LocalStiffnessLoss(),
        Cutout(),
        PointSupport(),
        Delamination(),
        *corners,
    ]


CANDIDATES = tuple(sorted({c.name for c in candidates()}))
