"""A case -> a folder with a Markdown report and its figures (``bayesplate report``).

The report runs a fixed list of steps on one case file:

``pairing``
    The modes at the prior mean (``m + 6`` of them) and the measured-to-computed pairing
    (:func:`bayesplate.pairing.pair_measured`: by shape when the case has shapes).
``B``, ``MVE``, ``MVE-mod``
    The paper's estimators (:func:`bayesplate.estimators.estimate`) with that pairing.
``modes``
    Modes, sensitivities and mode kinds at the B estimate (the posterior mode).
``sample``
    The posterior by MCMC (:func:`bayesplate.sampling.sample`), when the package has it.
``diagnose``
    Model discrepancy (:func:`bayesplate.discrepancy.diagnose.diagnose`).

Each step's result is plain data (numbers, strings, arrays), cached in ``DIR/.cache`` under
a key that hashes the case file's bytes, the step's name and options and the package
version; re-running reuses every result whose key matches (a changed case, mesh or option
redoes the steps it touches). Results are always used in their cached (serialised) form, so
a report from reused results is the same as one from fresh results.

Computation (:func:`compute_report`) is kept apart from drawing (:func:`report_figures`),
rendering (:func:`render_markdown`) and writing (:func:`write_report`). Every file is written
whole or not at all (a temporary name in the same folder, then a rename), and ``report.md``
is written last, after all its figures.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import json
import logging
import math
import pathlib
import sys
import threading
import time
import warnings
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from . import __version__
from .case import Case, load_case
from .io import atomic_write, atomic_write_text, jsonable, save_figure
from .laminate import stiffness_from_engineering
from .model import DEFAULT_MESH, ModalResult, PlateModel
from .pairing import DEFAULT_EXTRA_MODES, MAC_EXTRA_MODES, Pairing, pair_measured

__all__ = [
    "ESTIMATORS",
    "ReportData",
    "ReportOptions",
    "StepCache",
    "compute_report",
    "make_report",
    "render_markdown",
    "report_figures",
    "sampling_available",
    "write_report",
]

log = logging.getLogger(__name__)

ESTIMATORS = ("B", "MVE", "MVE-mod")
_HEARTBEAT = 30.0  # seconds without a progress line before a "still running" one
# Chain bounds of the posterior section: the sampler's own defaults (5000 steps, ESS 2000)
# cost tens of minutes of full solves where walkers leave the fast model's box.
_CHAINS = {"max_steps": 1000, "min_ess": 1000.0}
_QUICK_CHAINS = {"max_steps": 400, "min_ess": 400.0}
_CORNER_DRAWS = 4000  # posterior draws kept for the corner plot
_SHAPE_GRID = (81, 41)  # points along the long and short side (interpolation is per point)
_GPA = np.array([1e9, 1e9, 1.0, 1e9, 1e9, 1e9])  # SI -> case units (GPa, -)
_NAMES = ("E1", "E2", "nu12", "G12", "G13", "G23")
_UNITS = ("GPa", "GPa", "-", "GPa", "GPa", "GPa")


@dataclass(frozen=True)
class ReportOptions:
    """What the report computes.

    Parameters
    ----------
    quick : bool
        A first look: the working mesh has half the elements each way (unless `mesh` is
        given), diagnose makes one random start instead of four, and the posterior chains
        are shorter. Nothing is skipped.
    mesh : tuple of int, optional
        Elements along x and y; default the case's ``[model] mesh``.
    seed : int
        Seeds diagnose's random starts and the sampler.
    diagnose : bool
        Run the model-discrepancy diagnosis (the longest step).
    sample : bool
        Sample the posterior when :mod:`bayesplate.sampling` is available.
    n_shapes : int
        Mode shapes drawn.
    """

    quick: bool = False
    mesh: tuple | None = None
    seed: int = 0
    diagnose: bool = True
    sample: bool = True
    n_shapes: int = 6

    def working_mesh(self, case):
        """Elements ``(nx, ny)`` of the working mesh for `case`."""
        if self.mesh is not None:
            return tuple(int(n) for n in self.mesh)
        nx, ny = case.mesh or DEFAULT_MESH
        if self.quick:
            nx, ny = max(math.ceil(nx / 2), 2), max(math.ceil(ny / 2), 1)
        return int(nx), int(ny)

    @property
    def n_starts(self):
        """Random starts of diagnose's nominal fit (besides the prior mean)."""
        return 1 if self.quick else 4


# ----------------------------------------------------------------------------- the cache


def _serialise(data):
    """Split a step result into its arrays (npz) and the rest (a JSON string)."""
    arrays = {k: v for k, v in data.items() if isinstance(v, np.ndarray)}
    rest = {k: v for k, v in data.items() if k not in arrays}
    return arrays, json.dumps(rest, default=jsonable, sort_keys=True)


