"""Evaluate an identifier on a dataset: accuracy against time after contact,
confusions (7 classes and the first paper's 5 merged ones), anytime
decisions and the cost of one decision."""

from __future__ import annotations

import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np

from telethermal.data.dataset import Trial, load_dataset, trial_digest
from telethermal.ident.anytime import Reason, decide, decide_all
from telethermal.ident.base import Identifier
from telethermal.ident.prepare import FLUX, MIN_GAP_K, from_trials, window_key
from telethermal.ident.registry import check_scene, load_model
from telethermal.jsonfile import write_json

#: The first paper's merged classes (Table 1): metals, and graphite with rubber.
FIRST_PAPER_MERGE = {"aluminium": "aluminium-steel", "steel": "aluminium-steel",
                     "graphite": "graphite-rubber", "rubber": "graphite-rubber"}


def default_windows(channels) -> list[float]:
    """0.1..1.0 s for heat flux; 1.0..5.0 s for temperature-only models."""
    if FLUX in channels:
        return [round(0.1 * k, 1) for k in range(1, 11)]
    return [float(k) for k in range(1, 6)]


def _confusion(truth, predicted, merge=None):
    merge = merge or {}
    table: dict[str, dict[str, int]] = {}
    for t, p in zip(truth, predicted):
        t, p = merge.get(t, t), merge.get(p, p)
        row = table.setdefault(t, {})
        row[p] = row.get(p, 0) + 1
    return table


def _percentiles(values):
    if not values:
        return {"n": 0}
    v = np.asarray(values)
    return {"n": int(len(v)), "p50": float(np.percentile(v, 50)),
            "p90": float(np.percentile(v, 90)), "max": float(v.max()),
            "values": [round(float(x), 4) for x in v]}


#: Calibration errors pool the held-out posteriors of every window of a
#: model up to this time after contact (every posterior a decision within
#: 1 s consults): ``identify cv`` and ``bench identify`` alike.
ECE_MAX_S = 1.0


def expected_calibration_error(proba: np.ndarray, truth: np.ndarray, bins: int = 15) -> float:
    """Top-label expected calibration error (Guo et al. 2017): the mean over
    equal-width confidence bins of |accuracy - confidence|, weighted by the
    share of predictions in each bin.

    Parameters
    ----------
    proba : ndarray, shape (N, n_classes)
    truth : ndarray of int, shape (N,)
    """
    proba = np.asarray(proba, dtype=np.float64)
    if len(proba) == 0:
        return float("nan")
    confidence = proba.max(axis=1)
    correct = proba.argmax(axis=1) == np.asarray(truth)
    which = np.minimum((confidence * bins).astype(int), bins - 1)
    ece = 0.0
    for b in range(bins):
        inside = which == b
        if inside.any():
            ece += inside.mean() * abs(correct[inside].mean() - confidence[inside].mean())
    return float(ece)


def decision_summary(decisions, labels, within_s: float = 1.0) -> dict:
    """Commit rate, accuracy of the committed decisions and their median
    time, counting commitments to a class or a group within ``within_s``
    (the first commitment's time; a group is right when it holds the
    truth, and ``group_rate`` says how many stayed groups)."""
    def first(d):
        return d.time_first_s if d.time_first_s is not None else d.time_s

    committed = [(d, lab) for d, lab in zip(decisions, labels)
                 if not d.label.is_unknown and first(d) is not None and first(d) <= within_s + 1e-9]
    return {"commit_rate": len(committed) / len(decisions) if decisions else float("nan"),
            "accuracy": (float(np.mean([d.label.holds(lab) for d, lab in committed]))
                         if committed else None),
            "time_s_p50": (float(np.median([first(d) for d, _ in committed]))
                           if committed else None),
            "group_rate": (sum(d.reason == Reason.CONFIDENT_GROUP for d, _ in committed)
                           / len(decisions) if decisions else float("nan")),
            # Commitments to one material only (a group left as a group is not one).
            "single_commit_rate": (sum(d.reason != Reason.CONFIDENT_GROUP for d, _ in committed)
                                   / len(decisions) if decisions else float("nan")),
            "single_accuracy": (float(np.mean([d.label == lab for d, lab in committed
                                               if d.reason != Reason.CONFIDENT_GROUP]))
                                if any(d.reason != Reason.CONFIDENT_GROUP for d, _ in committed)
                                else None),
            "committed": len(committed), "touches": len(decisions),
            "unknown_reasons": _unknown_reasons(decisions),
            # named by the model's fallback after its pad-model check refused them
            "fallback_named": sum(d.reason == Reason.PAD_MODEL_FALLBACK for d in decisions)}


