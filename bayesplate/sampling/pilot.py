"""The pilot B run's model, and what is placed from its estimate: the box, the inputs' problem.

:func:`pilot_model` is the case on a mesh halved in each direction above
:data:`PILOT_MAX_ELEMENTS` elements; :func:`place_box` places the fast model's posterior box
from the pilot's estimate (``P`` widened by an inferred error scale, :func:`widened`, and of
the marginal problem where the inputs are marginalised); :func:`marginal` is that problem,
``J_p`` at a given point (the pilot's, then the MAP: :func:`~bayesplate.sampling.setup.prepare`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..likelihood.inputs import input_jacobian, input_sources
from ..likelihood.inputs_posterior import declared_readings, input_conditional
from ..plate.model import PlateModel
from .box import posterior_box

__all__ = ["PILOT_MAX_ELEMENTS", "marginal", "mesh_text", "pilot_model", "place_box", "widened"]

#: Meshes above this many elements get a pilot B run on a mesh halved in each direction.
PILOT_MAX_ELEMENTS = 400


def pilot_model(case, model, pilot_mesh):
    """The model of the pilot B run: the model itself, or the case on a coarser mesh."""
    if pilot_mesh is None:
        return model
    if pilot_mesh == "auto":
        mesh = model.mesh
        if mesh.nx * mesh.ny <= PILOT_MAX_ELEMENTS:
            return model
        pilot_mesh = (math.ceil(mesh.nx / 2), math.ceil(mesh.ny / 2))
    return PlateModel.from_case(case, mesh=tuple(pilot_mesh))


def marginal(case, model, problem, at):
    """The problem with the inputs marginalised (``J_p`` at `at`), full solves, conditional.

    The conditional is the readings'
    :class:`~bayesplate.likelihood.inputs_posterior.InputConditional` (None when every deviation is
    0). ``V_Y + B B^T`` with ``B = J_p A``: the arithmetic of
    :func:`bayesplate.likelihood.inputs.input_covariance`, to the bit.
    """
    names, A = input_sources(case.plate)
    modes = problem.pairing.modes
    if not np.any(A):
        return problem.with_observation_covariance(problem.V_Y + 0.0), 0, None
    J = input_jacobian(case, at, modes, mesh=(model.mesh.nx, model.mesh.ny)).J
    B = J @ A
    marginal = problem.with_observation_covariance(problem.V_Y + B @ B.T)
    _, value, sd = declared_readings(case.plate)
    conditional = input_conditional(J, A, problem.V_Y, names, value, sd, at)
    return marginal, 7, conditional  # the nominal solve and 3 central differences


def place_box(case, model, problem, pilot, inputs, box_sigma):
    """The (marginal) problem and the fast model's box from the pilot; full solves spent.

    With the inputs marginalised, the box is placed with ``P`` of the marginal problem at the
    pilot's ``b`` (one more full solve for the sensitivities): the pilot's own ``P`` ignores
    the inputs and would leave a box a few marginal deviations wide.
    """
    if inputs != "marginal":
        placed, spent = widened(problem, pilot)
        return problem, posterior_box(placed, problem.mu_b, problem.V_b, box_sigma), spent, None
    problem, spent, conditional = marginal(case, model, problem, pilot.b)
    S = problem.predict(pilot.b).S
    info = S.T @ np.linalg.solve(problem.V_Y, S) + np.linalg.inv(problem.V_b)
    placed, more = widened(problem, replace(pilot, covariance_b=np.linalg.inv(info)))
    box = posterior_box(placed, problem.mu_b, problem.V_b, box_sigma)
    return problem, box, spent + 1 + more, conditional


def widened(problem, pilot):
    """The pilot with ``P`` widened by an inferred error scale (linearised), full solves spent.

    With ``s`` unknown the posterior is ``s_hat`` times wider than ``P`` at ``s = 1``
    (:func:`bayesplate.likelihood.error_scale.linearised_scale`); a box placed with ``P`` would
    leave most walkers to the full model's fallback when the misfit is large.
    """
    if problem.error_scale is None:
        return pilot, 0
    from ..likelihood.error_scale import linearised_at

    return replace(pilot, covariance_b=linearised_at(problem, pilot.b).covariance_b), 1


def mesh_text(model):
    """``"nx x ny mesh"``: a model's mesh, for the messages."""
    return f"{model.mesh.nx} x {model.mesh.ny} mesh"
