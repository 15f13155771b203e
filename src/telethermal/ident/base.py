"""The identifier interface, shared by every method (scikit-learn conventions).

``fit(contacts)`` learns; learned attributes end in ``_``. Posteriors come for
any prefix of a contact: :meth:`Identifier.predict_proba` takes raw samples
since contact (the model's channels, at the model's sample rate) with the
gap and object temperature measured before contact.

Window-bank methods (``pca-fnn``, ``effusivity-lda``) fit one small model per
window length (every ``window_step_s`` up to ``max_window_s``) and answer a
prefix with the longest window it covers; their confidences are calibrated by
one temperature per window, fitted on out-of-fold predictions of the training
set (grouped k-fold, so trials of one group never both train and calibrate).

A model is saved as one ``.npz`` file: a JSON header (format version, method,
classes, channels, sample rate, windows, hyper-parameters, calibration) and
named weight arrays. No pickle: ``numpy.load(allow_pickle=False)``.
"""

from __future__ import annotations

import bisect
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import log_softmax

from telethermal.errors import IdentificationError, ModelFileError
from telethermal.ident.prepare import FLUX, MIN_GAP_K, Contacts, normalise
from telethermal.ident.rule import AnytimeRule
from telethermal.npzfile import check_names, read_npz, write_npz

FORMAT_VERSION = 1


def group_folds(groups: list[str], k: int) -> list[np.ndarray]:
    """Test indices of k folds that never split a group (round-robin by group)."""
    unique = sorted(set(groups))
    k = max(1, min(k, len(unique)))
    fold_of = {g: i % k for i, g in enumerate(unique)}
    return [np.array([i for i, g in enumerate(groups) if fold_of[g] == f]) for f in range(k)]


#: Held-out log loss under which the predictions are taken as separated (a
#: mean probability of the truth above 99.9 %): no temperature is fitted.
SEPARABLE_NLL = 1e-3


def fit_temperatures(logits: np.ndarray, y: np.ndarray, pool: int = 1) -> np.ndarray:
    """Temperature scaling (Guo et al. 2017) per window: the ``T`` that
    minimises the log loss of ``softmax(z / T)`` on held-out logits.

    Parameters
    ----------
    logits : ndarray, shape (n_windows, N, n_classes)
        Held-out logits; rows with NaN are ignored.
    y : ndarray, shape (N,)
    pool : int
        Windows fitted together in consecutive blocks of this many (for
        a recurrent network's many short steps: one temperature per block).
    """
    n_windows = len(logits)
    temps = np.ones(n_windows)
    for start in range(0, n_windows, pool):
        block = logits[start:start + pool]
        z = block.reshape(-1, block.shape[-1])
        yy = np.tile(y, len(block))
        ok = np.all(np.isfinite(z), axis=1)
        if not ok.any():
            continue
        z, yy = z[ok], yy[ok]

        def nll(log_t, z=z, yy=yy):
            p = log_softmax(z / np.exp(log_t), axis=1)
            return -np.mean(p[np.arange(len(yy)), yy])
        # Held-out predictions that are all right with margin leave the loss
        # flat near zero at any T <= 1: nothing says how much to sharpen, and
        # the optimiser would stop anywhere. Keep T = 1 then.
        if nll(0.0) < SEPARABLE_NLL:
            continue
        temps[start:start + pool] = float(np.exp(minimize_scalar(nll, bounds=(-5, 5),
                                                                 method="bounded").x))
    return temps


#: Samples averaged for the pressing force at the end of a window.
FORCE_SAMPLES = 3


def force_at(force_n: np.ndarray, n: int) -> np.ndarray:
    """Pressing force over the last ``FORCE_SAMPLES`` samples of the first
    ``n``, per contact; ``force_n`` (N, >= n)."""
    return np.nanmean(force_n[:, max(0, n - FORCE_SAMPLES):n], axis=1)


def force_ranges(model, contacts: Contacts) -> list | None:
    """The range of pressing forces the training touches had at the end of
    each window, [[lo, hi], ...]: a touch outside it (lighter or heavier,
    so its contact conductance differs) is not one the model has seen."""
    if contacts.force_n is None or not np.all(np.isfinite(contacts.force_n[:, 0])):
        return None
    rate = contacts.sample_rate_hz
    out = []
    for w in model.windows_s_:
        f = force_at(contacts.force_n, int(round(w * rate)) + 1)
        f = f[np.isfinite(f)]
        margin = FORCE_MARGIN * float(f.max() - f.min()) if len(f) else 0.0
        out.append([float(f.min()) - margin, float(f.max()) + margin] if len(f)
                   else [-np.inf, np.inf])
    return out


