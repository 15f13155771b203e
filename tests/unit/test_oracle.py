"""The oracle identifier (issue 29, deliverable 1): its Bayes rule against
closed-form cases, and its model against the simulator's own touches."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import norm

from telethermal.data.generate import _Contacts, _held_pad_contact, pad_database, \
    touch_contact_model
from telethermal.ident.oracle import CurveFamily, KernelPrior, Oracle, marginal_log_likelihood
from telethermal.ident.prepare import FLUX, Contacts, from_trials
from telethermal.physics.scene import load_scene

RATE_HZ = 10.0


def _toy_oracle(shapes: dict, amplitude=(1.0, 0.0)) -> Oracle:
    """An oracle over curves that depend on t only (no shape nuisance); the
    (u, tau) prior a single Gaussian kernel, so Laplace's integral over it is
    exact and the same for every class: the decision is the closed form's."""
    u = np.linspace(-1.0, 1.0, 9)
    t = np.arange(-0.1, 2.0, 0.005)
    curves = {m: CurveFamily.from_grid(u, t, np.tile(f(t), (len(u), 1))) for m, f in shapes.items()}
    prior = KernelPrior(np.zeros((1, 2)), np.diag([0.1 ** 2, 1e-7 ** 2]))
    return Oracle(curves, prior, {m: amplitude for m in shapes}, noise_w_m2=1.0,
                  sample_rate_hz=RATE_HZ, tau_range_s=(-1e-6, 1e-6))


def _contacts(x: np.ndarray, labels) -> Contacts:
    n, k = x.shape
    return Contacts(x[:, :, None], np.full(n, k), list(labels), ["g"] * n, np.ones(n), RATE_HZ,
                    (FLUX,))


def _binomial_tolerance(p: float, n: int) -> float:
    """Four binomial standard deviations: a correct oracle fails ~1 run in 16 000."""
    return 4.0 * math.sqrt(p * (1 - p) / n)


def test_marginal_likelihood_matches_the_gaussian_it_integrates(rng):
    g, x = rng.normal(size=7), rng.normal(size=7)
    s, a0, sa = 0.3, 0.8, 0.5
    cov = s * np.eye(7) + sa ** 2 * np.outer(g, g)
    r = x - a0 * g
    expected = -0.5 * (r @ np.linalg.solve(cov, r) + np.linalg.slogdet(2 * np.pi * cov)[1])
    logl, dg = marginal_log_likelihood(x, g, s, a0, sa)
    assert logl == pytest.approx(expected, rel=1e-12)
    eps = 1e-6
    numeric = [(marginal_log_likelihood(x, g + eps * e, s, a0, sa)[0]
                - marginal_log_likelihood(x, g - eps * e, s, a0, sa)[0]) / (2 * eps)
               for e in np.eye(7)]
    np.testing.assert_allclose(dg, numeric, rtol=1e-6, atol=1e-8)


def test_two_classes_in_gaussian_noise_reach_phi_of_half_the_separation(rng):
    # x = g_m + e, e ~ N(0, I) per sample, g_0 = 0, g_1 = delta: the Bayes
    # accuracy is Phi(d / 2) with d = delta sqrt(n).
    window_s = 0.5
    n = int(round(window_s * RATE_HZ)) + 1
    delta = 2.0 / math.sqrt(n)                        # d = 2: Phi(1) = 0.841
    oracle = _toy_oracle({"a": lambda t: 0 * t, "b": lambda t: 0 * t + delta})
    per = 400
    truth = np.repeat([0, 1], per)
    x = rng.normal(size=(2 * per, n)) + delta * truth[:, None]
    result = oracle.accuracy_by_window(_contacts(x, np.array(["a", "b"])[truth]), [window_s])
    expected = norm.cdf(1.0)
    assert result["0.5"]["accuracy"] == pytest.approx(
        expected, abs=_binomial_tolerance(expected, 2 * per))


def test_amplitude_nuisance_is_marginalised_to_the_closed_form_bayes_error(rng):
    # x = A g_m + e with A ~ N(0, sa^2), g_0 and g_1 orthogonal of equal
    # norm G over the window's samples: the Bayes rule compares the
    # projections, |x.g_0| > |x.g_1|, and is right with probability
    # (2 / pi) atan(sqrt(1 + sa^2 G / sigma^2)).
    window_s = 0.7
    n = int(round(window_s * RATE_HZ)) + 1            # 8 samples: a whole period
    f = RATE_HZ / n
    shapes = {"cos": lambda t: np.cos(2 * np.pi * f * t), "sin": lambda t: np.sin(2 * np.pi * f * t)}
    big_g = n / 2.0
    sa = math.sqrt(3.0 / big_g)                       # sa^2 G / sigma^2 = 3
    oracle = _toy_oracle(shapes, amplitude=(0.0, sa))
    per = 400
    truth = np.repeat([0, 1], per)
    t = np.arange(n) / RATE_HZ
    curves = np.stack([shapes["cos"](t), shapes["sin"](t)])
    x = rng.normal(0.0, sa, 2 * per)[:, None] * curves[truth] + rng.normal(size=(2 * per, n))
    result = oracle.accuracy_by_window(_contacts(x, np.array(["cos", "sin"])[truth]), [window_s])
    expected = 2 / np.pi * math.atan(2.0)             # 0.705
    assert result["0.7"]["accuracy"] == pytest.approx(
        expected, abs=_binomial_tolerance(expected, 2 * per))


