"""``bayesplate import``: a case file from a modal test (UFF, CSV or WAV) and a plate sheet."""

from __future__ import annotations

import pathlib

from .options import (
    BAND_HIGH_FACTOR,
    BAND_LOW_FACTOR,
    DEFAULT_BAND_MODES,
    finite_float,
    positive_int,
)

__all__ = ["register"]

_TAP_OPTIONS = (
    "poles",
    "chart",
    "use_poles",
    "band",
    "order",
    "window",
    "force_channel",
    "channel",
    "points",
    "modes",
    "rate_Hz",
    "force_column",
    "response_column",
)


def run(args):
    """Read the test file, combine it with the plate sheet, write the case file."""
    import_test(args)
    return 0


def import_taps(tests, plate, output, modes=None):
    """``bayesplate import TESTS --plate PLATE -o OUTPUT [--modes N]``, its tap test returned.

    What ``bayesplate report --taps`` runs first.

    Returns
    -------
    bayesplate.report.data.TapTest
    """
    import argparse

    parser = argparse.ArgumentParser(prog="bayesplate")
    register(parser.add_subparsers())
    words = ["import", *map(str, tests), "--plate", str(plate), "-o", str(output)]
    words += [] if modes is None else ["--modes", str(modes)]
    return import_test(parser.parse_args(words))


def import_test(args):
    """:func:`run`'s work: the case file written; the tap test (None for a file of modes)."""
    from ..io import (
        CaseError,
        case_from_modal_data,
        read_modal_data,
        write_case,
    )
    from ..io.checks import check_plausible
    from ..io.modal_file import is_tap_test

    if args.sigma_rel is not None and not 0 < args.sigma_rel < 1:
        raise CaseError("--sigma-rel", args.sigma_rel, "must be > 0 and < 1")
    if args.sigma_rel is not None:  # here, else the sheet would be blamed for it
        check_plausible(args.sigma_rel, "sigma_rel", "--sigma-rel")
    plate = _plate_path(args.plate)
    tests = [str(test) for test in args.test]
    tap_options = any(getattr(args, name) is not None for name in _TAP_OPTIONS)
    taps = None
    if tap_options or len(tests) > 1 or is_tap_test(tests[0]):
        modal, taps = _tap_modal_data(args, tests)
    else:
        modal = read_modal_data(tests[0])
    text = case_from_modal_data(plate, modal, sigma_rel=args.sigma_rel)
    try:
        write_case(args.output, text)
    except OSError as err:
        raise CaseError("-o", args.output, f"cannot write ({err.strerror or err})") from None
    named = tests[0] if len(tests) == 1 else f"{len(tests)} taps ({tests[0]}, ...)"
    print(f"{modal.size} modes, {modal.n_points} points from {named} -> {args.output}")
    return taps


def _tap_modal_data(args, tests):
    """Modes of a tap test and the test: poles extracted, written and charted on request."""
    from ..io import CaseError
    from ..io.poles import DEFAULT_ORDER, extract_poles, modal_data_from_poles
    from ..io.poles_file import read_poles, write_chart, write_poles

    kept = read_poles(args.use_poles) if args.use_poles is not None else None
    spectra = _read_spectra(args, tests)
    order = DEFAULT_ORDER if args.order is None else args.order
    analysis = None
    band, keep_below = args.band, None
    if kept is None or args.poles is not None or args.chart is not None:
        if band is None:
            band, keep_below = _prior_band(args, spectra)
        analysis = extract_poles(spectra, band_Hz=band, order=order, keep_below_Hz=keep_below)
    if kept is None:
        kept = analysis.kept
        if not kept:
            rule = (
                f"no pole is stable over the last orders ({len(analysis.candidates)} "
                "candidates): write them with --poles, edit, and give --use-poles"
            )
            raise CaseError(None, rule=rule, path=tests[0])
        listed = ", ".join(f"{pole.frequency_Hz:.6g}" for pole in kept)
        print(f"{len(kept)} stable poles taken automatically (Hz): {listed}")
    else:
        print(f"{len(kept)} poles kept in {args.use_poles}")
    for note in spectra.notes:
        print(f"{spectra.source}: {note}")
    _warn_coherence(spectra, kept)
    if args.poles is not None:
        _written("--poles", args.poles, write_poles, args.poles, analysis, spectra.source)
        print(f"{len(analysis.candidates)} candidate poles -> {args.poles}")
    if args.chart is not None:
        _written(
            "--chart",
            args.chart,
            write_chart,
            args.chart,
            analysis,
            spectra.frequency_Hz,
            spectra.frf,
            kept,
            spectra.coherence,
        )
        print(f"stabilisation chart -> {args.chart}")
    from ..report.data import TapTest

    taps = TapTest(spectra, analysis, tuple(kept), tuple(tests))
    return modal_data_from_poles(spectra, kept, band_Hz=band), taps


