"""What an unmodelled effect on the spruce plate 5R would do to its frequencies (issue 40).

A wood plate differs from its model in ways a lab cannot easily rule out: the accelerometer's
mass where it is glued, a thickness that varies across the plate. Each moves the measured
frequencies; the question for diagnose is how much of that move survives refitting the six
constants (what any fit absorbs, it turns into biased constants instead of a visible misfit).

For each effect, at the constants fitted to the plate's own taps, this study computes on the
finite-element model (the candidate's own ``Physics.apply``, a full eigen solve):

- the largest shift of the lowest ``N_MODES`` frequencies, in % (= units of the 1 % sigma);
- the chi-square that is left when the constants are refitted to first order (the shift
  ``d`` in units of sigma, ``chi2 = d^T (I - J J^+) d`` with ``J`` the sensitivity of
  ``ln f`` to ``ln b``, per sigma): above ``CHI2_01`` (6.63, alpha 0.01 for one parameter) a
  fitted test at 1 % would see it; below, it is absorbed;
- how far that refit moves C11, C22 and C66 (E1, E2, G12 to first order), in %.

The plate's constants are the B estimate of its taps, given in :data:`CONSTANTS_GPA` (what
``bayesplate import`` then ``bayesplate diagnose`` gave on the shared taps; the study does
not depend on their last digits). Writes ``spruce_what_shows.md``. Run:
``python -m studies.spruce_what_shows [--out DIR] [--mesh NX NY]``.
"""

import argparse
import os
import pathlib
import time

import numpy as np

from bayesplate import load_case, stiffness_from_engineering
from bayesplate.discrepancy import PointMass, ThicknessTaper
from bayesplate.io import atomic_write_text, bundled_case_path
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import CASE_SCALE
from studies._study_host import code_version, cpu, utc_now

REPORT = "spruce_what_shows.md"
CASE = "badiane_spruce_5R"
#: E1, E2, nu12, G12, G13, G23 (GPa, -): the nominal fit of the shared 5R taps.
CONSTANTS_GPA = (11.905, 1.0706, 0.388, 0.8655, 0.600, 0.0329)
N_MODES = 10
SIGMA_REL = 0.01
#: chi-square of one degree of freedom at alpha 0.01.
CHI2_01 = 6.635
MESH = (40, 16)


def effects(model):
    """``(label, physics, theta)`` of each effect, positions in mm."""
    a, w = model.mesh.a * 1e3, model.mesh.b * 1e3
    return [
        ("accelerometer 2 g at a corner", PointMass(), (2.0, 0.0, 0.0)),
        ("accelerometer 2 g at a long edge's middle", PointMass(), (2.0, a / 2, 0.0)),
        ("accelerometer 2 g at the centre", PointMass(), (2.0, a / 2, w / 2)),
        ("accelerometer 5 g at a corner", PointMass(), (5.0, 0.0, 0.0)),
        ("thickness 2 % thicker at one end than the other (x)", ThicknessTaper("x"), (0.01,)),
        ("thickness 2 % thicker at one long edge (y)", ThicknessTaper("y"), (0.01,)),
        ("thickness 5 % thicker at one end (x)", ThicknessTaper("x"), (0.025,)),
        ("thickness 5 % thicker at one long edge (y)", ThicknessTaper("y"), (0.025,)),
    ]


def what_shows(model, b, physics, theta, n=N_MODES, base=None):
    """Largest shift (in sigma), chi-square left after a first-order refit, refit move of b.

    `base`: ``model.solve(b, n)`` when already computed (it is the same for every effect).

    Returns
    -------
    largest : float
    left : float
    moved : numpy.ndarray, shape (6,)
        Relative change of each stiffness coefficient the refit makes, -.
    """
    base = model.solve(b, n) if base is None else base
    J = base.sensitivities * b[None, :] / (2 * base.eigenvalues[:, None]) / SIGMA_REL
    changed = physics.apply(model, np.asarray(theta, float)).solve(b, n)
    d = 0.5 * np.log(changed.eigenvalues / base.eigenvalues) / SIGMA_REL
    fit = np.linalg.lstsq(J, d, rcond=None)[0]
    rest = d - J @ fit
    return float(np.max(np.abs(d))), float(rest @ rest), np.expm1(fit)


def run(mesh=MESH):
    """The rows of the table and the model they were computed on."""
    case = load_case(bundled_case_path(CASE))
    model = PlateModel.from_case(case, mesh=mesh)
    b = stiffness_from_engineering(np.array(CONSTANTS_GPA) * CASE_SCALE)
    base = model.solve(b, N_MODES)
    rows = [
        (label, *what_shows(model, b, physics, theta, base=base))
        for label, physics, theta in effects(model)
    ]
    return model, rows


def report(model, rows, seconds):
    """The report's Markdown."""
    grams = model.mesh.a * model.mesh.b * model.thickness * model.density * 1e3
    lines = [
        "# What an unmodelled effect would do to the spruce plate 5R",
        "",
        f"{utc_now()}, code {code_version()}, {cpu()}, {os.cpu_count()} cores, load "
        f"{os.getloadavg()[0]:.1f}; {seconds:.0f} s. Made by "
        f"`python -m studies.{pathlib.Path(__file__).stem}`.",
        "",
        f"The plate: {model.mesh.a * 1e3:.0f} x {model.mesh.b * 1e3:.0f} x "
        f"{model.thickness * 1e3:.2f} mm, {grams:.0f} g, on a {model.mesh.nx} x "
        f"{model.mesh.ny} mesh, at the constants its taps give; its lowest {N_MODES} modes, "
        f"each with a {100 * SIGMA_REL:.0f} % sigma. A refit of the constants absorbs what "
        f"it can; a fitted test at alpha 0.01 sees what is left above {CHI2_01}.",
        "",
        "| effect | largest shift (%) | chi-square left after the refit | seen at 1 %? "
        "| the refit moves C11, C22, C66 (%) |",
        "|---|---|---|---|---|",
    ]
    for label, largest, left, moved in rows:
        seen = "yes" if left > CHI2_01 else "no"
        shown = ", ".join(f"{100 * moved[j]:+.1f}" for j in (0, 1, 3))
        lines.append(f"| {label} | {largest:.2f} | {left:.2f} | {seen} | {shown} |")
    return "\n".join(lines) + "\n"


def main(out_dir="reports", mesh=MESH):
    """Run and write the report; returns the rows."""
    start = time.perf_counter()
    model, rows = run(mesh)
    out = pathlib.Path(out_dir)
    atomic_write_text(out / REPORT, report(model, rows, time.perf_counter() - start))
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reports", help="folder of the report")
    parser.add_argument("--mesh", type=int, nargs=2, default=MESH, metavar=("NX", "NY"))
    args = parser.parse_args()
    main(args.out, tuple(args.mesh))
