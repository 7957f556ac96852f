"""Headless Chromium for the viewer tests: load a page, dump its DOM or take a screenshot, collect console lines.

Tests that need it are skipped with a reason when no Chromium binary is found (`.ci/run` installs the
Debian `chromium` package). The page's hidden `#status` element reports what it drew (see viewer.js).
"""

from __future__ import annotations

import html
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
needs_browser = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium found: apt-get install -y chromium "
                                                            "(.ci/run installs it)")
WINDOW = (1200, 800)
_CONSOLE = re.compile(r":CONSOLE[^\]]*\] (.*)")


def run_chromium(url: str, *, screenshot: Path | None = None, window: tuple[int, int] = WINDOW,
                 budget_ms: int = 5000) -> tuple[str, list[str]]:
    """(the DOM after scripts ran, or "" for a screenshot run; the page's console lines)."""
    args = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--enable-logging=stderr",
            "--v=0", f"--window-size={window[0]},{window[1]}", f"--virtual-time-budget={budget_ms}",
            "--force-device-scale-factor=1"]
    args += [f"--screenshot={screenshot}"] if screenshot else ["--dump-dom"]
    result = subprocess.run(args + [url], capture_output=True, text=True, timeout=90)
    assert result.returncode == 0, result.stderr[-3000:]
    return (result.stdout if screenshot is None else ""), _CONSOLE.findall(result.stderr)


def status(dom: str) -> dict[str, str]:
    """The data-* attributes of the page's #status element."""
    tag = re.search(r'<div id="status"[^>]*>', dom)
    assert tag, "the page has no #status element (did the script run?)"
    return {k: html.unescape(v) for k, v in re.findall(r'data-([a-z-]+)="([^"]*)"', tag.group(0))}


def ints(text: str) -> list[int]:
    return [int(round(float(v))) for v in text.split(",")]


def rgb(png: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def colour_mask(image: np.ndarray, hex_colour: str, tolerance: int = 40) -> np.ndarray:
    target = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
    return np.abs(image - target).sum(axis=-1) <= tolerance
