"""fork_map: the same results, in order, on one process or several."""

import numpy as np

from bayesplate.parallel import fork_map


def test_fork_map_keeps_order_and_closures():
    big = np.arange(1_000_000.0)  # inherited by the workers, never pickled

    def weigh(i):
        return float(big[i::7].sum())

    serial = fork_map(weigh, range(7), workers=1)
    assert (
        fork_map(weigh, range(7), workers=2) == serial == [float(big[i::7].sum()) for i in range(7)]
    )


def test_nested_maps_run_serially_inside_a_worker():
    def inner(i):
        return fork_map(lambda j: i * 10 + j, range(3), workers=2)

    assert fork_map(inner, range(2), workers=2) == [[0, 1, 2], [10, 11, 12]]


def test_full_solves_are_the_same_on_one_process_or_two():
    # the reduced model's snapshots (reduced/basis._solve_many): each solve at one BLAS
    # thread wherever it runs, so forked workers give the serial numbers to the last bit
    from bayesplate import laminate
    from bayesplate.plate.model import PlateModel
    from bayesplate.reduced.basis import _solve_many

    model = PlateModel(0.1, 0.06, 2e-3, 1537.0, [0, 90, 0], mesh=(6, 4))
    b = laminate.stiffness_from_engineering(np.array([113e9, 8.5e9, 0.323, 4.45e9, 4.43e9, 2.97e9]))
    points = [b * s for s in (0.9, 1.0, 1.1)]
    one, two = _solve_many(model, points, 5, workers=1), _solve_many(model, points, 5, workers=2)
    for a, c in zip(one, two, strict=True):
        assert np.array_equal(a.eigenvalues, c.eigenvalues)
        assert np.array_equal(a.vectors, c.vectors)
        assert np.array_equal(a.sensitivities, c.sensitivities)


def _in_a_daemon(queue):
    queue.put(fork_map(lambda i: i * i, range(4), workers=2))


def test_a_daemonic_process_maps_serially():
    # a Dask worker's process is daemonic and may not start children: the map runs in it
    import multiprocessing

    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    worker = context.Process(target=_in_a_daemon, args=(queue,), daemon=True)
    worker.start()
    assert queue.get(timeout=60) == [0, 1, 4, 9]
    worker.join()


def test_a_forked_call_returns_its_result_and_raises_its_error():
    from bayesplate.parallel import Forked

    big = np.arange(100_000.0)  # inherited, not pickled
    with Forked(lambda: float(big.sum())) as beside:
        here = float(big[:10].sum())  # this process goes on meanwhile
        assert beside.result() == float(big.sum()) and here == 45.0

    def fail():
        raise ValueError("no such plate")

    with Forked(fail) as beside:
        try:
            beside.result()
        except ValueError as err:
            assert str(err) == "no such plate"
        else:
            raise AssertionError("the error was not raised in the parent")
