"""Fixtures the unit tests share beyond tests/conftest.py's."""

import pytest


@pytest.fixture(scope="session")
def fit_model_0_3s():
    """effusivity-fit on fingertip-7's session-0 touches, windows to 0.3 s
    (tests/unit/fitcases.py); a test that changes it puts it back."""
    from fitcases import train
    return train()
