"""Pads as really built: a scene's ``[as_built]`` tables, read by the
simulator only.

A lab's pad is off its design by its datasheets' tolerances: the film's and
the grease's thickness, the contact conductance, the flux sensor's lag and
gain, the module's Seebeck coefficient, resistance and conductance (10-30 %
each). A scene may say how its pads are really built::

    [as_built.pad]                  # the slave's sensing pad
    layer_thickness = [1.2, 1.5, 1.0]  # one per layer of the pad's stack
    flux_lag_s = 1.2
    contact_conductance_w_m2k = 0.9
    flux_gain = 1.05
    module_seebeck = 1.0
    module_resistance = 1.0
    module_conductance = 1.0

    [as_built.display]              # the master's display pad: the same
    junction_lag_s = 1.3            # keys, and its junction sensor's lag

each a factor on the scene's nominal value (1: as designed; a key left out
is 1), or::

    [as_built]
    sd = 0.15                       # every factor drawn log-normal: exp(N(0, sd))
    seed = 3                        # reproducibly

The product never reads these: its models are built from the scene's
nominal values (``Scene.as_built`` is read only by the simulator:
:func:`simulated_pad_scene`, :func:`simulated_module`; a test proves that
removing the tables changes no model the product builds). The display's
simulated pad (sim/touch.py's ``DisplayTouch``) is built by
:func:`simulated_display`: its layers, flux sensor's lag and gain, module,
contact and junction sensor's lag times ``[as_built.display]``'s factors.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np

from telethermal.errors import SceneError

log = logging.getLogger(__name__)

#: The factors of one pad (besides ``layer_thickness``, one per layer).
SCALAR_KEYS = ("flux_lag_s", "contact_conductance_w_m2k", "flux_gain", "module_seebeck",
               "module_resistance", "module_conductance")
PART_KEYS = ("layer_thickness",) + SCALAR_KEYS
#: The display's own: its junction sensor's lag as mounted (the sensing
#: pad's held-pad thermistor is lag-free in the simulator: no such factor).
DISPLAY_KEYS = PART_KEYS + ("junction_lag_s",)
PARTS = ("pad", "display")
#: A factor outside this range is a typo, not a tolerance.
FACTOR_RANGE = (0.2, 5.0)
#: ``[as_built] sd``'s range (log-normal sd of every factor).
SD_RANGE = (0.0, 1.0)


@dataclass(frozen=True)
class BuiltFactors:
    """One pad's factors on its nominal values (1: as designed)."""

    layer_thickness: tuple[float, ...]
    flux_lag_s: float = 1.0
    contact_conductance_w_m2k: float = 1.0
    flux_gain: float = 1.0
    module_seebeck: float = 1.0
    module_resistance: float = 1.0
    module_conductance: float = 1.0
    junction_lag_s: float = 1.0         # the display's alone (DISPLAY_KEYS)

    @property
    def nominal(self) -> bool:
        return all(v == 1.0 for v in self.layer_thickness) and all(
            getattr(self, k) == 1.0 for k in SCALAR_KEYS + ("junction_lag_s",))

    def to_dict(self, keys: tuple[str, ...] = PART_KEYS) -> dict:
        """The factors of ``keys`` (the display's: :data:`DISPLAY_KEYS`)."""
        return {"layer_thickness": [round(v, 5) for v in self.layer_thickness],
                **{k: round(getattr(self, k), 5) for k in keys[1:]}}


@dataclass(frozen=True)
class AsBuilt:
    """A scene's pads as built: the sensing pad's and the display pad's
    factors, and the draw they came from (``sd``, ``seed``; None: given)."""

    pad: BuiltFactors
    display: BuiltFactors
    sd: float | None = None
    seed: int | None = None

    def describe(self) -> str:
        """One line for logs and reports."""
        how = (f"drawn log-normal, sd {self.sd:g}, seed {self.seed}" if self.sd is not None
               else "given factors")
        display = (f"display {_short(self.display, DISPLAY_KEYS)}" if not self.display.nominal
                   else "display as designed")
        return (f"pads built off their datasheet ([as_built], {how}): pad "
                f"{_short(self.pad)}; {display}")

    def to_dict(self) -> dict:
        return {"sd": self.sd, "seed": self.seed, "pad": self.pad.to_dict(),
                "display": self.display.to_dict(DISPLAY_KEYS)}


