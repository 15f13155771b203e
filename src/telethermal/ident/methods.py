"""Window-bank identifiers: the first paper's PCA + LM network, and
telethermal's effusivity features with linear discriminant analysis."""

from __future__ import annotations

import logging

import numpy as np
from scipy.stats import chi2

from telethermal.ident.base import Identifier
from telethermal.ident.lm import MLP, train_lm
from telethermal.ident.pca import SnapshotPCA
from telethermal.ident.prepare import FLUX

log = logging.getLogger(__name__)


class PcaFnn(Identifier):
    """learning-based-thermal-rendering section 3: the gap-normalised window,
    PCA by the snapshot method (at most ``n_components`` directions, scaled
    together by the first one's spread),
    a one-hidden-layer sigmoid network with MSE loss trained by
    Levenberg-Marquardt from ``restarts`` random starts (the best kept)."""

    method = "pca-fnn"

    def __init__(self, channels=(FLUX,), n_components: int = 8, n_hidden: int = 8,
                 max_iter: int = 60, restarts: int = 1, window_step_s: float = 0.1,
                 calibrate: bool = True, **kw):
        super().__init__(channels, window_step_s=window_step_s, calibrate=calibrate, **kw)
        self.n_components = n_components
        self.n_hidden = n_hidden
        self.max_iter = max_iter
        self.restarts = restarts

    def hyper(self) -> dict:
        return {**super().hyper(), "n_components": self.n_components,
                "n_hidden": self.n_hidden, "max_iter": self.max_iter, "restarts": self.restarts}

    def _features(self, params, x):
        flat = x.reshape(len(x), -1)
        u = (flat - params["mean"]) @ params["components"].T
        # One scale for all components (the first's spread): whitening each
        # would blow the noise directions up to the size of the signal one.
        return u / np.sqrt(params["eigenvalues"][0])

    def _fit_window(self, x, y):
        pca = SnapshotPCA(min(self.n_components, len(x) - 1)).fit(x.reshape(len(x), -1))
        params = {"mean": pca.mean_, "components": pca.components_,
                  "eigenvalues": pca.eigenvalues_}
        n_classes = int(y.max()) + 1
        if len(pca.eigenvalues_) == 0:          # nothing varies: no information
            return params
        u = self._features(params, x)
        target = np.eye(n_classes)[y]
        rng = np.random.default_rng(self.seed + x.shape[1])
        best = None
        for _ in range(self.restarts):
            net, hist = train_lm(MLP.init(u.shape[1], self.n_hidden, n_classes, rng), u, target,
                                 max_iter=self.max_iter)
            if best is None or hist.loss[-1] < best[1]:
                best = (net, hist.loss[-1])
        net = best[0]
        return {**params, "w1": net.w1, "b1": net.b1, "w2": net.w2, "b2": net.b2}

    def _logits(self, params, x):
        if "w1" not in params:
            return np.zeros((len(x), len(self.classes_)))
        net = MLP(params["w1"], params["b1"], params["w2"], params["b2"])
        z = net(self._features(params, x))
        return np.log(np.clip(z, 1e-6, None))


