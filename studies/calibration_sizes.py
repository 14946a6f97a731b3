"""The calibration's size table and its fitted-constants figures, kept by what they compute with.

Part of :mod:`studies.calibration`: the sizes its power replicates run at (the noncentrality of
each candidate on a grid of sizes, the ideal and the fitted test's, :func:`sizes`) and the
figures its report draws from them (:func:`figures`: the constants' absorption, diagnose's
widening, the fitted test's power at widened deviations, the mesh error the constants absorb).
They take about 21 minutes on the 120 x 60 recordings' mesh, and they depend on the finite
elements, the candidates' physics, the mesh-error estimate and this module, not on diagnose's
search: they are stored by the version of those (:data:`INPUTS`,
:func:`inputs_version`) in ``out_dir/.cache/calibration/sizes/<version>[-<rule>][-quick].json``,
so a change to diagnose alone runs the replicates again but not these.
"""

import json
import pathlib

import numpy as np
from scipy.stats import chi2, ncx2

from bayesplate import bundled_case_path, load_case, stiffness_from_engineering
from bayesplate.discrepancy.diagnose import DEFAULTS, mesh_error
from bayesplate.discrepancy.physics.location import absorbable_projector
from bayesplate.discrepancy.search import mesh_error as mesh_error_module
from bayesplate.io import atomic_write_text
from bayesplate.likelihood.posterior import prior_in_stiffness
from studies import recordings as rec
from studies._study_host import code_version
from studies.recordings import NOISE  # relative deviation of each recorded frequency

ALPHA = DEFAULTS["alpha"]
#: diagnose's mesh-error rules (``--mesh-error``) and its default.
RULES = mesh_error_module.MESH_ERROR_PARTS
DEFAULT_RULE = DEFAULTS["mesh_error_part"]

#: The power sizes, in running order: (label, reference test, its rejection probability,
#: factor): the size at which the reference test rejects with that probability, times the
#: factor. The ideal test is the chi-square at the true constants (m dof); the fitted test
#: the same once the six constants have absorbed what they can (m - 6 dof).
SIZES = (
    ("fitted 0.9", "fitted", 0.9, 1.0),
    ("3 x ideal 0.9", "ideal", 0.9, 3.0),
    ("ideal 0.9", "ideal", 0.9, 1.0),
    ("ideal 0.5", "ideal", 0.5, 1.0),
)
N_CONSTANTS = 6  # the constants diagnose fits (its stiffness coefficients)
#: diagnose's working mesh for each family (the recordings' is twice as fine each way). Its
#: frequencies sit 0.58 deviations rms from a converged mesh; 40 x 20's 1.29 widened the
#: deviations enough to hide most candidates at their fitted 0.9 size
#: (``reports/working_mesh_power.md``).
FAMILIES = {"frederiksen_t300": (60, 30), "crossply": (48, 24)}
QUICK_FAMILIES = {"frederiksen_t300": (6, 3), "crossply": (8, 4)}
POWER_FAMILY = "frederiksen_t300"

EFFECTS = rec.EFFECTS  # the candidates, their places and sizes
#: The fitted 0.9 size measured, where it has been: the smallest size run at which the fitted
#: test fitted globally (the constants from many starts, no prior: ``studies.fitted_test``,
#: ``reports/fitted_test.md``; the point support on the recordings' 120 x 60 mesh,
#: ``reports/fitted_test_point_support.md``) rejected at least 9 of these same 10 replicates.
#: Its linearised estimate (``fitted_noncentrality``) lets the constants absorb too little and
#: sets the size lower (the point mass 0.17 g, the point support 4.8e4 N/m, where the global
#: fit rejects fewer); it stands only for the candidate not measured (the thickness taper),
#: and in quick mode.
FITTED_MEASURED = {
    "point_mass": 0.24,
    "ply_misalignment": 0.9,
    "elastic_foundation": 1.2e7,
    "local_stiffness_loss": 0.36,
    "cutout": 7.5,
    "delamination": 0.8,
    "cut_corner": 6.5,
    "point_support": 6.5e4,
}


