"""The declared readings' posterior summarised: :class:`InputPosterior` from their draws.

The draws are those of :func:`bayesplate.likelihood.inputs_posterior.inputs_from_chain` (one per
kept draw of the constants); the summary holds their mean, deviation and 94 % highest-density
interval, and :meth:`InputPosterior.table` gives them in case units (mm, g, kg/m^3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .inputs import READING_UNITS

__all__ = ["InputPosterior", "highest_density_interval", "summarise_inputs"]

_PROB = 0.94  # the 94 % HDI, as the constants' (bayesplate.sampling.HDI_PROB)


def highest_density_interval(x, prob=_PROB):
    """The shortest interval holding a fraction `prob` of the draws `x` (as ArviZ's ``hdi``).

    Returns
    -------
    (float, float)
    """
    x = np.sort(np.asarray(x, dtype=float))
    n = x.size
    inside = int(np.floor(prob * n))
    width = x[inside:] - x[: n - inside]
    i = int(np.argmin(width))
    return float(x[i]), float(x[i + inside])


@dataclass(frozen=True)
class InputPosterior:
    """The declared readings' posterior, from one conditional draw per kept draw of ``b``.

    Attributes
    ----------
    names : tuple of str
        Declared readings (a deviation above 0), e.g. ``("thickness", "mass")``.
    keys : tuple of str
        Their case keys with units: ``"thickness_mm"``, ``"mass_g"``, ``"density_kg_m3"``...
    declared, declared_sd : numpy.ndarray, shape (k,)
        The case's value and deviation (the prior), SI.
    mean, sd : numpy.ndarray, shape (k,)
        Posterior mean and deviation, SI.
    hdi : numpy.ndarray, shape (2, k)
        94 % highest-density interval, SI.
    draws : numpy.ndarray, shape (n, k)
        The draws, SI (row i goes with kept draw ``rows[i]`` of the chain).
    rows : numpy.ndarray of int, shape (n,)
        Which kept draws of ``b`` they were drawn with.
    """

    names: tuple
    keys: tuple
    declared: np.ndarray
    declared_sd: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    hdi: np.ndarray
    draws: np.ndarray = field(repr=False)
    rows: np.ndarray = field(repr=False)

    def table(self):
        """``{"thickness_mm": {"declared", "declared_sd", "mean", "sd", "hdi_3%", "hdi_97%"}}``.

        Case units (mm, g, kg/m^3), floats.
        """
        out = {}
        for j, (name, key) in enumerate(zip(self.names, self.keys, strict=True)):
            k = READING_UNITS[name][0]
            values = (
                self.declared[j],
                self.declared_sd[j],
                self.mean[j],
                self.sd[j],
                self.hdi[0, j],
                self.hdi[1, j],
            )
            fields = ("declared", "declared_sd", "mean", "sd", "hdi_3%", "hdi_97%")
            out[key] = {f: float(v * k) for f, v in zip(fields, values, strict=True)}
        return out


def _case_key(name):
    unit = READING_UNITS[name][1]
    return f"{name}_{'kg_m3' if unit == 'kg/m^3' else unit}"


def summarise_inputs(conditional, draws, rows):
    """An :class:`InputPosterior` of the declared readings from draws (n, 4), SI."""
    keep = conditional.declared
    names = tuple(conditional.names[j] for j in keep)
    d = np.asarray(draws, dtype=float)[:, keep]
    hdi = np.array([highest_density_interval(d[:, j]) for j in range(keep.size)]).T
    return InputPosterior(
        names,
        tuple(_case_key(n) for n in names),
        conditional.value[keep],
        conditional.sd[keep],
        d.mean(axis=0),
        d.std(axis=0, ddof=1),
        hdi.reshape(2, keep.size),
        d,
        np.asarray(rows),
    )
