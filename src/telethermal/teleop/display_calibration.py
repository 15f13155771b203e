"""The display pad's calibration (``telethermal calibrate display``;
docs/calibration.md): the routine of :mod:`telethermal.control.display_calibration`
run through a display's devices, its result as the ``[display]`` table of a
calibration file (``CAL.toml``: beside the sensing pad's, one file for both
pads), read back, checked against the scene it is applied to, and what the
master's controllers take from it (:func:`calibrated_lags`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

from telethermal.control import display_calibration as routine
from telethermal.control.display_stack import BOUND as STACK_BOUND   # a layer's fitted range
from telethermal.errors import CalibrationError
from telethermal.tomltables import table_values, toml_str

FORMAT, FORMAT_VERSION = "telethermal-display-calibration", 3
#: Where a routine may have run (``DisplayCalibration.bench``).
BENCHES = ("simulated", "emulated", "hardware")
#: The reference block a lab presses on the pad (docs/calibration.md: a
#: low effusivity keeps the contact's own time far under the sensor's lag).
DEFAULT_BLOCK = "plexiglass"
#: The contact a greased block is first guessed at, W/(m^2 K) (fitted).
CONTACT_GUESS_W_M2K = 1.0e4
#: A flux gain outside this is not the sensor but the block: another
#: material than named, or too thin to be semi-infinite (an aluminium block
#: fitted as PMMA reads x36). Inside it a block's table error passes into
#: the gain unseen (a wood block fitted as PMMA read x0.83): the lags do
#: not depend on it (that wood's flux lag 0.145 s [0.139, 0.152], true 0.15).
GAIN_RANGE = (0.5, 2.0)


@dataclass(frozen=True)
class DisplayCalibration:
    """The display's fitted figures (each with its 95 % interval) and what
    they were fitted on and for."""

    format: str
    format_version: int
    scene: str
    pad_digest: str
    reference_block: str
    flux_lag_s: float
    flux_lag_s_lo: float
    flux_lag_s_hi: float
    junction_lag_s: float
    junction_lag_s_lo: float
    junction_lag_s_hi: float
    flux_gain: float
    flux_gain_lo: float
    flux_gain_hi: float
    #: The pad's layers on the block (control/display_stack.py): the face
    #: layer's thickness factor (lumped: the stack's resistance; the
    #: master's model takes it), the junction-side layer's and the junction
    #: sensor's lag against them (reported, not used).
    face_layer_thickness: float
    face_layer_thickness_lo: float
    face_layer_thickness_hi: float
    back_layer_thickness: float
    back_layer_thickness_lo: float
    back_layer_thickness_hi: float
    stack_junction_lag_s: float
    stack_junction_lag_s_lo: float
    stack_junction_lag_s_hi: float
    chi2_per_dof_air: float
    chi2_per_dof_block: float
    chi2_per_dof_stack: float
    residual_air_k: float
    noise_air_k: float
    residual_block_k: float
    noise_block_k: float
    residual_stack_k: float
    noise_stack_k: float
    #: Where the routine ran: "simulated" or "emulated" (the simulator's
    #: display, directly or behind the emulated devices: a master on
    #: hardware refuses these) or "hardware" (a lab's display:
    #: :mod:`telethermal.teleop.display_hardware`).
    bench: str = "simulated"
    source: str = ""

    def check(self, scene) -> None:
        """Refuse a calibration made for another scene (or pad, or sensors)."""
        from telethermal.ident.pad_calibration import pad_digest
        problem = (f"calibrates scene {self.scene!r}'s display; this runs scene "
                   f"{scene.name!r}: calibrate its own display" if scene.name != self.scene
                   else f"was made for another pad or sensors of scene {scene.name!r} (the "
                   "scene file changed since): calibrate again"
                   if pad_digest(scene) != self.pad_digest else "")
        if problem:
            raise CalibrationError(f"{self.source or 'the display calibration'} {problem} "
                                   f"(telethermal calibrate display --scene {scene.name})")

    def describe(self) -> list[str]:
        return [
            f"display calibration of {self.scene} (face in air, then a {self.reference_block} "
            "block on grease; current steps of +-1 A):",
            f"  on a {self.bench} bench" + ("" if self.bench == "hardware" else
                                             " (the simulator's display, not a lab's)"),
            f"  junction sensor lag against the face thermocouple: {self.junction_lag_s:.4f} s "
            f"[{self.junction_lag_s_lo:.4f}, {self.junction_lag_s_hi:.4f}] 95 %; residual "
            f"{self.residual_air_k:.4f} K rms against {self.noise_air_k:.4f} K of noise (chi2/dof "
            f"{self.chi2_per_dof_air:.2f}); NOT used by the master: {JUNCTION_NOT_USED}",
            f"  flux sensor lag: {self.flux_lag_s:.4f} s [{self.flux_lag_s_lo:.4f}, "
            f"{self.flux_lag_s_hi:.4f}] 95 %",
            f"  flux sensor gain: x{self.flux_gain:.4f} [{self.flux_gain_lo:.4f}, "
            f"{self.flux_gain_hi:.4f}] 95 % (against the block's table effusivity; the "
            "master divides its flux readings by it)",
            f"  on the block: residual {self.residual_block_k:.4f} K rms against "
            f"{self.noise_block_k:.4f} K of noise (chi2/dof {self.chi2_per_dof_block:.2f})",
            f"  pad layers, junction to face on the block: the face layer x"
            f"{self.face_layer_thickness:.4f} [{self.face_layer_thickness_lo:.4f}, "
            f"{self.face_layer_thickness_hi:.4f}] 95 % its design thickness (lumped: the "
            "stack's resistance; the master's model takes it); residual "
            f"{self.residual_stack_k:.4f} K rms against {self.noise_stack_k:.4f} K of noise "
            f"(chi2/dof {self.chi2_per_dof_stack:.2f})",
            f"  beside it, not used (they trade against each other): the junction-side layer x"
            f"{self.back_layer_thickness:.3f} [{self.back_layer_thickness_lo:.3f}, "
            f"{self.back_layer_thickness_hi:.3f}], the junction sensor's lag "
            f"{self.stack_junction_lag_s:.4f} s [{self.stack_junction_lag_s_lo:.4f}, "
            f"{self.stack_junction_lag_s_hi:.4f}]"]

    def to_toml(self) -> str:
        lines = ["[display]"]
        for f in fields(self):
            if f.name == "source":
                continue
            value = getattr(self, f.name)
            lines.append(f"{f.name} = {toml_str(value) if isinstance(value, str) else repr(value)}")
        return "\n".join(lines) + "\n"

    @classmethod
    def from_table(cls, table, source: str) -> "DisplayCalibration":
        where = f"{source}: [display]"
        if not isinstance(table, dict):
            raise CalibrationError(f"{where}: expected a table, got {table!r}"[:300])
        values = table_values(cls, table, where, CalibrationError, exclude=("source",))
        if values.get("format") != FORMAT or values.get("format_version") != FORMAT_VERSION:
            found = (f"version {values.get('format_version')!r}"
                     if values.get("format") == FORMAT else f"format {values.get('format')!r}")
            raise CalibrationError(f"{where}: {found}, not a {FORMAT} table of version "
                                   f"{FORMAT_VERSION} (version 3 added the pad's layers): "
                                   "calibrate the display again")
        missing = [f.name for f in fields(cls) if f.name not in values and f.name != "source"]
        if missing:
            raise CalibrationError(f"{where}: missing {', '.join(missing)}")
        if values["bench"] not in BENCHES:
            raise CalibrationError(f"{where}: bench = {values['bench']!r}: one of "
                                   f"{', '.join(BENCHES)}")
        for name in ("flux_lag_s", "junction_lag_s", "flux_gain", "face_layer_thickness",
                     "back_layer_thickness", "stack_junction_lag_s"):
            lo, x, hi = (values[name + "_lo"], values[name], values[name + "_hi"])
            if not all(math.isfinite(v) and v > 0 for v in (lo, x, hi)) or not lo <= x <= hi:
                raise CalibrationError(f"{where}: {name} = {x!r} with interval [{lo!r}, "
                                       f"{hi!r}]: must be finite, > 0 and inside it")
        for name in ("face_layer_thickness", "back_layer_thickness"):
            if not 1 / STACK_BOUND <= values[name] <= STACK_BOUND:
                raise CalibrationError(f"{where}: {name} = {values[name]!r}: the fit keeps a "
                                       f"layer within {1 / STACK_BOUND:g}-{STACK_BOUND:g} of "
                                       "its design; calibrate the display again")
        if not GAIN_RANGE[0] <= values["flux_gain"] <= GAIN_RANGE[1]:
            raise CalibrationError(f"{where}: flux_gain = {values['flux_gain']!r}: outside "
                                   f"{GAIN_RANGE[0]:g}-{GAIN_RANGE[1]:g}, which the fit refuses")
        for part in ("air", "block", "stack"):
            chi2 = values[f"chi2_per_dof_{part}"]
            if not 0 <= chi2 <= routine.CHI2_MAX:
                raise CalibrationError(f"{where}: chi2_per_dof_{part} = {chi2!r}: the fit "
                                       f"refuses a part past {routine.CHI2_MAX:g} (or not a "
                                       "number); calibrate the display again")
        return cls(**values, source=source)


def read_display_calibration(path: str | Path) -> DisplayCalibration:
    """The ``[display]`` table of a calibration file."""
    from telethermal.tomltables import read_toml
    data = read_toml(path, "calibration file", CalibrationError)
    if "display" not in data:
        raise CalibrationError(f"{path}: no [display] table (a sensing pad's calibration "
                               "only?): calibrate the display into it (telethermal calibrate "
                               f"display --scene SCENE --out {path})")
    return DisplayCalibration.from_table(data["display"], str(path))


def write_display_calibration(cal: DisplayCalibration, path: str | Path) -> Path:
    """Write ``cal`` as ``path``'s ``[display]`` table, atomically; a sensing
    pad's calibration already in the file is kept (its own text, read back
    through its reader), a previous ``[display]`` replaced."""
    from telethermal.jsonfile import write_text
    return write_text(path, keep_other_tables(path, "display") + cal.to_toml())


def keep_other_tables(path: str | Path, replaced: str) -> str:
    """The text of ``path``'s calibrations other than ``replaced`` ("pad" or
    "display"), each read back through its reader, to write beside the new
    one ("" when there is no file). A pad's goes first (its keys are the
    file's top level)."""
    from telethermal.tomltables import read_toml
    if not Path(path).exists():
        return ""
    data = read_toml(path, "calibration file", CalibrationError)
    if set(data) - {"display"} and "format" not in data:
        raise CalibrationError(f"{path}: not a calibration file (its keys: "
                               f"{', '.join(sorted(data))[:200]}): give another --out")
    text = ""
    kept = {"pad": "the sensing pad's", "display": "the display's"}
    try:
        if replaced != "pad" and "format" in data:
            from telethermal.ident.pad_calibration import PadCalibration
            text = PadCalibration.from_dict(data, str(path)).to_toml() + "\n"
        if replaced != "display" and "display" in data:
            text += "\n" + DisplayCalibration.from_table(data["display"], str(path)).to_toml()
    except CalibrationError as exc:
        other = kept["display" if replaced == "pad" else "pad"]
        raise CalibrationError(f"{exc}; {path} also holds {other} calibration, kept beside "
                               f"{kept[replaced]} when it is written, and that one cannot be "
                               "read: give another --out, or calibrate that one again") from exc
    return text


