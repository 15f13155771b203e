"""The display's junction sensor is configuration (``[sensors]
junction_sensor``, ``junction_lag_s``): the controller's design reads it,
the simulated sensor lags it times ``[as_built.display] junction_lag_s``
(issue 44's display half; the review: one constant was shared by both)."""

from __future__ import annotations

import tomllib
from importlib import resources

import numpy as np
import pytest

from telethermal.errors import SceneError
from telethermal.physics.scene import parse_scene
from telethermal.physics.thermoelectric import DEFAULT_JUNCTION_SENSOR, get_junction_sensor
from telethermal.teleop.display_setup import display_model_args
from telethermal.teleop.display_config import DisplayConfig
from telethermal.teleop.master import MasterDisplay
from telethermal.sim.touch import DisplayTouch, Operator


def _scene(sensors=None, as_built=None):
    data = tomllib.loads(resources.files("telethermal").joinpath(
        "scenes/fingertip-7.toml").read_text())
    data["objects"] = [o for o in data["objects"] if o["material"] == "plexiglass"]
    data.setdefault("sensors", {}).update(sensors or {})
    if as_built is not None:
        data["as_built"] = as_built
    return parse_scene(data, "variant.toml")


def _master(scene):
    return MasterDisplay(DisplayConfig(), None, finger_temp_c=33.0,
                         **display_model_args(scene))


def _touch(scene):
    return DisplayTouch(scene, Operator(33.0, 33.0, 1.0, 1.0, 10.0, 5000.0), 500.0, 0.2,
                        25.0, np.random.default_rng(0))


def test_the_default_is_the_part_at_its_stated_lag():
    scene = _scene()
    stated = get_junction_sensor(DEFAULT_JUNCTION_SENSOR)
    assert scene.sensors.junction_sensor_spec() == stated
    assert _master(scene).junction_design["sensor_tau_s"] == stated.tau_s
    assert _touch(scene).junction_lag_s == stated.tau_s


def test_the_configured_lag_designs_the_loop_and_the_factor_moves_only_the_plant():
    """A scene stating 0.2 s: the loop is designed for 0.2 s (its crossover
    lower than for 0.1 s: less phase left at the same frequency), the
    simulated sensor lags 0.2 s; with ``[as_built.display] junction_lag_s
    = 1.5`` the plant's lags 0.3 s and the controller is unchanged."""
    slow = _scene({"junction_lag_s": 0.2})
    built = _scene({"junction_lag_s": 0.2}, {"display": {"junction_lag_s": 1.5}})
    ms, mb, mn = _master(slow), _master(built), _master(_scene())
    assert ms.junction_design["sensor_tau_s"] == 0.2 == mb.junction_design["sensor_tau_s"]
    assert ms.junction_design == mb.junction_design
    assert ms.junction_design["crossover_rad_s"] < mn.junction_design["crossover_rad_s"]
    assert _touch(slow).junction_lag_s == pytest.approx(0.2)
    assert _touch(built).junction_lag_s == pytest.approx(0.3)


@pytest.mark.parametrize("sensors, words", [
    ({"junction_sensor": "B57861S-glued"}, "'junction_sensor' = 'B57861S-glued'"),
    ({"junction_lag_s": -0.1}, "'junction_lag_s' = -0.1"),
    ({"junction_lag_s": "fast"}, "'junction_lag_s' must be a number"),
])
def test_a_bad_sensor_key_is_refused_by_name(sensors, words):
    with pytest.raises(SceneError, match=r"variant.toml") as err:
        _scene(sensors)
    assert words in str(err.value)
