"""A one-hidden-layer network and its Levenberg-Marquardt training.

The network of learning-based-thermal-rendering section 3.2: inputs, one
hidden layer of sigmoids, sigmoid outputs for classification (or linear
outputs for the flux generator), mean squared error (eq. 4), trained by
``w <- w - (J^T J + mu I)^-1 J^T e`` (eq. 5) with the Jacobian of the
residuals computed analytically and the damping ``mu`` adapted: divided by
10 after a step that lowers the loss, multiplied by 10 and retried after one
that does not. The damped normal matrix is solved by Cholesky; should that
fail (a singular J^T J with mu underflowed), by least squares.

An optional L2 penalty enters as extra residuals ``sqrt(l2) * w``. Adam on
the same loss is here too, for the benchmark's comparison.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve, lstsq

from telethermal.errors import IdentificationError
from telethermal.threads import single_threaded_blas


def _sigmoid(x):
    return 0.5 * (1.0 + np.tanh(0.5 * x))       # no overflow for any x


@dataclass
class MLP:
    """Weights of an ``n_in -> n_hidden (sigmoid) -> n_out`` network."""

    w1: np.ndarray      # (H, d)
    b1: np.ndarray      # (H,)
    w2: np.ndarray      # (C, H)
    b2: np.ndarray      # (C,)
    output: str = "sigmoid"

    @classmethod
    def init(cls, n_in: int, n_hidden: int, n_out: int, rng: np.random.Generator,
             output: str = "sigmoid") -> "MLP":
        """Nguyen-Widrow-like scaled random start."""
        w1 = rng.normal(0.0, 1.0 / np.sqrt(max(n_in, 1)), (n_hidden, n_in))
        w2 = rng.normal(0.0, 1.0 / np.sqrt(n_hidden), (n_out, n_hidden))
        return cls(w1, np.zeros(n_hidden), w2, np.zeros(n_out), output)

    @property
    def shapes(self):
        return [self.w1.shape, self.b1.shape, self.w2.shape, self.b2.shape]

    def vector(self) -> np.ndarray:
        return np.concatenate([p.ravel() for p in (self.w1, self.b1, self.w2, self.b2)])

    def with_vector(self, theta: np.ndarray) -> "MLP":
        parts, start = [], 0
        for shape in self.shapes:
            size = int(np.prod(shape))
            parts.append(theta[start:start + size].reshape(shape))
            start += size
        return MLP(*parts, output=self.output)

    def hidden(self, x):
        return _sigmoid(x @ self.w1.T + self.b1)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Outputs, shape (N, C), for inputs (N, d)."""
        out = self.hidden(x) @ self.w2.T + self.b2
        return _sigmoid(out) if self.output == "sigmoid" else out

    def jacobian(self, x: np.ndarray):
        """Outputs (N, C) and d outputs / d weights, shape (N*C, P), row n*C + c."""
        a = self.hidden(x)                                  # (N, H)
        z = a @ self.w2.T + self.b2
        if self.output == "sigmoid":
            z = _sigmoid(z)
            g = z * (1.0 - z)                               # dz/do, (N, C)
        else:
            g = np.ones_like(z)
        n, c = z.shape
        h, d = self.w1.shape
        da = a * (1.0 - a)                                  # (N, H)
        # d z_nc / d w1_hj = g_nc w2_ch da_nh x_nj
        back = g[:, :, None] * self.w2[None] * da[:, None, :]      # (N, C, H)
        j_w1 = back[:, :, :, None] * x[:, None, None, :]           # (N, C, H, d)
        j_b1 = back
        eye = np.eye(c)
        j_w2 = g[:, :, None, None] * eye[None, :, :, None] * a[:, None, None, :]  # (N,C,C,H)
        j_b2 = g[:, :, None] * eye[None]
        jac = np.concatenate([j_w1.reshape(n, c, h * d), j_b1, j_w2.reshape(n, c, c * h), j_b2],
                             axis=2)
        return z, jac.reshape(n * c, -1)


@dataclass
class FitHistory:
    """Loss (eq. 4, plus the L2 term) after each accepted iteration."""

    loss: list[float] = field(default_factory=list)
    damping: list[float] = field(default_factory=list)
    fallbacks: int = 0
    stopped: str = ""


def _loss(net: MLP, x, y, l2):
    r = net(x) - y
    return 0.5 * np.sum(r * r) / len(x) + 0.5 * l2 * np.sum(net.vector() ** 2) / len(x)


def _damped_step(jtj, grad, mu, history):
    """Solve (J^T J + mu I) step = grad by Cholesky, else by least squares."""
    a = jtj + mu * np.eye(len(jtj))
    try:
        return cho_solve(cho_factor(a, check_finite=True), grad)
    except (LinAlgError, ValueError):
        history.fallbacks += 1
        return lstsq(a, grad, cond=None)[0]


@single_threaded_blas
def train_lm(net: MLP, x: np.ndarray, y: np.ndarray, max_iter: int = 200, l2: float = 1e-4,
             mu: float = 1e-2, tol: float = 1e-9) -> tuple[MLP, FitHistory]:
    """Levenberg-Marquardt on the mean squared error of ``net(x)`` against ``y``.

    Parameters
    ----------
    x : ndarray, shape (N, d)
    y : ndarray, shape (N, C)
    l2 : float
        Weight of the L2 penalty on the weights (0 for none).
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if mu < 0 or l2 < 0:
        raise IdentificationError(f"damping and l2 must be >= 0, got {mu}, {l2}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise IdentificationError("training data contain NaN or inf")
    history = FitHistory()
    loss = _loss(net, x, y, l2)
    history.loss.append(loss)
    for _ in range(max_iter):
        z, jac = net.jacobian(x)
        theta = net.vector()
        r = (z - y).ravel()
        jtj = jac.T @ jac + l2 * np.eye(len(theta))
        grad = jac.T @ r + l2 * theta
        if np.max(np.abs(grad)) < tol:
            history.stopped = "gradient"
            break
        while True:
            candidate = net.with_vector(theta - _damped_step(jtj, grad, mu, history))
            new_loss = _loss(candidate, x, y, l2)
            if np.isfinite(new_loss) and new_loss < loss:
                mu = max(mu / 10.0, 1e-12)
                break
            mu = max(mu * 10.0, 1e-12)          # also lifts a zero damping
            if mu > 1e12:
                history.stopped = "damping"
                return net, history
        improvement = loss - new_loss
        net, loss = candidate, new_loss
        history.loss.append(loss)
        history.damping.append(mu)
        if improvement < tol * max(loss, 1e-12):
            history.stopped = "loss"
            break
    else:
        history.stopped = "iterations"
    return net, history


@single_threaded_blas
def train_adam(net: MLP, x: np.ndarray, y: np.ndarray, epochs: int = 2000, lr: float = 1e-2,
               l2: float = 1e-4) -> tuple[MLP, FitHistory]:
    """Full-batch Adam on the same loss, for comparison with LM."""
    history = FitHistory()
    theta = net.vector()
    m = np.zeros_like(theta)
    v = np.zeros_like(theta)
    for k in range(1, epochs + 1):
        z, jac = net.jacobian(x)
        grad = (jac.T @ (z - y).ravel() + l2 * theta) / len(x)
        m = 0.9 * m + 0.1 * grad
        v = 0.999 * v + 0.001 * grad * grad
        theta = theta - lr * (m / (1 - 0.9 ** k)) / (np.sqrt(v / (1 - 0.999 ** k)) + 1e-8)
        net = net.with_vector(theta)
        history.loss.append(_loss(net, x, y, l2))
    history.stopped = "epochs"
    return net, history
