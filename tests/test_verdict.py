"""Model probabilities, the ``ambiguous`` verdict and two effects at once (issue 13).

References: the closed form of Bayes' rule for two models (a logistic function of the
log-evidence difference); exact equivalences of composed plates (an effect at zero size is
no effect, two masses at one point are one mass of their sum, a mass and a foundation
touch different matrices); the plate's mirror symmetry (mirror images of a fitted effect
have equal frequencies). Recordings for the diagnoses are made on a mesh twice as fine
with 0.2 % noise, as in tests/test_diagnose.py.
"""

import numpy as np
import pytest
from scipy.special import expit
from test_diagnose import MESH, NOISE, _plate1_case, _recordings

from bayesplate import PlateModel, stiffness_from_engineering
from bayesplate.cli.diagnose import diagnosis_text
from bayesplate.discrepancy import ElasticFoundation, PointMass, ThicknessTaper
from bayesplate.discrepancy.diagnose import diagnose
from bayesplate.discrepancy.physics.base import mirror_positions
from bayesplate.discrepancy.physics.combined import Pair, pairs_with
from bayesplate.discrepancy.physics.reduced_model import candidate_pencil
from bayesplate.discrepancy.search.probabilities import NOMINAL, model_probabilities
from bayesplate.discrepancy.search.separation import separate
from bayesplate.discrepancy.search.verdict import runner_up, tie_text, ties, verdict
from bayesplate.io import diagnosis_to_dict

N_MODES = 12


@pytest.fixture(scope="module")
def model():
    return PlateModel.from_case(_plate1_case(), mesh=MESH)


@pytest.fixture(scope="module")
def b():
    return stiffness_from_engineering(_plate1_case().reference)


# --- probabilities ---------------------------------------------------------------------


def test_probabilities_sum_to_one_and_ignore_a_common_constant(rng):
    names = ["point_mass", "thickness_taper", "thickness_taper", "ply_misalignment"]
    log_z = rng.normal(0.0, 5.0, len(names))
    p = model_probabilities(list(zip(names, log_z, strict=True)), nominal=1.5)
    assert set(p) == {NOMINAL, "point_mass", "thickness_taper", "ply_misalignment"}
    assert sum(p.values()) == pytest.approx(1.0, abs=1e-14)
    # log-evidences of thousands of nats (exp would overflow): only differences count
    shift = 5e3
    q = model_probabilities(list(zip(names, log_z + shift, strict=True)), nominal=1.5 + shift)
    for k in p:  # rounding of log_z + 5e3 is ~1e-12 nats: probabilities agree to 1e-10
        assert q[k] == pytest.approx(p[k], rel=1e-10, abs=1e-300)
    huge = model_probabilities([("point_mass", 800.0)])  # exp(800) overflows a float
    assert huge["point_mass"] == 1.0 and 0.0 <= huge[NOMINAL] < 1e-300


def test_two_models_follow_bayes_rule_in_closed_form():
    for gain in (-3.0, 0.0, 2.0, 7.5):
        p = model_probabilities([("point_mass", gain)])
        # P(candidate) = e^g / (1 + e^g): the logistic function of the evidence gain
        assert p["point_mass"] == pytest.approx(expit(gain), rel=1e-13)
        assert p[NOMINAL] == pytest.approx(expit(-gain), rel=1e-13)
        odds = 0.25
        q = model_probabilities([("point_mass", gain)], prior_odds={"point_mass": odds})
        assert q["point_mass"] == pytest.approx(expit(gain + np.log(odds)), rel=1e-13)


