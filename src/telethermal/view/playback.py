"""A recording (the MCAP files of ``--record``) as the page's series.

Each touch's periods, news and slave samples are recorded against the
touch's own time; a service's recording also holds when each touch started
(``/master/touch_start`` on the master, the master's ``contact_event`` on
the slave), which lays the touches on one time line. Series are decimated
to ``MAX_RATE_HZ`` like the live feed. A recording that cannot be read (not
a recording, another version) raises :class:`RecordingError` with the file
and the reason; one cut mid-write plays up to the cut and says so.
"""

from __future__ import annotations

import math
from pathlib import Path

from telethermal.record.recording import RecordingError, read_recording
from telethermal.teleop.master import Phase
from telethermal.view.stream import skin_estimate_c
from telethermal.view.feed import MAX_RATE_HZ

#: The phases of a touch (the recordings hold their values, plain strings).
CONTACT_PHASES = (Phase.CONTACT, Phase.RENDER, Phase.LINK_LOST)

__all__ = ["load_playback", "RecordingError"]


def _touch_starts(rec) -> dict[int, float]:
    starts: dict[int, float] = {}
    for t, m in rec.topics.get("/master/touch_start", []):
        starts.setdefault(m["contact_id"], t)
    for t, m in rec.topics.get("/wire/in/contact_event", []):
        if m.get("touching") and rec.role == "slave":
            starts.setdefault(m["contact_id"], t)
    return starts


def _held(rec, key: str) -> float | None:
    """A positive finite number the recording holds under ``key``: its
    session's config, else its first touch start; None if neither has one."""
    for held in [rec.config] + rec.messages("/master/touch_start")[:1]:
        v = held.get(key)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) \
                and v > 0:
            return float(v)
    return None


def _conductance(rec) -> float:
    """The pad-fingertip contact conductance the display was given: as the
    recording holds it (a session's config, a service's touch start), else
    its scene's, loaded by name (a scene file this process loaded, or a
    shipped one)."""
    from telethermal.physics.scene import load_scene, loaded_scene_file
    from telethermal.physics.scene import with_finger
    h = _held(rec, "contact_conductance_w_m2k")
    if h is not None:
        return h
    scene = rec.config.get("scene", "fingertip-7")
    if isinstance(scene, str) and loaded_scene_file(scene) is not None:
        return with_finger(loaded_scene_file(scene)).finger.contact_conductance_w_m2k
    try:
        return with_finger(load_scene(scene)).finger.contact_conductance_w_m2k
    except Exception as exc:        # noqa: BLE001 - a scene file not on this machine
        raise RecordingError(f"{rec.path}: its scene {scene!r} cannot be loaded here "
                             f"({exc})") from exc


def _flux_gain(rec) -> float:
    """The display's calibrated flux gain the recording holds (1: none, or
    an older file)."""
    g = _held(rec, "flux_gain")
    return 1.0 if g is None else g


def _master_series(rec, offset, out, h_w_m2k) -> int:
    batches = rec.messages("/master/periods")
    k = 1
    if batches and len(batches[0]["t_s"]) > 1:
        dt = batches[0]["t_s"][1] - batches[0]["t_s"][0]
        k = max(1, math.ceil(1.0 / dt / MAX_RATE_HZ)) if dt > 0 else 1
    n = 0
    gain = _flux_gain(rec)          # the sensor's readings, as the display read them
    for b in batches:
        off = offset(b.get("contact_id", 0))
        for i, t in enumerate(b["t_s"]):
            n += 1
            if (b["k0"] + i) % k:
                continue
            t = round(off + t, 4)
            temp, flux = b["pad_temp_c"][i], b["flux_w_m2"][i] / gain
            if math.isfinite(temp) and math.isfinite(flux):
                out["master_temp"].append([t, temp])
                out["master_flux"].append([t, flux])
                if b["phase"][i] in CONTACT_PHASES:
                    out["skin"].append([t, skin_estimate_c(temp, flux, h_w_m2k)])
            if math.isfinite(b["desired_flux_w_m2"][i]):
                out["master_setpoint"].append([t, b["desired_flux_w_m2"][i]])
            state = [b["phase"][i], bool(b["safe"][i])]
            if not out["phase"] or out["phase"][-1][1:] != state:
                out["phase"].append([t, *state])
    return n


def _slave_series(rec, offset, out) -> int:
    n = 0
    for s in rec.messages("/slave/samples"):
        off = offset(s.get("contact_id", 0))
        t_s = s.get("t_s", [])
        rate = (len(t_s) - 1) / (t_s[-1] - t_s[0]) if len(t_s) > 1 and t_s[-1] > t_s[0] else 1
        k = max(1, math.ceil(rate / MAX_RATE_HZ))
        for i in range(0, len(t_s), k):
            t = round(off + t_s[i], 4)
            out["slave_temp"].append([t, s["temperature_C"][i]])
            out["slave_flux"].append([t, s["heat_flux_W_m2"][i]])
        n += len(t_s)
    return n


