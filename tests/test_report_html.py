"""report.html (issue 41): one self-contained page, the same numbers as report.md and
report.json, and checked as a person sees it, in a headless Chromium.

The browser is driven through the DevTools protocol over a pipe (``--remote-debugging-pipe``:
Chromium reads NUL-terminated JSON commands on fd 3 and answers on fd 4), so no websocket
client is needed. Each page is opened in a window of a given width (a laptop's 1280 px and a
phone's 390 px, the phone as a mobile viewport that honours the page's viewport tag), and
the check fails on a console error or an exception, a request to anything but the file
itself and its data URIs, an image not shown (not loaded, or zero width), or a page that
lays out wider than its window (``scrollWidth`` above the window's width; a mobile viewport
widens its ``innerWidth`` to fit wide content, so that is not the measure).

Run on its own, the module writes the screenshots kept in ``reports/``::

    python tests/test_report_html.py REPORT_DIR SHOT.png [--width 1280] [--scale 0.5]
        [--phone PHONE.png]
"""

import base64
import html.parser
import json
import os
import pathlib
import re
import select
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter

import pytest

from bayesplate.report.pdf import find_browser

PNG = b"\x89PNG\r\n\x1a\n"
FIVE_MB = 5 * 1024 * 1024
CHROMIUM = find_browser()  # the one report --pdf would use


# ------------------------------------------------------------------------------- the page


class _Page(html.parser.HTMLParser):
    """Every tag's attributes, the summary table's cells and the page's text."""

    def __init__(self):
        super().__init__()
        self.tags, self.text, self.summary_rows = [], [], []
        self._in_summary = self._row = self._cell = None
        self._hidden = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append((tag, attrs))
        self._hidden = tag in ("style", "title", "nav")
        if tag == "section" and attrs.get("class") == "summary":
            self._in_summary = True
        elif tag == "section":
            self._in_summary = False
        if self._in_summary and tag == "tr":
            self._row = []
        if self._row is not None and tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        self._hidden = False
        if tag in ("td", "th") and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        if tag == "tr" and self._row is not None:
            self.summary_rows.append(self._row)
            self._row = None

    def handle_data(self, data):
        if not self._hidden:
            self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


def parse_page(text):
    page = _Page()
    page.feed(text)
    return page


def markdown_summary_rows(text):
    """The rows of report.md's summary table (header first)."""
    block = text.split("## Summary", 1)[1].split("\n## ", 1)[0]
    return [
        [c.strip() for c in line.strip().strip("|").split("|")]
        for line in block.splitlines()
        if line.startswith("|") and not line.startswith("|---")
    ]


def _numbers(cell):
    """The numbers written in a cell, each with half a unit of its last digit."""
    found = re.findall(r"[-+]?\d+(?:\.(\d*))?", cell)
    values = re.findall(r"[-+]?\d+(?:\.\d*)?", cell)
    return [(float(v), 0.5 * 10.0 ** -len(d) * 1.0001) for v, d in zip(values, found, strict=True)]


def check_summary_against_json(rows, summary):
    """The summary table's numbers are the JSON's, to the digits shown."""
    head, body = rows[0], rows[1:]
    assert head[:3] == ["constant", f"{summary['estimator']} ± sd", "94 % interval"]
    assert len(body) == len(summary["constants"]) == 6
    for row, c in zip(body, summary["constants"], strict=True):
        assert row[0] == f"{c['name']} ({c['unit']})"
        shown = _numbers(row[1]) + _numbers(row[2]) + (_numbers(row[3]) if len(row) > 3 else [])
        wanted = [c["estimate"], c["sd"], c["low"], c["high"]]
        wanted += [c["reference"]] if len(row) > 3 else []
        assert len(shown) == len(wanted), (row, c)
        for (a, tol), b in zip(shown, wanted, strict=True):
            assert abs(a - b) <= tol, (row, c)


# ------------------------------------------------------------------------------- the browser