def test_variants_share_their_candidate_prior_and_are_summed():
    # a taper along x and along y is one candidate whose direction has a uniform prior:
    # P(taper) = (e^g1 + e^g2) / 2 / (1 + (e^g1 + e^g2) / 2 + e^g3)
    g1, g2, g3 = 2.0, -1.0, 1.0
    p = model_probabilities([("thickness_taper", g1), ("thickness_taper", g2), ("pm", g3)])
    taper = 0.5 * (np.exp(g1) + np.exp(g2))
    total = 1.0 + taper + np.exp(g3)
    assert p["thickness_taper"] == pytest.approx(taper / total, rel=1e-13)
    assert p["pm"] == pytest.approx(np.exp(g3) / total, rel=1e-13)
    assert list(p) == [NOMINAL, "thickness_taper", "pm"]  # candidates most probable first
    # a failed fit (-inf, NaN) has probability zero and changes nothing else
    r = model_probabilities(
        [
            ("thickness_taper", g1),
            ("thickness_taper", g2),
            ("pm", g3),
            ("foundation", -np.inf),
            ("loss", np.nan),
        ]
    )
    assert r["foundation"] == r["loss"] == 0.0 and r["pm"] == pytest.approx(p["pm"], rel=1e-14)
    with pytest.raises(ValueError, match="prior_odds"):
        model_probabilities([("pm", 1.0)], prior_odds={"pm": -1.0})


# --- verdict ---------------------------------------------------------------------------


class _Result:
    """What the verdict reads of a CandidateResult."""

    def __init__(self, name, gain, refined=True, chi2=10.0):
        self.name, self.log_evidence_gain = name, gain
        self.fit = type("Fit", (), {"refined": refined, "chi2": chi2})()


def test_a_runner_up_within_two_nats_makes_an_explained_mismatch_ambiguous():
    ranked = [
        _Result("thickness_taper", 3.2),
        _Result("thickness_taper", 3.1),
        _Result("local_stiffness_loss", 2.6),
        _Result("point_mass", 0.5),
    ]
    p = model_probabilities([(c.name, c.log_evidence_gain) for c in ranked])
    rival, gap, tie = runner_up(ranked[0], ranked, p)
    assert (rival, tie) == (ranked[2], "odds")  # the other taper direction: a variant, no rival
    # odds of the taper (its two directions, each half its prior) against the loss
    assert gap == pytest.approx(np.log(0.5 * (np.exp(3.2) + np.exp(3.1)) / np.exp(2.6)))
    assert verdict(1e-6, True, 0.5, 0.01, ranked[0], tie is not None) == ("ambiguous", ranked[0])
    # a rival 2.5 nats below that fits worse (chi2 + 8) is no tie: explained
    apart = [
        _Result("thickness_taper", 3.2, chi2=1.0),
        _Result("local_stiffness_loss", 0.7, chi2=9.0),
    ]
    q = model_probabilities([(c.name, c.log_evidence_gain) for c in apart])
    assert runner_up(apart[0], apart, q)[1:] == (pytest.approx(2.5), None)
    assert ties(apart[0], apart, q) == []
    assert verdict(1e-6, True, 0.5, 0.01, apart[0], False) == ("explained", apart[0])
    assert verdict(1e-6, True, 1e-4, 0.01, ranked[0], tie is not None) == ("unexplained", None)
    alone = [ranked[0], _Result("point_mass", 3.0, refined=False)]  # not refined: no rival
    assert runner_up(ranked[0], alone, p) == (None, np.inf, None)


