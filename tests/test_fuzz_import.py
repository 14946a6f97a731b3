"""Fuzzing `bayesplate import`: CSV tables, UFF files, FRFs, impulse recordings, poles files.

Impulse recordings include CSV time series as a DAQ writes them (issue 37): the column
names, units, separators and time formats of :mod:`bayesplate.io.time_csv`, with and without
``--rate-Hz``, ``--force-column`` and ``--response-column``.

Each valid test file is damaged at one place (a cell, a line, a byte, a dataset number, the
units, a non-ASCII character, a cut). The in-process readers are the oracle: a damage they
accept is not a corruption (a cut after the last row) and is not counted; anything else they
raise but :class:`~bayesplate.io.CaseError` fails the test (a traceback). Every damage they
refuse must be refused by ``bayesplate import`` in one line naming the file (see
:func:`test_fuzz_cli.assert_refused_cleanly`), with no case file, poles file or chart written.
"""

import io
import string
import tempfile
from pathlib import Path

import numpy as np
import pyuff
from hypothesis import given
from hypothesis import strategies as st
from scipy.io import wavfile
from test_fuzz_cli import assert_refused_cleanly, fuzz_settings

from bayesplate.io import CaseError, bundled_plate_path, case_from_modal_data
from bayesplate.io.impulse import is_recording
from bayesplate.io.modal_file import is_tap_test, read_modal_data, read_spectra
from bayesplate.io.poles_file import read_poles
from bayesplate.io.taps import read_taps

SHEET = bundled_plate_path("frederiksen_plate")
RATE_HZ = 8192.0


def _accepted(path, reader):
    """Whether the in-process reader accepts `path` (CaseError: no; anything else: fails)."""
    try:
        reader(path)
    except CaseError as err:
        assert "\n" not in str(err)
        return False
    return True


def _modes_reader(path):
    if is_tap_test(path):
        return read_spectra(path)
    return case_from_modal_data(SHEET, read_modal_data(path))


def _import_refused(ledger, path, names=(), extra=(), reader=_modes_reader, inputs=()):
    """Refused by the reader => refused cleanly by `bayesplate import`; returns whether tried."""
    if _accepted(path, reader):
        return False
    out = path.with_name("case.toml")
    poles, chart = path.with_name("poles_out.csv"), path.with_name("chart.png")
    argv = ["import", path, "--plate", SHEET, "-o", out, *extra]
    if is_tap_test(path):
        argv += ["--poles", poles, "--chart", chart]
    assert_refused_cleanly(ledger, argv, [path, *inputs], [out, poles, chart], [path.name, *names])
    return True


# ----------------------------------------------------------------------------- byte damage


def _damage_bytes(data, text: bytes) -> bytes:
    """One damage of a file's bytes: a cut, a non-UTF-8 or non-ASCII insert, a flipped byte."""
    kind = data.draw(st.sampled_from(["cut", "latin-1", "non-ascii", "flip", "nul", "empty"]))
    at = data.draw(st.integers(0, max(len(text) - 1, 0)))
    if kind == "cut":
        return text[:at]
    if kind == "latin-1":
        return text[:at] + "µ°é".encode("latin-1") + text[at:]
    if kind == "non-ascii":
        return (
            text[:at]
            + data.draw(st.sampled_from(["µm", "é", "１", "\u2212", "😀"])).encode()
            + text[at:]
        )
    if kind == "flip":
        return text[:at] + bytes([text[at] ^ data.draw(st.integers(1, 255))]) + text[at + 1 :]
    if kind == "nul":
        return text[:at] + b"\0" + text[at:]
    return b""


def _damage_lines(data, text: str) -> str:
    """One to three line operations: delete, duplicate, replace with junk, truncate."""
    lines = text.splitlines(keepends=True)
    for _ in range(data.draw(st.integers(1, 3))):
        if not lines:
            break
        i = data.draw(st.integers(0, len(lines) - 1))
        action = data.draw(st.sampled_from(["delete", "duplicate", "replace", "truncate"]))
        if action == "delete":
            del lines[i]
        elif action == "duplicate":
            lines.insert(i, lines[i])
        elif action == "replace":
            lines[i] = data.draw(st.text(string.printable + "µé°", max_size=30)) + "\n"
        else:
            lines = lines[:i]
    return "".join(lines)


