"""The slave's sensing pad on its Peltier module: a batch of contacts in
which the junction behind the layers is a node of the module, not an ideal
temperature source.

Before contact every trial is in the steady state of its hold: the layers
uniform at the set point, the junction there too (the loop holds its
thermistor's reading at the set point), the module's current the hold
current and its hot side and heat sink in the steady state of that current
(:func:`hold_steady_state`; not at room: a pad held 10 K above an object
at room temperature draws heat from its hot side all along).

From contact on, the module is stepped at the pad's own control rate
(``dt_s``, 1 kHz by default: the rate of the pad's junction loop) for all
trials at once:

1. the loop reads the junction and the hot side (the previous period's end)
   and sets the current (:class:`BatchJunctionLoop`), held over the period;
2. the layers' period-mean heat flow into the pad from the junction is
   exact and affine in the junction temperature ``u`` held over the period:
   per m^2, ``back_w . w0 + back_u * (u - T_ref)`` with
   ``back_w = m4 phi(lam, dt) / dt`` and
   ``back_u = g_back + (m4 psi(lam, dt) / dt) . f_unit`` (``m4`` the modal
   row of the back-face inflow less its constant part ``g_back u``);
3. the module (cold junction, hot side, heat sink) takes one backward-Euler
   step with that load, its three unknowns solved in closed form per trial
   (the 3 x 3 system is tridiagonal), as
   :class:`~telethermal.physics.thermoelectric.ThermoelectricStack` does one
   at a time: the junction's end temperature is the ``u`` of the period;
4. the layers then step exactly with ``u`` held, and the flux sensor's lag
   by its exact one-step map.

Outputs are evaluated at the requested times exactly within their period
(the layers' state at the period's start, moved by the closed form for the
fraction of the period elapsed, the junction held): no interpolation.

Heat flux is positive from the pad into the object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from telethermal.errors import ModelError
from telethermal.physics.layered import LayeredContact, _batch_args
from telethermal.physics.modal import _psi, lag_kernels, phi_any
from telethermal.physics.thermoelectric import (KELVIN, HBridge, ModuleParams, SinkParams,
                                                hold_current_a)

#: The pad's own control rate (its junction loop), Hz.
PAD_LOOP_RATE_HZ = 1000.0


# ---------------------------------------------------------------- the loop
def hold_current_batch_a(params: ModuleParams, cold_c, hot_c, load_w):
    """:func:`~telethermal.physics.thermoelectric.hold_current_a` over arrays:
    the smaller root of ``Qc(I) = load_w``; past the module's capacity ``S Tc / R``."""
    s, r, k = params.seebeck_v_k, params.resistance_ohm, params.conductance_w_k
    tc = np.asarray(cold_c, float) + KELVIN
    c = k * (np.asarray(hot_c, float) - np.asarray(cold_c, float)) + np.asarray(load_w, float)
    disc = (s * tc) ** 2 - 2.0 * r * c
    return np.where(disc < 0, s * tc / r, (s * tc - np.sqrt(np.maximum(disc, 0.0))) / r)


def bridge_limit_batch(params: ModuleParams, driver: HBridge, current_a, cold_c, hot_c):
    """:meth:`~telethermal.physics.thermoelectric.HBridge.limit` over arrays:
    (what flows, whether the request was cut)."""
    emf = params.seebeck_v_k * (np.asarray(hot_c) - np.asarray(cold_c))
    lo = np.maximum(-driver.current_limit_a, (-driver.supply_v - emf) / params.resistance_ohm)
    hi = np.minimum(driver.current_limit_a, (driver.supply_v - emf) / params.resistance_ohm)
    out = np.minimum(np.maximum(current_a, lo), hi)
    return out, out != current_a