# ---------------------------------------------------------------- the ideal test


def noncentrality(f_effect, f_nominal, noise=NOISE):
    """``sum(((f_effect - f_nominal) / (noise f_nominal))**2)`` over the sorted frequencies."""
    f_effect, f_nominal = np.sort(f_effect), np.sort(f_nominal)
    return float(np.sum(((f_effect - f_nominal) / (noise * f_nominal)) ** 2))


def fitted_residual(delta_lambda, S, sigma_lambda):
    """The whitened effect the six constants leave, and their whitened sensitivities.

    ``(I - A A^+) r`` with ``r = delta_lambda / sigma_lambda`` and ``A = S / sigma_lambda``
    (linearised at the true constants): :func:`fitted_noncentrality`'s vector.

    Returns
    -------
    left : numpy.ndarray, shape (m,)
    A : numpy.ndarray, shape (m, 6)
    """
    r = np.asarray(delta_lambda, dtype=float) / sigma_lambda
    A = np.asarray(S, dtype=float) / np.asarray(sigma_lambda, dtype=float)[:, None]
    coef, *_ = np.linalg.lstsq(A, r, rcond=None)
    return r - A @ coef, A


def fitted_noncentrality(delta_lambda, S, sigma_lambda):
    """The noncentrality left once the six constants have absorbed what they can (linearised).

    ``|| (I - A A^+) r ||^2`` with ``r = delta_lambda / sigma_lambda`` and ``A = S /
    sigma_lambda``: the part of the effect no change of the constants mimics, the
    noncentrality of a chi-square test of the fitted nominal model (``m - 6`` dof, no prior).

    Parameters
    ----------
    delta_lambda : numpy.ndarray, shape (m,)
        Eigenvalues with the effect minus without, at the true constants, (rad/s)^2.
    S : numpy.ndarray, shape (m, 6)
        Their derivatives in the stiffness coefficients at the true constants.
    sigma_lambda : numpy.ndarray, shape (m,)
        The eigenvalues' deviations.
    """
    left, _ = fitted_residual(delta_lambda, S, sigma_lambda)
    return float(np.sum(left**2))


#: Noise draws of :func:`recorded_noise_power` (its standard error is at most 0.0011) and
#: their seed.
DRAWS, DRAWS_SEED = 200_000, 20261127


def recorded_noise_power(residual, jacobian, widening, dof, rng, draws=DRAWS, alpha=ALPHA):
    """The fitted test's power at widened deviations when the noise is as recorded.

    diagnose divides the residuals by ``w_i sigma_i`` (its deviations widened by the mesh's
    error, ``w_i >= 1``) and compares their chi-square with the ``chi2(dof)`` quantile; the
    recordings' noise has the sd ``sigma_i``, not ``w_i sigma_i``. Linearised at the fit, the
    fitted whitened residual of noisy recordings is ``r + (I - H) e``: ``r`` the noiseless
    fit's residual (`residual`, orthogonal to the columns of `jacobian`), ``H`` the
    projection on the columns of `jacobian` (the constants take up their share of the noise
    too; rows beyond ``m``, a prior's, carry no noise), ``e_i ~ N(0, 1 / w_i^2)`` in the
    ``m`` data rows. The chi-square of its data rows is a generalised chi-square, its tail
    drawn here by Monte Carlo.

    With every ``w_i = 1`` and no prior this is the noncentral chi-square's tail
    (:func:`ideal_power` at ``dof = m - 6``); with ``w_i = w``, that of ``ncx2(m - 6, w^2
    chi2) / w^2`` beyond the same quantile: widening the deviations shrinks the noise's
    share of the statistic and not its critical value, so the test is conservative.

    Parameters
    ----------
    residual : numpy.ndarray, shape (n,)
        Whitened (by the widened deviations), ``n >= m``.
    jacobian : numpy.ndarray, shape (n, 6)
    widening : numpy.ndarray, shape (m,)
    dof : float
    rng : numpy.random.Generator
    draws : int

    Returns
    -------
    float
        P(chi-square of the data rows > ``chi2.ppf(1 - alpha, dof)``).
    """
    w = np.asarray(widening, dtype=float)
    m, rows = w.size, np.size(residual)
    Q, _ = np.linalg.qr(np.asarray(jacobian, dtype=float))
    noise = np.zeros((draws, rows))
    noise[:, :m] = rng.standard_normal((draws, m)) / w
    left = noise - (noise @ Q) @ Q.T + residual
    statistic = np.sum(left[:, :m] ** 2, axis=1)
    return float(np.mean(statistic > chi2.ppf(1.0 - alpha, dof)))


