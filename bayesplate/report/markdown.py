"""The report's Markdown text, rendered from its plain data (:func:`render_markdown`).

Header, case and prior, measured frequencies and their pairing, the estimates and per-mode
residuals, modes, posterior and diagnose; constants are shown in case units (GPa, -).
"""

from __future__ import annotations

import numpy as np

from ..quantities import CASE_SCALE, ENGINEERING_NAMES, ENGINEERING_UNITS
from .data import ESTIMATORS, _estimate_for_modes, sampling_available
from .md_blocks import _constant, _image, _num, _short, _table
from .md_taps import tap_section

__all__ = ["render_markdown"]


def _header(data):
    c, o = data.case, data.options
    command = f"bayesplate report {data.label}" + (" --quick" if o.quick else "")
    steps = ", ".join(f"{s} ({data.seconds.get(s, 0):.0f} s)" for s in data.computed) or "none"
    lines = [
        f"# {c.name}",
        "",
        f"Made by `{command}` (bayesplate {data.version}, seed {o.seed}) on a "
        f"{data.mesh[0]} x {data.mesh[1]} mesh"
        + (" (quick: half the case's mesh)" if o.quick and o.mesh is None else "")
        + ".",
        f"Steps computed: {steps}; reused from the cache: {', '.join(data.reused) or 'none'}.",
        "",
    ]
    return lines + [f"> {note}" for note in data.notes] + ([""] if data.notes else [])


def _case_section(data):
    c, p = data.case, data.case.plate
    layup = "/".join(f"{a:g}" for a in p.layup_deg)
    lines = [
        "## Case",
        "",
        f"- Source: {c.source or 'not given'}",
        f"- Plate: {1e3 * p.length:g} x {1e3 * p.width:g} x {1e3 * p.thickness:g} mm, "
        f"density {p.density:g} kg/m^3, layup [{layup}] ({_plies(len(p.layup_deg))}), "
        "free-free",
        f"- Model: third-order shear deformation finite elements, {data.mesh[0]} x "
        f"{data.mesh[1]} mesh",
        "",
        "### Prior",
        "",
    ]
    head = ["constant", "unit", "prior mean", "prior sd"]
    head += ["reference"] if c.reference is not None else []
    rows = []
    for i, name in enumerate(ENGINEERING_NAMES):
        row = [name, ENGINEERING_UNITS[i], _constant(c.prior.mean, i), _constant(c.prior.sd, i)]
        rows.append(row + ([_constant(c.reference, i)] if c.reference is not None else []))
    return lines + _table(head, rows) + [""]


def _measured_section(data, figures):
    c, r = data.case, data.results["pairing"]
    pairing = data.pairing()
    kept = list(pairing.kept(c.measured.size))
    f_prior = np.asarray(r["prior_frequency_Hz"])
    head = [
        "measured mode",
        "f (Hz)",
        "sigma (Hz)",
        "sigma (%)",
        "computed mode",
        "prior mean (Hz)",
        "diff (%)",
    ] + (["MAC"] if pairing.mac is not None else [])
    rows = []
    for i, (f, s) in enumerate(zip(c.measured.frequency_Hz, c.measured.sigma_Hz, strict=True)):
        row = [i + 1, f"{f:.1f}", f"{s:.1f}", f"{100 * s / f:.2f}"]
        if i in kept:
            j = int(pairing.modes[kept.index(i)])
            row += [j + 1, f"{f_prior[j]:.1f}", f"{100 * (f_prior[j] - f) / f:+.2f}"]
            row += [f"{pairing.mac[i, j]:.2f}"] if pairing.mac is not None else []
        else:
            row += ["unpaired", "", ""] + (
                [f"{pairing.mac[i].max():.2f}"] if pairing.mac is not None else []
            )
        rows.append(row)
    lines = ["### Measured frequencies", "", f"Pairing: {r['describe']}."]
    if r.get("checked"):
        lines[-1] += (
            " The case has no measured mode shapes: each estimate, the posterior "
            "and diagnose check the order against the most probable assignment of "
            "the frequencies at their own answer, and say so where they set it "
            "aside."
        )
    elif pairing.mac is None:
        lines[-1] += " The case has no measured mode shapes, so the pairing is not checked."
    lines += [""] + _table(head, rows) + [""]
    return lines + _image(
        figures,
        "mac",
        "MAC of the measured shapes against the computed "
        "modes at the prior mean; the pairs used are outlined",
    )


