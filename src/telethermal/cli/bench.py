"""``telethermal bench ...``: each benchmark runs, writes its report and
prints its figures (the work is in ``telethermal.bench``)."""

from __future__ import annotations

import sys

from telethermal.cli._common import (_command, _models_folder, _png, _positive, _progress,
                                     _seed)


def bench_text(*args) -> str:
    """A bench's printout: its section of the report (one renderer)."""
    from telethermal.bench.report import bench_text as text
    return text(*args)


def cmd_bench_physics(args) -> int:
    from telethermal.bench import physics

    with _progress(6, "bench physics") as advance:
        report = physics.run_and_save(args.json, _png(args), repeats=args.repeats,
                                      command=_command(), progress=advance)
    print(bench_text("physics", report, args.json, report["png"]))
    return 0


def cmd_bench_render(args) -> int:
    from telethermal.bench import render

    if args.as_built is not None:
        _no_executor(args)
        return _bench_render_as_built(args)
    _no_references(args)
    with _progress(10, "bench render") as advance, _executor(args) as executor:
        report = render.run_and_save(args.json, _png(args), quick=args.quick,
                                     command=_command(), progress=advance, scene=args.scene,
                                     executor=executor, models=args.models)
    print(bench_text("render", report, args.json, report["png"]))
    return 0


def cmd_bench_devices(args) -> int:
    from telethermal.bench import devices

    with _progress(5, "bench devices") as advance:
        report = devices.run_and_save(args.json, n=args.samples, contact_s=args.contact_s,
                                      slave_trials=args.slave_trials, command=_command(),
                                      progress=advance, models=args.models)
    print(bench_text("devices", report, args.json))
    return 0


def cmd_bench_record(args) -> int:
    from telethermal.bench import record

    with _progress(2 * args.rounds, "bench record") as advance:
        report = record.run_and_save(args.json, rounds=args.rounds, contact_s=args.contact_s,
                                     command=_command(), progress=advance, models=args.models)
    print(bench_text("record", report, args.json))
    return 0


def cmd_bench_report(args) -> int:
    from telethermal.bench.report import write_report

    path = write_report(args.results, args.out, _command())
    print(f"wrote {path}")
    return 0


def cmd_bench_transport(args) -> int:
    from telethermal.bench import transport

    with _progress(2, "bench transport") as advance:
        report = transport.run_and_save(args.json, command=_command(), progress=advance,
                                        quick=args.quick)
    print(bench_text("transport", report, args.json))
    return 0


def cmd_bench_faults(args) -> int:
    from telethermal.bench import faults, faults_sim
    from telethermal.jsonfile import write_json

    delays = faults.parse_delays(args.delays) if args.delays else None
    png = _png(args)                                        # checked before the run
    n_rows = len(faults_sim.ROWS) + len(faults.SETTINGS) + 2 * len(delays or ())
    with _progress(n_rows + 1, "bench faults") as advance, _executor(args) as executor:
        report = faults.run(progress=advance, quick=args.quick, only=args.only,
                            seeds=args.seeds, processes=not args.no_processes,
                            executor=executor, scene_name=args.scene, delays_ms=delays,
                            models=args.models)
    traces = report.pop("_traces")
    report["command"] = _command()
    png = faults.plot(report, traces, png)
    report["png"] = str(png)
    write_json(args.json, report)
    print(bench_text("faults", report, args.json, png))
    return 0


def cmd_bench_identify(args) -> int:
    from telethermal.bench import identify
    from telethermal.bench.options import parse_methods

    if args.as_built is not None:
        _no_executor(args)
        return _bench_identify_as_built(args)
    _no_references(args)
    methods = parse_methods(args.methods) if args.methods else None
    png = _png(args)
    n_jobs = len(identify.jobs(methods or identify.DEFAULT_METHODS, not args.no_limit,
                               args.scene))
    with _progress(n_jobs, "bench identify") as advance, _executor(args) as executor:
        report = identify.run_and_save(args.json, png, seed=args.seed, methods=methods,
                                       command=_command(), progress=advance, scene=args.scene,
                                       sessions=args.sessions, with_limit=not args.no_limit,
                                       executor=executor)
    print(bench_text("identify", report, args.json, png))
    return 0


