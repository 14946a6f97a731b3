import hashlib
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# the independent closed-form references live in tests/reference
sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture
def rng():
    """One seeded generator per test: the same seed gives the same numbers."""
    return np.random.default_rng(20070461)


@pytest.fixture
def sheet(tmp_path):
    """plate1 without its measured frequencies: a plate sheet (the tap-test imports')."""
    from bayesplate.io import bundled_case_path

    text = bundled_case_path("plate1").read_text()
    path = tmp_path / "plate1_sheet.toml"
    path.write_text(re.sub(r"frequency_Hz = \[[^\]]*\]\n", "", text))
    return path


# ----------------------------------------------------------------------------- fuzz counting


class FuzzLedger:
    """The corrupted inputs the fuzz tests (tests/test_fuzz_*.py) saw refused cleanly.

    An input is counted once: by the bytes of the files it consists of and the command line
    with file paths reduced to their names (a temporary folder does not make it new).
    """

    def __init__(self):
        self.seen = set()

    def count(self, argv, files=()):
        """Record one corrupted input: `argv` and the contents of `files` (paths)."""
        digest = hashlib.sha256()
        for arg in argv:
            digest.update(Path(str(arg)).name.encode("utf-8", "surrogateescape") + b"\0")
        for path in files:
            digest.update(b"\1" + (Path(path).read_bytes() if Path(path).exists() else b""))
        self.seen.add(digest.hexdigest())


_LEDGER = FuzzLedger()


@pytest.fixture(scope="session")
def fuzz_ledger():
    """The session's :class:`FuzzLedger` (session scope: usable under hypothesis)."""
    return _LEDGER


def pytest_terminal_summary(terminalreporter):
    """Print how many distinct corrupted inputs the fuzz tests saw refused cleanly."""
    if not _LEDGER.seen:
        return
    failed = [r for r in terminalreporter.stats.get("failed", []) if "test_fuzz_" in r.nodeid]
    verdict = "all refused cleanly" if not failed else f"{len(failed)} fuzz tests FAILED"
    line = f"fuzzing: {len(_LEDGER.seen)} distinct corrupted inputs, {verdict}"
    terminalreporter.write_line(line)