def test_a_rival_that_fits_as_well_ties_within_the_prior_margin():
    """A point support named a foundation on a calibration replicate (chi2 0.7 against 1.6,
    gains +18.5 and +22.2): the odds, 3.7 nats, were the Occam factors' alone."""
    ranked = [
        _Result("elastic_foundation", 22.2, chi2=1.6),
        _Result("point_support", 18.5, chi2=0.7),
        _Result("local_stiffness_loss", 9.0, chi2=16.0),
    ]
    p = model_probabilities([(c.name, c.log_evidence_gain) for c in ranked])
    rival, gap, tie = runner_up(ranked[0], ranked, p, 2.0, 4.0)
    assert (rival, tie) == (ranked[1], "fit") and gap == pytest.approx(3.7)
    assert verdict(1e-6, True, 0.5, 0.01, ranked[0], tie is not None)[0] == "ambiguous"
    # a preference beyond the prior margin is the evidence's: explained, the rival kept
    assert runner_up(ranked[0], ranked, p, 2.0, 3.5) == (ranked[1], pytest.approx(3.7), None)
    # one that fits worse by more than the margin (chi2 + 4.1) is no tie however close
    worse = [ranked[0], _Result("point_support", 19.5, chi2=5.7), ranked[2]]
    p = model_probabilities([(c.name, c.log_evidence_gain) for c in worse])
    assert runner_up(worse[0], worse, p, 2.0, 4.0)[2] is None
    # three that tie (a calibration replicate: a point support of 32,000 N/m, 2026-11-27): all
    # are named, each name once, best first
    three = [
        _Result("elastic_foundation", 4.08, chi2=2.69),
        _Result("local_stiffness_loss", 1.88, chi2=2.82),
        _Result("point_support", 1.03, chi2=3.14),
        _Result("thickness_taper", 0.0, chi2=13.8),
        _Result("thickness_taper", -0.5),
        _Result("point_mass", -1.19, chi2=2.90),
    ]
    p = model_probabilities([(c.name, c.log_evidence_gain) for c in three])
    tied = ties(three[0], three, p, 2.0, 4.0)
    assert [(c.name, kind) for c, kind in tied] == [
        ("local_stiffness_loss", "fit"),
        ("point_support", "fit"),
    ]  # point mass: 5.3 nats
    assert runner_up(three[0], three, p, 2.0, 4.0)[0] is three[1]
    text = tie_text(three[0], tied, p)
    assert "local_stiffness_loss" in text and "so does point_support (chi2 3.1" in text
    # the first rival not tying, a lower one that fits as well is the rival
    lower = [
        ranked[0],
        _Result("local_stiffness_loss", 20.0, chi2=9.0),
        _Result("point_support", 18.5, chi2=2.0),
    ]
    p = model_probabilities([(c.name, c.log_evidence_gain) for c in lower])
    rival, gap, tie = runner_up(lower[0], lower, p, 2.0, 4.0)
    assert (rival, tie) == (lower[2], "fit")


def test_a_rival_that_fits_worse_does_not_tie_by_its_prior_volume():
    """A concealed slot (``studies/outside_effects.py``, replicate 0): the thickness taper
    came within 1.7 nats of the local stiffness loss in odds, by its one parameter against
    five, while fitting the recordings 3.8 nats worse. The recordings prefer the loss."""
    ranked = [
        _Result("local_stiffness_loss", 10.05, chi2=3.32),
        _Result("thickness_taper", 9.00, chi2=10.98),
        _Result("point_mass", 6.18, chi2=8.17),
        _Result("delamination", 4.18, chi2=9.52),
    ]
    p = model_probabilities([(c.name, c.log_evidence_gain) for c in ranked])
    gap = np.log(p["local_stiffness_loss"] / p["thickness_taper"])
    assert gap < 2.0  # within the odds margin ...
    assert 0.5 * (10.98 - 3.32) > 2.0  # ... but fitting worse by more than the margin
    assert ties(ranked[0], ranked, p, 2.0, 4.0) == []
    assert runner_up(ranked[0], ranked, p, 2.0, 4.0)[0] is ranked[1]  # the rival, untied
    assert verdict(1e-6, True, 0.5, 0.01, ranked[0], False) == ("explained", ranked[0])
    # the same odds with a fit within the margin (chi2 + 4) is a tie of odds
    close = [ranked[0], _Result("thickness_taper", 9.00, chi2=7.32), *ranked[2:]]
    assert [(c.name, k) for c, k in ties(close[0], close, p, 2.0, 4.0)] == [
        ("thickness_taper", "odds")
    ]


class _Twin(PointMass):
    """The point mass under another name: a constructed exact tie."""

    name = "point_mass_twin"


class _Triplet(PointMass):
    name = "point_mass_triplet"


