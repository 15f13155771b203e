"""Anytime decisions: commit to a material as soon as the calibrated
confidence passes the identifier's threshold, or say "unknown".

A commitment needs the threshold passed at ``confirm_windows`` windows in a
row (:class:`~telethermal.ident.rule.Runs`; the rule's one copy is
:class:`~telethermal.ident.rule.AnytimeRule`) and at a window the model's
held-out touches support (``commit_from_s_``, :func:`~telethermal.ident.base.commit_from_index`).

"unknown" is the answer, rather than a guess, when the contact exchanged too
little heat (a gap under ``MIN_GAP_K``: the passive pad at the object's own
temperature), when the contact lies outside every learnt class and the
identifier has no estimate of the object to report, or when the confidence
never reaches the threshold within the contact. An identifier that
estimates the object's effusivity (``effusivity-fit``) reports a touch whose
estimate lies outside every class at the last window (or, with its own
interval, at two windows in a row before it: :class:`EarlyNew`) as a **new
material** with its estimate (:mod:`telethermal.ident.openset`); its estimates carry the
window's effusivity and 95 % interval throughout.

Two materials may stay ambiguous (the first paper merges aluminium with
steel, graphite with rubber): when no class passes the threshold but the two
most probable together do, the decision commits to that *group* (label
``"a|b"``, members sorted) and keeps refining: a member passing the
threshold alone later replaces it. A master renders a group as the mixture
of its members weighted by the posteriors, as before any decision.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from telethermal.errors import IdentificationError
from telethermal.ident.base import FORCE_SAMPLES, Identifier, force_at, force_in_range
from telethermal.ident.rule import AnytimeRule
from telethermal.ident.label import GROUP_SEPARATOR, NEW_MATERIAL, UNKNOWN, Label, Reason
from telethermal.ident.misfit import MisfitRun, pad_model_misfit, with_missing
from telethermal.ident.openset import new_material_confidence, reading_fields, reading_of
from telethermal.ident.prepare import MIN_GAP_K

__all__ = ["GROUP_SEPARATOR", "UNKNOWN", "NEW_MATERIAL", "FORCE_OUTSIDE", "Label", "Reason",
           "Decision",
           "Estimate", "StreamingIdentifier", "decide", "decide_all", "group_label", "members",
           "MisfitRun", "pad_model_misfit", "with_missing"]

FORCE_OUTSIDE = Reason.FORCE_OUTSIDE


def group_label(members) -> str:
    """The text of a group's label (members sorted), a plain ``str``."""
    return str(Label.of(members))


def members(label: str) -> tuple[str, ...]:
    """The materials a decision's label stands for (one, or a group's; none
    for unknown): :attr:`Label.members`."""
    return Label(label).members


@dataclass(frozen=True, slots=True)
class Decision:
    label: Label               # a class of the identifier, a group, or unknown (any str given)
    confidence: float          # posterior of the best class when decided (or at the end)
    time_s: float | None       # time after contact of the commitment; None if none
    reason: str                # a Reason: confident | confident group | outside classes
    #                            | new material | gap too small | not confident
    #                            | force outside trained range
    time_first_s: float | None = None   # first commitment (a group's), when refined later
    # A new material's estimate (W s^0.5/(m^2 K), 95 % interval) and nearest class.
    effusivity_w_s05_m2k: float | None = None
    effusivity_lo_w_s05_m2k: float | None = None
    effusivity_hi_w_s05_m2k: float | None = None
    nearest: str | None = None
    # What a decision revised to a new material at the last window had
    # named before (a class or a pair: told the operator until then).
    revised_from: str | None = None

    def __post_init__(self):
        if type(self.label) is not Label:
            object.__setattr__(self, "label", Label(self.label))


