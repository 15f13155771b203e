"""A thermoelectric (Peltier) module on a heat sink, driven by current.

The module is the standard lumped model (e.g. Lineykin & Ben-Yaakov,
"Modeling and analysis of thermoelectric modules", IEEE Trans. Ind. Appl.
43(2), 2007; the Melcor/Laird "Thermoelectric Handbook"): with the module's
Seebeck coefficient ``S`` (V/K), electrical resistance ``R`` (ohm) and
thermal conductance ``K`` (W/K), a current ``I`` (A, positive: the pad side
is cooled) pumps

* ``Qc = S I Tc - I^2 R / 2 - K (Th - Tc)`` out of the cold junction (the
  pad side) and
* ``Qh = S I Th + I^2 R / 2 - K (Th - Tc)`` into the hot junction,

temperatures in kelvin. Their difference is the electrical power
``P = V I`` with ``V = S (Th - Tc) + I R``: ``Qh - Qc = P`` exactly.

``S``, ``R`` and ``K`` follow from the datasheet's Imax, Qmax and dTmax at
its hot-side temperature Th: at ``I = Imax`` and ``Qc = 0`` the module
reaches dTmax, which is the maximum over the current, so ``Imax = S Tc/R``
with ``Tc = Th - dTmax`` and ``dTmax = S^2 Tc^2 / (2 R K)``; at ``dT = 0``,
``Qmax = S Imax Th - Imax^2 R / 2``. Hence
``R = Qmax / (Imax^2 (Th/Tc - 1/2))``, ``S = Imax R / Tc``,
``K = S^2 Tc^2 / (2 R dTmax)``. Both datasheet steady states are then met
exactly; Vmax (``S Th``) and the datasheet's resistance are checks (the
datasheet's four figures over-determine three parameters; see
:attr:`ModuleParams.vmax_derived_v`). Properties are taken constant at the
datasheet's Th.

The junctions and the hot plate have heat capacities (from the module's
geometry; the cold ceramic plate is a layer of the pad, in the scene). The
hot side sits on a heat sink of finite capacity, through a grease joint, and
the sink loses heat to the room through a resistance: it warms over a
session.
"""

from __future__ import annotations

import functools
import math
import tomllib
from dataclasses import dataclass
from importlib import resources

import numpy as np

from telethermal.errors import SceneError
from telethermal.physics.materials import get_material

KELVIN = 273.15
#: Bi2Te3 pellets: rho 7,700 kg/m^3, c 154 J/(kg K) (Rowe, CRC Handbook of
#: Thermoelectrics, 1995, tables for (Bi,Sb)2(Te,Se)3 alloys).
BI2TE3_HEAT_J_M3K = 7700.0 * 154.0
#: Copper: rho 8,960 kg/m^3, c 385 J/(kg K) (CRC Handbook of Chemistry and Physics).
COPPER_HEAT_J_M3K = 8960.0 * 385.0


#: The ceramic of a module's plates (both sides; its geometry's ``plate_mm``).
PLATE_MATERIAL = "alumina"


@dataclass(frozen=True)
class ModuleSpec:
    """What a module's datasheet says (and its geometry, for its heat capacities)."""

    name: str
    source: str
    imax_a: float
    vmax_v: float
    qmax_w: float
    dtmax_k: float
    th_c: float
    size_mm: tuple[float, float]
    height_mm: float
    couples: int
    resistance_ohm: float
    pellet_mm: float
    plate_mm: float
    tab_mm: float
    hot_side_max_c: float

    @property
    def area_m2(self) -> float:
        return self.size_mm[0] * self.size_mm[1] * 1e-6


@dataclass(frozen=True)
class HeatSinkSpec:
    name: str
    source: str
    volume_cm3: float
    material: str
    to_air_k_w: float
    interface_um: float
    interface_material: str
    max_c: float


