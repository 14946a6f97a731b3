"""One task of a batch: one step on one case, run where a Dask worker runs it.

A task is given the case file's bytes (not its path: a worker on another machine need not
see the client's files) and the step's options; it returns plain data only: the step's JSON
document (the single-case command's, from :mod:`bayesplate.io.export`), one summary row, the
seconds it took and a status. It writes nothing; the client stores what comes back. Any
error becomes a ``"failed"`` result with a one-line reason, so that one case never stops the
others.
"""

from __future__ import annotations

import os
import sys
import time
import warnings

import numpy as np

from ..quantities import ENGINEERING_KEYS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 (as bayesplate.io.case_file)
    import tomli as tomllib

__all__ = ["FAILED", "Z94", "run_step"]

FAILED = "failed"
#: Half-width of a central 94 % Gaussian interval in standard deviations (``norm.ppf(0.97)``),
#: the probability of the sampler's HDI, so that every step's interval has the same level.
Z94 = 1.8807936081512509


def run_step(name, path, case_bytes, step, options):
    """Run `step` on one case; never raises.

    Parameters
    ----------
    name : str
        The case's label in the batch (its file's stem).
    path : str
        The case file's path on the client (named in errors only).
    case_bytes : bytes
        The case file's content (TOML).
    step : {"estimate", "sample", "diagnose"}
    options : dict
        :meth:`bayesplate.batch.BatchOptions.for_step` of `step`.

    Returns
    -------
    dict
        ``{"row": dict, "document": dict or None}``; the row has ``case``, ``step``,
        ``status``, ``reason``, ``seconds`` and ``worker`` besides the step's numbers.
    """
    from threadpoolctl import threadpool_limits

    started = time.perf_counter()
    base = {"case": name, "step": step, "worker": f"{os.uname().nodename}:{os.getpid()}"}
    try:
        with threadpool_limits(limits=1), warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            case = _parse(case_bytes, path)
            row, document = _STEPS[step](case, options)
        notes = sorted({str(w.message).splitlines()[0] for w in caught})
        row = {**base, **row, "warnings": "; ".join(notes)}
    except Exception as err:  # noqa: BLE001 - a failed case is a result, not a stop
        row, document = {**base, "status": FAILED, "reason": _one_line(err)}, None
    row["seconds"] = time.perf_counter() - started
    return {"row": row, "document": document}


def _one_line(err):
    text = " ".join(str(err).split()) or "(no message)"
    from ..io import CaseError

    return text if isinstance(err, CaseError) else f"{type(err).__name__}: {text}"


def _parse(case_bytes, path):
    """The case from its file's content, with the errors ``load_case`` gives."""
    from ..io import CaseError, parse_case

    try:
        data = tomllib.loads(case_bytes.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise CaseError(None, rule="not a UTF-8 text file", path=path) from err
    except tomllib.TOMLDecodeError as err:
        raise CaseError(None, rule=f"TOML syntax error: {err}", path=path) from err
    return parse_case(data, path=path)


def _model(case, options):
    from ..plate.model import PlateModel

    return PlateModel.from_case(case, mesh=_mesh(options))


def _mesh(options):
    """The step's mesh (a JSON list in its options) as the run layer takes it."""
    return None if options["mesh"] is None else tuple(options["mesh"])


def _estimate(case, options):
    """``bayesplate estimate`` (its defaults: TOL 1e-3, the paper's conventions)."""
    from ..run import EstimateOptions, run_estimate

    done = run_estimate(
        case,
        EstimateOptions(
            method=options["method"],
            mesh=_mesh(options),
            pairing=options["pairing"],
            forward=options["forward"],
        ),
    )
    r, model, scale, doc = done.result, done.model, done.scale, done.document
    chi2, dof = _estimate_chi2(case, r)
    row = {
        "status": r.status,
        "reason": "" if r.converged else r.message,
        "method": r.method,
        "mesh": f"{model.mesh.nx}x{model.mesh.ny}",
        **_gaussian_columns(doc["constants"]),
        "chi2": chi2,
        "dof": dof,
        **_scale_columns(None if scale is None else scale.summary),
    }
    return row, doc


def _scale_columns(summary):
    """The inferred error scale's median and 94 % interval (none without the case key)."""
    if summary is None:
        return {}
    lo, hi = summary.interval
    return {"error_scale": summary.median, "error_scale_lo94": lo, "error_scale_hi94": hi}


def _estimate_chi2(case, r):
    """``sum(((f_computed - f_measured) / sigma)^2)`` over the paired modes, and their count.

    Each paired measured frequency is the case's to round-off (it went through eigenvalue
    units and back); one that is not (relative difference over 1e-9) leaves no chi-square.
    """
    f, sigma = case.measured.frequency_Hz, case.measured.sigma_Hz
    fm = np.asarray(r.measured_Hz, dtype=float)
    rows = np.argmin(np.abs(f[None, :] - fm[:, None]), axis=1)
    if fm.size == 0 or np.max(np.abs(f[rows] / fm - 1.0)) > 1e-9:
        return float("nan"), int(fm.size)
    return float(np.sum((np.asarray(r.residual) / sigma[rows]) ** 2)), int(fm.size)


def _sample(case, options):
    """``bayesplate sample --seed SEED`` (on the reduced model, with MVE beside B)."""
    from ..run import SampleOptions, run_sample

    chain = SampleOptions(
        mesh=_mesh(options),
        walkers=options["walkers"],
        max_steps=options["max_steps"],
        min_ess=options["min_ess"],
        pairing=options["pairing"],
    )
    done = run_sample(case, chain, options["seed"])
    r, doc = done.result, done.document
    columns = {}
    for key, c in doc["constants"].items():
        columns.update(
            {
                key: c["mean"],
                f"{key}_sd": c["sd"],
                f"{key}_lo94": c["hdi_3%"],
                f"{key}_hi94": c["hdi_97%"],
            }
        )
    row = {
        "status": "converged" if r.converged else "stopped",
        "reason": "" if r.converged else r.message,
        "mesh": f"{done.model.mesh.nx}x{done.model.mesh.ny}",
        **columns,
        **_scale_columns(done.scale),
    }
    return row, doc


def _diagnose(case, options):
    """``bayesplate diagnose --seed SEED`` (its fits one after another: one core per task)."""
    from ..discrepancy.diagnose import diagnose
    from ..io import diagnosis_to_dict

    model = _model(case, options)
    d = diagnose(case, model=model, rng=options["seed"], pairing=options["pairing"], workers=1)
    doc = diagnosis_to_dict(d)
    fit = doc["refit"] if doc["refit"] is not None else doc["nominal"]
    row = {
        "status": "done",
        "reason": "",
        "mesh": f"{model.mesh.nx}x{model.mesh.ny}",
        **_gaussian_columns(fit["constants"]),
        "verdict": d.verdict,
        "physics": doc["chosen"] or "",
        "chi2": fit["chi2"],
        "dof": fit["dof"],
        "p_value": fit["p_value"],
    }
    return row, doc


def _gaussian_columns(constants):
    """``E1_GPa, E1_GPa_sd, E1_GPa_lo94, E1_GPa_hi94, ...``: mean -/+ Z94 sd."""
    out = {}
    for key in ENGINEERING_KEYS:
        m, s = constants[key]["mean"], constants[key]["sd"]
        s = float("nan") if s is None else s  # a fit without a covariance
        out.update({key: m, f"{key}_sd": s, f"{key}_lo94": m - Z94 * s, f"{key}_hi94": m + Z94 * s})
    return out


_STEPS = {"estimate": _estimate, "sample": _sample, "diagnose": _diagnose}