def _deserialise(arrays, text):
    return {**json.loads(text), **{k: np.asarray(v) for k, v in arrays.items()}}


class StepCache:
    """Results of report steps in a folder, keyed by case, step, options and version.

    Parameters
    ----------
    directory : path or None
        Where the ``.npz`` files live (created when needed); None keeps nothing (every
        step is computed).
    case_bytes : bytes
        The case file's content.
    version : str
        The package version (a new version invalidates every result).

    Attributes
    ----------
    reused, computed : list of str
        Steps taken from the cache and steps computed, in order.
    """

    def __init__(self, directory, case_bytes, version=__version__):
        self.directory = None if directory is None else pathlib.Path(directory)
        self.case_digest = hashlib.sha256(case_bytes).hexdigest()
        self.version = version
        self.reused = []
        self.computed = []

    def key(self, step, options):
        """SHA-256 of (case content, step name, step options, package version)."""
        blob = json.dumps(
            {"case": self.case_digest, "step": step, "options": options, "version": self.version},
            sort_keys=True,
            default=jsonable,
        )
        return hashlib.sha256(blob.encode()).hexdigest()

    def _path(self, step):
        return self.directory / f"{step}.npz"

    def load(self, step, options):
        """The cached result of `step` with these options, or None."""
        if self.directory is None or not self._path(step).exists():
            return None
        try:
            with np.load(self._path(step), allow_pickle=False) as stored:
                if str(stored["__key__"]) != self.key(step, options):
                    return None
                arrays = {k: stored[k] for k in stored.files if not k.startswith("__")}
                return _deserialise(arrays, str(stored["__json__"]))
        except (OSError, KeyError, ValueError) as err:  # unreadable: compute afresh
            log.warning("cache file %s unreadable (%s): recomputing", self._path(step), err)
            return None

    def save(self, step, options, data):
        """Store `data` (a dict of arrays and JSON-able values); returns its stored form."""
        arrays, text = _serialise(data)
        if self.directory is not None:
            self.directory.mkdir(parents=True, exist_ok=True)
            stored = {
                **arrays,
                "__json__": np.array(text),
                "__key__": np.array(self.key(step, options)),
            }
            atomic_write(self._path(step), lambda handle: np.savez(handle, **stored), "wb")
        return _deserialise(arrays, text)

    def get(self, step, options, compute):
        """The cached result of `step`, or ``compute()`` stored; ``(data, reused)``."""
        data = self.load(step, options)
        if data is not None:
            self.reused.append(step)
            return data, True
        data = self.save(step, options, compute())
        self.computed.append(step)
        return data, False


# ----------------------------------------------------------------------------- progress


class _Progress:
    """One line per event, with the seconds since the report started."""

    def __init__(self, say=None):
        self.say = say or (lambda line: print(line, file=sys.stderr, flush=True))
        self.started = self.last = time.perf_counter()
        self.lock = threading.Lock()

    def elapsed(self):
        return time.perf_counter() - self.started

    def __call__(self, message):
        with self.lock:
            self.last = time.perf_counter()
            self.say(f"[{self.elapsed():7.1f} s] {message}")

    @contextlib.contextmanager
    def heartbeat(self, title, every=_HEARTBEAT):
        """A "still running" line whenever `every` seconds pass without one."""
        done = threading.Event()

        def beat():
            while not done.wait(min(every, 5.0)):
                if time.perf_counter() - self.last >= every:
                    self(f"    {title}: still running")

        thread = threading.Thread(target=beat, daemon=True)
        thread.start()
        try:
            yield
        finally:
            done.set()
            thread.join()


class _Forward(logging.Handler):
    """Passes the library's log records on as progress lines.

    Estimator iterations (many, fast) are thinned to one line per `every` seconds.
    """

    def __init__(self, progress, every=10.0):
        super().__init__(logging.INFO)
        self.progress, self.every = progress, every
        self.last = time.perf_counter()

    def emit(self, record):
        if record.name.endswith("estimators") and time.perf_counter() - self.last < self.every:
            return
        self.last = time.perf_counter()
        self.progress(f"    {record.getMessage()}")


_LOGGERS = ("bayesplate.estimators", "bayesplate.sampling", "bayesplate.reduced")


@contextlib.contextmanager
def _logs_shown(progress):
    """Within the block, INFO records of the long steps become progress lines (only)."""
    handler = _Forward(progress)
    saved = []
    for name in _LOGGERS:
        target = logging.getLogger(name)
        saved.append((target, target.level, target.propagate))
        target.addHandler(handler)
        target.setLevel(logging.INFO)
        target.propagate = False
    try:
        yield
    finally:
        for target, level, propagate in saved:
            target.removeHandler(handler)
            target.setLevel(level)
            target.propagate = propagate


