"""A full posterior of the Frederiksen plate on its 50 x 50 mesh, timed (issue 4).

One run, one process, one seed: the pilot B estimate, the certified fast model over the
posterior box, the MAP, and emcee until the chain is longer than 50 autocorrelation times
with at least 2,000 effective samples per constant and R-hat below 1.01. Then, in the same
process, the time of one forward evaluation of the fast model (eigenvalues only, the
sampler's path) and of the full model (frequencies and sensitivities, as the estimators use
it) at posterior draws, and the linearised covariance of B against the sampled one for the
Frederiksen plate and for Plate 1 (its 8 x 4 mesh), with the figures of the Frederiksen run.

BLAS is limited to one thread (the sampler does so itself around the chain).

Writes ``benchmark_sampling.md`` and ``sampling_frederiksen_{corner,trace,autocorrelation}.png``.
Run: ``python benchmarks/bench_sampling.py [--out DIR]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402 - BLAS threads are fixed before numpy loads
import pathlib  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _machine  # noqa: E402  (this folder's shared helper)

REPORT = "benchmark_sampling.md"
FIGURES = "sampling_frederiksen_{}.png"
SEED = 20070461
MIN_ESS = 2000.0
MAX_RHAT = 1.01
TARGET_S = 120.0  # issue 4: the whole posterior in under 2 minutes on 2 cores
N_FULL = 3  # full solves timed at posterior draws
N_FAST = 200  # fast evaluations timed per batch
FAST_REPEATS = 5  # batches; the best is kept
NAMES = ("E1", "E2", "nu12", "G12", "G13", "G23")
UNITS = ("GPa", "GPa", "-", "GPa", "GPa", "GPa")
TO_CASE = np.array([1e-9, 1e-9, 1.0, 1e-9, 1e-9, 1e-9])


def machine():
    """Processor, core count, memory and library versions (see ``_machine``)."""
    return _machine.machine("emcee")


def run_frederiksen():
    """The timed posterior, then the per-evaluation times; a dict for the report."""
    from bayesplate.io import bundled_case_path, load_case
    from bayesplate.plate.model import PlateModel
    from bayesplate.sampling import prepare, sample

    load = [os.getloadavg()[0]]
    wall, cpu = time.perf_counter(), time.process_time()
    case = load_case(bundled_case_path("frederiksen_t300"))
    model = PlateModel.from_case(case)
    setup = prepare(case, model=model, rng=SEED)
    load.append(os.getloadavg()[0])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = sample(
            case, rng=SEED, setup=setup, progress=False, min_ess=MIN_ESS, max_rhat=MAX_RHAT
        )
    total_wall, total_cpu = time.perf_counter() - wall, time.process_time() - cpu
    load.append(os.getloadavg()[0])
    draws = result.samples_b[np.linspace(0, len(result.samples_b) - 1, N_FULL + 50).astype(int)]
    fast_s = _fast_time(setup, draws)
    full_wall, full_cpu = [], []
    for b in draws[:N_FULL]:
        t, c = time.perf_counter(), time.process_time()
        model.solve(b, setup.problem.pairing.n_modes())
        full_wall.append(time.perf_counter() - t)
        full_cpu.append(time.process_time() - c)
    load.append(os.getloadavg()[0])
    return {
        "case": case,
        "setup": setup,
        "result": result,
        "total_wall": total_wall,
        "total_cpu": total_cpu,
        "fast_s": fast_s,
        "full_wall": float(np.mean(full_wall)),
        "full_cpu": float(np.mean(full_cpu)),
        "load": load,
        "warnings": sorted({str(w.message) for w in caught}),
    }


def _fast_time(setup, draws):
    """Best-of-batches seconds of one sampler forward evaluation (eigenvalues only)."""
    forward = setup.sampling_forward()
    n = setup.problem.pairing.n_modes()
    best = np.inf
    for _ in range(FAST_REPEATS):
        t = time.perf_counter()
        for i in range(N_FAST):
            forward(draws[i % len(draws)], n)
        best = min(best, (time.perf_counter() - t) / N_FAST)
    return best


def agreement(setup, result):
    """Deviations and correlations: sampled, B's P, full-Hessian Laplace; with bands."""
    from bayesplate.laminate import engineering_from_stiffness
    from bayesplate.quantities import engineering_covariance
    from bayesplate.sampling import covariance_agreement, curvature_covariance, linearisation_band

    est = setup.estimate
    problem = setup.problem_on_fast_model()
    H = engineering_covariance(
        engineering_from_stiffness(est.b), curvature_covariance(problem, est.b, est.covariance_b)
    )
    a = covariance_agreement(result, est.covariance)
    a["sd_hessian"] = np.sqrt(np.diag(H))
    a["linearisation"] = linearisation_band(problem, est.b, est.covariance_b)
    a["agrees_with_lin"] = np.abs(a["ratio"] - 1) <= a["band"] + a["linearisation"]
    shift = (result.mean - est.constants) / np.sqrt(np.diag(result.covariance))
    a["mean_shift"] = shift
    return a


