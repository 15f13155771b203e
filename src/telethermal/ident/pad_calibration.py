"""A pad calibration: made from reference touches (:func:`calibrate_pad`,
the fit of :mod:`telethermal.ident.calibration`), written as a TOML file
(``CAL.toml``), read back, checked against the scene it is applied to, and
applied: the product's pad model with the calibrated factors, the contact
conductance the touches had, and the flux sensor's gain as the amplitude
prior of the effusivity estimator."""

from __future__ import annotations

import hashlib
import logging
import math
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from telethermal.errors import CalibrationError
from telethermal.physics.figures import DESCRIPTIVE_FIELDS, physical
from telethermal.tomltables import toml_str
from telethermal.ident.calibration import (CHI2_MAX, DESIGN_SD, SD_MAX, WINDOW_S, PadModelFit,
                                           ReferenceTouches, candidates, consider_sds,
                                           describe, marginal_sds,
                                           projected_columns, scaled_scene, select)
from telethermal.ident.openset import Z95

log = logging.getLogger(__name__)

#: A material's mean amplitude this many standard errors from the others'
#: is refused (normal tails: 6e-5 of materials with a right table value).
Z_MAX = 4.0

#: Version 2 added ``prior_fitted``; a version-1 file (its parts the
#: touches cannot tell held at their design) is still read.
FORMAT, FORMAT_VERSION = "telethermal-pad-calibration", 2
READABLE_VERSIONS = (1, 2)


#: What a pad digest leaves out besides the parts' descriptions: a material's
#: role, and the size of the scene's generated database.
NOT_THE_PAD = DESCRIPTIVE_FIELDS | {"role", "contact_duration_s", "trials_per_material"}


def pad_digest(scene) -> str:
    """What a calibration was made for: the figures of the scene's nominal
    pad (its layers' materials, module and heat sink) and sensors, its rate
    and room; not their descriptions nor the database's size."""
    from telethermal.physics import thermoelectric as te

    pad = scene.pad
    text = repr(physical((pad, te.get_module(pad.module), te.get_heat_sink(pad.heat_sink),
                          scene.sensors, scene.sample_rate_hz, scene.room_temp_c), NOT_THE_PAD))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class CalibratedParameter:
    """One fitted parameter: the candidates it scales together, its factor on
    the design value and the 95 % interval of the factor."""

    names: tuple[str, ...]
    label: str
    factor: float
    lo: float
    hi: float


