"""Principal component analysis by the snapshot method of
learning-based-thermal-rendering eq. (1)-(3).

With N recordings of M samples (N << M), the M x M covariance is never
formed: the N x N matrix ``C = A A^T`` with ``A = Y^T / sqrt(N)`` is
diagonalised and the basis is ``phi_i = A^T v_i / sqrt(lambda_i)`` (eq. 3,
written for column vectors). Eigenvalues at or below ``rank_tol`` times the
largest are dropped before that division: a rank-deficient set (fewer trials
than samples, repeated or constant recordings) keeps only the directions it
actually spans, and an all-constant set keeps none.
"""

from __future__ import annotations

import numpy as np

from telethermal.errors import IdentificationError


class SnapshotPCA:
    """``fit(x)`` learns ``mean_``, ``components_`` (k, M) and
    ``eigenvalues_`` (k,); ``transform`` projects."""

    def __init__(self, max_components: int = 20, rank_tol: float = 1e-10):
        self.max_components = max_components
        self.rank_tol = rank_tol
        # Learned by fit(); None until then.
        self.mean_: np.ndarray | None = None
        self.components_: np.ndarray | None = None
        self.eigenvalues_: np.ndarray | None = None

    def fit(self, x: np.ndarray) -> "SnapshotPCA":
        """Parameters: x, shape (N, M), one recording per row."""
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or len(x) == 0:
            raise IdentificationError(f"PCA needs a non-empty (N, M) array, got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise IdentificationError("PCA input contains NaN or inf")
        n = len(x)
        self.mean_ = x.mean(axis=0)                          # eq. (1)
        y = x - self.mean_                                   # rows are y_i^T, eq. (2)
        a = y / np.sqrt(n)                                   # A^T in the paper's notation
        lam, vec = np.linalg.eigh(a @ a.T)                   # N x N, ascending
        order = np.argsort(lam)[::-1]
        lam, vec = lam[order], vec[:, order]
        top = lam[0] if len(lam) and lam[0] > 0 else 0.0
        keep = lam > self.rank_tol * top if top > 0 else np.zeros(len(lam), bool)
        keep &= np.arange(len(lam)) < self.max_components
        lam, vec = lam[keep], vec[:, keep]
        self.components_ = (a.T @ vec / np.sqrt(lam)).T      # eq. (3), (k, M), orthonormal
        self.eigenvalues_ = lam
        return self

    def transform(self, x: np.ndarray) -> np.ndarray:
        """Projections u = (x - mean) . phi, shape (N, k)."""
        if self.components_ is None:
            raise IdentificationError("SnapshotPCA is not fitted")
        return (np.asarray(x, dtype=np.float64) - self.mean_) @ self.components_.T