def _stamp() -> dict:
    """An as-built bench's provenance: its command, the machine, the date."""
    import datetime
    import os
    import platform
    return {"command": _command(), "machine": f"{platform.node()} ({platform.machine()}, "
            f"{os.cpu_count()} CPUs, Python {platform.python_version()})",
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def _bench_identify_as_built(args) -> int:
    from telethermal.bench import identify_as_built as ab
    from telethermal.jsonfile import write_json

    with _progress(1 + 3 * args.pads, "bench identify --as-built") as advance:
        section = ab.run(args.as_built, args.pads, args.scene or "fingertip-7",
                         progress=advance, references=args.references,
                         partial=lambda part: write_json(
                             args.json, {"as_built": part, **_stamp()}))
    report = {"as_built": section, **_stamp()}
    write_json(args.json, report)
    print(bench_text("identify-as-built", report, args.json))
    return 0


def _bench_render_as_built(args) -> int:
    from telethermal.bench import render_as_built as ab
    from telethermal.jsonfile import write_json

    with _progress(1 + 4 * args.pads, "bench render --as-built") as advance:
        section = ab.run(args.as_built, args.pads, args.scene or "fingertip-7",
                         quick=args.quick, progress=advance, references=args.references,
                         partial=lambda part: write_json(
                             args.json, {"as_built": part, **_stamp()}))
    report = {"as_built": section, **_stamp()}
    write_json(args.json, report)
    print(bench_text("render-as-built", report, args.json))
    return 0


def cmd_bench_view(args) -> int:
    from telethermal.bench import view

    report = view.run_and_save(args.json, touches=args.touches, contact_s=args.contact_s,
                               progress=lambda m: print(m, flush=True),
                               realtime_priority=args.realtime_priority, command=_command(),
                               models=args.models)
    print(bench_text("view", report, args.json))
    return 0


def cmd_bench_skin_floor(args) -> int:
    from telethermal.bench import skin_floor

    steps = 14 if args.quick else 27
    with _progress(steps, "bench skin-floor") as advance:
        report = skin_floor.run_and_save(args.json, _png(args), quick=args.quick,
                                         command=_command(), progress=advance,
                                         scene=args.scene)
    print(bench_text("skin-floor", report, args.json, report["png"]))
    return 0


def cmd_bench_unseen(args) -> int:
    from telethermal.bench import unseen

    if args.as_built is not None:
        _no_executor(args)
        return _bench_unseen_as_built(args)
    _no_references(args)
    seeds = args.seeds or (1 if args.quick else 3)
    with _progress(2 * seeds + 3, "bench unseen") as advance, _executor(args) as executor:
        report = unseen.run_and_save(args.json, command=_command(), seeds=seeds,
                                     unseen=args.unseen, unseen_scene=args.unseen_scene,
                                     quick=args.quick, scene=args.scene, progress=advance,
                                     executor=executor)
    print(bench_text("unseen", report, args.json))
    return 0


def _bench_unseen_as_built(args) -> int:
    from telethermal.bench import unseen_as_built as ab
    from telethermal.jsonfile import write_json

    if args.unseen or args.unseen_scene:
        from telethermal.errors import BenchError
        raise BenchError("bench unseen --as-built touches the default unseen set; "
                         "--unseen and --unseen-scene are for the pad as modelled")
    with _progress(1 + 2 * args.pads, "bench unseen --as-built") as advance:
        section = ab.run(args.as_built, args.pads, args.seeds or 1, args.scene or "fingertip-7",
                         quick=args.quick, progress=advance, references=args.references,
                         partial=lambda part: write_json(
                             args.json, {"as_built": part, **_stamp()}))
    report = {"as_built": section, **_stamp()}
    write_json(args.json, report)
    print(bench_text("unseen-as-built", report, args.json))
    return 0


def _references_arg(p) -> None:
    p.add_argument("--references", type=_names, metavar="M,M,...",
                   help="with --as-built: the reference materials each drawn pad is "
                        "calibrated from, two or more of the scene's objects (default: "
                        "steel, plexiglass and wood, those of them the scene has, else "
                        "its first three)")


def _names(text: str) -> tuple[str, ...]:
    """A comma-separated list of names, none empty."""
    import argparse
    names = tuple(n.strip() for n in text.split(","))
    if not all(names):
        raise argparse.ArgumentTypeError(f"an empty name in {text!r}")
    return names


def _as_built_sd(text: str) -> float:
    """``--as-built``'s sd: a number in the scene table's range."""
    import argparse
    import math

    from telethermal.physics.as_built import SD_RANGE
    try:
        value = float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from exc
    if not (math.isfinite(value) and SD_RANGE[0] <= value <= SD_RANGE[1]):
        raise argparse.ArgumentTypeError(f"{text!r} must be an sd in {list(SD_RANGE)} "
                                         "(a factor's log-normal spread)")
    return value


def _add_speed(bsub) -> None:
    """physics, transport, report, record, devices."""
    p = bsub.add_parser("physics", help="contact models: error against runtime")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--png", help="plot (default: beside the JSON)")
    p.add_argument("--repeats", type=_positive(int), default=3,
                   help="how many times each model is timed (the fastest counts; default 3)")
    p.set_defaults(func=cmd_bench_physics)

    p = bsub.add_parser("transport", help="codec cost; one-way latency beside raw pyzmq on "
                                          "loopback and across network namespaces")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--quick", action="store_true",
                   help="a quarter of the messages per stack (a smoke run)")
    p.set_defaults(func=cmd_bench_transport)

    p = bsub.add_parser("report", help="every benchmark's JSON in one Markdown report with "
                                       "its figures")
    p.add_argument("--results", required=True, help="folder of the benches' JSON files")
    p.add_argument("--out", required=True, help="report.md (its PNGs are written beside it)")
    p.set_defaults(func=cmd_bench_report)

    p = bsub.add_parser("record", help="what recording costs the master's loop")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--rounds", type=int, default=3,
                   help="rounds of touches without and with recording (default 3)")
    p.add_argument("--contact-s", type=_positive(), default=3.0,
                   help="each touch's contact time, seconds (default 3)")
    _models_arg(p)
    p.set_defaults(func=cmd_bench_record)

    p = bsub.add_parser("devices", help="both sides' latencies through the emulated serial "
                                        "and CAN paths beside the direct simulator, and the "
                                        "slave's identification through its drivers")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--samples", type=int, default=3000,
                   help="readings timed on each serial and CAN path (default 3000)")
    p.add_argument("--contact-s", type=_positive(), default=3.0,
                   help="each touch's contact time, seconds (default 3)")
    p.add_argument("--slave-trials", type=int, default=10,
                   help="touches per material on the slave's side (simulated and through the "
                        "emulated drivers, the same trials)")
    _models_arg(p)
    p.set_defaults(func=cmd_bench_devices)


