"""Normalised sensitivities of eq. 29 (the paper's Figs. 2-3, section 4.1).

Writes ``sensitivity.md``, ``fig2_sensitivity_plate1.png``, ``fig3_sensitivity_plate2.png``
and ``sensitivity_frederiksen.png`` to ``out_dir``: ``s_ij = (d lambda_i / d C_j) C_j /
lambda_i`` of the first 14 modes at the case's reference constants, and a check, computed from the
numbers, of what section 4.1 says about them.

Run: ``python -m studies.sensitivity_figures [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib
import numpy as np

from bayesplate import plots
from bayesplate.discrepancy.search.locate import mode_kinds
from bayesplate.io import bundled_case_path, load_case
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import STIFFNESS_NAMES

matplotlib.use("Agg")  # files only, never a window

REPORT = "sensitivity.md"
N_MODES = 14
QUICK_MESH = (24, 12)  # Frederiksen plate in quick mode (its own mesh is 50 x 50)
CASES = {  # figure, label, paper figure, which constants the case's [reference] holds
    "plate1": ("fig2_sensitivity_plate1.png", "Plate 1", "paper Fig. 2", "the target constants"),
    "plate2": ("fig3_sensitivity_plate2.png", "Plate 2", "paper Fig. 3", "the target constants"),
    "frederiksen_t300": (
        "sensitivity_frederiksen.png",
        "Frederiksen T300/epoxy plate",
        None,
        "Frederiksen's constants",
    ),
}
STRONG = ("C11", "C22", "C66")  # the coefficients section 4.1 finds the frequencies sensitive to
WEAK = ("C12", "C44", "C55")


# ----------------------------------------------------------------------------- computation


def sensitivities(name, mesh=None):
    """Case, model mesh and modes (with sensitivities) at the case's reference constants."""
    case = load_case(bundled_case_path(name))
    model = PlateModel.from_case(case, mesh=mesh)
    result = model.solve(stiffness_from_engineering(case.reference), N_MODES)
    return {
        "case": case,
        "mesh": (model.mesh.nx, model.mesh.ny),
        "frequency_Hz": result.frequency_Hz,
        "s": result.normalised_sensitivities(),
        "kinds": mode_kinds(model, result),
    }


def _columns(names):
    return [STIFFNESS_NAMES.index(n) for n in names]


def claims(runs):
    """Section 4.1 (and 4.2) statements about Figs. 2-3, checked on our numbers.

    Returns
    -------
    list of dict
        ``claim``, ``paper`` (where it is said), ``ours`` (the numbers), ``agree`` (bool).
    """
    s1, s2 = np.abs(runs["plate1"]["s"]), np.abs(runs["plate2"]["s"])
    strong, weak = _columns(STRONG), _columns(WEAK)
    c11, c22, c12 = (STIFFNESS_NAMES.index(n) for n in ("C11", "C22", "C12"))
    out = []

    plates = {"plate1": s1, "plate2": s2}
    dominant = {k: [STIFFNESS_NAMES[j] for j in np.argmax(s, axis=1)] for k, s in plates.items()}
    share = {k: s[:, strong].sum(axis=1) / s.sum(axis=1) for k, s in plates.items()}
    mean = {k: s.mean(axis=0) for k, s in plates.items()}
    all_strong = all(d in STRONG for ds in dominant.values() for d in ds)
    ranked = all(m[strong].min() > m[weak].max() for m in mean.values())
    out.append(
        {
            "claim": "The first frequencies are most sensitive to C11, C22 and C66, much less "
            "to C12, C44 and C55",
            "paper": "4.1 (Figs. 2-3), 5",
            "ours": "largest abs(s) of each of the 14 modes is C11, C22 or C66: "
            f"{'yes' if all_strong else 'no'} on both plates; smallest mean abs(s) of "
            "C11, C22, C66 vs largest of C12, C44, C55: "
            + ", ".join(
                f"{k} {m[strong].min():.3f} vs {m[weak].max():.3f}" for k, m in mean.items()
            )
            + "; share of C11+C22+C66 in the row sum of abs(s), mean over modes: "
            + ", ".join(f"{k} {v.mean():.2f}" for k, v in share.items()),
            "agree": bool(all_strong and ranked),
        }
    )
    m1, m2 = s1[:, c12].mean(), s2[:, c12].mean()
    x1, x2 = s1[:, c12].max(), s2[:, c12].max()
    out.append(
        {
            "claim": "Plate 1 (a/b = 2) is more sensitive to C12 than Plate 2",
            "paper": "4.1",
            "ours": f"mean abs(s(C12)) over 14 modes {m1:.4f} vs {m2:.4f} (ratio {m1 / m2:.2f}); "
            f"max {x1:.4f} vs {x2:.4f}",
            "agree": bool(m1 > m2 and x1 > x2),
        }
    )
    m1, m2 = s1[:, c11].mean(), s2[:, c11].mean()
    out.append(
        {
            "claim": "Plate 2 (a/b = 1) is less sensitive to C11 than Plate 1",
            "paper": "4.1",
            "ours": f"mean abs(s(C11)) over 14 modes: Plate 2 {m2:.3f} vs Plate 1 {m1:.3f} "
            f"(ratio {m2 / m1:.2f}); modes with abs(s(C11)) > 0.1: Plate 2 "
            f"{int(np.sum(s2[:, c11] > 0.1))}, Plate 1 {int(np.sum(s1[:, c11] > 0.1))}",
            "agree": bool(m2 < m1),
        }
    )
    signed = [runs[k]["s"][:, [c11, c22]] for k in ("plate1", "plate2")]
    positive = all(bool(np.all(s > 0)) for s in signed)
    out.append(
        {
            "claim": "The sensitivities to C11 and C22 are positive for every mode (printed "
            "as s_i1 and s_i3)",
            "paper": "4.2",
            "ours": "smallest s(C11), s(C22): "
            + ", ".join(
                f"{k} {runs[k]['s'][:, c11].min():.4f}, {runs[k]['s'][:, c22].min():.4f}"
                for k in ("plate1", "plate2")
            ),
            "agree": positive,
        }
    )
    return out


