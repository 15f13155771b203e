"""The sensing pad's model calibrated from a lab's reference touches
(``telethermal calibrate pad``; issue 44, deliverable 2).

A lab knows its pad from its design and datasheets to 10-30 %: the layers'
thicknesses and conductivities, the flux sensor's lag and gain. It touches
objects of known effusivity (materials of the scene's table, semi-infinite
within the window) and fits the pad model to those touches by nonlinear
least squares (``scipy.optimize.least_squares``, trust-region reflective):

- the **candidates**, each a log factor on the design value: the flux
  sensor's lag and gain, and each layer's thermal resistance ``L / k`` and
  heat capacity ``L rho c`` per area. A layer's thickness and conductivity
  enter only through those two (a thin layer's heat capacity hardly at
  all): thickness and conductivity are never two parameters, and a
  thickness traded against conductivity at constant resistance is one
  resistance factor of 1.
- per touch, the nuisances the estimator has too: the contact conductance
  ``h_i``, the contact instant ``tau_i`` and the amplitude ``a_i`` (true
  gap over measured gap, its prior ``N(1, sd)`` from the thermometers'
  per-touch noise); the calibrated contact conductance is the touches'
  geometric mean.
- **identifiability from the Jacobian**: at a first fit (the design pad,
  the nuisances and the gain fitted), each candidate's column, the
  nuisances projected out, is added in order of its weight while its
  conditional sd of ``ln factor`` stays under :data:`SD_MAX`; a candidate
  that does not, nearly parallel (cosine over :data:`LUMP_COS`) to one
  kept, is lumped with it (both scaled by one factor, said so); any other
  is named as not identifiable from these touches alone and fitted under
  its **design prior**: ``ln factor ~ N(0, DESIGN_SD^2)``, what a lab
  knows of it from its datasheet, one residual row ``ln factor / sd``
  beside the touches' (a maximum a posteriori fit). The touches still
  move it as far as they tell it apart: a part off its design that the
  touches see only weakly (a thick cold plate whose conditional sd is
  past :data:`SD_MAX`) is not pinned at the design, where it would
  bias what the model says of objects far from the references (a metal
  more effusive than the metal reference). With ``design_sd = 0`` it is
  held at its design value.
- each parameter's **95 % interval**: ``+-1.96 sd`` of ``ln factor``
  from the Gauss-Newton covariance at the optimum (the nuisances and the
  prior-fitted parts marginalised; a prior-fitted part's own from the
  same covariance), the touches' and amplitudes' rows widened by the
  residual's chi-square per degree of freedom where it exceeds 1 (the
  priors' not).
  The touches' rows are weighed with the curves' allowance in their
  variance, far above the sensor's noise (a pad that fits reads a
  chi-square per degree of freedom of a few hundredths), so the prior
  pulls a weakly seen part toward its design harder than the noise alone
  would: a conservative balance.
- the **residual against the sensor's noise**: each sample's variance is
  the flux noise over the touch's gap plus the curves' own error (the
  scene's ``[model] tolerance_rel`` of the touch's rms, as the estimator);
  a chi-square per degree of freedom over :data:`CHI2_MAX` says the model
  cannot fit, and a material whose own is over it while the others' are
  not is named: its table value is likely wrong.

The product never reads the simulator's pad: the candidates are factors on
the scene's nominal values.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import least_squares

from telethermal.errors import CalibrationError

#: Reference materials (at least) and touches of each (at least) a calibration needs.
MIN_MATERIALS, MIN_TOUCHES = 2, 3
#: Touches of each material read at most (the first, by trial order).
MAX_TOUCHES = 5
#: Touches per reference block the demo and the as-built benches make:
#: what a calibration reads.
REFERENCE_TOUCHES = MAX_TOUCHES
#: The reference blocks the demo and the as-built benches touch (those of
#: them a scene has; its first three if none): a metal, a plastic and a
#: wood, effusivities about 7,500, 570 and 470 W s^0.5/(m^2 K) from the
#: materials table (docs/calibration.md: three, so a block off its table
#: value stands out). A lab touches its own.
REFERENCE_MATERIALS = ("steel", "plexiglass", "wood")


def reference_scene(scene, materials):
    """``scene`` with the objects named ``materials`` alone (by name, as
    :func:`reference_materials` gives them), :data:`REFERENCE_TOUCHES` of
    each: the reference session's scene."""
    return dataclasses.replace(
        scene, pad=dataclasses.replace(scene.pad, trials_per_material=REFERENCE_TOUCHES),
        objects=tuple(o for o in scene.objects if o.name in materials))


