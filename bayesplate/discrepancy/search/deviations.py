"""A pass's data: the paired peaks and their deviations, the mesh's own error folded in.

The mesh's error on every frequency is estimated by Richardson extrapolation from the half
mesh (the element converges as h^2) at the prior mean and reported beside the measurement
deviation; where it is not well under it, it (or the part of it the six constants cannot
absorb: :func:`.mesh_error.unabsorbed`) is added to the deviation in quadrature and a note
says so, so that discretisation is never blamed on physics.
"""

from __future__ import annotations

import numpy as np

from ...likelihood.posterior import observed_eigenvalues
from ...quantities import hz_from_eigenvalue
from .joint_fit import JointProblem
from .mesh_error import unabsorbed
from .state import Deviations

__all__ = ["deviations"]

_ERROR_SCALE_NOTE = (
    "the case gives an error scale for its deviations; diagnose tests against the declared "
    "deviations (s = 1), so a misfit the scale would absorb shows here as a mismatch"
)


def deviations(run, pairing):
    """The data of a pass with the assignment `pairing` (:class:`.state.Deviations`)."""
    measured, modes = pairing.select(run.case.measured), pairing.modes
    notes = []
    if getattr(run.case.measured, "error_scale", None) is not None:
        notes.append(_ERROR_SCALE_NOTE)
    at_fine, coarse_at_mean = _at_mean(run, int(modes.max()) + 1)
    fine_lam = at_fine.eigenvalues
    err = ((hz_from_eigenvalue(coarse_at_mean) - hz_from_eigenvalue(fine_lam)) / 3.0)[modes]
    sigma_Hz = np.asarray(measured.sigma_Hz, dtype=float)
    ratio = np.abs(err) / sigma_Hz
    run.say(f"mesh {run.model.mesh.nx} x {run.model.mesh.ny}: error up to {ratio.max():.2f} sigma")
    added, left, what = err, ratio.max(), "it was"
    if run.options.mesh_error_part == "unabsorbed":  # what the constants cannot take themselves
        added = unabsorbed(err, sigma_Hz, fine_lam[modes], at_fine.sensitivities[modes])
        left = np.abs(added / sigma_Hz).max()
        what = f"the part of it the constants cannot absorb (up to {left:.2f} sigma) was"
    if left > run.options.mesh_error_ratio:
        sigma_Hz = np.hypot(sigma_Hz, added)
        notes.append(
            f"the mesh's own error reaches {ratio.max():.2f} sigma (mode "
            f"{int(np.argmax(ratio)) + 1}); {what} added to the deviations in quadrature: "
            "use a finer [model] mesh"
        )
    Y = observed_eigenvalues(measured.frequency_Hz)
    sigma = 2.0 * Y * sigma_Hz / measured.frequency_Hz  # d lambda = 2 lambda df / f
    mu_b, V_b = run.prior
    problem = JointProblem(run.model, Y, sigma, mu_b, V_b, modes)
    return Deviations(
        measured,
        modes,
        sigma_Hz,
        err,
        Y,
        sigma,
        (fine_lam / coarse_at_mean)[modes],
        problem,
        tuple(notes),
    )


def _at_mean(run, n_solve):
    """Both meshes' lowest `n_solve` modes at the prior mean, solved once per run."""
    if n_solve not in run.at_mean:  # a second pass (another assignment) solves nothing again
        mu_b = run.prior[0]
        run.at_mean[n_solve] = (
            run.model.solve(mu_b, n_solve),
            run.coarse.solve(mu_b, n_solve).eigenvalues,
        )
    return run.at_mean[n_solve]
