"""Fixtures the unit tests share beyond tests/conftest.py's."""

import pytest


@pytest.fixture(scope="session")
def fit_model_0_3s():
    """effusivity-fit on fingertip-7's session-0 touches, windows to 0.3 s
    (tests/unit/fitcases.py); a test that changes it puts it back."""
    from fitcases import train
    return train()


@pytest.fixture(scope="session")
def small_estimator_0_5s():
    """fingertip-7's effusivity estimator to 0.5 s on a coarse grid and
    prior (the tests' budget: 21 x 5 curves, 300 prior draws, 5 sessions)."""
    from telethermal.ident.effusivity import EffusivityEstimator
    from telethermal.physics.scene import load_scene
    return EffusivityEstimator.for_scene(load_scene("fingertip-7"), max_s=0.5, n_e=21, n_h=5,
                                         n_prior=300, n_sessions=5)
