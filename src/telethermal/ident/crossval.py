"""Grouped k-fold cross-validation of an identification method on a dataset
(``telethermal identify cv``): what a reviewer asks of an accuracy.

A fold never splits a group (the trials' ``group``: a person, a session, an
object), so a model is always scored on groups it did not see. Each fold's
model is fitted on the other folds; every held-out trial is scored once:

* accuracy at every window of the method (the windows the anytime decision
  consults, from the first), each with its trial count and 95 % Wilson
  interval;
* the anytime decisions the slave would make on those touches (the same
  decision code): how many commit within 1 s, how many of those are right,
  how many name one material (a pair and "unknown" do not), the median
  time, and the confusion of the decisions (truth -> what was decided, pairs
  and "unknown" as their own columns);
* the calibration error of the held-out posteriors (windows up to 1 s).
"""

from __future__ import annotations

import time

import numpy as np

from telethermal.errors import IdentificationError
from telethermal.ident.anytime import decide_all
from telethermal.ident.base import group_folds
from telethermal.ident.evaluate import (ECE_MAX_S, decision_summary,
                                        expected_calibration_error, wilson_interval)
from telethermal.ident.label import Reason
from telethermal.ident.prepare import MIN_GAP_K, from_trials
from telethermal.ident.registry import make, with_fallback


def cross_validate(trials, method: str, folds: int = 5, channels=("heat_flux_W_m2",),
                   max_window_s: float = 1.0, progress=None, scene: str | None = None,
                   calibration=None, fallback: bool = False) -> dict:
    """Grouped ``folds``-fold cross-validation of ``method`` on ``trials``;
    the report described in the module docstring. ``progress(text)``:
    called before each fold; ``scene``: the trials' scene, for the methods
    that fit its pad's model, and ``calibration`` that pad's (a PadCalibration);
    ``fallback``: each fold's model with its model-free fallback trained on
    the same touches (``registry.with_fallback``), as the slave has it."""
    if folds < 2:
        raise IdentificationError(f"--folds {folds}: cross-validation needs at least 2 folds")
    probe = make(method, scene=scene, calibration=calibration, channels=channels,
                 max_window_s=max_window_s)
    contacts, skipped = from_trials(trials, probe.channels, max_s=max_window_s)
    groups = sorted(set(contacts.groups))
    if len(groups) < 2:
        raise IdentificationError(
            f"cross-validation holds out whole groups, and these trials have "
            f"{len(groups)} ({', '.join(groups) or 'none'}): give the trials' 'group' "
            f"(a person, a session, an object) so that at least two differ")
    k = min(folds, len(groups))
    hits: dict[str, list[bool]] = {}
    decisions, labels, probas, truth, fit_s = [], [], [], [], []
    for i, test in enumerate(group_folds(contacts.groups, k)):
        if progress is not None:
            progress(f"fold {i + 1} of {k}: training {method}")
        train = np.setdiff1d(np.arange(len(contacts)), test)
        held = contacts.subset(test)
        start = time.perf_counter()
        model = make(method, scene=scene, calibration=calibration, channels=channels,
                     max_window_s=max_window_s)
        model.fit(contacts.subset(train))
        if fallback:
            with_fallback(model, contacts.subset(train))
        fit_s.append(time.perf_counter() - start)
        unseen = sorted(set(held.labels) - set(model.classes_))
        if unseen:
            raise IdentificationError(
                f"fold {i + 1}: its training groups hold no trial of {', '.join(unseen)}: "
                f"every material needs trials in at least two groups")
        y = np.array([model.classes_.index(c) for c in held.labels])
        for index, w in enumerate(model.windows_s_):
            n_w = int(round(w * model.sample_rate_hz_)) + 1
            usable = held.lengths >= n_w
            if not usable.any():
                continue
            p = model.proba_normalised(held.x[usable], index)
            hits.setdefault(f"{w:g}", []).extend(p.argmax(axis=1) == y[usable])
            if w <= ECE_MAX_S + 1e-9:
                probas.append(p)
                truth.append(y[usable])
        decisions += decide_all(model, held)
        labels += held.labels
    accuracy = {w: float(np.mean(h)) for w, h in hits.items()}
    summary = decision_summary(decisions, labels)
    # What each touch ended as, over the whole contact (they sum to 1).
    n = len(decisions)
    unknown = sum(d.label.is_unknown for d in decisions)
    pairs = sum(not d.label.is_unknown and (d.reason == Reason.CONFIDENT_GROUP or
                                            len(d.label.members) == 2) for d in decisions)
    return {
        "method": method, "channels": list(probe.channels), "folds": k,
        "folds_asked": folds, "grouped_by": "group", "groups": len(groups),
        "trials": len(contacts), "trials_without_gap": len(skipped),
        "min_gap_k": MIN_GAP_K, "classes": sorted(set(contacts.labels)),
        "accuracy_by_window_s": accuracy,
        "accuracy_n_by_window_s": {w: len(h) for w, h in hits.items()},
        "accuracy_ci_by_window_s": {w: wilson_interval(int(np.sum(h)), len(h))
                                    for w, h in hits.items()},
        "calibration_ece": expected_calibration_error(np.vstack(probas), np.concatenate(truth))
        if probas else None,
        "calibration_ece_up_to_s": ECE_MAX_S,
        "decisions": {
            "commit_rate": summary["commit_rate"], "accuracy": summary["accuracy"],
            "accuracy_ci": (wilson_interval(round(summary["accuracy"] * summary["committed"]),
                                            summary["committed"])
                            if summary["committed"] else None),
            "named_rate": (n - unknown - pairs) / n if n else None,
            "pair_rate": pairs / n if n else None,
            "unknown_rate": unknown / n if n else None,
            "named_accuracy": summary["single_accuracy"],
            "time_s_p50": summary["time_s_p50"], "committed": summary["committed"],
            "touches": summary["touches"], "unknown_reasons": summary["unknown_reasons"],
            "fallback_named": summary["fallback_named"],
            "confusion": decision_confusion(decisions, labels),
        },
        "train_s_per_fold_mean": float(np.mean(fit_s)),
    }


