"""The ``telethermal`` command."""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from telethermal import __version__
from telethermal.errors import TelethermalError
from telethermal.jsonfile import write_json as _write_json

log = logging.getLogger("telethermal")
console = Console(stderr=True)


@contextmanager
def _progress(total: int, what: str):
    """A rich progress bar on stderr; ``advance(label)`` moves it on."""
    with Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(),
                  TextColumn("{task.completed}/{task.total}"), TimeElapsedColumn(),
                  console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task(what, total=total)

        def advance(label: str):
            bar.update(task, advance=1, description=f"{what}: {label}")
        yield advance


def _command() -> str:
    """The command line as typed, for the reports."""
    return "telethermal " + " ".join(sys.argv[1:])


def _png(args) -> Path:
    """``--png``, or the JSON's path with ``.png``."""
    return args.png or Path(args.json).with_suffix(".png")


def _print_lines(lines: list[str]) -> None:
    for line in lines:
        print(line)


# ------------------------------------------------------------------ commands
def cmd_scenes(args) -> int:
    from telethermal.physics.scene import describe_models, list_scenes, load_scene

    table = Table(title="shipped scenes")
    for col in ("name", "pad", "rate (Hz)", "objects", "finger"):
        table.add_column(col)
    for name in list_scenes():
        scene = load_scene(name)
        table.add_row(name, scene.pad.kind, f"{scene.sample_rate_hz:g}",
                      ", ".join(scene.materials), "yes" if scene.finger else "no")
        if args.verbose:
            for side, material, choice in describe_models(scene):
                table.add_row("", side, "", material, choice.describe())
    Console().print(table)
    return 0


