"""Choose the cheapest contact model that is accurate enough for a run.

Two models share one call, ``solve(t_s, temp_a_c, temp_b_c, conductance_w_m2k,
..., sensor_lag_s=None) -> ContactResult``:

- :class:`AnalyticContact`: two homogeneous semi-infinite bodies with a contact
  conductance (closed form with erfcx). Exact where it applies: chosen when
  both sides are one layer each and the first image term of each finite
  thickness, ``2 exp(-L^2 / (alpha t_max))``, is under the tolerance.
- :class:`~telethermal.physics.layered.LayeredContact`: everything else (thin
  layers, a finite object); its grid is sized to the run's penetration depths
  and its spatial error is estimated against a run on a twice-refined grid.

:func:`choose_model` returns the model and a :class:`ModelChoice` saying which
was chosen, why, and its error bound.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.special import erfcx

from telethermal.errors import ModelError
from telethermal.physics.contact import semi_infinite_error_bound
from telethermal.physics.layered import Boundary, ContactResult, Layer, LayeredContact

#: Sub-steps per sensor time constant when lagging a closed form.
_LAG_SUBSTEPS_PER_TAU = 200


@dataclass(frozen=True, slots=True)
class ModelChoice:
    """Which model a run uses, why, and how far it may be off (relative flux)."""

    kind: str            # "analytic" or "layered"
    reason: str
    error_bound_rel: float
    n_cells: int = 0
    min_dx_m: float = 0.0

    def describe(self) -> str:
        grid = f", {self.n_cells} cells, min dx {self.min_dx_m:.2e} m" if self.n_cells else ""
        return f"{self.kind} (error <= {self.error_bound_rel:.1e}{grid}): {self.reason}"


def first_order_lag(t_s: np.ndarray, values: np.ndarray, tau_s: float) -> np.ndarray:
    """Lag a signal with time constant ``tau_s`` from a zero state at ``t_s[0]``,
    exactly for an input that is linear between samples (first-order hold).

    The grid may be non-uniform (a geometric grid follows a 1/sqrt(t) flux
    with a few thousand points). With E_k = exp(-h_k / tau) the recursion
    ``y[k+1] = E_k y[k] + u_k`` is summed in closed form,
    ``y[n] = exp(-(t_n - t_s)/tau) (y[s] + sum_k exp((t_{k+1} - t_s)/tau) u_k)``,
    in blocks short enough that the exponentials cannot overflow.

    Parameters
    ----------
    t_s : ndarray, shape (n,), increasing
    values : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n)
    """
    t = np.asarray(t_s, dtype=np.float64)
    q = np.asarray(values, dtype=np.float64)
    h = np.diff(t)
    if np.any(h <= 0):
        raise ModelError("first_order_lag needs increasing times")
    decay = np.exp(-h / tau_s)
    ramp = -tau_s * np.expm1(-h / tau_s) / h
    u = (1.0 - ramp) * q[..., 1:] + (ramp - decay) * q[..., :-1]
    y = np.zeros_like(q)
    start = 0
    while start < len(t) - 1:
        stop = int(np.searchsorted(t, t[start] + 300.0 * tau_s, side="right"))
        stop = min(max(stop, start + 2), len(t))
        rel = (t[start + 1:stop] - t[start]) / tau_s
        acc = np.cumsum(np.exp(rel) * u[..., start:stop - 1], axis=-1)
        y[..., start + 1:stop] = np.exp(-rel) * (y[..., start:start + 1] + acc)
        start = stop - 1
    return y


class AnalyticContact:
    """Two semi-infinite bodies in contact, batched; same call as LayeredContact."""

    def __init__(self, material_a, material_b):
        self.material_a, self.material_b = material_a, material_b

    def solve(self, t_s, temp_a_c, temp_b_c, conductance_w_m2k=math.inf,
              k_scale_a=1.0, heat_scale_a=1.0, k_scale_b=1.0, heat_scale_b=1.0,
              sensor_lag_s=None, energy=False, **_ignored) -> ContactResult:
        t = np.asarray(t_s, dtype=np.float64)
        if t.ndim not in (1, 2):
            raise ModelError(f"t_s must have shape (n,) or (batch, n), got {t.shape}")
        ta, tb, h, ka, ha, kb, hb = (np.atleast_1d(np.asarray(v, dtype=np.float64))[:, None]
                                     for v in np.broadcast_arrays(
                                         np.atleast_1d(temp_a_c), np.atleast_1d(temp_b_c),
                                         np.atleast_1d(conductance_w_m2k),
                                         np.atleast_1d(k_scale_a), np.atleast_1d(heat_scale_a),
                                         np.atleast_1d(k_scale_b), np.atleast_1d(heat_scale_b)))
        if not np.all(h > 0):
            raise ModelError(f"contact conductance must be > 0, got {h.min()}")
        if energy:
            raise ModelError("heat-balance accounting needs the layered model")
        e_a = self.material_a.effusivity * np.sqrt(ka * ha)
        e_b = self.material_b.effusivity * np.sqrt(kb * hb)
        flux, settled = self._unit(t, h, e_a, e_b)
        gap = ta - tb
        if sensor_lag_s:
            if np.any(np.isinf(h)):
                raise ModelError("a sensor lag on a perfect contact needs the layered model")
            sensed = self._lag(t, h, e_a, e_b, sensor_lag_s) * gap
        else:
            sensed = None
        return ContactResult(
            t_s=t, flux_w_m2=flux * gap,
            surface_temp_a_c=ta - gap * e_b / (e_a + e_b) * settled,
            surface_temp_b_c=tb + gap * e_a / (e_a + e_b) * settled,
            flux_sensed_w_m2=sensed)

    @classmethod
    def _lag(cls, t, h, e_a, e_b, tau_s):
        """Lagged unit flux at times ``t``: the closed form on a geometric grid
        (ratio 1 + 1/_LAG_SUBSTEPS_PER_TAU, from tau/_LAG_SUBSTEPS_PER_TAU^2),
        lagged exactly with first-order hold, interpolated to ``t``."""
        t_end = float(np.max(t, initial=0.0))
        if t_end <= 0:
            return np.zeros(np.broadcast_shapes(t.shape, (len(h), t.shape[-1])))
        first = tau_s / _LAG_SUBSTEPS_PER_TAU**2
        ratio = 1.0 + 1.0 / _LAG_SUBSTEPS_PER_TAU
        n = max(int(np.ceil(np.log(max(t_end / first, 1.0)) / np.log(ratio))) + 2, 3)
        fine = np.concatenate([[0.0], first * ratio ** np.arange(n)])
        # The sensor sees the flux from t = 0+ (h * gap), not the 0 of t = 0.
        fine_plus = np.where(fine > 0, fine, np.finfo(np.float64).tiny)
        lagged = first_order_lag(fine, cls._unit(fine_plus, h, e_a, e_b)[0], tau_s)
        rows = np.broadcast_to(t, (len(lagged), t.shape[-1]))
        sensed = np.stack([np.interp(ti, fine, row) for ti, row in zip(rows, lagged)])
        return np.where(rows > 0, sensed, 0.0)

    @staticmethod
    def _unit(t, h, e_a, e_b):
        """Flux per kelvin of gap, and the settled fraction of eq. (10)."""
        after = t > 0
        root_t = np.sqrt(np.where(after, t, 0.0))
        finite = np.isfinite(h)
        a = np.where(finite, h, 1.0) * (1.0 / e_a + 1.0 / e_b)
        with np.errstate(divide="ignore"):
            perfect = e_a * e_b / (e_a + e_b) / (math.sqrt(math.pi) * root_t)
        flux = np.where(finite, np.where(finite, h, 0.0) * erfcx(a * root_t), perfect)
        settled = np.where(finite, 1.0 - erfcx(a * root_t), 1.0)
        return np.where(after, flux, 0.0), np.where(after, settled, 0.0)


def choose_model(side_a: Sequence[Layer], side_b: Sequence[Layer], back_a: Boundary,
                 back_b: Boundary, t_min_s: float, t_max_s: float,
                 tolerance_rel: float = 1e-3, nominal_conductance_w_m2k: float = math.inf):
    """Return ``(model, ModelChoice)`` for contacts lasting up to ``t_max_s``
    and sampled from ``t_min_s`` on. The choice is remembered (models are
    immutable once built), so a scene pays for it once per process;
    ``choose_model.cache_clear()`` forgets.

    Raises
    ------
    ModelError
        If no model reaches ``tolerance_rel`` (a layered grid that cannot be
        refined enough) or the inputs make no sense.
    """
    return _choose_cached(tuple(side_a), tuple(side_b), back_a, back_b, float(t_min_s),
                          float(t_max_s), float(tolerance_rel), float(nominal_conductance_w_m2k))


choose_model.cache_clear = lambda: _choose_cached.cache_clear()


@functools.lru_cache(maxsize=256)
def _choose_cached(side_a, side_b, back_a, back_b, t_min_s, t_max_s, tolerance_rel,
                   nominal_conductance_w_m2k):
    if not 0 < tolerance_rel < 1:
        raise ModelError(f"tolerance_rel must be in (0, 1), got {tolerance_rel}")
    if len(side_a) == 1 and len(side_b) == 1:
        bounds = [semi_infinite_error_bound(layer.thickness_m, layer.material.diffusivity_m2_s,
                                            t_max_s) for layer in (side_a[0], side_b[0])]
        bound = max(bounds)
        if bound <= tolerance_rel:
            depth = max(math.sqrt(la.material.diffusivity_m2_s * t_max_s)
                        for la in (side_a[0], side_b[0]))
            return AnalyticContact(side_a[0].material, side_b[0].material), ModelChoice(
                "analytic", f"both bodies homogeneous; penetration depth {depth:.2e} m over "
                f"{t_max_s:g} s stays inside each", bound)
        reason = (f"a finite thickness matters (semi-infinite error {bound:.1e} > "
                  f"tolerance {tolerance_rel:.0e})")
    else:
        reason = f"stacked layers ({len(side_a)} | {len(side_b)})"
    return layered_model(side_a, side_b, back_a, back_b, t_min_s, t_max_s, tolerance_rel,
                    nominal_conductance_w_m2k, reason)


def layered_model(side_a, side_b, back_a, back_b, t_min_s, t_max_s, tol, conductance, reason):
    """The coarsest layered grid of a refinement ladder whose estimated error
    meets ``tol``; returns ``(model, ModelChoice)`` (``reason`` says why)."""
    t = np.geomspace(t_min_s, t_max_s, 200)
    previous = None
    for resolution, growth in ((0.4, 1.3), (0.2, 1.2), (0.1, 1.15), (0.05, 1.1), (0.025, 1.05)):
        model = LayeredContact(side_a, side_b, back_a, back_b, t_min_s, t_max_s,
                               resolution, growth)
        finer = LayeredContact(side_a, side_b, back_a, back_b, t_min_s, t_max_s,
                               resolution / 2, 1 + (growth - 1) / 2)
        q = model.solve(t, 1.0, 0.0, conductance).flux_w_m2[0]
        q_fine = finer.solve(t, 1.0, 0.0, conductance).flux_w_m2[0]
        # Second-order in space: the error of the coarse grid is about 4/3 of
        # its distance to the refined one; quote that, rounded up.
        err = float(np.max(np.abs(q - q_fine) / np.abs(q_fine)) * 4.0 / 3.0)
        previous = (model, err)
        if err <= tol:
            break
    model, err = previous
    if err > tol:
        raise ModelError(f"layered model cannot reach tolerance {tol:.0e} "
                         f"(best estimate {err:.1e}); loosen [model] tolerance_rel")
    return model, ModelChoice("layered", reason, err, model.grid.n_cells, model.grid.min_dx_m)