class EffusivityLda(Identifier):
    """telethermal's own method, from the closed form: for a semi-infinite
    contact ``q sqrt(t) / gap = e_eff / sqrt(pi)`` whatever the gap, so the
    window is cut into ``n_boxes`` equal boxes and each box's mean normalised
    flux, times the square root of its mid time, estimates an effusivity (the
    pad's film, lag and contact conductance bend it in a way that is itself
    characteristic). ``asinh`` compresses the range; linear discriminant
    analysis with a shrunk pooled covariance classifies, and a contact whose
    squared Mahalanobis distance to every class exceeds the chi-square
    quantile ``1 - outlier_p`` is outside every class."""

    method = "effusivity-lda"

    #: Shrinkage values tried by grouped cross-validation (``shrinkage="cv"``).
    SHRINKAGE_GRID = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3)

    def __init__(self, channels=(FLUX,), n_boxes: int = 8, shrinkage: float | str = "cv",
                 outlier_p: float = 1e-4, window_step_s: float = 0.02, **kw):
        super().__init__(channels, window_step_s=window_step_s, **kw)
        self.n_boxes = n_boxes
        self.shrinkage = shrinkage
        self.outlier_p = outlier_p
        self.shrinkage_: float | None = None        # learned (or given) by fit()

    def hyper(self) -> dict:
        return {**super().hyper(), "n_boxes": self.n_boxes, "shrinkage": self.shrinkage,
                "outlier_p": self.outlier_p}

    def _raw_features(self, x):
        """Box means (cumulative sums: one pass, no Python loop over boxes),
        channel-major, (N, n_channels * n_boxes)."""
        n_trials, n, n_channels = x.shape
        boxes = min(self.n_boxes, n)
        edges = np.linspace(0, n, boxes + 1).round().astype(int)
        cs = np.zeros((n_trials, n + 1, n_channels))
        np.cumsum(x, axis=1, out=cs[:, 1:])
        means = (cs[:, edges[1:]] - cs[:, edges[:-1]]) / np.diff(edges)[None, :, None]
        mid_s = 0.5 * (edges[:-1] + edges[1:] - 1) / self.sample_rate_hz_
        root = np.sqrt(np.maximum(mid_s, 0.5 / self.sample_rate_hz_))
        for c, name in enumerate(self.channels):
            if name == FLUX:
                means[:, :, c] = np.arcsinh(means[:, :, c] * root)
        return means.transpose(0, 2, 1).reshape(n_trials, n_channels * boxes)

    def fit(self, contacts):
        """Choose the shrinkage (unless given as a number), then fit."""
        if self.shrinkage == "cv":
            self.classes_ = self._check_fit_input(contacts)
            self.sample_rate_hz_ = contacts.sample_rate_hz
            self.shrinkage_ = self._cv_shrinkage(contacts)
        elif isinstance(self.shrinkage, (int, float)) and 0 <= self.shrinkage <= 1:
            self.shrinkage_ = float(self.shrinkage)
        else:
            from telethermal.errors import IdentificationError
            raise IdentificationError(f"shrinkage must be 'cv' or a number in [0, 1], got "
                                      f"{self.shrinkage!r}")
        return super().fit(contacts)

    def learned(self) -> dict:
        return {**super().learned(), "shrinkage_": self.shrinkage_}

    def _cv_shrinkage(self, contacts) -> float:
        """The grid value with the lowest held-out log loss, pooled over
        windows every 0.1 s up to 1 s; folds grouped by the trials' group
        (``trial-k`` within one session of a generated database; a dataset
        of several sessions can name sessions as groups), so a group never
        both trains and scores."""
        from telethermal.ident.base import group_folds
        from scipy.special import log_softmax

        y = np.array([self.classes_.index(c) for c in contacts.labels])
        folds = group_folds(contacts.groups, 5)
        if len(folds) < 2:
            return 0.1
        usable = float(np.min(contacts.lengths - 1)) / self.sample_rate_hz_
        windows = [w for w in np.arange(1, 11) * 0.1 if w <= min(usable, self.max_window_s) + 1e-9]
        windows = windows or [usable]
        losses = []
        for shrinkage in self.SHRINKAGE_GRID:
            self.shrinkage_ = shrinkage
            total = 0.0
            for test in folds:
                train = np.setdiff1d(np.arange(len(y)), test)
                if len(set(y[train])) < len(self.classes_):
                    log.warning("shrinkage: a fold lacks a class; 0.1 used without "
                                "cross-validation")
                    return 0.1
                for w in windows:
                    params = self._fit_window(self._window(contacts.x[train], w), y[train])
                    z = self._logits(params, self._window(contacts.x[test], w))
                    total -= log_softmax(z, axis=1)[np.arange(len(test)), y[test]].sum()
            losses.append(total)
        best = int(np.argmin(losses))
        if best in (0, len(self.SHRINKAGE_GRID) - 1):
            log.info("shrinkage %g chosen at the edge of the grid %s", self.SHRINKAGE_GRID[best],
                     self.SHRINKAGE_GRID)
        return float(self.SHRINKAGE_GRID[best])

    def _fit_window(self, x, y):
        f = self._raw_features(x)
        centre, scale = f.mean(axis=0), np.maximum(f.std(axis=0), 1e-9)
        z = (f - centre) / scale
        classes = np.arange(int(y.max()) + 1)
        means = np.stack([z[y == c].mean(axis=0) for c in classes])
        resid = z - means[y]
        cov = resid.T @ resid / max(len(z) - len(classes), 1)
        p = cov.shape[0]
        target = np.trace(cov) / p if np.trace(cov) > 0 else 1.0
        cov = (1 - self.shrinkage_) * cov + self.shrinkage_ * target * np.eye(p)
        return {"centre": centre, "scale": scale, "means": means,
                "precision": np.linalg.pinv(cov, hermitian=True)}

    def _distances(self, params, x):
        z = (self._raw_features(x) - params["centre"]) / params["scale"]
        diff = z[:, None, :] - params["means"][None]
        return np.sum((diff @ params["precision"]) * diff, axis=2)

    def _logits(self, params, x):
        return -0.5 * self._distances(params, x)

    def outside_classes(self, x, window_index):
        params = self.params_[window_index]
        d2 = self._distances(params, self._window(x, self.windows_s_[window_index]))
        limit = chi2.ppf(1.0 - self.outlier_p, df=params["means"].shape[1])
        return d2.min(axis=1) > limit
