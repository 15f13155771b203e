"""Flux generators: the heat flux the operator's finger would exchange with a
material, from the time since contact and the finger-object gap.

Both follow learning-based-thermal-rendering section 3: database 2 (the
fingertip directly on each material) is normalised by each trial's initial
gap and averaged per material; the desired flux is then
``generator(t) * (T_finger - T_object)``.

- :class:`NetworkGenerator`: the paper's choice, one small network per
  material (one hidden sigmoid layer, linear output) trained by the project's
  Levenberg-Marquardt on the mean normalised curve. Its input is
  ``log10(t)``, so the 1/sqrt(t) start and the slow tail weigh alike.
- :class:`ContactGenerator`: the closed form of a finger on a semi-infinite
  material with a contact conductance, ``h erfcx(h (1/e_f + 1/e_m) sqrt(t))``,
  with ``h`` and the material's effusivity fitted per material (two numbers).

``telethermal bench render`` scores both on held-out persons
(``bench.render.generator_comparison``); the network renders better and is kept.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.special import erfcx

from telethermal.data.dataset import Trial
from telethermal.errors import IdentificationError, ModelFileError
from telethermal.ident.lm import MLP, train_lm
from telethermal.ident.prepare import FLUX, MIN_GAP_K
from telethermal.npzfile import check_names, read_npz, write_npz
from telethermal.physics.materials import get_material
from telethermal.render.sampled import SampledGenerator

#: Curves are fitted on this many log-spaced times from the first sample to the end.
N_KNOTS = 120


def _learned(empty=None):
    """A learned attribute of a generator: set by ``fit`` (or read from a
    file), not a constructor argument, not in its repr or equality."""
    if empty is None:
        return field(default=None, init=False, repr=False, compare=False)
    return field(default_factory=empty, init=False, repr=False, compare=False)


def mean_normalised_curves(trials: list[Trial], t_knots: np.ndarray | None = None):
    """Per material, the mean over trials of flux / gap at ``t_knots`` (s).

    Returns ``(t_knots, {material: curve})``; trials with a gap under
    ``MIN_GAP_K`` are left out.
    """
    usable = [t for t in trials if abs(t.gap_k) >= MIN_GAP_K and FLUX in t.channels]
    if not usable:
        raise IdentificationError("no trial with heat flux and a usable gap")
    if t_knots is None:
        rate = max(t.sample_rate_hz for t in usable)
        last = min(float(t.channels["t_s"][-1]) for t in usable)
        # Log-spaced, snapped to the sample grid: no interpolation between
        # samples where the curve bends most.
        t_knots = np.unique(np.round(np.geomspace(1.0 / rate, last, N_KNOTS) * rate)) / rate
        t_knots = t_knots[t_knots > 0]
    curves: dict[str, list[np.ndarray]] = {}
    for trial in usable:
        q = np.interp(t_knots, trial.channels["t_s"], trial.channels[FLUX]) / trial.gap_k
        curves.setdefault(trial.material, []).append(q)
    return t_knots, {m: np.mean(c, axis=0) for m, c in curves.items()}


@dataclass
class NetworkGenerator:
    """One ``log10(t) -> hidden sigmoid -> linear`` network per material."""

    n_hidden: int = 8
    max_iter: int = 300
    seed: int = 0
    #: Learned: the fitted times' range (s), the input's centre and spread
    #: (log10 s), one network per material and the peak |flux / gap| it was
    #: scaled by (stored as "scale" in the file).
    t_range_s_: tuple[float, float] | None = _learned()
    x_mean_: float | None = _learned()
    x_scale_: float | None = _learned()
    nets_: dict[str, MLP] = _learned(dict)
    peak_w_m2k_: dict[str, float] = _learned(dict)
    #: ``normalised_many``'s stacked weights per tuple of materials.
    _stacked: dict[tuple, tuple] = _learned(dict)

    kind = "network"

    def fit(self, trials: list[Trial]) -> "NetworkGenerator":
        t, curves = mean_normalised_curves(trials)
        self.t_range_s_ = (float(t[0]), float(t[-1]))
        x = np.log10(t)[:, None]
        self.x_mean_, self.x_scale_ = float(x.mean()), float(x.std())
        self.nets_, self.peak_w_m2k_ = {}, {}
        rng = np.random.default_rng(self.seed)
        for material, curve in curves.items():
            scale = float(np.max(np.abs(curve))) or 1.0
            net, _ = train_lm(MLP.init(1, self.n_hidden, 1, rng, output="linear"),
                              (x - self.x_mean_) / self.x_scale_, curve[:, None] / scale,
                              max_iter=self.max_iter, l2=1e-8)
            self.nets_[material], self.peak_w_m2k_[material] = net, scale
        return self

    @property
    def materials(self) -> list[str]:
        return sorted(self.nets_)

    def normalised(self, material: str, t_s) -> np.ndarray:
        """flux / gap, W/m^2/K, at times since contact (0 before contact).

        Below the first fitted time (one sample period of database 2) the
        network is not extrapolated: the curve ramps linearly from 0 at
        contact, which is what the recorded (sensor-lagged) flux does."""
        if material not in self.nets_:
            raise IdentificationError(f"no generator for {material!r}; it knows "
                                      f"{', '.join(self.materials)}")
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        t_first = self.t_range_s_[0]
        x = (np.log10(np.clip(t, t_first, None))[:, None] - self.x_mean_) / self.x_scale_
        q = self.nets_[material](x)[:, 0] * self.peak_w_m2k_[material]
        return np.where(t >= t_first, q, np.clip(t, 0, None) / t_first * q)

    def normalised_many(self, materials, t_s) -> np.ndarray:
        """``normalised`` for several materials at once, (n_materials, n_t)."""
        key = tuple(materials)
        stacked = self._stacked.get(key)
        if stacked is None:
            for m in key:
                if m not in self.nets_:
                    raise IdentificationError(f"no generator for {m!r}")
            nets = [self.nets_[m] for m in key]
            stacked = (np.stack([n.w1[:, 0] for n in nets]), np.stack([n.b1 for n in nets]),
                       np.stack([n.w2[0] for n in nets]), np.array([n.b2[0] for n in nets]),
                       np.array([self.peak_w_m2k_[m] for m in key]))
            self._stacked[key] = stacked
        w1, b1, w2, b2, scale = stacked
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        t_first = self.t_range_s_[0]
        x = (np.log10(np.maximum(t, t_first)) - self.x_mean_) / self.x_scale_
        hidden = 0.5 * (1.0 + np.tanh(0.5 * (w1[:, :, None] * x + b1[:, :, None])))
        q = (np.einsum("mh,mht->mt", w2, hidden) + b2[:, None]) * scale[:, None]
        return np.where(t >= t_first, q, np.clip(t, 0, None) / t_first * q)

    def _state(self):
        header = {"x_mean": self.x_mean_, "x_scale": self.x_scale_,
                  "t_range_s": list(self.t_range_s_), "scale": self.peak_w_m2k_,
                  "hyper": {"n_hidden": self.n_hidden, "max_iter": self.max_iter,
                            "seed": self.seed}}
        arrays = {f"{m}.{k}": getattr(net, k) for m, net in self.nets_.items()
                  for k in ("w1", "b1", "w2", "b2")}
        return header, arrays

    @classmethod
    def _restore(cls, header, arrays):
        gen = cls(**header["hyper"])
        gen.x_mean_, gen.x_scale_ = float(header["x_mean"]), float(header["x_scale"])
        gen.t_range_s_ = tuple(header["t_range_s"])
        gen.peak_w_m2k_ = {m: float(v) for m, v in header["scale"].items()}
        gen.nets_ = {m: MLP(*(arrays[f"{m}.{k}"] for k in ("w1", "b1", "w2", "b2")),
                            output="linear") for m in gen.peak_w_m2k_}
        return gen


@dataclass
class ContactGenerator:
    """The finger-material closed form with fitted ``h`` and effusivity."""

    #: Learned: per material, (h W/m^2/K, the material's effusivity, the
    #: finger's effusivity), effusivities in W s^0.5/m^2/K.
    params_: dict[str, tuple[float, float, float]] = _learned(dict)

    kind = "contact"

    @property
    def materials(self) -> list[str]:
        return sorted(self.params_)

    def _state(self):
        return {"params": self.params_}, {}

    @classmethod
    def _restore(cls, header, arrays):
        gen = cls()
        gen.params_ = {m: tuple(float(x) for x in v) for m, v in header["params"].items()}
        return gen

    def normalised_many(self, materials, t_s) -> np.ndarray:
        return np.stack([self.normalised(m, t_s) for m in materials])

    def fit(self, trials: list[Trial]) -> "ContactGenerator":
        t, curves = mean_normalised_curves(trials)
        e_finger = get_material("skin").effusivity
        self.params_ = {}
        for material, curve in curves.items():
            def resid(p, curve=curve):
                h, e_m = np.exp(p)
                return (h * erfcx(h * (1 / e_finger + 1 / e_m) * np.sqrt(t)) - curve) / curve.max()
            start = np.log([3000.0, get_material(material).effusivity])
            fit = least_squares(resid, start)
            self.params_[material] = (float(np.exp(fit.x[0])), float(np.exp(fit.x[1])), e_finger)
        return self

    def normalised(self, material: str, t_s) -> np.ndarray:
        if material not in self.params_:
            raise IdentificationError(f"no generator for {material!r}; it knows "
                                      f"{', '.join(self.materials)}")
        h, e_m, e_f = self.params_[material]
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        q = h * erfcx(h * (1 / e_f + 1 / e_m) * np.sqrt(np.clip(t, 0, None)))
        return np.where(t > 0, q, 0.0)


def rendering_error(generator, trials: list[Trial]) -> float:
    """RMS of (generated - recorded) flux over each held-out trial, relative
    to the trial's peak |flux|, averaged over trials."""
    errors = []
    for trial in trials:
        if abs(trial.gap_k) < MIN_GAP_K:
            continue
        t = trial.channels["t_s"]
        after = t > 0
        recorded = trial.channels[FLUX][after]
        generated = generator.normalised(trial.material, t[after]) * trial.gap_k
        errors.append(np.sqrt(np.mean((generated - recorded) ** 2)) / np.abs(recorded).max())
    return float(np.mean(errors))


