"""Effects outside diagnose's candidates: how often each comes out unexplained or named.

Issue 40 asks that an effect none of the candidates describes be named as the nearest true
physics or ``unexplained``, never as unrelated physics. Four such effects are concealed in
the Frederiksen plate (100.1 x 53.0 x 3.36 mm, T300/epoxy), each made here with its own
element fractions, not with a candidate's code:

- a through-slot 15 x 2 mm (material removed): near a hole or a local loss of stiffness;
- a round delamination 16 mm across (the transverse shear coefficients C44, C55 at 5 %):
  the candidate ``delamination`` is a rectangle, this is a disc;
- a bonded doubler 15 x 12 mm (stiffness x 1.6 and mass x 1.3 there): no candidate adds
  stiffness and mass over an area;
- a notch 6 x 4 mm cut into the middle of an edge: no candidate removes material there (a
  hole stays inside the plate, a cut corner is at a corner).

With a control (no effect), each is recorded on a mesh twice as fine as diagnose's, with
0.2 % noise from its own seed stream (:mod:`studies.recordings`), ``REPLICATES`` times, and
diagnosed blind with every candidate of the package. Rows are cached by code version in
``out_dir/.cache/outside_effects/<version>.jsonl`` (a run resumes); the report is the current
version's table alone. Run: ``python -m studies.outside_effects [--replicates N]``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import statistics
import time

import numpy as np

from bayesplate import bundled_case_path, load_case
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.discrepancy.physics.base import Parameter, Physics
from bayesplate.discrepancy.physics.cutout import disc_fractions
from bayesplate.discrepancy.physics.local_stiffness_loss import area_fractions
from bayesplate.io import atomic_write_text
from studies import recordings as rec
from studies._study_host import code_version, cpu, jsonl_rows, utc_now

SEED = 20261128
MESH = (30, 30)  # diagnose's working mesh; the recordings' is twice as fine
REPLICATES = 3
RESIDUAL = 1e-4  # the share of material kept where it is removed (as Cutout's)


class Concealed(Physics):
    """Stiffness terms and mass multiplied over a region, for recordings only (not fitted).

    ``region(mesh) -> fractions`` gives each element's share of area inside; ``stiffness``
    (6,) multiplies each lamina coefficient's terms there, ``mass`` the mass.
    """

    name = "concealed"

    def __init__(self, region, stiffness, mass):
        self.region, self.stiffness, self.mass = region, np.asarray(stiffness, float), mass

    def parameters(self, model, b):
        return (Parameter("none", 0.0, 1.0),)

    def apply(self, model, theta):
        frac = self.region(model.mesh)
        inside = np.flatnonzero(frac > 0)
        f = frac[inside, None, None]
        extra = [
            model.assembler.element_data(inside, f * Ke[None])
            for Ke in model.element_stiffness_terms()
        ]
        stiffness = model.stiffness_terms + (self.stiffness - 1.0)[:, None] * np.array(extra)
        mass = model.mass_data + (self.mass - 1.0) * model.assembler.element_data(
            inside, f * model.element_mass()[None]
        )
        return model.modified(stiffness_terms=stiffness, mass_data=mass)


def _rectangle(x0, x1, y0, y1):
    """Element fractions inside ``[x0, x1] x [y0, y1]`` (mm)."""
    centre = 1e-3 * np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    return lambda mesh: area_fractions(mesh, centre, 1e-3 * np.array([x1 - x0, y1 - y0]))


def _disc(x, y, d):
    """Element fractions inside a disc (mm)."""
    return lambda mesh: disc_fractions(mesh, 1e-3 * np.array([x, y]), 1e-3 * d)


GONE = np.full(6, RESIDUAL)
#: label: (the effect, the names that are the nearest true physics)
EFFECTS = {
    "control (no effect)": (None, set()),
    "slot 15 x 2 mm": (
        Concealed(_rectangle(60.0, 75.0, 17.0, 19.0), GONE, RESIDUAL),
        {"cutout", "local_stiffness_loss"},
    ),
    "round delamination 16 mm": (
        Concealed(_disc(64.0, 32.0, 16.0), [1, 1, 1, 1, 0.05, 0.05], 1.0),
        {"delamination"},
    ),
    "doubler 15 x 12 mm": (
        Concealed(_rectangle(22.0, 37.0, 33.0, 45.0), np.full(6, 1.6), 1.3),
        set(),
    ),
    "edge notch 6 x 4 mm": (
        Concealed(_rectangle(47.0, 53.0, 0.0, 4.0), GONE, RESIDUAL),
        {"cutout", "cut_corner", "local_stiffness_loss"},
    ),
}


def run_one(label, replicate):
    """Diagnose one recording of effect ``label``; its row (plain data)."""
    physics, near = EFFECTS[label]
    case = load_case(bundled_case_path("frederiksen_t300"))
    model, fine = rec.meshes(case, MESH)
    index = list(EFFECTS).index(label) * 100 + replicate
    f = rec.recordings(case, fine, physics, [0.0], rec.stream(SEED, index))
    start = time.perf_counter()
    d = diagnose(rec.blind(case, f), model=model, rng=SEED, pairing="order", workers=2)
    named = names_given(d)
    unnamed = d.unnamed
    return {
        "effect": label,
        "replicate": replicate,
        "verdict": d.verdict,
        "named": named,
        "outcome": outcome(d.verdict, named, near, control=physics is None),
        "p_value": float(d.p_value),
        "best": d.candidates[0].name if d.candidates else None,
        "best_gain": float(d.candidates[0].log_evidence_gain) if d.candidates else None,
        "unnamed_gain": None if unnamed is None else float(unnamed.log_evidence_gain),
        "seconds": time.perf_counter() - start,
    }


def names_given(d):
    """The candidates a diagnosis names: the chosen one, its rival, those tied with it."""
    named = [] if d.chosen is None else [d.chosen.name]
    return named + [c.name for c in ([d.rival] if d.rival else []) + list(d.also_tied)]


def outcome(verdict, named, near, control=False):
    """``consistent`` (not detected; a control's right answer), ``right`` (unexplained, or
    every name the nearest true physics) or ``wrong`` (a name of unrelated physics among
    those given; a control not consistent: a false alarm)."""
    if verdict == "consistent":
        return "consistent"
    if control:
        return "wrong"
    if verdict == "unexplained" or all(n in near for n in named):
        return "right"
    return "wrong"


def main(out_dir="reports", replicates=REPLICATES):
    """Run what the cache lacks, write ``outside_effects.md``; return the rows."""
    version = code_version()
    cache = pathlib.Path(out_dir) / ".cache" / "outside_effects" / f"{version}.jsonl"
    cache.parent.mkdir(parents=True, exist_ok=True)
    rows = jsonl_rows(cache)
    done = {(r["effect"], r["replicate"]) for r in rows}
    for label in EFFECTS:
        for k in range(replicates):
            if (label, k) in done:
                continue
            row = run_one(label, k)
            print(f"{label:26s} {k}: {row['verdict']:12s} {row['named']} ({row['seconds']:.0f} s)")
            with cache.open("a") as out:
                out.write(json.dumps(row) + "\n")
            rows.append(row)
    write_report(out_dir, rows, version)
    return rows


def write_report(out_dir, rows, version):
    """``outside_effects.md``: the current version's table alone."""
    lines = [
        "# Effects outside the candidates: unexplained, or named",
        "",
        f"Date: {utc_now()}. Machine: {cpu()}, 2 cores. Code: {version}. Made by "
        "`python -m studies.outside_effects` (its docstring says what each effect is).",
        "",
        f"The Frederiksen plate, diagnosed on {MESH[0]} x {MESH[1]} (recordings on twice as "
        "fine a mesh, 0.2 % noise), with every candidate of the package. *Right*: "
        "`unexplained`, or every name given the nearest true physics (the last column); "
        "*wrong*: a name of unrelated physics among those given.",
        "",
        *table(rows),
    ]
    lines += ["", "Each run: verdict, names, best candidate's and the unnamed change's gains.", ""]
    lines += [
        f"- {r['effect']} #{r['replicate']}: {r['verdict']} {r['named']}, best {r['best']} "
        f"{_nats(r['best_gain'])}, unnamed {_nats(r['unnamed_gain'])}, p {r['p_value']:.2g}, "
        f"{r['seconds']:.0f} s"
        for r in rows
    ]
    path = pathlib.Path(out_dir) / "outside_effects.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def table(rows):
    """The table of outcomes, a line per effect with rows:
    runs, consistent, unexplained, named right, wrong, the names given, median seconds,
    the nearest true physics. ``rows``: ``effect``, ``verdict``, ``named``, ``outcome``,
    ``seconds`` each."""
    lines = [
        "| effect | runs | consistent | unexplained | named right | wrong | names given | "
        "median s | nearest true physics |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, (_, near) in EFFECTS.items():
        mine = [r for r in rows if r["effect"] == label]
        if not mine:
            continue
        unexplained = _count(mine, "verdict", "unexplained")
        right, wrong = _count(mine, "outcome", "right"), _count(mine, "outcome", "wrong")
        names = sorted({n for r in mine for n in r["named"]})
        lines.append(
            f"| {label} | {len(mine)} | {_count(mine, 'outcome', 'consistent')} | {unexplained} | "
            f"{right - unexplained} | {wrong} | "
            f"{', '.join(names) or '-'} | {statistics.median(r['seconds'] for r in mine):.0f} | "
            f"{', '.join(sorted(near)) or 'none'} |"
        )
    return lines


def _count(rows, key, value):
    return sum(r[key] == value for r in rows)


def _nats(value):
    return "-" if value is None else f"{value:+.1f}"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reports")
    parser.add_argument("--replicates", type=int, default=REPLICATES)
    args = parser.parse_args()
    main(args.out, args.replicates)
