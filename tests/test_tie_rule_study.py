"""The tie rule's replay (``studies/tie_rule.py``) on constructed rows and the cached ones."""

import pathlib

import numpy as np

from studies import tie_rule

REPORTS = pathlib.Path(__file__).resolve().parents[1] / "reports"


def _row(effect, chosen, rival, gains, chi2):
    """A power row as the calibration caches it (probabilities from the gains, nominal 0)."""
    w = {"nominal": 1.0, **{n: float(np.exp(g)) for n, g in gains.items()}}
    total = sum(w.values())
    return {
        "key": f"power/{effect}",
        "kind": "power",
        "effect": effect,
        "verdict": "ambiguous" if rival else "explained",
        "chosen": chosen,
        "rival": rival,
        "also": [],
        "gains": gains,
        "chi2": chi2,
        "probabilities": {n: v / total for n, v in w.items()},
    }


def test_a_rival_tied_by_odds_alone_is_dropped_and_a_lost_truth_counted():
    # the slot's numbers: the taper within 1.1 nats of odds, 3.8 nats worse in fit
    slot = _row(
        "local_stiffness_loss",
        "local_stiffness_loss",
        "point_mass",
        {"local_stiffness_loss": 10.05, "point_mass": 9.0},
        {"local_stiffness_loss": 3.32, "point_mass": 10.98},
    )
    assert tie_rule.named_again(slot) == ["local_stiffness_loss"]
    # the same row with the rival the truth: its name is lost, and counted
    wrong = {**slot, "effect": "point_mass", "key": "power/lost"}
    counts, lost = tie_rule.replay([slot, wrong])
    assert lost == ["power/lost"]
    assert (counts["ambiguous_before"], counts["ambiguous_after"]) == (2, 0)
    assert (counts["right_before"], counts["right_after"]) == (2, 1)
    # a rival fitting as well stays; a taper (two variants, one stored) is kept undecided
    close = {**slot, "chi2": {"local_stiffness_loss": 3.32, "point_mass": 7.0}}
    assert tie_rule.named_again(close) == ["local_stiffness_loss", "point_mass"]
    taper = _row(
        "local_stiffness_loss",
        "local_stiffness_loss",
        "thickness_taper",
        {"local_stiffness_loss": 10.05, "thickness_taper": 9.0},
        {"local_stiffness_loss": 3.32, "thickness_taper": 10.98},
    )
    assert tie_rule.named_again(taper) == ["local_stiffness_loss", "thickness_taper"]


def test_the_cached_calibrations_lose_no_true_name():
    """The claim of ``reports/tie_rule.md``, on the committed caches."""
    for _, path in tie_rule.CACHES:
        counts, lost = tie_rule.replay(tie_rule.rows(REPORTS / path))
        assert counts["named"] > 40 and lost == []
        assert counts["ambiguous_after"] <= counts["ambiguous_before"]
