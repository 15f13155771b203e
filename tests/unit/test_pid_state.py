"""The PID's state is all named by ``reset()``: nothing from before a reset
comes back through :meth:`Pid.limited_downstream` (issue 20)."""

import pytest

from telethermal.control.pid import Pid, PidGains

DT = 1e-3


def _wound_up(ki: float = 10.0, steps: int = 80) -> Pid:
    # A pure integrator under a constant error of 1: integral = ki * steps * DT.
    pid = Pid(PidGains(kp=0.0, ki=ki), DT)
    for _ in range(steps):
        out = pid.update(1.0, 0.0, DT)
    assert out.integral == pytest.approx(ki * steps * DT)
    return pid


def test_a_limit_after_reset_does_not_bring_back_the_old_integral():
    pid = _wound_up()
    pid.reset()
    # Nothing was asked since the reset, so a downstream limit has nothing to undo.
    pid.limited_downstream(1.0, 0.0)
    out = pid.update(0.0, 0.0, DT)                 # no error: the integral shows as it is
    assert out.integral == 0.0 and out.output == 0.0


def test_a_limit_after_a_bumpless_reset_keeps_the_bumpless_integral():
    pid = _wound_up()
    pid.reset(measurement=0.0, output=0.3, setpoint=0.0)
    pid.limited_downstream(1.0, 0.0)
    out = pid.update(0.0, 0.0, DT)
    assert out.integral == pytest.approx(0.3) and out.output == pytest.approx(0.3)


def test_a_limit_on_a_fresh_controller_changes_nothing():
    pid = Pid(PidGains(kp=0.0, ki=10.0), DT)
    pid.limited_downstream(1.0, 0.0)
    pid.limited_downstream(0.0, 1.0)
    assert pid.update(0.0, 0.0, DT).integral == 0.0


def test_a_limit_after_reset_and_one_update_undoes_only_that_update():
    pid = _wound_up()
    pid.reset()
    out = pid.update(1.0, 0.0, DT)                 # one step of integration: 10 * DT
    pid.limited_downstream(out.output, 0.0)        # cut: that step is undone, back to 0
    assert pid.update(0.0, 0.0, DT).integral == 0.0
