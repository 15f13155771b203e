"""``telethermal bench faults``: rendering under network faults, the
compensated path beside the naive one, measured in the same run.

Slave and master run as processes (plain loopback sockets) with the fault
proxy (``telethermal faults``) between them, restarted for every fault
setting. For each setting the same touches (materials, seeds) are made
twice: ``trajectory`` (the master renders the slave's curves weighted by the
streamed posteriors, then the flux trajectory, timed from its own contact
onset) and ``setpoints`` (the naive baseline: the master tracks the latest
flux setpoint the slave streams sample by sample). Errors are against the
same finger touching the material directly, over the whole contact
(``flux_rms_error_rel_whole``), since the naive path has no identification
instant of its own.
"""

from __future__ import annotations

import datetime
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from telethermal.physics.scene import load_scene
from telethermal.render.generator import save_generator
from telethermal.services.admin import call
from telethermal.services.demo import (Services, free_ports, networked_touch, wait_connected,
                                       write_configs)
from telethermal.session.models import train_generator, train_identifier
from telethermal.session.run import with_finger

MATERIALS = ("wood", "steel")
CONTACT_S = 3.0
#: (name, overrides of the fault profile's [both] section)
SETTINGS = [
    ("delay 0 ms", {}),
    ("delay 10 ms", {"delay_s": 0.01}),
    ("delay 50 ms", {"delay_s": 0.05}),
    ("delay 100 ms", {"delay_s": 0.1}),
    ("delay 200 ms", {"delay_s": 0.2}),
    ("delay 500 ms", {"delay_s": 0.5}),
    ("delay 200 ms, jitter 20 ms, loss 5 %", {"delay_s": 0.2, "jitter": "normal",
                                              "jitter_s": 0.02, "loss": 0.05}),
    ("loss 20 %", {"delay_s": 0.005, "loss": 0.2}),
    ("jitter 50 ms", {"delay_s": 0.05, "jitter": "uniform", "jitter_s": 0.025}),
    ("2 s partition mid-contact", {"delay_s": 0.005, "partitions": "PARTITION"}),
]
#: The proxy starts; touches begin this long after (so a partition can be placed).
SETTLE_S = 4.0


def _profile(path: Path, link: dict, both: dict, touch_at_s: float) -> Path:
    lines = ["[link]"] + [f"{k} = {v!r}" if isinstance(v, str) else f"{k} = {v}"
                          for k, v in link.items()] + ["", "[both]"]
    for key, value in both.items():
        if value == "PARTITION":
            # Half a second into the first touch's contact, for 2 s.
            value = [[touch_at_s + 0.2 + 0.5, 2.0]]
        lines.append(f'{key} = "{value}"' if isinstance(value, str) else f"{key} = {value}")
    path.write_text("\n".join(lines) + "\n")
    return path


def run(progress=None, quick: bool = False) -> dict:
    step = progress or (lambda _m: None)
    scene = with_finger(load_scene("fingertip-7"))
    settings = [SETTINGS[0], SETTINGS[4]] if quick else SETTINGS
    materials = MATERIALS[:1] if quick else MATERIALS
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        step("training")
        ident = train_identifier(scene, 0).save(out / "identifier.npz")
        gen = save_generator(train_generator(scene, 0), out / "generator.npz")
        s_control, s_stream, p_control, p_stream, s_admin, m_admin = free_ports(6)
        ports = (s_control, s_stream, s_admin, m_admin)
        slave_cfg, master_cfg = write_configs(out, scene.name, ident, gen, ports, 0,
                                              security="plain",
                                              master_ports=(p_control, p_stream),
                                              realtime_priority=20)
        link = {"listen_host": "127.0.0.1", "control_port": p_control,
                "stream_port": p_stream, "slave_host": "127.0.0.1",
                "slave_control_port": s_control, "slave_stream_port": s_stream, "seed": 0}
        services = Services(out, slave_cfg, master_cfg)
        try:
            for name, both in settings:
                step(name)
                profile = _profile(out / "profile.toml", link, both, SETTLE_S)
                proxy = subprocess.Popen([sys.executable, "-m", "telethermal", "faults",
                                          "--profile", str(profile)],
                                         stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                         text=True)
                started = time.monotonic()
                try:
                    wait_connected(services, m_admin, timeout_s=60)
                    before = call(m_admin, "status")["counters"]
                    time.sleep(max(0.0, started + SETTLE_S - time.monotonic()))
                    results = {}
                    for source in ("trajectory", "setpoints"):
                        results[source] = [networked_touch(scene, m, ports, 10 + i, CONTACT_S,
                                                           source=source).summary
                                           for i, m in enumerate(materials)]
                    after = call(m_admin, "status")["counters"]
                finally:
                    proxy.terminate()
                    proxy_out, _ = proxy.communicate(timeout=10)
                rows.append(_row(name, both, results, before, after, proxy_out))
        finally:
            codes = services.stop()
    return _report(rows, codes, materials)


def _row(name, both, results, before, after, proxy_out) -> dict:
    def mean(source, key):
        return float(np.mean([r[key] for r in results[source]]))

    delta = {k: after[k] - before[k] for k in after}
    comp_events = sum(r["safety_events"] for r in results["trajectory"])
    naive_events = sum(r["safety_events"] for r in results["setpoints"])
    return {
        "fault": name, "profile": {k: v for k, v in both.items() if v != "PARTITION"} |
        ({"partitions": "2 s, 0.5 s into the first contact"} if "partitions" in both else {}),
        "compensated_flux_rms_error_rel": mean("trajectory", "flux_rms_error_rel_whole"),
        "naive_flux_rms_error_rel": mean("setpoints", "flux_rms_error_rel_whole"),
        "compensated_after_identification": mean("trajectory", "flux_rms_error_rel"),
        "compensated_temp_rms_error_c": mean("trajectory", "temp_rms_error_c"),
        "naive_temp_rms_error_c": mean("setpoints", "temp_rms_error_c"),
        "compensated_time_to_correct_flux_s": mean("trajectory", "time_to_correct_flux_s"),
        "naive_time_to_correct_flux_s": mean("setpoints", "time_to_correct_flux_s"),
        "safety_events": int(comp_events + naive_events),
        "lossless": {k: delta[k] for k in ("gaps", "recovered", "duplicates", "resent",
                                           "lossless_dropped", "invalid", "stream_lost",
                                           "heartbeats_missed", "reconnects")},
        "recovered": bool(delta["lossless_dropped"] == 0 and delta["invalid"] == 0),
        "identified": [r["identified"] for r in results["trajectory"]],
        "proxy": proxy_out.strip().splitlines()[-1] if proxy_out.strip() else "",
    }


def _report(rows, codes, materials) -> dict:
    by = {r["fault"]: r for r in rows}
    zero = by.get("delay 0 ms")
    wan = by.get("delay 200 ms, jitter 20 ms, loss 5 %") or by.get("delay 200 ms")
    summary = {}
    if zero and wan:
        summary = {"compensated_ratio_200ms": wan["compensated_flux_rms_error_rel"] /
                   zero["compensated_flux_rms_error_rel"],
                   "naive_ratio_200ms": wan["naive_flux_rms_error_rel"] /
                   zero["compensated_flux_rms_error_rel"],
                   "ratio_setting": wan["fault"]}
    return {"rows": rows, "summary": summary, "materials": list(materials),
            "contact_s": CONTACT_S, "exit_codes": codes,
            "machine": f"{platform.node()} ({platform.machine()}, "
                       f"{platform.python_implementation()} {platform.python_version()})",
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
