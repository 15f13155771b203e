"""The pad calibration's intervals carry what the touches cannot tell
(``ident.calibration.consider_sds``): a candidate held at its design value,
and a lumped parameter's members apart. On a linear model the fit's error
is exactly the consider shift times how far the part is off, so the
consider sd is checked against the least-squares error itself (closed
form, to 1e-9)."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from telethermal.ident.calibration import consider_sds, lump_weights
from telethermal.physics.scene import load_scene


class Linear:
    """Residuals linear in the log factors: each candidate's column, then
    the nuisances' (as the pad fit's, without its curves)."""

    def __init__(self, columns: dict, nuisances: np.ndarray, scene=None):
        self.columns, self.nuisances, self.scene = columns, nuisances, scene

    def split(self, z, free):
        factors = {}
        for group, value in zip(free, z[:len(free)]):
            for name in group:
                factors[name] = math.exp(value)
        return factors, 0.0, None, None, None

    def jacobian(self, z, free, fixed=None):
        cols = [sum(self.columns[m] for m in g) for g in free]
        return np.column_stack(cols + [self.nuisances])


def _fit_error(model: Linear, free, truth: dict) -> np.ndarray:
    """The least-squares estimate of the free groups' log factors less the
    true ones, the data made by ``truth`` (log factors of every candidate)."""
    data = sum(model.columns[m] * v for m, v in truth.items())
    jac = model.jacobian(None, free)
    est = np.linalg.lstsq(jac, data, rcond=None)[0][:len(free)]
    return est, jac


@functools.lru_cache(maxsize=1)
def _steel_plexiglass_fit():
    """fingertip-7's pad fit on 3 touches each of steel and plexiglass
    (seed 3): (scene, PadModelFit)."""
    import dataclasses

    from telethermal.data.generate import pad_database
    from telethermal.ident.calibration import PadModelFit, ReferenceTouches
    from telethermal.ident.pad_calibration import amplitude_sd

    scene = load_scene("fingertip-7")
    ref = dataclasses.replace(
        scene, pad=dataclasses.replace(scene.pad, trials_per_material=3),
        objects=tuple(o for o in scene.objects if o.material in ("steel", "plexiglass")))
    touches = ReferenceTouches.from_trials(pad_database(ref, np.random.default_rng(3)))
    return scene, PadModelFit(scene, touches, amplitude_sd(scene),
                              scene.sensors.flux_noise_w_m2())


def test_a_held_candidate_off_its_design_moves_the_fit_by_its_consider_shift():
    rng = np.random.default_rng(0)
    cols = {n: rng.normal(size=200) for n in ("a", "b", "c")}
    cols["c"] = 0.6 * cols["a"] + 0.3 * rng.normal(size=200)    # c mimics a, partly
    model = Linear(cols, rng.normal(size=(200, 3)))
    free, sd = [("a",), ("b",)], 0.2
    truth = {"a": 0.05, "b": -0.02, "c": sd}                     # c one sd off
    est, jac = _fit_error(model, free, truth)
    err = est - np.array([truth["a"], truth["b"]])
    got = consider_sds(model, np.zeros(2 + 3), free, ["c"], sd, jac)
    assert abs(err[0]) > 0.05                                   # a real bias
    np.testing.assert_allclose(got, np.abs(err), rtol=1e-9, atol=1e-12)
    # Nothing held, or a design taken as exact: no widening.
    assert not consider_sds(model, np.zeros(5), free, [], sd, jac).any()
    assert not consider_sds(model, np.zeros(5), free, ["c"], 0.0, jac).any()


def test_a_lumped_parameter_s_members_apart_are_carried_against_their_total():
    """Two layers' resistances lumped: the factor stands for their total
    (weights: their design resistances); each member off alone by one sd
    errs the fit by (its shift less its weight) sd; the consider sd is the
    quadrature of the two."""
    scene = load_scene("fingertip-7")
    names = ("layers[0].resistance", "layers[1].resistance")
    w = lump_weights(scene, names)
    assert math.isclose(sum(w), 1.0) and all(0 < x < 1 for x in w)
    rng = np.random.default_rng(1)
    base = rng.normal(size=300)
    cols = {names[0]: base + 0.2 * rng.normal(size=300),
            names[1]: 0.7 * base + 0.2 * rng.normal(size=300), "flux_lag_s": rng.normal(size=300)}
    model = Linear(cols, rng.normal(size=(300, 2)), scene)
    free, sd = [names, ("flux_lag_s",)], 0.2
    errors = []
    for i in range(2):
        truth = {names[0]: 0.0, names[1]: 0.0, "flux_lag_s": 0.0}
        truth[names[i]] = sd
        est, jac = _fit_error(model, free, truth)
        errors.append(est[0] - w[i] * sd)                          # against the total's factor
    got = consider_sds(model, np.zeros(2 + 2), free, [], sd, jac)
    assert got[0] == pytest.approx(math.hypot(*errors), rel=1e-9)
    assert got[0] > 0.01


def test_a_parameter_the_design_bounds_better_than_the_fit_is_said_so():
    """A fitted factor whose interval (with the consider term) stands for an
    sd of ln factor past the identifiability rule's is printed as known no
    better than its design allows; a sharp one is not."""
    from telethermal.ident.calibration import SD_MAX
    from telethermal.ident.pad_calibration import (CalibratedParameter, PadCalibration,
                                                   interval_sd, pad_digest)
    scene = load_scene("fingertip-7")
    from telethermal.ident.openset import Z95
    assert interval_sd(math.exp(-Z95 * 0.05), math.exp(Z95 * 0.05)) == pytest.approx(0.05)
    cal = PadCalibration(scene.name, pad_digest(scene), (
        CalibratedParameter(("flux_lag_s",), "flux sensor lag", 1.0, 0.99, 1.01),
        CalibratedParameter(("layers[0].heat_capacity", "layers[1].heat_capacity"),
                            "heat capacity", 1.02, 0.72, 1.45)), (), 3000.0, 1.0, 0.01, 0.1,
        15, ("steel", "wood"), design_sd=0.2)
    assert interval_sd(0.72, 1.45) > SD_MAX
    lines = cal.describe()
    loose = [line for line in lines if "known no better than its design allows" in line]
    assert len(loose) == 1 and "heat capacity" in loose[0]
    assert any("log sd of 0.2" in line for line in lines)


def test_the_pad_fit_s_consider_columns_are_its_own_jacobian_s_at_the_fit():
    """The real call path (``PadModelFit.jacobian(..., fixed=...)``, the
    gain kept, a lumped group's members at its factor): consider_sds equals
    the shifts computed from one Jacobian over every candidate alone, at the
    same point, to 1e-9."""
    scene, fit = _steel_plexiglass_fit()
    n = len(fit.touches.labels)
    lump = ("layers[0].resistance", "layers[1].resistance")
    free, fixed = [("flux_gain",), ("flux_lag_s",), lump], ["layers[2].resistance"]
    z = np.concatenate([[0.03, -0.05, 0.1], np.zeros(3 * n)])
    jac = fit.jacobian(z, free)
    got = consider_sds(fit, z, free, fixed, 1.0, jac)
    # Every candidate alone, at the same factors: the members at the lump's.
    alone = [("flux_gain",), ("flux_lag_s",), (lump[0],), (lump[1],), (fixed[0],)]
    full = fit.jacobian(np.concatenate([[0.03, -0.05, 0.1, 0.1, 0.0], np.zeros(3 * n)]), alone)
    parts = full[:, [4, 2, 3]]                           # the fixed one, then the members
    shift = np.linalg.lstsq(jac, parts, rcond=None)[0][:3]
    w = lump_weights(scene, lump)
    shift[2, 1] -= w[0]
    shift[2, 2] -= w[1]
    np.testing.assert_allclose(got, np.sqrt(np.sum(shift ** 2, axis=1)), rtol=1e-9)
    assert got[2] > 0                                   # the lump carries something


def test_the_pad_fit_s_prior_rows_are_its_residuals_own_and_its_jacobian_s():
    """A group given a prior sd adds one residual row ``ln factor / sd``
    after the touches' and the amplitudes' (none for a group without), and
    the Jacobian's row for it is exactly its derivative (1 / sd at that
    group's column, 0 elsewhere); the rows before are the fit's without
    priors, to the bit."""
    scene, fit = _steel_plexiglass_fit()
    n = len(fit.touches.labels)
    free = [("flux_gain",), ("flux_lag_s",), ("layers[2].resistance",)]
    prior = [None, None, 0.2]
    z = np.concatenate([[0.03, -0.05, 0.1], np.zeros(3 * n)])
    plain_r, plain_j = fit.residuals(z, free), fit.jacobian(z, free)
    r, j = fit.residuals(z, free, prior=prior), fit.jacobian(z, free, prior=prior)
    assert r.shape == (len(plain_r) + 1,) and j.shape == (len(plain_r) + 1, len(z))
    np.testing.assert_array_equal(r[:-1], plain_r)
    np.testing.assert_array_equal(j[:-1], plain_j)
    assert r[-1] == pytest.approx(0.1 / 0.2, rel=1e-15)
    want = np.zeros(len(z))
    want[2] = 1 / 0.2
    np.testing.assert_array_equal(j[-1], want)
    # The prior's posterior sd on a part the touches do not see at all is
    # the prior's own: a column of zeros but for its prior row.
    jac = np.vstack([np.column_stack([np.ones((5, 1)), np.zeros((5, 1))]), [[0.0, 1 / 0.2]]])
    from telethermal.ident.calibration import marginal_sds
    assert marginal_sds(jac, 2)[1] == pytest.approx(0.2, rel=1e-12)
