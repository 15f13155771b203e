"""Recurrent identifiers of active-heat-flow-sensing (Fig. 5, Appendix B):
linear encoder -> LSTM (or Elman RNN) -> linear decoder, cross-entropy,
backpropagation through time.

One network answers every prefix: it reads the gap-normalised heat flow step
by step and its decoder gives a posterior after each step, so the loss is
taken at every step from ``loss_from_s`` on (the paper scores only the end
of a 1 s window; scoring every step is what makes an anytime decision
possible). The input is box-averaged to ``input_rate_hz`` (100 Hz by
default): the paper's 1 kHz would cost ten times the training for a sensor
whose own response time is 0.2 s.
"""

from __future__ import annotations

import functools

import numpy as np

from telethermal.errors import IdentificationError
from telethermal.ident.base import Identifier
from telethermal.ident.prepare import FLUX, Contacts
from telethermal.threads import single_threaded_torch


def _softmax(z: np.ndarray) -> np.ndarray:
    z = z - z.max(axis=-1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=-1, keepdims=True)


def torch_module():
    """torch, imported when a recurrent model first trains or predicts: the
    other methods, and every process that only loads them (the services,
    the benches' workers), do without its import (about a second)."""
    import torch
    return torch


@functools.cache
def _net_class():
    """The network: encoder -> LSTM or RNN -> decoder (a torch module)."""
    nn = torch_module().nn

    class _Net(nn.Module):
        def __init__(self, n_in, n_hidden, n_out, cell):
            super().__init__()
            self.encoder = nn.Linear(n_in, n_hidden)
            rnn = nn.LSTM if cell == "lstm" else nn.RNN
            self.rnn = rnn(n_hidden, n_hidden, batch_first=True)
            self.decoder = nn.Linear(n_hidden, n_out)

        def forward(self, x, state=None):
            h, state = self.rnn(self.encoder(x), state)
            return self.decoder(h), state

    return _Net


