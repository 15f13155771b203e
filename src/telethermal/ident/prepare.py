"""Turn datasets into arrays for identification.

Every identifier sees contacts the same way: samples from the first contact
(``t_s >= 0``) at the model's sample rate, one column per channel, each
normalised by the initial pad-object gap as in learning-based-thermal-rendering
section 3 (heat flux divided by the gap; temperature as the fraction of the
gap it has crossed). A contact whose gap is smaller than ``min_gap_k`` carries
too little heat to identify anything and is never divided by: identifiers
answer "unknown" for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from telethermal.data.dataset import Trial
from telethermal.errors import IdentificationError

FLUX = "heat_flux_W_m2"
TEMPERATURE = "temperature_C"
FORCE = "force_N"
#: Below this gap (K) a contact is not normalised and not identified: the
#: passive pad at the object's own temperature (Case I-cnv) measures a gap
#: of noise (0.1 K calibrated, up to 1 K uncalibrated: the two instruments'
#: datasheet limits), and 2 K is twice the worst of that.
MIN_GAP_K = 2.0


@dataclass
class Contacts:
    """Contacts as arrays; ``x`` is (n_trials, n_samples, n_channels), NaN past
    each trial's end (trials may be of unequal length)."""

    x: np.ndarray
    lengths: np.ndarray
    labels: list[str]
    groups: list[str]
    gap_k: np.ndarray
    sample_rate_hz: float
    channels: tuple[str, ...]
    force_n: np.ndarray | None = None     # (n_trials, n_samples) pressing force, if recorded

    def __len__(self) -> int:
        return len(self.labels)

    def subset(self, index) -> "Contacts":
        index = np.asarray(index)
        return Contacts(self.x[index], self.lengths[index], [self.labels[i] for i in index],
                        [self.groups[i] for i in index], self.gap_k[index],
                        self.sample_rate_hz, self.channels,
                        None if self.force_n is None else self.force_n[index])


def window_key(w: float) -> str:
    """A window's key in reports: tenths as "0.1" ... "1.0" (as they always
    were), finer windows as "0.02"."""
    return f"{w:.1f}" if abs(round(w, 1) - w) < 1e-9 else f"{w:g}"


def normalise(values: np.ndarray, channel: str, gap_k, t_object_c=None) -> np.ndarray:
    """Divide a channel by the gap (flux), or map it to the crossed fraction
    of the gap (temperature); other channels pass through unchanged.

    Parameters
    ----------
    values : ndarray, shape (..., n)
    gap_k : float or ndarray broadcastable to values[..., :1]
        Pad minus object temperature before contact; ``|gap| >= MIN_GAP_K``.
    """
    gap = np.asarray(gap_k, dtype=np.float64)
    if np.any(np.abs(gap) < MIN_GAP_K):
        raise IdentificationError(f"gap {gap.min():.3g} K is below {MIN_GAP_K} K: too little "
                                  "heat exchange to normalise by")
    if channel == FLUX:
        return values / gap
    if channel == TEMPERATURE:
        if t_object_c is None:
            raise IdentificationError("normalising temperature needs the object temperature")
        return (values - np.asarray(t_object_c)) / gap
    return values


def trial_samples(trial: Trial, channels, sample_rate_hz: float, max_s: float) -> np.ndarray:
    """Normalised samples of one trial from contact to ``max_s`` (or its end),
    resampled to ``sample_rate_hz`` if its own rate differs; (n, n_channels)."""
    missing = [c for c in channels if c not in trial.channels]
    if missing:
        raise IdentificationError(f"trial {trial.trial_id} has no channel(s) "
                                  f"{', '.join(missing)} (it has {', '.join(trial.channels)})")
    t = trial.channels["t_s"]
    end = min(float(t[-1]), max_s)
    grid = np.arange(int(np.floor(end * sample_rate_hz + 1e-9)) + 1) / sample_rate_hz
    columns = []
    for c in channels:
        raw = np.interp(grid, t, trial.channels[c])
        columns.append(normalise(raw, c, trial.gap_k, trial.T_object_C))
    return np.stack(columns, axis=1)


def from_trials(trials: list[Trial], channels=(FLUX,), sample_rate_hz: float | None = None,
                max_s: float = 1.0) -> tuple[Contacts, list[Trial]]:
    """Arrays of the identifiable trials, and the trials left out (gap too small)."""
    if not trials:
        raise IdentificationError("no trials")
    rate = sample_rate_hz or trials[0].sample_rate_hz
    keep, skipped = [], []
    for trial in trials:
        (keep if abs(trial.gap_k) >= MIN_GAP_K else skipped).append(trial)
    if not keep:
        raise IdentificationError(f"every trial has a gap below {MIN_GAP_K} K: nothing to learn")
    rows = [trial_samples(t, channels, rate, max_s) for t in keep]
    n = max(len(r) for r in rows)
    x = np.full((len(rows), n, len(channels)), np.nan)
    for i, r in enumerate(rows):
        x[i, :len(r)] = r
    force = None
    if all(FORCE in t.channels for t in keep):
        force = np.full((len(rows), n), np.nan)
        for i, t in enumerate(keep):
            f = trial_samples(t, (FORCE,), rate, max_s)[:, 0]
            force[i, :len(f)] = f
    return Contacts(x, np.array([len(r) for r in rows]), [t.material for t in keep],
                    [t.group for t in keep], np.array([t.gap_k for t in keep]), float(rate),
                    tuple(channels), force), skipped
