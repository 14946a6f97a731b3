"""Certified reduced-basis forward model for fast repeated evaluation.

The stiffness is affine in the lamina coefficients, ``K(b) = K_0 + sum_j b_j K_j`` (eqs.
23-25; ``K_0`` is a stiffness that does not depend on ``b``, absent for the bare plate), and
the mass matrix does not depend on ``b``. A Rayleigh-Ritz projection on a fixed basis ``V``
of eigenvector snapshots, M-orthonormal, therefore turns every evaluation into a small dense
symmetric eigenproblem

    (V^T K_0 V + sum_j b_j V^T K_j V) x = lambda x,

whose ``r x r`` terms are computed once. Its eigenvalues are upper bounds of the finite-
element ones (Courant-Fischer), the mode shapes are ``V x`` and the sensitivities of eq. 28
are ``x^T (V^T K_j V) x``: no work of the size of the finite-element model per evaluation.

How the basis is built:

- snapshots are the lowest ``n_modes + margin`` elastic modes at a Latin-hypercube design
  over a box in ``b`` (by default the prior's 3-sigma box, cut to physical laminae) and at
  the prior mean; the margin keeps the top modes accurate where modes cross;
- the free plate's six rigid-body motions are part of the basis, so the reduced problem
  finds and drops its own rigid modes by the same two rules as the full model (near-zero
  eigenvalue, or mostly rigid shape);
- each batch of snapshots is M-orthogonalised against the basis and compressed by a
  proper orthogonal decomposition in the energy norm: directions carrying less than
  ``rank_tol**2`` of a snapshot's strain energy are dropped, which costs about that much
  relative accuracy in the eigenvalues;
- the reflections of the plate that leave every matrix unchanged (about the mid-lines, and
  about the mid-plane for a symmetric laminate; at least the half turn about the normal)
  split every snapshot into symmetry classes, each compressed on its own; no matrix couples
  two classes, so each is a separate, smaller eigenproblem.

The reduced model is certified empirically (:func:`certify`): held-out points of the box are
solved with the full model and the largest relative frequency error over the first
``n_modes`` modes is reported. The error is largest in small corners of the box (a soft
transverse shear modulus), which a few random points miss, so :func:`fast_model` adds probe
points where the model changed most with its last batch of snapshots, enriches the basis
greedily at the worst held-out points until the error is below the tolerance, and returns a
:class:`CertifiedModel` that falls back to the full model, with a warning, when the
certificate failed or a point lies outside the certified box.
"""

from .box import Box, prior_stiffness, stiffness_box
from .certified import CertifiedModel, ReducedModelWarning, fast_model
from .certify import DEFAULT_TOLERANCE, Certificate, certify, relative_errors
from .model import ReducedModalResult, ReducedModel
from .options import FastModelOptions

__all__ = [
    "DEFAULT_TOLERANCE",
    "Box",
    "Certificate",
    "CertifiedModel",
    "FastModelOptions",
    "ReducedModalResult",
    "ReducedModel",
    "ReducedModelWarning",
    "certify",
    "fast_model",
    "prior_stiffness",
    "relative_errors",
    "stiffness_box",
]
