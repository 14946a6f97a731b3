"""diagnose's stage store: the on-disk store's files, the keys, and resumed diagnoses.

A resumed diagnosis is compared with an uninterrupted one bit for bit (its JSON document):
the same seed makes the same arithmetic in the same order, so no tolerance is needed. The
diagnosis is a small one that goes through every kind of stage: two effects are concealed
(a point mass and an elastic foundation) on the mesh diagnose uses, so the best single
candidate's refit is rejected and the pairs are fitted too.
"""

import json
import pickle
import shutil

import numpy as np
import pytest
from test_diagnose import _plate1_case

from bayesplate import PlateModel, stiffness_from_engineering
from bayesplate.discrepancy import ElasticFoundation, PointMass, ThicknessTaper
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.discrepancy.physics.combined import Pair
from bayesplate.discrepancy.search.store import MemoryStore, digest
from bayesplate.io import diagnosis_to_dict, jsonable
from bayesplate.io.stage_store import DirectoryStore

MESH = (6, 3)


def _physics():
    return [PointMass(), ElasticFoundation()]


@pytest.fixture(scope="module")
def setting():
    """(recordings, model): a 20 g mass and a foundation concealed on the 6 x 3 mesh."""
    case = _plate1_case()
    model = PlateModel.from_case(case, mesh=MESH)
    b = stiffness_from_engineering(case.reference)
    pair = Pair(PointMass(), ElasticFoundation(), b)
    k_sd = pair.parameters(model, b)[-1].sd
    plate = pair.apply(model, np.array([20.0, 50.0, 30.0, 3.0 * k_sd]))
    f = plate.solve(b, 14).frequency_Hz
    f = f * (1 + 0.002 * np.random.default_rng(3).standard_normal(f.size))
    return case.with_measured(frequency_Hz=f, sigma_Hz=0.002 * f), model


def _run(setting, store=None, workers=1, rng=0, say=None):
    case, model = setting
    d = diagnose(
        case,
        model=model,
        physics=_physics(),
        rng=rng,
        n_starts=4,
        workers=workers,
        mesh_error_ratio=np.inf,
        store=store,
        progress=say or (lambda message: None),
    )
    return json.dumps(diagnosis_to_dict(d), default=jsonable, sort_keys=True), d


@pytest.fixture(scope="module")
def reference(setting):
    """The uninterrupted diagnosis without a store, one process."""
    text, d = _run(setting)
    assert any("+" in c.name for c in d.candidates)  # the pairs were fitted
    return text


# ----------------------------------------------------------------------------- the store