def calibrate_display(scene, display, block: str = DEFAULT_BLOCK,
                      rate_hz: float = routine.RATE_HZ, air_start_s: float | None = None,
                      bench: str = "simulated") -> DisplayCalibration:
    """Run the routine on ``display`` (the devices' ``read``/``apply``; the
    block pressed from session time 0, lifted at ``air_start_s``) and fit
    the display's figures; refused when the model does not fit."""
    on_block = routine.run_part(display, 0.0, rate_hz)
    in_air = routine.run_part(display, routine.steps_duration_s()
                              if air_start_s is None else air_start_s, rate_hz)
    return fit_display(scene, on_block, in_air, block, bench)


def fit_display(scene, on_block: routine.Record, in_air: routine.Record, block: str,
                bench: str) -> DisplayCalibration:
    """The display's figures fitted to the routine's two parts (read on the
    routine's grid); refused when the model does not fit."""
    from telethermal.control.display_stack import fit_stack
    from telethermal.ident.pad_calibration import pad_digest
    from telethermal.physics.materials import get_material

    sens, js = scene.sensors, scene.sensors.junction_sensor_spec()
    tc_noise_k = sens.thermocouple_noise_uv / routine.TYPE_T_UV_PER_K
    air = routine.fit_junction_lag(in_air, js.tau_s, math.hypot(js.noise_k, js.lsb_k / 12 ** 0.5),
                                   tc_noise_k)
    routine.refuse_misfit("in air (junction sensor)", air)
    m = get_material(block)
    effusivity = math.sqrt(m.conductivity_w_mk * m.density_kg_m3 * m.specific_heat_j_kgk)
    flux_noise = sens.flux_noise_w_m2()       # the configured sensor's, not the plant's
    blk = routine.fit_flux(on_block, effusivity, sens.flux_lag_s, CONTACT_GUESS_W_M2K,
                           tc_noise_k, flux_noise)
    routine.refuse_misfit(f"on the {block} block (flux sensor)", blk)
    gain = blk.params["flux_gain"].value
    if not GAIN_RANGE[0] <= gain <= GAIN_RANGE[1]:
        raise CalibrationError(
            f"the flux sensor reads x{gain:.3g} the flux a {block} block of the table's "
            f"effusivity ({effusivity:.0f} W s^0.5/(m^2 K)) takes: no sensor is that far off "
            f"its datasheet (refused outside {GAIN_RANGE[0]:g}-{GAIN_RANGE[1]:g}); is the "
            f"block {block}, and 3 cm thick? (--block names its material)")
    lag = blk.params["flux_lag_s"]
    sd_ln = {name: math.log(blk.params[name].hi / blk.params[name].value) / routine.Z95
             for name in ("flux_lag_s", "flux_gain")}
    stack = fit_stack(on_block, scene.pad.layers, lag.value, gain, js.tau_s,
                      math.hypot(js.noise_k, js.lsb_k / 12 ** 0.5), tc_noise_k, flux_noise,
                      sd_ln["flux_lag_s"], sd_ln["flux_gain"])
    routine.refuse_misfit(f"on the {block} block (the pad's layers)", stack)
    values = {}
    for key, name, fit in (("junction_lag_s", "junction_lag_s", air),
                           ("flux_lag_s", "flux_lag_s", blk), ("flux_gain", "flux_gain", blk),
                           ("face_layer_thickness", "face_layer_thickness", stack),
                           ("back_layer_thickness", "back_layer_thickness", stack),
                           ("stack_junction_lag_s", "junction_lag_s", stack)):
        p = fit.params[name]
        values.update({key: p.value, key + "_lo": p.lo, key + "_hi": p.hi})
    return DisplayCalibration(FORMAT, FORMAT_VERSION, scene.name, pad_digest(scene), block,
                              chi2_per_dof_air=air.chi2_per_dof, chi2_per_dof_block=blk.chi2_per_dof,
                              chi2_per_dof_stack=stack.chi2_per_dof,
                              residual_air_k=air.residual_rms, noise_air_k=air.noise_rms,
                              residual_block_k=blk.residual_rms, noise_block_k=blk.noise_rms,
                              residual_stack_k=stack.residual_rms, noise_stack_k=stack.noise_rms,
                              bench=bench, **{k: float(v) for k, v in values.items()})


