"""``report.pdf``: the report's page printed by a headless Chromium (``bayesplate report --pdf``).

The PDF is ``report.html`` as a browser prints it (A4, the page's own print styles), so it
says exactly what the page says. No Python library draws HTML as faithfully, and a lab that
files a result with a test record wants the page it saw. The browser is Debian's
``chromium`` (``apt-get install chromium``) or any Chromium-like browser on the ``PATH``, or
the one named by the environment variable ``BAYESPLATE_CHROMIUM``. It runs with a throw-away
profile and no network (the page's content security policy lets nothing leave the file).
The PDF is printed into a temporary folder, then written whole
(:func:`bayesplate.io.files.atomic_write`).
"""

from __future__ import annotations

import os
import pathlib
import shutil
import subprocess
import tempfile

from ..io.files import atomic_write

__all__ = ["BROWSERS", "PdfError", "find_browser", "print_pdf"]

#: Executables tried in turn when ``BAYESPLATE_CHROMIUM`` is not set.
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: Seconds the browser is given to print (an 8-page report takes about 3 s).
TIMEOUT_S = 120.0


class PdfError(RuntimeError):
    """The PDF could not be printed; ``str(err)`` is one line saying why and what to do."""


def find_browser():
    """The Chromium to print with (a path), or None when there is none."""
    named = os.environ.get("BAYESPLATE_CHROMIUM")
    if named:
        return shutil.which(named)
    return next((path for path in map(shutil.which, BROWSERS) if path), None)


def print_pdf(html_path, pdf_path=None, browser=None, timeout=TIMEOUT_S):
    """Print ``html_path`` to ``pdf_path`` (default: beside it, ``.pdf``) with Chromium.

    Parameters
    ----------
    html_path : path-like
        The report's page.
    pdf_path : path-like, optional
    browser : path-like, optional
        Default: :func:`find_browser`.
    timeout : float
        Seconds, s.

    Returns
    -------
    pathlib.Path
        The PDF written.

    Raises
    ------
    PdfError
        No browser, or the browser failed, timed out or wrote no PDF.
    """
    html_path = pathlib.Path(html_path).resolve()
    pdf_path = pathlib.Path(pdf_path or html_path.with_suffix(".pdf"))
    browser = browser or find_browser()
    if browser is None:
        raise PdfError(
            "no Chromium found to print the PDF (install it: apt-get install chromium, or "
            "name it in BAYESPLATE_CHROMIUM); report.html and report.md are written"
        )
    with tempfile.TemporaryDirectory(prefix="bayesplate-pdf-") as work:
        printed = pathlib.Path(work) / "report.pdf"
        _run_browser(browser, html_path, printed, pathlib.Path(work) / "profile", timeout)
        pdf = printed.read_bytes() if printed.exists() else b""
    if not pdf.startswith(b"%PDF"):
        raise PdfError(f"{browser} wrote no PDF of {html_path}")
    atomic_write(pdf_path, lambda handle: handle.write(pdf), "wb")
    return pdf_path


def _run_browser(browser, html_path, pdf_path, profile, timeout):
    """One headless Chromium printing the page, with a profile of its own."""
    argv = [
        str(browser),
        "--headless",
        "--disable-gpu",
        "--no-first-run",
        "--disable-extensions",
        "--disable-background-networking",
        "--no-pdf-header-footer",
        f"--user-data-dir={profile}",
        f"--print-to-pdf={pdf_path}",
        html_path.as_uri(),
    ]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        argv.insert(1, "--no-sandbox")  # Chromium refuses to run as root with it
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise PdfError(f"{browser} did not print {html_path} in {timeout:.0f} s") from None
    except OSError as err:
        raise PdfError(f"{browser} could not be started: {err}") from None
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise PdfError(f"{browser} exited {done.returncode} printing {html_path}: {last}")
