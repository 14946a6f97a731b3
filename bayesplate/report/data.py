"""What a report shows, as plain data: :class:`ReportData` and the questions asked of it.

Besides the container, the answers that the steps, the figures and the text must agree on:
the estimators shown (:data:`ESTIMATORS`), whether the posterior can be sampled, and the
estimate at which the modes are drawn.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, field

from .. import __version__
from ..estimators import METHODS, case_fast_model, modes_to_certify, resolve_forward
from ..io import Case
from ..laminate import stiffness_from_engineering
from ..matching.pairing import DEFAULT_EXTRA_MODES, Pairing
from ..plate.model import PlateModel
from .options import ReportOptions

__all__ = ["ESTIMATORS", "ReportData", "TapTest", "sampling_available"]

#: The estimators run and shown, in order: :data:`bayesplate.estimators.METHODS`.
ESTIMATORS = METHODS


def sampling_available():
    """Whether the package has :mod:`bayesplate.sampling` (the posterior section)."""
    return importlib.util.find_spec("bayesplate.sampling") is not None


@dataclass
class ReportData:
    """Everything a report shows, as plain data (see :mod:`bayesplate.report` for the steps).

    Attributes
    ----------
    case : Case
    case_file : str
        The case file read.
    options : ReportOptions
    mesh : tuple of int
        The working mesh.
    results : dict
        Step name -> its result (dict of JSON values and arrays).
    reused, computed : list of str
        Steps taken from the cache and steps computed.
    seconds : dict
        Step name -> wall time of this run (small for reused steps).
    notes : list of str
        Why a section is missing, warnings met on the way.
    taps : TapTest, optional
        The tap test the case was imported from (``bayesplate report --taps``).
    """

    case: Case
    case_file: str
    options: ReportOptions
    mesh: tuple
    results: dict = field(default_factory=dict)
    reused: list = field(default_factory=list)
    computed: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    version: str = __version__
    label: str = ""
    model: object = field(default=None, repr=False)
    fast: object = field(default=None, repr=False)
    taps: object = field(default=None, repr=False)

    def plate_model(self):
        """The working :class:`bayesplate.plate.model.PlateModel` (built when first needed)."""
        if self.model is None:
            self.model = PlateModel.from_case(self.case, mesh=self.mesh)
        return self.model

    def fast_model(self):
        """The certified fast model the steps share (built when first needed), or None.

        One model over the prior's box (:func:`bayesplate.estimators.case_fast_model`) for
        the estimators, the sampler and diagnose, on meshes where the estimators' ``"auto"``
        takes the fast path; None where a full solve is cheap. Every step gets it as built
        (seeded): a step's enrichments are not handed on, so that a report resumed after a
        kill runs each step on the same fast model as an unbroken one (the same numbers,
        bit for bit), whichever steps came from the cache.
        """
        model = self.plate_model()
        if self.fast is None and resolve_forward("auto", model) == "fast":
            # what the steps' pairing needs, and at least the modes of the pairing shown
            needed = modes_to_certify(self.case, self.pairing_for_steps())
            n_modes = max(self.pairing().n_modes(), needed)
            self.fast = case_fast_model(self.case, model, n_modes, rng=self.options.seed)
            self.seconds["fast_model"] = self.fast.build_seconds
        return self.fast

    def pairing_for_steps(self):
        """What the estimate, sample and diagnose steps are given as their pairing.

        The pairing step's :class:`bayesplate.matching.pairing.Pairing`; but ``"likelihood"`` by
        name, so that each step settles the assignment as :func:`bayesplate.estimators.estimate`
        does, from B's warm-started rounds (given only the pairing, B from the prior mean
        can reach another optimum when a mode is missing); and ``"auto"`` for pairing by
        order checked (:func:`bayesplate.matching.pairing.checks_order`), which each step checks
        again at its own answer.
        """
        if self.options.pairing == "likelihood" or self.results["pairing"]["how"] == "likelihood":
            return "likelihood"
        if self.results["pairing"].get("checked"):
            return "auto"  # by order, each step checking it at its answer
        return self.pairing()

    def pairing(self):
        """The :class:`bayesplate.matching.pairing.Pairing` the pairing step found."""
        p = self.results["pairing"]
        measured = p.get("measured")
        return Pairing(
            p["modes"], p["how"], DEFAULT_EXTRA_MODES, measured, p.get("mac"), p.get("threshold")
        )


@dataclass(frozen=True, eq=False)
class TapTest:
    """A tap test as imported: its spectra and its pole analysis.

    Attributes
    ----------
    spectra : bayesplate.io.frf.FRFData
        The averaged FRFs (H1 and coherence with a force channel).
    analysis : bayesplate.io.poles.PoleAnalysis
        The LSCF poles over the model orders, the candidates and their evidence.
    kept : tuple of bayesplate.io.poles.Pole
        The poles taken into the case, ascending.
    sources : tuple of str
        The recordings.
    """

    spectra: object
    analysis: object
    kept: tuple
    sources: tuple = ()


def _estimate_for_modes(data):
    """The estimate at which modes are drawn: B (the posterior mode) if it converged."""
    for method in ("B", "MVE-mod", "MVE"):
        if data.results[method]["converged"]:
            return method
    return "prior"


def _b_at(data, at):
    """Stiffness coefficients ``b`` (Pa), shape (6,), at estimate `at` or the prior mean."""
    if at == "prior":
        return stiffness_from_engineering(data.case.prior.mean)
    return data.results[at]["b"]