@dataclass(frozen=True)
class PadCalibration:
    """The calibration of a scene's sensing pad (see the module)."""

    scene: str
    pad_digest: str
    parameters: tuple[CalibratedParameter, ...]
    not_identifiable: tuple[str, ...]
    contact_conductance_w_m2k: float
    flux_gain: float
    flux_gain_sd: float
    chi2_per_dof: float
    touches: int
    materials: tuple[str, ...]
    source: str = ""
    #: The log sd of what the touches cannot tell: the prior of the parts
    #: it could not identify (``prior_fitted``) and the spread of a lumped
    #: parameter's members apart (``ident.calibration.consider_sds``); 0:
    #: those parts held at their design, statistical intervals alone, as
    #: for one made without it. :func:`calibrate_touches` sets it.
    design_sd: float = 0.0
    #: The parts named in ``not_identifiable``, fitted under their design
    #: prior (``ident.calibration``): each its factor and 95 % interval,
    #: the prior's ``design_sd`` in it. Empty: held at their design values
    #: (``design_sd = 0``, or a version-1 file). The flux gain is never
    #: among them (held, if the touches ever could not tell it).
    prior_fitted: tuple[CalibratedParameter, ...] = ()

    def factors(self) -> dict:
        """Candidate name -> factor on its design value (the gain apart)."""
        return {n: p.factor for p in self.parameters + self.prior_fitted for n in p.names
                if n != "flux_gain"}

    def check(self, scene) -> None:
        """Refuse a calibration made for another scene (or another pad), or
        one naming a parameter of the pad twice."""
        where = self.source or "the calibration"
        if scene.name != self.scene:
            raise CalibrationError(f"{where} calibrates scene {self.scene!r}'s pad; this runs "
                                   f"scene {scene.name!r}: calibrate its own pad "
                                   f"(telethermal calibrate pad --scene {scene.name})")
        if pad_digest(scene) != self.pad_digest:
            raise CalibrationError(f"{where} was made for another pad or sensors of scene "
                                   f"{scene.name!r} (the scene file changed since): calibrate "
                                   "again")
        known, seen = candidates(scene), set()
        for key, rows in (("parameters", self.parameters), ("prior_fitted", self.prior_fitted)):
            for i, p in enumerate(rows):
                for name in p.names:
                    if name in seen:
                        raise CalibrationError(f"{where}: {key}[{i}].names: {name!r} is "
                                               "fitted twice in the file")
                    seen.add(name)
                    if name not in known:
                        raise CalibrationError(f"{where}: {key}[{i}].names: {name!r} is not a "
                                               f"parameter of scene {scene.name!r}'s pad; "
                                               f"its parameters: {', '.join(known)}")

    def apply(self, scene):
        """The product's model of ``scene``'s pad as calibrated."""
        self.check(scene)
        return scaled_scene(scene, self.factors(), self.contact_conductance_w_m2k)

    def describe(self) -> list[str]:
        lines = [f"pad calibration of {self.scene}: {self.touches} touches of "
                 f"{', '.join(self.materials)}; residual chi2/dof {self.chi2_per_dof:.2f} "
                 f"(the sensor's noise and the curves' error allow {CHI2_MAX:g})"]
        for p in self.parameters:
            lumped = " (lumped: " + ", ".join(p.names) + ")" if len(p.names) > 1 else ""
            loose = "; known no better than its design allows" \
                if interval_sd(p.lo, p.hi) > SD_MAX else ""
            lines.append(f"  {p.label}: x{p.factor:.3f} [{p.lo:.3f}, {p.hi:.3f}] 95 %"
                         f"{lumped}{loose}")
        lines.append(f"  contact conductance: {self.contact_conductance_w_m2k:.0f} W/m^2K "
                     "(the touches' geometric mean)")
        if self.prior_fitted:
            lines.append(f"  not identifiable from these touches alone (fitted within their "
                         f"design's spread, log sd {self.design_sd:g}):")
            lines += [f"    {p.label}: x{p.factor:.3f} [{p.lo:.3f}, {p.hi:.3f}] 95 %"
                      for p in self.prior_fitted]
        held = [m for m in self.not_identifiable
                if m not in {p.label for p in self.prior_fitted}]
        if held:
            lines.append("  not identifiable from these touches (design value kept): "
                         + ", ".join(held))
        if self.design_sd > 0 and held:
            lines.append(f"  the intervals carry what the touches cannot tell (each part "
                         f"held at its design off it by a log sd of {self.design_sd:g})")
        elif self.design_sd > 0 and any(len(p.names) > 1 for p in self.parameters):
            lines.append(f"  the lumped parameters' intervals carry their members apart "
                         f"(each off its design by a log sd of {self.design_sd:g})")
        return lines

    # ------------------------------------------------------------ the file
    def to_toml(self) -> str:
        out = [f'format = "{FORMAT}"', f"format_version = {FORMAT_VERSION}",
               f"scene = {toml_str(self.scene)}", f"pad_digest = {toml_str(self.pad_digest)}",
               f"contact_conductance_w_m2k = {self.contact_conductance_w_m2k!r}",
               f"flux_gain = {self.flux_gain!r}", f"flux_gain_sd = {self.flux_gain_sd!r}",
               f"chi2_per_dof = {self.chi2_per_dof!r}", f"touches = {self.touches}",
               "materials = [" + ", ".join(map(toml_str, self.materials)) + "]",
               "not_identifiable = [" + ", ".join(map(toml_str, self.not_identifiable))
               + "]", f"design_sd = {self.design_sd!r}"]
        for key, rows in (("parameters", self.parameters), ("prior_fitted", self.prior_fitted)):
            for p in rows:
                out += ["", f"[[{key}]]", "names = [" + ", ".join(map(toml_str, p.names))
                        + "]", f"label = {toml_str(p.label)}", f"factor = {p.factor!r}",
                        f"lo = {p.lo!r}", f"hi = {p.hi!r}"]
        return "\n".join(out) + "\n"

    @classmethod
    def from_dict(cls, data: dict, source: str = "") -> "PadCalibration":
        """The calibration a ``CAL.toml``'s table holds; every field checked
        (its type; a number finite and > 0, a standard deviation >= 0; the
        names lists of strings), a bad one refused naming it."""
        version = data.get("format_version")
        if data.get("format") != FORMAT or type(version) is not int \
                or version not in READABLE_VERSIONS:
            raise CalibrationError(f"{source}: not a {FORMAT} file of version "
                                   f"{' or '.join(map(str, READABLE_VERSIONS))} (format "
                                   f"{data.get('format')!r}, version {version!r})")
        params = _parameters(data, "parameters", source)
        prior_fitted = _parameters(data, "prior_fitted", source) if version >= 2 else ()
        not_identifiable = _strings(data, "not_identifiable", source)
        design_sd = _number(data, "design_sd", source, positive=False, default=0.0)
        for i, p in enumerate(prior_fitted):
            if "flux_gain" in p.names:
                raise CalibrationError(f"{source}: prior_fitted[{i}]: the flux gain is never "
                                       "fitted under a prior (held when not identifiable)")
            if p.label not in not_identifiable:
                raise CalibrationError(f"{source}: prior_fitted[{i}]: {p.label!r} is not named in "
                                       "not_identifiable (a part fitted under its prior is one "
                                       "the touches could not identify)")
        if prior_fitted and design_sd == 0:
            raise CalibrationError(f"{source}: prior_fitted: parts fitted under a prior with "
                                   "design_sd = 0 (no prior): the file contradicts itself")
        touches = _field(data, "touches", int, source)
        if touches < 1:
            raise CalibrationError(f"{source}: touches: {touches}; must be at least 1")
        return cls(_field(data, "scene", str, source), _field(data, "pad_digest", str, source),
                   tuple(params), not_identifiable,
                   _number(data, "contact_conductance_w_m2k", source),
                   _number(data, "flux_gain", source),
                   _number(data, "flux_gain_sd", source, positive=False),
                   _number(data, "chi2_per_dof", source, positive=False),
                   touches, _strings(data, "materials", source), source,
                   # A file written before the key: statistical intervals alone.
                   design_sd, prior_fitted)

    def to_dict(self) -> dict:
        return tomllib.loads(self.to_toml())


