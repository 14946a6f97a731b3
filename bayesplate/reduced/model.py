"""The reduced model: Rayleigh-Ritz on a fixed M-orthonormal basis of snapshots.

:class:`ReducedModel` builds its basis from full-model snapshots at a design over the box
(:meth:`ReducedModel.build`), grows it (:meth:`ReducedModel.enrich`) and evaluates the lowest
elastic modes and their sensitivities with small dense eigenproblems only
(:meth:`ReducedModel.solve`, :meth:`ReducedModel.eigenvalues`): the
:class:`bayesplate.plate.forward.ForwardModel` interface, with the mesh and mass matrix of the full
model it was built from. :class:`ReducedModalResult` is what it returns.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..fem.eigen import RIGID_TOL
from ..plate.model import ModalResult
from .basis import _grow, _project_constant, _project_terms, _rigid_basis, _solve_many
from .blocks import _Blocks
from .box import Box, _as_box
from .symmetry import _cross_coupling, _symmetries

__all__ = ["ReducedModalResult", "ReducedModel"]

# the package's logger (the name the report and the tests listen to)
log = logging.getLogger(__package__)


@dataclass(frozen=True, eq=False)
class ReducedModalResult:
    """Elastic modes from the reduced model; the fields of :class:`ModalResult`.

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
        """The same modes as a :class:`~bayesplate.plate.model.ModalResult` (full vectors)."""
        return ModalResult(
            self.b, self.eigenvalues, self.vectors, self.sensitivities, self.rigid_eigenvalues
        )


@dataclass(frozen=True, eq=False)
class ReducedModel:
    """Rayleigh-Ritz model on a fixed M-orthonormal basis; build it with :meth:`build`.

    A :class:`bayesplate.plate.forward.ForwardModel`: :attr:`mesh` and :attr:`mass` are those of the
    full model the basis was built from, on whose unknowns the mode shapes live.

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
    full_model : bayesplate.plate.model.PlateModel
        The full model the basis was built from (keyword only; referenced, not copied).
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
    full_model: object = field(repr=False, kw_only=True)

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
    def mesh(self):
        """The full model's mesh, on whose unknowns the mode shapes live."""
        return self.full_model.mesh

    @property
    def mass(self):
        """The full model's mass matrix (CSR, all unknowns), shape (n_dofs, n_dofs)."""
        return self.full_model.mass

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
        model : bayesplate.plate.model.PlateModel
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
            full_model=model,
        )

    def enrich(self, model, points, results=None):
        """The model with the modes at more points added to its basis.

        Parameters
        ----------
        model : bayesplate.plate.model.PlateModel
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
            full_model=model,
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
