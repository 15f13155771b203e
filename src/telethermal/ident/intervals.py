"""The effusivity estimate's 95 % intervals calibrated on reference touches
(issue 30, part 1: "an uncertainty that is calibrated").

The estimator's interval (:mod:`telethermal.ident.effusivity`) is Laplace's,
with the samples' variance the flux sensor's noise plus an allowance for
the curves' own error: the scene's ``[model] tolerance_rel`` times the
touch's rms flux, as if white. The noise is the sensor's, known; the
allowance is a systematic error that the tolerance bounds but does not
measure, and treated as white it is wrong both ways: measured on
fingertip-7 (sessions 0-2 of ``telethermal bench unseen``) the 95 %
intervals held 96 % of the touches at 0.1 s and 99.7 % at 1 s, an interval
4-5 times too wide late in the contact.

A lab calibrates such an instrument on reference samples of known
property. The training touches are such references: each class is a
material whose effusivity the scene's materials table gives. Per
calibration window (every :data:`CALIBRATION_STEP_S` and the last), the
factor ``f`` on the allowance's variance is the smallest whose intervals
hold the references' table effusivities split-conformally
(:func:`allowance_factor`): the guarantee holds for a new touch drawn like
the references, whatever the errors' distribution. A touch unlike them
(another session's instruments, a material outside the classes, whose
systematic error differs) has no guarantee: ``bench unseen`` measures the
coverage on other sessions and on unseen materials. Between calibration
windows the factor is interpolated in the window's length, and held before
the first. Where a class names no material of known effusivity (a
recording's own labels) nothing is calibrated and the interval stays the
estimator's.

The allowance as white noise shrinks like one over the number of samples,
and a systematic error does not: the estimator's curves are solved to the
scene's 1e-3 tolerance, the simulated touches to a quarter of it
(:func:`~telethermal.data.generate.touch_contact_model`), a curve error of
3-5e-4 of the flux early in the contact, of one sign, that no number of
samples removes. Late in a metal's touch the flux hardly depends on ``e``
(the contact conductance limits it), so that error is a bias in ``ln e``
of about one of its white-noise sd (``bench unseen``, fingertip-7, seeds
0-2). When the touches of a metal were solved on a coarser grid than the
curves, copper's intervals held 24 of 30 touches at 1 s, every error of
the same sign. So the variance has a second term besides the
Laplace one: the **resolution floor** (:func:`resolution_var`), the
square of the ``ln e`` that moves the curve by the tolerance,
``(tol / S)^2`` with ``S`` the curve's sensitivity ``|d ln g / d ln e|``
over the samples. The same factor ``f`` multiplies both (the tolerance's
share that the references show), calibrated as above.

The Laplace variance of ``ln e`` is not linear in the samples' variance
(early in a touch ``e`` and the contact conductance are confounded and the
nuisances' prior carries part of the information), so the calibration
keeps the Hessian's terms per reference (:func:`variance_terms`) and
recomputes the variance for any ``f`` (:func:`log_e_variance`), one 3 x 3
inverse each.
"""

from __future__ import annotations

import numpy as np

#: The intervals are calibrated at windows at least this far apart, s, and
#: the last; the factor is interpolated in the window's length between.
CALIBRATION_STEP_S = 0.1
#: The calibrated allowance factor's bounds: from a millionth of the
#: variance the scene's tolerance allows (a thousandth of its sd) to a
#: hundred times it.
ALLOWANCE_BOUNDS = (1e-6, 1e2)
#: Bisection steps in ln f: 16 e-folds / 2^40, far below rounding.
BISECTIONS = 40
#: The samples whose sensitivity the resolution floor averages: where the
#: curve is above this fraction of its peak (before the contact it is 0).
SENSITIVE_FRACTION = 0.05


