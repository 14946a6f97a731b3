"""The report's figures, drawn from its plain data (:func:`report_figures`).

Residuals at each estimate, sensitivities, mode shapes, the MAC matrix (with measured
shapes), the posterior corner plot and diagnose's figures; all drawn by
:mod:`bayesplate.plots` (imported when first needed: matplotlib is slow to import), none
saved here.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..plate.model import ModalResult
from ..quantities import ENGINEERING_KEYS, ENGINEERING_NAMES, ENGINEERING_UNITS, to_case_units
from .data import ESTIMATORS, _estimate_for_modes

__all__ = ["figure_groups", "report_figures"]

_SHAPE_GRID = (81, 41)  # points along the long and short side (interpolation is per point)
_SHORT_KINDS = {"bending along x": "bend x", "bending along y": "bend y"}


def report_figures(data):
    """The figures of a report: ``{name: matplotlib Figure}``, in the order shown."""
    figs = {}
    for group in figure_groups(data):
        figs.update(group())
    return figs


def figure_groups(data):
    """The report's figures in independent groups, in the order shown.

    Returns
    -------
    list of callable
        Each ``group() -> {name: matplotlib Figure}``; they share nothing, so they may be
        drawn in separate processes (:func:`bayesplate.report.writer.write_report`).
    """
    from .. import plots  # imported here, before any fork: the workers inherit it

    r = data.results
    groups = [
        lambda: {
            **_residuals_figure(data, plots),
            **_budget_figure(data, plots),
            **_modes_figures(data, plots),
        }
    ]
    if data.taps is not None:
        groups.append(lambda: _tap_figures(data, plots))
    if "sample" in r:
        groups.append(lambda: _sample_figures(r["sample"], plots, r.get("B")))
    if "diagnose" in r:

        def diagnosis():
            view = _diagnosis_view(r["diagnose"])
            found = plots.diagnosis_figures(data.plate_model(), view)
            return {f"diagnose_{name}": fig for name, fig in found.items()}

        groups.append(diagnosis)
    return groups


def _residuals_figure(data, plots):
    """The measured frequencies' residuals at each estimate that has them all."""
    r = data.results
    kept = data.pairing().kept(data.case.measured.size)
    series = {
        m: r[m]["frequency_Hz"]
        for m in ESTIMATORS
        if m in r and np.all(np.isfinite(r[m]["frequency_Hz"]))
    }
    if not series:
        return {}
    fig = plots.estimate_residuals(
        data.case.measured.frequency_Hz[kept],
        data.case.measured.sigma_Hz[kept],
        series,
        labels=[str(i + 1) for i in kept],
        title="residuals at each estimate",
    )
    return {"residuals": fig}


def _budget_figure(data, plots):
    """Where B's uncertainty of each constant comes from (frequencies, inputs, prior)."""
    budget = data.results.get("B", {}).get("budget")
    if not budget:
        return {}
    sources = budget["sources"]
    share = np.array([[budget["share"][key][s] for key in ENGINEERING_KEYS] for s in sources])
    view = SimpleNamespace(sources=sources, share=share, method="B")
    title = "share of each constant's variance by source (B, linearised at its estimate)"
    return {"variance_budget": plots.variance_budget_bars(view, title=title)}


def _modes_figures(data, plots):
    """Sensitivity bars, mode shapes and (with measured shapes) the MAC matrix."""
    modes, figs = data.results["modes"], {}
    at, n = _estimate_for_modes(data), len(modes["frequency_Hz"])
    figs["sensitivities"] = plots.sensitivity_bars(
        modes["normalised_sensitivities"],
        notes=[_SHORT_KINDS.get(k, k) for k in modes["kinds"]],
        title=f"normalised sensitivities of the first {n} elastic modes at the {at} estimate",
    )
    k = modes["vectors"].shape[1]
    shapes = ModalResult(
        modes["b"], modes["eigenvalues"][:k], modes["vectors"], np.zeros((k, 6)), np.zeros(0)
    )
    tap = data.case.measured.tap_points
    marks = None if tap is None else {"tap": tap[0], "sensor": tap[1]}
    figs["mode_shapes"] = plots.mode_shapes(
        data.plate_model(), shapes, n=k, points=_SHAPE_GRID, marks=marks
    )
    pairing, m = data.pairing(), data.case.measured.size
    if pairing.mac is not None:
        pairs = np.full(m, -1)
        pairs[pairing.kept(m)] = pairing.modes
        figs["mac"] = plots.mac_matrix_plot(
            pairing.mac,
            pairs,
            measured_Hz=data.case.measured.frequency_Hz,
            title="MAC of measured shapes against computed modes (prior mean); pairs outlined",
        )
    return figs


