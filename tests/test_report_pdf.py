"""``bayesplate report --pdf``: report.html printed by a headless Chromium, or one clear line."""

import os
import re
import stat

import pytest

from bayesplate.cli import main
from bayesplate.report.pdf import PdfError, find_browser, print_pdf

CHROMIUM = find_browser()  # the one report --pdf would use
PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>t</title></head>
<body><h1>Plate 1</h1><p>E1 = 144.9 GPa</p>{more}</body></html>"""


def _fake_browser(tmp_path, body):
    """An executable that stands in for Chromium: `body` is its shell script after #!."""
    path = tmp_path / "fake-chromium"
    path.write_text("#!/bin/sh\n" + body)
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def test_the_arguments_a_browser_gets_and_the_pdf_written_whole(tmp_path):
    """The page's file URI and --print-to-pdf reach the browser; its PDF lands beside the page."""
    page = tmp_path / "report.html"
    page.write_text(PAGE.format(more=""))
    log = tmp_path / "argv"
    script = (
        f'echo "$@" > {log}\nfor a; do case $a in --print-to-pdf=*) '
        'printf "%%PDF-1.4 fake" > "${a#--print-to-pdf=}";; esac; done\n'
    )
    written = print_pdf(page, browser=_fake_browser(tmp_path, script))
    assert written == tmp_path / "report.pdf"
    assert written.read_bytes() == b"%PDF-1.4 fake"
    argv = log.read_text().split()
    assert "--headless" in argv and page.resolve().as_uri() in argv
    assert stat.S_IMODE(written.stat().st_mode) & 0o044 == 0o044 & ~_umask()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.parametrize(
    ("script", "said"),
    [
        ("exit 3\n", "exited 3"),
        ("exit 0\n", "wrote no PDF"),
        ("sleep 5\n", "did not print"),
    ],
)
def test_a_browser_that_fails_leaves_any_earlier_pdf_and_says_why(tmp_path, script, said):
    page = tmp_path / "report.html"
    page.write_text(PAGE.format(more=""))
    earlier = tmp_path / "report.pdf"
    earlier.write_bytes(b"%PDF earlier")
    with pytest.raises(PdfError, match=said):
        print_pdf(page, browser=_fake_browser(tmp_path, script), timeout=1.0)
    assert earlier.read_bytes() == b"%PDF earlier"


def test_no_browser_is_one_line_and_exit_2_with_the_report_kept(tmp_path, monkeypatch, capsys):
    """The report is written first; the missing browser is named with what to do."""
    monkeypatch.setenv("BAYESPLATE_CHROMIUM", "no-such-browser-here")
    out = tmp_path / "report"
    argv = ["report", "plate1", "--quick", "--no-sample", "--no-diagnose", "-o", str(out), "--pdf"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("bayesplate report: error: --pdf: no Chromium found")
    assert "apt-get install chromium" in err
    assert (out / "report.html").exists() and (out / "report.md").exists()
    assert not (out / "report.pdf").exists()


def _pages(pdf):
    """The number of pages of a PDF (its /Type /Page objects)."""
    return len(re.findall(rb"/Type\s*/Page\b", pdf))


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="no chromium (`.ci/run` installs it)")
def test_a_long_page_prints_to_several_pages(tmp_path):
    """A page three screens long prints to more pages than a short one (real Chromium)."""
    short, long_ = tmp_path / "short.html", tmp_path / "long.html"
    short.write_text(PAGE.format(more=""))
    long_.write_text(PAGE.format(more="".join(f"<p>row {i}</p>" for i in range(300))))
    pages = [_pages(print_pdf(p).read_bytes()) for p in (short, long_)]
    assert pages[0] == 1
    assert pages[1] >= 3
