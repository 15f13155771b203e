"""The effusivity estimate's intervals calibrated on the training touches
(issue 30, part 1: "an uncertainty that is calibrated"): the curves'
allowance (the estimator's systematic error, which the scene's tolerance
bounds but does not measure) is scaled per window so that the 95 %
intervals hold the reference touches' table effusivities, split-conformally
(``ident.intervals``); the flux noise stays the sensor's.

The model: effusivity-fit on fingertip-7's seed-0 touches, windows up to
0.3 s (tests/unit/fitcases.py)."""

import dataclasses
import math

import numpy as np
import pytest

from telethermal.ident.effusivity import Z95
from telethermal.ident.intervals import (ALLOWANCE_BOUNDS, allowance_factor, log_e_variance,
                                         variance_terms)
from telethermal.ident.registry import load_model, make

from fitcases import SCENE, contacts as _contacts


@pytest.fixture(scope="module")
def model(fit_model_0_3s):
    return fit_model_0_3s


def _covered(r, vn, va, f):
    return int(np.sum(np.abs(r) <= Z95 * np.sqrt(vn + f * va)))


def _linear(vn, va):
    return lambda f: vn + f * va


def test_the_conformal_factor_holds_95_percent_of_a_fresh_draw_of_the_same_errors():
    """Errors r ~ N(0, v_noise + f0 v_allowance), f0 = 0.3, with per-touch
    variances spread over two decades: the factor found on 4,000 of them
    holds 95 % of 20,000 fresh ones (binomial sd of that share at n =
    20,000: 0.0015; the factor's own sampling error adds about as much:
    tolerance +- 0.008), and it is f0 to within 10 % (the 95 % quantile of
    4,000 draws: about 3 % sd in f)."""
    rng = np.random.default_rng(11)
    f0 = 0.3

    def draw(n):
        vn = 10 ** rng.uniform(-6, -4, n)
        va = 10 ** rng.uniform(-5, -3, n)
        return rng.normal(0, np.sqrt(vn + f0 * va)), vn, va

    r, vn, va = draw(4000)
    f = allowance_factor(r, _linear(vn, va))
    fresh = draw(20000)
    assert _covered(*fresh, f) / 20000 == pytest.approx(0.95, abs=0.008)
    assert f == pytest.approx(f0, rel=0.10)


def test_the_factor_is_the_smallest_that_holds_the_conformal_count():
    """It holds ceil(0.95 (n + 1)) of the n references, and a factor a
    millionth smaller holds fewer (it is that reference's own need, found
    by bisection to far below that)."""
    rng = np.random.default_rng(5)
    n = 70
    vn, va = 10 ** rng.uniform(-6, -4, n), 10 ** rng.uniform(-5, -3, n)
    r = rng.normal(0, np.sqrt(vn + 2.0 * va))
    f = allowance_factor(r, _linear(vn, va))
    need = math.ceil(0.95 * (n + 1))
    assert _covered(r, vn, va, f * (1 + 1e-9)) >= need
    assert _covered(r, vn, va, f * (1 - 1e-6)) < need


def test_the_degenerate_cases_and_the_bounds():
    """No allowance, or no finite error: 1 (the estimator's own interval);
    fewer references than the count needs (n = 10: ceil(0.95 x 11) = 11):
    the upper bound; errors the noise alone holds: the lower bound."""
    one = np.ones(10)
    assert allowance_factor(one * 0.1, _linear(one * 1e-4, one * 0.0)) == 1.0
    assert allowance_factor(np.full(10, np.nan), _linear(one, one)) == 1.0
    assert allowance_factor(one * 0.1, _linear(one * 1e-4, one * 1e-4)) == \
        pytest.approx(ALLOWANCE_BOUNDS[1])
    many = np.ones(100)
    assert allowance_factor(many * 1e-3, _linear(many * 1e-4, many * 1e-4)) == \
        pytest.approx(ALLOWANCE_BOUNDS[0])


def test_the_variance_terms_give_the_estimators_own_interval_at_any_allowance(model):
    """log_e_variance of variance_terms is the Laplace variance the
    estimator's interval_at gives with the allowance scaled by f, to
    rounding (1e-9), at f = 0 (the noise alone), 0.05, 1 and 3: the same
    Hessian, split so the calibration can scale it cheaply. It is not
    linear in f (the prior on the nuisances carries part of it early: at
    0.3 s v(0.05) is over twice v(0) + 0.05 (v(1) - v(0)) on these touches),
    which is why the split keeps the terms, not two variances."""
    est, gap_k = model.estimator()
    x = _contacts(SCENE, 3).x
    for i in (0, 25):
        row = np.ascontiguousarray(x[i, :31, 0])
        fit = est.estimate(row, gap_k)
        terms = variance_terms(est, row, gap_k, fit.theta)
        assert log_e_variance(terms, 1.0)[0] == pytest.approx(fit.log_sd ** 2, rel=1e-9)
        for f in (0.0, 0.05, 1.0, 3.0):
            _, lo, hi, _ = est.interval_at(row, gap_k, fit.theta, f)
            sd = math.log(hi / lo) / (2 * Z95)
            assert log_e_variance(terms, f)[0] == pytest.approx(sd ** 2, rel=1e-9), (i, f)
        v0, v1 = log_e_variance(terms, 0.0)[0], log_e_variance(terms, 1.0)[0]
        assert v0 < log_e_variance(terms, 0.05)[0] < v1
        assert log_e_variance(terms, 0.05)[0] > 2 * (v0 + 0.05 * (v1 - v0))


def test_the_fit_calibrates_every_tenth_of_a_second_and_the_reading_uses_it(model):
    """Calibrated at 0.1, 0.2 and 0.3 s against the classes' table
    effusivities; the reading's interval is the estimator's at the
    calibrated factor (interpolated; held before 0.1 s)."""
    cal = model.interval_allowance_
    assert cal["windows_s"] == [0.1, 0.2, 0.3]
    assert all(ALLOWANCE_BOUNDS[0] <= f <= ALLOWANCE_BOUNDS[1] for f in cal["allowance"])
    assert model.allowance_at_s(0.02) == cal["allowance"][0]
    assert model.allowance_at_s(0.15) == pytest.approx(np.mean(cal["allowance"][:2]))
    est, gap_k = model.estimator()
    x = _contacts(SCENE, 3).x[:1]
    i = model.windows_s_.index(0.3)
    reading = model.effusivity_reading(x, i)
    row = np.ascontiguousarray(x[0, :31, 0])
    assert (reading.effusivity_lo_w_s05_m2k, reading.effusivity_hi_w_s05_m2k) == \
        est.interval_at(row, gap_k, model._theta(row, 31), cal["allowance"][-1])[1:3]


def test_the_calibration_survives_a_model_file_and_an_older_file_reads_uncalibrated(
        model, tmp_path):
    back = load_model(model.save(tmp_path / "fit.npz"))
    assert back.interval_allowance_ == model.interval_allowance_
    assert back.allowance_at(3) == model.allowance_at(3)
    back.interval_allowance_ = None             # what a file from before it restores
    assert back.allowance_at(3) == 1.0


def test_classes_of_no_known_material_are_not_calibrated():
    """A recording's own labels name no material of the table: the
    intervals stay the estimator's own (nothing to calibrate against)."""
    contacts = _contacts(SCENE, 0)
    renamed = dataclasses.replace(contacts,
                                  labels=[f"object-{c}" for c in contacts.labels])
    fitted = make("effusivity-fit", scene="fingertip-7", max_window_s=0.1).fit(renamed)
    assert fitted.interval_allowance_ is None
    assert fitted.allowance_at(0) == 1.0
