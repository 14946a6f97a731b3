"""The report as one page a person opens anywhere (``report.html``), and its summary.

:func:`report_summary` gathers the numbers a reader wants first, as plain data: each
constant's estimate, sd and 94 % interval (the posterior's highest-density interval when
sampled, else the estimate ± 1.88 sd of its linearised Gaussian), whether the model fits,
the estimator's status and the diagnosis' verdict. The same data are the top of
``report.md`` (:func:`summary_lines`), the top of ``report.html`` and ``report.json``.

:func:`render_html` converts the Markdown the report renders into one self-contained page:
a small converter for exactly the constructs :mod:`~bayesplate.report.markdown` emits
(headings, paragraphs, notes, lists, pipe tables, images with their captions, bold, italic,
code spans), the figures embedded as PNG data URIs, the styles inline, no script, and a
content security policy that lets nothing leave the file. Wide tables scroll in their own
box, so a phone's width does not make the page wider than its window.
"""

from __future__ import annotations

import base64
import html
import re
import struct

import numpy as np

from ..estimators.assess import REJECT_P
from ..quantities import CASE_SCALE, ENGINEERING_NAMES, ENGINEERING_UNITS
from .data import _estimate_for_modes

__all__ = ["Z94", "render_html", "report_summary", "summary_lines"]

#: Standard normal quantile of 97 %: a Gaussian's central 94 % interval is mean ± Z94 sd.
Z94 = 1.8807936081512509

_VERDICTS = {
    "consistent": "nothing found; the frequencies agree with the plate model, no local "
    "change or missing physics is needed",
    "explained": "the misfit is explained by {chosen}",
    "ambiguous": "the misfit is explained by {chosen}, or as well by {others}",
    "unexplained": "the model misses something that no candidate explains",
}


def _float(value):
    """A JSON number: a finite float, else None."""
    value = float(value)
    return value if np.isfinite(value) else None


def report_summary(data):
    """The numbers a reader wants first, as plain (JSON) data; constants in case units.

    Returns
    -------
    dict
        ``case``, ``label``, ``version``, ``estimator`` (the estimate shown: B unless it did
        not converge, None when none did), ``interval`` (how the 94 % intervals were made),
        ``constants`` (name, unit, estimate, sd, low, high, reference), ``fit`` (chi2, dof,
        p_value, fits; None when not known), ``status``, ``warnings`` and ``diagnosis``
        (verdict, chosen, rival, also_tied; None when diagnose did not run).
    """
    r = data.results
    at = _estimate_for_modes(data)
    estimate = None if at == "prior" else r[at]
    sample = r.get("sample")
    if sample is not None:
        interval = "posterior 94 % highest-density interval (MCMC draws)"
    elif estimate is not None:
        interval = f"{at} estimate ± 1.88 sd (its linearised Gaussian; not sampled)"
    else:
        interval = None
    constants = []
    for i, name in enumerate(ENGINEERING_NAMES):
        scale = CASE_SCALE[i]
        entry = {
            "name": name,
            "unit": ENGINEERING_UNITS[i],
            "estimate": None,
            "sd": None,
            "low": None,
            "high": None,
        }
        if estimate is not None:
            value, sd = estimate["constants"][i] / scale, estimate["sd"][i] / scale
            entry.update(estimate=_float(value), sd=_float(sd))
            entry.update(low=_float(value - Z94 * sd), high=_float(value + Z94 * sd))
        if sample is not None:
            entry.update(low=_float(sample["hdi"][0][i] / scale))
            entry.update(high=_float(sample["hdi"][1][i] / scale))
        ref = data.case.reference
        entry["reference"] = None if ref is None else _float(ref[i] / scale)
        constants.append(entry)
    fit = None if estimate is None else estimate.get("fit")
    if fit is not None:
        fits = bool(fit["p_value"] >= REJECT_P)
        fit = {
            "chi2": _float(fit["chi2"]),
            "dof": _float(fit["dof"]),
            "p_value": _float(fit["p_value"]),
            "fits": fits,
        }
    status = None
    if estimate is not None:
        status = estimate.get("status") or ("converged" if estimate["converged"] else "stopped")
    diagnosis = None
    if "diagnose" in r:
        d = r["diagnose"]["diagnosis"]
        diagnosis = {
            "verdict": d["verdict"],
            "chosen": d["chosen"],
            "rival": (d.get("rival") or {}).get("physics"),
            "also_tied": list(d.get("also_tied") or []),
        }
    return {
        "case": data.case.name,
        "label": data.label,
        "version": data.version,
        "estimator": None if estimate is None else at,
        "interval": interval,
        "constants": constants,
        "fit": fit,
        "fit_threshold_p": REJECT_P,
        "status": status,
        "warnings": [] if estimate is None else list(estimate.get("warnings", ())),
        "diagnosis": diagnosis,
    }


