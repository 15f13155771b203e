"""``bench unseen``'s open-set trade: the same touches decided by the same
identifier with its prior weight of an unseen material at 0 (a closed set,
the default) and at :data:`WEIGHTS` (``EffusivityFit.unseen_weight``): per
weight, the trained touches named right and when (the first commitment,
a pair's included), and the unseen touches named a trained class or pair at
any time (at the end, or before a revision to a new material). Speed
against the issue's "no unseen material named as a trained one"."""

from __future__ import annotations

import numpy as np

#: The weights reported beside the identifier's own (1: an unseen material
#: as likely as each trained one): the curve of speed against error, the
#: same touches decided at each (cheap: the fits are the identifier's cache).
WEIGHTS = (0.01, 0.03, 0.1, 0.3, 1.0)


def decisions(identifier, contacts, weight: float) -> list:
    """``decide_all`` with the identifier's ``unseen_weight`` set to
    ``weight`` for the call (its own afterwards)."""
    from telethermal.ident.anytime import decide_all

    own = identifier.unseen_weight
    identifier.unseen_weight = float(weight)
    try:
        return decide_all(identifier, contacts)
    finally:
        identifier.unseen_weight = own


def inside_at_commit(identifier, contacts, decided) -> list:
    """Per decision, for one that named a trained class or pair at some
    time: whether the touch's effusivity estimate lay inside the predictive
    of a material it named (the first name given; a pair's members and what
    it refined to) at the window it was first named; None otherwise."""
    from telethermal.ident.openset import reading_of

    windows = [round(float(w), 9) for w in identifier.windows_s_]
    out = []
    for j, d in enumerate(decided):
        t = d.time_first_s if d.time_first_s is not None else d.time_s
        if not _named_trained(d) or t is None:
            out.append(None)
            continue
        named = set(d.label.members if not d.label.is_new else ()) | \
            set(str(d.revised_from or "").split("|")) - {""}
        reading = reading_of(identifier, contacts.x[j][None], windows.index(round(float(t), 9)))
        out.append(reading is not None and bool(named & set(reading.inside)))
    return out


def _named_trained(d) -> bool:
    """Named a trained class or pair at any time."""
    if d.label.is_new:
        return bool(getattr(d, "revised_from", None))
    return not d.label.is_unknown


def summary(labels, decided, trained, inside=None) -> dict:
    """One weight's figures over ``decided`` (decisions, aligned with
    ``labels``); ``inside``: :func:`inside_at_commit` of them, when known."""
    per = {}
    inside = [None] * len(decided) if inside is None else list(inside)
    for m in dict.fromkeys(labels):
        ds = [(d, k) for lab, d, k in zip(labels, decided, inside) if lab == m]
        times = [d.time_first_s if d.time_first_s is not None else d.time_s for d, _ in ds
                 if d.time_s is not None and not d.label.is_new]
        per[m] = {"n": len(ds), "named_right": sum(str(d.label) == m for d, _ in ds),
                  "named_trained_ever": sum(_named_trained(d) for d, _ in ds),
                  "named_trained_inside_at_commit": sum(k is True for _, k in ds),
                  "first_decision_s_p50": float(np.median(times)) if times else None}
    tr = [r for m, r in per.items() if m in trained]
    un = [r for m, r in per.items() if m not in trained]
    return {"materials": per,
            "trained_named_right": sum(r["named_right"] for r in tr),
            "trained_n": sum(r["n"] for r in tr),
            "unseen_named_trained_ever": sum(r["named_trained_ever"] for r in un),
            "unseen_named_trained_inside_at_commit": sum(
                r["named_trained_inside_at_commit"] for r in un),
            "unseen_n": sum(r["n"] for r in un)}


def section_lines(report: dict) -> list[str]:
    """The open-set trade in ``bench unseen``'s section: per weight, the
    trained touches named right (and each material's first decision p50),
    the unseen touches named a trained class at any time."""
    trade = report.get("open_set_trade")
    if not isinstance(trade, dict):
        return []
    rows = []
    for w, s in trade.items():
        t50 = ", ".join(f"{m} {r['first_decision_s_p50']:.2f} s"
                        for m, r in s["materials"].items()
                        if m in report["trained"] and r["first_decision_s_p50"] is not None)
        inside = s.get("unseen_named_trained_inside_at_commit")
        rows.append([w, f"{s['trained_named_right']} of {s['trained_n']}", t50 or "-",
                     f"{s['unseen_named_trained_ever']} of {s['unseen_n']}",
                     "-" if inside is None else inside])
    from telethermal.bench.markdown import table
    return ["The open-set trade (`unseen_weight`):", ""] + table(
        ["weight", "trained named right", "first decision p50",
         "unseen named a trained class", "inside that class's predictive then"], rows)