class Browser:
    """A headless Chromium driven over the DevTools pipe (one page at a time)."""

    def __init__(self, executable=CHROMIUM, timeout=60.0):
        self.timeout = timeout
        self.profile = tempfile.mkdtemp(prefix="bayesplate-chromium-")
        to_child, self._write = os.pipe()  # commands: the child's fd 3
        self._read, from_child = os.pipe()  # answers: the child's fd 4

        def fds():
            os.dup2(to_child, 3)
            os.dup2(from_child, 4)

        argv = [
            executable,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--remote-debugging-pipe",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--mute-audio",
            f"--user-data-dir={self.profile}",
            "about:blank",
        ]
        self.proc = subprocess.Popen(
            argv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            pass_fds=(3, 4),
            preexec_fn=fds,
        )
        os.close(to_child)
        os.close(from_child)
        self._buffer, self._id, self.events = b"", 0, []

    def close(self):
        try:
            self.send("Browser.close")
        except (OSError, RuntimeError, TimeoutError):
            pass
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._write)
        os.close(self._read)
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _message(self, deadline):
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no answer from Chromium")
            ready, _, _ = select.select([self._read], [], [], left)
            if ready:
                chunk = os.read(self._read, 1 << 20)
                if not chunk:
                    raise RuntimeError("Chromium closed its pipe")
                self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def send(self, method, params=None, session=None):
        """Send one command and wait for its answer (events met on the way are kept)."""
        self._id += 1
        command = {"id": self._id, "method": method, "params": params or {}}
        if session:
            command["sessionId"] = session
        os.write(self._write, json.dumps(command).encode() + b"\0")
        deadline = time.monotonic() + self.timeout
        while True:
            message = self._message(deadline)
            if message.get("id") == self._id:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message.get("result", {})
            self.events.append(message)

    def wait_for(self, method, seconds):
        """Wait for an event (True) or `seconds` (False)."""
        deadline = time.monotonic() + seconds
        if any(e.get("method") == method for e in self.events):
            return True
        try:
            while True:
                message = self._message(deadline)
                self.events.append(message)
                if message.get("method") == method:
                    return True
        except TimeoutError:
            return False

    def look(
        self, path, width, height=900, mobile=False, screenshot=None, scale=1.0, full_page=True
    ):
        """Open `path` in a `width` x `height` window; what a person would see of it.

        `screenshot`: a PNG of the whole page (`full_page`) or of the window, at `scale`.

        Returns
        -------
        dict
            ``errors`` (console errors, exceptions, error log entries), ``requests`` (URLs
            requested other than the file itself and data URIs), ``scroll_width``,
            ``inner_width``, ``images`` (each ``{complete, width, data}``) and ``height``.
        """
        url = pathlib.Path(path).resolve().as_uri()
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"
        ]
        self.events = []
        for domain in ("Runtime", "Log", "Network", "Page"):
            self.send(f"{domain}.enable", session=session)
        self.send(
            "Emulation.setDeviceMetricsOverride",
            {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": mobile},
            session,
        )
        self.send("Page.navigate", {"url": url}, session)
        assert self.wait_for("Page.loadEventFired", self.timeout), "the page did not load"
        self.wait_for("never", 1.0)  # late console messages and requests
        probe = (
            "JSON.stringify({scroll: document.documentElement.scrollWidth,"
            " inner: window.innerWidth, height: document.documentElement.scrollHeight,"
            " images: Array.from(document.images).map(i => ({complete: i.complete,"
            " width: i.naturalWidth, shown: i.getBoundingClientRect().width,"
            " data: i.src.startsWith('data:image/png;base64,')}))})"
        )
        seen = json.loads(
            self.send("Runtime.evaluate", {"expression": probe, "returnByValue": True}, session)[
                "result"
            ]["value"]
        )
        errors, requests = [], []
        for event in self.events:
            method, p = event.get("method"), event.get("params", {})
            if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                errors.append(" ".join(str(a.get("value", a)) for a in p.get("args", [])))
            elif method == "Runtime.exceptionThrown":
                errors.append(p["exceptionDetails"].get("text", "exception"))
            elif method == "Log.entryAdded" and p["entry"].get("level") == "error":
                errors.append(p["entry"].get("text", ""))
            elif method == "Network.requestWillBeSent":
                request = p["request"]["url"]
                if request != url and not request.startswith("data:"):
                    requests.append(request)
            elif method == "Network.loadingFailed":
                errors.append(f"loading failed: {p.get('errorText')}")
        if screenshot is not None:
            full = seen["height"] if full_page else height
            shot = self.send(
                "Page.captureScreenshot",
                {
                    "format": "png",
                    "captureBeyondViewport": True,
                    "clip": {"x": 0, "y": 0, "width": width, "height": full, "scale": scale},
                },
                session,
            )
            pathlib.Path(screenshot).write_bytes(base64.b64decode(shot["data"]))
        self.send("Target.closeTarget", {"targetId": target})
        return {
            "errors": errors,
            "requests": requests,
            "scroll_width": seen["scroll"],
            "inner_width": seen["inner"],
            "images": seen["images"],
            "height": seen["height"],
        }


def check_in_browser(html_path, widths=((1280, False), (390, True)), screenshots=None):
    """Open the page at each width; assert what a person must see. ``{width: result}``."""
    found = {}
    with Browser() as browser:
        for width, mobile in widths:
            shot = None if screenshots is None else screenshots.get(width)
            seen = browser.look(html_path, width, mobile=mobile, screenshot=shot)
            assert not seen["errors"], (width, seen["errors"])
            assert not seen["requests"], (width, seen["requests"])
            # a mobile viewport widens to fit wide content: the window's own width decides
            assert seen["scroll_width"] <= width and seen["inner_width"] == width, (width, seen)
            assert seen["images"], "no figure"
            for image in seen["images"]:
                assert image["data"] and image["complete"] and image["width"] > 0, image
                assert 0 < image["shown"] <= width, image
            found[width] = seen
    return found


# ------------------------------------------------------------------------------- the tests


@pytest.fixture(scope="module")
def small_report(tmp_path_factory):
    """Plate 1's report without diagnose and sampling (the fast steps)."""
    from bayesplate.io import bundled_case_path
    from bayesplate.report import ReportOptions, make_report

    out = tmp_path_factory.mktemp("html_report")
    options = ReportOptions(diagnose=False, sample=False)
    make_report(bundled_case_path("plate1"), out, options, lambda line: None, "plate1")
    return out


def test_report_html_is_self_contained_and_says_what_md_and_json_say(small_report):
    out = small_report
    text = (out / "report.html").read_text(encoding="utf-8")
    markdown = (out / "report.md").read_text(encoding="utf-8")
    summary = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert (out / "report.html").stat().st_size < FIVE_MB
    page = parse_page(text)
    images = [attrs for tag, attrs in page.tags if tag == "img"]
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert len(images) == len(pngs) >= 3  # every figure written is shown
    embedded = []
    for attrs in images:
        src = attrs["src"]
        assert src.startswith("data:image/png;base64,"), src[:60]
        png = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert png[:8] == PNG
        embedded.append(png)
        assert attrs.get("alt") and int(attrs["width"]) > 0 and int(attrs["height"]) > 0
    assert sorted(embedded) == sorted((out / name).read_bytes() for name in pngs)
    for tag, attrs in page.tags:  # nothing that leaves the file
        for key in ("src", "href", "action", "srcset", "poster", "data"):
            value = attrs.get(key) or ""
            if tag == "img" and key == "src":
                continue
            assert not re.match(r"\s*(https?:|//|file:|ftp:)", value, re.I), (tag, key, value)
            assert not value or value.startswith(("#", "data:")), (tag, key, value)
    assert "<script" not in text.lower() and "@import" not in text and "url(" not in text
    assert "Content-Security-Policy" in text and 'name="viewport"' in text
    # every figure has a sentence under it
    assert text.count("<figcaption>") == len(images)
    # the same numbers in the three
    assert summary["estimator"] == "B" and summary["diagnosis"] is None
    assert summary["interval"].startswith("B estimate ± 1.88 sd")
    check_summary_against_json(markdown_summary_rows(markdown), summary)
    check_summary_against_json(page.summary_rows, summary)
    assert markdown_summary_rows(markdown) == page.summary_rows
    for c in summary["constants"]:  # not sampled: the estimate ± 1.88 sd
        assert abs(c["high"] - c["estimate"] - 1.8808 * c["sd"]) < 1e-3 * c["sd"]
    fit = summary["fit"]
    words = "the model fits" if fit["fits"] else "the model does not fit"
    assert f"**{words}**" in markdown and f"<strong>{words}</strong>" in text
    line = f"chi-square {fit['chi2']:.3g} on {fit['dof']:.1f} degrees of freedom"
    assert line in markdown and line in text
    assert f"Status of B: {summary['status']}" in markdown
    assert "Diagnosis: not run (--no-diagnose)" in markdown and "Diagnosis: not run" in text
    # every number the Markdown writes, the page writes as often (figures' alt text aside)
    shown = "\n".join(line for line in markdown.splitlines() if not line.startswith("!["))
    number = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
    assert Counter(number.findall(shown)) == Counter(number.findall(" ".join(page.text)))
    # the details below the summary: every section of the Markdown is in the page
    for heading in re.findall(r"^#{1,3} (.+)$", markdown, re.M):
        assert f">{heading}</h" in text.replace("&#x27;", "'"), heading


def test_summary_of_a_sampled_and_diagnosed_report(small_report, monkeypatch):
    # the summary's interval is the posterior's HDI when sampled; the verdict is said
    import numpy as np

    from bayesplate.io import bundled_case_path
    from bayesplate.report import ReportOptions, compute_report
    from bayesplate.report.html import render_html, report_summary, summary_lines

    options = ReportOptions(diagnose=False, sample=False)
    data = compute_report(
        bundled_case_path("plate1"), options, small_report / ".cache", lambda line: None
    )
    b = data.results["B"]
    data.results["sample"] = {"hdi": np.stack([0.9 * b["constants"], 1.1 * b["constants"]])}
    diagnosis = {
        "verdict": "ambiguous",
        "chosen": "point_mass",
        "rival": {"physics": "cutout"},
        "also_tied": [],
    }
    data.results["diagnose"] = {"diagnosis": diagnosis}
    summary = report_summary(data)
    assert summary["interval"].startswith("posterior 94 % highest-density interval")
    assert summary["constants"][0]["low"] == pytest.approx(0.9 * b["constants"][0] / 1e9)
    text = "\n".join(["# plate 1", "", *summary_lines(summary)])
    assert "**ambiguous**: the misfit is explained by point_mass, or as well by cutout" in text
    page = parse_page(render_html(text, {}, "plate 1"))
    check_summary_against_json(page.summary_rows, json.loads(json.dumps(summary)))


def test_the_map_of_a_consistent_plate_says_nothing_was_found(small_report):
    # the location map of a plate where diagnose found nothing marks no "best place" and
    # says in the figure how little of the chi-square that place would explain
    from types import SimpleNamespace

    import numpy as np

    from bayesplate.discrepancy.physics.location import LocationMap
    from bayesplate.io import bundled_case_path, load_case
    from bayesplate.plate.model import PlateModel
    from bayesplate.plots import diagnosis_figures

    model = PlateModel.from_case(load_case(bundled_case_path("plate1")))
    x, y = np.meshgrid(np.linspace(5, 195, 8), np.linspace(5, 95, 4))
    points = np.column_stack([x.ravel(), y.ravel()])
    drop = np.linspace(0.0, 0.03, points.shape[0])
    lm = LocationMap(points, drop, np.ones_like(drop), np.ones_like(drop, bool), (4, 8))
    for verdict, nothing in (("consistent", True), ("unexplained", False)):
        d = SimpleNamespace(
            verdict=verdict,
            chosen=None,
            measured_Hz=np.arange(1.0, 5.0),
            nominal=SimpleNamespace(residual_sigma=np.array([0.3, -0.4, 0.2, 0.1])),
            mode_kinds=None,
            maps={"point_mass": lm},
        )
        fig = diagnosis_figures(model, d)["map_point_mass"]
        ax = fig.axes[0]
        texts = " ".join(t.get_text().replace("\n", " ") for t in ax.texts)
        labels = [h.get_label() for h in ax.get_lines()]
        if nothing:
            assert ax.get_title().endswith("nothing found")
            assert "the best place explains only 0.03 of the chi-square 0.3 (10 %)" in texts
            assert "best place" not in labels
        else:
            assert "nothing found" not in ax.get_title() + texts and "best place" in labels
        assert ax.get_xlabel() == "x (mm)" and ax.get_ylabel() == "y (mm)"


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="no chromium (`.ci/run` installs it)")
def test_report_html_in_a_real_browser(small_report, tmp_path):
    shots = {1280: tmp_path / "wide.png", 390: tmp_path / "phone.png"}
    seen = check_in_browser(small_report / "report.html", screenshots=shots)
    n = len(list(small_report.glob("*.png")))
    assert all(len(s["images"]) == n for s in seen.values())
    assert seen[390]["inner_width"] == 390  # the viewport tag: laid out for the phone
    for shot in shots.values():
        assert shot.read_bytes()[:8] == PNG and shot.stat().st_size > 20_000


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="no chromium (`.ci/run` installs it)")
def test_the_browser_check_sees_what_a_broken_page_does(tmp_path):
    # the check itself: a request leaving the file, a console error, a missing image and a
    # page wider than a phone are each caught
    page = tmp_path / "broken.html"
    page.write_text(
        '<!DOCTYPE html><meta name="viewport" content="width=device-width">'
        '<img src="missing.png"><img src="https://example.invalid/x.png">'
        '<div style="width:900px">wide</div><script>console.error("boom")</script>'
    )
    with Browser() as browser:
        seen = browser.look(page, 390, mobile=True)
    assert any("boom" in e for e in seen["errors"])
    assert any(r.startswith("https://example.invalid") for r in seen["requests"])
    assert any(r.endswith("missing.png") for r in seen["requests"])
    assert not all(i["complete"] and i["width"] > 0 for i in seen["images"])
    assert seen["scroll_width"] > 390


def _main(argv):
    import argparse

    parser = argparse.ArgumentParser(description="check report.html in Chromium, screenshot it")
    parser.add_argument("report_dir")
    parser.add_argument("screenshot")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--scale", type=float, default=0.5)
    parser.add_argument("--phone", help="also a PNG of the page's first screen on a phone")
    args = parser.parse_args(argv)
    page = pathlib.Path(args.report_dir) / "report.html"
    seen = check_in_browser(page, widths=((args.width, args.width < 600), (390, True)))
    with Browser() as browser:
        browser.look(
            page, args.width, mobile=args.width < 600, screenshot=args.screenshot, scale=args.scale
        )
        if args.phone:
            browser.look(page, 390, 844, mobile=True, screenshot=args.phone, full_page=False)
    size = page.stat().st_size
    print(
        f"{page}: {size / 1e6:.2f} MB, {len(seen[args.width]['images'])} figures shown; "
        f"laid out {seen[args.width]['scroll_width']} px wide in {args.width} px and "
        f"{seen[390]['scroll_width']} px in 390 px; no console error, no request"
    )


if __name__ == "__main__":
    _main(sys.argv[1:])
