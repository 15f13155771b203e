"""The physical limit of identification: an oracle that knows the simulator.

:class:`Oracle` decides a touch by its likelihood under each material,
computed from the generative model of :func:`~telethermal.data.generate.pad_database`
itself, on the same :class:`~telethermal.ident.prepare.Contacts` the methods
see (``x``: the recorded flux over the *measured* gap, samples from the
detected onset). Equal priors over materials. No method that learns from the
same touches can beat its Bayes rule but for the approximations below.

What a touch of material ``m`` is, in the units of ``x`` (W/m^2 K)::

    x_k = A * g_m(t_k - tau; h) + e_k,   t_k = k / rate

- ``g_m(t; h)``: the flux sensor's lagged reading of the contact flux per
  kelvin of true gap, ``t`` after the true contact, for contact conductance
  ``h``: the scene's Peltier pad on its module and heat sink, the junction
  held by the pad's 1 kHz loop (:class:`~telethermal.physics.held_pad.HeldPad`
  through ``generate._held_pad_contact``, on the touches' own grid,
  :func:`~telethermal.data.generate.touch_contact_model`: pad layers, the object's finite
  thickness, the junction's droop, the sensor's lag), computed noise-free at
  the nominal temperatures (object at its ``temp_c``, pad ``gap_k`` above)
  on a grid of ``log h`` and of ``t`` and interpolated by a bicubic spline
  (error ~1e-6 W/m^2 K, against a noise of ~0.04). The flux is linear in the
  gap up to the droop's nonlinearity: a touch's true temperatures (0.3 K
  from nominal) change ``g`` by ~2e-4 W/m^2 K, 0.5 % of the noise; neglected
  (``tests/unit/test_oracle.py`` measures it against a simulated trial).
- ``h = h_ref (F / F_ref)^exponent`` with the force ``F ~ N(force_n,
  force_sd_n)`` clipped to [0.3, 3] ``force_n`` (``[variability]``, ``_draw``).
- ``tau``: the true contact instant on the recorded axis (``onset_offset_s``):
  the onset jitter ``N(0, onset_jitter_s)`` clipped at 3 sd (``_draw``) less
  the onset that :class:`~telethermal.control.contact.ContactDetector` finds
  in the force sensor's trace (its rise and noise, ``ForceSensor``), which
  also depends on ``F``. The joint prior of ``(log h, tau)`` is a Gaussian
  kernel density of Monte Carlo draws through those very functions
  (``_draw``, ``ForceSensor.read_n``, ``detected_onset_s``).
- ``A = gain * (true gap) / (measured gap)``: the flux sensor's gain
  (``draw_instruments``, fixed per scene), the object's true temperature
  ``N(temp_c, object_temp_sd_c)``, its measurement by the session's
  calibrated object thermometer (bias left by the calibration, per-reading
  noise, resolution), the pad's set point from it, the pad's thermocouple
  bias and set-point error ``N(0, PELTIER_SETPOINT_SD_K)``, its reading of
  the pad before contact and the manifest's rounding to 1 mK: drawn by Monte
  Carlo through the generator's own code per material and summarised by a
  Gaussian (mean, sd: ~1 % wide). ``A`` enters linearly: it is marginalised
  in closed form.
- ``e_k``: the flux sensor's noise and its ADC's quantisation
  (``HeatFluxSensor``: ``flux_noise_uv`` rms and ``adc_lsb_uv^2 / 12``,
  over its sensitivity), white and Gaussian, over the touch's measured gap.

The session: with ``seed``, :meth:`Oracle.for_scene` rebuilds the session
``pad_database(scene, default_rng(seed))`` draws first (its thermometer's
bias and calibration), as methods trained on that session's touches have
it in their data; without, the amplitude's prior pools many sessions.

Approximations: the integral over ``(log h, tau)`` is Laplace's around the
best fit (the likelihood is many orders sharper than the prior, so the
posterior there is Gaussian; the Hessian is Gauss-Newton's, exact at a fit
within noise, plus the prior's own); the kernel density smooths the prior's
edges (the onset's offset lies on a 10 ms sampling grid) by ~1 ms; ``A``'s
prior is Gaussian. Touches on a water pad are not modelled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RectBivariateSpline
from scipy.special import logsumexp

from telethermal.errors import IdentificationError
from telethermal.ident.prepare import FLUX, Contacts, window_key

#: Spacing of the forward model's time grid, s (the spline's knots).
MODEL_DT_S = 5e-4
#: Points of the forward model's grid in log h.
MODEL_N_H = 41


@dataclass(frozen=True)
class KernelPrior:
    """A Gaussian kernel density over draws ``theta`` (n, d) with bandwidth
    matrix ``bandwidth`` (d, d): log density, gradient and Hessian exact."""

    theta: np.ndarray
    bandwidth: np.ndarray

    @classmethod
    def scott(cls, theta: np.ndarray) -> "KernelPrior":
        """Scott's rule (``scipy.stats.gaussian_kde``'s default)."""
        n, d = theta.shape
        cov = np.atleast_2d(np.cov(theta, rowvar=False))
        return cls(np.asarray(theta, float), cov * n ** (-2.0 / (d + 4)))

    def __post_init__(self):
        inv = np.linalg.inv(self.bandwidth)
        norm = -0.5 * (len(inv) * np.log(2 * np.pi) + np.linalg.slogdet(self.bandwidth)[1])
        object.__setattr__(self, "_inv", inv)
        object.__setattr__(self, "_norm", norm - np.log(len(self.theta)))
        # What terms() needs that does not change between calls: B^-1 = L L^T
        # and the draws whitened, z_k = L^T (theta_k - centre), as (d, n) rows.
        chol = np.linalg.cholesky(inv)
        centre = np.mean(self.theta, axis=0)
        object.__setattr__(self, "_chol", chol)
        object.__setattr__(self, "_centre", centre)
        object.__setattr__(self, "_white", np.ascontiguousarray(chol.T @ (self.theta - centre).T))

    def terms(self, point):
        """(log density, gradient, Hessian) at ``point`` (d,). With ``z_k =
        L^T (point - theta_k)`` (``B^-1 = L L^T``): ``log w_k = -|z_k|^2 / 2``,
        gradient ``-L sum_k w_k z_k``, Hessian ``L (sum_k w_k z_k z_k^T) L^T
        - grad grad^T - B^-1`` (w normalised): the kernels' sums in the
        whitened draws, precomputed (equal to the direct sums to rounding)."""
        z = (self._chol.T @ (np.asarray(point, float) - self._centre))[:, None] - self._white
        log_w = -0.5 * np.einsum("ij,ij->j", z, z)
        top = log_w.max()
        w = np.exp(log_w - top)
        total = w.sum()
        w /= total
        grad = -(self._chol @ (z @ w))
        hess = self._chol @ ((z * w) @ z.T) @ self._chol.T - np.outer(grad, grad) - self._inv
        return top + np.log(total) + self._norm, grad, hess


@dataclass(frozen=True)
class CurveFamily:
    """One material's unit-gap sensed flux ``g(t; u)``, ``u = log(h / h_ref)``,
    on a grid, as a bicubic spline; ``u`` and ``tau`` bounded by the grid."""

    spline: RectBivariateSpline
    u_range: tuple[float, float]
    t_max_s: float

    @classmethod
    def from_grid(cls, u, t_s, g) -> "CurveFamily":
        return cls(RectBivariateSpline(u, t_s, g, kx=3, ky=3), (float(u[0]), float(u[-1])),
                   float(t_s[-1]))

    def curve(self, u: float, times_s: np.ndarray, deriv: bool = False):
        """g at ``times_s`` (after contact) for ``u``; with ``deriv``, also
        its derivatives in u and in t."""
        uu = np.full(times_s.shape, u)
        g = self.spline.ev(uu, times_s)
        if not deriv:
            return g
        return g, self.spline.ev(uu, times_s, dx=1), self.spline.ev(uu, times_s, dy=1)


def marginal_log_likelihood(x, g, noise_var, amp_mean, amp_sd):
    """log N(x; a0 g, s I + sa^2 g g^T) over the last axis: ``x = A g + e``
    with ``A ~ N(amp_mean, amp_sd^2)`` marginalised, ``e ~ N(0, s I)``.
    Broadcasts over the leading axes of ``g``; returns also d/dg."""
    s, sa2, a0 = noise_var, amp_sd ** 2, amp_mean
    gg = np.sum(g * g, axis=-1)
    gx = np.sum(g * x, axis=-1)
    r = x - a0 * g
    rr = np.sum(r * r, axis=-1)
    gr = gx - a0 * gg
    big_d = s + sa2 * gg
    n = x.shape[-1]
    logl = (-0.5 * (rr / s - sa2 * gr ** 2 / (s * big_d)) - 0.5 * n * np.log(2 * np.pi * s)
            - 0.5 * np.log(big_d / s))
    e = (lambda v: v) if g.ndim == 1 else (lambda v: np.expand_dims(v, -1))
    dg = (a0 * r / s + (sa2 / s) * (e(gr / big_d) * (x - 2 * a0 * g)
                                    - sa2 * e(gr ** 2 / big_d ** 2) * g)
          - sa2 * g / e(big_d))
    return logl, dg


class Oracle:
    """The Bayes rule of the simulator's pad touches (the module's docstring
    names the model, its nuisances and its approximations).

    Parameters
    ----------
    curves : dict[str, CurveFamily]
        Each material's unit-gap sensed flux over ``(log h, t)``.
    prior : KernelPrior
        Joint prior of ``(u, tau)``, ``u = log(h / h_ref)``.
    amplitude : dict[str, tuple[float, float]]
        Each material's (mean, sd) of ``A``.
    noise_w_m2 : float
        The recorded flux's noise, W/m^2 rms (divided by each touch's gap).
    sample_rate_hz : float
    tau_range_s : (float, float)
        Where the fit may put the contact instant (the prior's support).
    """

    def __init__(self, curves: dict, prior: KernelPrior, amplitude: dict, noise_w_m2: float,
                 sample_rate_hz: float, tau_range_s: tuple[float, float]):
        self.materials = list(curves)
        self.curves, self.prior, self.amplitude = curves, prior, amplitude
        self.noise_w_m2, self.sample_rate_hz = float(noise_w_m2), float(sample_rate_hz)
        self.tau_range_s = (float(tau_range_s[0]), float(tau_range_s[1]))
        self._starts: dict = {}

    # ----------------------------------------------------------- building
    @classmethod
    def for_scene(cls, scene, seed: int | None = None, max_s: float = 1.0,
                  n_prior: int = 3500, n_sessions: int = 20, prior_seed: int = 12345,
                  n_h: int = MODEL_N_H) -> "Oracle":
        """The oracle of ``scene``'s pad database up to ``max_s`` after the
        detected onset; ``seed``: the session of ``pad_database(scene,
        np.random.default_rng(seed))`` (else the amplitude's prior pools
        ``n_sessions`` sessions). ``n_prior`` Monte Carlo draws in all
        (split over the materials), from ``prior_seed``; ``n_h`` points of
        the forward model's grid in log h."""
        if scene.pad.kind != "peltier":
            raise IdentificationError(f"{scene.name}: the oracle models a Peltier pad, "
                                      f"not a {scene.pad.kind} pad")
        rng = np.random.default_rng(prior_seed)
        draws = draw_nuisances(scene, n_prior, rng, seed, n_sessions)
        theta = np.column_stack([draws["u"], draws["tau_s"]])
        lo = np.quantile(draws["u"], 0.0) - 0.1, np.quantile(draws["u"], 1.0) + 0.1
        tau = (float(draws["tau_s"].min()) - 0.003, float(min(draws["tau_s"].max() + 0.003, 0)))
        curves = forward_curves(scene, np.linspace(lo[0], lo[1], n_h),
                                max_s - tau[0] + 0.01)
        amplitude = {m: (float(np.mean(a)), float(np.std(a))) for m, a in draws["amp"].items()}
        return cls(curves, KernelPrior.scott(theta), amplitude, flux_noise_w_m2(scene),
                   scene.sample_rate_hz, tau)

    # ----------------------------------------------------------- evidence
    def _coarse(self, material: str, n: int):
        """Curves on a coarse (u, tau) grid at the first ``n`` samples: starts."""
        key = (material, n)
        if key not in self._starts:
            fam = self.curves[material]
            u = np.linspace(*fam.u_range, 29)
            tau = np.linspace(*self.tau_range_s, 25)
            t = np.arange(n) / self.sample_rate_hz
            uu, tt = np.meshgrid(u, tau, indexing="ij")
            g = fam.spline.ev(np.repeat(uu.ravel(), n), (t[None, :] - tt.ravel()[:, None]).ravel())
            self._starts[key] = (np.column_stack([uu.ravel(), tt.ravel()]),
                                 g.reshape(len(u) * len(tau), n))
        return self._starts[key]

    def _objective(self, material, theta, x, s, with_hess=True):
        """(log posterior density, gradient, Gauss-Newton Hessian) in (u, tau)."""
        fam, (a0, sa) = self.curves[material], self.amplitude[material]
        t = np.arange(len(x)) / self.sample_rate_hz - theta[1]
        g, g_u, g_t = fam.curve(theta[0], t, deriv=True)
        logl, dg = marginal_log_likelihood(x, g, s, a0, sa)
        jac = np.column_stack([g_u, -g_t])                  # d g / d(u, tau)
        lp, lp_grad, lp_hess = self.prior.terms(theta)
        grad = jac.T @ dg + lp_grad
        if not with_hess:
            return logl + lp, grad, None
        # Gauss-Newton: the Fisher information of x ~ N(a0 g, s I + sa^2 g g^T)
        # in the mean's direction (the amplitude's freedom projected out).
        c = s + sa ** 2 * np.dot(g, g)
        mj = a0 * jac
        proj = mj - np.outer(g, g @ mj) * (sa ** 2 / c)
        hess = -(mj.T @ proj) / s + lp_hess
        return logl + lp, grad, hess

    def _fit(self, material, x, s):
        """Maximise the log posterior density in (u, tau) from the coarse
        grid's best start by damped Newton steps; (best theta, value, Hessian)."""
        starts, g = self._coarse(material, len(x))
        a0, sa = self.amplitude[material]
        coarse, _ = marginal_log_likelihood(x, g, s, a0, sa)
        theta = starts[int(np.argmax(coarse))].copy()
        lo = np.array([self.curves[material].u_range[0], self.tau_range_s[0]])
        hi = np.array([self.curves[material].u_range[1], self.tau_range_s[1]])
        value, grad, hess = self._objective(material, theta, x, s)
        lam = 1e-3
        for _ in range(40):
            scale = np.sqrt(np.maximum(np.abs(np.diag(hess)), 1e-300))
            a = -hess / np.outer(scale, scale) + lam * np.eye(2)
            step = np.linalg.solve(a, grad / scale) / scale
            new = np.clip(theta + step, lo, hi)
            v_new, g_new, h_new = self._objective(material, new, x, s)
            if v_new >= value:
                done = v_new - value < 1e-6 * max(1.0, abs(value)) * 1e-3
                theta, value, grad, hess = new, v_new, g_new, h_new
                lam = max(lam / 10, 1e-9)
                if done:
                    break
            elif value - v_new < 1e-12 * max(1.0, abs(value)):
                break                                   # at the optimum to rounding
            else:
                lam *= 10
                if lam > 1e8:
                    break
        return theta, value, hess

    def log_evidence(self, x: np.ndarray, gap_k: float) -> np.ndarray:
        """log p(x | material) for each material (``self.materials``), one
        touch's first samples ``x`` (n,) normalised by its gap ``gap_k``."""
        s = (self.noise_w_m2 / gap_k) ** 2
        out = np.empty(len(self.materials))
        for i, m in enumerate(self.materials):
            _, value, hess = self._fit(m, x, s)
            sign, logdet = np.linalg.slogdet(-hess)
            out[i] = value + np.log(2 * np.pi) - 0.5 * logdet if sign > 0 else value
        return out

    def log_likelihood(self, contacts: Contacts, window_s: float) -> np.ndarray:
        """(n_touches, n_materials): log p of each touch's first
        ``round(window_s * rate) + 1`` samples (the methods' window)."""
        if contacts.channels[:1] != (FLUX,) or abs(contacts.sample_rate_hz
                                                   - self.sample_rate_hz) > 1e-9:
            raise IdentificationError("the oracle reads heat flux at the scene's sample rate")
        n = int(round(window_s * self.sample_rate_hz)) + 1
        if np.any(contacts.lengths < n):
            raise IdentificationError(f"a touch is shorter than the {window_s:g} s window")
        return np.array([self.log_evidence(contacts.x[i, :n, 0], contacts.gap_k[i])
                         for i in range(len(contacts))])

    def posterior(self, contacts: Contacts, window_s: float) -> np.ndarray:
        """(n_touches, n_materials) posterior, equal priors over materials."""
        ll = self.log_likelihood(contacts, window_s)
        return np.exp(ll - logsumexp(ll, axis=1, keepdims=True))

    def accuracy_by_window(self, contacts: Contacts, windows_s, merge=None) -> dict:
        """{window key: {"accuracy", "correct", "n", "predicted"}}: the
        maximum a posteriori material against the truth (``merge`` maps
        materials to merged classes, as ``FIRST_PAPER_MERGE``)."""
        merge = merge or {}
        out = {}
        for w in windows_s:
            guess = [self.materials[k] for k in self.posterior(contacts, w).argmax(axis=1)]
            hits = [merge.get(a, a) == merge.get(b, b) for a, b in zip(guess, contacts.labels)]
            out[window_key(w)] = {"accuracy": float(np.mean(hits)), "correct": int(sum(hits)),
                                  "n": len(hits), "predicted": guess}
        return out


# ---------------------------------------------------------------- the scene's model
def flux_noise_w_m2(scene) -> float:
    """The recorded flux's noise, W/m^2 rms: the amplifier's noise and the
    ADC's quantisation (``lsb^2 / 12``) over the sensor's sensitivity, as
    the scene's ``[sensors]`` configure them."""
    return scene.sensors.flux_noise_w_m2()


def forward_curves(scene, u_grid, t_max_s: float, dt_s: float = MODEL_DT_S) -> dict:
    """Each material's noise-free unit-gap sensed flux on ``u_grid`` x
    [0, t_max_s]: the generator's own held-pad contact at the nominal
    temperatures (object at its ``temp_c``, pad at the scene's set point
    for it), divided by that gap."""
    from telethermal.data.generate import _Contacts, _held_pad_contact, touch_contact_model
    u = np.asarray(u_grid, float)
    h = scene.pad.contact_conductance_w_m2k * np.exp(u)
    t = np.arange(int(np.ceil(t_max_s / dt_s)) + 1) * dt_s
    curves = {}
    for obj in scene.objects:
        model, _ = touch_contact_model(scene, obj)
        pad_c = scene.pad_temp_c(obj.temp_c)
        gap = pad_c - obj.temp_c
        b = len(u)
        draws = _Contacts(np.zeros(b), h, np.zeros(b), np.full(b, obj.temp_c), np.zeros(b))
        result = _held_pad_contact(scene, obj, model, t, np.full(b, pad_c), draws)
        curves[obj.name] = CurveFamily.from_grid(u, t, result.flux_sensed_w_m2 / gap)
    return curves


def draw_nuisances(scene, n: int, rng: np.random.Generator, seed: int | None = None,
                   n_sessions: int = 20, flux_gain: tuple[float, float] | None = None) -> dict:
    """Monte Carlo draws of a pad touch's nuisances through the generator's
    own code (``pad_database``, ``_draw``, ``_record``): ``u = log(h /
    h_ref)`` and ``tau_s`` (the true contact on the recorded axis), pooled,
    and per material the amplitude ``A = gain * true gap / measured gap``.
    ``seed``: the session of ``pad_database(scene, default_rng(seed))``;
    else ``n_sessions`` sessions drawn from ``rng``. ``flux_gain``: (mean,
    relative sd) of the flux sensor's gain from a calibration, drawn per
    session instead of the datasheet's limit (the scene's instruments)."""
    from telethermal.data.generate import (PELTIER_SETPOINT_SD_K, _draw, _time_axis,
                                           detected_onset_s, sensor_session)
    from telethermal.physics.scene import ONSET_MARGIN_S
    from telethermal.physics.sensors import ForceSensor, Thermocouple
    sessions = ([sensor_session(scene, np.random.default_rng(seed))] if seed is not None
                else [sensor_session(scene, rng) for _ in range(n_sessions)])
    times = _time_axis(scene, scene.pad.contact_duration_s + ONSET_MARGIN_S)
    h_ref = scene.pad.contact_conductance_w_m2k
    per = max(2, -(-n // (len(scene.objects) * len(sessions))))
    u, tau, amp = [], [], {}
    for obj in scene.objects:
        a_obj = []
        for session in sessions:
            inst = session.instruments
            d = _draw(scene, obj, per, h_ref, rng, session)
            command = np.array([scene.pad_temp_c(t) for t in d.object_ir_c])
            pad_c = command - inst.pad_tc_bias_k + rng.normal(0.0, PELTIER_SETPOINT_SD_K, per)
            before = Thermocouple(cold_junction_c=scene.room_temp_c,
                                  bias_k=inst.pad_tc_bias_k).read_c(pad_c, rng)
            measured = np.round(before, 3) - np.round(d.object_ir_c, 3)
            gain = inst.flux_gain if flux_gain is None else \
                flux_gain[0] * (1.0 + flux_gain[1] * rng.standard_normal())
            a_obj.append(gain * (pad_c - d.object_true_c) / measured)
            for i in range(per):
                force = ForceSensor().read_n(times - d.onset_s[i], d.force_n[i], rng)
                tau.append(d.onset_s[i] - detected_onset_s(times, force))
            u.append(np.log(d.conductance_w_m2k / h_ref))
        amp[obj.name] = np.concatenate(a_obj)
    return {"u": np.concatenate(u), "tau_s": np.array(tau), "amp": amp}