#: The trained force range is widened by this fraction of its width on each
#: side. The sample range of n touches leaves out 2 / (n + 1) of new touches
#: of the very same population by construction (3.5 % at the 56 touches of
#: a fold): each refused as "force outside trained range" with nothing
#: unlike about it. Widened by a tenth (about 2.8 sd of a normal population
#: at n = 56) it leaves out ~0.5 %, while a touch at 4 N or 20 N against the
#: 10 +- 1.5 N trained stays outside (tests/unit/test_decisions.py).
FORCE_MARGIN = 0.1


def commit_from_index(post: np.ndarray, y: np.ndarray, threshold: float,
                      confirm: int = 1) -> int:
    """The first window from which the anytime rule (a class at
    ``threshold``; a pair of the two most probable, refined by a member
    later) commits no held-out touch wrongly: ``post`` (n_windows, N,
    n_classes), the calibrated posteriors of touches the fits did not see;
    ``y`` their classes. Starting at window 0, each wrong commitment moves
    the start past the window it was made at; ``n_windows`` when no start
    is clean. The calibration is per window, while the rule looks at every
    window and takes the first crossing: this is the check that the
    crossings it takes are ones the held-out touches support."""
    n_windows, n = post.shape[:2]
    start = 0
    while start < n_windows:
        first_wrong = None
        for j in range(n):
            rule = AnytimeRule(threshold, confirm)
            for i in range(start, n_windows):
                p = post[i, j]
                if not np.all(np.isfinite(p)):
                    break
                step = rule.step(i, p)
                if step is None:
                    continue
                kind, what = step
                if (kind == "class" and what != y[j]) or (kind == "pair" and y[j] not in what):
                    first_wrong = i if first_wrong is None else min(first_wrong, i)
                    break
                if kind == "class":
                    break
        if first_wrong is None:
            return start
        start = first_wrong + 1
    return n_windows


def force_in_range(model, window_index: int, force_n: float | None) -> bool:
    """Whether a touch's force at a window lies within the trained range
    (True when either is unknown)."""
    ranges = getattr(model, "force_range_n_", None)
    if not ranges or force_n is None or not np.isfinite(force_n):
        return True
    lo, hi = ranges[min(window_index, len(ranges) - 1)]
    return lo <= force_n <= hi


