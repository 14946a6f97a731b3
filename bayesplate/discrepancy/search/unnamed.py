"""The rival every named candidate must beat: an unnamed local change.

A local change the named candidates leave out (a delamination, a cut corner, a slot, a
repair) changes the stiffness and the mass of some part of the plate. The rival is every
such change at once, as a mixture: a *window* (a rectangle of one to three regions each way
on a grid over the plate, :func:`windows`), uniform over the windows, changing inside it the
bending and in-plane stiffness, the transverse shear stiffness and the mass by relative
amounts ``w`` (three numbers, :data:`GROUPS`), ``w ~ N(0, tau^2 I)``.

Linearised at the nominal fit, each window's evidence is exact in closed form. In the
whitened unknowns ``z`` of the constants (``b = mu_b + L z``, ``z ~ N(0, I)``),

    r0 = r + J z_hat ~ N(0, I + J J^T + tau^2 G G^T)

with ``r`` the nominal fit's whitened residuals, ``J`` their Jacobian in ``z`` and ``G``
the window's three whitened columns. The nominal model is the same with ``tau = 0``, so
the window's evidence gain over it is (Woodbury, ``A = (I + J J^T)^-1``, ``B = G^T A G``,
``c = G^T A r0``)

    g(tau) = c^T (I / tau^2 + B)^-1 c / 2 - ln det(I + tau^2 B) / 2,

the Laplace gain of :mod:`.laplace` for a linear model: the named candidates' gains are on
the same scale. The rival's gain is the log of the mean of ``exp g`` over the windows and a
grid of scales (:data:`SCALES`): its Occam penalty is the log of their number, plus the
three amplitudes' own. Where it gains more than every named candidate, naming one would be
naming physics the recordings do not point at: the verdict is ``unexplained``, with the
window the rival puts most weight on (:func:`.conclude.conclude`).

Linearised, the rival under-fits a large change, which a named candidate's nonlinear fit
does not; and three free amplitudes cost more than a named candidate's one or two. So it
loses to the candidate that is true, and beats those that fit worse than a local change.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from .locate import paired

__all__ = [
    "GROUPS",
    "SCALES",
    "UnnamedChange",
    "beaten",
    "field_columns",
    "field_gain",
    "regions",
    "unnamed",
    "window_gains",
    "windows",
]

#: The relative changes inside a window: the lamina coefficients each stiffness group scales
#: (``C11, C22, C12, C66, C44, C55``), and the mass.
GROUPS = ("stiffness", "shear stiffness", "mass")
_WEIGHTS = {"stiffness": [1, 1, 1, 1, 0, 0], "shear stiffness": [0, 0, 0, 0, 1, 1]}
#: Prior deviations of the relative changes the gain averages over (a few per cent to the
#: whole of the material: a cut corner removes all of it).
SCALES = (0.03, 0.1, 0.3, 1.0)
#: Regions along the plate's shorter side (the longer one gets as many per length, at most
#: twice as many).
REGIONS_SHORT = 4
#: Regions a window spans each way, at most.
WINDOW = 3


@dataclass(frozen=True)
class UnnamedChange:
    """The unnamed local change fitted to the nominal fit's residuals.

    Attributes
    ----------
    log_evidence_gain : float
        Over the nominal model, nats (the candidates' ``log_evidence_gain`` scale).
    window_mm : numpy.ndarray, shape (4,)
        ``x0, x1, y0, y1`` of the window the rival puts most weight on, mm.
    weight : float
        That window's posterior weight among the windows.
    change : numpy.ndarray, shape (3,)
        Its posterior mean relative changes (:data:`GROUPS`) at its best scale.
    """

    log_evidence_gain: float
    window_mm: np.ndarray
    weight: float
    change: np.ndarray

    def text(self):
        """Where the mismatch sits and what changes there, in a sentence."""
        x0, x1, y0, y1 = self.window_mm
        changes = ", ".join(
            f"{name} {100 * v:+.0f} %" for name, v in zip(GROUPS, self.change, strict=True)
        )
        return (
            f"the mismatch sits most probably at x {x0:.0f}-{x1:.0f} mm, y {y0:.0f}-{y1:.0f} mm "
            f"(weight {self.weight:.2f} among the places tried; there {changes})"
        )


def beaten(gain, change, margin):
    """Whether the unnamed local `change` gains more than `gain` by over `margin` nats."""
    return change.log_evidence_gain > gain + margin


def regions(mesh, short=REGIONS_SHORT):
    """Each element's region on a grid over the plate, and the grid's edges.

    Parameters
    ----------
    mesh : RectangularMesh
    short : int
        Regions along the shorter side.

    Returns
    -------
    label : numpy.ndarray of int, shape (n_elements,)
        ``iy * nx + ix``; each region holds whole elements, as near equal in number as the
        mesh allows.
    edges_mm : tuple of numpy.ndarray
        ``(x edges (nx + 1,), y edges (ny + 1,))``, mm.
    """
    ratio = mesh.a / mesh.b
    nx = int(np.clip(round(short * ratio), 1, 2 * short)) if ratio >= 1 else short
    ny = short if ratio >= 1 else int(np.clip(round(short / ratio), 1, 2 * short))
    nx, ny = min(nx, mesh.nx), min(ny, mesh.ny)
    # element column i is in region column i nx // mesh.nx
    ex = np.floor(mesh.centroids[:, 0] / mesh.dx + 1e-9).astype(int)
    ey = np.floor(mesh.centroids[:, 1] / mesh.dy + 1e-9).astype(int)
    ix, iy = ex * nx // mesh.nx, ey * ny // mesh.ny
    edges_x = mesh.dx * np.searchsorted(np.arange(mesh.nx) * nx // mesh.nx, np.arange(nx + 1))
    edges_y = mesh.dy * np.searchsorted(np.arange(mesh.ny) * ny // mesh.ny, np.arange(ny + 1))
    return iy * nx + ix, (1e3 * edges_x, 1e3 * edges_y)


def windows(nx, ny, span=WINDOW):
    """Every rectangle of one to ``span`` regions each way on an ``nx`` x ``ny`` grid.

    Returns
    -------
    members : numpy.ndarray, shape (n_windows, nx * ny)
        1 where a region is in the window.
    corners : numpy.ndarray of int, shape (n_windows, 4)
        ``ix0, ix1, iy0, iy1`` (ends exclusive).
    """
    members, corners = [], []
    for w in range(1, min(span, nx) + 1):
        for h in range(1, min(span, ny) + 1):
            for i in range(nx - w + 1):
                for j in range(ny - h + 1):
                    inside = np.zeros((ny, nx))
                    inside[j : j + h, i : i + w] = 1.0
                    members.append(inside.ravel())
                    corners.append((i, i + w, j, j + h))
    return np.array(members), np.array(corners)


def field_columns(model, at_fit, b, label, n_regions):
    """``d lambda_i / d w``: each region's relative change of each group, rad^2/s^2.

    Parameters
    ----------
    model : PlateModel
    at_fit : ModalResult
        The nominal fit's modes paired with the measured ones: ``eigenvalues`` (m,),
        ``vectors`` (n_dofs, m), mass-normalised.
    b : numpy.ndarray, shape (6,)
        Stiffness coefficients of the nominal fit, Pa.
    label : numpy.ndarray of int, shape (n_elements,)
    n_regions : int

    Returns
    -------
    numpy.ndarray, shape (m, n_regions, 3)
        Stiffness scaled by ``1 + w``: ``+ a_i^T K_r a_i``; mass: ``- lambda_i a_i^T M_r a_i``.
    """
    q = at_fit.vectors[model.mesh.element_dofs]  # (n_el, 32, m)
    terms = model.element_stiffness_terms()
    onehot = np.zeros((label.size, n_regions))
    onehot[np.arange(label.size), label] = 1.0
    columns = []
    for group in GROUPS[:2]:
        Ke = np.einsum("j,jab->ab", np.asarray(b) * np.array(_WEIGHTS[group]), terms)
        columns.append(np.einsum("eai,ab,ebi->ie", q, Ke, q) @ onehot)
    kinetic = np.einsum("eai,ab,ebi->ie", q, model.element_mass(), q) @ onehot
    columns.append(-at_fit.eigenvalues[:, None] * kinetic)
    return np.stack(columns, axis=-1)


def field_gain(r0, J, G, scales=SCALES):
    """The evidence gain over the nominal model of columns ``G`` at each prior scale.

    Parameters
    ----------
    r0 : numpy.ndarray, shape (m,)
        Whitened residuals at the prior mean of the linearised model, ``r + J z_hat``.
    J : numpy.ndarray, shape (m, 6)
        Their Jacobian in the whitened constants.
    G : numpy.ndarray, shape (..., m, n)
        Whitened columns (a stack of them: one set per window).
    scales : sequence of float
        Prior deviations ``tau`` of the amplitudes.

    Returns
    -------
    gains : numpy.ndarray, shape (len(scales), ...)
        Nats.
    means : numpy.ndarray, shape (len(scales), ..., n)
        Posterior mean of the amplitudes at each scale.
    """
    m = r0.size
    chol = np.linalg.cholesky(np.eye(m) + J @ J.T)
    W = np.linalg.solve(chol, np.eye(m))  # A = W^T W
    WG = W @ G
    B = np.swapaxes(WG, -1, -2) @ WG
    c = np.swapaxes(WG, -1, -2) @ (W @ r0)
    eye = np.eye(B.shape[-1])
    gains, means = [], []
    for tau in scales:
        w = np.linalg.solve(eye / tau**2 + B, c[..., None])[..., 0]
        logdet = np.linalg.slogdet(eye + tau**2 * B)[1]
        gains.append(0.5 * np.sum(c * w, axis=-1) - 0.5 * logdet)
        means.append(w)
    return np.array(gains), np.array(means)


def window_gains(r0, J, columns, members, scales=SCALES):
    """Each window's gain at each scale: :func:`field_gain` of its summed columns.

    Parameters
    ----------
    columns : numpy.ndarray, shape (m, n_regions, 3)
        Whitened.
    members : numpy.ndarray, shape (n_windows, n_regions)

    Returns
    -------
    gains : numpy.ndarray, shape (len(scales), n_windows)
    means : numpy.ndarray, shape (len(scales), n_windows, 3)
    """
    G = np.einsum("wr,mrg->wmg", members, columns)
    return field_gain(r0, J, G, scales)


def unnamed(model, fit_, problem, modes):
    """The unnamed local change at the nominal fit ``fit_`` (:class:`UnnamedChange`).

    Parameters
    ----------
    model : PlateModel
        The working mesh (``fit_.modal`` was solved on it).
    fit_ : JointFit
        The nominal fit.
    problem : JointProblem
        The nominal problem (its prior ``L``, ``mu_b`` and deviations ``sigma``).
    modes : numpy.ndarray of int, shape (m,)
        0-based modes paired with the measured ones.
    """
    at_fit = paired(fit_, modes)
    sigma = problem.sigma
    J = at_fit.sensitivities @ problem.L / sigma[:, None]
    r0 = fit_.residual_sigma + J @ problem.pack(fit_.b)[:6]
    label, (edges_x, edges_y) = regions(model.mesh)
    nx, ny = edges_x.size - 1, edges_y.size - 1
    columns = field_columns(model, at_fit, fit_.b, label, nx * ny) / sigma[:, None, None]
    members, corners = windows(nx, ny)
    gains, means = window_gains(r0, J, columns, members)
    total = logsumexp(gains)
    by_window = logsumexp(gains, axis=0)
    k = int(np.argmax(by_window))
    i0, i1, j0, j1 = corners[k]
    return UnnamedChange(
        log_evidence_gain=float(total - np.log(gains.size)),
        window_mm=np.array([edges_x[i0], edges_x[i1], edges_y[j0], edges_y[j1]]),
        weight=float(np.exp(by_window[k] - total)),
        change=means[int(np.argmax(gains[:, k])), k],
    )