def _prior_band(args, spectra):
    """The fit's band and the top of the poles kept, from the sheet's prior (``--modes``)."""
    from ..io.band import prior_band_Hz
    from ..io.case_writer import sheet_case

    n_modes = args.modes or DEFAULT_BAND_MODES
    lower, upper, top = prior_band_Hz(sheet_case(_plate_path(args.plate)), n_modes)
    axis = spectra.frequency_Hz
    lower, top = max(lower, float(axis[axis > 0][0])), min(top, float(axis[-1]))
    print(
        f"band {lower:.4g}-{upper:.4g} Hz (poles fitted up to {top:.4g} Hz): the lowest "
        f"{n_modes} modes at the sheet's prior mean, x {BAND_LOW_FACTOR:g} and "
        f"x {BAND_HIGH_FACTOR:g} (--band, --modes)"
    )
    return (lower, top), upper


def _plate_path(plate):
    """The sheet's path: a file, or the name of a bundled plate sheet."""
    from ..io import bundled_plate_names, bundled_plate_path

    if not pathlib.Path(plate).exists() and plate in bundled_plate_names():
        return bundled_plate_path(plate)
    return plate


def _read_spectra(args, tests):
    """The spectra of the test: the taps averaged, or the one FRF file (with --points)."""
    from ..io import CaseError
    from ..io.frf import read_frf_csv
    from ..io.impulse import is_recording
    from ..io.modal_file import read_spectra
    from ..io.taps import read_taps

    window = args.window or "auto"
    named = (args.force_column, args.response_column)
    if len(tests) > 1 or is_recording(tests[0], named):
        for test in tests:
            if not is_recording(test, named):
                rule = "several files are taps of one test: each must be a WAV or a CSV time series"
                raise CaseError("TEST", rule=rule, path=test)
        force = {None: "auto", "none": None}.get(args.force_channel, args.force_channel)
        return read_taps(
            tests,
            window,
            force,
            args.channel,
            args.points,
            args.rate_Hz,
            args.force_column,
            args.response_column,
        )
    for option in ("force_channel", "channel", "rate_Hz", "force_column", "response_column"):
        if getattr(args, option) is not None:
            name = "--" + option.replace("_", "-")
            rule = f"is for impulse recordings (WAV or CSV time series); {tests[0]} holds FRFs"
            raise CaseError(name, getattr(args, option), rule)
    if args.points is not None:
        if not tests[0].lower().endswith(".csv"):
            rule = f"is for a WAV or an FRF CSV; {tests[0]} carries its own node coordinates"
            raise CaseError("--points", args.points, rule)
        return read_frf_csv(tests[0], points=args.points)
    return read_spectra(tests[0], window=window)


def _warn_coherence(spectra, kept):
    """One line on stderr naming the chosen poles whose coherence is low."""
    import sys

    from ..io.taps import COHERENCE_WARNING, coherence_at_poles

    low = [(f, c) for f, c in coherence_at_poles(spectra, kept) if c < COHERENCE_WARNING]
    if low:
        listed = ", ".join(f"{f:.6g} Hz ({c:.2f})" for f, c in low)
        print(
            f"bayesplate: warning: coherence below {COHERENCE_WARNING} at {len(low)} chosen "
            f"poles: {listed}: noise, a double hit or a nonlinearity; see --chart",
            file=sys.stderr,
        )


def _written(option, path, write, *args):
    """Call ``write(*args)``; an OSError becomes a CaseError naming `option` and `path`."""
    from ..io import CaseError

    try:
        write(*args)
    except OSError as err:
        raise CaseError(option, path, f"cannot write ({err.strerror or err})") from None