def test_a_constructed_tie_is_ambiguous_and_names_all(model):
    truth = np.array([15.0, 50.0, 30.0])  # as tests/test_diagnose.py: 15 g at (50, 30) mm
    case = _recordings(_plate1_case(), PointMass(), truth, seed=2)
    d = diagnose(case, model=model, rng=0, n_starts=1, physics=[PointMass(), _Twin(), _Triplet()])
    assert d.verdict == "ambiguous"
    named = [d.chosen.name, d.rival.name, *(c.name for c in d.also_tied)]
    assert sorted(named) == ["point_mass", "point_mass_triplet", "point_mass_twin"]
    assert all(f"or {name}" in diagnosis_text(d) for name in named[1:])
    assert diagnosis_to_dict(d)["also_tied"] == named[2:]
    # the same physics: equal evidence, equal probabilities, nothing would separate them
    assert d.chosen.log_evidence_gain == pytest.approx(d.rival.log_evidence_gain, abs=1e-6)
    assert d.probabilities["point_mass"] == pytest.approx(d.probabilities["point_mass_twin"])
    assert d.probabilities[NOMINAL] < 1e-3
    assert d.separation.difference_sd < 1e-3 and d.separation.shape_difference < 1e-3
    out = diagnosis_to_dict(d)
    assert out["verdict"] == "ambiguous"
    assert out["rival"]["physics"] in {"point_mass", "point_mass_twin"}
    assert any("point_mass_twin" in n for n in d.notes)
    # a clear winner is still explained: the point mass against a foundation
    d = diagnose(case, model=model, rng=0, n_starts=1, physics=[PointMass(), ElasticFoundation()])
    assert d.verdict == "explained" and d.chosen.name == "point_mass" and d.rival is None
    assert d.probabilities["point_mass"] > 0.99


def test_separation_of_mirror_images_is_in_the_shapes_not_the_frequencies(model, b):
    # a mass at (50, 30) mm and at its mirror image (150, 30) mm on the 0/90 plate: the
    # frequencies agree exactly (symmetry), the shapes do not: no mode separates them
    n = N_MODES
    fits = []
    for x in (50.0, 150.0):
        theta = np.array([15.0, x, 30.0])
        fit = type("Fit", (), {"physics": PointMass(), "b": b, "theta": theta})()
        fits.append(type("C", (), {"name": f"mass at {x:.0f} mm", "fit": fit})())
    s = separate(model, fits[0], fits[1], np.arange(n - 6), 0.002)
    assert s.mode is not None and s.difference_sd < 1e-4  # round-off of a symmetric mesh
    # a 15 g mass (11 % of the plate's mass) makes its side of the plate move differently:
    # shapes differ by far more than the 1 % a shape measurement resolves
    assert s.shape_difference > 0.05
    assert "measure the shape of mode" in s.text()
    same = separate(model, fits[0], fits[0], np.arange(n - 6), 0.002)
    assert same.difference_sd == 0.0 and same.shape_difference == 0.0


# --- two effects at once ---------------------------------------------------------------


def _eigenvalues(plate, b):
    return plate.solve(b, N_MODES).eigenvalues


def test_a_pair_with_the_second_effect_at_zero_size_is_the_first_alone(model, b):
    mass = np.array([12.0, 60.0, 25.0])
    pair = Pair(PointMass(), ThicknessTaper("x"), b)
    got = _eigenvalues(pair.apply(model, np.concatenate([mass, [0.0]])), b)
    want = _eigenvalues(PointMass().apply(model, mass), b)
    np.testing.assert_allclose(got, want, rtol=1e-10)  # same matrices up to round-off
    reverse = Pair(ThicknessTaper("x"), PointMass(), b)  # composition is symmetric
    np.testing.assert_allclose(
        _eigenvalues(reverse.apply(model, np.concatenate([[0.1], mass])), b),
        _eigenvalues(pair.apply(model, np.concatenate([mass, [0.1]])), b),
        rtol=1e-10,
    )


def test_two_point_masses_at_one_point_are_one_mass_of_their_sum(model, b):
    pair = Pair(PointMass(), PointMass(), b)
    got = _eigenvalues(pair.apply(model, [5.0, 70.0, 40.0, 9.0, 70.0, 40.0]), b)
    want = _eigenvalues(PointMass().apply(model, [14.0, 70.0, 40.0]), b)
    np.testing.assert_allclose(got, want, rtol=1e-10)
    names = [p.name for p in pair.parameters(model, b)]
    assert names[:3] == ["point_mass.mass_g", "point_mass.x_mm", "point_mass.y_mm"]


