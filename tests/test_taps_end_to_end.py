"""Hammer taps to elastic constants, end to end (issue 37, "what it must show").

Synthetic taps with known answers, one artefact per test, and the real spruce plate 5R's
five raw taps: each runs ``bayesplate import TAPS --plate SHEET -o CASE`` with no options
(band from the sheet's prior, poles and their p_spurious chosen automatically), then
``bayesplate estimate CASE --method B --json``, through :func:`bayesplate.cli.main`.

The synthetic plate: the 5R sheet's geometry, density and prior (580 x 217 x 4.89 mm,
436 kg/m^3), on a 30 x 12 mesh for speed; the recordings come from a finer 40 x 16 mesh, so
the model is not exactly the data's. The truth (below) has E2 1.5 times its prior mean, as
real spruce has, and was chosen among spruce-like constants for the lowest 12 modes at
least 2.9 % apart: three modes within 1 % (as near 420 Hz for some constants) would test
LSCF's resolution of close modes, not the artefacts.
"""

import contextlib
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from bayesplate.cli import main
from bayesplate.io import bundled_case_path, load_case
from bayesplate.io.synthetic_taps import TapArtefacts, plate_modes_at, synthetic_taps, write_taps
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.plate.model import PlateModel

DATA_5R = Path(__file__).parent / "data" / "taps_5R"
KEYS = ("E1_GPa", "E2_GPa", "G12_GPa")

# truth in case units (GPa): from the prior mean (10.9, 0.64, 0.39, 0.58, 0.59, 0.026) with
# prior sd (2.7, 0.16, 0.08, 0.15, 0.15, 0.0065) this is E1 -0.7 sd, E2 +2.0 sd (1.5x),
# nu12 +0.75 sd, G12 +1.1 sd, G13 +0.07 sd, G23 +0.6 sd
TRUTH = {
    "E1_GPa": 9.0,
    "E2_GPa": 0.96,
    "nu12": 0.45,
    "G12_GPa": 0.74,
    "G13_GPa": 0.60,
    "G23_GPa": 0.030,
}
SHEET_MESH = (30, 12)
DATA_MESH = (40, 16)  # finer than the sheet's: the data are not the model's own
N_MODES = 14  # recorded (up to 528 Hz; the import fits poles up to 591 Hz)
RATE_HZ = 48000  # as the real 5R taps
DURATION_S = 1.0  # half the real taps' 2 s: with this damping they have decayed (checked)
DAMPING = (0.010, 0.012)  # viscous ratio; the real 5R poles have 0.35 to 1.5 %
TAP_MM = (40.0, 8.0)  # near an edge (all 12 lowest modes at >= 1/7 of the largest there)
SENSOR_MM = (8.0, 176.0)  # on no symmetry line (x = 290.6, y = 108.7 mm)
NO_WINDOW = "no window: the response has decayed within the record"

# Tolerance on E1, E2, G12 (the constants ten bending frequencies determine; nu12, G13 and
# G23 stay near their priors and are not asserted). An estimate differs from the truth by
# (a) its own error, whose sd it states: 1.2 % (E1), 1.8 % (E2), 1.6 % (G12) here, as the
# sheet declares sigma_rel = 1 % per frequency (the synthetic frequencies are far more
# accurate, so the actual scatter is much smaller); (b) the prior's pull: nu12, which the
# frequencies hardly determine, stays near its prior (0.36 against 0.45), and E2 with it: on
# the 30 x 12 model's own exact frequencies B gives E1 +0.25, E2 +0.95, G12 +0.45 %;
# (c) the model's error: the 30 x 12 sheet against the 40 x 16 data, 0.02-0.4 % in frequency,
# which takes (b) to E1 +0.05, E2 +0.51, G12 +0.13 % on the 40 x 16 exact frequencies.
# Asserted: within 3 sd AND within 3 % (the figure); with these sd the 3 % binds.
N_SD = 3.0
RTOL = 0.03


# ------------------------------------------------------------------------------- helpers