# ----------------------------------------------------------------------------- the steps


def sampling_available():
    """Whether the package has :mod:`bayesplate.sampling` (the posterior section)."""
    return importlib.util.find_spec("bayesplate.sampling") is not None


@dataclass
class ReportData:
    """Everything a report shows, as plain data (see the module docstring for the steps).

    Attributes
    ----------
    case : Case
    case_file : str
        The case file read.
    options : ReportOptions
    mesh : tuple of int
        The working mesh.
    results : dict
        Step name -> its result (dict of JSON values and arrays).
    reused, computed : list of str
        Steps taken from the cache and steps computed.
    seconds : dict
        Step name -> wall time of this run (small for reused steps).
    notes : list of str
        Why a section is missing, warnings met on the way.
    """

    case: Case
    case_file: str
    options: ReportOptions
    mesh: tuple
    results: dict = field(default_factory=dict)
    reused: list = field(default_factory=list)
    computed: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    version: str = __version__
    label: str = ""
    model: object = field(default=None, repr=False)

    def plate_model(self):
        """The working :class:`bayesplate.model.PlateModel` (built when first needed)."""
        if self.model is None:
            self.model = PlateModel.from_case(self.case, mesh=self.mesh)
        return self.model

    def pairing(self):
        """The :class:`bayesplate.pairing.Pairing` every step used."""
        p = self.results["pairing"]
        measured = p.get("measured")
        return Pairing(
            p["modes"], p["how"], DEFAULT_EXTRA_MODES, measured, p.get("mac"), p.get("threshold")
        )


def _pairing_step(case, model):
    """Modes at the prior mean and the pairing (with any warnings as text)."""
    m = case.measured.size
    b = stiffness_from_engineering(case.prior.mean)
    modal = model.solve(b, m + MAC_EXTRA_MODES)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pairing = pair_measured(case, model, b, modal=modal)
    data = {
        "how": pairing.how,
        "modes": pairing.modes,
        "describe": pairing.describe(m),
        "warnings": [str(w.message) for w in caught],
        "prior_frequency_Hz": modal.frequency_Hz,
        "threshold": pairing.threshold,
    }
    if pairing.measured is not None:
        data["measured"] = pairing.measured
    if pairing.mac is not None:
        data["mac"] = pairing.mac
    return data


def _estimate_step(case, model, method, pairing):
    from .estimators import estimate

    r = estimate(case, method, model=model, pairing=pairing)
    return {
        "method": r.method,
        "converged": bool(r.converged),
        "iterations": int(r.iterations),
        "message": r.message,
        "n_solves": int(r.n_solves),
        "wall_time": float(r.wall_time),
        "modes": np.asarray(r.modes),
        "constants": r.constants,
        "sd": r.sd,
        "b": r.b,
        "frequency_Hz": r.frequency_Hz,
        "measured_Hz": r.measured_Hz,
        "residual_Hz": r.residual,
        "stages": [
            {"converged": bool(s.converged), "iterations": int(s.iterations), "message": s.message}
            for s in r.stages
        ],
    }


def _modes_step(case, model, b, n_modes, n_shapes):
    from .discrepancy.locate import mode_kinds

    modal = model.solve(np.asarray(b, dtype=float), n_modes)
    return {
        "b": modal.b,
        "frequency_Hz": modal.frequency_Hz,
        "eigenvalues": modal.eigenvalues,
        "normalised_sensitivities": modal.normalised_sensitivities(),
        "kinds": mode_kinds(model, modal),
        "vectors": modal.vectors[:, :n_shapes],
    }


def _diagnose_step(case, model, pairing, options, progress):
    from .discrepancy.diagnose import diagnose, diagnosis_to_dict

    d = diagnose(
        case,
        model=model,
        rng=options.seed,
        pairing=pairing,
        progress=lambda msg: progress(f"    {msg}"),
        n_starts=options.n_starts,
        workers=2,  # the fits are independent: the results do not depend on it
    )
    data = {"diagnosis": diagnosis_to_dict(d), "mode_kinds": d.mode_kinds}
    for key, lm in d.maps.items():
        for name in ("points_mm", "chi2_drop", "amplitude", "physical"):
            data[f"map_{key}_{name}"] = np.asarray(getattr(lm, name))
        data[f"map_{key}_shape"] = np.asarray(lm.shape)
    return data


