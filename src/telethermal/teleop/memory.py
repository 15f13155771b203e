"""What the slave has identified, kept per object: the evidence of all its touches.

A telepresence operator touches the same objects again and again. The slave
keeps, under the object's name (the scene names its objects; on hardware the
operator or a fiducial names them), the evidence of every touch it decided,
and announces what that evidence supports when it moves to the object, so
the master renders the right material from the first instant of a repeated
touch, whatever the network's delay.

The rules (issue 29, deliverable 4):

* A touch counts when its decision committed (to a material or a pair; not
  ``"unknown"``, not an estimate that is itself a recollection). Its
  evidence is the log of its calibrated posteriors (equal priors: the
  posterior is the likelihood normalised), each floored at
  ``EVIDENCE_FLOOR``: a calibration measured on a few hundred held-out
  touches cannot vouch for an error rate below about one in a thousand, so
  no single touch may rule a material out harder than that.
* The memory's posterior is the normalised sum of its touches' evidence
  (touches independent given the material). While no touch has disagreed,
  what is announced is what they decided (the sharpest: a pair refined by
  a member); once one has, what the evidence supports at the identifier's
  threshold: one material, else the two most probable together (a pair),
  else nothing. (A single touch committed at 0.99 is below 0.99 once its
  ruled-out classes are floored: the floor is for weighing disagreements,
  not for doubting agreement.)
* So one wrong decision cannot flip a memory built from several right
  ones: its evidence is outweighed (counted ``kept``), or, against a
  single earlier touch, leaves the two as a pair (``doubted``).
* A change of object is still found: by its announcement (another object's
  name), or when ``CHANGE_TOUCHES`` touches in a row each disagree with what
  is remembered and agree with each other; the memory then holds their
  evidence alone (``replaced``, logged).
* It lives in the slave's memory only: a restarted slave has forgotten
  everything (its first touch of each object is a first touch again).

A touch given without posteriors over the classes (a label and a
confidence only) counts as the confidence shared among the label's
members and the rest shared among the other classes. A new material
(issue 30: a touch outside every trained class) is kept the same way, as
one more class ``"new material"`` (its posteriors over the trained classes
say which class is nearest, not what it is): its confidence, one minus
the likeliest class's predictive tail, against the trained classes. A
touch named a class by an identifier that could have said "new material"
(its estimate carries an effusivity) counts as evidence against a new
material, at the floor.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from telethermal.ident.anytime import NEW_MATERIAL, Estimate, Label, Reason
from telethermal.ident.openset import EFFUSIVITY_KEYS, Z95, log_sd_of_interval

log = logging.getLogger(__name__)

#: The ``reason`` of an estimate made from memory rather than from sensing.
FROM_MEMORY = Reason.OBJECT_MEMORY
#: The smallest posterior a touch's evidence takes for any class (see above).
EVIDENCE_FLOOR = 1e-3
#: Disagreeing touches in a row, agreeing among themselves, that mean the
#: object was changed under its name.
CHANGE_TOUCHES = 2
#: The threshold of the announcement when none is given (the identifiers' default).
THRESHOLD = 0.99


@dataclass(frozen=True)
class Effusivity:
    """A new material's remembered estimate, in ``ln e`` (W s^0.5/(m^2 K))."""
    log_e: float
    sd: float                    # of ln e: the interval's wider half / Z95; pooled: the sharpest
    weight: float                # the sum of the touches' 1 / sd^2

    @classmethod
    def of_fields(cls, e, lo, hi) -> "Effusivity | None":
        """From an effusivity and its 95 % interval's ends; None when one is
        missing or unusable (not finite and > 0, or ``lo <= e <= hi`` not)."""
        if any(v is None or not math.isfinite(v) or v <= 0 for v in (e, lo, hi)) or \
                not lo <= e <= hi:
            return None
        sd = max(log_sd_of_interval(e, lo, hi), 1e-9)
        return cls(math.log(e), sd, sd ** -2)

    @classmethod
    def of(cls, estimate) -> "Effusivity | None":
        """An estimate's effusivity and interval (:meth:`of_fields`)."""
        return cls.of_fields(*(getattr(estimate, k, None) for k in EFFUSIVITY_KEYS[:3]))

    def pooled(self, other: "Effusivity") -> "Effusivity":
        """The inverse-variance mean of the two; the sharper one's sd (see
        the module: the touches share errors that averaging cannot remove)."""
        w1, w2 = self.weight, other.weight
        return Effusivity((w1 * self.log_e + w2 * other.log_e) / (w1 + w2),
                          min(self.sd, other.sd), w1 + w2)

    def consistent(self, other: "Effusivity") -> bool:
        """The two estimates' difference holds 0 at 95 %."""
        return abs(self.log_e - other.log_e) <= Z95 * math.hypot(self.sd, other.sd)

    @property
    def fields(self) -> dict:
        """Its effusivity and 95 % interval ends, W s^0.5/(m^2 K), by the
        estimate's field names."""
        return {"effusivity_w_s05_m2k": math.exp(self.log_e),
                "effusivity_lo_w_s05_m2k": math.exp(self.log_e - Z95 * self.sd),
                "effusivity_hi_w_s05_m2k": math.exp(self.log_e + Z95 * self.sd)}


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
    CONFIRMED = "confirmed"      # agrees; what is announced is unchanged
    REFINED = "refined"          # agrees; what is announced is sharper
    KEPT = "kept"                # disagrees, outweighed by the object's history
    DOUBTED = "doubted"          # disagrees; what is announced is now vaguer or nothing
    OVERRULED = "overruled"      # disagrees, and its material is now announced
    REPLACED = "replaced"        # CHANGE_TOUCHES disagreeing in a row: another object