def cmd_dataset_generate(args) -> int:
    from telethermal.data.generate import generate_databases
    from telethermal.physics.scene import describe_models, load_scene

    scene = load_scene(args.scene)
    for side, material, choice in describe_models(scene):
        log.info("%s on %s: %s", side, material, choice.describe())
    parts = 2 if scene.finger is not None else 1
    start = time.perf_counter()
    with _progress(parts, f"generating {scene.name}") as advance:
        summary = generate_databases(scene, args.out, seed=args.seed, overwrite=args.force,
                                     progress=advance)
    for name, info in summary["datasets"].items():
        print(f"{Path(args.out) / name}: {info['trials']} trials of "
              f"{', '.join(info['materials'])}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


def cmd_dataset_show(args) -> int:
    from telethermal.data.plots import plot_datasets

    with console.status(f"reading and plotting {args.dir}"):
        png = plot_datasets(args.dir, args.out)
    print(png)
    return 0


def cmd_dataset_validate(args) -> int:
    from telethermal.data.dataset import load_dataset

    with console.status(f"reading {args.dir}"):
        trials = load_dataset(args.dir)
    materials = sorted({t.material for t in trials})
    channels = sorted({c for t in trials for c in t.channels})
    print(f"{args.dir}: {len(trials)} trials, materials {', '.join(materials)}; "
          f"channels {', '.join(channels)}")
    return 0


def cmd_simulate(args) -> int:
    from telethermal.data.dataset import write_dataset
    from telethermal.data.generate import single_contact

    trial = single_contact(args.pad, args.object, args.pad_temp_c, args.object_temp_c,
                           args.seconds, args.rate_hz, ideal=args.ideal, seed=args.seed,
                           contact_conductance_w_m2k=args.contact_conductance_w_m2k)
    write_dataset(args.out, [trial], overwrite=args.force)
    print(f"{Path(args.out) / trial.file}: {len(trial.channels['t_s'])} samples")
    return 0


def cmd_bench_physics(args) -> int:
    from telethermal.bench import physics

    with _progress(6, "bench physics") as advance:
        report = physics.run_and_save(args.json, _png(args), repeats=args.repeats,
                                      command=_command(), progress=advance)
    _print_lines(physics.text_report(report, args.json))
    return 0


def cmd_bench_render(args) -> int:
    from telethermal.bench import render

    with _progress(7, "bench render") as advance:
        report = render.run_and_save(args.json, _png(args), quick=args.quick,
                                     command=_command(), progress=advance)
    _print_lines(render.text_report(report, args.json))
    return 0


def cmd_bench_devices(args) -> int:
    from telethermal.bench import devices

    with _progress(3, "bench devices") as advance:
        report = devices.run_and_save(args.json, n=args.samples, contact_s=args.contact_s,
                                      slave_trials=args.slave_trials, command=_command(),
                                      progress=advance)
    _print_lines(devices.text_report(report, args.json))
    return 0


def cmd_bench_record(args) -> int:
    from telethermal.bench import record

    with _progress(2 * args.rounds, "bench record") as advance:
        report = record.run_and_save(args.json, rounds=args.rounds, contact_s=args.contact_s,
                                     command=_command(), progress=advance)
    _print_lines(record.text_report(report, args.json))
    return 0


def cmd_bench_report(args) -> int:
    from telethermal.bench.report import write_report

    path = write_report(args.results, args.out, _command())
    print(f"wrote {path}")
    return 0


def cmd_bench_transport(args) -> int:
    from telethermal.bench import transport

    with _progress(2, "bench transport") as advance:
        report = transport.run_and_save(args.json, command=_command(), progress=advance)
    _print_lines(transport.text_report(report, args.json))
    return 0


def cmd_bench_faults(args) -> int:
    from telethermal.bench import faults, faults_sim

    with _progress(len(faults_sim.ROWS) + len(faults.SETTINGS) + 1, "bench faults") as advance:
        report = faults.run(progress=advance, quick=args.quick, only=args.only,
                            seeds=args.seeds, processes=not args.no_processes, jobs=args.jobs)
    traces = report.pop("_traces")
    report["command"] = "telethermal " + " ".join(sys.argv[1:])
    png = faults.plot(report, traces, args.png or Path(args.json).with_suffix(".png"))
    report["png"] = str(png)
    _write_json(args.json, report)
    for line in faults.text_report(report):
        print(line)
    print(f"wrote {args.json} and {png}")
    return 0


def _channels(text: str) -> tuple[str, ...]:
    names = tuple(c.strip() for c in text.split(",") if c.strip())
    if not names:
        raise argparse.ArgumentTypeError("give at least one channel")
    return names


def cmd_identify_methods(args) -> int:
    from telethermal.ident.registry import METHODS

    for name, cls in sorted(METHODS.items()):
        print(f"{name:16s} {cls.__doc__.strip().splitlines()[0]}")
    return 0


def cmd_identify_train(args) -> int:
    from telethermal.data.dataset import load_dataset
    from telethermal.ident.prepare import MIN_GAP_K, from_trials
    from telethermal.ident.registry import make

    with console.status(f"reading {args.data}"):
        trials = load_dataset(args.data)
    model = make(args.method, channels=args.channels, max_window_s=args.max_window_s)
    contacts, skipped = from_trials(trials, model.channels, max_s=args.max_window_s)
    if skipped:
        log.warning("%d trial(s) with a gap under %g K left out of training", len(skipped),
                    MIN_GAP_K)
    start = time.perf_counter()
    with console.status(f"training {args.method} on {len(contacts)} trials"):
        model.fit(contacts)
    from telethermal.ident.registry import dataset_scene
    scene_name = dataset_scene(args.data)
    if scene_name is not None:
        model.scene_ = scene_name
    path = model.save(args.out)
    print(f"{path}: {args.method} on {', '.join(model.classes_)}; "
          f"{len(model.windows_s_)} windows up to {model.windows_s_[-1]} s; "
          f"trained in {time.perf_counter() - start:.1f} s")
    return 0


def cmd_identify_eval(args) -> int:
    from telethermal.data.dataset import load_dataset
    from telethermal.ident.evaluate import evaluate, plot_accuracy
    from telethermal.ident.registry import check_scene, dataset_scene, load_model

    model = load_model(args.model)
    scene_name = dataset_scene(args.data)
    if scene_name is not None:
        check_scene(model, scene_name, str(args.model))
    with console.status(f"evaluating on {args.data}"):
        report = evaluate(model, load_dataset(args.data))
    report["command"] = "telethermal " + " ".join(sys.argv[1:])
    _write_json(args.json, report)
    png = args.png or Path(args.json).with_suffix(".png")
    plot_accuracy({model.method: report}, png, f"{args.model} on {args.data}")
    acc = ", ".join(f"{k} s {100 * v:.0f} %" for k, v in report["accuracy_by_window_s"].items())
    print(f"accuracy: {acc}")
    d = report["decision_time_s"]
    if d["n"]:
        print(f"decisions: {d['n']} committed, median {d['p50']:.2f} s, accuracy "
              f"{100 * report['decision_accuracy']:.1f} %; unknown "
              f"{100 * report['decision_unknown_rate']:.0f} %")
    print(f"inference p50 {report['inference_ms_p50']:.3f} ms, p99 {report['inference_ms_p99']:.3f} ms")
    print(f"wrote {args.json} and {png}")
    return 0


def cmd_bench_identify(args) -> int:
    from telethermal.bench import identify

    methods = args.methods.split(",") if args.methods else None
    png = _png(args)
    with _progress(5 * len(methods or identify.METHODS) + 3, "bench identify") as advance:
        report = identify.run_and_save(args.json, png, seed=args.seed, methods=methods,
                                       command=_command(), progress=advance)
    _print_lines(identify.text_report(report, args.json, png))
    return 0


def cmd_demo(args) -> int:
    """The main job on the default scene: databases, identifier and generator
    trained on them, then slave and master as two processes on loopback and
    a touch on each of several materials."""
    from telethermal.data.dataset import load_dataset
    from telethermal.data.generate import generate_databases
    from telethermal.data.plots import plot_datasets
    from telethermal.physics.scene import describe_models, load_scene
    from telethermal.render.generator import NetworkGenerator, save_generator
    from telethermal.services.demo import run_demo
    from telethermal.teleop.run import with_finger

    out = Path(args.out)
    scene = with_finger(load_scene(args.scene))
    print(f"scene {scene.name}: {scene.description.splitlines()[0]}")
    for side, material, choice in describe_models(scene):
        print(f"  {side:6s} on {material:10s} {choice.describe()}")
    start = time.perf_counter()
    with _progress(2, "generating") as advance:
        summary = generate_databases(scene, out / "databases", seed=args.seed, overwrite=True,
                                     progress=advance)
    print(f"databases in {time.perf_counter() - start:.1f} s: "
          + ", ".join(f"{k} {v['trials']} trials" for k, v in summary["datasets"].items()))
    print(f"plot: {plot_datasets(out / 'databases', out / 'databases.png')}")
    _demo_identify(scene, out, args.seed)
    with console.status("training the flux generator on database 2"):
        save_generator(NetworkGenerator().fit(load_dataset(out / "databases" / "finger")),
                       out / "generator.npz")
    materials = [m for m in args.materials.split(",") if m] if args.materials else \
        [m for m in DEMO_MATERIALS if m in scene.materials] or scene.materials[:3]
    report = run_demo(out, args.scene, out / "identifier.npz", out / "generator.npz",
                      materials, seed=args.seed, contact_s=args.contact_s,
                      record_dir=Path(args.record) if args.record else None,
                      view_port=args.view, devices=args.devices)
    view = report.pop("view", None)
    path = _write_json(args.json or out / "demo.json", report)
    print(f"touch plots: {out}/touch-*.png; summary: {path}")
    if args.record:
        files = sorted(Path(args.record).glob("*.mcap"))
        print(f"recordings: {', '.join(str(f) for f in files)} "
              f"(telethermal replay FILE --out DIR [--touch N])")
    if view is not None:
        from telethermal.view.command import wait_for_signal
        print(f"the view stays up at {view.url} (recordings play there); Ctrl-C to stop",
              flush=True)
        try:
            wait_for_signal()
        finally:
            view.close()
    return 0 if all(c == 0 for c in report["exit_codes"].values()) else 1


DEMO_MATERIALS = ("aluminium", "plexiglass", "wood")


def _demo_identify(scene, out: Path, seed: int) -> None:
    """Train telethermal's identifier on the pad database and score it on
    fresh trials of the same scene (another seed)."""
    import numpy as np

    from telethermal.data.dataset import load_dataset
    from telethermal.data.generate import pad_database
    from telethermal.ident.evaluate import evaluate, plot_accuracy
    from telethermal.ident.prepare import from_trials
    from telethermal.ident.registry import make

    model = make("effusivity-lda").fit(from_trials(load_dataset(out / "databases" / "pad"))[0])
    model.scene_ = scene.name
    model.save(out / "identifier.npz")
    report = evaluate(model, pad_database(scene, np.random.default_rng(seed + 1)))
    _write_json(out / "identify.json", report)
    plot_accuracy({model.method: report}, out / "identify.png",
                  f"{scene.name}: trained on seed {seed}, tested on seed {seed + 1}")
    acc = report["accuracy_by_window_s"]
    print(f"identification ({model.method}, fresh trials): "
          + ", ".join(f"{k} s {100 * v:.0f} %" for k, v in acc.items() if k in ("0.2", "0.5", "1.0"))
          + f"; 5 merged classes at 1 s {100 * report.get('accuracy_5_at_end', float('nan')):.0f} %"
          + f"; decisions {report['decision_time_s']['n']}/{report['trials']} committed")
    return model


def _session_models(scene, identifier_path, generator_path, seed):
    """Load the saved identifier and generator, or train them on the scene's
    databases (simulated in memory with ``seed``)."""
    from telethermal.ident.registry import load_model
    from telethermal.render.generator import load_generator
    from telethermal.teleop.models import train_generator, train_identifier

    with console.status("identifier: " + ("loading" if identifier_path else
                                          f"training on {scene.name}'s pad database")):
        identifier = load_model(identifier_path) if identifier_path else \
            train_identifier(scene, seed)
    with console.status("generator: " + ("loading" if generator_path else
                                         f"training on {scene.name}'s finger database")):
        generator = load_generator(generator_path) if generator_path else \
            train_generator(scene, seed)
    return identifier, generator


def cmd_session(args) -> int:
    """One touch, slave and master in one process; JSON and Fig. 3 plot."""
    from telethermal.physics.scene import load_scene
    from telethermal.teleop.master import DisplayConfig
    from telethermal.teleop.plots import plot_session
    from telethermal.teleop.run import run_session, with_finger

    scene = load_scene(args.scene)
    if scene.finger is None:
        console.print(f"scene {scene.name} has no [finger]: the operator is the default "
                      "fingertip (33 C, nominal skin)")
    scene = with_finger(scene)
    identifier, generator = _session_models(scene, args.identifier, args.generator, args.seed)
    config = DisplayConfig(rate_hz=args.rate_hz, before=args.before,
                           feedforward_model=args.controller)
    result = run_session(scene, args.material, identifier, generator, config,
                         contact_s=args.contact_s, seed=args.seed, realtime=args.realtime,
                         devices=args.devices, record=args.record)
    s = result.summary
    _write_json(args.json, s)
    if args.plot:
        plot_session(result, args.plot)
    decided = (f"{s['identified']} at {s['decision_time_s']:.2f} s ({s['decision_reason']})"
               if s["decision_time_s"] is not None else "no decision")
    print(f"{s['material']} on {scene.name}: slave identified {decided}; rendered flux error "
          f"{100 * s['flux_rms_error_rel']:.2f} % of peak after identification, "
          f"{100 * s['flux_rms_error_rel_first_s']:.2f} % over the first second; skin "
          f"{s['temp_rms_error_c']:.2f} K RMS; safety events {s['safety_events']}")
    if args.realtime:
        loop = s["loop"]
        print(f"real clock at {args.rate_hz:g} Hz: period p50 {loop['period_p50_us']:.0f} us, "
              f"p99 {loop['period_p99_us']:.0f} us, max {loop['period_max_us']:.0f} us, "
              f"{loop['deadline_misses']} deadline misses, {loop['stalls']} stalls")
    if args.record:
        r = s["recording"]
        print(f"recorded {r['written']} messages to {r['path']}"
              + (f"; {r['error']}" if r["error"] else ""))
    print(f"wrote {args.json}" + (f" and {args.plot}" if args.plot else ""))
    return 0


def cmd_replay(args) -> int:
    """Re-run the rendering and the identifier on a recording, and plot it."""
    from dataclasses import replace

    from telethermal.teleop.replay import plot_replay, replay

    identifier = generator = gains = None
    if args.identifier:
        from telethermal.ident.registry import load_model
        identifier = load_model(args.identifier)
    if args.generator:
        from telethermal.render.generator import load_generator
        generator = load_generator(args.generator)
    if args.gains:
        try:
            kp, ki, kd = (float(x) for x in args.gains.split(","))
        except ValueError:
            raise TelethermalError(f"--gains {args.gains!r}: give kp,ki,kd") from None
        from telethermal.teleop.master import DEFAULT_GAINS
        gains = replace(DEFAULT_GAINS, kp=kp, ki=ki, kd=kd)
    result = replay(args.file, identifier, generator, gains, touch=args.touch)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    png = plot_replay(result, out / "replay.png")
    s = result["summary"]
    _write_json(out / "replay.json", s)
    if "periods" in s:
        verdict = "identical to the recording, sample for sample" if s["identical"] else \
            f"junction differs from the recording by up to {s['junction_max_abs_diff_c']:.3g} K"
        print(f"{s['periods']} periods replayed: {verdict}")
    if s.get("slave"):
        sl = s["slave"]
        print(f"slave: now {sl['identified']} at {sl['decision_time_s']}, recorded "
              f"{sl['recorded_identified']} at {sl['recorded_decision_time_s']}")
    if s["truncated"]:
        print(f"the recording was cut: read up to the cut ({s['truncated']})")
    for note in s["notes"]:
        print(f"note: {note}")
    print(f"wrote {out / 'replay.json'} and {png}")
    return 0


def cmd_peltier_emulator(args) -> int:
    """An emulated Peltier driver on a CAN bus, until SIGTERM/SIGINT: to try
    a master's CAN path without the hardware."""
    import signal

    from telethermal.devices.emulators import PeltierEmulator

    stop = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.append(1))
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


