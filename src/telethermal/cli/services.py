"""``telethermal slave``, ``master``, ``faults`` (the fault proxy),
``peltier-emulator`` and ``keys``: the long-running processes, each until
SIGTERM or SIGINT."""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

from telethermal.cli._common import console, log
from telethermal.errors import TelethermalError


def _stop_flag() -> list:
    """A list that SIGTERM and SIGINT append to: stop when it is not empty."""
    stop = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.append(1))
    return stop


def cmd_peltier_emulator(args) -> int:
    """An emulated Peltier driver on a CAN bus, until SIGTERM/SIGINT: to try
    a master's CAN path without the hardware."""
    from telethermal.devices.emulators import PeltierEmulator

    stop = _stop_flag()
    emulator = PeltierEmulator(args.bus, lambda _c: None)
    print(f"Peltier driver emulator on {args.bus}", flush=True)
    try:
        while not stop:
            emulator.poll()
            time.sleep(5e-4)
    finally:
        emulator.close()
    print(json.dumps(emulator.counters))
    return 0


class _StatusLine:
    """The service's one-line status, for rich's Live display."""

    def __init__(self, service):
        self.service = service

    def __rich__(self):
        s = self.service.status()
        rtt = f"{1e6 * s['rtt_s']:.0f} us" if s.get("rtt_s") is not None else "-"
        c = s["counters"]
        return (f"[bold]{s['role']}[/bold] {s['state']:9s} peer "
                f"{'[green]alive[/green]' if s['peer_alive'] else '[red]silent[/red]'}"
                f"  rtt {rtt}  resent {c['resent']}  gaps {c['gaps']}  "
                f"reconnects {c['reconnects']}  invalid {c['invalid']}")


def _serve(service) -> int:
    """Run a service until SIGTERM or SIGINT; the pad goes to its safe state
    first (the service's shutdown), then the sockets close."""
    def stop(signum, _frame):
        log.info("signal %s: stopping", signal.Signals(signum).name)
        service.stop_requested = True

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    if console.is_terminal:
        from rich.live import Live

        with Live(_StatusLine(service), console=console, refresh_per_second=2, transient=True):
            service.run()
    else:
        service.run()
    print(f"{service.status()['role']} stopped cleanly")
    return 0


def cmd_slave(args) -> int:
    from telethermal.services.config import load_config
    from telethermal.services.slave import SlaveService

    return _serve(SlaveService(load_config(args.config, "slave")))


def cmd_master(args) -> int:
    from telethermal.services.config import load_config
    from telethermal.services.master import MasterService

    return _serve(MasterService(load_config(args.config, "master")))


def _overrides(items: list[str] | None) -> dict:
    """``--set section.key=value`` items; values as int, float or text."""
    overrides = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise TelethermalError(f"--set {item!r}: use section.key=value")
        for kind in (int, float, str):
            try:
                overrides[key] = kind(value)
                break
            except ValueError:
                continue
    return overrides


def cmd_faults(args) -> int:
    """A faulty network between a real master and slave, until SIGTERM/SIGINT."""
    from telethermal.sim.proxy import FaultProxy, load_profile

    profile = load_profile(args.profile, _overrides(args.set))
    proxy = FaultProxy(profile)
    stop = _stop_flag()
    link = profile.link
    print(f"fault proxy: masters connect to {link.listen_host}:{link.control_port}/"
          f"{link.stream_port}, slave at {link.slave_host}:{link.slave_control_port}/"
          f"{link.slave_stream_port}; partitions timed from monotonic {proxy.t0_s:.6f} s",
          flush=True)
    try:
        proxy.run(lambda: bool(stop))
    finally:
        proxy.close()
    print(json.dumps(proxy.counters))
    return 0


def cmd_keys(args) -> int:
    from telethermal.wire.handshake import key_file_fingerprint
    from telethermal.wire.keys import generate_keys

    public, secret = generate_keys(args.out, args.name, replace=args.force)
    print(f"wrote {public} (give it to the peer; fingerprint {key_file_fingerprint(public)}) "
          f"and {secret} (keep it here: mode 600, its folder 700)")
    if args.name == "slave":                 # where the masters' public keys go
        from telethermal.wire.keys import make_allowed_folder
        allowed = make_allowed_folder(Path(args.out) / "allowed")    # 700
        print(f"made {allowed}/: copy each master's master.key into it")
    return 0


def add_peltier_emulator(sub) -> None:
    p = sub.add_parser("peltier-emulator", help="an emulated Peltier driver on a CAN bus "
                                                "(proto/CAN.md), until SIGTERM")
    p.add_argument("--bus", required=True, help="interface:channel, e.g. virtual:display or "
                                                "udp_multicast:239.74.163.2")
    p.set_defaults(func=cmd_peltier_emulator)


def add_parsers(sub) -> None:
    """slave, master, faults, keys."""
    for role, func in (("slave", cmd_slave), ("master", cmd_master)):
        p = sub.add_parser(role, help=f"run the {role} service until SIGTERM/SIGINT")
        p.add_argument("--config", required=True, help=f"TOML (see services/{role}/config.toml)")
        p.set_defaults(func=func)
    p = sub.add_parser("faults", help="a faulty network (delay, jitter, loss, duplication, "
                                      "reordering, bandwidth, partitions) between master and slave")
    p.add_argument("--profile", required=True, help="TOML (see deploy/faults/*.toml)")
    p.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE",
                   help="override a profile value, e.g. both.delay_s=0.2 (repeatable)")
    p.set_defaults(func=cmd_faults)
    p = sub.add_parser("keys", help="make a CURVE key pair (name.key, name.key_secret)")
    p.add_argument("--out", required=True, help="folder")
    p.add_argument("--name", required=True, help="e.g. slave or master (a file name)")
    p.add_argument("--force", action="store_true",
                   help="replace a pair already there (every peer given its public key "
                        "is then locked out until given the new one)")
    p.set_defaults(func=cmd_keys)