class BatchJunctionLoop:
    """The junction loop's law (``control/junction.py``, ``JunctionLoop``)
    for a batch of independent pads: a feed-forward of the hold current at
    the target, a PI on the junction's error, the H-bridge's limits, and an
    integral that integrates only while the output is free or when the
    error takes it back inside. Kept here, beside the plant it closes, so
    that physics imports nothing from control; a test holds it equal to
    ``JunctionLoop`` period by period.

    Parameters
    ----------
    params, driver : the module and its H-bridge
    batch : int
    kp_a_k, ki_a_ks : float
        Proportional (A/K) and integral (A/(K s)) gains; defaults those of
        ``JunctionGains``.
    """

    def __init__(self, params: ModuleParams, driver: HBridge, batch: int,
                 kp_a_k: float = 10.0, ki_a_ks: float = 500.0):
        if not (kp_a_k >= 0 and ki_a_ks >= 0 and np.isfinite(kp_a_k) and np.isfinite(ki_a_ks)):
            raise ModelError(f"junction gains must be finite and >= 0, got {kp_a_k}, {ki_a_ks}")
        self.params, self.driver = params, driver
        self.kp_a_k, self.ki_a_ks = float(kp_a_k), float(ki_a_ks)
        self.integral_a = np.zeros(batch)
        self.saturated_periods = np.zeros(batch, dtype=int)

    def reset(self) -> None:
        self.integral_a[:] = 0.0
        self.saturated_periods[:] = 0

    def update(self, target_c, junction_c, hot_c, dt_s: float, load_w=0.0):
        """(current, saturated), arrays (B,): this period's current, A."""
        error = np.asarray(junction_c) - target_c      # positive: too warm, cool
        ff = hold_current_batch_a(self.params, target_c, hot_c, load_w)
        free = ff + self.kp_a_k * error + self.integral_a
        current, cut = bridge_limit_batch(self.params, self.driver, free, junction_c, hot_c)
        integrate = ~cut | ((free > current) != (error > 0))
        self.integral_a += np.where(integrate, self.ki_a_ks * error * dt_s, 0.0)
        self.saturated_periods += cut
        return current, cut

    def update_one(self, target_c: float, junction_c: float, hot_c: float, dt_s: float,
                   load_w: float = 0.0) -> tuple[float, bool]:
        """:meth:`update` for a batch of one, on floats: the same arithmetic
        bit for bit (the scalar hold current and H-bridge of
        ``thermoelectric``), without numpy's cost per call on one element."""
        error = junction_c - target_c
        free = (hold_current_a(self.params, target_c, hot_c, load_w) + self.kp_a_k * error
                + float(self.integral_a[0]))
        current, cut = self.driver.limit(self.params, free, junction_c, hot_c)
        if not cut or ((free > current) != (error > 0)):
            self.integral_a[0] += self.ki_a_ks * error * dt_s
        self.saturated_periods[0] += cut
        return current, cut


# ---------------------------------------------------------------- steady hold
def hold_steady_state(params: ModuleParams, sink: SinkParams, room_c: float, cold_c,
                      tol_k: float = 1e-12, max_iter: int = 200):
    """The steady state of a module holding its cold junction at ``cold_c``
    with nothing else drawing heat from it (the pad uniform, in air):
    ``Qc(I) = 0``, and the hot side's heat ``Qh`` crossing the grease and
    the sink to the room. Returns (current_a, hot_c, sink_c), arrays (B,).

    A fixed-point iteration on the hot side: its map has slope
    ``(R_grease + R_air) dQh/dTh``, about 0.3 for the shipped module and
    sink, so it contracts; it raises when it does not settle."""
    cold = np.atleast_1d(np.asarray(cold_c, dtype=float))
    r_total = sink.interface_k_w + sink.to_air_k_w
    hot = np.full_like(cold, room_c)
    for _ in range(max_iter):
        current = hold_current_batch_a(params, cold, hot, 0.0)
        _, qh, _ = params.heat_w(current, cold, hot)
        new = room_c + qh * r_total
        if np.max(np.abs(new - hot), initial=0.0) < tol_k:
            hot = new
            break
        hot = new
    else:
        raise ModelError(f"module hold at {cold} C: the hot side does not settle "
                         f"(the module cannot hold this set point on its sink)")
    current = hold_current_batch_a(params, cold, hot, 0.0)
    _, qh, _ = params.heat_w(current, cold, hot)
    return current, hot, room_c + qh * sink.to_air_k_w


# ---------------------------------------------------------------- the module
def module_step_batch(params: ModuleParams, sink: SinkParams, room_c: float, state_c,
                      current_a, dt_s: float, load_a_w, load_b_w_k):
    """One backward-Euler period of B modules, the current held: the
    equations of :meth:`~telethermal.physics.thermoelectric.ThermoelectricStack.step`
    written in deviations from the room (better conditioned than kelvin:
    the Peltier terms ``S I T`` keep their absolute temperature as a
    right-hand-side constant), the tridiagonal 3 x 3 system solved in
    closed form.

    Parameters
    ----------
    state_c : ndarray, shape (B, 3)
        Cold junction, hot side, sink at the period's start, degC.
    current_a, load_a_w, load_b_w_k : ndarray, shape (B,)
        The held current and the cold side's load ``a + b Tc_end`` (W into
        the junction, ``Tc_end`` in degC).

    Returns
    -------
    (state at the period's end (B, 3) degC, electrical power (B,) W, heat
    to the room (B,) W), the power and loss at the end temperatures (so
    that stored heat change = (load + power - loss) dt exactly).
    """
    x0 = np.asarray(state_c, dtype=float) - room_c
    step = _ModuleStepper(params, sink, room_c, dt_s)
    xc, xh, xs, power, air = step(x0[:, 0], x0[:, 1], x0[:, 2], np.asarray(current_a, float),
                                  np.asarray(load_a_w, float), np.asarray(load_b_w_k, float))
    return np.stack([xc, xh, xs], axis=1) + room_c, power, air