class Recurrent(Identifier):
    """Shared code of ``lstm`` and ``rnn``."""

    cell = "lstm"
    streaming = True

    def __init__(self, channels=(FLUX,), n_hidden: int = 64, epochs: int = 300,
                 lr: float = 1e-2, input_rate_hz: float = 100.0, loss_from_s: float = 0.05,
                 **kw):
        super().__init__(channels, **kw)
        self.n_hidden = n_hidden
        self.epochs = epochs
        self.lr = lr
        self.input_rate_hz = input_rate_hz
        self.loss_from_s = loss_from_s
        # Learned by fit(): the inputs' scale per channel, the last loss.
        self.scale_: np.ndarray | None = None
        self.final_loss_: float | None = None
        self._module = None                        # the network, built on first use
        self._probe_state = None                   # update_probe's carried state

    def hyper(self) -> dict:
        return {**super().hyper(), "n_hidden": self.n_hidden, "epochs": self.epochs,
                "lr": self.lr, "input_rate_hz": self.input_rate_hz,
                "loss_from_s": self.loss_from_s}

    # ------------------------------------------------------------ input
    @property
    def _factor(self) -> int:
        return max(1, int(round(self.sample_rate_hz_ / self.input_rate_hz)))

    def _steps(self, x: np.ndarray):
        """Box-average (N, n, C) to (N, n // factor, C) and scale: a float32
        tensor."""
        torch = torch_module()
        f = self._factor
        n = (x.shape[1] // f) * f
        boxed = x[:, :n].reshape(len(x), n // f, f, x.shape[2]).mean(axis=2)
        return torch.as_tensor(boxed / self.scale_, dtype=torch.float32)

    def _net(self):
        if self._module is None:
            torch = torch_module()
            self._module = _net_class()(len(self.channels), self.n_hidden, len(self.classes_),
                                        self.cell)
            self._module.load_state_dict({k: torch.as_tensor(v) for k, v in
                                          self.params_[0].items() if k != "scale"})
            self._module.eval()
        return self._module

    def prepare(self) -> "Recurrent":
        """torch imported and the network built (about a second) before the
        first touch, not in its first posterior."""
        if getattr(self, "params_", None):
            self._net()
        else:
            torch_module()
        return self

    # ------------------------------------------------------------ fitting
    @single_threaded_torch
    def fit(self, contacts: Contacts) -> "Recurrent":
        """Train on ``contacts``; with ``calibrate``, first train the same
        network on two thirds of the groups and fit one softmax temperature
        per 0.1 s of steps on the held-out third (one extra training)."""
        temperatures = None
        if self.calibrate:
            temperatures = self._held_out_temperatures(contacts)
        self._train(contacts)
        if temperatures is not None:
            self.softmax_temperature_ = temperatures
        return self

    def _held_out_temperatures(self, contacts: Contacts):
        from telethermal.ident.base import fit_temperatures, group_folds

        folds = group_folds(contacts.groups, 3)
        if len(folds) < 2:
            return None
        test = folds[0]
        train = np.setdiff1d(np.arange(len(contacts)), test)
        held = contacts.subset(test)
        part = type(self)(**{**self.hyper(), "calibrate": False}, channels=self.channels)
        if len(set(contacts.subset(train).labels)) < len(set(contacts.labels)):
            return None
        part._train(contacts.subset(train))
        if part.classes_ != sorted(set(contacts.labels)):
            return None
        n = int(np.min(held.lengths))
        with torch_module().no_grad():
            logits, _ = part._net()(part._steps(held.x[:, :n]))
        z = logits.numpy().astype(np.float64).transpose(1, 0, 2)     # (steps, N, classes)
        y = np.array([part.classes_.index(c) for c in held.labels])
        pool = max(1, int(round(0.1 * self.input_rate_hz)))
        temps = fit_temperatures(z, y, pool)
        # Steps past the held-out trials' length keep the last block's temperature.
        out = np.full(len(part.windows_s_), temps[-1] if len(temps) else 1.0)
        out[:len(temps)] = temps
        return out

    def _train(self, contacts: Contacts) -> None:
        self.classes_ = self._check_fit_input(contacts)
        self.sample_rate_hz_ = contacts.sample_rate_hz
        n = min(int(np.min(contacts.lengths)), int(round(self.max_window_s * self.sample_rate_hz_)) + 1)
        if n < 2 * self._factor:
            raise IdentificationError("trials are too short for the recurrent model")
        x = contacts.x[:, :n]
        self.scale_ = np.maximum(np.nanstd(x.reshape(-1, x.shape[2]), axis=0), 1e-12)
        inputs = self._steps(x)
        steps = inputs.shape[1]
        self.windows_s_ = [round(((j + 1) * self._factor - 1) / self.sample_rate_hz_, 6)
                           for j in range(steps)]
        first = next(j for j, w in enumerate(self.windows_s_) if w >= self.loss_from_s)
        torch = torch_module()
        target = torch.as_tensor([self.classes_.index(c) for c in contacts.labels])
        torch.manual_seed(self.seed)
        net = _net_class()(len(self.channels), self.n_hidden, len(self.classes_), self.cell)
        optimiser = torch.optim.Adam(net.parameters(), lr=self.lr)
        loss_fn = torch.nn.CrossEntropyLoss()
        for _ in range(self.epochs):
            optimiser.zero_grad()
            logits, _ = net(inputs)
            tail = logits[:, first:]
            loss = loss_fn(tail.reshape(-1, tail.shape[-1]),
                           target.repeat_interleave(tail.shape[1]))
            loss.backward()
            optimiser.step()
        self.final_loss_ = float(loss.detach())
        self.params_ = [{k: v.detach().numpy().copy() for k, v in net.state_dict().items()}]
        self.params_[0]["scale"] = self.scale_
        from telethermal.ident.base import force_ranges
        self.force_range_n_ = force_ranges(self, contacts)
        self.softmax_temperature_ = np.ones(len(self.windows_s_))
        net.eval()
        self._module = net

    # ------------------------------------------------------------ predicting
    @single_threaded_torch
    def posterior_path(self, x: np.ndarray) -> np.ndarray:
        """Posteriors after every input step of one contact, (steps, n_classes)."""
        with torch_module().no_grad():
            logits, _ = self._net()(self._steps(x[None]))
        z = logits[0].numpy().astype(np.float64)
        return _softmax(z / self._temperatures(len(z))[:, None])

    @single_threaded_torch
    def proba_normalised(self, x: np.ndarray, window_index: int) -> np.ndarray:
        n = (window_index + 1) * self._factor
        with torch_module().no_grad():
            logits, _ = self._net()(self._steps(x[:, :n]))
        z = logits[:, -1].numpy().astype(np.float64)
        return _softmax(z / self._temperatures(window_index + 1)[window_index])

    def _temperatures(self, steps: int) -> np.ndarray:
        """The softmax temperature of each of the first ``steps`` steps (a
        model file from before calibration holds a single 1)."""
        t = np.asarray(self.softmax_temperature_, dtype=np.float64)
        if len(t) >= steps:
            return t[:steps]
        return np.concatenate([t, np.full(steps - len(t), t[-1] if len(t) else 1.0)])

    @single_threaded_torch
    def update_probe(self, row: np.ndarray, window_index: int) -> None:
        """One streaming update: a single step from a carried state."""
        net = self._net()
        torch = torch_module()
        with torch.no_grad():
            if self._probe_state is None:
                _, self._probe_state = net(self._steps(row[:, :self._factor]))
            step = self._steps(row[:, :self._factor])
            logits, self._probe_state = net(step, self._probe_state)
            torch.softmax(logits[:, -1], dim=-1)

    @classmethod
    def restore(cls, header: dict, arrays: dict) -> "Recurrent":
        model = super().restore(header, arrays)
        model.scale_ = model.params_[0]["scale"]
        return model


class Lstm(Recurrent):
    """active-heat-flow-sensing's classifier: encoder 64 -> LSTM 64 -> decoder."""

    method = "lstm"
    cell = "lstm"


class Rnn(Recurrent):
    """The same with an Elman RNN cell, the paper's comparison."""

    method = "rnn"
    cell = "rnn"