def run_plate1():
    """Plate 1 (its own prior, 8 x 4 mesh): the same comparison, untimed."""
    from bayesplate.io import bundled_case_path, load_case
    from bayesplate.sampling import prepare, sample

    case = load_case(bundled_case_path("plate1"))
    setup = prepare(case, rng=SEED)
    result = sample(case, rng=SEED, setup=setup, progress=False, min_ess=MIN_ESS)
    return setup, result


# ----------------------------------------------------------------------------- report


def _table(headers, rows):
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    return lines + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def _agreement_lines(title, setup, result, a):
    est = setup.estimate
    rows = []
    for i, name in enumerate(NAMES):
        s = TO_CASE[i]
        verdict = "agrees" if a["agrees_with_lin"][i] else "**disagrees**"
        rows.append(
            [
                f"{name} ({UNITS[i]})",
                f"{est.constants[i] * s:#.4g}",
                f"{result.mean[i] * s:#.4g}",
                f"{a['mean_shift'][i]:+.2f}",
                f"{a['sd_linear'][i] * s:#.3g}",
                f"{a['sd_sampled'][i] * s:#.3g}",
                f"{a['ratio'][i]:.3f}",
                f"{a['sd_hessian'][i] / a['sd_linear'][i]:.3f}",
                f"{a['band'][i]:.3f}",
                f"{a['linearisation'][i]:.3f}",
                f"{result.ess_bulk[i]:.0f}",
                verdict,
            ]
        )
    head = [
        "constant",
        "B (MAP)",
        "posterior mean",
        "(mean - MAP) / sd",
        "sd of P",
        "sd sampled",
        "sampled / P",
        "full Hessian / P",
        "MC band (4 se)",
        "linearisation band",
        "ESS",
        "within MC + linearisation",
    ]
    corr = []
    for i in range(6):
        corr.append(
            [NAMES[i]]
            + [
                f"{a['corr_sampled'][i, j]:+.2f} / {a['corr_linear'][i, j]:+.2f}"
                + ("" if a["corr_agrees"][i, j] else " *")
                for j in range(6)
            ]
        )
    return [
        f"### {title}",
        "",
        *_table(head, rows),
        "",
        "Correlations, sampled / B's P (* where they differ by more than 4 Monte Carlo "
        "errors, `(1 - rho^2) / sqrt(ESS)`):",
        "",
        *_table(["", *NAMES], corr),
        "",
    ]