class _ModuleStepper:
    """:func:`module_step_batch` on deviations from the room, its constants
    computed once (the pad's loop calls it every period)."""

    def __init__(self, params: ModuleParams, sink: SinkParams, room_c: float, dt_s: float):
        self.s, self.r, self.g = params.seebeck_v_k, params.resistance_ohm, params.conductance_w_k
        self.cc, self.ch = params.cold_heat_j_k / dt_s, params.hot_heat_j_k / dt_s
        self.cs = sink.heat_j_k / dt_s
        self.gi, self.ga = 1.0 / sink.interface_k_w, 1.0 / sink.to_air_k_w
        self.d3 = self.cs + self.gi + self.ga
        self.room_c, self.room_k = room_c, room_c + KELVIN

    def __call__(self, xc0, xh0, xs0, i, load_a, load_b):
        s, r, g, gi = self.s, self.r, self.g, self.gi
        # cc (xc - xc0) = a + b (xc + room) - (s i (xc + room_K) - joule - g (xh - xc))
        # ch (xh - xh0) = s i (xh + room_K) + joule - g (xh - xc) - gi (xh - xs)
        # cs (xs - xs0) = gi (xh - xs) - ga xs
        si = s * i
        joule = 0.5 * r * i * i
        pumped = si * self.room_k
        d1 = (self.cc + g) - load_b + si
        d2 = (self.ch + g + gi) - si
        r1 = self.cc * xc0 + load_a + load_b * self.room_c - pumped + joule
        r2 = self.ch * xh0 + pumped + joule
        r3 = self.cs * xs0
        # Eliminate xs (row 3) and xc (row 1) into row 2.
        xh = (r2 + (gi / self.d3) * r3 + g * r1 / d1) / (d2 - gi * gi / self.d3 - g * g / d1)
        xc = (r1 + g * xh) / d1
        xs = (r3 + gi * xh) / self.d3
        power = i * (s * (xh - xc) + i * r)
        return xc, xh, xs, power, self.ga * xs


def module_stored_j(params: ModuleParams, sink: SinkParams, room_c: float, state_c):
    """Heat stored in B modules and sinks relative to the room, J, shape (B,)."""
    x = np.asarray(state_c, dtype=float) - room_c
    return params.cold_heat_j_k * x[:, 0] + params.hot_heat_j_k * x[:, 1] + sink.heat_j_k * x[:, 2]


# ---------------------------------------------------------------- the plant
@dataclass
class HeldPadResult:
    """A batch of contacts of the pad on its module; arrays (B, n) at the
    requested times unless said otherwise.

    ``flux_w_m2``/``flux_sensed_w_m2``: the contact flux and the flux
    sensor's lagged reading of it (0 before contact); ``surface_temp_a_c``:
    the pad's contact surface (what its thermocouple reads);
    ``current_a``/``junction_c``/``hot_c``/``sink_c``: the module's, held
    over the period each time falls in (the period's end temperatures).
    Per trial (B,): the peaks over the contact's periods, counts of periods
    past the datasheet's limits (``|I| > Imax``, hot side above
    ``hot_side_max_c``), and the heat accounts from contact to the last
    period's end (J): ``electrical_j - to_air_j = module_stored_j +
    layers_stored_j`` up to rounding.
    """

    t_s: np.ndarray
    flux_w_m2: np.ndarray
    flux_sensed_w_m2: np.ndarray | None
    surface_temp_a_c: np.ndarray
    current_a: np.ndarray
    junction_c: np.ndarray
    hot_c: np.ndarray
    sink_c: np.ndarray
    target_c: np.ndarray
    peak_droop_k: np.ndarray           # max over the contact of (target - junction)
    peak_rise_k: np.ndarray            # max over the contact of (junction - target)
    peak_current_a: np.ndarray         # max |I|
    over_current_periods: np.ndarray
    over_hot_periods: np.ndarray
    saturated_periods: np.ndarray
    electrical_j: np.ndarray
    to_air_j: np.ndarray
    module_stored_j: np.ndarray
    layers_stored_j: np.ndarray
    dt_s: float = 1.0 / PAD_LOOP_RATE_HZ

    def energy_balance_error(self) -> np.ndarray:
        """|electrical - to air - stored change| relative to the largest of
        the terms, per trial (B,)."""
        terms = np.stack([self.electrical_j, self.to_air_j, self.module_stored_j,
                          self.layers_stored_j])
        miss = self.electrical_j - self.to_air_j - self.module_stored_j - self.layers_stored_j
        scale = np.abs(terms).max(axis=0)
        return np.abs(miss) / np.where(scale > 0, scale, 1.0)


