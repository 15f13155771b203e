"""``telethermal bench faults``, processes part: the fault matrix (delay,
loss, a partition, a crash of either service) on the real services; it says
whether the simulated figures hold on real processes (same seeds: the same
physics) and whether every fault is survived safely and recovered from.

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
import time
from pathlib import Path

import numpy as np

from telethermal.errors import TransportError
from telethermal.services.admin import call
from telethermal.demo.run import Services, wait_connected, write_configs
from telethermal.demo.touches import networked_touch
from telethermal.ports import free_ports
from telethermal.teleop.session import PRE_CONTACT_S, ServiceState
from telethermal.wire.transport import TransportConfig

MATERIALS = ("wood", "steel")
CONTACT_S = 3.0
#: Seeds per material of the simulated part (the issue asks for >= 5).
SIM_SEEDS = 5
#: (name, overrides of the fault profile's [both] section): the processes' rows.
SETTINGS = [
    ("delay 0 ms", {}),
    ("delay 200 ms", {"delay_s": 0.2}),
    ("delay 200 ms, jitter 20 ms, loss 5 %", {"delay_s": 0.2, "jitter": "normal",
                                              "jitter_s": 0.02, "loss": 0.05}),
    ("loss 20 %", {"delay_s": 0.005, "loss": 0.2}),
    ("2 s partition mid-contact", {"delay_s": 0.005, "partitions": "PARTITION"}),
    ("slave crash and restart mid-contact", {"delay_s": 0.005, "crash": "slave"}),
    ("master crash and restart mid-contact", {"delay_s": 0.005, "crash": "master"}),
]
#: The proxy starts; a partition row's touches begin this long after (its
#: window is placed from the proxy's start, in the profile it reads), and a
#: master-crash row's (its touch is asked for without waiting to hear the
#: placement through the new proxy). Other rows start once the master has
#: heard the placement through it (``networked_touch``).
SETTLE_S = 1.5
#: Faults mid-contact start this long after the contact onset.
FAULT_AT_S = 0.5
PARTITION_S = 2.0
#: A crashed service is restarted this long after it was killed.
DOWN_S = 0.5


def _profile(path: Path, link: dict, both: dict, touch_at_s: float) -> Path:
    lines = ["[link]"] + [f"{k} = {v!r}" if isinstance(v, str) else f"{k} = {v}"
                          for k, v in link.items()] + ["", "[both]"]
    for key, value in both.items():
        if key == "crash":
            continue
        if value == "PARTITION":
            # FAULT_AT_S into the first touch's contact, for PARTITION_S.
            value = [[touch_at_s + PRE_CONTACT_S + FAULT_AT_S, PARTITION_S]]
        lines.append(f'{key} = "{value}"' if isinstance(value, str) else f"{key} = {value}")
    path.write_text("\n".join(lines) + "\n")
    return path


def _wait(predicate, timeout_s: float, every_s: float = 0.02) -> float | None:
    """Monotonic time at which ``predicate()`` first held, or None."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            if predicate():
                return time.monotonic()
        except TransportError:
            pass
        time.sleep(every_s)
    return None


class Nemesis:
    """What is done to the services mid-contact, and when (Jepsen's word):
    records the fault window and the recovery instants in contact time."""

    def __init__(self, services: Services, ports, kind: str | None, proxy_t0: float,
                 dead_after_s: float):
        self.services, self.ports, self.kind = services, ports, kind
        self.proxy_t0 = proxy_t0
        self.dead_after_s = dead_after_s
        self.info: dict = {}

    def __call__(self):
        """Run in a thread as the touch is requested."""
        t_call = time.monotonic()
        contact0 = t_call + PRE_CONTACT_S
        slave_admin, master_admin = self.ports[2], self.ports[3]
        rel = lambda t: None if t is None else t - contact0          # noqa: E731

        def slave_linked():
            return call(slave_admin, "status", timeout_s=0.5).get("peer_alive")

        if self.kind == "partition":
            start = self.proxy_t0 + SETTLE_S + PRE_CONTACT_S + FAULT_AT_S
            time.sleep(max(0.0, start + PARTITION_S - time.monotonic()))
            t_linked = _wait(slave_linked, 10.0)
            self.info = {"window_s": (rel(start), rel(start + PARTITION_S)),
                         "link_back_after_s": None if t_linked is None else
                         t_linked - (start + PARTITION_S)}
        elif self.kind == "slave":
            time.sleep(max(0.0, contact0 + FAULT_AT_S - time.monotonic()))
            t_kill = time.monotonic()
            self.services.kill("slave")
            time.sleep(DOWN_S)
            self.services.start("slave")
            t_ready = _wait(lambda: call(slave_admin, "status", timeout_s=0.5).get("ok"), 60.0)
            t_linked = _wait(slave_linked, 30.0)
            self.info = {"window_s": (rel(t_kill), rel(t_ready)),
                         "link_back_after_s": None if None in (t_ready, t_linked) else
                         t_linked - t_ready}
        elif self.kind == "master":
            time.sleep(max(0.0, contact0 + FAULT_AT_S - time.monotonic()))
            t_kill = time.monotonic()
            self.services.kill("master")
            t_safe = _wait(lambda: call(slave_admin, "status", timeout_s=0.5).get("state")
                           == ServiceState.IDLE, 10.0)
            time.sleep(max(0.0, t_kill + DOWN_S - time.monotonic()))
            self.services.start("master")
            t_ready = _wait(lambda: call(master_admin, "status", timeout_s=0.5).get("ok"), 60.0)
            t_linked = _wait(lambda: call(master_admin, "status", timeout_s=0.5).get(
                "peer_alive") and call(master_admin, "status", timeout_s=0.5).get("session"),
                30.0)
            self.info = {"window_s": (rel(t_kill), rel(t_ready)),
                         "slave_safe_after_s": None if t_safe is None else t_safe - t_kill,
                         "link_back_after_s": None if None in (t_ready, t_linked) else
                         t_linked - t_ready}


