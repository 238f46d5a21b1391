"""Serve the built-in lab with ``psg-data view demo --web`` and photograph Rerun's web viewer in a
real browser (headless Chromium through Playwright). Not part of CI.

Needs: Debian's chromium (``apt-get install chromium``), ``pip install playwright`` (only its
driver is used: the browser is the system's, ``/usr/bin/chromium``), psg-data[viewer]. Run from
the repository root:

    python docs/figures/viewer_screenshot.py [--out docs/figures/viewer_web.png] [--port 9093]

Prints the line ``psg-data view`` printed (scans, frames, points, label streams: the README's
numbers) and writes the screenshot.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from pathlib import Path

FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", type=Path, default=Path("docs/figures/viewer_web.png"))
    ap.add_argument("--port", type=int, default=9093)
    ap.add_argument("--wait", type=float, default=45.0, help="seconds for the viewer to load and draw")
    ap.add_argument("--step", type=int, default=20, help="scans to step forward (right arrow) before the picture")
    args = ap.parse_args()
    proc = subprocess.Popen(["psg-data", "view", "demo", "--web", "--port", str(args.port), "-q"],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    url = counts = ""
    try:
        for line in proc.stdout:
            print(line.rstrip())
            if line.startswith("web viewer: "):
                url = line.split(": ", 1)[1].strip()
            if line.startswith("sent to the web viewer"):
                counts = line.strip()
                break
        if not url:
            print("psg-data view --web did not print a URL", file=sys.stderr)
            return 1
        from playwright.sync_api import sync_playwright

        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=FLAGS)
            page = browser.new_page(viewport={"width": 1600, "height": 1000})
            page.goto(url)
            time.sleep(args.wait)
            page.mouse.click(800, 985)  # the time panel: keyboard focus for the arrow keys
            for _ in range(args.step):
                page.keyboard.press("ArrowRight")
                time.sleep(0.2)
            time.sleep(5.0)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out), timeout=120_000)
            browser.close()
        print(f"screenshot: {args.out}  ({counts})")
        return 0
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()


if __name__ == "__main__":
    sys.exit(main())