def decide(model: Identifier, x: np.ndarray, gap_k: float,
           force_n: np.ndarray | None = None, measured: np.ndarray | None = None) -> Decision:
    """Walk one contact's normalised samples ``x`` (n, C) window by window.

    ``force_n`` (n,): the pressing force; a window whose force lies outside
    the range the model was trained on commits nothing (a lighter or heavier
    touch changes the contact conductance, and so the flux), and a contact
    that ends so is "unknown" ("force outside trained range"). ``measured``
    (n,) bool: False where a sample was filled in by the driver (a frame
    lost on the line): the pad-model check leaves it out
    (:func:`pad_model_misfit`), and so does a model that reads it as
    missing (:func:`with_missing`).

    Posteriors change only where a longer window (or, for a recurrent
    network, a new input step) becomes available, so this gives the same
    decision as updating at every sample, at a fraction of the cost.

    A touch the pad-model check ends is named by the model's fallback where
    it has one (:func:`fallen_back`).
    """
    return fallen_back(model, _decide(model, x, gap_k, force_n, measured), x, gap_k, force_n,
                       measured)


def fallen_back(model, decision: Decision, x, gap_k, force_n=None, measured=None) -> Decision:
    """A touch the pad-model check ended (``decision``: unknown, reason
    ``PAD_MODEL_MISFIT``) named by the model's fallback, which needs no pad
    model (``Identifier.fallback_``, trained on the same touches) on the
    whole touch, by its own anytime rule: its class or pair with the reason
    ``PAD_MODEL_FALLBACK``, no earlier than the check's verdict; where it
    names nothing (or there is none) the misfit's unknown stands."""
    fallback = getattr(model, "fallback_", None)
    if fallback is None or decision.reason != Reason.PAD_MODEL_MISFIT:
        return decision
    named = decide(fallback, x, gap_k, force_n, measured)
    if named.label.is_unknown or named.label.is_new or named.time_s is None:
        return decision
    t = max(named.time_s, decision.time_s or 0.0)
    return replace(named, reason=Reason.PAD_MODEL_FALLBACK, time_s=t, time_first_s=t)


def _decide(model, x, gap_k, force_n, measured) -> Decision:
    """:func:`decide` by the model alone."""
    if not np.isfinite(gap_k) or abs(gap_k) < MIN_GAP_K:
        return Decision(UNKNOWN, 0.0, None, Reason.GAP_TOO_SMALL)
    n = int(np.sum(np.all(np.isfinite(x), axis=1)))
    x = with_missing(model, x[:n], None if measured is None else measured[:n])
    path = model.posterior_path(x)
    forces = None if force_n is None else np.asarray(force_n, dtype=np.float64)[None]
    rule = AnytimeRule(model.threshold, model.confirm_windows)
    group = None
    best = 0.0
    early = EarlyNew(model.confirm_windows)
    misfit = MisfitRun(model.confirm_windows)
    for i, p in enumerate(path):
        best = float(np.max(p))
        outside = False
        if forces is not None:
            n_w = int(round(model.windows_s_[i] * model.sample_rate_hz_)) + 1
            outside = not force_in_range(model, i, float(force_at(forces, n_w)[0]))
        flagged = not outside and pad_model_misfit(model, x[None, :n], i, measured)
        if misfit.step(flagged, i == len(path) - 1):
            return Decision(UNKNOWN, best, model.windows_s_[i], Reason.PAD_MODEL_MISFIT,
                            group.time_s if group else None,
                            revised_from=str(group.label) if group else None)
        step = rule.step(i, rule_posterior(model, p, x[None, :n], i),
                         may_commit=model.may_commit(i) and not flagged, force_outside=outside,
                         unlike=lambda i=i: bool(model.outside_classes(x[None, :n], i)[0]))
        new = early.step(model, x[None, :n], i,
                         step is None and group is None and not outside and not flagged)
        if new is not None:
            t = model.windows_s_[i]
            return Decision(NEW_MATERIAL, new_material_confidence(new), t, Reason.NEW_MATERIAL,
                            t, **reading_fields(new, True))
        if step is None:
            continue
        kind, what = step
        if kind == "class":
            # The group's earlier commitment counts only if it held this material.
            first = group.time_s if group and group.label.holds(model.classes_[what]) \
                else model.windows_s_[i]
            return _watched(model, x[:n], len(path), Decision(
                model.classes_[what], best, model.windows_s_[i], Reason.CONFIDENT, first),
                measured)
        group = Decision(Label.of(model.classes_[j] for j in what), float(p[list(what)].sum()),
                         model.windows_s_[i], Reason.CONFIDENT_GROUP, model.windows_s_[i])
    if group is not None:
        return _watched(model, x[:n], len(path), group, measured)
    new = _new_material(model, x[None, :n], len(path) - 1) \
        if len(path) and not rule.force_outside else None
    if new is not None:
        t = model.windows_s_[len(path) - 1]
        return Decision(NEW_MATERIAL, new_material_confidence(new), t, Reason.NEW_MATERIAL, t,
                        **reading_fields(new, True))
    if rule.unlike and not rule.force_outside:
        return Decision(UNKNOWN, best, model.windows_s_[len(path) - 1], Reason.OUTSIDE_CLASSES)
    return Decision(UNKNOWN, best, None,
                    FORCE_OUTSIDE if rule.force_outside else Reason.NOT_CONFIDENT)