def sheet_text(mesh=None):
    """The 5R case less its measured frequencies and reference: a plate sheet."""
    text = bundled_case_path("badiane_spruce_5R").read_text()
    text = re.sub(r"frequency_Hz = \[[^\]]*\]\n", "", text)
    text = re.sub(r"\n\[reference\].*", "\n", text, flags=re.S)
    if mesh is not None:
        text = text.replace("mesh = [60, 24]", f"mesh = [{mesh[0]}, {mesh[1]}]")
    return text


@pytest.fixture(scope="module")
def sheet(tmp_path_factory):
    """The synthetic plate's sheet: 5R's geometry, density and prior on the coarse mesh."""
    path = tmp_path_factory.mktemp("sheet") / "spruce_sheet.toml"
    path.write_text(sheet_text(SHEET_MESH))
    return path


@pytest.fixture(scope="module")
def plate(sheet):
    """The data's model (the finer mesh) and the truth's stiffness coefficients."""
    case = load_case(bundled_case_path("badiane_spruce_5R"))
    model = PlateModel.from_case(case, mesh=DATA_MESH)
    order = ("E1_GPa", "E2_GPa", "nu12", "G12_GPa", "G13_GPa", "G23_GPa")
    scale = np.array([1e9, 1e9, 1.0, 1e9, 1e9, 1e9])
    return model, stiffness_from_engineering(np.array([TRUTH[k] for k in order]) * scale)


def tap_and_estimate(folder, sheet, frequency, amplitude, seed, **artefacts):
    """Write 5 taps, import them with no options, estimate with B: what the CLI gave.

    Returns ``(case, estimate JSON, import stdout, import stderr)``.
    """
    art = TapArtefacts(damping=DAMPING, **artefacts)
    taps = synthetic_taps(frequency, amplitude, RATE_HZ, DURATION_S, 5, art, seed)
    paths = write_taps(folder / "taps", taps, RATE_HZ)
    case_path, json_path = folder / "case.toml", folder / "estimate.json"
    argv = ["import", *map(str, paths), "--plate", str(sheet), "-o", str(case_path)]
    status, out, err = run_cli(argv)
    assert status == 0, err
    status, _, estimate_err = run_cli(
        ["estimate", str(case_path), "--method", "B", "--json", str(json_path), "-q"]
    )
    assert status == 0, estimate_err
    result = json.loads(json_path.read_text())
    case = load_case(case_path)
    print(out + err + estimate_err)
    print(summary(case, result))
    return case, result, out, err


def run_cli(argv):
    """``bayesplate ARGV`` in this process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(argv)
    return status, out.getvalue(), err.getvalue()


def summary(case, result, truth=TRUTH):
    """One line per constant and the fit, for the test's log."""
    lines = [
        f"status {result['status']}, fit {result['fit']}, warnings {result['warnings']}",
        f"measured {case.measured.frequency_Hz.tolist()}",
        f"p_spurious {case.measured.p_spurious.tolist()}",
        f"paired modes {result['modes']} of peaks {result['measured_Hz']}",
    ]
    for key in KEYS:
        c = result["constants"][key]
        error = c["mean"] / truth[key] - 1
        z = (c["mean"] - truth[key]) / c["sd"]
        lines.append(
            f"{key}: {c['mean']:.4f} +- {c['sd']:.4f} against {truth[key]}: "
            f"{100 * error:+.2f} % ({z:+.2f} sd)"
        )
    return "\n".join(lines)


def assert_constants(result, truth=TRUTH, n_sd=N_SD, rtol=RTOL):
    """E1, E2, G12 within `n_sd` of their own sd and within `rtol` of `truth`."""
    for key in KEYS:
        mean, sd = result["constants"][key]["mean"], result["constants"][key]["sd"]
        assert abs(mean - truth[key]) <= n_sd * sd, (key, mean, sd, truth[key])
        assert abs(mean / truth[key] - 1) <= rtol, (key, mean, truth[key])


def unobserved_modes(result):
    """Computed modes (1-based) below the highest paired one that no peak is paired with."""
    modes = set(result["modes"])
    return sorted(set(range(1, max(modes) + 1)) - modes)