def write_report(m, plate1, out_dir, date=None):
    """Markdown report and figures of the Frederiksen run."""
    from bayesplate.io import atomic_write_text

    info = machine()
    r, setup = m["result"], m["setup"]
    cert = setup.certificate
    date = date or _machine.utc_now()
    ratio = m["full_wall"] / m["fast_s"]
    ess_per_s = r.ess_min / r.wall_time
    t = r.timings
    met = m["total_wall"] < TARGET_S and r.ess_min >= MIN_ESS and r.rhat_max < MAX_RHAT
    summary = [
        [
            "total wall time (model assembly, pilot, fast model, MAP, sampling)",
            f"{m['total_wall']:.1f} s (CPU {m['total_cpu']:.1f} s)",
        ],
        ["pilot B on a 25 x 25 mesh", f"{t['pilot']:.1f} s"],
        ["fast model: build + certify", f"{t['build']:.1f} s ({setup.n_full_solves} full solves)"],
        ["MAP (B to TOL 1e-7 on the fast model)", f"{t['map']:.2f} s"],
        ["sampling", f"{r.wall_time:.1f} s"],
        ["certificate", str(cert)],
        [
            "walkers x steps (tuning, burn-in)",
            f"{r.n_walkers} x {r.n_steps} ({r.settings['n_tune']}, {r.n_burn})",
        ],
        ["log-density evaluations", f"{r.n_evaluations}"],
        ["full solves while sampling (box fallbacks)", f"{r.n_full}"],
        ["DE proposals rejected on the Ritz bound (no solve)", f"{r.n_screened}"],
        ["acceptance", f"{r.acceptance:.2f}"],
        ["largest tau (sampler coordinates)", f"{np.max(r.tau):.1f} steps"],
        ["smallest bulk ESS / tail ESS", f"{r.ess_min:.0f} / {np.min(r.ess_tail):.0f}"],
        ["largest R-hat", f"{r.rhat_max:.4f}"],
        [
            "effective samples per second (smallest bulk ESS / sampling time)",
            f"{ess_per_s:.0f} /s ({r.ess_min / m['total_wall']:.0f} /s over the whole run)",
        ],
        ["fast forward evaluation (eigenvalues, best of 5 x 200)", f"{m['fast_s'] * 1e3:.3f} ms"],
        [
            "full forward evaluation (frequencies + sensitivities, mean of 3)",
            f"{m['full_wall']:.2f} s wall / {m['full_cpu']:.2f} s CPU",
        ],
        ["ratio full / fast (wall)", f"{ratio:,.0f}"],
    ]
    loads = m["load"]
    lines = [
        f"Made by `python benchmarks/bench_sampling.py` (seed {SEED}) on {date}; not part of "
        "`studies/run_all.py` (timings belong to a machine).",
        "",
        "# Posterior sampling: Frederiksen plate, 50 x 50 mesh",
        "",
        f"Machine: {info['cpu']}, {info['nproc']} processors available; {info['platform']}; "
        f"Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}, emcee "
        f"{info['emcee']}. BLAS limited to one thread. Load average (1 min) "
        f"{loads[0]:.2f} before the run and {min(loads[1:]):.2f} to {max(loads[1:]):.2f} "
        f"during it, on {info['nproc']} processors: the machine is shared, so wall times are "
        "inflated by other work; CPU times are this process's.",
        "",
        f"Target (issue 4): at least {MIN_ESS:.0f} effective samples per constant and R-hat "
        f"under {MAX_RHAT}, fast model built and certified included, in under "
        f"{TARGET_S:.0f} s on 2 cores: **{'met' if met else 'missed'}** "
        f"({m['total_wall']:.0f} s wall, ESS {r.ess_min:.0f}, R-hat {r.rhat_max:.4f}).",
        "",
        *_table(["quantity", "value"], summary),
        "",
        "Warnings raised during the run: "
        + ("; ".join(m["warnings"]) if m["warnings"] else "none")
        + ".",
        "",
        "## Posterior (case units)",
        "",
        *_table(
            ["constant", "mean", "sd", "hdi 3%", "hdi 97%", "ESS bulk", "ESS tail", "R-hat"],
            [
                [
                    f"{n} ({u})",
                    f"{r.mean[i] * TO_CASE[i]:#.4g}",
                    f"{r.sd[i] * TO_CASE[i]:#.3g}",
                    f"{r.hdi[0, i] * TO_CASE[i]:#.4g}",
                    f"{r.hdi[1, i] * TO_CASE[i]:#.4g}",
                    f"{r.ess_bulk[i]:.0f}",
                    f"{r.ess_tail[i]:.0f}",
                    f"{r.rhat[i]:.4f}",
                ]
                for i, (n, u) in enumerate(zip(NAMES, UNITS, strict=True))
            ],
        ),
        "",
        "## Linearised (B) against sampled covariance",
        "",
        "`P` is the covariance of the B estimate (eq. 9, Gauss-Newton at the MAP), carried to "
        "the engineering constants to first order as the estimators report it. The Monte "
        "Carlo band is 4 standard errors of a sampled deviation, `4 / sqrt(2 ESS)` "
        "relative. The linearisation band is measured without sampling: the largest "
        "relative change of B's deviations over the 12 points MAP +- one column of "
        "`chol(P)`. 'full Hessian / P' is the Laplace deviation with the full Hessian of "
        "the log-posterior (finite differences) over P's: the residual curvature that "
        "Gauss-Newton drops. '(mean - MAP) / sd' measures the asymmetry of the posterior.",
        "",
        *_agreement_lines("Frederiksen plate (case prior, 50 x 50 mesh)", setup, r, m["agree"]),
        *_agreement_lines(
            "Plate 1 (case prior: Table 3 test 1, d = 1/6; 8 x 4 mesh)",
            plate1[0],
            plate1[1],
            plate1[2],
        ),
        "## Findings",
        "",
        *_findings(m, plate1),
        "",
        "## Figures",
        "",
        f"![corner]({FIGURES.format('corner')})",
        "",
        f"![trace]({FIGURES.format('trace')})",
        "",
        f"![autocorrelation]({FIGURES.format('autocorrelation')})",
        "",
    ]
    out = pathlib.Path(out_dir)
    atomic_write_text(out / REPORT, "\n".join(lines))


