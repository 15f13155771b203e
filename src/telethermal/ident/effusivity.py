"""A live estimate of the touched object's effusivity ``e = sqrt(k rho c)``
(W s^0.5/(m^2 K)) with a 95 % interval, from the same
:class:`~telethermal.ident.prepare.Contacts` row the identifiers see, at any
window (prefix) of the contact (issue 30, part 1).

It generalises the oracle (:mod:`telethermal.ident.oracle`) from a discrete
set of materials to a continuous effusivity. What a touch is, in the units
of ``x`` (W/m^2 K)::

    x_k = A * g(t_k - tau; e, h) + e_k

- ``g(t; e, h)``: the flux sensor's lagged reading per kelvin of true gap,
  ``t`` after contact, of the scene's pad (a Peltier pad held by its loop on
  its module, :class:`~telethermal.physics.held_pad.HeldPad`, or the water
  pad with its pre-conditioned water behind it) against a **homogeneous
  semi-infinite object** of effusivity ``e``, noise-free at the nominal
  temperatures (the object at ``object_temp_c``, the pad at the scene's set
  point for it), on a grid of ``log e`` x ``log h`` x ``t``, as a tricubic
  tensor-product spline.
- For a semi-infinite homogeneous object the surface flux depends on ``e``
  only (its surface impedance is ``1 / (e sqrt(s))`` in the Laplace domain),
  not on how ``e`` splits into ``k`` and ``rho c``: the grid's objects are
  :data:`REFERENCE_MATERIAL` with ``k`` and ``rho c`` both scaled by
  ``e / e_ref`` (its diffusivity kept, so the layered grid sized for it
  stays valid); ``tests/unit/test_effusivity_estimate.py`` checks the
  independence of the split. A *finite* object is a different model: its
  flux depends on ``L / sqrt(alpha t)`` as well. The scenes' 30-50 mm
  objects are semi-infinite to ``2 exp(-L^2 / (alpha t))`` < 1e-3 at 1 s for
  every object material in the table (copper's diffusivity is the largest);
  a thin object on a base is not, and the estimate drifts with the window
  (see :attr:`EffusivityEstimate.fits`).
- ``h``, ``tau`` and ``A``: the oracle's nuisances drawn through the
  generator's own code (:func:`~telethermal.ident.oracle.draw_nuisances`):
  the joint kernel prior of ``(log h, tau)``, and ``A``'s Gaussian prior
  pooled over the scene's materials and ``n_sessions`` sessions (a slave
  does not know its instruments' errors); ``A`` is marginalised in closed
  form. The prior on ``log e`` is flat over the grid.

- The curves' own error: they are solved to the scene's ``[model]
  tolerance_rel`` (1e-3) on a grid sized for :data:`REFERENCE_MATERIAL`,
  the simulated touches to a quarter of it on one sized for the object
  (:func:`~telethermal.data.generate.touch_contact_model`): the curves
  differ from fingertip-7's touches by 3-5e-4 of the flux early in the
  contact, of one sign: up to 0.3 W/m^2 K, 5-9 times the flux noise per
  sample over a 10 K gap (0.04 W/m^2 K) but on the lowest effusivities.
  The allowance: ``model_error_rel`` (the scene's tolerance) times the rms
  of the touch's samples, added to the noise's variance as if white; and,
  since a systematic error does not average out over samples, a floor: the
  ``ln e`` that moves the curve by the tolerance
  (:func:`~telethermal.ident.intervals.resolution_var`).

- The water pad (the second paper's): its curves are those of the pad
  pre-conditioned to the nominal command (its water warmer than its face,
  so part of the flux is the pad relaxing, not proportional to the gap),
  and ``A``'s prior is drawn as for a Peltier pad (the set point's 0.05 K
  error instead of the pre-conditioning's): both approximations (in
  the 8 of gripper-case-I-pro's seed-0 touches looked at, the true pad sat
  within 0.15 K of its command, the thermocouple's bias included).

The fit: damped Gauss-Newton on the log posterior density in
``(log e, log h / h_ref, tau)`` from the best node of a coarse grid (or from
a previous window's estimate, as a live slave would); the interval is
Laplace's: ``log e +- 1.96 sd`` with ``sd`` from the inverse Gauss-Newton
Hessian (the other two parameters marginalised). An estimate whose
interval reaches the grid's edge says so (``at_bound``). Goodness of fit:
the residual's chi-square against the noise and the allowance; ``fits`` is
False when its p-value is below :data:`FIT_P_MIN` (the object is not what
the model assumes: a coat on another material fails it; a thin plate's
slow fall-off does not within 0.5 s, its estimate drifts down instead).

Cost (``bench unseen``'s ``time_per_estimate_s``): "cold" from the grid's
best node (every node, 9 onsets, at most :data:`START_SAMPLES` samples),
"warm" from the estimate one 50 Hz period before, as a live slave. The
curves: once per scene and object temperature (:mod:`.curvecache`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import NdBSpline, make_interp_spline
from scipy.special import chdtrc

from telethermal.errors import IdentificationError
from telethermal.ident.bspline import SplineAxis
from telethermal.ident.intervals import resolution_var
from telethermal.ident.openset import Z95  # the interval's normal quantile (95 %)
from telethermal.ident.oracle import KernelPrior, draw_nuisances, flux_noise_w_m2, \
    marginal_log_likelihood
from telethermal.ident.prepare import FLUX, MIN_GAP_K, Contacts

#: The grid's objects: this material with k and rho c scaled together.
REFERENCE_MATERIAL = "glass"
#: The effusivity grid's range, W s^0.5/(m^2 K): below the table's foam
#: (42) and above its copper (37 100) by a factor of ~3.
EFFUSIVITY_RANGE_W_S05_M2K = (15.0, 1.2e5)
#: Points of the grid in log e and in log h; the time grid's spacing, s (the
#: Peltier pad's loop period: its junction's current changes once per period).
N_E, N_H, MODEL_DT_S = 29, 9, 1e-3
#: Below this chi-square p-value a fit says the model does not fit.
FIT_P_MIN = 1e-3
#: Samples the coarse start reads at most (a 1 kHz window is strided).
START_SAMPLES = 101
#: The fit stops before an undamped Newton step under this many of the
#: conditional posterior sds in every parameter, and at a step under
#: ROUNDING_STEP_SD sds that lost less than the objective's resolution.
STEP_SD_MIN, ROUNDING_STEP_SD = 1e-5, 1e-3


def refusal(scene, object_temp_c: float | None = None) -> str | None:
    """Why :meth:`EffusivityEstimator.for_scene` refuses ``scene`` (None: it
    does not), without building anything: objects at several temperatures
    and no ``object_temp_c`` given (one family of curves is computed at one
    temperature), or the pad set under :data:`MIN_GAP_K` from the
    objects (a passive pad at the object's temperature; the identifiers'
    gap floor)."""
    if object_temp_c is None:
        temps = sorted({o.temp_c for o in scene.objects})
        if len(temps) != 1:
            return (f"its objects are at {temps} C; give the object temperature the "
                    "estimator's curves are computed at")
        object_temp_c = temps[0]
    gap_k = scene.pad_temp_c(object_temp_c) - object_temp_c
    if abs(gap_k) < MIN_GAP_K:
        return (f"the pad is set {gap_k:g} K from an object at {object_temp_c:g} C: too "
                "little heat flows to estimate anything (a passive pad at the object's "
                "temperature)")
    return None


@dataclass(frozen=True)
class EffusivityEstimate:
    """One window's estimate of one touch.

    ``effusivity_w_s05_m2k`` and ``interval_w_s05_m2k`` (95 %), ``log_sd``
    (the posterior sd of ``ln e``), the fitted contact conductance and
    contact instant on the recorded axis, the residual's ``chi2_per_dof``,
    ``fits`` (its p-value >= :data:`FIT_P_MIN`), ``at_bound`` (the interval
    reaches the grid's edge: clipped there, not calibrated)."""

    effusivity_w_s05_m2k: float
    interval_w_s05_m2k: tuple[float, float]
    log_sd: float
    window_s: float
    n_samples: int
    contact_conductance_w_m2k: float
    onset_offset_s: float
    chi2_per_dof: float
    fits: bool
    at_bound: bool
    theta: tuple[float, float, float]          # (ln e, ln(h / h_ref), tau_s): a warm start

    def covers(self, effusivity_w_s05_m2k: float) -> bool:
        lo, hi = self.interval_w_s05_m2k
        return lo <= effusivity_w_s05_m2k <= hi

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out["interval_w_s05_m2k"] = list(self.interval_w_s05_m2k)
        out.pop("theta")
        return out


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


# ---------------------------------------------------------------- the forward model
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


# ---------------------------------------------------------------- the estimator
class EffusivityEstimator:
    """The Laplace estimate of ``ln e`` (the module's docstring names the
    model, its priors and its approximations).

    Parameters
    ----------
    family : EffusivityFamily
    prior : KernelPrior
        Joint prior of ``(u, tau)``, ``u = ln(h / h_ref)``.
    amplitude : (float, float)
        Mean and sd of ``A``.
    noise_w_m2 : float
        The recorded flux's noise, W/m^2 rms (divided by each touch's gap).
    sample_rate_hz : float
    tau_range_s : (float, float)
        Where the fit may put the contact instant (the prior's support).
    h_ref_w_m2k : float
    object_temp_c : float
        The object temperature the curves were computed at.
    model_error_rel : float
        The curves' own relative error (the simulator's ``[model]
        tolerance_rel`` for a scene): added to the noise's variance as
        ``(model_error_rel * rms(x))^2``, white (the module's docstring).
    """

    def __init__(self, family: EffusivityFamily, prior: KernelPrior, amplitude, noise_w_m2,
                 sample_rate_hz, tau_range_s, h_ref_w_m2k, object_temp_c,
                 model_error_rel: float = 0.0):
        self.family, self.prior = family, prior
        self.amplitude = (float(amplitude[0]), float(amplitude[1]))
        self.noise_w_m2, self.sample_rate_hz = float(noise_w_m2), float(sample_rate_hz)
        self.tau_range_s = (float(tau_range_s[0]), float(tau_range_s[1]))
        self.h_ref_w_m2k, self.object_temp_c = float(h_ref_w_m2k), float(object_temp_c)
        self.model_error_rel = float(model_error_rel)
        self.lo = np.array([family.log_e[0], family.u[0], self.tau_range_s[0]])
        self.hi = np.array([family.log_e[-1], family.u[-1], self.tau_range_s[1]])

    @classmethod
    def for_scene(cls, scene, object_temp_c: float | None = None, max_s: float = 1.0,
                  n_e: int = N_E, n_h: int = N_H, n_prior: int = 2000, n_sessions: int = 20,
                  prior_seed: int = 12345, family=None, flux_gain=None) -> "EffusivityEstimator":
        """The estimator of ``scene``'s pad touches up to ``max_s`` after the
        detected onset, its curves at ``object_temp_c`` (default: the scene's
        objects' temperature, which must then be one). ``family``: what
        builds the curves, :func:`effusivity_family`'s signature (default:
        that function; :func:`telethermal.ident.curvecache.cached_family`
        reads them from disk when it can). ``flux_gain``: (mean, relative sd)
        of a calibration, the amplitude prior's gain (default: the datasheet's)."""
        reason = refusal(scene, object_temp_c)
        if reason is not None:
            raise IdentificationError(f"{scene.name}: {reason}")
        if object_temp_c is None:
            object_temp_c = scene.objects[0].temp_c
        rng = np.random.default_rng(prior_seed)
        draws = draw_nuisances(scene, n_prior, rng, None, n_sessions, flux_gain)
        amp = np.concatenate(list(draws["amp"].values()))
        theta = np.column_stack([draws["u"], draws["tau_s"]])
        u_lo, u_hi = float(draws["u"].min()) - 0.1, float(draws["u"].max()) + 0.1
        tau = (float(draws["tau_s"].min()) - 0.003, float(min(draws["tau_s"].max() + 0.003, 0)))
        curves = (family or effusivity_family)(scene, object_temp_c,
                                               np.linspace(u_lo, u_hi, n_h),
                                               max_s - tau[0] + 0.01, n_e)
        return cls(curves, KernelPrior.scott(theta), (float(np.mean(amp)), float(np.std(amp))),
                   flux_noise_w_m2(scene), scene.sample_rate_hz, tau,
                   scene.pad.contact_conductance_w_m2k, object_temp_c, scene.tolerance_rel)

    # ----------------------------------------------------------- the fit
    def _objective(self, theta, x, s):
        """(log posterior density, gradient, Gauss-Newton Hessian) in theta."""
        a0, sa = self.amplitude
        g, jac = self.family.curve(theta, np.arange(len(x)) / self.sample_rate_hz, deriv=True)
        logl, dg = marginal_log_likelihood(x, g, s, a0, sa)
        lp, lp_grad, lp_hess = self.prior.terms(theta[1:])
        grad = jac.T @ dg
        grad[1:] += lp_grad
        # The Fisher information of x ~ N(a0 g, s I + sa^2 g g^T) in the
        # mean's direction, the amplitude's freedom projected out (as the oracle).
        mj = a0 * jac
        proj = mj - np.outer(g, g @ mj) * (sa ** 2 / (s + sa ** 2 * np.dot(g, g)))
        hess = -(mj.T @ proj) / s
        hess[1:, 1:] += lp_hess
        return logl + lp, grad, hess

    def _start(self, x, s):
        """The best node of the grid (linear in t), tau on a coarse grid; on
        at most :data:`START_SAMPLES` of the samples (evenly strided: a start
        needs only to be near the optimum)."""
        stride = -(-len(x) // START_SAMPLES)
        taus = np.linspace(*self.tau_range_s, 9)
        thetas, g = self.family.nodes(np.arange(0, len(x), stride) / self.sample_rate_hz, taus)
        logl, _ = marginal_log_likelihood(x[::stride], g, s, *self.amplitude)
        return thetas[int(np.argmax(logl))].copy()

    def _fit(self, x, s, start=None):
        """Damped Newton steps from ``start`` (else the grid's best node).

        Done when a step gains under ``1e-9 |value|`` (the objective's
        resolution: its value wanders by ~1e-10 between points 1e-9 apart),
        or before evaluating a step that could not: an undamped step under
        :data:`STEP_SD_MIN` of the conditional posterior sds in every
        parameter, or a step that lost under that resolution while under
        :data:`ROUNDING_STEP_SD` sds (at the optimum to rounding: further
        steps, ever more damped, only wander within the resolution). The
        fit's result is that of evaluating those steps to within a fraction
        of the wander (issue 29; ``tests/unit/test_fit_speed.py``)."""
        theta = self._start(x, s) if start is None else np.clip(np.asarray(start, float),
                                                                 self.lo, self.hi)
        value, grad, hess = self._objective(theta, x, s)
        lam = 1e-3
        for _ in range(50):
            scale = np.sqrt(np.maximum(np.abs(np.diag(hess)), 1e-300))
            a = -hess / np.outer(scale, scale) + lam * np.eye(3)
            new = np.clip(theta + np.linalg.solve(a, grad / scale) / scale, self.lo, self.hi)
            size = float(np.max(np.abs(new - theta) * scale))      # in conditional sds
            if lam <= 1e-3 and size < STEP_SD_MIN:
                break
            v_new, g_new, h_new = self._objective(new, x, s)
            resolution = 1e-9 * max(1.0, abs(value))
            if v_new >= value:
                done = v_new - value < resolution
                theta, value, grad, hess = new, v_new, g_new, h_new
                lam = max(lam / 10, 1e-9)
                if done:
                    break
            elif value - v_new < resolution and size < ROUNDING_STEP_SD:
                break
            else:
                lam *= 10
                if lam > 1e8:
                    break
        return theta, hess

    def estimate(self, x: np.ndarray, gap_k: float, start=None) -> EffusivityEstimate:
        """The estimate from one touch's first samples ``x`` (n,), flux over
        the measured gap ``gap_k`` (W/m^2 K), from the detected onset at
        the scene's rate; ``start``: a previous window's ``theta``."""
        x = np.asarray(x, float)
        if x.ndim != 1 or len(x) < 4 or not np.all(np.isfinite(x)):
            raise IdentificationError(f"an estimate needs >= 4 finite samples, got shape "
                                      f"{x.shape}" + ("" if np.all(np.isfinite(x)) else
                                                      " with NaN or inf"))
        n = len(x)
        if (n - 1) / self.sample_rate_hz > self.family.t_s[-1] + self.tau_range_s[0]:
            raise IdentificationError(f"a {(n - 1) / self.sample_rate_hz:g} s window is longer "
                                      "than the estimator's curves: build it with a larger max_s")
        s = self._noise_var(x, gap_k)
        theta, hess = self._fit(x, s, start)
        sd, (lo, hi), bound = self._interval(theta, hess, resolution_var(self, theta, n))
        return EffusivityEstimate(
            float(math.exp(theta[0])), (lo, hi),
            sd, (n - 1) / self.sample_rate_hz, n, self.h_ref_w_m2k * float(math.exp(theta[1])),
            float(theta[2]), *self._goodness(theta, x, s), bool(bound),
            tuple(float(v) for v in theta))

    def _noise_var(self, x: np.ndarray, gap_k: float, allowance: float = 1.0) -> float:
        """The samples' variance: the flux noise over the gap and the curves'
        allowance (see the module) times ``allowance`` (1: the scene's
        tolerance; calibrated: :mod:`telethermal.ident.intervals`)."""
        return (self.noise_w_m2 / gap_k) ** 2 + \
            allowance * self.model_error_rel ** 2 * float(np.mean(x * x))

    def _interval(self, theta, hess, floor_var: float):
        """(sd of ln e, the 95 % interval in e clipped to the grid, at_bound):
        Laplace's variance plus ``floor_var`` (the resolution floor's)."""
        sd = float(math.sqrt(max(np.linalg.pinv(-hess)[0, 0], 0.0) + floor_var))
        lo, hi = theta[0] - Z95 * sd, theta[0] + Z95 * sd
        return sd, (float(math.exp(max(lo, self.lo[0]))), float(math.exp(min(hi, self.hi[0])))), \
            bool(lo <= self.lo[0] or hi >= self.hi[0])

    def interval_at(self, x: np.ndarray, gap_k: float, theta, allowance: float = 1.0,
                    floor_var: float | None = None) -> tuple[float, float, float, float]:
        """``(e, lo, hi, sd)`` of ``x`` at a fit ``theta`` made of them: the
        interval (W s^0.5/(m^2 K), clipped to the grid) and the sd of ``ln e``
        (unclipped) from the Hessian there, one evaluation, no refit;
        ``allowance``: the factor on the curves' allowance's variance and,
        unless ``floor_var`` (the floor's variance itself) is given, on the
        resolution floor's (:mod:`telethermal.ident.intervals`)."""
        x, theta = np.asarray(x, float), np.asarray(theta, float)
        _, _, hess = self._objective(theta, x, self._noise_var(x, gap_k, allowance))
        sd, (lo, hi), _ = self._interval(theta, hess, allowance * resolution_var(
            self, theta, len(x)) if floor_var is None else floor_var)
        return float(math.exp(theta[0])), lo, hi, sd

    def _goodness(self, theta, x, s, keep=slice(None)):
        """(chi-square per degree of freedom, fits): the residual after the amplitude's
        posterior mean, against the noise (4 fitted), of the samples ``keep`` (the measured)."""
        a0, sa = self.amplitude
        g, x = self.family.curve(theta, np.arange(len(x)) / self.sample_rate_hz)[keep], x[keep]
        amp = (a0 / sa ** 2 + g @ x / s) / (1 / sa ** 2 + g @ g / s) if sa > 0 else a0
        stat = float(np.sum((x - amp * g) ** 2) / s)
        dof = max(len(x) - 4, 1)
        return stat / dof, bool(chdtrc(dof, stat) >= FIT_P_MIN)      # chi2.sf, unchecked

    def estimate_contacts(self, contacts: Contacts, window_s: float) -> list[EffusivityEstimate]:
        """Each touch's estimate at its first ``round(window_s * rate) + 1``
        samples (the identifiers' window)."""
        if contacts.channels[:1] != (FLUX,) or abs(contacts.sample_rate_hz
                                                   - self.sample_rate_hz) > 1e-9:
            raise IdentificationError(
                f"the effusivity estimate reads heat flux at {self.sample_rate_hz:g} Hz; the "
                f"contacts have {contacts.channels} at {contacts.sample_rate_hz:g} Hz")
        n = int(round(window_s * self.sample_rate_hz)) + 1
        short = np.flatnonzero(contacts.lengths < n)
        if len(short):
            raise IdentificationError(f"touch {int(short[0])} is shorter than the "
                                      f"{window_s:g} s window")
        return [self.estimate(contacts.x[i, :n, 0], contacts.gap_k[i]) for i in range(len(contacts))]
