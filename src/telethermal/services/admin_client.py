"""``telethermal admin``: operate a session through the services' admin
sockets (``services/admin.py``): place an object, touch, lift, status, the
last touch's figures, or any other request by name.

A thin client: every subcommand is one or two admin requests, and ``send``
passes any request through, so a new request needs no change here. Each
admin socket is local to its host (127.0.0.1 or an ``ipc://`` path); from
another host, forward the port (``ssh -N -L 5570:127.0.0.1:5570 slave-host``).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from telethermal.errors import TelethermalError, TransportError
from telethermal.ident.label import Label
from telethermal.services.admin import call
from telethermal.teleop.decision import when_decided

DEFAULT = {"slave": 5570, "master": 5571}


class AdminError(TelethermalError):
    """A service that answered an admin request with an error."""


#: The names of this host an admin address may give (the admin socket
#: listens on 127.0.0.1 only).
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1", "[::1]")


def _host_port(where: str, role: str) -> int | None:
    """``HOST:PORT`` or ``tcp://HOST:PORT`` for this host: the port; None
    if ``where`` is not of that form (a config file's path)."""
    text = where[len("tcp://"):] if where.startswith("tcp://") else where
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not host or "/" in host:
        if where.startswith("tcp://"):
            raise AdminError(f"--{role} {where}: expected tcp://127.0.0.1:PORT")
        return None
    if host not in LOCAL_HOSTS:
        raise AdminError(f"--{role} {where}: the {role}'s admin socket listens on its own "
                         f"host's 127.0.0.1 only; from here, forward its port "
                         f"(ssh -N -L {port}:127.0.0.1:{port} {host}) and give "
                         f"127.0.0.1:{port}")
    return int(port)


def resolve(where: str | int | None, role: str):
    """A port, ``127.0.0.1:PORT`` (or ``tcp://``), an ``ipc://`` path, or a
    service config file (its admin_ipc or admin_port); None: the role's
    default port on 127.0.0.1."""
    if where is None or where == "":
        return DEFAULT[role]
    if isinstance(where, int) or str(where).isdigit():
        return int(where)
    if str(where).startswith("ipc://"):
        return str(where)
    port = None if Path(where).is_file() else _host_port(str(where), role)
    if port is not None:
        return port
    from telethermal.services.config import load_config

    config = load_config(Path(where), role)
    return config.admin_ipc or config.admin_port


def request(where, role: str, cmd: str, timeout_s: float = 5.0, **args) -> dict:
    """One request; an ``ok: false`` reply raises :class:`AdminError`."""
    try:
        reply = call(where, cmd, timeout_s=timeout_s, **args)
    except TransportError as exc:
        raise TransportError(f"{role} admin at {where}: no reply to {cmd!r} in {timeout_s} s: "
                             f"is `telethermal {role}` running on this host with this "
                             f"admin_port/admin_ipc? ({exc})") from exc
    if not reply.get("ok", False):
        raise AdminError(f"{role}: {reply.get('error', 'failed')}")
    return reply


def parse_args(items: list[str]) -> dict:
    """``key=value`` pairs; values are read as JSON where they parse
    (numbers, true/false, lists), as text otherwise."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise AdminError(f"{item!r}: arguments are key=value")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def truth_for_touch(slave, material: str | None, object_c: float | None) -> dict | None:
    """What was placed under the slave pad (simulation truth), for the
    figures against direct contact: given explicitly, or asked of the
    slave's admin socket when it is reachable from here."""
    if material is not None and object_c is not None:
        return {"material": material, "object_true_c": float(object_c)}
    try:
        status = request(slave, "slave", "status", timeout_s=1.0)
    except TelethermalError:
        return None
    if status.get("object_true_c") is None:
        return None
    return {"material": status["material"], "object_true_c": status["object_true_c"]}


@dataclass
class StatusPoll:
    """What :func:`poll_status` saw: each answering role's status reply,
    the lines describing them, whether the session is live, and the last
    error of a role that did not answer."""

    replies: dict = field(default_factory=dict)
    lines: list = field(default_factory=list)
    live: bool = True
    error: TelethermalError | None = None


def _poll_once(where: dict, roles) -> StatusPoll:
    poll = StatusPoll()
    for role in roles:
        try:
            poll.replies[role] = s = request(where[role], role, "status", timeout_s=1.0)
            poll.lines += describe_status(s)
            poll.live &= role == "slave" or (bool(s["peer_alive"]) and bool(s.get("session")))
        except TelethermalError as exc:
            poll.error = exc
            poll.live = False               # a role that does not answer is not live
            poll.lines.append(f"{role}: not reachable here ({exc})")
    poll.live &= bool(poll.replies)
    scales = {role: float(s.get("time_scale", 1.0)) for role, s in poll.replies.items()}
    if len(set(scales.values())) > 1:
        # Each judges the other's heartbeats and times on its own clock: no
        # session on two clocks is to be trusted (the services cannot tell).
        poll.live = False
        poll.lines.append("problem: the services run on different clocks (time_scale: "
                          + ", ".join(f"{r} {v:g}" for r, v in scales.items())
                          + "): give both configs the same time_scale")
    return poll


def poll_status(where: dict, roles, wait_s: float = 0.0, every_s: float = 0.2) -> StatusPoll:
    """Ask each of ``roles`` (at ``where[role]``) for its status, again every
    ``every_s`` until the session is live (every role answered; the master
    with a live peer and a session) or ``wait_s`` has passed."""
    end = time.monotonic() + wait_s
    while True:
        poll = _poll_once(where, roles)
        if poll.live or time.monotonic() >= end:
            return poll
        time.sleep(every_s)


def wait_for_session(master, wait_s: float, every_s: float = 0.2) -> dict:
    """The master's status once it has a live session with the slave, waiting
    up to ``wait_s`` (a touch right after start, while the slave still trains
    its models); raises :class:`AdminError` naming what it saw otherwise."""
    poll = poll_status({"master": master}, ("master",), wait_s, every_s)
    if poll.live:
        return poll.replies["master"]
    if "master" not in poll.replies:
        raise poll.error
    seen = "; ".join(line.strip() for line in poll.lines)
    raise AdminError(f"master: no session with the slave after waiting {wait_s:g} s ({seen})")


def _ms(value) -> str:
    return "-" if value is None else f"{1e3 * value:.2f} ms"


def describe_status(status: dict) -> list[str]:
    """Lines for a person: state, peer, round trip, counters that moved,
    and what is wrong if no session is up."""
    c = status.get("counters", {})
    moved = ", ".join(f"{k} {v}" for k, v in c.items() if v)
    lines = [f"{status['role']}: {status['state']}, peer "
             f"{'alive' if status['peer_alive'] else 'silent'}, rtt {_ms(status.get('rtt_s'))}"
             + (f", slave at {status['slave']}" if status.get("slave") else "")
             + (f", object {status['material']}" if status.get("material") else "")
             + (f", time scale {status['time_scale']:g}"
                if status.get("time_scale", 1.0) != 1.0 else ""),
             f"  counters: {moved or 'all zero'}"]
    if "memory" in status:                  # the slave's object memory
        known = ", ".join(f"{name}: {m['material']} ({m['confidence']:.3f})"
                          for name, m in status["memory"].items())
        lines.append(f"  object {status.get('object_id')}; memory: {known or 'empty'}")
    d = status.get("diagnosis")
    if d:
        lines += [f"  problem: {d['problem']}", f"  likely: {d['fix']}"]
        lines += [f"  or: {cause}" for cause in d["causes"] if cause != d["fix"]]
    r = status.get("last_rejected_key")
    if r:
        lines.append(f"  last rejected CURVE key {r['fingerprint']} from {r['address']} "
                     f"({c.get('curve_rejected', 0)} refusals)" + ("" if status["peer_alive"]
                     else ": to let that master in, copy its master.key into allowed_dir"))
    return lines


def describe_touch(result: dict) -> list[str]:
    when = when_decided(result)
    when = "no decision" if when is None else f"decided {when}"
    if result.get("unknown_reason"):
        when = f"{result['unknown_reason']}; {when}"
    # A newer master says what a new material was estimated at (its decision's text).
    said = (Label(result["identified"]).is_new and result.get("decision_text")) or \
        result["identified"]
    lines = [f"touch {result['contact_id']}: identified {said} ({when}), "
             f"rendering from {_s(result.get('render_start_s'))}, safety events "
             f"{result['safety_events']}, rtt {_ms(result.get('rtt_s'))}"]
    d = result.get("direct")
    if d:
        lines.append(f"  against direct contact with {d['material']}: flux error "
                     f"{_pct(d['flux_rms_error_rel'])} of peak after rendering began, "
                     f"{_pct(d['flux_rms_error_rel_first_s'])} over the first second; skin "
                     f"{d['temp_rms_error_c']:.2f} K RMS; flux within 10 % from "
                     f"{_s(d.get('time_to_correct_flux_s'))}")
    else:
        lines.append("  no direct-contact figures: the placed object is not known here "
                     "(reach the slave's admin socket, or give --material and --object-c)")
    return lines


def _s(value) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) \
        else f"{value:.2f} s"


def _pct(value) -> str:
    return "-" if value is None or math.isnan(value) else f"{100 * value:.2f} %"