# ----------------------------------------------------------------------------- CSV tables

CSV_TEXT = "frequency_Hz,sigma_Hz,mode\n" + "".join(
    f"{f},{f / 100},{m}\n" for f, m in [(120.5, 1), (310.0, 2), (455.25, 4), (470.0, 3)]
)
BAD_CELLS = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "abc",
    "",
    "1e400",
    "1e30",
    "1e-30",
    "0x10",
    "2.5.1",
    "--3",
    "µ",
    "1 2",
    "true",
    "1_000",
]


@fuzz_settings(150)
@given(data=st.data())
def test_a_damaged_frequency_table_is_refused(fuzz_ledger, data):
    rows = [line.split(",") for line in CSV_TEXT.splitlines()]
    kind = data.draw(st.sampled_from(["cell", "cells", "header", "bytes", "lines", "order"]))
    names = []
    if kind in ("cell", "cells"):
        for _ in range(1 if kind == "cell" else data.draw(st.integers(2, 4))):
            i = data.draw(st.integers(1, len(rows) - 1))
            j = data.draw(st.integers(0, 2))
            rows[i][j] = data.draw(st.sampled_from(BAD_CELLS))
        text = ("\n".join(",".join(r) for r in rows) + "\n").encode()
    elif kind == "header":
        j = data.draw(st.integers(0, 2))
        rows[0][j] = data.draw(
            st.sampled_from(
                [
                    "frequency_kHz",
                    "freq",
                    "sigma_%",
                    "",
                    "mode",
                    "frequency_Hz",
                    "Frequency_Hz",
                    "sigma_rel",
                ]
            )
        )
        text = ("\n".join(",".join(r) for r in rows) + "\n").encode()
        names = ["line 1"] if rows[0][j] != "sigma_rel" else []
    elif kind == "order":
        rows[1], rows[3] = rows[3], rows[1]
        text = ("\n".join(",".join(r) for r in rows) + "\n").encode()
        names = ["column frequency_Hz", "ascending"]
    elif kind == "bytes":
        text = _damage_bytes(data, CSV_TEXT.encode())
    else:
        text = _damage_lines(data, CSV_TEXT).encode()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp, "t.csv")
        path.write_bytes(text)
        _import_refused(fuzz_ledger, path, names)


# ----------------------------------------------------------------------------- UFF modes