def _short(f: BuiltFactors, keys: tuple[str, ...] = PART_KEYS) -> str:
    return ", ".join(f"{k} {v}" for k, v in f.to_dict(keys).items())


def parse_as_built(raw, n_layers: int, source: str) -> AsBuilt | None:
    """``[as_built]`` of a scene file (None: no table): either ``sd`` and
    ``seed`` (every factor drawn) or ``pad`` and/or ``display`` tables of
    factors; ``n_layers``: the layers of the scene's ``[pad]``."""
    if raw is None:
        return None
    where = f"{source}: [as_built]"
    if not isinstance(raw, dict):
        raise SceneError(f"{where} must be a table, got {raw!r}")
    extra = sorted(set(raw) - {"sd", "seed", *PARTS})
    if extra:
        raise SceneError(f"{where}: unknown key(s) {', '.join(extra)}; known: sd, seed, "
                         f"{', '.join(PARTS)}")
    drawn, given = {"sd", "seed"} & set(raw), set(PARTS) & set(raw)
    if drawn and given:
        raise SceneError(f"{where}: give either 'sd' and 'seed' (every factor drawn) or "
                         f"[as_built.pad]/[as_built.display] factors, not both")
    if drawn:
        if drawn != {"sd", "seed"}:
            raise SceneError(f"{where}: 'sd' and 'seed' go together (missing "
                             f"{', '.join(sorted({'sd', 'seed'} - drawn))})")
        sd, seed = raw["sd"], raw["seed"]
        if isinstance(sd, bool) or not isinstance(sd, (int, float)) or \
                not SD_RANGE[0] <= sd <= SD_RANGE[1]:
            raise SceneError(f"{where}: 'sd' = {sd!r} must be a number in {list(SD_RANGE)}")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise SceneError(f"{where}: 'seed' = {seed!r} must be a whole number >= 0")
        return draw_as_built(float(sd), seed, n_layers)
    if not given:
        raise SceneError(f"{where}: empty; give 'sd' and 'seed', or [as_built.pad] / "
                         f"[as_built.display] factors")
    return AsBuilt(*(_parse_part(raw.get(part, {}), n_layers, f"{where}.{part}",
                                 DISPLAY_KEYS if part == "display" else PART_KEYS)
                     for part in PARTS))


def _parse_part(table, n_layers: int, where: str, keys: tuple[str, ...]) -> BuiltFactors:
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table of factors, got {table!r}")
    extra = sorted(set(table) - set(keys))
    if extra:
        raise SceneError(f"{where}: unknown key(s) {', '.join(extra)}; known: "
                         f"{', '.join(keys)}")
    thick = table.get("layer_thickness", [1.0] * n_layers)
    if not isinstance(thick, list) or len(thick) != n_layers:
        raise SceneError(f"{where}: 'layer_thickness' must be a list of {n_layers} factor(s), "
                         f"one per layer of the pad's stack ([pad] layers, then a Peltier pad's "
                         f"cold plate), got {thick!r}")
    values = {k: _factor(table.get(k, 1.0), f"{where}: '{k}'") for k in keys[1:]}
    return BuiltFactors(tuple(_factor(v, f"{where}: 'layer_thickness'[{i}]")
                              for i, v in enumerate(thick)), **values)


def _factor(value, where: str) -> float:
    lo, hi = FACTOR_RANGE
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not (math.isfinite(value) and lo <= value <= hi):
        raise SceneError(f"{where} = {value!r}: a factor on the nominal value, in [{lo}, {hi}]")
    return float(value)


def read_as_built(scene, raw, source: str):
    """``scene`` with its ``[as_built]`` table ``raw`` (None: none) read,
    said in the log (every process that loads it says so)."""
    as_built = parse_as_built(raw, len(scene.pad.layers), source)
    if as_built is not None:
        log.warning("%s: %s", source, as_built.describe())
    return with_as_built(scene, as_built)


