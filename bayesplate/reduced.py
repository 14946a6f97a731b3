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

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
import warnings
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.linalg as sla
from scipy.linalg import lapack
from scipy.stats import qmc

from . import laminate
from .fem.eigen import RIGID_TOL
from .fem.mesh import DOF_NAMES
from .model import ModalResult

__all__ = [
    "DEFAULT_TOLERANCE",
    "Box",
    "Certificate",
    "CertifiedModel",
    "ReducedModalResult",
    "ReducedModel",
    "ReducedModelWarning",
    "certify",
    "fast_model",
    "prior_stiffness",
    "stiffness_box",
]

log = logging.getLogger(__name__)

DEFAULT_TOLERANCE = 1e-4
"""Largest relative frequency error the certificate accepts (issue 4)."""

# Parts of snapshots with less energy than this fraction of rank_tol**2 (the components of
# a mode in the other symmetry classes, the remainder of a mode already in the basis) are
# rounding noise; they are left out of the compression.
_NEGLIGIBLE = 1e-2
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
# syevr (some pairs) beats syevd (all pairs) when fewer than 1/_SUBSET_FRACTION are wanted.
_SUBSET_FRACTION = 6
# Fixed seed of the reference vector that fixes the sign of every basis vector, so that the
# same design gives the same basis whatever signs the eigensolver returns.
_SIGN_SEED = 461


class ReducedModelWarning(UserWarning):
    """The reduced model is not used for an evaluation; the full model is used instead."""


# ----------------------------------------------------------------------------- the box


@dataclass(frozen=True, eq=False)
class Box:
    """Axis-aligned box of lamina stiffness coefficients inside the physical region.

    Parameters
    ----------
    lower, upper : array_like, shape (6,)
        Bounds of ``(C11, C22, C12, C66, C44, C55)`` in Pa, ``lower < upper``. Every point
        of the box must be a positive-definite lamina, which is checked at the worst corner.
    """

    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self):
        lower = np.array(self.lower, dtype=float)
        upper = np.array(self.upper, dtype=float)
        if lower.shape != (6,) or upper.shape != (6,):
            raise ValueError(f"box bounds have shapes {lower.shape}, {upper.shape}: need (6,)")
        if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
            raise ValueError("box bounds must be finite")
        if not np.all(lower < upper):
            raise ValueError(f"box lower {lower} must be below upper {upper}")
        worst = lower.copy()
        worst[2] = max(abs(lower[2]), abs(upper[2]))
        if not laminate.is_physical(worst):
            raise ValueError(f"box [{lower}, {upper}] reaches non-physical laminae")
        lower.setflags(write=False)
        upper.setflags(write=False)
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)

    @classmethod
    def from_covariance(cls, mean, cov, n_sigma=3.0, floor=0.1):
        """The ``n_sigma`` box of a Gaussian in ``b``, cut to physical laminae.

        Parameters
        ----------
        mean : array_like, shape (6,)
            Pa.
        cov : array_like, shape (6, 6)
            Pa^2; only the diagonal is used.
        n_sigma : float
            Half-width of the box in standard deviations.
        floor : float
            The positive coefficients (all but C12) are kept above ``floor * mean``: the
            3-sigma box of a wide prior reaches zero stiffness (G23 = 4 +- 4.5 GPa in the
            Frederiksen case). C12 is kept within 0.99 of ``sqrt(C11 C22)`` at the lower
            corner, so that the whole box is positive definite.

        Returns
        -------
        Box
        """
        mean = np.asarray(mean, dtype=float)
        sd = np.sqrt(np.diag(np.asarray(cov, dtype=float)))
        lower, upper = mean - n_sigma * sd, mean + n_sigma * sd
        positive = np.array([0, 1, 3, 4, 5])
        lower[positive] = np.maximum(lower[positive], floor * mean[positive])
        cap = 0.99 * math.sqrt(lower[0] * lower[1])
        lower[2], upper[2] = max(lower[2], -cap), min(upper[2], cap)
        return cls(lower, upper)

    @property
    def center(self):
        """Centre of the box, shape (6,), Pa."""
        return 0.5 * (self.lower + self.upper)

    def contains(self, b):
        """Whether points lie in the box (bounds included).

        Parameters
        ----------
        b : array_like, shape (..., 6)
            Pa.

        Returns
        -------
        bool or numpy.ndarray of bool, shape (...)
        """
        b = np.asarray(b, dtype=float)
        return np.all((b >= self.lower) & (b <= self.upper), axis=-1)

    def sample(self, n, rng, spacing="linear"):
        """Latin-hypercube design of ``n`` points in the box.

        Parameters
        ----------
        n : int
        rng : numpy.random.Generator or int
            Source of the design; the same generator state gives the same points.
        spacing : {"linear", "log"}
            Uniform strata in ``b`` or, for the coefficients whose bounds are positive, in
            ``log b``.

        Returns
        -------
        numpy.ndarray, shape (n, 6)
            Pa.
        """
        unit = qmc.LatinHypercube(d=6, rng=np.random.default_rng(rng)).random(int(n))
        points = self.lower + unit * (self.upper - self.lower)
        if spacing == "log":
            pos = self.lower > 0
            lo, hi = np.log(self.lower[pos]), np.log(self.upper[pos])
            points[:, pos] = np.exp(lo + unit[:, pos] * (hi - lo))
        elif spacing != "linear":
            raise ValueError(f"spacing = {spacing!r}: must be 'linear' or 'log'")
        return points


