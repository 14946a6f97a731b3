"""The spruce plate's uncertain inputs: each constant's variance by source (issue 17, stage 1).

The bundled case `badiane_spruce_5R` takes its thickness, density and size as exact. Its sheet
says otherwise: ten thickness readings 4.7 to 5.1 mm (sd 0.11 mm, 2.3 %), five lengths
(sd 0.84 mm) and five widths (sd 0.55 mm); the density is the mass (269.2 g, read to 0.1 g)
over a b h. B and MVE are run on the case as it is; their variance budget
(:func:`bayesplate.run.budget.estimate_budget`) then adds each input's linearised share.

Two readings of the density's uncertainty:
- *independent*: what the case keys express (``density_sd_kg_m3``, inputs independent), with
  the density's sd propagated from those of h, a, b and the mass (2.3 %);
- *from the mass*: the case keys ``mass_g`` and ``mass_sd_g``: rho = m / (a b h) moves with
  h, a and b, so the inputs are h, a, b and m (:func:`bayesplate.likelihood.inputs.input_sources`):
  the eigenvalues depend on h through ``J_h - (rho / h) J_rho`` (and likewise a, b) and on the
  mass alone through ``J_rho`` with sd ``rho sd_m / m``. Bending eigenvalues go as
  ``E h^2 / rho``, i.e. as ``E h^3 a b / m``: thickness weighs 3 sd_h / h, not 2.

The posterior with the inputs: the sampler on the case with the mass
(``inputs="marginal"``, ``J_p A A^T J_p^T`` added to ``V_Y``, pairing by likelihood as in
``studies/spruce_badiane.py``), beside the same sampler with the inputs exact; the inputs
drawn with the constants (:mod:`bayesplate.likelihood.inputs_posterior`), each input's share of the
posterior variance of E1, E2 and G12 from those joint draws, and the linear input model's
certificate.

Writes ``spruce_input_budget.md`` to ``out_dir``. Run:
``python -m studies.spruce_input_budget [--quick] [--out DIR]`` (quick: B only, no sampler).
"""

import argparse
import dataclasses
import datetime
import os
import pathlib
import time

import numpy as np

from bayesplate.estimators import estimate
from bayesplate.io import atomic_write_text, bundled_case_path, load_case
from bayesplate.laminate import engineering_from_stiffness
from bayesplate.likelihood.inputs import input_jacobian
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import ENGINEERING_KEYS, to_case_units
from bayesplate.run.budget import estimate_budget
from studies._study_host import cpu

REPORT = "spruce_input_budget.md"
CASE = "badiane_spruce_5R"
SD_H_MM, SD_A_MM, SD_B_MM = 0.11, 0.84, 0.55  # the sheet's readings (case file comments)
MASS_G, SD_MASS_G = 269.2, 0.1
SHOWN = (0, 1, 3)  # E1, E2, G12: what the bending frequencies determine


def uncertain_case():
    """The bundled case with the sheet's deviations (density independent, 2.3 %)."""
    case = load_case(bundled_case_path(CASE))
    p = case.plate
    rel = np.hypot.reduce(
        [
            SD_H_MM * 1e-3 / p.thickness,
            SD_A_MM * 1e-3 / p.length,
            SD_B_MM * 1e-3 / p.width,
            SD_MASS_G / MASS_G,
        ]
    )
    plate = dataclasses.replace(
        p,
        thickness_sd=SD_H_MM * 1e-3,
        length_sd=SD_A_MM * 1e-3,
        width_sd=SD_B_MM * 1e-3,
        density_sd=rel * p.density,
    )
    return dataclasses.replace(case, plate=plate)


def mass_case(case):
    """The case as a lab that weighed the plate writes it (``mass_g``, ``mass_sd_g``).

    The sheet's mass and the case's geometry give a density 0.1 % from the case's (rounding
    of the printed values); the density is the case's own here, so that both readings share
    one estimate, and the mass is set to match it.
    """
    p = case.plate
    mass = p.density * p.length * p.width * p.thickness
    assert abs(mass / (MASS_G * 1e-3) - 1) < 2e-3, mass
    return dataclasses.replace(
        case, plate=dataclasses.replace(p, mass=mass, mass_sd=SD_MASS_G * 1e-3)
    )


SEED = 20261125