def _findings(m, plate1):
    """Sentences computed from the numbers."""
    lines = []
    for label, a in (("Frederiksen", m["agree"]), ("Plate 1", plate1[2])):
        bad = [NAMES[i] for i in range(6) if not a["agrees_with_lin"][i]]
        off_mc = [NAMES[i] for i in range(6) if not a["sd_agrees"][i]]
        lines.append(
            f"- {label}: B's deviations agree with the sampled ones within the Monte Carlo "
            f"band alone for {', '.join(n for n in NAMES if n not in off_mc) or 'none'}; "
            f"within Monte Carlo plus linearisation for "
            f"{', '.join(n for n in NAMES if n not in bad) or 'none'}; they disagree for "
            f"{', '.join(bad) or 'none'}"
            + "".join(
                f"; sampled / P {NAMES[i]} {a['ratio'][i]:.2f}"
                for i in range(6)
                if NAMES[i] in bad or NAMES[i] in off_mc
            )
            + "."
        )
    return lines


def figures(m, out_dir):
    """Corner (B and MVE ellipses, Frederiksen's constants), trace, autocorrelation."""
    from bayesplate.plots import sampling_figures

    case, setup, r = m["case"], m["setup"], m["result"]
    mve = setup.run_estimator("MVE")
    title = "Frederiksen T300/epoxy (case prior), 50 x 50 mesh"
    figs = sampling_figures(
        r,
        {"B": setup.estimate, "MVE": mve},
        case.reference,
        title=title,
        reference_label="Frederiksen's constants",
    )
    out = pathlib.Path(out_dir)
    for name, fig in figs.items():
        path = out / FIGURES.format(name)
        tmp = path.with_name(f".{path.name}.tmp.png")
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
        tmp.replace(path)
    return mve


def main(out_dir="reports"):
    m = run_frederiksen()
    m["agree"] = agreement(m["setup"], m["result"])
    setup1, result1 = run_plate1()
    plate1 = (setup1, result1, agreement(setup1, result1))
    figures(m, out_dir)
    write_report(m, plate1, out_dir)
    r = m["result"]
    print(
        f"total {m['total_wall']:.1f} s, ESS {r.ess_min:.0f}, R-hat {r.rhat_max:.4f}, "
        f"fast {m['fast_s'] * 1e3:.3f} ms, full {m['full_wall']:.2f} s"
    )
    return m, plate1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=pathlib.Path(__file__).parents[1] / "reports")
    args = parser.parse_args()
    main(args.out)
