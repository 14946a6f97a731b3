"""The pairs' stage: the leading single candidates' pairs in turn, until one explains.

The fits are stand-ins (a gain and a chi-square per pair, set here): what is tested is which
pairs are fitted and which is chosen, not the fitting, which the slow test of
``test_verdict.py`` runs on a real plate.
"""

from dataclasses import dataclass, field
from types import SimpleNamespace

import pytest

from bayesplate.discrepancy.search import two_effects as stage

M = 14  # frequencies: a chi-square of 5 is accepted, 80 rejected at alpha = 0.01


@dataclass
class _Physics:
    name: str

    def settings(self):
        return {}


@dataclass
class _Pair:
    first: _Physics
    second: _Physics

    @property
    def name(self):
        return f"{self.first.name}+{self.second.name}"


@dataclass
class _Fit:
    physics: object
    chi2: float
    refined: bool = True
    effective_parameters: float = 9.0


@dataclass
class _Result:
    name: str
    fit: _Fit
    log_evidence_gain: float


SINGLES = {"stiffness_loss": 565.0, "point_mass": 530.0, "cutout": 513.0, "misalignment": 143.0}


def _singles():
    physics = [_Physics(n) for n in SINGLES]
    ranked = [_Result(p.name, _Fit(p, 400.0), SINGLES[p.name]) for p in physics]
    return physics, ranked


@dataclass(frozen=True)
class _Fitting:
    """The fields of :class:`~bayesplate.discrepancy.search.state.Fitting` the stage reads."""

    say: object
    model: object = None
    scans: dict = field(default_factory=dict)
    margin: float = 1.0
    threshold: float = 3.0


def _run(monkeypatch, pairs_gain_chi2, enough=None):
    """two_effects with stand-in fits; returns (chosen, pairs, names fitted per turn, said)."""
    turns = []

    def pairs_with(leader, physics, ranked, model, scans):
        first = leader.fit.physics
        return [_Pair(first, p) for p in physics if p.name != first.name]

    def rank(physics_list, fitting):
        # ranked by the pairs' bars: over the best single gain (565), not the nominal's
        assert (fitting.margin, fitting.threshold) == (565.0 + 1.0 - 0.2 * 565.0, 568.0)
        turns.append(sorted(frozenset((p.first.name, p.second.name)) for p in physics_list))
        out = []
        for p in physics_list:
            gain, chi2 = pairs_gain_chi2[frozenset((p.first.name, p.second.name))]
            out.append(_Result(p.name, _Fit(p, chi2), gain))
        return sorted(out, key=lambda c: -c.log_evidence_gain)

    monkeypatch.setattr(stage, "pairs_with", pairs_with)
    monkeypatch.setattr(stage, "rank", rank)
    physics, ranked = _singles()
    said = []
    fitting = _Fitting(say=said.append)
    chosen, pairs, stopped = stage.two_effects(
        ranked[0], ranked, physics, fitting, 3.0, 0.01, M, enough=enough
    )
    assert (stopped is not None) == any("not paired" in line for line in said)
    return chosen, pairs, turns, said


def _table(good):
    """Every pair of the singles: gain 600 and rejected, but ``good`` (gain 700, accepted)."""
    names = list(SINGLES)
    table = {frozenset((a, b)): (600.0, 80.0) for a in names for b in names if a != b}
    table[frozenset(good)] = (700.0, 5.0)
    return table


def test_the_best_ones_pairs_alone_when_one_of_them_explains(monkeypatch):
    chosen, pairs, turns, said = _run(monkeypatch, _table(("stiffness_loss", "misalignment")))
    assert len(turns) == 1 and len(pairs) == 3 and said == []
    assert chosen.name == "stiffness_loss+misalignment"


def test_the_runner_ups_pairs_when_none_with_the_best_explains(monkeypatch):
    # the recording of a mass and a misalignment whose best single fit is a stiffness loss
    chosen, pairs, turns, said = _run(monkeypatch, _table(("point_mass", "misalignment")))
    assert len(turns) == 2 and said == [
        "no pair with stiffness_loss explains: point_mass paired as well"
    ]
    # the pair of the two leaders is fitted once, not again in the second turn
    assert frozenset(("stiffness_loss", "point_mass")) not in turns[1]
    assert len(pairs) == 3 + 2
    assert chosen.name == "point_mass+misalignment"


@pytest.mark.parametrize("leaders", [1, 2])
def test_no_more_than_the_leaders_and_none_chosen_when_none_gains(monkeypatch, leaders):
    table = {k: (560.0, 80.0) for k in _table(("point_mass", "cutout"))}  # below the best
    monkeypatch.setattr(stage, "LEADERS", leaders)
    chosen, pairs, turns, _ = _run(monkeypatch, table)
    assert chosen is None and len(turns) == stage.LEADERS


def _unnamed_at(gain, margin=2.0):
    """``enough`` as :mod:`.refit` makes it: an unnamed change gaining `gain` nats."""
    from bayesplate.discrepancy.search.refit import _beaten_by

    return _beaten_by(SimpleNamespace(log_evidence_gain=gain), margin)


def test_a_later_leaders_turn_is_skipped_when_the_unnamed_change_beats_every_fit(monkeypatch):
    # no pair of the best one explains (all rejected at 600); the unnamed change gains 603
    table = _table(("point_mass", "misalignment"))
    chosen, pairs, turns, said = _run(monkeypatch, table, enough=_unnamed_at(603.0))
    assert len(turns) == 1 and len(pairs) == 3
    assert chosen.fit.chi2 == 80.0  # a pair of the best one: its gain, its refit rejected
    assert said == [
        "point_mass not paired: an unnamed local change gains +603.0 nats, more than every "
        "candidate and pair fitted (+600.0) by over 2: the pairs of the next candidates were "
        "not fitted"
    ]


@pytest.mark.parametrize("gain", [601.0, 602.0])
def test_the_later_turn_runs_when_the_unnamed_change_is_not_ahead_by_its_margin(monkeypatch, gain):
    table = _table(("point_mass", "misalignment"))
    chosen, pairs, turns, _ = _run(monkeypatch, table, enough=_unnamed_at(gain))
    assert len(turns) == 2 and chosen.name == "point_mass+misalignment"


def _rough(gain):
    """A candidate's result left on its coarse reduced model, gaining ``gain``."""
    fit = SimpleNamespace(refined=False, rough_optima=[object()], check=None)
    return SimpleNamespace(name="pair", parameters={}, fit=fit, log_evidence_gain=gain, failed="")


def test_pairs_that_cannot_be_chosen_are_left_on_the_coarse_mesh():
    from bayesplate.discrepancy.search import rank

    # the calibration study's fifth edge notch (60 x 30): the stiffness loss gained +6.0
    # alone; its nine pairs' rough gains, of which the best was +5.9 refined
    best = SimpleNamespace(log_evidence_gain=6.0)
    bars = stage.pair_fitting(_Fitting(say=None), best, 3.0)
    assert bars.margin == pytest.approx(6.0 + 1.0 - 0.2 * 6.0) and bars.threshold == 9.0
    notch = [_rough(g) for g in (-1.9, 3.7, 5.3, 1.3, 2.8, 1.3, -1.6, 0.2, 2.1)]
    assert rank._within_reach(notch, bars.margin) == []
    assert rank._rivals(notch, bars.threshold, bars.margin) == []
    # a pair whose rough gain is within the margin of the best single one's is refined
    near = [*notch, _rough(6.5)]
    assert rank._within_reach(near, bars.margin) == [9]
    # against the nominal model's bars, as a single candidate's, six of the nine would be
    assert len(rank._within_reach(notch, 1.0)) == 6
