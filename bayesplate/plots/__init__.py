"""Figures: sensitivities, frequency differences, mode shapes, posteriors and diagnosis maps.

The only part of the package that uses matplotlib (import it only where figures are drawn:
matplotlib is slow to import). Every function draws on an ``ax`` (or ``fig``) it is given,
or on a new :class:`matplotlib.figure.Figure` built without pyplot (no global figure
registry, no GUI backend needed), and returns the figure; saving it is the caller's business
(:func:`bayesplate.io.save_figure`).

By topic: :mod:`~bayesplate.plots.estimates` (sensitivities, frequency differences,
residuals), :mod:`~bayesplate.plots.modes` (mode shapes, MAC matrix),
:mod:`~bayesplate.plots.posterior` (corner plots, traces, autocorrelation),
:mod:`~bayesplate.plots.budget` (each constant's variance by source) and
:mod:`~bayesplate.plots.diagnosis` (location maps, residuals before and after a refit).
"""

from __future__ import annotations

from ._style import CONSTANT_LABELS
from .budget import variance_budget_bars
from .diagnosis import diagnosis_figures, location_map, residual_comparison
from .estimates import estimate_residuals, frequency_comparison, sensitivity_bars
from .modes import mac_matrix_plot, mode_shapes
from .posterior import (
    autocorrelation_plot,
    corner_estimates,
    posterior_corner,
    sampling_figures,
    trace_plot,
)
from .taps import tap_frf

__all__ = [
    "CONSTANT_LABELS",
    "autocorrelation_plot",
    "corner_estimates",
    "diagnosis_figures",
    "estimate_residuals",
    "frequency_comparison",
    "location_map",
    "mac_matrix_plot",
    "mode_shapes",
    "tap_frf",
    "posterior_corner",
    "residual_comparison",
    "sampling_figures",
    "sensitivity_bars",
    "trace_plot",
    "variance_budget_bars",
]
