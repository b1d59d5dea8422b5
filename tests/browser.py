"""Headless Chromium for the tests of pages: find it, load a page, take a screenshot, read the console.

Debian's ``chromium`` package (``.ci/run`` installs it). The flags: no sandbox (root in
CI), no GPU (WebGL2 through SwiftShader, the software renderer), nothing that talks to
the network, a fresh profile per run.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

BINARIES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--enable-logging=stderr", "--v=0")
# The software renderer's own notes on reading pixels back for a screenshot: not the page's.
DRIVER_NOTE = re.compile(r"GL Driver Message \(OpenGL, Performance")


def chromium() -> str:
    """The Chromium binary; the test is skipped, saying how to install it, when there is none."""
    for name in BINARIES:
        found = shutil.which(name)
        if found:
            return found
    pytest.skip("no Chromium binary (chromium, chromium-browser, google-chrome) on PATH: `apt-get install -y "
                "chromium` (.ci/run installs it) to test the HTML view in a real browser")


def run(url: str, profile: Path, *extra: str, size=(1400, 950), budget_ms: int = 20000,
        timeout_s: float = 180.0) -> tuple[str, list[str]]:
    """Load ``url`` in headless Chromium with ``extra`` flags (--screenshot=..., --dump-dom); (stdout, the
    page's console messages, the renderer's notes left out)."""
    profile.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([chromium(), *FLAGS, f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}",
                           f"--virtual-time-budget={budget_ms}", *extra, url],
                          capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL)
    console = [line for line in proc.stderr.splitlines() if ":CONSOLE" in line and not DRIVER_NOTE.search(line)]
    return proc.stdout, console
