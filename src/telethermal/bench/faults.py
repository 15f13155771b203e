"""``telethermal bench faults``: rendering under network faults, the
compensated path beside the naive one, measured in the same run, in two
parts.

**Simulated clock** (:mod:`telethermal.bench.faults_sim`): every delay,
jitter and loss row, every material of fingertip-7, several seeds, every
mode (compensated first touch, naive, repeated touch with object memory,
the oracle floor) on the very same touches, errors over the blind window,
after the first news and the whole contact. This is where the modes are
compared: the real clock's noise is gone.

**Processes** (below): the fault matrix (delay, loss, a partition, a crash of
either service) on the real services; it says whether the simulated
figures hold on real processes (same seeds: the same physics) and whether
every fault is survived safely and recovered from.

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

from telethermal.errors import BenchError, TransportError
from telethermal.physics.scene import load_scene
from telethermal.render.generator import save_generator
from telethermal.services.admin import call
from telethermal.services.demo import (Services, free_ports, networked_touch, wait_connected,
                                       write_configs)
from telethermal.teleop.models import train_generator, train_identifier
from telethermal.teleop.run import PRE_CONTACT_S, with_finger
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
#: The proxy starts; touches begin this long after (so a partition can be placed).
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
                           == "idle", 10.0)
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
    """One touch with the nemesis at work; None when the master died with it."""
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


def _select(settings, only: str | None):
    if not only:
        return settings
    parts = [p.strip() for p in only.split(",") if p.strip()]
    return [s for s in settings if s[0] == "delay 0 ms" or any(p in s[0] for p in parts)]


def run(progress=None, quick: bool = False, only: str | None = None,
        seeds: int | None = None, processes: bool = True, jobs: int = 2) -> dict:
    """Both parts; ``quick``: the zero-delay and WAN rows, 2 seeds, the
    processes on one material; ``only``: parts of row names (the zero-delay
    row is always run, every ratio needs it)."""
    from telethermal.bench import faults_sim
    from telethermal.teleop.master import DisplayConfig

    step = progress or (lambda _m: None)
    scene = with_finger(load_scene("fingertip-7"))
    sim_rows = [r for r in faults_sim.ROWS if not quick or r[0] in faults_sim.ABLATION_ROWS]
    sim_rows = _select(sim_rows, only)
    settings = _select([SETTINGS[0], SETTINGS[2]] if quick else SETTINGS, only)
    names = list(dict.fromkeys([n for n, _ in faults_sim.ROWS] + [n for n, _ in SETTINGS]))
    parts = [q.strip() for q in (only or "").split(",") if q.strip()]
    if only and not any(q in n for q in parts for n in names):
        raise BenchError(f"--only {only!r} matches no setting; settings: " + "; ".join(names))
    n_seeds = seeds if seeds is not None else (2 if quick else SIM_SEEDS)
    if n_seeds < 1:
        raise BenchError(f"--seeds must be >= 1, got {n_seeds}")
    materials = MATERIALS[:1] if quick else MATERIALS
    rows, traces = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        step("training")
        ident = train_identifier(scene, 0).save(out / "identifier.npz")
        gen = save_generator(train_generator(scene, 0), out / "generator.npz")
        simulated = faults_sim.run(scene, ident, gen, DisplayConfig(), scene.materials,
                                   list(range(1, n_seeds + 1)), CONTACT_S, sim_rows, jobs=jobs,
                                   progress=step)
        if not processes:
            settings = []
        s_control, s_stream, p_control, p_stream, s_admin, m_admin = free_ports(6)
        ports = (s_control, s_stream, s_admin, m_admin)
        slave_cfg, master_cfg = write_configs(out, scene.name, ident, gen, ports, 0,
                                              security="plain",
                                              master_ports=(p_control, p_stream),
                                              realtime_priority=20)
        link = {"listen_host": "127.0.0.1", "control_port": p_control,
                "stream_port": p_stream, "slave_host": "127.0.0.1",
                "slave_control_port": s_control, "slave_stream_port": s_stream, "seed": 0}
        dead_after_s = TransportConfig().dead_after_s
        services = Services(out, slave_cfg, master_cfg)
        try:
            for name, both in settings:
                step(f"processes: {name}")
                profile = _profile(out / "profile.toml", link, both, SETTLE_S)
                kind = both.get("crash") or ("partition" if "partitions" in both else None)
                results, nemeses, after_fault, counters = {}, {}, {}, {}
                for source in ("trajectory", "setpoints"):
                    # A fresh proxy for each source: the partition's clock starts anew.
                    proxy = subprocess.Popen([sys.executable, "-m", "telethermal", "faults",
                                              "--profile", str(profile)],
                                             stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                             text=True)
                    started = _proxy_t0(proxy)
                    try:
                        wait_connected(services, m_admin, timeout_s=60)
                        before = call(m_admin, "status")["counters"]
                        time.sleep(max(0.0, started + SETTLE_S - time.monotonic()))
                        runs = []
                        for i, m in enumerate(materials):
                            nemesis = Nemesis(services, ports, kind if i == 0 else None,
                                              started, dead_after_s)
                            runs.append(_touch(scene, m, ports, 10 + i, source, nemesis))
                            if i == 0:
                                nemeses[source] = nemesis.info
                            if i == 0 and kind is not None:
                                wait_connected(services, m_admin, timeout_s=60)
                                again = _with_late_error(networked_touch(
                                    scene, m, ports, 20, CONTACT_S, source=source))
                                after_fault[source] = again.summary
                        if kind == "master":
                            before = {k: 0 for k in before}     # a new master: new counters
                        after = call(m_admin, "status")["counters"]
                    finally:
                        proxy.terminate()
                        proxy_out, _ = proxy.communicate(timeout=10)
                    results[source] = [r.summary for r in runs if r is not None]
                    if runs[0] is not None:
                        traces.setdefault(name, {})[source] = runs[0].trace
                    for k in after:
                        counters[k] = counters.get(k, 0) + after[k] - before[k]
                    if source == "trajectory":
                        proxy_line = proxy_out
                rows.append(_row(name, both, results, counters, proxy_line, nemeses,
                                 after_fault, dead_after_s))
        finally:
            codes = services.stop()
    report = _report(rows, codes, materials)
    report["simulated"] = simulated
    report["summary"] = {**simulated["summary"], **report["summary"],
                         **_confirm(rows, simulated)}
    report["_traces"] = traces
    return report


def _confirm(rows, simulated) -> dict:
    """Do the processes confirm the simulated figures? Per row both have,
    the processes' whole-contact error of each material against the
    simulated mean +- 2 sd of that material's touches (same physics seeds
    aside, the network's draws differ)."""
    checks = {}
    for row in rows:
        sim = simulated["rows"].get(row["fault"])
        if sim is None:
            continue
        for source, mode in (("trajectory", "compensated"), ("setpoints", "naive")):
            for r in row.get("runs", {}).get(source, []):
                st = sim["modes"][mode]["by_material"].get(r["material"])
                if not st or st["mean"] is None:
                    continue
                lo, hi = st["mean"] - 2 * st["sd"], st["mean"] + 2 * st["sd"]
                checks[f"{row['fault']} / {mode} / {r['material']}"] = {
                    "processes": r["flux_rms_error_rel_whole"], "simulated_mean": st["mean"],
                    "simulated_sd": st["sd"],
                    "within": bool(lo <= r["flux_rms_error_rel_whole"] <= hi)}
    within = [c["within"] for c in checks.values()]
    return {"processes_confirm": checks,
            "processes_within_simulated_spread": f"{sum(within)} of {len(within)}",
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
                                              "lossless_dropped", "invalid", "stream_lost",
                                              "heartbeats_missed", "reconnects")},
        "recovered": bool(counters["lossless_dropped"] == 0 and counters["invalid"] == 0),
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


