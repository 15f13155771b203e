"""``telethermal bench view``: the live view's first paint, its lag behind a
session at the display's default rate, and the master's loop timing without the view stream, with
it and no page, and with the page open in Chromium.

Slave and master run as processes on loopback (CURVE) with the display
loop at its default rate; the view server runs in this process and Chromium (the
distribution's, through Playwright) shows the page. First paint: from the
server's start to the page's first contentful paint (the browser's own
paint timing), with a fresh server each time. Lag: for every live frame
with samples, the newest sample's age when the page drew it (the frame's
age at the server, on the shared monotonic clock, plus its way to the
page's draw, on the shared wall clock). Loop timing: the master's own
per-touch figures (busy time per period, period p99, deadline misses).
"""

from __future__ import annotations

import datetime
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.jsonfile import write_json
from telethermal.physics.scene import load_scene, with_finger
from telethermal.render.generator import save_generator
from telethermal.demo.run import Services, wait_connected, write_configs
from telethermal.demo.touches import networked_touch
from telethermal.ports import free_ports
from telethermal.services.viewer import open_view
from telethermal.teleop.master import Phase
from telethermal.view.browser import launch

MATERIAL = "graphite"
MODES = ("no_view", "stream_no_page", "page_open")
#: The display loop's SCHED_FIFO priority, as in the demo (where granted).
REALTIME_PRIORITY = 20


def publisher_call_us(n: int = 5000) -> dict:
    """The view stream's cost to one display period, alone: the call the
    loop makes every period (one message every ``BATCH_S`` of them), with a
    subscriber connected."""
    import zmq

    from telethermal.view.stream import ViewPublisher
    state = {"contact_id": 3, "touching": True, "phase": Phase.RENDER, "safe": False,
             "setpoint_w_m2": -3500.0, "events": {}, "rtt_s": 0.0003,
             "link": dict.fromkeys(("lossless_sent", "stream_lost", "resent", "gaps",
                                    "heartbeats_missed", "reconnects", "invalid"), 0),
             "classes": ["a", "b", "c", "d", "e", "f", "g"], "posteriors": [1 / 7] * 7,
             "label": "a", "decided": True, "estimate_t_s": 0.3}
    pub = ViewPublisher(0, 3000.0)
    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.linger = 0
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(f"tcp://127.0.0.1:{pub.port}")
    time.sleep(0.2)
    calls = []
    try:
        for k in range(n):
            t0 = time.perf_counter()
            pub.period(k / DEFAULT_RATE_HZ, DEFAULT_RATE_HZ, -1234.5 + k, 30.1, 4.0,
                       lambda: dict(state))
            calls.append(time.perf_counter() - t0)
    finally:
        pub.close()
        sub.close(linger=0)
    us = np.asarray(calls) * 1e6
    return {"mean_us": float(us.mean()), "p50_us": float(np.percentile(us, 50)),
            "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max()),
            "sent": pub.counters["sent"]}


def _first_paint(browser, master_cfg: Path) -> dict:
    """Server start -> first contentful paint, and -> first live frame drawn."""
    page = browser.new_page()
    start_wall = time.time()
    view = open_view(master_cfg, None, 0)
    try:
        page.goto(view.url)
        page.wait_for_function("window.viewStats.fcp_ms !== null")
        fcp = page.evaluate("performance.timeOrigin + window.viewStats.fcp_ms") / 1000
        page.wait_for_function("Number(document.querySelector('#frames').dataset.value) > 0")
        frame_wall = time.time()
    finally:
        page.close()
        view.close()
    return {"first_paint_s": fcp - start_wall, "first_frame_s": frame_wall - start_wall}


def _touches(ports, scene, n: int, contact_s: float, seed0: int) -> list[dict]:
    rows = []
    for i in range(n):
        s = networked_touch(scene, MATERIAL, ports, seed0 + i, contact_s).summary
        loop = s["loop"]
        rows.append({k: loop[k] for k in ("busy_mean_us", "busy_p99_us", "period_p99_us",
                                          "lateness_p99_us", "deadline_misses", "steps",
                                          "deadlines_set_aside", "setup_s")}
                    | {"identified": s["identified"]})
    return rows


