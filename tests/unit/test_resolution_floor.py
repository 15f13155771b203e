"""The effusivity interval's resolution floor (ident/intervals.py): the
curves' own error is systematic, so besides the white allowance that
shrinks with the samples the variance of ln e has a floor, the square of
the ln e that moves the curve by the scene's tolerance, (tol / S)^2 with S
the curve's sensitivity |d ln g / d ln e|, times the calibrated factor.

The hard case is copper, above every trained class (aluminium is the
highest): late in its touch the flux hardly depends on e, and the
estimator's curves differ from the simulated touches (solved on a finer
grid) by a few 1e-4 of the flux, all of one sign."""

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from telethermal.bench.unseen import package_objects, touch_scene
from telethermal.data.generate import pad_database
from telethermal.ident.effusivity import Z95
from telethermal.ident.intervals import (SENSITIVE_FRACTION, log_e_variance, resolution_var,
                                         sensitivity, variance_terms)
from telethermal.ident.prepare import from_trials
from telethermal.physics.materials import get_material
from telethermal.physics.scene import load_scene

SCENE = load_scene("fingertip-7")


class PowerFamily:
    """g(t) = e^beta * phi(t): d ln g / d ln e = beta exactly; phi is 0
    before the contact at 0.05 s and rises as sqrt after it."""

    def __init__(self, beta: float):
        self.beta = beta

    def curve(self, theta, times_s, deriv=False):
        phi = np.sqrt(np.clip(times_s - 0.05, 0.0, None))
        g = math.exp(self.beta * theta[0]) * phi
        jac = np.column_stack([self.beta * g, np.zeros_like(g), np.zeros_like(g)])
        return (g, jac) if deriv else g


@pytest.mark.parametrize("beta", [0.017, 0.3, 1.0])
def test_the_sensitivity_of_a_power_law_family_is_its_exponent(beta):
    est = SimpleNamespace(family=PowerFamily(beta), sample_rate_hz=100.0, model_error_rel=1e-3)
    assert sensitivity(est, (math.log(2e4), 0.0, 0.0), 101) == pytest.approx(beta, rel=1e-12)
    assert resolution_var(est, (math.log(2e4), 0.0, 0.0), 101) == \
        pytest.approx((1e-3 / beta) ** 2, rel=1e-12)
    # Before the contact the curve is 0: no sensitivity, no floor (the
    # Laplace variance is then the prior's), never a division by zero.
    assert sensitivity(est, (0.0, 0.0, 0.0), 5) == 0.0
    assert resolution_var(est, (0.0, 0.0, 0.0), 5) == 0.0


@pytest.fixture(scope="module")
def model(trained_models):
    return trained_models.identifier(SCENE, 0)


def _touches(material: str, seed: int = 0):
    objects = package_objects([material], SCENE.materials, SCENE.objects[0].temp_c,
                              SCENE.objects[0].thickness_m)
    scene = touch_scene(dataclasses.replace(SCENE, objects=()), objects)
    return from_trials(list(pad_database(scene, np.random.default_rng(seed))), max_s=1.0)[0]


def test_the_sensitivity_is_the_estimators_curve_differentiated(model):
    """On the estimator's own curves (fingertip-7's pad) S is the central
    difference of ln g in ln e over the samples above 5 % of the peak, to
    1e-5; it falls with e (copper's flux depends on e least), and the
    floor is (tol / S)^2."""
    est, _ = model.estimator()
    t = np.arange(101) / est.sample_rate_hz
    seen = []
    for e in (1_000.0, 24_000.0, 37_000.0):
        theta = np.array([math.log(e), 0.0, 0.0])
        g = est.family.curve(theta, t)
        use = np.abs(g) > SENSITIVE_FRACTION * np.max(np.abs(g))
        d = 1e-4
        up = est.family.curve(theta + [d, 0, 0], t)[use]
        down = est.family.curve(theta - [d, 0, 0], t)[use]
        numeric = float(np.mean(np.abs((np.log(up) - np.log(down)) / (2 * d))))
        s = sensitivity(est, theta, 101)
        assert s == pytest.approx(numeric, rel=1e-5), e
        assert resolution_var(est, theta, 101) == pytest.approx((est.model_error_rel / s) ** 2)
        seen.append(s)
    assert seen[0] > seen[1] > seen[2] > 0


