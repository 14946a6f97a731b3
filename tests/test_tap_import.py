"""Tap tests in (issue 16): impulse recordings and FRFs -> LSCF poles (sdypy-EMA) -> case files."""

from pathlib import Path

import numpy as np
import pytest
import pyuff
from scipy.io import wavfile

from bayesplate.cli import main
from bayesplate.io import CaseError, bundled_case_path, load_case
from bayesplate.io.band import prior_band_Hz
from bayesplate.io.case_writer import _to_digits as to_digits
from bayesplate.io.case_writer import sheet_case
from bayesplate.io.frf import read_frf_csv, read_uff_frf
from bayesplate.io.modal_file import is_tap_test, read_spectra
from bayesplate.io.poles import extract_poles, modal_data_from_poles
from bayesplate.io.poles_file import read_poles
from bayesplate.io.taps import read_impulse
from bayesplate.laminate import stiffness_from_engineering
from bayesplate.plate.model import PlateModel

RATE_HZ = 25600.0  # 4 x the top mode of plate1 (6.4 kHz)
FREQUENCY_RTOL = 1e-3  # the figure: 0.1 %


def mac_matrix(A, B):
    """MAC between the columns of A (n, p) and B (n, q)."""
    return (A.T @ B) ** 2 / np.outer(np.sum(A * A, 0), np.sum(B * B, 0))


@pytest.fixture(scope="module")
def plate1():
    """Ten modes of the bundled plate1: frequencies (Hz) and w at a 4 x 3 grid (mm)."""
    case = load_case(bundled_case_path("plate1"))
    model = PlateModel.from_case(case)
    result = model.solve(stiffness_from_engineering(case.reference), 10)
    x, y = np.meshgrid([0.0, 60.0, 140.0, 200.0], [0.0, 50.0, 100.0])
    points_mm = np.column_stack([x.ravel(), y.ravel()])
    w = np.asarray(model.interpolation(points_mm * 1e-3, "w") @ result.vectors)
    return np.asarray(result.frequency_Hz), points_mm, w / np.abs(w).max(axis=0)


def damping_of(frequency):
    """0.5 % to 1 % damping, rising with the mode number."""
    return np.linspace(0.005, 0.01, len(frequency))


def tap_signal(frequency, amplitude, duration_s, rng, noise=1e-3):
    """Impulse response sum_k A_k exp(-zeta_k w_k t) sin(w_dk t) plus white noise."""
    t = np.arange(int(round(duration_s * RATE_HZ))) / RATE_HZ
    omega = 2 * np.pi * frequency
    zeta = damping_of(frequency)
    omega_d = omega * np.sqrt(1 - zeta**2)
    h = np.sum(
        (amplitude / omega_d)[:, None]
        * np.exp(-(zeta * omega)[:, None] * t)
        * np.sin(omega_d[:, None] * t),
        axis=0,
    )
    return t, h + rng.normal(0, noise * np.abs(h).max(), h.size)


def run_import(capsys, test, sheet, out, *extra):
    """`bayesplate import` through cli.main: (exit status, stdout, stderr)."""
    status = main(["import", str(test), "--plate", str(sheet), "-o", str(out), *map(str, extra)])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def assert_refused(status, err, *names):
    """Exit status 2 and one error line naming every one of `names`, no traceback."""
    assert status == 2
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("bayesplate: error:")]
    assert len(errors) == 1, err
    for name in names:
        assert name in errors[0], (name, errors[0])


# ------------------------------------------------------------------------- impulse recordings