def _sample_step(case, model, pairing, options):
    """The posterior by :func:`bayesplate.sampling.sample` (only when the module exists)."""
    from .laminate import engineering_from_stiffness
    from .sampling import sample

    chains = _QUICK_CHAINS if options.quick else _CHAINS
    with warnings.catch_warnings(record=True) as caught:  # counted below, not repeated
        warnings.simplefilter("always")
        r = sample(case, seed=options.seed, model=model, pairing=pairing, progress=False, **chains)
    e = engineering_from_stiffness(r.samples_b) / _GPA
    keep = np.linspace(0, len(e) - 1, min(len(e), _CORNER_DRAWS)).astype(int)
    return {
        "mean": r.mean,
        "sd": r.sd,
        "hdi": r.hdi,
        "ess_bulk": r.ess_bulk,
        "rhat": r.rhat,
        "converged": bool(r.converged),
        "message": r.message,
        "n_steps": int(r.n_steps),
        "n_burn": int(r.n_burn),
        "n_walkers": int(r.n_walkers),
        "acceptance": float(r.acceptance),
        "n_full": int(r.n_full),
        "certificate": None if r.certificate is None else str(r.certificate),
        "timings": {k: float(v) for k, v in r.timings.items()},
        "map": None if r.estimate is None else r.estimate.constants,
        "draws": e[keep],
        "warnings": sorted({str(w.message) for w in caught}),
    }


def compute_report(case_file, options=None, cache_dir=None, progress=None, label=None):
    """Run (or reuse) every step of the report of one case file.

    Parameters
    ----------
    case_file : path
        The case file (TOML).
    options : ReportOptions, optional
    cache_dir : path, optional
        Where step results are cached (``DIR/.cache``); None computes everything.
    progress : callable, optional
        ``progress(line)``; default: lines on standard error.
    label : str, optional
        How the case was named (``frederiksen_t300``), for the report; default the path.

    Returns
    -------
    ReportData
    """
    options = options or ReportOptions()
    case_file = pathlib.Path(case_file)
    case = load_case(case_file)
    cache = StepCache(cache_dir, case_file.read_bytes())
    say = progress if isinstance(progress, _Progress) else _Progress(progress)
    mesh = options.working_mesh(case)
    data = ReportData(
        case,
        str(case_file),
        options,
        mesh,
        reused=cache.reused,
        computed=cache.computed,
        label=label or str(case_file),
    )
    say(
        f"report of {case.name!r} on a {mesh[0]} x {mesh[1]} mesh"
        + (" (quick)" if options.quick else "")
    )
    run = _Runner(data, cache, say)
    with _logs_shown(say):
        run.pairing()
        for method in ESTIMATORS:
            run.estimate(method)
        run.modes()
        if options.sample:
            run.sample()
        if options.diagnose:
            run.diagnose()
    say("all steps done")
    return data


class _Runner:
    """Runs the steps of one report, each through the cache, with progress lines."""

    def __init__(self, data, cache, say):
        self.data, self.cache, self.say = data, cache, say
        self.case, self.options = data.case, data.options
        self.pairing_options = {"extra": MAC_EXTRA_MODES}

    def step(self, name, title, options, compute, optional=False):
        """``compute()`` or its cached result; an optional step may fail (noted)."""
        self.say(f"{title} ...")
        started = time.perf_counter()
        try:
            with self.say.heartbeat(title):
                result, reused = self.cache.get(name, {"mesh": self.data.mesh, **options}, compute)
        except Exception as err:
            if not optional:
                raise
            self.say(f"{title}: failed ({type(err).__name__}: {err}); section left out")
            self.data.notes.append(f"{title} failed: {type(err).__name__}: {err}")
            return None
        self.data.seconds[name] = time.perf_counter() - started
        done = "reused (cached)" if reused else f"done in {self.data.seconds[name]:.1f} s"
        self.say(f"{title}: {done}")
        self.data.results[name] = result
        return result

    def pairing(self):
        result = self.step(
            "pairing",
            "modes at the prior mean and mode pairing",
            self.pairing_options,
            lambda: _pairing_step(self.case, self.data.plate_model()),
        )
        for message in result["warnings"]:
            self.say(f"warning: {message}")
            self.data.notes.append(message)

    def estimate(self, method):
        self.step(
            method,
            f"estimate {method}",
            {"pairing": self.pairing_options},
            lambda: _estimate_step(self.case, self.data.plate_model(), method, self.data.pairing()),
        )

    def modes(self):
        data = self.data
        at = _estimate_for_modes(data)
        n = max(self.case.measured.size, int(np.max(data.pairing().modes)) + 1)
        b = _b_at(data, at)
        self.step(
            "modes",
            f"modes and sensitivities at the {at} estimate",
            {"b": b, "n": n, "shapes": self.options.n_shapes},
            lambda: _modes_step(self.case, data.plate_model(), b, n, self.options.n_shapes),
        )

    def sample(self):
        if not sampling_available():
            self.say("posterior sampling: not in this version of bayesplate (section left out)")
            return
        self.step(
            "sample",
            "posterior sampling",
            {
                "seed": self.options.seed,
                "quick": self.options.quick,
                "pairing": self.pairing_options,
            },
            lambda: _sample_step(
                self.case, self.data.plate_model(), self.data.pairing(), self.options
            ),
            optional=True,
        )

    def diagnose(self):
        self.step(
            "diagnose",
            "diagnose model discrepancy",
            {
                "seed": self.options.seed,
                "n_starts": self.options.n_starts,
                "pairing": self.pairing_options,
            },
            lambda: _diagnose_step(
                self.case, self.data.plate_model(), self.data.pairing(), self.options, self.say
            ),
        )


