"""What a touch decided, defined once: the ``identified``,
``decision_time_s`` and ``identified_at_s`` fields of every touch summary
(the in-process run's, the slave's report and the master's ``admin touch``
reply that ``demo.json`` is written from, the simulated network's, a
replay's and the recording's), computed from the touch's estimates by
:func:`touch_decision`.

* ``identified``: the label of the touch's last decided estimate (a
  material, a pair, a new material, or "unknown" with its reason);
  "unknown" when nothing was decided.
* ``decision_time_s`` (s after the slave's contact onset): when the touch
  committed, its first decided estimate naming a material, a pair or a new
  material, even if a later one refined it (a pair to one of its members)
  or changed it (to another material, or to "unknown"); the errors "after
  identification" run from there. A touch that never named one and ended
  "unknown": when it said so (its last decision). None: no decision.
* ``identified_at_s``: when the identified label itself was first decided
  (later than ``decision_time_s`` after a refinement); None when nothing
  was identified or the label is "unknown".

A recollection of the object memory (the master renders it before the
touch's own decision) is never among a touch's estimates: the summary says
what the slave decided on this touch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable

from telethermal.ident.label import UNKNOWN

if TYPE_CHECKING:               # the admin client imports this module: kept light
    from telethermal.ident.anytime import Estimate


#: The fields of a touch summary :meth:`TouchDecision.fields` gives.
DECISION_KEYS = ("identified", "decision_time_s", "identified_at_s")


@dataclass(frozen=True)
class TouchDecision:
    """What a touch decided (see the module)."""
    estimate: Estimate | None          # the final estimate: the last decided, else the last
    committed: Estimate | None         # the first commitment to a material, pair or new one
    identified: str
    decision_time_s: float | None
    identified_at_s: float | None

    def fields(self) -> dict:
        """The summary's fields, by their names."""
        return dict(zip(DECISION_KEYS, (self.identified, self.decision_time_s,
                                        self.identified_at_s)))

    def text(self) -> str:
        """When the identified label was decided, and the group the pad
        committed to first if there was one: the same words in the slave's
        "decided" and "touch over" lines, so the two give the same time for
        the same touch."""
        at_s, first = self.identified_at_s, self.committed
        text = "decided at -" if at_s is None else f"decided at {at_s:.2f} s"
        if first is not None and first.label != self.identified:
            text += f", after committing to {first.label} at {first.t_s:.2f} s"
        return text


def touch_decision(estimates: Iterable[Estimate | None]) -> TouchDecision:
    """What a touch decided, from its estimates (``t_s`` after the slave's
    onset; any order: they are taken by time, ties in the given order; None
    entries skipped): the slave's events, or those its master accepted."""
    ordered = sorted((e for e in estimates if e is not None), key=lambda e: e.t_s)
    decided = [e for e in ordered if e.decided]
    final = decided[-1] if decided else (ordered[-1] if ordered else None)
    committed = next((e for e in decided if not e.label.is_unknown), None)
    if not decided:
        return TouchDecision(final, None, UNKNOWN, None, None)
    if final.label.is_unknown:
        return TouchDecision(final, committed, final.label,
                             (committed or final).t_s, None)
    at_s = next(e.t_s for e in decided if e.label == final.label)
    return TouchDecision(final, committed, final.label, committed.t_s, at_s)


def when_decided(summary: dict) -> str | None:
    """When a summary's touch was decided, in words: "at 0.38 s (first
    committed at 0.06 s)" after a refinement, "at 0.06 s", None without a
    decision. The demo's line, ``admin touch`` and the master's log say it
    so."""
    t_s, at_s = summary.get("decision_time_s"), summary.get("identified_at_s")
    if t_s is None:
        return None
    if at_s is not None and at_s != t_s:
        return f"at {at_s:.2f} s (first committed at {t_s:.2f} s)"
    return f"at {t_s:.2f} s"


def pad_decision(pad) -> TouchDecision:
    """What a pad's touch (a :class:`~telethermal.teleop.slave.Slave`)
    decided so far, from its estimates."""
    return touch_decision(ev.estimate for ev in pad.events)
