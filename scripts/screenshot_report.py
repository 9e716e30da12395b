#!/usr/bin/env python3
"""Screenshots of a report.html in headless Chromium, for a look at the page as a browser shows it.

    python scripts/screenshot_report.py RUN_DIR/report.html [-o OUT_DIR] [--full-height 6000]

Renders the page at 1366x900 (a laptop's first screen) and 390x844 (a
phone's), with ``chromium --headless --screenshot=OUT.png --window-size=W,H
file://...``, and prints one JSON document: the PNG paths with their sizes
in pixels and bytes.  ``--full-height H`` adds a 1366xH shot of (most of) the
page below the first screen.  Chromium comes from Debian (``apt-get install
chromium``); ``--chromium PATH`` names another binary.  Exit status 2 when
no Chromium is found or it writes no PNG.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

#: (name, width, height) of the default shots.
VIEWPORTS = (("desktop", 1366, 900), ("phone", 390, 844))
CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium(path: str | None = None) -> str | None:
    """The Chromium binary: ``path``, else the first of :data:`CANDIDATES` on the PATH."""
    if path:
        return path if shutil.which(path) else None
    return next((p for p in map(shutil.which, CANDIDATES) if p), None)


def png_size(path) -> tuple[int, int]:
    """Width and height of a PNG from its IHDR chunk."""
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise ValueError(f"{path}: not a PNG")
    return struct.unpack(">II", head[16:24])


def screenshot(chromium: str, page: Path, out: Path, width: int, height: int, timeout: float = 120.0) -> dict:
    """One headless screenshot of ``page`` at ``width x height``; its path and sizes."""
    out.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory(prefix="polyrob-chromium-") as profile:
        cmd = [
            chromium,
            "--headless",
            "--no-sandbox",  # root in a container has no user namespace for the sandbox
            "--disable-gpu",
            "--hide-scrollbars",
            "--no-first-run",
            "--allow-file-access-from-files",
            f"--user-data-dir={profile}",
            f"--screenshot={out}",
            f"--window-size={width},{height}",
            page.resolve().as_uri(),
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env={**os.environ, "HOME": profile})
    if not out.is_file():
        raise RuntimeError(f"chromium wrote no {out.name} (exit {proc.returncode}): {proc.stderr.strip()[-500:]}")
    w, h = png_size(out)
    return {"path": str(out), "width": w, "height": h, "bytes": out.stat().st_size}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("report", help="report.html to render")
    ap.add_argument("-o", "--output", default=None, help="directory of the PNGs (default: beside the report)")
    ap.add_argument("--chromium", default=None, help="Chromium binary (default: chromium on the PATH)")
    ap.add_argument("--full-height", type=int, default=0, help="also a 1366 px wide shot this many px tall")
    args = ap.parse_args(argv)
    page = Path(args.report)
    if not page.is_file():
        print(f"screenshot_report: {page}: no such file", file=sys.stderr)
        return 2
    chromium = find_chromium(args.chromium)
    if chromium is None:
        print("screenshot_report: no chromium found (apt-get install -y chromium)", file=sys.stderr)
        return 2
    out_dir = Path(args.output) if args.output else page.parent / "screenshots"
    out_dir.mkdir(parents=True, exist_ok=True)
    views = list(VIEWPORTS) + ([("full", 1366, args.full_height)] if args.full_height > 0 else [])
    shots = {}
    try:
        for name, w, h in views:
            shots[name] = screenshot(chromium, page, out_dir / f"{page.stem}_{name}_{w}x{h}.png", w, h)
    except (RuntimeError, subprocess.TimeoutExpired, ValueError) as exc:
        print(f"screenshot_report: {exc}", file=sys.stderr)
        return 2
    print(json.dumps({"report": str(page), "chromium": chromium, "screenshots": shots}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