def reference_materials(scene, wanted=None) -> list[str]:
    """The reference blocks (the scene's objects, by name: ``scene.materials``)
    a calibration of ``scene``'s pad touches. ``wanted`` (names): those;
    None: :data:`REFERENCE_MATERIALS` the scene has when two or more, else
    its first three. ValueError, naming the scene's objects, for a name the
    scene has not, and for fewer than :data:`MIN_MATERIALS`."""
    if wanted is None:
        present = [m for m in REFERENCE_MATERIALS if m in scene.materials]
        wanted = present if len(present) >= MIN_MATERIALS else scene.materials[:3]
    names = list(dict.fromkeys(wanted))
    for m in names:
        if m not in scene.materials:
            raise ValueError(f"reference material {m!r} is not one of scene "
                             f"{scene.name}'s: {', '.join(scene.materials)}")
    if len(names) < MIN_MATERIALS:
        raise ValueError(f"a calibration needs at least {MIN_MATERIALS} reference materials "
                         f"(3 recommended); got {', '.join(names) or 'none'} (scene "
                         f"{scene.name}'s: {', '.join(scene.materials)})")
    return names
#: The window fitted from the detected onset, s (the identifier's longest).
WINDOW_S = 1.0
#: The curves are solved to this fraction of the scene's tolerance: the
#: estimator's own (a calibrated model is as exact as the curves it builds).
CURVE_TOLERANCE_FACTOR = 1.0
#: A parameter is identifiable when its conditional sd of ``ln factor`` is
#: under this: its 95 % interval within about +-20 % (the datasheets' 10-30 %
#: would not be narrowed otherwise).
SD_MAX = 0.1
#: How far (log sd) a candidate the touches cannot identify may be off its
#: design value: a lab knows its layers from their datasheets to 10-30 %
#: (the middle taken). The fit takes it as such a candidate's prior (see
#: the module); with 0 it holds the candidate at its design instead.
DESIGN_SD = 0.2
#: Columns (nuisances projected out) this parallel are one parameter.
LUMP_COS = 0.95
#: The residual's chi-square per degree of freedom past which the model
#: does not fit. The allowance for the curves' error is white where the
#: error is not, so a model that fits reads above 1; twice the noise's
#: variance is far beyond a chi-square's spread over thousands of samples.
CHI2_MAX = 2.0
#: Finite-difference step on a log factor (a curve solved on a grid: a
#: step much smaller would difference its discretisation).
FD_STEP = 0.02
#: Bounds of a log factor and of a touch's log contact conductance over the design's.
LOG_FACTOR_BOUND, LOG_H_BOUND = math.log(4.0), 2.5


def candidates(scene) -> list[str]:
    """The candidate parameters of ``scene``'s pad, in order."""
    names = ["flux_gain", "flux_lag_s"]
    for i, lay in enumerate(scene.pad.layers):
        names += [f"layers[{i}].resistance", f"layers[{i}].heat_capacity"]
    return names


def describe(scene, name: str) -> str:
    """A candidate's name for people: its layer's material."""
    if name.startswith("layers["):
        i = int(name[7:name.index("]")])
        return f"{scene.pad.layers[i].material.name} {name.split('.')[1].replace('_', ' ')}"
    return {"flux_gain": "flux sensor gain", "flux_lag_s": "flux sensor lag"}[name]


