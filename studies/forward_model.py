"""Forward model against the paper's frequencies (Tables 2, 16, 19, 22) and mesh convergence.

Writes ``forward_model.md``, ``forward_model_differences.png`` and
``mode_shapes_frederiksen.png`` to ``out_dir``:

- Plates 1 and 2 (Table 2, 8 x 4 and 8 x 8 meshes) at the target constants, with exact and
  with reduced (2 x 2) integration of the transverse-shear terms;
- the cross-ply and angle-ply laminates (Tables 16 and 19, 20 x 20) for both readings of the
  stacking sequences printed without subscripts (33 plies with a single middle 0 ply, and
  32 plies without it);
- the measured Frederiksen plate (Table 22, 50 x 50) at Frederiksen's constants and at the
  prior mean;
- mesh convergence of the Frederiksen plate with a Richardson estimate of the discretisation
  error of each mode, against the 1 % measurement deviation.

Run: ``python -m studies.forward_model [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from scipy.optimize import linear_sum_assignment

from bayesplate import plots
from bayesplate.discrepancy.search.locate import mode_kinds
from bayesplate.io import bundled_case_path, load_case
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.plate.model import PlateModel

matplotlib.use("Agg")  # files only, never a window

REPORT = "forward_model.md"
FIGURE = "forward_model_differences.png"
SHAPES = "mode_shapes_frederiksen.png"
N_MODES = 14
SIGMA_REL = 0.01  # the paper's measurement deviation, d f = 0.01 f (section 4)

# The stacking sequences of Tables 15 and 18, both readings of the lost subscripts.
LAYUPS = {
    "crossply": {
        "33 plies [(0/90)8/0/(90/0)8]": [0, 90] * 8 + [0] + [90, 0] * 8,
        "32 plies [(0/90)8/(90/0)8]": [0, 90] * 8 + [90, 0] * 8,
    },
    "angleply": {
        "33 plies [(0/45/90/-45)4/0/(45/90/-45/0)4]": [0, 45, 90, -45] * 4
        + [0]
        + [45, 90, -45, 0] * 4,
        "32 plies [(0/45/90/-45)4/(45/90/-45/0)4]": [0, 45, 90, -45] * 4 + [45, 90, -45, 0] * 4,
    },
}
TABLES = {"plate1": "Table 2", "plate2": "Table 2", "crossply": "Table 16", "angleply": "Table 19"}

# Mesh convergence of the Frederiksen plate: a family refined by 2 for Richardson
# extrapolation (it contains the paper's 50 x 50 mesh), plus the coarse default meshes.
FAMILY = [(25, 25), (50, 50), (100, 100)]
EXTRA = [(12, 6), (24, 12)]
QUICK_FAMILY = [(6, 6), (12, 12), (24, 24)]
QUICK_EXTRA = [(12, 6)]
QUICK_MESH = (24, 12)  # Frederiksen plate in quick mode
MAC_GRID = (13, 7)  # points along x and y where mode shapes are compared across meshes


# ----------------------------------------------------------------------------- computation


def percent(computed, reference):
    """``100 (computed - reference) / reference``."""
    return 100.0 * (np.asarray(computed) - reference) / reference


def printed_half_unit(values, digits=5):
    """Half a unit in the last printed digit of values printed to ``digits`` figures."""
    values = np.asarray(values, dtype=float)
    return 0.5 * 10.0 ** (np.floor(np.log10(values)) - (digits - 1))


def frequencies(model, e, n=N_MODES):
    """First ``n`` elastic frequencies (Hz) of ``model`` at engineering constants ``e`` (SI)."""
    return model.solve(stiffness_from_engineering(e), n).frequency_Hz


def case_model(case, layup=None, **kwargs):
    """Model of ``case`` on its own mesh, optionally with another layup (equal plies)."""
    if layup is None:
        return PlateModel.from_case(case, **kwargs)
    p = case.plate
    return PlateModel(p.length, p.width, p.thickness, p.density, layup, mesh=case.mesh, **kwargs)


def _runs(case, models):
    """Frequencies of every model at the reference constants, and the kinds of the first
    model's modes (:func:`bayesplate.discrepancy.physics.location.mode_kinds`)."""
    b = stiffness_from_engineering(case.reference)
    results = {label: model.solve(b, N_MODES) for label, model in models.items()}
    first = next(iter(models))
    kinds = mode_kinds(models[first], results[first])
    return {label: r.frequency_Hz for label, r in results.items()}, kinds


