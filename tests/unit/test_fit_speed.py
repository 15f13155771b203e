"""The effusivity fit made cheaper (issue 29) gives the same results.

The code path before issue 29 is kept here only, as the reference: the
curve through scipy ``BSpline`` objects built per call, the kernel prior's
direct sums, and the Newton loop that evaluated every step to the last
(``git show e8e7382:src/telethermal/ident/effusivity.py``). The new curve is
that path's to the bit; the prior's terms to rounding; the fits, walked
window by window as the slave walks a touch, within a thousandth of each
estimate's own posterior sd in ``ln e`` (measured: under 3e-5 sd, 1.1e-6 in
``ln e``, on 1 s walks of fingertip-7 and gripper-case-I-pro; the old loop's
own answer wanders by that much with rounding: it took steps whose gain was
below the objective's resolution, and the prior's terms alone, changed to
rounding, move it as much). No timing here: the evaluations are counted.
"""

import dataclasses

import numpy as np
import pytest
from scipy.interpolate import BSpline

from telethermal.data.generate import pad_database
from telethermal.errors import IdentificationError
from telethermal.ident.bspline import SplineAxis
from telethermal.ident.effusivity import EffusivityEstimator
from telethermal.ident.oracle import KernelPrior, marginal_log_likelihood
from telethermal.ident.prepare import from_trials
from telethermal.physics.scene import ObjectSpec, load_scene

WINDOW_S = 0.5
MATERIALS = ("foam", "plexiglass", "wood", "marble", "steel", "aluminium", "copper")


# ---------------------------------------------------------------- the old path
def _old_weights(family, axis, x):
    knots = family.spline.t[axis]
    basis = BSpline(knots, np.eye(len(knots) - 4), 3, extrapolate=True)
    last = int(np.clip(np.searchsorted(knots, x, side="right") - 1, 3, len(knots) - 5))
    idx = np.arange(last - 3, last + 1)
    return idx, basis(x)[idx], basis.derivative()(x)[idx]


def _old_curve(family, theta, times_s, deriv=False):
    (i, wi, di), (j, wj, dj) = [_old_weights(family, a, theta[a]) for a in (0, 1)]
    block = family.spline.c[i[0]:i[-1] + 1, j[0]:j[-1] + 1]
    cols = [np.einsum("a,b,abk->k", wi, wj, block)]
    if deriv:
        cols += [np.einsum("a,b,abk->k", di, wj, block), np.einsum("a,b,abk->k", wi, dj, block)]
    t = times_s - theta[2]
    values = BSpline(family.spline.t[2], np.stack(cols, axis=1), 3, extrapolate=True)(t)
    if not deriv:
        return values[:, 0]
    d_t = BSpline(family.spline.t[2], cols[0], 3, extrapolate=True).derivative()(t)
    return values[:, 0], np.column_stack([values[:, 1], values[:, 2], -d_t])


def _old_terms(prior, point):
    diff = point[None, :] - prior.theta
    v = diff @ prior._inv
    log_w = -0.5 * np.sum(v * diff, axis=1)
    top = log_w.max()
    w = np.exp(log_w - top)
    total = w.sum()
    w /= total
    grad = -(w @ v)
    hess = (v * w[:, None]).T @ v - np.outer(grad, grad) - prior._inv
    return top + np.log(total) + prior._norm, grad, hess


class _OldEstimator(EffusivityEstimator):
    """The estimator as it was: the old objective's parts and Newton loop."""

    evaluations = 0

    def _objective(self, theta, x, s):
        type(self).evaluations += 1
        a0, sa = self.amplitude
        g, jac = _old_curve(self.family, theta, np.arange(len(x)) / self.sample_rate_hz, True)
        logl, dg = marginal_log_likelihood(x, g, s, a0, sa)
        lp, lp_grad, lp_hess = _old_terms(self.prior, theta[1:])
        grad = jac.T @ dg
        grad[1:] += lp_grad
        mj = a0 * jac
        proj = mj - np.outer(g, g @ mj) * (sa ** 2 / (s + sa ** 2 * np.dot(g, g)))
        hess = -(mj.T @ proj) / s
        hess[1:, 1:] += lp_hess
        return logl + lp, grad, hess

    def _fit(self, x, s, start=None, t_s=None):
        # Every window here is whole (no lost frame): the old fit's times,
        # every sample from the onset, are t_s.
        assert t_s is None or np.allclose(t_s, np.arange(len(x)) / self.sample_rate_hz)
        t_s = np.arange(len(x)) / self.sample_rate_hz
        theta = self._start(x, s, t_s) if start is None else np.clip(
            np.asarray(start, float), self.lo, self.hi)
        value, grad, hess = self._objective(theta, x, s)
        lam = 1e-3
        for _ in range(50):
            scale = np.sqrt(np.maximum(np.abs(np.diag(hess)), 1e-300))
            a = -hess / np.outer(scale, scale) + lam * np.eye(3)
            new = np.clip(theta + np.linalg.solve(a, grad / scale) / scale, self.lo, self.hi)
            v_new, g_new, h_new = self._objective(new, x, s)
            if v_new >= value:
                done = v_new - value < 1e-9 * max(1.0, abs(value))
                theta, value, grad, hess = new, v_new, g_new, h_new
                lam = max(lam / 10, 1e-9)
                if done:
                    break
            else:
                lam *= 10
                if lam > 1e8:
                    break
        return theta, hess


class _CountedEstimator(EffusivityEstimator):
    evaluations = 0

    def _objective(self, theta, x, s, t_s=None):
        type(self).evaluations += 1
        return super()._objective(theta, x, s, t_s)


