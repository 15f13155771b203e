"""``telethermal bench identify``: the decisions as the slave makes them
live, the figures over several sessions with their intervals, and the
physical limit beside them (issue 29).

- **Live decisions.** Every held-out touch of Table 1's folds is decided by
  :func:`~telethermal.ident.anytime.decide` (the same decision the slave's
  :class:`~telethermal.ident.anytime.StreamingIdentifier` makes sample by
  sample: tested equal) and counted once as ``named`` (the right material
  alone), ``pair`` (a pair holding it), ``unknown`` (no commitment, or
  "unknown") or ``wrong`` (a material or pair without it): the four rates
  sum to 1. ``time_s_p50``: the median time of the first commitment.
- **Sessions.** Table 1 is run on ``sessions`` independent sessions (the
  pad database drawn with seeds ``seed``, ``seed + 1``, ...: other
  instruments, calibrations, trials); every figure pools their touches and
  carries a Wilson 95 % interval (``wilson_interval``).
- **The limit.** :class:`~telethermal.ident.oracle.Oracle`, the Bayes rule
  of the simulator's own generative model, on the same sessions' touches
  (all of them: it learns nothing from them), per window with its interval.
"""

from __future__ import annotations

import numpy as np

from telethermal.ident.evaluate import FIRST_PAPER_MERGE, wilson_interval
from telethermal.ident.label import Reason

#: The outcomes of a touch's live decision, in the order they are reported.
OUTCOMES = ("named", "pair", "unknown", "wrong")
#: The oracle's windows (Table 1's, and the first decisions').
LIMIT_WINDOWS_S = (0.1, 0.25, 0.5, 0.75, 1.0)


def outcome(decision, truth: str) -> str:
    """What a touch's decision told the operator: one of :data:`OUTCOMES`."""
    if decision.label.is_unknown or decision.time_s is None:
        return "unknown"
    if not decision.label.holds(truth):
        return "wrong"
    return "pair" if decision.reason == Reason.CONFIDENT_GROUP else "named"


def live_counts(decisions, labels) -> dict:
    """Per-touch outcomes of ``decisions`` (counts), and the first
    commitments' times (s)."""
    out = {o: 0 for o in OUTCOMES}
    times = []
    for d, truth in zip(decisions, labels):
        out[outcome(d, truth)] += 1
        first = d.time_first_s if d.time_first_s is not None else d.time_s
        if not d.label.is_unknown and first is not None:
            times.append(float(first))
    return {"counts": out, "touches": len(labels), "times_s": times}


def live_summary(per_session: list[dict]) -> dict:
    """The rates of :data:`OUTCOMES` over the sessions' touches, each with
    its Wilson interval, the median commitment time, and per session."""
    n = sum(s["touches"] for s in per_session)
    out = {"touches": n, "sessions": len(per_session)}
    for o in OUTCOMES:
        k = sum(s["counts"][o] for s in per_session)
        out[f"{o}_rate"] = k / n if n else None
        out[f"{o}_rate_ci"] = wilson_interval(k, n) if n else None
    times = [t for s in per_session for t in s["times_s"]]
    out["time_s_p50"] = float(np.median(times)) if times else None
    out["per_session"] = [{o: s["counts"][o] for o in OUTCOMES} for s in per_session]
    return out


def pooled_accuracy(per_session: list[dict], key: str) -> tuple[dict, dict]:
    """Table 1's ``key`` ("accuracy_7" or "accuracy_5") pooled over the
    sessions (each a mean over its ``n_touches``) and its Wilson intervals."""
    acc, ci = {}, {}
    for w in per_session[0][key]:
        right = sum(round(s[key][w] * s["n_touches"]) for s in per_session)
        n = sum(s["n_touches"] for s in per_session)
        acc[w], ci[w] = right / n, wilson_interval(right, n)
    return acc, ci


def sessions_table1(table1, method: str, seed: int, sessions: int, first: dict) -> dict:
    """``first`` (Table 1 of session ``seed``) with its figures pooled over
    ``sessions`` sessions: ``accuracy_7``/``accuracy_5`` and their ``_ci``,
    ``live`` (:func:`live_summary`); the first session's own figures stay
    under ``session_0``."""
    runs = [first] + [table1(method, seed + k) for k in range(1, sessions)]
    out = dict(first)
    out["session_0"] = {k: first[k] for k in ("accuracy_7", "accuracy_5")}
    out["session_seeds"] = [seed + k for k in range(sessions)]
    for key in ("accuracy_7", "accuracy_5"):
        out[key], out[f"{key}_ci"] = pooled_accuracy(runs, key)
    out["live"] = live_summary([r["live_counts"] for r in runs])
    for r in runs:
        r.pop("live_counts", None)
    out.pop("live_counts", None)
    return out


def limit(scene, sessions: list[tuple[int, object]], windows_s=LIMIT_WINDOWS_S) -> dict:
    """The oracle on every session's touches (``(seed, Contacts)``: Table 1's
    touches of that session, the oracle rebuilt for its instruments):
    accuracy per window over the 7 classes and the first paper's 5, pooled,
    with Wilson intervals; per session; and what it confused."""
    from telethermal.ident.oracle import Oracle

    right = {k: {f"{w:g}": 0 for w in windows_s} for k in ("7", "5")}
    confused: dict = {f"{w:g}": {} for w in windows_s}
    per_session, n = [], 0
    for seed, contacts in sessions:
        oracle = Oracle.for_scene(scene, seed=seed, max_s=max(windows_s))
        row = {"seed": seed, "touches": len(contacts), "accuracy_7": {}}
        # The oracle's own scoring (one posterior per window); the 5 merged
        # classes from the same guesses.
        by_window = oracle.accuracy_by_window(contacts, windows_s)
        for w, scored in zip(windows_s, by_window.values()):
            key, guess = f"{w:g}", scored["predicted"]
            row["accuracy_7"][key] = scored["accuracy"]
            right["7"][key] += scored["correct"]
            right["5"][key] += sum(FIRST_PAPER_MERGE.get(a, a) == FIRST_PAPER_MERGE.get(b, b)
                                   for a, b in zip(guess, contacts.labels))
            for t, g in zip(contacts.labels, guess):
                if t != g:
                    confused[key][f"{t}->{g}"] = confused[key].get(f"{t}->{g}", 0) + 1
        per_session.append(row)
        n += len(contacts)
    out = {"sessions": per_session, "touches": n, "confused": confused}
    for k in ("7", "5"):
        out[f"accuracy_{k}"] = {w: c / n for w, c in right[k].items()}
        out[f"accuracy_{k}_ci"] = {w: wilson_interval(c, n) for w, c in right[k].items()}
    out["model"] = ("the simulator's own held-pad contact per material; amplitude marginalised "
                    "in closed form, (log h, onset offset) by Laplace under their Monte Carlo "
                    "prior; each session's instruments known (as the methods trained on it "
                    "have them); see ident/oracle.py")
    return out


def gaps_to_limit(methods: dict, lim: dict) -> dict:
    """Per method, the oracle's accuracy less the method's (7 classes,
    pooled over sessions) at every window both have, in points."""
    out = {}
    for method, rep in methods.items():
        acc = rep["table1"]["accuracy_7"]
        out[method] = {w: round(100 * (lim["accuracy_7"][k] - acc[w]), 2)
                       for w in acc for k in lim["accuracy_7"] if float(k) == float(w)}
    return out