def unpaired_peaks(case, result):
    """Measured frequencies the estimate left out of the fit (called spurious)."""
    paired = np.asarray(result["measured_Hz"])
    return [f for f in case.measured.frequency_Hz if not np.any(np.isclose(paired, f))]


def nearest(values, target):
    """Index of the value nearest `target`."""
    return int(np.argmin(np.abs(np.asarray(values) - target)))


@pytest.fixture(scope="module")
def modes(plate):
    """The truth's modes tapped at TAP_MM and recorded at SENSOR_MM (the finer mesh)."""
    model, b = plate
    return plate_modes_at(model, b, TAP_MM, SENSOR_MM, N_MODES)


# ------------------------------------------------------------------------ synthetic taps


def test_clean_taps_with_noise(tmp_path, sheet, modes):
    frequency, amplitude = modes
    case, result, out, err = tap_and_estimate(
        tmp_path, sheet, frequency, amplitude, 1, noise=1e-3, force_noise=1e-3
    )

    assert NO_WINDOW in out  # the 1 s records have decayed: no window, no leakage
    assert "warning" not in err
    assert result["status"] == "converged", result["warnings"]
    assert_constants(result)
    # every recorded mode in the band found and paired with its own mode, in order
    n = case.measured.size
    np.testing.assert_allclose(case.measured.frequency_Hz, frequency[:n], rtol=1e-3)
    assert result["modes"] == list(range(1, n + 1))


def test_split_mode_one_of_its_two_peaks_paired(tmp_path, sheet, modes):
    frequency, amplitude = modes
    split = (2, 0.02, 0.7)  # mode 3 (125 Hz) and a partner 2 % above, 0.7 times as strong
    case, result, out, _ = tap_and_estimate(
        tmp_path, sheet, frequency, amplitude, 2, noise=1e-3, split=split
    )

    assert NO_WINDOW in out
    assert result["status"] != "rejected"
    assert_constants(result)
    measured = case.measured.frequency_Hz
    near = measured[np.abs(measured / frequency[2] - 1.01) < 0.02]
    np.testing.assert_allclose(near, [frequency[2], 1.02 * frequency[2]], rtol=2e-3)
    # the double peak: one of its two peaks is paired with mode 3, the other left out
    paired = np.asarray(result["measured_Hz"])
    assert sum(np.any(np.isclose(paired, f)) for f in near) == 1, (near, paired)
    assert unpaired_peaks(case, result) == [f for f in near if not np.any(np.isclose(paired, f))]
    assert unobserved_modes(result) == []


@pytest.mark.slow
def test_rattle_pole_in_a_coherence_dip_is_spurious(tmp_path, sheet, modes):
    frequency, amplitude = modes
    rattle = 320.0  # between modes 8 (272 Hz) and 9 (367 Hz), inside the band
    case, result, out, err = tap_and_estimate(
        tmp_path, sheet, frequency, amplitude, 3, noise=1e-3, rattle_Hz=rattle, rattle_level=0.05
    )

    assert NO_WINDOW in out
    assert result["status"] != "rejected"
    assert_constants(result)
    measured = case.measured.frequency_Hz
    k = nearest(measured, rattle)
    assert abs(measured[k] / rattle - 1) < 2e-3, measured  # the import keeps its pole ...
    warned = [float(f) for f in re.findall(r"([0-9.]+) Hz \(0\.[0-9]+\)", err)]
    assert "coherence below" in err and np.isclose(warned, rattle, rtol=2e-3).tolist() == [True]
    assert case.measured.p_spurious[k] > 0.5  # ... with a high p_spurious (and a warning) ...
    assert unpaired_peaks(case, result) == [measured[k]]  # ... and the estimate leaves it out
    assert unobserved_modes(result) == []


