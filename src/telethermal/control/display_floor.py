"""What the display can do on a touch with a real Peltier module behind it:
the floor of the skin temperature error no current trajectory can beat.

The plant is the pad stack (fingertip-7: flux film, grease, alumina) with
the module's cold junction behind it as one lumped node of heat capacity
``cold_heat_j_k / area`` (J/(m^2 K)), on the operator's semi-infinite
fingertip. Its input is the heat the module delivers to that node,
``q_j = -Qc / area`` (W/m^2, positive heating the pad: the flux sign of the
project, from the pad towards the finger). The layers, cells, contact
conductance and skin scalings are those of
:class:`~telethermal.physics.layered.LayeredContact` (the display model of
``sim/touch.py``: the same grid and conductances), with the junction node
added behind the back face, and the system is integrated exactly over each
5 ms slot with the input held (modal form, as ``DisplayPlant`` does).

The best trajectory is a bounded linear least-squares problem in ``q_j``:
the skin's surface temperature is affine in ``q_j``, and the module can only
pump what it can at the present junction and hot-side temperatures within
its driver's current limits (box bounds per slot). See :func:`best_touch`.

The direct-contact reference is the same finger (temperature, skin
scalings, contact conductance) on the object, from
:func:`~telethermal.physics.scene.finger_contact_model`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.linalg import eigh_tridiagonal, toeplitz
from scipy.optimize import lsq_linear

from telethermal.errors import ControlError, UnknownMaterialError
from telethermal.physics import thermoelectric as te
from telethermal.physics.layered import Boundary, Layer, LayeredContact
from telethermal.physics.materials import get_material
from telethermal.physics.modal import phi_any
from telethermal.physics.scene import Scene, finger_contact_model
from telethermal.threads import single_threaded_blas

GRID_S = 0.005
CONTACT_S = 3.0
#: Nonlinear verification: backward-Euler substeps of the module per slot.
SUBSTEPS = 5
#: The bounds given to the solver are this fraction of the pumping range
#: inside the module's own, so that the current realising the trajectory on
#: the nonlinear module (whose temperatures differ slightly from those the
#: bounds were computed at) stays within its limits.
BOUND_MARGIN = 0.01
MAX_ROUNDS = 6


@dataclass(frozen=True)
class Touch:
    """One operator's touch: finger and object temperatures (C), the
    pad/object-finger contact conductance (W/(m^2 K)), skin scalings."""

    finger_c: float
    object_c: float
    conductance_w_m2k: float
    skin_k_scale: float = 1.0
    skin_heat_scale: float = 1.0


def nominal_touch(scene: Scene, object_c: float | None = None,
                  finger_c: float | None = None) -> Touch:
    """The scene's nominal operator (mean finger temperature, nominal skin,
    the nominal force's contact conductance) on an object at room temperature."""
    if scene.finger is None:
        raise ControlError(f"scene {scene.name}: no [finger], so no operator to render for")
    var = scene.variability
    h = scene.finger.contact_conductance_w_m2k * \
        (var.force_n / var.reference_force_n) ** var.conductance_force_exponent
    return Touch(scene.finger.temp_c if finger_c is None else float(finger_c),
                 scene.room_temp_c if object_c is None else float(object_c), float(h))


@dataclass(frozen=True)
class Hardware:
    """The module, its sink and driver, and the pad's layers (contact first)."""

    params: te.ModuleParams
    sink: te.SinkParams
    driver: te.HBridge
    pad_layers: tuple[Layer, ...]
    room_c: float
    #: The pad's face (the scene's ``size_mm``); None: the module's face.
    #: (Left out of the repr; the idle policy's key takes it with every
    #: other field, and the scene's ``size_mm`` besides.)
    face_m2: float | None = field(default=None, repr=False)

    @property
    def area_m2(self) -> float:
        return self.params.spec.area_m2 if self.face_m2 is None else self.face_m2


