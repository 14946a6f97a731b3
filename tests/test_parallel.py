"""fork_map: the same results, in order, on one process or several."""

import numpy as np

from bayesplate.discrepancy.parallel import fork_map


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
