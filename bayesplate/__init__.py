"""bayesplate: elastic constants of thick laminated plates from natural frequencies.

The forward model is a finite-element model of Reddy's third-order shear deformation theory
(Daghia, de Miranda, Ubertini, Viola, Composite Structures 80 (2007) 461-473).
"""

from .discrepancy.diagnose import diagnose
from .estimators import EstimateResult, estimate
from .io import Case, CaseError, bundled_case_path, load_case
from .laminate import engineering_from_stiffness, stiffness_from_engineering
from .model import ModalResult, PlateModel

__all__ = [
    "Case",
    "CaseError",
    "ModalResult",
    "PlateModel",
    "EstimateResult",
    "bundled_case_path",
    "diagnose",
    "estimate",
    "engineering_from_stiffness",
    "load_case",
    "stiffness_from_engineering",
]

__version__ = "0.1.0"