def single_layer_rows(name):
    """Plates 1 and 2 at the target constants, exact and reduced shear integration.

    Returns ``(case, paper frequencies, {label: frequencies})`` and the kinds of the modes
    (exact integration).
    """
    case = load_case(bundled_case_path(name))
    models = {
        "exact (4x4) shear integration": case_model(case),
        "reduced (2x2) shear integration": case_model(case, shear_order=2),
    }
    runs, kinds = _runs(case, models)
    return (case, case.measured.frequency_Hz, runs), kinds


def laminate_rows(name):
    """Cross-ply or angle-ply laminate at the target constants for both layup readings.

    Returns ``(case, paper frequencies, {reading: frequencies})`` and the kinds of the
    modes (33-ply reading, the bundled one).
    """
    case = load_case(bundled_case_path(name))
    readings = LAYUPS[name]
    bundled = next(iter(readings.values()))
    assert np.array_equal(case.plate.layup_deg, bundled), "bundled layup is the 33-ply one"
    models = {label: case_model(case, layup) for label, layup in readings.items()}
    runs, kinds = _runs(case, models)
    return (case, case.measured.frequency_Hz, runs), kinds


def frederiksen_rows(mesh=None):
    """The measured plate at Frederiksen's constants and at the prior mean.

    Returns the case, the measured frequencies, the runs and the model with its modes at
    Frederiksen's constants (for the mode-shape figure).
    """
    case = load_case(bundled_case_path("frederiksen_t300"))
    model = PlateModel.from_case(case, mesh=mesh)
    at_reference = model.solve(stiffness_from_engineering(case.reference), N_MODES)
    runs = {
        "Frederiksen's constants": at_reference.frequency_Hz,
        "prior mean": frequencies(model, case.prior.mean),
    }
    return (case, case.measured.frequency_Hz, runs), (model, at_reference)


def _mac(shapes, reference):
    """MAC matrix between the columns of ``shapes`` and of ``reference``."""
    num = (shapes.T @ reference) ** 2
    den = np.outer(np.sum(shapes**2, axis=0), np.sum(reference**2, axis=0))
    return num / np.maximum(den, np.finfo(float).tiny)  # an in-plane mode has w = 0