def draw_as_built(sd: float, seed: int, n_layers: int) -> AsBuilt:
    """Every factor of both pads drawn ``exp(N(0, sd))`` from ``seed``
    (the pad's first, then the display's, in :data:`PART_KEYS` order, then
    the display's ``junction_lag_s``: a pad's draws as before it existed)."""
    rng = np.random.default_rng(seed)

    def part():
        thick = tuple(float(v) for v in np.exp(rng.normal(0.0, sd, n_layers)))
        return BuiltFactors(thick, *(float(v) for v in np.exp(rng.normal(0.0, sd,
                                                                            len(SCALAR_KEYS)))))
    pad, display = part(), part()
    display = dataclasses.replace(display, junction_lag_s=float(np.exp(rng.normal(0.0, sd))))
    return AsBuilt(pad, display, float(sd), int(seed))


def with_as_built(scene, as_built: AsBuilt | None):
    """``scene`` with these pads as built (None: as designed)."""
    return dataclasses.replace(scene, as_built=as_built)


def pad_factors(scene, part: str = "pad") -> BuiltFactors | None:
    """The sensing pad's factors (``part`` "display": the display pad's),
    None when the scene has none."""
    return None if scene.as_built is None else getattr(scene.as_built, part)


def simulated_pad_scene(scene):
    """The scene whose ``[pad]`` and sensors are the sensing pad as built
    (its layers' thicknesses, contact conductance and flux lag times their
    factors; ``as_built`` kept): what the simulator solves the slave's
    touches with. ``scene`` itself when it has no ``[as_built]``."""
    f = pad_factors(scene)
    if f is None:
        return scene
    from telethermal.physics.layered import Layer
    layers = tuple(Layer(lay.material, lay.thickness_m * k)
                   for lay, k in zip(scene.pad.layers, f.layer_thickness))
    pad = dataclasses.replace(scene.pad, layers=layers,
                              contact_conductance_w_m2k=scene.pad.contact_conductance_w_m2k
                              * f.contact_conductance_w_m2k)
    sensors = dataclasses.replace(scene.sensors,
                                  flux_lag_s=scene.sensors.flux_lag_s * f.flux_lag_s)
    return dataclasses.replace(scene, pad=pad, sensors=sensors)


def simulated_module(scene, params, part: str = "pad"):
    """The module ``params`` (:class:`~telethermal.physics.thermoelectric.ModuleParams`)
    of the sensing pad (``part`` "display": the display pad) as built: Seebeck,
    resistance, conductance times their factors."""
    f = pad_factors(scene, part)
    if f is None:
        return params
    return dataclasses.replace(params, seebeck_v_k=params.seebeck_v_k * f.module_seebeck,
                               resistance_ohm=params.resistance_ohm * f.module_resistance,
                               conductance_w_k=params.conductance_w_k * f.module_conductance)


def flux_gain_factor(scene) -> float:
    """The sensing pad's flux sensor's gain factor as built (1: as designed)."""
    f = pad_factors(scene)
    return 1.0 if f is None else f.flux_gain


@dataclass(frozen=True)
class DisplayBuild:
    """The display pad as the simulator builds it: the scene's nominal
    figures times ``[as_built.display]``'s factors (all 1 without one)."""

    layers: tuple
    flux_lag_s: float
    flux_gain: float
    contact_factor: float
    module: object              # ModuleParams
    junction_lag_factor: float


def simulated_display(scene) -> DisplayBuild:
    """The display pad of ``scene`` as built (sim/touch.py's ``DisplayTouch``
    alone reads it): its layers' thicknesses, flux sensor's lag and gain,
    the contact conductance on the finger, the module's S, R, K and the
    junction sensor's lag, each times its factor."""
    from telethermal.physics.layered import Layer
    f = pad_factors(scene, "display") or BuiltFactors((1.0,) * len(scene.pad.layers))
    layers = tuple(lay if k == 1.0 else Layer(lay.material, lay.thickness_m * k)
                   for lay, k in zip(scene.pad.layers, f.layer_thickness))
    return DisplayBuild(layers, scene.sensors.flux_lag_s * f.flux_lag_s, f.flux_gain,
                        f.contact_conductance_w_m2k,
                        simulated_module(scene, scene.pad.module_params()[0], "display"),
                        f.junction_lag_s)
