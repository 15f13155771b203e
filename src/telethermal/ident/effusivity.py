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
import math
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtrc

from telethermal.errors import IdentificationError
from telethermal.ident.effusivity_curves import N_E, N_H, EffusivityFamily, effusivity_family
from telethermal.ident.intervals import resolution_var
from telethermal.ident.openset import Z95  # the interval's normal quantile (95 %)
from telethermal.ident.oracle import KernelPrior, draw_nuisances, flux_noise_w_m2, \
    marginal_log_likelihood
from telethermal.ident.prepare import FLUX, MIN_GAP_K, Contacts

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
    def _times(self, n: int, measured=None) -> np.ndarray:
        """The instants (s, from the onset) of a window's ``n`` samples, or
        of its measured ones (``measured`` (n,) bool)."""
        index = np.arange(n) if measured is None else np.flatnonzero(measured)
        return index / self.sample_rate_hz

    def _objective(self, theta, x, s, t_s=None):
        """(log posterior density, gradient, Gauss-Newton Hessian) in theta,
        of the samples ``x`` taken at ``t_s`` (default: every sample from the onset)."""
        a0, sa = self.amplitude
        t_s = self._times(len(x)) if t_s is None else t_s
        g, jac = self.family.curve(theta, t_s, deriv=True)
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

    def _start(self, x, s, t_s):
        """The best node of the grid (linear in t), tau on a coarse grid; on
        at most :data:`START_SAMPLES` of the samples (evenly strided: a start
        needs only to be near the optimum)."""
        stride = -(-len(x) // START_SAMPLES)
        taus = np.linspace(*self.tau_range_s, 9)
        thetas, g = self.family.nodes(t_s[::stride], taus)
        logl, _ = marginal_log_likelihood(x[::stride], g, s, *self.amplitude)
        return thetas[int(np.argmax(logl))].copy()

    def _fit(self, x, s, start=None, t_s=None):
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
        t_s = self._times(len(x)) if t_s is None else t_s
        theta = self._start(x, s, t_s) if start is None else np.clip(np.asarray(start, float),
                                                                      self.lo, self.hi)
        value, grad, hess = self._objective(theta, x, s, t_s)
        lam = 1e-3
        for _ in range(50):
            scale = np.sqrt(np.maximum(np.abs(np.diag(hess)), 1e-300))
            a = -hess / np.outer(scale, scale) + lam * np.eye(3)
            new = np.clip(theta + np.linalg.solve(a, grad / scale) / scale, self.lo, self.hi)
            size = float(np.max(np.abs(new - theta) * scale))      # in conditional sds
            if lam <= 1e-3 and size < STEP_SD_MIN:
                break
            v_new, g_new, h_new = self._objective(new, x, s, t_s)
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

    def estimate(self, x: np.ndarray, gap_k: float, start=None,
                 measured=None) -> EffusivityEstimate:
        """The estimate from one touch's first samples ``x`` (n,), flux over
        the measured gap ``gap_k`` (W/m^2 K), from the detected onset at
        the scene's rate; ``start``: a previous window's ``theta``.
        ``measured`` (n,) bool, None for all: the samples the sensor
        delivered; the others (a frame lost on the line, filled in by the
        driver) are missing data: the fit, its residual and its degrees of
        freedom read the measured samples alone, at their own instants
        (``n_samples`` counts them)."""
        x = np.asarray(x, float)
        keep = None if measured is None else np.asarray(measured, bool)
        if keep is not None and keep.shape != x.shape:
            raise IdentificationError(f"measured flags shape {keep.shape} for samples of shape "
                                      f"{x.shape}: one flag per sample")
        if x.ndim != 1 or (len(x) if keep is None else int(keep.sum())) < 4 or \
                not np.all(np.isfinite(x)):
            raise IdentificationError(f"an estimate needs >= 4 finite measured samples, got "
                                      f"shape {x.shape}" + ("" if keep is None else
                                                            f", {int(keep.sum())} measured")
                                      + ("" if np.all(np.isfinite(x)) else " with NaN or inf"))
        n = len(x)
        if (n - 1) / self.sample_rate_hz > self.family.t_s[-1] + self.tau_range_s[0]:
            raise IdentificationError(f"a {(n - 1) / self.sample_rate_hz:g} s window is longer "
                                      "than the estimator's curves: build it with a larger max_s")
        t_s, xs = self._times(n, keep), (x if keep is None else x[keep])
        s = self.noise_var(xs, gap_k)
        theta, hess = self._fit(xs, s, start, t_s)
        sd, (lo, hi), bound = self._interval(theta, hess, resolution_var(self, theta, n))
        return EffusivityEstimate(
            float(math.exp(theta[0])), (lo, hi),
            sd, (n - 1) / self.sample_rate_hz, len(xs),
            self.h_ref_w_m2k * float(math.exp(theta[1])),
            float(theta[2]), *self.goodness(theta, x, s, slice(None) if keep is None else keep),
            bool(bound), tuple(float(v) for v in theta))

    def noise_var(self, x: np.ndarray, gap_k: float, allowance: float = 1.0) -> float:
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
                    floor_var: float | None = None,
                    measured=None) -> tuple[float, float, float, float]:
        """``(e, lo, hi, sd)`` of ``x`` at a fit ``theta`` made of them: the
        interval (W s^0.5/(m^2 K), clipped to the grid) and the sd of ``ln e``
        (unclipped) from the Hessian there, one evaluation, no refit;
        ``allowance``: the factor on the curves' allowance's variance and,
        unless ``floor_var`` (the floor's variance itself) is given, on the
        resolution floor's (:mod:`telethermal.ident.intervals`); ``measured``:
        as :meth:`estimate`'s."""
        x, theta = np.asarray(x, float), np.asarray(theta, float)
        t_s = self._times(len(x), measured)
        x = x if measured is None else x[np.asarray(measured, bool)]
        _, _, hess = self._objective(theta, x, self.noise_var(x, gap_k, allowance), t_s)
        sd, (lo, hi), _ = self._interval(theta, hess, allowance * resolution_var(
            self, theta, len(x)) if floor_var is None else floor_var)
        return float(math.exp(theta[0])), lo, hi, sd

    def goodness(self, theta, x, s, keep=slice(None)):
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
