"""``telethermal calibrate pad``: the sensing pad's model from a lab's
reference touches (docs/calibration.md)."""

from __future__ import annotations

from telethermal.cli._common import _print_lines, console


def cmd_calibrate_pad(args) -> int:
    from telethermal.data.dataset import load_dataset
    from telethermal.ident.pad_calibration import calibrate_pad, write_calibration
    from telethermal.ident.registry import pad_dataset, touches_scene
    from telethermal.physics.scene import load_scene

    scene = load_scene(args.scene)
    data = pad_dataset(args.data)
    touches_scene(data, scene)                  # a dataset of another scene: refused
    with console.status(f"reading {data}"):
        trials = load_dataset(data)
    with console.status(f"fitting {scene.name}'s pad model to the reference touches"):
        cal = calibrate_pad(scene, trials, args.window_s)
    write_calibration(cal, args.out)
    _print_lines(cal.describe() + [f"wrote {args.out}"])
    return 0


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
    q.add_argument("--window-s", type=float, default=1.0,
                   help="seconds of each touch fitted from the onset (default 1)")
    q.set_defaults(func=cmd_calibrate_pad)