def prior_stiffness(prior):
    """The prior on the engineering constants carried over to ``b`` to first order.

    Parameters
    ----------
    prior : bayesplate.case.Prior
        Independent Gaussian on ``(E1, E2, nu12, G12, G13, G23)`` (SI).

    Returns
    -------
    mean : numpy.ndarray, shape (6,)
        ``b`` at the prior mean, Pa.
    cov : numpy.ndarray, shape (6, 6)
        ``J diag(sd^2) J^T`` with ``J = d b / d e`` at the mean, Pa^2.
    """
    mean_e = np.asarray(prior.mean, dtype=float)
    J = laminate.stiffness_jacobian(mean_e)
    cov = J @ np.diag(np.asarray(prior.sd, dtype=float) ** 2) @ J.T
    return laminate.stiffness_from_engineering(mean_e), cov


def stiffness_box(prior, n_sigma=3.0, floor=0.1):
    """The ``n_sigma`` box in ``b`` of a prior on the engineering constants.

    Parameters
    ----------
    prior : bayesplate.case.Prior
    n_sigma, floor : float
        See :meth:`Box.from_covariance`.

    Returns
    -------
    Box
    """
    mean, cov = prior_stiffness(prior)
    return Box.from_covariance(mean, cov, n_sigma, floor)


def _as_box(mean_b, box, n_sigma, floor):
    """A :class:`Box` from a box, an array of bounds (2, 6) or a covariance (6, 6)."""
    if isinstance(box, Box):
        return box
    box = np.asarray(box, dtype=float)
    if box.shape == (2, 6):
        return Box(box[0], box[1])
    if box.shape == (6, 6):
        return Box.from_covariance(mean_b, box, n_sigma, floor)
    raise ValueError(f"box has shape {box.shape}: give a Box, bounds (2, 6) or a covariance")


# ----------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class ReducedModalResult:
    """Elastic modes from the reduced model; the fields of :class:`~bayesplate.model.ModalResult`.

    Attributes
    ----------
    b : numpy.ndarray, shape (6,)
        ``(C11, C22, C12, C66, C44, C55)`` in Pa.
    eigenvalues : numpy.ndarray, shape (n,)
        Ritz values ``lambda = (2 pi f)^2`` in rad^2/s^2, upper bounds of the full model's.
    coefficients : numpy.ndarray, shape (r, n)
        Mode shapes in the basis, orthonormal: ``vectors = basis @ coefficients``.
    sensitivities : numpy.ndarray, shape (n, 6)
        ``d lambda_i / d b_j`` in rad^2/s^2 per Pa, exact for the reduced eigenvalues.
    rigid_eigenvalues : numpy.ndarray
        Eigenvalues of the reduced problem detected as rigid-body modes and dropped.
    basis : numpy.ndarray, shape (n_dofs, r)
        The reduced model's basis (shared, not copied).
    """

    b: np.ndarray
    eigenvalues: np.ndarray
    coefficients: np.ndarray
    sensitivities: np.ndarray
    rigid_eigenvalues: np.ndarray = field(repr=False)
    basis: np.ndarray = field(repr=False)

    frequency_Hz = ModalResult.frequency_Hz
    n_rigid = ModalResult.n_rigid
    normalised_sensitivities = ModalResult.normalised_sensitivities
    engineering_sensitivities = ModalResult.engineering_sensitivities

    @cached_property
    def vectors(self):
        """Mass-normalised mode shapes on all unknowns, shape (n_dofs, n), computed on access."""
        return self.basis @ self.coefficients

    def to_modal_result(self):
        """The same modes as a :class:`~bayesplate.model.ModalResult` (full vectors)."""
        return ModalResult(
            self.b, self.eigenvalues, self.vectors, self.sensitivities, self.rigid_eigenvalues
        )


@dataclass(frozen=True, eq=False)
class Certificate:
    """Accuracy of a reduced model at held-out points, against the full model.

    Attributes
    ----------
    max_rel_error : float
        Largest ``|f_reduced / f_full - 1|`` over the points and the first ``n_modes`` modes.
    per_mode_max : numpy.ndarray, shape (n_modes,)
        The same, mode by mode.
    n_test : int
        Number of held-out points, probes included.
    tolerance : float
        The bound the error was checked against.
    passed : bool
        ``max_rel_error < tolerance``.
    errors : numpy.ndarray, shape (n_test, n_modes)
        Signed relative frequency errors ``f_reduced / f_full - 1`` (non-negative up to
        rounding: Ritz values are upper bounds).
    points : numpy.ndarray, shape (n_test, 6)
        The held-out points, Pa.
    basis_size : int
        Number of basis vectors of the certified model.
    n_probe : int
        How many of the points (the last ones) were not drawn at random but chosen where
        the model is likeliest to be wrong (see :func:`fast_model`); 0 for a plain draw.
    """

    max_rel_error: float
    per_mode_max: np.ndarray
    n_test: int
    tolerance: float
    passed: bool
    errors: np.ndarray = field(repr=False)
    points: np.ndarray = field(repr=False)
    basis_size: int
    n_probe: int = 0

    @property
    def n_modes(self):
        """Number of modes checked."""
        return self.errors.shape[1]

    def __str__(self):
        verdict = "passed" if self.passed else "FAILED"
        probes = f" ({self.n_probe} of them probes)" if self.n_probe else ""
        return (
            f"certificate {verdict}: max relative frequency error {self.max_rel_error:.2e} "
            f"(tolerance {self.tolerance:.0e}) over {self.n_modes} modes at {self.n_test} "
            f"held-out points{probes}, basis of {self.basis_size}"
        )


# ----------------------------------------------------------------------------- the model


