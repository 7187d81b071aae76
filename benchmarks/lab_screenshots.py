"""Screenshots of the teaching lab's pages for the docs (``docs/figures/lab/*.png``).

Serves the lab in-process on a free localhost port and photographs each page with Debian's
headless Chromium through Playwright (no network needed):

* ``valve.png``: the valve page, figure-7 preset (ramps: stick-slip);
* ``valve_fig6.png``: the valve page, figure-6 preset (slow sine: input vs stem);
* ``loop.png``: the loop page, the paper's tank with high friction and its frictionless ghost;
* ``loop_fig10.png``: the loop page, figure 10 (low and high friction side by side);
* ``compensator.png``: the compensator page, the knocker against the PI.

Usage::

    python benchmarks/lab_screenshots.py [--out docs/figures/lab] [--chromium /usr/bin/chromium]
"""
from __future__ import annotations

import argparse
import os
import socket
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))    # this checkout's valve_gym

from valve_gym._io import write_atomic  # noqa: E402

SHOTS = (
    ("valve.png", "?page=0", "valve_source"),
    ("valve_fig6.png", "?page=0", "valve_source"),
    ("loop.png", "?page=1", "loop_source"),
    ("loop_fig10.png", "?page=1&l_fig10=true", "loop_high_source"),
    ("compensator.png", "?page=2", "comp_source"),
)

_HAS = """(name) => { const d = window.Bokeh && window.Bokeh.documents && window.Bokeh.documents[0];
  return !!d && [...d._all_models.values()].some(m => m.name === name); }"""

_LEN = """([name, n]) => { const d = window.Bokeh.documents[0];
  const ms = [...d._all_models.values()].filter(m => m.name === name);
  return ms.length > 0 && ms[ms.length - 1].data.t.length === n; }"""


def main(argv=None) -> int:
    """Write the screenshots; prints each path."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--out", default="docs/figures/lab", help="output folder (default docs/figures/lab)")
    ap.add_argument("--chromium", default="/usr/bin/chromium", help="Chromium executable")
    args = ap.parse_args(argv)
    if not os.path.exists(args.chromium):
        print(f"lab_screenshots: {args.chromium} not found; apt-get install -y chromium", file=sys.stderr)
        return 1
    from playwright.sync_api import sync_playwright

    from valve_gym.lab.cli import serve

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = serve(port=port, address="localhost", show=False, threaded=True)
    try:
        with sync_playwright() as p:
            b = p.chromium.launch(executable_path=args.chromium,
                                  args=["--no-sandbox", "--disable-background-networking", "--disable-gpu"])
            for name, query, source in SHOTS:
                page = b.new_page(viewport={"width": 1400, "height": 1000})
                page.goto(f"http://localhost:{port}/lab{query}")
                page.wait_for_function(_HAS, arg=source, timeout=180_000)
                if name == "valve_fig6.png":      # pick the preset in its menu, wait for the sine's stem
                    page.locator(".vg-v-preset select").select_option("fig6")
                    page.wait_for_function(_LEN, arg=["valve_source", 4000], timeout=60_000)
                page.wait_for_load_state("networkidle")
                png = page.screenshot(full_page=True)
                print(write_atomic(os.path.join(args.out, name), lambda f, png=png: f.write(png)), flush=True)
                page.close()
            b.close()
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