def _parameters(data: dict, key: str, source: str) -> tuple[CalibratedParameter, ...]:
    """The ``[[key]]`` tables of a calibration file, each checked (none: a
    calibration that fitted none of that kind, which writes no table)."""
    params = []
    for i, p in enumerate(_field(data, key, list, source, [])):
        if not isinstance(p, dict):
            raise CalibrationError(f"{source}: {key}[{i}]: expected a table, got {p!r}")
        where = f"{key}[{i}]"
        names = _strings(p, "names", source, where)
        if not names:
            raise CalibrationError(f"{source}: {where}.names: empty; at least one parameter")
        factor, lo, hi = (_number(p, k, source, where) for k in ("factor", "lo", "hi"))
        if not lo <= factor <= hi:
            raise CalibrationError(f"{source}: {where}: factor {factor!r} outside its "
                                   f"interval [{lo!r}, {hi!r}]")
        params.append(CalibratedParameter(names, _field(p, "label", str, source,
                                                        where=where), factor, lo, hi))
    return tuple(params)


def read_calibration(path: str | Path) -> PadCalibration:
    """A ``CAL.toml`` written by ``telethermal calibrate pad``."""
    from telethermal.tomltables import read_toml
    try:
        data = read_toml(path, "pad calibration", CalibrationError)
    except OSError as exc:
        raise CalibrationError(f"{path}: cannot read a pad calibration: {exc}") from exc
    return PadCalibration.from_dict(data, str(path))


_MISSING = object()


def _field(table: dict, key: str, kind, source: str, default=_MISSING, where: str = ""):
    """``table[key]`` of type ``kind`` (a bool is no int), else
    CalibrationError naming the file and the field."""
    name = f"{where}.{key}" if where else key
    value = table.get(key, default)
    if value is _MISSING:
        raise CalibrationError(f"{source}: {name}: missing")
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise CalibrationError(f"{source}: {name}: expected {getattr(kind, '__name__', kind)},"
                               f" got {value!r}"[:300])
    return value


def _number(table: dict, key: str, source: str, where: str = "",
            positive: bool = True, default=_MISSING) -> float:
    """A finite number > 0 (``positive``), else >= 0."""
    name = f"{where}.{key}" if where else key
    value = _field(table, key, (int, float), source, default, where=where)
    if isinstance(value, bool) or not math.isfinite(value) or value < 0 or \
            (positive and value == 0):
        raise CalibrationError(f"{source}: {name}: {value!r}; must be a finite number "
                               f"{'> 0' if positive else '>= 0'}")
    return float(value)