def _proxy_t0(proxy: subprocess.Popen) -> float:
    """The proxy's own clock origin (CLOCK_MONOTONIC is system-wide), from
    its first line: partitions are timed from it, not from its spawning."""
    line = proxy.stdout.readline()
    if "monotonic" not in line:
        proxy.kill()
        raise TransportError(f"fault proxy did not start: {line}{proxy.stderr.read()}")
    return float(line.rsplit("monotonic", 1)[1].split()[0])


#: The common window for "does delay shift anything once the news is in":
#: from here to the end of the contact. Past the blind interval of the
#: 200 ms rows (2 x 200 ms, the onset detection and the first window).
LATE_FROM_S = 0.6


def _with_late_error(result):
    """Adds ``flux_rms_error_rel_late``: the error over [LATE_FROM_S, contact)."""
    tr = result.trace
    t = tr["t_s"]
    during = (t >= 0) & (t < CONTACT_S)
    late = during & (t >= LATE_FROM_S)
    err = tr["flux_w_m2"][late] - tr["direct_flux_w_m2"][late]
    peak = np.max(np.abs(tr["direct_flux_w_m2"][during]))
    result.summary["flux_rms_error_rel_late"] = float(np.sqrt(np.mean(err ** 2)) / peak)
    return result


def _touch(scene, material, ports, seed, source, nemesis):
    """One touch with the nemesis at work; None when the master died with it.
    A first touch, as on the simulated clock: the slave forgets the objects
    it identified under the earlier settings (its process lives through all
    of them, and from memory the master renders from t = 0: a repeat touch)."""
    forgot = call(ports[2], "forget")
    if not forgot.get("ok"):
        raise TransportError(f"slave: {forgot.get('error')}")
    if nemesis.kind != "master":
        return _with_late_error(networked_touch(scene, material, ports, seed, CONTACT_S,
                                                source=source, during=nemesis))
    import threading
    placed = call(ports[2], "place", material=material, seed=seed)
    if not placed.get("ok"):
        raise TransportError(f"slave: {placed.get('error')}")
    time.sleep(0.3)
    thread = threading.Thread(target=nemesis, daemon=True)
    thread.start()
    try:
        call(ports[3], "touch", timeout_s=CONTACT_S + 1, contact_s=CONTACT_S, seed=seed,
             source=source)
    except TransportError:
        pass                              # the master was killed under the touch
    thread.join()
    return None



def run_processes(scene, out: Path, ident: Path, gen: Path, settings, materials,
                  step) -> tuple[list[dict], dict, dict]:
    """Every fault setting on the services started in ``out`` (the model
    files ``ident`` and ``gen``); returns the rows, the first material's
    traces by setting and the services' exit codes."""
    s_control, s_stream, p_control, p_stream, s_admin, m_admin = free_ports(6)
    ports = (s_control, s_stream, s_admin, m_admin)
    slave_cfg, master_cfg = write_configs(out, scene.ref or scene.name, ident, gen, ports, 0,
                                          security="plain",
                                          master_ports=(p_control, p_stream),
                                          realtime_priority=20)
    link = {"listen_host": "127.0.0.1", "control_port": p_control,
            "stream_port": p_stream, "slave_host": "127.0.0.1",
            "slave_control_port": s_control, "slave_stream_port": s_stream, "seed": 0}
    dead_after_s = TransportConfig().dead_after_s
    services = Services(out, slave_cfg, master_cfg)
    rows, traces = [], {}
    try:
        for name, both in settings:
            step(f"processes: {name}")
            profile = _profile(out / "profile.toml", link, both, SETTLE_S)
            kind = both.get("crash") or ("partition" if "partitions" in both else None)
            results, nemeses, after_fault, counters = {}, {}, {}, {}
            for source in ("trajectory", "setpoints"):
                runs, proxy_out = _source(scene, services, ports, profile, kind, source,
                                          materials, dead_after_s, nemeses, after_fault,
                                          counters)
                results[source] = [r.summary for r in runs if r is not None]
                if runs[0] is not None:
                    traces.setdefault(name, {})[source] = runs[0].trace
                if source == "trajectory":
                    proxy_line = proxy_out
            rows.append(_row(name, both, results, counters, proxy_line, nemeses,
                             after_fault, dead_after_s))
    finally:
        codes = services.stop()
    return rows, traces, codes