def run(quick=False):
    """B and MVE on the spruce case; their budgets in both readings; the posteriors."""
    case = uncertain_case()
    model = PlateModel.from_case(case)
    rows = []
    for method in ("B",) if quick else ("B", "MVE"):
        result = estimate(case, method, model=model)
        J = input_jacobian(
            case, result.b, np.asarray(result.modes) - 1, mesh=(model.mesh.nx, model.mesh.ny)
        )
        independent = estimate_budget(case, result, model, jacobian=J)
        rows.append(
            (result, independent, estimate_budget(mass_case(case), result, model, jacobian=J))
        )
    posteriors = {}
    if not quick:
        from bayesplate.sampling import sample

        for inputs in ("exact", "marginal"):
            started = time.perf_counter()
            r = sample(
                mass_case(case),
                rng=SEED,
                model=model,
                pairing="likelihood",
                progress=False,
                max_steps=1000,
                min_ess=1000.0,
                inputs=inputs,
            )
            posteriors[inputs] = (r, time.perf_counter() - started)
    return case, rows, posteriors


def _posterior_lines(posteriors, mass_budget):
    """The sampled posterior of E1, E2, G12 with the inputs exact and marginal."""
    if not posteriors:
        return []
    out = [
        "",
        "## Posterior (sampler), density from the mass",
        "",
        "emcee on the certified fast model, pairing by likelihood, seed "
        f"{SEED}; `marginal`: the inputs' deviations in V_Y (`bayesplate sample` with the "
        "mass keys does this by default). The last column is B's linearised sd with the "
        "inputs (the budget above), for comparison.",
        "",
        "| inputs | constant | posterior mean | posterior sd | 94 % HDI | B sd with inputs |",
        "|---|---|---|---|---|---|",
    ]
    budget_sd = to_case_units(mass_budget.sd)
    for inputs, (r, _) in posteriors.items():
        mean, sd, hdi = (to_case_units(v) for v in (r.mean, r.sd, r.hdi))
        for j in SHOWN:
            out.append(
                f"| {inputs} | {ENGINEERING_KEYS[j]} | {mean[j]:.4g} | {sd[j]:.3g} "
                f"({100 * sd[j] / abs(mean[j]):.1f} %) | {hdi[0, j]:.4g} to "
                f"{hdi[1, j]:.4g} | {budget_sd[j]:.3g} |"
            )
    if "marginal" in posteriors:
        out += _sampled_inputs_lines(posteriors, mass_budget)
    if len(posteriors) == 2:
        shift = posteriors["marginal"][0].mean / posteriors["exact"][0].mean - 1
        out += [
            "",
            "The marginal posterior's means lie "
            + ", ".join(f"{100 * shift[j]:+.1f} %" for j in SHOWN)
            + " (E1, E2, G12) from the exact one's. Not a defect: a thickness error "
            "scales E1, E2 and G12 together (by 3 sd_h / h = 6.7 % here), so the data no "
            "longer fix their common scale and the prior does too; its means for E2 and "
            "G12 are 39 % and 34 % below the data's (Hearmon's nominal spruce), and its "
            "information on the common scale (about 10 % sd from E1, E2 and G12 together) "
            "against the inputs' (6.7 %) pulls it by about -31 % x 0.31 = -10 %. B's "
            "budget is the spread of the plug-in estimate and does not move it.",
        ]
    out += [
        "",
        "; ".join(
            f"{k}: {'converged' if r.converged else 'not converged'}, "
            f"{r.n_full} full solves while sampling, {s:.0f} s"
            for k, (r, s) in posteriors.items()
        )
        + ".",
    ]
    return out


def input_shares(result):
    """Each drawn input's share of each constant's posterior variance, shape (k, 6).

    The squared correlation of the constant with the input over the joint draws (one draw of
    the inputs per kept draw of the constants, :mod:`bayesplate.likelihood.inputs_posterior`): the
    fraction of its posterior variance the input explains linearly (a first-order Sobol
    index). The inputs are correlated a posteriori, so the shares need not add up.
    """
    post = result.input_posterior
    e = engineering_from_stiffness(result.samples_b[post.rows])
    return np.array(
        [
            [np.corrcoef(post.draws[:, k], e[:, j])[0, 1] ** 2 for j in range(6)]
            for k in range(len(post.names))
        ]
    )


