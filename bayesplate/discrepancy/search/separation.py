"""Which measurement would tell two fitted candidates apart (the ``ambiguous`` verdict).

Two candidates that fit the measured frequencies about equally well predict the same paired
frequencies; they differ elsewhere. Both fitted plates are solved on the working mesh (each
at its own constants and parameters) for the modes up to :data:`EXTRA_MODES` beyond the
highest paired one; their modes are compared in order (the k-th peak of a spectrum is what
a measurement of the k-th mode sees, and the fits pair measured and computed modes by order
too), and

- the *mode* to measure is the computed mode, not among the paired ones, whose
  predicted frequencies differ most in units of the measurement deviation (the median
  relative deviation of the measured frequencies, applied at that frequency);
- the *point* at which to measure a mode shape is, over the paired modes, the node where
  the two fitted models' transverse deflections ``w`` (each mode scaled to a largest
  ``|w|`` of one, signs matched) differ most.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...quantities import hz_from_eigenvalue

__all__ = ["EXTRA_MODES", "Separation", "separate"]

#: Computed modes beyond the highest paired one that are considered.
EXTRA_MODES = 6


@dataclass(frozen=True)
class Separation:
    """The measurement that best separates two fitted candidates.

    Attributes
    ----------
    names : tuple of str
        The two candidates, best first.
    mode : int or None
        1-based computed mode to measure; None when every
        computed mode up to :data:`EXTRA_MODES` beyond the paired ones is paired.
    frequency_Hz : tuple of float
        Its frequency predicted by each candidate, Hz.
    difference_sd : float
        ``|f_1 - f_2|`` in measurement deviations at that frequency.
    shape_mode : int
        1-based computed mode (paired) whose shape differs most.
    point_mm : tuple of float
        ``(x, y)`` of the node where it differs most, mm.
    shape_difference : float
        ``|w_1 - w_2|`` there, each shape scaled to a largest ``|w|`` of one.
    """

    names: tuple
    mode: int | None
    frequency_Hz: tuple
    difference_sd: float
    shape_mode: int
    point_mm: tuple
    shape_difference: float

    def text(self):
        """One sentence: what to measure to tell the two apart."""
        a, b = self.names
        parts = []
        if self.mode is not None:
            f1, f2 = self.frequency_Hz
            parts.append(
                f"measure mode {self.mode} ({a}: {f1:.1f} Hz, {b}: {f2:.1f} Hz, "
                f"{self.difference_sd:.1f} deviations apart)"
            )
        x, y = self.point_mm
        parts.append(
            f"measure the shape of mode {self.shape_mode} at x = {x:.0f} mm, "
            f"y = {y:.0f} mm (the shapes differ by {self.shape_difference:.2f} of "
            "their largest deflection)"
        )
        return f"to tell {a} from {b}: " + "; or ".join(parts)


def separate(model, first, second, modes, relative_sd):
    """The extra mode and the shape point that best separate two fitted candidates.

    Parameters
    ----------
    model : PlateModel
        The nominal plate on the working mesh.
    first, second : CandidateResult
        The two fitted candidates (their ``fit.physics``, ``fit.b``, ``fit.theta``).
    modes : numpy.ndarray of int, shape (m,)
        0-based computed elastic modes paired with the measured ones.
    relative_sd : float
        Relative deviation of a frequency measurement (``sigma_Hz / f``).

    Returns
    -------
    Separation
    """
    n = int(np.max(modes)) + 1 + EXTRA_MODES
    sols = [c.fit.physics.apply(model, c.fit.theta).solve(c.fit.b, n) for c in (first, second)]
    va, vb = sols[0].vectors, sols[1].vectors
    fa, fb = hz_from_eigenvalue(sols[0].eigenvalues), hz_from_eigenvalue(sols[1].eigenvalues)
    paired = set(np.asarray(modes).tolist())
    free = [i for i in range(n) if i not in paired]
    mode, freq, diff = None, (np.nan, np.nan), 0.0
    if free:
        z = [abs(fa[i] - fb[i]) / (relative_sd * 0.5 * (fa[i] + fb[i])) for i in free]
        k = int(np.argmax(z))
        mode, freq, diff = free[k] + 1, (float(fa[free[k]]), float(fb[free[k]])), z[k]

    w_dofs = model.mesh.dofs("w")
    best = (0.0, int(np.asarray(modes)[0]), 0)
    for i in np.asarray(modes):
        wa, wb = va[w_dofs, i], vb[w_dofs, i]
        scale_a, scale_b = np.abs(wa).max(), np.abs(wb).max()
        if not (scale_a > 0 and scale_b > 0):  # an in-plane mode: no deflection to measure
            continue
        wa, wb = wa / scale_a, wb / scale_b
        wb = wb if wa @ wb >= 0 else -wb
        d = np.abs(wa - wb)
        j = int(np.argmax(d))
        if d[j] > best[0]:
            best = (float(d[j]), int(i), j)
    point = tuple(float(v) for v in 1e3 * model.mesh.nodes[best[2]])
    return Separation(
        (first.name, second.name), mode, freq, float(diff), best[1] + 1, point, best[0]
    )