class Judgement(StrEnum):
    """What a touch's decision says of the memory announced for its object,
    judged the same way by the master (:class:`~telethermal.teleop.link.SlaveLink`,
    as the decisions arrive) and the slave (:class:`~telethermal.teleop.session.SlaveSession`,
    on the touch's final decision): :func:`judge`. The two that are counted
    carry their counters' names (PROTOCOL.md sections 4, 6b and 6c)."""
    AGREES = "agrees"                    # the same, or sharper: the decision takes over
    VAGUER = "vaguer"                    # holds what is remembered: the memory stays in force
    KEPT = "memory_kept"                 # a class named early, consistent with the
    #                                      remembered new material's estimate: not against it
    OVERRULED = "memory_overruled"       # disagrees with the memory


def judge(held: str, held_effusivity: "Effusivity | None", fresh: Estimate
          ) -> Judgement | None:
    """How the decision ``fresh`` stands to the remembered ``held`` (a
    material, a pair or "new material", with its estimate
    ``held_effusivity``); None when ``fresh`` is no decision on a material
    (undecided, or "unknown"). A decision disagrees (``OVERRULED``) when it
    names none of the remembered materials, or is a new material whose
    estimate is inconsistent with the remembered new material's; a class
    whose own estimate is consistent with the remembered new material's is
    what a closed set names early on an unseen material (``KEPT``), not a
    disagreement."""
    if not fresh.decided or fresh.label.is_unknown:
        return None
    fresh_e = Effusivity.of(fresh)
    verdict = agreement(held, fresh.label)
    if verdict == Agreement.DISAGREES:
        if Label(held).is_new and held_effusivity is not None and fresh_e is not None and \
                held_effusivity.consistent(fresh_e):
            return Judgement.KEPT
        return Judgement.OVERRULED
    if _other_new(Label(held), held_effusivity, fresh_e if fresh.label.is_new else None):
        return Judgement.OVERRULED
    return Judgement.VAGUER if verdict == Agreement.VAGUER else Judgement.AGREES


#: The counters :func:`judge` feeds (PROTOCOL.md 6b).
JUDGED = (str(Judgement.OVERRULED), str(Judgement.KEPT))


def judged_of(counters: dict) -> dict:
    """Those of ``counters`` that :func:`judge` feeds (0 where absent)."""
    return {k: int(counters.get(k, 0)) for k in JUDGED}


def judged_counts(judgement: Judgement | None) -> dict:
    """One touch's counters from its judgement (:func:`judge`; None: not
    judged), as :func:`memory_counts` reads them."""
    return {k: int(judgement == k) for k in JUDGED}


def memory_counts(master_counters: dict, slave_counters: dict) -> dict:
    """A touch summary's ``memory_counts``: the counters :func:`judge` feeds,
    as the master's link and the slave's session counted them."""
    return {"master": judged_of(master_counters), "slave": judged_of(slave_counters)}


@dataclass(frozen=True)
class Remembered:
    """What the memory announces for an object: a material or a pair, the
    memory's posterior of it, when the last touch was learnt, and how many
    touches the evidence holds."""
    material: str
    confidence: float
    t_s: float
    touches: int
    posteriors: dict = field(default_factory=dict)     # class -> the memory's posterior
    #: A new material's estimate (``material`` "new material"), else None.
    effusivity: Effusivity | None = None


@dataclass
class _Evidence:
    log_p: dict                  # class -> summed log evidence
    touches: int
    t_s: float
    streak: list                 # (label, log evidence, Effusivity | None) of the
    #                              disagreeing touches in a row
    agreed: Label | None         # the sharpest decision while none disagreed; None after one
    effusivity: Effusivity | None = None    # the new-material touches' pooled estimate


