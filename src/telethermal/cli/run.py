"""``telethermal demo``, ``session`` and ``replay``."""

from __future__ import annotations

from pathlib import Path

from telethermal.cli._common import (CONTACT_MAX_S, CONTACT_WHY, RATE_MAX_HZ, RATE_WHY,
                                     _positive, _progress, _seed, console)
from telethermal.control.loop import DEFAULT_RATE_HZ, MAX_TIME_SCALE
from telethermal.services.config import MIN_RATE_HZ, MIN_RATE_WHY
from telethermal.errors import TelethermalError
from telethermal.jsonfile import write_json


def cmd_demo(args) -> int:
    """The main job on the default scene: databases, identifier and generator
    trained on them, then slave and master as two processes on loopback and
    a touch on each of several materials."""
    from telethermal.outputfolder import prepare_output_folder

    prepare_output_folder(args.out)          # before anything is computed
    from telethermal.demo.run import demo
    from telethermal.services.viewer import serve_until_signal

    result = demo(args.out, args.scene,
                  [m for m in args.materials.split(",") if m] if args.materials else None,
                  seed=args.seed, contact_s=args.contact_s, record_dir=args.record,
                  view_port=args.view, devices=args.devices, json_path=args.json,
                  progress=_progress, status=console.status, method=args.method,
                  calibration=args.calibration or "", rate_hz=args.rate_hz,
                  time_scale=args.time_scale)
    if result.view is not None:
        print(f"the view stays up at {result.view.url} (recordings play there); Ctrl-C to "
              "stop", flush=True)
        serve_until_signal(result.view)
    return 0 if result.ok else 1


def _session_lines(s: dict, scene_name: str, args) -> list[str]:
    decided = (f"{s['identified']} at {s['decision_time_s']:.2f} s ({s['decision_reason']})"
               if s["decision_time_s"] is not None else "no decision")
    lines = [f"{s['material']} on {scene_name}: slave identified {decided}; rendered flux error "
             f"{100 * s['flux_rms_error_rel']:.2f} % of peak after identification, "
             f"{100 * s['flux_rms_error_rel_first_s']:.2f} % over the first second; skin "
             f"{s['temp_rms_error_c']:.2f} K RMS; safety events {s['safety_events']}"]
    if args.realtime:
        loop = s["loop"]
        lines.append(f"real clock at {args.rate_hz:g} Hz: period p50 "
                     f"{loop['period_p50_us']:.0f} us, p99 {loop['period_p99_us']:.0f} us, max "
                     f"{loop['period_max_us']:.0f} us, {loop['deadline_misses']} deadline "
                     f"misses, {loop['stalls']} stalls")
    if args.record:
        r = s["recording"]
        lines.append(f"recorded {r['written']} messages to {r['path']}"
                     + (f"; {r['error']}" if r["error"] else ""))
    return lines + [f"wrote {args.json}" + (f" and {args.plot}" if args.plot else "")]


def cmd_session(args) -> int:
    """One touch, slave and master in one process; JSON and Fig. 3 plot."""
    from telethermal.physics.scene import load_scene
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.teleop.models import session_models
    from telethermal.teleop.plots import plot_session
    from telethermal.sim.inprocess import run_session
    from telethermal.physics.scene import with_finger

    scene = load_scene(args.scene)
    if scene.finger is None:
        console.print(f"scene {scene.name} has no [finger]: the operator is the default "
                      "fingertip (33 C, nominal skin)")
    scene = with_finger(scene)
    identifier, generator = session_models(scene, args.identifier, args.generator, args.seed,
                                           status=console.status)
    config = DisplayConfig(rate_hz=args.rate_hz, before=args.before,
                           feedforward_model=args.controller)
    cal = None
    if args.calibration:
        from telethermal.teleop.display_calibration import display_calibration
        cal = display_calibration(args.calibration, scene)
    result = run_session(scene, args.material, identifier, generator, config,
                         contact_s=args.contact_s, seed=args.seed, realtime=args.realtime,
                         devices=args.devices, record=args.record, display_calibration=cal)
    write_json(args.json, result.summary)
    if args.plot:
        plot_session(result, args.plot)
    for line in _session_lines(result.summary, scene.name, args):
        print(line)
    return 0


def _gains(text: str | None) -> tuple[float, float, float] | None:
    if not text:
        return None
    try:
        kp, ki, kd = (float(x) for x in text.split(","))
    except ValueError as exc:
        raise TelethermalError(f"--gains {text!r}: give kp,ki,kd") from exc
    return kp, ki, kd