def test_a_mass_and_a_foundation_compose_as_applied_in_turn(model, b):
    (k,) = [p.sd for p in ElasticFoundation().parameters(model, b)]
    mass = np.array([10.0, 40.0, 70.0])
    pair = Pair(PointMass(), ElasticFoundation(), b)
    got = _eigenvalues(pair.apply(model, np.concatenate([mass, [2 * k]])), b)
    in_turn = ElasticFoundation().apply(PointMass().apply(model, mass), [2 * k])
    np.testing.assert_allclose(got, _eigenvalues(in_turn, b), rtol=1e-10)


def test_a_pairs_ritz_form_reproduces_its_plate_at_a_snapshot(model, b):
    pair = Pair(PointMass(), ThicknessTaper("y"), b)
    theta = np.array([10.0, 50.0, 30.0, 0.12])
    pencil = candidate_pencil(model, pair, b, [theta], N_MODES)
    # the exact modes at theta are in the basis: Rayleigh-Ritz returns their eigenvalues
    want = _eigenvalues(pair.apply(model, theta), b)
    np.testing.assert_allclose(pencil.eigenvalues(b, theta, N_MODES), want, rtol=1e-8)
    # its mirror images: a symmetry moves the mass and reverses the taper together. Under
    # y -> b - y: (50, 70) mm with -0.12; under x -> a - x: (150, 30) mm with +0.12; under
    # the half-turn: (150, 70) mm with -0.12 (a y-taper is unchanged by x -> a - x)
    images = sorted(tuple(np.round(t, 9)) for t in pair.mirror_images(model, theta))
    assert images == [
        (10.0, 50.0, 70.0, -0.12),
        (10.0, 150.0, 30.0, 0.12),
        (10.0, 150.0, 70.0, -0.12),
    ]


def test_a_pairs_ritz_differences_are_its_matrices_differenced(model, b):
    # each parameter's difference is its component's own (the mass's exact derivative,
    # the taper's central difference): against central differences of the pair's matrices
    # (the mass inside an element: across an element's edge w'' jumps and the central
    # difference of the slope is off by the step times the jump)
    pair = Pair(PointMass(), ThicknessTaper("y"), b)
    theta = np.array([10.0, 53.3, 31.7, 0.12])
    pencil = candidate_pencil(model, pair, b, [theta], N_MODES)
    matrices = pencil.matrices
    for i, h in enumerate([1e-3, 1e-3, 1e-3, 1e-5]):
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        want = [(x - y) / (2 * h) for x, y in zip(matrices(up), matrices(down), strict=True)]
        got = matrices.difference(theta, i, h)
        for g, w in zip(got, want, strict=True):
            scale = max(np.abs(w).max(), 1e-300)
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-5 * scale)


class _ImagesOnly(PointMass):
    """A point mass that lists its mirror images but does not say under which symmetry."""

    def image(self, model, theta, symmetry):
        return None

    def mirror_images(self, model, theta):
        return [np.array([theta[0], x, y]) for x, y in mirror_positions(model, *theta[1:])]


def test_a_pairs_mirror_images_are_told_on_a_small_mesh_as_on_its_own(b):
    # a component that does not say its image under each symmetry: the combinations of
    # its images and the other's are told apart by their frequencies, on a mesh of at
    # most 12 x 12 elements for a finer one; the images are those above
    fine = PlateModel.from_case(_plate1_case(), mesh=(20, 10))
    pair = Pair(_ImagesOnly(), ThicknessTaper("y"), b)
    theta = np.array([10.0, 50.0, 30.0, 0.12])
    images = sorted(tuple(np.round(t, 9)) for t in pair.mirror_images(fine, theta))
    assert images == [
        (10.0, 50.0, 70.0, -0.12),
        (10.0, 150.0, 30.0, 0.12),
        (10.0, 150.0, 70.0, -0.12),
    ]
    # a combination that is no image is told apart on the small mesh too: the same
    # eigenvalues there only for the images
    from bayesplate.discrepancy.physics.combined import _check_model

    small = _check_model(fine)
    assert (small.mesh.nx, small.mesh.ny) == (12, 10)
    want = pair.apply(small, theta).solve(b, 8).eigenvalues
    other = pair.apply(small, np.array([10.0, 150.0, 30.0, -0.12])).solve(b, 8).eigenvalues
    assert np.max(np.abs(other / want - 1.0)) > 1e-4


