"""Every setting of :func:`..diagnose.diagnose`, in one frozen object, and their defaults."""

from __future__ import annotations

from dataclasses import dataclass, fields

from ...settings import with_overrides
from .mesh_error import MESH_ERROR_PARTS
from .nominal import N_STARTS

__all__ = ["DEFAULTS", "DiagnoseOptions"]


@dataclass(frozen=True)
class DiagnoseOptions:
    """The settings of :func:`..diagnose.diagnose` (the defaults are :data:`DEFAULTS`).

    Attributes
    ----------
    alpha : float
        Significance of the chi-square tests (nominal fit and refit).
    evidence_threshold : float
        Laplace evidence gain a candidate needs to be chosen, nats (3: about 20 to 1).
    n_starts : int
        Random starts of the nominal fit (on the reduced model), besides the prior mean.
    unidentified_ratio : float
        Posterior sd / prior sd above which a constant is reported as unidentified.
    mesh_error_ratio : float
        Mesh error / measurement deviation above which the deviation is inflated.
    mesh_error_part : {"whole", "unabsorbed", "corrected"}
        What of the mesh's estimated error inflates the deviations: all of it, or the part
        the six constants cannot absorb (:mod:`.mesh_error`; measured by
        ``studies/mesh_error_rule.py``); or ``"corrected"``: the error (estimated with the
        mesh twice as fine) taken out of the model, the deviations widened only by what the
        correction leaves uncertain.
    refine_margin : float
        Candidates gaining less than this on their reduced coarse model are not refined on
        the working mesh, nats.
    basin_margin : float
        Another nominal optimum whose ``chi2 + chi2_prior`` is this close fits as well.
    workers : int
        Processes for the independent fits (fork); the results do not depend on it.
    ambiguity_margin : float
        Posterior log-odds of the best candidate against a different one under which the
        verdict is ``ambiguous``, nats (2: about 7 to 1); also the log-likelihood margin of
        a rival that fits as well.
    prior_margin : float
        Log-odds under which a different candidate that fits the recordings as well makes
        the verdict ``ambiguous``: the odds are then its prior volume's alone, nats (4:
        about 55 to 1; :func:`.verdict.ties`).
    pairs : bool
        Fit two effects at once when the best single candidate's refit is rejected.
    reassign : bool
        Make the assignment again at the fit the verdict rests on and, where it differs (by
        order checked: where it pairs a peak with another mode), diagnose again
        (:mod:`.reassign`). Order or index asked by name, and pairing by shapes, are kept as
        they are.
    unnamed_margin : float or None
        Nats by which the unnamed local change (:mod:`.unnamed`) must gain more than the
        best named candidate for the verdict to be ``unexplained`` rather than a name (2,
        the ambiguity margin: within it the two tie, and the name stands with a note that
        an unnamed change fits about as well); None leaves the rival out.
    prior_odds : dict, optional
        ``{candidate name: prior odds against the nominal model}`` (default 1 for every
        candidate; a case-file key for them is not defined yet).
    """

    alpha: float = 0.01  # significance of the chi-square test
    evidence_threshold: float = 3.0  # nats (about 20:1): a candidate must gain this much
    n_starts: int = N_STARTS  # random starts of the nominal fit (reduced model), and the mean
    unidentified_ratio: float = 0.7  # posterior sd / prior sd: a constant is unidentified
    mesh_error_ratio: float = 0.3  # mesh error / sigma above which sigma is inflated
    mesh_error_part: str = "whole"  # of the mesh error added: all, or what the constants leave
    refine_margin: float = 1.0  # nats: candidates below this on the coarse mesh are not refined
    basin_margin: float = 2.0  # chi2 + chi2_prior: another nominal optimum this close fits as well
    workers: int = 1  # processes for independent fits (fork); the CLI uses 2
    ambiguity_margin: float = 2.0  # nats (odds about 7:1): a different candidate this close ties
    prior_margin: float = 4.0  # nats (odds about 55:1): one that fits as well this close ties too
    pairs: bool = True  # fit two effects at once when the best single one is rejected
    reassign: bool = True  # the assignment made again at the verdict's fit (not by order/index)
    unnamed_margin: float | None = 2.0  # nats: the unnamed local change beats every name
    prior_odds: dict | None = None

    def __post_init__(self):
        if self.mesh_error_part not in MESH_ERROR_PARTS:
            raise ValueError(
                f"mesh_error_part = {self.mesh_error_part!r}: must be one of "
                f"{', '.join(MESH_ERROR_PARTS)}"
            )

    @classmethod
    def of(cls, options=None, **overrides):
        """`options` (default: the defaults) with `overrides`, each a field's name.

        Raises
        ------
        TypeError
            An override that is no field of :class:`DiagnoseOptions`, or `options` of
            another type.
        """
        return with_overrides(cls, options, "diagnose", overrides)

    def store_key(self):
        """What of the options the stored stages depend on (:mod:`.store`), as before."""
        key = (
            self.alpha,
            self.evidence_threshold,
            self.n_starts,
            self.unidentified_ratio,
            self.mesh_error_ratio,
            self.refine_margin,
            self.basin_margin,
            self.ambiguity_margin,
            self.prior_margin,
            self.pairs,
            self.prior_odds,
        )
        if self.mesh_error_part != "whole":  # (the default keeps the stores' keys of before)
            key += (self.mesh_error_part,)
        return key


#: Default values of :class:`DiagnoseOptions` (and of :func:`..diagnose.diagnose`'s
#: keywords) but ``prior_odds``: their single source is the class.
DEFAULTS = {f.name: f.default for f in fields(DiagnoseOptions) if f.name != "prior_odds"}