def fitted_lambdas(deltas, S, sigma_lambda):
    """:func:`fitted_noncentrality` of each effect vector in ``deltas`` (one per size)."""
    return [fitted_noncentrality(d, S, sigma_lambda) for d in deltas]


def fitted_size(grid, deltas, S, sigma_lambda, power, alpha=ALPHA):
    """The size at which the test of the fitted nominal model rejects with ``power``.

    ``deltas[i]`` is the effect on the eigenvalues at ``grid[i]``; the test has ``m - 6``
    degrees of freedom (``S`` has six columns); the fitted noncentralities on the grid are
    inverted by :func:`size_for`. Returns ``(size or None, the noncentralities)``.
    """
    lams = fitted_lambdas(deltas, S, sigma_lambda)
    m, k = np.shape(S)
    return size_for(grid, lams, noncentrality_for(power, m - k, alpha)), lams


def bound_power(lam, alpha=ALPHA):
    """The most powerful test at level ``alpha`` of an effect known in advance (1 dof):
    a bound on the rate at which any method with that false-alarm rate detects it, given
    the noncentrality ``lam`` it leaves."""
    return ideal_power(lam, 1, alpha)


def ideal_power(lam, m, alpha=ALPHA):
    """Probability that the chi-square test at the true constants rejects: ``ncx2.sf``."""
    crit = chi2.ppf(1.0 - alpha, m)
    return float(ncx2.sf(crit, m, lam)) if lam > 0 else alpha


def noncentrality_for(power, m, alpha=ALPHA):
    """The noncentrality at which the ideal test rejects with probability ``power``."""
    lo, hi = 0.0, 1.0
    while ideal_power(hi, m, alpha) < power:
        hi *= 2.0
    for _ in range(100):  # bisection: power is increasing in lambda
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ideal_power(mid, m, alpha) < power else (lo, mid)
    return 0.5 * (lo + hi)


def lambda_at(entry, size):
    """The noncentrality at ``size``, log-log interpolated on the grid of a ``sizes`` entry."""
    grid, lams = np.log(entry["grid"]), np.log(np.maximum(entry["lambda"], 1e-300))
    return float(np.exp(np.interp(np.log(size), grid, lams)))


def size_for(grid, lams, lam):
    """The size at which ``lambda(size)`` reaches ``lam``: log-log interpolation of the grid.

    Returns None when ``lam`` lies beyond the grid's largest value (the effect never gets
    that large within its admissible sizes).
    """
    grid, lams = np.asarray(grid, dtype=float), np.asarray(lams, dtype=float)
    top = np.maximum.accumulate(lams)  # the first size reaching a value
    if lam > top[-1]:
        return None
    k = int(np.searchsorted(top, lam))
    if k == 0:
        return float(grid[0])
    l0, l1 = np.log(max(top[k - 1], 1e-300)), np.log(top[k])
    t = (np.log(lam) - l0) / (l1 - l0) if l1 > l0 else 1.0
    return float(np.exp(np.log(grid[k - 1]) + t * (np.log(grid[k]) - np.log(grid[k - 1]))))


def _case(family):
    return load_case(bundled_case_path(family))


def _models(family, quick):
    """The family's case, diagnose's plate and the recordings' (twice as fine each way)."""
    case = _case(family)
    model, fine = rec.meshes(case, (QUICK_FAMILIES if quick else FAMILIES)[family])
    return case, model, fine