def scaled_scene(scene, factors: dict, contact_conductance_w_m2k: float | None = None):
    """``scene`` with its pad's design values times ``factors`` (candidate
    name -> factor; missing: 1): each layer's resistance and heat capacity
    (its thickness times the heat capacity's factor, its conductivity times
    that over the resistance's), the flux lag; the contact conductance
    replaced when given. (The flux gain is not the scene's: the estimator's
    amplitude prior carries it.)"""
    from telethermal.physics.layered import Layer

    layers = []
    for i, lay in enumerate(scene.pad.layers):
        f_r = factors.get(f"layers[{i}].resistance", 1.0)
        f_c = factors.get(f"layers[{i}].heat_capacity", 1.0)
        if f_r == 1.0 and f_c == 1.0:
            layers.append(lay)
            continue
        mat = dataclasses.replace(lay.material, conductivity_w_mk=lay.material.conductivity_w_mk
                                  * f_c / f_r)
        layers.append(Layer(mat, lay.thickness_m * f_c))
    pad = dataclasses.replace(scene.pad, layers=tuple(layers))
    if contact_conductance_w_m2k is not None:
        pad = dataclasses.replace(pad, contact_conductance_w_m2k=float(contact_conductance_w_m2k))
    sensors = dataclasses.replace(scene.sensors, flux_lag_s=scene.sensors.flux_lag_s
                                  * factors.get("flux_lag_s", 1.0))
    return dataclasses.replace(scene, pad=pad, sensors=sensors)


@dataclasses.dataclass
class ReferenceTouches:
    """The touches fitted: ``x`` (N, n) flux over the measured gap (W/m^2 K)
    from the detected onset, ``gap_k`` (N,), ``labels``, ``effusivity`` (N,)
    of each touch's material (the table's)."""

    x: np.ndarray
    gap_k: np.ndarray
    labels: list[str]
    effusivity: np.ndarray
    sample_rate_hz: float

    @classmethod
    def from_trials(cls, trials, window_s: float = WINDOW_S,
                    max_touches: int = MAX_TOUCHES) -> "ReferenceTouches":
        """Up to ``max_touches`` touches of each material, at least
        :data:`MIN_TOUCHES` of at least :data:`MIN_MATERIALS`, each as long
        as the window; refused with what is missing."""
        from telethermal.errors import UnknownMaterialError
        from telethermal.ident.prepare import from_trials
        from telethermal.physics.materials import get_material

        contacts, _ = from_trials(list(trials), max_s=window_s)
        n = int(round(window_s * contacts.sample_rate_hz)) + 1
        keep, counts = [], {}
        for i, label in enumerate(contacts.labels):
            if contacts.lengths[i] >= n and counts.get(label, 0) < max_touches:
                keep.append(i)
                counts[label] = counts.get(label, 0) + 1
        few = {m: c for m, c in counts.items() if c < MIN_TOUCHES}
        if few or len(counts) < MIN_MATERIALS:
            raise CalibrationError(
                f"a calibration needs at least {MIN_TOUCHES} touches ({window_s:g} s long) of "
                f"each of at least {MIN_MATERIALS} reference materials (3 recommended, "
                f"{MAX_TOUCHES} touches each are read); got "
                + (", ".join(f"{m}: {c}" for m, c in sorted(counts.items())) or "none"))
        effusivity = []
        for label in (contacts.labels[i] for i in keep):
            try:
                effusivity.append(get_material(label).effusivity)
            except UnknownMaterialError as exc:
                raise CalibrationError(f"reference touches of {label!r}: not a material of the "
                                       f"table, so its effusivity is not known: {exc}") from exc
        return cls(contacts.x[keep, :n, 0], contacts.gap_k[keep], [contacts.labels[i]
                                                                     for i in keep],
                   np.array(effusivity), contacts.sample_rate_hz)


