"""Cubic B-splines evaluated without building and checking scipy objects
per call (issue 29).

:class:`~telethermal.ident.effusivity_curves.EffusivityFamily` evaluates its
tensor spline a few times per Newton step of every 20 ms window; building a
``scipy.interpolate.BSpline`` per evaluation (its checks), its derivative,
and an identity-coefficient basis per scalar cost more than the arithmetic.
:class:`SplineAxis` holds one axis's knots and what does not change between
calls (the derivative's knots and differentiation factors):

- :meth:`SplineAxis.weights`: the 4 basis functions and their derivatives
  at a scalar, in Python floats (``_deBoor_D``'s recursion, and the
  derivative as ``BSpline(knots, eye, 3).derivative()`` evaluates it);
- :meth:`SplineAxis.evaluate` / :meth:`SplineAxis.evaluate_derivative`: a
  spline on the axis at many points through ``BSpline.construct_fast``
  (scipy's compiled evaluation, no checks), the coefficients only computed
  over the rows the points reach (the others are never read: zeros).

The arithmetic is scipy's, step for step (``splder``'s ``(c[i+1] - c[i]) *
k / (t[i+k+1] - t[i+1])`` on the knots ``t[1:-1]``), so the values are
those of the scipy objects to the last bit (``tests/unit/test_fit_speed.py``
checks it). Knots must not repeat inside the axis (a spline interpolating
distinct nodes: only its ends repeat). Points outside the knots
extrapolate the end polynomials (``extrapolate=True``).
"""

from __future__ import annotations

import bisect

import numpy as np
from scipy.interpolate import BSpline

from telethermal.errors import IdentificationError


def _interval(knots, k: int, x: float) -> int:
    """``ell`` with ``knots[ell] <= x < knots[ell + 1]`` clipped to the base
    interval ``[k, len(knots) - k - 2]`` (scipy's, extrapolating)."""
    return min(max(bisect.bisect_right(knots, x) - 1, k), len(knots) - k - 2)


def _de_boor(knots, k: int, x: float, ell: int) -> list:
    """The ``k + 1`` degree-``k`` B-splines that can be nonzero at ``x``
    (indices ``ell - k .. ell``): scipy's ``_deBoor_D`` (no derivative)."""
    h = [1.0]
    for j in range(1, k + 1):
        hh, h = h, [0.0] * (j + 1)
        for n in range(1, j + 1):
            xb, xa = knots[ell + n], knots[ell + n - j]
            w = hh[n - 1] / (xb - xa)
            h[n - 1] += w * (xb - x)
            h[n] = w * (x - xa)
    return h


class SplineAxis:
    """One axis of a cubic spline: its ``knots`` and those of its first
    derivative (``knots[1:-1]``, degree 2, factors over ``t[i+4] - t[i+1]``)."""

    def __init__(self, knots):
        self.knots = np.asarray(knots, float)
        if len(self.knots) < 8 or np.any(np.diff(self.knots[3:-3]) <= 0):
            raise IdentificationError("a spline axis needs >= 8 knots, increasing but for "
                                      "its repeated ends")
        self.n_coef = len(self.knots) - 4
        self.d_knots = self.knots[1:-1]
        self.d_dt = self.knots[4:-1] - self.knots[1:-4]       # splder's dt
        self._knots_list, self._d_knots_list = self.knots.tolist(), self.d_knots.tolist()
        self._d_dt_list = self.d_dt.tolist()

    # ------------------------------------------------------------ one point
    def weights(self, x: float):
        """The 4 cubic basis functions that can be nonzero at the scalar
        ``x``: (their indices, values, first derivatives)."""
        ell = _interval(self._knots_list, 3, x)
        i0 = ell - 3
        values = _de_boor(self._knots_list, 3, x, ell)
        ell2 = _interval(self._d_knots_list, 2, x)
        b2 = _de_boor(self._d_knots_list, 2, x, ell2)
        d = [0.0] * 4
        for a in range(3):       # the derivative's row r: -3/dt_r at column r, +3/dt_r at r + 1
            r = ell2 - 2 + a
            for col, diff in ((r, -1.0), (r + 1, 1.0)):
                if i0 <= col < i0 + 4:
                    d[col - i0] += diff * 3 / self._d_dt_list[r] * b2[a]
        return np.arange(i0, i0 + 4), np.array(values), np.array(d)

    # ------------------------------------------------------------ many points
    def rows(self, x: np.ndarray) -> slice:
        """The coefficients a cubic spline on this axis reads at ``x``
        (``ell - 3 .. ell`` at each point); its derivative reads the rows
        ``ell - 3 .. ell - 1`` of its own, made of the same."""
        return slice(_interval(self._knots_list, 3, float(np.min(x))) - 3,
                     _interval(self._knots_list, 3, float(np.max(x))) + 1)

    def evaluate(self, coef: np.ndarray, rows: slice, x: np.ndarray) -> np.ndarray:
        """The spline whose coefficients ``rows`` are ``coef`` (first axis;
        ``rows`` from :meth:`rows` of ``x``) at ``x``: (m,) + coef.shape[1:]."""
        full = np.zeros((self.n_coef,) + coef.shape[1:])
        full[rows] = coef
        return BSpline.construct_fast(self.knots, full, 3, extrapolate=True)(x)

    def evaluate_derivative(self, coef: np.ndarray, rows: slice, x: np.ndarray) -> np.ndarray:
        """Its first derivative, as ``BSpline(...).derivative()`` computes it."""
        lo, hi = rows.start, rows.stop - 1                  # derivative rows lo .. hi - 1
        dt = self.d_dt[lo:hi].reshape((-1,) + (1,) * (coef.ndim - 1))
        full = np.zeros((self.n_coef - 1,) + coef.shape[1:])
        full[lo:hi] = (coef[1:] - coef[:-1]) * 3 / dt
        return BSpline.construct_fast(self.d_knots, full, 2, extrapolate=True)(x)