def _report(rows, codes, materials) -> dict:
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


def plot(report: dict, traces: dict, path: str | Path) -> Path:
    """The simulated part against one-way delay (``path``) and, beside it
    (``<stem>-traces.png``), the processes' traces; returns ``path``."""
    path = Path(path)
    _plot_delay(report["simulated"], path)
    if report["rows"]:
        plot_traces(report, traces, path.with_name(f"{path.stem}-traces{path.suffix}"))
    return path


def _plot_delay(sim: dict, path: Path) -> None:
    """Error against one-way delay, one line per mode, +- 1 sd shaded, the
    oracle floor; one panel per window."""
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from telethermal.bench.faults_sim import WINDOWS

    rows = [(r["profile"].get("delay_s", 0.0), r) for n, r in sim["rows"].items()
            if n.startswith("delay") and "," not in n]
    rows.sort(key=lambda x: x[0])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), sharex=True)
    xs = np.array([1e3 * d for d, _ in rows])
    oracle = sim["oracle"]["whole"]
    for ax, window in zip(axes, WINDOWS):
        for mode, color in (("compensated", "C3"), ("naive", "C0"), ("repeat", "C2")):
            st = [r["modes"][mode][window] for _, r in rows]
            m = np.array([np.nan if s["mean"] is None else 100 * s["mean"] for s in st])
            sd = np.array([np.nan if s["sd"] is None else 100 * s["sd"] for s in st])
            label = {"repeat": "repeated touch (object memory)"}.get(mode, mode + ", first touch"
                                                                     if mode != "naive" else mode)
            ax.plot(xs, m, "o-", color=color, label=label)
            ax.fill_between(xs, m - sd, m + sd, color=color, alpha=0.12, lw=0)
        if window == "whole" and oracle["mean"] is not None:
            ax.axhline(100 * oracle["mean"], color="k", ls="--", lw=1,
                       label="oracle floor (material known at t = 0)")
        ax.set_title({"blind": "blind window (contact -> first news)",
                      "after_news": "after the first news", "whole": "whole contact"}[window],
                     fontsize=9)
        ax.set_xlabel("one-way delay (ms)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("flux RMS error (% of the direct contact's peak)")
    axes[2].legend(fontsize=7)
    fig.suptitle(f"telethermal bench faults, simulated clock: {len(sim['materials'])} "
                 f"materials x {len(sim['seeds'])} seeds per point, mean +- 1 sd over touches, "
                 f"{sim['contact_s']:g} s contacts at {sim['rate_hz']:g} Hz", fontsize=9)
    fig.tight_layout()
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    os.replace(tmp, path)


def plot_traces(report: dict, traces: dict, path: str | Path) -> Path:
    """Jepsen-style: for each fault setting, the first material's flux at the
    finger against time, compensated and naive beside direct contact, the
    fault's window shaded (red: partition or crash until the service is back;
    grey: the delay's blind interval, 2 x one-way delay, before which no news
    of the remote contact can reach the master)."""
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in report["rows"] if r["fault"] in traces]
    n = len(rows)
    cols = 3
    fig, axes = plt.subplots((n + cols - 1) // cols, cols, figsize=(15, 3.2 * ((n + 2) // 3)),
                             squeeze=False, sharex=True)
    for ax, row in zip(axes.flat, rows):
        tr = traces[row["fault"]]
        for source, style, label in (("trajectory", "C3-", "compensated"),
                                     ("setpoints", "C0-", "naive")):
            if source in tr:
                t = tr[source]["t_s"]
                ax.plot(t, tr[source]["flux_w_m2"] / 1e3, style, lw=1, label=label)
        ref = tr.get("trajectory") or tr.get("setpoints")
        if ref is not None:
            ax.plot(ref["t_s"], ref["direct_flux_w_m2"] / 1e3, "k-", lw=1.6, label="direct")
        delay = row["profile"].get("delay_s", 0.0)
        if delay:
            ax.axvspan(0, 2 * delay, color="0.85", lw=0)
        window = row.get("fault_window_s")
        if window and None not in window:
            ax.axvspan(window[0], window[1], color="C3", alpha=0.15, lw=0)
        c, nv = row["compensated_flux_rms_error_rel"], row["naive_flux_rms_error_rel"]
        ax.set_title(f"{row['fault']}\ncompensated {100 * c:.1f} %, naive {100 * nv:.1f} % "
                     f"of peak; safety events {row['safety_events']}", fontsize=8)
        ax.axhline(0, color="0.6", lw=0.5)
        ax.grid(alpha=0.3)
        ax.set_xlim(-0.2, report["contact_s"] + 0.3)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time since the master's contact onset (s)")
    for ax in axes[:, 0]:
        ax.set_ylabel("flux pad -> finger (kW/m$^2$)")
    fig.suptitle(f"telethermal bench faults: {report['materials'][0]}, first touch of each "
                 f"setting; {report['machine']}, {report['date']}", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    os.replace(tmp, path)
    return path


def text_report(report: dict) -> list[str]:
    """What ``telethermal bench faults`` prints."""
    from telethermal.bench.faults_sim import WINDOWS

    def pct(v):
        return "      -" if v is None else f"{100 * v:6.2f}%"

    sim = report["simulated"]
    lines = [f"simulated clock: {len(sim['materials'])} materials x {len(sim['seeds'])} seeds, "
             f"{sim['contact_s']:g} s contacts; flux RMS error (% of peak), mean over touches",
             f"{'row':38s} {'mode':12s} " + " ".join(f"{w:>10s}" for w in WINDOWS) +
             "  blind (s)  safety"]
    for name, row in sim["rows"].items():
        for mode, st in list(row["modes"].items()) + list(row.get("ablations", {}).items()):
            lines.append(f"{name:38s} {mode:12s} " + " ".join(
                f"{pct(st[w]['mean']):>10s}" for w in WINDOWS) +
                f"  {st['blind_s']['mean'] or 0:9.3f}  {st['safety_events']:6d}")
    o = sim["oracle"]
    lines.append(f"{'oracle floor':38s} {'':12s} {'':>10s} {'':>10s} "
                 f"{pct(o['whole']['mean']):>10s}")
    s = report["summary"]

    def x(key, digits=2):
        v = s.get(key)
        return "-" if v is None else f"{v:.{digits}f}x"

    lines.append(
        f"at {s['ratio_setting']}: first touch after the news "
        f"{x('first_touch_after_news_ratio_200ms')} zero delay (target <= 1.2), naive "
        f"{x('naive_after_news_ratio_200ms')} the compensated zero-delay error on that "
        f"window (target >= 2; {x('naive_after_news_ratio_200ms_own_zero')} its own), whole "
        f"contact {x('first_touch_whole_ratio_200ms')} (target <= 1.3); repeated touch "
        f"<= {x('repeat_touch_ratio_to_oracle_max', 3)} the oracle floor at every row "
        f"(target <= 1.05)")
    if report["rows"]:
        lines.append(f"{'processes: fault':38s} {'compensated':>11s} {'naive':>7s} safety  "
                     "lossless (gaps/recovered/dup/resent/dropped)  recovery (bound)")
        for r in report["rows"]:
            lo = r["lossless"]
            rec = "" if "recovery_s" not in r else (
                "not back" if r["recovery_s"] is None else
                f"{r['recovery_s']:.2f} s ({r['recovery_bound_s']:.2f} s)")
            lines.append(f"{r['fault']:38s} {pct(r['compensated_flux_rms_error_rel']):>11s} "
                         f"{pct(r['naive_flux_rms_error_rel'])} {r['safety_events']:6d}  "
                         f"{lo['gaps']}/{lo['recovered']}/{lo['duplicates']}/{lo['resent']}/"
                         f"{lo['lossless_dropped']:<22} {rec}")
        lines.append(f"processes within the simulated spread (mean +- 2 sd): "
                     f"{s['processes_within_simulated_spread']}; fault matrix: "
                     f"{s['fault_matrix_safety_events']} safety events, all recovered: "
                     f"{s['fault_matrix_all_recovered']}")
    return lines
