"""The operator's subcommands of ``telethermal``: ``admin`` (operate a
session), ``check`` (preflight of a service's set-up) and ``models`` (the
slave host's identifier and generator); printing is here, the work in the
modules they call."""

from __future__ import annotations

import json

from telethermal.cli._common import _positive, _seed, _temperature_c, _wait_s
from telethermal.errors import TelethermalError
from telethermal.services import admin_client as ac


def add_parsers(sub) -> None:
    """admin, check, models."""
    _admin_parser(sub)
    p = sub.add_parser("check", help="preflight: a service's config, keys, allowed folder, "
                                     "model files and the peer's reachability; or what the "
                                     "processor in the loop needs (--devices qemu)")
    p.add_argument("--config", help="a slave or master config file (TOML)")
    p.add_argument("--devices", choices=("qemu",),
                   help="qemu: QEMU, the Arm toolchain and picolibc (each missing one with "
                        "its apt package), and the firmware's STM32F405 images built")
    p.add_argument("--timeout-s", type=_positive(at_most=3600.0), default=3.0,
                   help="how long the master waits for the slave's handshake")
    p.set_defaults(func=cmd_check)
    p = sub.add_parser("models", help="train the slave's identifier and generator "
                                      "(from a scene, or a dataset) with a checksum file")
    p.add_argument("--out", required=True, help="folder for identifier.npz, generator.npz, "
                                                "SHA256SUMS")
    p.add_argument("--scene", default="fingertip-7",
                   help="shipped scene name or TOML path (default fingertip-7)")
    p.add_argument("--data", help="a dataset folder with pad/ and finger/ (e.g. from "
                                  "`dataset generate`), or one dataset of pad contacts (a "
                                  "lab's `dataset import`: the generator is then the scene's "
                                  "direct-contact model), instead of the scene's simulated "
                                  "databases")
    p.add_argument("--seed", type=_seed, default=0,
                   help="random seed of the simulated databases (default 0)")
    p.add_argument("--calibration", metavar="CAL.toml",
                   help="the sensing pad's calibration (telethermal calibrate pad): the "
                        "identifier fits the pad's model as calibrated, and records it")
    p.set_defaults(func=cmd_models)


def _admin_parser(sub) -> None:
    p = sub.add_parser("admin", help="operate a session: place, touch, lift, status, report, "
                                     "or any admin request (send)")
    p.add_argument("--slave", help="the slave's admin: PORT, 127.0.0.1:PORT, ipc:// path or "
                                   "its config file (default 5570)")
    p.add_argument("--master", help="the master's admin: PORT, 127.0.0.1:PORT, ipc:// path or "
                                    "its config file (default 5571)")
    p.add_argument("--json", action="store_true", help="print the raw replies as JSON")
    asub = p.add_subparsers(dest="admin_command", required=True)
    q = asub.add_parser("status", help="each reachable service's state, peer, counters and, "
                                       "with no session, the likely cause")
    q.add_argument("role", nargs="?", choices=("slave", "master", "both"), default="both",
                   help="which service to ask (default both)")
    q.add_argument("--wait", type=float, default=0.0, metavar="S",
                   help="wait up to S seconds for the services to answer and the "
                        "master to have a live session (exit 1 if not); without it, "
                        "exit 1 if a role asked for does not answer (a healthcheck)")
    q = asub.add_parser("place", help="put an object under the slave pad (simulation)")
    q.add_argument("material", help="the object's material (one of the slave's scene)")
    q.add_argument("--seed", type=_seed,
                   help="seed of the object's touch (default: the slave's next)")
    q.add_argument("--object-id", help="the object's name, its key in the slave's object "
                                       "memory (default: the scene object of MATERIAL)")
    q = asub.add_parser("touch", help="the simulated operator touches the master's pad; "
                                      "prints the touch's figures")
    q.add_argument("--contact-s", type=_positive(at_most=60.0, why="the master's touch "
                                                 "request takes up to 60 s"),
                   default=5.0, help="contact time, seconds (default 5)")
    q.add_argument("--seed", type=_seed, default=0,
                   help="seed of the simulated operator's touch (default 0)")
    q.add_argument("--no-wait", action="store_true", help="return at once (then lift, report)")
    q.add_argument("--session-wait", type=_wait_s, default=30.0, metavar="S",
                   help="wait up to S seconds for the master's session with the slave "
                        "(right after start, the slave may still be training; default 30)")
    q.add_argument("--material", help="the placed object, if the slave's admin is not "
                                      "reachable from here (for the direct-contact figures)")
    q.add_argument("--object-c", type=_temperature_c, help="its true temperature (C)")
    asub.add_parser("lift", help="end the touch in progress now")
    asub.add_parser("report", help="the last touch's figures (master and slave)")
    q = asub.add_parser("send", help="any admin request: send ROLE CMD [key=value ...]")
    q.add_argument("role", choices=("slave", "master"), help="the service to ask")
    q.add_argument("cmd",
                   help="the admin request's name (its list: proto/PROTOCOL.md, admin requests)")
    q.add_argument("args", nargs="*", metavar="key=value",
                   help="the request's arguments, each key=value")
    q.add_argument("--timeout-s", type=_positive(at_most=3600.0), default=10.0,
                   help="how long to wait for the reply, seconds (default 10)")
    p.set_defaults(func=cmd_admin)