def decision_confusion(decisions, labels) -> dict[str, dict[str, int]]:
    """truth -> {what was decided: count}: a material, a pair ``a|b`` or
    ``unknown``, each its own column."""
    table: dict[str, dict[str, int]] = {}
    for d, truth in zip(decisions, labels):
        row = table.setdefault(truth, {})
        row[str(d.label)] = row.get(str(d.label), 0) + 1
    return {t: dict(sorted(row.items())) for t, row in sorted(table.items())}


def text_report(report: dict, json_path=None) -> list[str]:
    """What ``telethermal identify cv`` prints."""
    def pct(x):
        return "-" if x is None else f"{100 * x:.1f} %"

    acc, ci = report["accuracy_by_window_s"], report["accuracy_ci_by_window_s"]
    shown = [w for w in acc if float(w) in (0.02, 0.05, 0.1, 0.25, 0.5, 0.75, 1.0)] or list(acc)
    d = report["decisions"]
    lines = [f"{report['method']}: {report['folds']} folds by group ({report['groups']} groups, "
             f"{report['trials']} trials)",
             "accuracy (95 % interval): " + ", ".join(
                 f"{w} s {pct(acc[w])} [{100 * ci[w][0]:.0f}-{100 * ci[w][1]:.0f}]"
                 for w in shown),
             f"decisions: {pct(d['commit_rate'])} committed within 1 s, {pct(d['accuracy'])} of "
             f"them right; named alone {pct(d['named_rate'])}, pair {pct(d['pair_rate'])}, "
             f"unknown {pct(d['unknown_rate'])}; median {d['time_s_p50']} s",
             f"calibration error (ECE, windows to {report['calibration_ece_up_to_s']:g} s): "
             + ("-" if report["calibration_ece"] is None else f"{report['calibration_ece']:.3f}")]
    if report["folds"] < report["folds_asked"]:
        lines.append(f"note: {report['folds_asked']} folds asked, {report['groups']} groups: "
                     f"{report['folds']} folds")
    if json_path is not None:
        lines.append(f"wrote {json_path}")
    return lines