def convergence(family=FAMILY, extra=EXTRA, n=N_MODES):
    """Frequencies of the Frederiksen plate on several meshes and a Richardson estimate.

    The modes of every mesh are paired with those of the finest mesh by their MAC (w on a
    grid of points), so that Richardson extrapolation follows one physical mode even where
    two close modes swap order between meshes. The family is refined by 2; per mode the
    observed order is ``p = log2((f_1 - f_2) / (f_2 - f_3))`` and the limit
    ``f_inf = f_3 + (f_3 - f_2) / (2^p - 1)``. Where the differences do not shrink
    monotonically the theoretical ``p = 2`` (bilinear in-plane and rotation fields) is used.

    Returns
    -------
    dict
        ``meshes``, ``f`` (n_meshes, n) Hz in the finest mesh's mode order, ``dofs``,
        ``order`` (n,), ``order_observed`` (bool, n), ``f_inf`` (n,), ``error_rel``
        (n_meshes, n) = ``f / f_inf - 1``, ``mac`` (n_meshes, n) MAC of each paired mode,
        ``swapped`` list of (mesh, frequency-order index, paired finest-mesh index), 1-based.
    """
    case = load_case(bundled_case_path("frederiksen_t300"))
    meshes = list(extra) + list(family)
    xs = np.linspace(0, case.plate.length, MAC_GRID[0])
    ys = np.linspace(0, case.plate.width, MAC_GRID[1])
    X, Y = np.meshgrid(xs, ys)
    points = np.column_stack([X.ravel(), Y.ravel()])
    f, dofs, shapes = [], [], []
    for mesh in meshes:
        model = PlateModel.from_case(case, mesh=mesh)
        # two spare modes so that a pair straddling mode n can still be matched
        result = model.solve(stiffness_from_engineering(case.reference), n + 2)
        f.append(result.frequency_Hz)
        dofs.append(model.mesh.n_dofs)
        shapes.append(model.interpolation(points, "w") @ result.vectors)
    paired, macs, swapped = [], [], []
    for mesh, fm, sm in zip(meshes, f, shapes, strict=True):
        mac = _mac(sm, shapes[-1][:, :n])
        rows, cols = linear_sum_assignment(-mac)
        index = np.empty(n, dtype=int)
        index[cols] = rows
        paired.append(fm[index])
        macs.append(mac[index, np.arange(n)])
        swapped += [(mesh, int(i) + 1, k + 1) for k, i in enumerate(index) if i != k]
    f = np.array(paired)
    f1, f2, f3 = f[len(extra) :]
    d12, d23 = f1 - f2, f2 - f3
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = d12 / d23
        observed = (ratio > 1.0) & np.isfinite(ratio)
        order = np.where(observed, np.log2(np.where(observed, ratio, 4.0)), 2.0)
    f_inf = f3 - d23 / (2.0**order - 1.0)
    return {
        "meshes": meshes,
        "n_extra": len(extra),
        "f": f,
        "dofs": np.array(dofs),
        "order": order,
        "order_observed": observed,
        "f_inf": f_inf,
        "error_rel": f / f_inf - 1.0,
        "mac": np.array(macs),
        "swapped": swapped,
    }


def compute(quick=False):
    """Every number of the report, as a dict of tables (no files, no plots).

    ``quick`` solves the Frederiksen plate on 24 x 12 instead of its 50 x 50 mesh and the
    convergence study on the family 6x6, 12x12, 24x24 (and 12x6).
    """
    tables, kinds = {}, {}
    for name in ("plate1", "plate2"):
        tables[name], kinds[name] = single_layer_rows(name)
    for name in ("crossply", "angleply"):
        tables[name], kinds[name] = laminate_rows(name)
    tables["frederiksen_t300"], shapes = frederiksen_rows(QUICK_MESH if quick else None)
    kinds["frederiksen_t300"] = mode_kinds(*shapes)
    family, extra = (QUICK_FAMILY, QUICK_EXTRA) if quick else (FAMILY, EXTRA)
    return {
        "tables": tables,
        "kinds": kinds,
        "shapes": shapes,
        "convergence": convergence(family, extra),
    }


def max_abs_diff(results):
    """``{case: {run label: max |diff| %}}``."""
    return {
        name: {label: float(np.max(np.abs(percent(f, paper)))) for label, f in runs.items()}
        for name, (_, paper, runs) in results["tables"].items()
    }


# ----------------------------------------------------------------------------- report


def _table(headers, rows):
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _comparison_table(paper, runs, paper_label, kinds):
    headers = ["mode", paper_label, "kind"]
    for label in runs:
        headers += [f"{label} (Hz)", "diff %"]
    rows = []
    for i, fp in enumerate(paper):
        row = [i + 1, f"{fp:.5g}", kinds[i]]
        for f in runs.values():
            row += [f"{f[i]:.2f}", f"{percent(f[i], fp):+.4f}"]
        rows.append(row)
    maxima = ["max abs", "", ""]
    for f in runs.values():
        maxima += ["", f"{np.max(np.abs(percent(f, paper))):.4f}"]
    return _table(headers, rows + [maxima])


def _in_plane_modes(kinds):
    """1-based indices of the in-plane modes."""
    return [i + 1 for i, kind in enumerate(kinds) if kind == "in-plane"]