@dataclass(frozen=True)
class ModuleParams:
    """The lumped model's parameters, derived from a :class:`ModuleSpec`."""

    spec: ModuleSpec
    seebeck_v_k: float
    resistance_ohm: float
    conductance_w_k: float
    cold_heat_j_k: float         # cold junction: copper tabs + half the pellets
    hot_heat_j_k: float          # hot junction and hot ceramic plate + half the pellets

    @property
    def vmax_derived_v(self) -> float:
        """The voltage at Imax and dTmax the derived parameters give (S Th)."""
        return self.seebeck_v_k * (self.spec.th_c + KELVIN)

    def heat_w(self, current_a, cold_c, hot_c):
        """(Qc pumped out of the cold junction, Qh released at the hot one,
        electrical power), W; arrays broadcast."""
        s, r, k = self.seebeck_v_k, self.resistance_ohm, self.conductance_w_k
        i = np.asarray(current_a, dtype=float)
        tc, th = np.asarray(cold_c, float) + KELVIN, np.asarray(hot_c, float) + KELVIN
        joule, cond = 0.5 * i * i * r, k * (th - tc)
        qc = s * i * tc - joule - cond
        qh = s * i * th + joule - cond
        power = i * (s * (th - tc) + i * r)
        return qc, qh, power

    def voltage_v(self, current_a, cold_c, hot_c):
        return self.seebeck_v_k * (np.asarray(hot_c) - np.asarray(cold_c)) + \
            self.resistance_ohm * np.asarray(current_a)


def derive(spec: ModuleSpec) -> ModuleParams:
    """S, R, K from Imax, Qmax and dTmax at Th (see the module docstring),
    and the junctions' heat capacities from the geometry."""
    for name in ("imax_a", "vmax_v", "qmax_w", "dtmax_k"):
        value = getattr(spec, name)
        if not (value > 0 and math.isfinite(value)):
            raise SceneError(f"module {spec.name}: {name} must be > 0, got {value}")
    th = spec.th_c + KELVIN
    tc = th - spec.dtmax_k
    if not tc > 0:
        raise SceneError(f"module {spec.name}: dtmax_k {spec.dtmax_k} >= Th in kelvin")
    r = spec.qmax_w / (spec.imax_a ** 2 * (th / tc - 0.5))
    s = spec.imax_a * r / tc
    k = s * s * tc * tc / (2.0 * r * spec.dtmax_k)
    pellet = spec.pellet_mm * 1e-3
    length = (spec.height_mm - 2 * spec.plate_mm - 2 * spec.tab_mm) * 1e-3
    if not length > 0:
        raise SceneError(f"module {spec.name}: plates and tabs are thicker than the module")
    legs = 2 * spec.couples * pellet * pellet * length * BI2TE3_HEAT_J_M3K
    # A tab joins two pellets: two pellet widths by one, per couple and side.
    tabs = spec.couples * 2 * pellet * pellet * spec.tab_mm * 1e-3 * COPPER_HEAT_J_M3K
    plate = spec.area_m2 * spec.plate_mm * 1e-3 * get_material(PLATE_MATERIAL).volumetric_heat_j_m3k
    return ModuleParams(spec, s, r, k, 0.5 * legs + tabs, 0.5 * legs + tabs + plate)


def cold_plate(spec: ModuleSpec):
    """The module's cold plate as the innermost layer of the pad built on
    it: ``plate_mm`` of :data:`PLATE_MATERIAL`, the one figure the pad's stack
    and the module's geometry (its pellets' length, its hot plate) share."""
    from telethermal.physics.layered import Layer
    return Layer(get_material(PLATE_MATERIAL), spec.plate_mm * 1e-3)


@dataclass(frozen=True)
class SinkParams:
    spec: HeatSinkSpec
    heat_j_k: float
    to_air_k_w: float
    interface_k_w: float         # hot junction to sink, over the module's area


def sink_params(spec: HeatSinkSpec, module: ModuleSpec) -> SinkParams:
    mat = get_material(spec.material)
    grease = get_material(spec.interface_material)
    if not (spec.volume_cm3 > 0 and spec.to_air_k_w > 0 and spec.interface_um > 0):
        raise SceneError(f"heat sink {spec.name}: volume, resistance and interface must be > 0")
    return SinkParams(spec, spec.volume_cm3 * 1e-6 * mat.volumetric_heat_j_m3k, spec.to_air_k_w,
                      spec.interface_um * 1e-6 / (grease.conductivity_w_mk * module.area_m2))