def _g(value, fmt="#.4g"):
    return "n/a" if value is None else format(value, fmt)


def _value(c, key, sd=False):
    """A constant's number as the estimates table writes it: nu12 to 3 decimals."""
    if c["name"] == "nu12":
        return _g(c[key], ".3f")
    return _g(c[key], "#.2g" if sd else "#.4g")


def _estimate_cell(c):
    """``"113.6 ± 2.6"``, as in the estimates table."""
    if c["estimate"] is None:
        return "n/a"
    return f"{_value(c, 'estimate')} ± {_value(c, 'sd', sd=True)}"


def summary_lines(summary):
    """The summary's Markdown lines (the top of ``report.md``), from :func:`report_summary`."""
    at = summary["estimator"]
    lines = ["## Summary", ""]
    if at is None:
        return lines + [
            "No estimator converged: there is no estimate to summarise (see Estimates below).",
            "",
        ]
    what = "the posterior mode" if at == "B" else "B did not converge"
    lines += [
        f"The elastic constants by {at} ({what}), with 94 % intervals: the {summary['interval']}.",
        "",
    ]
    ref = any(c["reference"] is not None for c in summary["constants"])
    head = ["constant", f"{at} ± sd", "94 % interval"] + (["reference"] if ref else [])
    rows = []
    for c in summary["constants"]:
        row = [
            f"{c['name']} ({c['unit']})",
            _estimate_cell(c),
            f"{_value(c, 'low')} to {_value(c, 'high')}",
        ]
        rows.append(row + ([_value(c, "reference")] if ref else []))
    lines += ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows] + [""]
    fit = summary["fit"]
    if fit is None:
        lines.append("- Fit: not assessed (a cache made before the fit statement)")
    else:
        says = "**the model fits**" if fit["fits"] else "**the model does not fit**"
        chi2, dof, p = _g(fit["chi2"], ".3g"), _g(fit["dof"], ".1f"), _g(fit["p_value"], ".2g")
        below = f"{summary['fit_threshold_p']:g}"
        lines.append(
            f"- Fit: {says} the measured frequencies: chi-square {chi2} on {dof} "
            f"degrees of freedom, p {p} (rejected below p {below})"
        )
    status = summary["status"]
    lines.append(f"- Status of {at}: " + (status if status == "converged" else f"**{status}**"))
    lines += [f"  - **warning**: {w}" for w in summary["warnings"]]
    d = summary["diagnosis"]
    if d is None:
        lines.append("- Diagnosis: not run (--no-diagnose)")
    else:
        others = " or ".join([d["rival"]] * bool(d["rival"]) + d["also_tied"])
        verdict = "explained" if d["verdict"] == "ambiguous" and not others else d["verdict"]
        text = _VERDICTS.get(verdict, "").format(chosen=d["chosen"], others=others)
        lines.append(f"- Diagnosis: **{d['verdict']}**" + (f": {text}" if text else ""))
    return lines + [""]


# --------------------------------------------------------------------------- Markdown -> HTML

