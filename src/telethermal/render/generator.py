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

:func:`compare` scores both on held-out persons; the bench keeps whichever
renders better.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.special import erfcx

from telethermal.data.dataset import Trial
from telethermal.errors import IdentificationError
from telethermal.ident.lm import MLP, train_lm
from telethermal.ident.prepare import FLUX, MIN_GAP_K
from telethermal.physics.materials import get_material

#: Curves are fitted on this many log-spaced times from the first sample to the end.
N_KNOTS = 120


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

    def fit(self, trials: list[Trial]) -> "NetworkGenerator":
        t, curves = mean_normalised_curves(trials)
        x = np.log10(t)[:, None]
        self.x_mean_, self.x_scale_ = float(x.mean()), float(x.std())
        self.nets_, self.scale_ = {}, {}
        rng = np.random.default_rng(self.seed)
        for material, curve in curves.items():
            scale = float(np.max(np.abs(curve))) or 1.0
            net, _ = train_lm(MLP.init(1, self.n_hidden, 1, rng, output="linear"),
                              (x - self.x_mean_) / self.x_scale_, curve[:, None] / scale,
                              max_iter=self.max_iter, l2=1e-8)
            self.nets_[material], self.scale_[material] = net, scale
        return self

    def normalised(self, material: str, t_s) -> np.ndarray:
        """flux / gap, W/m^2/K, at times since contact (0 before contact)."""
        if material not in getattr(self, "nets_", {}):
            raise IdentificationError(f"no generator for {material!r}")
        t = np.asarray(t_s, dtype=np.float64)
        x = (np.log10(np.clip(t, 1e-6, None))[:, None] - self.x_mean_) / self.x_scale_
        q = self.nets_[material](x)[:, 0] * self.scale_[material]
        return np.where(t > 0, q, 0.0)


@dataclass
class ContactGenerator:
    """The finger-material closed form with fitted ``h`` and effusivity."""

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
        if material not in getattr(self, "params_", {}):
            raise IdentificationError(f"no generator for {material!r}")
        h, e_m, e_f = self.params_[material]
        t = np.asarray(t_s, dtype=np.float64)
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
