"""What the subcommands share: the case argument, ``--mesh``, ``--json`` and their reading."""

from __future__ import annotations

import argparse
import math
import pathlib

__all__ = [
    "add_case_argument",
    "add_json_option",
    "add_mesh_option",
    "add_pairing_option",
    "PAIRING_CHOICES",
    "METHOD_CHOICES",
    "MESH_ERROR_CHOICES",
    "CONVENTION_CHOICES",
    "FORWARD_CHOICES",
    "DEFAULT_MAX_ITER",
    "mesh_of",
    "positive_int",
    "positive_float",
    "finite_float",
    "seed_int",
    "MAX_MESH",
    "walker_count",
    "resolve_case",
]


def add_case_argument(p):
    """The positional ``case``: a case file or the name of a bundled case."""
    p.add_argument("case", help="case file (TOML) or the name of a bundled case")


def add_mesh_option(p):
    """``--mesh NX NY``, shared by every command that builds the plate model."""
    p.add_argument(
        "--mesh",
        type=mesh_size,
        nargs=2,
        metavar=("NX", "NY"),
        help="elements along x and y (default: the case's [model] mesh)",
    )


def add_json_option(p):
    """``--json FILE``, shared by every command that writes results."""
    p.add_argument("--json", metavar="FILE", help="write results as JSON ('-' for stdout)")


def positive_int(text):
    """An integer of at least 1 (an argparse type)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a whole number of at least 1")
    return value


#: the sampler's tuning steps (``TUNE_ROUNDS * TUNE_STEPS`` of :mod:`bayesplate.sampling.chain`)
#: and one check of its stopping rule after them: a shorter chain has nothing to report
#: (spelled here so that the parser does not import numpy; tests/test_fuzz_cli.py holds them equal).
MIN_CHAIN_STEPS = 110


def chain_steps(text):
    """A cap on the sampler's steps: a whole number of at least :data:`MIN_CHAIN_STEPS`."""
    value = positive_int(text)
    if value < MIN_CHAIN_STEPS:
        raise argparse.ArgumentTypeError(
            f"{text!r}: must be at least {MIN_CHAIN_STEPS} (the sampler's 90 tuning steps "
            "and 20 to sample)"
        )
    return value


#: :data:`bayesplate.io.checks.MAX_MESH_ELEMENTS`, spelled here so that the parser does not
#: import numpy at start-up (tests/test_fuzz_cli.py holds the two equal).
MAX_MESH = 400


def mesh_size(text):
    """Elements along one side: a whole number from 1 to :data:`MAX_MESH` (an argparse type)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= MAX_MESH:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a whole number from 1 to {MAX_MESH}")
    return value


def finite_float(text):
    """A finite number (an argparse type): refuses nan and inf."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a finite number")
    return value


def positive_float(text):
    """A finite number above 0 (an argparse type)."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a positive number")
    return value


def seed_int(text):
    """A seed: a whole number from 0 to 2^63 - 1 (an argparse type)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a whole number from 0 to 2^63 - 1")
    return value


def walker_count(text):
    """Walkers of emcee: a whole number of at least 12, twice the six constants (argparse type)."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 12:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a whole number of at least 12")
    return value


def mesh_of(args):
    """The ``--mesh`` option as ``(nx, ny)``, or None to use the case's mesh."""
    return tuple(args.mesh) if args.mesh else None


def resolve_case(name_or_path):
    """Load a case from a path, or from the bundled cases by name (``plate1``)."""
    from ..io import bundled_case_names, bundled_case_path, load_case

    if not pathlib.Path(name_or_path).exists() and name_or_path in bundled_case_names():
        name_or_path = bundled_case_path(name_or_path)
    return load_case(name_or_path)


#: The pairings of :data:`bayesplate.matching.pairing.PAIRINGS`, spelled here so that the parser
#: does not import scipy at start-up (a test holds the two equal).
PAIRING_CHOICES = ("auto", "mac", "likelihood", "index", "order")

#: :data:`bayesplate.estimators.METHODS`, the keys of :data:`~bayesplate.estimators.CONVENTIONS`
#: and :data:`~bayesplate.estimators.DEFAULT_MAX_ITER`, spelled here for the same reason
#: (``tests/test_startup.py`` holds them equal).
METHOD_CHOICES = ("B", "MVE", "MVE-mod")
#: :data:`bayesplate.discrepancy.search.mesh_error.MESH_ERROR_PARTS`, the first the default.
MESH_ERROR_CHOICES = ("whole", "unabsorbed", "corrected")
CONVENTION_CHOICES = ("paper", "full-prior", "printed")
#: :data:`bayesplate.io.band.DEFAULT_BAND_MODES`, ``BAND_LOW_FACTOR`` and ``BAND_HIGH_FACTOR``,
#: spelled here so that the parser does not import :mod:`bayesplate.io` at start-up.
DEFAULT_BAND_MODES = 10
BAND_LOW_FACTOR = 0.5
BAND_HIGH_FACTOR = 1.25
FORWARD_CHOICES = ("auto", "fast", "full")
DEFAULT_MAX_ITER = 200


def add_pairing_option(p):
    """``--pairing``: how measured frequencies meet computed modes (estimate, sample, diagnose)."""
    p.add_argument(
        "--pairing",
        choices=PAIRING_CHOICES,
        default="auto",
        help="measured-to-computed modes. 'auto' (default): by shape and frequency ('mac') "
        "when the case has measured shapes, else by the case's mode numbers ('index') if any, "
        "else by order checked: the i-th peak with the i-th computed mode (the paper's "
        "pairing), set aside for 'likelihood' where the most probable assignment at the "
        "answer (each estimate, the sampler's MAP, diagnose's verdict fit) pairs a peak with "
        "another mode; 'order': by order unchecked; 'likelihood': the most probable "
        "assignment by frequency (a computed mode may go unobserved, a peak be spurious), "
        "settled by B; `sample` re-makes it at every point of "
        "the chain (kept as settled with marginalised inputs or an error scale)",
    )