def cmd_dataset_import(args) -> int:
    from telethermal.record.importer import import_recordings

    before, after = import_recordings(args.recordings, args.into, args.material, args.group)
    print(f"{args.into}: {before} trials before, {after} now")
    return 0


def _serve(service) -> int:
    """Run a service until SIGTERM or SIGINT; the pad goes to its safe state
    first (the service's shutdown), then the sockets close."""
    import signal

    def stop(signum, _frame):
        log.info("signal %s: stopping", signal.Signals(signum).name)
        service.stop_requested = True

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    if console.is_terminal:
        from rich.live import Live

        class Line:
            def __rich__(self):
                s = service.status()
                rtt = f"{1e6 * s['rtt_s']:.0f} us" if s.get("rtt_s") is not None else "-"
                c = s["counters"]
                return (f"[bold]{s['role']}[/bold] {s['state']:9s} peer "
                        f"{'[green]alive[/green]' if s['peer_alive'] else '[red]silent[/red]'}"
                        f"  rtt {rtt}  resent {c['resent']}  gaps {c['gaps']}  "
                        f"reconnects {c['reconnects']}  invalid {c['invalid']}")

        with Live(Line(), console=console, refresh_per_second=2, transient=True):
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


def cmd_faults(args) -> int:
    """A faulty network between a real master and slave, until SIGTERM/SIGINT."""
    import signal

    from telethermal.faults.proxy import FaultProxy, load_profile

    overrides = {}
    for item in args.set or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise TelethermalError(f"--set {item!r}: use section.key=value")
        for kind in (int, float, str):
            try:
                overrides[key] = kind(value)
                break
            except ValueError:
                continue
    profile = load_profile(args.profile, overrides)
    proxy = FaultProxy(profile)
    stop = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.append(1))
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
    from telethermal.wire.transport import generate_keys

    public, secret = generate_keys(args.out, args.name)
    print(f"wrote {public} (give it to the peer; fingerprint {key_file_fingerprint(public)}) "
          f"and {secret} (keep it here, mode 600)")
    if args.name == "slave":                 # where the masters' public keys go
        allowed = Path(args.out) / "allowed"
        allowed.mkdir(exist_ok=True)
        print(f"made {allowed}/: copy each master's master.key into it")
    return 0


