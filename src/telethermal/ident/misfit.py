"""The pad-model check's pieces the anytime decision uses
(:mod:`telethermal.ident.anytime`; docs/calibration.md): the check of one
window, its run over a touch's windows, and the samples a model reads as
missing."""

from __future__ import annotations

import numpy as np


def with_missing(model, x: np.ndarray, measured) -> np.ndarray:
    """One contact's samples ``x`` (n, C) as ``model`` reads them: for a
    model that takes missing samples (``Identifier.missing_samples``), the
    ones not ``measured`` ((n,) bool; None: all were) as NaN, so a frame
    lost on the line is missing data, not the sample the driver held
    (``effusivity-fit`` fits the measured ones alone); else ``x`` itself."""
    if measured is None or not getattr(model, "missing_samples", False):
        return x
    lost = ~np.asarray(measured, bool)[:len(x)]
    if not lost.any():
        return x
    x = np.array(x, dtype=np.float64)
    x[:len(lost)][lost] = np.nan
    return x


class MisfitRun:
    """The pad-model check (:func:`pad_model_misfit`) over one touch's
    windows: a touch ends on it once its window's fit has been past the
    limit at ``confirm`` windows in a row (``confirm_windows``, as a
    commitment), or at its last window; a window past it and not yet
    confirmed commits nothing (neither a class nor a new material). As the
    rule's :class:`~telethermal.ident.rule.Runs`: each window is a separate
    fit, and the first windows have few samples (0.04 s: 5, one degree of
    freedom), where one window past the limit is not the evidence a pad off
    its model gives (its residual grows with the window: docs/calibration.md)."""

    def __init__(self, confirm: int):
        self.need, self.run = max(1, int(confirm)), 0

    def step(self, flagged: bool, last: bool) -> bool:
        """Window past the limit (``flagged``): end the touch on it now?"""
        self.run = self.run + 1 if flagged else 0
        return flagged and (self.run >= self.need or last)


def pad_model_misfit(model, x: np.ndarray, window_index: int,
                     measured: np.ndarray | None = None) -> bool:
    """True where ``model`` fits a pad model to the touch ``x`` (1, n, C)
    and its fit at the window leaves a residual past what the noise allows
    (``EffusivityFit.misfit``): the touch is not named by that model.
    ``measured`` (n,) bool, None for all: the samples the sensor delivered;
    the ones filled in (False) are not counted in the residual."""
    check = getattr(model, "misfit", None)
    if check is None:
        return False
    if measured is None or bool(np.all(measured)):
        return bool(check(x, window_index))
    return bool(check(x, window_index, measured=np.asarray(measured, bool)))
