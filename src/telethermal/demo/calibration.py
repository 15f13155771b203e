"""The demo's lab calibration of pads built off their datasheet (issue 44):
on a scene with ``[as_built]`` tables, ``telethermal demo`` calibrates both
pads before it trains anything, as a lab would, and says what it found.

- the sensing pad from reference touches of that pad (the simulator's, as
  built) on the reference materials (``ident.calibration.reference_materials``),
  :data:`REFERENCE_TOUCHES` each, in
  a session of its own (another seed than the databases' and the touches'):
  ``telethermal calibrate pad``'s fit (``ident.pad_calibration``), as
  ``bench identify --as-built`` does;
- the display with ``telethermal calibrate display``'s routine on the
  simulated bench (``sim.display_rig.calibrate_simulated``).

One file, ``calibration.toml`` in the demo's folder, holds both (the pad's
at the top level, the display's ``[display]`` table: each command's writer).
The slave's identifier is trained with the pad's (its config key
``pad_calibration``), the master given the display's (its own key
``pad_calibration``). The reference touches are simulated: this module,
like the demo's databases, sits above the simulator (``data.generate``),
never below it in a product layer.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from telethermal.ident.calibration import (REFERENCE_TOUCHES, reference_materials,
                                           reference_scene)

#: The reference session's seed beside the demo's: its own draws.
REFERENCE_STREAM = 44
#: The file written in the demo's folder.
CALIBRATION_FILE = "calibration.toml"


@dataclass(frozen=True)
class DemoCalibration:
    """The calibration file and both pads' calibrations as read back from it."""

    path: Path
    pad: object            # ident.pad_calibration.PadCalibration (None: the file has none)
    display: object        # teleop.display_calibration.DisplayCalibration (None: idem)

    def summary(self) -> dict:
        """For ``demo.json``: the file and both calibrations' figures (None
        for a pad the file does not calibrate)."""
        display = None if self.display is None else {
            f.name: getattr(self.display, f.name)
            for f in dataclasses.fields(self.display) if f.name != "source"}
        return {"file": str(self.path), "pad": self.pad and self.pad.to_dict(),
                "display": display}

    @property
    def pad_path(self) -> str:
        """The file, for the slave's key ``pad_calibration`` ("": no pad's)."""
        return str(self.path) if self.pad is not None else ""

    @property
    def display_path(self) -> str:
        """The file, for the master's key ``pad_calibration`` ("": no display's)."""
        return str(self.path) if self.display is not None else ""


def given_calibration(path: str | Path, scene) -> DemoCalibration:
    """``demo --calibration FILE``: the sensing pad's calibration (the
    file's top level, ``telethermal calibrate pad``) for the slave and its
    ``[display]`` table (``calibrate display``) for the master, whichever the
    file holds, each checked against ``scene``; refused, naming the file,
    when it holds neither."""
    from telethermal.errors import CalibrationError
    from telethermal.ident.pad_calibration import pad_calibration
    from telethermal.teleop.display_calibration import display_calibration
    from telethermal.tomltables import read_toml

    data = read_toml(path, "calibration file", CalibrationError)
    if "format" not in data and "display" not in data:
        raise CalibrationError(
            f"{path}: neither a sensing pad's calibration (telethermal calibrate pad) nor a "
            f"[display] table (telethermal calibrate display); its keys: "
            f"{', '.join(sorted(data))[:200] or 'none'}")
    return DemoCalibration(Path(path), pad_calibration(str(path), scene) if "format" in data
                           else None,
                           display_calibration(str(path), scene) if "display" in data else None)


def path_line(key: str, path: str | Path) -> str:
    """A service config's line ``key = "PATH"`` (absolute), "" without a path."""
    from telethermal.tomltables import toml_str
    return f"{key} = {toml_str(str(Path(path).resolve()))}\n" if path else ""


def reference_touches(scene, seed: int) -> list:
    """:data:`REFERENCE_TOUCHES` simulated touches of ``scene``'s sensing pad
    as built on each reference material: a lab's session on its blocks."""
    from telethermal.data.generate import pad_database

    ref = reference_scene(scene, reference_materials(scene))
    return list(pad_database(ref, np.random.default_rng([seed, REFERENCE_STREAM])))


def calibrate_as_built(scene, out: Path, seed: int = 0, echo=print,
                       status=None) -> DemoCalibration | None:
    """Both pads of a scene with ``[as_built]`` calibrated, written to
    ``out/calibration.toml`` and each calibration's lines echoed; None
    (nothing done, nothing said) for a scene without. ``status(text)``: a
    context manager held around each fit."""
    if scene.as_built is None:
        return None
    from contextlib import nullcontext

    from telethermal.ident.pad_calibration import calibrate_pad, pad_calibration
    from telethermal.jsonfile import write_text
    from telethermal.teleop.display_calibration import (display_calibration,
                                                        keep_other_tables,
                                                        write_display_calibration)
    from telethermal.sim.display_rig import calibrate_simulated

    status = status or nullcontext
    path = Path(out) / CALIBRATION_FILE
    echo(f"{scene.name}'s pads are built off their datasheet ([as_built]): calibrating both "
         "first, as a lab would")
    with status(f"touching {', '.join(reference_materials(scene))} {REFERENCE_TOUCHES} times "
                "each with the sensing pad and fitting its model"):
        pad = calibrate_pad(scene, reference_touches(scene, seed))
    write_text(path, pad.to_toml() + keep_other_tables(path, "pad"))
    with status("running the display's routine on the simulated bench and fitting its sensors"):
        display = calibrate_simulated(scene, seed=seed)
    write_display_calibration(display, path)
    # Read back as the services will, and checked against the scene.
    cal = DemoCalibration(path, pad_calibration(str(path), scene),
                          display_calibration(str(path), scene))
    for line in cal.pad.describe() + cal.display.describe():
        echo(line)
    echo(f"calibration: {path} (the slave's identifier is trained with its pad's, the master "
         "given its display's)")
    return cal


def demo_calibration(scene, out: Path, seed: int = 0, echo=print, status=None,
                     given: str | Path = "") -> DemoCalibration | None:
    """The demo's calibrations: the file ``given`` (:func:`given_calibration`,
    nothing calibrated), else, on a scene with ``[as_built]``, both pads
    calibrated first (:func:`calibrate_as_built`); None without either."""
    if given:
        cal = given_calibration(given, scene)
        echo(f"calibration: {given} (the slave's identifier "
             + ("trained with its pad's" if cal.pad is not None else "without a pad's") +
             ", the master " + ("given its display's" if cal.display is not None else
                                "without a display's") + ")")
        return cal
    return calibrate_as_built(scene, out, seed, echo, status)