def _slave_classes(rec, n: int) -> list[str]:
    """The class names of the slave's estimates: its attached identifier's."""
    import tempfile

    from telethermal.ident.registry import load_model
    data = rec.attachments.get("identifier.npz")
    if data is not None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "identifier.npz"
            path.write_bytes(data)
            try:
                classes = [str(c) for c in load_model(path).classes_]
                if len(classes) == n:
                    return classes
            except Exception:         # noqa: BLE001 - a damaged attachment: names unknown
                pass
    return [f"class {i}" for i in range(n)]


def _estimates(rec, offset) -> list[dict]:
    """Posteriors over time: the master's news, or the slave's own."""
    out = []
    for m in rec.messages("/master/news"):
        e = m.get("estimate")
        if e is not None:
            out.append({"t": round(offset(m["contact_id"]) + m["t_s"], 4), "contact_id":
                        m["contact_id"], "classes": m.get("classes", []), "t_s": e[0],
                        "posteriors": e[1], "label": e[2], "decided": e[4],
                        "reason": e[5] if len(e) > 5 else "", **_effusivity(e)})
    slave = [m for m in rec.messages("/slave/estimates") if m.get("estimate")]
    if not out and slave:
        classes = _slave_classes(rec, len(slave[0]["estimate"][1]))
        for m in slave:
            e = m["estimate"]
            out.append({"t": round(offset(m["contact_id"]) + e[0], 4), "contact_id":
                        m["contact_id"], "classes": classes,
                        "t_s": e[0], "posteriors": e[1], "label": e[2], "decided": e[4],
                        "reason": e[5] if len(e) > 5 else "", **_effusivity(e)})
    return out


def _effusivity(e) -> dict:
    """A recorded estimate's effusivity fields (recorder._estimate), if any."""
    from telethermal.ident.openset import EFFUSIVITY_KEYS
    return dict(zip(EFFUSIVITY_KEYS, e[6:10])) if len(e) > 6 else {}


def _touch_ends(rec, offset, out) -> list[list]:
    """Per touch, at its last period: [t, events, link counters, round trip]
    from the touch's summary (what the page's safety and link panels show)."""
    from telethermal.view.feed import LINK_COUNTERS
    last_t: dict[int, float] = {}
    for b in rec.messages("/master/periods"):
        if b["t_s"]:
            last_t[b.get("contact_id", 0)] = offset(b.get("contact_id", 0)) + b["t_s"][-1]
    ends = []
    for m in rec.messages("/master/touch"):
        s, cid = m.get("summary", {}), m.get("contact_id", 0)
        link = s.get("transport", {})
        ends.append([round(last_t.get(cid, offset(cid)), 4),
                     {**s.get("safety_event_counts", {}), **s.get("display_event_counts", {})},
                     {k: link.get(k, 0) for k in LINK_COUNTERS}, s.get("rtt_s")])
    return ends


def load_playback(path: str | Path) -> dict:
    """The page's view of one recording (JSON-able)."""
    rec = read_recording(path)
    starts = _touch_starts(rec)
    base = min(starts.values()) if starts else 0.0

    def offset(contact_id: int) -> float:
        return starts.get(contact_id, base) - base

    out = {k: [] for k in ("master_temp", "master_flux", "master_setpoint", "skin",
                           "slave_temp", "slave_flux", "phase")}
    counts = {"master": _master_series(rec, offset, out, _conductance(rec))
              if rec.messages("/master/periods") else 0,
              "slave": _slave_series(rec, offset, out)}
    estimates = _estimates(rec, offset)
    times = [p[0] for s in out.values() for p in s[:1] + s[-1:]] + [e["t"] for e in estimates]
    if not times:
        raise RecordingError(f"{rec.path}: holds no touch to play"
                             + (f" (cut mid-write: {rec.truncated})" if rec.truncated else ""))
    meta = rec.metadata.get("telethermal", {})
    return {"name": Path(path).name, "role": rec.role, "software": meta.get("software", ""),
            "date": meta.get("date", ""), "t_min": min(times), "t_max": max(times),
            "series": out, "estimates": estimates, "counts": counts,
            "touches": sorted(starts) or sorted({e["contact_id"] for e in estimates}),
            "touch_ends": _touch_ends(rec, offset, out),
            "truncated": rec.truncated, "notes": rec.notes,
            "summaries": [m.get("summary", {}).get("identified") for m in
                          rec.messages("/master/touch")]}
