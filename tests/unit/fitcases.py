"""Touches the effusivity-fit unit tests share: fingertip-7's pad touches up
to 0.3 s, of its own materials or of package materials it was not trained
on; the model they share is the session fixture ``fit_model_0_3s``
(tests/unit/conftest.py: one training per test session, not one per file)."""

import dataclasses

import numpy as np

from telethermal.bench.unseen import package_objects, touch_scene
from telethermal.data.generate import pad_database
from telethermal.ident.prepare import from_trials
from telethermal.ident.registry import make
from telethermal.physics.scene import load_scene

SCENE = load_scene("fingertip-7")
MAX_S = 0.3


def contacts(scene, seed: int):
    """``scene``'s pad touches of session ``seed``, to :data:`MAX_S`."""
    return from_trials(list(pad_database(scene, np.random.default_rng(seed))), max_s=MAX_S)[0]


def unseen(material: str, seed: int = 3):
    """Touches of a package ``material`` on fingertip-7's pad, session ``seed``."""
    objects = package_objects([material], SCENE.materials, SCENE.objects[0].temp_c,
                              SCENE.objects[0].thickness_m)
    return contacts(touch_scene(dataclasses.replace(SCENE, objects=()), objects), seed)


def train():
    """effusivity-fit on fingertip-7's session-0 touches, windows to :data:`MAX_S`."""
    return make("effusivity-fit", scene="fingertip-7", max_window_s=MAX_S).fit(
        contacts(SCENE, 0))