def sensitivity(est, theta, n: int) -> float:
    """``S``: the mean over the window's first ``n`` samples where the curve
    is above :data:`SENSITIVE_FRACTION` of its peak of ``|d ln g / d ln e|``
    at ``theta`` (the relative change of the flux per relative change of
    the effusivity); 0 where the curve is nowhere positive."""
    g, jac = est.family.curve(np.asarray(theta, float), np.arange(n) / est.sample_rate_hz,
                              deriv=True)
    peak = float(np.max(np.abs(g))) if len(g) else 0.0
    if not peak > 0.0:
        return 0.0
    use = np.abs(g) > SENSITIVE_FRACTION * peak        # the peak's sample at least
    return float(np.mean(np.abs(jac[use, 0] / g[use])))


def resolution_var(est, theta, n: int) -> float:
    """The resolution floor's variance of ``ln e`` at factor 1 (see the
    module): ``(model_error_rel / S)^2``, S the :func:`sensitivity`; 0
    where the window holds no flux (the Laplace variance is then the
    prior's)."""
    s = sensitivity(est, theta, n)
    return (est.model_error_rel / s) ** 2 if s > 0.0 else 0.0


def variance_terms(est, x: np.ndarray, gap_k: float, theta) -> np.ndarray:
    """What the variance of ``ln e`` at the fit ``theta`` of the samples
    ``x`` depends on, for any factor on the curves' allowance, as one flat
    row (21) for :func:`log_e_variance`: the estimator's
    (:class:`~telethermal.ident.effusivity.EffusivityEstimator`) Gauss-Newton
    Hessian split into the data's information ``M = J^T J`` (the
    amplitude's mean times the curve's Jacobian), ``b = J^T g``, ``g.g``,
    the nuisances' prior Hessian ``P``, the noise's variance, the
    allowance's variance at factor 1, the amplitude's variance; then the
    resolution floor's variance at factor 1."""
    x = np.asarray(x, float)
    theta = np.asarray(theta, float)
    a0, sa = est.amplitude
    g, jac = est.family.curve(theta, np.arange(len(x)) / est.sample_rate_hz, deriv=True)
    mj = a0 * jac
    _, _, lp_hess = est.prior.terms(theta[1:])
    s_noise = est.noise_var(x, gap_k, 0.0)
    return np.concatenate([(mj.T @ mj).ravel(), mj.T @ g, [float(g @ g)],
                           np.asarray(lp_hess, float).ravel(),
                           [s_noise, est.noise_var(x, gap_k, 1.0) - s_noise, sa ** 2,
                            resolution_var(est, theta, len(x))]])


def log_e_variance(terms: np.ndarray, allowance) -> np.ndarray:
    """The variance of ``ln e`` of each row of :func:`variance_terms` (n, 21)
    with the curves' allowance's variance and the resolution floor's times
    ``allowance`` (scalar or (n,)): Laplace's ``[(-H)^+]_00`` with
    ``-H = (M - c b b^T) / s - P`` (``P`` in the two nuisances), ``s`` the
    samples' variance and ``c = sa^2 / (s + sa^2 g.g)`` (the amplitude
    marginalised), plus ``allowance`` times the floor: the estimator's own
    interval, to rounding."""
    t = np.atleast_2d(np.asarray(terms, float))
    f = np.broadcast_to(np.asarray(allowance, float), len(t))
    s = t[:, 17] + f * t[:, 18]
    c = t[:, 19] / (s + t[:, 19] * t[:, 12])
    b = t[:, 9:12]
    h = (t[:, :9].reshape(-1, 3, 3) - c[:, None, None] * b[:, :, None] * b[:, None, :]) \
        / s[:, None, None]
    h[:, 1:, 1:] -= t[:, 13:17].reshape(-1, 2, 2)
    return np.maximum(np.linalg.pinv(h)[:, 0, 0], 0.0) + f * t[:, 20]