def _estimates_section(data, figures):
    r, c = data.results, data.case
    methods = [m for m in ESTIMATORS if m in r]
    head = ["constant", *methods] + (["reference"] if c.reference is not None else [])
    rows = []
    for i, name in enumerate(ENGINEERING_NAMES):
        row = [f"{name} ({ENGINEERING_UNITS[i]})"]
        row += [_constant(r[m]["constants"], i, r[m]["sd"]) for m in methods]
        rows.append(row + ([_constant(c.reference, i)] if c.reference is not None else []))
    rows += [
        ["iterations", *[r[m]["iterations"] for m in methods]],
        ["converged", *["yes" if r[m]["converged"] else "**no**" for m in methods]],
        ["status", *[_status_cell(r[m]) for m in methods]],
        ["forward solves", *[r[m]["n_solves"] for m in methods]],
        ["time (s)", *[f"{r[m]['wall_time']:.0f}" for m in methods]],
    ]
    checks = [r[m].get("check") for m in methods]
    if any(ch is not None for ch in checks):
        rows.append(["full-model check", *[_check_cell(ch) for ch in checks]])
    rows = [row + [""] * (len(head) - len(row)) for row in rows]
    lines = [
        "## Estimates",
        "",
        "The paper's estimators from the prior mean: B (eq. 9, the posterior mode), MVE "
        "(eq. 12) and MVE-mod (section 5), with its conventions (`V_Y = diag(dlambda^2)`, "
        "`V_b = diag(dC^2)`). Values are estimate ± first-order standard deviation.",
        "",
        *_table(head, rows),
        "",
    ]
    lines += [f"- {m}: {r[m]['message']}" for m in methods] + [""]
    lines += _fit_lines(r, methods)
    scaled = [m for m in methods if r[m].get("error_scale")]
    if scaled:
        lines += [
            f"- {m}: {r[m]['error_scale']['text']}; s_hat "
            f"{r[m]['error_scale']['s_hat']:.3g} at the estimate. The sd above are "
            f"widened by it (Student-t, {r[m]['error_scale']['dof']:.1f} degrees of "
            "freedom)."
            for m in scaled
        ] + [""]
    if any(ch is not None for ch in checks):
        lines += [
            "The estimators iterated on the certified fast (reduced-basis) model; the full "
            "finite-element model was solved at each answer, and 'full-model check' gives the "
            "largest relative difference of the paired frequencies between the two (it must "
            "stay within the fast model's certificate).",
            "",
        ]
    return (
        lines
        + _residual_table(data)
        + _image(
            figures,
            "residuals",
            "Per-mode residuals at each estimate: (measured - computed) / sigma",
        )
        + _image(
            figures,
            "variance_budget",
            "Where each constant's uncertainty comes from, at the B estimate: the share of "
            "its variance from the measured frequencies, the measured inputs (thickness, "
            "density, size, where the case gives their deviations) and the prior; a "
            "constant mostly from its prior is one the test hardly determines",
        )
    )


def _status_cell(result):
    """An estimator's status: "converged" only when it stopped with nothing flagged."""
    status = result.get("status") or ("converged" if result["converged"] else "stopped")
    return status if status == "converged" else f"**{status}**"


def _fit_lines(r, methods):
    """Each estimate's fit statement and its warnings (absent from caches made before)."""
    lines = []
    for m in methods:
        fit = r[m].get("fit")
        if fit is None:
            continue
        worst = ", ".join(f"peak {w['peak']} {w['sd']:+.1f} sd" for w in fit["worst_residuals"])
        lines.append(
            f"- {m} fit: chi-square {fit['chi2']:.3g} on {fit['dof']:.1f} degrees of freedom, "
            f"p {fit['p_value']:.2g}; worst residuals: {worst or 'none'}"
        )
        lines += [f"  - **warning**: {w}" for w in r[m].get("warnings", ())]
    return lines + ([""] if lines else [])


def _check_cell(check):
    """One estimator's full-model check, in a table cell."""
    if check is None:
        return "full model"
    verdict = "confirmed" if check["confirmed"] else "**DISAGREES**"
    return f"{verdict} ({check['max_rel_error']:.0e})"


def _residual_table(data):
    r = data.results
    methods = [m for m in ESTIMATORS if m in r]
    pairing = data.pairing()
    kept = pairing.kept(data.case.measured.size)
    sigma = data.case.measured.sigma_Hz[kept]
    head = ["measured mode", "computed mode", "measured (Hz)"]
    for m in methods:
        head += [f"{m} (Hz)", f"(measured - {m}) / sigma"]
    rows = []
    for k, i in enumerate(kept):
        measured = data.case.measured.frequency_Hz[i]
        row = [i + 1, int(pairing.modes[k]) + 1, f"{measured:.1f}"]
        for m in methods:
            f = r[m]["frequency_Hz"][k]
            row += [_num(f, ".1f"), _num((measured - f) / sigma[k], "+.2f")]
        rows.append(row)
    return ["### Per-mode residuals", "", *_table(head, rows), ""]


