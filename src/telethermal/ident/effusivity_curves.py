"""The effusivity estimator's forward model (:mod:`telethermal.ident.effusivity`
describes it): the scene's pad, noise-free, against a semi-infinite
:data:`REFERENCE_MATERIAL` object with its k and rho c scaled together, and
the grid of those curves (:class:`EffusivityFamily`) the estimator fits."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import NdBSpline, make_interp_spline

from telethermal.errors import IdentificationError
from telethermal.ident.bspline import SplineAxis

#: The grid's objects: this material with k and rho c scaled together.
REFERENCE_MATERIAL = "glass"
#: The effusivity grid's range, W s^0.5/(m^2 K): below the table's foam
#: (42) and above its copper (37 100) by a factor of ~3.
EFFUSIVITY_RANGE_W_S05_M2K = (15.0, 1.2e5)
#: Points of the grid in log e and in log h; the time grid's spacing, s (the
#: Peltier pad's loop period: its junction's current changes once per period).
N_E, N_H, MODEL_DT_S = 29, 9, 1e-3


@dataclass(frozen=True)
class EffusivityFamily:
    """``g(t; e, h)`` on a grid: ``log_e`` (n_e,), ``u = ln(h / h_ref)``
    (n_u,), ``t_s`` (n_t,, uniform from 0) and ``g`` (n_e, n_u, n_t), with
    its tricubic spline (not-a-knot, interpolating the grid)."""

    log_e: np.ndarray
    u: np.ndarray
    t_s: np.ndarray
    g: np.ndarray
    spline: NdBSpline

    @classmethod
    def from_grid(cls, log_e, u, t_s, g) -> "EffusivityFamily":
        axes = [np.asarray(a, float) for a in (log_e, u, t_s)]
        if min(len(a) for a in axes) < 4:
            raise IdentificationError(f"a tricubic spline needs >= 4 points on each axis, got "
                                      f"{[len(a) for a in axes]} (log e, log h, t)")
        c, knots = np.asarray(g, float), []
        for ax, x in enumerate(axes):                  # tensor product: one axis at a time
            spl = make_interp_spline(x, c, k=3, axis=ax)
            c, knots = np.moveaxis(spl.c, 0, ax), knots + [spl.t]
        return cls(*axes, np.asarray(g, float), NdBSpline(tuple(knots), c, 3))

    def curve(self, theta, times_s: np.ndarray, deriv: bool = False):
        """g at ``times_s - tau`` for ``theta = (ln e, u, tau)``; with
        ``deriv`` also the Jacobian (n, 3) in ``theta``. The tensor spline is
        first contracted in ``ln e`` and ``u`` (a scalar each) to a spline in
        t, on the coefficients the samples reach, then evaluated once at
        every sample: the same values as ``spline`` (to rounding), several
        times cheaper than evaluating it four times. No scipy object is
        built and checked per call (:mod:`telethermal.ident.bspline`: the
        same arithmetic as the scipy objects, to the bit)."""
        (i, wi, di), (j, wj, dj) = [self._weights(axis, theta[axis]) for axis in (0, 1)]
        axis_t = self._axes[2]
        t = times_s - theta[2]
        rows = axis_t.rows(t)
        block = self.spline.c[i[0]:i[-1] + 1, j[0]:j[-1] + 1, rows]      # (4, 4, coef in t)
        c_g = np.einsum("a,b,abk->k", wi, wj, block)
        if not deriv:
            return axis_t.evaluate(c_g, rows, t)
        cols = np.stack([c_g, np.einsum("a,b,abk->k", di, wj, block),
                         np.einsum("a,b,abk->k", wi, dj, block)], axis=1)
        values = axis_t.evaluate(cols, rows, t)
        d_t = axis_t.evaluate_derivative(c_g, rows, t)
        return values[:, 0], np.column_stack([values[:, 1], values[:, 2], -d_t])

    @functools.cached_property
    def _axes(self):
        """The spline's three axes (ln e, u, t): knots and derivative factors."""
        return [SplineAxis(knots) for knots in self.spline.t]

    def _weights(self, axis: int, x: float):
        """The 4 cubic B-spline weights at ``x`` on ``axis`` (0: ln e, 1: u)
        that can be nonzero: (their coefficient indices, weights, derivative
        weights)."""
        return self._axes[axis].weights(float(x))

    def nodes(self, times_s: np.ndarray, taus_s: np.ndarray):
        """Every grid node's curve at ``times_s - tau`` for each of ``taus_s``
        (linear in t between the grid's samples): (thetas (m, 3), g (m, n))."""
        pos = (times_s[None, :] - taus_s[:, None]) / (self.t_s[1] - self.t_s[0])
        i = np.clip(np.floor(pos).astype(int), 0, len(self.t_s) - 2)
        w = np.clip(pos - i, 0.0, 1.0)
        g = self.g[:, :, i] * (1 - w) + self.g[:, :, i + 1] * w     # (n_e, n_u, n_tau, n)
        le, uu, tt = np.meshgrid(self.log_e, self.u, taus_s, indexing="ij")
        return np.column_stack([le.ravel(), uu.ravel(), tt.ravel()]), g.reshape(-1, len(times_s))


