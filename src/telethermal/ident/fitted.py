"""``effusivity-fit``: identification by the touched object's estimated effusivity.

At each window, :class:`~telethermal.ident.effusivity.EffusivityEstimator`
fits the scene's pad model to the touch: ``ln e`` with the contact
conductance, the contact instant and the flux amplitude as nuisances (the
contact conductance bends the first tenths of a second; fitted, it is no
longer confused with the material, which a window's flux shape alone
cannot undo: the box features of ``effusivity-lda`` spread each material
along its own curve of contact conductance). Each material is then one
number per window: its training touches' estimates, their mean and spread.

The class density is the Bayesian predictive of a normal sample of ``n``
touches with unknown mean and variance (Student's t with ``n - 1`` degrees
of freedom, scale ``s sqrt(1 + 1/n)``; Gelman et al., Bayesian Data
Analysis, 3rd ed., section 3.2): ten touches of a material do not say how
far its tails reach, and the posteriors do not pretend they do. A touch
whose estimate lies past every class's ``1 - outlier_p`` quantile is
outside every class (an unseen material: issue 30).

What it needs that the learned-only methods do not: the pad's own model
(layers, module, loop, sensor lag: the scene's ``[pad]``), as a lab has it
from its pad's design and datasheets. The touches' simulator uses the very
same model (solved to a quarter of the curves' tolerance), so on simulated
touches the pad model is exact but for the curves' discretisation; a real
pad's model is off by its datasheets' tolerances (``bench identify`` says so).
The estimates do not depend on the training set, so they are computed once
per touch and window and kept for the process, until :func:`clear_cache`:
a timed run and every touch on the slave service make theirs afresh (a
simulated pad's repeated seed gives the same samples, whose kept fits cost
nothing).
"""

from __future__ import annotations

import functools
import hashlib
import math

import numpy as np
from scipy.stats import t as student_t

from telethermal.errors import IdentificationError
from telethermal.ident.base import Identifier
from telethermal.ident.intervals import resolution_var
from telethermal.ident.prepare import FLUX

#: The fewest samples an estimate is made from (the estimator's own floor).
MIN_SAMPLES = 4


#: Fits kept in the process before the cache is emptied (the slave service
#: empties it at every touch).
CACHE_MAX = 200_000
#: Fits already made, shared by every model of the process (they do not
#: depend on the training touches): (scene, max_s, digest of the samples, n)
#: -> (ln e, u, tau).
_CACHE: dict = {}


def clear_cache() -> None:
    """Forget every fit made (a timing of a training from nothing)."""
    _CACHE.clear()


#: Scenes given to this process by name (:func:`register_scene`), before
#: the scene files it loaded (``physics.scene.loaded_scene_file``); the
#: shipped scenes :func:`scene_of` read, by name (asked at every window).
_SCENES: dict = {}
_SHIPPED: dict = {}


def register_scene(scene) -> None:
    """Make ``scene`` the one a model naming ``scene.name`` fits its pad's
    model to, in this process (the slave service gives the scene of its
    config; any scene file this process loads is found by name anyway)."""
    _SCENES[scene.name] = scene


def scene_of(scene_ref: str):
    """The registered scene of that name, else the scene file of that name
    this process loaded, else ``load_scene(scene_ref)`` (a shipped scene's
    name or a scene file's path)."""
    from telethermal.errors import SceneError
    from telethermal.physics.scene import list_scenes, load_scene, loaded_scene_file
    if scene_ref in _SCENES:
        return _SCENES[scene_ref]
    if loaded_scene_file(scene_ref) is not None:
        return loaded_scene_file(scene_ref)
    if scene_ref in _SHIPPED:            # package data: read once
        return _SHIPPED[scene_ref]
    try:
        scene = load_scene(scene_ref)
    except SceneError as exc:
        raise IdentificationError(
            f"effusivity-fit needs the pad model of scene {scene_ref!r}, which is neither a "
            f"shipped scene nor a scene file, and no scene file of that name was loaded by "
            f"this process (give the scene file: --scene FILE): {exc}") from exc
    return _SHIPPED.setdefault(scene_ref, scene) if scene_ref in list_scenes() else scene