def _unknown_reasons(decisions) -> dict[str, int]:
    """How many of the decisions were unknown, by reason (plain strings, sorted)."""
    reasons = [str(d.reason) for d in decisions if d.label.is_unknown]
    return {r: reasons.count(r) for r in sorted(set(reasons))}


def inference_cost_ms(model: Identifier, x: np.ndarray, repeats: int = 300) -> dict:
    """Milliseconds for one posterior update (one window, one contact), on one
    CPU thread, over ``repeats`` updates at random windows."""
    from telethermal.ident.recurrent import Recurrent, torch_module
    # torch's thread pool pinned for the methods that use it (imported here,
    # not in the timed calls); the others never import it.
    torch = torch_module() if isinstance(model, Recurrent) else None
    threads = torch.get_num_threads() if torch else None
    if torch:
        torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    costs = []
    try:
        for _ in range(repeats):
            i = int(rng.integers(len(model.windows_s_)))
            row = x[int(rng.integers(len(x)))][None]
            start = time.perf_counter()
            model.update_probe(row, i)
            costs.append((time.perf_counter() - start) * 1e3)
    finally:
        if torch:
            torch.set_num_threads(threads)
    return {"inference_ms_p50": float(np.percentile(costs, 50)),
            "inference_ms_p99": float(np.percentile(costs, 99))}


def wilson_interval(correct: int, n: int, level: float = 0.95) -> list[float]:
    """The Wilson score interval of a proportion ``correct / n`` (scipy's
    binomial test): [lo, hi], valid near 0 and 1 where the normal
    approximation is not (an accuracy of 100 % on 70 touches is [0.95, 1])."""
    from scipy.stats import binomtest

    ci = binomtest(int(correct), int(n)).proportion_ci(level, method="wilson")
    return [float(ci.low), float(ci.high)]


def _accuracy_by_window(model, contacts, windows_s):
    """Accuracy at each window (trials too short for it left out), and the
    guesses at the last window every trial covers, each window's trial
    count and its 95 % interval (the report's ``accuracy_n_by_window_s``
    and ``accuracy_ci_by_window_s``)."""
    accuracy, predicted_at_end = {}, None
    n_by, ci_by = {}, {}
    for w in windows_s:
        n_w = int(round(w * model.sample_rate_hz_)) + 1
        index = model.window_index(n_w)
        usable = contacts.lengths >= n_w
        if index is None or not usable.any():
            continue
        p = model.proba_normalised(contacts.x[usable], index)
        guess = [model.classes_[k] for k in p.argmax(axis=1)]
        truth = [lab for lab, ok in zip(contacts.labels, usable) if ok]
        right = sum(a == b for a, b in zip(guess, truth))
        key = window_key(w)
        accuracy[key] = right / len(truth)
        n_by[key] = len(truth)
        ci_by[key] = wilson_interval(right, len(truth))
        if usable.all():
            predicted_at_end = guess
    return accuracy, predicted_at_end, n_by, ci_by


def evaluate(model: Identifier, trials: list[Trial], windows_s=None) -> dict:
    """Score a fitted identifier on trials it has not seen."""
    # From the model's first window (where its decisions can commit: 0.02 s
    # for the flux methods at 100 Hz), then the usual tenths.
    windows_s = windows_s or sorted({w for w in model.windows_s_ if w < 0.1 - 1e-9} |
                                    set(default_windows(model.channels)))
    skipped = [t for t in trials if not abs(t.gap_k) >= MIN_GAP_K]
    usable_trials = [t for t in trials if abs(t.gap_k) >= MIN_GAP_K]
    accuracy, predicted_at_end, decisions, labels = {}, None, [], []
    n_by, ci_by = {}, {}
    if usable_trials:
        contacts, _ = from_trials(usable_trials, model.channels, model.sample_rate_hz_,
                                  max_s=max(windows_s))
        accuracy, predicted_at_end, n_by, ci_by = _accuracy_by_window(model, contacts,
                                                                      windows_s)
        decisions = decide_all(model, contacts)
        labels = contacts.labels
    decisions += [decide(model, np.empty((0, len(model.channels))), t.gap_k) for t in skipped]
    truth_all = labels + [t.material for t in skipped]
    committed = [(d, t) for d, t in zip(decisions, truth_all) if not d.label.is_unknown]
    report = {
        "method": model.method, "classes": model.classes_, "channels": list(model.channels),
        "trials": len(truth_all), "trials_without_gap": len(skipped),
        "accuracy_by_window_s": accuracy,
        "accuracy_n_by_window_s": n_by, "accuracy_ci_by_window_s": ci_by,
        "decision_time_s": _percentiles([d.time_s for d, _ in committed]),
        "decision_accuracy": (float(np.mean([d.label == t for d, t in committed]))
                              if committed else None),
        "decision_unknown_rate": 1.0 - len(committed) / len(truth_all),
        "unknown_reasons": _unknown_reasons(decisions),
        "threshold": model.threshold,
    }
    if usable_trials:
        report.update(inference_cost_ms(model, contacts.x))
    if predicted_at_end is not None:
        report["confusion"] = _confusion(contacts.labels, predicted_at_end)
        # Only where the scene holds the four materials the paper merged:
        # elsewhere "5 merged classes" has no meaning.
        if set(FIRST_PAPER_MERGE) <= set(contacts.labels):
            report["confusion_5"] = _confusion(contacts.labels, predicted_at_end,
                                               FIRST_PAPER_MERGE)
            merge = FIRST_PAPER_MERGE
            report["accuracy_5_at_end"] = float(np.mean(
                [merge.get(a, a) == merge.get(b, b)
                 for a, b in zip(contacts.labels, predicted_at_end)]))
    return report


