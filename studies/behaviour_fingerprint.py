"""Fingerprint of the package's numbers, to show that a redesign changed no behaviour.

Runs, through the top-level interfaces only (so that the same script runs before and after
a redesign): the paper's estimators on plate 1 (B, MVE, MVE-mod, tests 1 and 2, d = 1/3)
and plate 2; a seeded posterior chain on plate 1 (reduced model); and diagnose on four
concealed-effect recordings of the concealment study (Frederiksen plate, recordings on the
100 x 100 mesh with 0.2 % noise, diagnose on 50 x 50) plus its control, and on the quick
12 x 6 pair. Every run pairs by order, as before issue 16 made the most probable assignment
the default, so that fingerprints from either side of that change compare. Writes JSON
with every number in full precision (floats as hex, so that a comparison is bit for bit).

Run: ``python -m studies.behaviour_fingerprint OUT.json [--no-diagnose]``; compare two
files with ``python -m studies.behaviour_fingerprint --compare A.json B.json``.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time

import numpy as np

from bayesplate import PlateModel, bundled_case_path, load_case
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.estimators import estimate
from studies import concealment
from studies import recordings as rec

SI = np.array([1e9, 1e9, 1.0, 1e9, 1e9, 1e9])
SEED = concealment.SEED
#: The concealment study's scenarios diagnosed, by index: the control, the 1 g point mass,
#: the 0.08 thickness taper, the 8 degree misalignment and the stiffness loss keeping 40 %.
SCENARIOS = (0, 3, 5, 7, 11)


def _hex(a):
    return [float(x).hex() for x in np.ravel(np.asarray(a, dtype=float))]


def estimators():
    out = {}
    for name in ("plate1", "plate2"):
        case = load_case(bundled_case_path(name))
        model = PlateModel.from_case(case)
        for method in ("B", "MVE", "MVE-mod"):
            r = estimate(case, method, model=model, pairing="order")
            out[f"{name} {method}"] = {
                "constants": _hex(r.constants),
                "sd": _hex(r.sd),
                "iterations": r.iterations,
                "converged": bool(r.converged),
            }
    return out


def chain():
    from bayesplate.sampling import sample

    case = load_case(bundled_case_path("plate1"))
    import inspect

    seed = {"rng": 7} if "rng" in inspect.signature(sample).parameters else {"seed": 7}
    r = sample(
        case, **seed, n_walkers=16, max_steps=200, min_ess=100.0, progress=False, pairing="order"
    )
    samples = np.ascontiguousarray(np.asarray(r.samples_b, dtype=float))
    return {
        "samples_b_sha256": hashlib.sha256(samples.tobytes()).hexdigest(),
        "shape": list(samples.shape),
        "mean_b": _hex(samples.mean(axis=0)),
    }


def diagnoses(quick=False):
    case = load_case(bundled_case_path("frederiksen_t300"))
    mesh = (12, 6) if quick else case.mesh
    model, fine = rec.meshes(case, mesh)
    scenarios = concealment.scenarios()
    out = {}
    for index in SCENARIOS[:2] if quick else SCENARIOS:
        _, physics, _, theta = scenarios[index]
        f = rec.recordings(case, fine, physics, theta, rec.stream(SEED, index))
        blind = rec.blind(case, f)
        start = time.perf_counter()
        d = diagnose(blind, model=model, rng=SEED, pairing="order")
        top = d.candidates[0] if d.candidates else None
        out[f"{'quick ' if quick else ''}{index}"] = {
            "verdict": d.verdict,
            "chosen": None if d.chosen is None else d.chosen.name,
            "best": None if top is None else top.name,
            "gain": None if top is None else float(top.log_evidence_gain).hex(),
            "theta": None if top is None else _hex(top.fit.theta),
            "constants": None if top is None else _hex(top.fit.constants),
            "nominal_constants": _hex(d.nominal.constants),
            "p_value": float(d.p_value).hex(),
            "seconds": time.perf_counter() - start,
        }
        print(index, d.verdict, out[f"{'quick ' if quick else ''}{index}"]["chosen"], flush=True)
    return out


def compare(a, b):
    """Lines naming every difference (timings aside); empty when identical."""
    lines = []
    for section in sorted(set(a) | set(b)):
        for key in sorted(set(a.get(section, {})) | set(b.get(section, {}))):
            x, y = a.get(section, {}).get(key), b.get(section, {}).get(key)
            if isinstance(x, dict) and isinstance(y, dict):
                x = {k: v for k, v in x.items() if k != "seconds"}
                y = {k: v for k, v in y.items() if k != "seconds"}
            if x != y:
                lines.append(f"{section} / {key}: {x} != {y}")
    return lines


def main(argv):
    if argv[:1] == ["--compare"]:
        a, b = (json.loads(open(p).read()) for p in argv[1:3])
        lines = compare(a, b)
        print("\n".join(lines) if lines else "identical (timings aside)")
        return 1 if lines else 0
    out = {"estimators": estimators(), "chain": {"plate1": chain()}}
    out["diagnose"] = diagnoses(quick=True)
    if "--no-diagnose" not in argv:
        out["diagnose"].update(diagnoses())
    with open(argv[0], "w") as fh:
        json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
