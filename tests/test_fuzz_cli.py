"""Fuzzing the command line: every option given a value it must refuse, in one line, status 2.

Also home of :func:`assert_refused_cleanly`, the check every ``tests/test_fuzz_*.py`` applies
to a corrupted input: the CLI entry (in-process) answers with exit status 2 and ONE line on
standard error naming the file and the key or record, no traceback, the inputs unchanged
(SHA-256 before and after) and no output file, not even a temporary one. Each input that
passes is counted by the session's ``fuzz_ledger`` (tests/conftest.py), which prints the
total at the end of the run.
"""

import contextlib
import hashlib
import io
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bayesplate.cli import main
from bayesplate.cli.options import MAX_MESH
from bayesplate.io import bundled_case_path, bundled_plate_path
from bayesplate.io.checks import MAX_MESH_ELEMENTS


def fuzz_settings(n):
    """Deterministic hypothesis settings for `n` examples (CI reproducible, no database)."""
    return settings(
        max_examples=n,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=[
            HealthCheck.function_scoped_fixture,
            HealthCheck.too_slow,
            HealthCheck.filter_too_much,
        ],
    )


def _sha(path):
    path = Path(path)
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def assert_refused_cleanly(ledger, argv, inputs=(), outputs=(), names=()):
    """Run ``bayesplate argv`` in-process; assert a clean refusal; count the input.

    Parameters
    ----------
    ledger : FuzzLedger
        The session's counter (the ``fuzz_ledger`` fixture).
    argv : list
        The command line (items turned into str).
    inputs : sequence of path
        Files the command reads: their bytes must be unchanged; they make the input distinct.
    outputs : sequence of path
        Files or folders the command would write: none may exist afterwards, nor a
        ``.name.*`` temporary beside it.
    names : sequence of str
        Words the one error line must contain (the file, the key or record, the rule).

    Returns
    -------
    str
        The error line.
    """
    argv = [str(a) for a in argv]
    before = {str(p): _sha(p) for p in inputs}
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main(argv)
        except SystemExit as exit_:
            status = exit_.code
    text = err.getvalue()
    assert status == 2, (argv, status, text, out.getvalue())
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == 1, (argv, text)
    line = lines[0]
    assert "Traceback" not in text and "error:" in line, line
    for name in names:
        assert str(name) in line, (name, line)
    for path, digest in before.items():
        assert _sha(path) == digest, f"{path} was modified"
    for path in outputs:
        path = Path(path)
        assert not path.exists(), f"{path} was written"
        assert not list(path.parent.glob(f".{path.name}*")), f"a temporary of {path} is left"
    ledger.count(argv, inputs)
    return line


# ----------------------------------------------------------------------------- options

BAD_INT = ["0", "-1", "-7", "x", "1.5", "", "nan", "1e3", "0x10", "٠"]
BAD_FLOAT = ["nan", "NaN", "inf", "-inf", "x", "", "1,5", "--", "1e999"]
BAD_POSITIVE_FLOAT = BAD_FLOAT + ["0", "-1", "-1e-9", "-0.0"]
BAD_MESH = ["0", "-1", str(MAX_MESH + 1), "100000", "x", "2.5", ""]
BAD_SEED = ["-1", "x", "1.5", str(2**64), ""]
BAD_CHOICE = ["X", "", "b", "mve", "paper ", "ALL", "ü"]

#: subcommand -> option -> values it must refuse (the case is a valid bundled one).
OPTIONS = {
    "modes": {"--count": BAD_INT, "--mesh": BAD_MESH, "--constants": BAD_CHOICE},
    "estimate": {
        "--tol": BAD_POSITIVE_FLOAT,
        "--max-iter": BAD_INT,
        "--mesh": BAD_MESH,
        "--method": BAD_CHOICE,
        "--convention": BAD_CHOICE,
        "--pairing": BAD_CHOICE,
        "--forward": BAD_CHOICE,
    },
    "sample": {
        "--seed": BAD_SEED,
        "--walkers": BAD_INT + ["11", "2"],
        "--max-steps": BAD_INT + ["60", "109"],
        "--min-ess": BAD_POSITIVE_FLOAT,
        "--mesh": BAD_MESH,
        "--pairing": BAD_CHOICE,
        "--workers": BAD_INT,
    },
    "diagnose": {
        "--seed": BAD_SEED,
        "--workers": BAD_INT,
        "--mesh": BAD_MESH,
        "--pairing": BAD_CHOICE,
    },
    "report": {"--seed": BAD_SEED, "--mesh": BAD_MESH, "--pairing": BAD_CHOICE},
    "import": {
        "--sigma-rel": BAD_FLOAT + ["0", "1", "1.5", "-0.1", "0.7", "1e-9"],
        "--order": BAD_INT,
        "--band": BAD_FLOAT,
        "--window": BAD_CHOICE,
    },
}


