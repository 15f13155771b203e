"""What the slave has identified, kept per object.

A telepresence operator touches the same objects again and again. Once the
slave has decided what an object is made of, it remembers it under the
object's name (the scene names its objects; on hardware the operator or a
fiducial names them) and announces it when it moves to that object, so the
master renders the right material from the first instant of a repeated
touch, whatever the network's delay.

The rules:

* A decision is learned: for one material, or for a pair (``"a|b"``, the
  slave was sure it is one of the two; the master then renders the pair's
  mixture from t = 0, as it would live). Not ``"unknown"``, not an
  estimate that is itself a recollection.
* A sharper decision that agrees replaces it (a pair refined to a member,
  counted ``refined``); a vaguer one that agrees leaves it (a pair that
  holds the remembered member, ``confirmed``).
* A fresh decision that disagrees with what is remembered wins; the change
  is logged and counted (``overruled``). The slave's sensing of *this*
  touch is better evidence than an older touch of what may have been
  another object under the same name.
* It lives in the slave's memory only: a restarted slave has forgotten
  everything (its first touch of each object is a first touch again).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from enum import StrEnum

from telethermal.ident.anytime import Estimate, Label, Reason

log = logging.getLogger(__name__)

#: The ``reason`` of an estimate made from memory rather than from sensing.
FROM_MEMORY = Reason.OBJECT_MEMORY


class Agreement(StrEnum):
    """How a fresh decision stands to the one held (each a material or a pair)."""
    SAME = "same"
    SHARPER = "sharper"          # fewer materials, all held
    VAGUER = "vaguer"            # more, holding all held
    DISAGREES = "disagrees"


class Verdict(StrEnum):
    """What the memory did with a touch's decision (its counters' names)."""
    IGNORED = "ignored"
    LEARNED = "learned"
    CONFIRMED = "confirmed"
    REFINED = "refined"
    OVERRULED = "overruled"


@dataclass(frozen=True)
class Remembered:
    material: str
    confidence: float
    t_s: float               # when the deciding touch was made (the slave's clock)
    touches: int             # touches that decided this material in a row


class ObjectMemory:
    """object name -> :class:`Remembered`."""

    def __init__(self):
        self._known: dict[str, Remembered] = {}
        self.counters = {str(v): 0 for v in Verdict if v != Verdict.IGNORED}

    def __len__(self) -> int:
        return len(self._known)

    def recall(self, object_id: str | None) -> Remembered | None:
        return None if object_id is None else self._known.get(object_id)

    def learn(self, object_id: str | None, estimate: Estimate | None, t_s: float) -> Verdict:
        """Take a decision of a touch of ``object_id``; returns what was done."""
        if object_id is None or not learnable(estimate):
            return Verdict.IGNORED
        old = self._known.get(object_id)
        new = Remembered(estimate.label, float(estimate.confidence), t_s, 1)
        if old is None:
            self._known[object_id] = new
            self.counters[Verdict.LEARNED] += 1
            log.info("object %s remembered as %s (confidence %.3f)", object_id,
                     estimate.label, estimate.confidence)
            return Verdict.LEARNED
        verdict = agreement(old.material, estimate.label)
        if verdict == Agreement.SAME:
            self._known[object_id] = Remembered(old.material, new.confidence, t_s,
                                                old.touches + 1)
        elif verdict == Agreement.SHARPER:
            self._known[object_id] = Remembered(new.material, new.confidence, t_s,
                                                old.touches + 1)
        elif verdict == Agreement.VAGUER:
            self._known[object_id] = Remembered(old.material, old.confidence, t_s,
                                                old.touches + 1)
        else:
            self._known[object_id] = new
            self.counters[Verdict.OVERRULED] += 1
            log.warning("object %s: remembered as %s, the fresh touch says %s (confidence "
                        "%.3f): the fresh identification wins", object_id, old.material,
                        estimate.label, estimate.confidence)
            return Verdict.OVERRULED
        what = Verdict.REFINED if verdict == Agreement.SHARPER else Verdict.CONFIRMED
        self.counters[what] += 1
        return what

    def forget(self, object_id: str | None = None) -> None:
        """One object, or everything (``None``)."""
        if object_id is None:
            self._known.clear()
        else:
            self._known.pop(object_id, None)

    def to_dict(self) -> dict:
        return {name: asdict(r) for name, r in sorted(self._known.items())}


def learnable(estimate: Estimate | None) -> bool:
    return (estimate is not None and estimate.decided and not estimate.label.is_unknown and
            estimate.reason != FROM_MEMORY)


def agreement(held: str, fresh: str) -> Agreement:
    """How a fresh decision ``fresh`` stands to ``held`` (each a material or
    a pair "a|b")."""
    held, fresh = Label(held), Label(fresh)
    if held.is_unknown or fresh.is_unknown:      # no material: agrees only with itself
        return Agreement.SAME if held == fresh else Agreement.DISAGREES
    a, b = set(held.members), set(fresh.members)
    if a == b:
        return Agreement.SAME
    if b < a:
        return Agreement.SHARPER
    if a < b:
        return Agreement.VAGUER
    return Agreement.DISAGREES


def remembered_estimate(material: str, confidence: float, classes) -> Estimate:
    """The estimate the master renders from an announcement, at t = 0: one
    material, or a pair's members weighted equally."""
    these = Label(material).members
    return Estimate(0.0, tuple(1.0 / len(these) if c in these else 0.0 for c in classes),
                    material, float(confidence), True, FROM_MEMORY)