class PadModelFit:
    """The least-squares problem: the design scene's pad, its ``free``
    parameters (lists of candidates scaled together), each touch's
    nuisances; residuals and Jacobian (see the module)."""

    def __init__(self, scene, touches: ReferenceTouches, amplitude_sd: float,
                 noise_w_m2: float):
        self.scene, self.touches = scene, touches
        self.object_temp_c = float(scene.objects[0].temp_c)
        self.t_s = np.arange(touches.x.shape[1]) / touches.sample_rate_hz
        self.dt_s = 1e-3
        self.t_fine = np.arange(int(np.ceil((self.t_s[-1] + 0.06) / self.dt_s)) + 1) * self.dt_s
        rms = np.sqrt(np.mean(touches.x ** 2, axis=1))
        tol = scene.tolerance_rel * CURVE_TOLERANCE_FACTOR
        self.sigma = np.sqrt((noise_w_m2 / touches.gap_k) ** 2 + (tol * rms) ** 2)     # (N,)
        self.amplitude_sd = float(amplitude_sd)
        self._curves: dict = {}

    # ------------------------------------------------------------ the model
    def curves(self, factors: dict, log_h: np.ndarray) -> np.ndarray:
        """Each touch's sensed unit-gap flux on the fine grid (N, n_fine)."""
        from telethermal.ident.effusivity_curves import reference_object, sensed_unit_flux
        key = (tuple(sorted(factors.items())), np.asarray(log_h).tobytes())
        if key not in self._curves:
            if len(self._curves) > 64:
                self._curves.clear()
            scene = dataclasses.replace(scaled_scene(self.scene, factors),
                                        tolerance_rel=self.scene.tolerance_rel
                                        * CURVE_TOLERANCE_FACTOR)
            model, ref = reference_object(scene, self.object_temp_c)
            h = self.scene.pad.contact_conductance_w_m2k * np.exp(log_h)
            self._curves[key] = sensed_unit_flux(scene, model, self.t_fine, self.object_temp_c,
                                                 self.touches.effusivity / ref.effusivity, h)
        return self._curves[key]

    def _at(self, g: np.ndarray, tau: np.ndarray):
        """(values, time derivative) of fine curves at ``t_s - tau`` (N, n)."""
        t = self.t_s[None, :] - tau[:, None]
        pos = np.clip(t / self.dt_s, 0.0, len(self.t_fine) - 1.000001)
        i = pos.astype(int)
        w = pos - i
        rows = np.arange(len(g))[:, None]
        v = g[rows, i] * (1 - w) + g[rows, i + 1] * w
        d = np.where(t > 0, (g[rows, i + 1] - g[rows, i]) / self.dt_s, 0.0)
        return v, d

    def split(self, z, free):
        """(factors, log_gain, log_h, tau, log_a) of the parameter vector ``z``."""
        n, k = len(self.touches.labels), len(free)
        factors = {}
        for group, value in zip(free, z[:k]):
            for name in group:
                factors[name] = math.exp(value)
        gain = factors.pop("flux_gain", 1.0)
        return factors, math.log(gain), z[k:k + n], z[k + n:k + 2 * n], z[k + 2 * n:]

    def residuals(self, z, free, fixed=None, prior=None) -> np.ndarray:
        """The touches' residuals in noise units, the amplitudes' prior,
        then one row ``ln factor / sd`` per group ``prior`` gives a prior
        sd (``prior``: one sd or None per group of ``free``)."""
        factors, log_gain, log_h, tau, log_a = self.split(z, free)
        factors = {**(fixed or {}), **factors}
        v, _ = self._at(self.curves(factors, log_h), tau)
        pred = np.exp(log_gain + log_a)[:, None] * v
        r = (self.touches.x - pred) / self.sigma[:, None]
        return np.concatenate([r.ravel(), log_a / self.amplitude_sd,
                               [z[j] / sd for j, sd in _priors(prior)]])

    def jacobian(self, z, free, fixed=None, prior=None) -> np.ndarray:
        """d residuals / d z: finite differences of one batch solve per
        solved parameter (and one for every touch's contact conductance
        at once), analytic in the contact instant and the amplitudes (and
        the priors' rows, :meth:`residuals`)."""
        factors, log_gain, log_h, tau, log_a = self.split(z, free)
        factors = {**(fixed or {}), **factors}
        n, m = self.touches.x.shape
        k = len(free)
        amp = np.exp(log_gain + log_a)[:, None] / self.sigma[:, None]
        v, d = self._at(self.curves(factors, log_h), tau)
        jac = np.zeros((n * m + n, len(z)))
        for j, group in enumerate(free):
            if group == ("flux_gain",):
                jac[:n * m, j] = -(amp * v).ravel()
                continue
            moved = {**factors, **{g: factors.get(g, 1.0) * math.exp(FD_STEP) for g in group}}
            v2, _ = self._at(self.curves(moved, log_h), tau)
            jac[:n * m, j] = -(amp * (v2 - v) / FD_STEP).ravel()
        v2, _ = self._at(self.curves(factors, log_h + FD_STEP), tau)
        rows = np.arange(n)
        block = -(amp * (v2 - v) / FD_STEP)                      # (n, m): d r / d log_h_i
        for i in rows:
            jac[i * m:(i + 1) * m, k + i] = block[i]
            jac[i * m:(i + 1) * m, k + n + i] = amp[i] * d[i]       # d r / d tau_i
            jac[i * m:(i + 1) * m, k + 2 * n + i] = -amp[i] * v[i]  # d r / d log a_i
        jac[n * m + rows, k + 2 * n + rows] = 1.0 / self.amplitude_sd
        priors = _priors(prior)
        if priors:
            rows_p = np.zeros((len(priors), len(z)))
            for row, (j, sd) in enumerate(priors):
                rows_p[row, j] = 1.0 / sd
            jac = np.vstack([jac, rows_p])
        return jac

    def solve(self, free, z0, fixed=None, max_nfev: int = 25, prior=None):
        """``least_squares`` from ``z0`` (``prior``: :meth:`residuals`); the result."""
        n = len(self.touches.labels)
        k = len(free)
        lo = np.concatenate([np.full(k, -LOG_FACTOR_BOUND), np.full(n, -LOG_H_BOUND),
                             np.full(n, -0.05), np.full(n, -0.3)])
        hi = np.concatenate([np.full(k, LOG_FACTOR_BOUND), np.full(n, LOG_H_BOUND),
                             np.full(n, 0.05), np.full(n, 0.3)])
        return least_squares(self.residuals, np.clip(z0, lo, hi), jac=self.jacobian,
                             bounds=(lo, hi), args=(free, fixed, prior), method="trf",
                             x_scale="jac", max_nfev=max_nfev, xtol=1e-6, ftol=1e-8)


