"""The population of plates of one material as a JSON document (``sample --hierarchical``).

Case-file units, as :mod:`bayesplate.io.export`: moduli in GPa under the keys of
:data:`bayesplate.quantities.ENGINEERING_KEYS`; the spreads ``tau`` are of ``ln c``
(dimensionless: 0.05 is about 5 % from plate to plate).
"""

from __future__ import annotations

from ..quantities import ENGINEERING_KEYS, to_case_units

__all__ = ["hierarchical_to_dict"]


def _summary(mean, sd, lo, hi, ess, rhat):
    return {
        "mean": float(mean),
        "sd": float(sd),
        "hdi_3%": float(lo),
        "hdi_97%": float(hi),
        "ess_bulk": float(ess),
        "r_hat": float(rhat),
    }


def _plate_document(hier, p, name, case):
    """One plate of :func:`hierarchical_to_dict`: shrunk constants beside its own answer."""
    shrunk, own = to_case_units(hier.plate_mean[p]), to_case_units(hier.own[p])
    lo, hi = to_case_units(hier.plate_hdi[0, p]), to_case_units(hier.plate_hdi[1, p])
    return {
        "name": name,
        "file": case.path,
        "outlier_probability": float(hier.outlier[p]),
        "refined": p in hier.refined,
        "shrunk": {
            k: {"mean": float(shrunk[i]), "hdi_3%": float(lo[i]), "hdi_97%": float(hi[i])}
            for i, k in enumerate(ENGINEERING_KEYS)
        },
        "own": {k: float(own[i]) for i, k in enumerate(ENGINEERING_KEYS)},
    }


def hierarchical_to_dict(hier, cases, timings=None):
    """The population of plates (a ``HierarchicalResult``) as a JSON document.

    Parameters
    ----------
    hier : bayesplate.sampling.HierarchicalResult
    cases : sequence of bayesplate.io.Case
        The plates, in the result's order (their files are named).
    timings : dict of str to float, optional
        Seconds of each stage.

    Returns
    -------
    dict
        ``mean`` (the material's constants, case units), ``spread`` (``tau`` of ``ln c``,
        dimensionless), ``plates`` (each one's shrunk constants, own answer and outlier
        probability), ``flagged``, ``chain`` and ``timings``.
    """
    mean, sd = to_case_units(hier.mean), to_case_units(hier.sd)
    lo, hi = to_case_units(hier.hdi[0]), to_case_units(hier.hdi[1])
    keys = ENGINEERING_KEYS
    tau = (hier.tau_mean, hier.tau_sd, hier.tau_hdi[0], hier.tau_hdi[1])
    chain = ("n_walkers", "n_steps", "n_burn", "tau_max", "ess_min", "rhat_max", "acceptance")
    return {
        "status": hier.status,
        "mean": {
            k: _summary(mean[i], sd[i], lo[i], hi[i], hier.ess[i], hier.rhat[i])
            for i, k in enumerate(keys)
        },
        "spread": {
            k: _summary(*(x[i] for x in tau), hier.ess[6 + i], hier.rhat[6 + i])
            for i, k in enumerate(keys)
        },
        "plates": [
            _plate_document(hier, p, name, case)
            for p, (name, case) in enumerate(zip(hier.names, cases, strict=True))
        ],
        "flagged": [hier.names[p] for p in hier.flagged],
        "chain": {**{k: getattr(hier, k) for k in chain}, "message": hier.message},
        "timings": {} if timings is None else {k: float(v) for k, v in timings.items()},
    }
