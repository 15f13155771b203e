"""Shared fixtures."""

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

# The machines are shared and slow at times: hypothesis must not fail a test
# because drawing its inputs took long (a health check, not a property), nor
# for a slow example (no wall-clock figure in a test). Each test's own
# @settings inherits these.
settings.register_profile("shared-machine", deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("shared-machine")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
