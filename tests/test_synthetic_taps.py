"""Synthetic hammer taps with artefacts (issue 37): they hold what they say, the import reads them.

The references are independent of the generator: the FRF is the modal sum written out here,
the frequencies are those of the model solved here, and the artefacts are checked in the
arrays (a second pulse, a flat top) or in the H1 and coherence of `bayesplate.io.taps`.
"""

import numpy as np
import pytest

from bayesplate.cli import main
from bayesplate.io import bundled_case_path, load_case
from bayesplate.io.impulse import Recording, read_recording
from bayesplate.io.poles import extract_poles
from bayesplate.io.synthetic_taps import (
    TapArtefacts,
    plate_modes_at,
    recorded_poles,
    synthetic_taps,
    write_taps,
)
from bayesplate.io.taps import average_taps, coherence_at_poles
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.plate.model import PlateModel

RATE_HZ = 25600  # 4 x the top mode of plate1 (6.4 kHz)
PULSE_S = (0.08e-3, 0.12e-3)  # a hard tip: the half-sine's first zero above 12 kHz
BAND_HZ = (100.0, 7000.0)
FREQUENCY_RTOL = 1e-3  # the figure: 0.1 %
TAP_MM = (0.0, 0.0)  # a corner: no mode of a free plate has a node there
SENSOR_MM = (200.0, 100.0)  # the opposite corner
CENTRE_MM = (100.0, 50.0)  # a node of every mode odd in x or in y


@pytest.fixture(scope="module")
def plate1():
    """The bundled plate1: its model and stiffness coefficients."""
    case = load_case(bundled_case_path("plate1"))
    return PlateModel.from_case(case), stiffness_from_engineering(case.reference)


@pytest.fixture(scope="module")
def modes(plate1):
    """Ten modes of plate1, tapped at one corner, measured at the opposite one."""
    model, b = plate1
    return plate_modes_at(model, b, TAP_MM, SENSOR_MM, 10)


def taps_of(frequency, amplitude, rng, n_taps=5, duration_s=0.5, **artefacts):
    """`n_taps` synthetic taps of plate1's modes at RATE_HZ with a hard tip."""
    art = TapArtefacts(**artefacts)
    return synthetic_taps(
        frequency, amplitude, RATE_HZ, duration_s, n_taps, art, rng, pulse_s=PULSE_S
    )


def averaged(taps, window="auto"):
    """H1 and coherence of one-sensor taps (bayesplate.io.taps)."""
    return average_taps([Recording(RATE_HZ, y[None, :], f, (0,), "") for y, f in taps], window)


def kept_poles(data):
    """Frequencies of the poles LSCF keeps automatically in BAND_HZ."""
    return np.array([pole.frequency_Hz for pole in extract_poles(data, band_Hz=BAND_HZ).kept])


def nearest_error(found, frequency):
    """Relative distance from each of `frequency` to the nearest of `found`."""
    return np.array([np.min(np.abs(found / f - 1)) for f in frequency])


# ---------------------------------------------------------------------------- the clean taps


