"""One run layer (issue 38): the command line, batch and the report give the same numbers.

The same options and seed through (a) ``bayesplate estimate`` / ``bayesplate sample`` with
``--json``, (b) the task function a batch runs on a worker (:func:`bayesplate.batch.run_step`,
called here: no Dask cluster) and (c) the report's step functions: the estimate's constants
and deviations, and the posterior's mean and deviation, equal to the last bit. The sampler's
chain bounds are the report's quick ones (32 walkers, 400 steps, ESS 400), which the report
steps do not take as options. Every path runs on one BLAS thread, as a batch's worker does
(threaded reductions move the last bits with the thread count, not with the seed).
"""

import json

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from bayesplate.batch import BatchOptions, run_step
from bayesplate.cli import main
from bayesplate.cli.options import resolve_case
from bayesplate.io import bundled_case_path
from bayesplate.plate.model import PlateModel
from bayesplate.quantities import ENGINEERING_KEYS, to_case_units
from bayesplate.report import ReportOptions, steps
from bayesplate.sampling import CASE_UNITS

CASE = "plate1"
MESH = (8, 4)  # coarse; on 6 x 4 plate 1's B leaves the physical region
SEED = 5
METHOD = "MVE"
CHAIN = {"walkers": 32, "max_steps": 400, "min_ess": 400.0}  # the report's quick chains


def _columns(doc_constants, stat):
    return [doc_constants[key][stat] for key in ENGINEERING_KEYS]


def _cli(tmp_path, argv):
    out = tmp_path / "out.json"
    with threadpool_limits(limits=1):
        status = main([*map(str, argv), "--json", str(out)])
    assert status in (0, 1)
    return json.loads(out.read_text())


def _batch(step, **options):
    path = bundled_case_path(CASE)
    opts = BatchOptions(steps=(step,), mesh=MESH, **options).for_step(step)
    out = run_step(CASE, str(path), path.read_bytes(), step, opts)
    assert out["document"] is not None, out["row"]["reason"]
    return out["document"]


def _report_model():
    case = resolve_case(CASE)
    return case, PlateModel.from_case(case, mesh=MESH)


@pytest.fixture(scope="module")
def estimates(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("estimate")
    argv = ["estimate", CASE, "--mesh", *MESH, "--method", METHOD, "-q"]
    cli = _cli(tmp, argv)["constants"]
    batch = _batch("estimate", method=METHOD)["constants"]
    case, model = _report_model()
    pairing = steps.pairing_step(case, model)
    assert pairing["checked"]  # the report's steps then pair as "auto", as the others
    with threadpool_limits(limits=1):
        report = steps.estimate_step(case, model, METHOD, "auto")
    return cli, batch, report


@pytest.fixture(scope="module")
def posteriors(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sample")
    argv = [
        "sample",
        CASE,
        "--mesh",
        *MESH,
        "--seed",
        SEED,
        "--walkers",
        CHAIN["walkers"],
        "--max-steps",
        CHAIN["max_steps"],
        "--min-ess",
        CHAIN["min_ess"],
    ]
    cli = _cli(tmp, argv)["constants"]
    batch = _batch("sample", seed=SEED, **CHAIN)["constants"]
    case, model = _report_model()
    with threadpool_limits(limits=1):
        report = steps.sample_step(case, model, "auto", ReportOptions(quick=True, seed=SEED))
    return cli, batch, report


def test_the_estimate_is_the_same_through_the_three(estimates):
    cli, batch, report = estimates
    for stat, key in (("mean", "constants"), ("sd", "sd")):
        want = _columns(cli, stat)
        assert _columns(batch, stat) == want, stat
        # case units as the JSON document converts them (to_case_units)
        assert [float(x) for x in to_case_units(report[key])] == want, stat


def test_the_posterior_is_the_same_through_the_three(posteriors):
    cli, batch, report = posteriors
    for stat in ("mean", "sd"):
        want = _columns(cli, stat)
        assert _columns(batch, stat) == want, stat
        # case units as the JSON document converts them (times CASE_UNITS)
        assert [float(x) for x in np.asarray(report[stat]) * CASE_UNITS] == want, stat
    assert np.all(np.isfinite(_columns(cli, "sd")))


def test_one_seed_rule():
    from bayesplate.run import run_seeds
    from bayesplate.sampling.seeding import streams

    seeds = run_seeds(SEED)
    # prepare takes the first child of SeedSequence(seed), as sample() splits it itself
    want = streams(SEED)[1].random(3)
    assert np.array_equal(seeds.prepare.random(3), want)
    assert np.array_equal(seeds.prepare.random(3), want)  # a fresh stream on every access
    assert seeds.chain == SEED
    drawn = run_seeds(None).seed  # no seed: one fresh seed for the whole run
    assert isinstance(drawn, int) and 0 <= drawn < 2**63
    with pytest.raises(TypeError, match="whole number"):
        run_seeds(np.random.default_rng(SEED))