def reference_object(scene, object_temp_c: float):
    """(the scene's pad model against a semi-infinite :data:`REFERENCE_MATERIAL`
    object at ``object_temp_c``, that material)."""
    from telethermal.physics.materials import get_material
    from telethermal.physics.scene import ObjectSpec, pad_contact_model
    model, _ = pad_contact_model(scene, ObjectSpec(REFERENCE_MATERIAL, float(object_temp_c),
                                                   math.inf))
    return model, get_material(REFERENCE_MATERIAL)


def sensed_unit_flux(scene, model, t_s, object_temp_c: float, scale, h_w_m2k) -> np.ndarray:
    """The pad's noise-free sensed flux per kelvin of true gap against
    ``model``'s object with k and rho c scaled by ``scale`` (B,), contact
    conductance ``h_w_m2k`` (B,), at ``t_s`` (n,) after contact: (B, n).
    The pad at the scene's set point for ``object_temp_c``: a Peltier pad
    held by its loop on its module, a water pad pre-conditioned as the
    generator does (the pump off at contact)."""
    from telethermal.data.generate import PRECONDITION_S, _pad_module
    from telethermal.physics.held_pad import HeldPad
    from telethermal.physics.thermoelectric import default_driver
    from telethermal.physics.waterpad import precondition
    scale, h = np.asarray(scale, float), np.asarray(h_w_m2k, float)
    b = len(scale)
    command = scene.pad_temp_c(object_temp_c)
    obj_c = np.full(b, float(object_temp_c))
    lag = scene.sensors.flux_lag_s
    if scene.pad.kind == "peltier":
        params, sink = _pad_module(scene)
        plant = HeldPad(model, params, sink, default_driver(params), scene.room_temp_c,
                        sensor_lag_s=lag, area_m2=scene.pad.area_m2)
        pad_c = np.full(b, command)
        flux = plant.run(t_s, pad_c, obj_c, h, k_scale_b=scale, heat_scale_b=scale)
    else:
        run = precondition(np.array([command]), scene.room_temp_c, PRECONDITION_S)
        pad_c = np.full(b, float(run.final_pad_c[0]))
        flux = model.solve(t_s, pad_c, obj_c, h, k_scale_b=scale, heat_scale_b=scale,
                           back_temp_a_c=float(run.final_water_c[0]), sensor_lag_s=lag)
    return flux.flux_sensed_w_m2 / (pad_c - obj_c)[:, None]


def effusivity_family(scene, object_temp_c: float, u_grid, t_max_s: float,
                      n_e: int = N_E, e_range=EFFUSIVITY_RANGE_W_S05_M2K,
                      dt_s: float = MODEL_DT_S) -> EffusivityFamily:
    """:func:`sensed_unit_flux` on ``n_e`` log-spaced effusivities x
    ``u_grid`` x [0, t_max_s], as an :class:`EffusivityFamily`."""
    model, ref = reference_object(scene, object_temp_c)
    log_e = np.linspace(math.log(e_range[0]), math.log(e_range[1]), n_e)
    u = np.asarray(u_grid, float)
    t = np.arange(int(np.ceil(t_max_s / dt_s)) + 1) * dt_s
    le, uu = np.meshgrid(log_e, u, indexing="ij")
    g = sensed_unit_flux(scene, model, t, object_temp_c, np.exp(le.ravel()) / ref.effusivity,
                         scene.pad.contact_conductance_w_m2k * np.exp(uu.ravel()))
    return EffusivityFamily.from_grid(log_e, u, t, g.reshape(len(log_e), len(u), len(t)))