def _priors(prior) -> list[tuple[int, float]]:
    """(group index, sd) of each group ``prior`` gives a prior sd."""
    return [(j, float(sd)) for j, sd in enumerate(prior or ()) if sd]


def marginal_sds(jac: np.ndarray, k: int) -> np.ndarray:
    """The sds of the first ``k`` parameters from the Gauss-Newton covariance
    ``(J^T J)^-1`` (every other parameter marginalised)."""
    cov = np.linalg.pinv(jac.T @ jac)
    return np.sqrt(np.maximum(np.diag(cov)[:k], 0.0))


def design_value(scene, name: str) -> float:
    """A layer candidate's design value: its resistance per area ``L / k``
    (m^2 K/W) or its heat capacity per area ``L rho c`` (J/(m^2 K))."""
    lay = scene.pad.layers[int(name[7:name.index("]")])]
    if name.endswith(".resistance"):
        return lay.thickness_m / lay.material.conductivity_w_mk
    return lay.thickness_m * lay.material.volumetric_heat_j_m3k


def lump_weights(scene, group) -> list[float]:
    """What a lumped parameter (one factor on every member) stands for: the
    members' total (layers in series: their resistance, or their heat
    capacity), whose factor is the members' own weighted by their design
    values; these weights (1 for one member)."""
    if len(group) == 1:
        return [1.0]
    x = [design_value(scene, n) for n in group]
    return [v / sum(x) for v in x]


