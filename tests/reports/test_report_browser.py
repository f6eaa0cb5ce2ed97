"""The HTML report in a real browser: headless Chromium loads a copy of the page with a probe
script appended (the page itself has none), and the probe reports what a reader would see: every
image decoded, no part of the page wider than the window at a desktop and a narrow width (a wide
table scrolls in its own box, its caption stays in view), every in-page link landing on an element.
A page with a missing image, an unwrapped wide table and its caption is shown to fail the probe.

Needs Chromium (Debian's ``chromium``; ``$ECODRIVE_BROWSER`` names another binary). Without one the
tests skip, unless ``ECODRIVE_REQUIRE_BROWSER=1`` (set by ``.ci/run``, which installs Chromium), where
they fail."""
from __future__ import annotations

import html
import json
import os
import re
import shutil
import struct
import subprocess
import zlib
from pathlib import Path

import pytest

WIDTHS = (1280, 500)  # [px] a desktop window and about the narrowest headless Chromium opens
PROBE = """<script>
window.addEventListener('load', () => {
  const vw = document.documentElement.clientWidth;
  const scrolled = e => e.parentElement && e.parentElement.closest('.scroll');
  const r = {
    width: vw,
    images: document.images.length,
    broken: [...document.images].filter(i => !i.complete || i.naturalWidth === 0).map(i => i.getAttribute('src')),
    overflow: document.documentElement.scrollWidth - vw,
    wide: [...document.querySelectorAll('table, figure, pre, img')]
      .filter(e => e.getBoundingClientRect().right > vw + 1 && !scrolled(e)).map(e => e.tagName.toLowerCase()),
    cut_captions: [...document.querySelectorAll('caption')]
      .filter(c => c.getBoundingClientRect().right > vw + 1).map(c => c.textContent.slice(0, 40)),
    dangling: [...document.querySelectorAll('a[href^="#"]')]
      .filter(a => !document.getElementById(decodeURIComponent(a.getAttribute('href').slice(1))))
      .map(a => a.getAttribute('href')),
  };
  const out = document.createElement('pre');
  out.id = 'probe';
  out.textContent = JSON.stringify(r);
  document.body.appendChild(out);
});
</script>"""
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars"]


def browser() -> str | None:
    named = os.environ.get("ECODRIVE_BROWSER")
    if named:
        return named
    return next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)


@pytest.fixture(scope="module")
def chromium() -> str:
    exe = browser()
    if exe is not None and shutil.which(exe) is None:
        pytest.fail(f"$ECODRIVE_BROWSER={exe!r} is not an executable")
    if exe is None:
        if os.environ.get("ECODRIVE_REQUIRE_BROWSER") == "1":
            pytest.fail("ECODRIVE_REQUIRE_BROWSER=1 but no Chromium found (apt-get install chromium, or set "
                        "$ECODRIVE_BROWSER)")
        pytest.skip("no Chromium (apt-get install chromium, or set $ECODRIVE_BROWSER)")
    return exe


def probe(exe: str, page: Path, width: int, tmp: Path) -> dict:
    """Load a probed copy of ``page`` (next to the original's figures) at ``width`` px and return the probe's report."""
    copy = page.with_name(f".probe-{page.name}")
    copy.write_text(page.read_text().replace("</body>", PROBE + "</body>"))
    try:
        out = subprocess.run([exe, *FLAGS, f"--user-data-dir={tmp / f'profile-{width}'}", f"--window-size={width},900",
                              "--virtual-time-budget=10000", "--dump-dom", copy.as_uri()],
                             capture_output=True, text=True, timeout=120)
    finally:
        copy.unlink()
    m = re.search(r'<pre id="probe">([^<]*)</pre>', out.stdout)
    assert m, f"{exe} printed no probe (exit {out.returncode}): {out.stderr[-500:]}"
    return json.loads(html.unescape(m.group(1)))


@pytest.mark.parametrize("width", WIDTHS)
def test_the_report_renders_in_chromium(chromium, smoke_report, width, tmp_path):
    r = probe(chromium, smoke_report["dir"] / "index.html", width, tmp_path)
    assert r["width"] >= width * 0.9  # the window was opened at about the asked width
    assert r["images"] == 8 and r["broken"] == []  # a violin per setting, 3 trajectory cases per setting
    assert r["overflow"] <= 0 and r["wide"] == []  # wide tables scroll inside their own box
    assert r["cut_captions"] == []  # while their captions stay within the window
    assert r["dangling"] == []


def png_1x1() -> bytes:
    """A valid one-pixel PNG (signature, IHDR, IDAT, IEND)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\x00\x80")) + chunk(b"IEND", b""))


def test_the_probe_catches_a_bad_page(chromium, tmp_path):
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "ok.png").write_bytes(png_1x1())
    cells = "".join(f"<td>{'x' * 40}</td>" for _ in range(40))
    page = tmp_path / "index.html"
    page.write_text("<html><body><img src='figures/ok.png'><img src='figures/missing.png'>"
                    f"<a href='#nowhere'>x</a><table><caption>{'words ' * 400}</caption><tr>{cells}</tr></table>"
                    "</body></html>")
    r = probe(chromium, page, WIDTHS[0], tmp_path)
    assert r["images"] == 2 and r["broken"] == ["figures/missing.png"]
    assert r["overflow"] > 0 and "table" in r["wide"] and r["dangling"] == ["#nowhere"] and len(r["cut_captions"]) == 1