@dataclass(frozen=True, eq=False)
class ReducedModel:
    """Rayleigh-Ritz model on a fixed M-orthonormal basis; build it with :meth:`build`.

    Attributes
    ----------
    basis : numpy.ndarray, shape (n_dofs, r)
        M-orthonormal (``basis.T @ M @ basis = I``); the first ``n_rigid`` columns span the
        rigid-body motions.
    terms : numpy.ndarray, shape (6, r, r)
        ``basis.T @ K_j @ basis``, rad^2/s^2 per Pa.
    constant : numpy.ndarray, shape (r, r), or None
        ``basis.T @ K_0 @ basis`` for a stiffness independent of ``b``.
    box : Box
        Where the snapshots were taken and the model is meant to be used.
    n_modes : int
        Number of elastic modes the basis is built (and certified) for.
    margin : int
        Extra modes per snapshot.
    points : numpy.ndarray, shape (m, 6)
        Snapshot points, Pa.
    rank_tol : float
        Compression tolerance: fraction of a snapshot's energy norm below which directions
        are dropped.
    reference : numpy.ndarray, shape (6,)
        ``b`` of the energy inner product used to compress, Pa.
    n_rigid : int
        Rigid-body motions at the start of the basis (6 for a free plate, else 0).
    classes : numpy.ndarray of int, shape (r,)
        Symmetry class of each basis vector (see :attr:`block_sizes`).
    levels : tuple of int
        Basis size after each batch of snapshots (the rigid-body motions, each half of the
        initial design, each enrichment); the leading columns up to a level form the model
        of that stage.
    """

    basis: np.ndarray = field(repr=False)
    terms: np.ndarray = field(repr=False)
    constant: np.ndarray | None = field(repr=False)
    box: Box
    n_modes: int
    margin: int
    points: np.ndarray = field(repr=False)
    rank_tol: float
    reference: np.ndarray = field(repr=False)
    n_rigid: int
    classes: np.ndarray = field(repr=False)
    levels: tuple = ()

    def __post_init__(self):
        groups = [np.flatnonzero(self.classes == c) for c in np.unique(self.classes)]
        blocks = _Blocks(groups, self.terms, self.constant, self.n_rigid)
        object.__setattr__(self, "_blocks", blocks)

    @property
    def max_dropped_coupling(self):
        """Largest coupling between elastic basis vectors of two classes (rounding).

        A fraction of the geometric mean of their strain energies at ``reference``; the
        blocks leave these couplings out.
        """
        elastic = np.arange(self.n_rigid, self.size)
        return _cross_coupling(
            self.terms[:, elastic][:, :, elastic],
            None if self.constant is None else self.constant[np.ix_(elastic, elastic)],
            self.reference,
            self.classes[elastic],
        )

    @property
    def size(self):
        """Number of basis vectors r."""
        return self.basis.shape[1]

    @property
    def block_sizes(self):
        """Number of basis vectors in each symmetry class (no matrix couples two classes)."""
        return self._blocks.group_sizes

    @classmethod
    def build(
        cls,
        model,
        mean_b,
        box,
        n_modes,
        *,
        n_snapshots=16,
        margin=6,
        rng=None,
        rank_tol=2e-3,
        spacing="log",
        n_sigma=3.0,
        floor=0.1,
    ):
        """Snapshot basis at a space-filling design and the prior mean.

        Parameters
        ----------
        model : bayesplate.model.PlateModel
        mean_b : array_like, shape (6,)
            Prior mean of ``(C11, C22, C12, C66, C44, C55)``, Pa; always a snapshot point.
        box : Box or array_like, shape (2, 6) or (6, 6)
            The box (or its bounds, Pa), or the prior covariance of ``b`` (Pa^2) whose
            ``n_sigma`` box is used (see :meth:`Box.from_covariance` for ``floor``).
        n_modes : int
            Elastic modes to be reproduced.
        n_snapshots : int
            Design points besides the mean (Latin hypercube over the box).
        margin : int
            Extra modes computed at each snapshot point.
        rng : numpy.random.Generator or int, optional
            Seed of the design.
        rank_tol : float
            Compression tolerance in the energy norm; the eigenvalues lose about
            ``rank_tol**2`` relative accuracy. Use ~1e-7 to keep every snapshot exactly.
        spacing : {"log", "linear"}
            Strata of the design (see :meth:`Box.sample`). The mode shapes depend on the
            ratios of the coefficients only, and change fastest where one is small, so the
            default spreads the snapshots evenly in ``log b``.
        n_sigma, floor : float
            Used when ``box`` is a covariance.

        Returns
        -------
        ReducedModel
        """
        mean_b = np.asarray(mean_b, dtype=float)
        box = _as_box(mean_b, box, n_sigma, floor)
        design = box.sample(n_snapshots, np.random.default_rng(rng), spacing=spacing)
        points = np.vstack([mean_b, design])
        results = _solve_many(model, points, n_modes + margin)
        symmetries = _symmetries(model)
        rigid, classes = _rigid_basis(model, symmetries)
        stage = (rigid, classes, _project_terms(model, rigid, rigid))
        stage += (_project_constant(model, rigid, rigid),)
        levels = [rigid.shape[1]]
        # two batches, so that the model of the first half is there to compare with
        half = 1 + n_snapshots // 2
        for batch in (results[:half], results[half:]):
            if batch:
                snapshots = np.hstack([r.vectors for r in batch])
                stage = _grow(model, symmetries, *stage, snapshots, mean_b, rank_tol)
                levels.append(stage[0].shape[1])
        basis, classes, terms, constant = stage
        return cls(
            basis=basis,
            terms=terms,
            constant=constant,
            box=box,
            n_modes=int(n_modes),
            margin=int(margin),
            points=points,
            rank_tol=float(rank_tol),
            reference=mean_b,
            n_rigid=rigid.shape[1],
            classes=classes,
            levels=tuple(levels),
        )

    def enrich(self, model, points, results=None):
        """The model with the modes at more points added to its basis.

        Parameters
        ----------
        model : bayesplate.model.PlateModel
            The model the basis was built from.
        points : array_like, shape (k, 6)
            Pa.
        results : sequence of ModalResult, optional
            Full-model solutions at ``points`` with at least ``n_modes`` modes (computed with
            ``n_modes + margin`` modes if not given).

        Returns
        -------
        ReducedModel
            A new model whose basis contains this one's.
        """
        points = np.atleast_2d(np.asarray(points, dtype=float))
        if results is None:
            results = _solve_many(model, points, self.n_modes + self.margin)
        size = self.size
        basis, classes, terms, constant = _grow(
            model,
            _symmetries(model),
            self.basis,
            self.classes,
            self.terms,
            self.constant,
            np.hstack([r.vectors for r in results]),
            self.reference,
            self.rank_tol,
        )
        log.info(
            "reduced basis: %d + %d vectors from %d points", size, len(classes) - size, len(points)
        )
        return ReducedModel(
            basis=basis,
            terms=terms,
            constant=constant,
            box=self.box,
            n_modes=self.n_modes,
            margin=self.margin,
            points=np.vstack([self.points, points]),
            rank_tol=self.rank_tol,
            reference=self.reference,
            n_rigid=self.n_rigid,
            classes=classes,
            levels=(*self.levels, len(classes)),
        )

    def leading(self, size):
        """The model on the first ``size`` basis vectors (an earlier stage, see ``levels``).

        Parameters
        ----------
        size : int

        Returns
        -------
        ReducedModel
            Same box, points and settings; no work of the size of the full model.
        """
        return dataclasses.replace(
            self,
            basis=self.basis[:, :size],
            terms=self.terms[:, :size, :size],
            constant=None if self.constant is None else self.constant[:size, :size],
            classes=self.classes[:size],
            levels=tuple(n for n in self.levels if n <= size),
        )

    def solve(self, b, n_modes=None, vectors=False):
        """Lowest elastic modes and their sensitivities by Rayleigh-Ritz.

        Costs one batch of small dense eigenproblems; nothing of the size of the full model
        unless ``vectors`` is set (the result computes them on access anyway).

        Parameters
        ----------
        b : array_like, shape (6,)
            ``(C11, C22, C12, C66, C44, C55)`` in Pa.
        n_modes : int, optional
            At most ``n_modes + margin`` of the build; default ``n_modes`` of the build.
        vectors : bool
            Compute the full mode shapes now.

        Returns
        -------
        ReducedModalResult
        """
        n = self.n_modes if n_modes is None else int(n_modes)
        if not 0 < n <= self.n_modes + self.margin:
            raise ValueError(f"n_modes = {n}: this basis holds 1..{self.n_modes + self.margin}")
        b = np.asarray(b, dtype=float)
        values, where, index, pairs, rigid = self._blocks.lowest(b, n + self.n_rigid + 2)
        # the full model's two rules (fem.eigen.lowest_modes): near-zero, or mostly rigid
        rigid |= np.abs(values) <= RIGID_TOL * np.max(np.abs(values))
        elastic = np.flatnonzero(~rigid)[:n]
        if len(elastic) < n:
            raise ValueError(f"the basis of {self.size} vectors holds only {len(elastic)} modes")
        coefficients, sensitivities = self._blocks.modes(
            where[elastic], index[elastic], pairs, self.size
        )
        result = ReducedModalResult(
            b, values[elastic], coefficients, sensitivities, values[rigid], self.basis
        )
        if vectors:
            _ = result.vectors
        return result

    def eigenvalues(self, b, n_modes=None):
        """Lowest elastic eigenvalues only: the fastest path, for likelihoods without gradients.

        Equal to ``solve(b, n_modes).eigenvalues``; the eigenvectors are not computed when
        there is no stiffness independent of ``b``, so that the rigid modes are recognised by
        their near-zero eigenvalues alone.

        Parameters
        ----------
        b : array_like, shape (6,)
            ``(C11, C22, C12, C66, C44, C55)`` in Pa.
        n_modes : int, optional
            Default ``n_modes`` of the build.

        Returns
        -------
        numpy.ndarray, shape (n_modes,)
            rad^2/s^2.
        """
        n = self.n_modes if n_modes is None else int(n_modes)
        if not (self._blocks.rigid_at_zero and 0 < n <= self.n_modes + self.margin):
            return self.solve(b, n).eigenvalues
        values = self._blocks.lowest_values(np.asarray(b, dtype=float), n + self.n_rigid + 2)
        elastic = values[np.abs(values) > RIGID_TOL * np.max(np.abs(values))][:n]
        if len(elastic) < n:
            raise ValueError(f"the basis of {self.size} vectors holds only {len(elastic)} modes")
        return elastic