def _reproduced(f, paper):
    """Number of modes whose computed value rounds to the printed one (5 figures)."""
    return int(np.sum(np.abs(np.asarray(f) - paper) <= printed_half_unit(paper) * (1 + 1e-9)))


def _mesh_name(mesh):
    return f"{mesh[0]}x{mesh[1]}"


def _frederiksen_mesh(results):
    model = results["shapes"][0]
    return (model.mesh.nx, model.mesh.ny)


def _reduced_effect(results):
    """Which modes reduced shear integration leaves unchanged, against the in-plane ones."""
    same = True
    for name in ("plate1", "plate2"):
        _, _, runs = results["tables"][name]
        exact, reduced = runs.values()
        unchanged = [int(i) + 1 for i in np.flatnonzero(np.abs(reduced / exact - 1) < 1e-8)]
        same &= unchanged == _in_plane_modes(results["kinds"][name])
    return (
        "Reduced shear integration changes every bending mode and leaves exactly the in-plane "
        "modes unchanged (Plates 1 and 2)."
        if same
        else "Reduced shear integration does not leave exactly the in-plane modes unchanged."
    )


def findings(results):
    """The findings paragraph, computed from the numbers."""
    t = results["tables"]
    mx = max_abs_diff(results)
    lines = []
    for name in ("plate1", "plate2"):
        case, paper, runs = t[name]
        (exact_label, exact), (reduced_label, reduced) = runs.items()
        lines.append(
            f"- **{name}** ({TABLES[name]}, mesh {_mesh_name(case.mesh)}): exact shear "
            f"integration max |diff| {mx[name][exact_label]:.4f} %, "
            f"{_reproduced(exact, paper)}/{len(paper)} modes equal to the printed digits; "
            f"reduced 2x2 shear integration max |diff| {mx[name][reduced_label]:.3f} % "
            f"({_reproduced(reduced, paper)}/{len(paper)} printed digits). Exact integration "
            "is what reproduces the paper."
        )
    for name in ("crossply", "angleply"):
        case, paper, runs = t[name]
        parts = [
            f"{label}: max |diff| {mx[name][label]:.4f} % "
            f"({_reproduced(f, paper)}/{len(paper)} printed digits)"
            for label, f in runs.items()
        ]
        best = min(mx[name], key=mx[name].get)
        lines.append(
            f"- **{name}** ({TABLES[name]}, {_mesh_name(case.mesh)}): "
            + "; ".join(parts)
            + f". The reading that reproduces the paper is **{best}**."
        )
    case, measured, runs = t["frederiksen_t300"]
    (ref_label, ref), (prior_label, _) = runs.items()
    diff = percent(ref, measured)
    lines.append(
        f"- **frederiksen_t300** (Table 22, measured, {_mesh_name(_frederiksen_mesh(results))}):"
        f" at Frederiksen's constants max |diff| {mx['frederiksen_t300'][ref_label]:.3f} % "
        f"(rms {np.sqrt(np.mean(diff**2)):.3f} %), inside the 1 % measurement deviation for "
        f"{int(np.sum(np.abs(diff) < 100 * SIGMA_REL))}/{len(measured)} modes; at the prior "
        f"mean max |diff| {mx['frederiksen_t300'][prior_label]:.1f} %."
    )
    inplane = {
        name: _in_plane_modes(results["kinds"][name])
        for name in ("plate1", "plate2", "crossply", "angleply")
    }
    listed = "; ".join(f"{name} {modes}" for name, modes in inplane.items() if modes)
    lines.append(
        "- **in-plane modes among the paper's 14**: "
        + (listed if listed else "none")
        + " (kinetic energy mostly in u, v; `kind` column). An out-of-plane vibration test "
        "would not normally measure these; the measured Frederiksen plate has "
        f"{len(_in_plane_modes(results['kinds']['frederiksen_t300']))} among its first 14 "
        "computed modes. " + _reduced_effect(results)
        if listed
        else "none."
    )
    conv = results["convergence"]
    worst = np.max(np.abs(conv["error_rel"]), axis=1) / SIGMA_REL
    per_mesh = ", ".join(
        f"{_mesh_name(m)} {w:.2f}" for m, w in zip(conv["meshes"], worst, strict=True)
    )
    swaps = ""
    if conv["swapped"]:
        by_mesh = {}
        for mesh, i, k in conv["swapped"]:
            by_mesh.setdefault(mesh, []).append(f"{i}->{k}")
        groups = {}
        for mesh, pairs in by_mesh.items():
            groups.setdefault(", ".join(sorted(pairs)), []).append(_mesh_name(mesh))
        swaps = (
            " Close modes swap order on coarser meshes (frequency-order index -> mode of "
            "the finest mesh): "
            + "; ".join(f"{pairs} on {', '.join(meshes)}" for pairs, meshes in groups.items())
            + "; the table pairs them by MAC."
        )
    lines.append(
        "- **mesh convergence** (Frederiksen plate): largest Richardson estimate of the "
        f"discretisation error over the 14 modes, in units of the 1 % deviation: {per_mesh}."
        + swaps
    )
    return "\n".join(lines)