class Identifier:
    """Base of all identification methods."""

    method = ""
    streaming = False        # True: one model answers every prefix (recurrent nets)
    #: Whether the temperature may be under 1 (sharpen). Scores that are not
    #: probabilities (a network's, a discriminant's) are scaled either way;
    #: a method whose posterior is a Bayesian predictive may only be
    #: softened: the mean held-out log loss that would sharpen it is the
    #: easy touches' say, while commitments are made in the tail.
    calibration_may_sharpen = True
    #: True: a sample the driver filled in (a frame lost on the line) reaches
    #: the model as NaN, missing data (``anytime.with_missing``); False: as
    #: the value the driver held.
    missing_samples = False
    #: A fitted model that needs no pad model, trained on the same touches,
    #: that names a touch this one's pad-model check refuses
    #: (``anytime``; saved in the same file); None: such a touch is not named.
    fallback_ = None

    def __init__(self, channels=(FLUX,), max_window_s: float = 1.0, window_step_s: float = 0.05,
                 threshold: float = 0.99, calibrate: bool = True, seed: int = 0,
                 confirm_windows: int = 2):
        self.confirm_windows = int(confirm_windows)
        self.channels = tuple(channels)
        self.max_window_s = max_window_s
        self.window_step_s = window_step_s
        self.threshold = threshold
        self.calibrate = calibrate
        self.seed = seed
        # Learned by fit() (or read from a model file); None until then.
        self.classes_: list[str] | None = None
        self.sample_rate_hz_: float | None = None
        self.windows_s_: list[float] | None = None
        self.params_: list[dict] | None = None
        #: Per window, the range of pressing forces the training touches had.
        self.force_range_n_: list | None = None
        #: The first window a decision may commit at (``commit_from_index``);
        #: 0.0 for a model not calibrated, None: at no window.
        self.commit_from_s_: float | None = 0.0
        #: Content digests of the training trials (``data.dataset.trial_digest``),
        #: when trained from a dataset: an evaluation on them is not held out.
        self.training_digests_: list[str] | None = None
        #: Per window, the softmax temperature of the calibration (Guo et al.
        #: 2017): logits are divided by it. Stored as "temperature" in files.
        self.softmax_temperature_: np.ndarray | None = None
        #: The scene the model was trained on, when known.
        self.scene_: str | None = None

    # ------------------------------------------------------------ fitting
    def hyper(self) -> dict:
        return {k: getattr(self, k) for k in ("max_window_s", "window_step_s", "threshold",
                                              "calibrate", "seed", "confirm_windows")}

    def _check_fit_input(self, contacts: Contacts):
        if tuple(contacts.channels) != self.channels:
            raise IdentificationError(f"contacts have channels {contacts.channels}, the "
                                      f"identifier was set up for {self.channels}")
        classes = sorted(set(contacts.labels))
        if len(classes) < 2:
            raise IdentificationError(f"need at least two materials to tell apart, got {classes}")
        return classes

    def fit(self, contacts: Contacts) -> "Identifier":
        self.classes_ = self._check_fit_input(contacts)
        self.sample_rate_hz_ = contacts.sample_rate_hz
        y = np.array([self.classes_.index(c) for c in contacts.labels])
        step = max(self.window_step_s, 1.0 / self.sample_rate_hz_)
        usable = float(np.min(contacts.lengths - 1)) / self.sample_rate_hz_
        top = min(self.max_window_s, usable)
        if top < step:
            raise IdentificationError(f"trials are too short ({usable:.3g} s after contact) "
                                      f"for a window of {step:.3g} s")
        self.windows_s_ = [round(w, 6) for w in np.arange(1, int(top / step + 1e-9) + 1) * step]
        self.params_ = [self._fit_window(self.window(contacts.x, w), y) for w in self.windows_s_]
        self.force_range_n_ = force_ranges(self, contacts)
        self.softmax_temperature_ = np.ones(len(self.windows_s_))
        if self.calibrate and not self.streaming:
            self._calibrate(contacts, y)
        return self

    def window(self, x: np.ndarray, window_s: float) -> np.ndarray:
        """The first ``window_s`` of each contact, (N, n_w, C); n_w includes t = 0."""
        n = int(round(window_s * self.sample_rate_hz_)) + 1
        return x[:, :n]

    def _calibrate(self, contacts: Contacts, y: np.ndarray):
        """One temperature per window minimising out-of-fold log loss
        (grouped folds: trials of one group never both train and calibrate)."""
        logits = self._held_out_logits(contacts, y)
        if logits is None:
            return
        self.softmax_temperature_ = fit_temperatures(logits, y)
        if not self.calibration_may_sharpen:
            self.softmax_temperature_ = np.maximum(self.softmax_temperature_, 1.0)
        z = logits / self.softmax_temperature_[:, None, None]
        z = z - np.nanmax(z, axis=2, keepdims=True)
        post = np.exp(z) / np.exp(z).sum(axis=2, keepdims=True)
        index = commit_from_index(post, y, self.threshold, self.confirm_windows)
        self.commit_from_s_ = (float(self.windows_s_[index]) if index < len(self.windows_s_)
                               else None)

    def _held_out_logits(self, contacts: Contacts, y: np.ndarray):
        """Logits of every trial at every window from models that did not
        see its group, (n_windows, N, n_classes); None when the groups are too
        few or a fold would lack a class."""
        folds = group_folds(contacts.groups, 3)
        if len(folds) < 2:
            return None
        logits = np.full((len(self.windows_s_), len(y), len(self.classes_)), np.nan)
        for test in folds:
            train = np.setdiff1d(np.arange(len(y)), test)
            if len(set(y[train])) < len(self.classes_):
                return None
            for i, w in enumerate(self.windows_s_):
                params = self._fit_window(self.window(contacts.x[train], w), y[train])
                logits[i][test] = self._logits(params, self.window(contacts.x[test], w))
        return logits

    # ------------------------------------------------------------ predicting
    def _require_fitted(self):
        if self.classes_ is None:
            raise IdentificationError(f"this {self.method} identifier is not fitted; call fit()")

    def window_index(self, n_samples: int) -> int | None:
        """Index of the longest window a prefix of n samples covers, or None."""
        elapsed = (n_samples - 1) / self.sample_rate_hz_
        count = bisect.bisect_right(self.windows_s_, elapsed + 1e-9)   # windows are ascending
        return count - 1 if count else None

    def proba_normalised(self, x: np.ndarray, window_index: int) -> np.ndarray:
        """Posteriors (N, n_classes) for normalised contacts x (N, >= n_w, C)."""
        w = self.windows_s_[window_index]
        z = self._logits(self.params_[window_index], self.window(x, w))
        z = z / self.softmax_temperature_[window_index]
        z = z - z.max(axis=1, keepdims=True)          # a softmax without scipy's overhead
        e = np.exp(z)
        return e / e.sum(axis=1, keepdims=True)

    def posterior_path(self, x: np.ndarray) -> np.ndarray:
        """Posteriors of one normalised contact (n, C) at each window it
        covers, (k, n_classes): what a per-sample update would have shown."""
        last = self.window_index(len(x))
        if last is None:
            return np.empty((0, len(self.classes_)))
        return np.vstack([self.proba_normalised(x[None], i) for i in range(last + 1)])

    def update_probe(self, row: np.ndarray, window_index: int) -> None:
        """The work of one posterior update (for timing): one window model."""
        self.proba_normalised(row, window_index)

    def predict_proba(self, samples: np.ndarray, gap_k: float, t_object_c: float | None = None
                      ) -> np.ndarray:
        """Posterior over ``classes_`` for raw samples since contact.

        Parameters
        ----------
        samples : ndarray, shape (n,) or (n, n_channels)
            From t = 0 at ``sample_rate_hz_``, channels in ``channels`` order.
        gap_k : float
            Pad minus object temperature before contact, K.
        t_object_c : float, optional
            Needed when a temperature channel is used.

        Returns
        -------
        ndarray, shape (n_classes,)
            Uniform when the prefix is shorter than the first window (nothing
            to go on yet).

        Raises
        ------
        IdentificationError
            Unfitted, wrong shape, non-finite samples, or a gap under
            ``MIN_GAP_K`` (use :mod:`telethermal.ident.anytime` for "unknown").
        """
        self._require_fitted()
        x = self._check_samples(samples, gap_k, t_object_c)
        index = self.window_index(len(x))
        if index is None:
            return np.full(len(self.classes_), 1.0 / len(self.classes_))
        return self.proba_normalised(x[None], index)[0]

    def _check_samples(self, samples, gap_k, t_object_c):
        x = np.asarray(samples, dtype=np.float64)
        if x.ndim == 1:
            x = x[:, None]
        if x.ndim != 2 or x.shape[1] != len(self.channels):
            raise IdentificationError(f"samples must have shape (n, {len(self.channels)}) for "
                                      f"channels {self.channels}, got {np.shape(samples)}")
        bad = ~np.isfinite(x)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise IdentificationError(f"sample {row} of channel {self.channels[col]} is "
                                      f"{x[row, col]}")
        if not np.isfinite(gap_k) or abs(gap_k) < MIN_GAP_K:
            raise IdentificationError(f"gap {gap_k} K: below {MIN_GAP_K} K nothing can be "
                                      "identified")
        return np.stack([normalise(x[:, i], c, gap_k, t_object_c)
                         for i, c in enumerate(self.channels)], axis=1)

    def learned(self) -> dict:
        """Learned values (names ending in ``_``, JSON-able) kept in the
        model file's header beside the weights; subclasses add theirs
        (an attribute a model file from before it lacks is saved as None)."""
        return {"force_range_n_": self.force_range_n_,
                "training_digests_": self.training_digests_,
                "commit_from_s_": self.commit_from_s_}

    def may_commit(self, window_index: int) -> bool:
        """Whether the calibration supports a commitment at this window
        (``commit_from_s_``; 0.0: from the first, None: at none)."""
        if self.commit_from_s_ is None:
            return False
        return self.windows_s_[window_index] >= self.commit_from_s_ - 1e-9

    def prepare(self) -> "Identifier":
        """Make ready whatever the first posterior would otherwise build
        (a slave calls it at start, not in its first touch's loop)."""
        return self

    # ------------------------------------------------------------ subclass hooks
    def _fit_window(self, x: np.ndarray, y: np.ndarray) -> dict:
        raise NotImplementedError

    def _logits(self, params: dict, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def outside_classes(self, x: np.ndarray, window_index: int) -> np.ndarray:
        """Per contact: True where the sample lies outside every learnt class
        (methods that cannot tell return False)."""
        return np.zeros(len(x), dtype=bool)

    def rule_posterior(self, p: np.ndarray, x: np.ndarray, window_index: int) -> np.ndarray:
        """The posteriors ``p`` (n_classes,) of the touch ``x`` (1, n, C) the
        anytime rule commits on: ``p`` itself for a closed set (a method
        with a density of materials outside its classes gives them less)."""
        return p

    # ------------------------------------------------------------ persistence
    def save(self, path: str | Path) -> Path:
        """Write one ``.npz`` (header JSON + arrays), through a temporary file."""
        self._require_fitted()
        header, arrays = self._file_parts()
        return write_npz(path, "telethermal-identifier", FORMAT_VERSION, header, arrays)

    def _file_parts(self) -> tuple[dict, dict]:
        """(header, arrays) of the model file; a fallback's under ``fallback``
        and its arrays' names prefixed with :data:`FALLBACK_PREFIX`."""
        header = {"method": self.method,
                  "classes": self.classes_, "channels": list(self.channels),
                  "sample_rate_hz": self.sample_rate_hz_, "windows_s": self.windows_s_,
                  "temperature": self.softmax_temperature_.tolist(), "hyper": self.hyper(),
                  "min_gap_k": MIN_GAP_K, "scene": self.scene_,
                  "learned": self.learned()}
        arrays = {f"w{i}.{name}": value for i, params in enumerate(self.params_)
                  for name, value in params.items()}
        if self.fallback_ is not None:
            fb_header, fb_arrays = self.fallback_._file_parts()
            header["fallback"] = fb_header
            arrays.update({FALLBACK_PREFIX + k: v for k, v in fb_arrays.items()})
        return header, arrays

    @classmethod
    def restore(cls, header: dict, arrays: dict) -> "Identifier":
        # A model file from before confirm_windows decided at the first
        # window past the threshold: it keeps deciding so.
        model = cls(channels=header["channels"], **{"confirm_windows": 1, **header["hyper"]})
        model.classes_ = list(header["classes"])
        model.sample_rate_hz_ = float(header["sample_rate_hz"])
        model.windows_s_ = list(header["windows_s"])
        model.softmax_temperature_ = np.asarray(header["temperature"], dtype=np.float64)
        if header.get("scene") is not None:
            model.scene_ = header["scene"]
        for key, value in (header.get("learned") or {}).items():
            setattr(model, key, value)
        arrays = {k: v for k, v in arrays.items() if not k.startswith(FALLBACK_PREFIX)}
        # One parameter set per window for a bank, one in all for a network.
        n_sets = len({k.split(".", 1)[0] for k in arrays})
        model.params_ = [{k.split(".", 1)[1]: v for k, v in arrays.items()
                          if k.startswith(f"w{i}.")} for i in range(n_sets)]
        return model


#: The names of a fallback's arrays in its model's file start so.
FALLBACK_PREFIX = "fallback:"


def read_model_file(path: str | Path) -> tuple[dict, dict]:
    """Header and arrays of a model file, with clear errors for anything else
    (the limits of ``docs/limits.md``, checked before anything runs)."""
    header, arrays = read_npz(path, "telethermal-identifier", FORMAT_VERSION, "model")
    check_identifier_header(Path(path), header)
    return header, arrays


def _number(path: Path, value, field: str, lo: float, hi: float, open_lo=True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not (lo < float(value) if open_lo else lo <= float(value)) or not float(value) <= hi:
        raise ModelFileError(f"{path}: {field} must be a number in {'(' if open_lo else '['}"
                             f"{lo:g}, {hi:g}], got {str(value)[:64]}")
    return float(value)


def check_identifier_header(path: Path, header: dict) -> None:
    """What an identifier's header must hold before it is restored: its
    classes and channels (names of at most 256 bytes), a sample rate, its
    windows, temperatures, a threshold in (0, 1], learned values named as
    learned attributes (ending in ``_``)."""
    check_names(path, header.get("classes"), "classes", "model")
    check_names(path, header.get("channels"), "channels", "model")
    _number(path, header.get("sample_rate_hz"), "sample_rate_hz", 0.0, 1e6)
    windows = header.get("windows_s")
    if not isinstance(windows, list) or not windows:
        raise ModelFileError(f"{path}: windows_s must be a non-empty list of times")
    for i, w in enumerate(windows):
        _number(path, w, f"windows_s[{i}]", 0.0, 3600.0, open_lo=False)
    temperature = header.get("temperature")
    for i, t in enumerate(temperature if isinstance(temperature, list) else [temperature]):
        _number(path, t, f"temperature[{i}]", 0.0, 1e12)
    hyper = header.get("hyper")
    if not isinstance(hyper, dict):
        raise ModelFileError(f"{path}: hyper must be a map of the method's settings")
    if "threshold" in hyper:
        _number(path, hyper["threshold"], "hyper.threshold", 0.0, 1.0)
    learned = header.get("learned") or {}
    if not isinstance(learned, dict):
        raise ModelFileError(f"{path}: learned must be a map")
    for key in learned:
        if not (key.isidentifier() and key.endswith("_") and not key.startswith("_")):
            raise ModelFileError(f"{path}: learned.{key[:64]}: not a learned value's name "
                                 "(a learned attribute's name ends in '_')")