def _strings(table: dict, key: str, source: str, where: str = "") -> tuple[str, ...]:
    """A list of strings (a string alone is refused, not split into letters)."""
    value = _field(table, key, list, source, where=where)
    name = f"{where}.{key}" if where else key
    for v in value:
        if not isinstance(v, str):
            raise CalibrationError(f"{source}: {name}: expected a list of strings, "
                                   f"got {v!r} in it"[:300])
    return tuple(value)


def write_calibration(cal: PadCalibration, path: str | Path) -> Path:
    """Write ``cal`` to ``path`` atomically."""
    from telethermal.jsonfile import write_text
    return write_text(path, cal.to_toml())


def pad_calibration(path: str, scene) -> PadCalibration | None:
    """A service's ``pad_calibration`` (a CAL.toml path; "": none), checked
    against its scene."""
    if not path:
        return None
    cal = read_calibration(path)
    cal.check(scene)
    return cal


def check_model_calibration(model, cal: PadCalibration | None, where: str) -> None:
    """Refuse an identifier that fits the pad's model with another
    calibration than the service's (a model file records its own)."""
    if not hasattr(model, "calibration"):
        return                                   # a method that fits no pad model
    mine = None if cal is None else cal.to_dict()
    theirs = None if model.calibration is None else model.calibration.to_dict()
    if mine != theirs:
        from telethermal.errors import ModelFileError
        raise ModelFileError(
            f"{where} was trained with {'no' if theirs is None else 'another'} pad calibration"
            f" than the config's pad_calibration ({cal.source if cal else 'none'}): train it "
            "with that calibration (identify train --calibration), or give the one it has")


# ---------------------------------------------------------------- the fit
def interval_sd(lo: float, hi: float) -> float:
    """The sd of ``ln factor`` a 95 % interval ``[lo, hi]`` stands for."""
    return (math.log(hi) - math.log(lo)) / (2 * Z95)


def amplitude_sd(scene) -> float:
    """The per-touch relative spread of the true over the measured gap: the
    thermometers' per-reading noise over the scene's gap (one session of
    the scene's instruments, drawn through the generator's own code; its
    gain and bias are common to the touches and are what the fit finds)."""
    from telethermal.ident.oracle import draw_nuisances
    draws = draw_nuisances(scene, 400, np.random.default_rng(20261129), n_sessions=1)
    return float(np.mean([np.std(a) / np.mean(a) for a in draws["amp"].values()]))


def calibrate_pad(scene, trials, window_s: float = WINDOW_S,
                  design_sd: float = DESIGN_SD) -> PadCalibration:
    """Fit ``scene``'s pad model to reference ``trials`` (see
    :mod:`telethermal.ident.calibration`; ``design_sd``: how far, log sd,
    the parts the touches cannot identify may be off their design);
    refused with the reason when the touches cannot calibrate it."""
    if not (0.0 <= design_sd <= 1.0):
        raise CalibrationError(f"design_sd = {design_sd!r}: a log sd in [0, 1] (0.2: a part "
                               "known to about 20 %)")
    return calibrate_touches(scene, ReferenceTouches.from_trials(trials, window_s), design_sd)