class EarlyNew:
    """A new material before the last window: where nothing commits at a
    window the calibration lets commit and the touch's estimate lies
    outside every class, with its own uncertainty too (:func:`_new_material`,
    the last window's test), at ``confirm`` windows in a row. Foam (e 42,
    wood the lowest class at 470) is one from its first windows; an unseen
    material inside a class's early predictive is not (it is checked at the
    last window)."""

    def __init__(self, confirm: int):
        self.confirm, self.run = max(1, int(confirm)), 0

    def step(self, model, x: np.ndarray, i: int, may: bool):
        """The reading of a new material decided at window ``i``, else None;
        ``may``: nothing committed here, no group standing, the force in range."""
        reading = _new_material(model, x, i) if may and model.may_commit(i) else None
        self.run = self.run + 1 if reading is not None else 0
        return reading if self.run >= self.confirm else None


def rule_posterior(model, p: np.ndarray, x: np.ndarray, window_index: int) -> np.ndarray:
    """The posteriors the rule commits on (``Identifier.rule_posterior``;
    ``p`` itself for a model without it)."""
    get = getattr(model, "rule_posterior", None)
    return p if get is None else get(p, x, window_index)


def _watched(model, x: np.ndarray, n_windows: int, decision: Decision,
             measured: np.ndarray | None = None) -> Decision:
    """A decision naming a class (or a pair), checked at the model's last
    window when the touch reaches it: an identifier that estimates the
    effusivity revises it to a new material where the estimate there lies
    outside the named class's predictive (:mod:`telethermal.ident.openset`)."""
    last = len(model.windows_s_) - 1
    if n_windows != last + 1:
        return decision
    if pad_model_misfit(model, x[None], last, measured):
        return Decision(UNKNOWN, decision.confidence, model.windows_s_[last],
                        Reason.PAD_MODEL_MISFIT, decision.time_first_s or decision.time_s,
                        revised_from=str(decision.label))
    reading = reading_of(model, x[None], last)
    if reading is None or not reading.outside(decision.label):
        return decision
    first = decision.time_first_s if decision.time_first_s is not None else decision.time_s
    return Decision(NEW_MATERIAL, new_material_confidence(reading), model.windows_s_[last],
                    Reason.NEW_MATERIAL, first, **reading_fields(reading, True),
                    revised_from=str(decision.label))


def _new_material(model, x: np.ndarray, window_index: int):
    """The touch's effusivity reading when its estimate at ``window_index``
    lies outside every class (a new material), else None (inside a class,
    or a method without estimates)."""
    if not bool(model.outside_classes(x, window_index)[0]):
        return None
    reading = reading_of(model, x, window_index)
    # Outside every class with the touch's own uncertainty too (the
    # reading's ``inside``): else "unknown, outside classes", not a claim.
    return reading if reading is not None and not reading.inside else None


