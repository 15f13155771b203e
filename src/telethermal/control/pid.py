"""A PID controller for the display's heat-flux loop.

Small and explicit, in the manner of simple-pid, but with the step ``dt_s``
always given by the caller (never read from a clock):

- derivative on the measurement, not the error, so a setpoint step gives no
  derivative kick; low-pass filtered with time constant ``derivative_filter_s``;
- output saturation, and anti-windup by clamping: the integral does not grow
  while the output is saturated in the direction the error pushes;
- bumpless start: :meth:`Pid.reset` sets the integral so the first output
  equals the output already applied;
- optional feed-forward added before saturation;
- a step that is not positive is refused with a clear error; across a step
  longer than ``max_step_factor`` nominal steps (a stall of the loop) the
  integral and the filtered derivative are held, so no jump follows it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.errors import ControlError


@dataclass(frozen=True, slots=True)
class PidGains:
    kp: float
    ki: float = 0.0
    kd: float = 0.0
    derivative_filter_s: float = 0.01
    output_min: float = -math.inf
    output_max: float = math.inf

    def __post_init__(self):
        if not self.output_min < self.output_max:
            raise ControlError(f"output_min {self.output_min} must be below output_max "
                               f"{self.output_max}")
        if self.derivative_filter_s <= 0:
            raise ControlError("derivative_filter_s must be > 0")


@dataclass(frozen=True, slots=True)
class PidOutput:
    """What the controller asks for, after saturation, and its parts."""

    output: float
    saturated: bool
    proportional: float
    integral: float
    derivative: float
    skipped_long_step: bool = False


class Pid:
    """``update(setpoint, measurement, dt_s)`` -> :class:`PidOutput`."""

    def __init__(self, gains: PidGains, nominal_dt_s: float, max_step_factor: float = 10.0):
        if not nominal_dt_s > 0:
            raise ControlError(f"nominal_dt_s must be > 0, got {nominal_dt_s}")
        self.gains = gains
        self.nominal_dt_s = nominal_dt_s
        self.max_step_factor = max_step_factor
        self.reset()

    def reset(self, measurement: float | None = None, output: float = 0.0,
              setpoint: float | None = None) -> None:
        """Start (again) so that the next output continues from ``output``.

        Every piece of state is set here: nothing from before a reset comes
        back, not even through :meth:`limited_downstream`."""
        self._integral = 0.0
        self._derivative = 0.0
        self._last_measurement = measurement
        if measurement is not None and setpoint is not None:
            proportional = self.gains.kp * (setpoint - measurement)
            self._integral = output - proportional        # bumpless hand-over
        elif self.gains.ki:
            self._integral = output
        # What the last update would undo, and the error it saw: no update
        # since the reset, so there is nothing to undo (error 0 pushes nowhere).
        self._before_update = self._integral
        self._last_error = 0.0

    def update(self, setpoint: float, measurement: float, dt_s: float,
               feedforward: float = 0.0) -> PidOutput:
        for name, value in (("setpoint", setpoint), ("measurement", measurement),
                            ("dt_s", dt_s), ("feedforward", feedforward)):
            if not math.isfinite(value):
                raise ControlError(f"PID {name} is {value}")
        if dt_s <= 0:
            raise ControlError(f"PID step dt_s must be > 0, got {dt_s}")
        g = self.gains
        error = setpoint - measurement
        long_step = dt_s > self.max_step_factor * self.nominal_dt_s
        if self._last_measurement is None:
            self._derivative = 0.0
        elif not long_step:                               # a stall: hold, do not jump
            raw = -(measurement - self._last_measurement) / dt_s
            alpha = dt_s / (g.derivative_filter_s + dt_s)
            self._derivative += alpha * (raw - self._derivative)
        self._last_measurement = measurement
        proportional = g.kp * error
        derivative = g.kd * self._derivative
        candidate = self._integral
        if not long_step:
            candidate += g.ki * error * dt_s
        unclamped = proportional + candidate + derivative + feedforward
        output = min(max(unclamped, g.output_min), g.output_max)
        saturated = output != unclamped
        # Clamping anti-windup: keep the new integral unless it pushes further
        # into the saturation the output is already in.
        pushes_out = (unclamped > g.output_max and error > 0) or \
                     (unclamped < g.output_min and error < 0)
        self._before_update = self._integral
        self._last_error = error
        if not (saturated and pushes_out):
            self._integral = candidate
        return PidOutput(output, saturated, proportional, self._integral, derivative, long_step)

    def limited_downstream(self, requested: float, applied: float) -> None:
        """Anti-windup for limits applied after the controller (a slew limit,
        a safety supervisor): when what was applied differs from what the
        last :meth:`update` asked for in the direction its error pushes, that
        step's integration is undone."""
        error = self._last_error
        if (applied < requested and error > 0) or (applied > requested and error < 0):
            self._integral = self._before_update