def _add_faults(bsub) -> None:
    p = bsub.add_parser("faults", help="rendering under network faults, compensated beside "
                                       "naive (processes and the fault proxy)")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--png", help="the Jepsen-style plot (default: next to the JSON)")
    p.add_argument("--quick", action="store_true",
                   help="the zero-delay and 200 ms rows on a third of the materials, 2 "
                        "seeds; processes on one material")
    p.add_argument("--only", help="comma-separated parts of setting names to run "
                                  "(e.g. 'crash,partition'); 'delay 0 ms' is always run")
    p.add_argument("--seeds", type=int, help="seeds per material on the simulated clock "
                                             "(default 5; 2 with --quick)")
    _executor_args(p, "the simulated rows")
    p.add_argument("--scene", default="fingertip-7",
                   help="a shipped scene or a scene file (a lab's own): its materials, seeds "
                        "and processes")
    p.add_argument("--delays", help="comma-separated one-way delays in ms (e.g. 0,30,80,150): "
                                    "the pure-delay rows of both parts (0 is always run; "
                                    "default: the committed rows)")
    p.add_argument("--no-processes", action="store_true",
                   help="the simulated part only (no services, no fault proxy)")
    _models_arg(p)
    p.set_defaults(func=cmd_bench_faults)


def _executor_args(p, what: str) -> None:
    p.add_argument("--executor", metavar="KIND",
                   help=f"where {what} run: process (worker processes, the default), serial "
                        "(this process), dask:ADDRESS (a Dask cluster's scheduler; needs "
                        "--work-dir) or dask-local (pip install 'telethermal[dask]'); the same "
                        "JSON from each")
    p.add_argument("--jobs", type=_positive(int), default=None,
                   help="workers of --executor process or dask-local (default: one a CPU "
                        "this process may use)")
    p.add_argument("--work-dir", metavar="DIR",
                   help="where the bench writes the model files its jobs read: a folder the "
                        "workers see at the same path (default: the temporary folder)")