def _estimate_for_modes(data):
    """The estimate at which modes are drawn: B (the posterior mode) if it converged."""
    for method in ("B", "MVE-mod", "MVE"):
        if data.results[method]["converged"]:
            return method
    return "prior"


def _b_at(data, at):
    if at == "prior":
        return stiffness_from_engineering(data.case.prior.mean)
    return data.results[at]["b"]


# ----------------------------------------------------------------------------- figures


def _diagnosis_view(result):
    """What :func:`bayesplate.plots.diagnosis_figures` reads, from a cached diagnosis."""
    from .discrepancy.locate import LocationMap

    d = result["diagnosis"]
    maps = {}
    for key in ("stiffness_loss", "point_mass"):
        fields = [result[f"map_{key}_{n}"] for n in ("points_mm", "chi2_drop", "amplitude")]
        physical = result[f"map_{key}_physical"].astype(bool)
        maps[key] = LocationMap(
            *fields, physical, tuple(int(n) for n in result[f"map_{key}_shape"])
        )
    refit = d["refit"]
    chosen = (
        None
        if refit is None
        else SimpleNamespace(
            fit=SimpleNamespace(residual_sigma=np.asarray(refit["residual_sigma"]))
        )
    )
    return SimpleNamespace(
        verdict=d["verdict"],
        nominal=SimpleNamespace(residual_sigma=np.asarray(d["nominal"]["residual_sigma"])),
        chosen=chosen,
        measured_Hz=np.asarray(d["measured_Hz"]),
        mode_kinds=list(result["mode_kinds"]),
        maps=maps,
    )


def report_figures(data):
    """The figures of a report: ``{name: matplotlib Figure}``, in the order shown."""
    from . import plots

    r, figs = data.results, {}
    kept = data.pairing().kept(data.case.measured.size)
    series = {
        m: r[m]["frequency_Hz"]
        for m in ESTIMATORS
        if m in r and np.all(np.isfinite(r[m]["frequency_Hz"]))
    }
    if series:
        figs["residuals"] = plots.estimate_residuals(
            data.case.measured.frequency_Hz[kept],
            data.case.measured.sigma_Hz[kept],
            series,
            labels=[str(i + 1) for i in kept],
            title="residuals at each estimate",
        )
    figs.update(_modes_figures(data, plots))
    if "sample" in r:
        figs.update(_sample_figures(r["sample"]))
    if "diagnose" in r:
        view = _diagnosis_view(r["diagnose"])
        for name, fig in plots.diagnosis_figures(data.plate_model(), view).items():
            figs[f"diagnose_{name}"] = fig
    return figs


_SHORT_KINDS = {"bending along x": "bend x", "bending along y": "bend y"}


def _modes_figures(data, plots):
    """Sensitivity bars, mode shapes and (with measured shapes) the MAC matrix."""
    modes, figs = data.results["modes"], {}
    at, n = _estimate_for_modes(data), len(modes["frequency_Hz"])
    figs["sensitivities"] = plots.sensitivity_bars(
        modes["normalised_sensitivities"],
        notes=[_SHORT_KINDS.get(k, k) for k in modes["kinds"]],
        title=f"normalised sensitivities of the first {n} elastic modes at the {at} estimate",
    )
    k = modes["vectors"].shape[1]
    shapes = ModalResult(
        modes["b"], modes["eigenvalues"][:k], modes["vectors"], np.zeros((k, 6)), np.zeros(0)
    )
    figs["mode_shapes"] = plots.mode_shapes(data.plate_model(), shapes, n=k, points=_SHAPE_GRID)
    pairing, m = data.pairing(), data.case.measured.size
    if pairing.mac is not None:
        pairs = np.full(m, -1)
        pairs[pairing.kept(m)] = pairing.modes
        figs["mac"] = plots.mac_matrix_plot(
            pairing.mac,
            pairs,
            measured_Hz=data.case.measured.frequency_Hz,
            title="MAC of measured shapes against computed modes (prior mean); pairs outlined",
        )
    return figs