def plot_accuracy(reports: dict[str, dict], out_png, title: str = "") -> None:
    """Accuracy against time after contact, one line per method."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, rep in reports.items():
        acc = rep["accuracy_by_window_s"]
        x = [float(k) for k in acc]
        y = np.array([100 * v for v in acc.values()])
        ci = rep.get("accuracy_ci_by_window_s") or {}
        counts = sorted(set((rep.get("accuracy_n_by_window_s") or {}).values()))
        n = "" if not counts else f" (n = {counts[0]}" + (
            f"-{counts[-1]}" if len(counts) > 1 else "") + " touches)"
        if ci and set(ci) == set(acc):
            lo = np.array([100 * ci[k][0] for k in acc])
            hi = np.array([100 * ci[k][1] for k in acc])
            ax.errorbar(x, y, yerr=[y - lo, hi - y], fmt="o-", capsize=3,
                        label=f"{name}{n}, bars: 95 % interval (Wilson)")
        else:
            ax.plot(x, y, "o-", label=f"{name}{n}")
    ax.set_xlabel("time after contact (s)")
    ax.set_ylabel("accuracy (%)")
    ax.set_ylim(0, 102)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    from telethermal.jsonfile import write_figure
    write_figure(fig, out_png, dpi=110)
    plt.close(fig)


def evaluate_saved(model_path: str | Path, data: str | Path, json_path: str | Path,
                   png_path: str | Path, command: str = "", status=nullcontext,
                   scene=None) -> dict:
    """Score the saved model ``model_path`` on the dataset folder ``data``
    (or its ``pad/``; refused when the dataset, or ``scene``, names another
    scene than the model's); the report, with ``command``, goes to
    ``json_path``, the accuracy plot to ``png_path``. ``status(text)``: a
    context manager held while evaluating. ``scene``: the touches' Scene
    (a ``--scene`` file: the model finds its pad model by that name)."""
    from telethermal.ident.registry import pad_dataset, scene_name, touches_scene

    model = load_model(model_path)
    data = pad_dataset(data)
    named = scene_name(touches_scene(data, scene))
    if scene is not None:
        from telethermal.ident.fitted import register_scene
        register_scene(scene)
    if named is not None:
        check_scene(model, named, str(model_path))
    trials = load_dataset(data)
    with status(f"evaluating on {data}"):
        report = evaluate(model, trials)
    if model.training_digests_:
        trained = set(model.training_digests_)
        report["trials_in_training"] = sum(trial_digest(t) in trained for t in trials)
    report["command"] = command
    write_json(json_path, report)
    plot_accuracy({model.method: report}, png_path, f"{model_path} on {data}")
    return report


def text_report(report: dict, json_path, png_path) -> list[str]:
    """What ``telethermal identify eval`` prints of ``report``."""
    acc = ", ".join(f"{k} s {100 * v:.0f} %" for k, v in report["accuracy_by_window_s"].items())
    lines = [f"accuracy: {acc}"]
    if report.get("trials_in_training"):
        lines.insert(0, f"warning: {report['trials_in_training']} of {report['trials']} "
                        f"evaluation trials were in the model's training data: these figures "
                        f"are not held out (use `identify cv`, or data the model did not see)")
    d = report["decision_time_s"]
    if d["n"]:
        lines.append(f"decisions: {d['n']} committed, median {d['p50']:.2f} s, accuracy "
                     f"{100 * report['decision_accuracy']:.1f} %; unknown "
                     f"{100 * report['decision_unknown_rate']:.0f} %")
    return lines + [f"inference p50 {report['inference_ms_p50']:.3f} ms, p99 "
                    f"{report['inference_ms_p99']:.3f} ms",
                    f"wrote {json_path} and {png_path}"]
