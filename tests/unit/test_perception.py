"""Perceptual units of a rendered touch (teleop/perception.py), on traces
whose answer is known in closed form."""

import math

import numpy as np
import pytest

from telethermal.teleop.perception import (COOL_DETECTION_K, WARM_DETECTION_K,
                                           heat_extraction_ratio, skin_above_threshold_s)

DT = 0.002


def trace(flux_scale=1.0, skin_error_k=0.0):
    t = np.arange(-0.2, 3.0, DT)
    during = t >= 0
    direct = np.where(during, -2000.0 / np.sqrt(np.maximum(t, DT)), np.nan)
    skin = np.where(during, 30.0, np.nan)
    return {"t_s": t, "direct_flux_w_m2": direct, "flux_w_m2": flux_scale * np.nan_to_num(direct),
            "direct_skin_c": skin, "skin_surface_c": skin + skin_error_k}


@pytest.mark.parametrize("scale", [1.0, 0.5, 1.43])
def test_the_extraction_ratio_is_the_heat_ratio(scale):
    """The rendered flux a fixed multiple of the direct one: the ratio is
    that multiple (to 1e-12: both integrals share the trapezoidal rule)."""
    assert heat_extraction_ratio(trace(scale)) == pytest.approx(scale, rel=1e-12)


def test_no_direct_heat_gives_nan():
    tr = trace()
    tr["direct_flux_w_m2"][:] = np.nan
    assert math.isnan(heat_extraction_ratio(tr))


def test_time_above_threshold_takes_each_direction_its_own_threshold():
    """A constant error over the 3 s contact: counted wholly when beyond its
    direction's threshold (cooling 0.3 K, warming 0.5 K), not at all within."""
    contact_s = 3.0
    between = 0.5 * (COOL_DETECTION_K + WARM_DETECTION_K)       # 0.4 K
    assert skin_above_threshold_s(trace(skin_error_k=between)) == 0.0
    assert skin_above_threshold_s(trace(skin_error_k=-between)) == pytest.approx(contact_s,
                                                                                 abs=DT)
    assert skin_above_threshold_s(trace(skin_error_k=WARM_DETECTION_K + 0.01)) == \
        pytest.approx(contact_s, abs=DT)
