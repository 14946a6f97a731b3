"""The batch engine for any independent tasks: :func:`map_tasks` and :class:`TaskPool`.

The reference is the serial path, the plain ``[fn(item) for item in items]`` in this process
with one BLAS thread (as on the Dask workers, where a different thread count may change the
last bits of an eigen solve): the cluster must give the same results, bit for bit, in the
order of the items, whichever worker ran which task. The study-like task is the concealment
study's shape in small: a plate model built in the task, frequencies with noise from the
task's own stream of one seed, a row of plain data back.
"""

import sys

import cloudpickle
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from bayesplate import PlateModel, bundled_case_path, load_case, stiffness_from_engineering
from bayesplate.batch import TaskPool, map_tasks

SEED = 20261125
N_TASKS = 5

# the workers cannot import this test module: its functions travel by value
cloudpickle.register_pickle_by_value(sys.modules[__name__])


def _study_row(index):
    """One scenario of a study in small: its own noise stream, a model built here."""
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case, mesh=(6, 4))
    rng = np.random.default_rng(np.random.SeedSequence(SEED).spawn(index + 1)[index])
    f = model.solve(stiffness_from_engineering(case.reference), 6).frequency_Hz
    noisy = f * (1 + 0.002 * rng.standard_normal(f.size))
    return {"index": index, "f_Hz": noisy.tolist(), "mean_Hz": float(noisy.mean())}


@pytest.fixture(scope="module")
def client():
    """A client of a local cluster of 2 single-threaded workers, given to the engine.

    Started with Dask's own settings, as a user's cluster would be, not through the
    engine's ``_client``: the tests below pass it as a client given by the caller.
    """
    from distributed import Client, LocalCluster

    from bayesplate.batch.run import _ONE_THREAD

    with (
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env=_ONE_THREAD,
        ) as cluster,
        Client(cluster) as given,
    ):
        yield given


def _fails(index):
    if index == 2:
        raise ValueError(f"task {index} fails")
    return index


def test_the_same_rows_with_one_and_two_workers():
    items = list(range(N_TASKS))
    with threadpool_limits(limits=1):
        serial = [_study_row(i) for i in items]
        one = map_tasks(_study_row, items, workers=1, progress=False)
    seen, lines = {}, []
    two = map_tasks(_study_row, items, workers=2, progress=lines.append, on_result=seen.__setitem__)
    assert one == serial
    assert two == serial  # bit for bit, in the order of the items
    assert seen == dict(enumerate(serial))  # each row handed over once, as it came
    assert "2 workers" in lines[0] and len(lines) == 1 + N_TASKS
    # the noise streams differ between tasks: the order is not trivially right
    assert len({r["mean_Hz"] for r in two}) == N_TASKS


def test_a_failing_task_raises_its_error_on_both_paths(client):
    with pytest.raises(ValueError, match="task 2 fails"):
        map_tasks(_fails, range(4), workers=1, progress=False)
    with pytest.raises(ValueError, match="task 2 fails"):
        map_tasks(_fails, range(4), scheduler=client, progress=False)
    assert map_tasks(_fails, [0, 1, 3], scheduler=client, progress=False) == [0, 1, 3]


def test_no_items_start_no_cluster():
    assert map_tasks(_fails, [], workers=2, progress=False) == []