def _source(scene, services, ports, profile, kind, source, materials, dead_after_s,
            nemeses, after_fault, counters):
    """One source's touches behind a fresh proxy (the partition's clock
    starts anew); fills ``nemeses``, ``after_fault`` and ``counters`` for
    ``source``; returns the touches (None where the master died with one)
    and the proxy's output."""
    m_admin = ports[3]
    proxy = subprocess.Popen([sys.executable, "-m", "telethermal", "faults",
                              "--profile", str(profile)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    started = _proxy_t0(proxy)
    try:
        wait_connected(services, m_admin, timeout_s=60)
        before = call(m_admin, "status")["counters"]
        if kind in ("partition", "master"):
            time.sleep(max(0.0, started + SETTLE_S - time.monotonic()))
        runs = []
        for i, m in enumerate(materials):
            nemesis = Nemesis(services, ports, kind if i == 0 else None, started, dead_after_s)
            runs.append(_touch(scene, m, ports, 10 + i, source, nemesis))
            if i == 0:
                nemeses[source] = nemesis.info
            if i == 0 and kind is not None:
                wait_connected(services, m_admin, timeout_s=60)
                again = _with_late_error(networked_touch(scene, m, ports, 20, CONTACT_S,
                                                         source=source))
                after_fault[source] = again.summary
        if kind == "master":
            before = {k: 0 for k in before}     # a new master: new counters
        after = call(m_admin, "status")["counters"]
    finally:
        proxy.terminate()
        proxy_out, _ = proxy.communicate(timeout=10)
    for k in after:
        counters[k] = counters.get(k, 0) + after[k] - before[k]
    return runs, proxy_out


def confirm(rows, simulated) -> dict:
    """Do the processes confirm the simulated figures? Per row both have,
    the processes' whole-contact error of each material against the
    simulated mean +- 2 sd of that material's touches (same physics seeds
    aside, the network's draws differ)."""
    checks, unjudged = {}, 0
    for row in rows:
        sim = simulated["rows"].get(row["fault"])
        if sim is None:
            continue
        for source, mode in (("trajectory", "compensated"), ("setpoints", "naive")):
            for r in row.get("runs", {}).get(source, []):
                st = sim["modes"][mode]["by_material"].get(r["material"])
                if not st or st["mean"] is None:
                    continue
                if st.get("n", 2) < 2:          # one simulated touch: a point, no spread
                    unjudged += 1
                    continue
                lo, hi = st["mean"] - 2 * st["sd"], st["mean"] + 2 * st["sd"]
                checks[f"{row['fault']} / {mode} / {r['material']}"] = {
                    "processes": r["flux_rms_error_rel_whole"], "simulated_mean": st["mean"],
                    "simulated_sd": st["sd"],
                    "within": bool(lo <= r["flux_rms_error_rel_whole"] <= hi)}
    within = [c["within"] for c in checks.values()]
    spread = f"{sum(within)} of {len(within)}" + (
        f" ({unjudged} not judged: one simulated touch of their material, no spread; "
        "run 2 seeds or more)" if unjudged else "")
    return {"processes_confirm": checks,
            "processes_within_simulated_spread": spread,
            "fault_matrix_safety_events": int(sum(r["safety_events"] for r in rows)),
            "fault_matrix_all_recovered": bool(all(r["recovered"] for r in rows))}


def _row(name, both, results, counters, proxy_out, nemeses, after_fault, dead_after_s) -> dict:
    def mean(source, key, runs=None):
        runs = results[source] if runs is None else runs
        values = [r[key] for r in runs if r.get(key) is not None]
        return float(np.mean(values)) if values else None

    # The master crash leaves no in-flight trace (the process that had it is
    # gone): for the first material that row counts the touch after recovery.
    lost = {s: "slave_safe_after_s" in nemeses.get(s, {}) for s in results}   # master crash
    measured_on = "the touches under the fault" if not lost["trajectory"] else \
        "first material: the touch after recovery (the master died with the one under the " \
        "fault); the others: under the fault"
    runs = {s: ([after_fault[s]] if lost[s] else []) + results[s] for s in results}
    events = sum(r["safety_events"] for s in runs for r in runs[s]) + \
        sum(r["safety_events"] for r in after_fault.values())
    row = {
        "fault": name, "profile": {k: v for k, v in both.items() if v != "PARTITION"} |
        ({"partitions": f"{PARTITION_S:g} s, {FAULT_AT_S:g} s into the first contact"}
         if "partitions" in both else {}),
        "measured_on": measured_on,
        "compensated_flux_rms_error_rel": mean("trajectory", "flux_rms_error_rel_whole",
                                               runs["trajectory"]),
        "naive_flux_rms_error_rel": mean("setpoints", "flux_rms_error_rel_whole",
                                         runs["setpoints"]),
        "compensated_flux_rms_error_rel_late": mean("trajectory", "flux_rms_error_rel_late",
                                                    runs["trajectory"]),
        "naive_flux_rms_error_rel_late": mean("setpoints", "flux_rms_error_rel_late",
                                              runs["setpoints"]),
        "compensated_after_identification": mean("trajectory", "flux_rms_error_rel",
                                                 runs["trajectory"]),
        "compensated_temp_rms_error_c": mean("trajectory", "temp_rms_error_c",
                                             runs["trajectory"]),
        "naive_temp_rms_error_c": mean("setpoints", "temp_rms_error_c", runs["setpoints"]),
        "compensated_time_to_correct_flux_s": mean("trajectory", "time_to_correct_flux_s",
                                                   runs["trajectory"]),
        "naive_time_to_correct_flux_s": mean("setpoints", "time_to_correct_flux_s",
                                             runs["setpoints"]),
        "safety_events": int(events),
        "display_events": [r.get("display_event_counts", {}) for r in runs["trajectory"]],
        "lossless": {k: counters[k] for k in ("gaps", "recovered", "duplicates", "resent",
                                              "refused_by_window", "invalid", "stream_lost",
                                              "heartbeats_missed", "reconnects")},
        "recovered": bool(counters["refused_by_window"] == 0 and counters["invalid"] == 0),
        "identified": [r["identified"] for r in runs["trajectory"]],
        "runs": {s: [{"material": r["material"], "seed": r["seed"],
                      "flux_rms_error_rel_whole": r["flux_rms_error_rel_whole"]}
                     for r in results[s]] for s in results},
        "proxy": proxy_out.strip().splitlines()[-1] if proxy_out.strip() else "",
    }
    info = nemeses.get("trajectory") or {}
    if after_fault:
        after = after_fault["trajectory"]
        back = info.get("link_back_after_s")
        row.update({
            "fault_window_s": info.get("window_s"),
            "link_back_after_s": back,
            "after_recovery_flux_rms_error_rel": after["flux_rms_error_rel_whole"],
            "after_recovery_time_to_correct_flux_s": after["time_to_correct_flux_s"],
            # From the fault's end: the link back, then one identification.
            "recovery_s": None if back is None else back + after["time_to_correct_flux_s"],
            "recovery_bound_s": dead_after_s + after["time_to_correct_flux_s"],
            "naive_recovery_s": None if nemeses["setpoints"].get("link_back_after_s") is None
            else nemeses["setpoints"]["link_back_after_s"] +
            after_fault["setpoints"]["time_to_correct_flux_s"]})
        if "slave_safe_after_s" in info:
            row["slave_safe_after_s"] = info["slave_safe_after_s"]
    return row


def processes_report(rows, codes, materials) -> dict:
    by = {r["fault"]: r for r in rows}
    zero = by.get("delay 0 ms")
    wan = by.get("delay 200 ms, jitter 20 ms, loss 5 %") or by.get("delay 200 ms")
    summary = {}
    if zero and wan:
        summary = {"processes_compensated_ratio_200ms": wan["compensated_flux_rms_error_rel"] /
                   zero["compensated_flux_rms_error_rel"],
                   "processes_naive_ratio_200ms": wan["naive_flux_rms_error_rel"] /
                   zero["compensated_flux_rms_error_rel"],
                   "processes_ratio_setting": wan["fault"]}
    return {"rows": rows, "summary": summary, "materials": list(materials),
            "contact_s": CONTACT_S, "exit_codes": codes,
            "machine": f"{platform.node()} ({platform.machine()}, "
                       f"{platform.python_implementation()} {platform.python_version()})",
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