# ---------------------------------------------------------------- the table
@functools.lru_cache(maxsize=1)
def _table() -> dict:
    text = resources.files("telethermal").joinpath("physics/modules.toml").read_text()
    return tomllib.loads(text)


def module_names() -> list[str]:
    return sorted(_table()["modules"])


def heat_sink_names() -> list[str]:
    return sorted(_table()["heat_sinks"])


def get_module(name: str) -> ModuleSpec:
    table = _table()["modules"]
    if name not in table:
        raise SceneError(f"unknown thermoelectric module {name!r}; known: "
                         f"{', '.join(sorted(table))}")
    row = dict(table[name])
    row["size_mm"] = tuple(row["size_mm"])
    return ModuleSpec(name=name, **row)


def get_heat_sink(name: str) -> HeatSinkSpec:
    table = _table()["heat_sinks"]
    if name not in table:
        raise SceneError(f"unknown heat sink {name!r}; known: {', '.join(sorted(table))}")
    return HeatSinkSpec(name=name, **table[name])


@dataclass(frozen=True)
class JunctionSensorSpec:
    """The sensor on the module's cold plate that the junction loop reads:
    its time constant as mounted, bias limit, noise and resolution (K)."""

    name: str
    source: str
    tau_s: float
    bias_limit_k: float
    noise_k: float
    lsb_k: float

    def __post_init__(self):
        for key in ("tau_s", "bias_limit_k", "noise_k", "lsb_k"):
            value = getattr(self, key)
            if not (value >= 0 and math.isfinite(value)) or (key == "lsb_k" and value == 0):
                raise SceneError(f"junction sensor {self.name}: {key} must be finite and "
                                 f"{'> 0' if key == 'lsb_k' else '>= 0'}, got {value!r}")


def junction_sensor_names() -> list[str]:
    return sorted(_table()["junction_sensors"])


def get_junction_sensor(name: str) -> JunctionSensorSpec:
    table = _table()["junction_sensors"]
    if name not in table:
        raise SceneError(f"unknown junction sensor {name!r}; known: {', '.join(sorted(table))}")
    return JunctionSensorSpec(name=name, **table[name])


#: A Peltier scene that names no module gets these (the first paper's pad).
DEFAULT_MODULE = "TM-31-1.4-8.5"
DEFAULT_HEAT_SINK = "fan-40"
#: The display's junction sensor (physics/modules.toml, README's parts table).
DEFAULT_JUNCTION_SENSOR = "NTCG103JF103F-bonded"


# ---------------------------------------------------------------- the driver
@dataclass(frozen=True)
class HBridge:
    """The module's driver: a current-mode H-bridge on a supply. The current
    it can force is bounded by its own limit (set to the module's Imax) and
    by the supply: ``|S (Th - Tc) + I R| <= supply_v``."""

    current_limit_a: float
    supply_v: float

    def limit(self, params: ModuleParams, current_a: float, cold_c: float,
              hot_c: float) -> tuple[float, bool]:
        """(what flows, whether the request was cut)."""
        emf = params.seebeck_v_k * (hot_c - cold_c)
        lo = max(-self.current_limit_a, (-self.supply_v - emf) / params.resistance_ohm)
        hi = min(self.current_limit_a, (self.supply_v - emf) / params.resistance_ohm)
        out = min(max(current_a, lo), hi)
        return out, out != current_a


def default_driver(params: ModuleParams) -> HBridge:
    """Current limit at Imax; a 5 V supply (the usual rail for a module
    whose Vmax is under 5 V), so the current limit binds first."""
    return HBridge(params.spec.imax_a, 5.0)


# ---------------------------------------------------------------- the state
@dataclass
class ModuleState:
    """Temperatures (C) of the cold junction, hot junction and heat sink."""

    cold_c: float
    hot_c: float
    sink_c: float


@dataclass(frozen=True, slots=True)
class ModuleStep:
    """One period's heat, W (the period's values at its end temperatures)."""

    current_a: float
    voltage_v: float
    qc_w: float
    qh_w: float
    power_w: float
    to_air_w: float


