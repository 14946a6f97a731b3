"""studies/coarse_mesh.py: its tasks, its rows and a regression run."""

import pytest

from studies import calibration as cal
from studies import coarse_mesh as cm


def test_clean_runs_both_families_and_an_effect_the_frederiksen_plate():
    clean = cm.tasks("clean", 2)
    assert {t[1] for t in clean} == set(cal.FAMILIES) and len(clean) == 2 * len(cal.FAMILIES)
    (one,) = cm.tasks("cutout:7.5", 1)
    assert one == ("power", "frederiksen_t300", "cutout", "fitted 0.9", 7.5, 0)
    with pytest.raises(ValueError, match="effect = 'hole'"):
        cm.tasks("hole:3", 1)


def test_a_name_without_the_truth_is_wrong_and_a_clean_plate_named_is_too():
    row = {"effect": "cutout", "verdict": "ambiguous", "chosen": "cutout", "rival": "point_mass"}
    assert not cal.misnamed(row)
    assert cal.misnamed({**row, "chosen": "thickness_taper"})
    assert cal.misnamed({"effect": None, "verdict": "explained", "chosen": "point_mass"})
    clean = {"effect": None, "verdict": "ambiguous", "chosen": "cutout", "rival": "point_mass"}
    assert cal.misnamed(clean)
    assert not cal.misnamed({"effect": None, "verdict": "unexplained", "chosen": None})


def test_the_quick_run_diagnoses_on_the_coarser_mesh_and_resumes(tmp_path):
    rows = cm.main("clean", "whole", 0.5, 1, tmp_path, workers=1, quick=True)
    # the quick families' meshes, halved each way: 6 x 3 -> 3 x 2 (at least 2 x 1), 8 x 4 -> 4 x 2
    assert sorted(tuple(r["mesh"]) for r in rows) == [(3, 2), (4, 2)]
    text = (tmp_path / "coarse_mesh.md").read_text()
    assert "| clean | crossply | 4 x 2 | `whole` | 1 |" in text
    again = cm.main("clean", "whole", 0.5, 1, tmp_path, workers=1, quick=True)
    assert again == rows  # from the cache, not diagnosed again