def hardware(scene: Scene, qmax_scale: float = 1.0, film_r_scale: float = 1.0,
             module: str | None = None, heat_sink: str | None = None) -> Hardware:
    """The display's hardware: the module and heat sink the scene's
    ``[pad]`` names (``module``, ``heat_sink``: others of
    physics/modules.toml instead); ``qmax_scale`` multiplies Imax and Qmax
    together (S unchanged, R / scale, K x scale: more couples in parallel,
    the junction's heat capacity kept), ``film_r_scale`` the thickness of the
    contact-side layer (the flux film: a thinner film, R and C both scaled)."""
    if not (qmax_scale > 0 and film_r_scale > 0):
        raise ControlError(f"qmax_scale and film_r_scale must be > 0, got {qmax_scale}, "
                           f"{film_r_scale}")
    spec = te.get_module(scene.pad.module if module is None else module)
    spec = replace(spec, imax_a=spec.imax_a * qmax_scale, qmax_w=spec.qmax_w * qmax_scale)
    params = te.derive(spec)
    layers = list(scene.pad.layers)
    layers[0] = Layer(layers[0].material, layers[0].thickness_m * film_r_scale)
    face = None if scene.pad.size_mm is None else scene.pad.area_m2
    sink = te.get_heat_sink(scene.pad.heat_sink if heat_sink is None else heat_sink)
    return Hardware(params, te.sink_params(sink, spec),
                    te.default_driver(params), tuple(layers), scene.room_temp_c, face)


# ---------------------------------------------------------------- the plant
def _modes(cap, links, back_g=0.0):
    """Diagonalise C dT/dt = -K T (+ inputs) for a chain of nodes:
    capacities ``cap`` (J/(m^2 K)), conductances ``links`` between
    neighbours, ``back_g`` from node 0 to a held temperature. Returns
    (lam, to_temp) with T = to_temp @ w, w the modal coordinates
    (w = (to_temp * cap[:, None]).T @ T)."""
    diag = np.zeros_like(cap)
    diag[:-1] += links
    diag[1:] += links
    diag[0] += back_g
    root = np.sqrt(cap)
    lam, vec = eigh_tridiagonal(diag / cap, -links / (root[:-1] * root[1:]))
    lam[np.abs(lam) < 1e-11 * lam.max()] = 0.0
    return lam, vec / root[:, None]


class JunctionPlant:
    """The pad stack with the junction node, on the finger; exact per slot.

    Nodes: the junction, then the cells of ``LayeredContact`` (pad from its
    back face, then the skin). Attributes after construction: ``n`` slots,
    ``skin_pulse`` and ``junction_pulse`` (n,), the response at slot ends
    k = 0..n-1 to a unit ``q_j`` (1 W/m^2) held over slot 0 (K), so the
    response to any input is ``toeplitz(pulse) @ q_j``.
    """

    def __init__(self, hw: Hardware, touch: Touch, contact_s: float = CONTACT_S,
                 grid_s: float = GRID_S):
        model = LayeredContact(hw.pad_layers, (Layer(get_material("skin"), math.inf),),
                               Boundary("isothermal"), Boundary("adiabatic"), 1e-3,
                               round(contact_s + 1.0, 3))
        one = np.ones(1)
        g_link, g_ba, _, cap, r_half = model._assemble(
            np.array([touch.conductance_w_m2k]), one, one, one * touch.skin_k_scale,
            one * touch.skin_heat_scale)
        self.n, self.grid_s, self.touch = int(round(contact_s / grid_s)), grid_s, touch
        self.na = model.grid.n_a
        self.cells_cap, self.cells_links, self.back_g = cap[0], g_link[0], float(g_ba[0])
        self.r_pad, self.r_skin = r_half[0, self.na - 1], r_half[0, self.na]
        self.g_contact = g_link[0, self.na - 1]
        c_j = hw.params.cold_heat_j_k / hw.area_m2
        self.cap = np.r_[c_j, self.cells_cap]
        lam, to_t = _modes(self.cap, np.r_[self.back_g, self.cells_links])
        self._lam, self._to_t = lam, to_t
        self._to_w = (to_t * self.cap[:, None]).T           # w = to_w @ T
        self._rows = self._output_rows(1) @ to_t             # (2, N) junction, skin surface
        k = np.arange(self.n)
        decay = np.exp(-np.outer(k, lam) * grid_s)           # (n, N)
        drive = phi_any(lam, grid_s) * to_t[0]             # unit q_j into node 0
        pulse = (decay * drive) @ self._rows.T               # (n, 2)
        self.junction_pulse, self.skin_pulse = pulse[:, 0], pulse[:, 1]
        self._free_decay = np.exp(-np.outer(k + 1, lam) * grid_s)

    def _output_rows(self, offset: int) -> np.ndarray:
        """Rows on the node temperatures: junction (node 0) and the skin's
        surface (first skin cell plus the flux times its half-cell resistance)."""
        rows = np.zeros((2, len(self.cells_cap) + offset))
        s = self.na + offset
        rows[0, 0] = 1.0
        rows[1, s] = 1.0 - self.g_contact * self.r_skin
        rows[1, s - 1] = self.g_contact * self.r_skin
        return rows

    def initial_temps(self, idle_c: float) -> np.ndarray:
        """Junction and pad cells at ``idle_c``, skin at the finger's temperature."""
        cells = np.where(np.arange(len(self.cells_cap)) < self.na, idle_c, self.touch.finger_c)
        return np.r_[idle_c, cells]

    def free(self, idle_c: float) -> tuple[np.ndarray, np.ndarray]:
        """(junction, skin surface) at slot ends with q_j = 0, C; shapes (n,)."""
        w0 = self._to_w @ self.initial_temps(idle_c)
        out = (self._free_decay * w0) @ self._rows.T
        return out[:, 0], out[:, 1]

    @functools.cached_property
    def skin_matrix(self) -> np.ndarray:
        return toeplitz(self.skin_pulse, np.zeros(self.n))

    @functools.cached_property
    def junction_matrix(self) -> np.ndarray:
        return toeplitz(self.junction_pulse, np.zeros(self.n))


