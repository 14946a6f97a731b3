"""bayesplate: elastic constants of thick laminated plates from natural frequencies.

The forward model is a finite-element model of Reddy's third-order shear deformation theory
(Daghia, de Miranda, Ubertini, Viola, Composite Structures 80 (2007) 461-473).

The public names below are imported on first use (PEP 562): ``import bayesplate`` (and so
``bayesplate --help``) does not load numpy, scipy or the finite elements; ``from bayesplate
import estimate`` works as before. The subpackages that ``import bayesplate`` used to load
(``bayesplate.io``, ``bayesplate.estimators``, ...) are attributes on first use as well.
"""

from __future__ import annotations

import importlib

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

#: Public name -> the module (relative to this package) it comes from.
_LAZY = {
    "Case": ".io",
    "CaseError": ".io",
    "bundled_case_path": ".io",
    "load_case": ".io",
    "ModalResult": ".plate.model",
    "PlateModel": ".plate.model",
    "EstimateResult": ".estimators",
    "estimate": ".estimators",
    "diagnose": ".discrepancy.diagnose",
    "engineering_from_stiffness": ".laminate",
    "stiffness_from_engineering": ".laminate",
}

#: Submodules that the eager ``__init__`` left as attributes of the package -> where they
#: live now (``from bayesplate import pairing`` still gives ``bayesplate.matching.pairing``).
_SUBMODULES = {
    "assignment": ".matching.assignment",
    "discrepancy": ".discrepancy",
    "estimators": ".estimators",
    "fem": ".fem",
    "io": ".io",
    "laminate": ".laminate",
    "model": ".plate.model",
    "pairing": ".matching.pairing",
    "posterior": ".likelihood.posterior",
    "quantities": ".quantities",
}


def __getattr__(name):
    """Import a public name, or a submodule, on first access (PEP 562)."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(_SUBMODULES[name], __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    """The module's names, the lazy ones included."""
    return sorted(set(globals()) | set(__all__) | set(_SUBMODULES))