@pytest.mark.parametrize("kind", ["wav", "csv", "csv-short"])
def test_synthetic_tap_gives_the_model_frequencies(tmp_path, capsys, sheet, plate1, rng, kind):
    frequency, _, w = plate1
    corner = w[0]  # response and tap at the corner (0, 0): no mode has a node there
    duration = 0.1 if kind == "csv-short" else 0.5  # short: not decayed, exponential window
    t, h = tap_signal(frequency, corner * corner, duration, rng)
    if kind == "wav":
        test = tmp_path / "tap.wav"
        wavfile.write(test, int(RATE_HZ), (h / np.abs(h).max()).astype(np.float32))
    else:
        test = tmp_path / "tap.csv"
        rows = "\n".join(f"{a:.17g},{b:.17g}" for a, b in zip(t, h, strict=True))
        test.write_text("# a synthetic tap\ntime_s,signal\n" + rows + "\n")
    assert is_tap_test(test)
    out = tmp_path / "case.toml"

    status, stdout, err = run_import(capsys, test, sheet, out)

    assert status == 0, err
    assert "10 stable poles taken automatically" in stdout
    assert ("exponential window" in stdout) == (kind == "csv-short")
    case = load_case(out)
    error = case.measured.frequency_Hz / frequency - 1
    print(f"{kind}: max frequency error {100 * np.abs(error).max():.4f} %")
    assert np.abs(error).max() < FREQUENCY_RTOL, error
    lower, upper, top = prior_band_Hz(sheet_case(sheet), 10)  # the CLI's default band
    spectra = read_spectra(test)  # the library path agrees with the CLI
    poles = extract_poles(spectra, (lower, top), keep_below_Hz=upper).kept
    modal = modal_data_from_poles(spectra, poles, (lower, top))
    written = [
        to_digits(f, s) for f, s in zip(modal.frequency_Hz, case.measured.sigma_Hz, strict=True)
    ]
    np.testing.assert_array_equal(written, case.measured.frequency_Hz)  # to its digits
    np.testing.assert_allclose(modal.damping, damping_of(frequency), rtol=0.2)


def test_tap_with_a_force_channel_gives_h1(tmp_path, capsys, sheet, plate1, rng):
    frequency, _, w = plate1
    t, h = tap_signal(frequency, w[0] * w[0], 0.5, rng, noise=0.0)
    force = np.where(t < 1e-4, np.sin(np.pi * t / 1e-4), 0.0)  # a 0.1 ms half-sine tap
    n = 2 * t.size
    response = np.fft.irfft(np.fft.rfft(h, n) * np.fft.rfft(force, n), n)[: t.size]
    response += rng.normal(0, 1e-3 * np.abs(response).max(), t.size)
    test = tmp_path / "tap.wav"
    stereo = np.column_stack([response / np.abs(response).max(), force]).astype(np.float32)
    wavfile.write(test, int(RATE_HZ), stereo)
    out = tmp_path / "case.toml"

    status, stdout, err = run_import(capsys, test, sheet, out)

    assert status == 0, err
    assert "H1 = conj(F) Y / |F|^2" in stdout
    error = load_case(out).measured.frequency_Hz / frequency - 1
    print(f"force channel: max frequency error {100 * np.abs(error).max():.4f} %")
    assert np.abs(error).max() < FREQUENCY_RTOL, error


# ------------------------------------------------------------------------------- UFF 58 FRFs


def receptance(frequency, w, ref, axis_Hz):
    """H_j(f) = sum_k w_jk w_ref,k / (omega_k^2 - omega^2 + 2 i zeta_k omega_k omega)."""
    omega = 2 * np.pi * axis_Hz[None, :, None]
    omega_k = 2 * np.pi * frequency
    zeta = damping_of(frequency)
    modal = (w * w[ref])[:, None, :] / (omega_k**2 - omega**2 + 2j * zeta * omega_k * omega)
    return modal.sum(axis=2)


def write_uff58(path, points_mm, frf, axis_Hz):
    """Nodes (dataset 15) and one dataset 58 receptance per response node, reference node 1."""
    p = len(points_mm)
    sets = [
        pyuff.prepare_15(
            node_nums=list(range(1, p + 1)),
            def_cs=[0] * p,
            disp_cs=[0] * p,
            color=[0] * p,
            x=[float(v) for v in points_mm[:, 0]],
            y=[float(v) for v in points_mm[:, 1]],
            z=[0.0] * p,
        )
    ]
    for j in range(p):
        sets.append(
            pyuff.prepare_58(
                func_type=4,
                rsp_node=j + 1,
                rsp_dir=3,
                ref_node=1,
                ref_dir=3,
                ord_data_type=6,
                abscissa_spacing=1,
                abscissa_spec_data_type=18,
                ordinate_spec_data_type=8,
                orddenom_spec_data_type=13,
                data=frf[j],
                x=axis_Hz,
                id1="FRF",
                rsp_ent_name="pt",
                ref_ent_name="pt",
            )
        )
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    return path


