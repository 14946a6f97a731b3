"""A second measured plate: the spruce plate 5R of Badiane et al. (issue 16).

The bundled case `badiane_spruce_5R` (581 x 217 x 4.89 mm, free-free, one-point FRF, the
first 10 peaks the authors picked) is identified with B, MVE and MVE-mod, paired by order
and by the most probable assignment (`pairing="likelihood"`), its posterior sampled, and
diagnosed. Everything is compared with the source's own vibration-based constants, rescaled
to this case's thickness and density: the source computed them with h = 5.0 mm and
rho = 416 kg/m^3, and bending frequencies scale as h sqrt(E / rho), so the same frequencies
need E and G larger by (5.0 / 4.89)^2 (435.7 / 416) = 1.095 here (the case file's comment).
The source's constants are not an independent reference (a 3D FE model and a neural-network
surrogate fitted to 12 peaks and their amplitudes, coefficients of variation 2.5 to 30 %).

Writes ``spruce_badiane.md`` to ``out_dir``. Run:
``python -m studies.spruce_badiane [--quick] [--out DIR]`` (quick: B only, by likelihood:
no posterior, no diagnosis).
"""

import argparse
import os
import pathlib
import sys
import time

import numpy as np

from bayesplate.estimators import METHODS, estimate
from bayesplate.io import atomic_write_text, bundled_case_path, load_case
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import ENGINEERING_NAMES, ENGINEERING_UNITS, to_case_units
from studies._study_host import cpu

REPORT = "spruce_badiane.md"
CASE = "badiane_spruce_5R"
SEED = 5
#: The source's h and rho against this case's: E and G scale by (h0 / h)^2 (rho / rho0).
H_SOURCE_MM, RHO_SOURCE = 5.0, 416.0
IN_PLANE = (0, 1, 3)  # E1, E2, G12: what bending frequencies of a thin plate determine
TOLERANCE = 0.03  # the issue's: within 3 % of the source's rescaled constants


def rescaled_reference(case):
    """The source's constants at this case's thickness and density (SI), shape (6,)."""
    h_mm = case.plate.thickness * 1e3
    factor = (H_SOURCE_MM / h_mm) ** 2 * (case.plate.density / RHO_SOURCE)
    scale = np.where(np.arange(6) == 2, 1.0, factor)  # nu12 unchanged
    return case.reference * scale, factor


def run(quick=False):
    """Every estimate, the posterior and the diagnosis; plain rows for the report."""
    case = load_case(bundled_case_path(CASE))
    model = PlateModel.from_case(case)
    rows = []
    for pairing in ("likelihood",) if quick else ("order", "likelihood"):
        for method in ("B",) if quick else METHODS:
            started = time.perf_counter()
            r = estimate(case, method, model=model, pairing=pairing)
            rows.append(
                {
                    "what": f"{method} ({pairing})",
                    "status": r.status,
                    "iterations": r.iterations,
                    "constants": r.constants,
                    "sd": r.sd,
                    "seconds": time.perf_counter() - started,
                    "message": r.message,
                    "unobserved": r.settings.get("unobserved_modes"),
                    "spurious": r.settings.get("spurious_peaks"),
                }
            )
            print(rows[-1]["what"], r.status, to_case_units(r.constants)[[0, 1, 3]], flush=True)
    posterior = diagnosis = None
    if not quick:
        from bayesplate.discrepancy.diagnose import diagnose
        from bayesplate.sampling import sample

        started = time.perf_counter()
        posterior = sample(
            case,
            rng=SEED,
            model=model,
            pairing="likelihood",
            progress=False,
            max_steps=1000,
            min_ess=1000.0,
        )
        rows.append(
            {
                "what": "posterior (likelihood)",
                "status": "converged" if posterior.converged else "not converged",
                "iterations": None,
                "constants": posterior.mean,
                "sd": posterior.sd,
                "seconds": time.perf_counter() - started,
                "message": "",
                "unobserved": None,
                "spurious": None,
            }
        )
        started = time.perf_counter()
        diagnosis = diagnose(case, model=model, rng=SEED, pairing="order")
        diagnosis_seconds = time.perf_counter() - started
        print("diagnose", diagnosis.verdict, flush=True)
    return case, model, rows, (diagnosis, diagnosis_seconds if diagnosis else None)


def report(case, model, rows, diagnosed, quick):
    """The Markdown text."""
    reference, factor = rescaled_reference(case)
    lines = [
        f"Made by `python -m studies.spruce_badiane{' --quick' if quick else ''}` "
        f"on {time.strftime('%Y-%m-%d')} ({cpu()}, {os.cpu_count()} cores, load "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} at writing).",
        "",
        "# The measured spruce plate 5R (Badiane et al. 2023)",
        "",
        f"Case `{CASE}`: {case.plate.length * 1e3:.1f} x {case.plate.width * 1e3:.1f} x "
        f"{case.plate.thickness * 1e3:.2f} mm, {case.plate.density:.1f} kg/m^3, "
        f"{case.measured.size} peaks, mesh {model.mesh.nx} x {model.mesh.ny}. The source's "
        f"constants are rescaled by {factor:.3f} (E and G; nu12 as it is) to this case's "
        "thickness and density (see the case file's comments).",
        "",
        "| estimate | status | iterations | "
        + " | ".join(
            f"{n} ({u})" for n, u in zip(ENGINEERING_NAMES, ENGINEERING_UNITS, strict=True)
        )
        + " | E1, E2, G12 vs source | time (s) |",
        "|---|---|---|" + "---|" * 6 + "---|---|",
        "| source, rescaled | - | - | "
        + " | ".join(f"{v:.4g}" for v in to_case_units(reference))
        + " | - | - |",
    ]
    for row in rows:
        e, sd = to_case_units(row["constants"]), to_case_units(row["sd"])
        dev = 100 * (row["constants"] - reference) / reference
        within = np.all(np.abs(dev[list(IN_PLANE)]) <= 100 * TOLERANCE)
        cells = " | ".join(f"{v:.4g} +- {s:.2g}" for v, s in zip(e, sd, strict=True))
        devs = ", ".join(f"{dev[i]:+.1f} %" for i in IN_PLANE)
        lines.append(
            f"| {row['what']} | {row['status']} | {_dash(row['iterations'])} | {cells} | {devs} "
            f"({'within' if within else 'NOT within'} 3 %) | {row['seconds']:.0f} |"
        )
    lines += ["", "Messages:", ""]
    for row in rows:
        if row["message"]:
            lines.append(f"- {row['what']}: {row['message']}")
    diagnosis, seconds = diagnosed
    if diagnosis is not None:
        lines += [
            "",
            f"**diagnose** (pairing by order, {seconds:.0f} s): verdict "
            f"**{diagnosis.verdict}**, nominal p = {diagnosis.p_value:.3g}.",
        ]
        for note in diagnosis.notes:
            lines.append(f"- {note}")
    return "\n".join(lines) + "\n"


def _dash(value):
    return "-" if value is None else str(value)


def main(out_dir="reports", quick=False):
    """Run and write the report; returns the rows."""
    case, model, rows, diagnosed = run(quick)
    out_dir = pathlib.Path(out_dir)
    atomic_write_text(out_dir / REPORT, report(case, model, rows, diagnosed, quick))
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", default="reports")
    args = parser.parse_args(sys.argv[1:])
    main(args.out, args.quick)