_CSS = """
*{box-sizing:border-box}
html{-webkit-text-size-adjust:100%}
body{margin:0;color:#1f2328;background:#fff;font:16px/1.5 system-ui,-apple-system,"Segoe UI",
Roboto,"Helvetica Neue",Arial,sans-serif}
main{max-width:74rem;margin:0 auto;padding:1rem 1.2rem 3rem}
h1{font-size:1.7rem;line-height:1.25;margin:.6rem 0}
h2{font-size:1.35rem;border-bottom:1px solid #d0d7de;padding-bottom:.2rem;margin:2.2rem 0 .8rem}
h3{font-size:1.1rem;margin:1.6rem 0 .6rem}
h1,h2,h3,p,li,blockquote,figcaption{overflow-wrap:anywhere}
code{font-family:ui-monospace,SFMono-Regular,Menlo,Consolas,monospace;font-size:.88em;
background:#f2f4f7;padding:.05em .3em;border-radius:4px}
blockquote{margin:.8rem 0;padding:.3rem .9rem;border-left:4px solid #d4a72c;background:#fff8c5}
blockquote p{margin:.3rem 0}
ul{padding-left:1.4rem}
li{margin:.2rem 0}
.table-wrap{overflow-x:auto;margin:.8rem 0;max-width:100%}
table{border-collapse:collapse;font-size:.86rem}
th,td{border:1px solid #d0d7de;padding:.25rem .55rem;white-space:nowrap;text-align:left}
th{background:#f6f8fa}
td.num{text-align:right;font-variant-numeric:tabular-nums}
tbody tr:nth-child(even){background:#fafbfc}
figure{margin:1.4rem 0}
figure img{display:block;max-width:100%;height:auto;margin:0 auto}
figcaption{font-size:.9rem;color:#424a53;margin-top:.4rem}
.summary{background:#f6f8fa;border:1px solid #d0d7de;border-radius:8px;padding:.1rem 1rem .6rem;
margin-top:1.2rem}
.summary h2{border:0;margin-top:.8rem}
.summary table{background:#fff;font-size:.95rem}
nav.contents{font-size:.92rem;margin:1rem 0}
nav.contents a{margin-right:.9rem;white-space:nowrap}
@media (max-width:600px){body{font-size:15px}main{padding:.6rem .5rem 2rem}h1{font-size:1.4rem}
th,td{padding:.2rem .35rem}.summary{padding:.1rem .4rem .5rem}
.summary th,.summary td{padding:.2rem .25rem}
.summary table{font-size:.8rem}.summary th,.summary td{white-space:normal}
.summary td.num{white-space:nowrap}}
@media print{main{max-width:none;padding:0}.table-wrap{overflow:visible}
figure,table,.summary{break-inside:avoid}nav.contents{display:none}}
"""
# nothing may leave the file: images only from data URIs, styles only inline, no script
_CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
_IMAGE = re.compile(r"^!\[(.*)\]\(([^()\s]+)\)$")
_CAPTION = re.compile(r"^\*(.+)\*$")
_NUMBER = re.compile(r"^[-+]?(\d[\d.,]*(e[-+]?\d+)?|n/a)( ± [\d.e+-]+)?( to [-+\d.e]+)?$")


def _inline(text):
    """Escaped text with code spans, bold and italic."""
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for part in parts:
        if len(part) > 1 and part.startswith("`") and part.endswith("`"):
            out.append(f"<code>{html.escape(part[1:-1])}</code>")
            continue
        part = html.escape(part, quote=False)
        part = re.sub(r"\*\*(\S(?:.*?\S)?)\*\*", r"<strong>\1</strong>", part)
        part = re.sub(r"(?<![\w*])\*(?!\s)([^*]+?)(?<!\s)\*(?![\w*])", r"<em>\1</em>", part)
        out.append(part)
    return "".join(out)


def _slug(text):
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "section"


def _png_size(png):
    """``(width, height)`` in pixels from a PNG's header."""
    if png[:8] != b"\x89PNG\r\n\x1a\n" or png[12:16] != b"IHDR":
        raise ValueError("not a PNG")
    return struct.unpack(">II", png[16:24])


def _cells(line):
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _table_html(rows):
    head, body = rows[0], rows[2:]
    out = ['<div class="table-wrap"><table>', "<thead><tr>"]
    out += [f"<th>{_inline(c)}</th>" for c in head] + ["</tr></thead>", "<tbody>"]
    for row in body:
        cells = [
            f'<td class="num">{_inline(c)}</td>' if _NUMBER.match(c) else f"<td>{_inline(c)}</td>"
            for c in row
        ]
        out.append("<tr>" + "".join(cells) + "</tr>")
    return out + ["</tbody></table></div>"]