def _sampled_inputs_lines(posteriors, mass_budget):
    """The inputs' posterior, their shares of E1, E2, G12, the certificate."""
    r = posteriors["marginal"][0]
    post, cert = r.input_posterior, r.input_certificate
    lines = [
        "",
        "The inputs drawn with the constants (one draw per kept draw, from their "
        "Gaussian conditional: exact joint draws under the linear input model), case "
        "units; the declared value and sd are the prior:",
        "",
        "| input | declared ± sd | posterior mean ± sd | 94 % HDI |",
        "|---|---|---|---|",
    ]
    for key, row in post.table().items():
        lines.append(
            f"| {key} | {row['declared']:.4g} ± {row['declared_sd']:.2g} | "
            f"{row['mean']:.4g} ± {row['sd']:.2g} | {row['hdi_3%']:.4g} to "
            f"{row['hdi_97%']:.4g} |"
        )
    shares = input_shares(r)
    lines += [
        "",
        "Share of each constant's posterior variance: all inputs together, 1 - "
        "(sd exact / sd marginal)^2 from the two chains; each input alone, its squared "
        "correlation with the constant over the joint draws (`input_shares`); beside "
        "B's linearised share of the same input (budget above, mass reading).",
        "",
        "| constant | all inputs (sampled) | "
        + " | ".join(f"{n} (sampled / B)" for n in post.names)
        + " |",
        "|---|---|" + "---|" * len(post.names),
    ]
    sources = list(mass_budget.sources)
    exact = posteriors.get("exact")
    for j in SHOWN:
        total = "-" if exact is None else f"{100 * (1 - (exact[0].sd[j] / r.sd[j]) ** 2):.0f} %"
        cells = [
            f"{100 * shares[k, j]:.0f} % / {100 * mass_budget.share[sources.index(n), j]:.0f} %"
            for k, n in enumerate(post.names)
        ]
        lines.append(f"| {ENGINEERING_KEYS[j]} | {total} | " + " | ".join(cells) + " |")
    lines += ["", f"{cert}."]
    return lines


def _table(result, budget):
    head = ["constant", "estimate", "sd, frequencies + prior", "sd with inputs"]
    head += [f"share {s}" for s in budget.sources]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    estimate_ = to_case_units(result.constants)
    own = to_case_units(np.sqrt(np.diag(budget.estimator_covariance)))
    total = to_case_units(budget.sd)
    for j in range(6):
        cells = [
            ENGINEERING_KEYS[j],
            f"{estimate_[j]:.4g}",
            f"{own[j]:.3g} ({100 * own[j] / abs(estimate_[j]):.1f} %)",
            f"{total[j]:.3g} ({100 * total[j] / abs(estimate_[j]):.1f} %)",
        ]
        cells += [f"{100 * s:.0f} %" for s in budget.share[:, j]]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def report(case, rows, seconds, posteriors=None):
    """The Markdown report."""
    load = os.getloadavg()[0]
    out = [
        "# The spruce plate's uncertain inputs: variance budget of B and MVE",
        "",
        f"Made by `python -m studies.spruce_input_budget` on {datetime.date.today()}, "
        f"{cpu()}, {os.cpu_count()} cores, load "
        f"{load:.1f}, {seconds:.0f} s. Case `{CASE}` with the sheet's deviations: h "
        f"{SD_H_MM} mm, a {SD_A_MM} mm, b {SD_B_MM} mm, mass {SD_MASS_G} g. Linearised at "
        "each estimate; `share` is the fraction of the total variance; the sd without inputs "
        "is the estimator's own (what `bayesplate estimate` reported before).",
    ]
    for result, independent, mass in rows:
        out += ["", f"## {result.method} ({result.status}, {result.iterations} iterations)", ""]
        rho_rel = 100 * case.plate.density_sd / case.plate.density
        out += [
            f"Inputs independent (density sd {rho_rel:.1f} %, budget status "
            f"{independent.status}, closure {independent.closure:.1e}):",
            "",
        ]
        out += _table(result, independent)
        out += [
            "",
            "Density from the mass (case keys `mass_g`, `mass_sd_g`), rho = m / (a b h)"
            f" (budget status {mass.status}):",
            "",
        ]
        out += _table(result, mass)
    out += _posterior_lines(posteriors or {}, rows[0][2])
    return "\n".join(out) + "\n"


def main(out_dir, quick=False):
    """Run and write the report; return its path."""
    start = time.perf_counter()
    case, rows, posteriors = run(quick)
    path = pathlib.Path(out_dir) / REPORT
    atomic_write_text(path, report(case, rows, time.perf_counter() - start, posteriors))
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="B only")
    parser.add_argument("--out", default=pathlib.Path(__file__).resolve().parents[1] / "reports")
    print(main(parser.parse_args().out, parser.parse_args().quick))