# ----------------------------------------------------------------------------- reduced problem


class _Blocks:
    """The reduced eigenproblem as independent blocks, small groups packed together.

    Groups of basis vectors that no term couples (the symmetry classes) are packed, largest
    first, into bins no larger than the largest group; each bin is one dense symmetric
    eigenproblem.

    Parameters
    ----------
    groups : list of numpy.ndarray of int
        Column indices of each group.
    terms : numpy.ndarray, shape (6, r, r)
    constant : numpy.ndarray, shape (r, r), or None
    n_rigid : int
        The first ``n_rigid`` columns are the rigid-body motions.
    """

    def __init__(self, groups, terms, constant, n_rigid):
        self.group_sizes = tuple(len(g) for g in groups)
        self.cols = _pack(groups)
        label = np.empty(terms.shape[1], dtype=int)
        for i, g in enumerate(groups):
            label[g] = i
        # groups packed into one bin are exactly decoupled: drop the rounding between them
        same = [label[c][:, None] == label[c][None, :] for c in self.cols]
        self.terms = [terms[:, c][:, :, c] * m for c, m in zip(self.cols, same, strict=True)]
        self.stacked = [T.reshape(6, -1) for T in self.terms]
        self.constant = [
            None if constant is None else constant[np.ix_(c, c)] * m
            for c, m in zip(self.cols, same, strict=True)
        ]
        self.on_rigid = [c < n_rigid for c in self.cols]
        # without a stiffness independent of b, K_j r = 0 for every rigid-body motion r: the
        # rigid modes are the near-zero eigenvalues, found without eigenvectors
        self.rigid_at_zero = constant is None

    @property
    def bin_sizes(self):
        """Sizes of the dense eigenproblems solved per evaluation."""
        return tuple(len(c) for c in self.cols)

    def lowest(self, b, k):
        """The ``k`` lowest eigenpairs over all bins, ascending.

        Returns
        -------
        values : numpy.ndarray, shape (k,)
        where, index : numpy.ndarray of int, shape (k,)
            Bin of each pair and its column in that bin's eigenvectors.
        vectors : list of numpy.ndarray, shape (size_c, k_c)
            Eigenvectors of each bin.
        rigid : numpy.ndarray of bool, shape (k,)
            Mostly rigid: M-projection on the rigid-body motions above one half.
        """
        values, where, index, vectors, rigid = [], [], [], [], []
        for c, (cols, S, C, on_rigid) in enumerate(
            zip(self.cols, self.stacked, self.constant, self.on_rigid, strict=True)
        ):
            A = (b @ S).reshape(len(cols), len(cols))
            if C is not None:
                A += C
            w, x = _lowest_eigh(A, min(k, len(cols)))
            values.append(w)
            where.append(np.full(len(w), c))
            index.append(np.arange(len(w)))
            vectors.append(x)
            rigid.append(np.sum(x[on_rigid] ** 2, axis=0) > 0.5)
        values = np.concatenate(values)
        order = np.argsort(values, kind="stable")[:k]
        return (
            values[order],
            np.concatenate(where)[order],
            np.concatenate(index)[order],
            vectors,
            np.concatenate(rigid)[order],
        )

    def lowest_values(self, b, k):
        """The ``k`` lowest eigenvalues over all bins, ascending, shape (k,)."""
        values = []
        for cols, S, C in zip(self.cols, self.stacked, self.constant, strict=True):
            A = (b @ S).reshape(len(cols), len(cols))
            if C is not None:
                A += C
            w, _, info = lapack.dsyev(A.T, compute_v=0, overwrite_a=1)
            if info != 0:
                raise np.linalg.LinAlgError(f"symmetric eigensolver failed (info = {info})")
            values.append(w[:k])
        return np.sort(np.concatenate(values))[:k]

    def modes(self, where, index, vectors, r):
        """Coefficients in the whole basis and sensitivities of some eigenpairs.

        Parameters
        ----------
        where, index : numpy.ndarray of int, shape (n,)
            Bin and column of each pair, as from :meth:`lowest`.
        vectors : list of numpy.ndarray
            Eigenvectors of each bin, as from :meth:`lowest`.
        r : int
            Basis size.

        Returns
        -------
        coefficients : numpy.ndarray, shape (r, n)
        sensitivities : numpy.ndarray, shape (n, 6)
            ``x^T T_j x`` (eq. 28 in the basis).
        """
        n = len(where)
        coefficients = np.zeros((r, n))
        sensitivities = np.empty((n, 6))
        for c in np.unique(where):
            sel = np.flatnonzero(where == c)
            x = vectors[c][:, index[sel]]
            size = len(x)
            Tx = (self.terms[c].reshape(6 * size, size) @ x).reshape(6, size, -1)
            sensitivities[sel] = np.einsum("jai,ai->ij", Tx, x)
            coefficients[np.ix_(self.cols[c], sel)] = x
        return coefficients, sensitivities