def _figure_html(alt, src, caption, images):
    if src not in images:
        raise ValueError(f"report.html: the figure {src} is not among the images given")
    png = images[src]
    width, height = _png_size(png)
    data = base64.b64encode(png).decode("ascii")
    return [
        "<figure>",
        f'<img src="data:image/png;base64,{data}" alt="{html.escape(alt)}" width="{width}" '
        f'height="{height}">',
        f"<figcaption>{_inline(caption)}</figcaption>" if caption else "",
        "</figure>",
    ]


def _body_html(text, images):
    """The HTML of the Markdown `text` (the constructs markdown.py emits), sections wrapped."""
    lines = text.splitlines()
    out, paragraph, in_list, section = [], [], 0, False
    sections = []

    def flush():
        nonlocal in_list
        if paragraph:
            out.append(f"<p>{_inline(' '.join(paragraph))}</p>")
            paragraph.clear()
        while in_list:
            out.append("</li></ul>")
            in_list -= 1

    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        heading = re.match(r"^(#{1,3}) (.+)$", line)
        image = _IMAGE.match(stripped)
        if not stripped:
            flush()
        elif heading:
            flush()
            level, title = len(heading.group(1)), heading.group(2)
            if level == 2:
                if section:
                    out.append("</section>")
                slug = _slug(title)
                sections.append((slug, title))
                kind = ' class="summary"' if title == "Summary" else ""
                out.append(f'<section id="{slug}"{kind}>')
                section = True
            out.append(f"<h{level}>{_inline(title)}</h{level}>")
        elif image:
            flush()
            caption = None
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            if j < len(lines) and _CAPTION.match(lines[j].strip()):
                caption, i = _CAPTION.match(lines[j].strip()).group(1), j
            out += _figure_html(image.group(1), image.group(2), caption, images)
        elif stripped.startswith("|"):
            flush()
            rows = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                rows.append(_cells(lines[i]))
                i += 1
            out += _table_html(rows)
            continue
        elif stripped.startswith(">"):
            flush()
            out.append("<blockquote>")
            while i < len(lines) and lines[i].strip().startswith(">"):
                out.append(f"<p>{_inline(lines[i].strip()[1:].strip())}</p>")
                i += 1
            out.append("</blockquote>")
            continue
        elif re.match(r"^ *- ", line):
            if paragraph:
                out.append(f"<p>{_inline(' '.join(paragraph))}</p>")
                paragraph.clear()
            depth = (len(line) - len(line.lstrip(" "))) // 2 + 1
            if depth > in_list:
                while in_list < depth:
                    out.append("<ul><li>")
                    in_list += 1
            else:
                while in_list > depth:
                    out.append("</li></ul>")
                    in_list -= 1
                out.append("</li><li>")
            out.append(_inline(stripped[2:]))
        elif in_list and line.startswith("  "):
            out.append(" " + _inline(stripped))  # a list item's continued line
        else:
            if in_list:
                flush()
            paragraph.append(stripped)
        i += 1
    flush()
    if section:
        out.append("</section>")
    return out, sections


def render_html(markdown_text, images, title):
    """One self-contained HTML page of a report.

    Parameters
    ----------
    markdown_text : str
        The report's Markdown (:func:`~bayesplate.report.markdown.render_markdown`).
    images : dict
        File name in the Markdown (``"residuals.png"``) -> its PNG bytes; every figure the
        text shows must be here (embedded as a data URI).
    title : str
        The page's title.

    Returns
    -------
    str
    """
    body, sections = _body_html(markdown_text, images)
    links = [f'<a href="#{slug}">{html.escape(name)}</a>' for slug, name in sections]
    if links:  # a line of contents after the summary, else before the first section
        starts = [k for k, line in enumerate(body) if line.startswith("<section")]
        at = starts[1] if sections[0][1] == "Summary" and len(starts) > 1 else starts[0]
        body.insert(at, '<nav class="contents">Contents: ' + " ".join(links) + "</nav>")
    head = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        f'<meta http-equiv="Content-Security-Policy" content="{_CSP}">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        '<link rel="icon" href="data:,">',
        f"<title>{html.escape(title)}</title>",
        f"<style>{_CSS.strip()}</style>",
        "</head>",
        "<body>",
        "<main>",
    ]
    return (
        "\n".join(head + [line for line in body if line] + ["</main>", "</body>", "</html>"]) + "\n"
    )
