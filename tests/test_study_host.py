"""The code version a study's cached rows are keyed on (``studies/_study_host.py``)."""

import shutil
import subprocess

import pytest

from studies._study_host import code_version

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="needs git")


def _git(root, *args):
    subprocess.run(
        ["git", "-c", "user.name=t", "-c", "user.email=t@t", *args],
        cwd=root,
        check=True,
        capture_output=True,
    )


def _head(root):
    return subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=root, text=True, capture_output=True
    ).stdout.strip()


def test_a_commit_of_documents_alone_keeps_the_version_a_change_of_code_marks_it(tmp_path):
    for d in ("bayesplate", "studies", "docs"):
        (tmp_path / d).mkdir()
    (tmp_path / "bayesplate" / "a.py").write_text("x = 1\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "code")
    code = _head(tmp_path)
    assert code_version(tmp_path) == code
    (tmp_path / "docs" / "page.md").write_text("words\n")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "a page")
    assert _head(tmp_path) != code and code_version(tmp_path) == code
    (tmp_path / "studies" / "s.py").write_text("y = 2\n")  # not committed
    assert code_version(tmp_path) == code + "+modified"
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "a study")
    assert code_version(tmp_path) == _head(tmp_path) != code
