"""Open-set decisions (issue 30, part 2): a touch is named a trained
material only where its live effusivity estimate lies inside what that
material's training touches covered; otherwise it is a **new material**,
reported with its estimate.

An identifier that estimates the touched object's effusivity
(``effusivity-fit``) gives, per window, an :class:`EffusivityReading`: the
estimate and its 95 % interval (W s^0.5/(m^2 K)), the trained class whose
mean estimate at that window is nearest (in ``ln e``), and the largest
two-sided predictive tail probability over the classes (how likely the
likeliest class's touches are to lie this far out). Other identifiers give
none (:func:`reading_of` returns None) and decide as before: a touch outside
every class is then "unknown" ("outside classes"), there being no estimate
to report.

The rule (the same code in :func:`~telethermal.ident.anytime.decide` and
the slave's :class:`~telethermal.ident.anytime.StreamingIdentifier`), for an
identifier that gives readings, at the identifier's last window (the
longest, whose predictive is the narrowest):

* a touch that committed nothing, whose force stayed in the trained range
  and whose estimate lies outside every class's ``1 - outlier_p``
  predictive (``outside_classes``) is decided
  :data:`~telethermal.ident.label.NEW_MATERIAL` with reason
  :attr:`~telethermal.ident.label.Reason.NEW_MATERIAL`;
* a touch committed earlier to a class (or standing as a pair) whose
  estimate there lies outside the predictive of the class it was named
  (of both of the pair) is revised to a new material: a change of mind,
  sent as one (PROTOCOL.md section 6a). An early window's predictive is
  wide (the contact conductance hides the material in the first tenths of
  a second): ``bench unseen`` measured copper, carbon steel, brass, glass
  and concrete committed at 0.06-0.2 s to the trained class next to them,
  every one outside that class's predictive at 1 s.

A new material's confidence is one minus the likeliest class's tail
probability. "unknown" stays for what really is unknown: a gap too small,
the force outside the trained range, a posterior that never convinced, an
estimate-less method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from telethermal.ident.label import Label

#: The unit of an effusivity as printed.
EFFUSIVITY_UNIT = "W s^0.5/(m^2 K)"


@dataclass(frozen=True, slots=True)
class EffusivityReading:
    """One window's effusivity estimate of a touch (see the module)."""

    effusivity_w_s05_m2k: float
    effusivity_lo_w_s05_m2k: float          # the 95 % interval's ends
    effusivity_hi_w_s05_m2k: float
    nearest: str | None                     # class whose mean ln e is nearest; None untrained
    class_tail_p: float | None              # largest two-sided predictive tail over classes
    inside: tuple[str, ...] = ()            # the classes whose predictive holds the estimate

    def outside(self, label) -> bool:
        """The estimate lies outside the predictive of every material
        ``label`` names (a class, or a pair's two)."""
        return not any(m in self.inside for m in Label(label).members)


#: The two-sided 95 % point of the normal (the estimator's intervals' too):
#: an estimate's interval in ``ln e`` is its estimate +- Z95 sd.
Z95 = 1.959963984540054


def log_sd_of_interval(e: float, lo: float, hi: float) -> float:
    """The standard deviation in ``ln e`` of an estimate ``e`` and its 95 %
    interval [lo, hi], normal in ``ln e`` about ``ln e`` (the estimator's
    Laplace interval): its wider half over the 95 % quantile, so an
    interval clipped at one end of the estimator's grid (a metal early in
    its touch) gives its sd all the same (clipped at both, less)."""
    return max(math.log(e / lo), math.log(hi / e)) / Z95


def reading_of(model, x, window_index: int) -> EffusivityReading | None:
    """``model``'s effusivity reading of the touch ``x`` (1, n, C) at its
    window ``window_index``; None when the method gives none."""
    get = getattr(model, "effusivity_reading", None)
    return None if get is None else get(x, window_index)


def new_material_confidence(reading: EffusivityReading) -> float:
    """A new material's confidence: one minus the likeliest class's tail."""
    tail = reading.class_tail_p
    return 1.0 if tail is None else float(max(0.0, 1.0 - tail))


