"""The live view in a real browser: the distribution's Chromium driven by
Playwright (marker ``browser``). Skipped when no Chromium is found, unless
TELETHERMAL_REQUIRE_BROWSER=1 (CI), where that is a failure.

One live session on loopback (slave and master as processes, the view
server in this process), one touch on graphite, then its recording and two
bad ones played on the same page.
"""

import json
import os
import shutil
import threading
import urllib.request
from pathlib import Path

import pytest

from telethermal.physics.scene import load_scene, with_finger
from telethermal.demo.run import Services, wait_connected, write_configs
from telethermal.demo.touches import networked_touch
from telethermal.ports import free_ports
from telethermal.view.browser import BrowserUnavailable, find_chromium, launch
from telethermal.services.viewer import open_view

pytestmark = pytest.mark.browser
SCENE = with_finger(load_scene("fingertip-7"))
#: Decided confidently by the default identifier in every seed tried.
MATERIAL = "graphite"


@pytest.fixture(scope="module")
def browser():
    try:
        path = find_chromium()
    except BrowserUnavailable as exc:
        if os.environ.get("TELETHERMAL_REQUIRE_BROWSER") == "1":
            pytest.fail(f"TELETHERMAL_REQUIRE_BROWSER=1 but {exc}")
        pytest.skip(str(exc))
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        browser = launch(p, path)
        yield browser
        browser.close()


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.files(SCENE, 0)


class PageWatch:
    """A page with every failed request, error response and script error."""

    def __init__(self, page):
        self.page, self.failed, self.errors = page, [], []
        page.on("requestfailed", lambda r: self.failed.append(f"{r.url}: {r.failure}"))
        # (a bad recording is answered 422 with its reason: that is expected)
        page.on("response", lambda r: r.status >= 400 and "/api/recording" not in r.url and
                self.failed.append(f"{r.url}: {r.status}"))
        page.on("pageerror", lambda e: self.errors.append(str(e)))

    def number(self, selector: str) -> float:
        return float(self.page.get_attribute(selector, "data-value") or "nan")

    def points(self, canvas: str) -> int:
        return int(self.page.get_attribute(f"#plot-{canvas}", "data-points") or 0)


def _other_version(path: Path) -> Path:
    """A recording whose metadata says version 99."""
    import telethermal.record.recording as recording
    saved = recording.RECORDING_VERSION
    recording.RECORDING_VERSION = 99
    try:
        recording.Recorder(path, "master").close()
    finally:
        recording.RECORDING_VERSION = saved
    return path