def _lowest_eigh(A, k):
    """Lowest ``k`` eigenpairs of a small dense symmetric matrix.

    LAPACK through SciPy (NumPy's ``eigh`` spawns threads that cost ten times the work on a
    busy machine): syevr for a few pairs of a larger matrix, syevd for all pairs otherwise
    (faster from about a sixth of the spectrum on).
    """
    # A is symmetric, so its transpose is the Fortran-ordered array LAPACK wants
    if k * _SUBSET_FRACTION <= len(A):
        w, x, m, _, info = lapack.dsyevr(A.T, compute_v=1, range="I", il=1, iu=k, overwrite_a=1)
    else:
        w, x, info = lapack.dsyevd(A.T, compute_v=1, overwrite_a=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"symmetric eigensolver failed (info = {info})")
    return w[:k], x[:, :k]


def _pack(groups):
    """Groups of columns packed first-fit, largest first, into bins of the largest size."""
    capacity = max(len(g) for g in groups)
    bins = []
    for g in sorted(groups, key=len, reverse=True):
        for b in bins:
            if len(b) + len(g) <= capacity:
                b.extend(g.tolist())
                break
        else:
            bins.append(g.tolist())
    return [np.array(b) for b in bins]


# ----------------------------------------------------------------------------- symmetry


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
    if getattr(model, "extra_stiffness_data", None) is not None:
        mats.append(model.assembler.matrix(model.extra_stiffness_data))
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