def consider_sds(fit: "PadModelFit", z: np.ndarray, free, fixed, design_sd: float,
                 jac: np.ndarray) -> np.ndarray:
    """The sds of the first ``len(free)`` parameters (``ln factor``) that
    what the touches cannot tell carries into them (a "consider"
    covariance), each such part off its design by a log sd ``design_sd``:

    - a candidate held at its design value (``fixed``): where it truly is,
      its effect on the flux is absorbed by the free parameters (and the
      nuisances) that can mimic it (the calibration holds none since it
      fits such candidates under their prior, whose covariance carries
      them; kept for a fit that holds some);
    - each member of a lumped parameter apart from the others: the lumped
      factor stands for the members' total (:func:`lump_weights`), and a
      member off alone moves the fit and that total differently.

    ``jac``: the fit's Jacobian at ``z`` (free parameters, then nuisances;
    its rows the residuals', in noise units, then any priors' rows, which
    no part moves)."""
    k = len(free)
    members = [(m,) for g in free if len(g) > 1 for m in g]
    parts = [(m,) for m in fixed] + members
    if not parts or design_sd <= 0:
        return np.zeros(k)
    # The parts' columns alone (one solve each), at the fit: the free
    # factors given as fixed, a member at its group's factor, the gain kept.
    factors = fit.split(z, free)[0]
    gain = [z[i] for i, g in enumerate(free) if g == ("flux_gain",)]
    at = [0.0] * len(fixed) + [math.log(factors[m]) for (m,) in members] + gain
    groups = parts + [("flux_gain",)] * len(gain)
    cols = fit.jacobian(np.concatenate([at, z[k:]]), groups, fixed=factors)[:, :len(parts)]
    # A fit with priors has their rows last: a part moves none of them.
    cols = np.vstack([cols, np.zeros((jac.shape[0] - cols.shape[0], cols.shape[1]))])
    shift, *_ = np.linalg.lstsq(jac, cols, rcond=None)     # d z / d ln(part's factor)
    shift = shift[:k]
    # A member moves its own lumped quantity by its weight: the fit's error
    # on that quantity is the fit's shift less that.
    for j, (m,) in enumerate(members, start=len(fixed)):
        for i, g in enumerate(free):
            if m in g:
                shift[i, j] -= lump_weights(fit.scene, g)[g.index(m)]
    return design_sd * np.sqrt(np.sum(shift ** 2, axis=1))


def projected_columns(jac: np.ndarray, k: int) -> np.ndarray:
    """The first ``k`` columns with the span of the others projected out."""
    rest = jac[:, k:]
    coef, *_ = np.linalg.lstsq(rest, jac[:, :k], rcond=None)
    return jac[:, :k] - rest @ coef


def select(cols: np.ndarray, names: list[str]):
    """(free groups, not identifiable) from the projected columns (see the
    module): greedily in order of weight, kept while the conditional sd
    stays under :data:`SD_MAX`, else lumped with a kept column of the same
    kind (layers' resistances together, heat capacities together) it is
    nearly parallel to, else not identifiable (the calibration fits those
    under their design prior, or holds them at the design without one)."""
    order = np.argsort(-np.linalg.norm(cols, axis=0))
    groups: list[list[int]] = []
    fixed = []
    for c in order:
        trial = [list(g) for g in groups] + [[c]]
        if _worst_sd(cols, trial) < SD_MAX:
            groups = trial
            continue
        unit = cols[:, c] / max(np.linalg.norm(cols[:, c]), 1e-300)
        best, cos = None, LUMP_COS
        for gi, g in enumerate(groups):
            col = cols[:, g].sum(axis=1)
            value = float(unit @ col / max(np.linalg.norm(col), 1e-300))
            if value > cos and _kind(names[g[0]]) == _kind(names[c]):
                best, cos = gi, value
        if best is not None and _kind(names[c]) in ("resistance", "heat_capacity"):
            lumped = [list(g) for g in groups]
            lumped[best].append(c)
            if _worst_sd(cols, lumped) < SD_MAX:
                groups = lumped
                continue
        fixed.append(names[c])
    return [tuple(names[i] for i in g) for g in groups], fixed


def _kind(name: str) -> str:
    """A candidate's kind: a layer's ``resistance`` or ``heat_capacity``, else its name."""
    return name.split(".")[-1]


def _worst_sd(cols: np.ndarray, groups) -> float:
    merged = np.column_stack([cols[:, g].sum(axis=1) for g in groups])
    return float(np.max(marginal_sds(merged, merged.shape[1])))
