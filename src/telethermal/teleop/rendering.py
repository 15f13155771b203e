"""What the display renders while it tracks, and how it hands over from one
rendering to the next without a step (:class:`Handover`).

Split out of :mod:`telethermal.teleop.master`: the weights over the rendered
materials (the slave's posterior mixture before a decision, the decided
material after it), the linear blend of those weights over ``blend_s`` at
every change, and the flux and ``1/e`` they stand for.

A new material (issue 30) is rendered from the slave's estimate
(:class:`Estimated`, a key of the weights beside the material names): the
flux a finger exchanges with a semi-infinite object of that effusivity
(:func:`~telethermal.physics.contact.contact_flux_sensed_w_m2`, as the pad's
sensor reads it, the generator's curves being sensor readings too), and its
``1/e`` for the impedance controller: the same two things a known material
takes from its generator curve and its table row.

Why a blend (over ``blend_s``) and not continuity of the curve: both what
the flux loop tracks and the ``1/e`` the impedance controller renders are
linear in the weights, so one blend removes the step from both and ends on
exactly the new model, with no offset left to decay. What it cannot remove:
a new ``1/e`` is a new object with a new past, its surface target moves by
``delta(1/e)`` times the flux's half-integral so far; the finger feels that
move as a transient, largest just after the revision and decaying over the
following seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from telethermal.errors import ControlError, UnknownMaterialError
from telethermal.physics.contact import contact_flux_sensed_w_m2
from telethermal.physics.materials import get_material
from telethermal.render.generator import mixture


@dataclass(frozen=True, slots=True)
class Estimated:
    """A new material, rendered from the slave's effusivity estimate."""

    effusivity_w_s05_m2k: float

    def __post_init__(self):
        if not (math.isfinite(self.effusivity_w_s05_m2k) and self.effusivity_w_s05_m2k > 0):
            raise ControlError("a new material's effusivity must be finite and > 0, got "
                               f"{self.effusivity_w_s05_m2k} W s^0.5/(m^2 K)")

    def __str__(self) -> str:
        return f"new material ({self.effusivity_w_s05_m2k:.0f} W s^0.5/(m^2 K))"

    def normalised(self, t_s, conductance_w_m2k: float, sensor_lag_s: float) -> np.ndarray:
        """The display's flux per kelvin of (object - finger), W/m^2/K, at
        times since contact, as the pad's sensor reads it: the nominal skin
        on this effusivity through the finger's contact conductance."""
        return contact_flux_sensed_w_m2(t_s, 1.0, 0.0, get_material("skin").effusivity,
                                        self.effusivity_w_s05_m2k, conductance_w_m2k,
                                        sensor_lag_s)


def estimated_target(estimate) -> Estimated | None:
    """What a decision of a new material renders: its effusivity estimate;
    None when it is not one, or carries no usable estimate (an older peer's)."""
    e = getattr(estimate, "effusivity_w_s05_m2k", None)
    if estimate is None or not estimate.label.is_new or e is None or \
            not (math.isfinite(e) and e > 0):
        return None
    return Estimated(float(e))