def direct_skin_c(scene: Scene, material: str, touch: Touch, n: int,
                  grid_s: float = GRID_S) -> np.ndarray:
    """The finger's surface temperature touching ``material`` directly, at
    slot ends, C; shape (n,)."""
    obj = scene.object_named(material)
    if obj is None:
        raise UnknownMaterialError(f"material {material!r} is not in scene {scene.name} "
                                   f"(its materials: {', '.join(scene.materials)})")
    model, _ = finger_contact_model(scene, obj)
    t = (np.arange(n) + 1) * grid_s
    ref = model.solve(t, touch.finger_c, touch.object_c, touch.conductance_w_m2k,
                      k_scale_a=touch.skin_k_scale, heat_scale_a=touch.skin_heat_scale)
    return ref.surface_temp_a_c[0]


# ---------------------------------------------------------------- the module's limits
def pump_bounds_w_m2(hw: Hardware, cold_c, hot_c) -> tuple[np.ndarray, np.ndarray]:
    """(lowest, highest) heat the module can deliver to its cold junction,
    W/m^2 (``-Qc / area``), at these junction temperatures (C; arrays
    broadcast), over every current the driver can force: Qc(I) is concave
    with its top at I = S Tc / R, so its largest value is at the driver's
    highest current (or that top) and its smallest at the lowest current."""
    p, drv = hw.params, hw.driver
    s, r = p.seebeck_v_k, p.resistance_ohm
    tc, th = np.asarray(cold_c, float), np.asarray(hot_c, float)
    emf = s * (th - tc)
    i_lo = np.maximum(-drv.current_limit_a, (-drv.supply_v - emf) / r)
    i_hi = np.minimum(drv.current_limit_a, (drv.supply_v - emf) / r)
    qc_max = p.heat_w(np.minimum(i_hi, s * (tc + te.KELVIN) / r), tc, th)[0]
    qc_min = p.heat_w(i_lo, tc, th)[0]
    return -qc_max / hw.area_m2, -qc_min / hw.area_m2


def idle_hold(hw: Hardware, idle_c: float) -> tuple[float, float, float]:
    """(current A, hot junction C, sink C) holding the pad at ``idle_c`` in
    air (no load: Qc = 0) in steady state; raises if the driver cannot."""
    p, sink = hw.params, hw.sink
    hot = sink_c = hw.room_c
    for _ in range(100):
        current = te.hold_current_a(p, idle_c, hot, 0.0)
        qh = float(p.heat_w(current, idle_c, hot)[1])
        sink_c = hw.room_c + qh * sink.to_air_k_w
        hot = sink_c + qh * sink.interface_k_w
    current = te.hold_current_a(p, idle_c, hot, 0.0)
    applied, cut = hw.driver.limit(p, current, idle_c, hot)
    if cut or abs(float(p.heat_w(current, idle_c, hot)[0])) > 1e-6:
        raise ControlError(f"module {p.spec.name} cannot hold the pad at {idle_c:.2f} C "
                           f"(room {hw.room_c} C): it would need {current:.2f} A")
    return float(current), float(hot), float(sink_c)


