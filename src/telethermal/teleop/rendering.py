"""What the display renders while it tracks, and how it hands over from one
rendering to the next without a step (:class:`Handover`).

Split out of :mod:`telethermal.teleop.master`: the weights over the rendered
materials (the slave's posterior mixture before a decision, the decided
material after it), the linear blend of those weights over ``blend_s`` at
every change, and the flux and ``1/e`` they stand for.
"""

from __future__ import annotations

from dataclasses import dataclass

from telethermal.errors import UnknownMaterialError
from telethermal.physics.materials import get_material
from telethermal.render.generator import mixture


@dataclass(slots=True)
class Handover:
    """What the display carries from one way of driving the pad to the next
    (holding, tracking, the posterior mixture, the decided material, the
    link lost and back), so none of these changes makes a step."""

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


def generator_flux(generator, weights: dict, t_s: float) -> tuple[float, float]:
    """(sum of the weighted normalised curves, its time derivative) at ``t_s``
    since onset, W/m^2/K (and per s)."""
    names = list(weights)
    return mixture(generator, names, [weights[n] for n in names], t_s)


def inverse_effusivity(weights: dict) -> float | None:
    """``sum w / e`` over the rendered materials (m^2 K s^-1/2 / W); None
    when a material is not in the materials table."""
    try:
        return sum(w / get_material(n).effusivity for n, w in weights.items())
    except UnknownMaterialError:
        return None
