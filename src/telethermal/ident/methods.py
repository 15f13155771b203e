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

    def features(self, params, x):
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
        u = self.features(params, x)
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
        z = net(self.features(params, x))
        return np.log(np.clip(z, 1e-6, None))


class EffusivityLda(Identifier):
    """telethermal's own method, from the closed form: for a semi-infinite
    contact ``q sqrt(t) / gap = e_eff / sqrt(pi)`` whatever the gap, so the
    window is cut into ``n_boxes`` equal boxes and each box's mean normalised
    flux, times the square root of its mid time, estimates an effusivity (the
    pad's film, lag and contact conductance bend it in a way that is itself
    characteristic). ``asinh`` compresses the range; discriminant analysis
    classifies: a shrunk pooled covariance blended with each class's own
    (regularised discriminant analysis, Friedman 1989, J. Am. Stat. Assoc.
    84:165; weight 1 is linear discriminant analysis). A material's touches
    spread along its own curve of contact conductance, which a single pooled
    covariance cannot follow for two close materials (plexiglass and rubber,
    6 % apart in effusivity). Both the shrinkage and the weight are chosen by
    grouped cross-validation on the training touches. A contact whose
    squared Mahalanobis distance to every class exceeds the chi-square
    quantile ``1 - outlier_p`` is outside every class."""

    method = "effusivity-lda"

    #: Shrinkage values tried by grouped cross-validation (``shrinkage="cv"``).
    SHRINKAGE_GRID = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3)

    #: Weights of the pooled scatter tried by grouped cross-validation
    #: (``pooled_weight="cv"``; 1: linear discriminant analysis).
    POOLED_WEIGHT_GRID = (1.0, 0.85, 0.7, 0.5, 0.3)

    def __init__(self, channels=(FLUX,), n_boxes: int = 8, shrinkage: float | str = "cv",
                 outlier_p: float = 1e-4, window_step_s: float = 0.02,
                 pooled_weight: float | str = "cv", **kw):
        super().__init__(channels, window_step_s=window_step_s, **kw)
        self.pooled_weight = pooled_weight
        self.pooled_weight_: float | None = None    # learned (or given) by fit()
        self.n_boxes = n_boxes
        self.shrinkage = shrinkage
        self.outlier_p = outlier_p
        self.shrinkage_: float | None = None        # learned (or given) by fit()

    def hyper(self) -> dict:
        return {**super().hyper(), "n_boxes": self.n_boxes, "shrinkage": self.shrinkage,
                "outlier_p": self.outlier_p, "pooled_weight": self.pooled_weight}

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
        from telethermal.errors import IdentificationError

        for name, value in (("shrinkage", self.shrinkage), ("pooled_weight", self.pooled_weight)):
            if value != "cv" and not (isinstance(value, (int, float)) and 0 <= value <= 1):
                raise IdentificationError(f"{name} must be 'cv' or a number in [0, 1], got "
                                          f"{value!r}")
        if "cv" in (self.shrinkage, self.pooled_weight):
            self.classes_ = self._check_fit_input(contacts)
            self.sample_rate_hz_ = contacts.sample_rate_hz
        # The shrinkage first, as linear discriminant analysis; then how much
        # of each class's own scatter to keep, with that shrinkage.
        self.pooled_weight_ = 1.0
        cases = self._cv_cases(contacts) if "cv" in (self.shrinkage, self.pooled_weight) \
            else None
        self.shrinkage_ = self._cv_choose(cases, "shrinkage_", self.SHRINKAGE_GRID, 0.1) \
            if self.shrinkage == "cv" else float(self.shrinkage)
        self.pooled_weight_ = self._cv_choose(cases, "pooled_weight_",
                                              self.POOLED_WEIGHT_GRID, 1.0) \
            if self.pooled_weight == "cv" else float(self.pooled_weight)
        return super().fit(contacts)

    def learned(self) -> dict:
        return {**super().learned(), "shrinkage_": self.shrinkage_,
                "pooled_weight_": self.pooled_weight_}

    def _cv_cases(self, contacts):
        """The cross-validation's cases: folds grouped by the trials' group
        (``trial-k`` within one session of a generated database; a dataset
        of several sessions can name sessions as groups), so a group never
        both trains and scores, and windows every 0.1 s up to 1 s; each
        fold's and window's features, train and test, in the order the loss
        sums them (they do not depend on the value tried: made once for
        both choices). "few groups" or "a fold lacks a class" when there
        are none to make."""
        from telethermal.ident.base import group_folds

        y = np.array([self.classes_.index(c) for c in contacts.labels])
        folds = group_folds(contacts.groups, 5)
        if len(folds) < 2:
            return "few groups"
        usable = float(np.min(contacts.lengths - 1)) / self.sample_rate_hz_
        windows = [w for w in np.arange(1, 11) * 0.1 if w <= min(usable, self.max_window_s) + 1e-9]
        windows = windows or [usable]
        cases = []
        for test in folds:
            train = np.setdiff1d(np.arange(len(y)), test)
            if len(set(y[train])) < len(self.classes_):
                return "a fold lacks a class"
            for w in windows:
                cases.append((self._raw_features(self.window(contacts.x[train], w)), y[train],
                              self._raw_features(self.window(contacts.x[test], w)), y[test]))
        return cases

    def _cv_choose(self, cases, attr: str, grid, fallback: float) -> float:
        """The value of ``attr`` in ``grid`` with the lowest held-out log
        loss, pooled over the :meth:`_cv_cases`; ``fallback`` when there
        are none (too few groups, or a fold lacks a class: said)."""
        from scipy.special import log_softmax

        if isinstance(cases, str):                    # none to make: why
            if cases == "a fold lacks a class":
                log.warning("%s: a fold lacks a class; %g used without cross-validation",
                            attr.rstrip("_"), fallback)
            return fallback
        losses = []
        for value in grid:
            setattr(self, attr, value)
            total = 0.0
            for f_train, y_train, f_test, y_test in cases:
                params = self._fit_features(f_train, y_train)
                z = self._logits_of_features(params, f_test)
                total -= log_softmax(z, axis=1)[np.arange(len(y_test)), y_test].sum()
            losses.append(total)
        best = int(np.argmin(losses))
        if best in (0, len(grid) - 1):
            log.info("%s %g chosen at the edge of the grid %s", attr.rstrip("_"), grid[best],
                     grid)
        return float(grid[best])

    def _fit_window(self, x, y):
        return self._fit_features(self._raw_features(x), y)

    def _fit_features(self, f, y):
        """:meth:`_fit_window` on the window's features (:meth:`_raw_features`)."""
        centre, scale = f.mean(axis=0), np.maximum(f.std(axis=0), 1e-9)
        z = (f - centre) / scale
        classes = np.arange(int(y.max()) + 1)
        means = np.stack([z[y == c].mean(axis=0) for c in classes])
        resid = z - means[y]
        cov = resid.T @ resid / max(len(z) - len(classes), 1)
        p = cov.shape[0]
        target = np.trace(cov) / p if np.trace(cov) > 0 else 1.0
        cov = (1 - self.shrinkage_) * cov + self.shrinkage_ * target * np.eye(p)
        if self.pooled_weight_ >= 1.0:
            return {"centre": centre, "scale": scale, "means": means,
                    "precision": np.linalg.pinv(cov, hermitian=True)}
        # Regularised discriminant analysis (Friedman 1989): each class's own
        # scatter blended with the pooled one.
        blends = []
        for c in classes:
            r = resid[y == c]
            own = r.T @ r / max(len(r) - 1, 1)
            blends.append(self.pooled_weight_ * cov + (1 - self.pooled_weight_) * own)
        blends = np.stack(blends)           # one LAPACK call per kind for every class
        _, logdets = np.linalg.slogdet(blends)
        return {"centre": centre, "scale": scale, "means": means,
                "precision": np.linalg.pinv(blends, hermitian=True), "logdet": logdets}

    def _distances(self, params, x):
        return self._distances_of_features(params, self._raw_features(x))

    def _distances_of_features(self, params, f):
        z = (f - params["centre"]) / params["scale"]
        diff = z[:, None, :] - params["means"][None]
        prec = params["precision"]
        if prec.ndim == 3:
            return np.einsum("nci,cij,ncj->nc", diff, prec, diff)
        return np.sum((diff @ prec) * diff, axis=2)

    def _logits(self, params, x):
        return self._logits_of_features(params, self._raw_features(x))

    def _logits_of_features(self, params, f):
        d = self._distances_of_features(params, f)
        if "logdet" in params:
            return -0.5 * (d + params["logdet"][None])
        return -0.5 * d

    def outside_classes(self, x, window_index):
        params = self.params_[window_index]
        d2 = self._distances(params, self.window(x, self.windows_s_[window_index]))
        limit = chi2.ppf(1.0 - self.outlier_p, df=params["means"].shape[1])
        return d2.min(axis=1) > limit
