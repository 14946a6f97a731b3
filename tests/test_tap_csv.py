"""Tap recordings as a lab writes them (issue 37): CSV time series with DAQ column names.

The reference is independent of the CSV reader: the same samples as a WAV file (the source
lab's 5R tap in tests/data/taps_5R, and synthetic taps written both ways).
"""

import contextlib
import io
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from bayesplate.cli import main
from bayesplate.io import CaseError, bundled_case_path, load_case
from bayesplate.io.impulse import is_recording, read_recording
from bayesplate.io.modal_file import is_tap_test
from bayesplate.io.taps import read_taps

DATA = Path(__file__).parent / "data" / "taps_5R"
RATE_HZ = 48000.0
MODES_HZ = np.array([611.23, 2002.7, 2171.2])  # plate1's first three
BAND = ("300", "2300")


def synthetic_tap(n=12000, rate_Hz=RATE_HZ):
    """A hammer tap (half-sine force, 0.2 ms) on three damped modes: float32 (force, response)."""
    t = np.arange(n) / rate_Hz
    pulse = np.sin(np.pi * t[t < 2e-4] / 2e-4)
    omega = 2 * np.pi * MODES_HZ
    h = np.sum(np.exp(-0.01 * omega[:, None] * t) * np.sin(omega[:, None] * t), axis=0)
    force = np.zeros(n)
    force[10 : 10 + pulse.size] = pulse
    response = np.convolve(force, h)[:n] / rate_Hz
    return force.astype(np.float32), (response / np.abs(response).max()).astype(np.float32)