@dataclass
class _Layers:
    """The layers' modal system and its per-period maps (arrays (B, N))."""

    lam: np.ndarray
    w0: np.ndarray
    f_unit: np.ndarray
    m: np.ndarray                  # (B, 5, N)
    decay: np.ndarray
    drive: np.ndarray
    back_w: np.ndarray             # W/m^2 per unit modal state, period mean
    back_u: np.ndarray             # (B,) W/(m^2 K)
    r_pad: np.ndarray              # (B,) half-cell resistance at the pad's surface
    ref_c: np.ndarray              # (B,) the object's initial temperature


def _layers(model: LayeredContact, ta, tb, hc, scales, dt_s: float) -> _Layers:
    # Temperatures are deviations from the object's initial one; a unit back
    # temperature gives the drive per kelvin of junction deviation.
    system = model.modal_system(ta, tb, hc, scales, tb + 1.0, None, 5)
    lam, f_unit, m = system.lam, system.f, system.m
    m4 = m[:, 4]
    back_w = m4 * phi_any(lam, dt_s) / dt_s
    back_u = system.g_ba + np.einsum("bn,bn->b", m4 * _psi(lam, dt_s) / dt_s, f_unit)
    return _Layers(lam, system.w0, f_unit, m, np.exp(-lam * dt_s), phi_any(lam, dt_s) * f_unit,
                   back_w, back_u, system.r_half[:, model.grid.n_a - 1], tb)