@single_threaded_blas
def bounded_fit(matrix: np.ndarray, target: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                exact: bool = True) -> np.ndarray:
    """argmin ||matrix q - target|| subject to lo <= q <= hi (W/m^2).

    ``scipy.optimize.lsq_linear`` because the plant is linear in q (so the
    problem is a convex quadratic), the module's limits are box bounds per
    slot, and scipy is already a dependency (no QP solver to add). With
    ``exact`` its active-set method ``bvls`` (a few hundred variables,
    dense: 0.5-0.8 s on one BLAS thread); without, ``trf`` at tol 1e-6 (~0.1
    s; on the touches tried its objective was within 1e-4 K of bvls's), for
    the idle searches. q is scaled to 10 kW/m^2 for conditioning.
    """
    scale = 1e4
    if exact:
        fit = lsq_linear(matrix * scale, target, bounds=(lo / scale, hi / scale),
                         method="bvls", max_iter=50 * len(target))
    else:
        fit = lsq_linear(matrix * scale, target, bounds=(lo / scale, hi / scale),
                         method="trf", tol=1e-6, lsmr_tol=None, max_iter=2000)
    return fit.x * scale


# ---------------------------------------------------------------- the nonlinear check
class _PadLoad:
    """The pad's cells and the finger without the junction node, their back
    face tied to the junction: exact over a substep with the junction held
    at u, giving the substep's mean heat flow into the junction as a + b u
    (W/m^2), the coupling :class:`~telethermal.physics.thermoelectric.ThermoelectricStack`
    takes."""

    def __init__(self, plant: JunctionPlant, dt_s: float):
        lam, to_t = _modes(plant.cells_cap, plant.cells_links, plant.back_g)
        self.to_w = (to_t * plant.cells_cap[:, None]).T
        f = to_t[0] * plant.back_g
        phi = phi_any(lam, dt_s)
        self._decay, self._drive = np.exp(-lam * dt_s), phi * f
        self._a_row = plant.back_g * to_t[0] * phi / dt_s
        self._b = plant.back_g * (to_t[0] @ ((dt_s - phi) / (lam * dt_s) * f) - 1.0)
        self._skin_row = plant._output_rows(0)[1] @ to_t

    def load(self, w: np.ndarray) -> tuple[float, float]:
        return float(self._a_row @ w), float(self._b)

    def advance(self, w: np.ndarray, junction_c: float) -> np.ndarray:
        return self._decay * w + self._drive * junction_c

    def skin_c(self, w: np.ndarray) -> float:
        return float(self._skin_row @ w)


@dataclass
class Verified:
    """The trajectory on the nonlinear module: per slot the current (A), the
    junction and hot-side temperatures at its start (C), the skin at its end."""

    current_a: np.ndarray
    cold_c: np.ndarray
    hot_c: np.ndarray
    skin_c: np.ndarray
    violations: int
    sink_end_c: float