def _summary(rows: list[dict]) -> dict:
    return {"busy_mean_us": float(np.mean([r["busy_mean_us"] for r in rows])),
            "busy_p99_us": float(np.mean([r["busy_p99_us"] for r in rows])),
            "period_p99_us": float(np.mean([r["period_p99_us"] for r in rows])),
            "deadline_misses": int(sum(r["deadline_misses"] for r in rows)),
            "steps": int(sum(r["steps"] for r in rows)),
            # Each touch's set-up, before its first period (services/master.py).
            "deadlines_set_aside": int(sum(r["deadlines_set_aside"] for r in rows)),
            "setup_s_max": float(max(r["setup_s"] for r in rows)), "touches": rows}


def run_view_bench(touches: int = 3, contact_s: float = 3.0, progress=print,
                   realtime_priority: int = REALTIME_PRIORITY, models=None) -> dict:
    """The report; ``models``: a folder of ``telethermal models`` for
    fingertip-7 (:func:`telethermal.bench.models.bench_models`; None:
    trained here)."""
    from playwright.sync_api import sync_playwright

    from telethermal.bench.models import bench_models

    scene = with_finger(load_scene("fingertip-7"))
    rows = {m: [] for m in MODES}
    lags: list[float] = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        tmp = Path(tmp)
        identifier, generator, provenance = bench_models(scene, models)
        ident = identifier.save(tmp / "identifier.npz")
        gen = save_generator(generator, tmp / "generator.npz")
        browser = launch(pw)
        for mode_set in (("no_view",), ("stream_no_page", "page_open")):
            out = tmp / mode_set[0]
            out.mkdir()
            ports = free_ports(5)
            slave_cfg, master_cfg = write_configs(
                out, scene.name, ident, gen, ports[:4], 0, realtime_priority=realtime_priority,
                view_port=ports[4] if mode_set[0] != "no_view" else 0)
            services = Services(out, slave_cfg, master_cfg)
            try:
                wait_connected(services, ports[3])
                if mode_set[0] == "no_view":
                    progress(f"{touches} touches, no view stream")
                    rows["no_view"] = _touches(ports[:4], scene, touches, contact_s, 1)
                    continue
                paints = [_first_paint(browser, master_cfg) for _ in range(3)]
                view = open_view(master_cfg, None, 0)
                try:
                    progress(f"{touches} touches, view stream, no page")
                    rows["stream_no_page"] = _touches(ports[:4], scene, touches, contact_s, 1)
                    progress(f"{touches} touches, view stream, page open")
                    page = browser.new_page(viewport={"width": 1100, "height": 860})
                    page.goto(view.url)
                    page.wait_for_selector('#mode[data-mode="live"]')
                    rows["page_open"] = _touches(ports[:4], scene, touches, contact_s, 1)
                    time.sleep(0.3)
                    lags = page.evaluate("live.lags")
                    points = page.evaluate("Object.values(plots).map((p) => p.points())")
                    page.close()
                finally:
                    view.close()
            finally:
                services.stop()
        browser.close()
    lag = np.asarray(lags)
    return {
        "material": MATERIAL, "touches_per_mode": touches, "contact_s": contact_s,
        "rate_hz": DEFAULT_RATE_HZ, "models": provenance,
        "first_paint_s": max(p["first_paint_s"] for p in paints),
        "first_frame_s": max(p["first_frame_s"] for p in paints), "first_paints": paints,
        "lag_frames": int(len(lag)),
        "lag_p50_s": float(np.percentile(lag, 50)) if len(lag) else None,
        "lag_p99_s": float(np.percentile(lag, 99)) if len(lag) else None,
        "lag_max_s": float(lag.max()) if len(lag) else None,
        "page_points_held": points,
        "loop": {m: _summary(rows[m]) for m in MODES},
        "realtime_priority": realtime_priority,
        "publisher_call": publisher_call_us(),
        "targets": {"first_paint_s": 2.0, "lag_p99_s": 0.2},
        "command": "telethermal bench view --json bench/results/view.json" + (
            f" --realtime-priority {realtime_priority}"
            if realtime_priority != REALTIME_PRIORITY else ""),
        "machine": f"{platform.node()} ({platform.machine()}, "
                   f"{platform.python_implementation()} {platform.python_version()})",
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def run_and_save(json_path, touches: int = 3, contact_s: float = 3.0, progress=print,
                 realtime_priority: int = REALTIME_PRIORITY, command: str = "",
                 models=None) -> dict:
    """:func:`run_view_bench`, its report written to ``json_path`` with
    ``command`` (the command line as typed; the bench's default when empty)."""
    report = run_view_bench(touches=touches, contact_s=contact_s, progress=progress,
                            realtime_priority=realtime_priority, models=models)
    if command:
        report["command"] = command
    write_json(json_path, report)
    return report