def _modes_section(data, figures):
    at = _estimate_for_modes(data)
    k = data.results["modes"]["vectors"].shape[1]
    return [
        "## Modes",
        "",
        *_image(
            figures,
            "sensitivities",
            f"Normalised sensitivities (eq. 29) at the {at} "
            "estimate; under each mode number where its energy sits",
        ),
        *_image(
            figures,
            "mode_shapes",
            f"The first {k} elastic mode shapes at the {at} "
            "estimate (w, scaled to max |w| = 1); nodal lines in black" + _tap_marks(data),
        ),
    ]


def _tap_marks(data):
    """The caption's words for the tap and sensor points, when the case gives them."""
    if data.case.measured.tap_points is None:
        return ""
    return (
        "; the tap (x) and the sensor (o): a mode with a nodal line through either is "
        "barely excited or seen, so its peak may be missing"
    )


def _posterior_section(data, figures):
    lines = ["## Posterior", ""]
    if "sample" not in data.results:
        if not data.options.sample:
            why = "not requested (--no-sample)"
        elif not sampling_available():
            why = (
                "this version of bayesplate has no `bayesplate.sampling`; the section is "
                "produced when it has"
            )
        else:
            why = "the sampler failed (see the note at the top)"
        return lines + [f"Not sampled: {why}.", ""]
    return (
        lines
        + _sample_lines(data.results["sample"])
        + _image(
            figures,
            "posterior_corner",
            "Posterior draws of the engineering constants (histograms and 1 and 2 sigma "
            "contours) with B's linearised Gaussian (its ellipses enclose the same "
            "probabilities: where they lie on the contours, the linearised intervals hold)",
        )
    )


def _sample_lines(result):
    """Posterior intervals and the sampler's diagnostics."""
    rows = []
    for i, name in enumerate(ENGINEERING_NAMES):
        lo, hi = result["hdi"][0][i] / CASE_SCALE[i], result["hdi"][1][i] / CASE_SCALE[i]
        rows.append(
            [
                f"{name} ({ENGINEERING_UNITS[i]})",
                _constant(result["mean"], i, result["sd"]),
                f"{lo:#.4g} to {hi:#.4g}",
                f"{result['ess_bulk'][i]:.0f}",
                f"{result['rhat'][i]:.3f}",
            ]
        )
    t = result["timings"]
    return [
        f"emcee, {result['n_walkers']} walkers, {result['n_steps']} steps ({result['n_burn']} "
        f"burn-in), acceptance {result['acceptance']:.2f}: {result['message']}. Fast model: "
        f"{result['certificate'] or 'none (full model)'}; {result['n_full']} full solves while "
        f"sampling; {t.get('total', float('nan')):.0f} s in all.",
        "",
        *_inputs_lines(result),
        *_scale_lines(result),
        *[f"- Sampler warning: {w}" for w in result.get("warnings", [])],
        "",
        *_table(["constant", "mean ± sd", "94 % HDI", "ESS (bulk)", "R-hat"], rows),
        "",
        *_input_rows(result),
    ]


def _input_rows(result):
    """The declared inputs' posterior beside the case's values, and the linear model's check."""
    rows = [
        [
            key,
            f"{r['declared']:#.4g} ± {r['declared_sd']:#.2g}",
            f"{r['mean']:#.4g} ± {r['sd']:#.2g}",
            f"{r['hdi_3%']:#.4g} to {r['hdi_97%']:#.4g}",
        ]
        for key, r in (result.get("inputs_posterior") or {}).items()
    ]
    lines = []
    if rows:
        lines += [
            "The measured inputs, drawn once per kept draw of the constants from their "
            "Gaussian conditional given them (exact joint draws under the linear input "
            "model; case units):",
            "",
            *_table(["input", "declared ± sd", "posterior mean ± sd", "94 % HDI"], rows),
            "",
        ]
    certificate = result.get("input_certificate")
    if certificate:
        mark = "" if certificate["passed"] else "**Warning:** "
        lines += [f"{mark}{certificate['text']}.", ""]
    return lines


def _scale_lines(result):
    """The error scale's posterior, when the case gives one (none otherwise)."""
    if not result.get("error_scale"):
        return []
    return [
        f"- {result['error_scale']['text']}: the frequencies' deviations are s times the "
        "declared ones, s integrated out (the intervals below include it).",
        "",
    ]


