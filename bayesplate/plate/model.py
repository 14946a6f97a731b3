"""The forward model: lamina stiffness coefficients -> natural frequencies and sensitivities.

The plate stiffness is linear in the six lamina stiffness coefficients when all plies share
one material (eqs. 23-25), so it is assembled once as ``K(b) = sum_j b_j K_j``; the mass
matrix does not depend on ``b``. Sensitivities follow Fox and Kapoor (paper eq. 28):
``d lambda_i / d b_j = a_i^T K_j a_i`` for mass-normalised eigenvectors ``a_i``.
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp

from .. import laminate
from ..fem.assembly import Assembler
from ..fem.eigen import lowest_modes
from ..fem.element import TSDTRectangle
from ..fem.mesh import RectangularMesh
from ..fem.submatrix import SubPattern
from . import plate_bounds
from .modal import ModalResult

__all__ = ["BOUNDARIES", "DEFAULT_MESH", "ModalResult", "PlateModel"]  # ModalResult from .modal

BOUNDARIES = ("free", "simply_supported")
DEFAULT_MESH = (24, 12)


class PlateModel:
    """Finite-element model of one plate (geometry, layup, density) on one mesh.

    Parameters
    ----------
    length, width, thickness : float
        Plate sides and total thickness in m.
    density : float
        kg/m^3.
    layup_deg : sequence of float
        Ply angles from the bottom face upward, degrees.
    ply_thickness : sequence of float, optional
        m, one per ply; default equal plies.
    mesh : tuple of int
        Elements along x and y.
    boundary : {"free", "simply_supported"}
        Free-free (the test configuration) or SS-1 simple supports (for verification).
    shear_order : int, optional
        Gauss points per direction for the transverse-shear terms (default: exact, 4).

    Attributes
    ----------
    extra_stiffness_data : numpy.ndarray, shape (nnz,), or None
        CSR data of a stiffness ``K_0`` independent of ``b`` added to ``K(b)`` (a foundation,
        say; set by :meth:`modified`), or None for the bare plate.
    """

    def __init__(
        self,
        length,
        width,
        thickness,
        density,
        layup_deg,
        ply_thickness=None,
        mesh=DEFAULT_MESH,
        boundary="free",
        shear_order=None,
    ):
        if boundary not in BOUNDARIES:
            raise ValueError(f"boundary = {boundary!r}: must be one of {BOUNDARIES}")
        self.layup_deg = np.asarray(layup_deg, dtype=float)
        n_plies = len(self.layup_deg)
        if ply_thickness is None:
            ply_thickness = np.full(n_plies, thickness / n_plies)
        self.ply_thickness = np.asarray(ply_thickness, dtype=float)
        self.thickness = float(thickness)
        self.density = float(density)
        self.boundary = boundary
        self.mesh = RectangularMesh(float(length), float(width), int(mesh[0]), int(mesh[1]))
        self.element = TSDTRectangle(self.mesh.dx, self.mesh.dy, shear_order=shear_order)
        self.assembler = Assembler(self.mesh.element_dofs, self.mesh.n_dofs)
        element_terms = self.element_stiffness_terms()
        self.stiffness_terms = self.assembler.uniform_data(element_terms)
        # the same K_j^e on every element: sensitivities element by element (see there)
        self._uniform_terms = (self.stiffness_terms, element_terms)
        self.mass_data = self.assembler.uniform_data(self.element_mass())
        self.extra_stiffness_data = None
        self._sparse = {}  # the assembled matrices of :meth:`_pruned`, by name
        self.free_dofs = self._free_dofs()
        self._ordering = self._free_ordering()
        self._rigid_basis = self._rigid_basis_on_free_dofs()
        self._parts = None  # index maps to the free-dof matrices, built on the first solve
        #: Solve in-plane and bending unknowns apart when K and M do not couple them (see
        #: :meth:`_decoupled`): the same modes at about half the cost (reports/
        #: benchmark_forward.md). The in-plane modes' w is then exactly zero, not round-off;
        #: the MAC (pairing.mac_matrix) counts both as no shape.
        self.split_decoupled = True

    @classmethod
    def from_case(cls, case, mesh=None, **kwargs):
        """Model of a :class:`bayesplate.io.Case`, on ``mesh`` or the case's own mesh."""
        p = case.plate
        return cls(
            p.length,
            p.width,
            p.thickness,
            p.density,
            p.layup_deg,
            p.ply_thickness,
            mesh=mesh or case.mesh or DEFAULT_MESH,
            **kwargs,
        )

    def on_mesh(self, mesh):
        """The same plate (geometry, layup, density, boundary, element) on ``mesh``, (nx, ny)."""
        return type(self)(
            self.mesh.a,
            self.mesh.b,
            self.thickness,
            self.density,
            self.layup_deg,
            self.ply_thickness,
            mesh=mesh,
            boundary=self.boundary,
            shear_order=self.element.shear_order,
        )

    def laminate(self, b, thickness_scale=1.0, angle_offset_deg=0.0):
        """Laminate integrals of eqs. 24-25 for stiffness coefficients ``b``.

        ``thickness_scale`` scales every ply (a locally thicker or thinner plate) and
        ``angle_offset_deg`` turns every ply by the same angle.
        """
        return laminate.laminate_matrices(
            b, self.layup_deg + angle_offset_deg, self.ply_thickness * thickness_scale
        )

    def element_stiffness_terms(self, thickness_scale=1.0, angle_offset_deg=0.0):
        """Element matrices ``K_j^e`` of a unit value of each coefficient, shape (6, 32, 32).

        See :meth:`laminate` for the optional arguments.
        """
        C = np.array(
            [
                laminate.constitutive_matrix(self.laminate(e, thickness_scale, angle_offset_deg))
                for e in np.eye(6)
            ]
        )
        return self.element.stiffness(C)

    def element_mass(self, thickness_scale=1.0):
        """Consistent element mass with all inertias I0..I6, shape (32, 32)."""
        plies = self.ply_thickness * thickness_scale
        moments = laminate.inertias(self.density, plies)
        c = laminate.higher_order_coefficient(plies.sum())
        return self.element.mass(laminate.inertia_matrix(moments, c))

    def modified(self, stiffness_terms=None, mass_data=None, extra_stiffness_data=None):
        """A copy of the model with some assembled matrices replaced (same mesh and pattern).

        Parameters
        ----------
        stiffness_terms : numpy.ndarray, shape (6, nnz), optional
            CSR data of the ``K_j``.
        mass_data : numpy.ndarray, shape (nnz,), optional
            CSR data of ``M``.
        extra_stiffness_data : numpy.ndarray, shape (nnz,), optional
            CSR data of a stiffness independent of ``b`` (a foundation, say), added to
            ``K(b)``.

        Returns
        -------
        PlateModel
        """
        other = copy.copy(self)
        other._sparse = {}
        if stiffness_terms is not None:
            other.stiffness_terms = np.asarray(stiffness_terms)
        if mass_data is not None:
            other.mass_data = np.asarray(mass_data)
        if extra_stiffness_data is not None:
            other.extra_stiffness_data = np.asarray(extra_stiffness_data)
        return other

    def stiffness(self, b):
        """Assembled ``K(b) = sum_j b_j K_j`` (+ any extra stiffness; CSR, all unknowns)."""
        return self.assembler.matrix(self._stiffness_data(b))

    def stiffness_term(self, j):
        """Assembled ``K_j = d K / d b_j`` (CSR, all unknowns, its exact zeros left out)."""
        return self._pruned(("K", j), self.stiffness_terms, self.stiffness_terms[j])

    @property
    def extra_stiffness(self):
        """Assembled stiffness independent of ``b`` (CSR, as ``K_j``), or None."""
        data = self.extra_stiffness_data
        return None if data is None else self._pruned("K0", data, data)

    @property
    def mass(self):
        """Assembled consistent mass matrix (CSR, as ``K_j``)."""
        return self._pruned("M", self.mass_data, self.mass_data)

    def _pruned(self, name, source, data):
        """``Assembler.sparse(data)``, built once while ``source`` is the model's array.

        A modified copy starts afresh. The matrix is shared: not to be changed in place.
        """
        kept = self._sparse.get(name)
        if kept is None or kept[0] is not source:
            self._sparse[name] = kept = (source, self.assembler.sparse(data))
        return kept[1]

    def _free_dofs(self):
        """Unknowns left free by the boundary conditions."""
        fixed = []
        if self.boundary == "simply_supported":
            m = self.mesh
            for edge, names in (
                ("x0", ("v", "w", "w_y", "psi_y")),
                ("xa", ("v", "w", "w_y", "psi_y")),
                ("y0", ("u", "w", "w_x", "psi_x")),
                ("yb", ("u", "w", "w_x", "psi_x")),
            ):
                fixed += [m.dofs(n, m.edge_nodes(edge)) for n in names]
        fixed = np.unique(np.concatenate(fixed)) if fixed else np.array([], dtype=int)
        return np.setdiff1d(np.arange(self.mesh.n_dofs), fixed)

    def _free_ordering(self):
        """Nested-dissection order of the free unknowns, as positions in ``free_dofs``."""
        position = np.full(self.mesh.n_dofs, -1)
        position[self.free_dofs] = np.arange(len(self.free_dofs))
        order = position[self.mesh.nested_dissection()]
        return order[order >= 0]

    def rigid_body_modes(self):
        """The six rigid-body motions of the free plate on all unknowns, shape (n_dofs, 6).

        Translations along x, y, z; rotations about y (``w = x``, ``psi_x = -1``) and x
        (``w = y``, ``psi_y = -1``), for which every strain of eq. 15 vanishes; and the
        in-plane rotation ``u = -y``, ``v = x``.
        """
        m = self.mesh
        x, y = m.nodes.T
        R = np.zeros((m.n_dofs, 6))
        R[m.dofs("u"), 0] = 1.0
        R[m.dofs("v"), 1] = 1.0
        R[m.dofs("w"), 2] = 1.0
        R[m.dofs("w"), 3], R[m.dofs("w_x"), 3], R[m.dofs("psi_x"), 3] = x, 1.0, -1.0
        R[m.dofs("w"), 4], R[m.dofs("w_y"), 4], R[m.dofs("psi_y"), 4] = y, 1.0, -1.0
        R[m.dofs("u"), 5], R[m.dofs("v"), 5] = -y, x
        return R

    def _rigid_basis_on_free_dofs(self):
        """M-orthonormal basis of the rigid-body motions the supports allow, or None."""
        if self.boundary != "free":
            return None
        R = self.rigid_body_modes()
        G = R.T @ (self.mass @ R)
        return R @ np.linalg.inv(np.linalg.cholesky(G)).T

    def spectral_shift(self, b):
        """Spectral shift, a tenth of a plate-bending estimate of the lowest eigenvalue."""
        D = self.laminate(b).Cf[2]
        I0 = laminate.inertias(self.density, self.ply_thickness)[0]
        span = max(self.mesh.a, self.mesh.b)
        return -0.1 * (np.pi / span) ** 4 * min(D[0, 0], D[1, 1], D[2, 2]) / I0

    def lowest_eigenvalue_bound(self, b):
        """Rayleigh-Ritz bound of the lowest elastic eigenvalue, rad^2/s^2, no solve.

        :func:`bayesplate.plate.plate_bounds.lowest_eigenvalue_bound` of this plate.
        """
        return plate_bounds.lowest_eigenvalue_bound(
            self.laminate(b),
            laminate.inertias(self.density, self.ply_thickness)[0],
            self.mesh.a,
            self.mesh.b,
            self.boundary,
        )

    def solve(self, b, n_modes=14, method="block"):
        """Lowest ``n_modes`` elastic modes and their sensitivities.

        Parameters
        ----------
        b : array_like, shape (6,)
            ``(C11, C22, C12, C66, C44, C55)`` in Pa.
        n_modes : int
        method : {"block", "arpack"}
            Eigensolver (:func:`bayesplate.fem.eigen.lowest_modes`).

        Returns
        -------
        ModalResult
        """
        b = np.asarray(b, dtype=float)
        k_data = self._stiffness_data(b)
        shift = self.spectral_shift(b)
        parts = [self._free_part()]
        if method == "block" and self.split_decoupled and self._decoupled(k_data):
            parts = sorted(self._split_parts(), key=lambda part: -len(part["pattern"].dofs))
        values, shapes, rigid_values = [], [], []
        bound = np.inf  # the largest eigenvalue the merged n_modes can reach
        for part in parts:
            # the first part's n_modes bound the others: of those, only the modes below
            # the bound can count, so ask for 2, 4, ... until one lies above it
            wanted = n_modes if np.isinf(bound) else min(2, n_modes)
            while True:
                sol = self._solve_part(part, k_data, shift, wanted, method)
                found = sol.eigenvalues
                if len(found) < wanted or wanted >= n_modes or found[-1] > bound:
                    break
                wanted = min(2 * wanted, n_modes)
            if len(found) == n_modes:
                bound = min(bound, found[-1])
            values.append(found)
            rigid_values.append(sol.rigid_eigenvalues)
            vectors = np.zeros((self.mesh.n_dofs, len(found)))
            vectors[part["pattern"].dofs] = sol.vectors
            shapes.append(vectors)
        values = np.concatenate(values)
        keep = np.argsort(values, kind="stable")[:n_modes]
        vectors = np.hstack(shapes)[:, keep]
        return ModalResult(
            b,
            values[keep],
            vectors,
            self.sensitivities(vectors),
            np.sort(np.concatenate(rigid_values)),
        )

    def _solve_part(self, part, k_data, shift, n_modes, method):
        """:func:`lowest_modes` on the unknowns of one part (see :meth:`_part`)."""
        pattern = part["pattern"]
        data, mass = part["mass"]
        if data is not self.mass_data:
            mass = pattern.blocked(self.mass_data)
            part["mass"] = (self.mass_data, mass)
        rigid = None
        if self._rigid_basis is not None:
            rigid = self._rigid_basis[pattern.dofs][:, part["rigid"]]
        return lowest_modes(
            pattern.csr(k_data),
            mass,
            n_modes,
            shift,
            n_rigid_max=0 if rigid is None else rigid.shape[1],
            ordering="given",
            rigid_basis=rigid,
            method=method,
            shifted=pattern.csc(k_data - shift * self.mass_data),
        )

    def _stiffness_data(self, b):
        """CSR data of ``K(b)`` on all unknowns, shape (nnz,)."""
        data = sum(bj * term for bj, term in zip(b, self.stiffness_terms, strict=True))
        if self.extra_stiffness_data is not None:
            data = data + self.extra_stiffness_data
        return data

    def _part(self, dofs):
        """Index maps to the matrices on ``dofs``, the rigid motions living there only."""
        part = {"pattern": SubPattern(self.assembler, dofs), "rigid": None, "mass": (None, None)}
        if self._rigid_basis is not None:
            outside = np.ones(self.mesh.n_dofs, dtype=bool)
            outside[dofs] = False
            part["rigid"] = np.flatnonzero(~np.any(self._rigid_basis[outside], axis=0))
        return part

    def _free_part(self):
        """All free unknowns in nested-dissection order, built on the first solve."""
        if self._parts is None:
            self._parts = {"all": self._part(self.free_dofs[self._ordering])}
        return self._parts["all"]

    def _split_parts(self):
        """The free in-plane (u, v) and bending unknowns apart, built once."""
        dofs = self._free_part()["pattern"].dofs
        if "split" not in self._parts:
            in_plane = dofs % 8 < 2
            self._parts["split"] = [self._part(dofs[in_plane]), self._part(dofs[~in_plane])]
        return self._parts["split"]

    def _decoupled(self, k_data):
        """Whether K(b) and M have no entry coupling in-plane and bending unknowns.

        True for a symmetric laminate (no B, no odd inertias) whose supports treat the two
        alike, and whose every rigid motion is either in-plane or bending: the eigenproblem
        is then two smaller ones, solved apart (the same modes, at about half the cost).
        """
        self._free_part()
        if "coupling" not in self._parts:
            rows = np.repeat(np.arange(self.mesh.n_dofs), np.diff(self.assembler.indptr))
            in_plane = np.arange(self.mesh.n_dofs) % 8 < 2
            across = in_plane[rows] != in_plane[self.assembler.indices]
            self._parts["coupling"] = np.flatnonzero(across)
        coupling = self._parts["coupling"]
        if np.any(k_data[coupling]) or np.any(self.mass_data[coupling]):
            return False
        if self._rigid_basis is None:
            return True
        n_rigid = sum(len(part["rigid"]) for part in self._split_parts())
        return n_rigid == self._rigid_basis.shape[1]

    def eigenvalues(self, b, n_modes=14):
        """Lowest `n_modes` elastic eigenvalues at `b`, rad^2/s^2, shape (n_modes,).

        The :class:`bayesplate.plate.forward.ForwardModel` interface: the full model has no cheaper
        path than :meth:`solve`.
        """
        return self.solve(b, n_modes).eigenvalues

    def interpolation(self, points, field="w"):
        """Sparse matrix evaluating one field of a nodal vector at points on the plate.

        Parameters
        ----------
        points : array_like, shape (p, 2)
            ``(x, y)`` in m.
        field : str
            ``"w"`` (default), ``"u"``, ``"v"``, ``"psi_x"``, ``"psi_y"`` or a derivative of w
            (``"w_x"``, ``"w_y"``).

        Returns
        -------
        scipy.sparse.csr_matrix, shape (p, n_dofs)
            ``interpolation(points) @ vectors`` gives the field at the points.
        """
        element, local = self.mesh.locate(points)
        values = self.element.fields(local, (field,))[field]  # (p, 32), all points at once
        rows = np.repeat(np.arange(len(element)), values.shape[1])
        cols = self.mesh.element_dofs[element].ravel()
        shape = (len(element), self.mesh.n_dofs)
        return sp.csr_matrix((values.ravel(), (rows, cols)), shape=shape)

    def point_values(self, points, vectors, field="w"):
        """Fields of nodal vectors at points on the plate: ``interpolation(points) @ vectors``.

        Parameters
        ----------
        points : array_like, shape (p, 2)
            ``(x, y)`` in m.
        vectors : numpy.ndarray, shape (n_dofs, n)
        field : str or tuple of str
            As :meth:`interpolation`'s; a tuple gives each of its fields.

        Returns
        -------
        numpy.ndarray, shape (p, n), or (len(field), p, n) for a tuple
        """
        names = (field,) if isinstance(field, str) else tuple(field)
        element, local = self.mesh.locate(points)
        values = self.element.fields(local, names)  # each (p, 32)
        at = vectors[self.mesh.element_dofs[element]]  # (p, 32, n)
        out = np.array([np.einsum("pa,pan->pn", values[name], at) for name in names])
        return out[0] if isinstance(field, str) else out

    def sensitivities(self, vectors):
        """``d lambda_i / d b_j = a_i^T K_j a_i`` for mass-normalised ``a_i``, shape (n, 6).

        While the model's ``K_j`` are those it was built with, every element has the same
        ``K_j^e`` and ``a^T K_j a = sum_e a_e^T K_j^e a_e = <K_j^e, S>`` with the 32 x 32
        ``S = sum_e a_e a_e^T`` of each mode: small dense products. Otherwise (terms
        replaced by :meth:`modified`) the six ``K_j``, which share one pattern, are stacked
        into one ``(6 n_dofs, n_dofs)`` CSR matrix for one sparse product.
        """
        vectors = np.asarray(vectors, dtype=float)
        data, element_terms = self._uniform_terms
        if self.stiffness_terms is data:
            local = vectors[self.mesh.element_dofs]  # (n_elements, 32, n)
            local = np.ascontiguousarray(local.transpose(2, 1, 0))  # (n, 32, n_elements)
            S = local @ local.transpose(0, 2, 1)  # (n, 32, 32)
            return np.einsum("jab,iab->ij", element_terms, S)
        n, nnz = self.mesh.n_dofs, self.assembler.nnz
        terms = np.ascontiguousarray(self.stiffness_terms).reshape(-1)
        indices = np.tile(self.assembler.indices, 6)
        indptr = np.concatenate(
            [self.assembler.indptr[:-1] + j * nnz for j in range(6)] + [[6 * nnz]]
        )
        stacked = sp.csr_matrix((terms, indices, indptr), shape=(6 * n, n))
        products = (stacked @ vectors).reshape(6, n, -1)
        return np.einsum("jdi,di->ij", products, vectors)