# a 40-step chain is too short for emcee's and arviz's diagnostics: they warn, rightly
@pytest.mark.filterwarnings("ignore:More chains:UserWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered in divide:RuntimeWarning")
def test_task_pool_is_a_map_for_the_sampler(client):
    from bayesplate.likelihood.posterior import GaussianProblem, prior_in_stiffness
    from bayesplate.matching.pairing import Pairing
    from bayesplate.sampling import sample_problem

    # g(b) = A b: a problem cheap to evaluate, its log-density a closure shipped to workers
    rng = np.random.default_rng(SEED)
    e0 = np.array([150e9, 10e9, 0.25, 3e9, 3e9, 2e9])
    mu, V_b = prior_in_stiffness(e0, e0 / 6, "full")
    A = rng.uniform(0.2, 2.0, size=(8, 6)) * 1e7 / mu[None, :]
    Y = A @ (mu * rng.uniform(0.9, 1.1, 6))
    V_Y = np.diag((0.01 * Y) ** 2)

    class Linear:
        def __init__(self, b):
            self.eigenvalues, self.sensitivities = A @ b, A

    pairing = Pairing(np.arange(8), extra=0)
    problem = GaussianProblem(Y, V_Y, mu, V_b, lambda b, n: Linear(b), pairing)
    P = np.linalg.inv(A.T @ np.linalg.solve(V_Y, A) + np.linalg.inv(V_b))
    kwargs = {
        "progress": False,
        "max_steps": 40,
        "min_ess": np.inf,
        "rng": 4,
        "tune_rounds": 1,
        "tune_steps": 10,
        "check_every": 20,
    }
    plain = sample_problem(problem, mu, P, **kwargs)
    with TaskPool(scheduler=client) as pool:
        assert pool.map(abs, [-1, 2, -3]) == [1, 2, 3]
        pooled = sample_problem(problem, mu, P, pool=pool, **kwargs)
    np.testing.assert_array_equal(plain.chain, pooled.chain)
    assert client.status == "running"  # a client given is the caller's to close
    with pytest.raises(RuntimeError, match="outside its `with` block"):
        pool.map(abs, [1])


@pytest.mark.filterwarnings("ignore:More chains:UserWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered in divide:RuntimeWarning")
def test_sample_command_on_dask_workers_gives_the_same_chain(client, tmp_path, capsys):
    import json

    from bayesplate.cli.main import main

    chain = [
        "plate1",
        "--mesh",
        "6",
        "4",
        "--seed",
        "5",
        "--walkers",
        "12",
        "--max-steps",
        "200",
        "--min-ess",
        "1e9",
    ]
    plain, pooled = tmp_path / "plain.json", tmp_path / "pooled.json"
    with threadpool_limits(limits=1):  # as on the workers
        main(["sample", *chain, "--json", str(plain)])
    address = client.scheduler.address
    main(["sample", *chain, "--scheduler", address, "--json", str(pooled)])
    want, got = (json.loads(p.read_text()) for p in (plain, pooled))
    for doc in (want, got):
        doc.pop("timings_s", None)
        doc.pop("n_evaluations", None)  # counted in this process only: 0 on the workers
    # the same chain to round-off: a worker's OpenBLAS starts with one thread
    # (OPENBLAS_NUM_THREADS=1) where this process is limited to one by threadpoolctl, and
    # the two pick kernels that sum in another order (1e-13 relative measured with numpy
    # 2.4 / OpenBLAS 0.3.31; this process with and without the limit differ by as much)
    for key, value in want["constants"].items():
        for stat, number in value.items():
            assert got["constants"][key][stat] == pytest.approx(number, rel=1e-9), (key, stat)
    assert got["constants"]["E1_GPa"]["mean"] > 0
    assert client.status == "running"  # a cluster reached by address is not shut down
    capsys.readouterr()


def _logs_errors():
    """Whether this worker's Dask records of an error (a heartbeat's traceback) are written."""
    import logging

    return logging.getLogger("distributed.worker").isEnabledFor(logging.ERROR)


def test_the_workers_of_a_cluster_started_here_keep_dask_records_off(client):
    """A stopped batch's workers log a heartbeat traceback: none reaches the command line.

    The control is the workers of a scheduler given (their owner's to configure): they
    write their records of an error.
    """
    from bayesplate.batch.run import _client

    assert all(client.run(_logs_errors).values())
    with _client(None, 2) as started:
        said = started.run(_logs_errors)  # {worker address: writes its error records}
    assert len(said) == 2 and not any(said.values())


def _malloc_trim():
    import os

    return os.environ.get("MALLOC_TRIM_THRESHOLD_")


def test_the_workers_of_a_cluster_started_here_keep_glibcs_mmap_threshold(client, monkeypatch):
    """Dask's ``MALLOC_TRIM_THRESHOLD_`` fixes glibc's mmap threshold, and a diagnosis on a
    worker then spends a third of its time mapping and unmapping its arrays: the workers
    started here go without it. The control: the given cluster's workers (Dask's defaults)
    carry it."""
    from bayesplate.batch.run import _client

    assert set(client.run(_malloc_trim).values()) == {"65536"}
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    with _client(None, 1) as started:
        assert list(started.run(_malloc_trim).values()) == [None]
