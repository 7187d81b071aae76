"""The teaching lab in a real browser: Debian's headless Chromium driven by Playwright, no network.

The lab is served in-process on a free localhost port; each test opens a page, waits for a
condition (never a fixed sleep) and reads the plotted data from the page's Bokeh document.
Skipped when /usr/bin/chromium (``apt-get install -y chromium``) or Playwright is missing.
"""
from __future__ import annotations

import os
import re
import socket

import numpy as np
import pytest

pytestmark = pytest.mark.slow   # end-to-end runs of several seconds each: outside the fast subset

CHROMIUM = "/usr/bin/chromium"

if not os.path.exists(CHROMIUM):
    pytest.skip(f"{CHROMIUM} not found: the browser tests need Debian's chromium (apt-get install -y chromium)",
                allow_module_level=True)
pytest.importorskip("panel")
sync_api = pytest.importorskip("playwright.sync_api")

#: First page load and first simulation (numba compiles the kernel on a cold cache): generous; later waits short.
LOAD_MS = 120_000
WAIT_MS = 60_000

#: JS: the data column ``col`` of the newest ColumnDataSource called ``name`` in the page's Bokeh document.
_GET = """([name, col]) => {
  const d = window.Bokeh && window.Bokeh.documents && window.Bokeh.documents[0];
  if (!d) return null;
  const ms = [...d._all_models.values()].filter(m => m.name === name);
  const m = ms[ms.length - 1];
  return m && m.data[col] ? Array.from(m.data[col]) : null;
}"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def server():
    from valve_gym.lab.cli import serve
    from valve_gym.lab.models import LoopLab, ValveLab

    ValveLab(preset="fig7").simulate()     # compile the kernels before the browser waits on them
    LoopLab(seconds=300.0, settle=0.0).simulate()
    port = _free_port()
    srv = serve(port=port, address="localhost", show=False, threaded=True)
    yield f"http://localhost:{port}/lab"
    srv.stop()


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM,
                              args=["--no-sandbox", "--disable-background-networking", "--disable-gpu"])
        yield b
        b.close()


class Page:
    """A browser page on the lab that records page errors, console errors and requests off the server."""

    def __init__(self, browser, url: str):
        self.errors: list[str] = []
        self.offsite: list[str] = []
        self.page = browser.new_page(viewport={"width": 1400, "height": 1100})
        origin = url.split("/lab")[0]
        self.page.on("pageerror", lambda e: self.errors.append(f"pageerror: {e}"))
        self.page.on("console", lambda m: self.errors.append(f"console {m.type}: {m.text}")
                     if m.type == "error" else None)
        self.page.on("request", lambda r: None if r.url.startswith((origin, origin.replace("http", "ws"),
                                                                     "blob:", "data:"))
                     else self.offsite.append(r.url))
        self.page.set_default_timeout(WAIT_MS)

    def open(self, url: str, source: str):
        self.page.goto(url)
        self.wait_for(source, timeout=LOAD_MS)
        return self

    def wait_for(self, source: str, timeout: int = WAIT_MS):
        self.page.wait_for_function(f"() => ({_GET})([{source!r}, 't']) !== null", timeout=timeout)

    def data(self, source: str, col: str) -> np.ndarray:
        return np.array(self.page.evaluate(_GET, [source, col]), dtype=float)

    def wait_changed(self, source: str, col: str, old: np.ndarray):
        self.page.wait_for_function(
            f"""(old) => {{ const x = ({_GET})([{source!r}, {col!r}]);
                 return x !== null && (x.length !== old.length || x.some((v, i) => Math.abs(v - old[i]) > 1e-9)); }}""",
            arg=old.tolist())

    def clean(self):
        assert self.errors == [], self.errors
        assert self.offsite == [], f"requests off the server (no network allowed): {self.offsite}"

    def close(self):
        self.page.close()


@pytest.mark.slow
def test_each_page_loads_without_errors(server, browser):
    pg = Page(browser, server).open(server, "valve_source")
    try:
        assert pg.data("valve_source", "stem").size > 100
        pg.page.locator(".bk-tab", has_text="Loop").click()
        pg.wait_for("loop_source")
        pg.page.locator(".vg-lc p").first.wait_for()
        pg.page.locator(".bk-tab", has_text="Compensator").click()
        pg.wait_for("comp_source")
        pg.page.locator(".vg-comp-scores table").first.wait_for()
        assert "page=2" in pg.page.evaluate("() => window.location.search")
        pg.clean()
    finally:
        pg.close()


def test_moving_z_max_changes_the_stem_and_the_url(server, browser):
    pg = Page(browser, server).open(server, "valve_source")
    try:
        before = pg.data("valve_source", "stem")
        handle = pg.page.locator(".vg-v-z_max .noUi-handle")
        handle.focus()
        for _ in range(3):
            handle.press("ArrowLeft")        # 0.2 -> 0.185 s: less friction
        pg.wait_changed("valve_source", "stem", before)
        after = pg.data("valve_source", "stem")
        assert after.shape == before.shape and np.abs(after - before).max() > 1e-3
        pg.page.wait_for_function("() => window.location.search.includes('v_z_max=0.1')")
        pg.clean()
    finally:
        pg.close()


def _stick_slip(u: np.ndarray, h: np.ndarray) -> tuple[int, float]:
    """While the input ramps: samples where the stem stands still, and its largest one-sample move."""
    du, dh = np.abs(np.diff(u)), np.abs(np.diff(h))
    ramp = du > 0
    return int(np.sum(ramp & (dh < 1e-9))), float(dh[ramp].max())


@pytest.mark.slow
def test_fig7_preset_shows_stick_slip_and_downloads_its_traces(server, browser, tmp_path):
    pg = Page(browser, server).open(server + "?v_input=sine&v_seconds=200", "valve_source")
    try:
        sine = pg.data("valve_source", "stem")
        pg.page.locator(".vg-v-preset select").select_option("fig7")
        pg.wait_changed("valve_source", "stem", sine)
        u, h = pg.data("valve_source", "input"), pg.data("valve_source", "stem")
        healthy = pg.data("valve_source", "healthy")
        stalls, jump = _stick_slip(u, h)
        assert stalls > 100 and jump > 0.02          # the stem sticks, then jumps, while the input ramps
        assert _stick_slip(u, healthy)[1] < 0.01     # the healthy ghost follows the ramps
        # the summary is re-rendered after the data: wait for its text, do not read it once
        sync_api.expect(pg.page.locator(".vg-valve-summary p").first).to_contain_text("stem jump", timeout=WAIT_MS)
        # the downloads: the CSV holds the plotted traces, the PNG is a PNG
        with pg.page.expect_download() as dl:
            pg.page.locator(".vg-valve-csv button").click()
        dl.value.save_as(tmp_path / "valve.csv")
        rows = (tmp_path / "valve.csv").read_text().splitlines()
        assert rows[0].startswith("t_s,input_-,stem_-,healthy_h_-,friction_")
        csv = np.array([[float(x) for x in r.split(",")] for r in rows[1:]])
        np.testing.assert_allclose(csv[:, 2], h, rtol=1e-5, atol=1e-6)
        with pg.page.expect_download() as dl:
            pg.page.locator(".vg-valve-png button").click()
        dl.value.save_as(tmp_path / "valve.png")
        assert (tmp_path / "valve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        pg.clean()
    finally:
        pg.close()


def test_loop_page_limit_cycle_with_high_friction_and_none_without(server, browser):
    pg = Page(browser, server).open(server + "?page=1", "loop_source")
    try:
        sync_api.expect(pg.page.locator(".vg-lc p").first).to_have_text(re.compile(r"^limit cycle: amplitude"),
                                                                         timeout=WAIT_MS)
        pg.close()
        pg = Page(browser, server).open(server + "?page=1&l_z_max=0&l_e_dead=0", "loop_source")
        sync_api.expect(pg.page.locator(".vg-lc p").first).to_have_text(re.compile(r"^no limit cycle"),
                                                                         timeout=WAIT_MS)
        pg.clean()
    finally:
        pg.close()