def test_h1_of_clean_taps_is_the_modal_frf_at_the_lines(modes, rng):
    frequency, amplitude = modes
    zeta = np.linspace(0.005, 0.01, frequency.size)  # the default damping law
    # 1 s: the slowest mode (611 Hz, 0.5 %) rings down to 5e-9 within the record
    taps = taps_of(frequency, amplitude, rng, n_taps=4, duration_s=1.0)

    data = averaged(taps, window="none")

    omega, omega_k = 2 * np.pi * data.frequency_Hz, 2 * np.pi * frequency
    H = np.zeros(omega.size, dtype=complex)
    for k in range(frequency.size):  # accelerance: a = -w^2 x, term by term
        H += (
            amplitude[k]
            * -(omega**2)
            / (omega_k[k] ** 2 - omega**2 + 2j * zeta[k] * omega_k[k] * omega)
        )
    band = (data.frequency_Hz > 0) & (data.frequency_Hz < 10000)
    error = np.abs(data.frf[0] - H)[band].max() / np.abs(H[band]).max()
    print(f"clean H1 against the modal FRF: max error {error:.2e} of its peak")
    # what is left is the band-limited response's faint precursor before t = 0, which the
    # record cuts: 3e-7 of the peak below 3 kHz, 3.4e-6 at 10 kHz, the same with 2 s
    assert error < 1e-5, error
    inside = (data.frequency_Hz >= BAND_HZ[0]) & (data.frequency_Hz <= BAND_HZ[1])
    assert np.all(data.coherence[0][inside] > 1 - 1e-5)  # noise-free: linear to that cut
    for y, force in taps:  # the force is a half-sine: zero before it; the response follows
        onset = int(np.argmax(force > 0))
        assert np.all(force[:onset] == 0) and np.all(force >= 0)
        assert np.ptp(np.flatnonzero(force)) / RATE_HZ < PULSE_S[1]  # one pulse, that long
        # band-limited: a faint precursor, 4e-4 of the peak 5 samples ahead, then less
        assert np.abs(y[: onset - 5]).max() < 1e-3 * np.abs(y).max()
        assert np.abs(y[: onset - 20]).max() < 2e-4 * np.abs(y).max()