def _models_arg(p) -> None:
    p.add_argument("--models", metavar="DIR", type=_models_folder,
                   help="the identifier and generator `telethermal models --out DIR` wrote "
                        "for the bench's scene, checked against its SHA256SUMS (default: "
                        "trained here on the scene's databases, seed 0: the same files)")


def _no_references(args) -> None:
    """--references calibrates the drawn pads of --as-built alone."""
    if args.references is not None:
        from telethermal.errors import BenchError
        raise BenchError("--references is for --as-built (the reference materials its drawn "
                         "pads are calibrated from)")


def _no_executor(args) -> None:
    """--as-built runs its pads in this process and trains on each: its
    executor options and --models refused."""
    from telethermal.errors import BenchError
    if args.executor is not None or args.jobs or args.work_dir:
        raise BenchError("--executor, --jobs and --work-dir are not for --as-built (its pads "
                         "run one after another in this process)")
    if getattr(args, "models", None):
        raise BenchError("--models is not for --as-built (it trains on each drawn pad)")


def _executor(args):
    """The executor a bench's options name (BenchError for one it cannot open)."""
    from telethermal.bench.executor import open_executor

    return open_executor(args.executor, args.jobs, args.work_dir)


def _scene_arg(p) -> None:
    p.add_argument("--scene", default="fingertip-7",
                   help="a shipped scene or a scene file (a lab's own; default fingertip-7)")


def _add_render(bsub) -> None:
    p = bsub.add_parser("render", help="rendering error against loop rate, gains, strategy; "
                                       "the loop on the real clock")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--png", help="plot (default: beside the JSON)")
    p.add_argument("--quick", action="store_true",
                   help="a few materials, rates and gains, one seed (a smoke run)")
    p.add_argument("--as-built", type=_as_built_sd, metavar="SD",
                   help="instead: every material's first touch on pads built off their "
                        "datasheet (factors drawn log-normal with this sd): as modelled, "
                        "uncalibrated, both pads calibrated, and the display modelled "
                        "exactly as drawn (an oracle); with --quick, a third of the materials")
    p.add_argument("--pads", type=_positive(int), default=5,
                   help="with --as-built: how many pads are drawn (default 5)")
    _references_arg(p)
    _scene_arg(p)
    _executor_args(p, "the sessions")
    _models_arg(p)
    p.set_defaults(func=cmd_bench_render)