def _show(args, reply: dict, lines: list[str]) -> None:
    if args.json:
        print(json.dumps(reply, indent=1, default=str))
    else:
        print("\n".join(lines))


def cmd_admin(args) -> int:
    where = {"slave": ac.resolve(args.slave, "slave"),
             "master": ac.resolve(args.master, "master")}
    return _ADMIN[args.admin_command](args, where)


def _status(args, where) -> int:
    roles = ("slave", "master") if args.role == "both" else (args.role,)
    poll = ac.poll_status(where, roles, args.wait)
    if poll.error is not None and args.role != "both":
        raise poll.error
    _show(args, poll.replies, poll.lines)
    if args.wait:
        return 0 if poll.live else 1
    return 0 if poll.error is None else 1         # a role that did not answer


def _place(args, where) -> int:
    extra = {} if args.seed is None else {"seed": args.seed}
    if args.object_id:
        extra["object_id"] = args.object_id
    r = ac.request(where["slave"], "slave", "place", material=args.material, **extra)
    known = f"remembered as {r['object_material']}" if r.get("object_material") else \
        "nothing remembered of it"
    _show(args, r, [f"placed {args.material} under the slave pad: {r['object_true_c']:.2f} C "
                    f"(true), {r['object_ir_c']:.2f} C by IR; object "
                    f"{r.get('object_id')}: {known}"])
    return 0


def _touch(args, where) -> int:
    status = ac.wait_for_session(where["master"], args.session_wait)
    truth = ac.truth_for_touch(where["slave"], args.material, args.object_c)
    # The contact lasts contact_s of the master's clock (time_scale of the machine's).
    scale = float(status.get("time_scale", 1.0))
    r = ac.request(where["master"], "master", "touch", timeout_s=scale * args.contact_s + 30,
                   contact_s=args.contact_s, seed=args.seed, wait=not args.no_wait,
                   truth=truth)
    if args.no_wait:
        _show(args, r, [f"touch {r['contact_id']} started ({args.contact_s:.1f} s)"])
        return 0
    r.pop("trace", None)
    _show(args, r, ac.describe_touch(r))
    return 0


def _lift(args, where) -> int:
    r = ac.request(where["master"], "master", "lift")
    _show(args, r, [f"touch {r['contact_id']} lifted after {r['contact_s']:.2f} s"])
    return 0


def _report(args, where) -> int:
    r = ac.request(where["master"], "master", "report")
    lines = ac.describe_touch(r)
    try:
        s = ac.request(where["slave"], "slave", "report", timeout_s=1.0)
        if s.get("material"):
            r["slave"] = s
            lines.append(f"  slave: placed {s['material']}, identified {s['identified']} "
                         f"({s['reason']})")
    except TelethermalError:
        pass
    _show(args, r, lines)
    return 0


def _send(args, where) -> int:
    r = ac.request(where[args.role], args.role, args.cmd, timeout_s=args.timeout_s,
                   **ac.parse_args(args.args))
    print(json.dumps(r, indent=1, default=str))
    return 0


_ADMIN = {"status": _status, "place": _place, "touch": _touch, "lift": _lift,
          "report": _report, "send": _send}


def cmd_check(args) -> int:
    from telethermal.services.preflight import run_checks

    from telethermal.services.preflight import qemu_findings

    if args.config is None and args.devices is None:
        raise TelethermalError("check: give --config FILE (a service's set-up) and/or "
                               "--devices qemu (the processor in the loop)")
    findings = run_checks(args.config, timeout_s=args.timeout_s) if args.config else []
    if args.devices == "qemu":
        findings += qemu_findings()
    problems = 0
    for line in findings:
        print(line.text())
        problems += not line.ok
    print(f"{problems} problem{'s' if problems != 1 else ''}" if problems else
          "ready: no problem found")
    return 1 if problems else 0


def cmd_models(args) -> int:
    from telethermal.teleop.models import write_models

    paths = write_models(args.out, args.scene, args.data, args.seed, echo=print,
                         calibration=args.calibration)
    for path in paths:
        print(f"wrote {path}")
    print(f"copy them to the slave host and check them there with `sha256sum -c SHA256SUMS` "
          f"in {args.out}")
    return 0