@dataclass(slots=True)
class Handover:
    """What the display carries from one way of driving the pad to the next
    (holding, tracking, the posterior mixture, the decided material, the
    link lost and back), so none of these changes makes a step. A hand-over
    (the PID restarted from what is read, the step closed at
    ``handover_k_s``) follows holding and the safe state; a link that comes
    back is followed at the controller's slew limit, the PID carried on."""

    #: The pad was held (not tracking) during this contact.
    held: bool = False
    #: The flux PID is running; False: the next tracking period restarts it
    #: bumplessly from what the pad reads.
    pid_running: bool = False
    #: What is left of the step between what was applied and what the
    #: controller asked for at the hand-over, closed at ``handover_k_s``.
    offset_k: float = 0.0
    #: (time it began, weights before it): the blend from the posterior
    #: mixture (or a material the slave changed its mind about) to the
    #: decided material, over ``blend_s``; None when no blend runs.
    blend: tuple[float, dict] | None = None
    #: The posterior mixture's weights at the last tracked period.
    last_weights: dict | None = None
    #: The phase to return to when a lost link comes back.
    lost_from: object | None = None

    def close_offset(self, applied_c: float, command_c: float, step_k: float) -> float:
        """The offset for this period: ``step_k`` closer to zero, and never
        more than what separates the command from what is applied. The
        command may move while the step closes (a new posterior or decision
        changes what the controller asks for); when it comes back towards
        what is applied, or past it, the offset shrinks with it: added to the
        command it never drives the pad further from the command than it
        was. Kept whole, a stale offset would ask for a junction beyond
        both what is applied and what the controller wants (a posterior
        collapsing from insulators onto a conductor: the wish falls by
        several kelvin while the step opened towards the insulators is
        still open). Once shrunk it stays small: a command that then moves
        away again is followed at the controller's own slew limit, not at
        the hand-over's slope. A step from or to a non-finite command (a
        reading lost in the hand-over's first period) leaves no offset."""
        gap = applied_c - command_c
        if not (math.isfinite(self.offset_k) and math.isfinite(gap)):
            self.offset_k = 0.0
            return self.offset_k
        self.offset_k -= min(max(self.offset_k, -step_k), step_k)
        self.offset_k = min(max(self.offset_k, min(gap, 0.0)), max(gap, 0.0))
        return self.offset_k


def blended(h: Handover, t_s: float, weights: dict, blend_s: float) -> dict:
    """``weights`` (what is rendered now), reached from the blend's starting
    weights linearly over ``blend_s``: no setpoint step. Ends the blend once
    it has run its course."""
    if h.blend is None:
        return weights
    t_switch, before = h.blend
    a = min(1.0, (t_s - t_switch) / blend_s)
    out = {n: (1 - a) * before.get(n, 0.0) + a * weights.get(n, 0.0)
           for n in sorted(set(before) | set(weights), key=str)}
    if a >= 1.0:
        h.blend = None
    return out


def has_estimate(weights: dict | None) -> bool:
    """Whether a new material's estimate is among the weights."""
    return bool(weights) and any(isinstance(k, Estimated) for k in weights)


def generator_flux(generator, weights: dict, t_s: float, conductance_w_m2k: float = math.inf,
                   sensor_lag_s: float = 0.0, step_s: float = 1e-4) -> tuple[float, float]:
    """(sum of the weighted normalised curves, its time derivative) at ``t_s``
    since onset, W/m^2/K (and per s): the generator's for the materials, the
    closed form for an estimate (the derivative by the same central
    difference as :func:`~telethermal.render.generator.mixture`)."""
    names = [n for n in weights if not isinstance(n, Estimated)]
    if len(names) == len(weights):
        return mixture(generator, names, [weights[n] for n in names], t_s, step_s)
    g, dg = mixture(generator, names, [weights[n] for n in names], t_s, step_s) \
        if names else (0.0, 0.0)
    lo, hi = max(t_s - step_s, 0.0), t_s + step_s
    for key, w in weights.items():
        if isinstance(key, Estimated) and w:
            at = key.normalised(np.array([t_s, lo, hi]), conductance_w_m2k, sensor_lag_s)
            g += w * float(at[0])
            dg += w * float((at[2] - at[1]) / (hi - lo))
    return g, dg


def inverse_effusivity(weights: dict) -> float | None:
    """``sum w / e`` over the rendered materials (m^2 K s^-1/2 / W): the
    table's effusivity for a material, the estimate's for a new one; None
    when a material is not in the materials table."""
    try:
        return sum(w / (n.effusivity_w_s05_m2k if isinstance(n, Estimated)
                        else get_material(n).effusivity) for n, w in weights.items())
    except UnknownMaterialError:
        return None
