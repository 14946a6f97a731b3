"""studies/mesh_error_rule.py: which replicates it runs again and how it pairs the rows."""

from studies import mesh_error_rule as mer


def _row(key, kind, family, effect, verdict, chosen=None, p=0.5, widening=(1.0, 1.2)):
    return {
        "key": key,
        "kind": kind,
        "family": family,
        "effect": effect,
        "size": 0.17,
        "verdict": verdict,
        "chosen": chosen,
        "rival": None,
        "also": [],
        "p_value": p,
        "widening": list(widening),
    }


def test_every_clean_replicate_and_the_fitted_size_of_every_candidate_are_run_again():
    table = {
        # in the order of the calibration study's SIZES: fitted 0.9, 3 x ideal, ideal 0.9, 0.5
        "point_mass": {"sizes": [0.17, 0.42, 0.14, 0.11]},
        "cutout": {"sizes": [6.2, 13.0, None, 3.7]},
    }
    tasks = mer.selected(table)
    clean = [t for t in tasks if t[0] == "clean"]
    power = [t for t in tasks if t[0] == "power"]
    assert len(clean) == 40 and {t[1] for t in clean} == {"frederiksen_t300", "crossply"}
    assert {t[3] for t in power} == {"fitted 0.9"} and len(power) == 20
    assert {(t[2], t[4]) for t in power} == {("point_mass", 0.17), ("cutout", 6.2)}


def test_rows_are_paired_by_replicate_and_counted_on_both_sides():
    rule = {
        "clean/crossply/0": _row(
            "clean/crossply/0", "clean", "crossply", None, "explained", "cutout", p=0.004
        ),
        "clean/crossply/1": _row("clean/crossply/1", "clean", "crossply", None, "consistent"),
        "power/f/point_mass/0.17/0": _row(
            "power/f/point_mass/0.17/0", "power", "f", "point_mass", "explained", "point_mass"
        ),
        "power/f/point_mass/0.17/1": _row(
            "power/f/point_mass/0.17/1", "power", "f", "point_mass", "explained", "cutout"
        ),
        "power/f/point_mass/0.17/2": _row(
            "power/f/point_mass/0.17/2", "power", "f", "point_mass", "explained", "point_mass"
        ),
    }
    base = {
        k: {**r, "verdict": "consistent", "chosen": None, "widening": [1.3, 1.5]}
        for k, r in rule.items()
        if not k.endswith("/2")
    }
    table = mer.summary(rule, base)
    assert set(table) == {"clean/crossply", "power/point_mass"}
    clean, power = table["clean/crossply"], table["power/point_mass"]
    assert clean["n"] == 2 and clean["rule"]["alarms"] == 1 and clean["default"]["alarms"] == 0
    assert clean["rule"]["nominal_rejected"] == 1
    assert power["n"] == 2  # the third replicate has no row of the default rule: not counted
    assert power["rule"]["named"] == 1 and power["rule"]["wrong"] == 1
    assert power["default"]["named"] == 0 and power["default"]["wrong"] == 0
    assert power["rule"]["widening"] == "1.10" and power["default"]["widening"] == "1.40"