def decide_all(model: Identifier, contacts) -> list[Decision]:
    """:func:`decide` for every contact of a :class:`~telethermal.ident.prepare.Contacts`,
    with its pressing force when recorded."""
    force = contacts.force_n
    return [decide(model, contacts.x[i], contacts.gap_k[i], None if force is None else force[i])
            for i in range(len(contacts))]


@dataclass(frozen=True, slots=True)
class Estimate:
    """What a streaming identifier knows ``t_s`` after contact."""

    t_s: float
    posteriors: tuple[float, ...]      # over the identifier's classes
    label: Label                       # the best class, a group, or unknown (any str given)
    confidence: float
    decided: bool                      # committed (to a class, a group or "unknown")
    reason: str = Reason.UNDECIDED     # a Reason (a peer's unknown one stays its string)
    # The window's effusivity estimate and its 95 % interval, W s^0.5/(m^2 K),
    # when the identifier gives one (effusivity-fit); the nearest class, for
    # a new material (:mod:`telethermal.ident.openset`).
    effusivity_w_s05_m2k: float | None = None
    effusivity_lo_w_s05_m2k: float | None = None
    effusivity_hi_w_s05_m2k: float | None = None
    nearest: str | None = None
    # What a decision revised to a new material at the last window had
    # named before (a class or a pair: told the operator until then).
    revised_from: str | None = None

    def __post_init__(self):
        if type(self.label) is not Label:
            object.__setattr__(self, "label", Label(self.label))

    @property
    def final(self) -> bool:
        """Committed for good: a group's commitment may still be refined."""
        return self.decided and self.reason != Reason.CONFIDENT_GROUP


def unknown_reason(estimate: Estimate | None) -> str | None:
    """Why a touch ended without a name (a :class:`Reason`), or None when it
    was named (a class or a pair): what a person is told beside "unknown"."""
    if estimate is None:
        return Reason.NO_ESTIMATE
    if not estimate.decided:
        return Reason.NO_DECISION
    if estimate.label.is_unknown:
        return estimate.reason or Reason.NO_DECISION
    return None