class HeldPad:
    """The sensing pad's layers (side a of ``model``, its back face the
    module's cold junction) on a Peltier module and heat sink, the junction
    held by a loop.

    Parameters
    ----------
    model : LayeredContact
        The pad's layers as side a (its back boundary isothermal: the
        junction), the object as side b.
    params, sink : ModuleParams, SinkParams
    driver : HBridge
    room_c : float
    area_m2 : float, optional
        The area the layers' W/m^2 act on; default the module's.
    dt_s : float
        The pad loop's period, s (default 1 ms: the pad's own 1 kHz loop).
    sensor_lag_s : float, optional
        The flux sensor's time constant (none: no sensed flux).
    """

    def __init__(self, model: LayeredContact, params: ModuleParams, sink: SinkParams,
                 driver: HBridge, room_c: float, area_m2: float | None = None,
                 dt_s: float = 1.0 / PAD_LOOP_RATE_HZ, sensor_lag_s: float | None = None):
        if not isinstance(model, LayeredContact) or model.back_a.kind != "isothermal":
            raise ModelError("a pad on its module needs a LayeredContact whose side a's back "
                             f"face is the junction (isothermal), got {type(model).__name__}")
        if not (dt_s > 0 and np.isfinite(dt_s)):
            raise ModelError(f"the pad loop's period must be > 0, got {dt_s}")
        if sensor_lag_s is not None and not sensor_lag_s > 0:
            raise ModelError(f"sensor_lag_s must be > 0, got {sensor_lag_s}")
        self.model, self.params, self.sink, self.driver = model, params, sink, driver
        self.room_c = float(room_c)
        self.area_m2 = float(params.spec.area_m2 if area_m2 is None else area_m2)
        self.dt_s, self.sensor_lag_s = float(dt_s), sensor_lag_s

    def run(self, t_s, pad_c, object_c, conductance_w_m2k, k_scale_a=1.0, heat_scale_a=1.0,
            k_scale_b=1.0, heat_scale_b=1.0, target_c=None, loop=None,
            oracle_load: bool = False) -> HeldPadResult:
        """Simulate a batch of contacts starting at t = 0.

        Parameters
        ----------
        t_s : ndarray, shape (n,) or (B, n)
            Output times after contact, s (<= 0: before contact).
        pad_c, object_c, conductance_w_m2k, k_scale_*, heat_scale_* :
            As :meth:`LayeredContact.solve` takes them, shape (B,) or scalars.
        target_c : ndarray, shape (B,), optional
            The loop's set point for the junction's reading; default
            ``pad_c`` (the pad settled at its set point).
        loop : object, optional
            ``update(target_c, junction_c, hot_c, dt_s, load_w) -> (current,
            saturated)`` on arrays (B,); default a :class:`BatchJunctionLoop`
            with its default gains.
        oracle_load : bool
            Give the loop the layers' true load at the target as
            feed-forward (tests of an ideal loop). Default False: the loop
            knows only its thermistors.
        """
        ta, tb, hc, ksa, hsa, ksb, hsb = _batch_args(
            pad_c, object_c, conductance_w_m2k, k_scale_a, heat_scale_a, k_scale_b, heat_scale_b)
        batch = len(ta)
        t = np.asarray(t_s, dtype=np.float64)
        if t.ndim not in (1, 2) or not np.all(np.isfinite(t)):
            raise ModelError(f"t_s must be finite, of shape (n,) or (batch, n); got {t.shape}")
        tc = np.broadcast_to(np.clip(t, 0.0, None), (batch, t.shape[-1]))
        target = ta.copy() if target_c is None else \
            np.broadcast_to(np.asarray(target_c, float), (batch,)).copy()
        loop = loop or BatchJunctionLoop(self.params, self.driver, batch)
        lay = _layers(self.model, ta, tb, hc, (ksa, hsa, ksb, hsb), self.dt_s)
        current0, hot0, sink0 = hold_steady_state(self.params, self.sink, self.room_c, ta)
        periods = max(int(np.ceil(tc.max() / self.dt_s - 1e-9)), 1)
        hist = self._step(lay, loop, target, np.stack([ta, hot0, sink0], axis=1), periods,
                          oracle_load)
        return self._outputs(t, tc, lay, hist, target, (current0, ta, hot0, sink0))

    def _step(self, lay: _Layers, loop, target, state, periods: int, oracle_load: bool) -> dict:
        """Step every trial ``periods`` times; the history each output needs.

        A batch of one (a live touch: the slave's one trial) is stepped on
        Python floats, every operation the batch's own in the same order
        (elementwise IEEE arithmetic, the modal sums still by ``einsum``), so
        its history is the batch path's bit for bit (finite temperatures) at
        a fraction of its cost: numpy's overhead per call, not arithmetic,
        is what a period of one trial costs. The loop's own class only (a
        subclass may change ``update``), made for one trial."""
        batch, n_modes = lay.w0.shape
        dt, area, room = self.dt_s, self.area_m2, self.room_c
        one = batch == 1 and type(loop) is BatchJunctionLoop and loop.integral_a.shape == (1,)
        module = _ModuleStepper(self.params, self.sink, room, dt)   # floats or arrays alike
        w = lay.w0.copy()
        hist = {"w": np.empty((periods, batch, n_modes)), "sensed": np.zeros((periods, batch)),
                "state": np.empty((periods, batch, 3)), "current": np.empty((periods, batch)),
                "saturated": np.zeros(batch, dtype=int)}
        e_tau = ge_m = gp_m = None
        if self.sensor_lag_s:
            ge, gp = lag_kernels(lay.lam, dt, self.sensor_lag_s)
            e_tau, ge_m = np.exp(-dt / self.sensor_lag_s), ge * lay.m[:, 0]
            gp_m = np.einsum("bn,bn->b", gp * lay.f_unit, lay.m[:, 0])
        stored0 = module_stored_j(self.params, self.sink, room, state)
        layers0 = np.einsum("bn,bn->b", lay.m[:, 3], w)
        xc, xh, xs = (state[:, k] - room for k in range(3))
        # Heat into the junction from the layers over a period, W:
        # -(area) (back_w . w + back_u (u - ref)) = a + b u, u the junction.
        load_b = -area * lay.back_u
        load_a0 = area * lay.back_u * lay.ref_c
        back_w = -area * lay.back_w
        ref_c = lay.ref_c

        def dot(a, b):                       # the modal sums, per trial
            sums = np.einsum("bn,bn->b", a, b)
            return sums.item() if one else sums

        update = loop.update_one if one else loop.update
        if one:                              # every per-trial quantity a float
            xc, xh, xs, load_b, load_a0, target, ref_c = (
                float(v[0]) for v in (xc, xh, xs, load_b, load_a0, target, ref_c))
            e_tau, gp_m = (None, None) if gp_m is None else (float(e_tau), float(gp_m[0]))
        sensed, electrical, to_air = ((0.0 if one else np.zeros(batch)) for _ in range(3))
        feed = 0.0
        for p in range(periods):
            load_a = load_a0 + dot(back_w, w)
            if oracle_load:
                feed = load_a + load_b * target
            current, cut = update(target, xc + room, xh + room, dt, feed)
            hist["saturated"] += cut
            xc, xh, xs, power, air = module(xc, xh, xs, current, load_a, load_b)
            electrical += power
            to_air += air
            hist["w"][p], hist["sensed"][p], hist["current"][p] = w, sensed, current
            hist["state"][p, :, 0], hist["state"][p, :, 1], hist["state"][p, :, 2] = xc, xh, xs
            u = xc + (room - ref_c)
            if e_tau is not None:
                sensed = e_tau * sensed + dot(ge_m, w) + gp_m * u
            w = lay.decay * w + lay.drive * (u if one else u[:, None])
        if one:
            xc, xh, xs, electrical, to_air = (np.array([v]) for v in
                                              (xc, xh, xs, electrical, to_air))
        hist["state"] += room
        end = np.stack([xc, xh, xs], axis=1) + room
        hist["accounts"] = (electrical * dt, to_air * dt,
                            module_stored_j(self.params, self.sink, room, end) - stored0,
                            area * (np.einsum("bn,bn->b", lay.m[:, 3], w) - layers0))
        return hist

    def _outputs(self, t, tc, lay: _Layers, hist: dict, target, before) -> HeldPadResult:
        """Every output at the requested times, exact within each period."""
        periods, batch = hist["current"].shape
        after = tc > 0
        # The period each time falls in: (p dt, (p + 1) dt], and the time into it.
        p = np.clip(np.ceil(tc / self.dt_s - 1e-9).astype(int) - 1, 0, periods - 1)
        into = np.where(after, tc - p * self.dt_s, 0.0)[..., None]         # (B, n, 1)
        rows = np.arange(batch)[:, None]
        w = hist["w"][p, rows]                                              # (B, n, N)
        state = hist["state"][p, rows]                                      # (B, n, 3)
        u = (state[..., 0] - lay.ref_c[:, None])[..., None]
        lam, f_unit = lay.lam[:, None, :], lay.f_unit[:, None, :]
        moved = np.exp(-lam * into) * w + phi_any(lam, into) * f_unit * u
        m0, m1 = lay.m[:, None, 0], lay.m[:, None, 1]
        flux = np.where(after, (moved * m0).sum(-1), 0.0)
        cell = (moved * m1).sum(-1)
        current0, pad0, hot0, sink0 = before
        surface = np.where(after, lay.ref_c[:, None] + cell - flux * lay.r_pad[:, None],
                           pad0[:, None])
        sensed = None
        if self.sensor_lag_s:
            ge, gp = lag_kernels(lam, into, self.sensor_lag_s)
            s0 = hist["sensed"][p, rows]
            sensed = (np.exp(-into[..., 0] / self.sensor_lag_s) * s0 +
                      (ge * w * m0).sum(-1) + (gp * f_unit * m0).sum(-1) * u[..., 0])
            sensed = np.where(after, sensed, 0.0)

        def held(values, initial):
            return np.where(after, values, initial[:, None])

        junction_all = hist["state"][..., 0]
        spec = self.params.spec
        return HeldPadResult(
            t_s=t, flux_w_m2=flux, flux_sensed_w_m2=sensed, surface_temp_a_c=surface,
            current_a=held(hist["current"][p, rows], current0),
            junction_c=held(state[..., 0], pad0), hot_c=held(state[..., 1], hot0),
            sink_c=held(state[..., 2], sink0), target_c=target,
            peak_droop_k=(target[None, :] - junction_all).max(axis=0),
            peak_rise_k=(junction_all - target[None, :]).max(axis=0),
            peak_current_a=np.abs(hist["current"]).max(axis=0),
            over_current_periods=(np.abs(hist["current"]) > spec.imax_a).sum(axis=0),
            over_hot_periods=(hist["state"][..., 1] > spec.hot_side_max_c).sum(axis=0),
            saturated_periods=hist["saturated"],
            electrical_j=hist["accounts"][0], to_air_j=hist["accounts"][1],
            module_stored_j=hist["accounts"][2], layers_stored_j=hist["accounts"][3],
            dt_s=self.dt_s)