def serves(scene) -> str | None:
    """None when effusivity-fit can model ``scene``'s touches, else why
    not (cheap: the checks ``EffusivityEstimator.for_scene`` makes before
    building anything; :func:`telethermal.ident.effusivity.refusal`)."""
    from telethermal.ident.effusivity import refusal
    return refusal(scene)


def _estimator(scene, max_s: float, calibration=None):
    """The estimator of ``scene`` (a Scene, or a name for :func:`scene_of`),
    its pad as ``calibration`` has it (a PadCalibration; None: as designed),
    and its nominal gap, K."""
    return _estimator_of(scene_of(scene) if isinstance(scene, str) else scene, max_s,
                         calibration)


@functools.lru_cache(maxsize=8)
def _estimator_of(scene, max_s: float, calibration=None):
    """Its curves take seconds to compute: read from the per-user cache
    (:mod:`telethermal.ident.curvecache`), or built and cached there; once
    per process, scene and calibration (equal scenes share one)."""
    from telethermal.ident.curvecache import cached_family
    from telethermal.ident.effusivity import EffusivityEstimator

    gain = None
    if calibration is not None:
        scene = calibration.apply(scene)            # refused for another scene's pad
        gain = (calibration.flux_gain, calibration.flux_gain_sd)
    est = EffusivityEstimator.for_scene(scene, max_s=max_s, family=cached_family,
                                        flux_gain=gain)
    return est, abs(scene.pad_temp_c(est.object_temp_c) - est.object_temp_c)