def calibrated_layers(scene, cal: DisplayCalibration | None) -> tuple:
    """The display pad's layers as the master models them: the scene's
    (``[pad] layers``), the face layer's thickness times the calibration's
    ``face_layer_thickness`` when given (the caller checks ``cal`` against
    ``scene``: :func:`calibrated_lags`, :func:`display_calibration`)."""
    from telethermal.physics.layered import Layer
    layers = tuple(scene.pad.layers)
    if cal is None:
        return layers
    face = layers[0]
    return (Layer(face.material, face.thickness_m * cal.face_layer_thickness),) + layers[1:]


def modelled_scene(scene, cal: DisplayCalibration | None):
    """``scene`` with the display pad's layers as the master models them
    (:func:`calibrated_layers`): what the idle policy is searched on, so a
    calibrated display idles for its own layers (a policy of its own, cached
    under its own key: control/preconditioning.py)."""
    if cal is None:
        return scene
    from dataclasses import replace
    return replace(scene, pad=replace(scene.pad, layers=calibrated_layers(scene, cal)))


def calibrated_lags(scene, cal: DisplayCalibration | None) -> tuple[float, float]:
    """(flux sensor lag, junction sensor lag) the master's controllers use,
    s: the flux sensor's from the calibration when given (checked against
    ``scene``), else the configuration's; the junction sensor's always the
    configuration's (:data:`JUNCTION_NOT_USED`)."""
    configured = scene.sensors.junction_sensor_spec().tau_s
    if cal is None:
        return scene.sensors.flux_lag_s, configured
    cal.check(scene)
    return cal.flux_lag_s, configured