# ----------------------------------------------------------------------------- basis algebra


def _rigid_basis(model, symmetries):
    """M-orthonormal rigid-body motions of a free plate by class; none if supported.

    Returns
    -------
    basis : numpy.ndarray, shape (n_dofs, 6) or (n_dofs, 0)
    classes : numpy.ndarray of int, shape (6,) or (0,)
    """
    if model.boundary != "free":
        return np.zeros((model.mesh.n_dofs, 0)), np.zeros(0, dtype=int)
    M, R = model.mass, model.rigid_body_modes()
    R = _m_orthonormal(M, R)
    basis, classes = [], []
    for label, part in _by_class(R, symmetries):
        # each rigid motion (about the centre) lies in one class: keep the rank of the part
        w, U = np.linalg.eigh(part.T @ (M @ part))
        keep = w > 1e-8
        if keep.any():
            basis.append(_m_orthonormal(M, part @ U[:, keep]))
            classes += [label] * int(keep.sum())
    return _fix_signs(np.hstack(basis)), np.array(classes, dtype=int)


def _m_orthonormal(M, X):
    """Columns of ``X`` made M-orthonormal by Cholesky QR, twice."""
    for _ in range(2):
        G = X.T @ (M @ X)
        L = np.linalg.cholesky(0.5 * (G + G.T))
        X = sla.solve_triangular(L, X.T, lower=True).T
    return X


def _project_out(M, V, X):
    """``X`` minus its M-orthogonal projection on the M-orthonormal ``V``, twice."""
    for _ in range(2):
        X = X - V @ (V.T @ (M @ X))
    return X


def _grow(model, symmetries, basis, classes, terms, constant, snapshots, reference, rank_tol):
    """Basis, classes and projected terms with the new directions of ``snapshots`` appended.

    Returns
    -------
    basis : numpy.ndarray, shape (n_dofs, r + q)
    classes : numpy.ndarray of int, shape (r + q,)
    terms : numpy.ndarray, shape (6, r + q, r + q)
    constant : numpy.ndarray, shape (r + q, r + q), or None
    """
    new, labels = [], []
    for label, part in _by_class(_energy_normalised(model, snapshots, reference), symmetries):
        D = _new_directions(model, basis[:, classes == label], part, reference, rank_tol)
        new.append(D)
        labels += [label] * D.shape[1]
    new = np.hstack(new)
    basis = np.hstack([basis, new])
    classes = np.concatenate([classes, np.array(labels, dtype=int)])
    terms = _extend(terms, _project_terms(model, basis, new))
    if constant is not None:
        constant = _extend(constant[None], _project_constant(model, basis, new)[None])[0]
    return basis, classes, terms, constant


def _energy_normalised(model, snapshots, reference):
    """Snapshots scaled to unit strain energy at ``reference``."""
    K = model.stiffness(reference)
    return snapshots / np.sqrt(np.einsum("di,di->i", snapshots, K @ snapshots))


def _new_directions(model, V, S, reference, rank_tol):
    """New M-orthonormal basis vectors of one class, compressed in the energy norm.

    Parameters
    ----------
    model : PlateModel
    V : numpy.ndarray, shape (n_dofs, r_c)
        The M-orthonormal basis vectors of the class so far.
    S : numpy.ndarray, shape (n_dofs, k)
        The class's parts of snapshots of unit strain energy.
    reference : numpy.ndarray, shape (6,)
        ``b`` of the energy inner product.
    rank_tol : float
        Directions with less than ``rank_tol**2`` of a snapshot's energy are dropped.

    Returns
    -------
    numpy.ndarray, shape (n_dofs, q)
    """
    M, K = model.mass, model.stiffness(reference)
    S = _project_out(M, V, S)
    KS = K @ S
    keep = np.einsum("di,di->i", S, KS) > _NEGLIGIBLE * rank_tol**2
    if not keep.any():
        return np.zeros((V.shape[0], 0))
    S, KS = S[:, keep], KS[:, keep]
    w, U = np.linalg.eigh(S.T @ KS)  # proper orthogonal decomposition in the energy norm
    keep = w > rank_tol**2
    if not keep.any():
        return np.zeros((V.shape[0], 0))
    D = _project_out(M, V, S @ (U[:, keep] / np.sqrt(w[keep])))
    return _fix_signs(_m_orthonormal(M, D))


def _fix_signs(D):
    """Flip columns so that each has a positive product with a fixed random vector."""
    g = np.random.default_rng(_SIGN_SEED).standard_normal(D.shape[0])
    return D * np.where(g @ D < 0, -1.0, 1.0)


def _project_terms(model, basis, new):
    """``basis.T @ K_j @ new`` for the six terms, shape (6, r, q)."""
    return np.array([basis.T @ (model.stiffness_term(j) @ new) for j in range(6)])


def _project_constant(model, basis, new):
    """``basis.T @ K_0 @ new`` for the stiffness independent of ``b``, or None."""
    data = getattr(model, "extra_stiffness_data", None)
    if data is None:
        return None
    return basis.T @ (model.assembler.matrix(data) @ new)


def _extend(terms, columns):
    """Symmetric ``(t, r + q, r + q)`` from ``(t, r, r)`` and new columns ``(t, r + q, q)``."""
    t, r, _ = terms.shape
    n = columns.shape[1]
    out = np.empty((t, n, n))
    out[:, :r, :r] = terms
    out[:, :, r:] = columns
    out[:, r:, :r] = np.transpose(columns[:, :r, :], (0, 2, 1))
    out[:, r:, r:] = 0.5 * (out[:, r:, r:] + np.transpose(out[:, r:, r:], (0, 2, 1)))
    return out