class EffusivityFit(Identifier):
    """Classes by the touch's estimated effusivity (see the module).

    Parameters
    ----------
    scene : Scene or str
        The scene whose pad made the touches: its pad model is what the
        estimate fits. A model file keeps its name; a model read from one
        finds the scene by :func:`scene_of` (the scene registered under
        that name in the process, else a shipped scene's name or a scene
        file's path).
    unseen_weight : float
        The prior weight of a material outside the classes against one
        class's (0: a closed set, the default; 1: an unseen material as
        likely as each trained one): the anytime rule commits on the
        classes' posteriors times one minus the posterior of "another
        material", whose estimate is spread evenly in ``ln e`` over the
        estimator's grid (:meth:`rule_posterior`). Early in a touch a
        class's predictive is wide and an unseen neighbour lies inside it;
        with a weight the rule waits until the class's density stands above
        the spread. ``bench unseen`` reports the trade against time.
    outlier_p : float
        A touch beyond every class's two-sided ``1 - outlier_p`` predictive
        interval is outside every class.
    """

    method = "effusivity-fit"
    needs_scene = True
    missing_samples = True      # a lost frame is left out of the fit (NaN in a window)
    calibration_may_sharpen = False
    #: The intervals' calibration on the training touches (:meth:`fit`;
    #: :func:`telethermal.ident.intervals.calibrate_allowance`):
    #: ``{"windows_s": [...], "allowance": [...], "reference": why}``, None
    #: where the classes are not materials of known effusivity (and in a
    #: model file from before it: the interval is then the estimator's own).
    interval_allowance_ = None

    def __init__(self, channels=(FLUX,), scene=None, outlier_p: float = 1e-4,
                 window_step_s: float = 0.02, unseen_weight: float = 0.0,
                 calibration=None, **kw):
        super().__init__(channels, window_step_s=window_step_s, **kw)
        if tuple(self.channels) != (FLUX,):
            raise IdentificationError(f"effusivity-fit reads the heat flux alone, not "
                                      f"{self.channels}")
        self.scene = scene
        self.outlier_p = outlier_p
        if not (np.isfinite(unseen_weight) and unseen_weight >= 0):
            raise IdentificationError(f"unseen_weight must be a finite number >= 0, got "
                                      f"{unseen_weight!r}")
        self.unseen_weight = float(unseen_weight)
        self.calibration = _calibration(calibration)

    @property
    def scene_name(self) -> str | None:
        return getattr(self.scene, "name", self.scene)

    def hyper(self) -> dict:
        return {**super().hyper(), "scene": self.scene_name, "outlier_p": self.outlier_p,
                "unseen_weight": self.unseen_weight,
                "calibration": None if self.calibration is None else self.calibration.to_dict()}

    def fit(self, contacts):
        if not self.scene:
            raise IdentificationError(
                "effusivity-fit needs the scene whose pad made the touches (--scene NAME|FILE; "
                "scene=... in Python): its estimate fits that pad's model, and these touches "
                "name no scene (a lab's import has no generation.json)")
        from telethermal.ident.intervals import calibrate_allowance

        super().fit(contacts)
        self.interval_allowance_ = calibrate_allowance(self, contacts, MIN_SAMPLES)
        return self

    def learned(self) -> dict:
        return {**super().learned(), "interval_allowance_": self.interval_allowance_}

    def allowance_at(self, window_index: int) -> float:
        """The factor on the curves' allowance at window ``window_index``
        (1: uncalibrated)."""
        return self.allowance_at_s(self.windows_s_[window_index])

    def allowance_at_s(self, window_s: float) -> float:
        """The factor on the curves' allowance for a ``window_s`` window,
        interpolated between the calibration's windows (held before the
        first; 1: uncalibrated)."""
        cal = self.interval_allowance_
        if not cal:
            return 1.0
        return float(np.interp(window_s, cal["windows_s"], cal["allowance"]))

    def floor_at_s(self, window_s: float) -> float:
        """The factor on the resolution floor's variance for a ``window_s``
        window: the allowance's where the calibration included the floor
        (or none was made), 0 for a model file calibrated before it had one
        (its factors hold the references with the Laplace variance alone)."""
        cal = self.interval_allowance_
        return self.allowance_at_s(window_s) if not cal or cal.get("floor") else 0.0

    def estimator(self):
        """(the scene's estimator, its nominal gap in K), built once per process."""
        return _estimator(self.scene, float(self.max_window_s), self.calibration)

    def prepare(self) -> "EffusivityFit":
        """The estimator's curves (seconds to build) before the first touch."""
        self.estimator()
        return self

    def log_effusivity(self, x: np.ndarray) -> np.ndarray:
        """``ln e`` of each touch's window ``x`` (N, n, 1), NaN where the
        window has under :data:`MIN_SAMPLES` measured samples (a NaN
        sample is missing: a frame lost on the line)."""
        n = x.shape[1]
        out = np.full(len(x), np.nan)
        if len(_CACHE) > CACHE_MAX:
            _CACHE.clear()
        for i, row in enumerate(x[:, :, 0]):
            if _enough(row, n):
                out[i] = self._theta(np.ascontiguousarray(row), n)[0]
        return out

    def _key(self, row: np.ndarray, n: int):
        # The estimator itself (equal scenes share one): two scenes of one
        # name (a variant made in a test) are not mixed up.
        return (self.estimator()[0], self.max_window_s,
                hashlib.blake2b(row[:n].tobytes(), digest_size=16).digest(), n)

    def update_probe(self, row: np.ndarray, window_index: int) -> None:
        """One window's estimate made afresh (for timing: a cached one
        costs nothing), from the previous window's fit when known, as the
        slave makes it, else from cold (dearer)."""
        x = np.ascontiguousarray(self.window(row, self.windows_s_[window_index])[0, :, 0])
        if len(x) < MIN_SAMPLES:
            return
        est, gap_k = self.estimator()
        start = _CACHE.get(self._key(x, len(x) - self._step_samples(est)))
        est.estimate(x, gap_k, start=start)

    def follow(self, x: np.ndarray, window_index: int) -> None:
        """Make window ``window_index``'s fit of the touch ``x`` (1, n, 1)
        now, kept in the process's fits, while a decided touch is watched
        to its last window (``StreamingIdentifier``): the revision there
        then makes one fit, not every window's since the decision in one
        go (each window's fit starts from the previous one's: the same
        fits, so the same decisions, made as the windows come; measured
        by helper-18 at ~125 ms on one sample at the last window)."""
        row = np.ascontiguousarray(self.window(x, self.windows_s_[window_index])[0, :, 0])
        if _enough(row, len(row)):
            self._theta(row, len(row))

    def _step_samples(self, est) -> int:
        """Samples from one window to the next."""
        return max(1, int(round(self.window_step_s * est.sample_rate_hz)))

    def _theta(self, row: np.ndarray, n: int):
        """The fit ``(ln e, u, tau)`` of ``row[:n]``, started from the fit
        of the previous window's samples, as a live slave walks them: the
        fit follows its optimum from window to window (from cold, a short
        window's optimum can be another of a few near-equal ones). A NaN
        sample is missing: the fit reads the measured ones alone."""
        key = self._key(row, n)
        theta = _CACHE.get(key)
        if theta is None:
            est, gap_k = self.estimator()
            step = self._step_samples(est)
            start = self._theta(row, n - step) if _enough(row, n - step) else None
            # The noise at the scene's gap: x is already over the touch's
            # measured gap, which a window does not carry.
            xs, keep = _measured(row[:n])
            theta = _CACHE[key] = est.estimate(xs, gap_k, start=start, measured=keep).theta
        return theta

    def _fit_window(self, x, y):
        f = self.log_effusivity(x)
        classes = np.arange(int(y.max()) + 1)
        if not np.all(np.isfinite(f)):
            return {"n": np.zeros(len(classes))}
        n = np.array([np.sum(y == c) for c in classes], dtype=float)
        if np.any(n < 2):
            raise IdentificationError("effusivity-fit needs at least two training touches "
                                      "of every material")
        means = np.array([f[y == c].mean() for c in classes])
        var = np.array([f[y == c].var(ddof=1) for c in classes])
        # Touches estimated to the same value (noise-free data) still have
        # a spread: the estimator's resolution, far below any class's.
        var = np.maximum(var, 1e-12)
        return {"n": n, "means": means, "var": var}

    def _t_terms(self, params, x):
        f = self.log_effusivity(x)
        n = params["n"]
        scale = np.sqrt(params["var"] * (1.0 + 1.0 / n))
        z = (f[:, None] - params["means"][None]) / scale[None]
        return z, n - 1.0, scale

    def _logits(self, params, x):
        if "means" not in params:
            return np.zeros((len(x), len(params["n"])))
        z, dof, scale = self._t_terms(params, x)
        # A window without enough measured samples has no estimate: no say.
        return np.where(np.isfinite(z), student_t.logpdf(z, dof[None]) - np.log(scale)[None],
                        0.0)

    def rule_posterior(self, p, x, window_index):
        """``p`` times ``1 - P(another material | estimate)`` at the window:
        the classes' predictive densities of the touch's ``ln e`` (uniform
        priors) against ``unseen_weight`` times a density even in ``ln e``
        over the estimator's grid (:attr:`unseen_weight`)."""
        params = self.params_[window_index]
        if self.unseen_weight == 0 or "means" not in params:
            return p
        est, _ = self.estimator()
        log_other = np.log(self.unseen_weight) - np.log(est.hi[0] - est.lo[0])
        log_f = self._logits(params, self.window(x, self.windows_s_[window_index]))[0]
        top = max(float(np.max(log_f)), log_other)
        other = np.exp(log_other - top)
        return np.asarray(p) * (1.0 - other / (other + float(np.sum(np.exp(log_f - top)))))

    def interval_of(self, row: np.ndarray, window_s: float):
        """What the slave reports of a touch's samples ``row`` (1-d, the
        flux over its measured gap, from the onset) in a ``window_s``
        window, any length: ``(theta, e, lo, hi, sd, floor_var)``, the fit
        walked from window to window as the slave makes it
        (:meth:`_theta`), the calibrated 95 % interval's ends (W
        s^0.5/(m^2 K), clipped to the estimator's grid), the sd of ``ln e``
        (unclipped) and the resolution floor's part of its variance (see
        :mod:`telethermal.ident.intervals`); None under
        :data:`MIN_SAMPLES` samples. ``bench unseen`` scores this."""
        n = int(round(window_s * self.sample_rate_hz_)) + 1
        row = np.ascontiguousarray(np.asarray(row, float)[:n])
        if not _enough(row, len(row)):
            return None
        est, gap_k = self.estimator()
        theta = self._theta(row, len(row))
        floor_var = self.floor_at_s(window_s) * resolution_var(est, theta, len(row))
        xs, keep = _measured(row)
        e, lo, hi, sd = est.interval_at(xs, gap_k, theta, self.allowance_at_s(window_s),
                                        floor_var, measured=keep)
        return theta, e, lo, hi, sd, floor_var

    def misfit(self, x, window_index: int, measured=None) -> bool:
        """The window's fit of the touch ``x`` (1, n, 1) leaves a residual
        chi-square per degree of freedom past
        :data:`~telethermal.ident.calibration.CHI2_MAX` (:meth:`misfit_chi2`'s
        first): the pad is not the model the estimate fits. ``measured``:
        as :meth:`misfit_chi2`."""
        from telethermal.ident.calibration import CHI2_MAX
        chi2 = self.misfit_chi2(x, window_index, measured)
        return chi2 is not None and chi2[0] > CHI2_MAX

    def misfit_chi2(self, x, window_index: int, measured=None) -> tuple[float, float] | None:
        """The residual of the window's fit of the touch ``x`` (1, n, 1), as
        chi-square per degree of freedom (measured samples - 4), against two
        denominators, one variance for every sample of the window:
        ``(chi2, chi2_noise)``.
        ``chi2``, what :meth:`misfit` tests: the flux noise over the touch's
        gap plus the curves' allowance (the scene's ``tolerance_rel`` times
        the window's rms flux over gap, squared), the estimator's own
        variance; the allowance dominates, so a pad as modelled reads far
        under 1. ``chi2_noise``: the sensor's noise alone (the same fit and
        residual), for comparison with the noise. ``measured`` (n,) bool,
        from the onset: False where the sample was filled in (a frame lost
        on the line, held by the driver), as a NaN in ``x``: left out of the
        residual and its degrees of freedom, the amplitude, the rms, and
        the fit itself (:meth:`_theta`, when ``x`` carries it as NaN). None
        with no more measured samples than the fit's 4 parameters
        (docs/calibration.md)."""
        row = np.ascontiguousarray(self.window(x, self.windows_s_[window_index])[0, :, 0])
        keep = np.isfinite(row)
        if measured is not None:
            flags = np.asarray(measured, bool)[:len(row)]
            if len(flags) < len(row):
                raise IdentificationError(f"measured flags {len(flags)} samples of a window of "
                                          f"{len(row)}: one flag per sample from the onset")
            keep &= flags
        # At least one degree of freedom left over the fit's 4 (the
        # statistic of fewer is no test).
        if keep.sum() <= MIN_SAMPLES:
            return None
        est, gap_k = self.estimator()
        theta = np.asarray(self._theta(row, len(row)), float)
        xs = np.where(keep, row, 0.0)
        chi2, _ = est.goodness(theta, xs, est.noise_var(xs[keep], gap_k), keep)
        chi2_noise, _ = est.goodness(theta, xs, est.noise_var(xs[keep], gap_k, allowance=0.0),
                                      keep)
        return chi2, chi2_noise

    def outside_classes(self, x, window_index):
        params = self.params_[window_index]
        if "means" not in params:
            return np.zeros(len(x), dtype=bool)
        z, dof, _ = self._t_terms(params, self.window(x, self.windows_s_[window_index]))
        limit = student_t.ppf(1.0 - self.outlier_p / 2, dof)
        return np.all(np.abs(z) > limit[None], axis=1)

    def effusivity_reading(self, x, window_index):
        """The touch's effusivity estimate at window ``window_index`` (``x``
        (1, n, 1), as ``outside_classes``): an
        :class:`~telethermal.ident.openset.EffusivityReading`, None on a
        window under :data:`MIN_SAMPLES` samples: the window's fit (the one
        the classes are scored on) and its calibrated 95 % interval there
        (Laplace's and the resolution floor, :mod:`telethermal.ident.intervals`)."""
        from telethermal.ident.openset import EffusivityReading

        w = self.window(x, self.windows_s_[window_index])
        got = self.interval_of(w[0, :, 0], self.windows_s_[window_index])
        if got is None:
            return None
        theta, e, lo, hi, sd, floor_var = got
        params = self.params_[window_index]
        nearest = tail = None
        inside = ()
        if "means" in params:
            z, dof, _ = self._t_terms(params, w)
            tails = 2.0 * student_t.sf(np.abs(z[0]), dof)
            tail = float(np.max(tails))
            nearest = str(self.classes_[int(np.argmin(np.abs(theta[0] - params["means"])))])
            # Against a class's training touches the resolution floor (the
            # curves' systematic error, ident/intervals.py) is common to
            # both: their estimates carry it too. The touch's own part is
            # its interval less the floor.
            own = sd ** 2 - floor_var
            inside = classes_holding(float(theta[0]), math.sqrt(max(own, 0.0)), params,
                                     self.classes_, self.outlier_p)
        return EffusivityReading(e, lo, hi, nearest, tail, inside)