# ---------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def scene():
    return load_scene("fingertip-7")


@pytest.fixture(scope="module")
def estimator(small_estimator_0_5s):
    """A small estimator (tests/unit/conftest.py; WINDOW_S its max_s)."""
    return small_estimator_0_5s


def _as(cls, est):
    return cls(est.family, est.prior, est.amplitude, est.noise_w_m2, est.sample_rate_hz,
               est.tau_range_s, est.h_ref_w_m2k, est.object_temp_c, est.model_error_rel)


@pytest.fixture(scope="module")
def touches(scene):
    """Simulated touches (seed 29) of seven materials, foam to copper, 2 each."""
    objects = tuple(ObjectSpec(m, 24.0, 0.03) for m in MATERIALS)
    copy = dataclasses.replace(scene, objects=objects, pad=dataclasses.replace(
        scene.pad, trials_per_material=2, contact_duration_s=0.6))
    contacts, _ = from_trials(pad_database(copy, np.random.default_rng(29)), max_s=WINDOW_S)
    return contacts


# ---------------------------------------------------------------- the tests
def test_the_curve_is_the_scipy_objects_to_the_bit(estimator, rng):
    fam = estimator.family
    lo = np.array([fam.log_e[0], fam.u[0], -0.02])
    hi = np.array([fam.log_e[-1], fam.u[-1], 0.0])
    thetas = [lo, hi, (lo + hi) / 2, lo - 0.3, hi + 0.3] + [rng.uniform(lo, hi) for _ in range(30)]
    for k, theta in enumerate(thetas):
        t = np.arange(4 + 3 * k) / 100.0                        # windows short and long
        for axis in (0, 1):
            for old, new in zip(_old_weights(fam, axis, theta[axis]), fam._weights(axis, theta[axis])):
                np.testing.assert_array_equal(new, old)
        np.testing.assert_array_equal(fam.curve(theta, t), _old_curve(fam, theta, t))
        for old, new in zip(_old_curve(fam, theta, t, True), fam.curve(theta, t, True)):
            np.testing.assert_array_equal(new, old)


def test_the_kernel_prior_terms_are_the_direct_sums_to_rounding(estimator, rng):
    prior = estimator.prior
    lo, hi = estimator.lo[1:], estimator.hi[1:]
    for point in [lo, hi, lo - 0.05] + [rng.uniform(lo, hi) for _ in range(50)]:
        value, grad, hess = prior.terms(point)
        ref = _old_terms(prior, point)
        assert value == pytest.approx(ref[0], rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(grad, ref[1], rtol=0, atol=1e-11 * np.abs(ref[1]).max())
        np.testing.assert_allclose(hess, ref[2], rtol=0, atol=1e-9 * np.abs(ref[2]).max())


def test_walked_fits_are_the_old_fits_within_a_thousandth_of_their_sd(scene, estimator,
                                                                       touches):
    # Every 20 ms window of 14 touches (foam to copper) to 0.5 s, each
    # started from the previous window's fit (the slave's walk), the first
    # from cold; then every fifth window from cold.
    old_est, new_est = _as(_OldEstimator, estimator), _as(_CountedEstimator, estimator)
    gap = abs(scene.pad_temp_c(24.0) - 24.0)
    _OldEstimator.evaluations = _CountedEstimator.evaluations = 0
    n_max = int(round(WINDOW_S * estimator.sample_rate_hz)) + 1
    for i in range(len(touches)):
        row = touches.x[i, :n_max, 0]
        starts = [None, None]
        for n in range(4, n_max + 1, 2):
            cold = (n - 4) % 10 == 0
            pair = [e.estimate(row[:n], gap, start=None if cold else st)
                    for e, st in zip((old_est, new_est), starts)]
            old, new = pair
            if not cold:
                starts = [old.theta, new.theta]
            d = np.abs(np.subtract(new.theta, old.theta))
            where = f"{touches.labels[i]} touch {i} n={n} cold={cold}"
            assert d[0] <= 1e-3 * old.log_sd, (where, d, old.log_sd)
            assert d[1] <= 1e-5 and d[2] <= 1e-8, (where, d)
            assert new.log_sd == pytest.approx(old.log_sd, rel=1e-4), where
            assert (new.fits, new.at_bound) == (old.fits, old.at_bound), where
            assert new.chi2_per_dof == pytest.approx(old.chi2_per_dof, rel=1e-3), where
    # Measured here: |d ln e| at most 5.9e-6 of the sd (6.1e-6 in ln e, on a
    # 4-sample window whose sd is ~1), |d u| 1.6e-7, |d tau| 3.9e-10 s,
    # log_sd and chi2 within 6e-6 and 3e-5 (relative); 1403 evaluations of
    # the objective against 1775 (the cold windows' starts cost as before;
    # on warm 1 s walks 3.1 a window against 4.9).
    assert _CountedEstimator.evaluations < 0.9 * _OldEstimator.evaluations


def test_a_spline_axis_with_repeated_inner_knots_is_refused():
    with pytest.raises(IdentificationError, match="increasing"):
        SplineAxis([0, 0, 0, 0, 1, 1, 2, 3, 3, 3, 3])


def test_the_prior_precomputes_from_its_draws_only(rng):
    theta = rng.normal(size=(200, 2)) * [0.1, 0.003]
    a, b = KernelPrior.scott(theta), KernelPrior.scott(theta.copy())
    point = np.array([0.05, -0.001])
    for u, v in zip(a.terms(point), b.terms(point)):
        np.testing.assert_array_equal(u, v)
