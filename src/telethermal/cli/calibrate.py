"""``telethermal calibrate pad``: the sensing pad's model from a lab's
reference touches; ``telethermal calibrate display``: the display pad's
sensor lags from its bench routine (docs/calibration.md). One calibration
file holds both: each command keeps the other's table."""

from __future__ import annotations

from telethermal.cli._common import _non_negative, _positive, _print_lines, _seed, console
from telethermal.errors import CalibrationError


def cmd_calibrate_pad(args) -> int:
    from telethermal.data.dataset import load_dataset
    from telethermal.ident.pad_calibration import calibrate_pad
    from telethermal.ident.registry import pad_dataset, touches_scene
    from telethermal.physics.scene import load_scene

    from telethermal.teleop.display_calibration import keep_other_tables

    scene = load_scene(args.scene)
    data = pad_dataset(args.data)
    touches_scene(data, scene)                  # a dataset of another scene: refused
    keep_other_tables(args.out, "pad")          # a file it cannot keep: refused before the fit
    with console.status(f"reading {data}"):
        trials = load_dataset(data)
    with console.status(f"fitting {scene.name}'s pad model to the reference touches"):
        cal = calibrate_pad(scene, trials, args.window_s, *(
            () if args.design_sd is None else (args.design_sd,)))
    from telethermal.jsonfile import write_text
    write_text(args.out, cal.to_toml() + keep_other_tables(args.out, "pad"))
    _print_lines(cal.describe() + [f"wrote {args.out}"])
    return 0


def cmd_calibrate_display(args) -> int:
    from telethermal.physics.scene import load_scene
    from telethermal.teleop.display_calibration import (keep_other_tables,
                                                        write_display_calibration)

    scene = load_scene(args.scene)
    keep_other_tables(args.out, "display")      # a file it cannot keep: refused before the routine
    lab = [f"--{k.replace('_', '-')}" for k in ("master_config", "board", "can",
                                                 "board_calibration") if getattr(args, k)]
    if args.devices == "hardware":
        if args.seed is not None:
            raise CalibrationError("--seed draws the simulated bench's noise: a lab's display "
                                   "(--devices hardware) has its own")
        cal = _calibrate_hardware_display(scene, args)
    else:
        from telethermal.sim.display_rig import calibrate_simulated
        if lab:
            raise CalibrationError(f"{', '.join(lab)} name a lab's display: give --devices "
                                   "hardware")
        with console.status(f"running {scene.name}'s display routine (simulated bench, "
                            f"devices {args.devices}) and fitting its sensors"):
            cal = calibrate_simulated(scene, args.block, args.seed or 0, args.devices)
    write_display_calibration(cal, args.out)
    _print_lines(cal.describe() + [f"wrote {args.out} ([display])"])
    return 0


def _calibrate_hardware_display(scene, args):
    """The routine on the lab's display: the board, driver and board
    calibration its master's config names (or given one by one), the lab
    asked at the terminal to press and to lift the block."""
    from telethermal.devices.board import Calibration
    from telethermal.teleop.display_hardware import calibrate_hardware

    board, can, board_cal_file = args.board, args.can, args.board_calibration
    if args.master_config:
        if board or can or board_cal_file:
            raise CalibrationError("--master-config names the board, the bus and the board's "
                                   "calibration: give it alone, or --board and --can")
        from telethermal.services.config import load_config
        master = load_config(args.master_config, "master")
        board, can, board_cal_file = master.board_url, master.can_bus, master.calibration
    if not (board and can):
        raise CalibrationError("--devices hardware needs the master's config (--master-config "
                               "FILE: its board_url, can_bus and calibration) or --board URL "
                               "(the sensor board) and --can BUS (the Peltier driver)")
    board_cal = Calibration.load(board_cal_file) if board_cal_file else Calibration()

    def ask(text: str) -> None:
        try:
            console.input(f"[bold]{text}[/bold] ")
        except EOFError:
            raise CalibrationError("the routine asks at the terminal (press the block, then "
                                   "lift it) and its input was closed: run it at a "
                                   "terminal") from None
        console.print("running the current steps (6 s); keep the setup still")

    return calibrate_hardware(scene, board, can, block=args.block,
                              board_calibration=board_cal, prompt=ask)


def add_parser(sub) -> None:
    p = sub.add_parser("calibrate", help="calibrate a pad's model from reference touches")
    csub = p.add_subparsers(dest="calibrate_command", required=True)
    q = csub.add_parser("pad", help="fit the sensing pad's model (layers, flux sensor lag and "
                                    "gain) to touches on materials of known effusivity")
    q.add_argument("--scene", required=True, help="the pad's scene: a shipped name or a file")
    q.add_argument("--data", required=True,
                   help="a dataset of reference touches: at least 3 touches of each of at "
                        "least 2 materials of the scene's table (5 of each of 3 recommended)")
    q.add_argument("--out", required=True, help="the calibration file to write (TOML)")
    q.add_argument("--window-s", type=_positive(at_most=60.0, why="a touch's first minute"),
                   default=1.0,
                   help="seconds of each touch fitted from the onset (default 1)")
    q.add_argument("--design-sd", type=_non_negative, default=None,
                   help="how far (log sd) the parts the touches cannot identify alone may "
                        "be off their design: their prior, under which they are fitted, "
                        "carried into the intervals (default 0.2: a part known to about "
                        "20 %%; 0: held at their design, statistical intervals alone)")
    q.set_defaults(func=cmd_calibrate_pad)
    d = csub.add_parser("display", help="fit the display pad's flux sensor lag (and gain) and "
                                        "junction sensor lag from current steps with a "
                                        "reference block on its face, then in air")
    d.add_argument("--scene", required=True, help="the display's scene: a shipped name or a file")
    d.add_argument("--out", required=True,
                   help="the calibration file to write its [display] table to (TOML; a "
                        "sensing pad's calibration already in it is kept)")
    d.add_argument("--block", default="plexiglass",
                   help="the reference block's material, of the materials table (default "
                        "plexiglass: a low effusivity, see docs/calibration.md)")
    d.add_argument("--seed", type=_seed, default=None,
                   help="the simulated bench's draws (default 0)")
    d.add_argument("--devices", default="sim", choices=("sim", "emulated", "hardware"),
                   help="the display's devices: the simulator, or it behind the emulated "
                        "board and driver read through the master's drivers, or a lab's "
                        "display (--master-config, or --board and --can; the routine asks "
                        "at the terminal to press the block, then to lift it)")
    d.add_argument("--master-config", default="",
                   help="with --devices hardware: the master's config file, whose board_url, "
                        "can_bus and calibration (the board's) the routine uses, as the master "
                        "will (the flux gain it fits is on top of that board calibration)")
    d.add_argument("--board", default="",
                   help="with --devices hardware: the sensor board's URL (a serial port or "
                        "pyserial URL, as the master's board_url)")
    d.add_argument("--can", default="",
                   help="with --devices hardware: the Peltier driver's bus "
                        "(INTERFACE:CHANNEL, as the master's can_bus)")
    d.add_argument("--board-calibration", default="",
                   help="with --devices hardware and --board: the board's ADC calibration "
                        "file (the master's calibration key; the fitted gain is on top of it)")
    d.set_defaults(func=cmd_calibrate_display)