def cmd_replay(args) -> int:
    """Re-run the rendering and the identifier on a recording's touches (or
    the one asked), and plot each."""
    from telethermal.teleop.replay import touch_count

    if args.scene:
        _load_recorded_scene(args.file, args.scene)
    n = touch_count(args.file)
    if n == 0:
        from telethermal.record.recording import RecordingError
        raise RecordingError(f"{args.file}: no touch recorded: nothing to replay")
    touches = range(n) if args.touch is None else [args.touch]
    for i in touches:
        # One touch: its files in --out; several: one folder per touch.
        out = Path(args.out) if len(touches) == 1 else Path(args.out) / f"touch-{i}"
        if len(touches) > 1 or n > 1:
            print(f"touch {i} of {n} (0..{n - 1}):")
        _replay_one(args, i, out)
    return 0


def _load_recorded_scene(path, scene_arg) -> None:
    """Load the scene file a recording was made on (its models find their
    pad's scene by the recorded name), refusing one of another name."""
    from telethermal.physics.scene import load_scene
    from telethermal.record.recording import RecordingError, read_recording

    scene, recorded = load_scene(scene_arg), read_recording(path).config.get("scene")
    if recorded is not None and recorded != scene.name:
        raise RecordingError(f"{path}: recorded on scene {recorded!r}, but --scene is "
                             f"{scene.name!r}")


def _replay_one(args, touch: int, out: Path) -> None:
    from telethermal.teleop.replay import replay_to_folder

    s, png = replay_to_folder(args.file, out, args.identifier, args.generator,
                              _gains(args.gains), touch=touch)
    d = s["direct"]
    if d is not None:
        print(f"against direct contact (the simulator's truth, as recorded): flux "
              f"{100 * d['flux_rms_error_rel']:.2f} % of peak from the decision on, "
              f"{100 * d['flux_rms_error_rel_first_s']:.2f} % over the first second; skin "
              f"{d['temp_rms_error_c']:.2f} K RMS")
    else:
        print("no figures against direct contact: the recording holds no truth to compare "
              "with (a lab's recording, or a slave's)")
    if "periods" in s:
        verdict = "identical to the recording, sample for sample" if s["identical"] else \
            "not compared whole: the recording is damaged" if s.get("damaged") else \
            f"junction differs from the recording by up to {s['junction_max_abs_diff_c']:.3g} K"
        print(f"{s['periods']} periods replayed: {verdict}")
    if s.get("slave"):
        sl = s["slave"]
        print(f"slave: now {sl['identified']} at {sl['decision_time_s']}, recorded "
              f"{sl['recorded_identified']} at {sl['recorded_decision_time_s']}")
    if s.get("damaged"):
        print(f"the recording is damaged (what could not be read was skipped): {s['damaged']}")
    if s["truncated"]:
        print(f"the recording was cut: read up to the cut ({s['truncated']})")
    for note in s["notes"]:
        print(f"note: {note}")
    print(f"wrote {out / 'replay.json'} and {png}")


def add_replay(sub) -> None:
    p = sub.add_parser("replay", help="re-run the rendering and the identifier on a recording "
                                      "(new models or gains) and plot the session")
    p.add_argument("file",
                   help="an MCAP recording (from session --record, demo --record or a "
                        "service's record_dir)")
    p.add_argument("--out", required=True, help="folder for the replay's plots and JSON")
    p.add_argument("--identifier", help="identifier model instead of the recorded one")
    p.add_argument("--generator", help="generator model instead of the recorded one")
    p.add_argument("--gains", help="kp,ki,kd instead of the recorded gains")
    p.add_argument("--touch", type=int, default=None,
                   help="which touch of a service's recording (0: the first); default: "
                        "every touch, each in its own folder OUT/touch-N")
    p.add_argument("--scene", metavar="FILE",
                   help="the scene file the recording was made on (a recording names its "
                        "scene; a shipped one is found by that name)")
    p.set_defaults(func=cmd_replay)