def calibrate_touches(scene, touches: ReferenceTouches,
                      design_sd: float = DESIGN_SD) -> PadCalibration:
    """:func:`calibrate_pad` of touches already read."""
    from telethermal.ident.oracle import flux_noise_w_m2

    start = time.process_time()
    fit = PadModelFit(scene, touches, amplitude_sd(scene), flux_noise_w_m2(scene))
    n = len(touches.labels)
    first = fit.solve([("flux_gain",)], np.zeros(1 + 3 * n), max_nfev=10)
    names = candidates(scene)
    z_all = np.concatenate([[first.x[0]], np.zeros(len(names) - 1), first.x[1:]])
    cols = projected_columns(fit.jacobian(z_all, [(m,) for m in names]), len(names))
    free, fixed = select(cols, names)
    # The parts the touches cannot tell alone: fitted under their design
    # prior (held at the design when there is none).
    prior_groups = [(m,) for m in fixed if m != "flux_gain"] if design_sd > 0 else []
    groups = free + prior_groups
    prior = [None] * len(free) + [design_sd] * len(prior_groups)
    z0 = np.concatenate([[first.x[0] if g == ("flux_gain",) else 0.0 for g in free],
                         np.zeros(len(prior_groups)), first.x[1:]])
    result = fit.solve(groups, z0, max_nfev=25, prior=prior)
    n_data = len(result.fun) - len(prior_groups)                # the priors' rows apart
    data = result.fun[:n_data]
    # Every parameter counted against the data's rows: conservative by the
    # prior-fitted ones (a few, against about 1,500 rows).
    dof = max(n_data - len(result.x), 1)
    chi2 = float(data @ data) / dof
    log.info("pad calibration: %d touches, %d evaluations, %.1f s of CPU, chi2/dof %.3f",
             n, result.nfev, time.process_time() - start, chi2)
    _refuse_misfit(fit, result, touches, chi2, fit.split(result.x, groups)[4])
    # The prior-fitted parts' uncertainty is in the covariance itself (a
    # misfit widens the data's rows, not the priors'); what it cannot hold
    # is a lumped parameter's members apart.
    jac = result.jac.copy()
    jac[:n_data] /= math.sqrt(max(1.0, chi2))
    sds = np.hypot(marginal_sds(jac, len(groups)),
                   consider_sds(fit, result.x, groups, [], design_sd, result.jac))
    fitted = [CalibratedParameter(g, " + ".join(describe(scene, m) for m in g),
                                  math.exp(v), math.exp(v - Z95 * sd), math.exp(v + Z95 * sd))
              for g, v, sd in zip(groups, result.x, sds)]
    params, prior_fitted = tuple(fitted[:len(free)]), tuple(fitted[len(free):])
    gain = next((p for p in params if p.names == ("flux_gain",)), None)
    log_h = fit.split(result.x, groups)[2]
    return PadCalibration(
        scene.name, pad_digest(scene), params, tuple(describe(scene, m) for m in fixed),
        float(scene.pad.contact_conductance_w_m2k * math.exp(float(np.mean(log_h)))),
        gain.factor if gain else 1.0,
        float((math.log(gain.hi) - math.log(gain.lo)) / (2 * Z95)) if gain else 0.0,
        float(chi2), n, tuple(sorted(set(touches.labels))), design_sd=float(design_sd),
        prior_fitted=prior_fitted)


def amplitude_z(touches: ReferenceTouches, log_a: np.ndarray, sd: float) -> dict:
    """Per material, the mean of its touches' fitted ``ln a`` (true over
    measured gap, the gain apart) in standard errors of the thermometers'
    per-touch noise: a material whose table effusivity is off shifts all of
    its touches' amplitudes one way."""
    out = {}
    for label in sorted(set(touches.labels)):
        rows = [i for i, lab in enumerate(touches.labels) if lab == label]
        out[label] = float(np.mean(log_a[rows]) / (sd / math.sqrt(len(rows))))
    return out


def _refuse_misfit(fit: PadModelFit, result, touches: ReferenceTouches, chi2: float,
                   log_a: np.ndarray) -> None:
    """A material whose touches' amplitudes stand out (past :data:`Z_MAX`
    standard errors) named, its table value likely wrong (with two
    materials, which of them cannot be told: both named); a residual past
    :data:`CHI2_MAX`: the model itself cannot fit."""
    z = amplitude_z(touches, log_a, fit.amplitude_sd)
    table = ", ".join(f"{k} {v:+.1f}" for k, v in z.items())
    out = [k for k, v in z.items() if abs(v) > Z_MAX]
    if out:
        worst = max(z, key=lambda k: abs(z[k]))
        named = worst if len(z) > 2 else " or ".join(sorted(z))
        raise CalibrationError(
            f"the touches of {named} do not fit {'its' if len(z) > 2 else 'their'} table "
            f"value{'' if len(z) > 2 else 's'}: each material's mean amplitude against the "
            f"others' in standard errors of the thermometers' noise: {table} (beyond +-{Z_MAX:g}"
            f"{'' if len(z) > 2 else '; two materials cannot say which is off'}): check "
            f"{named}'s entry in the materials table, or leave its touches out")
    if chi2 > CHI2_MAX:
        raise CalibrationError(
            f"the pad model cannot fit these touches: residual chi2/dof {chi2:.2f} against "
            f"{CHI2_MAX:g} from the sensor's noise and the curves' error; the pad differs "
            "from its model by more than its parameters can take (a layer missing or extra?)")