def test_live_session_then_its_recording_in_chromium(tmp_path, models, browser):
    ident, gen = models
    ports = free_ports(5)
    record = tmp_path / "rec"
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, ident, gen, ports[:4], 0,
                                          record_dir=record, view_port=ports[4])
    services = Services(tmp_path, slave_cfg, master_cfg)
    view = None
    try:
        wait_connected(services, ports[3])
        view = open_view(master_cfg, None, 0)
        page = browser.new_page(viewport={"width": 1100, "height": 860})
        watch = PageWatch(page)
        page.goto(view.url)
        page.wait_for_selector('#mode[data-mode="live"]')
        result = {}
        # Every count the page shows, recorded in the page as it shows it (a
        # test that read the first count itself could read it after the
        # touch had ended, on a loaded host, and wait for a rise in vain).
        page.evaluate("""() => {
            const el = document.querySelector('#count-master');
            window.shownCounts = [];
            new MutationObserver(() => {
                const v = Number(el.dataset.value);
                if (v > 0 && window.shownCounts.at(-1) !== v) window.shownCounts.push(v);
            }).observe(el, {attributes: true, attributeFilter: ['data-value']});
        }""")
        touch = threading.Thread(target=lambda: result.update(networked_touch(
            SCENE, MATERIAL, ports[:4], seed=2, contact_s=1.5).summary))
        touch.start()
        page.wait_for_selector('#decision:not([data-label=""])', timeout=20_000)
        touch.join(30)
        # The counters rose while the touch went on: the page showed a
        # count, then a larger one (by how much between two renders is the
        # browser's and the machine's pace).
        shown = page.evaluate("window.shownCounts")
        assert len(shown) >= 2 and shown == sorted(shown), shown
        assert result["identified"] == MATERIAL
        # The posterior shows the decided material, as the slave decided it.
        assert page.get_attribute("#decision", "data-label") == MATERIAL
        page.wait_for_function("Number(document.querySelector('#count-slave').dataset.value)"
                               " > 50", timeout=10_000)
        for canvas in ("temp", "master-flux", "slave-flux"):
            assert watch.points(canvas) > 10, canvas
        # The view stream carries the newest posterior every 20 ms and the page
        # takes the newest every 50 ms, while a confident touch has a few
        # estimates 10 ms apart before its commit (then none until the last
        # window): one to three of them reach the page, by the load. Every one
        # has a point per class, and the last is the decision's.
        # Each estimate drawn is a distribution over the 7 classes, and the
        # last one drawn is the decision's, its largest posterior the class
        # named.
        classes, drawn = page.evaluate("""() => [posterior.classes,
            posterior.plot.series.map((s) => s.pts)]""")
        assert len(classes) == 7 and len(drawn) == 7
        times = [t for t, _ in drawn[0]]
        assert times and all([t for t, _ in s] == times for s in drawn)
        for j in range(len(times)):
            assert sum(s[j][1] for s in drawn) == pytest.approx(1.0, abs=1e-6), times[j]
        last = [s[-1][1] for s in drawn]
        assert classes[last.index(max(last))] == MATERIAL
        assert times[-1] == pytest.approx(page.evaluate("posterior.plot.marker[0]"), abs=1e-9)
        page.wait_for_function("document.querySelector('#lag-p99').dataset.value !== ''")
        shot = tmp_path / "view.png"
        page.screenshot(path=str(shot))
        if os.environ.get("TELETHERMAL_VIEW_SCREENSHOT"):
            shutil.copy(shot, os.environ["TELETHERMAL_VIEW_SCREENSHOT"])
        # Rollover: 100 s of 1 kHz into a plot keeps only the window.
        kept = page.evaluate("""() => { const p = plots.temp; p.clear();
            for (let i = 0; i < 100000; i++) p.push('master_temp', [[i / 1000, 20]]);
            p.trim(100 - WINDOW_S); return p.points(); }""")
        assert kept == 20_000
        assert not watch.failed and not watch.errors, (watch.failed, watch.errors)
    finally:
        codes = services.stop()
        if view is not None:
            view.close()
    assert codes == {"slave": 0, "master": 0}

    # The recordings, and two bad files, played by a view with no live session.
    (master_rec,) = record.glob("master-*.mcap")
    data = master_rec.read_bytes()
    (record / "cut.mcap").write_bytes(data[:int(len(data) * 0.6)])
    _other_version(record / "v99.mcap")
    (record / "junk.mcap").write_bytes(b"not an mcap file at all")
    view = open_view(None, record, 0)
    try:
        page.goto(view.url)
        page.wait_for_selector('#mode[data-mode="idle"]')
        for bad, why in (("v99.mcap", "recording version 99"),
                         ("junk.mcap", "not a telethermal recording")):
            page.select_option("#recording", bad)
            page.wait_for_selector('#playback-status[data-state="error"]')
            assert bad in page.inner_text("#message") and why in page.inner_text("#message")
        # The server is still there after the bad files.
        with urllib.request.urlopen(view.url + "api/info") as resp:
            assert "cut.mcap" in json.load(resp)["recordings"]
        for name, note in ((master_rec.name, ""), ("cut.mcap", "cut mid-write")):
            page.select_option("#recording", name)
            page.wait_for_selector('#playback-status[data-state="ready"]')
            assert note in page.inner_text("#message")
            assert watch.number("#count-master") > 100
            page.select_option("#speed", "32")
            page.click("#play")
            page.wait_for_selector('#playback-status[data-state="ended"]', timeout=20_000)
            assert watch.points("temp") > 10
            if name == master_rec.name:
                assert page.get_attribute("#decision", "data-label") == MATERIAL
        assert not watch.errors, watch.errors
    finally:
        view.close()


def test_the_flux_plots_draw_flux_out_of_the_finger_positive(tmp_path, browser):
    """The view's flux plots in the project's one convention (issue 46's
    review): the master's flux and setpoint and the slave's setpoint are the
    display's flux into the finger, drawn negated (a cold object: positive,
    as the touch and replay plots draw it); the slave pad's own flux (pad
    -> object) as it is; each caption says so."""
    view = open_view(None, tmp_path, 0)
    try:
        page = browser.new_page()
        watch = PageWatch(page)
        page.goto(view.url)
        page.wait_for_selector('#mode[data-mode="idle"]')
        drawn = page.evaluate("""() => {
            plots.masterFlux.push('master_flux', [[0, -5000]]);
            plots.masterFlux.push('master_setpoint', [[0, -4000]]);
            plots.slaveFlux.push('slave_setpoint', [[0, -3000]]);
            plots.slaveFlux.push('slave_flux', [[0, 2000]]);
            return [plots.masterFlux, plots.slaveFlux].flatMap(
                (p) => p.series.map((s) => [s.name, s.pts[0][1]])); }""")
        assert dict(drawn) == {"master_flux": 5000, "master_setpoint": 4000,
                               "slave_setpoint": 3000, "slave_flux": 2000}
        captions = page.locator("figcaption").all_inner_texts()
        assert any("positive out of the finger" in c and "Master" in c for c in captions)
        assert any("positive into the object" in c and "Slave" in c for c in captions)
        assert not watch.errors, watch.errors
    finally:
        view.close()