def touch_evidence(estimate: Estimate, classes) -> dict:
    """A decided touch's log evidence per class (floored posteriors)."""
    classes = tuple(classes or ())
    label = estimate.label
    if classes and len(estimate.posteriors) == len(classes) and not label.is_new:
        p = np.asarray(estimate.posteriors, dtype=np.float64)
        if estimate.effusivity_w_s05_m2k is not None:
            # An identifier that can say "new material" named a class: the
            # touch lay inside it, evidence against a new material (floored).
            classes, p = (*classes, str(NEW_MATERIAL)), np.append(p, 0.0)
    else:
        classes = tuple(dict.fromkeys((*classes, *label.members)))
        inside = [c in label.members for c in classes]
        n_in, n_out = sum(inside), len(classes) - sum(inside)
        conf = float(estimate.confidence)
        p = np.array([conf / n_in if i else (1.0 - conf) / max(n_out, 1) for i in inside])
    p = np.maximum(np.nan_to_num(p, nan=0.0), EVIDENCE_FLOOR)
    return {c: float(math.log(v / p.sum())) for c, v in zip(classes, p)}


def _add(a: dict, b: dict) -> dict:
    floor = math.log(EVIDENCE_FLOOR)            # a class one side never saw
    return {c: a.get(c, floor) + b.get(c, floor) for c in dict.fromkeys((*a, *b))}


def _posterior(log_p: dict) -> dict:
    top = max(log_p.values())
    w = {c: math.exp(v - top) for c, v in log_p.items()}
    total = sum(w.values())
    return {c: v / total for c, v in w.items()}


def supported(log_p: dict, threshold: float) -> tuple[Label | None, float, dict]:
    """What evidence ``log_p`` supports at ``threshold``: a material (or a
    new material), else a pair of materials, else None; with its posterior
    and the posteriors."""
    post = _posterior(log_p)
    ranked = sorted(post, key=lambda c: (-post[c], c))
    if post[ranked[0]] >= threshold:
        return Label(ranked[0]), post[ranked[0]], post
    # A new material pairs with nothing: "graphite or something new" names nothing.
    if len(ranked) >= 2 and post[ranked[0]] + post[ranked[1]] >= threshold and \
            not any(Label(c).is_new for c in ranked[:2]):
        return Label.of(ranked[:2]), post[ranked[0]] + post[ranked[1]], post
    return None, post[ranked[0]], post


