"""A candidate whose fit meets a plate that cannot be solved does not end the diagnosis; a
phase chained to the one before in the same task gives the results of the two in turn."""

from dataclasses import dataclass

import numpy as np
import pytest

from bayesplate.discrepancy.search.phases import run_phase as _phase
from bayesplate.discrepancy.search.rank import CandidateResult


class _Physics:
    def __init__(self, name):
        self.name = name

    def settings(self):
        return {}


@dataclass(frozen=True)
class _Fit:
    refined: bool
    physics: object = None


def _result(name, refined):
    return CandidateResult(name, _Fit(refined), 1.0, {}, {}, [])


def _compute(item):
    physics = item[0] if isinstance(item, tuple) else item
    if physics.name == "bad":
        raise np.linalg.LinAlgError("the leading minor of order 89 of B is not positive definite")
    return _result(physics.name, refined=isinstance(item, tuple))


def test_a_failed_first_phase_leaves_the_candidate_out_and_says_so():
    physics = [_Physics("good"), _Physics("bad")]
    results, hits, said = [None, None], [[], []], []
    _phase(
        None,
        "rough",
        _compute,
        [(0, physics[0], None), (1, physics[1], None)],
        results,
        hits,
        1,
        said.append,
    )
    assert results[0].name == "good" and results[1] is None
    assert said == [
        "bad: its rough fit failed (LinAlgError: the leading minor of order 89 of B "
        "is not positive definite); left out"
    ]


def test_a_failed_later_phase_keeps_the_phase_before_marked_failed():
    physics = [_Physics("good"), _Physics("bad")]
    rough = [_result("good", False), _result("bad", False)]
    results, hits, said = list(rough), [[], []], []
    items = [(i, p, r.fit) for i, (p, r) in enumerate(zip(physics, rough, strict=True))]
    _phase(None, "settled", _compute, items, results, hits, 1, said.append)
    assert results[0].fit.refined and not results[0].failed
    assert results[1].fit is rough[1].fit
    assert results[1].failed.startswith("its settled fit failed (LinAlgError")
    assert results[1].failed.endswith("; the phase before kept") and len(said) == 1


def _refined_later(item):
    """A later phase's result: refined, named after the candidate, its rough fit seen."""
    physics, earlier = item
    if physics.name == "bad later":
        raise np.linalg.LinAlgError("Matrix is singular")
    assert not earlier.refined and earlier.physics is physics  # the parent's own object
    return _result(physics.name, refined=True)


def _rough(item):
    if item.name == "bad":
        raise np.linalg.LinAlgError("the leading minor of order 89 of B is not positive definite")
    return CandidateResult(
        item.name,
        _Fit(False, physics=_Physics("a worker's copy")),
        2.0 if item.name != "weak" else -1.0,
        {},
        {},
        [],
    )


@pytest.mark.parametrize("workers", [1, 2])
def test_a_next_phase_in_the_same_task_is_the_two_phases_one_after_the_other(workers):
    names = ["strong", "weak", "bad", "bad later"]
    physics = [_Physics(n) for n in names]
    items = [(i, p, None) for i, p in enumerate(physics)]
    wanted = lambda r: r.log_evidence_gain > 0  # noqa: E731
    # the next phase chained in the task
    chained, chained_hits, chained_said = [None] * 4, [[] for _ in names], []
    _phase(
        None,
        "rough",
        _rough,
        items,
        chained,
        chained_hits,
        workers,
        chained_said.append,
        then=("settled", _refined_later, wanted),
    )
    # the two phases one after the other, the second on the items the first wanted
    apart, apart_hits, apart_said = [None] * 4, [[] for _ in names], []
    _phase(None, "rough", _rough, items, apart, apart_hits, workers, apart_said.append)
    todo = [(i, physics[i], r.fit) for i, r in enumerate(apart) if r is not None and wanted(r)]
    _phase(None, "settled", _refined_later, todo, apart, apart_hits, workers, apart_said.append)

    assert [r and (r.name, r.fit.refined, r.failed) for r in chained] == [
        ("strong", True, ""),
        ("weak", False, ""),  # not wanted: its rough fit stays
        None,  # its first phase failed: left out, no second phase
        (
            "bad later",
            False,
            "its settled fit failed (LinAlgError: Matrix is singular); the phase before kept",
        ),
    ]
    assert [r and (r.name, r.fit.refined, r.failed) for r in apart] == [
        r and (r.name, r.fit.refined, r.failed) for r in chained
    ]
    assert all(r is None or r.fit.physics is p for r, p in zip(chained, physics, strict=True))
    assert sorted(chained_said) == sorted(apart_said) and len(chained_said) == 2