def test_pairs_are_the_best_with_every_other_candidate(model, b):
    physics = [PointMass(), ThicknessTaper("x"), ThicknessTaper("y"), ElasticFoundation()]
    fit = type("Fit", (), {"physics": physics[1], "b": b, "theta": np.array([0.1])})()
    best = type("C", (), {"name": "thickness_taper", "fit": fit})()
    pairs = pairs_with(best, physics, [best], model, {})
    # the other taper direction is a variant of the same candidate, not a second effect
    assert [p.name for p in pairs] == [
        "thickness_taper+point_mass",
        "thickness_taper+elastic_foundation",
    ]
    starts = pairs[0].starting_points(model, b)
    np.testing.assert_allclose(starts[0][0], 0.1)  # from the best single fit


@pytest.mark.slow
def test_two_concealed_effects_are_named_as_a_pair(model, b):
    # a 15 g mass at (50, 30) mm on a plate tapered 15 % along x, recorded on the working
    # mesh itself (its own error switched off): no single candidate can fit, the pair can
    truth = np.array([15.0, 50.0, 30.0, 0.15])
    f = Pair(PointMass(), ThicknessTaper("x"), b).apply(model, truth).solve(b, 14).frequency_Hz
    f = f * (1 + NOISE * np.random.default_rng(3).standard_normal(f.size))
    case = _plate1_case().with_measured(frequency_Hz=f, sigma_Hz=NOISE * f)
    physics = [PointMass(), ThicknessTaper("x"), ElasticFoundation()]
    d = diagnose(case, model=model, rng=0, n_starts=1, physics=physics, mesh_error_ratio=1e9)
    assert d.verdict == "explained" and d.chosen.name == "point_mass+thickness_taper"
    single = next(c for c in d.candidates if c.name == "point_mass")
    assert d.chosen.log_evidence_gain > single.log_evidence_gain + 3.0
    assert d.refit_p_value > 0.01 and d.probabilities["point_mass+thickness_taper"] > 0.99
    got, sd = d.chosen.fit.theta, d.chosen.fit.theta_sd
    # the truth or one of its mirror images (a symmetry moves the mass and turns the taper)
    images = [
        truth,
        [15.0, 150.0, 30.0, -0.15],
        [15.0, 50.0, 70.0, 0.15],
        [15.0, 150.0, 70.0, -0.15],
    ]
    near = min(images, key=lambda t: np.hypot(*(got[1:3] - np.asarray(t)[1:3])))
    assert np.all(np.abs(got - near) < 3 * sd + np.array([0.5, 3.0, 3.0, 0.01]))


def test_mirror_images_count_as_posterior_modes():
    # two equal Gaussian modes at +-mu (unit deviations): their integral against the Laplace
    # approximation at the highest point (its height and curvature), computed numerically
    from bayesplate.discrepancy.search.probabilities import images_log_weight

    assert images_log_weight(np.array([3.0]), np.eye(1), []) == 0.0
    far = [np.array([300.0]), np.array([-300.0])]
    assert images_log_weight(np.array([0.0]), np.eye(1), far) == pytest.approx(np.log(3))
    x = np.linspace(-20.0, 20.0, 200001)
    for mu in (0.25, 0.5, 1.5, 2.0, 3.0, 6.0):
        both = np.exp(-0.5 * (x - mu) ** 2) + np.exp(-0.5 * (x + mu) ** 2)
        i, log_both = int(np.argmax(both)), np.log(both)
        curvature = -(log_both[i + 1] - 2 * log_both[i] + log_both[i - 1]) / (x[1] - x[0]) ** 2
        laplace = both[i] * np.sqrt(2 * np.pi / curvature)
        exact = np.log(np.trapezoid(both, x) / laplace)
        # the fit sits at the highest point; its image is the mirror of it
        weight = images_log_weight(np.array([x[i]]), np.eye(1) / curvature, [np.array([-x[i]])])
        assert weight == pytest.approx(exact, abs=0.03), mu


def _ranked(gain, refined, failed=""):
    """A ranked candidate as rank's phase choices see it."""
    from types import SimpleNamespace

    fit = SimpleNamespace(refined=refined, rough_optima=() if refined else (np.zeros(7),))
    return SimpleNamespace(name="c", parameters={}, log_evidence_gain=gain, fit=fit, failed=failed)