# ------------------------------------------------------------------ parser
def _positive(kind=float):
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not (value > 0 and math.isfinite(value)):
            raise argparse.ArgumentTypeError(f"{text!r} must be positive and finite")
        return value
    return parse


def _finite(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} must be finite")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="telethermal", description=__doc__)
    parser.add_argument("--version", action="version", version=f"telethermal {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("scenes", help="list the shipped scenes")
    p.add_argument("--verbose", "-v", action="store_true", help="show each contact's model")
    p.set_defaults(func=cmd_scenes)

    ds = sub.add_parser("dataset", help="generate, show or validate datasets")
    dsub = ds.add_subparsers(dest="dataset_command", required=True)
    p = dsub.add_parser("generate", help="write a scene's databases (pad/ and finger/)")
    p.add_argument("--scene", required=True, help="shipped scene name or TOML path")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true", help="replace a non-empty --out")
    p.set_defaults(func=cmd_dataset_generate)
    p = dsub.add_parser("show", help="plot a dataset (or a folder of datasets)")
    p.add_argument("dir")
    p.add_argument("--out", required=True, help="PNG to write")
    p.set_defaults(func=cmd_dataset_show)
    p = dsub.add_parser("validate", help="read and check every file of a dataset")
    p.add_argument("dir")
    p.set_defaults(func=cmd_dataset_validate)

    p = dsub.add_parser("import", help="add recorded slave contacts to a dataset "
                                       "(identification database)")
    p.add_argument("recordings", nargs="+", help="MCAP recordings (session or slave)")
    p.add_argument("--into", required=True, help="dataset folder (created if absent)")
    p.add_argument("--material", help="the material touched (required for lab recordings)")
    p.add_argument("--group", default="recorded")
    p.set_defaults(func=cmd_dataset_import)

    p = sub.add_parser("peltier-emulator", help="an emulated Peltier driver on a CAN bus "
                                                "(proto/CAN.md), until SIGTERM")
    p.add_argument("--bus", required=True, help="interface:channel, e.g. virtual:display or "
                                                "udp_multicast:239.74.163.2")
    p.set_defaults(func=cmd_peltier_emulator)

    p = sub.add_parser("replay", help="re-run the rendering and the identifier on a recording "
                                      "(new models or gains) and plot the session")
    p.add_argument("file")
    p.add_argument("--out", required=True)
    p.add_argument("--identifier", help="identifier model instead of the recorded one")
    p.add_argument("--generator", help="generator model instead of the recorded one")
    p.add_argument("--gains", help="kp,ki,kd instead of the recorded gains")
    p.add_argument("--touch", type=int, default=0, help="which touch of a service's "
                                                        "recording (0: the first)")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("simulate", help="one contact between two semi-infinite bodies")
    p.add_argument("--pad", required=True, help="material of the pad (or finger: skin)")
    p.add_argument("--object", required=True, help="material of the object")
    p.add_argument("--pad-temp-c", type=_finite, required=True)
    p.add_argument("--object-temp-c", type=_finite, required=True)
    p.add_argument("--seconds", type=_positive(), required=True)
    p.add_argument("--rate-hz", type=_positive(), required=True)
    p.add_argument("--out", required=True, help="output dataset folder")
    p.add_argument("--ideal", action="store_true",
                   help="perfect contact, no sensor, no noise: the closed form")
    p.add_argument("--contact-conductance-w-m2k", type=_positive(), default=3000.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--force", action="store_true", help="replace a non-empty --out")
    p.set_defaults(func=cmd_simulate)

    bench = sub.add_parser("bench", help="benchmarks: speed against error")
    bsub = bench.add_subparsers(dest="bench_command", required=True)
    p = bsub.add_parser("physics", help="contact models: error against runtime")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--png", help="plot (default: beside the JSON)")
    p.add_argument("--repeats", type=_positive(int), default=3)
    p.set_defaults(func=cmd_bench_physics)

    p = bsub.add_parser("transport", help="codec cost; one-way latency beside raw pyzmq on "
                                          "loopback and across network namespaces")
    p.add_argument("--json", required=True)
    p.set_defaults(func=cmd_bench_transport)

    p = bsub.add_parser("report", help="every benchmark's JSON in one Markdown report with "
                                       "its figures")
    p.add_argument("--results", required=True, help="folder of the benches' JSON files")
    p.add_argument("--out", required=True, help="report.md (its PNGs are written beside it)")
    p.set_defaults(func=cmd_bench_report)

    p = bsub.add_parser("record", help="what recording costs the master's 1 kHz loop")
    p.add_argument("--json", required=True)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--contact-s", type=_positive(), default=3.0)
    p.set_defaults(func=cmd_bench_record)

    p = bsub.add_parser("devices", help="both sides' latencies through the emulated serial "
                                        "and CAN paths beside the direct simulator, and the "
                                        "slave's identification through its drivers")
    p.add_argument("--json", required=True)
    p.add_argument("--samples", type=int, default=3000)
    p.add_argument("--contact-s", type=_positive(), default=3.0)
    p.add_argument("--slave-trials", type=int, default=10,
                   help="touches per material on the slave's side (simulated and through the "
                        "emulated drivers, the same trials)")
    p.set_defaults(func=cmd_bench_devices)

    p = bsub.add_parser("faults", help="rendering under network faults, compensated beside "
                                       "naive (processes and the fault proxy)")
    p.add_argument("--json", required=True)
    p.add_argument("--png", help="the Jepsen-style plot (default: next to the JSON)")
    p.add_argument("--quick", action="store_true",
                   help="the zero-delay and 200 ms rows, 2 seeds; processes on one material")
    p.add_argument("--only", help="comma-separated parts of setting names to run "
                                  "(e.g. 'crash,partition'); 'delay 0 ms' is always run")
    p.add_argument("--seeds", type=int, help="seeds per material on the simulated clock "
                                             "(default 5; 2 with --quick)")
    p.add_argument("--jobs", type=int, default=2,
                   help="worker processes for the simulated rows (default 2)")
    p.add_argument("--no-processes", action="store_true",
                   help="the simulated part only (no services, no fault proxy)")
    p.set_defaults(func=cmd_bench_faults)

    p = bsub.add_parser("render", help="rendering error against loop rate, gains, strategy; "
                                       "the loop on the real clock")
    p.add_argument("--json", required=True)
    p.add_argument("--png")
    p.add_argument("--quick", action="store_true", help="a few materials and rates (tests)")
    p.set_defaults(func=cmd_bench_render)

    ident = sub.add_parser("identify", help="material identification")
    isub = ident.add_subparsers(dest="identify_command", required=True)
    p = isub.add_parser("methods", help="list the identification methods")
    p.set_defaults(func=cmd_identify_methods)
    p = isub.add_parser("train", help="fit an identifier on a dataset")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--method", required=True)
    p.add_argument("--channels", type=_channels, default=("heat_flux_W_m2",),
                   help="comma-separated channels (default heat_flux_W_m2)")
    p.add_argument("--max-window-s", type=_positive(), default=1.0)
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    p.set_defaults(func=cmd_identify_train)
    p = isub.add_parser("eval", help="score a model on a dataset")
    p.add_argument("--model", required=True)
    p.add_argument("--data", required=True)
    p.add_argument("--json", required=True)
    p.add_argument("--png")
    p.set_defaults(func=cmd_identify_eval)

    p = bsub.add_parser("identify", help="the papers' identification tables, ours beside")
    p.add_argument("--json", required=True)
    p.add_argument("--png")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--methods", help="comma-separated (default: all)")
    p.set_defaults(func=cmd_bench_identify)

    p = sub.add_parser("session", help="one telepresence touch, slave and master in one "
                                       "process on the simulator")
    p.add_argument("--scene", default="fingertip-7", help="shipped scene name or TOML path")
    p.add_argument("--material", required=True, help="the remote object's material")
    p.add_argument("--json", required=True, help="summary to write")
    p.add_argument("--plot", help="PNG of flux and temperature against direct contact")
    p.add_argument("--identifier", help="saved identifier (.npz); default: train one")
    p.add_argument("--generator", help="saved flux generator (.npz); default: train one")
    p.add_argument("--rate-hz", type=_positive(), default=1000.0, help="display loop rate")
    p.add_argument("--before", choices=("prior", "hold"), default="prior",
                   help="before identification: track the posterior-weighted flux (prior) "
                        "or hold the pad at the object temperature (hold, the paper's)")
    p.add_argument("--controller", choices=("impedance", "static"), default="impedance",
                   help="impedance: the pad's surface behaves as the object's (default); "
                        "static: the flux PID on the generator's flux")
    p.add_argument("--contact-s", type=_positive(), default=5.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--realtime", action="store_true",
                   help="run the master loop on the real clock and report its timing")
    p.add_argument("--record", help="record the session to this MCAP file")
    p.add_argument("--devices", choices=("sim", "emulated"), default="sim",
                   help="sim: the simulator directly; emulated: the display's sensor board on "
                        "a pty and its Peltier driver on a virtual CAN bus, through the drivers")
    p.set_defaults(func=cmd_session)

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
    p.add_argument("--name", required=True, help="e.g. slave or master")
    p.set_defaults(func=cmd_keys)
    from telethermal.services.operate import register
    register(sub)                            # admin, check, models

    p = sub.add_parser("demo", help="run the main job on the default scene: master and slave "
                                    "as two processes on loopback, a touch per material")
    p.add_argument("--scene", default="fingertip-7")
    p.add_argument("--out", default="out/demo")
    p.add_argument("--json", help="per-touch summary (default: OUT/demo.json)")
    p.add_argument("--materials", help="comma-separated (default: aluminium,plexiglass,wood)")
    p.add_argument("--contact-s", type=_positive(), default=5.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--devices", choices=("sim", "emulated"), default="sim",
                   help="emulated: master and slave each on emulated boards (ptys) and CAN "
                        "drivers (virtual buses), read through the drivers")
    p.add_argument("--record", metavar="DIR", help="both services record every touch here "
                                                   "(one MCAP file per host; see replay)")
    p.add_argument("--view", type=int, nargs="?", const=8050, metavar="PORT",
                   help="open the live view alongside (telethermal view) on 127.0.0.1:PORT "
                        "(default 8050); it stays up after the touches until Ctrl-C")
    p.set_defaults(func=cmd_demo)
    from telethermal.view.command import add_parsers
    add_parsers(sub, bsub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    service = args.command in ("slave", "master")
    logging.basicConfig(level=logging.INFO if args.verbose or service else logging.WARNING,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s" if service
                        else "%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except TelethermalError as exc:
        console.print(f"[red]error:[/red] {exc}", highlight=False)
        return 2
    except KeyboardInterrupt:
        console.print("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