#: Why the junction sensor's fitted lag is reported, not used (review): the
#: in-air fit takes the face thermocouple for the junction, but on a real
#: pad the face lags the junction by the layers' diffusion (the shipped
#: stack's slowest mode about 0.2 s, as long as the sensor's own lag), and
#: the simulated display lumps its layers with the junction in air, which
#: hid that. A face computed through the layers made the fit read 0.002 s
#: with chi2/dof 102.
JUNCTION_NOT_USED = ("the face lags the junction by the layers' diffusion (about 0.2 s on "
                     "the shipped stack), which the simulated display does not model")


def refuse_on_hardware(cal: DisplayCalibration | None) -> None:
    """A master on a lab's hardware takes no calibration made on a simulated
    or emulated bench: its figures are the simulator's display's."""
    if cal is not None and cal.bench != "hardware":
        raise CalibrationError(
            f"{cal.source or 'the display calibration'} was made on a {cal.bench} bench (the "
            "simulator's display), not on this master's hardware: calibrate this display "
            "(telethermal calibrate display --devices hardware --board URL --can BUS; "
            "docs/calibration.md)")


def display_calibration(path: str, scene) -> DisplayCalibration | None:
    """A service's ``pad_calibration`` (a calibration file's path; "": none):
    its ``[display]`` table, checked against ``scene``."""
    if not path:
        return None
    cal = read_display_calibration(path)
    cal.check(scene)
    return cal