def _convergence_section(conv):
    ne = conv["n_extra"]
    names = [_mesh_name(m) for m in conv["meshes"]]
    blank = [""] * len(names)
    headers = ["mode"] + [f"{m} (Hz)" for m in names] + ["p", "f_inf (Hz)"]
    headers += [f"err {m} / sigma" for m in names]
    rows = []
    for i in range(conv["f"].shape[1]):
        p = f"{conv['order'][i]:.2f}" + ("" if conv["order_observed"][i] else " (assumed)")
        row = [i + 1] + [f"{v:.2f}" for v in conv["f"][:, i]] + [p, f"{conv['f_inf'][i]:.2f}"]
        row += [f"{e / SIGMA_REL:+.3f}" for e in conv["error_rel"][:, i]]
        rows.append(row)
    rows.append(["unknowns"] + [str(d) for d in conv["dofs"]] + ["", ""] + blank)
    mac = np.min(conv["mac"], axis=1)
    rows.append(["min MAC of pairs"] + [f"{m:.3f}" for m in mac] + ["", ""] + blank)
    worst = np.max(np.abs(conv["error_rel"]), axis=1) / SIGMA_REL
    rows.append(["max abs err / sigma"] + blank + ["", ""] + [f"{w:.3f}" for w in worst])
    return "\n".join(
        [
            "## Mesh convergence, Frederiksen plate at Frederiksen's constants",
            "",
            f"Richardson extrapolation per mode on the family {', '.join(names[ne:])} (refined "
            "by 2): observed order `p = log2((f1 - f2) / (f2 - f3))`, limit "
            "`f_inf = f3 + (f3 - f2) / (2^p - 1)` (p = 2, the order of the bilinear in-plane "
            "and rotation fields, where the differences are not monotone). `err / sigma` is the "
            "discretisation error `f_mesh / f_inf - 1` in units of the 1 % measurement "
            f"deviation; the meshes {', '.join(names[:ne])} are judged against the same limit. "
            "Rows are physical modes in the finest mesh's order: every mesh's modes are paired "
            f"with them by the MAC of w on a {MAC_GRID[0]}x{MAC_GRID[1]} grid of points "
            "(row `min MAC of pairs`).",
            "",
            _table(headers, rows),
        ]
    )


