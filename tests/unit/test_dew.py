"""No dew on the display's pad (control/dew.py, the idle and the standby)."""

import logging
import math
from dataclasses import replace

import pytest

from telethermal.control.dew import DEW_MARGIN_K, dew_point_c, idle_floor_c
from telethermal.errors import ControlError
from telethermal.physics.scene import load_scene
from telethermal.teleop.display_setup import display_idle
from telethermal.teleop.display_config import DisplayConfig

SCENE = load_scene("fingertip-7")


def test_the_magnus_dew_point_meets_its_closed_form_checks():
    """Saturated air's dew point is its temperature (exactly: gamma = a T /
    (b + T) inverts to T); the saturation pressure ratio at the dew point is
    the humidity (Magnus: e_s(T) = 6.1094 exp(a T / (b + T)), to 1e-12)."""
    assert dew_point_c(24.0, 100.0) == pytest.approx(24.0, abs=1e-12)

    def es(t):
        return 6.1094 * math.exp(17.625 * t / (243.04 + t))
    for rh in (30.0, 50.0, 80.0):
        assert es(dew_point_c(24.0, rh)) / es(24.0) == pytest.approx(rh / 100, rel=1e-12)
    # Psychrometric tables: 24 C at 50 % has its dew point at 12.9 C.
    assert dew_point_c(24.0, 50.0) == pytest.approx(12.9, abs=0.1)
    with pytest.raises(ControlError, match="humidity"):
        dew_point_c(24.0, 0.0)
    assert idle_floor_c(24.0, 0.0) == -math.inf


def test_the_scenes_humidity_has_a_default():
    assert SCENE.room_humidity_pct == 50.0


def test_at_80_percent_a_remembered_metal_idles_above_the_dew_point_and_says_so(caplog):
    """80 % RH at 24 C: dew point 20.4 C. Aluminium remembered is
    pre-conditioned to about 15.6 C (below it): the idle is lifted to the
    dew point plus the margin, and the log says so; at the default 50 %
    (dew point 12.9 C) the same idle is left where the policy puts it."""
    humid = replace(SCENE, room_humidity_pct=80.0)
    floor = dew_point_c(24.0, 80.0) + DEW_MARGIN_K
    normal, _ = display_idle(SCENE, DisplayConfig(), 33.0, 24.0, "aluminium")
    assert normal < floor                       # the policy's idle would fog at 80 %
    with caplog.at_level(logging.INFO, logger="telethermal.teleop.display_setup"):
        lifted, _ = display_idle(humid, DisplayConfig(), 33.0, 24.0, "aluminium")
    assert lifted == pytest.approx(floor, abs=1e-12)
    assert "idle lifted" in caplog.text and "dew point" in caplog.text
    assert normal > idle_floor_c(24.0, 50.0)    # not lifted at 50 %


def test_a_scenes_humidity_is_read_and_checked(tmp_path):
    """``room_humidity_pct`` in a scene file is read; one outside 0-100 is
    refused with the key named."""
    from importlib import resources

    from telethermal.errors import SceneError
    from telethermal.physics.scene import load_scene as load

    # A scene of its own (a shipped scene's name with other content is refused).
    text = resources.files("telethermal").joinpath("scenes", "fingertip-7.toml").read_text() \
        .replace('name = "fingertip-7"', 'name = "humid-room"')
    good = tmp_path / "humid.toml"
    good.write_text(text.replace("room_temp_c = 24.0",
                                 "room_temp_c = 24.0\nroom_humidity_pct = 80"))
    assert load(good).room_humidity_pct == 80.0
    bad = tmp_path / "wet.toml"
    bad.write_text(text.replace("room_temp_c = 24.0",
                                "room_temp_c = 24.0\nroom_humidity_pct = 120"))
    with pytest.raises(SceneError, match="room_humidity_pct"):
        load(bad)
