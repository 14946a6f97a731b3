"""Two effects at once: a candidate physics made of two, for when one does not explain.

A :class:`Pair` is a :class:`~.base.Physics` whose parameters are its two components', one
after the other (each prefixed by its component's name: ``point_mass.mass_g``), so that the
joint fit, the reduced models and the ranking of :mod:`..search.rank` run on it unchanged.

Composition. The candidates' :meth:`~.base.Physics.apply` do not all compose by applying one
to the other's plate (a taper rebuilds the stiffness and mass from the element matrices, a
foundation sets the extra stiffness): the pair's plate is the nominal one plus the sum of
the two changes, each made on the nominal plate,

    K_j = K_j^A + K_j^B - K_j^0,   M = M^A + M^B - M^0,   K_extra = K_extra^A + K_extra^B.

It is exact where the two changes do not interact (any effect with a point mass, with a
foundation or with a point support; either effect at zero size: the pair is the other one
alone) and neglects only the product of two changes where they do (a damaged patch on a
tapered plate: a second-order term). It is symmetric in the two components. Its Ritz form
(:meth:`Pair.ritz`) is the same sum of the components' reduced matrices, exact in the
basis; a pair with a component without one runs on the finite-element model.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np

from .base import Physics, distinct_images, plate_symmetries
from .reduced_model import _has_ritz, project

__all__ = ["Pair", "pairs_with"]

#: Modes compared to tell a true mirror image of a pair from a mere combination of images.
MIRROR_MODES = 8
#: Most elements each way of the mesh that tells them apart (see :meth:`Pair.mirror_images`).
MIRROR_MESH = 12


class Pair(Physics):
    """Two candidate physics on the same plate, fitted together.

    Parameters
    ----------
    first, second : Physics
        The components (the first is the best single candidate in :func:`..diagnose.diagnose`).
    b : numpy.ndarray, shape (6,)
        Stiffness coefficients at which mirror images are checked, Pa (the best single
        fit's; see :meth:`mirror_images`).
    starts : sequence of array_like, optional
        Extra starting values of the concatenated parameters, shape (k_first + k_second,)
        each, in their units (the single candidates' fits, say).
    """

    def __init__(self, first, second, b, starts=()):
        self.first, self.second = first, second
        self.b = np.asarray(b, dtype=float)
        self.name = f"{first.name}+{second.name}"
        self.description = f"{first.description}, and {second.description}"
        self.starts = [np.asarray(s, dtype=float) for s in starts]

    def settings(self):
        """The components' settings, each key prefixed by its component's name."""
        return {
            f"{c.name}.{k}": v for c in (self.first, self.second) for k, v in c.settings().items()
        }

    def parameters(self, model, b):
        """The first component's parameters, then the second's, names prefixed."""
        return tuple(
            replace(p, name=f"{c.name}.{p.name}")
            for c in (self.first, self.second)
            for p in c.parameters(model, b)
        )

    def split(self, model, theta):
        """``(theta_first, theta_second)`` of a concatenated parameter vector.

        The first component's parameters counted at the pair's :attr:`b`: their number does
        not depend on the constants, but their priors are sized from a physical plate.
        """
        k = len(self.first.parameters(model, self.b))
        theta = np.asarray(theta, dtype=float)
        return theta[:k], theta[k:]

    def apply(self, model, theta):
        """The nominal plate plus both components' changes (see the module docstring)."""
        ta, tb = self.split(model, theta)
        pa, pb = self.first.apply(model, ta), self.second.apply(model, tb)
        terms = pa.stiffness_terms + pb.stiffness_terms - model.stiffness_terms
        mass = pa.mass_data + pb.mass_data - model.mass_data
        extras = [p.extra_stiffness_data for p in (pa, pb, model)]
        extra = None
        if any(e is not None for e in extras):
            zero = np.zeros_like(model.mass_data)
            ea, eb, e0 = (zero if e is None else e for e in extras)
            extra = ea + eb - e0
        return model.modified(stiffness_terms=terms, mass_data=mass, extra_stiffness_data=extra)

    def ritz(self, model, b, basis, near=None):
        """The components' reduced matrices summed, less the nominal ones.

        None when either component has no Ritz form (the pair runs on the finite-element
        model).
        """
        if not (_has_ritz(self.first) and _has_ritz(self.second)):
            return None
        na, nb = (None, None) if near is None else self.split(model, near)
        ma = self.first.ritz(model, b, basis, na)
        mb = self.second.ritz(model, b, basis, nb)
        if ma is None or mb is None:
            return None
        nominal = project(model, basis)
        k = len(self.first.parameters(model, b))

        def matrices(theta):
            theta = np.asarray(theta, dtype=float)
            return tuple(
                x + y - z for x, y, z in zip(ma(theta[:k]), mb(theta[k:]), nominal, strict=True)
            )

        def difference(theta, i, h):
            # the pair's matrices less its component's do not depend on that component's
            # parameters: the difference is the component's own (by its cheaper path when
            # its Ritz form has one)
            theta = np.asarray(theta, dtype=float)
            own, t, j = (ma, theta[:k], i) if i < k else (mb, theta[k:], i - k)
            by_own = getattr(own, "difference", None)
            if by_own is not None:
                return by_own(t, j, h)
            up, down = t.copy(), t.copy()
            up[j] += h
            down[j] -= h
            return tuple((x - y) / (2 * h) for x, y in zip(own(up), own(down), strict=True))

        matrices.difference = difference
        return matrices

    def starting_points(self, model, b):
        """The given ``starts``, then each component's starts with the other at its mean."""
        mean_a = np.array([p.mean for p in self.first.parameters(model, b)])
        mean_b = np.array([p.mean for p in self.second.parameters(model, b)])
        out = list(self.starts)
        out += [np.concatenate([t, mean_b]) for t in self.first.starting_points(model, b)]
        out += [np.concatenate([mean_a, t]) for t in self.second.starting_points(model, b)]
        return out

    def image(self, model, theta, symmetry):
        """Both components' images under the same symmetry (it moves both effects at once).

        None when either component does not say (:meth:`mirror_images` then tells the
        images apart by their frequencies).
        """
        ta, tb = self.split(model, theta)
        ia, ib = self.first.image(model, ta, symmetry), self.second.image(model, tb, symmetry)
        return None if ia is None or ib is None else np.concatenate([ia, ib])

    def mirror_images(self, model, theta):
        """The pair's images under the plate's symmetries.

        A symmetry moves both effects at once (turning the plate end for end moves a mass
        and reverses a taper along that side): by :meth:`image` when both components
        give theirs. Otherwise, of every combination of the components' images, those whose
        frequencies at :attr:`b` equal ``theta``'s (relative 1e-8; a mirror image on a
        uniform mesh agrees to round-off) are kept: a test of symmetry, not of accuracy,
        run on the same plate on a mesh of at most :data:`MIRROR_MESH` elements each way,
        one small eigen solve per combination.
        """
        images = [self.image(model, theta, s) for s in plate_symmetries(model)]
        if all(t is not None for t in images):
            return distinct_images(theta, images)
        ta, tb = self.split(model, theta)
        images_a = [ta, *self.first.mirror_images(model, ta)]
        images_b = [tb, *self.second.mirror_images(model, tb)]
        combos = [
            np.concatenate([images_a[i], images_b[j]])
            for i, j in itertools.product(range(len(images_a)), range(len(images_b)))
            if (i, j) != (0, 0)
        ]
        if not combos:
            return []
        check = _check_model(model)
        n = MIRROR_MODES
        want = self.apply(check, theta).solve(self.b, n).eigenvalues
        return [
            t
            for t in combos
            if np.allclose(
                self.apply(check, t).solve(self.b, n).eigenvalues, want, rtol=1e-8, atol=0.0
            )
        ]


#: The last plate checked for mirror images and its small mesh (kept out of the pairs'
#: attributes, which key their stored fits).
_CHECKED = [None, None]


def _check_model(model):
    """``model``'s plate on a mesh of at most :data:`MIRROR_MESH` elements each way."""
    mesh = (min(model.mesh.nx, MIRROR_MESH), min(model.mesh.ny, MIRROR_MESH))
    if mesh == (model.mesh.nx, model.mesh.ny):
        return model
    if _CHECKED[0] is not model:
        _CHECKED[:] = [model, model.on_mesh(mesh)]
    return _CHECKED[1]


def pairs_with(best, physics_list, ranked, model, scans, n_places=3):
    """The pairs to fit when the best single candidate does not explain the recordings.

    The best candidate's physics with every candidate of another name (another variant of
    the same candidate, a taper along the other side, is not a second effect), started from
    the best one's fit with the second at its prior mean, at its own single fit and, when it
    is located, at the best distinct places of its scan.

    Parameters
    ----------
    best : CandidateResult
        The best single candidate (its ``fit.physics`` is the first component).
    physics_list : list of Physics
        The candidates.
    ranked : list of CandidateResult
        Their single fits.
    model : PlateModel
    scans : dict of Scan
        Keyed by :attr:`~.base.Physics.name`.
    n_places : int
        Places of a located second candidate's scan to start from.

    Returns
    -------
    list of Pair
    """
    first = best.fit.physics
    ta = np.asarray(best.fit.theta, dtype=float)
    out = []
    for second in physics_list:
        if second.name == first.name:
            continue
        mean_b = np.array([p.mean for p in second.parameters(model, best.fit.b)])
        own = [c.fit.theta for c in ranked if c.fit.physics is second]
        scan = scans.get(second.name)
        places = [] if scan is None else scan.best(model, n_places)
        starts = [np.concatenate([ta, np.asarray(t, dtype=float)]) for t in [mean_b, *own, *places]]
        out.append(Pair(first, second, best.fit.b, starts))
    return out
