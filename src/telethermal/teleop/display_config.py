"""The display's configuration (:class:`DisplayConfig`) and its choices,
which the master's display (:mod:`telethermal.teleop.master`) runs by."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

from telethermal.choices import choice
from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.control.pid import PidGains
from telethermal.control.safety import SafetyLimits
from telethermal.errors import ControlError


class Before(StrEnum):
    """What the display renders before the slave's decision: ``prior``,
    the posterior mixture from the master's own onset; ``hold``, the pad
    held where it was."""

    HOLD = "hold"
    PRIOR = "prior"


class Source(StrEnum):
    """``trajectory``: render the slave's curves from the master's own onset
    (the compensated path); ``setpoints``: track the latest flux setpoint
    streamed by the slave sample by sample (the naive baseline of the fault
    benchmark)."""

    TRAJECTORY = "trajectory"
    SETPOINTS = "setpoints"


class FeedforwardModel(StrEnum):
    """``impedance``: the pad's surface made to behave as the rendered
    object's (control/feedforward.py; needs the pad's layers); ``static``:
    ``T_pad + q R_pad`` plus the flux PID on the generator's flux."""

    STATIC = "static"
    IMPEDANCE = "impedance"


class Idle(StrEnum):
    """Before a touch: ``policy``, the object's temperature shifted by the
    scene's idle policy (control/preconditioning.py), for the material the
    slave expects or, unknown, the minimax idle; ``object``: at the object's."""

    POLICY = "policy"
    OBJECT = "object"


#: The choices as strings (command-line choices, messages).
BEFORE_MODES = tuple(Before)
SOURCES = tuple(Source)
FEEDFORWARD_MODELS = tuple(FeedforwardModel)
IDLES = tuple(Idle)
#: The display's event when the junction loop stops on an implausible sensor.
JUNCTION_STOPPED = "junction sensor implausible: module stopped"
JUNCTION_REARMED = "junction sensor agrees again: module re-armed"

#: PID gains of the flux loop (K of junction per W/m^2 of flux error), from ``bench render``:
#: the lowest mean flux error with the pad model right and 30 % off; more integral rings
#: through the sensor's 0.15 s lag after a late hand-over; the derivative bought nothing.
DEFAULT_GAINS = PidGains(kp=1e-3, ki=3e-3, kd=0.0, derivative_filter_s=0.01,
                         output_min=-25.0, output_max=25.0)


@dataclass(frozen=True)
class DisplayConfig:
    rate_hz: float = DEFAULT_RATE_HZ
    gains: PidGains = DEFAULT_GAINS
    feedforward: bool = True
    #: :class:`FeedforwardModel` (impedance needs the pad's layers, else static).
    feedforward_model: FeedforwardModel = FeedforwardModel.IMPEDANCE
    #: The impedance controller's prediction horizon: no shorter than the
    #: junction loop takes to move the junction (its target moves no faster
    #: than the module can follow), else the outer loop re-plans faster
    #: than the inner one follows and the two oscillate (0.1 s did: +-8 A at
    #: about 2 Hz on plexiglass with the bonded sensor, on the thinner cold
    #: layer modelled before the module's own plate; not re-tuned since:
    #: docs/display-loop.md).
    impedance_horizon_s: float = 0.2
    #: A string naming a choice is taken (``before="hold"``): each is made
    #: its enum, and one that names none is refused, saying which.
    before: Before = Before.PRIOR
    source: Source = Source.TRAJECTORY
    idle: Idle = Idle.POLICY
    #: The controller's own slew limit on the junction command; the
    #: supervisor's rate limit above it is the independent backstop.
    slew_k_s: float = 100.0
    #: After a hand-over (hold -> render), the step between what was applied
    #: and what the controller asks for is closed at this slope.
    handover_k_s: float = 50.0
    #: From the posterior mixture to the decided material: weights blended over this long.
    blend_s: float = 0.1
    limits: SafetyLimits = field(default_factory=lambda: SafetyLimits(
        max_rate_k_s=200.0, max_flux_w_m2=20_000.0))
    #: For robustness studies: the controller's pad resistance relative to
    #: the true one (1: the model is right).
    r_pad_belief: float = 1.0
    #: The junction loop: its target smoothed over this long (the feed-forward
    #: differentiates the smoothed target), and the module current's slew
    #: bound (8.5 A in 85 ms: under the junction sensor's lag; module makers
    #: warn against fast reversals and ripple). The feed-forward's current is
    #: the junction's heat capacity times the target's rate over S T, so the
    #: target's noise reaches the current in proportion to that capacity:
    #: with the module's own 0.8 mm plate (1.43 J/K against 0.714 with the
    #: thinner layer modelled before) this and the impedance controller's
    #: offset filter below were doubled (0.02 -> 0.04 s, 0.05 -> 0.1 s),
    #: halving the target's noise; both stay under the junction loop's
    #: closed-loop time constant (0.93 Hz: 0.17 s), which sets how fast the
    #: junction follows anyway.
    junction_reference_s: float = 0.04
    current_slew_a_s: float = 100.0
    #: The impedance controller's inversion of the flux sensor's lag is
    #: regularised: ``(tau s + 1) / (flux_inverse_s s + 1)``, its noise gain
    #: ``tau / flux_inverse_s`` (7.5 with the shipped 0.15 s sensor) instead
    #: of ``tau / dt`` (75 at 500 Hz).
    flux_inverse_s: float = 0.02
    #: The impedance controller's measured-minus-model offsets (its
    #: disturbance estimate) are filtered over this long.
    impedance_bias_filter_s: float = 0.1
    contact_on_n: float = 2.0
    contact_off_n: float = 1.0
    debounce_s: float = 0.02

    def __post_init__(self):
        if not (self.rate_hz > 0 and math.isfinite(self.rate_hz)):
            raise ControlError(f"display rate_hz must be > 0, got {self.rate_hz}")
        if not (self.slew_k_s > 0 and self.handover_k_s > 0 and self.blend_s > 0):
            raise ControlError("slew_k_s, handover_k_s and blend_s must be > 0")
        for name, kind in (("before", Before), ("source", Source),
                           ("feedforward_model", FeedforwardModel), ("idle", Idle)):
            object.__setattr__(self, name, choice(kind, getattr(self, name), name, ControlError))
        if not (self.junction_reference_s > 0 and self.current_slew_a_s > 0
                and self.flux_inverse_s > 0):
            raise ControlError("junction_reference_s, current_slew_a_s and flux_inverse_s must "
                               f"be > 0, got {self.junction_reference_s}, "
                               f"{self.current_slew_a_s}, {self.flux_inverse_s}")
        if not self.impedance_horizon_s > 0:
            raise ControlError("impedance_horizon_s must be > 0, got "
                               f"{self.impedance_horizon_s}")