def add_session(sub) -> None:
    p = sub.add_parser("session", help="one telepresence touch, slave and master in one "
                                       "process on the simulator")
    p.add_argument("--scene", default="fingertip-7", help="shipped scene name or TOML path")
    p.add_argument("--material", required=True, help="the remote object's material")
    p.add_argument("--json", required=True, help="summary to write")
    p.add_argument("--plot", help="PNG of flux and temperature against direct contact")
    p.add_argument("--identifier", help="saved identifier (.npz); default: train one")
    p.add_argument("--generator", help="saved flux generator (.npz); default: train one")
    p.add_argument("--rate-hz", type=_positive(at_most=RATE_MAX_HZ, why=RATE_WHY,
                                               at_least=MIN_RATE_HZ, why_least=MIN_RATE_WHY),
                   default=DEFAULT_RATE_HZ,
                   help=f"display loop rate (default {DEFAULT_RATE_HZ:g} Hz, at least "
                        f"{MIN_RATE_HZ:g}, as a master service runs)")
    p.add_argument("--before", choices=("prior", "hold"), default="prior",
                   help="before identification: track the posterior-weighted flux (prior) "
                        "or hold the pad at the object temperature (hold, the paper's)")
    p.add_argument("--controller", choices=("impedance", "static"), default="impedance",
                   help="impedance: the pad's surface behaves as the object's (default); "
                        "static: the flux PID on the generator's flux")
    p.add_argument("--contact-s", type=_positive(at_most=CONTACT_MAX_S, why=CONTACT_WHY),
                   default=5.0,
                   help="contact time, seconds (default 5)")
    p.add_argument("--seed", type=_seed, default=0, help="random seed of the touch (default 0)")
    p.add_argument("--realtime", action="store_true",
                   help="run the master loop on the real clock and report its timing")
    p.add_argument("--record", help="record the session to this MCAP file")
    p.add_argument("--calibration", metavar="CAL.toml", help=DISPLAY_CAL_HELP)
    p.add_argument("--devices", choices=("sim", "emulated", "qemu"), default="sim",
                   help="sim: the simulator directly; emulated: the display's sensor board on "
                        "a pty and its Peltier driver on a virtual CAN bus, through the drivers; "
                        "qemu: the reference firmware as those boards on emulated STM32F405 "
                        "cores (qemu-system-arm, gcc-arm-none-eabi, picolibc-arm-none-eabi)")
    p.set_defaults(func=cmd_session)


DISPLAY_CAL_HELP = ("the display's calibration (telethermal calibrate display: the file's "
                    "[display] table): the master's controllers use its flux and junction "
                    "sensor lags instead of the scene's")


def add_demo(sub) -> None:
    p = sub.add_parser("demo", help="run the main job on the default scene: master and slave "
                                    "as two processes on loopback, a touch per material")
    p.add_argument("--scene", default="fingertip-7",
                   help="shipped scene name or TOML path (default fingertip-7)")
    p.add_argument("--out", default="out/demo",
                   help="output folder: plots, demo.json, models, logs (default out/demo)")
    p.add_argument("--json", help="per-touch summary (default: OUT/demo.json)")
    p.add_argument("--materials", help="comma-separated (default: aluminium,plexiglass,wood)")
    p.add_argument("--contact-s", type=_positive(at_most=CONTACT_MAX_S, why=CONTACT_WHY),
                   default=5.0,
                   help="each touch's contact time, seconds (default 5)")
    p.add_argument("--seed", type=_seed, default=0,
                   help="random seed of the databases and the touches (default 0)")
    p.add_argument("--devices", choices=("sim", "emulated", "qemu"), default="sim",
                   help="emulated: master and slave each on emulated boards (ptys) and CAN "
                        "drivers (virtual buses), read through the drivers; qemu: the boards "
                        "are the reference firmware on emulated STM32F405s (qemu-system-arm, "
                        "processor in the loop)")
    p.add_argument("--record", metavar="DIR", help="both services record every touch here "
                                                   "(one MCAP file per host; see replay)")
    p.add_argument("--method", choices=("effusivity-lda", "effusivity-fit"),
                   help="the slave's identifier (default effusivity-fit, which fits the pad's "
                        "model to each window, on a scene it can model; else effusivity-lda: "
                        "telethermal bench identify compares them)")
    p.add_argument("--calibration", metavar="CAL.toml",
                   help="a calibration file (telethermal calibrate pad and/or calibrate "
                        "display): the slave's identifier is trained with the sensing pad's "
                        "calibration it holds and the master given its [display] table "
                        "(each service's config key pad_calibration); either may be absent. "
                        "Without it, a scene with [as_built] is calibrated first")
    p.add_argument("--rate-hz", type=_positive(at_most=RATE_MAX_HZ, why=RATE_WHY,
                                               at_least=MIN_RATE_HZ, why_least=MIN_RATE_WHY),
                   default=DEFAULT_RATE_HZ,
                   help=f"the master's display loop rate (default {DEFAULT_RATE_HZ:g} Hz, at "
                        f"least {MIN_RATE_HZ:g})")
    p.add_argument("--time-scale", type=_positive(at_most=MAX_TIME_SCALE,
                                                  why="a 500 Hz period then lasts 0.2 s",
                                                  at_least=1.0, why_least="real time"),
                   help="how many of the machine's seconds one second of the services (and "
                        "of the cores' firmware) lasts (default 1; under --devices qemu what "
                        "QEMU's slow UARTs need to carry each period: firmware/README.md)")
    p.add_argument("--view", type=int, nargs="?", const=8050, metavar="PORT",
                   help="open the live view alongside (telethermal view) on 127.0.0.1:PORT "
                        "(default 8050); it stays up after the touches until Ctrl-C")
    p.set_defaults(func=cmd_demo)
