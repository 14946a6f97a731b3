"""A pass's data: the paired peaks and their deviations, the mesh's own error folded in.

The mesh's error on every frequency is estimated by Richardson extrapolation from the half
mesh (the element converges as h^2) at the prior mean and reported beside the measurement
deviation; where it is not well under it, it (or the part of it the six constants cannot
absorb: :func:`.mesh_error.unabsorbed`) is added to the deviation in quadrature and a note
says so, so that discretisation is never blamed on physics. With ``mesh_error_part =
"corrected"`` the error (estimated with the mesh twice as fine) is taken out of the model
instead: the peaks are compared with what the working mesh would show for them, and only
what the correction leaves uncertain widens the deviations.
"""

from __future__ import annotations

import numpy as np

from ...likelihood.posterior import observed_eigenvalues
from ...quantities import hz_from_eigenvalue
from .joint_fit import JointProblem
from .mesh_error import finer_model, richardson, unabsorbed
from .state import Deviations

__all__ = ["deviations"]

_ERROR_SCALE_NOTE = (
    "the case gives an error scale for its deviations; diagnose tests against the declared "
    "deviations (s = 1), so a misfit the scale would absorb shows here as a mismatch"
)


def deviations(run, pairing, at=None):
    """The data of a pass with the assignment `pairing` (:class:`.state.Deviations`).

    `at`: the stiffness coefficients (Pa) where the corrected rule estimates the mesh's
    error (default: the prior mean); the working mesh's modes are taken in their order
    there, which moves as the constants do, so the pass estimates it again at its nominal
    fit (:func:`.passes.one_pass`).
    """
    measured, modes = pairing.select(run.case.measured), pairing.modes
    notes = []
    if getattr(run.case.measured, "error_scale", None) is not None:
        notes.append(_ERROR_SCALE_NOTE)
    at_fine, coarse_at_mean = _at_mean(run, int(modes.max()) + 1)
    fine_lam = at_fine.eigenvalues
    err = ((hz_from_eigenvalue(coarse_at_mean) - hz_from_eigenvalue(fine_lam)) / 3.0)[modes]
    sigma_Hz = np.asarray(measured.sigma_Hz, dtype=float)
    f = np.asarray(measured.frequency_Hz, dtype=float)
    scale = np.ones_like(f)  # the working mesh's frequency over the plate's, each mode
    if run.options.mesh_error_part == "corrected":
        err, scale, sigma_Hz, note = _corrected(run, modes, f, sigma_Hz, at)
    else:
        sigma_Hz, note = _widened(run, err, sigma_Hz, fine_lam[modes], at_fine.sensitivities[modes])
    notes += [note] if note else []
    Y = observed_eigenvalues(f * scale)  # what the working mesh would show for these peaks
    sigma = 2.0 * Y * sigma_Hz / f  # d lambda = 2 lambda df / f
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


def _widened(run, err, sigma_Hz, eigenvalues, sensitivities):
    """The deviations widened by the mesh's error (or the part the constants leave).

    Returns ``(sigma_Hz, note)``, the note None when the error is well under them.
    """
    ratio = np.abs(err) / sigma_Hz
    run.say(f"mesh {run.model.mesh.nx} x {run.model.mesh.ny}: error up to {ratio.max():.2f} sigma")
    added, left, what = err, ratio.max(), "it was"
    if run.options.mesh_error_part == "unabsorbed":  # what the constants cannot take themselves
        added = unabsorbed(err, sigma_Hz, eigenvalues, sensitivities)
        left = np.abs(added / sigma_Hz).max()
        what = f"the part of it the constants cannot absorb (up to {left:.2f} sigma) was"
    if left <= run.options.mesh_error_ratio:
        return sigma_Hz, None
    return np.hypot(sigma_Hz, added), (
        f"the mesh's own error reaches {ratio.max():.2f} sigma (mode "
        f"{int(np.argmax(ratio)) + 1}); {what} added to the deviations in quadrature: "
        "use a finer [model] mesh"
    )


def _corrected(run, modes, f, sigma_Hz, at=None):
    """The mesh's error taken out of the model, its correction's uncertainty into the deviations.

    The error is :func:`.mesh_error.richardson`'s with the mesh twice as fine, at `at` or
    the prior mean. Returns ``(error_Hz, scale, sigma_Hz, note)``, ``scale`` the working
    mesh's frequency over the corrected one (the peaks are compared times it).
    """
    working, finer = _both_meshes(run, int(modes.max()) + 1, at)
    working, finer = working[modes], finer[modes]
    err, u = richardson(working, finer)
    scale = working / (working - err)
    u_Hz = u / working * f  # relative, as the peaks are
    ratio, left = np.abs(err) / sigma_Hz, u_Hz / sigma_Hz
    run.say(
        f"mesh {run.model.mesh.nx} x {run.model.mesh.ny}: error up to {ratio.max():.2f} sigma, "
        f"corrected; {left.max():.2f} sigma left"
    )
    note = None
    if ratio.max() > run.options.mesh_error_ratio:
        note = (
            f"each computed frequency is corrected by its mesh's estimated error (up to "
            f"{ratio.max():.2f} sigma, mode {int(np.argmax(ratio)) + 1}: Richardson with the mesh "
            f"twice as fine); what the correction leaves uncertain (up to {left.max():.2f} sigma) "
            "is added to the deviations in quadrature"
        )
    return err, scale, np.hypot(sigma_Hz, u_Hz), note


def _both_meshes(run, n_solve, at=None):
    """The working mesh's and the finer mesh's lowest `n_solve` frequencies at `at`, Hz.

    `at` defaults to the prior mean, where both are solved once per run.
    """
    if "finer" not in run.at_mean:  # the mesh twice as fine, built once per run
        run.at_mean["finer"] = finer_model(run.model)
    finer = run.at_mean["finer"]
    if at is not None:
        return run.model.solve(at, n_solve).frequency_Hz, finer.solve(at, n_solve).frequency_Hz
    key = ("finer", n_solve)
    if key not in run.at_mean:
        run.at_mean[key] = finer.solve(run.prior[0], n_solve).frequency_Hz
    return _at_mean(run, n_solve)[0].frequency_Hz, run.at_mean[key]


def _at_mean(run, n_solve):
    """Both meshes' lowest `n_solve` modes at the prior mean, solved once per run."""
    if n_solve not in run.at_mean:  # a second pass (another assignment) solves nothing again
        mu_b = run.prior[0]
        run.at_mean[n_solve] = (
            run.model.solve(mu_b, n_solve),
            run.coarse.solve(mu_b, n_solve).eigenvalues,
        )
    return run.at_mean[n_solve]