@pytest.fixture(scope="module")
def nodal_sensor(plate):
    """A point on a nodal line of mode 4 (157.6 Hz; its two nodal lines run lengthwise).

    At x = 228 mm (chosen where every other of the 13 lowest modes keeps at least 9 % of
    the largest amplitude); y found on the data's own mesh, so mode 4 is exactly not seen.
    """
    model, b = plate
    vectors = model.solve(b, 4).vectors

    def w4(y_mm):
        point = np.array([[228e-3, y_mm * 1e-3]])
        return float((model.interpolation(point, "w") @ vectors)[0, 3])

    return (228.0, brentq(w4, 150.0, 200.0, xtol=1e-6))


@pytest.mark.slow
def test_mode_at_a_node_of_the_sensor_is_unobserved(tmp_path, sheet, plate, nodal_sensor):
    model, b = plate
    frequency, amplitude = plate_modes_at(model, b, TAP_MM, nodal_sensor, N_MODES)
    relative = np.abs(amplitude) / np.abs(amplitude).max()
    print(f"sensor at {nodal_sensor}: amplitudes / largest {relative.round(4)}")
    assert relative[3] < 1e-6 and np.delete(relative[:13], 3).min() > 0.05  # mode 4 alone

    case, result, out, _ = tap_and_estimate(tmp_path, sheet, frequency, amplitude, 4, noise=1e-3)

    assert NO_WINDOW in out
    assert result["status"] != "rejected"
    assert_constants(result)
    measured = case.measured.frequency_Hz
    assert np.min(np.abs(measured / frequency[3] - 1)) > 0.01  # no peak at mode 4
    # the estimate pairs around it: mode 4 unobserved (the JSON has no list of unobserved
    # modes: its "modes" skip 4, its message names it), every peak paired
    assert unobserved_modes(result) == [4]
    assert "computed mode 4 unobserved" in result["message"]
    assert unpaired_peaks(case, result) == []


@pytest.mark.slow
def test_clipped_tap(tmp_path, sheet, modes):
    frequency, amplitude = modes
    clip = (1, 0.5)  # tap 2's response clipped at half its peak (a recorder's range)
    case, result, out, err = tap_and_estimate(
        tmp_path, sheet, frequency, amplitude, 5, noise=1e-3, clip=clip
    )

    assert result["status"] != "rejected"
    assert_constants(result)
    # the clipped tap's harmonics give poles that are no modes; each has a high p_spurious
    # and the estimate leaves it out; the modes are all paired, in order
    extra = unpaired_peaks(case, result)
    spurious = case.measured.p_spurious[np.isin(case.measured.frequency_Hz, extra)]
    print(f"clip: unpaired {extra}, their p_spurious {spurious}")
    assert np.all(spurious > 0.5)
    paired = np.asarray(result["measured_Hz"])
    assert result["modes"] == list(range(1, paired.size + 1))
    np.testing.assert_allclose(paired, frequency[: paired.size], rtol=2e-3)


def test_double_hit(tmp_path, sheet, modes):
    frequency, amplitude = modes
    hit = (2, 2e-3, 0.5)  # tap 3: a second hit 2 ms after the first, half as strong
    case, result, out, err = tap_and_estimate(
        tmp_path, sheet, frequency, amplitude, 6, noise=1e-3, double_hit=hit
    )

    assert NO_WINDOW in out
    assert result["status"] != "rejected"
    assert_constants(result)
    # H1 divides by the force that holds both hits: the same modes as a clean test
    n = case.measured.size
    np.testing.assert_allclose(case.measured.frequency_Hz, frequency[:n], rtol=2e-3)
    assert result["modes"] == list(range(1, n + 1))


# ------------------------------------------------------------ a plate not quite the sheet's


@pytest.mark.slow
def test_tapered_plate_within_tolerance(tmp_path, sheet, plate):
    model, b = plate
    # thickness h (1 + 0.05 (2 x / a - 1)): 5 % thinner at one end, 5 % thicker at the other
    frequency, amplitude = plate_modes_at(model, b, TAP_MM, SENSOR_MM, N_MODES, taper=("x", 0.05))
    case, result, out, _ = tap_and_estimate(tmp_path, sheet, frequency, amplitude, 7, noise=1e-3)

    assert result["status"] == "converged"  # not flagged: the fit is as good as the flat plate's
    assert_constants(result)
    assert result["modes"] == list(range(1, case.measured.size + 1))