def test_uff58_round_trip_frequencies_and_shapes(tmp_path, capsys, sheet, plate1, rng):
    frequency, points_mm, w = plate1
    axis = np.arange(0, 8000.0 + 1, 4.0)
    frf = receptance(frequency, w, 0, axis)
    frf += rng.normal(0, 1e-4 * np.abs(frf).max(), frf.shape) * (1 + 1j)
    test = write_uff58(tmp_path / "frf.uff", points_mm, frf, axis)
    assert is_tap_test(test)
    data = read_uff_frf(test)
    assert data.frf.shape == (12, axis.size) and data.form == "receptance"
    np.testing.assert_array_equal(data.points_mm, points_mm)
    out = tmp_path / "case.toml"

    status, stdout, _ = run_import(capsys, test, sheet, out)

    assert status == 0, stdout
    assert stdout.splitlines()[-1] == f"10 modes, 12 points from {test} -> {out}"
    case = load_case(out)
    error = case.measured.frequency_Hz / frequency - 1
    mac = np.diag(mac_matrix(case.measured.shapes.T, w))
    print(f"UFF 58: max frequency error {100 * np.abs(error).max():.4f} %, min MAC {mac.min():.6f}")
    assert np.abs(error).max() < FREQUENCY_RTOL, error
    assert np.all(mac > 0.9), mac


# ----------------------------------------------------------------------------- the poles file


def test_poles_file_edit_and_use(tmp_path, capsys, sheet, plate1, rng):
    frequency, _, w = plate1
    t, h = tap_signal(frequency, w[0] * w[0], 0.5, rng)
    test = tmp_path / "tap.wav"
    wavfile.write(test, int(RATE_HZ), (h / np.abs(h).max()).astype(np.float32))
    poles, chart, out = tmp_path / "poles.csv", tmp_path / "chart.png", tmp_path / "case.toml"

    status, stdout, _ = run_import(capsys, test, sheet, out, "--poles", poles, "--chart", chart)

    assert status == 0
    assert chart.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = poles.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("keep,"))
    rows = lines[header + 1 :]
    assert len(rows) >= 10 and sum(row.startswith("1,") for row in rows) == 10
    kept_rows = [row for row in rows if row.startswith("1,")]
    dropped = kept_rows[2]
    poles.write_text("\n".join(line for line in lines if line != dropped) + "\n")
    out2 = tmp_path / "case2.toml"

    status, stdout, _ = run_import(capsys, test, sheet, out2, "--use-poles", poles)

    assert status == 0
    assert "9 poles kept" in stdout
    expected = [float(row.split(",")[1]) for row in kept_rows if row != dropped]
    measured = load_case(out2).measured  # written to the digits its spread supports
    written = [to_digits(f, s) for f, s in zip(expected, measured.sigma_Hz, strict=True)]
    np.testing.assert_array_equal(measured.frequency_Hz, written)
    assert measured.p_spurious is not None  # the poles file carries the evidence
    assert [p.frequency_Hz for p in read_poles(poles)] == expected

    # marking a row 0 leaves it out too
    poles.write_text(poles.read_text().replace(kept_rows[0], "0" + kept_rows[0][1:]))
    assert [p.frequency_Hz for p in read_poles(poles)] == expected[1:]


@pytest.mark.parametrize(
    "text, names",
    [
        ("keep,frequency_Hz\n1,100.0\n", ["line 1, column damping", "missing"]),
        ("keep,frequency_Hz,damping\nmaybe,100.0,0.01\n", ["line 2, column keep", "1 or 0"]),
        ("keep,frequency_Hz,damping\n1,abc,0.01\n", ["line 2, column frequency_Hz", "number"]),
        ("keep,frequency_Hz,damping\n1,100.0\n", ["line 2", "comma-separated"]),
        ("keep,frequency_Hz,damping\n0,100.0,0.01\n", ["keep", "no pole is kept"]),
        ("keep,frequency_Hz,damping\n1,100.0,1.5\n", ["line 2, column damping", "< 1"]),
    ],
)
def test_malformed_poles_file_is_refused_in_one_line(tmp_path, capsys, sheet, rng, text, names):
    t, h = tap_signal(np.array([1000.0, 2500.0]), np.ones(2), 0.1, rng)
    test = tmp_path / "tap.wav"
    wavfile.write(test, int(RATE_HZ), h.astype(np.float32))
    poles = tmp_path / "poles.csv"
    poles.write_text(text)
    out = tmp_path / "case.toml"
    status, _, err = run_import(capsys, test, sheet, out, "--use-poles", poles)
    assert_refused(status, err, "poles.csv", *names)
    assert not out.exists()


