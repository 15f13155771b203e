"""Train what a session needs, from a scene's simulated databases (in
memory), when no saved identifier or generator is given."""

from __future__ import annotations

import numpy as np

from telethermal.data.generate import finger_database, pad_database
from telethermal.ident.prepare import from_trials
from telethermal.ident.registry import make
from telethermal.physics.scene import Scene
from telethermal.render.generator import NetworkGenerator


def train_identifier(scene: Scene, seed: int = 0, method: str = "effusivity-lda"):
    """Database 1 of ``scene`` (seed ``seed``) -> a fitted identifier."""
    trials = pad_database(scene, np.random.default_rng(seed))
    model = make(method).fit(from_trials(trials)[0])
    model.scene_ = scene.name
    return model


def train_generator(scene: Scene, seed: int = 0):
    """Database 2 of ``scene`` (a scene with a finger) -> a fitted generator.

    The network generator is the default: on held-out persons it renders
    closer to the recorded flux than the fitted closed form (see
    ``telethermal bench render``, ``generator`` section)."""
    trials = finger_database(scene, np.random.default_rng(seed + 1000))
    return NetworkGenerator().fit(trials)