def test_import_of_clean_taps_gives_the_model_frequencies(tmp_path, capsys, sheet, modes, rng):
    frequency, amplitude = modes
    paths = write_taps(tmp_path / "taps", taps_of(frequency, amplitude, rng), RATE_HZ)
    assert [p.name for p in paths] == [f"tap{k}.wav" for k in range(1, 6)]
    recording = read_recording(paths[0])  # as the real ones: channel 0 response, 1 force
    assert recording.rate_Hz == RATE_HZ and recording.channels == (0,)
    assert recording.force is not None and recording.responses.shape == (1, RATE_HZ // 2)
    out = tmp_path / "case.toml"

    argv = [
        "import",
        *map(str, paths),
        "--plate",
        str(sheet),
        "-o",
        str(out),
        "--band",
        *map(str, BAND_HZ),
    ]
    status = main(argv)
    captured = capsys.readouterr()

    assert status == 0, captured.err
    assert "H1 over 5 taps" in captured.out and "warning" not in captured.err
    error = load_case(out).measured.frequency_Hz / frequency - 1
    print(f"import of 5 clean taps: max frequency error {100 * np.abs(error).max():.2e} %")
    assert np.abs(error).max() < FREQUENCY_RTOL, error


def test_several_sensors_give_the_model_shapes(tmp_path, capsys, sheet, plate1, rng):
    model, b = plate1
    points_mm = np.array([SENSOR_MM, [0.0, 100.0], [140.0, 50.0]])
    frequency, amplitude = plate_modes_at(model, b, TAP_MM, points_mm, 10)
    assert amplitude.shape == (3, 10)
    paths = write_taps(tmp_path, taps_of(frequency, amplitude, rng, n_taps=3), RATE_HZ)
    points = tmp_path / "points.csv"
    points.write_text(
        "point,x_mm,y_mm\n" + "".join(f"p{i},{x},{y}\n" for i, (x, y) in enumerate(points_mm))
    )
    out = tmp_path / "case.toml"

    argv = [
        "import",
        *map(str, paths),
        "--plate",
        str(sheet),
        "-o",
        str(out),
        "--band",
        *map(str, BAND_HZ),
        "--force-channel",
        "3",
        "--points",
        str(points),
    ]
    status = main(argv)
    captured = capsys.readouterr()

    assert status == 0, captured.err
    measured = load_case(out).measured
    w = np.asarray(model.interpolation(points_mm * 1e-3, "w") @ model.solve(b, 10).vectors)
    shapes = measured.shapes.T  # (3, 10)
    mac = np.sum(shapes * w, 0) ** 2 / (np.sum(shapes**2, 0) * np.sum(w**2, 0))
    error = measured.frequency_Hz / frequency - 1
    print(f"3 sensors: min MAC {mac.min():.6f}, max error {100 * np.abs(error).max():.2e} %")
    assert np.all(mac > 0.99), mac
    assert np.abs(error).max() < FREQUENCY_RTOL, error


# ------------------------------------------------------------------------------ artefacts


def test_rattle_is_a_coherence_dip_with_a_pole_in_it(modes, rng):
    frequency, amplitude = modes
    rattle = 3000.0  # between the modes at 2478 and 3810 Hz
    data = averaged(taps_of(frequency, amplitude, rng, rattle_Hz=rattle))
    axis, coherence = data.frequency_Hz, data.coherence[0]
    band = (axis >= BAND_HZ[0]) & (axis <= BAND_HZ[1])

    kept = kept_poles(data)

    low = axis[band & (coherence < 0.9)]
    at_rattle = coherence[np.argmin(np.abs(axis - rattle))]
    at_modes = [c for _, c in coherence_at_poles(data, [_pole(f) for f in frequency])]
    print(
        f"rattle: coherence {at_rattle:.3f} at {rattle:g} Hz, below 0.9 from {low.min():g} to "
        f"{low.max():g} Hz; at the modes min {min(at_modes):.5f}"
    )
    assert at_rattle < 0.9
    assert np.all(np.abs(low / rattle - 1) < 0.05), low  # and nowhere else
    assert min(at_modes) > 0.99
    assert nearest_error(kept, [rattle])[0] < FREQUENCY_RTOL, kept  # a pole in the dip
    assert np.all(nearest_error(kept, frequency) < FREQUENCY_RTOL)  # the modes all there


def _pole(f):
    from bayesplate.io.poles import Pole

    return Pole(float(f), 0.0)


def test_split_mode_gives_two_poles(modes, rng):
    frequency, amplitude = modes
    split = (0, 0.03, 0.7)  # the 611 Hz mode and a partner 3 % above, 0.7 times as strong
    truth, _, _ = recorded_poles(frequency, amplitude, TapArtefacts(split=split))
    assert truth.size == 11 and np.isclose(truth[1], 1.03 * frequency[0])

    kept = kept_poles(averaged(taps_of(frequency, amplitude, rng, split=split)))

    near = kept[np.abs(kept / frequency[0] - 1.015) < 0.03]
    print(f"split: poles near {frequency[0]:.1f} Hz: {near.round(2)}")
    assert near.size == 2, kept
    np.testing.assert_allclose(near, [frequency[0], 1.03 * frequency[0]], rtol=FREQUENCY_RTOL)


def test_mode_at_a_node_of_the_sensor_is_absent(plate1, rng):
    model, b = plate1
    frequency, amplitude = plate_modes_at(model, b, TAP_MM, CENTRE_MM, 10)
    # the centre is a node of every mode odd in x or y: 7 of the 10 (by symmetry, not by fit)
    node = np.abs(amplitude) < 1e-6 * np.abs(amplitude).max()
    assert node.sum() == 7, amplitude

    kept = kept_poles(averaged(taps_of(frequency, amplitude, rng)))

    print(f"sensor at the centre: kept {kept.round(1)}; absent {frequency[node].round(1)}")
    assert np.all(nearest_error(kept, frequency[~node]) < FREQUENCY_RTOL), kept
    assert np.all(nearest_error(kept, frequency[node]) > 0.005), kept
    assert kept.size == (~node).sum()


def test_double_hit_and_clip_are_in_the_arrays(modes, rng):
    frequency, amplitude = modes
    seed = int(rng.integers(2**32))
    clean = taps_of(frequency, amplitude, np.random.default_rng(seed), n_taps=3, noise=1e-3)
    hit, clip = (1, 3e-3, 0.4), (2, 0.3)
    odd = taps_of(
        frequency,
        amplitude,
        np.random.default_rng(seed),
        n_taps=3,
        noise=1e-3,
        double_hit=hit,
        clip=clip,
    )

    # the second hit: in the force of tap 1 only, 3 ms after the first, 0.4 times as strong
    for k, ((_, f0), (_, f1)) in enumerate(zip(clean, odd, strict=True)):
        pulses = np.flatnonzero(np.diff((f1 > 0.05 * f1.max()).astype(int)) == 1)
        assert len(pulses) == (2 if k == 1 else 1)
        if k != 1:
            np.testing.assert_array_equal(f0, f1)
    f0, f1 = clean[1][1], odd[1][1]
    extra = f1 - f0
    start = [int(np.argmax(f0 > 0)), int(np.argmax(extra > 0))]
    assert abs((start[1] - start[0]) / RATE_HZ - 3e-3) <= 1.5 / RATE_HZ
    np.testing.assert_allclose(extra.max(), 0.4 * f0.max(), rtol=0.05)  # same pulse, sampled
    # ... and the response follows it, not before
    y_extra = odd[1][0] - clean[1][0]
    assert np.abs(y_extra[: start[1] - 5]).max() < 1e-3 * np.abs(y_extra).max()

    # the clip: tap 2's response flat at 0.3 of its peak; the other samples untouched
    y0, y2 = clean[2][0], odd[2][0]
    top = 0.3 * np.abs(y0).max()
    assert np.isclose(np.abs(y2).max(), top) and np.sum(np.isclose(np.abs(y2), top)) > 10
    inside = np.abs(y0) < top
    np.testing.assert_array_equal(y2[inside], y0[inside])
    np.testing.assert_array_equal(odd[0][0], clean[0][0])
    print(
        f"double hit: {start[1] - start[0]} samples apart; clip: "
        f"{np.sum(~inside)} samples at the rails"
    )


def test_noise_has_the_level_asked_for(modes, rng):
    frequency, amplitude = modes
    seed = int(rng.integers(2**32))
    ((y0, f0),) = taps_of(frequency, amplitude, np.random.default_rng(seed), n_taps=1)
    ((y, f),) = taps_of(
        frequency, amplitude, np.random.default_rng(seed), n_taps=1, noise=1e-3, force_noise=2e-3
    )
    # the same hammer (drawn first): the difference is the noise alone, white, zero mean
    ratio_y = np.std(y - y0) / (1e-3 * np.abs(y0).max())
    ratio_f = np.std(f - f0) / (2e-3 * np.abs(f0).max())
    lag1 = np.corrcoef((y - y0)[1:], (y - y0)[:-1])[0, 1]
    print(
        f"noise: response {ratio_y:.4f}, force {ratio_f:.4f} of the level asked for; "
        f"lag-1 correlation {lag1:.4f}"
    )
    assert 0.97 < ratio_y < 1.03 and 0.97 < ratio_f < 1.03 and abs(lag1) < 0.05
    assert np.abs(y0[-RATE_HZ // 10 :]).max() < 1e-3 * np.abs(y0).max()  # rung down, no noise


# ---------------------------------------------------------------------- seeds, plate options


def test_same_seed_gives_the_same_taps(modes):
    frequency, amplitude = modes
    options = dict(
        noise=1e-3,
        force_noise=1e-3,
        rattle_Hz=(3000.0,),
        split=(0, 0.02, 0.5),
        double_hit=(0, 2e-3, 0.3),
        clip=(1, 0.8),
    )
    one, two, other = (
        taps_of(frequency, amplitude, np.random.default_rng(seed), n_taps=3, **options)
        for seed in (7, 7, 8)
    )
    for (y1, f1), (y2, f2) in zip(one, two, strict=True):
        np.testing.assert_array_equal(y1, y2)
        np.testing.assert_array_equal(f1, f2)
    assert not np.array_equal(one[0][1], other[0][1])
    # the hammer is drawn first: switching artefacts on leaves the forces alone
    plain = taps_of(frequency, amplitude, np.random.default_rng(7), n_taps=3)
    quiet = taps_of(
        frequency, amplitude, np.random.default_rng(7), n_taps=3, **{**options, "force_noise": 0.0}
    )
    np.testing.assert_array_equal(plain[2][1], quiet[2][1])


def test_plate_a_little_thicker_denser_or_tapered(plate1):
    model, b = plate1
    f0, a0 = plate_modes_at(model, b, TAP_MM, SENSOR_MM, 6)
    # density: frequencies / sqrt(1.1), mass-normalised amplitudes / 1.1, exactly
    f1, a1 = plate_modes_at(model, b, TAP_MM, SENSOR_MM, 6, density_scale=1.1)
    np.testing.assert_allclose(f1, f0 / np.sqrt(1.1), rtol=1e-9)
    np.testing.assert_allclose(a1, a0 / 1.1, rtol=1e-7)
    # thickness: bending frequencies scale as h, less where shear takes part
    f2, _ = plate_modes_at(model, b, TAP_MM, SENSOR_MM, 6, thickness_scale=1.02)
    assert np.all((f2 / f0 > 1.0) & (f2 / f0 < 1.02 + 1e-9)) and f2[0] / f0[0] > 1.015
    # a taper along x seen from the other end is the opposite taper: mirror the points
    f3, a3 = plate_modes_at(model, b, TAP_MM, SENSOR_MM, 6, taper=("x", 0.05))
    f4, a4 = plate_modes_at(model, b, (200.0, 0.0), (0.0, 100.0), 6, taper=("x", -0.05))
    np.testing.assert_allclose(f3, f4, rtol=1e-9)
    np.testing.assert_allclose(a3, a4, rtol=1e-6)
    shift = np.abs(f3 / f0 - 1)
    print(f"taper 5 %: frequency shifts {shift.round(5)}")
    assert 1e-4 < shift.max() < 0.02


def test_report_from_taps_shows_the_tap_test(tmp_path, capsys, sheet, plate1, rng):
    # `bayesplate report --taps ... --plate ...`: the import with no options into DIR/case.toml,
    # then the report, with the peaks' evidence and roles and the FRF and stabilisation chart.
    # The sensor at (200, 70) mm, near a nodal line of mode 3 (a search over a 5 mm grid:
    # mode 3's amplitude there below 1 % of its largest, every other mode's above 42 %), set
    # to the line itself (amplitude 0): the taps miss mode 3, and the report must name it as
    # the computed mode no peak explains.
    model, b = plate1
    frequency, amplitude = plate_modes_at(model, b, TAP_MM, (200.0, 70.0), 10)
    assert np.abs(amplitude[2]) < 0.01 * np.abs(amplitude).max()
    amplitude[2] = 0.0
    seen = amplitude != 0.0
    paths = write_taps(tmp_path / "taps", taps_of(frequency, amplitude, rng), RATE_HZ)
    out = tmp_path / "report"
    words = ["report", "--taps", *map(str, paths), "--plate", str(sheet), "-o", str(out)]
    status = main([*words, "--no-diagnose", "--no-sample"])  # plate1: 8 x 4 already
    assert status == 0, capsys.readouterr().err
    text = (out / "report.md").read_text(encoding="utf-8")
    assert "## Tap test" in text and "| p spurious | role |" in text
    for name in ("frf.png", "stabilisation.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    case = load_case(out / "case.toml")
    assert case.measured.p_spurious is not None
    found = case.measured.frequency_Hz
    assert len(found) == int(seen.sum())  # the modes the sensor sees, no more
    np.testing.assert_allclose(found, frequency[seen], rtol=1e-3)
    missed = ", ".join(str(j + 1) for j in np.flatnonzero(~seen) if frequency[j] < found.max())
    assert f"unobserved: a node at the tap or the sensor, or too weak): {missed}." in text