def _sig(value: float, digits: int = 3) -> str:
    """``value`` to ``digits`` significant figures, thousands separated."""
    if not math.isfinite(value) or value == 0:
        return f"{value:g}"
    places = digits - 1 - int(math.floor(math.log10(abs(value))))
    rounded = round(value, places)
    return f"{rounded:,.{max(places, 0)}f}"


def describe_effusivity(effusivity_w_s05_m2k, lo_w_s05_m2k=None, hi_w_s05_m2k=None) -> str:
    """``"effusivity 1,390 W s^0.5/(m^2 K) (95 %: 1,270 to 1,520)"``."""
    out = f"effusivity {_sig(float(effusivity_w_s05_m2k))} {EFFUSIVITY_UNIT}"
    if lo_w_s05_m2k is not None and hi_w_s05_m2k is not None:
        out += f" (95 %: {_sig(float(lo_w_s05_m2k))} to {_sig(float(hi_w_s05_m2k))})"
    return out


def describe(label, reason=None, effusivity_w_s05_m2k=None, lo_w_s05_m2k=None,
             hi_w_s05_m2k=None, nearest=None) -> str:
    """What a person is told of a touch's decision: the label, and for a new
    material its estimate and nearest class ("new material, effusivity 1,390
    W s^0.5/(m^2 K) (95 %: 1,270 to 1,520), nearest: glass"); for
    "unknown", why (its reason), as before."""
    label = Label(label)
    if label.is_new:
        out = str(label)
        if effusivity_w_s05_m2k is not None:
            out += ", " + describe_effusivity(effusivity_w_s05_m2k, lo_w_s05_m2k, hi_w_s05_m2k)
        return out + (f", nearest: {nearest}" if nearest else "")
    if label.is_unknown and reason:
        return f"{label} ({reason})"
    return str(label)


def describe_estimate(estimate) -> str:
    """:func:`describe` of an :class:`~telethermal.ident.anytime.Estimate`."""
    return describe(estimate.label, estimate.reason, estimate.effusivity_w_s05_m2k,
                    estimate.effusivity_lo_w_s05_m2k, estimate.effusivity_hi_w_s05_m2k,
                    estimate.nearest)


def touch_text(estimate) -> str:
    """What a touch ended as, for a person: :func:`describe_estimate` of a
    decided estimate; "unknown (why)" otherwise (no estimate, undecided)."""
    if estimate is None:
        return "unknown (no estimate)"
    if not estimate.decided:
        return "unknown (no decision)"
    return describe_estimate(estimate)


#: An estimate's effusivity fields, as the wire, the view and recordings name them.
EFFUSIVITY_KEYS = ("effusivity_w_s05_m2k", "effusivity_lo_w_s05_m2k", "effusivity_hi_w_s05_m2k",
                   "nearest")


def effusivity_of(estimate) -> dict:
    """The effusivity fields an estimate (or a decision) holds, None ones
    left out: what goes on the wire (optional fields, section 6c)."""
    out = {}
    for key in EFFUSIVITY_KEYS:
        value = getattr(estimate, key, None)
        if value is not None:
            out[key] = value if key == "nearest" else float(value)
    return out


def reading_fields(reading: EffusivityReading | None, new: bool) -> dict:
    """An estimate's effusivity fields from ``reading`` (``nearest`` only for
    a new material: what it is reported beside)."""
    if reading is None:
        return {}
    return {"effusivity_w_s05_m2k": reading.effusivity_w_s05_m2k,
            "effusivity_lo_w_s05_m2k": reading.effusivity_lo_w_s05_m2k,
            "effusivity_hi_w_s05_m2k": reading.effusivity_hi_w_s05_m2k,
            **({"nearest": reading.nearest} if new else {})}


__all__ = ["EFFUSIVITY_KEYS", "EFFUSIVITY_UNIT", "effusivity_of", "touch_text", "EffusivityReading", "describe", "describe_effusivity",
           "describe_estimate", "new_material_confidence", "reading_fields", "reading_of"]