_frequencies = rec.frequencies  # the plate's frequencies at the case's reference constants


def sizes(quick=False):
    """``{effect: {"grid", "lambda", "fitted_lambda", "sizes": [size of each of SIZES or None]}}``.

    The noncentrality of each effect on a grid of sizes (Frederiksen plate, recordings' mesh,
    true constants), of the ideal test and of the fitted one (the six constants' linearised
    absorption, :func:`fitted_noncentrality`), and the sizes of ``SIZES``, rounded to two
    digits; None where the grid (the admissible sizes) does not reach it. The fitted 0.9
    size is the measured one of ``FITTED_MEASURED`` where there is one (``"measured"``).
    """
    case, _, fine = _models(POWER_FAMILY, quick)
    b = stiffness_from_engineering(case.reference)
    nominal = fine.solve(b, case.measured.size)
    f0 = nominal.frequency_Hz
    m = f0.size
    sigma_lambda = 2.0 * NOISE * nominal.eigenvalues  # d lambda = 2 lambda df / f
    out = {}
    for name, (make, theta, _, grid) in EFFECTS.items():
        if quick and name != "point_mass":
            continue
        physics = make()
        solved = [physics.apply(fine, np.asarray(theta(s), dtype=float)).solve(b, m) for s in grid]
        lams = [noncentrality(x.frequency_Hz, f0) for x in solved]
        deltas = [np.sort(x.eigenvalues) - nominal.eigenvalues for x in solved]
        fitted = fitted_lambdas(deltas, nominal.sensitivities, sigma_lambda)
        found = []
        for _, reference, p, factor in SIZES:
            if reference == "fitted" and not quick and name in FITTED_MEASURED:
                at = FITTED_MEASURED[name]
            elif reference == "fitted":
                at = size_for(grid, fitted, noncentrality_for(p, m - N_CONSTANTS))
            else:
                at = size_for(grid, lams, noncentrality_for(p, m))
            found.append(None if at is None or factor * at > grid[-1] else factor * at)
        rounded = [None if s is None else float(f"{s:.2g}") for s in found]
        out[name] = {
            "grid": list(map(float, grid)),
            "lambda": lams,
            "fitted_lambda": fitted,
            "sizes": rounded,
            "measured": not quick and name in FITTED_MEASURED,
        }
    return out


def widening(quick=False, frequency_Hz=None, rule=DEFAULT_RULE, b=None):
    """How much diagnose widens each recorded frequency's deviation (Frederiksen plate).

    As diagnose does under its mesh-error ``rule`` (:data:`RULES`):

    - ``"whole"``: its mesh's own error at the prior mean, estimated as a third of the
      difference to the mesh half as fine, is added in quadrature when it exceeds
      ``mesh_error_ratio`` deviations somewhere;
    - ``"unabsorbed"``: the same with the part of that error the six constants cannot absorb
      (:func:`.mesh_error.unabsorbed`), under the same threshold;
    - ``"corrected"``: the computed frequencies are corrected by the error estimated with the
      mesh twice as fine, and the uncertainty the correction leaves, ``u``
      (:func:`.mesh_error.corrected_error`), is always added in quadrature, relative to the
      working mesh's frequency as diagnose scales it onto the peaks:
      ``hypot(1, (u / f_mesh) / NOISE)`` (``frequency_Hz`` unused). diagnose estimates it
      again at its nominal fit, which for these recordings lies near the true constants:
      here it is taken at ``b`` (default the true constants; on the quick study's 6 x 3
      mesh the fit strays far enough from them to move ``u`` by up to 40 %).

    Returns ``hypot(1, added / (NOISE f))`` per mode (ones when it does not widen), ``f`` the
    recorded frequencies (default: the clean plate's on the recordings' mesh, without noise).
    """
    if rule not in RULES:
        raise ValueError(f"rule {rule!r}: must be one of {', '.join(RULES)}")
    case, model, fine = _models(POWER_FAMILY, quick)
    mu_b, _ = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    m = case.measured.size
    if rule == "corrected":
        b = stiffness_from_engineering(case.reference) if b is None else b  # (diagnose: its fit)
        working = model.solve(b, m).frequency_Hz
        finer = mesh_error_module.finer_model(model).solve(b, m).frequency_Hz
        _, u = mesh_error_module.richardson(working, finer)  # corrected_error, solved once
        return np.hypot(1.0, u / working / NOISE)
    if frequency_Hz is None:
        frequency_Hz = np.sort(_frequencies(case, fine))
    sigma = NOISE * np.asarray(frequency_Hz, dtype=float)
    added = mesh_error(model, mu_b, m)
    if rule == "unabsorbed":
        at = model.solve(mu_b, m)
        added = mesh_error_module.unabsorbed(added, sigma, at.eigenvalues, at.sensitivities)
    ratio = np.abs(added) / sigma
    return np.hypot(1.0, ratio) if ratio.max() > DEFAULTS["mesh_error_ratio"] else np.ones(m)


