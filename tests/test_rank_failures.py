"""A candidate whose fit meets a plate that cannot be solved does not end the diagnosis."""

from dataclasses import dataclass

import numpy as np

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