def _sample_figures(result):
    """Corner plot of the posterior draws (see :func:`_sample_step`)."""
    from .plots import posterior_corner

    labels = [f"{n} ({u})" for n, u in zip(_NAMES, _UNITS, strict=True)]
    truths = None if result["map"] is None else np.asarray(result["map"]) / _GPA
    fig = posterior_corner(
        result["draws"], labels, truths=truths, title="posterior (emcee); red: the B estimate (MAP)"
    )
    return {"posterior_corner": fig}


# ----------------------------------------------------------------------------- Markdown


def _table(head, rows):
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return lines


def _num(value, fmt):
    return "n/a" if value is None or not np.isfinite(value) else format(value, fmt)


def _constant(values, i, sd=None):
    """Constant i in case units, ``"113.5 ± 2.6"``."""
    v = values[i] / _GPA[i]
    text = _num(v, "#.4g") if i != 2 else _num(v, ".3f")
    if sd is not None:
        s = sd[i] / _GPA[i]
        text += " ± " + (_num(s, "#.2g") if i != 2 else _num(s, ".3f"))
    return text


def _image(figures, name, caption):
    return [f"![{caption}]({figures[name]})", "", f"*{caption}*", ""] if name in figures else []


def _header(data):
    c, o = data.case, data.options
    command = f"bayesplate report {data.label}" + (" --quick" if o.quick else "")
    steps = ", ".join(f"{s} ({data.seconds.get(s, 0):.0f} s)" for s in data.computed) or "none"
    lines = [
        f"# {c.name}",
        "",
        f"Made by `{command}` (bayesplate {data.version}, seed {o.seed}) on a "
        f"{data.mesh[0]} x {data.mesh[1]} mesh"
        + (" (quick: half the case's mesh)" if o.quick and o.mesh is None else "")
        + ".",
        f"Steps computed: {steps}; reused from the cache: {', '.join(data.reused) or 'none'}.",
        "",
    ]
    return lines + [f"> {note}" for note in data.notes] + ([""] if data.notes else [])


def _case_section(data):
    c, p = data.case, data.case.plate
    layup = "/".join(f"{a:g}" for a in p.layup_deg)
    lines = [
        "## Case",
        "",
        f"- Source: {c.source or 'not given'}",
        f"- Plate: {1e3 * p.length:g} x {1e3 * p.width:g} x {1e3 * p.thickness:g} mm, "
        f"density {p.density:g} kg/m^3, layup [{layup}] ({_plies(len(p.layup_deg))}), "
        "free-free",
        f"- Model: third-order shear deformation finite elements, {data.mesh[0]} x "
        f"{data.mesh[1]} mesh",
        "",
        "### Prior",
        "",
    ]
    head = ["constant", "unit", "prior mean", "prior sd"]
    head += ["reference"] if c.reference is not None else []
    rows = []
    for i, name in enumerate(_NAMES):
        row = [name, _UNITS[i], _constant(c.prior.mean, i), _constant(c.prior.sd, i)]
        rows.append(row + ([_constant(c.reference, i)] if c.reference is not None else []))
    return lines + _table(head, rows) + [""]


def _measured_section(data, figures):
    c, r = data.case, data.results["pairing"]
    pairing = data.pairing()
    kept = list(pairing.kept(c.measured.size))
    f_prior = np.asarray(r["prior_frequency_Hz"])
    head = [
        "measured mode",
        "f (Hz)",
        "sigma (Hz)",
        "sigma (%)",
        "computed mode",
        "prior mean (Hz)",
        "diff (%)",
    ] + (["MAC"] if pairing.mac is not None else [])
    rows = []
    for i, (f, s) in enumerate(zip(c.measured.frequency_Hz, c.measured.sigma_Hz, strict=True)):
        row = [i + 1, f"{f:.1f}", f"{s:.1f}", f"{100 * s / f:.2f}"]
        if i in kept:
            j = int(pairing.modes[kept.index(i)])
            row += [j + 1, f"{f_prior[j]:.1f}", f"{100 * (f_prior[j] - f) / f:+.2f}"]
            row += [f"{pairing.mac[i, j]:.2f}"] if pairing.mac is not None else []
        else:
            row += ["unpaired", "", ""] + (
                [f"{pairing.mac[i].max():.2f}"] if pairing.mac is not None else []
            )
        rows.append(row)
    lines = ["### Measured frequencies", "", f"Pairing: {r['describe']}."]
    if pairing.mac is None:
        lines[-1] += " The case has no measured mode shapes, so the pairing is not checked."
    lines += [""] + _table(head, rows) + [""]
    return lines + _image(
        figures,
        "mac",
        "MAC of the measured shapes against the computed "
        "modes at the prior mean; the pairs used are outlined",
    )