# ----------------------------------------------------------------------------- full solves


def _solve_many(model, points, n_modes):
    """Full-model solutions at several points, in order.

    Serial on purpose: ARPACK's reverse communication and SuperLU's solves hold the GIL, so
    threads gave no speed-up (4 solves at 32 x 32: 4.9 s on two threads, 3.9 s serial).
    """
    return [model.solve(p, n_modes) for p in points]


# ----------------------------------------------------------------------------- certification


def _relative_errors(reduced, results, n_modes):
    """``f_reduced / f_full - 1`` at the points of ``results``, shape (k, n_modes)."""
    errors = []
    for r in results:
        ritz = reduced.solve(r.b, n_modes).eigenvalues
        errors.append(np.sqrt(ritz / r.eigenvalues[:n_modes]) - 1.0)
    return np.array(errors)


def _certify(model, reduced, points, tolerance, n_modes, n_solve, n_probe=0):
    """Certificate and the full solutions (with ``n_solve`` modes) at ``points``."""
    results = _solve_many(model, points, n_solve)
    errors = _relative_errors(reduced, results, n_modes)
    per_mode = np.max(np.abs(errors), axis=0)
    worst = float(per_mode.max())
    certificate = Certificate(
        max_rel_error=worst,
        per_mode_max=per_mode,
        n_test=len(points),
        tolerance=float(tolerance),
        passed=bool(worst < tolerance),
        errors=errors,
        points=np.asarray(points, dtype=float),
        basis_size=reduced.size,
        n_probe=int(n_probe),
    )
    return certificate, results


def certify(
    model,
    reduced,
    points=None,
    *,
    n_test=10,
    rng=None,
    tolerance=DEFAULT_TOLERANCE,
    n_modes=None,
):
    """Largest relative frequency error of a reduced model at held-out points.

    Parameters
    ----------
    model : bayesplate.model.PlateModel
        The full model the reduced one was built from.
    reduced : ReducedModel
    points : array_like, shape (k, 6), optional
        Held-out points, Pa; default ``n_test`` Latin-hypercube points of the box drawn from
        ``rng`` (a different design from the snapshots' if ``rng`` is not reused).
    n_test : int
    rng : numpy.random.Generator or int, optional
    tolerance : float
        Bound on ``max |f_reduced / f_full - 1|``.
    n_modes : int, optional
        Modes checked; default those the basis is built for.

    Returns
    -------
    Certificate
    """
    n = reduced.n_modes if n_modes is None else int(n_modes)
    if points is None:
        points = reduced.box.sample(n_test, np.random.default_rng(rng))
    points = np.atleast_2d(np.asarray(points, dtype=float))
    return _certify(model, reduced, points, tolerance, n, n)[0]


def fast_model(
    model,
    mean_b,
    box,
    n_modes,
    *,
    tolerance=DEFAULT_TOLERANCE,
    safety=1.0,
    n_snapshots=16,
    n_test=6,
    n_probe=4,
    n_candidates=256,
    n_add=3,
    max_rounds=4,
    max_basis=None,
    margin=6,
    rank_tol=2e-3,
    spacing="log",
    rng=None,
    n_sigma=3.0,
    floor=0.1,
):
    """Build, certify and greedily enrich a reduced model; wrap it with a full-model fallback.

    Each round certifies the current basis against the full model on ``n_test`` fresh
    Latin-hypercube points of the box and ``n_probe`` probe points; if the error is above
    ``safety * tolerance``, the modes at the (up to ``n_add``) worst of them, already
    computed, join the basis and the next round certifies again on fresh points.

    Parameters
    ----------
    model : bayesplate.model.PlateModel
    mean_b, box, n_modes, n_snapshots, margin, rank_tol, spacing, n_sigma, floor
        As for :meth:`ReducedModel.build`.
    tolerance : float
        Bound on the relative frequency error over the first ``n_modes`` modes.
    safety : float
        Enrichment goes on until the held-out error is below ``safety * tolerance`` (1:
        until the certificate passes; less for a margin). The certificate passes below
        ``tolerance``.
    n_test : int
        Held-out points per round drawn at random (Latin hypercube) from the box.
    n_probe : int
        Held-out points per round chosen among ``n_candidates`` random ones where the model
        changed most with its last batch of snapshots (its error is likeliest to be large
        there); they join the certificate, which a random draw alone makes optimistic (the
        error is largest in small corners of the box).
    n_candidates : int
        Candidates for the probes, evaluated with the reduced model only.
    n_add : int
        Points added per failed round.
    max_rounds : int
        Certification rounds at most.
    max_basis : int, optional
        Stop enriching once the basis would grow beyond this size.
    rng : numpy.random.Generator or int, optional
        Seed of every design; the same seed gives the same basis and certificate.

    Returns
    -------
    CertifiedModel
    """
    rng = np.random.default_rng(rng)
    reduced = ReducedModel.build(
        model,
        mean_b,
        box,
        n_modes,
        n_snapshots=n_snapshots,
        margin=margin,
        rng=rng,
        rank_tol=rank_tol,
        spacing=spacing,
        n_sigma=n_sigma,
        floor=floor,
    )
    n_solve = n_modes + margin
    history = []
    for round_ in range(1, max_rounds + 1):
        probes = _probe_points(reduced, n_probe, n_candidates, rng)
        points = np.vstack([reduced.box.sample(n_test, rng), probes])
        certificate, results = _certify(
            model, reduced, points, tolerance, n_modes, n_solve, n_probe=len(probes)
        )
        history.append(certificate)
        log.info("round %d: %s", round_, certificate)
        if certificate.max_rel_error < safety * tolerance or round_ == max_rounds:
            break
        worst = np.argsort(-np.max(np.abs(certificate.errors), axis=1), kind="stable")
        target = safety * tolerance
        worst = [i for i in worst[:n_add] if np.abs(certificate.errors[i]).max() >= target]
        enriched = reduced.enrich(model, points[worst], [results[i] for i in worst])
        if max_basis is not None and enriched.size > max_basis:
            log.info("basis cap %d reached (%d needed)", max_basis, enriched.size)
            break
        reduced = enriched
    return CertifiedModel(model, reduced, certificate, history)