class ObjectMemory:
    """object name -> the evidence of its touches (see the module's rules).
    ``threshold``: what the announcement must reach (the identifier's)."""

    def __init__(self, threshold: float = THRESHOLD):
        if not 0.5 < threshold < 1.0:
            raise ValueError(f"threshold must be in (0.5, 1), got {threshold}")
        self.threshold = float(threshold)
        self._known: dict[str, _Evidence] = {}
        self.counters = {str(v): 0 for v in Verdict if v != Verdict.IGNORED}

    def __len__(self) -> int:
        return len(self._known)

    def recall(self, object_id: str | None) -> Remembered | None:
        """What is announced for ``object_id``; None when nothing is known
        or the evidence supports neither a material nor a pair."""
        ev = None if object_id is None else self._known.get(object_id)
        if ev is None:
            return None
        label, conf, post = supported(ev.log_p, self.threshold)
        if ev.agreed is not None:        # no touch disagreed: what they decided, sharpest
            label = ev.agreed
            conf = sum(post.get(m, 0.0) for m in label.members)
        if label is None:
            return None
        return Remembered(str(label), conf, ev.t_s, ev.touches, post,
                          ev.effusivity if label.is_new else None)

    def learn(self, object_id: str | None, estimate: Estimate | None, t_s: float,
              classes=None) -> Verdict:
        """Take a touch of ``object_id`` (its final estimate; ``classes``: the
        identifier's, the order of its posteriors); returns what was done."""
        if object_id is None or not learnable(estimate):
            return Verdict.IGNORED
        fresh = touch_evidence(estimate, classes)
        fresh_e = Effusivity.of(estimate) if estimate.label.is_new else None
        old = self._known.get(object_id)
        if old is None:
            self._known[object_id] = _Evidence(fresh, 1, t_s, [], Label(estimate.label),
                                               fresh_e)
            self.counters[Verdict.LEARNED] += 1
            log.info("object %s: learnt %s (confidence %.3f)", object_id, estimate.label,
                     estimate.confidence)
            return Verdict.LEARNED
        before = self.recall(object_id)
        held = Label(before.material) if before else None
        disagrees = held is not None and (
            agreement(held, estimate.label) == Agreement.DISAGREES or
            _other_new(held, old.effusivity, fresh_e))
        streak = old.streak + [(estimate.label, fresh, fresh_e)] if disagrees else []
        last, _, last_e = streak[-1] if streak else (None, None, None)
        if len(streak) >= CHANGE_TOUCHES and all(
                set(a.members) & set(last.members) and not _other_new(a, e, last_e)
                for a, _, e in streak):
            log_p = streak[0][1]
            for _, ev, _e in streak[1:]:
                log_p = _add(log_p, ev)
            labels = [a for a, _, _e in streak]
            agreed = min(labels, key=lambda a: len(a.members)) \
                if all(agreement(a, b) != Agreement.DISAGREES
                       for a in labels for b in labels) else None
            self._known[object_id] = _Evidence(log_p, len(streak), t_s, [], agreed,
                                               _pool(e for _a, _ev, e in streak))
            verdict = Verdict.REPLACED
        else:
            agreed = None if disagrees or old.agreed is None else (
                Label(estimate.label) if agreement(old.agreed, estimate.label) ==
                Agreement.SHARPER else old.agreed)
            # A new material's estimate is pooled whatever the label's verdict
            # (one named against a class may yet be what the evidence
            # supports), unless it is inconsistent with the estimate held.
            pooled = old.effusivity if _inconsistent(old.effusivity, fresh_e) else \
                _pool((old.effusivity, fresh_e))
            self._known[object_id] = _Evidence(_add(old.log_p, fresh), old.touches + 1, t_s,
                                               streak, agreed, pooled)
            after = self.recall(object_id)
            verdict = _verdict(held, None if after is None else Label(after.material),
                               disagrees)
        self.counters[verdict] += 1
        if disagrees:
            now = self.recall(object_id)
            log.warning("object %s: remembered as %s, a touch says %s (confidence %.3f): "
                        "%s, now %s", object_id, held, estimate.label, estimate.confidence,
                        verdict, now.material if now else "nothing announced")
        return verdict

    def forget(self, object_id: str | None = None) -> None:
        """One object, or everything (``None``)."""
        if object_id is None:
            self._known.clear()
        else:
            self._known.pop(object_id, None)

    def to_dict(self) -> dict:
        out = {}
        for name in sorted(self._known):
            r = self.recall(name)
            ev = self._known[name]
            post = r.posteriors if r else _posterior(ev.log_p)
            out[name] = {"material": r.material if r else None,
                         "confidence": r.confidence if r else None, "t_s": ev.t_s,
                         "touches": ev.touches,
                         "posteriors": {c: round(p, 6) for c, p in sorted(post.items())},
                         **(r.effusivity.fields if r and r.effusivity else {})}
        return out


def _other_new(held: Label, held_e: Effusivity | None, fresh_e: Effusivity | None) -> bool:
    """A new material's touch whose estimate is inconsistent with the held
    new material's: another new material (a disagreement)."""
    return Label(held).is_new and _inconsistent(held_e, fresh_e)


def _inconsistent(a: Effusivity | None, b: Effusivity | None) -> bool:
    """Both given, and not :meth:`Effusivity.consistent`."""
    return a is not None and b is not None and not a.consistent(b)


def _pool(estimates) -> Effusivity | None:
    """The pooled estimate of those given (None ones skipped)."""
    out = None
    for e in estimates:
        if e is not None:
            out = e if out is None else out.pooled(e)
    return out


def _verdict(held: Label | None, now: Label | None, disagrees: bool) -> Verdict:
    if not disagrees:
        if held is None or now is None:
            return Verdict.CONFIRMED if now is None else Verdict.REFINED
        return Verdict.REFINED if agreement(held, now) == Agreement.SHARPER \
            else Verdict.CONFIRMED
    if now is not None and now == held:
        return Verdict.KEPT
    if now is not None and agreement(held, now) == Agreement.DISAGREES:
        return Verdict.OVERRULED
    return Verdict.DOUBTED


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


def remembered_estimate(material: str, confidence: float, classes,
                        effusivity: dict | None = None) -> Estimate:
    """The estimate the master renders from an announcement, at t = 0: one
    material, or a pair's members weighted equally; a new material with its
    ``effusivity`` fields (:attr:`Effusivity.fields`), the classes equally
    likely (it is none of them)."""
    label = Label(material)
    if label.is_new:
        n = max(len(classes), 1)
        return Estimate(0.0, (1.0 / n,) * len(classes), NEW_MATERIAL, float(confidence), True,
                        FROM_MEMORY, **(effusivity or {}))
    these = label.members
    return Estimate(0.0, tuple(1.0 / len(these) if c in these else 0.0 for c in classes),
                    material, float(confidence), True, FROM_MEMORY)