def _estimates_section(data, figures):
    r, c = data.results, data.case
    methods = [m for m in ESTIMATORS if m in r]
    head = ["constant", *methods] + (["reference"] if c.reference is not None else [])
    rows = []
    for i, name in enumerate(_NAMES):
        row = [f"{name} ({_UNITS[i]})"]
        row += [_constant(r[m]["constants"], i, r[m]["sd"]) for m in methods]
        rows.append(row + ([_constant(c.reference, i)] if c.reference is not None else []))
    rows += [
        ["iterations", *[r[m]["iterations"] for m in methods]],
        ["converged", *["yes" if r[m]["converged"] else "**no**" for m in methods]],
        ["forward solves", *[r[m]["n_solves"] for m in methods]],
        ["time (s)", *[f"{r[m]['wall_time']:.0f}" for m in methods]],
    ]
    rows = [row + [""] * (len(head) - len(row)) for row in rows]
    lines = [
        "## Estimates",
        "",
        "The paper's estimators from the prior mean: B (eq. 9, the posterior mode), MVE "
        "(eq. 12) and MVE-mod (section 5), with its conventions (`V_Y = diag(dlambda^2)`, "
        "`V_b = diag(dC^2)`). Values are estimate ± first-order standard deviation.",
        "",
        *_table(head, rows),
        "",
    ]
    lines += [f"- {m}: {r[m]['message']}" for m in methods] + [""]
    return (
        lines
        + _residual_table(data)
        + _image(
            figures,
            "residuals",
            "Per-mode residuals at each estimate: (measured - computed) / sigma",
        )
    )


def _residual_table(data):
    r = data.results
    methods = [m for m in ESTIMATORS if m in r]
    pairing = data.pairing()
    kept = pairing.kept(data.case.measured.size)
    sigma = data.case.measured.sigma_Hz[kept]
    head = ["measured mode", "computed mode", "measured (Hz)"]
    for m in methods:
        head += [f"{m} (Hz)", f"(measured - {m}) / sigma"]
    rows = []
    for k, i in enumerate(kept):
        measured = data.case.measured.frequency_Hz[i]
        row = [i + 1, int(pairing.modes[k]) + 1, f"{measured:.1f}"]
        for m in methods:
            f = r[m]["frequency_Hz"][k]
            row += [_num(f, ".1f"), _num((measured - f) / sigma[k], "+.2f")]
        rows.append(row)
    return ["### Per-mode residuals", "", *_table(head, rows), ""]


def _modes_section(data, figures):
    at = _estimate_for_modes(data)
    k = data.results["modes"]["vectors"].shape[1]
    return [
        "## Modes",
        "",
        *_image(
            figures,
            "sensitivities",
            f"Normalised sensitivities (eq. 29) at the {at} "
            "estimate; under each mode number where its energy sits",
        ),
        *_image(
            figures,
            "mode_shapes",
            f"The first {k} elastic mode shapes at the {at} "
            "estimate (w, scaled to max |w| = 1); nodal lines in black",
        ),
    ]


def _posterior_section(data, figures):
    lines = ["## Posterior", ""]
    if "sample" not in data.results:
        if not data.options.sample:
            why = "not requested (--no-sample)"
        elif not sampling_available():
            why = (
                "this version of bayesplate has no `bayesplate.sampling`; the section is "
                "produced when it has"
            )
        else:
            why = "the sampler failed (see the note at the top)"
        return lines + [f"Not sampled: {why}.", ""]
    return (
        lines
        + _sample_lines(data.results["sample"])
        + _image(
            figures,
            "posterior_corner",
            "Posterior draws of the engineering constants; dashed: 3 %, 50 % and 97 % "
            "quantiles; red: the B estimate",
        )
    )


def _sample_lines(result):
    """Posterior intervals and the sampler's diagnostics."""
    rows = []
    for i, name in enumerate(_NAMES):
        lo, hi = result["hdi"][0][i] / _GPA[i], result["hdi"][1][i] / _GPA[i]
        rows.append(
            [
                f"{name} ({_UNITS[i]})",
                _constant(result["mean"], i, result["sd"]),
                f"{lo:#.4g} to {hi:#.4g}",
                f"{result['ess_bulk'][i]:.0f}",
                f"{result['rhat'][i]:.3f}",
            ]
        )
    t = result["timings"]
    return [
        f"emcee, {result['n_walkers']} walkers, {result['n_steps']} steps ({result['n_burn']} "
        f"burn-in), acceptance {result['acceptance']:.2f}: {result['message']}. Fast model: "
        f"{result['certificate'] or 'none (full model)'}; {result['n_full']} full solves while "
        f"sampling; {t.get('total', float('nan')):.0f} s in all.",
        "",
        *[f"- Sampler warning: {w}" for w in result.get("warnings", [])],
        "",
        *_table(["constant", "mean ± sd", "94 % HDI", "ESS (bulk)", "R-hat"], rows),
        "",
    ]