# ---------------------------------------------------------------- rendering
def display_flux(generator, material: str, t_s, finger_c: float, object_c: float) -> np.ndarray:
    """The flux the display pad must put into the finger (pad -> finger
    positive) at times since contact: the finger would lose
    ``g(t) (T_finger - T_object)`` to the object, so the pad gives minus that.
    """
    return generator.normalised(material, t_s) * (object_c - finger_c)


def posterior_weights(classes, posteriors, known) -> dict[str, float]:
    """Posteriors over ``classes`` as weights over the ``known`` materials,
    renormalised (uniform while there are no posteriors yet)."""
    post = list(posteriors or ())
    raw = post if len(post) == len(classes) else [1.0] * len(classes)
    pairs = [(c, w) for c, w in zip(classes, raw) if c in known]
    total = sum(w for _, w in pairs) or 1.0
    return {c: w / total for c, w in pairs}


def mixture(generator, materials, weights, t_s: float, step_s: float = 1e-4):
    """``(sum_m w_m g_m(t), d/dt of it)`` at one time since contact, with the
    derivative by central difference (one-sided at contact); one batched
    evaluation per material."""
    lo, hi = max(t_s - step_s, 0.0), t_s + step_s
    # A row-by-row sum, not a BLAS product: BLAS may round differently with
    # the arrays' alignment, and a replay must give the same bits.
    g = generator.weighted_sum(materials, [float(w) for w in weights], (t_s, lo, hi)) \
        if isinstance(generator, SampledGenerator) else None
    if g is None:
        w = np.asarray(weights, dtype=np.float64)
        g = np.sum(w[:, None] * generator.normalised_many(materials, np.array([t_s, lo, hi])),
                   axis=0)
    return float(g[0]), float((g[2] - g[1]) / (hi - lo))