def allowance_factor(r: np.ndarray, variance, level: float = 0.95) -> float:
    """The smallest ``f`` in :data:`ALLOWANCE_BOUNDS` whose ``level``
    intervals ``|r_j| <= z sqrt(variance(f)_j)`` hold at least
    ``ceil(level (n + 1))`` of the ``n`` reference errors ``r`` (ln e):
    split-conformal calibration (Vovk, Gammerman and Shafer, Algorithmic
    Learning in a Random World, 2005; Angelopoulos and Bates,
    arXiv:2107.07511, section 1.1). ``variance``: ``f`` (n,) -> each
    reference's variance of ln e at its own ``f``, increasing in ``f``
    (:func:`log_e_variance`). Each reference's need ``f_j`` is found by
    bisection in ``ln f``; ``f`` is their ``ceil(level (n + 1))``-th
    smallest (the upper bound where that is past ``n``). 1 when the
    allowance adds no variance or no error is finite."""
    from scipy.stats import norm

    r = np.asarray(r, float)
    n = len(r)
    lo, hi = np.log(ALLOWANCE_BOUNDS)
    v_lo, v_hi = variance(np.full(n, np.exp(lo))), variance(np.full(n, np.exp(hi)))
    ok = np.isfinite(r) & np.isfinite(v_lo) & np.isfinite(v_hi)
    if not np.any(ok) or not np.any(v_hi[ok] > v_lo[ok]):
        return 1.0
    z2, r2 = float(norm.ppf(0.5 + level / 2)) ** 2, np.where(ok, r * r, np.inf)
    a, b = np.full(n, lo), np.full(n, hi)
    for _ in range(BISECTIONS):
        mid = 0.5 * (a + b)
        holds = z2 * variance(np.exp(mid)) >= r2
        a, b = np.where(holds, a, mid), np.where(holds, mid, b)
    need = np.where(z2 * v_lo >= r2, lo, np.where(z2 * v_hi >= r2, b, np.inf))
    k = int(np.ceil(level * (n + 1)))
    return float(np.exp(np.clip(np.sort(need)[k - 1] if k <= n else hi, lo, hi)))


def calibrate_allowance(model, contacts, min_samples: int) -> dict | None:
    """The allowance's factor per calibration window of a fitted
    ``effusivity-fit`` ``model`` (its windows, estimator and fits) on its
    training ``contacts``, against the classes' table effusivities:
    ``{"windows_s", "allowance", "reference"}``, or None when a class is
    not a material of known effusivity (see the module). Windows under
    ``min_samples`` samples are not calibrated."""
    from telethermal.errors import UnknownMaterialError
    from telethermal.physics.materials import get_material

    try:
        log_e = {c: float(np.log(get_material(c).effusivity)) for c in model.classes_}
    except UnknownMaterialError:
        return None
    est, gap_k = model.estimator()
    windows_s = model.windows_s_
    step = windows_s[1] - windows_s[0] if len(windows_s) > 1 else CALIBRATION_STEP_S
    stride = max(1, int(round(CALIBRATION_STEP_S / step)))
    out_s, out_f = [], []
    for i, w in enumerate(windows_s):
        if (i + 1) % stride and i != len(windows_s) - 1:
            continue
        n = int(round(w * model.sample_rate_hz_)) + 1
        if n < min_samples:
            continue
        r, terms = [], []
        for row, label in zip(contacts.x[:, :n, 0], contacts.labels):
            row = np.ascontiguousarray(row)
            theta = model._theta(row, n)
            terms.append(variance_terms(est, row, gap_k, theta))
            r.append(theta[0] - log_e[label])
        terms = np.array(terms)
        out_s.append(float(w))
        out_f.append(allowance_factor(np.array(r), lambda f, t=terms: log_e_variance(t, f)))
    if not out_s:
        return None
    # "floor": the factors hold the references with the resolution floor in
    # the variance (a file calibrated before it has none: see
    # EffusivityFit.floor_at_s).
    return {"windows_s": out_s, "allowance": out_f, "floor": True,
            "reference": "the classes' table effusivities (physics.materials)"}