def _diagnose_section(data, figures):
    lines = ["## Model discrepancy (diagnose)", ""]
    if "diagnose" not in data.results:
        return lines + ["Not run (--no-diagnose).", ""]
    d = data.results["diagnose"]["diagnosis"]
    nominal = d["nominal"]
    lines += [
        f"**Verdict: {d['verdict']}**" + (f" ({d['chosen']})" if d["chosen"] else ""),
        "",
        f"- Nominal fit: chi-square {nominal['chi2']:.1f} on {nominal['dof']:.1f} degrees of "
        f"freedom, p = {nominal['p_value']:.3g}",
    ]
    located = d["located"]
    kept = data.pairing().kept(data.case.measured.size)
    if located["modes"]:
        kinds = ", ".join(
            f"{kept[i - 1] + 1} ({located['mode_kinds'][i - 1]})" for i in located["modes"]
        )
        lines.append(f"- Misfit carried by measured modes {kinds}")
    if located["region_mm"] is not None:
        x, y = located["region_mm"]
        lines.append(f"- Located near x = {x:.0f} mm, y = {y:.0f} mm")
    if d["refit"] is not None:
        refit = d["refit"]
        lines.append(
            f"- Refit with {d['chosen']}: chi-square {refit['chi2']:.1f} on "
            f"{refit['dof']:.1f} degrees of freedom, p = {refit['p_value']:.3g}"
        )
    if d["unidentified"]:
        lines.append(
            "- Not identified by the data (the prior dominates): " + ", ".join(d["unidentified"])
        )
    lines += [f"- Note: {n}" for n in d["notes"]] + [""]
    rows = [
        [
            c["physics"],
            f"{c['log_evidence_gain']:+.1f}",
            f"{c['chi2']:.1f}",
            ", ".join(f"{k} = {_short(v)}" for k, v in c["parameters"].items()),
        ]
        for c in d["candidates"]
    ]
    lines += _table(["candidate", "evidence gain (nats)", "chi-square", "parameters"], rows)
    lines.append("")
    for name, caption in (
        ("diagnose_residuals", "Standardised residuals of the nominal fit (and of the refit)"),
        ("diagnose_map_stiffness_loss", "Where a local stiffness loss would explain the misfit"),
        ("diagnose_map_point_mass", "Where a point mass would explain the misfit"),
    ):
        lines += _image(figures, name, caption)
    return lines


def _plies(n):
    return "1 ply" if n == 1 else f"{n} plies"


def _short(value):
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def render_markdown(data, figures):
    """The Markdown text of a report.

    Parameters
    ----------
    data : ReportData
    figures : dict
        Figure name -> file name relative to the report (only figures that exist).

    Returns
    -------
    str
    """
    lines = _header(data) + _case_section(data) + _measured_section(data, figures)
    lines += _estimates_section(data, figures) + _modes_section(data, figures)
    lines += _posterior_section(data, figures) + _diagnose_section(data, figures)
    return "\n".join(lines).rstrip() + "\n"


# ----------------------------------------------------------------------------- writing


def write_report(data, out_dir, progress=None):
    """Draw the figures and write them and ``report.md`` into `out_dir`.

    Each figure is written whole (temporary name, then rename); ``report.md`` last.

    Returns
    -------
    pathlib.Path
        The ``report.md`` written.
    """
    out = pathlib.Path(out_dir)
    say = progress or (lambda line: None)
    figures = {}
    for name, fig in report_figures(data).items():
        save_figure(fig, out / f"{name}.png")
        figures[name] = f"{name}.png"
    say(f"{len(figures)} figures written")
    path = out / "report.md"
    text = render_markdown(data, figures)
    atomic_write_text(path, text)
    return path


def make_report(case_file, out_dir, options=None, progress=None, label=None):
    """Compute (reusing ``out_dir/.cache``) and write the report of one case file.

    Returns
    -------
    (pathlib.Path, ReportData)
        ``report.md`` and the data it shows.
    """
    say = _Progress(progress)
    data = compute_report(case_file, options, pathlib.Path(out_dir) / ".cache", say, label)
    path = write_report(data, out_dir, say)
    say(f"report written: {path}")
    return path, data
