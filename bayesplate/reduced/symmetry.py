"""Symmetry classes: the reflections of the plate that leave every matrix unchanged.

The reflections about the mid-lines ``x = a/2`` and ``y = b/2``, and about the mid-plane
for a symmetric laminate (at least the half turn about the normal), commute with every
``K_j``, ``M`` and any stiffness independent of ``b``. Their characters split every vector
into symmetry classes that no matrix couples: each class is a separate, smaller problem.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..fem.mesh import DOF_NAMES

# A reflection is a symmetry of the model when it commutes with every matrix to this
# relative accuracy (rounding is ~1e-15; a broken symmetry gives order one).
_SYMMETRY_TOL = 1e-9
# Sign of each nodal unknown under the reflections x -> a - x, y -> b - y and z -> -z (the
# mid-plane); unknowns not listed keep their sign.
_PARITY = {
    "x": ("u", "w_x", "w_xy", "psi_x"),
    "y": ("v", "w_y", "w_xy", "psi_y"),
    "z": ("w", "w_x", "w_y", "w_xy", "psi_x", "psi_y"),
}
# Fixed seed of the reference vector that fixes the sign of every basis vector, so that the
# same design gives the same basis whatever signs the eigensolver returns.
_SIGN_SEED = 461


def _symmetries(model):
    """Independent reflections of the plate that commute with all its matrices.

    Candidates are the reflections about the two mid-lines and the mid-plane and their
    products (the half turn about the normal is one); each is tried on a random vector
    against every ``K_j``, ``M`` and the constant stiffness, and must map the constrained
    unknowns onto themselves.

    Returns
    -------
    list of (numpy.ndarray of int, numpy.ndarray), each shape (n_dofs,)
        ``(perm, sign)`` with ``(S x)[d] = sign[d] * x[perm[d]]``; generators of the
        symmetry group, whose characters label the classes.
    """
    mats = [model.stiffness_term(j) for j in range(6)] + [model.mass]
    if model.extra_stiffness is not None:
        mats.append(model.extra_stiffness)
    x = np.random.default_rng(_SIGN_SEED).standard_normal(model.mesh.n_dofs)
    images = [A @ x for A in mats]
    fixed = np.zeros(model.mesh.n_dofs, dtype=bool)
    fixed[np.setdiff1d(np.arange(model.mesh.n_dofs), model.free_dofs)] = True
    generators, group = [], {(False, False, False)}
    for flags in itertools.product((False, True), repeat=3):
        if flags in group:
            continue
        perm, sign = _reflection(model.mesh, flags)
        commutes = all(
            np.linalg.norm(A @ (sign * x[perm]) - sign * Ax[perm])
            <= _SYMMETRY_TOL * np.linalg.norm(Ax)
            for A, Ax in zip(mats, images, strict=True)
        )
        if commutes and np.array_equal(fixed[perm], fixed):
            generators.append((perm, sign))
            group |= {tuple(a != f for a, f in zip(g, flags, strict=True)) for g in group}
    return generators


def _reflection(mesh, flags):
    """``(perm, sign)`` of the reflection about x = a/2, y = b/2, z = 0 where flagged."""
    i, j = np.meshgrid(np.arange(mesh.nx + 1), np.arange(mesh.ny + 1))
    if flags[0]:
        i = mesh.nx - i
    if flags[1]:
        j = mesh.ny - j
    image = (j * (mesh.nx + 1) + i).ravel()
    sign = np.ones(len(DOF_NAMES))
    for flag, axis in zip(flags, "xyz", strict=True):
        if flag:
            sign *= [-1.0 if name in _PARITY[axis] else 1.0 for name in DOF_NAMES]
    perm = (len(DOF_NAMES) * image[:, None] + np.arange(len(DOF_NAMES))).ravel()
    return perm, np.tile(sign, mesh.n_nodes)


def _by_class(X, symmetries):
    """Components of the columns of ``X`` in each symmetry class.

    Returns
    -------
    list of (int, numpy.ndarray)
        Class label (bit s set: odd under generator s) and ``P_c X``, for all ``2^s``
        classes.
    """
    parts = [(0, X)]
    for s, (perm, sign) in enumerate(symmetries):
        split = []
        for label, Y in parts:
            SY = sign[:, None] * Y[perm]
            split += [(label, 0.5 * (Y + SY)), (label | 1 << s, 0.5 * (Y - SY))]
        parts = split
    return parts


def _cross_coupling(terms, constant, reference, classes):
    """Largest ``|V_a^T K V_b|`` between classes over ``sqrt(E_a E_b)`` (0 for one class)."""
    weighted = list(reference[:, None, None] * terms)
    if constant is not None:
        weighted.append(constant)
    energy = np.abs(np.diag(np.sum(weighted, axis=0)))
    cross = classes[:, None] != classes[None, :]
    if not cross.any():
        return 0.0
    coupling = np.max([np.abs(W) for W in weighted], axis=0) / np.sqrt(np.outer(energy, energy))
    return float(coupling[cross].max())