def _enough(row: np.ndarray, n: int) -> bool:
    """The first ``n`` samples of ``row`` hold :data:`MIN_SAMPLES` measured (finite) ones."""
    return n >= MIN_SAMPLES and int(np.sum(np.isfinite(row[:n]))) >= MIN_SAMPLES


def _measured(row: np.ndarray):
    """(``row`` with its missing (NaN) samples as 0, their flags: None when
    every sample was measured)."""
    keep = np.isfinite(row)
    return (row, None) if keep.all() else (np.where(keep, row, 0.0), keep)


def _calibration(value):
    """A pad calibration from what a model is given or its file holds: a
    PadCalibration, its dict (a model file's header), a CAL.toml path, or None."""
    if value is None:
        return None
    from telethermal.ident.pad_calibration import (PadCalibration, read_calibration)
    if isinstance(value, PadCalibration):
        return value
    if isinstance(value, dict):
        return PadCalibration.from_dict(value, "the model file's calibration")
    return read_calibration(value)


def classes_holding(log_e: float, log_sd: float, params: dict, classes, outlier_p: float):
    """The classes whose two-sided ``1 - outlier_p`` predictive holds a
    touch's estimate ``log_e`` (ln W s^0.5/(m^2 K)) with its own standard
    deviation ``log_sd``: ``|log_e - mean| <= t_(n-1) quantile x
    sqrt(scale^2 + log_sd^2)``, the class's Student t scale widened by the
    touch's own uncertainty (its interval holds the estimator's noise and
    model-error allowance). The training touches' spread alone is the
    spread under their conditions; a touch measured otherwise (frames
    dropped and held, another session) carries a bias its own interval
    allows, and is not a new material for it."""
    n = params["n"]
    scale = np.sqrt(params["var"] * (1.0 + 1.0 / n) + log_sd ** 2)
    limit = student_t.ppf(1.0 - outlier_p / 2, n - 1.0)
    z = np.abs(log_e - params["means"]) / scale
    return tuple(str(c) for c, a, b in zip(classes, z, limit) if a <= b)