def naive_setpoint(generator, classes, estimate, t_s: float, gap_k: float) -> float | None:
    """The naive baseline's display flux at ``t_s`` since the slave's onset:
    the decided material's curve, else the posterior mixture, times the
    gap (object - finger). None when no material of ``classes`` is known."""
    known = generator.materials
    if estimate is not None and estimate.decided and estimate.label in known:
        weights = {estimate.label: 1.0}
    else:
        weights = posterior_weights(classes, estimate.posteriors if estimate else None, known)
    if not weights:
        return None
    names = list(weights)
    g, _ = mixture(generator, names, [weights[n] for n in names], t_s)
    return g * gap_k


# ---------------------------------------------------------------- files
GENERATOR_FORMAT_VERSION = 1
GENERATORS = {"network": NetworkGenerator, "contact": ContactGenerator}


def save_generator(generator, path: str | Path) -> Path:
    """One ``.npz``: a JSON header and named weight arrays; written through a
    temporary file, so a crash leaves the old file or none, never half a one."""
    if not generator.materials:
        raise IdentificationError("this generator is not fitted; call fit()")
    state, arrays = generator._state()
    return write_npz(path, "telethermal-generator", GENERATOR_FORMAT_VERSION,
                     {"kind": generator.kind, "materials": generator.materials, **state}, arrays)


def load_generator(path: str | Path):
    header, arrays = read_npz(path, "telethermal-generator", GENERATOR_FORMAT_VERSION,
                              "generator")
    cls = GENERATORS.get(header.get("kind"))
    if cls is None:
        raise ModelFileError(f"{path}: unknown generator kind {str(header.get('kind'))[:64]!r}")
    try:
        gen = cls._restore(header, arrays)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ModelFileError(f"{path}: generator file is incomplete: {exc}") from exc
    check_names(Path(path), list(gen.materials), "materials", "generator")
    _check_runs(Path(path), gen)
    return gen


def _check_runs(path: Path, gen) -> None:
    """The restored generator run once per material on its own time range:
    finite curves, or a ModelFileError naming the material (weights of
    mismatched shapes, a zero scale), before anything uses it."""
    t_s = np.linspace(1e-3, 1.0, 8)
    for material in gen.materials:
        try:
            curve = np.asarray(gen.normalised(material, t_s), dtype=float)
        except (ValueError, TypeError, ZeroDivisionError, FloatingPointError) as exc:
            raise ModelFileError(f"{path}: material {material!r}: the generator cannot run: "
                                 f"{exc}") from exc
        if curve.shape != t_s.shape or not np.isfinite(curve).all():
            raise ModelFileError(f"{path}: material {material!r}: the generator gives "
                                 f"{'non-finite values' if curve.shape == t_s.shape else 'shape ' + str(curve.shape)}"
                                 f" (weights or scales out of range)")