def _base_argv(command, tmp):
    """A valid command line of `command` and the outputs it would write."""
    out = Path(tmp, "out.json")
    if command == "import":
        test = Path(tmp, "t.csv")
        test.write_text("frequency_Hz\n100\n200\n")
        case = Path(tmp, "c.toml")
        argv = ["import", test, "--plate", bundled_plate_path("frederiksen_plate"), "-o", case]
        return argv, [test], [case]
    if command == "report":
        return ["report", "plate1", "-o", Path(tmp, "rep")], [], [Path(tmp, "rep")]
    return [command, "plate1", "--json", out], [], [out]


@fuzz_settings(150)
@given(data=st.data())
def test_a_bad_option_value_is_refused_in_one_line(fuzz_ledger, data):
    command = data.draw(st.sampled_from(sorted(OPTIONS)))
    option = data.draw(st.sampled_from(sorted(OPTIONS[command])))
    value = data.draw(st.sampled_from(OPTIONS[command][option]))
    with tempfile.TemporaryDirectory() as tmp:
        argv, inputs, outputs = _base_argv(command, tmp)
        if option in ("--mesh", "--band"):  # two values: spoil one of them
            good = {"--mesh": "8", "--band": "10"}[option]
            pair = data.draw(st.sampled_from([[value, good], [good, value]]))
            argv += [option, *pair]
        else:
            argv += [f"{option}={value}"]
        assert_refused_cleanly(fuzz_ledger, argv, inputs, outputs, [option])


MALFORMED = {
    "no command": ([], ["required"]),
    "unknown command": (["estimat", "plate1"], ["invalid choice"]),
    "unknown option": (["modes", "plate1", "--bogus"], ["--bogus"]),
    "missing case": (["estimate"], ["case"]),
    "extra argument": (["modes", "plate1", "plate2"], ["plate2"]),
    "missing value": (["modes", "plate1", "--count"], ["--count"]),
    "mesh one value": (["modes", "plate1", "--mesh", "8"], ["--mesh"]),
    "import without plate": (["import", "t.csv", "-o", "c.toml"], ["--plate"]),
    "import without output": (["import", "t.csv", "--plate", "p.toml"], ["-o"]),
}


@pytest.mark.parametrize("kind", MALFORMED)
def test_a_malformed_command_line_is_refused_in_one_line(fuzz_ledger, kind):
    argv, names = MALFORMED[kind]
    assert_refused_cleanly(fuzz_ledger, argv, names=names)


@fuzz_settings(40)
@given(
    command=st.sampled_from(["modes", "estimate", "sample", "diagnose", "report"]),
    name=st.text(
        st.characters(codec="utf-8", exclude_characters="\0/\\"), min_size=1, max_size=12
    ).filter(lambda s: s.strip() not in ("", ".", "..")),
)
def test_a_case_that_is_neither_a_file_nor_a_bundled_name_is_refused(fuzz_ledger, command, name):
    with tempfile.TemporaryDirectory() as tmp:
        missing = Path(tmp, name)
        out = Path(tmp, "out")
        extra = ["-o", out] if command == "report" else ["--json", out]
        assert_refused_cleanly(
            fuzz_ledger, [command, missing, *extra], [], [out], ["cannot read", "error:"]
        )


def test_a_directory_as_case_is_refused(fuzz_ledger, tmp_path):
    assert_refused_cleanly(fuzz_ledger, ["modes", tmp_path], names=[str(tmp_path), "cannot read"])


def test_an_unwritable_output_is_refused_naming_the_option(fuzz_ledger, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a file, not a folder")
    test = tmp_path / "t.csv"
    test.write_text("frequency_Hz\n100\n200\n")
    out = blocker / "c.toml"
    argv = ["import", test, "--plate", "frederiksen_plate", "-o", out]
    assert_refused_cleanly(fuzz_ledger, argv, [test, blocker], [out], ["-o", "cannot write"])


def test_the_parser_mesh_limit_is_the_case_files():
    assert MAX_MESH == MAX_MESH_ELEMENTS


def test_the_parser_chain_minimum_is_the_samplers():
    from bayesplate.cli.options import MIN_CHAIN_STEPS
    from bayesplate.sampling import ChainOptions
    from bayesplate.sampling.chain import TUNE_ROUNDS, TUNE_STEPS

    check_every = ChainOptions().check_every
    assert MIN_CHAIN_STEPS == TUNE_ROUNDS * TUNE_STEPS + check_every


def test_the_base_command_lines_are_valid(tmp_path):
    """The fuzzed command lines differ from valid ones only by the corruption."""
    from bayesplate.cli.main import build_parser

    for command in OPTIONS:
        argv, _, _ = _base_argv(command, tmp_path)
        build_parser().parse_args([str(a) for a in argv])  # no SystemExit
    assert bundled_case_path("plate1").exists()