def _add_error(bsub) -> None:
    """render (:func:`_add_render`), skin-floor, identify, view."""
    _add_render(bsub)

    p = bsub.add_parser("skin-floor", help="the best any current trajectory within the "
                                           "Peltier module's limits can do on the skin, per "
                                           "material and idle; a Qmax and flux-film sweep")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--png", help="plot (default: beside the JSON)")
    p.add_argument("--quick", action="store_true",
                   help="a coarser idle search and a 2 x 2 sweep")
    _scene_arg(p)
    p.set_defaults(func=cmd_bench_skin_floor)

    p = bsub.add_parser("identify", help="the papers' identification tables, ours beside")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--png", help="plot (default: beside the JSON)")
    p.add_argument("--seed", type=_seed, default=0,
                   help="the first session's seed: sessions SEED .. SEED+SESSIONS-1 (default 0)")
    p.add_argument("--methods", help="comma-separated (default: those whose calibration error "
                                     "is within 0.05: effusivity-fit, effusivity-lda, "
                                     "pca-fnn)")
    p.add_argument("--scene", help="a scene (name or path, a lab's own): each method's grouped "
                                   "5-fold cross-validation on its simulated pad database "
                                   "instead of the papers' tables")
    p.add_argument("--sessions", type=_positive(int), default=3,
                   help="Table 1 on this many independent sessions (seeds SEED, SEED+1, ...): "
                        "pooled figures with 95 %% intervals and the live decisions' rates")
    p.add_argument("--no-limit", action="store_true",
                   help="skip the physical limit (the oracle on every session's touches, "
                        "a few minutes)")
    p.add_argument("--as-built", type=_as_built_sd, metavar="SD",
                   help="instead: the default identifier on pads built off their datasheet "
                        "(every factor drawn log-normal with this sd), as modelled, "
                        "uncalibrated and calibrated (telethermal calibrate pad)")
    p.add_argument("--pads", type=_positive(int), default=5,
                   help="with --as-built: how many pads are drawn (default 5)")
    _references_arg(p)
    _executor_args(p, "the methods and sections")
    p.set_defaults(func=cmd_bench_identify)

    p = bsub.add_parser("unseen", help="materials the identifiers never saw: the live "
                                       "effusivity estimate's error and interval coverage")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--seeds", type=_positive(int),
                   help="sessions (seeds 0 .. N-1; default 3, 1 with --quick)")
    p.add_argument("--quick", action="store_true", help="3 touches per material")
    p.add_argument("--unseen", help="comma-separated package materials to touch (default "
                                    "copper,carbon_steel,glass,foam and the shipped "
                                    "unseen-objects scene's brass, concrete and a glass "
                                    "slide on aluminium)")
    p.add_argument("--unseen-scene", help="a scene file whose objects (with its own materials "
                                          "table; layered ones too) are touched as unseen "
                                          "materials")
    p.add_argument("--as-built", type=_as_built_sd, metavar="SD",
                   help="instead: the unseen materials' effusivity on pads built off their "
                        "datasheet (every factor drawn log-normal with this sd), as "
                        "modelled, uncalibrated and calibrated (telethermal calibrate pad); "
                        "--seeds sessions per pad (default 1)")
    p.add_argument("--pads", type=_positive(int), default=5,
                   help="with --as-built: how many pads are drawn (default 5)")
    _references_arg(p)
    _scene_arg(p)
    _executor_args(p, "the rendered touches")
    p.set_defaults(func=cmd_bench_unseen)

    p = bsub.add_parser("view", help="the view's first paint, its lag behind a session, and the "
                                     "master's loop timing with and without the page")
    p.add_argument("--json", required=True, help="JSON report to write")
    p.add_argument("--touches", type=int, default=3, help="touches per mode (default 3)")
    p.add_argument("--contact-s", type=_positive(), default=3.0,
                   help="each touch's contact time, seconds (default 3)")
    p.add_argument("--realtime-priority", type=int, default=20,
                   help="the master loop's SCHED_FIFO priority, as in the demo (0: normal "
                        "scheduling, where the browser competes with the loop for the CPU)")
    _models_arg(p)
    p.set_defaults(func=cmd_bench_view)


def add_parser(sub) -> None:
    bench = sub.add_parser("bench", help="benchmarks: speed against error")
    bsub = bench.add_subparsers(dest="bench_command", required=True)
    _add_speed(bsub)
    _add_faults(bsub)
    _add_error(bsub)
    for name, p in bsub.choices.items():
        if name != "report":
            p.set_defaults(func=_timed(name, p.get_default("func")))


def _timed(name: str, func):
    """A bench's command, and on stderr how long it took (what ``make
    bench`` logs per bench)."""
    def run(args) -> int:
        import time
        t0 = time.monotonic()
        code = func(args)
        print(f"bench {name}: {time.monotonic() - t0:.0f} s", file=sys.stderr)
        return code
    return run