# ------------------------------------------------------------ the simulator
@pytest.fixture(scope="module")
def hard_three():
    """fingertip-7's three closest materials (effusivity 567, 536, 470),
    4 touches each, 0.3 s: the oracle of seed 3's session and its touches."""
    scene = load_scene("fingertip-7")
    scene = dataclasses.replace(
        scene, objects=tuple(o for o in scene.objects
                             if o.material in ("plexiglass", "rubber", "wood")),
        pad=dataclasses.replace(scene.pad, trials_per_material=4))
    trials = pad_database(scene, np.random.default_rng(3))
    oracle = Oracle.for_scene(scene, seed=3, max_s=0.3, n_prior=600, n_h=21)
    contacts, _ = from_trials(trials, max_s=0.3)
    return scene, oracle, trials, contacts


def test_the_true_material_fits_the_touch_to_its_noise(hard_three):
    # The forward model, the nuisances' fit and the noise model together:
    # at the true material the residual's chi-square per degree of freedom
    # (n samples less A, h and the onset) pools 12 touches of 28 degrees
    # each, sd 0.27 / sqrt(12) = 0.08: 1 +- 0.3 is 4 sd. A forward model off
    # by one noise sd anywhere would double it. The fitted onset and
    # conductance are the trial's true ones (its manifest's extras) within
    # what the fit's curvature allows (far below 0.2 ms and 1 %).
    _, oracle, trials, contacts = hard_three
    n = int(round(0.3 * oracle.sample_rate_hz)) + 1
    chi2 = []
    for i, trial in enumerate(trials):
        x, s = contacts.x[i, :n, 0], (oracle.noise_w_m2 / contacts.gap_k[i]) ** 2
        theta, _, _ = oracle._fit(trial.material, x, s)
        g = oracle.curves[trial.material].curve(theta[0], np.arange(n) / oracle.sample_rate_hz
                                                - theta[1])
        amp = (g @ x) / (g @ g)
        chi2.append(np.sum((x - amp * g) ** 2) / s / (n - 3))
        assert theta[1] == pytest.approx(float(trial.extra["onset_offset_s"]), abs=2e-4)
        h = float(trial.extra["contact_conductance_w_m2k"])
        assert 3000.0 * math.exp(theta[0]) == pytest.approx(h, rel=0.01)
    assert np.mean(chi2) == pytest.approx(1.0, abs=0.3)


def test_the_flux_is_linear_in_the_gap_to_far_below_the_noise(hard_three):
    # The oracle scales one unit-gap curve by the amplitude; the held pad's
    # junction droop makes the flux slightly nonlinear in the gap and in the
    # absolute temperatures. A touch 0.6 K off the nominal gap and 0.3 K off
    # the object's temperature against the scaled curve: within 2 % of the
    # noise of the normalised flux (0.4 W/m^2 over 10 K), so neglected.
    scene, oracle, _, _ = hard_three
    obj = scene.objects[0]
    model, _ = touch_contact_model(scene, obj)        # as the touches are solved
    t = np.arange(0.005, 0.3, 0.01)
    h = np.array([2500.0])
    draws = _Contacts(np.zeros(1), h, np.zeros(1), np.array([obj.temp_c - 0.3]), np.zeros(1))
    pad_c = obj.temp_c - 0.3 + 10.6
    flux = _held_pad_contact(scene, obj, model, t, np.array([pad_c]), draws).flux_sensed_w_m2[0]
    predicted = 10.6 * oracle.curves[obj.material].curve(math.log(h[0] / 3000.0), t)
    noise = oracle.noise_w_m2 / 10.0
    assert np.max(np.abs(flux / 10.0 - predicted / 10.0)) < 0.02 * noise


def test_the_oracle_tells_the_three_closest_materials_apart_and_is_sure(hard_three):
    # Each touch's log-likelihood under its own material beats the others;
    # its posterior is calibrated in the only way 12 touches can show: the
    # wrong materials' summed posterior stays below 1 % on every touch. (The
    # oracle is not bound to be right: the bench measures how often it is.)
    _, oracle, _, contacts = hard_three
    p = oracle.posterior(contacts, 0.3)
    truth = [oracle.materials.index(m) for m in contacts.labels]
    assert np.all(p[np.arange(len(truth)), truth] > 0.99)