def write_csv(path, header, columns, formats, separator=","):
    """A CSV of `columns` (one format each); float32 values written exactly (repr of float)."""
    columns = [np.asarray(column, dtype=float).tolist() for column in columns]
    rows = [
        separator.join(f.format(v) for f, v in zip(formats, row, strict=True))
        for row in zip(*columns, strict=True)
    ]
    path.write_text(separator.join(header) + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.fixture(scope="module")
def wav_frequencies(tmp_path_factory):
    """The frequencies `bayesplate import` finds in the synthetic tap as a WAV file."""
    folder = tmp_path_factory.mktemp("wav")
    force, response = synthetic_tap()
    wav = folder / "tap.wav"
    wavfile.write(wav, int(RATE_HZ), np.column_stack([response, force]))
    text = bundled_case_path("plate1").read_text()
    sheet = folder / "sheet.toml"
    sheet.write_text(re.sub(r"frequency_Hz = \[[^\]]*\]\n", "", text))
    argv = ["import", str(wav), "--plate", str(sheet), "-o", str(folder / "case.toml")]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main([*argv, "--band", *BAND]) == 0
    return load_case(folder / "case.toml").measured.frequency_Hz


def run_import(capsys, tests, sheet, out, *extra):
    """`bayesplate import` through cli.main: (exit status, stdout, stderr)."""
    tests = [tests] if isinstance(tests, (str, Path)) else tests
    argv = ["import", *map(str, tests), "--plate", str(sheet), "-o", str(out), *map(str, extra)]
    try:
        status = main(argv)
    except SystemExit as exit_:  # a usage error
        status = exit_.code
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def assert_refused(status, err, *names):
    """Exit status 2 and one error line naming every one of `names`, no traceback."""
    assert status == 2
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and re.match(r"bayesplate( import)?: error: ", lines[0]), err
    for name in names:
        assert name in lines[0], (name, lines[0])


# ----------------------------------------------------------------------- the lab's own file


def test_the_5R_csv_as_recorded_gives_the_wav_samples_and_frf():
    csv, wav = DATA / "tap1_as_recorded.csv", DATA / "tap1.wav"
    assert is_recording(csv) and is_tap_test(csv)
    from_csv = read_recording(csv, rate_Hz=RATE_HZ)
    from_wav = read_recording(wav)
    assert from_csv.rate_Hz == from_wav.rate_Hz == RATE_HZ
    assert from_csv.responses.shape == from_wav.responses.shape == (1, 96000)
    # the WAV holds the CSV's decimals as float32: the same samples, exactly, once rounded
    np.testing.assert_array_equal(from_csv.responses.astype(np.float32), from_wav.responses)
    np.testing.assert_array_equal(from_csv.force.astype(np.float32), from_wav.force)

    frf_csv, frf_wav = read_taps([csv], rate_Hz=RATE_HZ), read_taps([wav])
    np.testing.assert_array_equal(frf_csv.frequency_Hz, frf_wav.frequency_Hz)
    # one tap: H = Y / F. Rounding each sample to float32 moves it by at most 2^-24 of itself,
    # so each line of Y by eY = 2^-24 sum|y| (F likewise): |dH| <= (eY + |H| eF) / (|F| - eF)
    y, f = from_csv.responses[0], from_csv.force
    e_y, e_f = 2.0**-24 * np.abs(y).sum(), 2.0**-24 * np.abs(f).sum()
    force_spectrum = np.abs(np.fft.rfft(f))
    assert force_spectrum.min() > e_f
    h = np.abs(frf_csv.frf[0])
    bound = (e_y + h * e_f) / (force_spectrum - e_f)
    assert np.all(np.abs(frf_csv.frf[0] - frf_wav.frf[0]) <= bound)
    assert frf_csv.notes[:2] == (
        'columns read: force "force", response "acceleration"',
        "no time column: sampling rate 48000 Hz from --rate-Hz",
    )


def test_the_5R_csv_without_a_rate_is_refused_in_one_line(tmp_path, capsys, sheet):
    out = tmp_path / "case.toml"
    status, _, err = run_import(capsys, DATA / "tap1_as_recorded.csv", sheet, out)
    assert_refused(status, err, "tap1_as_recorded.csv", "no time column", "--rate-Hz")
    assert not out.exists()
    with pytest.raises(CaseError, match="--rate-Hz = 44100.0: disagrees with the WAV"):
        read_recording(DATA / "tap1.wav", rate_Hz=44100.0)


# ------------------------------------------------------------------- DAQ headers, both ways


HEADERS = [  # time, force, response as a DAQ writes them; seconds per unit of the time
    (("Time (s)", "Force (N)", "Acceleration (m/s^2)"), 1.0),
    (("time [ms]", "hammer", "mic"), 1e-3),
    (("t", "F", "a"), 1.0),
    (("TIME_S", "Impact Force", "Response"), 1.0),
    (("time_ms", "force_N", "Accel 1"), 1e-3),
    ((None, "force", "acceleration"), None),  # the source lab's: no time column
    ((None, "Hammer [N]", "velocity [mm/s]"), None),
]


@pytest.mark.parametrize("header, seconds", HEADERS)
def test_a_daq_csv_imports_as_its_wav(tmp_path, capsys, sheet, wav_frequencies, header, seconds):
    force, response = synthetic_tap()
    columns, formats, names = [force, response], ["{!r}", "{!r}"], list(header[1:])
    extra = ["--rate-Hz", "48000"] if seconds is None else []
    if seconds is not None:  # written to 9 significant digits, as a DAQ does
        columns.insert(0, np.arange(force.size) / RATE_HZ / seconds)
        formats.insert(0, "{:.9g}")
        names.insert(0, header[0])
    csv = write_csv(tmp_path / "tap.csv", names, columns, formats)
    assert is_recording(csv) and is_tap_test(csv)

    status, stdout, err = run_import(
        capsys, csv, sheet, tmp_path / "csv.toml", "--band", *BAND, *extra
    )
    assert status == 0, err
    assert f'response "{header[2]}"' in stdout and "sampling rate 48000 Hz" in stdout
    frequency = load_case(tmp_path / "csv.toml").measured.frequency_Hz
    np.testing.assert_array_equal(frequency, wav_frequencies)  # the same samples
    assert frequency.size >= 2  # the poles found depend on io.poles; the same from both


@pytest.mark.parametrize("separator", [";", "\t"])
def test_semicolons_or_tabs_separate_when_the_header_has_no_comma(tmp_path, separator):
    force, response = synthetic_tap(256)
    t = np.arange(256) / RATE_HZ
    csv = write_csv(
        tmp_path / "tap.csv",
        ["Time (s)", "Force (N)", "Acc (g)"],
        [t, force, response],
        ["{!r}"] * 3,
        separator,
    )
    assert is_recording(csv)
    rec = read_recording(csv)
    assert rec.rate_Hz == RATE_HZ
    np.testing.assert_array_equal(rec.responses[0], response)
    np.testing.assert_array_equal(rec.force, force)
    decimal_commas = tmp_path / "comma.csv"
    decimal_commas.write_text(csv.read_text().replace(".", ","))
    with pytest.raises(CaseError, match=r"line 2, column Time \(s\) = .*with a decimal point"):
        read_recording(decimal_commas)


# --------------------------------------------------------------------------- the time column


def test_a_time_column_written_to_9_decimals_at_48kHz_is_accepted(tmp_path):
    # the steps of 1/48000 s written to 1e-9 s differ by 1e-9 s: 5e-5 of a step, 50 times
    # what a fixed 1e-6 of a step allowed; each time is within 5e-10 s of its exact value
    force, response = synthetic_tap(48000)
    t = np.arange(48000) / RATE_HZ
    csv = write_csv(
        tmp_path / "tap.csv",
        ["time_s", "force", "signal"],
        [t, force, response],
        ["{:.9f}", "{!r}", "{!r}"],
    )
    steps = np.diff([float(f"{v:.9f}") for v in t])
    assert np.ptp(steps) > 1e-6 * steps.mean()  # refused before issue 37
    assert read_recording(csv).rate_Hz == RATE_HZ
    assert read_recording(csv, rate_Hz=RATE_HZ).rate_Hz == RATE_HZ
    with pytest.raises(
        CaseError,
        match=r"--rate-Hz = 48000.01: disagrees with the time column "
        r'"time_s" \(4799\d.\d+ Hz, between \d+.\d+ and \d+.\d+ Hz',
    ):
        read_recording(csv, rate_Hz=48000.01)
    csv_ms = write_csv(
        tmp_path / "ms.csv", ["Time [ms]", "Accel"], [t * 1e3, response], ["{:.6f}", "{!r}"]
    )
    assert read_recording(csv_ms).rate_Hz == RATE_HZ


UNEVEN = {
    "a sample 10 ns late": (lambda t: t + 1e-8 * (np.arange(t.size) == 5000), 5002),
    "a sample dropped": (lambda t: np.delete(t, 7000), None),
    "the clock drifting 1e-7": (lambda t: t * (1 + 1e-7 * np.arange(t.size) / t.size), None),
}


@pytest.mark.parametrize("kind", UNEVEN)
def test_an_uneven_time_column_is_refused_in_one_line(tmp_path, capsys, sheet, kind):
    damage, line = UNEVEN[kind]
    t = damage(np.arange(20000) / RATE_HZ)
    force, response = synthetic_tap(t.size)
    csv = write_csv(
        tmp_path / "tap.csv",
        ["time_s", "force", "signal"],
        [t, force, response],
        ["{:.9f}", "{!r}", "{!r}"],
    )
    out = tmp_path / "case.toml"
    status, _, err = run_import(capsys, csv, sheet, out, "--band", *BAND)
    names = ["tap.csv", "column time_s", "evenly spaced", "written decimals allow"]
    assert_refused(status, err, *names, *([f"line {line}, "] if line else []))
    assert not out.exists()


def test_a_time_column_going_back_is_refused(tmp_path):
    t = np.arange(100) / RATE_HZ
    t[[40, 41]] = t[[41, 40]]
    csv = write_csv(tmp_path / "tap.csv", ["t", "a"], [t, np.sin(t * 1e4)], ["{:.9f}", "{!r}"])
    with pytest.raises(
        CaseError,
        match=r"line 43, column t = \"0.000833333\": times must be "
        "ascending and evenly spaced; the previous is 0.000854167",
    ):
        read_recording(csv)


# ------------------------------------------------------------------ ambiguity and the options


AMBIGUOUS = [
    ("time_s,acc1,acc2", [], ["line 1", "2 response columns (acc1, acc2)", "--response-column"]),
    ("time_s,force,hammer,signal", [], ["2 force columns (force, hammer)", "--force-column"]),
    ("time_s,t,signal", [], ["2 time columns (time_s, t)"]),
    ("time_s,force", [], ["line 1, column signal", "required column", "--response-column"]),
    (
        "time_s,acc1,acc2",
        ["--response-column", "acc3"],
        ['--response-column = "acc3"', "not a column", "time_s, acc1, acc2"],
    ),
    (
        "time_s,acc1,acc2",
        ["--force-column", "acc1", "--response-column", "ACC1"],
        ['--response-column = "ACC1"', "also the --force-column"],
    ),
    ("time (min),signal", [], ["column time (min)", '"min"', "unit of the time"]),
    ("time_s,signal", ["--force-column", "force"], ["--force-column", "not a column"]),
]


@pytest.mark.parametrize("header, extra, names", AMBIGUOUS)
def test_an_ambiguous_header_is_refused_in_one_line(tmp_path, capsys, sheet, header, extra, names):
    n = len(header.split(","))
    rows = "".join(f"{i / RATE_HZ:.9f}" + ",1.0" * (n - 1) + "\n" for i in range(100))
    csv = tmp_path / "tap.csv"
    csv.write_text(header + "\n" + rows)
    out = tmp_path / "case.toml"
    status, _, err = run_import(capsys, csv, sheet, out, "--band", *BAND, *extra)
    assert_refused(status, err, "tap.csv", *names)
    assert not out.exists()


def test_the_column_options_pick_the_columns(tmp_path, capsys, sheet):
    force, response = synthetic_tap()
    t = np.arange(force.size) / RATE_HZ
    csv = write_csv(
        tmp_path / "tap.csv",
        ["time_s", "acc1", "acc2", "ch3"],
        [t, response, -response, force],
        ["{:.9f}", "{!r}", "{!r}", "{!r}"],
    )
    status, stdout, err = run_import(
        capsys,
        csv,
        sheet,
        tmp_path / "case.toml",
        "--band",
        *BAND,
        "--response-column",
        "ACC2",
        "--force-column",
        "ch3",
    )
    assert status == 0, err
    assert 'columns read: time "time_s", force "ch3", response "acc2"; ignored: "acc1"' in stdout
    rec = read_recording(csv, force_column="ch3", response_column="acc2")
    np.testing.assert_array_equal(rec.responses[0], -response)
    np.testing.assert_array_equal(rec.force, force)
    no_names = write_csv(tmp_path / "ch.csv", ["ch0", "ch1"], [force, response], ["{!r}"] * 2)
    assert not is_recording(no_names) and is_recording(no_names, ["ch1"])
    rec = read_recording(no_names, rate_Hz=RATE_HZ, force_column="ch0", response_column="ch1")
    np.testing.assert_array_equal(rec.responses[0], response)


def test_csv_options_are_refused_for_a_wav_or_frfs(tmp_path, capsys, sheet):
    force, response = synthetic_tap()
    wav = tmp_path / "tap.wav"
    wavfile.write(wav, int(RATE_HZ), np.column_stack([response, force]))
    out = tmp_path / "case.toml"
    status, _, err = run_import(
        capsys, wav, sheet, out, "--band", *BAND, "--response-column", "signal"
    )
    assert_refused(status, err, "tap.wav", "--response-column", "CSV time series")
    status, _, err = run_import(capsys, wav, sheet, out, "--band", *BAND, "--rate-Hz", "44100")
    assert_refused(status, err, "tap.wav", "--rate-Hz = 44100.0", "48000 Hz")
    frf = tmp_path / "frf.csv"
    frf.write_text("frequency_Hz,H1_re,H1_im\n" + "".join(f"{i},1.0,0.5\n" for i in range(64)))
    status, _, err = run_import(capsys, frf, sheet, out, "--band", *BAND, "--rate-Hz", "48000")
    assert_refused(status, err, "frf.csv", "--rate-Hz", "holds FRFs")
    status, _, err = run_import(capsys, wav, sheet, out, "--band", *BAND, "--rate-Hz", "-5")
    assert_refused(status, err, "--rate-Hz", "'-5': must be a positive number")
    assert not out.exists()


def test_recordings_frfs_and_modes_are_told_apart(tmp_path):
    texts = {
        "modes.csv": ("frequency_Hz,sigma_Hz,mode", False, False),
        "frf.csv": ("frequency_Hz,H1_re,H1_im", False, True),
        "frf2.csv": ("Frequency (Hz),acceleration", False, False),
        "lab.csv": ("force,acceleration", True, True),
        "mic.csv": ("Time (s);Microphone (Pa)", True, True),
        "ch.csv": ("ch0,ch1", False, False),
        "tap.csv": ("time_s,signal", True, True),
    }
    for name, (header, recording, tap) in texts.items():
        path = tmp_path / name
        path.write_text(f"# a comment\n{header}\n1,2,3\n")
        assert (is_recording(path), is_tap_test(path)) == (recording, tap), name


def test_csv_taps_with_time_columns_share_their_rate_and_average(tmp_path):
    # the last times written to 9 decimals give 48000.00000x Hz, a different x in each file;
    # the shortest rate within each file's precision is 48000 in both, so they average
    paths = []
    for k, start in enumerate((0.0, 0.123456789)):
        force, response = synthetic_tap(20000)
        t = start + np.arange(force.size) / RATE_HZ
        paths.append(
            write_csv(
                tmp_path / f"tap{k}.csv",
                ["Time (s)", "Force (N)", "Acc (g)"],
                [t, force, response],
                ["{:.9f}", "{!r}", "{!r}"],
            )
        )
    data = read_taps(paths)
    assert data.coherence is not None
    np.testing.assert_array_equal(data.frequency_Hz, np.fft.rfftfreq(20000, 1 / RATE_HZ))