THICKNESS_SCALE = 1.02


@pytest.fixture(scope="module")
def thicker(tmp_path_factory, sheet, plate):
    """Taps of a plate 2 % thicker than its sheet says, imported and estimated."""
    model, b = plate
    frequency, amplitude = plate_modes_at(
        model, b, TAP_MM, SENSOR_MM, N_MODES, thickness_scale=THICKNESS_SCALE
    )
    folder = tmp_path_factory.mktemp("thicker")
    return tap_and_estimate(folder, sheet, frequency, amplitude, 8, noise=1e-3)


@pytest.mark.slow
def test_thicker_plate_gives_moduli_scaled_by_its_square(thicker):
    # bending frequencies go as h sqrt(E / rho): the sheet's h, 2 % too small, makes the
    # moduli that give the same frequencies 1.02^2 = 1.0404 times the truth; the fit is as
    # good as with the right thickness and cannot tell (the shear share is small here)
    case, result, _, _ = thicker
    scaled = {k: v * THICKNESS_SCALE**2 for k, v in TRUTH.items()}
    print(summary(case, result, scaled))
    assert result["status"] == "converged"
    assert result["fit"]["p_value"] > 0.5
    assert_constants(result, truth=scaled)
    assert result["modes"] == list(range(1, case.measured.size + 1))


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="a plate 2 % thicker than its sheet: E1 +4.11 %, E2 +4.56 %, G12 +4.17 % from the "
    "truth (3.3, 2.4, 2.5 sd) with a fit as good as the right plate's (chi-square 1.55 on "
    "9.2 dof, p 0.997, status converged): a uniform thickness error scales every frequency "
    "alike, so the frequencies cannot reveal it; only the sheet's thickness_sd_mm (none in "
    "the 5R sheet) would widen the sd",
)
def test_thicker_plate_flagged_or_within_tolerance(thicker):
    _, result, _, _ = thicker
    if result["status"] == "converged":
        assert_constants(result)


# ------------------------------------------------------------------ the real 5R taps

# The reference: NOT an independent measurement but the source's own vibration-based estimate
# (Badiane et al. 2023, paramsEstimations.xlsx, row 5R: E1 10.8, E2 0.970, G12 0.794 GPa,
# with h = 5.0 mm and rho = 416 kg/m^3), rescaled to the sheet's h = 4.89 mm and
# rho = 435.7 kg/m^3 by (5.0 / 4.89)^2 (435.7 / 416) = 1.095 (bending frequencies go as
# h sqrt(E / rho)); see tests/data/taps_5R/README.md. The target: within 3 %.
REFERENCE_5R = {"E1_GPa": 11.83, "E2_GPa": 1.062, "G12_GPa": 0.869}


@pytest.mark.slow
def test_real_5R_taps_give_the_source_constants(tmp_path):
    sheet = tmp_path / "spruce_5R_sheet.toml"
    sheet.write_text(sheet_text())  # its own 60 x 24 mesh
    taps = [DATA_5R / f"tap{k}.wav" for k in range(1, 6)]
    case_path, json_path = tmp_path / "case.toml", tmp_path / "estimate.json"

    status, out, err = run_cli(
        ["import", *map(str, taps), "--plate", str(sheet), "-o", str(case_path)]
    )
    assert status == 0, err
    status, _, err = run_cli(
        ["estimate", str(case_path), "--method", "B", "--json", str(json_path), "-q"]
    )
    assert status == 0, err

    case, result = load_case(case_path), json.loads(json_path.read_text())
    print(out + err)
    print(result["message"])
    print(summary(case, result, REFERENCE_5R))
    assert NO_WINDOW in out  # the 2 s records have decayed
    assert result["status"] != "rejected"
    for key, reference in REFERENCE_5R.items():
        assert abs(result["constants"][key]["mean"] / reference - 1) <= RTOL, (key, result)