def test_the_variance_terms_carry_the_floor_times_the_factor(model):
    """log_e_variance (the calibration's) is the interval the estimator
    reports at any factor f, the floor included, and the floor is f times
    its own column."""
    est, gap_k = model.estimator()
    x = _touches("copper").x[0, :, 0]
    for n in (51, 101):
        row = np.ascontiguousarray(x[:n])
        fit = est.estimate(row, gap_k)
        terms = variance_terms(est, row, gap_k, fit.theta)
        assert log_e_variance(terms, 1.0)[0] == pytest.approx(fit.log_sd ** 2, rel=1e-9)
        for f in (0.0, 0.03, 1.0):
            _, lo, hi, _ = est.interval_at(row, gap_k, fit.theta, f)
            sd = math.log(hi / lo) / (2 * Z95)
            assert log_e_variance(terms, f)[0] == pytest.approx(sd ** 2, rel=1e-9), (n, f)
            no_floor = terms.copy()
            no_floor[20] = 0.0
            assert log_e_variance(terms, f)[0] - log_e_variance(no_floor, f)[0] == \
                pytest.approx(f * terms[20], rel=1e-9)


def test_copper_beyond_every_reference_is_covered_at_1_s(model):
    """Copper's ten seed-0 touches at 1 s: every error of one sign (the
    curves' systematic error: the estimator's curves are solved on a
    coarser grid than the touches), and the calibrated intervals hold the
    table effusivity on at least 9 of 10. Without the floor, at the same
    factor, the intervals hold it on fewer (measured: 8 of 10; 2 of 10
    while the touches of a metal were solved coarser than the curves, when
    bench unseen held 24 of 30 at 1 s before the floor)."""
    est, _ = model.estimator()
    touches = _touches("copper")
    true = math.log(get_material("copper").effusivity)
    f = model.allowance_at_s(1.0)
    errors, covered, covered_no_floor = [], 0, 0
    for i in range(len(touches.labels)):
        row = np.ascontiguousarray(touches.x[i, :101, 0])
        fit = est.estimate(row, touches.gap_k[i])
        terms = variance_terms(est, row, touches.gap_k[i], fit.theta)
        no_floor = terms.copy()
        no_floor[20] = 0.0
        r = fit.theta[0] - true
        errors.append(r)
        covered += abs(r) <= Z95 * math.sqrt(log_e_variance(terms, f)[0])
        covered_no_floor += abs(r) <= Z95 * math.sqrt(log_e_variance(no_floor, f)[0])
    assert len(errors) == 10 and len({r > 0 for r in errors}) == 1, errors
    assert covered >= 9, (covered, errors)
    assert covered_no_floor < covered, (covered_no_floor, covered)


@pytest.fixture
def compared_sds(monkeypatch) -> list:
    """The touch's own sd each class comparison receives (classes_holding
    spied on), in order."""
    import telethermal.ident.fitted as fitted

    seen = []
    real = fitted.classes_holding
    monkeypatch.setattr(fitted, "classes_holding",
                        lambda log_e, log_sd, *a: seen.append(log_sd) or real(log_e, log_sd, *a))
    return seen


