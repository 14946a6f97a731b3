"""Running a report's steps in order, each through the cache, with progress lines.

:func:`compute_report` is the computation of a report (no drawing, no writing besides the
cache): pairing, the estimators, modes, then optionally the posterior and diagnose.
"""

from __future__ import annotations

import pathlib
import time

import numpy as np

from ..io import load_case
from ..matching.pairing import MAC_EXTRA_MODES
from ..parallel import Forked, available_cores
from . import steps
from .cache import StepCache
from .data import ESTIMATORS, ReportData, _b_at, _estimate_for_modes, sampling_available
from .options import ReportOptions
from .progress import _logs_shown, _Progress

__all__ = ["compute_report"]

#: Subfolder of the cache where diagnose keeps its stages (a killed report resumes inside it).
DIAGNOSE_STAGES = "diagnose-stages"


def compute_report(case_file, options=None, cache_dir=None, progress=None, label=None, taps=None):
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
    taps : TapTest, optional
        The tap test the case was imported from: shown in the report.

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
        taps=taps,
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
        if options.sample and options.diagnose:
            run.sample_beside_diagnose()
        elif options.sample:
            run.sample()
        elif options.diagnose:
            run.diagnose()
    say("all steps done")
    return data


class _Runner:
    """Runs the steps of one report, each through the cache, with progress lines."""

    def __init__(self, data, cache, say):
        self.data, self.cache, self.say = data, cache, say
        self.case, self.options = data.case, data.options
        self.pairing_options = {"extra": MAC_EXTRA_MODES}
        if data.options.pairing != "auto":  # (the default keeps the caches' keys)
            self.pairing_options["how"] = data.options.pairing

    def _keyed(self, options):
        """A step's options as its cache entry is keyed: the working mesh added."""
        return {"mesh": self.data.mesh, **options}

    def step(self, name, title, options, compute, optional=False):
        """``compute()`` or its cached result; an optional step may fail (noted)."""
        self.say(f"{title} ...")
        started = time.perf_counter()
        try:
            with self.say.heartbeat(title):
                result, reused = self.cache.get(name, self._keyed(options), compute)
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
            lambda: steps.pairing_step(
                self.case, self.data.plate_model(), self.data.options.pairing
            ),
        )
        for message in result["warnings"]:
            self.say(f"warning: {message}")
            self.data.notes.append(message)

    def estimate(self, method):
        self.step(
            method,
            f"estimate {method}",
            {"pairing": self.pairing_options},
            lambda: steps.estimate_step(
                self.case,
                self.data.plate_model(),
                method,
                self.data.pairing_for_steps(),
                self.data.fast_model(),
            ),
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
            lambda: steps.modes_step(self.case, data.plate_model(), b, n, self.options.n_shapes),
        )

    def _sample_options(self):
        return {
            "seed": self.options.seed,
            "quick": self.options.quick,
            "pairing": self.pairing_options,
        }

    def _sample(self):
        return steps.sample_step(
            self.case,
            self.data.plate_model(),
            self.data.pairing_for_steps(),
            self.options,
            self.data.fast_model(),
        )

    def sample(self, compute=None, title="posterior sampling"):
        if not sampling_available():
            self.say("posterior sampling: not in this version of bayesplate (section left out)")
            return
        self.step("sample", title, self._sample_options(), compute or self._sample, optional=True)

    def sample_beside_diagnose(self):
        """The sampler in a forked process while diagnose runs in this one.

        Both are long and independent (the sampler runs on the fast model B built, diagnose
        on the full model); on two cores side by side they take about the longer one's time
        (diagnose's own workers share the cores with the sampler). The results are those of
        the two run in turn: the sampler's numbers depend only on its seed. One core, a
        cached posterior, or no sampler: in turn.
        """
        cached = self.cache.load("sample", self._keyed(self._sample_options()))
        if not sampling_available() or cached is not None or available_cores() < 2:
            self.sample()
            self.diagnose()
            return
        self.data.fast_model()  # built here (its progress lines, its time): the child inherits it

        def timed():
            started = time.perf_counter()
            return self._sample(), time.perf_counter() - started

        self.say("posterior sampling: started beside diagnose")
        with Forked(timed) as beside:
            self.diagnose()
            took = {}

            def wait():
                result, took["seconds"] = beside.result()
                return result

            self.sample(compute=wait, title="posterior sampling (beside diagnose)")
        if "seconds" in took and "sample" in self.data.seconds:
            self.data.seconds["sample"] = took["seconds"]  # its own time, not the wait
            self.say(f"posterior sampling took {took['seconds']:.1f} s beside diagnose")

    def diagnose(self):
        from ..io.stage_store import DirectoryStore

        folder = self.cache.directory
        store = None if folder is None else DirectoryStore(folder / DIAGNOSE_STAGES)
        self.step(
            "diagnose",
            "diagnose model discrepancy",
            {
                "seed": self.options.seed,
                "n_starts": self.options.n_starts,
                "pairing": self.pairing_options,
            },
            lambda: steps.diagnose_step(
                self.case,
                self.data.plate_model(),
                self.data.pairing_for_steps(),
                self.options,
                self.say,
                store,
            ),
        )
