"""Step 2 of a pass, locate: which modes carry the misfit, what kind, where on the plate.

At the nominal fit: the kind of each mode (:func:`mode_kinds`), the location map of every
located candidate (its :meth:`~..physics.base.Physics.location_map`) and the best place over
them (:func:`best_region`), the measured modes whose standardised residual exceeds 2, and
the Ritz scan of every located candidate (its :meth:`~..physics.base.Physics.scan`). What
the six constants can absorb is projected out of the maps and the scans first. The stage
also gathers what every candidate's fit takes (:class:`.state.Fitting`).
"""

from __future__ import annotations

import numpy as np

from ...parallel import fork_map
from ..physics.base import mirror_positions
from ..physics.location import absorbable_projector
from ..physics.ritz_scan import RitzBasis
from .state import Fitting, Located

__all__ = ["RITZ_EXTRA_MODES", "best_region", "locate", "mode_kinds", "paired"]

#: Elastic modes of the Ritz basis of the scans beyond the highest paired one.
RITZ_EXTRA_MODES = 20

_KIND_BY_COEFFICIENT = {0: "bending along x", 1: "bending along y", 3: "torsion"}


def mode_kinds(model, result, threshold=0.6):
    """Name each mode by where its energy sits.

    A mode is ``in-plane`` when most of its kinetic energy is in ``u0, v0``; otherwise it is
    named by the stiffness coefficient that carries most of its strain energy (the
    normalised sensitivities of eq. 29 sum to one): C11 -> ``bending along x`` (plate x),
    C22 -> ``bending along y``, C66 -> ``torsion``; ``mixed`` when no share exceeds
    ``threshold``. For angle plies the names refer to the lamina coefficients.

    Parameters
    ----------
    model : PlateModel
    result : ModalResult

    Returns
    -------
    list of str, one per mode
    """
    phi = result.vectors
    inplane = np.zeros(model.mesh.n_dofs)
    inplane[np.concatenate([model.mesh.dofs("u"), model.mesh.dofs("v")])] = 1.0
    kinetic_inplane = np.einsum(
        "di,di->i", phi * inplane[:, None], model.mass @ (phi * inplane[:, None])
    )
    shares = result.normalised_sensitivities()
    kinds = []
    for k, s in zip(kinetic_inplane, shares, strict=True):
        j = int(np.argmax(s))
        if k > 0.5:
            kinds.append("in-plane")
        elif s[j] > threshold and j in _KIND_BY_COEFFICIENT:
            kinds.append(_KIND_BY_COEFFICIENT[j])
        else:
            kinds.append("mixed")
    return kinds


def best_region(model, maps):
    """The best located place over all maps (mm), with its mirror images; ``(None, [])``."""
    best = None
    for m in maps.values():
        i = m.best()
        if i is not None and (best is None or m.chi2_drop[i] > best[0]):
            best = (m.chi2_drop[i], tuple(float(v) for v in m.points_mm[i]))
    if best is None:
        return None, []
    return best[1], [tuple(float(v) for v in p) for p in mirror_positions(model, *best[1])]


def locate(run, data, nominal_stage):
    """Step 2 at the nominal fit of `nominal_stage` (:class:`.state.Located`)."""
    nominal, model, modes, sigma = nominal_stage.check.fit, run.model, data.modes, data.sigma
    kinds = mode_kinds(model, paired(nominal, modes))
    # what the constants can absorb, whitened: projected out of the maps and of the scans
    P = absorbable_projector(paired(nominal, modes).sensitivities * nominal.b / sigma[:, None])
    maps = _maps(run.physics, model, nominal, modes, sigma, P)
    region, mirrors = best_region(model, maps)
    located = [int(i) + 1 for i in np.flatnonzero(np.abs(nominal.residual_sigma) > 2.0)]
    n = int(modes.max()) + 1 + RITZ_EXTRA_MODES
    coarse_nominal = run.coarse.solve(nominal.b, n)
    ritz = model.solve(nominal.b, n)
    scans = _scans(run.physics, model, nominal, modes, data.Y, sigma, P, ritz, run.options.workers)
    mu_b, V_b = run.prior
    fitting = Fitting(
        model=model,
        coarse=run.coarse,
        Y=data.Y,
        sigma=sigma,
        mu_b=mu_b,
        V_b=V_b,
        modes=modes,
        nominal=nominal,
        scans=scans,
        say=run.say,
        stages=nominal_stage.stages,
        scale=nominal.eigenvalues / coarse_nominal.eigenvalues[modes],
        coarse_modes=coarse_nominal.vectors,
        ritz_modes=ritz.vectors,
        rough=nominal_stage.rough,
        margin=run.options.refine_margin,
        workers=run.options.workers,
        threshold=run.options.evidence_threshold,
    )
    return Located(kinds, maps, region, mirrors, located, fitting)


def paired(fit_, modes):
    """The fit's modal result restricted to the paired modes (measured order)."""
    modal = fit_.modal
    return type(modal)(
        modal.b,
        modal.eigenvalues[modes],
        modal.vectors[:, modes],
        modal.sensitivities[modes],
        modal.rigid_eigenvalues,
    )


def _maps(physics_list, model, nominal, modes, sigma, P):
    """Location maps of the located candidates at the nominal fit, keyed by name."""
    at_fit = paired(nominal, modes)
    r = nominal.residual_sigma
    maps = {}
    for physics in physics_list:
        location = physics.location_map(model, at_fit, nominal.b, r, sigma, P)
        if location is not None:
            maps[physics.name] = location
    return maps


def _scans(physics_list, model, nominal, modes, Y, sigma, P, ritz, workers=1):
    """Ritz scans of the located candidates at the nominal fit, keyed by name.

    The Ritz basis (:mod:`..physics.ritz_scan`) holds the nominal modes up to
    :data:`RITZ_EXTRA_MODES` beyond the highest paired one (``ritz``: the nominal fit's
    modes). The candidates' scans are independent: on ``workers`` processes
    (:func:`bayesplate.parallel.fork_map`).
    """
    basis = RitzBasis.from_modes(model, ritz)
    found = fork_map(
        lambda physics: physics.scan(model, basis, nominal.b, Y, sigma, modes, P),
        physics_list,
        workers,
    )
    return {
        physics.name: result
        for physics, result in zip(physics_list, found, strict=True)
        if result is not None
    }