def write_report(results, out_dir, quick=False):
    """Write the Markdown report."""
    t = results["tables"]
    flag = " --quick" if quick else ""
    parts = [
        f"Made by `python -m studies.forward_model{flag}` (every report: "
        f"`python -m studies.run_all{flag}`); no random numbers (ARPACK's start vector "
        "aside: results repeat to rounding).",
        "",
        "# Forward model against the paper",
        "",
        "`diff % = 100 (ours - paper) / paper`. The paper prints five significant figures, "
        "so a computed value equal to the printed one is within half a unit of the last "
        "digit (0.0037 % to 0.0049 % of these values).",
        "",
        "## Findings",
        "",
        findings(results),
        "",
    ]
    for name, label in (
        ("plate1", "Plate 1"),
        ("plate2", "Plate 2"),
        ("crossply", "Cross-ply laminate"),
        ("angleply", "Angle-ply laminate"),
    ):
        case, paper, runs = t[name]
        parts += [
            f"## {label} ({TABLES[name]}, mesh {_mesh_name(case.mesh)}, target constants)",
            "",
            _comparison_table(paper, runs, f"paper {TABLES[name]} (Hz)", results["kinds"][name]),
            "",
        ]
    case, measured, runs = t["frederiksen_t300"]
    parts += [
        "## Frederiksen T300/epoxy plate (Table 22, measured; mesh "
        f"{_mesh_name(_frederiksen_mesh(results))})",
        "",
        "Frederiksen's constants (Table 23): E1 113.0, E2 8.50 GPa, nu12 0.323, G12 4.45, "
        "G13 4.43, G23 2.97 GPa. Prior mean (rule of mixtures): 144, 16.5 GPa, 0.30, 6, 6, "
        "4 GPa.",
        "",
        _comparison_table(
            measured, runs, "measured Table 22 (Hz)", results["kinds"]["frederiksen_t300"]
        ),
        "",
        _convergence_section(results["convergence"]),
        "",
        f"![differences]({FIGURE})",
        "",
        f"![mode shapes]({SHAPES})",
        "",
    ]
    path = pathlib.Path(out_dir) / REPORT
    path.write_text("\n".join(parts))
    return path


def plot(results):
    """Figure of the percent differences of every table and of the discretisation error."""
    t = results["tables"]
    fig = Figure(figsize=(13, 13.5), layout="constrained")
    axes = fig.subplots(3, 2).ravel()
    titles = {
        "plate1": "Plate 1 (8x4) vs Table 2",
        "plate2": "Plate 2 (8x8) vs Table 2",
        "crossply": "cross-ply (20x20) vs Table 16",
        "angleply": "angle-ply (20x20) vs Table 19",
        "frederiksen_t300": f"Frederiksen plate ({_mesh_name(_frederiksen_mesh(results))}) "
        "vs measured Table 22",
    }
    for ax, (name, title) in zip(axes, titles.items(), strict=False):
        _, paper, runs = t[name]
        plots.frequency_comparison(runs, paper, ax=ax, title=title)
    ax = axes[-1]
    conv = results["convergence"]
    mode = np.arange(1, conv["f"].shape[1] + 1)
    for k, mesh in enumerate(conv["meshes"]):
        ax.semilogy(mode, np.abs(conv["error_rel"][k]) * 100, "o-", label=_mesh_name(mesh))
    ax.axhline(100 * SIGMA_REL, color="black", linestyle="--", label="1 % deviation")
    ax.set_xticks(mode)
    ax.set_xlabel("mode number")
    ax.set_ylabel("|f_mesh / f_inf - 1| [%]")
    ax.set_title("Frederiksen plate: discretisation error (Richardson)")
    ax.legend(fontsize="small", ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.16))
    return fig


def plot_mode_shapes(results, quick=False):
    """First six mode shapes of the Frederiksen plate at Frederiksen's constants."""
    model, result = results["shapes"]
    fig = plots.mode_shapes(model, result, n=6, points=(41, 21) if quick else (121, 61))
    fig.suptitle(
        "Frederiksen T300/epoxy plate, free-free, at Frederiksen's constants "
        f"({_mesh_name(_frederiksen_mesh(results))} mesh)"
    )
    return fig


def main(out_dir, quick=False):
    """Compute, write the report and the figures; return the results dict."""
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = compute(quick=quick)
    write_report(results, out_dir, quick=quick)
    plot(results).savefig(out_dir / FIGURE, dpi=110)
    plot_mode_shapes(results, quick).savefig(out_dir / SHAPES, dpi=110)
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small meshes for the convergence")
    parser.add_argument("--out", default=pathlib.Path(__file__).parents[1] / "reports")
    args = parser.parse_args()
    main(args.out, quick=args.quick)