def tap_roles(data):
    """Each measured peak's role and the computed modes no peak explains (0-based).

    Returns
    -------
    roles : list of str
        ``"paired"`` or ``"spurious"`` for each measured peak (the pairing step's pairing).
    computed_Hz : numpy.ndarray
        The computed elastic frequencies at the modes' estimate, Hz.
    unobserved : list of int
        Computed modes up to the highest peak that no peak is paired with.
    """
    m = data.case.measured.size
    pairing = data.pairing()
    kept = set(int(i) for i in pairing.kept(m))
    roles = ["paired" if i in kept else "spurious" for i in range(m)]
    computed = np.sqrt(np.maximum(data.results["modes"]["eigenvalues"], 0.0)) / (2 * np.pi)
    top = data.case.measured.frequency_Hz.max()
    paired = set(int(j) for j in pairing.modes)
    unobserved = [j for j, f in enumerate(computed) if f <= top and j not in paired]
    return roles, computed, unobserved


def _tap_figures(data, plots):
    """The stabilisation chart and the FRF with the peaks' roles and the computed modes."""
    from ..io.poles_file import stabilisation_chart

    taps, spectra = data.taps, data.taps.spectra
    chart = stabilisation_chart(
        taps.analysis, spectra.frequency_Hz, spectra.frf, taps.kept, spectra.coherence
    )
    roles, computed, unobserved = tap_roles(data)
    frf = plots.tap_frf(
        spectra.frequency_Hz,
        spectra.frf,
        taps.analysis.band_Hz,
        data.case.measured.frequency_Hz,
        roles,
        computed,
        unobserved,
    )
    return {"stabilisation": chart, "frf": frf}


def _sample_figures(result, plots, b_result=None):
    """Corner plot of the posterior draws, with B's linearised ellipses where B converged.

    See :func:`bayesplate.report.steps.sample_step`; the ellipses enclose what the draws'
    contours do (1 and 2 sigma), so a linearised covariance that holds lies on them.
    """
    labels = [f"{n} ({u})" for n, u in zip(ENGINEERING_NAMES, ENGINEERING_UNITS, strict=True)]
    covariance = None if b_result is None else b_result.get("covariance")
    if covariance is None or not b_result["converged"]:
        truths = None if result["map"] is None else to_case_units(result["map"])
        title = "posterior (emcee); red: the B estimate (MAP)"
        return {
            "posterior_corner": plots.posterior_corner(
                result["draws"], labels, truths=truths, title=title
            )
        }
    scale = to_case_units(np.ones(6))
    estimate = (
        to_case_units(b_result["constants"]),
        np.asarray(covariance) * np.outer(scale, scale),
    )
    fig = plots.corner_estimates(
        result["draws"],
        labels,
        estimates={"B, linearised": estimate},
        title="posterior (emcee draws) and B's linearised Gaussian (1 and 2 sigma ellipses)",
    )
    return {"posterior_corner": fig}


def _diagnosis_view(result):
    """What :func:`bayesplate.plots.diagnosis_figures` reads, from a cached diagnosis."""
    from ..discrepancy.physics.location import LocationMap

    d = result["diagnosis"]
    maps = {}
    names = [
        k[len("map_") : -len("_shape")]
        for k in result
        if k.startswith("map_") and k.endswith("_shape")
    ]
    for key in names:  # the located candidates' physics names, as diagnose keyed them
        fields = [result[f"map_{key}_{n}"] for n in ("points_mm", "chi2_drop", "amplitude")]
        physical = result[f"map_{key}_physical"].astype(bool)
        maps[key] = LocationMap(
            *fields, physical, tuple(int(n) for n in result[f"map_{key}_shape"])
        )
    refit = d["refit"]
    chosen = (
        None
        if refit is None
        else SimpleNamespace(
            fit=SimpleNamespace(residual_sigma=np.asarray(refit["residual_sigma"]))
        )
    )
    return SimpleNamespace(
        verdict=d["verdict"],
        nominal=SimpleNamespace(residual_sigma=np.asarray(d["nominal"]["residual_sigma"])),
        chosen=chosen,
        measured_Hz=np.asarray(d["measured_Hz"]),
        mode_kinds=list(result["mode_kinds"]),
        maps=maps,
    )