class ThermoelectricStack:
    """The module and its sink, stepped by backward Euler over each period
    with the current held (zero-order hold), coupled to whatever the cold
    junction touches through an affine period-mean heat flow
    ``load_w = a + b * Tc_end`` (W into the cold junction; the caller's
    exact solution of its own side gives ``a`` and ``b``).

    The three temperatures at the period's end solve one 3 x 3 linear system
    (the Peltier terms ``S I T`` are linear in T for the held current), so
    the step is unconditionally stable and its discrete energy balance is
    exact: stored heat change = (load + electrical power - loss to air) dt.
    """

    def __init__(self, params: ModuleParams, sink: SinkParams, room_c: float,
                 state: ModuleState):
        self.params, self.sink, self.room_c = params, sink, room_c
        self.state = state

    def step(self, current_a: float, dt_s: float, load_a_w: float, load_b_w_k: float
             ) -> ModuleStep:
        p, k, st = self.params, self.sink, self.state
        s, r, g = p.seebeck_v_k, p.resistance_ohm, p.conductance_w_k
        i = float(current_a)
        cc, ch, cs = p.cold_heat_j_k / dt_s, p.hot_heat_j_k / dt_s, k.heat_j_k / dt_s
        gi, ga = 1.0 / k.interface_k_w, 1.0 / k.to_air_k_w
        joule = 0.5 * i * i * r
        # Unknowns x = (Tc, Th, Ts) in kelvin.
        #   cc (Tc - Tc0) = a + b Tc - (s i Tc - joule - g (Th - Tc))
        #   ch (Th - Th0) = s i Th + joule - g (Th - Tc) - gi (Th - Ts)
        #   cs (Ts - Ts0) = gi (Th - Ts) - ga (Ts - Troom)
        b_k = load_b_w_k
        a_k = load_a_w - b_k * KELVIN            # the load written in kelvin
        tc0, th0, ts0 = st.cold_c + KELVIN, st.hot_c + KELVIN, st.sink_c + KELVIN
        m = np.array([[cc - b_k + s * i + g, -g, 0.0],
                      [-g, ch - s * i + g + gi, -gi],
                      [0.0, -gi, cs + gi + ga]])
        rhs = np.array([cc * tc0 + a_k + joule, ch * th0 + joule,
                        cs * ts0 + ga * (self.room_c + KELVIN)])
        tc, th, ts = np.linalg.solve(m, rhs)
        self.state = ModuleState(float(tc - KELVIN), float(th - KELVIN), float(ts - KELVIN))
        qc, qh, power = p.heat_w(i, tc - KELVIN, th - KELVIN)
        return ModuleStep(i, float(p.voltage_v(i, tc - KELVIN, th - KELVIN)), float(qc),
                          float(qh), float(power), float(ga * (ts - self.room_c - KELVIN)))

    def stored_j(self, state: ModuleState | None = None) -> float:
        """Heat stored relative to the room, J (for balance checks)."""
        st = state or self.state
        return (self.params.cold_heat_j_k * (st.cold_c - self.room_c) +
                self.params.hot_heat_j_k * (st.hot_c - self.room_c) +
                self.sink.heat_j_k * (st.sink_c - self.room_c))


def hold_current_a(params: ModuleParams, cold_c: float, hot_c: float, load_w: float = 0.0
                   ) -> float:
    """The current at which the module pumps ``load_w`` out of the cold
    junction at these temperatures (the smaller root of Qc(I) = load_w): the
    steady hold, and the inner loop's feed-forward. Past the module's
    capacity, the current of its maximum (S Tc / R)."""
    s, r, k = params.seebeck_v_k, params.resistance_ohm, params.conductance_w_k
    tc = cold_c + KELVIN
    # (r/2) I^2 - s Tc I + (k dT + load) = 0
    c = k * (hot_c - cold_c) + load_w
    # Squared by multiplying (correctly rounded, as numpy squares its arrays;
    # ``x ** 2`` on a float is the C library's pow, off by an ulp now and
    # then): the same bits as the array twin in ``physics/held_pad.py``.
    disc = (s * tc) * (s * tc) - 2.0 * r * c
    if disc < 0:
        return s * tc / r
    return (s * tc - math.sqrt(disc)) / r