def register(sub):
    """Add the ``import`` subcommand."""
    from .options import positive_float

    p = sub.add_parser(
        "import",
        help="make a case file from a modal test (UFF, CSV or a WAV tap) and a plate sheet",
        description="Combine measured modes with a plate sheet (a case file without "
        "[measured] frequencies) into a case file. UFF: dataset 55 per mode, node "
        "coordinates from dataset 15 or 2411, units from dataset 164 (default mm); the z "
        "component of each shape is kept. CSV: a header with frequency_Hz and optionally "
        "sigma_Hz or sigma_rel, and mode. Tap tests: FRFs (UFF dataset 58 per response "
        "node; CSV frequency_Hz, H1_re, H1_im, ...) or an impulse recording (WAV: channel 0 "
        "response, 1 force, or as --force-channel says; CSV time series: one row per "
        "sample, columns found by name: time (time_s, Time (s), time [ms]; else give "
        "--rate-Hz), a response (signal, acceleration, mic, ...) and a force (force, hammer, "
        "...), or as --force-column and --response-column say); the "
        "modes are the LSCF poles (sdypy-EMA) stable over the last model orders, or those "
        "kept in --use-poles. Several recordings are taps averaged (H1 and its coherence "
        "with a force channel).",
    )
    p.add_argument(
        "test",
        metavar="TEST",
        nargs="+",
        help="the test: .uff/.unv/.uf, .csv or .wav; several WAV or CSV time series are taps "
        "of the same test, averaged (a shell glob such as taps/*.wav gives them)",
    )
    p.add_argument(
        "--plate",
        required=True,
        help="plate sheet (TOML) or the name of a bundled one (frederiksen_plate)",
    )
    p.add_argument("-o", "--output", required=True, metavar="CASE", help="case file to write")
    p.add_argument(
        "--sigma-rel",
        type=finite_float,
        help="relative standard deviation of each frequency (default: the sheet's, else 0.01)",
    )
    tap = p.add_argument_group("tap tests (FRFs or impulse recordings)")
    tap.add_argument("--poles", metavar="CSV", help="write the candidate poles here, to edit")
    tap.add_argument("--chart", metavar="PNG", help="write the stabilisation chart here")
    tap.add_argument(
        "--use-poles",
        metavar="CSV",
        help="take exactly the poles marked keep = 1 in this (edited) poles file",
    )
    tap.add_argument(
        "--band",
        nargs=2,
        type=finite_float,
        metavar=("LOW_HZ", "HIGH_HZ"),
        help="frequency band of the fit, Hz (default: from the plate sheet, see --modes)",
    )
    tap.add_argument(
        "--modes",
        type=positive_int,
        metavar="N",
        help=f"without --band, fit the band where the sheet's prior mean puts the lowest N "
        f"elastic modes: {BAND_LOW_FACTOR:g} x the first to {BAND_HIGH_FACTOR:g} x the N-th "
        f"(default {DEFAULT_BAND_MODES})",
    )
    tap.add_argument("--order", type=positive_int, help="highest LSCF model order (default 60)")
    tap.add_argument(
        "--window",
        choices=("auto", "none", "exponential"),
        help="window of an impulse recording (default auto: none if the response has "
        "decayed within the record, else exponential with the poles corrected)",
    )
    tap.add_argument(
        "--force-channel",
        type=_channel_or_none,
        metavar="N",
        help="WAV channel (from 0) of the hammer's force, or none (default: 1 in a "
        "2-channel file, else none); the other channels are responses",
    )
    tap.add_argument(
        "--channel",
        type=_channel,
        metavar="N",
        help="keep only this WAV response channel (from 0)",
    )
    tap.add_argument(
        "--rate-Hz",
        type=positive_float,
        metavar="HZ",
        help="sampling rate of CSV time series, Hz: required without a time column; checked "
        "against a time column or a WAV header",
    )
    tap.add_argument(
        "--force-column",
        metavar="NAME",
        help="the CSV column of the hammer's force, by its header (default: the one named "
        "force, hammer, F, impact, ...)",
    )
    tap.add_argument(
        "--response-column",
        metavar="NAME",
        help="the CSV column of the response, by its header (default: the one named "
        "signal, response, acceleration, accel, acc, a, velocity, mic, ...)",
    )
    tap.add_argument(
        "--points",
        metavar="CSV",
        help="points file point,x_mm,y_mm: one row per WAV response channel in channel "
        "order, or per H<point>_re/_im pair of an FRF CSV, matched by name; gives shapes",
    )
    p.set_defaults(func=run)


def _channel_or_none(text):
    """A channel number (0 or more) or ``none`` (an argparse type)."""
    return "none" if text.strip().lower() == "none" else _channel(text)


def _channel(text):
    """A channel number, 0 or more (an argparse type)."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be a channel number (0 or more)")
    return value