def mesh_error_left(quick=False):
    """How much of the mesh's error the six constants absorb (Frederiksen plate).

    Whitened by the recordings' deviations (``NOISE f``, ``f`` the clean plate's frequencies
    on the recordings' mesh), RMS over the modes: diagnose's estimate at the prior mean (a
    third of the difference to the mesh half as fine), and the actual difference at the true
    constants to the recordings' mesh; each whole, and what is left of it once projected off
    the whitened sensitivities of diagnose's mesh there (:func:`.locate.absorbable_projector`:
    what a change of the constants cannot mimic, linearised).

    Returns
    -------
    dict
        ``estimated``, ``estimated_left``, ``actual``, ``actual_left`` (RMS, deviations),
        ``estimated_max`` and ``actual_max`` (the largest, deviations).
    """
    case, model, fine = _models(POWER_FAMILY, quick)
    m = case.measured.size
    f = np.sort(_frequencies(case, fine))
    mu_b, _ = prior_in_stiffness(case.prior.mean, case.prior.sd, "full")
    b = stiffness_from_engineering(case.reference)
    at_mean, at_truth = model.solve(mu_b, m), model.solve(b, m)
    out = {}
    for label, r, err_Hz in (
        ("estimated", at_mean, mesh_error(model, mu_b, m)),
        ("actual", at_truth, at_truth.frequency_Hz - f),
    ):
        whitened = err_Hz / (NOISE * f)
        # d f / d b = f / (2 lambda) d lambda / d b, whitened by the same deviations
        S = r.sensitivities * (r.frequency_Hz / (2.0 * r.eigenvalues))[:, None]
        left = absorbable_projector(S / (NOISE * f)[:, None]) @ whitened
        out[label] = float(np.sqrt(np.mean(whitened**2)))
        out[f"{label}_left"] = float(np.sqrt(np.mean(left**2)))
        out[f"{label}_max"] = float(np.max(np.abs(whitened)))
    return out


def absorbed(size_table, quick=False, widen=None, power=False):
    """``{effect: [fitted-constants noncentrality at each size, or None]}`` (Frederiksen).

    ``widen``: factors on the recordings' deviations (:func:`widening`: the test diagnose
    runs); None for the declared ones. ``power``: instead of the noncentralities, the fitted
    test's power (``m - 6`` dof) with the noise as recorded, not widened
    (:func:`recorded_noise_power`, seeded by :data:`DRAWS_SEED` at each size).
    """
    case, _, fine = _models(POWER_FAMILY, quick)
    b = stiffness_from_engineering(case.reference)
    m = case.measured.size
    nominal = fine.solve(b, m)
    sigma_lambda = 2.0 * NOISE * nominal.eigenvalues  # d lambda = 2 lambda df / f
    widen = np.ones(m) if widen is None else np.asarray(widen, dtype=float)
    sigma_lambda = sigma_lambda * widen
    out = {}
    for name, entry in size_table.items():
        make, theta_of, _, _ = EFFECTS[name]
        out[name] = []
        for size in entry["sizes"]:
            if size is None:
                out[name].append(None)
                continue
            plate = make().apply(fine, np.asarray(theta_of(size), dtype=float))
            lam = np.sort(plate.solve(b, m).eigenvalues)
            left, A = fitted_residual(
                lam - nominal.eigenvalues, nominal.sensitivities, sigma_lambda
            )
            if power:
                rng = np.random.default_rng(DRAWS_SEED)
                out[name].append(recorded_noise_power(left, A, widen, m - N_CONSTANTS, rng))
            else:
                out[name].append(float(np.sum(left**2)))
    return out