def test_directory_store_round_trip_and_atomic_write(tmp_path, monkeypatch):
    store = DirectoryStore(tmp_path / "s")
    assert store.get("abc1") is None and store.misses == 1
    store.put("abc1", {"x": np.arange(3.0), "n": None})
    got = store.get("abc1")
    assert np.array_equal(got["x"], np.arange(3.0)) and got["n"] is None and store.hits == 1
    # a write interrupted before its rename (as a kill would) leaves the previous file whole
    # and no temporary file behind
    import bayesplate.io.files as export  # where the atomic writers live

    def killed(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(export.os, "replace", killed)
    with pytest.raises(KeyboardInterrupt):
        store.put("abc1", {"x": np.zeros(3)})
    monkeypatch.undo()
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["abc1.pkl"]
    assert np.array_equal(store.get("abc1")["x"], np.arange(3.0))
    with pytest.raises(ValueError):  # a key is a digest, never a path
        store.path("../escape")


def test_corrupt_or_foreign_files_are_ignored(tmp_path):
    store = DirectoryStore(tmp_path)
    store.put("good", [1.0, 2.0])
    blob = (tmp_path / "good.pkl").read_bytes()
    (tmp_path / "cut.pkl").write_bytes(blob[: len(blob) // 2])  # truncated
    (tmp_path / "junk.pkl").write_bytes(b"\x00not a pickle at all")
    (tmp_path / "other.pkl").write_bytes(blob)  # whole, but stored under another key
    (tmp_path / "plain.pkl").write_bytes(pickle.dumps([1.0, 2.0]))  # not written by the store
    for key in ("cut", "junk", "other", "plain"):
        assert store.get(key) is None
    assert store.ignored == 4 and store.hits == 0
    assert store.get("good") == [1.0, 2.0]
    store.put("cut", "again")  # a stage computed again overwrites the bad file
    assert store.get("cut") == "again"


def test_keys_cover_exact_values_variants_and_state():
    base = digest(np.array([1.0, 2.0]), {"b": 1, "a": 2.5}, ThicknessTaper("x"))
    assert base == digest(np.array([1.0, 2.0]), {"a": 2.5, "b": 1}, ThicknessTaper("x"))
    assert base != digest(
        np.array([1.0, np.nextafter(2.0, 3.0)]), {"b": 1, "a": 2.5}, ThicknessTaper("x")
    )
    assert base != digest(np.array([1.0, 2.0]), {"b": 1, "a": 2.5}, ThicknessTaper("y"))
    assert base != digest(
        np.array([1.0, 2.0], dtype=np.float32), {"b": 1, "a": 2.5}, ThicknessTaper("x")
    )
    # what has no stable content is never taken for something else
    assert digest(lambda: 1) != digest(lambda: 2)
    one, two = np.random.default_rng(1), np.random.default_rng(1)
    two.standard_normal()
    assert digest(one.bit_generator.state) != digest(two.bit_generator.state)


# ----------------------------------------------------------------------------- diagnose


def test_a_store_changes_no_number_and_a_full_store_computes_nothing(setting, reference):
    store = MemoryStore()
    first, _ = _run(setting, store)
    assert first == reference
    # the nominal fit; each candidate's rough fit (2) and the mass's settled fit (the
    # foundation, +314 on its coarse model against the mass's +1,169, is out of reach); the
    # nominal refit from the candidates' constants; the best single's constants searched
    # again (its refit is rejected: two effects are concealed); the pair's rough and settled
    # fits
    stages = store.puts
    assert stages == 8 and store.hits == 0
    said = []
    again, _ = _run(setting, store, say=said.append)
    assert again == reference
    assert store.hits == stages and store.puts == stages
    # each stage used announced, on its result's line: the nominal fit, the refit, each
    # candidate, the search again and the pair (6 lines, 8 stages)
    assert sum("taken from the store" in line for line in said) == 6
    assert sum(line.count("taken from the store") for line in said) == stages


def test_workers_with_a_directory_store_and_a_resume_from_part_of_it(setting, reference, tmp_path):
    # two forked workers store the candidates' fits themselves: the parent sees them all
    store = DirectoryStore(tmp_path / "all")
    uninterrupted = np.random.default_rng(0)
    two, _ = _run(setting, store, workers=2, rng=uninterrupted)
    assert two == reference
    files = sorted((tmp_path / "all").glob("*.pkl"), key=lambda p: p.stat().st_mtime_ns)
    assert len(files) == 8 and not list((tmp_path / "all").glob(".*.tmp"))
    # as a kill would leave it: the last stage (the pair's) not stored, a candidate's file cut
    # short (the nominal fit, first, stays)
    part = tmp_path / "part"
    shutil.copytree(tmp_path / "all", part)
    (part / files[-1].name).unlink()
    (part / files[1].name).write_bytes(files[1].read_bytes()[:100])
    resumed = DirectoryStore(part)
    rng = np.random.default_rng(0)
    text, _ = _run(setting, resumed, rng=rng)
    assert text == reference
    assert resumed.hits == 6 and resumed.ignored == 1 and resumed.puts == 2
    # the generator ends where the uninterrupted run left it (the nominal stage's state)
    assert rng.bit_generator.state == uninterrupted.bit_generator.state
    assert len(list(part.glob("*.pkl"))) == 8