def test_a_named_candidates_rivals_left_on_the_coarse_model_are_refined():
    # rank's phase 2b: once a refined candidate may be named (gain over the threshold), the
    # unrefined ones within RIVAL_REACH of it are refined too
    from bayesplate.discrepancy.search.rank import RIVAL_REACH, _rivals

    results = [
        _ranked(3.5, True),
        _ranked(-0.7, False),
        _ranked(3.5 - RIVAL_REACH - 0.1, False),
        _ranked(2.0, True),
    ]
    assert _rivals(results, threshold=3.0, margin=1.0) == [1]
    # one whose refinement failed already is not tried again
    failed = _ranked(3.0, False, "its settled fit failed")
    assert _rivals([*results, failed], 3.0, margin=1.0) == [1]
    # when none may be named, every unrefined one over the margin, however far behind
    behind = [*results, _ranked(1.5, False), _ranked(0.5, False)]
    assert _rivals(behind, threshold=4.0, margin=1.0) == [4]
    assert _rivals([_ranked(-0.7, False)], threshold=3.0, margin=1.0) == []


def test_only_the_rough_fits_within_reach_of_the_best_are_refined_first():
    # rank's phase 2: over the margin and within REACH of the best rough gain; a refined
    # fit (a candidate without a reduced form, refined in its rough phase) is not chosen
    from bayesplate.discrepancy.search.rank import REACH, REACH_SHARE, _rivals, _within_reach

    results = [
        _ranked(26.8, False),
        _ranked(26.8 - REACH + 0.1, False),
        _ranked(26.8 - REACH - 0.1, False),
        _ranked(0.9, False),
        _ranked(40.0, True),
    ]
    assert _within_reach(results, margin=1.0) == [0, 1]
    # the one left behind is refined after, if it may rival the refined best: here the
    # best's coarse gain had overstated its gain
    results[:2] = [_ranked(25.0, True), _ranked(14.0, True)]
    assert _rivals(results[:4], threshold=3.0, margin=1.0) == [2]
    results[0] = _ranked(29.5, True)
    assert _rivals(results[:4], threshold=3.0, margin=1.0) == []
    # a strong effect: within a share of the best gain (a coarse model's error grows with it)
    strong = [_ranked(4975.0, False), _ranked(4975.0 * (1 - REACH_SHARE) + 1, False)]
    assert _within_reach([*strong, _ranked(3900.0, False)], margin=1.0) == [0, 1]


def test_every_named_fit_not_settled_gets_its_note():
    # an ambiguous verdict names the best and every candidate tied with it: a note for each
    # fit among them (and the nominal one) whose full-model check did not settle, none else
    from types import SimpleNamespace

    from bayesplate.discrepancy.search.settling import FitCheck
    from bayesplate.discrepancy.search.verdict import unsettled_notes

    def fitted(name, settled, objective=10.0):
        check = FitCheck(objective, objective, 1e-6, 0.0 if settled else 2.5, 6, 6, settled)
        return SimpleNamespace(name=name, fit=SimpleNamespace(check=check))

    nominal = fitted("nominal", True).fit
    best, second, third = fitted("a", False, 12.0), fitted("b", True), fitted("c", False, 14.0)
    notes = unsettled_notes(nominal, best, [(second, "fit"), (third, "odds")])
    assert len(notes) == 2
    assert notes[0].startswith("a: the full model's objective 12 could still fall by 2.5")
    assert notes[1].startswith("c: the full model's objective 14 could still fall by 2.5")
    assert unsettled_notes(nominal, None) == []
    assert len(unsettled_notes(fitted("nominal", False).fit, None)) == 1
    # and a note for each ranked candidate whose fit failed (ranked as its phase before)
    failed = SimpleNamespace(name="cutout+thickness_taper", failed="its settled fit failed (x)")
    fitted_ok = SimpleNamespace(name="b", failed="")
    assert unsettled_notes(nominal, None, ranked=[fitted_ok, failed]) == [
        "cutout+thickness_taper: its settled fit failed (x)"
    ]