#: What :func:`figures` computes from the size table, by key.
FIGURES = ("absorbed", "widening", "widened_power", "widened_grid_power", "mesh_error_left")


def figures(table, quick=False, rule=DEFAULT_RULE):
    """The size table's fitted-constants figures (:data:`FIGURES`), by key.

    ``absorbed``: the fitted test's noncentrality at each size; ``widening``: diagnose's
    factors on the deviations under ``rule``; ``widened_power`` (at each size) and
    ``widened_grid_power`` (on the grid): the fitted test at those widened deviations, the
    noise as recorded; ``mesh_error_left``: how much of the mesh's error the constants absorb.
    """
    widen = widening(quick, rule=rule)
    on_grid = {e: {"sizes": entry["grid"]} for e, entry in table.items()}
    return {
        "absorbed": absorbed(table, quick),
        "widening": list(map(float, widen)),
        "widened_power": absorbed(table, quick, widen, power=True),
        "widened_grid_power": absorbed(on_grid, quick, widen, power=True),
        "mesh_error_left": mesh_error_left(quick),
    }


# ---------------------------------------------------------------- kept by their inputs

#: The code the size table and its figures run (paths in the repository): the finite
#: elements, the plate and its laminate, the cases and their reading, the candidates'
#: physics, the mesh-error estimate and diagnose's options (its defaults), the prior, the
#: recordings and this module. ``tests/test_calibration_study.py`` checks that every
#: function of the package or the studies they call lies in one of these.
INPUTS = (
    "bayesplate/data",
    "bayesplate/discrepancy/physics",
    "bayesplate/discrepancy/search/mesh_error.py",
    "bayesplate/discrepancy/search/options.py",
    "bayesplate/fem",
    "bayesplate/io",
    "bayesplate/laminate.py",
    "bayesplate/likelihood",
    "bayesplate/plate",
    "bayesplate/quantities.py",
    "studies/calibration_sizes.py",
    "studies/recordings.py",
)


def inputs_version():
    """The last commit that changed :data:`INPUTS` (``+modified`` when they differ from it)."""
    return code_version(paths=INPUTS)


def table_path(out_dir, quick, rule=None, version=None):
    """Where the size table and the figures of ``version`` (default :func:`inputs_version`)
    under mesh-error ``rule`` are kept."""
    version = version or inputs_version()
    rule = rule or DEFAULT_RULE
    name = f"{version}{'' if rule == DEFAULT_RULE else '-' + rule}{'-quick' if quick else ''}"
    return pathlib.Path(out_dir) / ".cache" / "calibration" / "sizes" / f"{name}.json"


def kept(out_dir, quick, spec, rule=None):
    """The kept table and figures of this version, ``{"sizes", "size_spec", *FIGURES}``
    (those computed), or ``{}``: none, or made for another ``spec`` (the sizes' plan)."""
    path = table_path(out_dir, quick, rule)
    if not path.exists():
        return {}
    held = json.loads(path.read_text())
    return held if held.get("size_spec") == spec and held.get("sizes") is not None else {}


def keep(out_dir, quick, stored, rule=None):
    """Keep ``stored``'s table and whatever figures it holds, under this version."""
    path = table_path(out_dir, quick, rule)
    path.parent.mkdir(parents=True, exist_ok=True)
    held = {k: stored[k] for k in ("sizes", "size_spec", *FIGURES) if k in stored}
    atomic_write_text(path, json.dumps({"inputs": inputs_version(), **held}))