# --------------------------------------------------------------------------- corrupted inputs


def corrupted(tmp_path, kind, rng):
    """A corrupted tap test file and what its error must name."""
    if kind == "truncated-wav":
        _, h = tap_signal(np.array([1000.0]), np.ones(1), 0.1, rng)
        path = tmp_path / "tap.wav"
        wavfile.write(path, int(RATE_HZ), h.astype(np.float32))
        path.write_bytes(path.read_bytes()[:30])
        return path, ["tap.wav", "not a readable WAV file"], []
    if kind == "short-wav":
        path = tmp_path / "tap.wav"
        wavfile.write(path, int(RATE_HZ), np.ones(10, dtype=np.float32))
        return path, ["tap.wav", "signal = 10", "at least 64 samples"], []
    if kind == "csv-no-signal":
        path = tmp_path / "tap.csv"
        path.write_text("time_s,force\n" + "".join(f"{i / 1e4},0.0\n" for i in range(100)))
        return path, ["tap.csv", "line 1, column signal", "required column"], []
    if kind == "csv-uneven-time":
        path = tmp_path / "tap.csv"
        path.write_text("time_s,signal\n" + "".join(f"{i**1.5},1.0\n" for i in range(100)))
        return path, ["tap.csv", "column time_s", "evenly spaced"], []
    if kind == "frf-csv-no-im":
        path = tmp_path / "frf.csv"
        path.write_text("frequency_Hz,H1_re\n" + "".join(f"{i},1.0\n" for i in range(100)))
        return path, ["frf.csv", "line 1, column H1_im", "required column"], []
    if kind == "uff-without-58":
        path = tmp_path / "modes.uff"
        p = 3
        pyuff.UFF(str(path)).write_sets(
            [
                pyuff.prepare_15(
                    node_nums=[1, 2, 3],
                    def_cs=[0] * p,
                    disp_cs=[0] * p,
                    color=[0] * p,
                    x=[0.0, 1.0, 2.0],
                    y=[0.0] * p,
                    z=[0.0] * p,
                )
            ],
            mode="overwrite",
        )
        return path, ["modes.uff", "dataset 58", "no dataset 58"], ["--poles", tmp_path / "p.csv"]
    raise AssertionError(kind)


KINDS = [
    "truncated-wav",
    "short-wav",
    "csv-no-signal",
    "csv-uneven-time",
    "frf-csv-no-im",
    "uff-without-58",
]


@pytest.mark.parametrize("kind", KINDS)
def test_corrupted_tap_test_is_refused_in_one_line(tmp_path, capsys, sheet, rng, kind):
    path, names, extra = corrupted(tmp_path, kind, rng)
    out = tmp_path / "case.toml"
    status, _, err = run_import(capsys, path, sheet, out, *extra)
    assert_refused(status, err, *names)
    assert not out.exists()
    assert not Path(tmp_path / "p.csv").exists()


def test_readers_and_options_refuse_bad_values(tmp_path, plate1, rng):
    frequency, _, w = plate1
    _, h = tap_signal(frequency[:2], np.ones(2), 0.05, rng)
    path = tmp_path / "tap.wav"
    wavfile.write(path, int(RATE_HZ), h.astype(np.float32))
    data = read_impulse(path)
    with pytest.raises(CaseError, match=r"--band = \[10.0, 1000000.0\]: must lie within the data"):
        extract_poles(data, band_Hz=(10.0, 1e6))
    with pytest.raises(CaseError, match=r"--order = 1: must be an integer from 7"):
        extract_poles(data, order=1)
    with pytest.raises(CaseError, match="--window"):
        read_impulse(path, window="hann")
    frf_csv = tmp_path / "frf.csv"
    axis = np.arange(0, 4000.0, 4.0)
    H = receptance(frequency[:3], w[:, :3], 0, axis)[0]
    rows = "".join(f"{f:.17g},{z.real:.17g},{z.imag:.17g}\n" for f, z in zip(axis, H, strict=True))
    frf_csv.write_text("frequency_Hz,H1_re,H1_im\n" + rows)
    data = read_frf_csv(frf_csv)
    assert data.frf.shape == (1, axis.size) and data.points_mm is None
    modal = modal_data_from_poles(data, extract_poles(data, order=30).kept)
    np.testing.assert_allclose(modal.frequency_Hz, frequency[:3], rtol=FREQUENCY_RTOL)
    assert modal.shapes is None