def _inputs_lines(result):
    """Whether the posterior has the plate's input deviations in it (none when exact)."""
    if result.get("inputs", "exact") != "marginal":
        return []
    return [
        "With the plate's measured inputs uncertain (the case's deviations: "
        + str(result["inputs_given"])
        + "), marginalised to first order: the eigenvalue covariance is V_Y + J Σ J^T, "
        "J the eigenvalues' derivatives in the inputs. The intervals below include them.",
        "",
    ]


def _diagnose_section(data, figures):
    lines = ["## Model discrepancy (diagnose)", ""]
    if "diagnose" not in data.results:
        return lines + ["Not run (--no-diagnose).", ""]
    d = data.results["diagnose"]["diagnosis"]
    nominal = d["nominal"]
    lines += [
        f"**Verdict: {d['verdict']}**"
        + (f" ({d['chosen']}" if d["chosen"] else "")
        + (f" or {d['rival']['physics']}" if d.get("rival") else "")
        + "".join(f" or {name}" for name in d.get("also_tied") or [])
        + (")" if d["chosen"] else ""),
        "",
        f"- Nominal fit: chi-square {nominal['chi2']:.1f} on {nominal['dof']:.1f} degrees of "
        f"freedom, p = {nominal['p_value']:.3g}",
    ]
    located = d["located"]
    kept = data.pairing().kept(data.case.measured.size)
    if located["modes"]:
        kinds = ", ".join(
            f"{kept[i - 1] + 1} ({located['mode_kinds'][i - 1]})" for i in located["modes"]
        )
        lines.append(f"- Misfit carried by measured modes {kinds}")
    if located["region_mm"] is not None:
        x, y = located["region_mm"]
        lines.append(f"- Located near x = {x:.0f} mm, y = {y:.0f} mm")
    if d["refit"] is not None:
        refit = d["refit"]
        lines.append(
            f"- Refit with {d['chosen']}: chi-square {refit['chi2']:.1f} on "
            f"{refit['dof']:.1f} degrees of freedom, p = {refit['p_value']:.3g}"
        )
    if d.get("probabilities"):
        shown = [f"{k} {v:.3g}" for k, v in d["probabilities"].items() if v >= 1e-3]
        lines.append("- Posterior probabilities (equal prior odds): " + ", ".join(shown))
    if d["unidentified"]:
        lines.append(
            "- Not identified by the data (the prior dominates): " + ", ".join(d["unidentified"])
        )
    lines += [f"- Note: {n}" for n in d["notes"]] + [""]
    rows = [
        [
            c["physics"],
            f"{c['log_evidence_gain']:+.1f}",
            f"{c['chi2']:.1f}",
            ", ".join(f"{k} = {_short(v)}" for k, v in c["parameters"].items()),
        ]
        for c in d["candidates"]
    ]
    lines += _table(["candidate", "evidence gain (nats)", "chi-square", "parameters"], rows)
    lines.append("")
    located = [k for k in figures if k.startswith("diagnose_map_")]
    # a consistent plate: the maps show how little any place would explain, not a defect
    nothing = ""
    if d["verdict"] == "consistent":
        nothing = (
            ": nothing found, the model fits without a local change, so the map shows "
            "where noise would be explained, not where a defect is"
        )
    for name, caption in (
        ("diagnose_residuals", "Standardised residuals of the nominal fit (and of the refit)"),
        *((k, f"Where a {_located_name(k)} would explain the misfit{nothing}") for k in located),
    ):
        lines += _image(figures, name, caption)
    return lines


def _located_name(figure):
    """``"diagnose_map_point_mass"`` -> ``"point mass"``."""
    return figure[len("diagnose_map_") :].replace("_", " ")


def _plies(n):
    return "1 ply" if n == 1 else f"{n} plies"


def render_markdown(data, figures):
    """The Markdown text of a report.

    Parameters
    ----------
    data : ReportData
    figures : dict
        Figure name -> file name relative to the report (only figures that exist).

    Returns
    -------
    str
    """
    from .html import report_summary, summary_lines

    lines = _header(data) + summary_lines(report_summary(data))
    lines += _case_section(data) + tap_section(data, figures)
    lines += _measured_section(data, figures)
    lines += _estimates_section(data, figures) + _modes_section(data, figures)
    lines += _posterior_section(data, figures) + _diagnose_section(data, figures)
    return "\n".join(lines).rstrip() + "\n"
