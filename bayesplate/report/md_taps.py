"""The report's tap-test section: the recordings, the peaks with their evidence and roles.

Rendered by :func:`tap_section` for :func:`~bayesplate.report.markdown.render_markdown`
when the report was opened from raw taps (``bayesplate report --taps``).
"""

from __future__ import annotations

from .md_blocks import _image, _table

__all__ = ["tap_section"]


def tap_section(data, figures):
    """The tap test: its recordings, the peaks with their evidence and roles, two figures."""
    if data.taps is None:
        return []
    from .figures import tap_roles

    taps, measured = data.taps, data.case.measured
    roles, _, unobserved = tap_roles(data)
    lower, upper = taps.analysis.band_Hz
    lines = [
        "## Tap test",
        "",
        (
            f"{len(taps.sources)} recording{'s' if len(taps.sources) != 1 else ''} averaged; "
            f"LSCF poles fitted over {lower:.4g}-{upper:.4g} Hz at model orders up to "
            f"{int(taps.analysis.orders[-1])}; {len(taps.kept)} poles kept. Each peak's prior "
            "probability of being spurious comes from its pole's evidence (coherence, the phase "
            "of its modal constant, damping, stability); the loss factor is twice the damping "
            "ratio."
        ),
        "",
    ]
    head = [
        "peak",
        "f (Hz)",
        "loss factor (%)",
        "coherence",
        "phase off (deg)",
        "p spurious",
        "role",
    ]
    by_f = {round(p.frequency_Hz, 6): p for p in taps.kept}
    rows = []
    for i, f in enumerate(measured.frequency_Hz):
        pole = min(taps.kept, key=lambda p, f=f: abs(p.frequency_Hz - f))
        pole = by_f.get(round(f, 6), pole)
        evidence = (pole.coherence, pole.phase_deviation_deg, pole.p_spurious)
        rows.append(
            [
                i + 1,
                f"{f:.2f}",
                f"{200 * pole.damping:.2f}",
                *(f"{v:.3g}" for v in evidence),
                roles[i],
            ]
        )
    lines += _table(head, rows) + [""]
    if unobserved:
        listed = ", ".join(str(j + 1) for j in unobserved)
        lines += [
            f"Computed modes no peak explains (unobserved: a node at the tap or the "
            f"sensor, or too weak): {listed}.",
            "",
        ]
    lines += _image(
        figures,
        "frf",
        "the measured FRF (mean magnitude), the peaks paired and "
        "those called spurious (top), the computed modes at the estimate "
        "(dotted; dashed red: no peak explains them)",
    )
    return lines + _image(
        figures,
        "stabilisation",
        "stabilisation chart: poles of each LSCF "
        "model order, the kept ones marked at the top; below, the coherence",
    )