def _uff_modes_text():
    """Two modes at three nodes, in mm, with a dataset 164 (units): a valid UFF file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp, "m.uff")
        p = 3
        sets = [
            pyuff.prepare_164(
                units_code=1,
                units_description="SI",
                temp_mode=1,
                length=1.0,
                force=1.0,
                temp=1.0,
                temp_offset=273.15,
            ),
            pyuff.prepare_15(
                node_nums=[1, 2, 3],
                def_cs=[0] * p,
                disp_cs=[0] * p,
                color=[0] * p,
                x=[0.0, 0.05, 0.1],
                y=[0.0, 0.02, 0.05],
                z=[0.0] * p,
            ),
        ]
        for n, (f, shape) in enumerate([(300.0, [1.0, 0.5, -1.0]), (500.0, [-1.0, 2.0, 1.0])]):
            sets.append(
                pyuff.prepare_55(
                    model_type=1,
                    id1="NONE",
                    id2="NONE",
                    id3="NONE",
                    id4="NONE",
                    id5="NONE",
                    data_ch=2,
                    spec_data_type=8,
                    n_data_per_node=3,
                    node_nums=np.arange(1, 4),
                    load_case=1,
                    mode_n=n + 1,
                    analysis_type=2,
                    data_type=2,
                    r1=np.zeros(p),
                    r2=np.zeros(p),
                    r3=np.array(shape),
                    freq=f,
                    modal_m=1.0,
                    modal_damp_vis=0.01,
                    modal_damp_his=0.0,
                )
            )
        pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
        return path.read_text()


UFF_TEXT = _uff_modes_text()


def _uff_field_damage(data, text):
    """Dataset numbers, units, record fields changed to wrong or absurd values."""
    kind = data.draw(st.sampled_from(["dataset", "units", "frequency", "number"]))
    if kind == "dataset":
        old = data.draw(st.sampled_from(["    55", "    15", "   164"]))
        new = data.draw(
            st.sampled_from(["    58", "    56", "    16", "  2412", "    -1", "  abcd"])
        )
        return text.replace(f"\n{old}\n", f"\n{new}\n", 1)
    if kind == "units":  # dataset 164 record 2: the length factor (m per unit)
        line = next(ln for ln in text.splitlines() if ln.strip().startswith("1.00000000000000"))
        bad = data.draw(st.sampled_from(["0.0", "-1.0", "nan", "inf", "1e300", "abc", "1e-300"]))
        return text.replace(line, line.replace("1.00000000000000", f"{bad:>16}", 1), 1)
    if kind == "frequency":
        bad = data.draw(
            st.sampled_from(
                [
                    "          nan",
                    "         -300",
                    "        1e+30",
                    "        1e-30",
                    "            0",
                    "  3.0000xe+02",
                ]
            )
        )
        return text.replace("  3.00000e+02", bad, 1)
    numbers = [tok for tok in set(text.split()) if tok.replace(".", "").replace("-", "").isdigit()]
    tok = data.draw(st.sampled_from(sorted(numbers)))
    return text.replace(f" {tok}", " " + data.draw(st.sampled_from(["-9", "nan", "x", "99999"])), 1)


@fuzz_settings(150)
@given(data=st.data())
def test_a_damaged_uff_file_is_refused(fuzz_ledger, data):
    kind = data.draw(st.sampled_from(["fields", "bytes", "lines"]))
    if kind == "fields":
        text = _uff_field_damage(data, UFF_TEXT).encode()
    elif kind == "bytes":
        text = _damage_bytes(data, UFF_TEXT.encode())
    else:
        text = _damage_lines(data, UFF_TEXT).encode()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp, "m.uff")
        path.write_bytes(text)
        _import_refused(fuzz_ledger, path)


# ----------------------------------------------------------------------------- tap tests


def _impulse(n=2048):
    t = np.arange(n) / RATE_HZ
    return t, np.exp(-30 * t) * (np.sin(2 * np.pi * 700 * t) + 0.5 * np.sin(2 * np.pi * 1900 * t))


def _frf_csv_text():
    f = np.arange(0.0, 4000.0, 8.0)
    s = 2j * np.pi * f
    h = sum(
        1 / ((2 * np.pi * fk) ** 2 + 2 * 0.01 * 2 * np.pi * fk * s + s**2) for fk in (700, 1900)
    )
    rows = "".join(f"{a:.10g},{z.real:.10g},{z.imag:.10g}\n" for a, z in zip(f, h, strict=True))
    return "frequency_Hz,H1_re,H1_im\n" + rows


def _impulse_csv_text():
    t, y = _impulse(256)
    return "time_s,signal\n" + "".join(f"{a:.10g},{b:.10g}\n" for a, b in zip(t, y, strict=True))


TAP_TEXTS = {"frf.csv": _frf_csv_text(), "tap.csv": _impulse_csv_text()}


def _wav_bytes(data):
    t, y = _impulse()
    kind = data.draw(st.sampled_from(["channels", "short", "nan", "zeros", "rate", "bytes"]))
    signal, rate = y.astype(np.float32), int(RATE_HZ)
    if kind == "channels":
        signal = np.column_stack([signal] * data.draw(st.sampled_from([3, 4])))
    elif kind == "short":
        signal = signal[: data.draw(st.integers(1, 63))]
    elif kind == "nan":
        signal[data.draw(st.integers(0, signal.size - 1))] = data.draw(
            st.sampled_from([np.nan, np.inf])
        )
    elif kind == "zeros":
        signal[:] = 0
    elif kind == "rate":
        rate = data.draw(st.sampled_from([0, 1]))
    buffer = io.BytesIO()
    wavfile.write(buffer, rate, signal)
    raw = buffer.getvalue()
    return _damage_bytes(data, raw) if kind == "bytes" else raw


@fuzz_settings(150)
@given(data=st.data())
def test_a_damaged_tap_test_is_refused(fuzz_ledger, data):
    name = data.draw(st.sampled_from(["frf.csv", "tap.csv", "tap.wav"]))
    if name == "tap.wav":
        raw = _wav_bytes(data)
    else:
        text = TAP_TEXTS[name]
        kind = data.draw(st.sampled_from(["cell", "bytes", "lines", "axis"]))
        if kind == "cell":
            lines = text.splitlines()
            i = data.draw(st.integers(1, len(lines) - 1))
            cells = lines[i].split(",")
            cells[data.draw(st.integers(0, len(cells) - 1))] = data.draw(st.sampled_from(BAD_CELLS))
            lines[i] = ",".join(cells)
            raw = ("\n".join(lines) + "\n").encode()
        elif kind == "axis":  # the first column no longer evenly spaced or ascending
            lines = text.splitlines()
            i = data.draw(st.integers(2, len(lines) - 2))
            lines[i], lines[i + 1] = lines[i + 1], lines[i]
            raw = ("\n".join(lines) + "\n").encode()
        elif kind == "bytes":
            raw = _damage_bytes(data, text.encode())
        else:
            raw = _damage_lines(data, text).encode()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp, name)
        path.write_bytes(raw)
        _import_refused(fuzz_ledger, path, reader=read_spectra)


# ----------------------------------------------------------------------------- DAQ CSV taps

DAQ_HEADERS = [
    ("Time (s)", "Force (N)", "Acceleration (m/s^2)"),
    ("time [ms]", "hammer", "mic"),
    ("t", "F", "a"),
    ("time_s", "force", "signal"),
    (None, "force", "acceleration"),
    (None, "Hammer [N]", "Accel 1"),
]
DAQ_NAMES = ["acc", "acc2", "force", "Time (min)", "time_s", "t", "", "frequency_Hz", "H1_re"]
DAQ_NAMES += ["signal", "Velocity (mm/s)", "ch0", "F", "a", "Time [us]", '"mic"', "time;s"]
DAQ_CELLS = BAD_CELLS + ["1,5", "0,001", "1e-3;", "１", "\u2212" + "1", '"1"', "1e5", "0e99999"]


def _daq_csv(data):
    """A DAQ-style CSV tap (header, separator, time format drawn) and its options."""
    header = data.draw(st.sampled_from(DAQ_HEADERS))
    separator = data.draw(st.sampled_from([",", ";", "\t"]))
    t, y = _impulse(256)
    force = np.where(np.arange(t.size) < 4, 1.0, 0.0)
    columns = [f"{a!r}{separator}{b!r}" for a, b in zip(force.tolist(), y.tolist(), strict=True)]
    options = {}
    if header[0] is None:
        options["rate_Hz"] = data.draw(st.sampled_from([RATE_HZ, 8000.0, 1e-3]))
    else:
        scale = 1e3 if "ms" in header[0] else 1.0
        form = data.draw(st.sampled_from(["{:.9f}", "{:.10g}", "{!r}", "{:.4f}"]))
        columns = [form.format(a * scale) + separator + c for a, c in zip(t, columns, strict=True)]
        if data.draw(st.booleans()):
            options["rate_Hz"] = data.draw(st.sampled_from([RATE_HZ, 8000.0]))
    names = separator.join(name for name in header if name is not None)
    return names + "\n" + "\n".join(columns) + "\n", separator, options


def _daq_damage(data, text, separator, options):
    """One damage of a DAQ CSV: a cell, a header name, an option, the lines, the bytes."""
    lines = text.splitlines()
    kind = data.draw(
        st.sampled_from(["cell", "header", "option", "axis", "bytes", "lines", "body"])
    )
    if kind == "cell":
        i = data.draw(st.integers(1, len(lines) - 1))
        cells = lines[i].split(separator)
        cells[data.draw(st.integers(0, len(cells) - 1))] = data.draw(st.sampled_from(DAQ_CELLS))
        lines[i] = separator.join(cells)
    elif kind == "header":  # a name replaced, or one more column
        cells = lines[0].split(separator)
        name = data.draw(st.one_of(st.sampled_from(DAQ_NAMES), st.text(max_size=12)))
        j = data.draw(st.integers(0, len(cells)))
        cells[j : j + 1] = [name]
        lines[0] = separator.join(cells)
    elif kind == "option":
        option = data.draw(st.sampled_from(["rate_Hz", "force_column", "response_column"]))
        values = [1e-3, 8000.0, 4096.5] if option == "rate_Hz" else DAQ_NAMES + ["ACC", "F "]
        options[option] = data.draw(st.sampled_from(values))
    elif kind == "axis":  # two samples swapped: no longer ascending or evenly spaced
        i = data.draw(st.integers(2, len(lines) - 2))
        lines[i], lines[i + 1] = lines[i + 1], lines[i]
    elif kind == "bytes":
        return _damage_bytes(data, text.encode()), options
    elif kind == "lines":
        return _damage_lines(data, text).encode(), options
    else:
        lines[1:] = data.draw(st.text(string.printable + "µé°;\t", max_size=200)).splitlines()
    return ("\n".join(lines) + "\n").encode(), options


def _daq_reader(options):
    """The in-process readers as `bayesplate import` chooses them for these options."""

    def reader(path):
        named = (options.get("force_column"), options.get("response_column"))
        if not is_tap_test(path):
            return _modes_reader(path)
        if is_recording(path, named):
            return read_taps([path], **options)
        if options:
            raise CaseError("--rate-Hz", rule="is for impulse recordings: the CLI refuses it")
        return read_spectra(path)

    return reader


@fuzz_settings(200)
@given(data=st.data())
def test_a_damaged_daq_csv_is_refused(fuzz_ledger, data):
    text, separator, options = _daq_csv(data)
    raw, options = _daq_damage(data, text, separator, options)
    extra = []
    for option, value in options.items():
        extra += ["--" + option.replace("_", "-"), str(value)]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp, "daq.csv")
        path.write_bytes(raw)
        _import_refused(fuzz_ledger, path, extra=extra, reader=_daq_reader(options))


POLES_TEXT = "keep,frequency_Hz,damping\n1,700.0,0.01\n0,1200.0,0.02\n1,1900.0,0.01\n"


@fuzz_settings(100)
@given(data=st.data())
def test_a_damaged_poles_file_is_refused(fuzz_ledger, data):
    kind = data.draw(st.sampled_from(["cell", "bytes", "lines", "none kept", "order"]))
    if kind == "cell":
        lines = POLES_TEXT.splitlines()
        i = data.draw(st.integers(1, len(lines) - 1))
        cells = lines[i].split(",")
        cells[data.draw(st.integers(0, 2))] = data.draw(
            st.sampled_from(BAD_CELLS + ["2", "0.9999"])
        )
        raw = ("\n".join(lines) + "\n").encode()
        raw = ("\n".join(lines[:i] + [",".join(cells)] + lines[i + 1 :]) + "\n").encode()
    elif kind == "none kept":
        raw = POLES_TEXT.replace("\n1,", "\n0,").encode()
    elif kind == "order":
        raw = b"keep,frequency_Hz,damping\n1,1900.0,0.01\n1,700.0,0.01\n"
    elif kind == "bytes":
        raw = _damage_bytes(data, POLES_TEXT.encode())
    else:
        raw = _damage_lines(data, POLES_TEXT).encode()
    with tempfile.TemporaryDirectory() as tmp:
        test = Path(tmp, "tap.wav")
        t, y = _impulse()
        wavfile.write(test, int(RATE_HZ), y.astype(np.float32))
        poles = Path(tmp, "kept.csv")
        poles.write_bytes(raw)
        if _accepted(poles, read_poles):
            return
        out = Path(tmp, "case.toml")
        argv = ["import", test, "--plate", SHEET, "-o", out, "--use-poles", poles]
        assert_refused_cleanly(fuzz_ledger, argv, [test, poles], [out], ["kept.csv"])