def _probe_points(reduced, n_probe, n_candidates, rng):
    """Points of the box where the model changed most with its last batch of snapshots.

    Where the last batch moved the eigenvalues most, the basis is still converging, and the
    current model is likeliest to be wrong there too (a hierarchical error indicator; on the
    Frederiksen plate its logarithm correlates with that of the true error at 0.65 to 0.8).

    Returns
    -------
    numpy.ndarray, shape (n_probe, 6), or (0, 6) if there is no earlier stage
    """
    if n_probe <= 0 or len(reduced.levels) < 2:
        return np.empty((0, 6))
    earlier = reduced.leading(reduced.levels[-2])
    candidates = reduced.box.sample(n_candidates, rng)
    change = np.empty(len(candidates))
    for i, b in enumerate(candidates):
        try:
            ratio = earlier.eigenvalues(b) / reduced.eigenvalues(b)
        except ValueError:  # the earlier stage does not hold n_modes modes
            return np.empty((0, 6))
        change[i] = np.max(np.abs(np.sqrt(ratio) - 1.0))
    return candidates[np.argsort(-change, kind="stable")[:n_probe]]


# ----------------------------------------------------------------------------- the wrapper


class CertifiedModel:
    """Reduced model where it is certified, the full model elsewhere.

    ``solve`` uses the reduced model when its certificate passed, the point lies in the
    certified box and no more modes are asked than were certified; otherwise it uses the full
    model and counts the fallback. The first fallback of each kind is reported by
    ``logging`` and by one :class:`ReducedModelWarning`; repeats are only counted (and logged
    again at 10, 100, 1000, ... occurrences).

    Parameters
    ----------
    model : bayesplate.model.PlateModel
    reduced : ReducedModel
    certificate : Certificate
    history : sequence of Certificate, optional
        The certificates of every round of :func:`fast_model`, the last one included.

    Attributes
    ----------
    fallbacks : dict of str to int
        Full-model evaluations by reason: ``"uncertified"``, ``"outside_box"``,
        ``"n_modes"``.
    n_reduced : int
        Reduced-model evaluations.
    """

    def __init__(self, model, reduced, certificate, history=()):
        self.model = model
        self.reduced = reduced
        self.certificate = certificate
        self.history = tuple(history) or (certificate,)
        self.fallbacks = {"uncertified": 0, "outside_box": 0, "n_modes": 0}
        self.n_reduced = 0

    @property
    def certified(self):
        """Whether the certificate passed."""
        return bool(self.certificate.passed)

    @property
    def box(self):
        """The certified box."""
        return self.reduced.box

    @property
    def n_modes(self):
        """Number of certified modes."""
        return self.certificate.n_modes

    def solve(self, b, n_modes=None):
        """Lowest elastic modes and sensitivities, reduced if certified there.

        Parameters
        ----------
        b : array_like, shape (6,)
            ``(C11, C22, C12, C66, C44, C55)`` in Pa.
        n_modes : int, optional
            Default: the certified number.

        Returns
        -------
        ReducedModalResult or ModalResult
        """
        return self._dispatch(b, n_modes, self.reduced.solve, lambda full: full)

    def eigenvalues(self, b, n_modes=None):
        """Lowest elastic eigenvalues, reduced if certified there (fastest path).

        Parameters
        ----------
        b : array_like, shape (6,)
            ``(C11, C22, C12, C66, C44, C55)`` in Pa.
        n_modes : int, optional
            Default: the certified number.

        Returns
        -------
        numpy.ndarray, shape (n_modes,)
            rad^2/s^2.
        """
        return self._dispatch(b, n_modes, self.reduced.eigenvalues, lambda full: full.eigenvalues)

    def _dispatch(self, b, n_modes, reduced, from_full):
        """``reduced(b, n)`` where certified, else ``from_full`` of the full model's solve."""
        n = self.n_modes if n_modes is None else int(n_modes)
        reason = self._fallback_reason(b, n)
        if reason is None:
            self.n_reduced += 1
            return reduced(b, n)
        self._report(reason)
        return from_full(self.model.solve(np.asarray(b, dtype=float), n))

    def _fallback_reason(self, b, n):
        if not self.certified:
            return "uncertified"
        if n > self.n_modes:
            return "n_modes"
        if not self.box.contains(b):
            return "outside_box"
        return None

    def _report(self, reason):
        count = self.fallbacks[reason] = self.fallbacks[reason] + 1
        if count == 1:
            message = {
                "uncertified": f"reduced model not certified ({self.certificate}); "
                "evaluating with the full model",
                "outside_box": "point outside the certified box; evaluating with the full model",
                "n_modes": f"more modes asked than the {self.n_modes} certified; evaluating "
                "with the full model",
            }[reason]
            log.warning(message)
            warnings.warn(message, ReducedModelWarning, stacklevel=3)
        elif math.log10(count).is_integer():
            log.warning("%d full-model evaluations so far: %s", count, reason)