def verify(hw: Hardware, plant: JunctionPlant, q_j_w_m2: np.ndarray, idle_c: float
           ) -> Verified:
    """Drive :class:`ThermoelectricStack` (module, sink, room) under the
    pad with, per slot, the current that pumps ``q_j`` at the slot's start
    temperatures (held over the slot, SUBSTEPS backward-Euler steps). A slot
    whose current the driver cuts (past Imax or the supply) or that no
    current realises counts as a violation; the cut current is applied."""
    p, area = hw.params, hw.area_m2
    dt = plant.grid_s / SUBSTEPS
    pad = _PadLoad(plant, dt)
    w = pad.to_w @ plant.initial_temps(idle_c)[1:]
    _, hot, sink = idle_hold(hw, idle_c)
    stack = te.ThermoelectricStack(p, hw.sink, hw.room_c, te.ModuleState(idle_c, hot, sink))
    out = np.zeros((4, plant.n))
    violations = 0
    for k in range(plant.n):
        st = stack.state
        want_w = -q_j_w_m2[k] * area
        current, cut = hw.driver.limit(p, te.hold_current_a(p, st.cold_c, st.hot_c, want_w),
                                       st.cold_c, st.hot_c)
        got_w = float(p.heat_w(current, st.cold_c, st.hot_c)[0])
        violations += bool(cut or abs(got_w - want_w) > 1e-6 * p.spec.qmax_w)
        out[:3, k] = current, st.cold_c, st.hot_c
        for _ in range(SUBSTEPS):
            a, b = pad.load(w)
            stack.step(current, dt, a * area, b * area)
            w = pad.advance(w, stack.state.cold_c)
        out[3, k] = pad.skin_c(w)
    return Verified(*out, violations, stack.state.sink_c)


# ---------------------------------------------------------------- the best touch
@dataclass
class Floor:
    """The best trajectory for one touch from one idle temperature."""

    idle_c: float
    skin_rms_k: float
    q_j_w_m2: np.ndarray
    skin_c: np.ndarray
    junction_c: np.ndarray
    rounds: int
    verified: Verified | None = None

    def summary(self, target_c: np.ndarray) -> dict:
        out = {"idle_c": self.idle_c, "floor_k": self.skin_rms_k, "rounds": self.rounds,
               "q_j_min_w_m2": float(self.q_j_w_m2.min()),
               "q_j_max_w_m2": float(self.q_j_w_m2.max()),
               "junction_min_c": float(self.junction_c.min()),
               "junction_max_c": float(self.junction_c.max())}
        if self.verified is not None:
            v = self.verified
            out.update(verified_floor_k=_rms(v.skin_c - target_c),
                       peak_current_a=float(np.abs(v.current_a).max()),
                       violations=v.violations, hot_max_c=float(v.hot_c.max()),
                       sink_end_c=v.sink_end_c)
        return out


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def best_touch(hw: Hardware, plant: JunctionPlant, target_c: np.ndarray, idle_c: float,
               nonlinear: bool = True, max_rounds: int = MAX_ROUNDS, exact: bool = True
               ) -> Floor:
    """The trajectory of q_j minimising the skin's RMS error against
    ``target_c`` (n,) from the pad idle at ``idle_c``, within what the
    module can pump.

    The bounds depend on the junction's temperature along the trajectory:
    solve, recompute them on the result's temperatures, solve again, until
    the floor moves by under 1e-4 K (at most ``max_rounds``; the trajectory
    itself need not settle: the problem is ill-conditioned, slots far apart
    trade off at equal cost, so the junction may move by ~1 K between rounds
    at the same floor, which the bounds' margin covers). Without
    ``nonlinear`` the temperatures are the linear plant's junction and a hot
    side held at the idle's steady hot-side temperature (cheap, for the
    searches); with it, the junction and hot side of the nonlinear module
    driven by the realising current (:func:`verify`), which also gives the
    violations.
    """
    free_j, free_s = plant.free(idle_c)
    cold = np.r_[idle_c, free_j[:-1]]
    hot = np.full(plant.n, idle_hold(hw, idle_c)[1])
    residual = target_c - free_s
    checked, last = None, math.inf
    for rounds in range(1, max_rounds + 1):
        lo, hi = pump_bounds_w_m2(hw, cold, hot)
        margin = BOUND_MARGIN * (hi - lo)
        q = bounded_fit(plant.skin_matrix, residual, lo + margin, hi - margin, exact)
        junction = free_j + plant.junction_matrix @ q
        if nonlinear:
            checked = verify(hw, plant, q, idle_c)
            new_cold, hot = checked.cold_c, checked.hot_c
        else:
            new_cold = np.r_[idle_c, junction[:-1]]
        skin = free_s + plant.skin_matrix @ q
        floor, change = _rms(skin - target_c), abs(_rms(skin - target_c) - last)
        cold, last = new_cold, floor
        if change < 1e-4 and (checked is None or checked.violations == 0):
            break
    return Floor(idle_c, floor, q, skin, junction, rounds, checked)