def test_a_class_is_compared_at_the_touchs_interval_less_the_floor(model, compared_sds):
    """A class's predictive comes from its training touches' estimates,
    which carry the same systematic curve error as a touch of a nearby
    material: the floor is common to both, so the comparison widens the
    class by the touch's interval less the floor (with the floor in it,
    bench unseen named 15 of 30 brass touches aluminium at 1 s, brass 6 %
    below aluminium; without, 0). The reported interval keeps the floor."""
    seen = compared_sds
    est, gap_k = model.estimator()
    touches = _touches("copper")
    k = model.windows_s_.index(1.0)
    f = model.allowance_at(k)
    for i in range(3):
        reading = model.effusivity_reading(touches.x[i:i + 1], k)
        row = np.ascontiguousarray(touches.x[i, :101, 0])
        theta = model._theta(row, 101)
        full = math.log(reading.effusivity_hi_w_s05_m2k / reading.effusivity_lo_w_s05_m2k) \
            / (2 * Z95)
        floor = f * resolution_var(est, theta, 101)
        assert floor > 0.5 * full ** 2            # copper at 1 s: the floor is most of it
        assert seen[-1] ** 2 == pytest.approx(full ** 2 - floor, rel=1e-9)


def test_a_clipped_interval_is_compared_at_its_unclipped_sd(model, compared_sds):
    """Early in a copper touch the interval reaches past the estimator's
    grid (1.2e5) and is clipped there: the interval's ends then understate
    the sd of ln e. The class comparison takes the sd itself less the floor
    (from the clipped ends the floor left nothing: a touch compared with no
    uncertainty of its own). Checked against the estimator's own Laplace
    variance at the same fit: the comparison's variance plus the floor is
    the interval's variance to 1e-9."""
    seen = compared_sds
    est, gap_k = model.estimator()
    touches = _touches("copper")
    k = model.windows_s_.index(0.1)
    clipped = 0
    for i in range(len(touches)):
        reading = model.effusivity_reading(touches.x[i:i + 1], k)
        row = np.ascontiguousarray(touches.x[i, :11, 0])
        theta, e, lo, hi, sd, floor = model.interval_of(row, 0.1)
        assert (lo, hi) == (reading.effusivity_lo_w_s05_m2k, reading.effusivity_hi_w_s05_m2k)
        assert seen[-1] ** 2 + floor == pytest.approx(sd ** 2, rel=1e-9)
        if hi >= math.exp(est.hi[0]) * (1 - 1e-12):
            clipped += 1
            from_ends = math.log(hi / lo) / (2 * Z95)
            assert from_ends < sd and seen[-1] > math.sqrt(max(from_ends ** 2 - floor, 0.0))
    assert clipped >= 1                           # the case this test is about occurred


def test_a_model_file_calibrated_before_the_floor_reads_as_it_was_calibrated(model):
    """A calibration made before the floor (no "floor" key: its factors
    hold the references with the Laplace variance alone) gets no floor: its
    intervals and its class comparisons are what they were; this
    calibration says it has the floor, and a model file keeps that."""
    import copy

    assert model.interval_allowance_["floor"] is True
    old = copy.copy(model)
    old.interval_allowance_ = {k: v for k, v in model.interval_allowance_.items()
                               if k != "floor"}
    k = model.windows_s_.index(1.0)
    f = model.allowance_at(k)
    assert old.allowance_at(k) == f and old.floor_at_s(1.0) == 0.0
    assert model.floor_at_s(1.0) == f
    est, gap_k = model.estimator()
    x = _touches("copper").x[:1]
    row = np.ascontiguousarray(x[0, :101, 0])
    theta = model._theta(row, 101)
    now, before = model.effusivity_reading(x, k), old.effusivity_reading(x, k)
    assert (before.effusivity_lo_w_s05_m2k, before.effusivity_hi_w_s05_m2k) == \
        est.interval_at(row, gap_k, theta, f, 0.0)[1:3]
    assert (now.effusivity_lo_w_s05_m2k, now.effusivity_hi_w_s05_m2k) == \
        est.interval_at(row, gap_k, theta, f)[1:3]
    assert now.effusivity_hi_w_s05_m2k > before.effusivity_hi_w_s05_m2k


def test_the_calibrations_floor_mark_survives_a_model_file(model, tmp_path):
    from telethermal.ident.registry import load_model
    back = load_model(model.save(tmp_path / "fit.npz"))
    assert back.interval_allowance_["floor"] is True
    assert back.floor_at_s(1.0) == model.floor_at_s(1.0)