class StreamingIdentifier:
    """The anytime decision of :func:`decide`, fed one sample at a time.

    ``push(sample)`` takes the raw samples since contact (t = 0 first) at
    the model's rate and returns a new :class:`Estimate` whenever a longer
    window becomes available (posteriors change only there), else None.
    It commits once: to a class when the calibrated confidence passes the
    threshold, or to "unknown" (gap too small, outside every class, or the
    last window passed unconvinced). Gives the same decision as
    :func:`decide` on the same contact (tested).
    """

    def __init__(self, model: Identifier, gap_k: float, t_object_c: float | None = None):
        from telethermal.ident.prepare import normalise

        model._require_fitted()
        self.model, self.gap_k, self.t_object_c = model, gap_k, t_object_c
        self._normalise = normalise
        self._rows: list[np.ndarray] = []
        self._forces: list[float] = []
        #: Per sample pushed: delivered by the sensor (False: filled in).
        self._measured: list[bool] = []
        self._window = -1
        #: A class committed before the last window, by an identifier that
        #: estimates the effusivity: the touch is watched to the last window.
        self._watch = False
        self._rule = AnytimeRule(model.threshold, model.confirm_windows)
        self._early = EarlyNew(model.confirm_windows)
        self._misfit_run = MisfitRun(model.confirm_windows)
        #: The samples as pushed (sample, force, measured), replayed into the
        #: model's fallback once the pad-model check ends the touch; then
        #: the fallback's stream (:meth:`_misfit`).
        self._pushed: list = []
        self._fallback: StreamingIdentifier | None = None
        n_classes = len(model.classes_)
        self.estimate = Estimate(0.0, (1.0 / n_classes,) * n_classes, UNKNOWN, 1.0 / n_classes,
                                 False)
        self.gap_ok = bool(np.isfinite(gap_k) and abs(gap_k) >= MIN_GAP_K)
        if not self.gap_ok:
            self.estimate = Estimate(0.0, self.estimate.posteriors, UNKNOWN, 0.0, True,
                                     Reason.GAP_TOO_SMALL)

    @property
    def decided(self) -> bool:
        """Committed for good (a group keeps refining until the contact's
        last window)."""
        return self.estimate.final

    @property
    def finished(self) -> bool:
        """No estimate will follow: committed for good (a class named by an
        identifier that estimates the effusivity only once the last window
        has checked it), or the model's last window is past (a group then
        stands as the contact's answer)."""
        if self._fallback is not None:
            return self._fallback.finished
        return (self.decided and not self._watch) or \
            self._window == len(self.model.windows_s_) - 1

    def push(self, sample, force_n: float | None = None,
             measured: bool = True) -> Estimate | None:
        """One sample (the model's channels); ``force_n``, the pressing force
        with it, lets the decision refuse a touch unlike the trained ones;
        ``measured`` False: the sample was filled in by the driver (a frame
        lost on the line, the previous sample held), not counted in the
        pad-model check's residual (:func:`pad_model_misfit`), and missing
        data to a model that reads it so (:func:`with_missing`). Once the
        pad-model check has ended the touch, the model's fallback reads
        them (:meth:`_misfit`)."""
        if self._fallback is not None:
            return self._from_fallback(self._fallback.push(sample, force_n, measured))
        if self.decided and not self._watch:
            return None
        if force_n is not None:
            self._forces.append(float(force_n))
        model = self.model
        row = np.atleast_1d(np.asarray(sample, dtype=np.float64))
        if row.shape != (len(model.channels),) or not np.all(np.isfinite(row)):
            raise IdentificationError(f"sample must be {len(model.channels)} finite value(s) "
                                      f"for channels {model.channels}, got {sample!r}")
        self._rows.append(np.array([self._normalise(row[i], c, self.gap_k, self.t_object_c)
                                    for i, c in enumerate(model.channels)]))
        self._measured.append(bool(measured))
        self._pushed.append((row, force_n, measured))
        n = len(self._rows)
        index = model.window_index(n)
        if index is None or index == self._window:
            return None
        self._window = index
        last = index == len(model.windows_s_) - 1
        if self._watch and not last:
            follow = getattr(model, "follow", None)
            if follow is not None:      # the watched fit, one window at a time
                follow(with_missing(model, np.stack(self._rows), self._measured)[None], index)
            return None
        x = with_missing(model, np.stack(self._rows), self._measured)[None]
        p = model.proba_normalised(x, index)[0]
        if self._watch:
            return self._revised(x, p, index)
        k = int(np.argmax(p))
        t_s = model.windows_s_[index]
        held = self.estimate if self.estimate.reason == Reason.CONFIDENT_GROUP else None
        outside = bool(self._forces) and not force_in_range(
            model, index, float(np.mean(self._forces[-FORCE_SAMPLES:])))
        flagged = not outside and pad_model_misfit(model, x, index, self._measured)
        if self._misfit_run.step(flagged, last):
            return self._misfit(p, index)
        step = self._rule.step(index, rule_posterior(model, p, x, index),
                               may_commit=model.may_commit(index) and not flagged,
                               force_outside=outside,
                               unlike=lambda: bool(model.outside_classes(x, index)[0]))
        kind, what = step if step is not None else (None, None)
        reading = None
        early = self._early.step(model, x, index,
                                 step is None and held is None and not outside and not flagged)
        if early is not None:
            est = Estimate(t_s, tuple(p), NEW_MATERIAL, new_material_confidence(early), True,
                           Reason.NEW_MATERIAL)
            reading = early
        elif outside and held is None:
            est = Estimate(t_s, tuple(p), UNKNOWN if last else model.classes_[k], float(p[k]),
                           last, FORCE_OUTSIDE if last else Reason.UNDECIDED)
        elif outside:
            est = Estimate(t_s, tuple(p), held.label, float(p[k]), True, Reason.CONFIDENT_GROUP)
        elif kind == "class":
            est = Estimate(t_s, tuple(p), model.classes_[what], float(p[k]), True,
                           Reason.CONFIDENT)
        elif held is not None:            # a group stands until a member is sure alone
            est = Estimate(t_s, tuple(p), held.label, float(p[k]), True, Reason.CONFIDENT_GROUP)
        elif kind == "pair":
            est = Estimate(t_s, tuple(p), Label.of(model.classes_[j] for j in what),
                           float(p[list(what)].sum()), True, Reason.CONFIDENT_GROUP)
        elif last and (reading := _new_material(model, x, index)) is not None:
            est = Estimate(t_s, tuple(p), NEW_MATERIAL, new_material_confidence(reading), True,
                           Reason.NEW_MATERIAL)
        elif last:
            est = Estimate(t_s, tuple(p), UNKNOWN, float(p[k]), True,
                           Reason.OUTSIDE_CLASSES if self._rule.unlike else Reason.NOT_CONFIDENT)
        else:
            est = Estimate(t_s, tuple(p), model.classes_[k], float(p[k]), False)
        if not est.label.is_new:
            reading = reading_of(model, x, index)
        if reading is not None:
            est = replace(est, **reading_fields(reading, est.label.is_new))
        self.estimate = est
        if last and est.decided and reading is not None and est.label.members and \
                not est.label.is_new and reading.outside(est.label):
            return self._revised(x, p, index, reading)  # a pair or class decided at the last
        self._watch = est.final and not last and est.label.is_material and \
            not est.label.is_new and hasattr(model, "effusivity_reading")
        return est

    def _misfit(self, p, index: int) -> Estimate:
        """The touch not named by the pad model, for good (see :func:`pad_model_misfit`):
        unknown; with a fallback (``model.fallback_``), the fallback's stream
        from now on, fed the touch's samples so far (:func:`fallen_back`)."""
        self._watch = False
        t_s = self.model.windows_s_[index]
        self.estimate = Estimate(t_s, tuple(p), UNKNOWN, float(np.max(p)), True,
                                 Reason.PAD_MODEL_MISFIT)
        fallback = getattr(self.model, "fallback_", None)
        if fallback is None:
            return self.estimate
        self._fallback = StreamingIdentifier(fallback, self.gap_k, self.t_object_c)
        for row, force_n, measured in self._pushed:
            self._fallback.push(row, force_n, measured)
        return self._from_fallback(replace(self._fallback.estimate,
                                           t_s=max(t_s, self._fallback.estimate.t_s)))

    def _from_fallback(self, est: Estimate | None) -> Estimate | None:
        """The fallback's estimate as this stream's: a class or pair it names
        with the reason ``PAD_MODEL_FALLBACK``; anything else it decides
        (unknown) is the pad model's misfit."""
        if est is None:
            return None
        if est.decided and (est.label.is_unknown or est.label.is_new):
            est = replace(est, label=UNKNOWN, reason=Reason.PAD_MODEL_MISFIT)
        elif est.decided:
            est = replace(est, reason=Reason.PAD_MODEL_FALLBACK)
        self.estimate = est
        return est

    def _revised(self, x, p, index: int, reading=None) -> Estimate | None:
        """The last window of a touch named before: a new material where
        the estimate lies outside the named class's predictive, else the
        decision stands (None: nothing new). ``reading``: the window's, when
        the caller has it already."""
        self._watch = False
        if pad_model_misfit(self.model, x, index, self._measured):
            return self._misfit(p, index)
        if reading is None:
            reading = reading_of(self.model, x, index)
        if reading is None or not reading.outside(self.estimate.label):
            return None
        self.estimate = Estimate(self.model.windows_s_[index], tuple(p), NEW_MATERIAL,
                                 new_material_confidence(reading), True, Reason.NEW_MATERIAL,
                                 **reading_fields(reading, True))
        return self.estimate