def compute(quick=False):
    """Sensitivities of the three plates and the checks of section 4.1 (no files)."""
    runs = {
        name: sensitivities(name, QUICK_MESH if quick and name == "frederiksen_t300" else None)
        for name in CASES
    }
    return {"runs": runs, "claims": claims(runs)}


# ----------------------------------------------------------------------------- report


def _table(headers, rows):
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _sensitivity_table(run):
    s = run["s"]
    headers = ["mode", "f (Hz)", "kind"] + [f"s {n}" for n in STIFFNESS_NAMES] + ["sum"]
    kind = run["kinds"]
    rows = [
        [i + 1, f"{run['frequency_Hz'][i]:.1f}", kind[i]]
        + [f"{v:+.4f}" for v in s[i]]
        + [f"{s[i].sum():.4f}"]
        for i in range(len(s))
    ]
    rows.append(["mean abs", "", ""] + [f"{v:.4f}" for v in np.abs(s).mean(axis=0)] + [""])
    return _table(headers, rows)


def write_report(results, out_dir, quick=False):
    """Write the Markdown report."""
    flag = " --quick" if quick else ""
    runs = results["runs"]
    agree = all(c["agree"] for c in results["claims"])
    parts = [
        f"Made by `python -m studies.sensitivity_figures{flag}` (every report: "
        f"`python -m studies.run_all{flag}`); no random numbers (ARPACK's start vector "
        "aside: results repeat to rounding).",
        "",
        "# Normalised sensitivities (eq. 29; paper Figs. 2-3)",
        "",
        "`s_ij = (d lambda_i / d C_j) C_j / lambda_i` (dimensionless) at the reference "
        "constants, from `ModalResult.normalised_sensitivities()`. The paper plots `|s_ij|` "
        "and prints no numbers, so its statements about the figures are checked instead. "
        "Because `K` is linear in the six coefficients and `M` does not depend on them, every "
        "row sums to 1 (Euler's theorem); the `sum` column is that check. `kind` is "
        "`bayesplate.discrepancy.physics.location.mode_kinds`: `in-plane` when most of the kinetic "
        "energy is in u, v (the paper's 14 modes include such modes, which do not depend on "
        "C44 and C55), otherwise named by the dominant coefficient.",
        "",
        "## The paper's statements against our numbers",
        "",
        _table(
            ["statement", "paper section", "ours", "agree"],
            [
                [c["claim"], c["paper"], c["ours"], "yes" if c["agree"] else "**no**"]
                for c in results["claims"]
            ],
        ),
        "",
        f"All statements {'agree' if agree else 'do NOT all agree'} with our sensitivities.",
        "",
    ]
    for name, (png, label, fig, constants) in CASES.items():
        run = runs[name]
        where = f", cf. {fig}" if fig else ""
        parts += [
            f"## {label} (mesh {run['mesh'][0]}x{run['mesh'][1]}, at {constants}{where})",
            "",
            _sensitivity_table(run),
            "",
            f"![{label}]({png})",
            "",
        ]
    path = pathlib.Path(out_dir) / REPORT
    path.write_text("\n".join(parts))
    return path


def plot(results):
    """One figure per plate, ``{file name: figure}``."""
    figures = {}
    for name, (png, label, fig_ref, constants) in CASES.items():
        run = results["runs"][name]
        p = run["case"].plate
        title = (
            f"{label} ({p.length * 1e3:g} x {p.width * 1e3:g} x {p.thickness * 1e3:g} mm, "
            f"{run['mesh'][0]}x{run['mesh'][1]} mesh) at {constants}"
            + (f"; cf. {fig_ref}" if fig_ref else "")
        )
        notes = ["in-plane" if kind == "in-plane" else "" for kind in run["kinds"]]
        figures[png] = plots.sensitivity_bars(run["s"], title=title, notes=notes)
    return figures


def main(out_dir, quick=False):
    """Compute, write the report and the figures; return the results dict."""
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = compute(quick=quick)
    write_report(results, out_dir, quick=quick)
    for png, fig in plot(results).items():
        fig.savefig(out_dir / png, dpi=110)
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="Frederiksen plate on 24 x 12")
    parser.add_argument("--out", default=pathlib.Path(__file__).parents[1] / "reports")
    args = parser.parse_args()
    main(args.out, quick=args.quick)
