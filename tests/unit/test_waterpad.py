"""The water-circulation pad of active-heat-flow-sensing eq. (11)-(13)."""

import numpy as np
import pytest

from telethermal.errors import ModelError
from telethermal.physics.waterpad import WaterPadParams, precondition


def test_at_room_temperature_with_no_command_nothing_moves():
    # Equilibrium: every node at room, command at room -> stays exactly there.
    run = precondition(np.array([24.0]), 24.0, 30.0)
    assert np.all(run.temp_pad_c == 24.0) and not run.pump_on.any()


@pytest.mark.parametrize("target", [44.0, 34.0, 29.0, 19.0])
def test_pad_reaches_its_command_within_the_pump_band(target):
    # Tables 1 and 2 commands. The pump switches at 0.3 K lag and stops at 0.1 K,
    # so after settling the pad sits within ~0.5 K of its command.
    run = precondition(np.array([target]), 24.0, 120.0)
    assert abs(run.final_pad_c[0] - target) < 0.5
    assert not run.pump_on[-1, 0]  # the pump is off at contact (natural heat flow)


def test_peltier_power_stays_within_its_limit():
    p = WaterPadParams()
    run = precondition(np.array([44.0, 10.0]), 24.0, 60.0, params=p)
    assert np.all(np.abs(run.peltier_w) <= p.u_max_w + 1e-12)


def test_exact_discretisation_does_not_depend_on_the_step():
    # PI off, pump held off: a linear system relaxing to room. The exact
    # zero-order-hold step gives the same state at shared times for any step
    # (to rounding), unlike an explicit or implicit Euler step.
    p = WaterPadParams(kp_w_k=0.0, ki_w_ks=0.0)
    a = precondition(np.array([24.0]), 24.0, 10.0, dt_s=0.01, params=p, start_c=40.0)
    b = precondition(np.array([24.0]), 24.0, 10.0, dt_s=0.5, params=p, start_c=40.0)
    np.testing.assert_allclose(a.temp_pad_c[49::50], b.temp_pad_c, rtol=1e-10)
    assert 24.0 < b.final_pad_c[0] < 40.0


def test_bad_steps_raise():
    with pytest.raises(ModelError):
        precondition(np.array([30.0]), 24.0, 1.0, dt_s=0.0)
