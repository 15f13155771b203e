"""The simulated pad touches are solved finer than the product's curves
(data/generate.py, ``touch_contact_model``): solved on one grid, a model
would match the touches it fits to rounding (an inverse crime)."""

import dataclasses
import logging
from importlib import resources

import pytest

from telethermal.data import generate
from telethermal.data.generate import TOUCH_TOLERANCE_FACTOR, touch_contact_model
from telethermal.physics.scene import load_scene, pad_contact_model

SHIPPED = sorted(p.name[:-5] for p in resources.files("telethermal").joinpath("scenes").iterdir()
                 if p.name.endswith(".toml"))


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_scenes_touches_reach_the_finer_tolerance(name, caplog):
    """No shipped object falls back to the scene's tolerance: each touch's
    model meets a quarter of it (its own error estimate, the layered grid's
    4/3 of its distance to the grid refined once)."""
    scene = load_scene(name)
    with caplog.at_level(logging.WARNING, logger=generate.__name__):
        for obj in scene.objects:
            _, choice = touch_contact_model(scene, obj)
            assert choice.error_bound_rel <= scene.tolerance_rel * TOUCH_TOLERANCE_FACTOR, \
                (obj.name, choice)
    assert not caplog.records


def test_the_touches_are_not_solved_on_the_product_curves_grid():
    """fingertip-7's glass: the estimator's reference material is glass, so
    at the scene's tolerance the touches' grid would be the curves' own;
    the touches' grid is finer (more cells), its error bound under a
    quarter of the tolerance, the curves' over it."""
    scene = load_scene("fingertip-7")
    glass = dataclasses.replace(scene.objects[0], material="glass")
    _, touch = touch_contact_model(scene, glass)
    _, curves = pad_contact_model(scene, glass)
    assert touch.n_cells > curves.n_cells
    assert touch.error_bound_rel <= 0.25 * scene.tolerance_rel < curves.error_bound_rel


def test_a_scene_at_the_grids_limit_falls_back_to_its_tolerance_and_says_so(caplog):
    """A tolerance of 2e-4: aluminium's finest grid reaches 1.2e-4, not the
    5e-5 a quarter asks; the touches are solved to 2e-4 (the model the
    scene's own tolerance gives) and the log says so, once."""
    scene = dataclasses.replace(load_scene("fingertip-7"), tolerance_rel=2e-4)
    aluminium = next(o for o in scene.objects if o.material == "aluminium")
    with caplog.at_level(logging.WARNING, logger=generate.__name__):
        first = touch_contact_model(scene, aluminium)
        again = touch_contact_model(scene, aluminium)
    assert first is again
    assert first[1] == pad_contact_model(scene, aluminium)[1]
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 1 and "aluminium" in warned[0] and "0.0002" in warned[0], warned
